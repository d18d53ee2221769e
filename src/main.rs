//! The `wheelid` command.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};

/// `println!` that survives a closed pipe (`wheelid identify | head`): once standard output is
/// gone, further output is dropped and the command still finishes its work (the files it
/// writes are written).
macro_rules! out {
    ($($t:tt)*) => {
        emit(format_args!($($t)*), true)
    };
}

/// As [`out!`], without the line end (`print!`).
macro_rules! out_raw {
    ($($t:tt)*) => {
        emit(format_args!($($t)*), false)
    };
}

/// Writes one line to standard output unless it was closed; any other write error is said
/// once on standard error.
fn emit(args: std::fmt::Arguments<'_>, line: bool) {
    use std::io::Write;
    use std::sync::atomic::{AtomicBool, Ordering};
    static CLOSED: AtomicBool = AtomicBool::new(false);
    if CLOSED.load(Ordering::Relaxed) {
        return;
    }
    let mut o = std::io::stdout().lock();
    if let Err(e) = o
        .write_fmt(args)
        .and_then(|()| if line { o.write_all(b"\n") } else { Ok(()) })
    {
        CLOSED.store(true, Ordering::Relaxed);
        if e.kind() != std::io::ErrorKind::BrokenPipe {
            eprintln!("wheelid: standard output: {e}; the rest of the report is dropped");
        }
    }
}

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
    /// Identify θ1…θ6 of eq. 2.19 from recordings (CSV or ROS 2 bags).
    ///
    /// Least squares on the filtered regression (thesis eqs. 4.2–4.7), then the chosen
    /// estimator (output error by default). With no file, identifies 150 s of the built-in
    /// simulated Pioneer 3-DX and prints the true θ beside the estimates.
    Identify(IdentifyArgs),
    /// Simulate a robot under an excitation and write the recording (CSV or MCAP).
    ///
    /// The simulator integrates eq. 2.19 with encoders and optional effects; the physics
    /// backend is an independent rigid-body robot.
    Simulate(SimulateArgs),
    /// Diagnose where a model and recordings disagree, and name the physics left out.
    ///
    /// Tests the residuals, locates the misfit, names the physics left out from a library of
    /// candidates, models it and shows the validation fit improve. With no file, diagnoses a
    /// built-in simulated Pioneer 3-DX with a concealed dead time and yaw-rate limit.
    Diagnose(DiagnoseArgs),
    /// Run a whole identification job from a TOML file: drive a robot, identify, write.
    ///
    /// Drives a robot backend (simulator, physics, replay of a CSV or ROS 2 MCAP bag, Pioneer
    /// over ARCOS, Khepera III over serial/TCP, or a plugin's) with an excitation, identifies
    /// the chosen model with the chosen solver, and writes the recording, the model (TOML) and
    /// the report. See `examples/configs/run_*.toml`.
    Run(RunArgs),
    /// Track a figure eight with the adaptive inverse-dynamics controller (thesis ch. 3–4).
    ///
    /// Runs on a simulated robot (eq. 2.19, or the rigid-body robot with `--backend physics`)
    /// and reports the distance error.
    Track(TrackArgs),
    /// Move a tracking controller from one robot to another and check it on the target.
    ///
    /// θ̂ and the projection bounds come from the target's model; gains, γ and the figure
    /// eight are scaled to the target, every choice with its reason (thesis ch. 3–4). Then the
    /// migrated figure eight is tracked on the target with the controller as it was and as
    /// migrated. With no model files: the built-in Khepera III's controller moved to the
    /// built-in Pioneer 3-DX.
    Migrate(MigrateArgs),
    /// Export a model file for another stack (ROS 2 controller and Nav2 parameters).
    ///
    /// `--format ros2` writes the YAML parameters of ROS 2's diff_drive_controller and Nav2's
    /// MPPI controller (limits found by diagnosis, wheel geometry of the built-in profile) and
    /// the response lag.
    Export(ExportArgs),
    /// Design the excitation that identifies θ to an accuracy in the shortest drive.
    ///
    /// Multisine amplitudes chosen on the Fisher information of the output-error problem at a
    /// prior θ, within the robot's top speeds and a floor space; prints the predicted standard
    /// errors and the drive's length, and writes the plan for `wheelid run`.
    Design(DesignArgs),
}

mod cli;

use cli::{
    design::DesignArgs, diagnose::DiagnoseArgs, export::ExportArgs, identify::IdentifyArgs,
    migrate::MigrateArgs, run::RunArgs, simulate::SimulateArgs, track::TrackArgs,
};

/// The built-in physical profile `name` (default `khepera3`).
fn physical_profile(name: Option<&str>) -> Result<wheelid::robots::physics::PhysicalProfile> {
    use wheelid::robots::physics::PhysicalProfile;
    let name = name.unwrap_or("khepera3");
    PhysicalProfile::by_name(name).with_context(|| {
        format!(
            "unknown physical profile `{name}` (known: {})",
            PhysicalProfile::NAMES.join(", ")
        )
    })
}

/// Lists the plot files written (not in JSON mode, whose stdout is JSON only).
fn list_plots(files: &[PathBuf], json: bool) {
    if !json {
        for f in files {
            out!("plot: {}", f.display());
        }
    }
}

/// A library call's progress ([`wheelid::observer::Observer`]) as a bar on standard error in
/// the indicatif `template` (hidden when it is not a terminal or the output is JSON).
struct Bar(indicatif::ProgressBar);

impl Bar {
    fn new(show: bool, template: &str) -> Self {
        use std::io::IsTerminal;
        let bar = if show && std::io::stderr().is_terminal() {
            indicatif::ProgressBar::no_length()
        } else {
            indicatif::ProgressBar::hidden()
        };
        bar.set_style(
            indicatif::ProgressStyle::with_template(template)
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        Self(bar)
    }
}

impl wheelid::observer::Observer for Bar {
    fn progress(&self, message: &str, done: u64, total: u64) {
        if total > 0 {
            self.0.set_length(total);
        }
        self.0.set_position(done);
        self.0.set_message(message.to_owned());
    }
}

fn main() -> Result<()> {
    match Cli::parse().command {
        Command::Diagnose(a) => cli::diagnose::run_diagnose(a),
        Command::Identify(a) => cli::identify::run_identify(a),
        Command::Run(a) => cli::run::run_run(a),
        Command::Simulate(a) => cli::simulate::run_simulate(a),
        Command::Track(a) => cli::track::run_track(a),
        Command::Migrate(a) => cli::migrate::run_migrate(a),
        Command::Export(a) => cli::export::run_export(a),
        Command::Design(a) => cli::design::run_design(a),
    }
}
