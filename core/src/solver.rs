//! The [`Solver`] trait: least-squares estimation of θ from one channel's regression,
//!
//! ```text
//! θ̂ = argmin ‖y − Xθ‖²   (subject to lb ≤ θ ≤ ub for bounded solvers)
//! ```
//!
//! Outcomes are a [`SolveStatus`] plus, for problems that cannot be solved, a [`SolveError`];
//! solvers never panic on data.

use nalgebra::{DMatrix, DVector};

/// A least-squares problem: y (n) ≈ x (n × p) · θ.
#[derive(Debug, Clone, Copy)]
pub struct LinearProblem<'a> {
    /// Regressor matrix, n × p.
    pub x: &'a DMatrix<f64>,
    /// Regressand, length n.
    pub y: &'a DVector<f64>,
    /// Parameter names, length p (used in errors).
    pub names: &'a [&'a str],
    /// Box bounds (lower, upper) per parameter; ±∞ for none. Ignored by unbounded solvers.
    pub bounds: Option<&'a [(f64, f64)]>,
    /// Residual correlation length in samples (0: independent residuals). Filtered data have
    /// residuals correlated over about f_s/f_c samples; the covariance then uses the
    /// Newey–West (Bartlett-kernel) estimator with this many lags.
    pub correlation_lags: usize,
}

/// How a solve ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum SolveStatus {
    /// Solved to the solver's tolerance.
    Solved,
    /// Solved to a reduced tolerance (interior-point solvers), or no further improvement
    /// possible at the requested tolerance (iterative solvers).
    AlmostSolved,
    /// An iterative solver stopped at its iteration or evaluation limit; the result is the
    /// best point found, not a converged one.
    IterationLimit,
}

/// Whether a bounded parameter ended on a bound.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum BoundState {
    /// Strictly inside its bounds (or unbounded).
    Free,
    /// At its lower bound.
    AtLower,
    /// At its upper bound.
    AtUpper,
}

/// A fitted linear model.
#[derive(Debug, Clone, PartialEq)]
pub struct LinearFit {
    /// θ̂, length p.
    pub theta: DVector<f64>,
    /// Standard errors of θ̂, length p (from the unconstrained covariance at θ̂).
    pub std_err: DVector<f64>,
    /// Covariance of θ̂, p × p.
    pub covariance: DMatrix<f64>,
    /// Residual sum of squares ‖y − Xθ̂‖².
    pub rss: f64,
    /// Number of rows n.
    pub n: usize,
    /// Numerical rank of X.
    pub rank: usize,
    /// 2-norm condition number of X with unit-norm columns (scale-free identifiability measure).
    pub condition_number: f64,
    /// Per-parameter bound state.
    pub bound_state: Vec<BoundState>,
    /// Solver status.
    pub status: SolveStatus,
}

/// Why a least-squares problem could not be solved.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum SolveError {
    /// The data cannot separate some parameters (X loses rank).
    #[error(
        "the data cannot separate {}: the regressor has rank {rank} of {p} (the recording does not excite these parameters; vary the commands that drive them)",
        names.join(", ")
    )]
    RankDeficient {
        /// Parameters involved in the null space of X.
        names: Vec<String>,
        /// Numerical rank.
        rank: usize,
        /// Number of parameters.
        p: usize,
    },
    /// Bounds are inconsistent or the bounded problem is infeasible.
    #[error("infeasible bounds: {0}")]
    Infeasible(String),
    /// The numerical solver stopped without a solution.
    #[error("solver failed: {0}")]
    Numerical(String),
    /// The problem's shapes or values are invalid.
    #[error("invalid problem: {0}")]
    InvalidProblem(String),
}

/// A least-squares solver. `Send + Sync`: a run solves its channels' problems at once, on
/// the available cores.
pub trait Solver: Send + Sync {
    /// Solver name as used on the command line, e.g. `ols`.
    fn name(&self) -> &str;

    /// Solves the problem.
    ///
    /// # Errors
    /// [`SolveError`] when the problem cannot be solved (rank deficiency, infeasible bounds,
    /// numerical failure, bad shapes).
    fn solve(&self, problem: &LinearProblem<'_>) -> Result<LinearFit, SolveError>;
}
