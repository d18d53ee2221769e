//! The loopback server: a Khepera III that speaks the serial text protocol over TCP, with the
//! simulator behind it.

use std::io::{self, BufRead, BufReader, Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use super::KheperaSettings;
use super::codec::{Command, Units, Wheels};
use crate::profile::RobotProfile;
use crate::simulator::{Sample, SimRobot, SimSettings};

/// How the loopback server's simulation advances.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pacing {
    /// With the wall clock: before answering any command, the simulation takes as many periods
    /// as have elapsed since the client connected (never running ahead of the wall clock). A
    /// client reading every period sees about one step per read.
    RealTime,
    /// Deterministic: the simulation advances exactly one period at each `E` request (with the
    /// command in force), and at no other time. `D` sets the command for the following steps;
    /// `R` and `I` act at the current simulated instant. A client that sends `D`, then `E` and
    /// `R` each period runs the simulation as fast as the link allows, the same way every time.
    LockStep,
}

/// What a finished session did.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ServerStats {
    /// Command lines answered (including those answered `$`).
    pub commands: u64,
    /// Simulation periods taken.
    pub steps: u64,
    /// Simulated time at the end \[s\].
    pub sim_time_s: f64,
}

/// A Khepera-III-speaking server on top of the simulator, for tests and demos.
///
/// It listens on `127.0.0.1` (an ephemeral port) and serves one client, answering the commands
/// of the [codec](super::codec) as the robot would:
///
/// - `D,l<left>,l<right>` → `d`: holds the wheel speeds, turned back into a command
///   (v_ref, ω_ref) = ((v_r + v_l)/2, (v_r − v_l)/d) from the *integer* speed units (so the
///   simulated robot gets the command as rounded by the protocol, 1/144.01 mm/s per unit);
/// - `E` → `e,<left>,<right>`: the simulator's measured wheel speeds v ∓ dω/2 in speed units,
///   rounded (the sample's v, ω are the encoder window averages of the
///   [simulator](crate::simulator), with its noise when `measurement_noise` is on);
/// - `R` → `r,<left>,<right>`: 32-bit position counters (wrapping) that count the simulated
///   wheel travel in pulses. Each period's wheel travels are recovered from the simulator's
///   odometry pose (Δs = Δx cos φ̄ + Δy sin φ̄, Δφ; left/right = Δs ∓ dΔφ/2), which with the
///   encoder model gives back the simulator's whole encoder ticks, so a client integrating these
///   counters reproduces the simulator's pose (of the axle centre, which starts `a` behind the
///   point h the simulator reports when the profile's `a` ≠ 0);
/// - `I,l<left>,l<right>` → `i`: sets the counters;
/// - anything else → `$` (as K-Team's `kh3server`).
///
/// Units are [`Units::from_profile`]: 144.01 speed units per mm/s, the profile's encoder
/// (`ticks_per_rev` per wheel revolution, i.e. one pulse per simulated tick), track and v_max.
/// Answers end with `\r\n`. The session ends when the client disconnects, on a line the server
/// cannot read (not UTF-8, or longer than 4 KiB), or at [`ServerHandle::shutdown`].
#[derive(Debug)]
pub struct KheperaServer;

impl KheperaServer {
    /// Starts a server thread for one client, listening on `127.0.0.1:0`.
    ///
    /// # Errors
    /// [`io::ErrorKind::InvalidInput`] if the simulator rejects the profile or settings; the
    /// socket's errors if it cannot listen.
    pub fn spawn(
        profile: RobotProfile,
        sim: SimSettings,
        pacing: Pacing,
    ) -> io::Result<ServerHandle> {
        let robot = SimRobot::new(&profile, &sim)
            .map_err(|e| io::Error::new(io::ErrorKind::InvalidInput, e.to_string()))?;
        let units = Units::from_profile(&profile);
        let listener = TcpListener::bind("127.0.0.1:0")?;
        listener.set_nonblocking(true)?;
        let addr = listener.local_addr()?;
        let stop = Arc::new(AtomicBool::new(false));
        let flag = Arc::clone(&stop);
        let thread = std::thread::Builder::new()
            .name(format!("khepera-server-{}", addr.port()))
            .spawn(move || {
                let session = Session::new(robot, units, pacing);
                serve(&listener, session, &flag)
            })?;
        Ok(ServerHandle {
            addr,
            pacing,
            profile,
            stop,
            thread: Some(thread),
        })
    }
}

/// A running [`KheperaServer`]: its address; stops and joins the thread on
/// [`ServerHandle::shutdown`] or when dropped.
#[derive(Debug)]
pub struct ServerHandle {
    addr: SocketAddr,
    pacing: Pacing,
    profile: RobotProfile,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<io::Result<ServerStats>>>,
}

impl ServerHandle {
    /// The address the server listens on (`127.0.0.1:<port>`).
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// The address as a [`KheperaSettings::port`]: `tcp://127.0.0.1:<port>`.
    pub fn url(&self) -> String {
        format!("tcp://{}", self.addr)
    }

    /// Client settings that match this server: its URL, the profile's units and period,
    /// `realtime` for [`Pacing::RealTime`] only, and a 2 s timeout.
    pub fn client_settings(&self) -> KheperaSettings {
        KheperaSettings {
            port: self.url(),
            realtime: self.pacing == Pacing::RealTime,
            timeout_s: 2.0,
            ..KheperaSettings::for_profile(&self.profile)
        }
    }

    /// Whether the server thread has ended (its client disconnected, or it was stopped).
    pub fn is_finished(&self) -> bool {
        self.thread.as_ref().is_none_or(JoinHandle::is_finished)
    }

    /// Stops the server (ending a session in progress within about 20 ms) and returns what the
    /// session did.
    ///
    /// # Errors
    /// A socket error of the session (a client disconnecting is not one), or
    /// [`io::ErrorKind::Other`] if the server thread panicked.
    pub fn shutdown(mut self) -> io::Result<ServerStats> {
        self.stop_and_join()
    }

    fn stop_and_join(&mut self) -> io::Result<ServerStats> {
        self.stop.store(true, Ordering::SeqCst);
        match self.thread.take() {
            Some(thread) => thread
                .join()
                .unwrap_or_else(|_| Err(io::Error::other("the khepera server thread panicked"))),
            None => Ok(ServerStats::default()),
        }
    }
}

impl Drop for ServerHandle {
    fn drop(&mut self) {
        let _ = self.stop_and_join();
    }
}

/// How often a waiting server looks at the stop flag.
const POLL: Duration = Duration::from_millis(20);

/// Longest command line read [bytes].
const MAX_LINE: u64 = 4096;

/// Waits for one client and serves it until it leaves or the server is stopped.
fn serve(
    listener: &TcpListener,
    mut session: Session,
    stop: &AtomicBool,
) -> io::Result<ServerStats> {
    let stream = loop {
        if stop.load(Ordering::SeqCst) {
            return Ok(session.stats());
        }
        match listener.accept() {
            Ok((stream, _)) => break stream,
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => std::thread::sleep(POLL),
            Err(e) => return Err(e),
        }
    };
    stream.set_nonblocking(false)?;
    stream.set_read_timeout(Some(POLL))?;
    stream.set_nodelay(true)?;
    session.started = Instant::now();
    let mut writer = stream.try_clone()?;
    let mut reader = BufReader::new(stream);
    let mut line = String::new();
    loop {
        if stop.load(Ordering::SeqCst) {
            break;
        }
        match read_line(&mut reader, &mut line) {
            Ok(0) => break, // the client disconnected
            Ok(_) => {
                if !line.ends_with('\n') {
                    continue; // the rest of the line is still on its way
                }
                let command = line.trim();
                if !command.is_empty() {
                    let answer = format!("{}\r\n", session.answer(command));
                    match writer.write_all(answer.as_bytes()) {
                        Ok(()) => {}
                        Err(e) if is_disconnect(&e) => break, // the client left meanwhile
                        Err(e) => return Err(e),
                    }
                }
                line.clear();
            }
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut
                ) => {}
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) if is_disconnect(&e) => break,
            Err(e) => return Err(e),
        }
    }
    Ok(session.stats())
}

/// Appends to `line` up to and including the next `\n` (partial lines stay in `line` across a
/// read timeout). `Ok(0)` at the end of the stream.
fn read_line(reader: &mut BufReader<TcpStream>, line: &mut String) -> io::Result<usize> {
    let before = line.len();
    let n = reader.by_ref().take(MAX_LINE).read_line(line)?;
    if n == 0 && before == 0 {
        return Ok(0);
    }
    if line.len() as u64 >= MAX_LINE && !line.ends_with('\n') {
        return Err(io::Error::new(
            io::ErrorKind::InvalidData,
            format!("a command line longer than {MAX_LINE} bytes"),
        ));
    }
    if n == 0 {
        // End of stream in the middle of a line: the client left.
        return Ok(0);
    }
    Ok(n)
}

fn is_disconnect(e: &io::Error) -> bool {
    matches!(
        e.kind(),
        io::ErrorKind::ConnectionReset
            | io::ErrorKind::ConnectionAborted
            | io::ErrorKind::BrokenPipe
            | io::ErrorKind::UnexpectedEof
    )
}

/// The simulated robot behind one connection.
struct Session {
    robot: SimRobot,
    units: Units,
    pacing: Pacing,
    started: Instant,
    /// The command in force (v_ref [m/s], ω_ref [rad/s]), from the last `D`.
    command: (f64, f64),
    /// The last sample of the simulator.
    last: Sample,
    /// Wheel travel since the start [pulses, not rounded], and the counters' offset set by `I`.
    travel: Wheels<f64>,
    offset: Wheels<i64>,
    commands: u64,
    steps: u64,
}

impl Session {
    fn new(robot: SimRobot, units: Units, pacing: Pacing) -> Self {
        let last = robot.sample();
        Self {
            robot,
            units,
            pacing,
            started: Instant::now(),
            command: (0.0, 0.0),
            last,
            travel: Wheels::default(),
            offset: Wheels::default(),
            commands: 0,
            steps: 0,
        }
    }

    fn stats(&self) -> ServerStats {
        ServerStats {
            commands: self.commands,
            steps: self.steps,
            sim_time_s: self.last.t,
        }
    }

    /// Advances the simulation one period under the command in force and counts the wheel
    /// travel from the change in its odometry pose.
    fn step(&mut self) {
        let (v_ref, w_ref) = self.command;
        let before = self.last;
        let after = self.robot.step(v_ref, w_ref);
        let a = self.robot.profile().a;
        // The axle centre (the simulator reports the point h, `a` ahead of it).
        let axle = |s: &Sample| (s.x - a * s.phi.cos(), s.y - a * s.phi.sin());
        let ((x0, y0), (x1, y1)) = (axle(&before), axle(&after));
        let dphi = after.phi - before.phi;
        let mid = before.phi + dphi / 2.0;
        let ds = (x1 - x0) * mid.cos() + (y1 - y0) * mid.sin();
        let half = self.units.track * dphi / 2.0;
        self.travel.left += self.units.m_to_pulses(ds - half);
        self.travel.right += self.units.m_to_pulses(ds + half);
        self.last = after;
        self.steps += 1;
    }

    /// [`Pacing::RealTime`]: catches the simulation up with the wall clock.
    fn catch_up(&mut self) {
        let elapsed = self.started.elapsed().as_secs_f64();
        let due = (elapsed / self.robot.period_s()).floor() as u64;
        while self.steps < due {
            self.step();
        }
    }

    /// The 32-bit counters as the firmware reports them (wrapping).
    fn counters(&self) -> Wheels<i32> {
        // f64 → i64 saturates; i64 → i32 keeps the low 32 bits, as the register does.
        let c = |travel: f64, offset: i64| (travel.round() as i64).wrapping_add(offset) as i32;
        Wheels::new(
            c(self.travel.left, self.offset.left),
            c(self.travel.right, self.offset.right),
        )
    }

    /// The answer (without terminator) to one command line.
    fn answer(&mut self, line: &str) -> String {
        self.commands += 1;
        if self.pacing == Pacing::RealTime {
            self.catch_up();
        }
        match Command::parse(line) {
            Ok(Command::SetSpeed(w)) => {
                self.command = self.units.velocity_of_units(w);
                "d".into()
            }
            Ok(Command::ReadSpeed) => {
                if self.pacing == Pacing::LockStep {
                    self.step();
                }
                let wheels = self.units.wheel_speeds(self.last.v, self.last.w);
                // Measured speeds are reported as they are, beyond the command clamp.
                let units =
                    |mps: f64| (mps * 1000.0 * self.units.speed_units_per_mm_s).round() as i64;
                format!("e,{},{}", units(wheels.left), units(wheels.right))
            }
            Ok(Command::ReadPosition) => {
                let c = self.counters();
                format!("r,{},{}", c.left, c.right)
            }
            Ok(Command::SetPosition(w)) => {
                let now = self.counters();
                self.offset.left += i64::from(w.left) - i64::from(now.left);
                self.offset.right += i64::from(w.right) - i64::from(now.right);
                "i".into()
            }
            Err(_) => "$".into(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::khepera::Odometer;
    use wheelid_core::Pose;

    /// The counters carry the simulator's ticks also when it reports a point h ahead of the
    /// axle: integrating them gives back its odometry.
    #[test]
    fn counters_reproduce_the_simulator_odometry_with_an_offset_point() {
        let profile = RobotProfile {
            a: 0.03,
            ..RobotProfile::khepera3()
        };
        // As `KheperaServer::spawn` makes it: `SimRobot::new` starts its odometry consistent
        // with the point h at the origin, so the first period's travel is not off by `a`.
        let robot = SimRobot::new(&profile, &SimSettings::default()).expect("sim");
        let units = Units::from_profile(&profile);
        let mut session = Session::new(robot, units, Pacing::LockStep);
        // The client's odometer follows the axle, which starts `a` behind h.
        let start = Pose {
            x: -profile.a,
            ..Pose::default()
        };
        let mut odo = Odometer::new(units, session.counters(), start);
        for k in 0..400 {
            let t = k as f64 * profile.period_s;
            let w = Command::SetSpeed(units.speed_command(0.2, 3.0 * (1.3 * t).sin()));
            assert_eq!(session.answer(&w.to_string()), "d");
            assert!(session.answer("E").starts_with("e,"));
            let pose = odo.update(session.counters());
            let s = session.last;
            let (hx, hy) = (
                pose.x + profile.a * pose.heading.cos(),
                pose.y + profile.a * pose.heading.sin(),
            );
            assert!((hx - s.x).abs() < 1e-9 && (hy - s.y).abs() < 1e-9, "{k}");
            assert!((pose.heading - s.phi).abs() < 1e-12, "{k}");
        }
        assert_eq!(session.stats().steps, 400);
    }
}
