//! The Khepera III serial text protocol: commands, answers and unit conversions.
//!
//! Manual ver 2.2, Appendix A: a command is an upper-case letter, then comma-separated
//! parameters, ended by a line feed; 32-bit parameters carry the prefix `l` (`d` for 16 bits).
//! The answer starts with the same letter in lower case, then comma-separated values, ended by a
//! line feed (K-Team's `kh3server` sends `\r\n`; [`parse_answer`] takes either and ignores blank
//! lines). Wheel pairs are always left first, right second.
//!
//! | command             | answer             | effect                                        |
//! |---------------------|--------------------|-----------------------------------------------|
//! | `D,l<left>,l<right>` | `d`               | set both wheel speeds [speed units]           |
//! | `E`                 | `e,<left>,<right>` | read both wheel speeds [speed units]          |
//! | `R`                 | `r,<left>,<right>` | read both 32-bit position counters \[pulses\]   |
//! | `I,l<left>,l<right>` | `i`               | set both position counters \[pulses\]           |
//! | anything else       | `$`                | not understood (`kh3server`'s error answer)    |
//!
//! See the [module docs](super) for the sources and the units.

use std::fmt;

use wheelid_core::RobotError;

use crate::profile::RobotProfile;

/// The line terminator of a command (manual ver 2.2, Appendix A: "terminated by a line feed").
pub const TERMINATOR: &str = "\n";

/// Speed units per mm/s for a dsPIC firmware before 3.0: `Kspeed` = 144.01 (manual ver 2.2
/// §3.2.1; `MM_S_TO_SPEED_FIRMWARE_S_3` in K-Team's libkorebot examples, manual ver 3.3).
pub const SPEED_UNITS_PER_MM_S_BEFORE_3: f64 = 144.01;

/// Speed units per mm/s for a firmware 3.0 or later: `MM_S_TO_SPEED_FIRMWARE_BE_3` = 218.72
/// (K-Team's libkorebot examples, manual ver 3.3).
pub const SPEED_UNITS_PER_MM_S_FROM_3: f64 = 218.72;

/// Millimetres per encoder pulse for a firmware 3.0 or later: `PULSE_TO_MM_FIRMWARE_BE_3` =
/// 0.03068 mm (K-Team's libkorebot examples, manual ver 3.3).
pub const MM_PER_PULSE_FROM_3: f64 = 0.03068;

/// A value per wheel, left and right (the protocol's order).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Wheels<T> {
    /// Left wheel (motor 1).
    pub left: T,
    /// Right wheel (motor 2).
    pub right: T,
}

impl<T> Wheels<T> {
    /// The pair (left, right).
    pub fn new(left: T, right: T) -> Self {
        Self { left, right }
    }
}

/// A command of the protocol, as the client sends it and the loopback server reads it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Command {
    /// `D,l<left>,l<right>`: set the wheel speeds [speed units]; answer `d`.
    SetSpeed(Wheels<i32>),
    /// `E`: read the wheel speeds; answer `e,<left>,<right>` [speed units].
    ReadSpeed,
    /// `R`: read the position counters; answer `r,<left>,<right>` \[pulses\].
    ReadPosition,
    /// `I,l<left>,l<right>`: set the position counters \[pulses\]; answer `i`.
    SetPosition(Wheels<i32>),
}

impl Command {
    /// The command letter (`D`, `E`, `R`, `I`).
    pub fn letter(&self) -> char {
        match self {
            Command::SetSpeed(_) => 'D',
            Command::ReadSpeed => 'E',
            Command::ReadPosition => 'R',
            Command::SetPosition(_) => 'I',
        }
    }

    /// The letter its answer starts with (`d`, `e`, `r`, `i`).
    pub fn answer_letter(&self) -> char {
        self.letter().to_ascii_lowercase()
    }

    /// The line to send, terminator included: e.g. `D,l14401,l14401\n`, `E\n`.
    pub fn encode(&self) -> String {
        match self {
            Command::SetSpeed(w) | Command::SetPosition(w) => {
                format!("{},l{},l{}{TERMINATOR}", self.letter(), w.left, w.right)
            }
            Command::ReadSpeed | Command::ReadPosition => format!("{}{TERMINATOR}", self.letter()),
        }
    }

    /// Reads a command line (terminator and surrounding blanks ignored). 32-bit arguments may
    /// come with or without their `l` prefix.
    ///
    /// # Errors
    /// A message naming the line and what was wrong, for an unknown letter, a wrong argument
    /// count or an argument that is not a 32-bit integer.
    pub fn parse(line: &str) -> Result<Self, String> {
        let line = line.trim();
        let mut fields = line.split(',');
        let head = fields.next().unwrap_or_default().trim();
        let args: Vec<&str> = fields.map(str::trim).collect();
        let pair = |args: &[&str]| -> Result<Wheels<i32>, String> {
            let [l, r] = args else {
                return Err(format!(
                    "`{line}`: expected two arguments, got {}",
                    args.len()
                ));
            };
            let num = |s: &str| {
                let digits = s.strip_prefix('l').unwrap_or(s);
                digits
                    .parse::<i32>()
                    .map_err(|_| format!("`{line}`: `{s}` is not a 32-bit integer"))
            };
            Ok(Wheels::new(num(l)?, num(r)?))
        };
        match head {
            "D" => Ok(Command::SetSpeed(pair(&args)?)),
            "I" => Ok(Command::SetPosition(pair(&args)?)),
            "E" | "R" if !args.is_empty() => Err(format!("`{line}`: `{head}` takes no arguments")),
            "E" => Ok(Command::ReadSpeed),
            "R" => Ok(Command::ReadPosition),
            _ => Err(format!("`{line}`: unknown command")),
        }
    }
}

impl fmt::Display for Command {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.encode().trim_end())
    }
}

/// What an answer line says.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Answer {
    /// An acknowledgement with no values (`d`, `i`).
    Ack,
    /// Two values, left and right (`e,…`: speed units; `r,…`: pulses).
    Pair(Wheels<i32>),
}

/// Reads the answer `line` to `command`: `d`/`i` for the setters, `e,<left>,<right>` for
/// [`Command::ReadSpeed`], `r,<left>,<right>` for [`Command::ReadPosition`]. Surrounding blanks
/// and `\r` are ignored. A value is a decimal 32-bit integer; one printed unsigned (up to
/// 2³² − 1) is taken modulo 2³², as the firmware's 32-bit registers hold it.
///
/// # Errors
/// [`RobotError::Protocol`] naming the line that came and the answer expected: `$` (command
/// not understood), another letter, a wrong value count, or a value that is not an integer or
/// outside [−2³¹, 2³²).
pub fn parse_answer(command: &Command, line: &str) -> Result<Answer, RobotError> {
    let line = line.trim();
    let letter = command.answer_letter();
    let expected = match command {
        Command::SetSpeed(_) | Command::SetPosition(_) => format!("`{letter}`"),
        Command::ReadSpeed | Command::ReadPosition => format!("`{letter},<left>,<right>`"),
    };
    let bad = |why: &str| {
        RobotError::Protocol(format!(
            "answer to `{command}`: got `{}`, expected {expected} ({why})",
            line.escape_debug()
        ))
    };
    let mut fields = line.split(',');
    let head = fields.next().unwrap_or_default().trim();
    if head == "$" {
        return Err(bad("the robot did not understand the command"));
    }
    if head.len() != 1 || !head.starts_with(letter) {
        return Err(bad("wrong answer letter"));
    }
    let values: Vec<&str> = fields.map(str::trim).collect();
    match command {
        Command::SetSpeed(_) | Command::SetPosition(_) => {
            if values.is_empty() {
                Ok(Answer::Ack)
            } else {
                Err(bad("unexpected values"))
            }
        }
        Command::ReadSpeed | Command::ReadPosition => {
            let [l, r] = values[..] else {
                return Err(bad(&format!("{} values instead of 2", values.len())));
            };
            let l = parse_i32_register(l).map_err(|e| bad(&e))?;
            let r = parse_i32_register(r).map_err(|e| bad(&e))?;
            Ok(Answer::Pair(Wheels::new(l, r)))
        }
    }
}

/// A decimal value of a 32-bit register, printed signed or unsigned, as the register's bits
/// read as a signed (two's complement) i32.
fn parse_i32_register(s: &str) -> Result<i32, String> {
    let v: i64 = s
        .parse()
        .map_err(|_| format!("`{}` is not an integer", s.escape_debug()))?;
    if !(i64::from(i32::MIN)..=i64::from(u32::MAX)).contains(&v) {
        return Err(format!("{v} does not fit a 32-bit register"));
    }
    // Keep the low 32 bits: a value printed unsigned is the same register as its signed reading.
    Ok(v as u32 as i32)
}

/// The conversions between SI and the protocol's units, and the geometry they need.
///
/// Speeds: wheel speed [mm/s] = speed units / `speed_units_per_mm_s`. Positions: wheel travel
/// \[mm\] = pulses / `pulses_per_mm`. v = (v_r + v_l)/2, ω = (v_r − v_l)/`track`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Units {
    /// Speed units per mm/s of wheel speed (`Kspeed`).
    pub speed_units_per_mm_s: f64,
    /// Encoder pulses per mm of wheel travel.
    pub pulses_per_mm: f64,
    /// Track width d \[m\].
    pub track: f64,
    /// Largest wheel speed sent [m/s]; faster wheel commands are clamped to it.
    pub max_wheel_speed: f64,
}

impl Units {
    /// The units of a Khepera III robot described by `profile`, firmware before 3.0: 144.01
    /// speed units per mm/s (manual ver 2.2 §3.2.1), `ticks_per_rev` pulses per wheel
    /// circumference 2π·`wheel_radius` (2764 per 128.8 mm in the manual), the profile's track and
    /// its `v_max` as the wheel-speed limit.
    pub fn from_profile(profile: &RobotProfile) -> Self {
        Self {
            speed_units_per_mm_s: SPEED_UNITS_PER_MM_S_BEFORE_3,
            pulses_per_mm: profile.ticks_per_rev
                / (2.0 * std::f64::consts::PI * profile.wheel_radius * 1000.0),
            track: profile.track,
            max_wheel_speed: profile.v_max,
        }
    }

    /// Checks every number is finite and > 0.
    ///
    /// # Errors
    /// [`RobotError::Setting`] naming the first bad one.
    pub fn validate(&self) -> Result<(), RobotError> {
        for (name, x) in [
            ("speed_units_per_mm_s", self.speed_units_per_mm_s),
            ("pulses_per_mm", self.pulses_per_mm),
            ("track", self.track),
            ("max_wheel_speed", self.max_wheel_speed),
        ] {
            if !(x.is_finite() && x > 0.0) {
                return Err(RobotError::Setting(format!(
                    "khepera: {name} = {x} must be finite and > 0"
                )));
            }
        }
        Ok(())
    }

    /// Wheel speeds [m/s] for (v_ref [m/s], ω_ref [rad/s]): v ∓ dω/2 (left, right).
    pub fn wheel_speeds(&self, v_ref: f64, w_ref: f64) -> Wheels<f64> {
        let half = self.track * w_ref / 2.0;
        Wheels::new(v_ref - half, v_ref + half)
    }

    /// (v [m/s], ω [rad/s]) of wheel speeds [m/s].
    pub fn body_velocity(&self, wheels: Wheels<f64>) -> (f64, f64) {
        (
            (wheels.right + wheels.left) / 2.0,
            (wheels.right - wheels.left) / self.track,
        )
    }

    /// A wheel speed [m/s] in whole speed units: clamped to ±`max_wheel_speed`, then rounded to
    /// the nearest unit (halves away from zero). NaN gives 0.
    pub fn speed_units(&self, wheel_speed: f64) -> i32 {
        let clamped = wheel_speed.clamp(-self.max_wheel_speed, self.max_wheel_speed);
        // `as` saturates at the i32 range; a sane `max_wheel_speed` never gets there.
        (clamped * 1000.0 * self.speed_units_per_mm_s).round() as i32
    }

    /// A wheel speed in speed units as m/s: `units / speed_units_per_mm_s / 1000`.
    pub fn speed_mps(&self, units: i32) -> f64 {
        f64::from(units) / self.speed_units_per_mm_s / 1000.0
    }

    /// The `D` speeds for (v_ref, ω_ref): [`Units::wheel_speeds`], then [`Units::speed_units`].
    pub fn speed_command(&self, v_ref: f64, w_ref: f64) -> Wheels<i32> {
        let w = self.wheel_speeds(v_ref, w_ref);
        Wheels::new(self.speed_units(w.left), self.speed_units(w.right))
    }

    /// (v [m/s], ω [rad/s]) of wheel speeds in speed units (an `E` answer, or what a `D`
    /// command asks for).
    pub fn velocity_of_units(&self, units: Wheels<i32>) -> (f64, f64) {
        self.body_velocity(Wheels::new(
            self.speed_mps(units.left),
            self.speed_mps(units.right),
        ))
    }

    /// Wheel travel \[m\] of a pulse count.
    pub fn pulses_to_m(&self, pulses: f64) -> f64 {
        pulses / self.pulses_per_mm / 1000.0
    }

    /// Pulses of a wheel travel \[m\] (not rounded).
    pub fn m_to_pulses(&self, metres: f64) -> f64 {
        metres * 1000.0 * self.pulses_per_mm
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn commands_encode_and_parse_back() {
        let d = Command::SetSpeed(Wheels::new(-6372, 6372));
        assert_eq!(d.encode(), "D,l-6372,l6372\n");
        assert_eq!(d.to_string(), "D,l-6372,l6372");
        assert_eq!(Command::ReadSpeed.encode(), "E\n");
        assert_eq!(Command::ReadPosition.encode(), "R\n");
        for c in [
            d,
            Command::ReadSpeed,
            Command::ReadPosition,
            Command::SetPosition(Wheels::new(i32::MIN, i32::MAX)),
        ] {
            assert_eq!(Command::parse(&c.encode()), Ok(c));
        }
        // The manual's example, with and without the 32-bit prefix, \r\n tolerated.
        assert_eq!(
            Command::parse("D,l20000,l20000\r\n"),
            Ok(Command::SetSpeed(Wheels::new(20000, 20000)))
        );
        assert_eq!(
            Command::parse("D,20000,-3"),
            Ok(Command::SetSpeed(Wheels::new(20000, -3)))
        );
        for bad in [
            "D,l1",
            "D,l1,l2,l3",
            "D,lx,l2",
            "D,l3000000000,l0",
            "Q",
            "E,1",
            "",
        ] {
            assert!(Command::parse(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn registers_read_signed_or_unsigned() {
        assert_eq!(parse_i32_register("-100"), Ok(-100));
        assert_eq!(parse_i32_register("4294967196"), Ok(-100));
        assert_eq!(parse_i32_register("2147483648"), Ok(i32::MIN));
        assert!(parse_i32_register("4294967296").is_err());
        assert!(parse_i32_register("-2147483649").is_err());
        assert!(parse_i32_register("1.5").is_err());
    }

    #[test]
    fn speed_units_round_half_away_and_clamp() {
        let u = Units::from_profile(&RobotProfile::khepera3());
        // 0.1 m/s = 100 mm/s = 14401 units exactly.
        assert_eq!(u.speed_units(0.1), 14401);
        // 1/144.01 mm/s is one unit; half a unit rounds away from zero.
        assert_eq!(u.speed_units(0.5e-3 / 144.01 * 1.000001), 1);
        assert_eq!(u.speed_units(-0.5e-3 / 144.01 * 1.000001), -1);
        assert_eq!(u.speed_units(f64::NAN), 0);
        assert_eq!(u.speed_units(7.0), 72005); // 0.5 m/s
        assert_eq!(u.speed_units(-7.0), -72005);
    }
}
