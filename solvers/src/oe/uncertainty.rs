//! The output-error fit's uncertainty at θ̂: the sandwich covariance of the module doc of
//! [`super`] (Newey–West weights over the residuals' correlation length), the channels' noise
//! levels and the bound states.

use std::borrow::Cow;

use nalgebra::{DMatrix, DVector};
use wheelid_core::{BoundState, DynamicModel, LinearProblem, Recording, SolveError, SolveStatus};

use super::lm::Termination;
use super::problem::{Problem, Raw};
use super::{OutputError, OutputErrorFit};
use crate::ols;

/// The last iteration's sensitivities serve the covariance if they were taken within this
/// distance of θ̂, relative to ‖u‖ (the final step of a converged minimisation is far smaller;
/// sensitivities a relative 1e-4 away change the standard errors in their fourth digit at
/// most, for the smooth simulations this fits).
const JACOBIAN_REUSE: f64 = 1e-4;

/// The fit at the problem's θ̂: the sandwich covariance (module doc) from the last
/// iteration's Jacobian when it was taken there, else a new one; `evaluations` and
/// `seconds` are the caller's to fill.
pub(super) fn uncertainty<M: DynamicModel + ?Sized>(
    settings: &OutputError,
    problem: Problem<'_, M>,
    u: DVector<f64>,
    raw: &Raw,
    termination: Termination,
) -> Result<OutputErrorFit, SolveError> {
    let (model, recordings) = (problem.model, problem.recs);
    let (p, s) = (problem.p(), problem.nch());
    let (rows, unknowns) = (problem.rows, problem.unknowns());
    let active = rows;
    let status = match termination {
        Termination::LostPatience => SolveStatus::IterationLimit,
        Termination::NoImprovementPossible => SolveStatus::AlmostSolved,
        Termination::Converged => SolveStatus::Solved,
    };
    // Uncertainty at θ̂ (module doc), with the sensitivities of the last iteration if they
    // were taken at θ̂ or within the last, converged step of it.
    let theta = problem.theta_of(&u);
    let noise_std = channel_std(raw, &problem.mask, active, unknowns);
    let jac = problem
        .jacobian_theta(&u, JACOBIAN_REUSE)
        .ok_or_else(|| SolveError::Numerical("non-finite sensitivities at θ̂".into()))?;
    // Not held beside the Jacobian's copies below.
    problem.last_sensitivities.replace(None);
    let e = problem.weighted_rows(raw);
    let longest = recordings.iter().map(Recording::len).max().unwrap_or(0);
    let lags = settings
        .correlation_lags
        .unwrap_or_else(|| (4.0 * (longest as f64 / 100.0).powf(2.0 / 9.0)).floor() as usize);
    let names = settings.unknown_names(model, recordings.len());
    // Parameters pinned on a bound (decided in u, where the transform is flat) take no part
    // in the covariance: their columns are dropped and their standard error is 0.
    let bound_state: Vec<BoundState> = problem
        .transform
        .iter()
        .zip(u.iter())
        .map(|(t, &x)| t.bound_state(x))
        .collect();
    let keep: Vec<usize> = (0..jac.ncols())
        .filter(|&j| j >= p || bound_state[j] == BoundState::Free)
        .collect();
    let jac_free = if keep.len() == jac.ncols() {
        Cow::Borrowed(&jac)
    } else {
        Cow::Owned(jac.select_columns(keep.iter()))
    };
    let name_refs: Vec<&str> = keep.iter().map(|&j| names[j].as_str()).collect();
    let lp = LinearProblem {
        x: jac_free.as_ref(),
        y: &e,
        names: &name_refs,
        bounds: None,
        correlation_lags: 0,
    };
    let d = ols::decompose(&lp, 1e-12)?;
    let full = sandwich(&d, jac_free.as_ref(), &e, &problem.spans(), s, lags, active);
    let mut covariance = DMatrix::zeros(p, p);
    for (a, &i) in keep.iter().enumerate().filter(|(_, i)| **i < p) {
        for (b, &j) in keep.iter().enumerate().filter(|(_, j)| **j < p) {
            covariance[(i, j)] = full[(a, b)];
        }
    }
    let initial = (0..recordings.len())
        .map(|r| problem.initial_of(&u, r))
        .collect();
    drop(jac_free);
    // The residuals' Jacobian −w_c ∂ŷ/∂(θ, x0) back to plain sensitivities.
    let mut jacobian = jac;
    for (i, mut row) in jacobian.row_iter_mut().enumerate() {
        row *= -1.0 / problem.weight[i % s];
    }
    Ok(OutputErrorFit {
        std_err: covariance
            .diagonal()
            .iter()
            .map(|v| v.max(0.0).sqrt())
            .collect(),
        covariance,
        theta,
        initial,
        noise_std,
        cost: e.norm_squared(),
        residuals: active,
        evaluations: 0,
        status,
        bound_state,
        correlation_lags: lags,
        jacobian,
        seconds: 0.0,
    })
}

/// The sandwich covariance of the module doc: bread from the SVD of the weighted Jacobian
/// (J = U Σ Vᵀ D with D its column scaling), meat from the per-instant scores
/// G_k = Σ_c J[(k, c), :]ᵀ e_(k, c) of each recording with Bartlett weights over `lags`
/// instants (never across recordings; `spans` gives each one's first row and samples), scaled
/// by N/(N − P), N the residuals in the cost (`rows`).
fn sandwich(
    d: &ols::Decomposition,
    jac: &DMatrix<f64>,
    e: &DVector<f64>,
    spans: &[(usize, usize)],
    nch: usize,
    lags: usize,
    rows: usize,
) -> DMatrix<f64> {
    let k = jac.ncols();
    // H⁻¹ = D⁻¹ V Σ⁻² Vᵀ D⁻¹.
    let mut a = d.v_t.transpose();
    for (j, mut c) in a.column_iter_mut().enumerate() {
        c /= d.sv[j] * d.sv[j];
    }
    let mut h_inv = a * &d.v_t;
    for i in 0..k {
        for j in 0..k {
            h_inv[(i, j)] /= d.scales[i] * d.scales[j];
        }
    }
    let mut meat = DMatrix::zeros(k, k);
    for &(off, n) in spans {
        let g = DMatrix::from_fn(n, k, |t, j| {
            (0..nch)
                .map(|c| jac[(off + t * nch + c, j)] * e[off + t * nch + c])
                .sum::<f64>()
        });
        meat += ols::bartlett_meat(&g, lags);
    }
    let dof = rows as f64 / (rows - k).max(1) as f64;
    &h_inv * meat * &h_inv * dof
}

/// Residual standard deviation per channel over the samples in the cost, with the degrees of
/// freedom shared out in proportion to the channel's share of the residuals.
pub(super) fn channel_std(raw: &Raw, mask: &[Vec<bool>], rows: usize, unknowns: usize) -> Vec<f64> {
    let nch = raw.first().map_or(0, Vec::len);
    let dof_scale = rows as f64 / (rows - unknowns).max(1) as f64;
    (0..nch)
        .map(|c| {
            let (ss, n) = raw
                .iter()
                .zip(mask)
                .fold((0.0, 0usize), |(ss, n), (per, m)| {
                    let kept = per[c].iter().zip(m).filter(|(_, b)| **b);
                    let (a, b) = kept.fold((0.0, 0), |(a, b), (x, _)| (a + x * x, b + 1));
                    (ss + a, n + b)
                });
            (ss / n.max(1) as f64 * dof_scale).sqrt()
        })
        .collect()
}
