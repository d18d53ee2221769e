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
//! **Minimisation.** Levenberg–Marquardt (Moré's MINPACK `lmder`, through the
//! `levenberg-marquardt` crate), started from a given θ (the least-squares answer). The
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
//! fit that fails leaves the start as given.
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

use std::cell::RefCell;
use std::time::Instant;

use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt, TerminationReason};
use nalgebra::{DMatrix, DVector};
use nalgebra034 as na;
use wheelid_core::{
    BoundState, DynamicModel, LinearProblem, Recording, Sensitivities, Simulation, SolveError,
    SolveStatus,
};

use crate::ols;

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
    /// other directions (a score test) projects it out without simulating again.
    pub jacobian: DMatrix<f64>,
    /// Wall time of the fit \[s\].
    pub seconds: f64,
}

/// The change of variables that keeps one parameter inside its bounds.
#[derive(Debug, Clone, Copy)]
enum Transform {
    Free,
    Both(f64, f64),
    Lower(f64),
    Upper(f64),
}

impl Transform {
    fn new((lo, hi): (f64, f64)) -> Self {
        match (lo.is_finite(), hi.is_finite()) {
            (true, true) => Self::Both(lo, hi),
            (true, false) => Self::Lower(lo),
            (false, true) => Self::Upper(hi),
            (false, false) => Self::Free,
        }
    }
    fn theta(self, u: f64) -> f64 {
        match self {
            Self::Free => u,
            Self::Both(lo, hi) => lo + (hi - lo) * (1.0 + u.sin()) / 2.0,
            Self::Lower(lo) => lo - 1.0 + (u * u + 1.0).sqrt(),
            Self::Upper(hi) => hi + 1.0 - (u * u + 1.0).sqrt(),
        }
    }
    fn dtheta_du(self, u: f64) -> f64 {
        match self {
            Self::Free => 1.0,
            Self::Both(lo, hi) => (hi - lo) * u.cos() / 2.0,
            Self::Lower(_) => u / (u * u + 1.0).sqrt(),
            Self::Upper(_) => -u / (u * u + 1.0).sqrt(),
        }
    }
    /// Whether u puts θ on a bound: where the transform is flat (dθ/du ≈ 0), θ is within
    /// ~1e-8 of the bound's scale and the data no longer move it.
    fn bound_state(self, u: f64) -> BoundState {
        match self {
            Self::Free => BoundState::Free,
            Self::Both(..) if u.cos().abs() < 1e-4 => {
                if u.sin() < 0.0 {
                    BoundState::AtLower
                } else {
                    BoundState::AtUpper
                }
            }
            Self::Lower(_) if u.abs() < 1e-4 => BoundState::AtLower,
            Self::Upper(_) if u.abs() < 1e-4 => BoundState::AtUpper,
            _ => BoundState::Free,
        }
    }
    /// u for θ; θ is first moved a hair inside the bounds so that the derivative is not 0.
    fn u(self, theta: f64) -> f64 {
        match self {
            Self::Free => theta,
            Self::Both(lo, hi) => {
                let x = (2.0 * (theta - lo) / (hi - lo) - 1.0).clamp(-1.0 + 1e-9, 1.0 - 1e-9);
                x.asin()
            }
            Self::Lower(lo) => ((theta - lo + 1.0).max(1.0 + 1e-9).powi(2) - 1.0).sqrt(),
            Self::Upper(hi) => ((hi - theta + 1.0).max(1.0 + 1e-9).powi(2) - 1.0).sqrt(),
        }
    }
}

/// The least-squares problem handed to Levenberg–Marquardt: parameters u = (u_θ, x0_1, …).
struct Problem<'a, M: ?Sized> {
    model: &'a M,
    recs: &'a [Recording],
    /// 1/σ_c per channel.
    weight: Vec<f64>,
    transform: Vec<Transform>,
    /// Initial states when they are not estimated.
    fixed_initial: Option<Vec<Vec<f64>>>,
    u: na::DVector<f64>,
    /// Offsets of each recording's rows (its samples in the cost, both channels).
    offsets: Vec<usize>,
    /// Per recording, the samples that enter the cost (the mask's), in time order: row
    /// `offsets[r] + i·s + c` is sample `index[r][i]`, channel c.
    index: Vec<Vec<usize>>,
    /// Per recording, whether each sample enters the cost.
    mask: Vec<Vec<bool>>,
    /// Forward instead of central differences.
    forward: bool,
    rows: usize,
    /// The last weighted Jacobian in (θ, x0) and the u it was taken at.
    last_jacobian: RefCell<Option<(na::DVector<f64>, DMatrix<f64>)>>,
    /// The simulations of the last residual evaluation and the u they were run at: the base of
    /// the next forward-difference Jacobian, which Levenberg–Marquardt asks for at that u.
    last_simulation: RefCell<Option<(na::DVector<f64>, Vec<Simulation>)>>,
    /// The last raw residuals and the u they were taken at: the minimiser asks again for the
    /// residuals at the u the fit starts from and at the one it ends at (a whole simulation
    /// each); taken by the repeated request.
    last_raw: RefCell<Option<Residuals>>,
}

/// Raw residuals (per recording and channel, every sample) and the u they were taken at.
type Residuals = (na::DVector<f64>, Vec<Vec<Vec<f64>>>);

/// A minimisation's end: the problem at θ̂, its raw residuals (per recording and channel),
/// the residual evaluations, and how the last pass ended.
type Minimised<'a, M> = (Problem<'a, M>, Vec<Vec<Vec<f64>>>, usize, TerminationReason);

/// One central-difference column: parameter index, step, outputs at +step and −step.
type FdColumn = (usize, f64, Vec<Vec<f64>>, Vec<Vec<f64>>);

/// Most minimisations: a second (third) one only if the noise weights moved.
const MAX_PASSES: usize = 3;

/// Samples (over all recordings) of the head problem a long fit starts from (module doc,
/// *Long recordings*).
pub const WARM_START_SAMPLES: usize = 50_000;

/// A problem is long, and starts from its heads' fit, from this many times
/// [`WARM_START_SAMPLES`] samples.
pub const WARM_START_FACTOR: usize = 4;
/// Relative change of a weight ratio σ_1/σ_c that calls for another pass.
const WEIGHT_TOLERANCE: f64 = 0.1;

/// The last iteration's Jacobian serves the covariance if it was taken within this distance of
/// θ̂, relative to ‖u‖ (the final step of a converged minimisation is far smaller; a Jacobian
/// a relative 1e-4 away changes the standard errors in their fourth digit at most, for the
/// smooth simulations this fits).
const JACOBIAN_REUSE: f64 = 1e-4;

/// Weighted residual of a failed or diverged simulation: large enough that Levenberg–Marquardt
/// rejects the step and shrinks its trust region.
const PENALTY: f64 = 1e8;

impl<M: DynamicModel + ?Sized> Problem<'_, M> {
    fn p(&self) -> usize {
        self.transform.len()
    }
    fn nch(&self) -> usize {
        self.model.channels().len()
    }
    fn theta_of(&self, u: &na::DVector<f64>) -> Vec<f64> {
        self.transform
            .iter()
            .zip(u.iter())
            .map(|(t, &x)| t.theta(x))
            .collect()
    }
    fn initial_of(&self, u: &na::DVector<f64>, r: usize) -> Vec<f64> {
        match &self.fixed_initial {
            Some(x) => x[r].clone(),
            None => {
                let (p, s) = (self.p(), self.nch());
                u.as_slice()[p + r * s..p + (r + 1) * s].to_vec()
            }
        }
    }
    /// Unweighted residuals y − ŷ per recording and channel, or `None` if a simulation failed
    /// or diverged.
    fn raw_residuals(&self, theta: &[f64], u: &na::DVector<f64>) -> Option<Vec<Vec<Vec<f64>>>> {
        // Asked again at the same u (taken: a third time simulates again).
        if let Some((at, raw)) = self.last_raw.take()
            && at == *u
        {
            return Some(raw);
        }
        let mut out = Vec::with_capacity(self.recs.len());
        let mut sims = Vec::with_capacity(self.recs.len());
        for (r, rec) in self.recs.iter().enumerate() {
            let sim = self
                .model
                .simulate(theta, rec, &self.initial_of(u, r))
                .ok()?;
            let meas = measured(rec);
            let mut per = Vec::with_capacity(sim.len());
            for (c, y) in sim.iter().enumerate() {
                if y.len() != rec.len() || y.iter().any(|x| !x.is_finite()) {
                    return None;
                }
                per.push(meas[c].iter().zip(y).map(|(m, s)| m - s).collect());
            }
            out.push(per);
            sims.push(sim);
        }
        if self.forward {
            self.last_simulation.replace(Some((u.clone(), sims)));
        }
        self.last_raw.replace(Some((u.clone(), out.clone())));
        Some(out)
    }
    /// The weighted residual rows of `raw` (per recording and channel, every sample): the
    /// cost's rows in order.
    fn weighted_rows(&self, raw: &[Vec<Vec<f64>>]) -> DVector<f64> {
        let s = self.nch();
        let mut e = DVector::zeros(self.rows);
        for (r, per) in raw.iter().enumerate() {
            for (c, ec) in per.iter().enumerate() {
                for (i, &k) in self.index[r].iter().enumerate() {
                    e[self.offsets[r] + i * s + c] = self.weight[c] * ec[k];
                }
            }
        }
        e
    }
    /// Runs of consecutive samples in the cost, as (first row, samples): the lags of the
    /// long-run covariance stay inside them.
    fn spans(&self) -> Vec<(usize, usize)> {
        let s = self.nch();
        let mut spans: Vec<(usize, usize)> = Vec::new();
        for (&o, ix) in self.offsets.iter().zip(&self.index) {
            for (i, &k) in ix.iter().enumerate() {
                match spans.last_mut() {
                    Some((start, n))
                        if i > 0 && ix[i - 1] + 1 == k && *start + *n * s == o + i * s =>
                    {
                        *n += 1
                    }
                    _ => spans.push((o + i * s, 1)),
                }
            }
        }
        spans
    }
    /// ∂ŷ/∂θ and ∂ŷ/∂x0 of recording `r` (per channel n × p and n × s), the model's own
    /// when it has them (used as returned, not copied), else by differences.
    fn sensitivities(
        &self,
        theta: &[f64],
        x0: &[f64],
        rec: &Recording,
        cached: Option<Simulation>,
    ) -> Option<Sensitivities> {
        let (p, s, n) = (self.p(), self.nch(), rec.len());
        if let Ok(Some((_, sens))) = self.model.simulate_with_sensitivities(theta, rec, x0) {
            return Some(sens);
        }
        // Central differences, step ~ 1e-5 relative (above the integrator's sub-step jitter),
        // the columns shared out over the available cores.
        let scale = theta.iter().fold(0.0f64, |a, x| a.max(x.abs())).max(1e-12);
        let base_sim = match (self.forward, cached) {
            (true, Some(sim)) => Some(sim),
            (true, None) => Some(self.model.simulate(theta, rec, x0).ok()?),
            (false, _) => None,
        };
        let column = |j: usize| -> Option<FdColumn> {
            let mut th = theta.to_vec();
            let mut x = x0.to_vec();
            let base = if j < p { th[j] } else { x[j - p] };
            let h = 1e-5 * (base.abs() + 1e-3 * scale);
            let mut eval = |delta: f64| {
                if j < p {
                    th[j] = base + delta;
                } else {
                    x[j - p] = base + delta;
                }
                self.model.simulate(&th, rec, &x).ok()
            };
            let up = eval(h)?;
            match &base_sim {
                // (up − base)/h written as (up − dn)/(2h) with dn = 2 base − up.
                Some(b) => {
                    let dn = up
                        .iter()
                        .zip(b)
                        .map(|(u, b)| u.iter().zip(b).map(|(u, b)| 2.0 * b - u).collect())
                        .collect();
                    Some((j, h, up, dn))
                }
                None => Some((j, h, up, eval(-h)?)),
            }
        };
        let workers = std::thread::available_parallelism()
            .map_or(1, |n| n.get())
            .clamp(1, p + s);
        let done: Vec<Option<FdColumn>> = std::thread::scope(|scope| {
            let handles: Vec<_> = (0..workers)
                .map(|w| {
                    let column = &column;
                    scope.spawn(move || (w..p + s).step_by(workers).map(column).collect::<Vec<_>>())
                })
                .collect();
            // A worker that panicked (inside a model) counts as a failed simulation.
            handles
                .into_iter()
                .flat_map(|h| h.join().unwrap_or_else(|_| vec![None]))
                .collect()
        });
        let mut out = Sensitivities {
            theta: vec![DMatrix::zeros(n, p); s],
            initial: vec![DMatrix::zeros(n, s); s],
        };
        for item in done {
            let (j, h, up, dn) = item?;
            for c in 0..s {
                let (m, col) = if j < p {
                    (&mut out.theta[c], j)
                } else {
                    (&mut out.initial[c], j - p)
                };
                for k in 0..n {
                    m[(k, col)] = (up[c][k] - dn[c][k]) / (2.0 * h);
                }
            }
        }
        Some(out)
    }
    /// Weighted Jacobian of the residuals with respect to (θ, x0) — not u — time-major rows.
    fn jacobian_theta(&self, u: &na::DVector<f64>) -> Option<DMatrix<f64>> {
        let (p, s) = (self.p(), self.nch());
        let cols = p + self
            .fixed_initial
            .as_ref()
            .map_or(s * self.recs.len(), |_| 0);
        let theta = self.theta_of(u);
        // The residuals are not asked for again at a Jacobian's u (not held through its peak).
        self.last_raw.replace(None);
        let mut jac = DMatrix::zeros(self.rows, cols);
        let mut cached = match self.last_simulation.take() {
            Some((at, sims)) if at == *u => sims.into_iter().map(Some).collect(),
            _ => vec![None; self.recs.len()],
        };
        for (r, rec) in self.recs.iter().enumerate() {
            let sens = self.sensitivities(&theta, &self.initial_of(u, r), rec, cached[r].take())?;
            let channels = sens.theta.iter().zip(&sens.initial).zip(&self.weight);
            // Column by column (both matrices are column-major): row offsets[r] + i·s + c of
            // column j is −w_c ∂ŷ_c(t_k)/∂(θ, x0)_j, k = index[r][i].
            for (c, ((st, si), &w)) in channels.enumerate() {
                let mut fill = |col: usize, src: &[f64]| {
                    let dst = &mut jac.column_mut(col);
                    for (i, &k) in self.index[r].iter().enumerate() {
                        dst[self.offsets[r] + i * s + c] = -w * src[k];
                    }
                };
                let n = st.nrows();
                for j in 0..p {
                    fill(j, &st.as_slice()[j * n..(j + 1) * n]);
                }
                if self.fixed_initial.is_none() {
                    for i in 0..s {
                        fill(p + r * s + i, &si.as_slice()[i * n..(i + 1) * n]);
                    }
                }
            }
        }
        jac.iter().all(|x| x.is_finite()).then_some(jac)
    }
}

/// The measured output columns of a recording, in channel order (v, ω).
fn measured(rec: &Recording) -> [&[f64]; 2] {
    [&rec.v, &rec.w]
}

impl<M: DynamicModel + ?Sized> LeastSquaresProblem<f64, na::Dyn, na::Dyn> for Problem<'_, M> {
    type ResidualStorage = na::VecStorage<f64, na::Dyn, na::U1>;
    type JacobianStorage = na::VecStorage<f64, na::Dyn, na::Dyn>;
    type ParameterStorage = na::VecStorage<f64, na::Dyn, na::U1>;

    fn set_params(&mut self, u: &na::DVector<f64>) {
        self.u.copy_from(u);
    }

    fn params(&self) -> na::DVector<f64> {
        self.u.clone()
    }

    fn residuals(&self) -> Option<na::DVector<f64>> {
        let theta = self.theta_of(&self.u);
        let Some(raw) = self.raw_residuals(&theta, &self.u) else {
            return Some(na::DVector::from_element(self.rows, PENALTY));
        };
        let s = self.nch();
        let mut out = na::DVector::zeros(self.rows);
        for (r, per) in raw.iter().enumerate() {
            for (c, e) in per.iter().enumerate() {
                for (i, &k) in self.index[r].iter().enumerate() {
                    out[self.offsets[r] + i * s + c] = self.weight[c] * e[k];
                }
            }
        }
        Some(out)
    }

    fn jacobian(&self) -> Option<na::DMatrix<f64>> {
        let jac = self.jacobian_theta(&self.u)?;
        let p = self.p();
        // Chain rule to u: each θ column scaled by dθ/du (the x0 columns are u's own); the
        // minimiser's nalgebra is another version, whose matrix takes the same column-major
        // values.
        let mut out = na::DMatrix::from_column_slice(jac.nrows(), jac.ncols(), jac.as_slice());
        for (j, mut col) in out.column_iter_mut().enumerate().take(p) {
            col *= self.transform[j].dtheta_du(self.u[j]);
        }
        self.last_jacobian.replace(Some((self.u.clone(), jac)));
        Some(out)
    }
}

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
        let (problem, raw, evaluations, termination) = self.minimise(problem)?;
        let mut fit = self.uncertainty(problem, &raw, termination)?;
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
        let (problem, _, evaluations, _) = head_fit.minimise(problem).ok()?;
        Some((problem.theta_of(&problem.u), evaluations))
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
            u: na::DVector::from_vec(u0),
            offsets,
            index,
            mask,
            forward: self.forward_differences,
            rows,
            last_jacobian: RefCell::new(None),
            last_simulation: RefCell::new(None),
            last_raw: RefCell::new(None),
        })
    }

    /// Minimises the problem's cost by Levenberg–Marquardt, passes re-weighting the channels
    /// (module doc); returns the problem at θ̂ with its raw residuals, the residual
    /// evaluations and how the last pass ended.
    fn minimise<'a, M: DynamicModel + ?Sized>(
        &self,
        mut problem: Problem<'a, M>,
    ) -> Result<Minimised<'a, M>, SolveError> {
        let s = problem.nch();
        let (active, unknowns) = (problem.rows, problem.u.len());
        let lm = LevenbergMarquardt::new()
            .with_ftol(self.tolerance)
            .with_xtol(self.tolerance)
            .with_gtol(0.0)
            .with_patience(self.patience);
        let mut evaluations = 0;
        let mut termination = TerminationReason::NoParameters;
        let theta = problem.theta_of(&problem.u);
        let mut raw = problem.raw_residuals(&theta, &problem.u).ok_or_else(|| {
            SolveError::InvalidProblem(format!(
                "the model does not simulate (finitely) at θ = {theta:?}"
            ))
        })?;
        for pass in 0..MAX_PASSES {
            let weight: Vec<f64> = channel_std(&raw, &problem.mask, active, unknowns)
                .iter()
                .map(|&sd| 1.0 / sd.max(1e-12))
                .collect();
            // Only the ratios move the minimiser (module doc).
            let settled = weight.iter().zip(&problem.weight).all(|(a, b)| {
                ((a / weight[0]) / (b / problem.weight[0]) - 1.0).abs() < WEIGHT_TOLERANCE
            });
            if pass > 0 && settled {
                // The last Jacobian is re-weighted with the weights at θ̂: rows are
                // time-major, so row i belongs to channel i mod s.
                if let Some((_, jac)) = problem.last_jacobian.get_mut() {
                    for (i, mut row) in jac.row_iter_mut().enumerate() {
                        row *= weight[i % s] / problem.weight[i % s];
                    }
                }
                problem.weight = weight;
                break;
            }
            problem.weight = weight;
            problem.last_jacobian.replace(None);
            let (solved, report) = lm.minimize(problem);
            problem = solved;
            evaluations += report.number_of_evaluations;
            termination = report.termination;
            if !termination.was_successful()
                && !matches!(
                    termination,
                    TerminationReason::LostPatience | TerminationReason::NoImprovementPossible(_)
                )
            {
                return Err(SolveError::Numerical(format!(
                    "Levenberg–Marquardt stopped: {termination:?}"
                )));
            }
            let theta = problem.theta_of(&problem.u);
            raw = problem.raw_residuals(&theta, &problem.u).ok_or_else(|| {
                SolveError::Numerical("the fitted model does not simulate".into())
            })?;
        }
        Ok((problem, raw, evaluations, termination))
    }

    /// The fit at the problem's θ̂: the sandwich covariance (module doc) from the last
    /// iteration's Jacobian when it was taken there, else a new one; `evaluations` and
    /// `seconds` are the caller's to fill.
    fn uncertainty<M: DynamicModel + ?Sized>(
        &self,
        problem: Problem<'_, M>,
        raw: &[Vec<Vec<f64>>],
        termination: TerminationReason,
    ) -> Result<OutputErrorFit, SolveError> {
        let (model, recordings) = (problem.model, problem.recs);
        let (p, s) = (problem.p(), problem.nch());
        let (rows, unknowns) = (problem.rows, problem.u.len());
        let active = rows;
        let status = match termination {
            TerminationReason::LostPatience => SolveStatus::IterationLimit,
            TerminationReason::NoImprovementPossible(_) => SolveStatus::AlmostSolved,
            _ => SolveStatus::Solved,
        };
        // Uncertainty at θ̂ (module doc), with the Jacobian of the last iteration if it was
        // taken at θ̂ or within the last, converged step of it.
        let u = problem.u.clone();
        let theta = problem.theta_of(&u);
        let noise_std = channel_std(raw, &problem.mask, active, unknowns);
        let cached = problem
            .last_jacobian
            .take()
            .and_then(|(at, j)| ((&u - at).norm() <= JACOBIAN_REUSE * u.norm()).then_some(j));
        let jac = match cached {
            Some(j) => j,
            None => problem
                .jacobian_theta(&u)
                .ok_or_else(|| SolveError::Numerical("non-finite sensitivities at θ̂".into()))?,
        };
        let e = problem.weighted_rows(raw);
        let longest = recordings.iter().map(Recording::len).max().unwrap_or(0);
        let lags = self
            .correlation_lags
            .unwrap_or_else(|| (4.0 * (longest as f64 / 100.0).powf(2.0 / 9.0)).floor() as usize);
        let names = self.unknown_names(model, recordings.len());
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
        let jac_free = jac.select_columns(keep.iter());
        let name_refs: Vec<&str> = keep.iter().map(|&j| names[j].as_str()).collect();
        let lp = LinearProblem {
            x: &jac_free,
            y: &e,
            names: &name_refs,
            bounds: None,
            correlation_lags: 0,
        };
        let d = ols::decompose(&lp, 1e-12)?;
        let full = sandwich(&d, &jac_free, &e, &problem.spans(), s, lags, active);
        let mut covariance = DMatrix::zeros(p, p);
        for (a, &i) in keep.iter().enumerate().filter(|(_, i)| **i < p) {
            for (b, &j) in keep.iter().enumerate().filter(|(_, j)| **j < p) {
                covariance[(i, j)] = full[(a, b)];
            }
        }
        let initial = (0..recordings.len())
            .map(|r| problem.initial_of(&u, r))
            .collect();
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
fn channel_std(
    raw: &[Vec<Vec<f64>>],
    mask: &[Vec<bool>],
    rows: usize,
    unknowns: usize,
) -> Vec<f64> {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn transforms_round_trip_and_stay_inside() {
        for t in [
            Transform::Free,
            Transform::Both(-1.0, 3.0),
            Transform::Lower(0.5),
            Transform::Upper(-2.0),
        ] {
            for x in [0.7f64, 1.9, -0.3] {
                let x = match t {
                    Transform::Lower(lo) => lo + x.abs(),
                    Transform::Upper(hi) => hi - x.abs(),
                    _ => x,
                };
                let u = t.u(x);
                approx::assert_relative_eq!(t.theta(u), x, max_relative = 1e-12);
                let h = 1e-6;
                let fd = (t.theta(u + h) - t.theta(u - h)) / (2.0 * h);
                approx::assert_relative_eq!(t.dtheta_du(u), fd, max_relative = 1e-6);
            }
            // On a bound the transform is flat and the state says so; inside it does not.
            match t {
                Transform::Both(lo, hi) => {
                    assert_eq!(t.bound_state(t.u(hi)), BoundState::AtUpper);
                    assert_eq!(t.bound_state(t.u(lo)), BoundState::AtLower);
                    assert_eq!(t.bound_state(t.u(0.5 * (lo + hi))), BoundState::Free);
                }
                Transform::Lower(lo) => {
                    assert_eq!(t.bound_state(t.u(lo)), BoundState::AtLower);
                    assert_eq!(t.bound_state(t.u(lo + 1e-3)), BoundState::Free);
                }
                Transform::Upper(hi) => {
                    assert_eq!(t.bound_state(t.u(hi)), BoundState::AtUpper);
                    assert_eq!(t.bound_state(t.u(hi - 1e-3)), BoundState::Free);
                }
                Transform::Free => assert_eq!(t.bound_state(0.0), BoundState::Free),
            }
            for u in [-40.0, -1.0, 0.0, 2.0, 123.0] {
                let x = t.theta(u);
                match t {
                    Transform::Both(lo, hi) => assert!((lo..=hi).contains(&x)),
                    Transform::Lower(lo) => assert!(x >= lo),
                    Transform::Upper(hi) => assert!(x <= hi),
                    Transform::Free => {}
                }
            }
        }
    }
}
