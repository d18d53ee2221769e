//! Step 7 of the diagnosis: accept a fitted candidate only on validation evidence, with
//! significant and plausible parameters, and its fingerprint gone.

use super::*;

/// Significance and plausibility of a fitted candidate ([`wheelid_core::Effect::plausible`]
/// for each free parameter, then together); `Err` says why not.
pub(super) fn check_candidate(
    data: &Data,
    new: &Current,
    c: Candidate,
) -> std::result::Result<(), String> {
    let base = new.theta.len() - c.params().len();
    let fit = FitData {
        recordings: &data.recs,
        theta: &new.theta,
        covariance: &new.covariance,
        base,
    };
    for j in (0..c.params().len()).filter(|j| !new.pinned.contains(&(base + j))) {
        c.effect()
            .plausible(j, new.theta[base + j], new.std_err[base + j], &fit)?;
    }
    c.effect().plausible_together(&fit)
}

/// What a verdict is judged against: the model before, the round's nominees, the Jacobian
/// and its basis, the settings.
pub(super) struct Context<'a> {
    pub(super) data: &'a Data,
    pub(super) cur: &'a Current,
    pub(super) nominees: &'a [Nominee],
    pub(super) nominated: &'a [bool],
    pub(super) jacobian: &'a DMatrix<f64>,
    pub(super) q: &'a DMatrix<f64>,
    pub(super) settings: &'a DiagnoseSettings,
}

/// Accepts nominee `i` fitted into `new` when: the validation cost drops by at least
/// `min_improvement`, no channel's validation fit falls by more than a point, its parameters
/// pass [`check_candidate`], and its fingerprint is gone from the new residual (no longer
/// significant, or at least halved — judged net of the other nominees' patterns, since with
/// two effects present the other one leaves a trace along this one's). Returns the new model,
/// its validation fits and the relative drop of the validation cost.
///
/// # Errors
/// The reason it is turned down, for the report.
pub(super) fn verdict(
    cx: &Context<'_>,
    i: usize,
    new: Current,
) -> std::result::Result<(Current, Channels, f64), String> {
    let (data, settings) = (cx.data, cx.settings);
    let n = &cx.nominees[i];
    let c = n.pattern.candidate;
    let (before, cost_before) = data.validate(&cx.cur.sim);
    let (after, cost) = data.validate(&new.sim);
    let drop = 1.0 - cost / cost_before;
    if drop < settings.min_improvement {
        return Err(format!(
            "the validation cost drops by {:.1} % only (< {:.0} %)",
            100.0 * drop,
            100.0 * settings.min_improvement
        ));
    }
    for (name, b, a) in [
        ("v", before.v.fit_percent, after.v.fit_percent),
        ("ω", before.w.fit_percent, after.w.fit_percent),
    ] {
        // A channel constant over the validation blocks has no fit % (NaN).
        if b.is_finite() && (a.is_nan() || a < b - 1.0) {
            return Err(format!(
                "{name}'s validation fit falls from {b:.1} % to {a:.1} %"
            ));
        }
    }
    check_candidate(data, &new, c)?;
    let frame = data.frame();
    let e_new = frame.residuals(&new.sim);
    let others: Vec<&DMatrix<f64>> = cx
        .nominees
        .iter()
        .zip(cx.nominated)
        .filter(|(m, d)| **d && m.pattern.candidate != c)
        .map(|(m, _)| &m.pattern.s)
        .collect();
    let q_net = if others.is_empty() {
        cx.q.clone()
    } else {
        let mut cols: Vec<nalgebra::DVector<f64>> =
            cx.jacobian.column_iter().map(|x| x.into_owned()).collect();
        for m in others {
            cols.extend(m.column_iter().map(|x| x.into_owned()));
        }
        score::basis(&DMatrix::from_columns(&cols))
    };
    if let Some(s) = score::score(&frame, &q_net, &n.pattern.s, &e_new, data.hac_lags())
        && s.p_value * (n.pattern.grid as f64) < settings.alpha
        && s.stat > FINGERPRINT_LEFT * n.score.stat
    {
        return Err(format!(
            "its fingerprint stays (χ²({}) = {:.1} of {:.1}, p = {:.1e})",
            s.dof, s.stat, n.score.stat, s.p_value
        ));
    }
    Ok((new, after, drop))
}
