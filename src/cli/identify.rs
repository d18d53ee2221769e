//! `wheelid identify`: θ of eq. 2.19 from recordings, or from the built-in simulated Pioneer 3-DX.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use wheelid::core::Columns;
use wheelid::estimators;
use wheelid::files::{ModelFile, read_bounds};
use wheelid::identify::{IdentifySettings, identify_with};
use wheelid::registry::Registry;
use wheelid::robots::{Excitation, RobotProfile, SimSettings, simulate_recording};
use wheelid::{report, solvers};

use crate::{emit, list_plots};

#[derive(clap::Args)]
pub(crate) struct IdentifyArgs {
    /// Recordings: CSV (RECORDING_FORMAT.md) or ROS 2 bags (`.mcap`, a rosbag2 folder; by
    /// extension, else by content); several files are one multi-experiment identification.
    files: Vec<PathBuf>,
    /// Model parameterization: vw-pd, wheel-pd, or a model a `--plugin` registers; or a saved
    /// model (`….toml`, from `diagnose --out` or `identify --out`), whose θ and effects are
    /// refitted on the recordings from their saved values.
    #[arg(long, default_value = "vw-pd")]
    model: String,
    /// Plugin library to load first (repeatable): a path, or a bare name looked up beside
    /// this executable (as in a run config's `plugins`); its models become `--model` choices
    /// and its estimators `--estimator` choices.
    #[arg(long)]
    plugin: Vec<PathBuf>,
    /// Estimator: ls (the thesis's filtered regression), iv (instrumental variables), oe
    /// (output error, the default: unbiased, no cut-off in the answer), or a plugin's.
    #[arg(long, default_value = "oe")]
    estimator: String,
    /// Run every estimator and show their θ side by side.
    #[arg(long)]
    compare: bool,
    /// Least-squares solver (the regression every estimator starts from).
    #[arg(long, default_value = "ols", value_parser = solvers::SOLVER_NAMES)]
    solver: String,
    /// Bounds on θ (TOML: theta_lower/theta_upper, or [physical.lower]/[physical.upper]); kept by
    /// `--estimator oe`, projected on by iv, and by `--solver box` for ls.
    #[arg(long)]
    bounds: Option<PathBuf>,
    /// Low-pass cut-off \[Hz\] (default: chosen from the commands' bandwidth, see the report).
    #[arg(long)]
    cutoff: Option<f64>,
    /// Butterworth order of one filter pass.
    #[arg(long, default_value_t = 4)]
    order: usize,
    /// Write the identified model as TOML.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Write PNG plots into this directory.
    #[arg(long)]
    plot: Option<PathBuf>,
    /// Print the report as JSON.
    #[arg(long)]
    json: bool,
    /// Noise seed of the built-in simulated recording (no files given).
    #[arg(long, default_value_t = 1)]
    seed: u64,
}

pub(crate) fn run_identify(a: IdentifyArgs) -> Result<()> {
    if Path::new(&a.model).extension().is_some_and(|e| e == "toml") {
        return run_refit_saved(&a);
    }
    let registry = Registry::load(Path::new(""), &a.plugin)?;
    let model = registry.model(&a.model)?;
    registry.check_estimator(&a.estimator)?;
    let solver = solvers::by_name(&a.solver).context("unknown solver")?;
    let (recordings, truth) = if a.files.is_empty() {
        let robot = RobotProfile::pioneer3dx();
        let settings = SimSettings {
            seed: a.seed,
            ..SimSettings::default()
        };
        let rec = simulate_recording(&robot, &Excitation::thesis_pioneer(), &settings)?;
        if !a.json {
            out!(
                "No recording given: identifying {:.0} s of the built-in simulated Pioneer 3-DX \
                 (10 Hz, thesis §4.4.2 excitation, encoder quantization and noise, seed {}).\n",
                settings.duration_s,
                a.seed
            );
        }
        (vec![rec], Some(robot.theta.to_vec()))
    } else {
        let recs = a
            .files
            .iter()
            .map(|f| wheelid::files::read_recording(f, Columns::Required))
            .collect::<Result<Vec<_>, _>>()?;
        (recs, None)
    };
    let mut settings = IdentifySettings::default();
    settings.condition.cutoff_hz = a.cutoff;
    settings.condition.order = a.order;
    settings.estimator.clone_from(&a.estimator);
    settings.compare = a.compare;
    if let Some(path) = &a.bounds {
        if a.solver != "box" && a.estimator == estimators::LEAST_SQUARES {
            bail!(
                "--bounds with --estimator ls needs --solver box (ordinary least squares is unbounded)"
            );
        }
        settings.bounds = Some(read_bounds(path, &a.model)?);
    }
    let id = identify_with(
        &recordings,
        model.as_ref(),
        solver.as_ref(),
        &registry.estimators()?,
        &settings,
    )?;
    if a.json {
        out!(
            "{}",
            serde_json::to_string_pretty(&report::to_json(&id, truth.as_deref()))?
        );
    } else {
        out_raw!("{}", report::to_text(&id, truth.as_deref()));
    }
    if let Some(out) = &a.out {
        let fallback = a.files.is_empty().then_some("pioneer3dx");
        ModelFile::from_identification(&id)
            .on_robot_of(&recordings, fallback)
            .write(out)?;
        if !a.json {
            out!("identified model written to {}", out.display());
        }
    }
    if let Some(dir) = &a.plot {
        list_plots(&wheelid::plot::write_plots(&id, dir)?, a.json);
    }
    Ok(())
}

/// `identify --model model.toml FILES`: the saved model's θ and effects refitted on the
/// recordings (`wheelid::diagnose::refit_saved`), the nominal model beside it.
fn run_refit_saved(a: &IdentifyArgs) -> Result<()> {
    let path = Path::new(&a.model);
    if a.files.is_empty() {
        bail!(
            "--model {}: a saved model is refitted on recordings; give them (FILES)",
            path.display()
        );
    }
    let refused = [
        (a.compare, "--compare"),
        (a.estimator != "oe", "--estimator"),
        (a.solver != "ols", "--solver"),
        (a.bounds.is_some(), "--bounds"),
        (a.cutoff.is_some(), "--cutoff"),
        (a.plot.is_some(), "--plot"),
    ];
    if let Some((_, flag)) = refused.iter().find(|(given, _)| *given) {
        bail!(
            "{flag} does not apply to a saved model (--model {}): it is refitted by output \
             error, each effect within its own bounds",
            path.display()
        );
    }
    let file = ModelFile::read(path)?;
    let theta = file.theta6(path)?;
    let model = Registry::load(Path::new(""), &a.plugin)?.model(&file.model)?;
    let recordings = a
        .files
        .iter()
        .map(|f| wheelid::files::read_recording(f, Columns::Required))
        .collect::<Result<Vec<_>, _>>()?;
    let mut settings = wheelid::diagnose::DiagnoseSettings::default();
    // The recordings' track, else the saved robot's (a per-wheel effect needs one).
    if !(recordings.iter()).any(|r| r.meta("track").is_some() || r.meta("kinematics").is_some()) {
        settings.track_m = (file.robot.as_deref())
            .and_then(RobotProfile::by_name)
            .map(|p| p.track);
    }
    let r = wheelid::diagnose::refit_saved(
        &recordings,
        model.as_ref(),
        &theta,
        &file.effects,
        &settings,
    )
    .with_context(|| format!("{}", path.display()))?;
    if a.json {
        out!("{}", serde_json::to_string_pretty(&r)?);
    } else {
        out_raw!("{}", report::saved_refit_text(&r));
    }
    if let Some(out) = &a.out {
        ModelFile::from_saved_refit(&r, &file.model)
            .on_robot_of(&recordings, file.robot.as_deref())
            .write(out)?;
        if !a.json {
            out!("refitted model written to {}", out.display());
        }
    }
    Ok(())
}
