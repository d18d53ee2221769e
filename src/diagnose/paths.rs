//! The search's paths: forward selection is greedy, so where its final model leaves a channel
//! above the noise floor the whole search is run again from the first round's runner-up (the
//! best candidate that passed its verdict and was outscored on the information criterion),
//! and the better of the two explanations is kept. Each path ends with the measured effects'
//! turn: placed in the model, they drop what they make redundant, and the search goes on
//! beside them.
//!
//! For the greedy model g and the other o, judged on the same validation samples (n_eff of
//! them after the residual's autocorrelation, J the validation cost, k the free parameters):
//!
//! ```text
//! AIC_o − AIC_g = n_eff ln(J_o / J_g) + 2 (k_o − k_g)  < 0
//! ```
//!
//! whether or not o names other effects than g (the same effects are the same explanation,
//! o's fit of it the better one).

use super::backward::backward_step;
use super::search::{Accepted, Outcome, above_floor, rounds};
use super::*;

/// A first round's runner-up ([`Outcome::runner_up`]): its information score, its fit, and
/// the round's refusals.
pub(super) struct RunnerUp {
    pub(super) score: f64,
    pub(super) fit: Accepted,
    pub(super) rejected: Vec<Rejected>,
}

/// Keeps `fit` (information score `score`) as the runner-up in `slot` where it scores better
/// than the one there.
pub(super) fn keep_runner_up(slot: &mut Option<RunnerUp>, score: f64, fit: Accepted) {
    if slot.as_ref().is_none_or(|r| score < r.score) {
        *slot = Some(RunnerUp {
            score,
            fit,
            rejected: Vec::new(),
        });
    }
}

/// Runs the search from the nominal model `cur` (module docs, steps 2–7); then, where
/// another sensor measures an effect (`measured`), that effect takes the place of its
/// quantity's alternatives in the model and the search goes on beside it for them alone.
///
/// Forward selection is greedy: where its final model leaves a channel above the noise floor
/// ([`above_floor`]) and the first round had a runner-up, the search from the runner-up is
/// tried too ([`second_path`]).
pub(super) fn run(
    data: &Data,
    cur: Current,
    settings: &DiagnoseSettings,
    location: &Location,
    progress: &Progress<'_>,
) -> Result<Outcome, DiagnoseError> {
    let mut out = path(data, cur.clone(), settings, location, progress, None);
    let (fits, _) = data.validate_on(&out.cur.sim, &data.judged(&[&out.cur]));
    if !above_floor(&fits).iter().any(|&a| a) {
        return Ok(out);
    }
    let Some(runner_up) = out.runner_up.take() else {
        return Ok(out);
    };
    let other = path(data, cur, settings, location, progress, Some(runner_up));
    Ok(second_path(data, out, other))
}

/// One forward selection from the nominal model `cur` located at `location` ([`run`]), the
/// first round's pick `forced` where given, then the measured effects' turn
/// ([`measured::settle`], [`redundant_beside_measured`]).
fn path(
    data: &Data,
    cur: Current,
    settings: &DiagnoseSettings,
    location: &Location,
    progress: &Progress<'_>,
    forced: Option<RunnerUp>,
) -> Outcome {
    let mut out = Outcome {
        cur: cur.clone(),
        findings: Vec::new(),
        rejected: Vec::new(),
        rounds: Vec::new(),
        unscored: None,
        tests: Vec::new(),
        mismatch: false,
        searched_s: data.recs.iter().map(Recording::len).sum::<usize>() as f64 * data.dt,
        runner_up: None,
    };
    let first = (Some(location), forced);
    let cur = rounds(data, cur, settings, first, progress, &mut out);
    let (cur, settled) = measured::settle(data, cur, &mut out);
    let cur = if settled {
        // A measured effect is a mismatch of the nominal model whatever the dynamics show.
        out.mismatch = true;
        let cur = redundant_beside_measured(data, cur, settings, &mut out);
        rounds(data, cur, settings, (None, None), progress, &mut out)
    } else {
        cur
    };
    out.cur = cur;
    out
}

/// The model `cur` once the measured effects are placed ([`measured::settle`]), less an
/// effect each of them makes redundant ([`backward_step`]): an effect found beside the
/// stand-in a measured effect replaced may have explained only what the stand-in left. On
/// the Pioneer-like robot with a sagging battery and a larger right tyre (hold-out seed 1063,
/// looked at after its report) the search named the drift, a weak amplifier for the tyre and a
/// turning loss (`slip`, k_ω = 0.045 s/m) for what the amplifier left; the heading's tyre
/// replaced the amplifier, and without the turning loss the validation cost then rises by
/// 3.8 % only.
fn redundant_beside_measured(
    data: &Data,
    mut cur: Current,
    settings: &DiagnoseSettings,
    out: &mut Outcome,
) -> Current {
    for (c, _) in &data.measured {
        if cur.candidates.contains(c) {
            let mut tried = Vec::new();
            cur = backward_step(data, cur, *c, settings.min_improvement, out, &mut tried).0;
        }
    }
    cur
}

/// The better of the greedy search `greedy` and the search from its first round's runner-up
/// `other` ([`run`]): `other` where its final model explains the validation blocks better for
/// its parameters (Akaike's criterion over both models' judged samples, n_eff ln(J_other /
/// J_greedy) + 2 (k_other − k_greedy) < 0, k the free parameters), its refusals then led by
/// the greedy search's effects it does not hold; where it names the same effects, its better
/// fit of them. (Until the same effects were kept from the better path, seed 1110's
/// Pioneer-like rate limit, looked at after its report, stayed at the greedy fit's side
/// valley: θ2 0.445 for ≈ 0.25, the ω level +37 %, ω 85.3 %; the runner-up's path, a dead
/// time removed once the limit was in, had fitted the same limit within 0.1 % at 99.9 %.)
/// A dead time beside
/// a voltage clamp on the Pioneer-like robot (hold-out seed 1057, 53.5 ms, looked at after
/// its report): the first round's rate limit outscored the
/// dead time (information −33.2 against −26.0), the dead time beside it fitted to 21.6 ms and
/// was refused, and the search ended at v 95.2 %, ω 92.6 %, unexplained; from the dead time, the
/// clamp follows and the fits reach 100.0 %, 99.9 %.
fn second_path(data: &Data, greedy: Outcome, mut other: Outcome) -> Outcome {
    let judged = data.judged(&[&greedy.cur, &other.cur]);
    let (fits_g, cost_g) = data.validate_on(&greedy.cur.sim, &judged);
    let (fits_o, cost_o) = data.validate_on(&other.cur.sim, &judged);
    let n_eff = data.effective_samples(&greedy.cur.sim);
    let free = |c: &Current| (c.theta.len() - c.pinned.len()) as f64;
    let score = n_eff * (cost_o / cost_g).ln() + 2.0 * (free(&other.cur) - free(&greedy.cur));
    let named =
        |o: &Outcome| -> Vec<String> { o.findings.iter().map(|f| f.effect.clone()).collect() };
    let (ours, theirs) = (named(&greedy), named(&other));
    let mut sorted = [ours.clone(), theirs.clone()];
    sorted.iter_mut().for_each(|n| n.sort());
    let better = score < 0.0; // false for a NaN score
    if !better {
        return greedy;
    }
    // The same effects are the same explanation, the other path's fit a better one of it.
    if sorted[0] == sorted[1] {
        return other;
    }
    let gone: Vec<&str> = (ours.iter())
        .filter(|e| !theirs.contains(e))
        .map(String::as_str)
        .collect();
    let list = |n: &[String]| {
        if n.is_empty() {
            "nothing".into()
        } else {
            n.join(" + ")
        }
    };
    if !gone.is_empty() {
        other.rejected.insert(
            0,
            Rejected {
                effect: gone.join(" + "),
                reason: format!(
                    "the greedy search ends at {} with v {:.1} %, ω {:.1} %; the search from \
                     its first round's runner-up ends at {} with v {:.1} %, ω {:.1} %, better \
                     for its parameters (information {score:.1})",
                    list(&ours),
                    fits_g.v.fit_percent,
                    fits_g.w.fit_percent,
                    list(&theirs),
                    fits_o.v.fit_percent,
                    fits_o.w.fit_percent
                ),
            },
        );
    }
    other
}
