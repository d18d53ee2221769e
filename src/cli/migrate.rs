//! `wheelid migrate`: a tracking controller moved between robots and checked on the target.

use std::path::PathBuf;

use anyhow::{Context, Result};
use wheelid::files::ModelFile;
use wheelid::robots::RobotProfile;

use crate::{emit, list_plots, physical_profile};

#[derive(clap::Args)]
pub(crate) struct MigrateArgs {
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
    /// Tracking time on the target \[s\].
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

pub(crate) fn run_migrate(a: MigrateArgs) -> Result<()> {
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
