//! `wheelid export`: a model file for another stack (ROS 2, Nav2).

use std::path::PathBuf;

use anyhow::{Context, Result};
use wheelid::files::ModelFile;
use wheelid::robots::RobotProfile;

use crate::emit;

#[derive(clap::Args)]
pub(crate) struct ExportArgs {
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

pub(crate) fn run_export(a: ExportArgs) -> Result<()> {
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
