//! Reports of an identification: a text table for people, and JSON of a fixed shape for
//! programs:
//! `{"model", "theta": [6], "std_err": [6], "cutoff_hz", "samples",
//!   "channels": {"v": {"r2", "fit_percent"}, "w": {…}}, …}` (more keys allowed).

use serde_json::{Value, json};

use crate::diagnose::Diagnosis;
use crate::identify::Identification;
use wheelid_robots::{RobotProfile, TrackResult, TrackSettings};

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
        "estimator": id.estimator,
        "estimates": id.estimates,
        "ls_shift_percent": id.ls_shift_percent,
        "noise_std": id.noise_std,
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
        "timing": id.timing,
        "warnings": id.warnings,
    });
    if let Some(t) = truth {
        v["theta_true"] = json!(t);
    }
    v
}

/// Human-readable report.
pub fn to_text(id: &Identification, truth: Option<&[f64]>) -> String {
    let mut s = String::new();
    text_header(&mut s, id);
    text_parameters(&mut s, id, truth);
    text_estimates(&mut s, id);
    text_quality(&mut s, id);
    s
}

/// The run's header: model, estimator, solver, files, filter.
fn text_header(s: &mut String, id: &Identification) {
    use std::fmt::Write;
    let _ = writeln!(
        s,
        "model {}  estimator {}  solver {}  samples {}  files {}",
        id.model,
        id.estimator,
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
}

/// θ̂ with its standard errors (and the truth, when known).
fn text_parameters(s: &mut String, id: &Identification, truth: Option<&[f64]>) {
    use std::fmt::Write;
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
}

/// Every estimator's θ side by side, and the warning when the answer left least squares.
fn text_estimates(s: &mut String, id: &Identification) {
    use std::fmt::Write;
    if id.estimates.len() > 1 {
        let _ = write!(s, "{:<8}", "param");
        for e in &id.estimates {
            let _ = write!(s, " {:>12} {:>9}", e.estimator, "± 2σ");
        }
        let _ = writeln!(s, " {:>12}", "shift % vs ls");
        for i in 0..id.theta.len() {
            let _ = write!(s, "{:<8}", id.param_names[i]);
            for e in &id.estimates {
                let _ = write!(s, " {:>12.6} {:>9.6}", e.theta[i], 2.0 * e.std_err[i]);
            }
            let _ = writeln!(s, " {:>12.2}", id.ls_shift_percent[i]);
        }
        let _ = write!(s, "{:<8}", "time");
        for e in &id.estimates {
            let _ = write!(s, " {:>10.3} s {:>9}", e.seconds, "");
        }
        let _ = writeln!(s);
        let _ = writeln!(s);
    }
    // Bias warning: the answer left the least-squares one by more than 3 of its σ and 1 %.
    let moved: Vec<String> = (0..id.theta.len())
        .filter(|&i| {
            id.ls_shift_percent[i].abs() > 1.0
                && (id.theta[i] - id.estimates[0].theta[i]).abs() > 3.0 * id.std_err[i]
        })
        .map(|i| format!("{} {:+.1} %", id.param_names[i], id.ls_shift_percent[i]))
        .collect();
    if id.estimator != crate::estimators::LEAST_SQUARES && !moved.is_empty() {
        let _ = writeln!(
            s,
            "warning: {} moved {} from least squares, beyond 3 σ: the filtered regression is \
             biased here (noisy or coarsely sampled regressors), or the model misses physics \
             that the two estimators weigh differently — check the free-run fit",
            id.estimator,
            moved.join(", "),
        );
        let _ = writeln!(s);
    }
}

/// The timing, the noise, each channel's fit, the steady state and the warnings.
fn text_quality(s: &mut String, id: &Identification) {
    use std::fmt::Write;
    if let Some(t) = &id.timing {
        let _ = writeln!(s, "{}", t.summary);
    }
    if let Some(sd) = &id.noise_std {
        let _ = writeln!(
            s,
            "output-error residual std: v {:.5} m/s, ω {:.5} rad/s",
            sd[0], sd[1]
        );
    }
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
    for w in &id.warnings {
        let _ = writeln!(s, "\nwarning: {w}");
    }
}

/// The online estimate of a drive ([`crate::run::OnlineTrace`]) against the batch
/// identification of the same recording: θ̂ at the end with its standard errors, the batch θ
/// and their difference \[%\], and the times of the change alarms.
pub fn online_text(trace: &crate::run::OnlineTrace, id: &Identification) -> String {
    use std::fmt::Write as _;
    let mut s = String::new();
    let n = trace.t.len();
    use crate::online::OnlineForm;
    let how = match trace.form {
        Some(OnlineForm::LeastSquares) => "recursive least squares",
        Some(OnlineForm::InstrumentalVariables) => {
            "recursive least squares, then instrumental variables"
        }
        Some(OnlineForm::OutputError) | None => {
            "recursive least squares, then the recursive output-error fit"
        }
    };
    let _ = writeln!(
        s,
        "Online ({how}, while driving, {n} samples; wheelid::online):"
    );
    if let Some((target, reached)) = trace.accuracy {
        let whose = if trace.batch_checks.is_empty() {
            "online"
        } else {
            "batch"
        };
        let _ = match reached {
            Some(t) => writeln!(
                s,
                "  stopped at {t:.1} s: the {whose} 95 % intervals of θ1, θ2, θ4, θ6 within {:.2} %",
                100.0 * target
            ),
            None => writeln!(
                s,
                "  accuracy {:.2} % NOT reached within the run's duration",
                100.0 * target
            ),
        };
    }
    online_checks(&mut s, trace);
    let (Some(th), Some(se)) = (trace.theta.last(), trace.std_err.last()) else {
        return s;
    };
    for i in 0..6 {
        let b = id.theta.get(i).copied().unwrap_or(f64::NAN);
        let _ = writeln!(
            s,
            "  θ{} {:>10.5} ± {:.5}   batch {:>10.5}   {:+.2} %",
            i + 1,
            th[i],
            se[i],
            b,
            100.0 * (th[i] - b) / b
        );
    }
    let alarms: Vec<String> = trace
        .t
        .iter()
        .zip(&trace.change)
        .filter(|(_, c)| c[0] || c[1])
        .map(|(t, c)| {
            let which = match c {
                [true, true] => "v, ω",
                [true, false] => "v",
                _ => "ω",
            };
            format!("{t:.2} s ({which})")
        })
        .collect();
    let _ = writeln!(
        s,
        "  change alarms: {}",
        if alarms.is_empty() {
            "none".to_owned()
        } else {
            alarms.join(", ")
        }
    );
    s
}

/// The batch checks and re-designs of an online run, one line each ([`online_text`]).
fn online_checks(s: &mut String, trace: &crate::run::OnlineTrace) {
    use std::fmt::Write as _;
    for c in &trace.batch_checks {
        let _ = match &c.outcome {
            Ok((th, w)) => writeln!(
                s,
                "  batch check of the first {:.1} s ({} samples): θ1, θ2, θ4, θ6 = [{}], \
                 intervals ± {:.2} %",
                c.started_s,
                c.samples,
                th.map(|x| format!("{x:.4}")).join(", "),
                100.0 * w
            ),
            Err(why) => writeln!(
                s,
                "  batch check of the first {:.1} s: no answer ({why})",
                c.started_s
            ),
        };
    }
    for r in &trace.redesigns {
        let th = r.theta.map(|x| format!("{x:.4}")).join(", ");
        let _ = match &r.outcome {
            Ok((from, f)) => writeln!(
                s,
                "  re-designed at {:.1} s for θ̂ = [{th}] from ({:.2}, {:.2}) m: lines to {f:.2} Hz \
                 from {from:.1} s",
                r.started_s, r.start_pose[0], r.start_pose[1]
            ),
            Err(why) => writeln!(
                s,
                "  re-design at {:.1} s for θ̂ = [{th}] from ({:.2}, {:.2}) m: none ({why}); the \
                 commands went on",
                r.started_s, r.start_pose[0], r.start_pose[1]
            ),
        };
    }
}

/// JSON report of a tracking run:
/// `{"robot", "theta_true": [6], "theta_hat0": [6], "theta_hat_final": [6],
///   "error_m": {"rms", "final", "max"}, "duration_s", "steps", "adaptation": {…}}`.
///
/// `backend` is `simulator` (eq. 2.19; `theta_true` its θ) or `physics` (the rigid-body robot;
/// `theta_true` the θ its constants map to); `effects` the active effects of that backend.
pub fn track_json(
    robot: &RobotProfile,
    backend: &str,
    effects: &[&str],
    s: &TrackSettings,
    r: &TrackResult,
) -> Value {
    json!({
        "robot": robot.name,
        "backend": backend,
        "ground_truth": r.ground_truth,
        "theta_true": robot.theta,
        "theta_hat0": s.theta_hat0,
        "theta_hat_final": r.final_theta_hat(),
        "error_m": {"rms": r.summary.rms, "final": r.summary.last, "max": r.summary.max},
        "duration_s": s.duration_s,
        "steps": r.t.len(),
        "adaptation": s.adaptation,
        "effects": effects,
    })
}

/// Text report of a tracking run (arguments as [`track_json`]).
pub fn track_text(
    robot: &RobotProfile,
    backend: &str,
    effects: &[&str],
    s: &TrackSettings,
    r: &TrackResult,
) -> String {
    use std::fmt::Write;
    let mut o = String::new();
    let g = s.adaptation.effective_gamma();
    let adapting = g.iter().any(|&x| x > 0.0);
    let _ = writeln!(
        o,
        "robot {} ({backend})  {:.1} s  {} steps of {} s  adaptation {}",
        robot.name,
        s.duration_s,
        r.t.len(),
        s.control_period_s.unwrap_or(robot.period_s),
        if adapting {
            format!("from t = {} s, γ = {g:?}", s.adaptation.start_s)
        } else {
            "off".to_string()
        }
    );
    if !effects.is_empty() {
        let _ = writeln!(o, "effects: {}", effects.join(", "));
    }
    let truth = if backend == "physics" { "map" } else { "true" };
    let _ = writeln!(o, "\nparam      θ̂(0)     θ̂(end)  {truth:>9}");
    let th_end = r.final_theta_hat();
    for (i, ((t0, t1), tt)) in s.theta_hat0.iter().zip(th_end).zip(robot.theta).enumerate() {
        let _ = writeln!(o, "theta{}  {t0:>9.4}  {t1:>9.4}  {tt:>9.4}", i + 1);
    }
    let _ = writeln!(
        o,
        "\ndistance error [m]{}: RMS {:.4}  final {:.4}  max {:.4}",
        if r.ground_truth { "" } else { " (odometry)" },
        r.summary.rms,
        r.summary.last,
        r.summary.max
    );
    o
}

/// Text report of a diagnosis, its six steps in order (fit, test, locate, name, model and
/// accept, show).
pub fn diagnosis_text(d: &Diagnosis) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    diagnosis_fit_and_test(&mut s, d);
    let _ = writeln!(s, "   → {}", verdict(d));
    diagnosis_locate_and_name(&mut s, d);
    diagnosis_model_and_show(&mut s, d);
    s
}

/// The validation fits of both channels, in words.
fn fits(c: &crate::diagnose::Channels) -> String {
    format!("v {:.1} %, ω {:.1} %", c.v.fit_percent, c.w.fit_percent)
}

/// Steps 1 and 2: the nominal fit and the tests on the validation blocks.
fn diagnosis_fit_and_test(s: &mut String, d: &Diagnosis) {
    use std::fmt::Write;
    let _ = writeln!(
        s,
        "1. Fit: nominal model (eq. 2.19) by output error on {:.0} s; {:.0} s in {} validation \
         blocks held out (blocks 2, 4, … of {} per recording).",
        d.split.training_s,
        d.split.validation_s,
        d.split.blocks / 2,
        d.split.blocks
    );
    let whole = d.split.training_s + d.split.validation_s;
    if d.split.searched_s < whole - 1e-6 {
        let _ = writeln!(
            s,
            "   The candidates were screened and fitted on {:.0} s of the {:.0} s, in windows \
             spread over each long recording; the model found was refitted on all of it.",
            d.split.searched_s, whole
        );
    }
    let names = ["θ1", "θ2", "θ3", "θ4", "θ5", "θ6"];
    let _ = writeln!(
        s,
        "   θ = {}",
        d.nominal
            .theta
            .iter()
            .zip(&d.nominal.std_err)
            .zip(names)
            .map(|((t, e), n)| format!("{n} {}", estimate(*t, *e, "±")))
            .collect::<Vec<_>>()
            .join(", ")
    );
    let _ = writeln!(
        s,
        "2. Test (validation blocks): free-run fit {}.",
        fits(&d.nominal.channels)
    );
    let floor = [
        d.nominal.channels.v.noise_ratio,
        d.nominal.channels.w.noise_ratio,
    ];
    for (ch, ratio) in d.location.channels.iter().zip(floor) {
        let _ = writeln!(
            s,
            "   {}: residual RMS {:.4} = {ratio:.1} × the noise floor, whiteness Q = {:.0} \
             (p = {:.1e}, not used alone)",
            ch.channel, ch.rms, ch.whiteness.q, ch.whiteness.p_value
        );
    }
    for t in &d.tests {
        let _ = writeln!(
            s,
            "   {:<48} p = {:<9.2e} {}",
            t.name,
            t.p_value,
            if t.significant { "SIGNIFICANT" } else { "" }
        );
    }
}

/// The verdict of step 2 in words: a mismatch or not, and why.
fn verdict(d: &Diagnosis) -> String {
    let tested = d.tests.iter().any(|t| t.significant);
    let practical = [d.nominal.channels.v, d.nominal.channels.w]
        .iter()
        .all(|c| c.fit_percent >= crate::diagnose::PRACTICAL_FIT_PERCENT);
    let within_noise = [d.nominal.channels.v, d.nominal.channels.w]
        .iter()
        .all(|c| c.noise_corrected_fit_percent >= crate::diagnose::PRACTICAL_FIT_PERCENT);
    let low: Vec<String> = [("v", d.nominal.channels.v), ("ω", d.nominal.channels.w)]
        .iter()
        .filter(|(_, c)| c.fit_percent < crate::diagnose::LOW_FIT_PERCENT)
        .map(|(n, c)| format!("{n}'s validation fit is {:.1} %", c.fit_percent))
        .collect();
    let floor_words: Vec<String> = [("v", d.nominal.channels.v), ("ω", d.nominal.channels.w)]
        .iter()
        .filter(|(_, c)| {
            c.fit_percent < crate::diagnose::PRACTICAL_FIT_PERCENT
                && c.noise_ratio > crate::diagnose::NOISE_FLOOR_FACTOR
        })
        .map(|(n, c)| format!("{:.1} × on {n}", c.noise_ratio))
        .collect();
    match (tested, low.is_empty()) {
        (true, _) if !d.mismatch && practical => format!(
            "no practical mismatch: evidence survives Holm's correction, but the model explains \
             ≥ {:.0} % of every channel (fits v {:.2} %, ω {:.2} %); the model is kept",
            crate::diagnose::PRACTICAL_FIT_PERCENT,
            d.nominal.channels.v.fit_percent,
            d.nominal.channels.w.fit_percent
        ),
        (true, _) if !d.mismatch && within_noise => format!(
            "no practical mismatch: evidence survives Holm's correction, but what the model \
             misses is the measurement noise (residual {:.1} × the noise floor on v, {:.1} × on \
             ω; beyond it the model explains v {:.2} %, ω {:.2} %, ≥ {:.0} %); the model is kept",
            d.nominal.channels.v.noise_ratio,
            d.nominal.channels.w.noise_ratio,
            d.nominal.channels.v.noise_corrected_fit_percent,
            d.nominal.channels.w.noise_corrected_fit_percent,
            crate::diagnose::PRACTICAL_FIT_PERCENT,
        ),
        (true, _) if !d.mismatch => "no mismatch kept: evidence survives Holm's correction, but \
             no candidate improves the held-out fit and the residual is then independent of the \
             commands; the model is kept"
            .to_string(),
        (true, _) => "mismatch: evidence survives Holm's correction".to_string(),
        (false, false) => format!(
            "mismatch: {} (below {:.0} %), though no test survives Holm's correction",
            low.join(", "),
            crate::diagnose::LOW_FIT_PERCENT
        ),
        (false, true) if !floor_words.is_empty() => format!(
            "mismatch: the residual is {} the noise floor (> {:.0} ×) with the fit below {:.0} %, \
             though no test survives Holm's correction",
            floor_words.join(", "),
            crate::diagnose::NOISE_FLOOR_FACTOR,
            crate::diagnose::PRACTICAL_FIT_PERCENT
        ),
        (false, true) if d.mismatch => {
            "mismatch: what the final model leaves is unexplained".into()
        }
        (false, true) => {
            "no mismatch: nothing survives Holm's correction; the model is kept as it is".into()
        }
    }
}

/// Steps 3 and 4: where the residual lies, and which effects the fingerprints nominate.
fn diagnosis_locate_and_name(s: &mut String, d: &Diagnosis) {
    use std::fmt::Write;
    let _ = writeln!(s, "3. Locate (nominal residual):");
    for (c, ch) in d.location.channels.iter().enumerate() {
        let _ = writeln!(
            s,
            "   {}: cross-correlation peaks at {:+.2} s (v_ref), {:+.2} s (ω_ref); {}",
            ["v", "ω"][c],
            ch.peak_lag_s[0],
            ch.peak_lag_s[1],
            d.location.summary(c)
        );
    }
    let _ = writeln!(s, "4. Name (fingerprints, score tests):");
    for (round, fps) in d.fingerprints.iter().enumerate() {
        let nominated: Vec<String> = fps
            .iter()
            .filter(|f| f.nominated)
            .map(|f| {
                format!(
                    "{} (χ²({}) = {:.1}, p = {:.1e})",
                    f.effect, f.dof, f.stat, f.p_value
                )
            })
            .collect();
        let _ = writeln!(
            s,
            "   round {}: {}",
            round + 1,
            if nominated.is_empty() {
                "nothing nominated".to_owned()
            } else {
                nominated.join("; ")
            }
        );
    }
    if let Some(why) = &d.unscored_round {
        let _ = writeln!(
            s,
            "   round {}: not scored: {why}",
            d.fingerprints.len() + 1
        );
    }
}

/// Steps 5 and 6: the effects kept and rejected, and the fit they reach.
fn diagnosis_model_and_show(s: &mut String, d: &Diagnosis) {
    use std::fmt::Write;
    let _ = writeln!(s, "5. Model and accept:");
    for f in &d.findings {
        let params: Vec<String> = f
            .parameters
            .iter()
            .map(|(k, v)| {
                let e = f.std_err.get(k).copied().unwrap_or(0.0);
                format!("{k} = {}", held_or_estimate(*v, e, " ± "))
            })
            .collect();
        let _ = writeln!(
            s,
            "   + {} on {}: {}; validation fit v {:.1} %, ω {:.1} %\n     {}",
            f.effect,
            f.channels.join(", "),
            params.join(", "),
            f.fit_percent_after.get("v").copied().unwrap_or(f64::NAN),
            f.fit_percent_after.get("w").copied().unwrap_or(f64::NAN),
            f.evidence
        );
    }
    for r in &d.rejected {
        let _ = writeln!(s, "   − {} not kept: {}", r.effect, r.reason);
    }
    if d.findings.is_empty() && d.rejected.is_empty() {
        let _ = writeln!(s, "   nothing to add");
    }
    if let Some(u) = &d.unexplained {
        let _ = writeln!(
            s,
            "   unexplained structure left in {}: {}",
            u.channels.join(", "),
            u.location.join("; ")
        );
    }
    let _ = writeln!(
        s,
        "6. Show: validation fit nominal {} → final ({}) {}.",
        fits(&d.nominal.channels),
        d.final_stage.model,
        fits(&d.final_stage.channels)
    );
    if !d.findings.is_empty() {
        let f = &d.final_stage;
        let params: Vec<String> = f
            .names
            .iter()
            .zip(f.theta.iter().zip(&f.std_err))
            .map(|(n, (x, e))| format!("{n} {}", held_or_estimate(*x, *e, "±")))
            .collect();
        let _ = writeln!(s, "   refitted: {}", params.join(", "));
    }
    if let Some(h) = &d.heading {
        let _ = writeln!(
            s,
            "   heading (a pose independent of the encoders): the chassis turns as a right/left \
             tyre radius ratio of {} — the right wheel covers {:+.1} % more ground than its \
             encoder says; {}",
            estimate(h.ratio, h.std_err, "±"),
            100.0 * (h.ratio - 1.0),
            if h.modelled {
                "tyre_asymmetry holds it"
            } else {
                "the model holds no tyre_asymmetry (the dynamics do not show it apart from the \
                 wheels' efforts): calibrate the odometry's wheel radii"
            }
        );
    }
    let _ = writeln!(s, "   ({:.2} s)", d.seconds);
}

/// The text report of a saved model refitted on recordings
/// ([`crate::diagnose::refit_saved`]): the split, θ and every effect's parameters with their
/// standard errors ("held" where the data cannot separate one), and the validation fits of
/// the nominal and the refitted model with each channel's residual over its noise floor.
pub fn saved_refit_text(r: &crate::diagnose::SavedRefit) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "Refit of the saved model ({}) by output error on {:.0} s; {:.0} s in the validation \
         blocks held out (blocks 2, 4, … of {} per recording).",
        r.refitted.model, r.split.training_s, r.split.validation_s, r.split.blocks
    );
    let theta: Vec<String> = (r.refitted.names.iter().zip(&r.refitted.theta))
        .zip(&r.refitted.std_err)
        .take(6)
        .map(|((n, x), e)| format!("{n} {}", held_or_estimate(*x, *e, "±")))
        .collect();
    let _ = writeln!(s, "   θ = {}", theta.join(", "));
    for (effect, params) in &r.effects {
        let shown: Vec<String> = params
            .iter()
            .map(|(k, v)| {
                let e = r.effects_std_err[effect].get(k).copied().unwrap_or(0.0);
                format!("{k} = {}", held_or_estimate(*v, e, " ± "))
            })
            .collect();
        let _ = writeln!(s, "   {effect}: {}", shown.join(", "));
    }
    let floor = |c: &crate::diagnose::Channels| {
        format!(
            "residual v {:.1}, ω {:.1} × the noise floor",
            c.v.noise_ratio, c.w.noise_ratio
        )
    };
    let _ = writeln!(
        s,
        "Validation fit: nominal {} ({}) → refitted {} ({}).",
        fits(&r.nominal.channels),
        floor(&r.nominal.channels),
        fits(&r.refitted.channels),
        floor(&r.refitted.channels)
    );
    if !r.misfit.is_empty() {
        let _ = writeln!(
            s,
            "warning: the refitted model misses {} beyond the noise floor: the saved effects do \
             not explain these recordings; `wheelid diagnose FILE…` searches again",
            r.misfit
                .iter()
                .map(|c| if c == "w" { "ω" } else { "v" })
                .collect::<Vec<_>>()
                .join(" and ")
        );
    }
    let _ = writeln!(s, "   ({:.2} s)", r.seconds);
    s
}

/// `x ± e` with at least 4 decimals and enough for the standard error's two leading digits
/// (a fit on nearly noiseless data has errors of 10⁻⁷: printed so, never as `± 0.0000`).
fn estimate(x: f64, e: f64, sep: &str) -> String {
    let decimals = if e > 0.0 && e.is_finite() {
        ((1.0 - e.log10()).ceil() as usize).clamp(4, 10)
    } else {
        4
    };
    format!("{x:.decimals$}{sep}{e:.decimals$}")
}

/// A diagnosis's parameter: `x (held)` where its standard error is exactly 0 — a parameter the
/// fit held at its value (one quantity two effects carry, [`wheelid_core::Effect::held_beside`],
/// or one the data could not separate) — else [`estimate`].
fn held_or_estimate(x: f64, e: f64, sep: &str) -> String {
    if e == 0.0 {
        format!("{x:.4} (held)")
    } else {
        estimate(x, e, sep)
    }
}

#[cfg(test)]
mod tests {
    use super::{estimate, held_or_estimate};

    #[test]
    fn a_held_parameter_says_so_instead_of_a_zero_error() {
        assert_eq!(held_or_estimate(0.811_23, 0.0, " ± "), "0.8112 (held)");
        assert_eq!(held_or_estimate(1.0668, 0.0015, " ± "), "1.0668 ± 0.0015");
    }

    #[test]
    fn estimates_keep_two_digits_of_a_tiny_standard_error() {
        assert_eq!(estimate(0.045_177_35, 3.0e-7, "±"), "0.04517735±0.00000030");
        assert_eq!(estimate(0.0379, 0.0010, " ± "), "0.0379 ± 0.0010");
        assert_eq!(estimate(1.0042, 0.0, "±"), "1.0042±0.0000");
    }
}
