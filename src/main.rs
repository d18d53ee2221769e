//! The `wheelid` command.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand};
use wheelid::config::{
    DiagnoseConfig, ExcitationConfig, SimulateConfig, TrackConfig, read_toml, read_toml_or_default,
    robot_profile,
};
use wheelid::core::Columns;
use wheelid::estimators;
use wheelid::files::{ModelFile, read_bounds};
use wheelid::identify::{IdentifySettings, identify_with};
use wheelid::registry::Registry;
use wheelid::robots::{
    Excitation, RobotProfile, SimSettings, TrajectorySpec, simulate_recording, track, track_robot,
};
use wheelid::{core::Recording, models, report, solvers};

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
}

#[derive(clap::Args)]
struct ExportArgs {
    /// The model file (from `identify --out` or `diagnose --out`).
    model: PathBuf,
    /// Output format.
    #[arg(long, value_parser = ["ros2"], default_value = "ros2")]
    format: String,
    /// Built-in profile for the wheel geometry and top speeds (default: the model's robot,
    /// if it has one).
    #[arg(long)]
    robot: Option<String>,
    /// Write to this file (default: standard output).
    #[arg(short, long)]
    out: Option<PathBuf>,
}

#[derive(clap::Args)]
struct MigrateArgs {
    /// The controller as tuned on the source (TOML, as `--out` writes it); default: the
    /// source's figure eight, default gains, θ̂ = the source's θ, θ1, θ2, θ3, θ5 adapting.
    #[arg(long)]
    controller: Option<PathBuf>,
    /// The source robot's model (TOML from `identify --out` or `diagnose --out`).
    #[arg(long, requires = "to")]
    from: Option<PathBuf>,
    /// The target robot's model.
    #[arg(long, requires = "from")]
    to: Option<PathBuf>,
    /// Built-in profile of the source robot (its period and limits), when the model file
    /// does not name one (simulator profiles: pioneer3dx, pioneer3dx_laut, khepera3).
    #[arg(long)]
    from_robot: Option<String>,
    /// Built-in profile of the target robot.
    #[arg(long)]
    to_robot: Option<String>,
    /// Write the migrated controller (TOML; `wheelid track --controller` runs it).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Tracking time on the target [s].
    #[arg(long, default_value_t = 90.0)]
    duration: f64,
    /// Where the target runs: `simulator` (eq. 2.19 with the target model's θ) or `physics`
    /// (the rigid-body robot of the target's name: pioneer3dx, khepera3, burger; the θ its
    /// constants map to is the third run's).
    #[arg(long, value_parser = ["simulator", "physics"], default_value = "simulator")]
    backend: String,
    /// Seed of the target robot's noise.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Run the check on the robot of this config file's `[robot]` table (as `wheelid run`:
    /// simulator, physics, replay, pioneer or khepera — `port = "loopback"` starts the
    /// protocol server — or a plugin's); overrides --backend.
    #[arg(long)]
    robot: Option<PathBuf>,
    /// Print the report as JSON.
    #[arg(long)]
    json: bool,
    /// Write PNG plots (the paths and the errors of the runs) into this directory.
    #[arg(long)]
    plot: Option<PathBuf>,
}

#[derive(clap::Args)]
struct SimulateArgs {
    /// TOML configuration (robot, [excitation], [simulation] with [simulation.effects.*]);
    /// the flags below override it.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Built-in robot (simulator: pioneer3dx, pioneer3dx_laut, khepera3; physics: pioneer3dx,
    /// khepera3, burger).
    #[arg(long)]
    robot: Option<String>,
    /// Backend: `simulator` (eq. 2.19 with encoders and effects) or `physics` (the independent
    /// rigid-body robot of `wheelid_robots::physics`; its settings from `[physics]` in the
    /// config).
    #[arg(long, value_parser = ["simulator", "physics"], default_value = "simulator")]
    backend: String,
    /// Physics backend: how the host stamps its rows (instant, window_end, window_middle).
    #[arg(long, value_parser = ["instant", "window_end", "window_middle"])]
    timing: Option<String>,
    /// Physics backend: host jitter as a fraction of the period (uniform ±).
    #[arg(long)]
    jitter: Option<f64>,
    /// Excitation preset: thesis (the thesis's signal for the robot), regression (§4.2), or
    /// multisine (random-phase multisines up to 2 Hz, seeded by --seed).
    #[arg(long, value_parser = ["thesis", "regression", "multisine"])]
    excitation: Option<String>,
    /// Duration [s].
    #[arg(long)]
    duration: Option<f64>,
    /// Random seed (noise, jitter, multisine phases).
    #[arg(long)]
    seed: Option<u64>,
    /// Report the exact v, ω and pose instead of the encoder model.
    #[arg(long)]
    exact: bool,
    /// Simulator backend: a model file (from `identify --out` or `diagnose --out`) whose θ and
    /// `[effects.*]` replace the robot's θ and the config's effects.
    #[arg(long)]
    model: Option<PathBuf>,
    /// Output file: CSV, or a ROS 2 bag (`.mcap`: /cmd_vel Twist, /odom Odometry).
    #[arg(long, short)]
    out: PathBuf,
}

#[derive(clap::Args)]
struct RunArgs {
    /// The run's TOML configuration.
    config: PathBuf,
    /// Print the report as JSON.
    #[arg(long)]
    json: bool,
}

#[derive(clap::Args)]
struct TrackArgs {
    /// TOML configuration (robot, model, [track] with [track.adaptation] and
    /// [track.simulation.effects.*]); the flags below override it.
    #[arg(long)]
    config: Option<PathBuf>,
    /// A controller description (TOML from `wheelid migrate --out`): its gains, γ, bounds,
    /// θ̂(0) and trajectory replace the config's `[track]` ones; its robot is the default
    /// `--robot`. The flags below still override it.
    #[arg(long)]
    controller: Option<PathBuf>,
    /// Built-in robot (simulator: pioneer3dx, pioneer3dx_laut, khepera3; physics: pioneer3dx,
    /// khepera3, burger).
    #[arg(long)]
    robot: Option<String>,
    /// Backend: `simulator` (eq. 2.19 with encoders and effects) or `physics` (the rigid-body
    /// robot of `wheelid_robots::physics`, its settings from `[physics]` in the config; the
    /// "true" θ shown is the one its constants map to).
    #[arg(long, value_parser = ["simulator", "physics"], default_value = "simulator")]
    backend: String,
    /// Identified model file (from `wheelid identify --out`) whose θ seeds θ̂(0).
    #[arg(long)]
    model: Option<PathBuf>,
    /// Initial θ̂(0) as six comma-separated values.
    #[arg(long, value_delimiter = ',')]
    theta_hat: Option<Vec<f64>>,
    /// Adaptation gains γ1…γ6, comma-separated (one value: the same for all).
    #[arg(long, value_delimiter = ',')]
    gamma: Option<Vec<f64>>,
    /// Adaptation start time [s].
    #[arg(long)]
    adapt_from: Option<f64>,
    /// Parameters held fixed during adaptation, 1-based, comma-separated (e.g. 4,6).
    #[arg(long, value_delimiter = ',')]
    freeze: Option<Vec<usize>>,
    /// Use the figure eight with the dither (A.2).
    #[arg(long)]
    dither: bool,
    /// Duration [s].
    #[arg(long)]
    duration: Option<f64>,
    /// Random seed of the robot's noise.
    #[arg(long)]
    seed: Option<u64>,
    /// Exact measurements instead of encoders and odometry.
    #[arg(long)]
    exact: bool,
    /// Write trajectory.png, error.png and theta.png into this directory.
    #[arg(long)]
    plot: Option<PathBuf>,
    /// Print the report as JSON.
    #[arg(long)]
    json: bool,
}

fn run_run(a: RunArgs) -> Result<()> {
    let bar = Bar::new(!a.json, "{spinner} {msg} [{bar:30}] {pos}/{len} samples");
    let out = wheelid::run::run(&a.config, &bar);
    bar.0.finish_and_clear();
    let out = out?;
    if a.json {
        out!(
            "{}",
            serde_json::to_string_pretty(&report::to_json(&out.identification, None))?
        );
    } else {
        out_raw!("{}", report::to_text(&out.identification, None));
        for f in &out.files {
            out!("written: {}", f.display());
        }
    }
    Ok(())
}

/// `wheelid simulate --backend physics`: the rigid-body robot under a random multisine (or the
/// config's excitation), written as CSV or a bag.
fn run_simulate_physics(a: &SimulateArgs, cfg: &SimulateConfig) -> Result<()> {
    use wheelid::robots::physics::simulate_physics_recording;
    let profile = physical_profile(a.robot.as_deref())?;
    let mut s = cfg.physics.clone();
    if let Some(d) = a.duration {
        s.duration_s = d;
    }
    if let Some(seed) = a.seed {
        s.seed = seed;
    }
    if a.exact {
        s.encoders = false;
    }
    if let Some(t) = a.timing.as_deref().and_then(wheelid_core::Timing::parse) {
        s.timing = t;
    }
    if let Some(j) = a.jitter {
        s.jitter = j;
    }
    let excitation = match (a.excitation.as_deref(), &cfg.excitation) {
        (None, Some(e)) => e.build()?,
        _ => profile.random_multisine(s.seed)?,
    };
    let rec = simulate_physics_recording(&profile, &excitation, &s)?;
    write_recording(&rec, &a.out)?;
    out!(
        "{} samples ({:.1} s of the physics {} at {} s, timing {}) written to {}",
        rec.len(),
        s.duration_s,
        profile.name,
        profile.period_s,
        s.timing.name(),
        a.out.display()
    );
    Ok(())
}

/// Writes `rec` as CSV, or as a ROS 2 bag for a `.mcap` path.
fn write_recording(rec: &wheelid_core::Recording, out: &std::path::Path) -> Result<()> {
    if out.extension().is_some_and(|e| e == "mcap") {
        wheelid::robots::replay::write_mcap(
            rec,
            out,
            &wheelid::robots::replay::BagTopics::default(),
        )?;
    } else {
        rec.write_csv(out)?;
    }
    Ok(())
}

fn run_simulate(a: SimulateArgs) -> Result<()> {
    let cfg: SimulateConfig = match &a.config {
        Some(p) => read_toml(p)?,
        None => SimulateConfig::default(),
    };
    if a.backend == "physics" {
        return run_simulate_physics(&a, &cfg);
    }
    if let Some(r) = a.robot.as_deref()
        && !RobotProfile::NAMES.contains(&r)
    {
        anyhow::bail!(
            "unknown robot `{r}` for the simulator (known: {})",
            RobotProfile::NAMES.join(", ")
        );
    }
    let mut robot = robot_profile(
        a.robot.as_deref(),
        cfg.robot.as_deref(),
        cfg.profile.as_ref(),
    )?;
    let mut sim = cfg.simulation.clone();
    if let Some(m) = &a.model {
        let file = ModelFile::read(m)?;
        robot.theta.copy_from_slice(&file.theta);
        sim.effects = wheelid::robots::Effects::from_found(&robot.theta, &file.effects)
            .with_context(|| format!("{}: [effects]", m.display()))?;
    }
    if let Some(d) = a.duration {
        sim.duration_s = d;
    }
    if let Some(s) = a.seed {
        sim.seed = s;
    }
    if a.exact {
        sim.measurement_noise = false;
    }
    let excitation = match a.excitation.as_deref() {
        Some("thesis") => ExcitationConfig::for_robot(&robot),
        Some("regression") => ExcitationConfig::ThesisRegression,
        Some(_) => ExcitationConfig::RandomMultisine {
            seed: sim.seed,
            v_offset: 0.25 * robot.v_max,
            v_amp: 0.25 * robot.v_max,
            w_amp: 0.25 * robot.w_max,
            f_max_hz: 2.0,
        },
        None => cfg
            .excitation
            .clone()
            .unwrap_or_else(|| ExcitationConfig::for_robot(&robot)),
    };
    let rec = simulate_recording(&robot, &excitation.build()?, &sim)?;
    // CSV, or a ROS 2 bag: /cmd_vel (geometry_msgs/Twist) and /odom (nav_msgs/Odometry).
    write_recording(&rec, &a.out)?;
    out!(
        "{} samples ({:.1} s of {} at {} s) written to {}",
        rec.len(),
        sim.duration_s,
        robot.name,
        robot.period_s,
        a.out.display()
    );
    let effects = sim.effects.active();
    if !effects.is_empty() {
        out!("effects: {}", effects.join(", "));
    }
    Ok(())
}

fn run_track(a: TrackArgs) -> Result<()> {
    let (mut cfg, base): (TrackConfig, PathBuf) = read_toml_or_default(a.config.as_deref())?;
    if let Some(path) = &a.controller {
        let c = wheelid::migrate::read_controller(path)?;
        cfg.robot = c.robot.or(cfg.robot);
    }
    let physics = a.backend == "physics";
    let robot = if physics {
        physical_profile(a.robot.as_deref().or(cfg.robot.as_deref()))?.model_profile()
    } else {
        if let Some(r) = a.robot.as_deref()
            && !RobotProfile::NAMES.contains(&r)
        {
            bail!(
                "unknown robot `{r}` for the simulator (known: {})",
                RobotProfile::NAMES.join(", ")
            );
        }
        robot_profile(
            a.robot.as_deref(),
            cfg.robot.as_deref(),
            cfg.profile.as_ref(),
        )?
    };
    let s = track_settings(&a, &cfg, &base, &robot)?;
    let (r, effects) = if physics {
        let mut ps = cfg.physics.clone();
        ps.duration_s = s.duration_s;
        if let Some(seed) = a.seed {
            ps.seed = seed;
        }
        if a.exact {
            ps.encoders = false;
        }
        let p = physical_profile(Some(&robot.name))?;
        let mut plant = wheelid::robots::physics::PhysicsRobot::new(&p, &ps)?;
        let traj = s
            .trajectory
            .unwrap_or_else(|| TrajectorySpec::for_profile(&robot, false));
        let r = track_robot(&mut plant, &traj, &s, [robot.v_max, robot.w_max])?;
        (r, ps.effects.active())
    } else {
        (track(&robot, &s)?, s.simulation.effects.active())
    };
    let backend = a.backend.as_str();
    if a.json {
        let j = report::track_json(&robot, backend, &effects, &s, &r);
        out!("{}", serde_json::to_string_pretty(&j)?);
    } else {
        out_raw!("{}", report::track_text(&robot, backend, &effects, &s, &r));
    }
    if let Some(dir) = &a.plot {
        list_plots(&wheelid::plot::write_track_plots(&r, dir)?, a.json);
    }
    Ok(())
}

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

/// The tracking settings: the config's `[track]`, the model file's θ, then the flags.
fn track_settings(
    a: &TrackArgs,
    cfg: &TrackConfig,
    base: &std::path::Path,
    robot: &RobotProfile,
) -> Result<wheelid::robots::TrackSettings> {
    let mut s = cfg.track.clone();
    if let Some(path) = &a.controller {
        let c = wheelid::migrate::read_controller(path)?;
        let d = s.duration_s;
        s = c.track_settings(d);
        s.simulation = cfg.track.simulation.clone();
    }
    let model = a
        .model
        .clone()
        .or_else(|| cfg.model.as_ref().map(|m| base.join(m)));
    if let Some(m) = &model {
        let file = ModelFile::read(m)?;
        s.theta_hat0.copy_from_slice(&file.theta);
    }
    if let Some(th) = &a.theta_hat {
        if th.len() != 6 {
            bail!(
                "--theta-hat takes 6 comma-separated values, got {}",
                th.len()
            );
        }
        s.theta_hat0.copy_from_slice(th);
    }
    if let Some(g) = &a.gamma {
        s.adaptation.gamma = match g.len() {
            1 => [g[0]; 6],
            6 => [g[0], g[1], g[2], g[3], g[4], g[5]],
            n => bail!("--gamma takes 1 or 6 values, got {n}"),
        };
    }
    if let Some(t) = a.adapt_from {
        s.adaptation.start_s = t;
    }
    if let Some(f) = &a.freeze {
        s.adaptation.frozen = f.clone();
    }
    if a.dither {
        s.trajectory = Some(TrajectorySpec::for_profile(robot, true));
    }
    if let Some(d) = a.duration {
        s.duration_s = d;
    }
    if let Some(seed) = a.seed {
        s.simulation.seed = seed;
    }
    if a.exact {
        s.simulation.measurement_noise = false;
    }
    Ok(s)
}

#[derive(clap::Args)]
struct IdentifyArgs {
    /// Recordings: CSV (RECORDING_FORMAT.md) or ROS 2 bags (`.mcap`, a rosbag2 folder; by
    /// extension, else by content); several files are one multi-experiment identification.
    files: Vec<PathBuf>,
    /// Model parameterization: vw-pd, wheel-pd, or a model a `--plugin` registers.
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

/// Lists the plot files written (not in JSON mode, whose stdout is JSON only).
fn list_plots(files: &[PathBuf], json: bool) {
    if !json {
        for f in files {
            out!("plot: {}", f.display());
        }
    }
}

#[derive(clap::Args)]
struct DiagnoseArgs {
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
    /// Wheel track [m] for wheel_asymmetry (default: from the recording's metadata).
    #[arg(long)]
    track: Option<f64>,
    /// Write PNG plots into this directory.
    #[arg(long)]
    plot: Option<PathBuf>,
    /// Write the final (extended) model as TOML: θ and `[effects.*]` with their parameters
    /// (readable by `track --model` and `simulate --model`).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Print the report as JSON.
    #[arg(long)]
    json: bool,
    /// Noise seed of the built-in simulated recording (no files given).
    #[arg(long, default_value_t = 1)]
    seed: u64,
}

fn run_diagnose(a: DiagnoseArgs) -> Result<()> {
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
            .map(|f| wheelid::files::read_recording(f, Columns::Required))
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

/// The built-in diagnosis example: 5 minutes of the simulated Pioneer 3-DX under a random
/// multisine, with a 150 ms dead time and a 1 rad/s yaw-rate limit that the model lacks.
fn builtin_diagnosis_recording(seed: u64) -> Result<(Recording, String)> {
    use wheelid::robots::effects::{Effects, InputDelay, VelocitySaturation};
    let robot = RobotProfile::pioneer3dx();
    let exc = Excitation::random_multisine(
        seed,
        0.25 * robot.v_max,
        0.25 * robot.v_max,
        0.25 * robot.w_max,
        2.0,
    )?;
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

/// The built-in profile for a model file: `flag`, else the file's robot.
fn profile_of(flag: Option<&str>, file: &ModelFile, which: &str) -> Result<RobotProfile> {
    let name = flag.or(file.robot.as_deref()).with_context(|| {
        format!(
            "the {which} model names no robot: give --{which}-robot (one of {})",
            RobotProfile::NAMES.join(", ")
        )
    })?;
    RobotProfile::by_name(name).with_context(|| {
        format!(
            "the {which} robot `{name}` has no built-in profile for its period and limits: give --{which}-robot (one of {})",
            RobotProfile::NAMES.join(", ")
        )
    })
}

/// The check of a migration on the target chosen by the flags: a config's robot, the physics
/// robot, or the simulation of the target model; with the plant's description.
fn migrate_check(
    a: &MigrateArgs,
    ctrl: &wheelid::robots::migrate::ControllerSpec,
    from: &wheelid::robots::migrate::RobotModel,
    to: &wheelid::robots::migrate::RobotModel,
    to_p: &RobotProfile,
) -> Result<(wheelid::migrate::Migration, String)> {
    use wheelid::migrate::migrate_on_simulator;
    if let Some(cfg) = &a.robot {
        let duration = a.duration + 5.0;
        let mut make = || -> wheelid::core::Result<Box<dyn wheelid::core::Robot>> {
            wheelid::run::connect_robot(cfg, duration)
                .map_err(|e| wheelid::core::Error::InvalidSetting(format!("{e:#}")))
        };
        let m = wheelid::migrate::migrate_on_robot(ctrl, from, to, &mut make, None, a.duration)?;
        Ok((
            m,
            format!("the robot of {} ({} s)", cfg.display(), a.duration),
        ))
    } else if a.backend == "physics" {
        let pp = physical_profile(Some(&to.robot))?;
        let ps = wheelid::robots::physics::PhysicsSettings {
            duration_s: a.duration + 5.0,
            seed: a.seed,
            ..Default::default()
        };
        let mut make = || -> wheelid::core::Result<Box<dyn wheelid::core::Robot>> {
            Ok(Box::new(wheelid::robots::physics::PhysicsRobot::new(
                &pp, &ps,
            )?))
        };
        let m = wheelid::migrate::migrate_on_robot(
            ctrl,
            from,
            to,
            &mut make,
            Some(pp.theta()),
            a.duration,
        )?;
        Ok((m, format!("the rigid-body {} ({} s)", to.robot, a.duration)))
    } else {
        let mut check = wheelid::migrate::CheckSettings {
            duration_s: a.duration,
            ..Default::default()
        };
        check.simulation.seed = a.seed;
        let m = migrate_on_simulator(ctrl, from, to, to_p, &check)?;
        let plant = format!(
            "{} (eq.-2.19 simulation with the target model's θ, {} s)",
            to.robot, a.duration
        );
        Ok((m, plant))
    }
}

fn run_migrate(a: MigrateArgs) -> Result<()> {
    use wheelid::migrate::{migration_text, robot_model};
    use wheelid::robots::migrate::{ControllerSpec, RobotModel};
    let (from, to, from_p, mut to_p) = match (&a.from, &a.to) {
        (Some(f), Some(t)) => {
            let (ff, tf) = (ModelFile::read(f)?, ModelFile::read(t)?);
            let fp = profile_of(a.from_robot.as_deref(), &ff, "from")?;
            let tp = profile_of(a.to_robot.as_deref(), &tf, "to")?;
            let fm = robot_model(&ff, &fp).with_context(|| f.display().to_string())?;
            let tm = robot_model(&tf, &tp).with_context(|| t.display().to_string())?;
            (fm, tm, fp, tp)
        }
        _ => {
            let (fp, tp) = (RobotProfile::khepera3(), RobotProfile::pioneer3dx());
            if !a.json {
                out!(
                    "No model files: the built-in Khepera III's controller moved to the built-in \
                     Pioneer 3-DX (their thesis θ taken as identified models).\n"
                );
            }
            (
                RobotModel::from_profile(&fp),
                RobotModel::from_profile(&tp),
                fp,
                tp,
            )
        }
    };
    let ctrl = match &a.controller {
        Some(p) => wheelid::migrate::read_controller(p)?,
        None => ControllerSpec::tuned_on(&from, &from_p)?,
    };
    // The target's simulation runs the target model's θ.
    if let Some(th) = to.theta {
        to_p.theta = th;
    }
    let (m, plant) = migrate_check(&a, &ctrl, &from, &to, &to_p)?;
    if let Some(out) = &a.out {
        wheelid::migrate::write_controller(out, &m.migrated.controller)?;
    }
    if a.json {
        out!("{}", serde_json::to_string_pretty(&m)?);
    } else {
        out_raw!("{}", migration_text(&m, &from.robot, &to.robot, &plant));
        if let Some(out) = &a.out {
            out!("migrated controller written to {}", out.display());
        }
    }
    if let Some(dir) = &a.plot {
        let runs: Vec<(&str, &wheelid::robots::TrackResult)> = m
            .runs
            .iter()
            .map(|r| (r.label.as_str(), &r.result))
            .collect();
        list_plots(&wheelid::plot::write_migration_plots(&runs, dir)?, a.json);
    }
    Ok(())
}

fn run_export(a: ExportArgs) -> Result<()> {
    let model = ModelFile::read(&a.model)?;
    let name = a.robot.as_deref().or(model.robot.as_deref());
    let profile = match name {
        Some(n) => Some(RobotProfile::by_name(n).with_context(|| {
            format!(
                "robot `{n}` has no built-in profile (known: {}); give --robot or leave the geometry out by removing `robot` from {}",
                RobotProfile::NAMES.join(", "),
                a.model.display()
            )
        })?),
        None => None,
    };
    let text = wheelid::export::ros2_yaml(&model, profile.as_ref(), &a.model.display().to_string());
    match &a.out {
        Some(p) => wheelid::core::recording::write_atomic(p, text.as_bytes())
            .with_context(|| p.display().to_string())?,
        None => out_raw!("{text}"),
    }
    Ok(())
}

fn main() -> Result<()> {
    match Cli::parse().command {
        Command::Diagnose(a) => run_diagnose(a),
        Command::Identify(a) => run_identify(a),
        Command::Run(a) => run_run(a),
        Command::Simulate(a) => run_simulate(a),
        Command::Track(a) => run_track(a),
        Command::Migrate(a) => run_migrate(a),
        Command::Export(a) => run_export(a),
    }
}
