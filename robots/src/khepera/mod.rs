//! Khepera III backend over the robot's serial text protocol, and a loopback server that speaks
//! it on top of the simulator.
//!
//! - [`codec`]: the command and answer lines (`D`, `E`, `R`, `I`) and the unit conversions;
//! - [`client`]: [`Khepera`], the [`Robot`](wheelid_core::Robot) that drives a real robot
//!   through a serial port or a TCP–serial bridge ([`KheperaSettings`]);
//! - [`server`]: [`KheperaServer`], the simulator behind a TCP socket, for tests and demos.
//!
//! ```text
//! host                                   Khepera III (dsPIC firmware)
//! D,l16057,l41547\n        ───────────▶  set speeds (left, right) [speed units]
//!                          ◀───────────  d\r\n
//! E\n                      ───────────▶  e,16050,41540\r\n      wheel speeds [speed units]
//! R\n                      ───────────▶  r,-1203,88410\r\n      position counters [pulses]
//! ```
//!
//! # Protocol sources
//!
//! - K-Team, *Khepera III User Manual* ver 2.2 (F. Lambercy, G. Caprari), Appendix A
//!   "Communication protocol": ASCII commands starting with an upper-case letter, parameters
//!   separated by commas, 32-bit values prefixed `l` (`D,l20000,l20000`), terminated by a line
//!   feed; the answer starts with the same letter in lower case and ends with a line feed;
//!   115200 Bd, 8 data bits, 1 stop bit, no parity. Command table: `D` set speed (left, right;
//!   answer `d`), `E` read speed (`e,<left>,<right>`), `R` read the position counters,
//!   `I` set the "32 bit position counter" (answer `i`), one pulse = 0.047 mm at the default ×4
//!   encoder resolution.
//! - Same manual, §3.2.1 "Speed": 2764 measures per wheel revolution, wheel circumference
//!   128.8 mm, RealSpeed [mm/s] = MotorSpeed / Kspeed with Kspeed = 144.01 in the default
//!   configuration; 43 000 (298 mm/s) is the fastest regulated speed, 48 000 (333 mm/s) open loop.
//! - K-Team's `kh3server.c` (J. Tharin, 2012; the "kh3 server" of manual ver 3.3), which answers
//!   the same letters from a KoreBot: `d\r\n`, `e,%d,%d\r\n`, `r,%d,%d\r\n` with motor 1 = left,
//!   motor 2 = right as signed 32-bit integers, takes `\r` or `\n` as the end of a command and
//!   answers `$` to an unknown one.
//! - K-Team's libkorebot examples reproduced in manual ver 3.3: `MM_S_TO_SPEED` 144.01 and
//!   `PULSE_TO_MM` 0.04629 mm for a dsPIC firmware before 3.0, 218.72 and 0.03068 mm from 3.0
//!   (chosen by the version in the `B` answer).
//! - Independent user code (Politechnika Poznańska, `Pioch/Sterowanie-robotem-mobilnym`,
//!   Matlab, 2011–2012): sends `D,l<left>,l<right>` with Kspeed = 144.01, reads `r,<left>,<right>`
//!   with 0.047 mm per pulse, r = 20.5 mm, and integrates the pose with the midpoint heading.
//! - Laut 2011, §3.1 (odometry eq. 3.2–3.3, midpoint heading φ̄ = φ + Δφ/2) and §4.3 (Khepera
//!   III: 500 mm/s, 89 mm track, ≈ 0.02 s sample time with the Khepera III toolbox).
//!
//! # Units followed, and what could not be confirmed
//!
//! The defaults ([`KheperaSettings::default`], from [`RobotProfile::khepera3`]) are those of a
//! dsPIC firmware **before 3.0**, the manual ver 2.2 robot the profile describes:
//!
//! - speed: 144.01 speed units per mm/s (manual §3.2.1 and libkorebot agree);
//! - position: 2764 pulses per wheel revolution of 2π·20.5 mm = 21.459 pulses/mm (0.046601
//!   mm/pulse; the manual's 2764 per 128.8 mm is 0.046599, its "0,047 mm" the same rounded).
//!   libkorebot's 0.04629 mm/pulse disagrees by 0.7 %. Cross-check: a speed unit is a fixed
//!   encoder rate in both firmware families — 144.01 × 0.046599 = 6.7107 and
//!   218.72 × 0.03068 = 6.7103 speed units per pulse/s agree to 0.01 %, while 0.04629 would give
//!   6.666 — so the manual's 128.8/2764 is kept;
//! - another Matlab toolbox (`ernest-galbrun/ensem-sami`, `@khepera3/RWtoK3.m`) uses 288 speed
//!   units per mm/s ("see manual p. 14"), twice Kspeed, while agreeing on 2764.8 pulses per
//!   128.8 mm; this could not be resolved, so
//! - every constant is a setting: `speed_units_per_mm_s`, `pulses_per_mm`, `track` (profile
//!   88.5 mm; thesis 89 mm, the Poznań code 88 mm, libkorebot users 88.41 mm),
//!   `max_wheel_speed` (profile's 0.5 m/s; the manual's regulated maximum is 298 mm/s). For a
//!   firmware 3.0 or later set `speed_units_per_mm_s = 218.72` and
//!   `pulses_per_mm = 32.595` (1/0.03068) — see [`codec::SPEED_UNITS_PER_MM_S_FROM_3`] and
//!   [`codec::MM_PER_PULSE_FROM_3`];
//! - the position counters are 32-bit registers (manual, `I`); they are taken to wrap around
//!   modulo 2³², and a value printed unsigned is read as the same register
//!   ([`codec::parse_answer`]); the [`client::Odometer`] differences them modulo 2³²;
//! - positive speeds drive both wheels forward and counters count up going forward (the
//!   manual's `D,l20000,l20000` example; `kh3server` inverts motor 1 so that both agree).
//!
//! # Conversions
//!
//! `send(v_ref, ω_ref)`: wheel speeds v_l = v_ref − dω_ref/2, v_r = v_ref + dω_ref/2 [m/s],
//! each clamped to ±`max_wheel_speed`, times 1000 · `speed_units_per_mm_s`, rounded to the
//! nearest integer (half away from zero): v_ref = 0.1 m/s, ω_ref = 0 → `D,l14401,l14401`.
//! `read`: `E` → wheel speeds → v = (v_r + v_l)/2, ω = (v_r − v_l)/d; `R` → counter changes →
//! pose by eq. 3.2–3.3. `send` returns the command as the robot will act on it: (v, ω) of the
//! rounded, clamped wheel speeds it sent, the one to record. Time: reports counted × period,
//! t = k·`period_s` for the k-th read (deterministic, not the host's clock; with `realtime`
//! the client waits for each period on the host's monotonic clock and counts
//! [`Khepera::late_reads`]; see [`Khepera`]).

pub mod client;
pub mod codec;
pub mod server;

use serde::{Deserialize, Serialize};
use wheelid_core::RobotError;

pub use client::{Khepera, Link, Odometer};
pub use codec::{Answer, Command, Units, Wheels};
pub use server::{KheperaServer, Pacing, ServerHandle, ServerStats};

use crate::profile::RobotProfile;

/// How to reach a Khepera III and the units its firmware speaks (`[robot] type = "khepera"`).
///
/// All fields are optional in a config; the defaults are [`RobotProfile::khepera3`]'s robot
/// with a firmware before 3.0 on `/dev/ttyUSB0` (see the [module docs](self) for the sources).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct KheperaSettings {
    /// Serial device path (e.g. `/dev/ttyUSB0`, `COM3`), opened at `baud` 8N1; or
    /// `tcp://host:port` for a TCP–serial bridge or the [`KheperaServer`].
    pub port: String,
    /// Serial baud rate \[Bd\] (manual: 115200).
    pub baud: u32,
    /// Control and sampling period Δt \[s\] (profile: 0.02 s, the thesis' toolbox loop).
    pub period_s: f64,
    /// Longest wait for an answer, and for a TCP connection \[s\].
    pub timeout_s: f64,
    /// Whether `read` waits for the next period on the host clock (a real robot); false reads
    /// at once (a [`Pacing::LockStep`] loopback server, where the simulation sets the pace).
    pub realtime: bool,
    /// Speed units per mm/s of wheel speed (`Kspeed`; firmware < 3.0: 144.01, ≥ 3.0: 218.72).
    pub speed_units_per_mm_s: f64,
    /// Encoder pulses per mm of wheel travel (firmware < 3.0: 2764 per 2π·20.5 mm = 21.459;
    /// ≥ 3.0: 1/0.03068 = 32.595).
    pub pulses_per_mm: f64,
    /// Track width d \[m\] (profile: 0.0885).
    pub track: f64,
    /// Largest wheel speed commanded [m/s]; faster wheels are clamped (profile: 0.5).
    pub max_wheel_speed: f64,
}

impl Default for KheperaSettings {
    fn default() -> Self {
        Self::for_profile(&RobotProfile::khepera3())
    }
}

impl KheperaSettings {
    /// Settings for the robot `profile` describes: its period, [`Units::from_profile`], port
    /// `/dev/ttyUSB0` at 115200 Bd, 0.5 s timeout, `realtime`.
    pub fn for_profile(profile: &RobotProfile) -> Self {
        let units = Units::from_profile(profile);
        Self {
            port: "/dev/ttyUSB0".into(),
            baud: 115_200,
            period_s: profile.period_s,
            timeout_s: 0.5,
            realtime: true,
            speed_units_per_mm_s: units.speed_units_per_mm_s,
            pulses_per_mm: units.pulses_per_mm,
            track: units.track,
            max_wheel_speed: units.max_wheel_speed,
        }
    }

    /// The unit conversions these settings describe.
    pub fn units(&self) -> Units {
        Units {
            speed_units_per_mm_s: self.speed_units_per_mm_s,
            pulses_per_mm: self.pulses_per_mm,
            track: self.track,
            max_wheel_speed: self.max_wheel_speed,
        }
    }

    /// Checks the settings: a port, a baud rate, and finite positive period, timeout and units.
    ///
    /// # Errors
    /// [`RobotError::Setting`] naming the first bad field.
    pub fn validate(&self) -> Result<(), RobotError> {
        if self.port.trim().is_empty() {
            return Err(RobotError::Setting("khepera: port is empty".into()));
        }
        if self.baud == 0 {
            return Err(RobotError::Setting("khepera: baud must be > 0".into()));
        }
        for (name, x) in [("period_s", self.period_s), ("timeout_s", self.timeout_s)] {
            // Duration::from_secs_f64 panics beyond ~1.8e19 s; a day is plenty.
            if !(x.is_finite() && x > 0.0 && x <= 86_400.0) {
                return Err(RobotError::Setting(format!(
                    "khepera: {name} = {x} must be in (0, 86400] s"
                )));
            }
        }
        self.units().validate()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_the_profile_robot_before_firmware_3() {
        let s = KheperaSettings::default();
        assert_eq!(s.speed_units_per_mm_s, 144.01);
        // 2764 pulses per 2π·20.5 mm; the manual's 2764 per 128.8 mm within 0.004 %.
        assert!(
            (s.pulses_per_mm - 21.4588).abs() < 1e-4,
            "{}",
            s.pulses_per_mm
        );
        assert!((s.pulses_per_mm / (2764.0 / 128.8) - 1.0).abs() < 5e-5);
        assert_eq!(
            (s.period_s, s.track, s.max_wheel_speed),
            (0.02, 0.0885, 0.5)
        );
        assert_eq!((s.baud, s.realtime), (115_200, true));
        s.validate().expect("defaults are valid");
    }

    #[test]
    fn validation_names_the_field() {
        let bad = |f: fn(&mut KheperaSettings)| {
            let mut s = KheperaSettings::default();
            f(&mut s);
            s.validate().expect_err("invalid").to_string()
        };
        assert!(bad(|s| s.period_s = 0.0).contains("period_s"));
        assert!(bad(|s| s.timeout_s = f64::NAN).contains("timeout_s"));
        assert!(bad(|s| s.pulses_per_mm = -1.0).contains("pulses_per_mm"));
        assert!(bad(|s| s.port = " ".into()).contains("port"));
        assert!(bad(|s| s.baud = 0).contains("baud"));
    }

    #[test]
    fn firmware_constants_share_one_speed_unit_per_pulse_rate() {
        // The cross-check of the module docs: speed units per (pulse/s) in both families.
        let before_3 = codec::SPEED_UNITS_PER_MM_S_BEFORE_3 * 128.8 / 2764.0;
        let from_3 = codec::SPEED_UNITS_PER_MM_S_FROM_3 * codec::MM_PER_PULSE_FROM_3;
        assert!(
            (before_3 / from_3 - 1.0).abs() < 1e-4,
            "{before_3} vs {from_3}"
        );
    }
}
