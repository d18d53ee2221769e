//! `wheelid track`: the figure eight with the adaptive inverse-dynamics controller.

use std::path::PathBuf;

use anyhow::{Result, bail};
use wheelid::config::{TrackConfig, read_toml_or_default, robot_profile};
use wheelid::files::ModelFile;
use wheelid::report;
use wheelid::robots::{RobotProfile, TrajectorySpec, track, track_robot};

use crate::{emit, list_plots, physical_profile};

#[derive(clap::Args)]
pub(crate) struct TrackArgs {
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
    /// Adaptation start time \[s\].
    #[arg(long)]
    adapt_from: Option<f64>,
    /// Parameters held fixed during adaptation, 1-based, comma-separated (e.g. 4,6).
    #[arg(long, value_delimiter = ',')]
    freeze: Option<Vec<usize>>,
    /// Use the figure eight with the dither (A.2).
    #[arg(long)]
    dither: bool,
    /// Duration \[s\].
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

pub(crate) fn run_track(a: TrackArgs) -> Result<()> {
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
