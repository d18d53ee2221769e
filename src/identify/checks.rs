//! What an identification checks before it calls an answer one: that the commands excite the
//! dynamics at all, that an estimate is a model (finite, stable, with a covariance), and what
//! the answer cannot say (a lag shorter than a sample, a poor free-run fit).
//!
//! Stability of eq. 2.19 at rest: linearised about v = ω = 0 the model is
//!
//! ```text
//! θ1 v̇ = v_ref − θ4 v,   θ2 ω̇ = ω_ref − θ6 ω
//! ```
//!
//! (θ3 ω² and θ5 v ω are second order), stable iff θ4/θ1 > 0 and θ6/θ2 > 0, with time
//! constants τ_v = θ1/θ4 and τ_ω = θ2/θ6 \[s\].

use wheelid_core::{BoundState, Recording};

use super::{ChannelReport, EstimateReport, IdentifyError};
use crate::estimators::{LEAST_SQUARES, iv, oe};

/// Free-run fit % below which identify points at `wheelid diagnose`: the model explains less
/// than 70 % of a channel's variation about its mean (the diagnosis calls a channel
/// unexplained at the same level).
pub const POOR_FIT_PERCENT: f64 = 70.0;

/// Errors unless some recording's v_ref and some recording's ω_ref change: a constant
/// command leaves its channel's parameters without information (its regressors are noise;
/// without noise least squares would find the channel rank-deficient and say which
/// parameters, which is why this runs after it).
///
/// # Errors
/// [`IdentifyError::Setting`] naming the files and the command.
pub(super) fn check_excitation(recordings: &[Recording]) -> Result<(), IdentifyError> {
    let constant = |x: &[f64]| {
        let (lo, hi) = x
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
                (a.min(v), b.max(v))
            });
        hi - lo <= 1e-12 * (1.0 + hi.abs().max(lo.abs()))
    };
    type Column = fn(&Recording) -> &[f64];
    let commands: [(&str, &str, Column); 2] = [
        ("v_ref", "θ1, θ3, θ4", |r| &r.v_ref),
        ("w_ref", "θ2, θ5, θ6", |r| &r.w_ref),
    ];
    for (name, params, column) in commands {
        let all_constant = recordings.iter().all(|r| constant(column(r)));
        if all_constant {
            let files: Vec<String> = recordings
                .iter()
                .map(|r| r.source.display().to_string())
                .collect();
            return Err(IdentifyError::Setting(format!(
                "{}: {name} is constant, so the commands do not excite the dynamics of {params}: \
                 any fit of them is a fit of the noise; drive with commands that change (thesis \
                 §4.2: sums of sines; `wheelid simulate --excitation multisine` shows one)",
                files.join(", ")
            )));
        }
    }
    Ok(())
}

/// Why `e` is no model, or `None` if it is one: a non-finite θ or standard error, a standard
/// error of exactly 0 on a parameter not held at a bound (a singular covariance), or, for
/// eq. 2.19, an unstable response (module doc).
pub(super) fn invalid(e: &EstimateReport, bound: &[BoundState], eq_2_19: bool) -> Option<String> {
    if let Some(i) = e.theta.iter().position(|x| !x.is_finite()) {
        return Some(format!("θ{} is not finite", i + 1));
    }
    if let Some(i) = e.std_err.iter().enumerate().position(|(i, s)| {
        !s.is_finite() || (*s == 0.0 && bound.get(i).is_none_or(|b| *b == BoundState::Free))
    }) {
        return Some(format!(
            "the covariance is singular (standard error of θ{} is {})",
            i + 1,
            e.std_err[i]
        ));
    }
    if eq_2_19 {
        let t = &e.theta;
        for (ch, a, b) in [("v", 0usize, 3usize), ("ω", 1, 5)] {
            if t[b] / t[a] <= 0.0 {
                return Some(format!(
                    "the {ch} response is unstable (θ{}/θ{} = {:.4} s ≤ 0)",
                    a + 1,
                    b + 1,
                    t[a] / t[b]
                ));
            }
        }
    }
    None
}

/// The estimator whose answer is reported: `asked` if its estimate is valid, else the first
/// valid one of output error, instrumental variables (the order of their bias, least first),
/// any other estimator in the order they ran, least squares; with the warnings that say so,
/// and one for every other invalid estimate.
///
/// # Errors
/// [`IdentifyError::NoModel`] if no estimate is valid, with each one's reason, unless
/// `allow_invalid` (then the estimate asked for, with the warnings).
pub(super) fn choose(
    estimates: &[EstimateReport],
    asked: &str,
    allow_invalid: bool,
) -> Result<(String, Vec<String>), IdentifyError> {
    let mut preference: Vec<&str> = vec![asked, oe::NAME, iv::NAME];
    preference.extend(estimates.iter().map(|e| e.estimator.as_str()));
    preference.push(LEAST_SQUARES);
    let answer = preference
        .iter()
        .filter_map(|&name| estimates.iter().find(|x| x.estimator == name))
        .find(|e| e.invalid.is_none())
        .map(|e| e.estimator.as_str())
        .or(allow_invalid.then_some(asked));
    let Some(answer) = answer else {
        let why: Vec<String> = estimates
            .iter()
            .map(|e| format!("{}: {}", e.estimator, e.invalid.as_deref().unwrap_or("?")))
            .collect();
        return Err(IdentifyError::NoModel(format!(
            "no estimator gave a model ({}); the recordings do not fit eq. 2.19 — run `wheelid \
             diagnose` on them to locate and name what the model leaves out",
            why.join("; ")
        )));
    };
    let warnings = estimates
        .iter()
        .filter_map(|e| {
            let why = e.invalid.as_deref()?;
            let name = &e.estimator;
            Some(if name == asked && answer == asked {
                format!("{name} gave no model: {why}; no estimator did")
            } else if name == asked {
                format!(
                    "{name} gave no model: {why}; the answer is {answer}'s, the best valid estimate"
                )
            } else {
                format!("{name}'s estimate is no model ({why}); not used")
            })
        })
        .collect();
    Ok((answer.to_owned(), warnings))
}

/// A warning per channel whose free-run fit is below [`POOR_FIT_PERCENT`], pointing at
/// `wheelid diagnose` on the same files.
pub(super) fn poor_fit(channels: &[ChannelReport], recordings: &[Recording]) -> Vec<String> {
    let files: Vec<String> = recordings
        .iter()
        .map(|r| r.source.display().to_string())
        .collect();
    channels
        .iter()
        .filter(|c| c.fit_percent.is_nan() || c.fit_percent < POOR_FIT_PERCENT)
        .map(|c| {
            format!(
                "the free-run fit of {} is {:.1} % (< {POOR_FIT_PERCENT} %): the model leaves \
                 out physics that drives this robot — `wheelid diagnose {}` locates and names \
                 it",
                c.name,
                c.fit_percent,
                files.join(" ")
            )
        })
        .collect()
}

/// Notices on a valid eq. 2.19 answer `theta` at sample period `dt` [s]: time constants
/// shorter than one sample (the lag does not show at this sampling; θ1, θ2 then carry little
/// information and their errors say so).
pub(super) fn lag_notices(theta: &[f64], dt: f64) -> Vec<String> {
    [("v", 0usize, 3usize), ("ω", 1, 5)]
        .iter()
        .filter_map(|&(ch, a, b)| {
            let tau = theta[a] / theta[b];
            (tau < dt).then(|| {
                format!(
                    "θ{} below {:.4} s: the {ch} lag (θ{}/θ{} = {:.2} ms) is shorter than one \
                     sample ({:.1} ms); the {ch} response is nearly static at this sampling and \
                     θ{} is poorly determined — sample faster to measure it",
                    a + 1,
                    dt * theta[b],
                    a + 1,
                    b + 1,
                    1e3 * tau,
                    1e3 * dt,
                    a + 1
                )
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use wheelid_core::SolveStatus;

    fn estimate(theta: [f64; 6], std_err: [f64; 6]) -> EstimateReport {
        EstimateReport {
            estimator: oe::NAME.into(),
            theta: theta.to_vec(),
            std_err: std_err.to_vec(),
            status: SolveStatus::Solved,
            bound_state: vec![BoundState::Free; 6],
            invalid: None,
            iterations: 1,
            seconds: 0.0,
        }
    }

    #[test]
    fn unstable_singular_and_non_finite_estimates_are_no_model() {
        let free = [BoundState::Free; 6];
        let se = [0.01; 6];
        // The issue's README example: θ6 = −1.50 (ω unstable, τ_ω = θ2/θ6 < 0).
        let unstable = estimate([0.3, 0.2, 0.0, 1.0, 0.0, -1.5], se);
        let why = invalid(&unstable, &free, true).expect("unstable");
        assert!(why.contains("ω response is unstable"), "{why}");
        // Both negative: θ1 < 0, θ4 > 0.
        let why = invalid(&estimate([-0.02, 0.2, 0.0, 1.0, 0.0, 1.0], se), &free, true)
            .expect("unstable v");
        assert!(why.contains("v response"), "{why}");
        let mut zero = se;
        zero[1] = 0.0;
        let why = invalid(&estimate([0.3, 0.2, 0.0, 1.0, 0.0, 1.0], zero), &free, true)
            .expect("singular");
        assert!(why.contains("singular") && why.contains("θ2"), "{why}");
        // The same zero on a parameter held at its bound is the bound's, not a singularity.
        let mut held = free;
        held[1] = BoundState::AtLower;
        assert_eq!(
            invalid(&estimate([0.3, 0.2, 0.0, 1.0, 0.0, 1.0], zero), &held, true),
            None
        );
        let nan = estimate([0.3, f64::NAN, 0.0, 1.0, 0.0, 1.0], se);
        assert!(invalid(&nan, &free, true).is_some());
        // A plugin model with other parameters: no stability test on its signs.
        assert_eq!(invalid(&unstable, &free, false), None);
    }

    #[test]
    fn a_lag_shorter_than_a_sample_is_said() {
        // τ_v = 0.001 s at 50 Hz (20 ms): said; τ_ω = 0.05 s: not.
        let n = lag_notices(&[0.001, 0.05, 0.0, 1.0, 0.0, 1.0], 0.02);
        assert_eq!(n.len(), 1);
        assert!(n[0].starts_with("θ1 below 0.0200 s"), "{}", n[0]);
        assert!(lag_notices(&[0.1, 0.05, 0.0, 1.0, 0.0, 1.0], 0.02).is_empty());
    }

    #[test]
    fn constant_commands_are_refused_naming_the_file() {
        let t: Vec<f64> = (0..50).map(|k| 0.1 * k as f64).collect();
        let c = vec![0.2; 50];
        let w: Vec<f64> = t.iter().map(|x| x.sin()).collect();
        let rec = |w_ref: Vec<f64>| {
            Recording::new(
                "flat.csv",
                t.clone(),
                c.clone(),
                w_ref.clone(),
                c.clone(),
                w_ref,
            )
            .expect("valid")
        };
        let e = check_excitation(&[rec(w.clone())]).expect_err("v_ref constant");
        let msg = e.to_string();
        assert!(msg.starts_with("flat.csv: v_ref is constant"), "{msg}");
        assert!(check_excitation(&[rec(vec![0.0; 50])]).is_err());
        // Another recording that moves v_ref makes the set informative.
        let mut moving = rec(w);
        moving.v_ref = moving.w_ref.clone();
        assert!(check_excitation(&[rec(vec![0.0; 50]), moving]).is_ok());
    }
}
