//! Ordinary least squares by singular value decomposition.
//!
//! The columns of X are first scaled to unit norm (X = X̃ D), so that rank and condition number
//! measure identifiability rather than units; then X̃ = U Σ Vᵀ and
//!
//! ```text
//! θ̂ = D⁻¹ V Σ⁻¹ Uᵀ y,       Cov(θ̂) = D⁻¹ V Σ⁻¹ Uᵀ S U Σ⁻¹ Vᵀ D⁻¹
//! ```
//!
//! with S = σ̂² I for independent residuals (σ̂² = RSS/(n − p)), or the Newey–West estimate
//! S = Σ_{|l| ≤ L} (1 − |l|/(L+1)) e_k e_{k+l} (Bartlett kernel) when the problem declares
//! residuals correlated over L samples, as filtered data are. This never forms (XᵀX)⁻¹
//! (eq. 4.5 of the thesis), whose condition number is the square of X's.
//!
//! The Bartlett-weighted sum is computed in O((n + L) p²), not O(n p² L): with g_t = U_tᵀ e_t
//! (zero outside 0 ≤ t < n) and the moving sums B_s = Σ_{t=s}^{s+L} g_t, s = −L … n−1,
//!
//! ```text
//! Σ_{|l| ≤ L} (1 − |l|/(L+1)) Σ_t g_t g_{t+l}ᵀ = (1/(L+1)) Σ_s B_s B_sᵀ
//! ```
//!
//! exactly, because the pair (t, u) lies in L + 1 − |t − u| of the windows (the Bartlett
//! kernel is the autocorrelation of a box, Newey & West 1987).
//!
//! A singular value below `rank_tol · σ_max` makes the problem rank-deficient: the error names
//! the parameters with weight in the corresponding right singular vectors.

use nalgebra::{DMatrix, DVector};
use wheelid_core::{BoundState, LinearFit, LinearProblem, SolveError, SolveStatus, Solver};

/// Ordinary least squares (`ols`).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Ols {
    /// Relative singular-value threshold for rank (of the column-normalised X).
    pub rank_tol: f64,
}

impl Default for Ols {
    fn default() -> Self {
        Self { rank_tol: 1e-9 }
    }
}

/// Column norms of X (zero columns keep scale 1 so they show up as rank loss).
pub(crate) fn column_scales(x: &DMatrix<f64>) -> DVector<f64> {
    DVector::from_iterator(
        x.ncols(),
        x.column_iter().map(|c| {
            let n = c.norm();
            if n > 0.0 && n.is_finite() { n } else { 1.0 }
        }),
    )
}

pub(crate) fn check_problem(p: &LinearProblem<'_>) -> Result<(), SolveError> {
    let (n, k) = p.x.shape();
    if p.y.len() != n {
        return Err(SolveError::InvalidProblem(format!(
            "X has {n} rows, y has {}",
            p.y.len()
        )));
    }
    if p.names.len() != k {
        return Err(SolveError::InvalidProblem(format!(
            "{k} columns but {} names",
            p.names.len()
        )));
    }
    if n <= k {
        return Err(SolveError::InvalidProblem(format!(
            "{n} samples cannot determine {k} parameters"
        )));
    }
    if p.x.iter().chain(p.y.iter()).any(|v| !v.is_finite()) {
        return Err(SolveError::InvalidProblem(
            "X or y has a non-finite value".into(),
        ));
    }
    Ok(())
}

/// Everything [`Ols`] computes, reused by the bounded solver for its covariance.
pub(crate) struct Decomposition {
    pub scales: DVector<f64>,
    pub u: DMatrix<f64>,
    pub sv: DVector<f64>,
    pub v_t: DMatrix<f64>,
    pub rank: usize,
    pub cond: f64,
}

pub(crate) fn decompose(p: &LinearProblem<'_>, rank_tol: f64) -> Result<Decomposition, SolveError> {
    let scales = column_scales(p.x);
    let mut xs = p.x.clone();
    for (j, mut c) in xs.column_iter_mut().enumerate() {
        c /= scales[j];
    }
    let svd = xs.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return Err(SolveError::Numerical("SVD did not converge".into()));
    };
    let sv = svd.singular_values;
    let smax = sv.max();
    let rank = sv.iter().filter(|s| **s > rank_tol * smax).count();
    if rank < sv.len() {
        // Parameters with weight > 0.1 in a null-space direction.
        let mut involved = vec![false; sv.len()];
        for (i, s) in sv.iter().enumerate() {
            if *s <= rank_tol * smax {
                for (j, flag) in involved.iter_mut().enumerate() {
                    if v_t[(i, j)].abs() > 0.1 {
                        *flag = true;
                    }
                }
            }
        }
        return Err(SolveError::RankDeficient {
            names: p
                .names
                .iter()
                .zip(involved)
                .filter(|(_, f)| *f)
                .map(|(n, _)| (*n).to_owned())
                .collect(),
            rank,
            p: sv.len(),
        });
    }
    let cond = smax / sv.min();
    Ok(Decomposition {
        scales,
        u,
        sv,
        v_t,
        rank,
        cond,
    })
}

/// Covariance of θ̂ at residuals `e` (see module docs).
pub(crate) fn covariance(d: &Decomposition, e: &DVector<f64>, lags: usize) -> DMatrix<f64> {
    let (n, k) = (d.u.nrows(), d.sv.len());
    // A = D⁻¹ V Σ⁻¹ (k × k); θ̂ = A Uᵀ y, Cov = A (Uᵀ S U) A.
    let mut a = d.v_t.transpose();
    for (j, mut c) in a.column_iter_mut().enumerate() {
        c /= d.sv[j];
    }
    for (i, mut r) in a.row_iter_mut().enumerate() {
        r /= d.scales[i];
    }
    let dof = (n - k).max(1) as f64;
    let meat = if lags == 0 {
        DMatrix::identity(k, k) * (e.norm_squared() / dof)
    } else {
        // Σ_l w_l Σ_t g_t g_{t+l}ᵀ with g_t = U[t,:]ᵀ e_t by moving sums (module doc), scaled
        // by n/(n−k).
        let g = DMatrix::from_fn(n, k, |t, j| d.u[(t, j)] * e[t]);
        bartlett_meat(&g, lags) * (n as f64 / dof)
    };
    &a * meat * a.transpose()
}

/// Σ_{|l| ≤ L} (1 − |l|/(L+1)) Σ_t g_t g_{t+l}ᵀ over the rows g_t of `g` (n × k; the result
/// k × k, L = `lags`), by the moving-window identity of the module doc in O((n + L) k²): the
/// Newey–West meat of least squares, instrumental variables and output error.
pub(crate) fn bartlett_meat(g: &DMatrix<f64>, lags: usize) -> DMatrix<f64> {
    let (n, k) = g.shape();
    let mut m = DMatrix::<f64>::zeros(k, k);
    let mut window = vec![0.0; k];
    // Window s covers t = s … s + L; s runs from −L, so t = s + L enters as s advances and
    // t = s − 1 leaves.
    for enter in 0..n + lags {
        if enter < n {
            for (j, b) in window.iter_mut().enumerate() {
                *b += g[(enter, j)];
            }
        }
        if let Some(leave) = enter.checked_sub(lags + 1) {
            for (j, b) in window.iter_mut().enumerate() {
                *b -= g[(leave, j)];
            }
        }
        for a in 0..k {
            for b in a..k {
                m[(a, b)] += window[a] * window[b];
            }
        }
    }
    for a in 0..k {
        for b in 0..a {
            m[(a, b)] = m[(b, a)];
        }
    }
    m / (lags + 1) as f64
}

impl Solver for Ols {
    fn name(&self) -> &str {
        "ols"
    }

    fn solve(&self, p: &LinearProblem<'_>) -> Result<LinearFit, SolveError> {
        check_problem(p)?;
        let d = decompose(p, self.rank_tol)?;
        let uty = d.u.transpose() * p.y;
        let z = DVector::from_iterator(d.sv.len(), uty.iter().zip(d.sv.iter()).map(|(a, s)| a / s));
        let theta = (d.v_t.transpose() * z).component_div(&d.scales);
        let e = p.y - p.x * &theta;
        let cov = covariance(&d, &e, p.correlation_lags);
        Ok(LinearFit {
            std_err: cov.diagonal().map(|v| v.max(0.0).sqrt()),
            covariance: cov,
            rss: e.norm_squared(),
            n: p.x.nrows(),
            rank: d.rank,
            condition_number: d.cond,
            bound_state: vec![BoundState::Free; theta.len()],
            theta,
            status: SolveStatus::Solved,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn moving_sums_equal_the_direct_bartlett_sum() {
        // The direct O(n k² L) sum of the Newey–West meat, against the moving-window form,
        // for lags shorter and longer than the data.
        let n = 57;
        let u = DMatrix::from_fn(n, 3, |t, j| ((t * 7 + j * 13) % 11) as f64 - 5.0);
        let e = DVector::from_fn(n, |t, _| ((t * 5) % 9) as f64 * 0.1 - 0.4);
        for lags in [1usize, 4, 20, 80] {
            let mut direct = DMatrix::<f64>::zeros(3, 3);
            for t in 0..n {
                for v in 0..n {
                    let l = t.abs_diff(v);
                    if l <= lags {
                        let w = 1.0 - l as f64 / (lags + 1) as f64;
                        for a in 0..3 {
                            for b in 0..3 {
                                direct[(a, b)] += w * u[(t, a)] * e[t] * u[(v, b)] * e[v];
                            }
                        }
                    }
                }
            }
            let g = DMatrix::from_fn(n, 3, |t, j| u[(t, j)] * e[t]);
            let fast = bartlett_meat(&g, lags);
            assert_relative_eq!(fast, direct, max_relative = 1e-12, epsilon = 1e-9);
        }
    }

    #[test]
    fn fits_a_line_through_three_points_with_textbook_errors() {
        // y = a + b x through (0,1), (1,2), (2,4): b = 1.5, a = 5/6; RSS = 1/6,
        // σ² = 1/6, Var(b) = σ²/Σ(x − x̄)² = 1/12, Var(a) = σ²(1/3 + 1/2) = 5/36.
        let x = DMatrix::from_row_slice(3, 2, &[1.0, 0.0, 1.0, 1.0, 1.0, 2.0]);
        let y = DVector::from_vec(vec![1.0, 2.0, 4.0]);
        let p = LinearProblem {
            x: &x,
            y: &y,
            names: &["a", "b"],
            bounds: None,
            correlation_lags: 0,
        };
        let f = Ols::default().solve(&p).expect("solves");
        assert_relative_eq!(f.theta[0], 5.0 / 6.0, max_relative = 1e-12);
        assert_relative_eq!(f.theta[1], 1.5, max_relative = 1e-12);
        assert_relative_eq!(f.rss, 1.0 / 6.0, max_relative = 1e-12);
        assert_relative_eq!(f.std_err[1], (1.0f64 / 12.0).sqrt(), max_relative = 1e-12);
        assert_relative_eq!(f.std_err[0], (5.0f64 / 36.0).sqrt(), max_relative = 1e-12);
    }

    #[test]
    fn rank_deficiency_names_the_inseparable_parameters() {
        // Column 0 constant zero (ω̇ of a constant ω), columns 1, 2 independent.
        let n = 50;
        let x = DMatrix::from_fn(n, 3, |i, j| match j {
            0 => 0.0,
            1 => (i as f64 * 0.1).sin(),
            _ => 1.0,
        });
        let y = DVector::from_fn(n, |i, _| i as f64);
        let p = LinearProblem {
            x: &x,
            y: &y,
            names: &["theta2", "theta5", "theta6"],
            bounds: None,
            correlation_lags: 0,
        };
        match Ols::default().solve(&p) {
            Err(SolveError::RankDeficient { names, rank, p }) => {
                assert_eq!(names, vec!["theta2".to_owned()]);
                assert_eq!((rank, p), (2, 3));
            }
            other => panic!("expected rank deficiency, got {other:?}"),
        }
        // Two proportional columns: both named.
        let x = DMatrix::from_fn(n, 2, |i, j| (i as f64 + 1.0) * (j as f64 + 1.0));
        let p = LinearProblem {
            x: &x,
            y: &y,
            names: &["a", "b"],
            bounds: None,
            correlation_lags: 0,
        };
        assert!(
            matches!(Ols::default().solve(&p), Err(SolveError::RankDeficient { names, .. }) if names.len() == 2)
        );
    }

    #[test]
    fn newey_west_matches_the_textbook_sum_for_a_mean() {
        // For x = 1 (estimating a mean): Var = n/(n−1) · (1/n²) Σ_{|l|≤L} w_l Σ_t e_t e_{t+l},
        // w_l = 1 − |l|/(L+1). Residuals that repeat in blocks widen the error.
        let n = 1000;
        let lags = 10;
        let x = DMatrix::from_fn(n, 1, |_, _| 1.0);
        let y = DVector::from_fn(n, |i, _| ((i / 10) * 7919 % 13) as f64 - 6.0);
        let p0 = LinearProblem {
            x: &x,
            y: &y,
            names: &["c"],
            bounds: None,
            correlation_lags: 0,
        };
        let p1 = LinearProblem {
            correlation_lags: lags,
            ..p0
        };
        let f0 = Ols::default().solve(&p0).expect("ok");
        let f1 = Ols::default().solve(&p1).expect("ok");
        let e: Vec<f64> = y.iter().map(|v| v - f1.theta[0]).collect();
        let mut s = e.iter().map(|v| v * v).sum::<f64>();
        for l in 1..=lags {
            let w = 1.0 - l as f64 / (lags + 1) as f64;
            s += 2.0 * w * (0..n - l).map(|t| e[t] * e[t + l]).sum::<f64>();
        }
        let var = s / (n * n) as f64 * n as f64 / (n - 1) as f64;
        assert_relative_eq!(f1.std_err[0], var.sqrt(), max_relative = 1e-10);
        assert!(f1.std_err[0] > 2.0 * f0.std_err[0]);
    }
}
