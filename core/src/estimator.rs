//! Estimators of θ behind one trait, so that the built-in ones (instrumental variables,
//! output error) and a plugin's are chosen by name and run the same way.
//!
//! Every estimator starts where the thesis's method ends: the least-squares answer of the
//! filtered regression (Laut 2011 eq. 4.3–4.7), which the host computes once per run. An
//! estimator refines it on the same data — the recordings as stamped and the conditioned
//! (resampled, filtered, differentiated) copies — and returns θ̂ with its standard errors:
//!
//! ```text
//! θ̂ = E(model, recordings, conditioned, θ_LS, bounds),   θ̂, σ(θ̂) ∈ ℝᵖ
//! ```
//!
//! An estimator is plain Rust behind [`Estimator`]; the host holds built-ins and plugins'
//! (registered with [`crate::plugin::Registrar::estimator`]) in one list, and `--estimator
//! NAME` or a config's `estimator = "NAME"` picks one. Its [`Estimate`] is checked by the host
//! (stable, finite, non-singular covariance) before it may be the answer.

use serde::Serialize;

use crate::{
    BoundState, ConditionSettings, Conditioned, Recording, RegressorModel, SolveError, SolveStatus,
    Timing, VelocitySampling,
};

/// What an estimator is given: the run's data, prepared once by the host.
#[derive(Clone, Copy)]
pub struct EstimatorInput<'a> {
    /// The model, p = `model.params().len()` parameters.
    pub model: &'a dyn RegressorModel,
    /// The recordings on their own stamps (window-middle stamps restamped to window ends):
    /// what a simulation-based estimator fits.
    pub recordings: &'a [Recording],
    /// The same recordings resampled, aligned and filtered (`crate::condition`), one each:
    /// what a regression-based estimator fits.
    pub conditioned: &'a [Conditioned<'a>],
    /// Least squares' θ (eq. 4.3–4.7), length p: the start.
    pub start: &'a [f64],
    /// Bounds (lower, upper) on θ, length p, when the run has them.
    pub bounds: Option<&'a [(f64, f64)]>,
    /// The run's low-pass cut-off \[Hz\].
    pub cutoff_hz: f64,
    /// The conditioning settings the data were prepared with.
    pub condition: &'a ConditionSettings,
    /// Samples over which the filtered residuals are correlated (Newey–West window).
    pub lags: usize,
}

/// How an estimate is simulated free-run when it fitted its own initial states or timing.
#[derive(Debug, Clone)]
pub struct FreeRun {
    /// Initial state per recording, one value per channel.
    pub initial: Vec<Vec<f64>>,
    /// The command-to-response offset δ \[s\] it estimated, if it did.
    pub offset: Option<f64>,
    /// The recordings as it fitted them (restamped, their output sampling set).
    pub recordings: Vec<Recording>,
    /// Its free run on those recordings from those states (per recording, the outputs per
    /// channel, every sample), when it has it at hand: the validation uses it instead of
    /// simulating the same thing again.
    pub outputs: Option<Vec<crate::Simulation>>,
}

/// An estimator's answer.
#[derive(Debug, Clone)]
pub struct Estimate {
    /// θ̂, length p.
    pub theta: Vec<f64>,
    /// Standard errors of θ̂, length p (0 for a parameter pinned on a bound).
    pub std_err: Vec<f64>,
    /// How the estimator ended.
    pub status: SolveStatus,
    /// Per-parameter bound state, length p.
    pub bound_state: Vec<BoundState>,
    /// Iterations or residual evaluations it used.
    pub iterations: usize,
    /// How to simulate it, when that differs from the recordings as given.
    pub free_run: Option<FreeRun>,
    /// Residual standard deviation per channel, in the channel's unit, when it measured it.
    pub noise_std: Option<Vec<f64>>,
    /// The stamping convention it used, stated or estimated, when it decided one.
    pub timing: Option<TimingReport>,
}

impl Estimate {
    /// An estimate with only θ̂, its standard errors and status (no free-run, noise or timing
    /// information), every parameter free.
    pub fn new(theta: Vec<f64>, std_err: Vec<f64>, status: SolveStatus, iterations: usize) -> Self {
        let bound_state = vec![BoundState::Free; theta.len()];
        Self {
            theta,
            std_err,
            status,
            bound_state,
            iterations,
            free_run: None,
            noise_std: None,
            timing: None,
        }
    }
}

/// An estimator of θ that refines least squares' answer.
pub trait Estimator: Send + Sync {
    /// Its name, as `--estimator` and configs give it (`iv`, `oe`, a plugin's).
    fn name(&self) -> &str;

    /// θ̂ for `input.model` on `input`'s data, started from `input.start`.
    ///
    /// # Errors
    /// [`SolveError`] when its problem cannot be posed or solved (a status, never a panic).
    fn estimate(&self, input: &EstimatorInput<'_>) -> Result<Estimate, SolveError>;
}

/// Where the timing used by a fit came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum TimingSource {
    /// Every recording states its convention (metadata).
    Stated,
    /// Estimated by the fit (no metadata, or some recordings without it).
    Estimated,
}

/// The timing a fit used, for the report.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TimingReport {
    /// Stated or estimated.
    pub source: TimingSource,
    /// The stated convention (when every recording states the same one).
    pub stated: Option<Timing>,
    /// Output sampling used (stated, or the hypothesis the likelihood chose).
    pub sampling: VelocitySampling,
    /// Residual offset δ \[s\] under the winning hypothesis, when fitted and kept: its commands
    /// act from t_k + δ (negative: before their stamps); 0 when stated or not significant.
    pub offset_s: f64,
    /// Standard error of the fitted residual offset \[s\] (0 when stated).
    pub offset_std_s: f64,
    /// The median sample period Δ \[s\] (the longest over the recordings).
    pub period_s: f64,
    /// −2 ln L of each convention fitted as a hypothesis (with its own offset), (convention,
    /// value): the smaller wins (instants with a handicap, `INSTANT_MARGIN` of the host's timing module).
    pub hypotheses: Vec<(Timing, f64)>,
    /// The convention the data point at: the stated one, or the hypothesis that won.
    pub likely: Option<Timing>,
    /// One sentence for the report.
    pub summary: String,
}
