//! `wheelid diagnose`: where a model and recordings disagree, and the physics left out.

use std::path::{Path, PathBuf};

use anyhow::Result;
use wheelid::config::{DiagnoseConfig, read_toml_or_default};
use wheelid::core::Columns;
use wheelid::files::ModelFile;
use wheelid::registry::Registry;
use wheelid::robots::{RobotProfile, SimSettings, simulate_recording};
use wheelid::{core::Recording, models, report};

use crate::{Bar, emit, list_plots};

#[derive(clap::Args)]
pub(crate) struct DiagnoseArgs {
    /// Recordings: CSV or ROS 2 bags (`.mcap`, a rosbag2 folder); several are diagnosed
    /// together.
    files: Vec<PathBuf>,
    /// TOML configuration (files, model, candidates, blocks, alpha, …; see
    /// `wheelid::config::DiagnoseConfig`); the flags below override it.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Model parameterization of the least-squares start: vw-pd, wheel-pd, or a model a
    /// `--plugin` registers.
    #[arg(long)]
    model: Option<String>,
    /// Plugin library to load first (repeatable), as `identify --plugin`.
    #[arg(long)]
    plugin: Vec<PathBuf>,
    /// Candidates to search, comma-separated (default: every registered one).
    #[arg(long, value_delimiter = ',', value_parser = clap::builder::PossibleValuesParser::new(models::Candidate::names()))]
    candidates: Option<Vec<String>>,
    /// Most effects added.
    #[arg(long)]
    max_effects: Option<usize>,
    /// Family-wise level of the residual tests (Holm).
    #[arg(long)]
    alpha: Option<f64>,
    /// Wheel track \[m\] for wheel_asymmetry (default: from the recording's metadata).
    #[arg(long)]
    track: Option<f64>,
    /// Search a recording longer than this many samples on an excerpt of windows spread over
    /// it, then refit the model found on all of it (default 3600; a number at least as long
    /// as the recording searches it whole: slower, and on 10-minute recordings a little more
    /// accurate — see the README).
    #[arg(long)]
    search_samples: Option<usize>,
    /// Write PNG plots into this directory.
    #[arg(long)]
    plot: Option<PathBuf>,
    /// Write the final (extended) model as TOML: θ and `[effects.*]` with their parameters
    /// (readable by `track --model`, `simulate --model` and `identify --model`, which refits it).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Print the report as JSON.
    #[arg(long)]
    json: bool,
    /// Noise seed of the built-in simulated recording (no files given).
    #[arg(long, default_value_t = 1)]
    seed: u64,
}

pub(crate) fn run_diagnose(a: DiagnoseArgs) -> Result<()> {
    let (cfg, base): (DiagnoseConfig, PathBuf) = read_toml_or_default(a.config.as_deref())?;
    let mut settings = cfg.settings();
    let name = a.model.clone().or(cfg.model.clone());
    let model =
        Registry::load(Path::new(""), &a.plugin)?.model(name.as_deref().unwrap_or("vw-pd"))?;
    if let Some(c) = &a.candidates {
        settings.candidates = c
            .iter()
            .filter_map(|n| models::Candidate::by_name(n))
            .collect();
    }
    settings.max_effects = a.max_effects.unwrap_or(settings.max_effects);
    settings.alpha = a.alpha.unwrap_or(settings.alpha);
    settings.track_m = a.track.or(settings.track_m);
    settings.search_samples = a.search_samples.unwrap_or(settings.search_samples);
    let files: Vec<PathBuf> = if a.files.is_empty() {
        cfg.files.iter().map(|f| base.join(f)).collect()
    } else {
        a.files.clone()
    };
    let recordings = if files.is_empty() {
        let (rec, what) = builtin_diagnosis_recording(a.seed)?;
        if !a.json {
            out!("No recording given: diagnosing {what}.\n");
        }
        vec![rec]
    } else {
        files
            .iter()
            // The heading too: where the metadata names a pose independent of the encoders,
            // it tells a larger tyre from a weak amplifier (`tyre_asymmetry`).
            .map(|f| wheelid::files::read_recording(f, Columns::All))
            .collect::<Result<Vec<_>, _>>()?
    };
    let bar = Bar::new(!a.json, "{spinner} diagnose [{bar:30}] {pos}/{len} {msg}");
    let d = wheelid::diagnose::diagnose_observed(&recordings, model.as_ref(), &settings, &bar)?;
    bar.0.finish_and_clear();
    if a.json {
        out!("{}", serde_json::to_string_pretty(&d)?);
    } else {
        out_raw!("{}", report::diagnosis_text(&d));
    }
    let plot = a.plot.clone().or(cfg.plot.map(|p| base.join(p)));
    if let Some(dir) = &plot {
        list_plots(&wheelid::plot::write_diagnosis_plots(&d, dir)?, a.json);
    }
    if let Some(out) = &a.out {
        let name = name.as_deref().unwrap_or("vw-pd");
        let fallback = files.is_empty().then_some("pioneer3dx");
        ModelFile::from_diagnosis(&d, name)
            .on_robot_of(&recordings, fallback)
            .write(out)?;
        if !a.json {
            out!("written: {}", out.display());
        }
    }
    Ok(())
}

/// The built-in diagnosis example: 5 minutes of the simulated Pioneer 3-DX under a random
/// multisine, with a 150 ms dead time and a 1 rad/s yaw-rate limit that the model lacks.
fn builtin_diagnosis_recording(seed: u64) -> Result<(Recording, String)> {
    use wheelid::robots::effects::{Effects, InputDelay, VelocitySaturation};
    let robot = RobotProfile::pioneer3dx();
    let exc = robot.multisine(seed)?;
    let settings = SimSettings {
        duration_s: 300.0,
        seed,
        effects: Effects {
            input_delay: Some(InputDelay { delay_s: 0.15 }),
            velocity_saturation: Some(VelocitySaturation {
                v_max: robot.v_max,
                w_max: 1.0,
            }),
            ..Effects::default()
        },
        ..SimSettings::default()
    };
    let rec = simulate_recording(&robot, &exc, &settings)?;
    Ok((
        rec,
        format!(
            "300 s of the built-in simulated Pioneer 3-DX (10 Hz, random multisine, encoders, \
             seed {seed}) with a concealed 150 ms dead time and a 1 rad/s yaw-rate limit"
        ),
    ))
}
