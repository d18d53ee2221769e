//! Reports of an identification: a text table for people, and JSON of a fixed shape for
//! programs:
//! `{"model", "theta": [6], "std_err": [6], "cutoff_hz", "samples",
//!   "channels": {"v": {"r2", "fit_percent"}, "w": {…}}, …}` (more keys allowed).

use serde_json::{Value, json};

use crate::identify::Identification;

/// JSON report. `truth` (e.g. the embedded robot's θ) is included when given.
pub fn to_json(id: &Identification, truth: Option<&[f64]>) -> Value {
    let channels: serde_json::Map<String, Value> = id
        .channels
        .iter()
        .map(|c| {
            (
                c.name.clone(),
                json!({"r2": c.r2, "fit_percent": c.fit_percent, "condition_number": c.condition_number, "samples": c.samples}),
            )
        })
        .collect();
    let mut v = json!({
        "model": id.model,
        "solver": id.solver,
        "theta": id.theta,
        "std_err": id.std_err,
        "param_names": id.param_names,
        "bound_state": id.bound_state,
        "cutoff_hz": id.cutoff_hz,
        "cutoff_rule": id.cutoff_choice,
        "filter_order": id.filter_order,
        "samples": id.samples,
        "channels": channels,
        "files": id.files,
        "steady_state": {"theta4": id.steady_theta4, "theta6": id.steady_theta6},
    });
    if let Some(t) = truth {
        v["theta_true"] = json!(t);
    }
    v
}

/// Human-readable report.
pub fn to_text(id: &Identification, truth: Option<&[f64]>) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "model {}  solver {}  samples {}  files {}",
        id.model,
        id.solver,
        id.samples,
        id.files.len()
    );
    for f in &id.files {
        let _ = write!(
            s,
            "  {}: {} samples at {:.4} s",
            f.source.display(),
            f.samples,
            f.dt
        );
        if let Some(from) = f.resampled_from {
            let _ = write!(
                s,
                " (resampled from non-uniform sampling, median {from:.4} s)"
            );
        }
        let _ = writeln!(s);
    }
    let rule = match id.cutoff_choice {
        wheelid_core::CutoffChoice::Given => "given".to_owned(),
        wheelid_core::CutoffChoice::CommandBandwidth { f95_hz, clamped } => format!(
            "rule: 2 × f95 of the commands (f95 = {}){}",
            f95_hz.map_or("n/a".into(), |f| format!("{f:.3} Hz")),
            if clamped { ", clamped" } else { "" }
        ),
    };
    let _ = writeln!(
        s,
        "filter: zero-phase Butterworth order {}, cut-off {:.3} Hz ({rule})",
        id.filter_order, id.cutoff_hz
    );
    let _ = writeln!(s);
    let _ = write!(
        s,
        "{:<8} {:>12} {:>12} {:<10}",
        "param", "estimate", "std err", "unit"
    );
    if truth.is_some() {
        let _ = write!(s, " {:>12} {:>9}", "true", "error %");
    }
    let _ = writeln!(s);
    for i in 0..id.theta.len() {
        let _ = write!(
            s,
            "{:<8} {:>12.6} {:>12.6} {:<10}",
            id.param_names[i], id.theta[i], id.std_err[i], id.param_units[i]
        );
        if let Some(t) = truth {
            let _ = write!(
                s,
                " {:>12.6} {:>9.3}",
                t[i],
                100.0 * (id.theta[i] - t[i]) / t[i]
            );
        }
        if id.bound_state[i] != wheelid_core::BoundState::Free {
            let _ = write!(s, "  [{:?}]", id.bound_state[i]);
        }
        let _ = writeln!(s);
    }
    let _ = writeln!(s);
    let _ = writeln!(
        s,
        "{:<8} {:>10} {:>14} {:>12}",
        "channel", "R²", "free-run fit %", "cond(X)"
    );
    for c in &id.channels {
        let _ = writeln!(
            s,
            "{:<8} {:>10.4} {:>14.2} {:>12.1}",
            c.name, c.r2, c.fit_percent, c.condition_number
        );
    }
    let _ = writeln!(s);
    let ss = |name: &str, e: Option<crate::identify::SteadyStateEstimate>| match e {
        Some(e) => format!(
            "{name} = {:.4} from {} constant-command segments ({:.1} s settled)",
            e.value, e.segments, e.seconds
        ),
        None => format!("{name}: no settled constant-command segment"),
    };
    let _ = writeln!(
        s,
        "steady state (§4.1): {}; {}",
        ss("θ4", id.steady_theta4),
        ss("θ6", id.steady_theta6)
    );
    s
}
