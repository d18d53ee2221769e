//! Closed-loop trajectory tracking: the thesis's 11-state system (5 robot states of eq. 2.19,
//! 6 estimates θ̂), with the kinematic law, the inverse-dynamics controller and the adaptive law
//! of [`crate::control`] driving a [`SimRobot`] ([`track`]) or any [`Robot`] backend — the
//! physics robot, a real robot, a plugin's ([`track_robot`]).
//!
//! Each period k: the robot reports (v, ω) and its pose (odometry with encoders, exact
//! otherwise); the trajectory gives the desired state at t_k; eq. 4.8 gives (v_ref^k, ω_ref^k);
//! the controller returns v_ref = G θ̂ and updates θ̂; the robot holds v_ref for one period.
//! The distance error (§4.3) is √((x_d − x)² + (y_d − y)²) with the robot's **true** position.

use serde::{Deserialize, Serialize};
use wheelid_core::{Error, Result, Robot, RobotError};

use crate::control::{AdaptiveController, AdaptiveSettings, KinematicLaw};
use crate::profile::RobotProfile;
use crate::simulator::{SimRobot, SimSettings};
use crate::trajectory::{Trajectory, TrajectorySpec};

/// Where the robot starts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Start {
    /// On the trajectory's start pose, at rest (as a real robot starts).
    #[default]
    AtRest,
    /// On the trajectory's start pose, moving at its desired v, ω (the "perfect initial
    /// conditions for position and velocity" of §4.2).
    OnTrajectory,
}

/// A tracking run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrackSettings {
    /// Duration \[s\].
    pub duration_s: f64,
    /// The desired trajectory; `None`: the figure-eight preset for the robot
    /// ([`TrajectorySpec::for_profile`]).
    pub trajectory: Option<TrajectorySpec>,
    /// Kinematic-law gains (eq. 4.8).
    pub kinematic: KinematicLaw,
    /// Initial estimate θ̂(0).
    pub theta_hat0: [f64; 6],
    /// Inverse-dynamics gains and adaptation.
    pub adaptation: AdaptiveSettings,
    /// Initial state.
    pub start: Start,
    /// Control period \[s\]; `None`: the robot's period.
    pub control_period_s: Option<f64>,
    /// Clip the commands to the profile's ±v_max, ±w_max before sending them (as a robot's
    /// firmware does; without it a diverging adaptation ends the run with an error).
    pub clip_commands: bool,
    /// The simulated robot's settings (seed, sub-steps, encoder model, effects);
    /// `duration_s` there is ignored.
    pub simulation: SimSettings,
}

impl Default for TrackSettings {
    /// 120 s of the robot's figure eight, θ̂ = 1, no adaptation, from rest, robot period,
    /// commands clipped to the robot's limits.
    fn default() -> Self {
        Self {
            duration_s: 120.0,
            trajectory: None,
            kinematic: KinematicLaw::default(),
            theta_hat0: [1.0; 6],
            adaptation: AdaptiveSettings::default(),
            start: Start::AtRest,
            control_period_s: None,
            clip_commands: true,
            simulation: SimSettings::default(),
        }
    }
}

fn yes() -> bool {
    true
}

/// Summary of a distance-error series \[m\].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ErrorSummary {
    /// Root mean square over the run.
    pub rms: f64,
    /// At the end of the run.
    pub last: f64,
    /// Largest.
    pub max: f64,
}

impl ErrorSummary {
    /// Summary of `e` (NaN for an empty slice).
    pub fn of(e: &[f64]) -> Self {
        let n = e.len() as f64;
        Self {
            rms: (e.iter().map(|x| x * x).sum::<f64>() / n).sqrt(),
            last: e.last().copied().unwrap_or(f64::NAN),
            max: e.iter().copied().fold(f64::NAN, f64::max),
        }
    }
}

/// The time series of a tracking run, one entry per control period.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrackResult {
    /// Robot profile name.
    pub robot: String,
    /// Time \[s\].
    pub t: Vec<f64>,
    /// Desired position (x_d, y_d) \[m\].
    pub desired: Vec<[f64; 2]>,
    /// True position (x, y) of the point h \[m\].
    pub actual: Vec<[f64; 2]>,
    /// Position the controller used (odometry with encoders) \[m\].
    pub measured: Vec<[f64; 2]>,
    /// Distance error \[m\].
    pub error: Vec<f64>,
    /// Commands sent (v_ref [m/s], ω_ref [rad/s]).
    pub command: Vec<[f64; 2]>,
    /// θ̂ in force at each step.
    pub theta_hat: Vec<[f64; 6]>,
    /// Whether `actual` (and the error) is the backend's ground truth; `false`: the reported
    /// (odometry) pose, from a backend that does not know its true pose.
    #[serde(default = "yes")]
    pub ground_truth: bool,
    /// Error summary over the run.
    pub summary: ErrorSummary,
}

impl TrackResult {
    /// The error summary over [t0, t1).
    pub fn summary_between(&self, t0: f64, t1: f64) -> ErrorSummary {
        let e: Vec<f64> = self
            .t
            .iter()
            .zip(&self.error)
            .filter(|(t, _)| **t >= t0 && **t < t1)
            .map(|(_, e)| *e)
            .collect();
        ErrorSummary::of(&e)
    }

    /// The final estimate θ̂.
    pub fn final_theta_hat(&self) -> [f64; 6] {
        self.theta_hat.last().copied().unwrap_or([f64::NAN; 6])
    }
}

/// Runs figure-eight (or any [`TrajectorySpec`]) tracking of the simulated `profile` (eq. 2.19,
/// [`SimRobot`] with `settings.simulation`) under `settings`, the robot placed on the
/// trajectory's start pose ([`Start`]).
///
/// # Errors
/// [`Error::InvalidSetting`] for invalid settings, or if the loop diverges (a non-finite state
/// or command), naming the time.
pub fn track(profile: &RobotProfile, settings: &TrackSettings) -> Result<TrackResult> {
    let mut profile = profile.clone();
    if let Some(dt) = settings.control_period_s {
        if !(dt.is_finite() && dt > 0.0) {
            return Err(Error::InvalidSetting(format!(
                "control_period_s = {dt} must be > 0"
            )));
        }
        profile.period_s = dt;
    }
    let trajectory = settings
        .trajectory
        .unwrap_or_else(|| TrajectorySpec::for_profile(&profile, false));
    trajectory.validate()?;
    let mut robot = SimRobot::new(&profile, &settings.simulation)?;
    let d0 = trajectory.at(0.0);
    let (v0, w0) = match settings.start {
        Start::AtRest => (0.0, 0.0),
        Start::OnTrajectory => (d0.v, d0.w),
    };
    robot.set_state([d0.x, d0.y, d0.phi, v0, w0]);
    let limits = [profile.v_max, profile.w_max];
    let mut plant = SimPlant(robot);
    run_loop(&mut plant, &profile.name, &trajectory, settings, limits)
}

/// Runs tracking on any robot backend through the [`Robot`] trait (the physics robot, a real
/// robot over its link, a plugin's) under `settings` (`settings.simulation` and
/// `control_period_s` are not used: the robot has its own period). The trajectory is anchored
/// at the robot's first reported pose (its start pose and heading moved onto the robot's) and
/// starts at that report's time. Commands are clipped to ±`limits` = [v_max m/s, ω_max rad/s]
/// when `settings.clip_commands`; what is recorded is what [`Robot::send`] returns. The
/// distance error is measured against [`Robot::true_pose`] where the backend knows it, else
/// against the reported pose ([`TrackResult::ground_truth`] says which). The robot is stopped
/// at the end, and on an error.
///
/// # Errors
/// [`Error::InvalidSetting`] for invalid settings (and [`Start::OnTrajectory`]: a robot
/// backend starts where it is, at rest), a robot error (naming the time), or a divergence.
pub fn track_robot(
    robot: &mut dyn Robot,
    trajectory: &TrajectorySpec,
    settings: &TrackSettings,
    limits: [f64; 2],
) -> Result<TrackResult> {
    if settings.start == Start::OnTrajectory {
        return Err(Error::InvalidSetting(
            "start = on_trajectory needs the simulator; a robot backend starts at rest".into(),
        ));
    }
    trajectory.validate()?;
    let name = robot.name().to_string();
    let d0 = trajectory.at(0.0);
    let mut plant = RobotPlant {
        robot,
        t0: None,
        start: [d0.x, d0.y, d0.phi],
        anchor: None,
    };
    let out = run_loop(&mut plant, &name, trajectory, settings, limits);
    let stopped = plant.robot.stop().map_err(robot_error);
    let out = out?;
    stopped?;
    Ok(out)
}

fn robot_error(e: RobotError) -> Error {
    Error::InvalidSetting(format!("robot: {e}"))
}

/// What the tracking loop reads from a plant each period.
struct Report {
    /// Time since the run's start \[s\].
    t: f64,
    v: f64,
    w: f64,
    /// Pose the controller uses (x, y, φ), in the trajectory's frame.
    pose: [f64; 3],
    /// True pose in the trajectory's frame, if known.
    truth: Option<[f64; 3]>,
}

/// The loop's view of a robot: report, then act for one period.
trait Plant {
    fn report(&mut self) -> Result<Report>;
    /// Sends `u` and returns the command as the robot acts on it.
    fn act(&mut self, u: [f64; 2]) -> Result<[f64; 2]>;
}

/// The eq.-2.19 simulator, driven directly (report k at t_k without stepping, as the thesis's
/// 11-state loop).
struct SimPlant(SimRobot);

impl Plant for SimPlant {
    fn report(&mut self) -> Result<Report> {
        let m = self.0.sample();
        let s = self.0.true_state();
        Ok(Report {
            t: m.t,
            v: m.v,
            w: m.w,
            pose: [m.x, m.y, m.phi],
            truth: Some([s[0], s[1], s[2]]),
        })
    }
    fn act(&mut self, u: [f64; 2]) -> Result<[f64; 2]> {
        self.0.step(u[0], u[1]);
        Ok(u)
    }
}

/// A [`Robot`] backend; poses are moved into the trajectory's frame by the rigid motion that
/// takes the first reported pose onto the trajectory's start.
struct RobotPlant<'a> {
    robot: &'a mut dyn Robot,
    t0: Option<f64>,
    /// The trajectory's start pose.
    start: [f64; 3],
    /// (first reported pose, trajectory start pose), set at the first report.
    anchor: Option<([f64; 3], [f64; 3])>,
}

impl RobotPlant<'_> {
    /// `p` (robot frame) in the trajectory's frame.
    fn to_trajectory(&self, p: [f64; 3]) -> [f64; 3] {
        let Some((r0, d0)) = self.anchor else {
            return p;
        };
        let dpsi = d0[2] - r0[2];
        let (s, c) = dpsi.sin_cos();
        let (dx, dy) = (p[0] - r0[0], p[1] - r0[1]);
        [
            d0[0] + c * dx - s * dy,
            d0[1] + s * dx + c * dy,
            p[2] + dpsi,
        ]
    }
}

impl Plant for RobotPlant<'_> {
    fn report(&mut self) -> Result<Report> {
        let o = self.robot.read().map_err(robot_error)?;
        let t0 = *self.t0.get_or_insert(o.t);
        let pose = [o.pose.x, o.pose.y, o.pose.heading];
        let start = self.start;
        self.anchor.get_or_insert((pose, start));
        let truth = self.robot.true_pose().map(|p| [p.x, p.y, p.heading]);
        Ok(Report {
            t: o.t - t0,
            v: o.v,
            w: o.w,
            pose: self.to_trajectory(pose),
            truth: truth.map(|p| self.to_trajectory(p)),
        })
    }
    fn act(&mut self, u: [f64; 2]) -> Result<[f64; 2]> {
        let (v, w) = self.robot.send(u[0], u[1]).map_err(robot_error)?;
        Ok([v, w])
    }
}

/// The tracking loop (module docs) on `plant` for `settings.duration_s`.
fn run_loop(
    plant: &mut dyn Plant,
    name: &str,
    trajectory: &TrajectorySpec,
    settings: &TrackSettings,
    limits: [f64; 2],
) -> Result<TrackResult> {
    if !(settings.duration_s.is_finite() && settings.duration_s > 0.0) {
        return Err(Error::InvalidSetting(format!(
            "duration_s = {} must be > 0",
            settings.duration_s
        )));
    }
    let mut ctrl = AdaptiveController::new(settings.adaptation.clone(), settings.theta_hat0)?;
    let mut out = TrackResult {
        robot: name.to_string(),
        t: Vec::new(),
        desired: Vec::new(),
        actual: Vec::new(),
        measured: Vec::new(),
        error: Vec::new(),
        command: Vec::new(),
        theta_hat: Vec::new(),
        ground_truth: true,
        summary: ErrorSummary::of(&[]),
    };
    let mut m = plant.report()?;
    let mut t_prev = m.t;
    while m.t <= settings.duration_s + 1e-9 {
        let d = trajectory.at(m.t);
        let kin = settings
            .kinematic
            .command(&d, m.pose[0], m.pose[1], m.pose[2]);
        let dt = if out.t.is_empty() { 0.0 } else { m.t - t_prev };
        let th = ctrl.theta_hat();
        let mut u = ctrl.step(m.t, dt, kin, m.v, m.w);
        if settings.clip_commands {
            u = [0, 1].map(|i| u[i].clamp(-limits[i], limits[i]));
        }
        let truth = m.truth.unwrap_or(m.pose);
        out.ground_truth &= m.truth.is_some();
        if !truth.iter().chain(&u).all(|x| x.is_finite()) {
            return Err(Error::InvalidSetting(format!(
                "tracking diverged at t = {:.3} s (pose {truth:?}, command {u:?})",
                m.t
            )));
        }
        out.t.push(m.t);
        out.desired.push([d.x, d.y]);
        out.actual.push([truth[0], truth[1]]);
        out.measured.push([m.pose[0], m.pose[1]]);
        out.error.push((d.x - truth[0]).hypot(d.y - truth[1]));
        out.theta_hat.push(th);
        t_prev = m.t;
        let sent = plant.act(u)?;
        out.command.push(sent);
        m = plant.report()?;
    }
    out.summary = ErrorSummary::of(&out.error);
    Ok(out)
}
