//! Fingerprints: does the residual carry the pattern a candidate physics would imprint on it?
//!
//! For a candidate with parameters β (null value β₀, where the extended model is the current
//! one), its pattern is the change it makes to the free-run output, S = ∂ŷ/∂β at β₀ (forward
//! differences), or, for a limit whose null is at infinity (`velocity_saturation`,
//! `acceleration_limit`), S = ŷ(β_probe) − ŷ(∞) with a probe level read off the data. Part of
//! S can be absorbed by θ and the initial states, so only what is left after projecting out
//! the current model's Jacobian J counts:
//!
//! ```text
//! S⊥ = (I − J J⁺) S,   g = S⊥ᵀ e = Σ_k g_k,   LM = gᵀ V⁻¹ g ~ χ²(q),
//! V = Σ_r n_r/((n_r − L) (L + 1)) Σ_t B_t B_tᵀ,  B_t = Σ_{k=t}^{t+L} g_k,   β̂ = (S⊥ᵀ S⊥)⁻¹ S⊥ᵀ e,
//! ```
//!
//! the Lagrange-multiplier (score) test of β = β₀ (Engle 1984), with rows weighted by 1/σ_c,
//! g_k the per-instant scores, and V the Bartlett-kernel (Newey–West) estimate of their
//! long-run covariance over L instants within each recording, computed as overlapping batch
//! means of L + 1 instants (equal up to edge terms), so that coloured residuals do not pass for
//! structure. β̂ is one Gauss–Newton step from β₀: the candidate's first guess.
//! `payload_change` has a time that is not identified under the null; its statistic is the
//! largest over a grid of times, with a Bonferroni factor for the grid (Davies 1987).

use nalgebra::{DMatrix, DVector};
use statrs::distribution::{ChiSquared, ContinuousCDF};
use wheelid_core::{DynamicModel, Recording};

/// Simulated outputs of every recording: per recording (v̂, ω̂).
pub(crate) type Outputs = Vec<[Vec<f64>; 2]>;

/// Simulates `model` at `theta` over every recording; `None` if a simulation fails or is not
/// finite.
pub(crate) fn simulate_all(
    model: &dyn DynamicModel,
    theta: &[f64],
    recs: &[Recording],
    initial: &[Vec<f64>],
) -> Option<Outputs> {
    recs.iter()
        .zip(initial)
        .map(|(r, x0)| {
            let y = model.simulate(theta, r, x0).ok()?;
            let [v, w]: [Vec<f64>; 2] = y.try_into().ok()?;
            (v.iter().chain(&w).all(|x| x.is_finite()) && v.len() == r.len()).then_some([v, w])
        })
        .collect()
}

/// The rows of a fit: the training samples of each recording, both channels, weighted 1/σ_c.
pub(crate) struct Frame<'a> {
    pub recs: &'a [Recording],
    pub mask: &'a [Vec<bool>],
    pub weight: [f64; 2],
}

impl Frame<'_> {
    /// Number of rows (training samples × 2).
    pub fn rows(&self) -> usize {
        2 * self.mask.iter().flatten().filter(|&&b| b).count()
    }

    /// The weighted training rows of per-recording outputs (or residuals).
    pub fn flatten(&self, ys: &Outputs) -> DVector<f64> {
        let mut out = Vec::with_capacity(self.rows());
        for (y, m) in ys.iter().zip(self.mask) {
            for k in (0..m.len()).filter(|&k| m[k]) {
                out.push(self.weight[0] * y[0][k]);
                out.push(self.weight[1] * y[1][k]);
            }
        }
        DVector::from_vec(out)
    }

    /// The frame's weighting applied to unweighted rows in its order (sample, then channel),
    /// such as [`OutputErrorFit::jacobian`](wheelid_solvers::OutputErrorFit::jacobian) of a
    /// fit on the same training rows.
    pub fn weigh(&self, rows: &DMatrix<f64>) -> DMatrix<f64> {
        let mut out = rows.clone();
        for (i, mut row) in out.row_iter_mut().enumerate() {
            row *= self.weight[i % 2];
        }
        out
    }

    /// Weighted training residuals y − ŷ.
    pub fn residuals(&self, sim: &Outputs) -> DVector<f64> {
        let e: Outputs = self
            .recs
            .iter()
            .zip(sim)
            .map(|(r, s)| {
                [
                    r.v.iter().zip(&s[0]).map(|(a, b)| a - b).collect(),
                    r.w.iter().zip(&s[1]).map(|(a, b)| a - b).collect(),
                ]
            })
            .collect();
        self.flatten(&e)
    }

    /// Row ranges of each recording (for the per-recording long-run covariance).
    fn spans(&self) -> Vec<std::ops::Range<usize>> {
        let mut at = 0;
        self.mask
            .iter()
            .map(|m| {
                let n = 2 * m.iter().filter(|&&b| b).count();
                at += n;
                at - n..at
            })
            .collect()
    }
}

/// Difference quotient (a − b)/h of two output sets.
pub(crate) fn difference(a: &Outputs, b: &Outputs, h: f64) -> Outputs {
    a.iter()
        .zip(b)
        .map(|(x, y)| [0, 1].map(|c| x[c].iter().zip(&y[c]).map(|(p, q)| (p - q) / h).collect()))
        .collect()
}

/// Jacobian of the weighted training outputs with respect to θ and each recording's initial
/// state (columns: θ, then (v0, ω0) per recording): the model's sensitivities, or forward
/// differences of its simulation if it has none; `None` if a simulation fails.
pub(crate) fn jacobian(
    model: &dyn DynamicModel,
    theta: &[f64],
    initial: &[Vec<f64>],
    base: &Outputs,
    frame: &Frame<'_>,
) -> Option<DMatrix<f64>> {
    let p = theta.len();
    let nrec = frame.recs.len();
    let mut cols: Vec<DVector<f64>> = Vec::with_capacity(p + 2 * nrec);
    // The model's own sensitivities where it has them.
    let mut sens = Vec::with_capacity(nrec);
    for (rec, x0) in frame.recs.iter().zip(initial) {
        match model.simulate_with_sensitivities(theta, rec, x0) {
            Ok(Some((_, s))) => sens.push(s),
            Ok(None) => break,
            Err(_) => return None,
        }
    }
    if sens.len() == nrec {
        let zeros = || -> Outputs {
            frame
                .recs
                .iter()
                .map(|rec| [vec![0.0; rec.len()], vec![0.0; rec.len()]])
                .collect()
        };
        for j in 0..p {
            let d: Outputs = sens
                .iter()
                .map(|s| [0, 1].map(|c| s.theta[c].column(j).iter().copied().collect()))
                .collect();
            cols.push(frame.flatten(&d));
        }
        for (r, s) in sens.iter().enumerate() {
            for i in 0..2 {
                let mut d = zeros();
                d[r] = [0, 1].map(|c| s.initial[c].column(i).iter().copied().collect());
                cols.push(frame.flatten(&d));
            }
        }
        let j = DMatrix::from_columns(&cols);
        return j.iter().all(|x| x.is_finite()).then_some(j);
    }
    for j in 0..p {
        let h = 1e-6 * theta[j].abs().max(1e-3);
        let mut th = theta.to_vec();
        th[j] += h;
        let y = simulate_all(model, &th, frame.recs, initial)?;
        cols.push(frame.flatten(&difference(&y, base, h)));
    }
    for r in 0..nrec {
        for c in 0..2 {
            let h = 1e-6 * initial[r][c].abs().max(1e-3);
            let mut x0 = initial[r].clone();
            x0[c] += h;
            let y = model.simulate(theta, &frame.recs[r], &x0).ok()?;
            let mut d: Outputs = frame
                .recs
                .iter()
                .map(|rec| [vec![0.0; rec.len()], vec![0.0; rec.len()]])
                .collect();
            for ch in 0..2 {
                for k in 0..frame.recs[r].len() {
                    d[r][ch][k] = (y[ch][k] - base[r][ch][k]) / h;
                }
            }
            cols.push(frame.flatten(&d));
        }
    }
    Some(DMatrix::from_columns(&cols))
}

/// An orthonormal basis of the column space of J (thin SVD, relative tolerance 1e-10).
pub(crate) fn basis(j: &DMatrix<f64>) -> DMatrix<f64> {
    // Scale the columns first: θ and initial states have unrelated units.
    let mut js = j.clone();
    for mut c in js.column_iter_mut() {
        let n = c.norm();
        if n > 0.0 {
            c /= n;
        }
    }
    let svd = js.svd(true, false);
    let Some(u) = svd.u else {
        return DMatrix::zeros(j.nrows(), 0);
    };
    let smax = svd.singular_values.max();
    let keep: Vec<usize> = (0..svd.singular_values.len())
        .filter(|&i| svd.singular_values[i] > 1e-10 * smax)
        .collect();
    u.select_columns(keep.iter())
}

/// The result of one score test.
#[derive(Debug, Clone)]
pub(crate) struct Score {
    /// LM statistic.
    pub stat: f64,
    /// Degrees of freedom (independent pattern columns).
    pub dof: usize,
    /// p-value (χ² upper tail).
    pub p_value: f64,
    /// One Gauss–Newton step per column.
    pub beta: Vec<f64>,
    /// What that step would take off ‖e‖² (the weighted training residual's sum of squares
    /// along the pattern net of `q`: gᵀ (SₚᵀSₚ)⁻¹ g) — the effect size the pattern still
    /// explains, in the units of the training cost.
    pub explained: f64,
}

/// The score test of the pattern columns `s` (rows as `frame`) against weighted residuals `e`,
/// given an orthonormal basis `q` of what θ and the initial states absorb; `lags` instants of
/// Newey–West weights. `None` if the pattern vanishes after the projection.
pub(crate) fn score(
    frame: &Frame<'_>,
    q: &DMatrix<f64>,
    s: &DMatrix<f64>,
    e: &DVector<f64>,
    lags: usize,
) -> Option<Score> {
    let proj = q.transpose() * s;
    let sp = s - q * proj;
    let k = sp.ncols();
    // Drop columns that θ absorbs entirely.
    let keep: Vec<usize> = (0..k)
        .filter(|&j| sp.column(j).norm() > 1e-6 * s.column(j).norm().max(1e-300))
        .collect();
    if keep.is_empty() {
        return None;
    }
    let sp = sp.select_columns(keep.iter());
    let k = sp.ncols();
    let spans = frame.spans();
    let mut meat = DMatrix::zeros(k, k);
    let mut g_total = DVector::zeros(k);
    for span in spans {
        let n = span.len() / 2;
        // Per-instant scores g_t (row-major n × k), and their running sums (n + 1 rows).
        let mut pre = vec![0.0; (n + 1) * k];
        for t in 0..n {
            let r = span.start + 2 * t;
            for j in 0..k {
                let g = sp[(r, j)] * e[r] + sp[(r + 1, j)] * e[r + 1];
                pre[(t + 1) * k + j] = pre[t * k + j] + g;
            }
        }
        for j in 0..k {
            g_total[j] += pre[n * k + j];
        }
        // Overlapping batch means over windows of m = L + 1 instants: the Bartlett-kernel
        // estimate of Var(Σ g_k) up to edge terms, in O(n k²) instead of O(n L k²).
        // (A span no longer than L + 1 instants: the plain sum of outer products, m = 1.)
        let m = if n > lags + 1 { lags + 1 } else { 1 };
        let windows = (n + 1).saturating_sub(m);
        let mut acc = DMatrix::<f64>::zeros(k, k);
        let mut b = vec![0.0; k];
        for t in 0..windows {
            for (j, bj) in b.iter_mut().enumerate() {
                *bj = pre[(t + m) * k + j] - pre[t * k + j];
            }
            for i in 0..k {
                for j in 0..=i {
                    acc[(i, j)] += b[i] * b[j];
                }
            }
        }
        for i in 0..k {
            for j in 0..i {
                acc[(j, i)] = acc[(i, j)];
            }
        }
        meat += acc * (n as f64 / (windows.max(1) as f64 * m as f64));
    }
    let meat_inv = meat.clone().pseudo_inverse(1e-12 * meat.max().abs()).ok()?;
    let stat = (g_total.transpose() * &meat_inv * &g_total)[(0, 0)].max(0.0);
    let bread = (sp.transpose() * &sp).pseudo_inverse(1e-14).ok()?;
    let beta_kept = &bread * &g_total;
    let explained = g_total.dot(&beta_kept).max(0.0);
    let mut beta = vec![0.0; s.ncols()];
    for (a, &j) in keep.iter().enumerate() {
        beta[j] = beta_kept[a];
    }
    let p_value = ChiSquared::new(k as f64).map_or(1.0, |d| d.sf(stat));
    Some(Score {
        stat,
        dof: k,
        p_value,
        beta,
        explained,
    })
}
