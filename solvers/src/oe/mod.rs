//! Output-error (simulation-error) estimation of any [`DynamicModel`].
//!
//! The parameters and each recording's initial state are chosen to make the model's free-run
//! response to the recorded commands match the measured outputs:
//!
//! ```text
//! (θ̂, x̂0_1 … x̂0_R) = argmin  Σ_r Σ_c Σ_k  ( y_{r,c}(t_k) − ŷ_{r,c}(t_k; θ, x0_r) )² / σ_c²
//!                     subject to lb ≤ θ ≤ ub
//! ```
//!
//! where ŷ is [`DynamicModel::simulate`] — commands applied as the recording says (zero-order
//! hold between samples), outputs as the recording samples them (instants or window averages) —
//! so the command, known exactly, stays on the input side and the measurement noise on the
//! output side: no filter, no derivative, no cut-off, and no errors-in-variables bias (Ljung,
//! *System Identification*, 2nd ed., §7.3; the output-error model of §4.2).
//!
//! **Minimisation.** Levenberg–Marquardt on the normal equations ([`lm`](self): Marquardt's
//! damping with Moré's scaling and MINPACK's stopping tests; JᵀJ and Jᵀe are summed from the
//! sensitivities, so the 2n × P Jacobian is neither stored nor factored while iterating),
//! started from a given θ (the least-squares answer). The
//! Jacobian comes from the model's forward sensitivities when it has them
//! ([`DynamicModel::simulate_with_sensitivities`]), else from central differences of the
//! simulation. Bounds are kept by the MINUIT/lmfit change of variables,
//! θ = lb + (ub − lb)(1 + sin u)/2 (one side: θ = lb − 1 + √(u² + 1)), so the search is
//! unconstrained in u and every trial θ is feasible.
//!
//! **Weights.** σ_c is the residual standard deviation of channel c, first at the starting θ;
//! after each minimisation it is taken again at the optimum, and if the weights' *ratio*
//! σ_1/σ_c moved by more than 10 % the problem is solved again from there (at most three
//! passes; a repeat starts converged and costs a few evaluations). A common scale of the
//! weights does not move the minimiser, so a change of scale alone calls for no new pass; the
//! weights at θ̂ are still the ones the cost and the covariance are reported with. Any fixed
//! weights give a consistent θ̂; these make it efficient when the channels' noise levels
//! differ.
//!
//! **Long recordings.** From [`WARM_START_FACTOR`] × `OutputError::warm_start` samples on (a
//! 1e6-sample drive), the same fit is first run on the recordings' heads — their first
//! `warm_start` ([`WARM_START_SAMPLES`]) samples in all, shared in proportion to their lengths, the same
//! bounds and weighting — and the full fit starts from that θ̂, so that its own iterations,
//! each a simulation with sensitivities of every sample, are the few that move a nearly
//! converged θ (the answer is the full fit's, to its tolerance, whatever the start). A head
//! fit that fails leaves the start as given. A long problem's points (from 400,000 residuals)
//! are simulated with their sensitivities at once: a nearly converged fit takes nearly every
//! step, and the normal equations at a step taken then need no second integration of the
//! state (a step refused costs a sensitivity integration instead of a simulation).
//!
//! **Uncertainty.** At θ̂ the weighted Jacobian J (rows time-major: sample k, then channel c)
//! and the weighted residuals e give the sandwich covariance
//!
//! ```text
//! Cov = (JᵀJ)⁻¹ (Σ_r Σ_l w_l Σ_k G_k G_{k+l}ᵀ + transposes) (JᵀJ)⁻¹ · N/(N − P),
//! G_k = Σ_c J[(k, c), :]ᵀ e_(k, c),
//! ```
//!
//! summed over each recording r separately, with Bartlett weights w_l = 1 − l/(L + 1) over
//! L = ⌊4 (n/100)^{2/9}⌋ instants (Newey & West 1994), so that coloured residuals (encoder
//! quantization, unmodelled dynamics) widen the intervals instead of being ignored. P counts θ
//! and the initial states; a parameter pinned on a bound is left out (its standard error is 0).

mod lm;
mod problem;
mod transform;
mod uncertainty;

use std::cell::RefCell;
use std::time::Instant;

use nalgebra::{DMatrix, DVector};
use wheelid_core::{BoundState, DynamicModel, Recording, SolveError, SolveStatus};

use lm::Termination;
use problem::{Evaluated, Problem, measured};
use transform::Transform;

/// Settings of an output-error fit (the result is an [`OutputErrorFit`]).
#[derive(Debug, Clone, PartialEq)]
pub struct OutputError {
    /// Box bounds (lower, upper) on θ, one per parameter; ±∞ for none.
    pub bounds: Option<Vec<(f64, f64)>>,
    /// Estimate each recording's initial state (default); otherwise hold it at the first
    /// measured sample.
    pub estimate_initial: bool,
    /// Relative tolerance on the cost and the step (MINPACK `ftol` = `xtol`).
    pub tolerance: f64,
    /// Limit on residual evaluations per pass, as a multiple of (parameters + 1).
    pub patience: usize,
    /// Residual correlation length in samples for the covariance; `None`: the Newey–West rule
    /// L = ⌊4 (n/100)^{2/9}⌋ with n the samples of the longest recording.
    pub correlation_lags: Option<usize>,
    /// Which samples enter the cost, per recording one flag per sample (validation blocks held
    /// out are `false`); `None`: every sample. The model is still simulated over the whole
    /// recording, so the held-out samples keep their place in time.
    pub mask: Option<Vec<Vec<bool>>>,
    /// Finite-difference Jacobians (models without sensitivities) by forward differences: one
    /// simulation per column instead of two, truncation error O(h) instead of O(h²) (h ~ 1e-5
    /// relative). Off by default.
    pub forward_differences: bool,
    /// Samples of the head problem a long fit starts from (module doc, *Long recordings*);
    /// `None`: always start from the θ given. Default [`WARM_START_SAMPLES`].
    pub warm_start: Option<usize>,
    /// Hand back the Jacobian at θ̂ ([`OutputErrorFit::jacobian`]; default): rows × unknowns,
    /// 128 MB for 10⁶ samples. Without it the covariance reads the sensitivities where they
    /// lie and no rows × unknowns matrix is formed.
    pub keep_jacobian: bool,
}

impl Default for OutputError {
    fn default() -> Self {
        Self {
            bounds: None,
            estimate_initial: true,
            tolerance: 1e-10,
            patience: 100,
            correlation_lags: None,
            mask: None,
            forward_differences: false,
            warm_start: Some(WARM_START_SAMPLES),
            keep_jacobian: true,
        }
    }
}

/// A fitted output-error model.
#[derive(Debug, Clone, PartialEq)]
pub struct OutputErrorFit {
    /// θ̂, one per model parameter.
    pub theta: Vec<f64>,
    /// Standard errors of θ̂ (sandwich covariance, see the module doc); 0 for a parameter
    /// pinned on a bound.
    pub std_err: Vec<f64>,
    /// Covariance of θ̂, p × p (the θ block of the full covariance).
    pub covariance: DMatrix<f64>,
    /// Initial state per recording, one value per channel.
    pub initial: Vec<Vec<f64>>,
    /// Residual standard deviation per channel at θ̂, in the channel's unit.
    pub noise_std: Vec<f64>,
    /// Weighted cost Σ e²/σ² at θ̂ over all residuals.
    pub cost: f64,
    /// Number of residuals (samples × channels over all recordings).
    pub residuals: usize,
    /// Residual evaluations (simulations) used, both passes.
    pub evaluations: usize,
    /// How the minimisation ended.
    pub status: SolveStatus,
    /// Per-parameter bound state.
    pub bound_state: Vec<BoundState>,
    /// Residual correlation length used for the covariance \[samples\].
    pub correlation_lags: usize,
    /// Sensitivities ∂ŷ/∂(θ, x0) at θ̂ (or within the last converged step of it, see
    /// [`OutputError::fit`]), unweighted: one row per residual in the cost, time-major (sample
    /// k of recording r, then channel c — the rows of the cost in order), columns θ then each
    /// recording's initial state (when estimated). Rows × (p + channels · recordings). It is
    /// the Jacobian the covariance was computed from; a caller that tests the residual against
    /// other directions (a score test) projects it out without simulating again. `None` when
    /// [`OutputError::keep_jacobian`] is off.
    pub jacobian: Option<DMatrix<f64>>,
    /// The free run at θ̂ from the fitted initial states, per recording ŷ per channel, every
    /// sample: the simulation the cost was last evaluated on (a validation need not run it
    /// again).
    pub simulated: Vec<wheelid_core::Simulation>,
    /// Wall time of the fit \[s\].
    pub seconds: f64,
}

/// Most minimisations: a second (third) one only if the noise weights moved.
const MAX_PASSES: usize = 3;

/// Samples (over all recordings) of the head problem a long fit starts from (module doc,
/// *Long recordings*).
pub const WARM_START_SAMPLES: usize = 50_000;

/// A problem is long, and starts from its heads' fit, from this many times
/// [`WARM_START_SAMPLES`] samples.
pub const WARM_START_FACTOR: usize = 4;

/// A minimisation's end: the problem, θ̂ in u, its simulations and raw residuals, the
/// residual evaluations, and how the last pass ended.
type Minimised<'a, M> = (Problem<'a, M>, DVector<f64>, Evaluated, usize, Termination);

/// Relative change of a weight ratio σ_1/σ_c that calls for another pass.
const WEIGHT_TOLERANCE: f64 = 0.1;

impl OutputError {
    /// Fits `model` to `recordings` by output error, starting from `theta0`.
    ///
    /// Every recording must have the outputs the model's channels name (`v`, `w`), at least
    /// as many samples as there are unknowns, and `theta0` must simulate. The covariance and
    /// [`OutputErrorFit::jacobian`] use the last iteration's Jacobian when it was taken within
    /// 10⁻⁴ ‖u‖ of the optimum (u: θ in the bound transform's variables, then x0), else one
    /// taken there.
    ///
    /// # Errors
    /// [`SolveError::InvalidProblem`] for wrong lengths, bad bounds, or a starting θ whose
    /// simulation fails; [`SolveError::RankDeficient`] if the recordings cannot separate some
    /// parameters at θ̂; [`SolveError::Numerical`] if the minimiser stops on a failure.
    pub fn fit<M: DynamicModel + ?Sized>(
        &self,
        model: &M,
        recordings: &[Recording],
        theta0: &[f64],
    ) -> Result<OutputErrorFit, SolveError> {
        let clock = Instant::now();
        let (start, warm_evaluations) = match self.warm_start(model, recordings, theta0) {
            Some((theta, evaluations)) => (theta, evaluations),
            None => (theta0.to_vec(), 0),
        };
        let problem = self.problem(model, recordings, &start)?;
        let (problem, u, point, evaluations, termination) = self.minimise(problem)?;
        let mut fit = uncertainty::uncertainty(self, problem, u, point, termination)?;
        fit.evaluations = warm_evaluations + evaluations;
        fit.seconds = clock.elapsed().as_secs_f64();
        Ok(fit)
    }

    /// A start for a long problem (module doc, *Long recordings*): θ̂ of the same fit on the
    /// recordings' heads, about [`OutputError::warm_start`] samples in all, with the residual
    /// evaluations it used (a mask is cut with its recordings); `None` for a short problem, or
    /// when the head's fit fails (the full fit then starts from `theta0` as it would have).
    fn warm_start<M: DynamicModel + ?Sized>(
        &self,
        model: &M,
        recordings: &[Recording],
        theta0: &[f64],
    ) -> Option<(Vec<f64>, usize)> {
        let head = self.warm_start?;
        let total: usize = recordings.iter().map(Recording::len).sum();
        if total < WARM_START_FACTOR * head {
            return None;
        }
        let lengths: Vec<usize> = recordings
            .iter()
            .map(|r| (head * r.len()).div_ceil(total))
            .collect();
        let heads: Vec<Recording> = recordings
            .iter()
            .zip(&lengths)
            .map(|(r, &n)| r.head(n))
            .collect();
        let head_fit = OutputError {
            warm_start: None,
            mask: self.mask.as_ref().map(|m| {
                m.iter()
                    .zip(&lengths)
                    .map(|(m, &n)| m[..n.min(m.len())].to_vec())
                    .collect()
            }),
            ..self.clone()
        };
        let problem = head_fit.problem(model, &heads, theta0).ok()?;
        let (problem, u, _, evaluations, _) = head_fit.minimise(problem).ok()?;
        Some((problem.theta_of(&u), evaluations))
    }

    /// The model's channels, θ0's length, the recordings' lengths and the bounds, checked; the
    /// bounds (±∞ where none).
    ///
    /// # Errors
    /// [`SolveError::InvalidProblem`] or, for a bound pair out of order,
    /// [`SolveError::Infeasible`].
    fn checked_bounds<M: DynamicModel + ?Sized>(
        &self,
        model: &M,
        recordings: &[Recording],
        theta0: &[f64],
    ) -> Result<Vec<(f64, f64)>, SolveError> {
        let p = model.params().len();
        let s = model.channels().len();
        if s != 2 {
            return Err(SolveError::InvalidProblem(format!(
                "output error fits (v, ω) outputs; model `{}` has {s} channels",
                model.name()
            )));
        }
        if theta0.len() != p {
            return Err(SolveError::InvalidProblem(format!(
                "θ0 has {} values, model `{}` has {p} parameters",
                theta0.len(),
                model.name()
            )));
        }
        if recordings.is_empty() {
            return Err(SolveError::InvalidProblem("no recording".into()));
        }
        if let Some(r) = recordings.iter().find(|r| r.len() < 2) {
            return Err(SolveError::InvalidProblem(format!(
                "{}: {} samples; output error needs at least 2",
                r.source.display(),
                r.len()
            )));
        }
        let bounds = match &self.bounds {
            Some(b) if b.len() != p => {
                return Err(SolveError::InvalidProblem(format!(
                    "{} bounds for {p} parameters",
                    b.len()
                )));
            }
            Some(b) => b.clone(),
            None => vec![(f64::NEG_INFINITY, f64::INFINITY); p],
        };
        for (i, &(lo, hi)) in bounds.iter().enumerate() {
            if lo.is_nan() || hi.is_nan() || lo >= hi {
                return Err(SolveError::Infeasible(format!(
                    "{}: lower {lo} is not below upper {hi}",
                    model.params()[i].name
                )));
            }
        }
        Ok(bounds)
    }

    /// The samples in the cost per recording: the mask's, else every one.
    ///
    /// # Errors
    /// [`SolveError::InvalidProblem`] for a mask that does not match the recordings.
    fn sample_mask(&self, recordings: &[Recording]) -> Result<Vec<Vec<bool>>, SolveError> {
        Ok(match &self.mask {
            Some(m) => {
                if m.len() != recordings.len()
                    || m.iter().zip(recordings).any(|(m, r)| m.len() != r.len())
                {
                    return Err(SolveError::InvalidProblem(
                        "the sample mask must have one flag per sample of each recording".into(),
                    ));
                }
                m.clone()
            }
            None => recordings.iter().map(|r| vec![true; r.len()]).collect(),
        })
    }

    /// The unknowns' names: θ's, then each recording's initial state when it is estimated.
    fn unknown_names<M: DynamicModel + ?Sized>(&self, model: &M, recordings: usize) -> Vec<String> {
        let mut names: Vec<String> = model.params().iter().map(|q| q.name.to_owned()).collect();
        if self.estimate_initial {
            for r in 0..recordings {
                for c in model.channels() {
                    names.push(format!("{}0 of recording {}", c.name, r + 1));
                }
            }
        }
        names
    }

    /// Checks the inputs of [`OutputError::fit`] and sets up its problem at `theta0`.
    fn problem<'a, M: DynamicModel + ?Sized>(
        &self,
        model: &'a M,
        recordings: &'a [Recording],
        theta0: &[f64],
    ) -> Result<Problem<'a, M>, SolveError> {
        let (p, s) = (model.params().len(), model.channels().len());
        let bounds = self.checked_bounds(model, recordings, theta0)?;
        let transform: Vec<Transform> = bounds.iter().map(|&b| Transform::new(b)).collect();
        let unknowns = p + if self.estimate_initial {
            s * recordings.len()
        } else {
            0
        };
        let mask = self.sample_mask(recordings)?;
        // Only the residuals that count are rows of the problem.
        let index: Vec<Vec<usize>> = mask
            .iter()
            .map(|m| (0..m.len()).filter(|&k| m[k]).collect())
            .collect();
        let mut offsets = Vec::with_capacity(recordings.len());
        let mut rows = 0;
        for ix in &index {
            offsets.push(rows);
            rows += ix.len() * s;
        }
        let active = rows;
        if active <= unknowns {
            return Err(SolveError::InvalidProblem(format!(
                "{active} residuals cannot determine {unknowns} unknowns"
            )));
        }
        let first: Vec<Vec<f64>> = recordings
            .iter()
            .map(|r| measured(r).iter().map(|y| y[0]).collect())
            .collect();
        let mut u0: Vec<f64> = transform.iter().zip(theta0).map(|(t, &x)| t.u(x)).collect();
        if self.estimate_initial {
            u0.extend(first.iter().flatten());
        }
        Ok(Problem {
            model,
            recs: recordings,
            weight: vec![1.0; s],
            transform,
            fixed_initial: (!self.estimate_initial).then(|| first.clone()),
            u0: DVector::from_vec(u0),
            offsets,
            index,
            mask,
            forward: self.forward_differences,
            rows,
            last_sensitivities: RefCell::new(None),
        })
    }

    /// Minimises the problem's cost by Levenberg–Marquardt, passes re-weighting the channels
    /// (module doc); returns the problem, θ̂ in u with its raw residuals, the residual
    /// evaluations and how the last pass ended.
    fn minimise<'a, M: DynamicModel + ?Sized>(
        &self,
        mut problem: Problem<'a, M>,
    ) -> Result<Minimised<'a, M>, SolveError> {
        let (active, unknowns) = (problem.rows, problem.unknowns());
        let settings = lm::Settings {
            ftol: self.tolerance,
            xtol: self.tolerance,
            max_evaluations: self.patience * (unknowns + 1),
        };
        let mut u = problem.u0.clone();
        let mut point = lm::NormalProblem::evaluate(&problem, &u).ok_or_else(|| {
            SolveError::InvalidProblem(format!(
                "the model does not simulate (finitely) at θ = {:?}",
                problem.theta_of(&u)
            ))
        })?;
        let (mut evaluations, mut termination) = (1, Termination::Converged);
        for pass in 0..MAX_PASSES {
            let weight: Vec<f64> =
                uncertainty::channel_std(&point.raw, &problem.mask, active, unknowns)
                    .iter()
                    .map(|&sd| 1.0 / sd.max(1e-12))
                    .collect();
            // Only the ratios move the minimiser (module doc).
            let settled = weight.iter().zip(&problem.weight).all(|(a, b)| {
                ((a / weight[0]) / (b / problem.weight[0]) - 1.0).abs() < WEIGHT_TOLERANCE
            });
            problem.weight = weight;
            if pass > 0 && settled {
                break;
            }
            let out = lm::minimise(&problem, u, Some(point), settings).map_err(|f| match f {
                lm::Failure::Start => {
                    SolveError::Numerical("the fit's start does not simulate".into())
                }
                lm::Failure::Jacobian => SolveError::Numerical(
                    "Levenberg–Marquardt stopped: the sensitivities are not finite".into(),
                ),
            })?;
            (u, point) = (out.u, out.point);
            evaluations += out.evaluations;
            termination = out.termination;
        }
        Ok((problem, u, point, evaluations, termination))
    }
}
