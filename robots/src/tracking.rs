//! Closed-loop trajectory tracking: the thesis's 11-state system (5 robot states of eq. 2.19,
//! 6 estimates θ̂), with the kinematic law, the inverse-dynamics controller and the adaptive law
//! of [`crate::control`] driving a [`SimRobot`].
//!
//! Each period k: the robot reports (v, ω) and its pose (odometry with encoders, exact
//! otherwise); the trajectory gives the desired state at t_k; eq. 4.8 gives (v_ref^k, ω_ref^k);
//! the controller returns v_ref = G θ̂ and updates θ̂; the robot holds v_ref for one period.
//! The distance error (§4.3) is √((x_d − x)² + (y_d − y)²) with the robot's **true** position.

use serde::{Deserialize, Serialize};
use wheelid_core::{Error, Result};

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
    /// Duration [s].
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
    /// Control period [s]; `None`: the robot's period.
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

/// Summary of a distance-error series [m].
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
    /// Time [s].
    pub t: Vec<f64>,
    /// Desired position (x_d, y_d) [m].
    pub desired: Vec<[f64; 2]>,
    /// True position (x, y) of the point h [m].
    pub actual: Vec<[f64; 2]>,
    /// Position the controller used (odometry with encoders) [m].
    pub measured: Vec<[f64; 2]>,
    /// Distance error [m].
    pub error: Vec<f64>,
    /// Commands sent (v_ref [m/s], ω_ref [rad/s]).
    pub command: Vec<[f64; 2]>,
    /// θ̂ in force at each step.
    pub theta_hat: Vec<[f64; 6]>,
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

/// Runs figure-eight (or any [`TrajectorySpec`]) tracking of `profile` under `settings`.
///
/// # Errors
/// [`Error::InvalidSetting`] for invalid settings, or if the loop diverges (a non-finite state
/// or command), naming the time.
pub fn track(profile: &RobotProfile, settings: &TrackSettings) -> Result<TrackResult> {
    if !(settings.duration_s.is_finite() && settings.duration_s > 0.0) {
        return Err(Error::InvalidSetting(format!(
            "duration_s = {} must be > 0",
            settings.duration_s
        )));
    }
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
    let mut ctrl = AdaptiveController::new(settings.adaptation.clone(), settings.theta_hat0)?;
    let d0 = trajectory.at(0.0);
    let (v0, w0) = match settings.start {
        Start::AtRest => (0.0, 0.0),
        Start::OnTrajectory => (d0.v, d0.w),
    };
    robot.set_state([d0.x, d0.y, d0.phi, v0, w0]);
    let n = (settings.duration_s / profile.period_s).floor() as usize + 1;
    let mut out = TrackResult {
        robot: profile.name.clone(),
        t: Vec::with_capacity(n),
        desired: Vec::with_capacity(n),
        actual: Vec::with_capacity(n),
        measured: Vec::with_capacity(n),
        error: Vec::with_capacity(n),
        command: Vec::with_capacity(n),
        theta_hat: Vec::with_capacity(n),
        summary: ErrorSummary::of(&[]),
    };
    let mut m = robot.sample();
    let mut t_prev = m.t;
    for k in 0..n {
        let d = trajectory.at(m.t);
        let kin = settings.kinematic.command(&d, m.x, m.y, m.phi);
        let dt = if k == 0 { 0.0 } else { m.t - t_prev };
        let th = ctrl.theta_hat();
        let mut u = ctrl.step(m.t, dt, kin, m.v, m.w);
        if settings.clip_commands {
            u = [
                u[0].clamp(-profile.v_max, profile.v_max),
                u[1].clamp(-profile.w_max, profile.w_max),
            ];
        }
        let s = robot.true_state();
        if !s.iter().chain(&u).all(|x| x.is_finite()) {
            return Err(Error::InvalidSetting(format!(
                "tracking diverged at t = {:.3} s (state {s:?}, command {u:?})",
                m.t
            )));
        }
        out.t.push(m.t);
        out.desired.push([d.x, d.y]);
        out.actual.push([s[0], s[1]]);
        out.measured.push([m.x, m.y]);
        out.error.push((d.x - s[0]).hypot(d.y - s[1]));
        out.command.push(u);
        out.theta_hat.push(th);
        t_prev = m.t;
        if k + 1 < n {
            m = robot.step(u[0], u[1]);
        }
    }
    out.summary = ErrorSummary::of(&out.error);
    Ok(out)
}
