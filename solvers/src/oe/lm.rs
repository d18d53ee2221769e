//! Levenberg–Marquardt on the normal equations, for problems whose Jacobian is too tall to
//! store and factor (10⁶ samples × 2 channels) but whose normal equations are small.
//!
//! For residuals e(u) ∈ ℝᴺ with Jacobian J = ∂e/∂u (N × P, P small) the step δ solves
//!
//! ```text
//! (JᵀJ + μ D²) δ = −Jᵀe,        D = diag(d_j),  d_j = max over the iterations of ‖J_{:,j}‖
//! ```
//!
//! (Marquardt 1963 with Moré's 1978 column scaling, so the step does not depend on the units
//! of u), by Cholesky. The linear model predicts the reduction of ‖e‖²
//! `pred = −(2 gᵀδ + δᵀ JᵀJ δ)`, g = Jᵀe; with the actual reduction `act`, the ratio
//! ρ = act/pred accepts the step when ρ > 10⁻⁴ and sets the damping as Nielsen (1999)
//! does: μ ← μ · max(⅓, 1 − (2ρ − 1)³) after an accepted step, μ ← μ·ν, ν ← 2ν after a
//! rejected one; an undamped step that promises less than `ftol` of the cost is not taken (the
//! point is stationary to the tolerance: the Gauss–Newton decrement). It starts undamped (μ = 0, Gauss–Newton, as MINPACK's first trust region of
//! 100 ‖Du‖ in effect does: a warm start is then done in two or three steps) and takes
//! μ = 10⁻⁴ at the first rejected step. The stopping tests are MINPACK's (`lmder`, Moré, Garbow & Hillstrom 1980):
//! both relative reductions at most `ftol` (with ρ ≤ 2), or a scaled step at most `xtol`
//! of the scaled point, ‖Dδ‖ ≤ xtol ‖Du‖.
//!
//! The normal equations lose the digits of cond(J)² that a QR of J keeps; with the column
//! scaling the conditions met here (≤ 10⁴) leave ≥ 8 digits of the step, and the step only
//! has to go downhill: the answer is where the gradient Jᵀe vanishes, whatever the digits of
//! the steps that lead there. Each iteration costs one evaluation of e (a simulation) and,
//! after an accepted step, one of JᵀJ and Jᵀe (a simulation with sensitivities).

use nalgebra::{DMatrix, DVector};

/// A least-squares problem as the minimiser sees it.
pub(super) trait NormalProblem {
    /// What an evaluation leaves for the normal equations and the caller (raw residuals).
    type Point;
    /// Evaluates the residuals at `u`; `None` where they cannot be computed (a model that does
    /// not simulate there), which the minimiser treats as an infinite cost.
    fn evaluate(&self, u: &DVector<f64>) -> Option<Self::Point>;
    /// ‖e‖² at an evaluated point.
    fn cost(&self, point: &Self::Point) -> f64;
    /// JᵀJ (P × P) and Jᵀe (P) at `u`, whose evaluation is `point`; `None` when the Jacobian
    /// is not finite there.
    fn normal_equations(
        &self,
        u: &DVector<f64>,
        point: &Self::Point,
    ) -> Option<(DMatrix<f64>, DVector<f64>)>;
}

/// Stopping tolerances and budget.
#[derive(Debug, Clone, Copy)]
pub(super) struct Settings {
    /// Relative reduction of ‖e‖² (actual and predicted) below which the fit has converged.
    pub ftol: f64,
    /// Relative scaled step below which the fit has converged.
    pub xtol: f64,
    /// Most evaluations of e in one minimisation.
    pub max_evaluations: usize,
}

/// How a minimisation ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Termination {
    /// A stopping test of `ftol` or `xtol` was met.
    Converged,
    /// The evaluation budget ran out first.
    LostPatience,
    /// No step reduces the cost any more, though the tolerances are not met (they are below
    /// what the arithmetic resolves).
    NoImprovementPossible,
}

/// Where a minimisation stopped: the point, its evaluation, the evaluations used, how it
/// ended, and the u of the last normal equations (the caller may reuse them).
pub(super) struct Outcome<P> {
    pub u: DVector<f64>,
    pub point: P,
    pub evaluations: usize,
    pub termination: Termination,
}

/// Why a minimisation could not run.
#[derive(Debug, Clone, PartialEq)]
pub(super) enum Failure {
    /// The start cannot be evaluated.
    Start,
    /// The Jacobian is not finite at an accepted point.
    Jacobian,
}

/// Damping beyond which no step is tried any more.
const MAX_DAMPING: f64 = 1e32;
/// Damping after the first rejected undamped step, relative to D².
const FIRST_DAMPING: f64 = 1e-4;
/// Damping below which the step is Gauss–Newton's again.
const MIN_DAMPING: f64 = 1e-15;
/// Smallest ρ that accepts a step.
const ACCEPT: f64 = 1e-4;

/// Minimises ‖e(u)‖² from `u0`, whose evaluation `start` is given when the caller has it
/// (module doc).
///
/// # Errors
/// [`Failure::Start`] if `u0` cannot be evaluated; [`Failure::Jacobian`] if the normal
/// equations are not finite at a point the minimiser reached.
pub(super) fn minimise<N: NormalProblem>(
    problem: &N,
    u0: DVector<f64>,
    start: Option<N::Point>,
    settings: Settings,
) -> Result<Outcome<N::Point>, Failure> {
    let mut evaluations = 0;
    let mut point = match start {
        Some(p) => p,
        None => {
            evaluations += 1;
            problem.evaluate(&u0).ok_or(Failure::Start)?
        }
    };
    let mut u = u0;
    let mut f = problem.cost(&point);
    if !f.is_finite() {
        return Err(Failure::Start);
    }
    let (mut a, mut g) = problem
        .normal_equations(&u, &point)
        .ok_or(Failure::Jacobian)?;
    let mut d = scaling(&a, None);
    // Gauss–Newton first (MINPACK's first trust region, 100 ‖Du‖, is as good as unbounded);
    // damping from the first rejected step on.
    let (mut mu, mut nu) = (0.0, 2.0);
    let end = |u, point, evaluations, termination| Outcome {
        u,
        point,
        evaluations,
        termination,
    };
    loop {
        if f == 0.0 {
            return Ok(end(u, point, evaluations, Termination::Converged));
        }
        let Some(delta) = step(&a, &g, &d, mu) else {
            (mu, nu) = (damp(mu, nu), nu * 2.0);
            if mu > MAX_DAMPING {
                return Ok(end(
                    u,
                    point,
                    evaluations,
                    Termination::NoImprovementPossible,
                ));
            }
            continue;
        };
        if evaluations >= settings.max_evaluations {
            return Ok(end(u, point, evaluations, Termination::LostPatience));
        }
        let pred = -(2.0 * g.dot(&delta) + delta.dot(&(&a * &delta)));
        // The Gauss–Newton decrement: when even the undamped step promises less than `ftol`
        // of the cost, the point is stationary to the tolerance, and no evaluation is spent
        // to confirm it (the Newton-decrement rule, Boyd & Vandenberghe 2004, §9.5.1).
        if mu == 0.0 && pred <= settings.ftol * f {
            return Ok(end(u, point, evaluations, Termination::Converged));
        }
        let scaled_step = d.component_mul(&delta).norm();
        let scaled_point = d.component_mul(&u).norm();
        let trial = &u + &delta;
        evaluations += 1;
        let evaluated = problem.evaluate(&trial);
        let ft = evaluated
            .as_ref()
            .map_or(f64::INFINITY, |p| problem.cost(p))
            .max(0.0);
        let ft = if ft.is_finite() { ft } else { f64::INFINITY };
        let rho = if pred > 0.0 { (f - ft) / pred } else { 0.0 };
        let (act_rel, pred_rel) = ((1.0 - ft / f).abs(), pred.max(0.0) / f);
        let accepted = rho > ACCEPT;
        if let (true, Some(p)) = (accepted, evaluated) {
            (u, f, point) = (trial, ft, p);
            mu *= (1.0 - (2.0 * rho - 1.0).powi(3)).max(1.0 / 3.0);
            if mu < MIN_DAMPING {
                mu = 0.0;
            }
            nu = 2.0;
        } else {
            (mu, nu) = (damp(mu, nu), nu * 2.0);
        }
        let converged = (act_rel <= settings.ftol && pred_rel <= settings.ftol && rho <= 2.0)
            || scaled_step <= settings.xtol * scaled_point;
        if converged {
            return Ok(end(u, point, evaluations, Termination::Converged));
        }
        if !accepted && (mu > MAX_DAMPING || pred_rel <= f64::EPSILON) {
            return Ok(end(
                u,
                point,
                evaluations,
                Termination::NoImprovementPossible,
            ));
        }
        if accepted {
            (a, g) = problem
                .normal_equations(&u, &point)
                .ok_or(Failure::Jacobian)?;
            d = scaling(&a, Some(&d));
        }
    }
}

/// The damping after a rejected step: ν times more, [`FIRST_DAMPING`] if there was none.
fn damp(mu: f64, nu: f64) -> f64 {
    if mu == 0.0 { FIRST_DAMPING } else { mu * nu }
}

/// Moré's scaling: each column's norm √(JᵀJ)_jj, never below what it was (`previous`), 1
/// for a column that has been zero throughout.
fn scaling(a: &DMatrix<f64>, previous: Option<&DVector<f64>>) -> DVector<f64> {
    DVector::from_fn(a.nrows(), |j, _| {
        let norm = a[(j, j)].max(0.0).sqrt();
        let norm = previous.map_or(norm, |p| norm.max(p[j]));
        if norm > 0.0 { norm } else { 1.0 }
    })
}

/// The damped Gauss–Newton step −(A + μD²)⁻¹ g, or `None` if the damped matrix is not
/// positive definite or the step not finite.
fn step(a: &DMatrix<f64>, g: &DVector<f64>, d: &DVector<f64>, mu: f64) -> Option<DVector<f64>> {
    let mut m = a.clone();
    for j in 0..m.nrows() {
        m[(j, j)] += mu * d[j] * d[j];
    }
    let chol = m.cholesky()?;
    let delta = -chol.solve(g);
    delta.iter().all(|x| x.is_finite()).then_some(delta)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rosenbrock's function as residuals e = (10 (u2 − u1²), 1 − u1): minimum 0 at (1, 1).
    struct Rosenbrock;

    impl NormalProblem for Rosenbrock {
        type Point = [f64; 2];
        fn evaluate(&self, u: &DVector<f64>) -> Option<[f64; 2]> {
            Some([10.0 * (u[1] - u[0] * u[0]), 1.0 - u[0]])
        }
        fn cost(&self, e: &[f64; 2]) -> f64 {
            e[0] * e[0] + e[1] * e[1]
        }
        fn normal_equations(
            &self,
            u: &DVector<f64>,
            e: &[f64; 2],
        ) -> Option<(DMatrix<f64>, DVector<f64>)> {
            let j = DMatrix::from_row_slice(2, 2, &[-20.0 * u[0], 10.0, -1.0, 0.0]);
            let e = DVector::from_row_slice(e);
            Some((j.transpose() * &j, j.transpose() * e))
        }
    }

    /// A line y = a + b x through noisy points, and a model that cannot be evaluated for
    /// b > 3 nor at its second evaluation (the first trial step): the minimiser must shorten
    /// the step and go on.
    struct Line {
        x: Vec<f64>,
        y: Vec<f64>,
        calls: std::cell::Cell<usize>,
    }

    impl NormalProblem for Line {
        type Point = Vec<f64>;
        fn evaluate(&self, u: &DVector<f64>) -> Option<Vec<f64>> {
            self.calls.set(self.calls.get() + 1);
            (u[1] <= 3.0 && self.calls.get() != 2).then(|| {
                let r = self.x.iter().zip(&self.y);
                r.map(|(x, y)| y - u[0] - u[1] * x).collect()
            })
        }
        fn cost(&self, e: &Vec<f64>) -> f64 {
            e.iter().map(|x| x * x).sum()
        }
        fn normal_equations(
            &self,
            _: &DVector<f64>,
            e: &Vec<f64>,
        ) -> Option<(DMatrix<f64>, DVector<f64>)> {
            let j = DMatrix::from_fn(
                self.x.len(),
                2,
                |i, c| if c == 0 { -1.0 } else { -self.x[i] },
            );
            let e = DVector::from_column_slice(e);
            Some((j.transpose() * &j, j.transpose() * e))
        }
    }

    const TIGHT: Settings = Settings {
        ftol: 1e-12,
        xtol: 1e-12,
        max_evaluations: 1000,
    };

    #[test]
    fn rosenbrock_reaches_its_minimum_from_the_classic_start() {
        let out = minimise(
            &Rosenbrock,
            DVector::from_row_slice(&[-1.2, 1.0]),
            None,
            TIGHT,
        )
        .expect("runs");
        assert_eq!(out.termination, Termination::Converged);
        assert!((out.u[0] - 1.0).abs() < 1e-8 && (out.u[1] - 1.0).abs() < 1e-8);
        // Moré, Garbow & Hillstrom report ~20 evaluations for lmder on this start.
        assert!(out.evaluations < 60, "{} evaluations", out.evaluations);
    }

    #[test]
    fn a_linear_problem_gives_the_least_squares_line_and_steps_around_failures() {
        // Closed form: a = ȳ − b x̄, b = Sxy/Sxx.
        let x: Vec<f64> = (0..50).map(|i| i as f64 * 0.1).collect();
        let y: Vec<f64> = x
            .iter()
            .enumerate()
            .map(|(i, x)| 0.5 + 2.0 * x + 0.01 * ((i * 7 % 11) as f64 - 5.0))
            .collect();
        let n = x.len() as f64;
        let (mx, my) = (x.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
        let sxy: f64 = x.iter().zip(&y).map(|(x, y)| (x - mx) * (y - my)).sum();
        let sxx: f64 = x.iter().map(|x| (x - mx) * (x - mx)).sum();
        let (b, a) = (sxy / sxx, my - sxy / sxx * mx);
        for start in [[0.0, 2.9], [10.0, -40.0]] {
            let line = Line {
                x: x.clone(),
                y: y.clone(),
                calls: Default::default(),
            };
            let out = minimise(&line, DVector::from_row_slice(&start), None, TIGHT).expect("runs");
            assert_eq!(out.termination, Termination::Converged);
            assert!(
                (out.u[0] - a).abs() < 1e-9 && (out.u[1] - b).abs() < 1e-9,
                "{}",
                out.u
            );
            // The failed trial was rejected and the fit went on.
            assert!(line.calls.get() > 3);
        }
    }

    #[test]
    fn the_budget_and_a_bad_start_are_reported() {
        let few = Settings {
            max_evaluations: 3,
            ..TIGHT
        };
        let out = minimise(
            &Rosenbrock,
            DVector::from_row_slice(&[-1.2, 1.0]),
            None,
            few,
        )
        .expect("runs");
        assert_eq!(out.termination, Termination::LostPatience);
        assert_eq!(out.evaluations, 3);
        let line = Line {
            x: vec![0.0, 1.0, 2.0],
            y: vec![0.0, 1.0, 2.0],
            calls: Default::default(),
        };
        let bad = minimise(&line, DVector::from_row_slice(&[0.0, 5.0]), None, TIGHT);
        assert_eq!(bad.err(), Some(Failure::Start));
    }
}
