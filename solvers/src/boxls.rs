//! Box-constrained least squares through Clarabel (interior point), the thesis's parameter
//! projection (§4.1) applied to the regression:
//!
//! ```text
//! minimise ½ βᵀ(X̃ᵀX̃)β − (X̃ᵀy)ᵀβ   subject to  D·lb ≤ β ≤ D·ub,     θ = D⁻¹β
//! ```
//!
//! in Clarabel's form ½zᵀPz + qᵀz, Az + s = b, s ∈ ℝ₊²ᵏ with A = [I; −I], where X̃ = X D⁻¹ has
//! unit-norm columns. The problem is k × k whatever the number of samples (lifting the residual
//! into the variables would avoid squaring X̃'s condition number, but costs n variables; with unit
//! columns the squared condition number stays far from double precision's limit, and the rank
//! check rejects near-singular problems first). Infinite bounds are allowed (Clarabel drops those rows). Active bounds are
//! met to about 1e-8 by the interior point; the result is clamped onto [lb, ub] and each
//! parameter's [`BoundState`] reported. Standard errors are those of the unconstrained problem
//! evaluated at the bounded residuals.

use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettingsBuilder, DefaultSolver, IPSolver, NonnegativeConeT, SolverStatus, SupportedConeT,
};
use nalgebra::{DMatrix, DVector};
use wheelid_core::{BoundState, LinearFit, LinearProblem, SolveError, SolveStatus, Solver};

use crate::ols::{check_problem, covariance, decompose};

/// Box-bounded least squares (`box`).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BoxLs {
    /// Relative singular-value threshold for rank (as [`crate::Ols`]).
    pub rank_tol: f64,
    /// Clarabel iteration limit.
    pub max_iter: u32,
}

impl Default for BoxLs {
    fn default() -> Self {
        Self {
            rank_tol: 1e-9,
            max_iter: 200,
        }
    }
}

fn to_csc(m: &DMatrix<f64>) -> CscMatrix<f64> {
    let (nr, nc) = m.shape();
    let (mut colptr, mut rowval, mut nzval) = (vec![0], vec![], vec![]);
    for j in 0..nc {
        for i in 0..nr {
            let v = m[(i, j)];
            if v != 0.0 {
                rowval.push(i);
                nzval.push(v);
            }
        }
        colptr.push(rowval.len());
    }
    CscMatrix::new(nr, nc, colptr, rowval, nzval)
}

impl Solver for BoxLs {
    fn name(&self) -> &str {
        "box"
    }

    fn solve(&self, p: &LinearProblem<'_>) -> Result<LinearFit, SolveError> {
        check_problem(p)?;
        let (n, k) = p.x.shape();
        let bounds = checked_bounds(p)?;
        let d = decompose(p, self.rank_tol)?;
        // Scaled variables β = D θ, so X θ = X̃ β.
        let mut xs = p.x.clone();
        for (j, mut c) in xs.column_iter_mut().enumerate() {
            c /= d.scales[j];
        }
        let inf = clarabel::get_infinity();
        let clip = |v: f64| v.clamp(-inf, inf);
        // Normal-equation form on the scaled variables: P = X̃ᵀX̃, q = −X̃ᵀy, A = [I; −I].
        let pm = xs.transpose() * &xs;
        let pm = DMatrix::from_fn(k, k, |i, j| if i <= j { pm[(i, j)] } else { 0.0 });
        let q: Vec<f64> = (-(xs.transpose() * p.y)).iter().copied().collect();
        let mut am = DMatrix::zeros(2 * k, k);
        for j in 0..k {
            am[(j, j)] = 1.0;
            am[(k + j, j)] = -1.0;
        }
        let mut b = Vec::with_capacity(2 * k);
        b.extend(
            bounds
                .iter()
                .zip(d.scales.iter())
                .map(|((_, hi), s)| clip(hi * s)),
        );
        b.extend(
            bounds
                .iter()
                .zip(d.scales.iter())
                .map(|((lo, _), s)| clip(-lo * s)),
        );
        let cones: Vec<SupportedConeT<f64>> = vec![NonnegativeConeT(2 * k)];
        let settings = DefaultSettingsBuilder::default()
            .verbose(false)
            .max_iter(self.max_iter)
            .build()
            .map_err(|e| SolveError::InvalidProblem(e.to_string()))?;
        let mut solver = DefaultSolver::new(&to_csc(&pm), &q, &to_csc(&am), &b, &cones, settings)
            .map_err(|e| SolveError::InvalidProblem(format!("{e:?}")))?;
        solver.solve();
        let status = match solver.solution.status {
            SolverStatus::Solved => SolveStatus::Solved,
            SolverStatus::AlmostSolved => SolveStatus::AlmostSolved,
            SolverStatus::PrimalInfeasible | SolverStatus::AlmostPrimalInfeasible => {
                return Err(SolveError::Infeasible(
                    "Clarabel reports the bounds infeasible".into(),
                ));
            }
            other => {
                return Err(SolveError::Numerical(format!(
                    "Clarabel stopped with {other:?}"
                )));
            }
        };
        let mut theta =
            DVector::from_iterator(k, (0..k).map(|j| solver.solution.x[j] / d.scales[j]));
        let mut state = vec![BoundState::Free; k];
        for j in 0..k {
            let (lo, hi) = bounds[j];
            let tol = 1e-6 * (1.0 + theta[j].abs());
            if theta[j] <= lo + tol {
                theta[j] = lo;
                state[j] = BoundState::AtLower;
            } else if theta[j] >= hi - tol {
                theta[j] = hi;
                state[j] = BoundState::AtUpper;
            }
        }
        let e = p.y - p.x * &theta;
        let cov = covariance(&d, p.x, &e, p.correlation_lags);
        Ok(LinearFit {
            std_err: cov.diagonal().map(|v| v.max(0.0).sqrt()),
            covariance: cov,
            rss: e.norm_squared(),
            n,
            rank: d.rank,
            condition_number: d.cond,
            bound_state: state,
            theta,
            status,
        })
    }
}

/// The problem's bounds, one (lower, upper) pair per column (±∞ where none).
///
/// # Errors
/// [`SolveError::InvalidProblem`] for a count that does not match the columns;
/// [`SolveError::Infeasible`] for a pair out of order or NaN.
fn checked_bounds(p: &LinearProblem<'_>) -> Result<Vec<(f64, f64)>, SolveError> {
    let k = p.x.ncols();
    let bounds: Vec<(f64, f64)> = match p.bounds {
        Some(b) if b.len() == k => b.to_vec(),
        Some(b) => {
            return Err(SolveError::InvalidProblem(format!(
                "{k} parameters but {} bounds",
                b.len()
            )));
        }
        None => vec![(f64::NEG_INFINITY, f64::INFINITY); k],
    };
    for ((lo, hi), name) in bounds.iter().zip(p.names) {
        if lo.is_nan() || hi.is_nan() || lo > hi {
            return Err(SolveError::Infeasible(format!(
                "{name}: lower {lo} > upper {hi}"
            )));
        }
    }
    Ok(bounds)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Ols;
    use approx::assert_relative_eq;

    fn problem_data() -> (DMatrix<f64>, DVector<f64>) {
        let n = 200;
        let x = DMatrix::from_fn(n, 3, |i, j| {
            let t = i as f64 * 0.05;
            match j {
                0 => (1.3 * t).cos() * 2.0,
                1 => (0.4 * t).sin() * 1e-3,
                _ => 0.5 + 0.1 * (0.7 * t).sin(),
            }
        });
        let theta = DVector::from_vec(vec![0.3, 2.0, 1.0]);
        let y =
            &x * &theta + DVector::from_fn(n, |i, _| 1e-3 * ((i * 7919 % 101) as f64 / 50.0 - 1.0));
        (x, y)
    }

    #[test]
    fn infinite_bounds_equal_ols() {
        let (x, y) = problem_data();
        let p = LinearProblem {
            x: &x,
            y: &y,
            names: &["a", "b", "c"],
            bounds: None,
            correlation_lags: 0,
        };
        let o = Ols::default().solve(&p).expect("ols");
        let b = BoxLs::default().solve(&p).expect("box");
        for j in 0..3 {
            assert_relative_eq!(o.theta[j], b.theta[j], max_relative = 1e-6);
        }
        assert!(b.bound_state.iter().all(|s| *s == BoundState::Free));
    }

    #[test]
    fn an_active_bound_holds_and_matches_the_reduced_problem() {
        let (x, y) = problem_data();
        let bounds = [(0.0, 0.25), (f64::NEG_INFINITY, f64::INFINITY), (0.0, 2.0)];
        let p = LinearProblem {
            x: &x,
            y: &y,
            names: &["a", "b", "c"],
            bounds: Some(&bounds),
            correlation_lags: 0,
        };
        let f = BoxLs::default().solve(&p).expect("box");
        assert_eq!(f.theta[0], 0.25);
        assert_eq!(f.bound_state[0], BoundState::AtUpper);
        // Closed form: with a fixed at 0.25, (b, c) are the OLS fit of y − 0.25·x₀ on x₁, x₂.
        let yr = &y - x.column(0) * 0.25;
        let xr = x.columns(1, 2).into_owned();
        let pr = LinearProblem {
            x: &xr,
            y: &yr,
            names: &["b", "c"],
            bounds: None,
            correlation_lags: 0,
        };
        let r = Ols::default().solve(&pr).expect("ols");
        assert_relative_eq!(f.theta[1], r.theta[0], max_relative = 1e-5);
        assert_relative_eq!(f.theta[2], r.theta[1], max_relative = 1e-5);
    }

    #[test]
    fn crossed_bounds_are_infeasible() {
        let (x, y) = problem_data();
        let bounds = [(1.0, 0.0), (0.0, 1.0), (0.0, 1.0)];
        let p = LinearProblem {
            x: &x,
            y: &y,
            names: &["a", "b", "c"],
            bounds: Some(&bounds),
            correlation_lags: 0,
        };
        assert!(
            matches!(BoxLs::default().solve(&p), Err(SolveError::Infeasible(m)) if m.starts_with("a:"))
        );
    }
}
