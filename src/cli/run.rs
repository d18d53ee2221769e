//! `wheelid run`: a whole identification job from a TOML file.

use std::path::PathBuf;

use anyhow::Result;
use wheelid::report;

use crate::{Bar, emit};

#[derive(clap::Args)]
pub(crate) struct RunArgs {
    /// The run's TOML configuration.
    config: PathBuf,
    /// Print the report as JSON.
    #[arg(long)]
    json: bool,
    /// Also estimate θ̂ online while driving (recursive least squares, then the recursive
    /// output-error fit — instrumental variables where the robot's stamping is unknown — with
    /// change detection; the file's `[online]` table or its defaults) and write `online.csv`.
    #[arg(long)]
    online: bool,
}

pub(crate) fn run_run(a: RunArgs) -> Result<()> {
    let bar = Bar::new(!a.json, "{spinner} {msg} [{bar:30}] {pos}/{len} samples");
    let options = wheelid::run::RunOptions { online: a.online };
    let out = wheelid::run::run_with(&a.config, &bar, options);
    bar.0.finish_and_clear();
    let out = out?;
    if a.json {
        out!(
            "{}",
            serde_json::to_string_pretty(&report::to_json(&out.identification, None))?
        );
    } else {
        out_raw!("{}", report::to_text(&out.identification, None));
        if let Some(trace) = &out.online {
            out_raw!("{}", report::online_text(trace, &out.identification));
        }
        for f in &out.files {
            out!("written: {}", f.display());
        }
    }
    Ok(())
}
