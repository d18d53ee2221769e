//! The `wheelid` command.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand};
use wheelid::files::{ModelFile, read_bounds};
use wheelid::identify::{IdentifySettings, identify};
use wheelid::robots::{Excitation, RobotProfile, SimSettings, simulate_recording};
use wheelid::{core::Recording, models, report, solvers};

#[derive(Parser)]
#[command(
    name = "wheelid",
    version,
    about = "Identify wheeled-robot dynamics (Laut 2011) from recordings"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Identify θ1…θ6 from recordings (CSV, see RECORDING_FORMAT.md). With no file, identifies a
    /// recording of the built-in simulated Pioneer 3-DX and prints the true values beside.
    Identify(IdentifyArgs),
}

#[derive(clap::Args)]
struct IdentifyArgs {
    /// Recording CSV files; several files are one multi-experiment identification.
    files: Vec<PathBuf>,
    /// Model parameterization.
    #[arg(long, default_value = "vw-pd", value_parser = models::MODEL_NAMES)]
    model: String,
    /// Least-squares solver.
    #[arg(long, default_value = "ols", value_parser = solvers::SOLVER_NAMES)]
    solver: String,
    /// Bounds on θ (TOML: theta_lower/theta_upper, or [physical.lower]/[physical.upper]); used by `--solver box`.
    #[arg(long)]
    bounds: Option<PathBuf>,
    /// Low-pass cut-off [Hz] (default: chosen from the commands' bandwidth, see the report).
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

fn run_identify(a: IdentifyArgs) -> Result<()> {
    let model = models::by_name(&a.model).context("unknown model")?;
    let solver = solvers::by_name(&a.solver).context("unknown solver")?;
    let (recordings, truth) = if a.files.is_empty() {
        let robot = RobotProfile::pioneer3dx();
        let settings = SimSettings {
            seed: a.seed,
            ..SimSettings::default()
        };
        let rec = simulate_recording(&robot, &Excitation::thesis_pioneer(), &settings)?;
        if !a.json {
            println!(
                "No recording given: identifying {:.0} s of the built-in simulated Pioneer 3-DX \
                 (10 Hz, thesis §4.4.2 excitation, encoder quantization and noise, seed {}).\n",
                settings.duration_s, a.seed
            );
        }
        (vec![rec], Some(robot.theta.to_vec()))
    } else {
        let recs = a
            .files
            .iter()
            .map(Recording::read_csv)
            .collect::<Result<Vec<_>, _>>()?;
        (recs, None)
    };
    let mut settings = IdentifySettings::default();
    settings.condition.cutoff_hz = a.cutoff;
    settings.condition.order = a.order;
    if let Some(path) = &a.bounds {
        if a.solver != "box" {
            bail!("--bounds needs --solver box (ordinary least squares is unbounded)");
        }
        settings.bounds = Some(read_bounds(path, &a.model)?);
    }
    let id = identify(&recordings, model.as_ref(), solver.as_ref(), &settings)?;
    if a.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&report::to_json(&id, truth.as_deref()))?
        );
    } else {
        print!("{}", report::to_text(&id, truth.as_deref()));
    }
    if let Some(out) = &a.out {
        ModelFile::from_identification(&id).write(out)?;
        if !a.json {
            println!("identified model written to {}", out.display());
        }
    }
    if let Some(dir) = &a.plot {
        let files = wheelid::plot::write_plots(&id, dir)?;
        if !a.json {
            for f in files {
                println!("plot: {}", f.display());
            }
        }
    }
    Ok(())
}

fn main() -> Result<()> {
    match Cli::parse().command {
        Command::Identify(a) => run_identify(a),
    }
}
