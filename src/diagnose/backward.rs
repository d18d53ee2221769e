//! The backward step of the forward selection: effects a newly accepted one makes redundant
//! leave the model ([`backward_step`]).

use super::search::Outcome;
use super::*;

/// Backward step: each effect other than `added` that it makes redundant (without it the
/// validation cost rises by less than `min_improvement`) is removed, and joins `tried`; after
/// a removal the others are judged again against the smaller model, until none is redundant.
/// Returns the model and how many effects left it. Removing only the first redundant one left
/// a `coulomb_friction` of no size (w_coulomb = 0.00000 ± 0.00036 rad/s) named beside a rate
/// limit on the Pioneer-like robot (hold-out seed 1107, looked at after its report): the
/// search from the first round's runner-up took the friction, then a dead time, then the rate
/// limit, whose backward step removed the dead time and stopped.
pub(super) fn backward_step(
    data: &Data,
    mut cur: Current,
    added: Candidate,
    min_improvement: f64,
    out: &mut Outcome,
    tried: &mut Vec<Candidate>,
) -> (Current, usize) {
    let mut removed = 0;
    loop {
        match remove_redundant(data, &cur, added, min_improvement, out, tried) {
            Some(without) => {
                cur = without;
                removed += 1;
            }
            None => return (cur, removed),
        }
    }
}

/// The model `cur` less the last effect other than `added` (or a measured one) without which
/// the validation cost rises by less than `min_improvement` ([`backward_step`]); `None` if
/// there is none.
fn remove_redundant(
    data: &Data,
    cur: &Current,
    added: Candidate,
    min_improvement: f64,
    out: &mut Outcome,
    tried: &mut Vec<Candidate>,
) -> Option<Current> {
    if cur.candidates.len() < 2 {
        return None;
    }
    for k in (0..cur.candidates.len()).rev() {
        // What another sensor measures stays, however little the dynamics show it.
        if cur.candidates[k] == added || data.measurement(cur.candidates[k]).is_some() {
            continue;
        }
        let Ok(without) = remove_candidate(data, cur, k) else {
            continue;
        };
        let judged = data.judged(&[cur, &without]);
        let (_, cost_with) = data.validate_on(&cur.sim, &judged);
        let (_, cost_without) = data.validate_on(&without.sim, &judged);
        let rise = cost_without / cost_with - 1.0;
        if rise < min_improvement {
            let gone = cur.candidates[k];
            out.findings.retain(|f| f.effect != gone.name());
            out.rejected.push(Rejected {
                effect: gone.name().into(),
                reason: if rise < 0.0 {
                    format!(
                        "redundant once {} is in: without it the validation cost falls by \
                         {:.1} %",
                        added.name(),
                        -100.0 * rise
                    )
                } else {
                    format!(
                        "redundant once {} is in: without it the validation cost rises by \
                         {:.1} % only",
                        added.name(),
                        100.0 * rise
                    )
                },
            });
            tried.push(gone);
            return Some(without);
        }
    }
    None
}
