//! The ARCOS client: [`Pioneer`] drives a Pioneer 3-DX (or MobileSim, or the loopback
//! [`ArcosServer`](super::ArcosServer)) through the [`Robot`] trait.

use std::io::{self, Read, Write};
use std::net::TcpStream;
use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};
use wheelid_core::{Odometry, Robot, RobotError};

use super::arcos::{Odometer, Packet, PacketReader, Sip, cmd, is_standard_sip};
use crate::profile::RobotProfile;

/// How to reach and drive a Pioneer (`[robot] type = "pioneer"`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PioneerSettings {
    /// Where the robot is: a serial device path (`/dev/ttyS0`, `/dev/ttyUSB0`, `COM1`), opened
    /// at `baud`, 8N1; or `tcp://host:port` (MobileSim listens on 8101, the default).
    pub port: String,
    /// Serial baud rate (ARCOS's HOST port starts at 9600); unused over TCP.
    pub baud: u32,
    /// SIP cycle \[s\] of the firmware (ARCOS's default SipCycle 100 ms): the time between two
    /// reports, and the step of the report timestamps.
    pub period_s: f64,
    /// How long to wait for a reply or a SIP before [`RobotError::Timeout`] \[s\].
    pub timeout_s: f64,
    /// Track width d \[m\] for ω = (v_R − v_L)/d (default: the Pioneer 3-DX profile's).
    pub track_m: f64,
    /// Optional clamp of |v_ref| [m/s] before sending.
    pub max_v: Option<f64>,
    /// Optional clamp of |ω_ref| [rad/s] before sending.
    pub max_w: Option<f64>,
}

impl Default for PioneerSettings {
    fn default() -> Self {
        let profile = RobotProfile::pioneer3dx();
        Self {
            port: "tcp://127.0.0.1:8101".into(),
            baud: 9600,
            period_s: profile.period_s,
            timeout_s: 2.0,
            track_m: profile.track,
            max_v: None,
            max_w: None,
        }
    }
}

impl PioneerSettings {
    /// Checks the settings.
    ///
    /// # Errors
    /// [`RobotError::Setting`] for an empty port, a zero baud rate, or a period, timeout,
    /// track or clamp that is not a positive finite number.
    pub fn validate(&self) -> Result<(), RobotError> {
        let bad = |msg: String| Err(RobotError::Setting(format!("pioneer: {msg}")));
        if self.port.trim().is_empty() {
            return bad("port is empty".into());
        }
        if self.baud == 0 {
            return bad("baud = 0".into());
        }
        let positive = [
            ("period_s", Some(self.period_s)),
            ("timeout_s", Some(self.timeout_s)),
            ("track_m", Some(self.track_m)),
            ("max_v", self.max_v),
            ("max_w", self.max_w),
        ];
        for (name, value) in positive {
            if let Some(x) = value
                && !(x.is_finite() && x > 0.0)
            {
                return bad(format!("{name} = {x} must be > 0"));
            }
        }
        Ok(())
    }

    fn timeout(&self) -> Duration {
        Duration::from_secs_f64(self.timeout_s)
    }
}

/// The commands (VEL [mm/s], RVEL [°/s]) that `send(v_ref, w_ref)` puts on the wire: clamped to
/// `max_v`/`max_w` if set, rounded to the protocol's integer units, clamped to ±32767.
///
/// # Errors
/// [`RobotError::Setting`] if a command is not finite.
pub fn quantize_command(
    v_ref: f64,
    w_ref: f64,
    settings: &PioneerSettings,
) -> Result<(i16, i16), RobotError> {
    if !(v_ref.is_finite() && w_ref.is_finite()) {
        return Err(RobotError::Setting(format!(
            "pioneer: command (v_ref, w_ref) = ({v_ref}, {w_ref}) is not finite"
        )));
    }
    let clamp = |x: f64, limit: Option<f64>| limit.map_or(x, |l| x.clamp(-l, l));
    let to_i16 = |x: f64| x.round().clamp(-32767.0, 32767.0) as i16;
    Ok((
        to_i16(clamp(v_ref, settings.max_v) * 1000.0),
        to_i16(clamp(w_ref, settings.max_w).to_degrees()),
    ))
}

/// A command in protocol units (VEL [mm/s], RVEL [°/s]) in SI units (m/s, rad/s).
fn command_si(vel: i16, rvel: i16) -> (f64, f64) {
    (f64::from(vel) / 1000.0, f64::from(rvel).to_radians())
}

/// A byte link to the robot whose reads can time out: a TCP socket or a serial port.
pub trait Link: Read + Write + Send {
    /// Sets how long one `read` may block (> 0).
    ///
    /// # Errors
    /// As the underlying socket or port.
    fn set_read_timeout(&mut self, timeout: Duration) -> io::Result<()>;
}

impl Link for TcpStream {
    fn set_read_timeout(&mut self, timeout: Duration) -> io::Result<()> {
        TcpStream::set_read_timeout(self, Some(timeout.max(Duration::from_millis(1))))
    }
}

impl Link for Box<dyn serialport::SerialPort> {
    fn set_read_timeout(&mut self, timeout: Duration) -> io::Result<()> {
        self.set_timeout(timeout).map_err(io::Error::from)
    }
}

/// Opens `port` (`tcp://host:port` or a serial device path).
fn open_link(settings: &PioneerSettings) -> Result<Box<dyn Link>, RobotError> {
    Ok(
        match crate::link::open(&settings.port, settings.baud, settings.timeout())? {
            crate::link::Port::Tcp(s) => Box::new(s),
            crate::link::Port::Serial(s) => Box::new(s),
        },
    )
}

/// What the robot told about itself in its SYNC2 echo.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct RobotIdentity {
    /// Robot name (user-settable in the firmware).
    pub name: String,
    /// Robot class, e.g. `Pioneer`.
    pub class: String,
    /// Robot subclass, e.g. `p3dx-sh`.
    pub subclass: String,
}

/// A Pioneer driven over ARCOS: [`Robot::send`] writes VEL and RVEL, [`Robot::read`] returns the
/// next standard SIP as [`Odometry`].
///
/// * Timestamps (the robot's clock of [`Odometry::t`]): reports counted × period, t = k ·
///   `period_s` for the k-th report — the first SIP, at [`Pioneer::connect`], is report 0
///   (t = 0, [`Pioneer::last_report`]), the first `read` report 1. Deterministic, not the
///   host's clock: SIPs come on the firmware's fixed cycle, so the count is the robot's clock,
///   and a session replayed against the lock-step loopback server gives bit-for-bit the same
///   reports. Only valid standard SIPs count: a SIP lost to a bad checksum (reported by `read`
///   as [`RobotError::Protocol`]) shifts the later timestamps by one period.
/// * `send` returns the command as the robot will act on it: the request clamped to
///   `max_v`/`max_w`, rounded to whole mm/s and °/s and clamped to ±32767 as the protocol
///   carries it ([`quantize_command`]), converted back to m/s and rad/s. (The firmware's own
///   velocity limits, which the client does not know, may still cut it.)
/// * Watchdog: ARCOS stops the robot when no command arrives for its watchdog time (2 s by
///   default); `read` sends a PULSE when no command went out since the previous `read`.
/// * Dropping a `Pioneer` that was not stopped sends VEL 0, RVEL 0, CLOSE (best effort).
pub struct Pioneer {
    settings: PioneerSettings,
    link: Option<Box<dyn Link>>,
    reader: PacketReader,
    identity: RobotIdentity,
    odometer: Odometer,
    last_sip: Sip,
    last: Odometry,
    sips: u64,
    command: (i16, i16),
    sent_since_read: bool,
}

impl std::fmt::Debug for Pioneer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Pioneer")
            .field("port", &self.settings.port)
            .field("identity", &self.identity)
            .field("open", &self.link.is_some())
            .field("sips", &self.sips)
            .field("command", &self.command)
            .finish_non_exhaustive()
    }
}

impl Pioneer {
    /// Opens `settings.port`, runs the SYNC0–SYNC2 handshake, sends OPEN and ENABLE 1, and
    /// waits for the first SIP (the report at t = 0, [`Pioneer::last_report`]).
    ///
    /// # Errors
    /// [`RobotError::Setting`] for bad settings; [`RobotError::Io`] naming the port if it cannot
    /// be opened or the link fails; [`RobotError::Timeout`] if the robot does not answer within
    /// `timeout_s`; [`RobotError::Protocol`] if it answers something else.
    pub fn connect(settings: &PioneerSettings) -> Result<Self, RobotError> {
        settings.validate()?;
        let link = open_link(settings)?;
        Self::over(link, settings)
    }

    /// As [`Pioneer::connect`] over an already open `link`; `settings.port` only names it in
    /// errors.
    ///
    /// # Errors
    /// As [`Pioneer::connect`].
    pub fn over(link: Box<dyn Link>, settings: &PioneerSettings) -> Result<Self, RobotError> {
        settings.validate()?;
        let mut robot = Self {
            settings: settings.clone(),
            link: Some(link),
            reader: PacketReader::new(),
            identity: RobotIdentity::default(),
            odometer: Odometer::new(settings.track_m),
            last_sip: Sip::default(),
            last: Odometry {
                t: 0.0,
                v: 0.0,
                w: 0.0,
                pose: Default::default(),
            },
            sips: 0,
            command: (0, 0),
            sent_since_read: false,
        };
        robot.identity = robot.handshake()?;
        let mut open = Packet::command(cmd::OPEN).to_bytes();
        open.extend(Packet::command_int(cmd::ENABLE, 1).to_bytes());
        robot.write(&open, "sending OPEN and ENABLE 1")?;
        let sip = robot.next_sip("waiting for the first SIP")?;
        let (v, w, pose) = robot.odometer.update(&sip);
        robot.last = Odometry { t: 0.0, v, w, pose };
        robot.last_sip = sip;
        Ok(robot)
    }

    /// The settings in use.
    pub fn settings(&self) -> &PioneerSettings {
        &self.settings
    }

    /// Name, class and subclass from the handshake.
    pub fn identity(&self) -> &RobotIdentity {
        &self.identity
    }

    /// The latest report: after [`Pioneer::connect`] the first SIP (t = 0), then the last
    /// [`Robot::read`].
    pub fn last_report(&self) -> Odometry {
        self.last
    }

    /// The latest standard SIP as received (battery, stall, flags, sonar, …).
    pub fn last_sip(&self) -> &Sip {
        &self.last_sip
    }

    /// The command in force, in protocol units (VEL [mm/s], RVEL [°/s]).
    pub fn command(&self) -> (i16, i16) {
        self.command
    }

    fn what(&self, op: &str) -> String {
        format!("{}: {op}", self.settings.port)
    }

    fn closed(&self) -> RobotError {
        RobotError::Protocol(self.what("the connection was closed by stop()"))
    }

    fn write(&mut self, bytes: &[u8], op: &str) -> Result<(), RobotError> {
        let what = self.what(op);
        let Some(link) = self.link.as_mut() else {
            return Err(self.closed());
        };
        link.write_all(bytes)
            .and_then(|()| link.flush())
            .map_err(|e| RobotError::io(what, e))
    }

    /// The next packet, waiting until `deadline`.
    fn next_packet(&mut self, deadline: Instant, op: &str) -> Result<Packet, RobotError> {
        let mut chunk = [0u8; 512];
        loop {
            match self.reader.next_packet() {
                Ok(Some(packet)) => return Ok(packet),
                Ok(None) => {}
                Err(RobotError::Protocol(msg)) => {
                    return Err(RobotError::Protocol(self.what(&format!("{op}: {msg}"))));
                }
                Err(e) => return Err(e),
            }
            let now = Instant::now();
            if now >= deadline {
                return Err(RobotError::Timeout(self.what(&format!(
                    "{op}: nothing within {} s",
                    self.settings.timeout_s
                ))));
            }
            let what = self.what(op);
            let Some(link) = self.link.as_mut() else {
                return Err(self.closed());
            };
            link.set_read_timeout(deadline - now)
                .map_err(|e| RobotError::io(&what, e))?;
            match link.read(&mut chunk) {
                Ok(0) => {
                    return Err(RobotError::io(
                        what,
                        io::Error::new(
                            io::ErrorKind::UnexpectedEof,
                            "the robot closed the connection",
                        ),
                    ));
                }
                Ok(n) => self.reader.push(&chunk[..n]),
                Err(e) if crate::link::is_transient(&e) => {}
                Err(e) => return Err(RobotError::io(what, e)),
            }
        }
    }

    /// The next standard SIP within the timeout, skipping other packet types.
    fn next_sip(&mut self, op: &str) -> Result<Sip, RobotError> {
        let deadline = Instant::now() + self.settings.timeout();
        loop {
            let packet = self.next_packet(deadline, op)?;
            if is_standard_sip(packet.id()) {
                return Sip::decode(&packet)
                    .map_err(|e| RobotError::Protocol(self.what(&format!("{op}: {e}"))));
            }
        }
    }

    /// SYNC0, SYNC1, SYNC2, each echoed by the robot; the SYNC2 echo carries the identity.
    /// Noise on the line before an echo is skipped. A robot still open from an earlier client
    /// answers with SIPs (it reads SYNC0 as PULSE): it gets a CLOSE, and once its SIPs stop the
    /// handshake starts over (as in ARIA's `asyncConnectHandler`).
    fn handshake(&mut self) -> Result<RobotIdentity, RobotError> {
        const ATTEMPTS: usize = 3;
        let mut trouble = String::new();
        'attempt: for _ in 0..ATTEMPTS {
            for step in [cmd::SYNC0, cmd::SYNC1, cmd::SYNC2] {
                let op = format!("waiting for the echo of SYNC{step}");
                self.write(
                    &Packet::command(step).to_bytes(),
                    &format!("sending SYNC{step}"),
                )?;
                let deadline = Instant::now() + self.settings.timeout();
                let packet = loop {
                    match self.next_packet(deadline, &op) {
                        Ok(packet) => break packet,
                        Err(RobotError::Protocol(msg)) => trouble = msg,
                        Err(e) => return Err(e),
                    }
                };
                if packet.id() == step {
                    if step == cmd::SYNC2 {
                        let mut s = packet.strings().into_iter();
                        return Ok(RobotIdentity {
                            name: s.next().unwrap_or_default(),
                            class: s.next().unwrap_or_default(),
                            subclass: s.next().unwrap_or_default(),
                        });
                    }
                    continue;
                }
                if is_standard_sip(packet.id()) {
                    trouble = "the robot was still open from an earlier connection".into();
                    self.write(&Packet::command(cmd::CLOSE).to_bytes(), "sending CLOSE")?;
                    self.wait_until_quiet(deadline)?;
                } else {
                    trouble = format!(
                        "packet type 0x{:02X} instead of the echo of SYNC{step}",
                        packet.id()
                    );
                }
                continue 'attempt;
            }
        }
        Err(RobotError::Protocol(self.what(&format!(
            "no ARCOS handshake after {ATTEMPTS} attempts: {trouble}"
        ))))
    }

    /// Discards packets until none has come for two SIP periods (or `deadline` passes).
    fn wait_until_quiet(&mut self, deadline: Instant) -> Result<(), RobotError> {
        let quiet = Duration::from_secs_f64(2.0 * self.settings.period_s);
        loop {
            let until = (Instant::now() + quiet).min(deadline);
            match self.next_packet(until, "waiting for the SIPs to stop after CLOSE") {
                Ok(_) | Err(RobotError::Protocol(_)) if Instant::now() < deadline => {}
                Ok(_) | Err(RobotError::Protocol(_)) | Err(RobotError::Timeout(_)) => {
                    return Ok(());
                }
                Err(e) => return Err(e),
            }
        }
    }

    fn stop_bytes() -> Vec<u8> {
        let mut bytes = Packet::command_int(cmd::VEL, 0).to_bytes();
        bytes.extend(Packet::command_int(cmd::RVEL, 0).to_bytes());
        bytes.extend(Packet::command(cmd::CLOSE).to_bytes());
        bytes
    }
}

impl Robot for Pioneer {
    fn name(&self) -> &str {
        "pioneer"
    }

    fn period_s(&self) -> f64 {
        self.settings.period_s
    }

    /// Window averages: the SIP's wheel velocities are the firmware's encoder counts over its
    /// cycle (MobileSim and the loopback server report the simulator's period averages).
    fn velocity_sampling(&self) -> wheelid_core::VelocitySampling {
        wheelid_core::VelocitySampling::WindowAverage
    }

    /// Writes VEL (v_ref in whole mm/s) and RVEL (ω_ref in whole °/s), see
    /// [`quantize_command`], and returns that command as the robot will act on it:
    /// (VEL/1000 m/s, RVEL·π/180 rad/s).
    ///
    /// # Errors
    /// [`RobotError::Setting`] for a non-finite command (nothing is sent);
    /// [`RobotError::Io`] if the link fails; [`RobotError::Protocol`] after [`Robot::stop`].
    fn send(&mut self, v_ref: f64, w_ref: f64) -> Result<(f64, f64), RobotError> {
        let (vel, rvel) = quantize_command(v_ref, w_ref, &self.settings)?;
        let mut bytes = Packet::command_int(cmd::VEL, i32::from(vel)).to_bytes();
        bytes.extend(Packet::command_int(cmd::RVEL, i32::from(rvel)).to_bytes());
        self.write(&bytes, "sending VEL and RVEL")?;
        self.command = (vel, rvel);
        self.sent_since_read = true;
        Ok(command_si(vel, rvel))
    }

    /// Waits for the next standard SIP (other packet types are skipped), sending a PULSE first
    /// if no command went out since the previous `read`.
    fn read(&mut self) -> Result<Odometry, RobotError> {
        if self.link.is_none() {
            return Err(self.closed());
        }
        if !self.sent_since_read {
            self.write(&Packet::command(cmd::PULSE).to_bytes(), "sending PULSE")?;
        }
        // This read answers the command sent before it, whether or not a SIP comes through.
        self.sent_since_read = false;
        let sip = self.next_sip("waiting for a SIP")?;
        self.sips += 1;
        let (v, w, pose) = self.odometer.update(&sip);
        self.last = Odometry {
            t: self.sips as f64 * self.settings.period_s,
            v,
            w,
            pose,
        };
        self.last_sip = sip;
        Ok(self.last)
    }

    /// Sends VEL 0, RVEL 0 and CLOSE, then releases the link; later calls fail with
    /// [`RobotError::Protocol`] (a second `stop` does nothing).
    fn stop(&mut self) -> Result<(), RobotError> {
        if self.link.is_none() {
            return Ok(());
        }
        let result = self.write(&Self::stop_bytes(), "sending VEL 0, RVEL 0 and CLOSE");
        self.link = None;
        self.command = (0, 0);
        result
    }
}

impl Drop for Pioneer {
    fn drop(&mut self) {
        if let Some(link) = self.link.as_mut() {
            let _ = link.write_all(&Self::stop_bytes());
            let _ = link.flush();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn commands_round_to_mm_per_s_and_degrees_per_s() {
        let s = PioneerSettings::default();
        assert_eq!(quantize_command(0.3004, 0.5, &s).expect("ok"), (300, 29)); // 28.65°/s
        assert_eq!(quantize_command(-0.0015, -0.5, &s).expect("ok"), (-2, -29));
        assert_eq!(quantize_command(40.0, 1e6, &s).expect("ok"), (32767, 32767));
        let clamped = PioneerSettings {
            max_v: Some(0.5),
            max_w: Some(1.0),
            ..s.clone()
        };
        assert_eq!(
            quantize_command(0.9, -3.0, &clamped).expect("ok"),
            (500, -57)
        );
        assert!(matches!(
            quantize_command(f64::NAN, 0.0, &s),
            Err(RobotError::Setting(_))
        ));
    }

    #[test]
    fn settings_are_checked() {
        assert!(PioneerSettings::default().validate().is_ok());
        let bad = [
            PioneerSettings {
                period_s: 0.0,
                ..Default::default()
            },
            PioneerSettings {
                timeout_s: f64::NAN,
                ..Default::default()
            },
            PioneerSettings {
                max_w: Some(-1.0),
                ..Default::default()
            },
            PioneerSettings {
                port: " ".into(),
                ..Default::default()
            },
        ];
        for s in bad {
            assert!(matches!(s.validate(), Err(RobotError::Setting(_))), "{s:?}");
        }
    }
}
