//! The migration pipeline (issue 16): model files → [`RobotModel`]s, [`migrate`], and the
//! closed loop on the target with the controller as it was, as migrated, and (where the
//! target's true θ is known, as in simulation) set up with that θ.
//!
//! The three runs track the same path — the migrated trajectory — so their errors compare
//! the controllers, not the paths. "As it was" keeps the source's gains, γ, bounds and θ̂(0).

use serde::Serialize;
use wheelid_core::{Error, Result, Robot};
use wheelid_robots::migrate::{ControllerSpec, Migrated, RobotModel, migrate};
use wheelid_robots::tracking::ErrorSummary;
use wheelid_robots::{RobotProfile, SimSettings, TrackResult, TrackSettings, track, track_robot};

use crate::files::ModelFile;

/// The [`RobotModel`] of a model file on `profile`'s robot: θ and standard errors from the
/// file; period and limits from the profile, tightened by what a diagnosis found
/// (`velocity_saturation` `v_max`/`w_max`, `acceleration_limit` `v_accel_max`/`w_accel_max`,
/// the dead time: `input_delay` and `output_delay` `delay_s` together, which a controller's
/// loop meets alike).
///
/// # Errors
/// [`Error::InvalidSetting`] when the file's θ does not have 6 values.
pub fn robot_model(file: &ModelFile, profile: &RobotProfile) -> Result<RobotModel> {
    let six = |x: &[f64], what: &str| -> Result<[f64; 6]> {
        x.try_into().map_err(|_| {
            Error::InvalidSetting(format!("the model's {what} has {} values, not 6", x.len()))
        })
    };
    let mut m = RobotModel::from_profile(profile);
    m.robot = file.robot.clone().unwrap_or_else(|| profile.name.clone());
    m.theta = Some(six(&file.theta, "theta")?);
    m.std_err = six(&file.std_err, "std_err").ok();
    let get = |e: &str, p: &str| file.effects.get(e).and_then(|ps| ps.get(p)).copied();
    if let Some(v) = get("velocity_saturation", "v_max") {
        m.v_max = m.v_max.min(v);
    }
    if let Some(w) = get("velocity_saturation", "w_max") {
        m.w_max = m.w_max.min(w);
    }
    let (av, aw) = (
        get("acceleration_limit", "v_accel_max"),
        get("acceleration_limit", "w_accel_max"),
    );
    if av.is_some() || aw.is_some() {
        m.accel_max = Some([av.unwrap_or(f64::INFINITY), aw.unwrap_or(f64::INFINITY)]);
    }
    let (din, dout) = (
        get("input_delay", "delay_s"),
        get("output_delay", "delay_s"),
    );
    if din.is_some() || dout.is_some() {
        m.delay_s = Some(din.unwrap_or(0.0) + dout.unwrap_or(0.0));
    }
    Ok(m)
}

/// One tracking run's outcome.
#[derive(Debug, Clone, Serialize)]
pub struct Run {
    /// What ran (`as it was`, `migrated`, `target's true θ`).
    pub label: String,
    /// Distance error summary \[m\] over the whole run.
    pub error: ErrorSummary,
    /// θ̂ at the end.
    pub theta_hat_end: [f64; 6],
    /// The run's time series (for plots; not in the JSON).
    #[serde(skip)]
    pub result: TrackResult,
}

impl Run {
    fn of(label: &str, r: &TrackResult) -> Self {
        Self {
            label: label.into(),
            error: r.summary,
            theta_hat_end: r.final_theta_hat(),
            result: r.clone(),
        }
    }
}

/// A migration and its check on the target.
#[derive(Debug, Clone, Serialize)]
pub struct Migration {
    /// The migrated controller with its choices and warnings.
    pub migrated: Migrated,
    /// The closed-loop runs, in the order: as it was, migrated, and (if known) with the
    /// target's true θ.
    pub runs: Vec<Run>,
}

/// How the migrated controller is checked on the target.
#[derive(Debug, Clone)]
pub struct CheckSettings {
    /// Tracking time \[s\].
    pub duration_s: f64,
    /// Also run the controller set up with the target's true θ (known in simulation).
    pub with_truth: bool,
    /// The simulated target's settings (seed, encoders, effects such as a payload);
    /// `duration_s` there is ignored. Not used on a [`Robot`] backend.
    pub simulation: SimSettings,
}

impl Default for CheckSettings {
    /// 90 s, no true-θ run, the simulator's defaults.
    fn default() -> Self {
        Self {
            duration_s: 90.0,
            with_truth: false,
            simulation: SimSettings::default(),
        }
    }
}

/// The runs of a check: as it was (the migrated path), migrated, and with the true θ
/// (`truth`), each through `run`.
fn check(
    ctrl: &ControllerSpec,
    from: &RobotModel,
    migrated: Migrated,
    truth: Option<RobotModel>,
    duration_s: f64,
    run: &mut dyn FnMut(&TrackSettings) -> Result<TrackResult>,
) -> Result<Migration> {
    let mut as_was = ctrl.track_settings(duration_s);
    as_was.trajectory = Some(migrated.controller.trajectory);
    let mut runs = vec![
        Run::of("as it was", &run(&as_was)?),
        Run::of(
            "migrated",
            &run(&migrated.controller.track_settings(duration_s))?,
        ),
    ];
    if let Some(truth) = truth {
        let reference = migrate(ctrl, from, &truth)?;
        runs.push(Run::of(
            "target's true θ",
            &run(&reference.controller.track_settings(duration_s))?,
        ));
    }
    Ok(Migration { migrated, runs })
}

/// Migrates `ctrl` from `from` to `to` and tracks the migrated path on the eq.-2.19
/// simulation of `target` (its θ is the plant) with the controller as it was and as migrated,
/// and with θ̂(0) and bounds from `target.theta` when `check.with_truth`.
///
/// # Errors
/// As [`migrate`] and [`track`] (a diverging run is an error naming the time).
pub fn migrate_on_simulator(
    ctrl: &ControllerSpec,
    from: &RobotModel,
    to: &RobotModel,
    target: &RobotProfile,
    settings: &CheckSettings,
) -> Result<Migration> {
    let migrated = migrate(ctrl, from, to)?;
    let truth = settings.with_truth.then(|| {
        let mut t = RobotModel::from_profile(target);
        t.robot = to.robot.clone();
        t
    });
    let mut run = |s: &TrackSettings| {
        let mut s = s.clone();
        s.simulation = settings.simulation.clone();
        track(target, &s)
    };
    check(ctrl, from, migrated, truth, settings.duration_s, &mut run)
}

/// As [`migrate_on_simulator`], on any robot backend: `make` gives a fresh robot at rest for
/// each run (the physics robot, a loopback or real robot, a plugin's); commands are clipped to
/// the target model's ±(v_max, ω_max). `truth`: the target's true θ where the backend knows it
/// (the physics robot's map), for the third run.
///
/// # Errors
/// As [`migrate`] and [`track_robot`]; errors of `make`.
pub fn migrate_on_robot(
    ctrl: &ControllerSpec,
    from: &RobotModel,
    to: &RobotModel,
    make: &mut dyn FnMut() -> Result<Box<dyn Robot>>,
    truth: Option<[f64; 6]>,
    duration_s: f64,
) -> Result<Migration> {
    let migrated = migrate(ctrl, from, to)?;
    let truth = truth.map(|th| RobotModel {
        theta: Some(th),
        std_err: None,
        bounds: None,
        ..to.clone()
    });
    let limits = [to.v_max, to.w_max];
    let mut run = |s: &TrackSettings| {
        let mut robot = make()?;
        let path = s.trajectory.unwrap_or(migrated.controller.trajectory);
        track_robot(robot.as_mut(), &path, s, limits)
    };
    check(ctrl, from, migrated.clone(), truth, duration_s, &mut run)
}

/// Reads a controller description (TOML: `robot`, `theta_hat0`, `[kinematic]` k1 k2 k3,
/// `[adaptation]` k_v k_w gamma frozen lower upper …, `[trajectory]` type = "figure_eight"
/// ax ay f), as [`write_controller`] writes it.
///
/// # Errors
/// I/O errors and TOML errors with the file, line and column.
pub fn read_controller(path: &std::path::Path) -> anyhow::Result<ControllerSpec> {
    crate::config::read_toml(path)
}

/// Writes `spec` as TOML, atomically (a failed write leaves no half-written file).
///
/// # Errors
/// Serialization or I/O errors naming the file.
pub fn write_controller(path: &std::path::Path, spec: &ControllerSpec) -> anyhow::Result<()> {
    let text = toml::to_string(spec)?;
    wheelid_core::recording::write_atomic(path, text.as_bytes())
        .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    Ok(())
}

/// The text report: warnings, every choice with its reason, and the runs side by side.
pub fn migration_text(m: &Migration, from: &str, to: &str, plant: &str) -> String {
    use std::fmt::Write as _;
    let mut s = format!("Migrating the controller from {from} to {to}.\n");
    for w in &m.migrated.warnings {
        let _ = writeln!(s, "warning: {w}");
    }
    s.push_str("\nChoices:\n");
    for c in &m.migrated.choices {
        let _ = writeln!(s, "  {:<28} {} → {}", c.item, c.before, c.after);
        let _ = writeln!(s, "  {:<28} ({})", "", c.reason);
    }
    let _ = writeln!(
        s,
        "\nThe migrated figure eight on {plant}:\n  {:<18} {:>10} {:>10}",
        "controller", "RMS [m]", "max [m]"
    );
    for r in &m.runs {
        let _ = writeln!(
            s,
            "  {:<18} {:>10.4} {:>10.4}",
            r.label, r.error.rms, r.error.max
        );
    }
    if let [was, migrated, ..] = m.runs.as_slice() {
        let _ = writeln!(
            s,
            "  the migrated controller's RMS error is {:.1}× smaller than as it was",
            was.error.rms / migrated.error.rms
        );
    }
    s
}
