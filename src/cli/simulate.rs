//! `wheelid simulate`: a recording from the simulator or the physics backend.

use std::path::PathBuf;

use anyhow::{Context, Result};
use wheelid::config::{ExcitationConfig, SimulateConfig, read_toml, robot_profile};
use wheelid::files::ModelFile;
use wheelid::robots::{RobotProfile, simulate_model_recording, simulate_recording};

use crate::{emit, physical_profile};

#[derive(clap::Args)]
pub(crate) struct SimulateArgs {
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
    /// Duration \[s\].
    #[arg(long)]
    duration: Option<f64>,
    /// Random seed (noise, jitter, multisine phases).
    #[arg(long)]
    seed: Option<u64>,
    /// Report the exact v, ω and pose instead of the encoder model.
    #[arg(long)]
    exact: bool,
    /// Simulator backend: a model file (from `identify --out` or `diagnose --out`) simulated
    /// by its own equations — its θ and every `[effects.*]` a diagnosis found, actuator ones
    /// included — in place of the robot's θ and the config's effects (the robot's period,
    /// wheels and encoders stay).
    #[arg(long)]
    model: Option<PathBuf>,
    /// Output file: CSV, or a ROS 2 bag (`.mcap`: /cmd_vel Twist, /odom Odometry).
    #[arg(long, short)]
    out: PathBuf,
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

/// A saved model (θ and the effects a diagnosis found), to be simulated by its own equations:
/// the extended model and its parameters; θ goes into `robot`, and the model's physics
/// replaces the configuration's effects (extra measurement noise stays).
fn saved_model(
    m: &std::path::Path,
    robot: &mut RobotProfile,
    sim: &mut wheelid::robots::SimSettings,
) -> Result<(wheelid::models::Extended, Vec<f64>)> {
    let file = ModelFile::read(m)?;
    let theta = file.theta6(m)?;
    robot.theta = theta;
    let saved = wheelid::models::Extended::from_found(&theta, &file.effects, robot.track)
        .with_context(|| format!("{}: [effects]", m.display()))?;
    sim.effects = wheelid::robots::Effects {
        measurement_noise: sim.effects.measurement_noise,
        ..Default::default()
    };
    Ok(saved)
}

pub(crate) fn run_simulate(a: SimulateArgs) -> Result<()> {
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
    let saved = match &a.model {
        Some(m) => Some(saved_model(m, &mut robot, &mut sim)?),
        None => None,
    };
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
        Some("thesis") => ExcitationConfig::for_robot(&robot).build()?,
        Some("regression") => ExcitationConfig::ThesisRegression.build()?,
        Some(_) => robot.multisine(sim.seed)?,
        None => cfg
            .excitation
            .clone()
            .unwrap_or_else(|| ExcitationConfig::for_robot(&robot))
            .build()?,
    };
    let rec = match &saved {
        Some((model, params)) => {
            simulate_model_recording(&robot, model, params, &excitation, &sim)?
        }
        None => simulate_recording(&robot, &excitation, &sim)?,
    };
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
    let effects: Vec<&str> = match &saved {
        Some((model, _)) => model.candidates().iter().map(|c| c.name()).collect(),
        None => sim.effects.active(),
    };
    if !effects.is_empty() {
        out!("effects: {}", effects.join(", "));
    }
    Ok(())
}
