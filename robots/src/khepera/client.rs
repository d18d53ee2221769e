//! The client: a [`Robot`] that drives a Khepera III over a serial line or a TCP–serial bridge.

use std::io::{self, Read, Write};
use std::time::{Duration, Instant};

use wheelid_core::{Odometry, Pose, Robot, RobotError};

use super::KheperaSettings;
use super::codec::{Answer, Command, Units, Wheels, parse_answer};

/// Longest answer line accepted [bytes]; the longest Khepera III answer (`g`, ultrasound) is
/// about 100.
const MAX_LINE: usize = 512;

/// The byte stream to the robot: a serial port or a TCP socket, both `Read + Write` with their
/// read timeout set when opened.
pub trait Link: Read + Write + Send {}

impl<T: Read + Write + Send + ?Sized> Link for T {}

/// Opens `settings.port`: `tcp://host:port` as a TCP connection (connect, read and write
/// timeouts `timeout_s`, Nagle off), anything else as a serial device at `baud` (8N1, read
/// timeout `timeout_s`).
///
/// # Errors
/// [`RobotError::Io`] naming the port.
fn open_link(settings: &KheperaSettings) -> Result<Box<dyn Link>, RobotError> {
    let timeout = Duration::from_secs_f64(settings.timeout_s);
    Ok(
        match crate::link::open(&settings.port, settings.baud, timeout)? {
            crate::link::Port::Tcp(s) => Box::new(s),
            crate::link::Port::Serial(s) => Box::new(s),
        },
    )
}

/// A line-oriented request–answer channel over a [`Link`].
struct Channel {
    link: Box<dyn Link>,
    /// The port, for messages.
    port: String,
    timeout: Duration,
    /// Bytes received and not yet consumed.
    pending: Vec<u8>,
}

impl Channel {
    /// Sends `command` and returns its answer.
    fn request(&mut self, command: &Command) -> Result<Answer, RobotError> {
        self.write(command)?;
        let line = self.read_line(command)?;
        parse_answer(command, &line)
    }

    fn write(&mut self, command: &Command) -> Result<(), RobotError> {
        let bytes = command.encode();
        self.link
            .write_all(bytes.as_bytes())
            .and_then(|()| self.link.flush())
            .map_err(|e| RobotError::io(format!("{}: sending `{command}`", self.port), e))
    }

    /// The next non-blank line (up to `\n`, blanks and `\r` trimmed) within the timeout.
    fn read_line(&mut self, command: &Command) -> Result<String, RobotError> {
        let deadline = Instant::now() + self.timeout;
        loop {
            while let Some(end) = self.pending.iter().position(|&b| b == b'\n') {
                let raw: Vec<u8> = self.pending.drain(..=end).collect();
                let line = String::from_utf8_lossy(&raw).trim().to_string();
                if !line.is_empty() {
                    return Ok(line);
                }
            }
            if self.pending.len() > MAX_LINE {
                return Err(RobotError::Protocol(format!(
                    "answer to `{command}`: more than {MAX_LINE} bytes without a line feed: `{}…`",
                    String::from_utf8_lossy(&self.pending[..64]).escape_debug()
                )));
            }
            if Instant::now() >= deadline {
                return Err(self.timed_out(command));
            }
            let mut chunk = [0u8; 128];
            match self.link.read(&mut chunk) {
                Ok(0) => {
                    return Err(RobotError::io(
                        format!("{}: reading the answer to `{command}`", self.port),
                        io::Error::new(io::ErrorKind::UnexpectedEof, "the link was closed"),
                    ));
                }
                Ok(n) => self.pending.extend_from_slice(&chunk[..n]),
                Err(e) if crate::link::is_transient(&e) => {}
                Err(e) => {
                    return Err(RobotError::io(
                        format!("{}: reading the answer to `{command}`", self.port),
                        e,
                    ));
                }
            }
        }
    }

    fn timed_out(&self, command: &Command) -> RobotError {
        let partial = if self.pending.is_empty() {
            String::new()
        } else {
            format!(
                " (received `{}` without a line feed)",
                String::from_utf8_lossy(&self.pending).escape_debug()
            )
        };
        RobotError::Timeout(format!(
            "{}: no answer to `{command}` within {} s{partial}",
            self.port,
            self.timeout.as_secs_f64()
        ))
    }
}

/// Pose by odometry from the two position counters (thesis eq. 3.2–3.3, midpoint heading), with
/// the counters' 32-bit wrap-around.
///
/// Each update takes the counter change Δp (left, right) as the wrapping 32-bit difference, so a
/// counter that passes 2³¹ − 1 → −2³¹ still gives the right step (as long as a wheel moves less
/// than 2³¹ pulses, about 100 km, between two reads). Then Δs = (Δr + Δl)/2, Δφ = (Δr − Δl)/d
/// with Δl, Δr the wheel travels \[m\], and x += Δs cos φ̄, y += Δs sin φ̄, φ += Δφ with
/// φ̄ = φ + Δφ/2. The pose is that of the axle centre; the heading is not wrapped.
#[derive(Debug, Clone, PartialEq)]
pub struct Odometer {
    units: Units,
    last: Wheels<i32>,
    pose: Pose,
}

impl Odometer {
    /// An odometer at `pose` whose counters last read `counters`.
    pub fn new(units: Units, counters: Wheels<i32>, pose: Pose) -> Self {
        Self {
            units,
            last: counters,
            pose,
        }
    }

    /// Advances to the counters read now and returns the new pose.
    pub fn update(&mut self, counters: Wheels<i32>) -> Pose {
        let dl = f64::from(counters.left.wrapping_sub(self.last.left));
        let dr = f64::from(counters.right.wrapping_sub(self.last.right));
        self.last = counters;
        let (l, r) = (self.units.pulses_to_m(dl), self.units.pulses_to_m(dr));
        let ds = (r + l) / 2.0;
        let dphi = (r - l) / self.units.track;
        let mid = self.pose.heading + dphi / 2.0;
        self.pose.x += ds * mid.cos();
        self.pose.y += ds * mid.sin();
        self.pose.heading += dphi;
        self.pose
    }

    /// The current pose.
    pub fn pose(&self) -> Pose {
        self.pose
    }

    /// The counters last read.
    pub fn counters(&self) -> Wheels<i32> {
        self.last
    }
}

/// A Khepera III driven over its serial text protocol (see the [module docs](super)).
///
/// `send` writes `D` with the rounded, clamped wheel speeds, waits for `d`, and returns the
/// command as the robot will act on it: the wheel speeds v_ref ∓ dω_ref/2, each clamped to
/// `max_wheel_speed` and rounded to whole speed units, turned back into
/// (v, ω) = ((v_r + v_l)/2, (v_r − v_l)/d) ([`Units::velocity_of_units`]). `read` waits for the
/// next period (when [`KheperaSettings::realtime`]), asks `E` (wheel speeds → v, ω) and `R`
/// (position counters → pose by [`Odometer`]).
///
/// Timestamps (the robot's clock of [`Odometry::t`]): reports counted × period, t = k ·
/// `period_s` for the k-th report — [`Khepera::connect`] is t = 0 (no report), the first `read`
/// is report 1 at t = Δt. Deterministic, not the host's clock (which only paces the reads when
/// `realtime`, see [`Khepera::late_reads`]).
///
/// Dropping the client sends `D,l0,l0` (without waiting for the answer) unless the last command
/// already was a stop.
pub struct Khepera {
    channel: Channel,
    settings: KheperaSettings,
    units: Units,
    odometer: Odometer,
    reads: u64,
    /// The command in force, as sent (speed units).
    command: Wheels<i32>,
    /// When the last read was due (host clock), for [`KheperaSettings::realtime`].
    due: Instant,
    late_reads: u64,
}

impl std::fmt::Debug for Khepera {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Khepera")
            .field("port", &self.settings.port)
            .field("reads", &self.reads)
            .field("command", &self.command)
            .field("pose", &self.odometer.pose())
            .finish_non_exhaustive()
    }
}

impl Khepera {
    /// Opens the link and brings the robot to a known state: `D,l0,l0` (stopped, answer `d`),
    /// then `R` to take the position counters as the odometry origin (pose (0, 0, 0), t = 0).
    ///
    /// # Errors
    /// [`RobotError::Setting`] for invalid settings; [`RobotError::Io`] if the port cannot be
    /// opened (the message names it); [`RobotError::Timeout`] or [`RobotError::Protocol`] if the
    /// robot does not answer the two commands as the protocol says.
    pub fn connect(settings: &KheperaSettings) -> Result<Self, RobotError> {
        settings.validate()?;
        let link = open_link(settings)?;
        Self::over(link, settings)
    }

    /// As [`Khepera::connect`], over an already open link (named `settings.port` in messages).
    ///
    /// # Errors
    /// As [`Khepera::connect`].
    pub fn over(link: Box<dyn Link>, settings: &KheperaSettings) -> Result<Self, RobotError> {
        settings.validate()?;
        let units = settings.units();
        let mut channel = Channel {
            link,
            port: settings.port.clone(),
            timeout: Duration::from_secs_f64(settings.timeout_s),
            pending: Vec::new(),
        };
        let stop = Command::SetSpeed(Wheels::default());
        expect_ack(&stop, channel.request(&stop)?)?;
        let counters = expect_pair(
            &Command::ReadPosition,
            channel.request(&Command::ReadPosition)?,
        )?;
        Ok(Self {
            channel,
            settings: settings.clone(),
            units,
            odometer: Odometer::new(units, counters, Pose::default()),
            reads: 0,
            command: Wheels::default(),
            due: Instant::now(),
            late_reads: 0,
        })
    }

    /// The settings the client runs with.
    pub fn settings(&self) -> &KheperaSettings {
        &self.settings
    }

    /// The wheel speeds [speed units] of the command in force.
    pub fn command(&self) -> Wheels<i32> {
        self.command
    }

    /// The position counters \[pulses\] of the last `R` answer.
    pub fn counters(&self) -> Wheels<i32> {
        self.odometer.counters()
    }

    /// How many reads started more than one period late (with
    /// [`KheperaSettings::realtime`]): the host could not keep up with `period_s`. The schedule
    /// restarts from such a read, so reports stay at least one period apart.
    pub fn late_reads(&self) -> u64 {
        self.late_reads
    }

    /// Waits until the next period is due (host monotonic clock).
    fn pace(&mut self) {
        let period = Duration::from_secs_f64(self.settings.period_s);
        let due = self.due + period;
        let now = Instant::now();
        if now < due {
            std::thread::sleep(due - now);
            self.due = due;
        } else if now - due > period {
            self.late_reads += 1;
            self.due = now;
        } else {
            self.due = due;
        }
    }
}

fn expect_ack(command: &Command, answer: Answer) -> Result<(), RobotError> {
    match answer {
        Answer::Ack => Ok(()),
        Answer::Pair(_) => Err(RobotError::Protocol(format!(
            "answer to `{command}`: values where `{}` was expected",
            command.answer_letter()
        ))),
    }
}

fn expect_pair(command: &Command, answer: Answer) -> Result<Wheels<i32>, RobotError> {
    match answer {
        Answer::Pair(p) => Ok(p),
        Answer::Ack => Err(RobotError::Protocol(format!(
            "answer to `{command}`: no values where `{},<left>,<right>` was expected",
            command.answer_letter()
        ))),
    }
}

impl Robot for Khepera {
    fn name(&self) -> &str {
        "khepera"
    }

    fn period_s(&self) -> f64 {
        self.settings.period_s
    }

    /// Window averages: the motor controllers' speeds are encoder counts over their sampling
    /// interval (and the loopback server reports the simulator's period averages).
    fn velocity_sampling(&self) -> wheelid_core::VelocitySampling {
        wheelid_core::VelocitySampling::WindowAverage
    }

    /// Writes `D,l<left>,l<right>` with the wheel speeds v_ref ∓ dω_ref/2 in whole speed units
    /// (clamped to `max_wheel_speed`), waits for `d`, and returns the command as the robot will
    /// act on it: (v, ω) of those integer wheel speeds ([`Units::velocity_of_units`]).
    ///
    /// # Errors
    /// [`RobotError::Setting`] for a non-finite command (nothing is sent); link and protocol
    /// errors as [`Khepera::connect`].
    fn send(&mut self, v_ref: f64, w_ref: f64) -> Result<(f64, f64), RobotError> {
        if !(v_ref.is_finite() && w_ref.is_finite()) {
            return Err(RobotError::Setting(format!(
                "khepera: command v_ref = {v_ref}, w_ref = {w_ref} is not finite"
            )));
        }
        let wheels = self.units.speed_command(v_ref, w_ref);
        let command = Command::SetSpeed(wheels);
        let answer = self.channel.request(&command)?;
        expect_ack(&command, answer)?;
        self.command = wheels;
        Ok(self.units.velocity_of_units(wheels))
    }

    /// Waits for the next period (if `realtime`), then `E` → v, ω and `R` → pose.
    ///
    /// # Errors
    /// Link and protocol errors as [`Khepera::connect`].
    fn read(&mut self) -> Result<Odometry, RobotError> {
        if self.settings.realtime {
            self.pace();
        }
        let speeds = expect_pair(
            &Command::ReadSpeed,
            self.channel.request(&Command::ReadSpeed)?,
        )?;
        let counters = expect_pair(
            &Command::ReadPosition,
            self.channel.request(&Command::ReadPosition)?,
        )?;
        let (v, w) = self.units.velocity_of_units(speeds);
        let pose = self.odometer.update(counters);
        self.reads += 1;
        Ok(Odometry {
            t: self.reads as f64 * self.settings.period_s,
            v,
            w,
            pose,
        })
    }

    /// Sends `D,l0,l0` and waits for `d`; the link stays open until the client is dropped.
    fn stop(&mut self) -> Result<(), RobotError> {
        self.send(0.0, 0.0).map(|_| ())
    }
}

impl Drop for Khepera {
    fn drop(&mut self) {
        if self.command != Wheels::default() {
            // Best effort: the robot keeps its last speeds otherwise.
            let _ = self.channel.write(&Command::SetSpeed(Wheels::default()));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::profile::RobotProfile;

    #[test]
    fn odometer_follows_wrapping_counters() {
        let units = Units::from_profile(&RobotProfile::khepera3());
        let start = Wheels::new(i32::MAX - 50, i32::MIN + 50);
        let mut odo = Odometer::new(units, start, Pose::default());
        // Left +100 pulses (wraps past i32::MAX), right −100 (wraps past i32::MIN): a turn
        // on the spot, clockwise.
        let pose = odo.update(Wheels::new(i32::MIN + 49, i32::MAX - 49));
        let travel = 100.0 / units.pulses_per_mm / 1000.0;
        assert!(pose.x.abs() < 1e-15 && pose.y.abs() < 1e-15, "{pose:?}");
        assert!((pose.heading + 2.0 * travel / units.track).abs() < 1e-15);
        // Straight ahead 1000 pulses on both wheels after a quarter turn to the left.
        let mut odo = Odometer::new(
            units,
            Wheels::default(),
            Pose {
                heading: std::f64::consts::FRAC_PI_2,
                ..Pose::default()
            },
        );
        let pose = odo.update(Wheels::new(1000, 1000));
        assert!(pose.x.abs() < 1e-15);
        assert!((pose.y - 1000.0 / units.pulses_per_mm / 1000.0).abs() < 1e-15);
    }
}
