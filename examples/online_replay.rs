//! Replays recordings through the online estimator (`wheelid::online::OnlineTheta`, default
//! settings, one update per row at the row's stamp — as on a robot's computer) and compares its
//! final θ̂ with the batch answer of the same recording (`identify`, default settings, the
//! `vw-pd` model): θ1, θ2, θ4, θ6 online and batch, their difference in per cent and in the
//! online standard errors, the estimator's form and its change alarms.
//!
//! Run: `cargo run --release --example online_replay -- [--no-detection] [--memory S]
//! [--form ls|iv|oe] FILE...` (e.g. `../shared/data/real/husky_drive_wetgrass/husky_wetgrass_seg*.csv`;
//! the options change the estimator's defaults: no change detector, the forgetting memory
//! T_mem in seconds, the form after the warm-up).

use anyhow::{Context, Result};
use wheelid::core::Recording;
use wheelid::identify::{IdentifySettings, identify};
use wheelid::online::{OnlineForm, OnlineSettings, OnlineTheta};
use wheelid::solvers::Ols;

fn main() -> Result<()> {
    let mut files = Vec::new();
    let mut base = OnlineSettings::default();
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--no-detection" => base.detection = None,
            "--memory" => {
                let s = args.next().context("--memory needs seconds")?;
                base.memory_s = s.parse().with_context(|| format!("--memory {s}"))?;
            }
            "--form" => {
                base.form = match args.next().as_deref() {
                    Some("ls") => OnlineForm::LeastSquares,
                    Some("iv") => OnlineForm::InstrumentalVariables,
                    Some("oe") => OnlineForm::OutputError,
                    other => anyhow::bail!("--form ls|iv|oe, got {other:?}"),
                }
            }
            _ => files.push(a),
        }
    }
    anyhow::ensure!(!files.is_empty(), "usage: online_replay [OPTIONS] FILE...");
    let model = wheelid::models::by_name("vw-pd").context("the vw-pd model")?;
    for f in &files {
        let rec = Recording::read_csv(f).with_context(|| format!("reading {f}"))?;
        let batch = identify(
            std::slice::from_ref(&rec),
            model.as_ref(),
            &Ols::default(),
            &IdentifySettings::default(),
        )
        .with_context(|| format!("identifying {f}"))?;
        let n = rec.len();
        let dt = (rec.t[n - 1] - rec.t[0]) / (n - 1) as f64;
        let settings = base.for_timing(rec.timing());
        let mut est = OnlineTheta::new(settings, dt).context("online settings")?;
        for k in 0..n {
            est.update(rec.t[k], rec.v_ref[k], rec.w_ref[k], rec.v[k], rec.w[k]);
        }
        let (th, se) = (est.theta(), est.std_err());
        println!(
            "{f}: {n} rows, {:.1} s; online form {:?}, settled {}, alarms {:?}",
            rec.t[n - 1] - rec.t[0],
            est.form(),
            est.settled(),
            est.changes()
        );
        for (i, name) in [(0, "θ1"), (1, "θ2"), (3, "θ4"), (5, "θ6")] {
            println!(
                "  {name} online {:9.5} ± {:7.5}  batch {:9.5} ± {:7.5}  {:+7.2} %  {:+6.2} s.e.",
                th[i],
                se[i],
                batch.theta[i],
                batch.std_err[i],
                100.0 * (th[i] - batch.theta[i]) / batch.theta[i],
                (th[i] - batch.theta[i]) / se[i]
            );
        }
    }
    Ok(())
}
