//! The output-error fit's uncertainty at θ̂: the sandwich covariance of the module doc of
//! [`super`] (Newey–West weights over the residuals' correlation length), the channels' noise
//! levels and the bound states.

use nalgebra::{DMatrix, DVector};
use wheelid_core::{BoundState, DynamicModel, Recording, Sensitivities, SolveError, SolveStatus};

use super::lm::Termination;
use super::problem::{Evaluated, Problem, Raw};
use super::{OutputError, OutputErrorFit};
use crate::ols;

/// The last iteration's sensitivities serve the covariance if they were taken within this
/// distance of θ̂, relative to ‖u‖ (the final step of a converged minimisation is far smaller;
/// sensitivities a relative 1e-4 away change the standard errors in their fourth digit at
/// most, for the smooth simulations this fits).
const JACOBIAN_REUSE: f64 = 1e-4;

/// The fit at the problem's θ̂: the sandwich covariance (module doc) from the last
/// iteration's sensitivities when they were taken there, else new ones, read where they lie
/// (the weighted Jacobian is formed only when [`OutputError::keep_jacobian`] asks for it);
/// `evaluations` and `seconds` are the caller's to fill.
pub(super) fn uncertainty<M: DynamicModel + ?Sized>(
    settings: &OutputError,
    problem: Problem<'_, M>,
    u: DVector<f64>,
    point: Evaluated,
    termination: Termination,
) -> Result<OutputErrorFit, SolveError> {
    let Evaluated { raw, sims } = point;
    let raw = &raw;
    let (model, recordings) = (problem.model, problem.recs);
    let (p, s) = (problem.p(), problem.nch());
    let (rows, unknowns) = (problem.rows, problem.unknowns());
    let status = match termination {
        Termination::LostPatience => SolveStatus::IterationLimit,
        Termination::NoImprovementPossible => SolveStatus::AlmostSolved,
        Termination::Converged => SolveStatus::Solved,
    };
    let theta = problem.theta_of(&u);
    let noise_std = channel_std(raw, &problem.mask, rows, unknowns);
    let non_finite = || SolveError::Numerical("non-finite sensitivities at θ̂".into());
    problem
        .sensitivities_at(&u, JACOBIAN_REUSE, &sims)
        .ok_or_else(non_finite)?;
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
    let keep: Vec<usize> = (0..problem.columns())
        .filter(|&j| j >= p || bound_state[j] == BoundState::Free)
        .collect();
    let name_refs: Vec<&str> = keep.iter().map(|&j| names[j].as_str()).collect();
    let full = kept_covariance(&problem, &keep, &name_refs, &e, lags)?;
    let mut covariance = DMatrix::zeros(p, p);
    for (a, &i) in keep.iter().enumerate().filter(|(_, i)| **i < p) {
        for (b, &j) in keep.iter().enumerate().filter(|(_, j)| **j < p) {
            covariance[(i, j)] = full[(a, b)];
        }
    }
    let initial = (0..recordings.len())
        .map(|r| problem.initial_of(&u, r))
        .collect();
    // The residuals' Jacobian −w_c ∂ŷ/∂(θ, x0) back to plain sensitivities, when asked for.
    let jacobian = match settings.keep_jacobian {
        true => {
            let mut jac = problem
                .jacobian_theta(&u, JACOBIAN_REUSE, &sims)
                .ok_or_else(non_finite)?;
            for (i, mut row) in jac.row_iter_mut().enumerate() {
                row *= -1.0 / problem.weight[i % s];
            }
            Some(jac)
        }
        false => None,
    };
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
        residuals: rows,
        evaluations: 0,
        status,
        bound_state,
        correlation_lags: lags,
        jacobian,
        simulated: sims,
        seconds: 0.0,
    })
}

/// The sandwich covariance (module doc) of the unknowns `keep` (named `names`) from the cached
/// sensitivities at θ̂ and the weighted residuals `e`, over `lags` instants.
///
/// # Errors
/// [`SolveError::RankDeficient`] if the data cannot separate the kept unknowns;
/// [`SolveError::Numerical`] if no sensitivities are cached.
fn kept_covariance<M: DynamicModel + ?Sized>(
    problem: &Problem<'_, M>,
    keep: &[usize],
    names: &[&str],
    e: &DVector<f64>,
    lags: usize,
) -> Result<DMatrix<f64>, SolveError> {
    let cache = problem.last_sensitivities.borrow();
    let (_, sens) = cache
        .as_ref()
        .ok_or_else(|| SolveError::Numerical("no sensitivities at θ̂".into()))?;
    let jac = JacobianRows {
        sens,
        weight: &problem.weight,
        index: &problem.index,
        offsets: &problem.offsets,
        p: problem.p(),
        s: problem.nch(),
        keep,
    };
    let row = |q: usize, out: &mut [f64]| {
        jac.row(q, &mut out[..keep.len()]);
        out[keep.len()] = e[q];
    };
    let d = ols::decompose_rows(problem.rows, names, jac.column_norms(), 1e-12, &row)?;
    Ok(sandwich(&d, &jac, e, &problem.spans(), lags, problem.rows))
}

/// The weighted Jacobian of the residuals in (θ, x0) — row `offsets[r] + i·s + c` is
/// −w_c ∂ŷ_c(t_k)/∂(θ, x0), k = `index[r][i]` — in the columns `keep`, read from the
/// sensitivities where they lie.
struct JacobianRows<'a> {
    sens: &'a [Sensitivities],
    weight: &'a [f64],
    index: &'a [Vec<usize>],
    offsets: &'a [usize],
    p: usize,
    s: usize,
    keep: &'a [usize],
}

impl JacobianRows<'_> {
    /// The recording that row `q` belongs to.
    fn recording(&self, q: usize) -> usize {
        self.offsets.partition_point(|&o| o <= q).saturating_sub(1)
    }
    /// Row `q` of recording `r` in the kept columns, into `out`.
    fn row_of(&self, r: usize, q: usize, out: &mut [f64]) {
        let (p, s) = (self.p, self.s);
        let local = q - self.offsets[r];
        let (i, c) = (local / s, local % s);
        let k = self.index[r][i];
        let w = self.weight[c];
        let (st, si) = (&self.sens[r].theta[c], &self.sens[r].initial[c]);
        for (o, &j) in out.iter_mut().zip(self.keep) {
            *o = if j < p {
                -w * st[(k, j)]
            } else if (j - p) / s == r {
                -w * si[(k, (j - p) % s)]
            } else {
                0.0
            };
        }
    }
    /// Row `q` in the kept columns, into `out`.
    fn row(&self, q: usize, out: &mut [f64]) {
        self.row_of(self.recording(q), q, out);
    }
    /// The kept columns' norms (1 for a zero column, which then shows as rank loss), as
    /// [`ols`] scales them: w_c² Σ_k (∂ŷ_c(t_k)/∂·)² summed over the rows in the cost, from
    /// each sensitivity column where it lies.
    fn column_norms(&self) -> DVector<f64> {
        let (p, s) = (self.p, self.s);
        let norm2 = |j: usize| -> f64 {
            let mut sum = 0.0;
            for (r, sens) in self.sens.iter().enumerate() {
                if j >= p && (j - p) / s != r {
                    continue;
                }
                for c in 0..s {
                    let m = if j < p {
                        &sens.theta[c]
                    } else {
                        &sens.initial[c]
                    };
                    let col = m.column(if j < p { j } else { (j - p) % s });
                    let w2 = self.weight[c] * self.weight[c];
                    sum += w2 * self.index[r].iter().map(|&k| col[k] * col[k]).sum::<f64>();
                }
            }
            sum
        };
        DVector::from_iterator(
            self.keep.len(),
            self.keep.iter().map(|&j| {
                let n = norm2(j).sqrt();
                if n > 0.0 && n.is_finite() { n } else { 1.0 }
            }),
        )
    }
}

/// The sandwich covariance of the module doc: bread from the SVD of the weighted Jacobian
/// (J = U Σ Vᵀ D with D its column scaling), meat from the per-instant scores
/// G_k = Σ_c J[(k, c), :]ᵀ e_(k, c) of each recording with Bartlett weights over `lags`
/// instants (never across recordings; `spans` gives each one's first row and samples), scaled
/// by N/(N − P), N the residuals in the cost (`rows`).
fn sandwich(
    d: &ols::Decomposition,
    jac: &JacobianRows<'_>,
    e: &DVector<f64>,
    spans: &[(usize, usize)],
    lags: usize,
    rows: usize,
) -> DMatrix<f64> {
    let (k, nch) = (jac.keep.len(), jac.s);
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
        let r = jac.recording(off);
        let g = |t: usize, out: &mut [f64], buf: &mut Vec<f64>| {
            buf.resize(k, 0.0);
            out.fill(0.0);
            for c in 0..nch {
                let q = off + t * nch + c;
                jac.row_of(r, q, buf);
                for (o, b) in out.iter_mut().zip(buf.iter()) {
                    *o += b * e[q];
                }
            }
        };
        // A long recording's instants in runs on the available cores.
        let parts = if n >= 100_000 {
            rayon::current_num_threads()
        } else {
            1
        };
        meat += ols::bartlett_meat_parts(n, k, lags, parts, g);
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
