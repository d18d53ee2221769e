//! The migration pipeline (issue 16): model files → [`RobotModel`]s, [`migrate`], and the
//! closed loop on the target with the controller as it was, as migrated, and (where the
//! target's true θ is known, as in simulation) set up with that θ.
//!
//! The three runs track the same path — the migrated trajectory — so their errors compare
//! the controllers, not the paths. "As it was" keeps the source's gains, γ, bounds and θ̂(0).

use serde::Serialize;
use wheelid_core::{Error, Result};
use wheelid_robots::migrate::{ControllerSpec, Migrated, RobotModel, migrate};
use wheelid_robots::tracking::ErrorSummary;
use wheelid_robots::{RobotProfile, TrackResult, track};

use crate::files::ModelFile;

/// The [`RobotModel`] of a model file on `profile`'s robot: θ and standard errors from the
/// file; period and limits from the profile, tightened by what a diagnosis found
/// (`velocity_saturation` `v_max`/`w_max`, `acceleration_limit` `v_accel_max`/`w_accel_max`,
/// `input_delay` `delay_s`).
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
    m.delay_s = get("input_delay", "delay_s");
    Ok(m)
}

/// One tracking run's outcome.
#[derive(Debug, Clone, Serialize)]
pub struct Run {
    /// What ran (`as it was`, `migrated`, `target's true θ`).
    pub label: String,
    /// Distance error summary [m] over the whole run.
    pub error: ErrorSummary,
    /// θ̂ at the end.
    pub theta_hat_end: [f64; 6],
}

impl Run {
    fn of(label: &str, r: &TrackResult) -> Self {
        Self {
            label: label.into(),
            error: r.summary,
            theta_hat_end: r.final_theta_hat(),
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

/// Migrates `ctrl` from `from` to `to` and tracks the migrated path for `duration_s` on the
/// eq.-2.19 simulation of `target` (its θ is the plant; `settings` seed and noise as
/// [`wheelid_robots::TrackSettings::default`]) with the controller as it was and as migrated,
/// and with θ̂(0) and bounds from `target.theta` when `with_truth`.
///
/// # Errors
/// As [`migrate`] and [`track`] (a diverging run is an error naming the time).
pub fn migrate_on_simulator(
    ctrl: &ControllerSpec,
    from: &RobotModel,
    to: &RobotModel,
    target: &RobotProfile,
    duration_s: f64,
    with_truth: bool,
) -> Result<Migration> {
    let migrated = migrate(ctrl, from, to)?;
    let path = migrated.controller.trajectory;
    let mut as_was = ctrl.track_settings(duration_s);
    as_was.trajectory = Some(path);
    let mut runs = vec![
        Run::of("as it was", &track(target, &as_was)?),
        Run::of(
            "migrated",
            &track(target, &migrated.controller.track_settings(duration_s))?,
        ),
    ];
    if with_truth {
        let mut truth = RobotModel::from_profile(target);
        truth.robot = to.robot.clone();
        let reference = migrate(ctrl, from, &truth)?;
        runs.push(Run::of(
            "target's true θ",
            &track(target, &reference.controller.track_settings(duration_s))?,
        ));
    }
    Ok(Migration { migrated, runs })
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
