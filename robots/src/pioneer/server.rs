//! The loopback ARCOS server: an ARCOS-speaking server on top of the simulator, for tests and
//! demos, as MobileSim is for ARIA.

use std::io::{self, Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use super::arcos::{
    FLAG_MOTORS_ENABLED, Packet, PacketReader, Sip, SipIo, angle_units, cmd, position_counter,
};
use crate::profile::RobotProfile;
use crate::simulator::{Sample, SimRobot, SimSettings};

/// When the server sends SIPs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pacing {
    /// As the firmware does: one SIP every period of wall-clock time from OPEN, whatever the
    /// client does; a client silent for 2 s (ARCOS's watchdog) gets its robot stopped until it
    /// sends again.
    RealTime,
    /// Deterministic, for tests: SIP 0 on OPEN; after SIP k the server waits until the client
    /// has sent both a VEL and an RVEL (in any order, the last of each counting) or a PULSE,
    /// then steps the simulator one period and sends SIP k + 1. A client silent for 10 s is
    /// disconnected.
    LockStep,
}

/// A client silent this long in lock-step (or during the handshake) is disconnected.
const LOCKSTEP_TIMEOUT: Duration = Duration::from_secs(10);
/// ARCOS's default watchdog: the robot stops after this long without a client packet.
const WATCHDOG: Duration = Duration::from_secs(2);
/// In real time, a client silent this long is disconnected (MobileSim's 60 s).
const REALTIME_CLIENT_TIMEOUT: Duration = Duration::from_secs(60);
/// How often the server looks at its stop flag while waiting.
const POLL: Duration = Duration::from_millis(10);
/// The battery voltage the server reports [0.1 V].
const BATTERY_DECIVOLTS: u8 = 125;

/// The SYNC2 echo: robot name, class, subclass (ARIA loads `params/<subclass>.p` from it).
const CLASS: &str = "Pioneer";
const SUBCLASS: &str = "p3dx-sh";

/// An ARCOS-speaking server on top of the simulator, for tests and demos, as MobileSim is for
/// ARIA: it answers the SYNC0–SYNC2 handshake (name = the profile's name, class `Pioneer`,
/// subclass `p3dx-sh`), OPEN, ENABLE, VEL, RVEL, PULSE and CLOSE, steps a [`SimRobot`] one
/// period per SIP with the last VEL/RVEL held (motors disabled until ENABLE 1), and sends
/// standard SIPs encoded from the simulator's sample:
///
/// * commands: v_ref = VEL/1000 m/s, ω_ref = RVEL·π/180 rad/s — the client's rounding to whole
///   mm/s and °/s is what the simulated robot gets;
/// * L VEL, R VEL = round(1000 (v ∓ ω d/2)) mm/s with the profile's track d; ROTVEL =
///   round(10 ω·180/π);
/// * XPOS, YPOS = round(1000 x) mm mod 2¹⁵ (the firmware's 15-bit counters); THPOS =
///   round(ψ/(2π/4096)) wrapped to [−2048, 2048); FLAGS bit 0 = motors enabled; battery
///   12.5 V; no sonar, stall or bumpers.
///
/// Clients are served one at a time, each with a fresh simulator (so sessions repeat exactly);
/// a client that disconnects ends its session and the server waits for the next.
#[derive(Debug, Clone)]
pub struct ArcosServer {
    profile: RobotProfile,
    sim: SimSettings,
    pacing: Pacing,
}

/// A running [`ArcosServer`]: its address; stops and joins the server thread on
/// [`ServerHandle::shutdown`] or drop.
#[derive(Debug)]
pub struct ServerHandle {
    addr: SocketAddr,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl ServerHandle {
    /// The address the server listens on (127.0.0.1, a free port).
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// The address as a [`PioneerSettings::port`](super::PioneerSettings::port):
    /// `tcp://127.0.0.1:<port>`.
    pub fn url(&self) -> String {
        format!("tcp://{}", self.addr)
    }

    /// Stops the server (ending any session within a few milliseconds) and joins its thread.
    pub fn shutdown(mut self) {
        self.stop_and_join();
    }

    fn stop_and_join(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

impl Drop for ServerHandle {
    fn drop(&mut self) {
        self.stop_and_join();
    }
}

impl ArcosServer {
    /// Binds 127.0.0.1 on a free port and serves there from a new thread.
    ///
    /// # Errors
    /// [`io::ErrorKind::InvalidInput`] if the simulator rejects `profile` or `sim`; the socket's
    /// error if binding fails.
    pub fn spawn(
        profile: RobotProfile,
        sim: SimSettings,
        pacing: Pacing,
    ) -> io::Result<ServerHandle> {
        SimRobot::new(&profile, &sim)
            .map_err(|e| io::Error::new(io::ErrorKind::InvalidInput, e.to_string()))?;
        let listener = TcpListener::bind(("127.0.0.1", 0))?;
        listener.set_nonblocking(true)?;
        let addr = listener.local_addr()?;
        let stop = Arc::new(AtomicBool::new(false));
        let server = Self {
            profile,
            sim,
            pacing,
        };
        let flag = Arc::clone(&stop);
        let thread = std::thread::Builder::new()
            .name(format!("arcos-server-{}", addr.port()))
            .spawn(move || server.serve(&listener, &flag))?;
        Ok(ServerHandle {
            addr,
            stop,
            thread: Some(thread),
        })
    }

    /// Accepts clients one after the other until `stop`.
    fn serve(&self, listener: &TcpListener, stop: &AtomicBool) {
        while !stop.load(Ordering::Relaxed) {
            match listener.accept() {
                // A session ends on CLOSE, on disconnect, on a link error or on a timeout;
                // whichever it was, the server goes on to the next client.
                Ok((stream, _)) => {
                    let _ = Session::new(self, stream).and_then(|s| s.run(stop));
                }
                // WouldBlock (nobody waiting) or a connection aborted before accept.
                Err(_) => std::thread::sleep(POLL),
            }
        }
    }

    fn period(&self) -> Duration {
        Duration::from_secs_f64(self.profile.period_s)
    }
}

/// Where a session is in the protocol.
enum Phase {
    /// Waiting for SYNC`n`.
    Sync(u8),
    /// Handshake done, waiting for OPEN.
    Synced,
    /// Open: the robot runs.
    Open(Box<Motion>),
}

/// The simulated robot of an open session and the commands it holds.
struct Motion {
    sim: SimRobot,
    /// VEL [mm/s] and RVEL [°/s] in force.
    vel: i16,
    rvel: i16,
    enabled: bool,
    /// Lock-step: what arrived since the last SIP.
    got_vel: bool,
    got_rvel: bool,
    got_pulse: bool,
    /// Real time: when the next SIP is due.
    next_due: Instant,
}

struct Session<'a> {
    server: &'a ArcosServer,
    stream: TcpStream,
    reader: PacketReader,
    phase: Phase,
    last_rx: Instant,
}

enum Flow {
    Continue,
    Close,
}

impl<'a> Session<'a> {
    fn new(server: &'a ArcosServer, stream: TcpStream) -> io::Result<Self> {
        // Accepted sockets may inherit the listener's non-blocking mode on some systems.
        stream.set_nonblocking(false)?;
        stream.set_nodelay(true)?;
        Ok(Self {
            server,
            stream,
            reader: PacketReader::new(),
            phase: Phase::Sync(0),
            last_rx: Instant::now(),
        })
    }

    fn run(mut self, stop: &AtomicBool) -> io::Result<()> {
        let mut chunk = [0u8; 512];
        loop {
            if stop.load(Ordering::Relaxed) {
                return Ok(());
            }
            loop {
                match self.reader.next_packet() {
                    Ok(Some(packet)) => {
                        if let Flow::Close = self.handle(&packet)? {
                            return Ok(());
                        }
                    }
                    Ok(None) => break,
                    // A real controller ignores damaged packets; so does the simulation.
                    Err(_) => {}
                }
            }
            let now = Instant::now();
            let realtime = self.server.pacing == Pacing::RealTime;
            let wait = match &mut self.phase {
                Phase::Open(motion) if realtime => {
                    while now >= motion.next_due {
                        let idle = now.duration_since(self.last_rx) > WATCHDOG;
                        let sip = Self::step(self.server, motion, idle);
                        self.stream.write_all(&sip)?;
                        motion.next_due += self.server.period();
                    }
                    if now.duration_since(self.last_rx) > REALTIME_CLIENT_TIMEOUT {
                        return Ok(());
                    }
                    (motion.next_due - now).min(POLL)
                }
                _ => {
                    if now.duration_since(self.last_rx) > LOCKSTEP_TIMEOUT {
                        return Ok(());
                    }
                    POLL
                }
            };
            self.stream
                .set_read_timeout(Some(wait.max(Duration::from_millis(1))))?;
            match self.stream.read(&mut chunk) {
                Ok(0) => return Ok(()),
                Ok(n) => {
                    self.reader.push(&chunk[..n]);
                    self.last_rx = Instant::now();
                }
                Err(e) if crate::link::is_transient(&e) => {}
                Err(e) => return Err(e),
            }
        }
    }

    /// Acts on one client packet.
    fn handle(&mut self, packet: &Packet) -> io::Result<Flow> {
        let id = packet.id();
        match &mut self.phase {
            Phase::Sync(expected) => {
                // Echo the expected step; SYNC0 always restarts the handshake (ARCOS restarts
                // on a sync error, and ARIA starts over from SYNC0).
                let step = if id == *expected || id == cmd::SYNC0 {
                    id
                } else {
                    self.phase = Phase::Sync(0);
                    return Ok(Flow::Continue);
                };
                if step == cmd::SYNC2 {
                    let name = &self.server.profile.name;
                    let text = format!("{name}\0{CLASS}\0{SUBCLASS}\0");
                    let echo = Packet::new(cmd::SYNC2, text.into_bytes())
                        .map_err(|e| io::Error::new(io::ErrorKind::InvalidData, e.to_string()))?;
                    self.stream.write_all(&echo.to_bytes())?;
                    self.phase = Phase::Synced;
                } else {
                    self.stream.write_all(&Packet::command(step).to_bytes())?;
                    self.phase = Phase::Sync(step + 1);
                }
            }
            Phase::Synced => match id {
                cmd::OPEN => {
                    let sim = SimRobot::new(&self.server.profile, &self.server.sim)
                        .map_err(|e| io::Error::new(io::ErrorKind::InvalidInput, e.to_string()))?;
                    let mut motion = Box::new(Motion {
                        sim,
                        vel: 0,
                        rvel: 0,
                        enabled: false,
                        got_vel: false,
                        got_rvel: false,
                        got_pulse: false,
                        next_due: Instant::now() + self.server.period(),
                    });
                    let first = sip_bytes(
                        &motion.sim.sample(),
                        self.server.profile.track,
                        motion.enabled,
                    )?;
                    self.stream.write_all(&first)?;
                    motion.next_due = Instant::now() + self.server.period();
                    self.phase = Phase::Open(motion);
                }
                cmd::CLOSE => return Ok(Flow::Close),
                cmd::SYNC0 => {
                    self.stream
                        .write_all(&Packet::command(cmd::SYNC0).to_bytes())?;
                    self.phase = Phase::Sync(1);
                }
                _ => {}
            },
            Phase::Open(motion) => {
                let arg = packet.int_arg().ok().flatten().unwrap_or(0);
                let to_i16 = |x: i32| i16::try_from(x.clamp(-32767, 32767)).unwrap_or(0);
                match id {
                    cmd::CLOSE => return Ok(Flow::Close),
                    cmd::PULSE => motion.got_pulse = true,
                    cmd::ENABLE => motion.enabled = arg != 0,
                    cmd::VEL => {
                        motion.vel = to_i16(arg);
                        motion.got_vel = true;
                    }
                    cmd::RVEL => {
                        motion.rvel = to_i16(arg);
                        motion.got_rvel = true;
                    }
                    _ => {}
                }
                let cycle_done = motion.got_pulse || (motion.got_vel && motion.got_rvel);
                if self.server.pacing == Pacing::LockStep && cycle_done {
                    let sip = Self::step(self.server, motion, false);
                    self.stream.write_all(&sip)?;
                }
            }
        }
        Ok(Flow::Continue)
    }

    /// Advances the simulator one period under the held command (zero if the motors are
    /// disabled or the watchdog tripped) and returns the next SIP's bytes.
    fn step(server: &ArcosServer, motion: &mut Motion, watchdog: bool) -> Vec<u8> {
        let run = motion.enabled && !watchdog;
        let (v_ref, w_ref) = if run {
            (
                f64::from(motion.vel) / 1000.0,
                f64::from(motion.rvel).to_radians(),
            )
        } else {
            (0.0, 0.0)
        };
        let sample = motion.sim.step(v_ref, w_ref);
        motion.got_vel = false;
        motion.got_rvel = false;
        motion.got_pulse = false;
        // The SIP of a sample always fits one packet (no sonar readings).
        sip_bytes(&sample, server.profile.track, motion.enabled).unwrap_or_default()
    }
}

/// The standard SIP the server sends for `sample` (see [`ArcosServer`]).
pub(super) fn sip_from_sample(sample: &Sample, track: f64, enabled: bool) -> Sip {
    let to_i16 = |x: f64| x.round().clamp(-32767.0, 32767.0) as i16;
    let mm = |m: f64| (m * 1000.0).round() as i64;
    let half = sample.w * track / 2.0;
    let (l_vel, r_vel) = (
        to_i16((sample.v - half) * 1000.0),
        to_i16((sample.v + half) * 1000.0),
    );
    let thpos = angle_units(sample.phi);
    Sip {
        moving: l_vel != 0 || r_vel != 0,
        xpos: position_counter(mm(sample.x)),
        ypos: position_counter(mm(sample.y)),
        thpos,
        l_vel,
        r_vel,
        battery: BATTERY_DECIVOLTS,
        stall_bumpers: 0,
        control: thpos,
        flags: if enabled { FLAG_MOTORS_ENABLED } else { 0 },
        compass: 0,
        sonars: Vec::new(),
        io: Some(SipIo::default()),
        battery_x10: Some(u16::from(BATTERY_DECIVOLTS)),
        charge_state: Some(0),
        rot_vel: Some(to_i16(sample.w.to_degrees() * 10.0)),
        fault_flags: Some(0),
    }
}

fn sip_bytes(sample: &Sample, track: f64, enabled: bool) -> io::Result<Vec<u8>> {
    sip_from_sample(sample, track, enabled)
        .to_packet()
        .map(|p| p.to_bytes())
        .map_err(|e| io::Error::new(io::ErrorKind::InvalidData, e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_sample_becomes_wheel_speeds_and_wrapped_counters() {
        let s = Sample {
            t: 1.0,
            v: 0.5,
            w: 1.0,
            x: 33.0,
            y: -0.002,
            phi: 3.0 * std::f64::consts::PI / 2.0,
        };
        let sip = sip_from_sample(&s, 0.34, true);
        // v ∓ ωd/2 = 0.5 ∓ 0.17 m/s.
        assert_eq!((sip.l_vel, sip.r_vel), (330, 670));
        // 33 000 mm mod 32 768 = 232; −2 mm is 32 766 on the counter.
        assert_eq!((sip.xpos, sip.ypos), (232, 32_766));
        // 3π/2 ≡ −π/2 = −1024 units.
        assert_eq!(sip.thpos, -1024);
        assert_eq!(sip.rot_vel, Some(573));
        assert!(sip.moving && sip.motors_enabled());
    }
}
