//! `wheelid design`: the excitation that identifies θ to an accuracy in the shortest drive.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use wheelid::design::{Criterion, DesignSettings, design};
use wheelid::files::ModelFile;
use wheelid::models;

use crate::emit;

#[derive(clap::Args)]
pub(crate) struct DesignArgs {
    /// Built-in robot profile: its θ as the prior, its period and top speeds as the limits.
    #[arg(long, default_value = "pioneer3dx")]
    robot: String,
    /// A model file whose θ is the prior instead (from `identify --out`).
    #[arg(long)]
    model: Option<PathBuf>,
    /// Target relative standard error of θ1, θ2, θ4, θ6 (0.01 or 1%).
    #[arg(long, default_value = "1%")]
    accuracy: String,
    /// White noise of the measured v [m/s] and ω [rad/s], comma-separated.
    #[arg(long, value_delimiter = ',', default_values_t = [0.005, 0.01])]
    noise: Vec<f64>,
    /// The floor space, x and y sides [m], comma-separated (the robot starts at its centre).
    #[arg(long, value_delimiter = ',', default_values_t = [4.0, 4.0])]
    space: Vec<f64>,
    /// Share of the robot's top speeds the commands may use.
    #[arg(long, default_value_t = 0.8)]
    speed_share: f64,
    /// What the amplitudes optimise: the shortest drive, or log det of the information.
    #[arg(long, value_parser = ["duration", "d-optimal"], default_value = "duration")]
    criterion: String,
    /// Write the plan as a run config's `duration_s` and `[excitation]` (TOML).
    #[arg(short, long)]
    out: Option<PathBuf>,
    /// Write `design.png` (the commands and the predicted pose) into this directory.
    #[arg(long)]
    plot: Option<PathBuf>,
}

fn accuracy(text: &str) -> Result<f64> {
    let t = text.trim();
    let x: f64 = match t.strip_suffix('%') {
        Some(p) => p.trim().parse::<f64>().map(|x| x / 100.0),
        None => t.parse(),
    }
    .with_context(|| format!("--accuracy {text}: not a number or a percentage"))?;
    if !(x > 0.0 && x < 1.0) {
        bail!("--accuracy {text}: must be in (0, 100 %)");
    }
    Ok(x)
}

pub(crate) fn run_design(a: DesignArgs) -> Result<()> {
    let robot = wheelid::config::robot_profile(Some(&a.robot), None, None)?;
    let theta: [f64; 6] = match &a.model {
        Some(p) => {
            let m = ModelFile::read(p)?;
            m.theta
                .get(..6)
                .and_then(|t| t.try_into().ok())
                .with_context(|| format!("{}: θ has fewer than six values", p.display()))?
        }
        None => robot.theta,
    };
    let mut s = DesignSettings::for_robot(
        theta,
        robot.period_s,
        [a.speed_share * robot.v_max, a.speed_share * robot.w_max],
    );
    s.accuracy = accuracy(&a.accuracy)?;
    if a.noise.len() != 2 || a.space.len() != 2 {
        bail!("--noise and --space take two values each, comma-separated (v,w and x,y)");
    }
    s.noise_std = [a.noise[0], a.noise[1]];
    s.space_m = [a.space[0], a.space[1]];
    s.criterion = if a.criterion == "d-optimal" {
        Criterion::DOptimal
    } else {
        Criterion::Duration
    };
    let model = models::by_name(if robot.name.starts_with("khepera") {
        "wheel-pd"
    } else {
        "vw-pd"
    })
    .context("built-in model")?;
    let d = design(model.as_ref(), &s)?;
    out!(
        "Designed experiment for {} ({} candidates): drive {:.0} s on lines up to {:.2} Hz, pose \
         within ±{:.2} m × ±{:.2} m",
        robot.name,
        d.evaluations,
        d.duration_s,
        d.f_max_hz,
        d.extent_m[0],
        d.extent_m[1]
    );
    for (i, (th, se)) in theta.iter().zip(d.predicted_std_err).enumerate() {
        out!(
            "  θ{} {th:>9.5}  predicted standard error {se:.5} ({:.2} %)",
            i + 1,
            100.0 * se / th.abs()
        );
    }
    if let Some(dir) = &a.plot {
        std::fs::create_dir_all(dir).with_context(|| dir.display().to_string())?;
        let p = wheelid::plot::write_design_plot(&d, s.space_m, dir)?;
        out!("written: {}", p.display());
    }
    let text = plan_toml(&d)?;
    match &a.out {
        Some(p) => {
            wheelid::core::recording::write_atomic(p, text.as_bytes())
                .with_context(|| p.display().to_string())?;
            out!(
                "written: {} (a run config's duration_s and [excitation])",
                p.display()
            );
        }
        None => out_raw!("{text}"),
    }
    Ok(())
}

/// The plan as run-config TOML: `duration_s` and `[excitation]` of type `signals`.
fn plan_toml(d: &wheelid::design::Design) -> Result<String> {
    #[derive(serde::Serialize)]
    struct Plan<'a> {
        duration_s: f64,
        excitation: wheelid::config::ExcitationConfig,
        #[serde(skip)]
        _d: std::marker::PhantomData<&'a ()>,
    }
    let plan = Plan {
        duration_s: d.duration_s,
        excitation: wheelid::config::ExcitationConfig::Signals(Box::new(d.excitation.clone())),
        _d: std::marker::PhantomData,
    };
    Ok(format!(
        "# wheelid design: predicted standard errors {:?}\n{}",
        d.predicted_std_err.map(|x| (x * 1e6).round() / 1e6),
        toml::to_string(&plan)?
    ))
}
