//! The identification run: recordings in, θ with its uncertainty and the fit out.
//!
//! One walk through the layers, each crossed once:
//! 1. **condition** every recording on its own (`wheelid_core::condition`: restamp a
//!    window-middle recording to window ends, resample, align, filter — with one cut-off for
//!    the run, chosen by the documented rule unless given);
//! 2. **model**: build each recording's regression (eq. 4.2) and stack them per channel;
//! 3. **fit** each channel's stacked problem with the solver (eq. 4.3–4.7, by SVD or
//!    with bounds) — the least-squares answer — and then, unless least squares was asked for,
//!    remove its errors-in-variables bias with the chosen estimator
//!    ([`wheelid_core::Estimator`], by name; [`crate::estimators`] and plugins'): output error
//!    (`wheelid_solvers::oe`, the default) or instrumental variables (`wheelid_solvers::iv`),
//!    both started from the least-squares θ; output error runs on the recordings' own stamps
//!    (non-uniform ones included) and, where a recording does not state how its host stamped
//!    it, estimates the command-to-response offset with θ ([`crate::timing`]);
//! 4. **validate**: simulate the identified model free-run from each recording's commands and
//!    compare with the measurements (fit %, as MATLAB's `compare`); estimate θ4 and θ6 from
//!    steady constant-command segments as the thesis's §4.1 suggests.

use std::path::PathBuf;

use serde::Serialize;
use wheelid_core::condition::{ConditionSettings, CutoffChoice};
use wheelid_core::{
    BoundState, ChannelRegression, Conditioned, Estimator, Recording, RegressorModel, SolveError,
    SolveStatus, Solver,
};

use crate::timing::TimingReport;

mod checks;
mod estimators;
mod prepare;
mod validation;
pub use checks::POOR_FIT_PERCENT;

/// Errors of an identification run.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum IdentifyError {
    /// Reading or conditioning a recording failed.
    #[error(transparent)]
    Core(#[from] wheelid_core::Error),
    /// A channel's least-squares problem could not be solved.
    #[error("channel `{channel}`: {source}")]
    Solve {
        /// The channel.
        channel: String,
        /// Why.
        #[source]
        source: SolveError,
    },
    /// Unknown model or solver name, bad bounds, or commands that excite nothing.
    #[error("{0}")]
    Setting(String),
    /// No estimator gave a model (each estimate unstable, non-finite or with a singular
    /// covariance); the message says why for each.
    #[error("{0}")]
    NoModel(String),
}

/// Settings of an identification run (separate from its result, [`Identification`]).
#[derive(Debug, Clone, PartialEq)]
pub struct IdentifySettings {
    /// Conditioning (cut-off, filter order, derivative stencil).
    pub condition: ConditionSettings,
    /// Bounds on θ (lower, upper) for bounded solvers, one per parameter (kept by the
    /// bounded least-squares solver and by output error; the IV answer is projected onto them).
    pub bounds: Option<Vec<(f64, f64)>>,
    /// The name of the estimator whose θ is the answer: `ls` (the thesis's filtered
    /// regression, Laut 2011 eq. 4.3–4.7), `iv` (instrumental variables), `oe` (output error,
    /// the default) or a plugin's ([`crate::registry::Registry`]).
    pub estimator: String,
    /// Also run the other estimators and report every θ side by side.
    pub compare: bool,
    /// Return the estimate asked for even when no estimate is a model (flagged in
    /// `warnings` and `estimates[..].invalid`) instead of [`IdentifyError::NoModel`]: for a
    /// caller that only starts from it (the diagnosis starts its own fit from least squares).
    pub allow_invalid: bool,
}

impl Default for IdentifySettings {
    fn default() -> Self {
        Self {
            condition: ConditionSettings::default(),
            bounds: None,
            estimator: crate::estimators::oe::NAME.into(),
            compare: false,
            allow_invalid: false,
        }
    }
}

/// One estimator's answer, for the side-by-side report.
#[derive(Debug, Clone, Serialize)]
pub struct EstimateReport {
    /// Which estimator (its name: `ls`, `iv`, `oe`, a plugin's).
    pub estimator: String,
    /// θ̂.
    pub theta: Vec<f64>,
    /// Standard errors of θ̂.
    pub std_err: Vec<f64>,
    /// How it ended.
    pub status: SolveStatus,
    /// Per-parameter bound state.
    pub bound_state: Vec<BoundState>,
    /// Why this estimate is no model (unstable, non-finite, singular covariance), if it is
    /// not one; such an estimate is never the answer.
    pub invalid: Option<String>,
    /// Iterations (IV) or residual evaluations (OE); 1 for least squares.
    pub iterations: usize,
    /// Wall time \[s\].
    pub seconds: f64,
}

/// One recording's part in the run.
#[derive(Debug, Clone, Serialize)]
pub struct FileReport {
    /// Where it came from.
    pub source: PathBuf,
    /// Samples used (after resampling).
    pub samples: usize,
    /// Sample period \[s\].
    pub dt: f64,
    /// Median period before resampling \[s\], if it was resampled onto a uniform grid.
    pub resampled_from: Option<f64>,
    /// Free-run fit % per channel on this recording.
    pub fit_percent: Vec<f64>,
    /// Initial state (v0, ω0) of the free-run simulation: estimated by output error, else the
    /// smoothed first sample.
    pub initial: Vec<f64>,
}

/// Per-channel fit quality.
#[derive(Debug, Clone, Serialize)]
pub struct ChannelReport {
    /// Channel name (`v`, `w`).
    pub name: String,
    /// R² of the (filtered) regression.
    pub r2: f64,
    /// Free-run fit % over all recordings: 100·(1 − ‖y − ŷ‖/‖y − ȳ‖).
    pub fit_percent: f64,
    /// Condition number of the column-normalised regressor.
    pub condition_number: f64,
    /// Samples in the stacked regression.
    pub samples: usize,
}

/// The steady-state estimate of θ4 or θ6 (thesis §4.1, last paragraph).
#[derive(Debug, Clone, Copy, Serialize)]
pub struct SteadyStateEstimate {
    /// Duration-weighted mean of the ratios over the segments.
    pub value: f64,
    /// Number of constant-command segments used.
    pub segments: usize,
    /// Total settled time used \[s\].
    pub seconds: f64,
}

/// Data behind the plots: one recording's measured and simulated outputs, every k-th sample
/// of a long recording (at most [`FileSeries::MAX_POINTS`] a series; all of a shorter one).
#[derive(Debug, Clone)]
pub struct FileSeries {
    /// Source.
    pub source: PathBuf,
    /// Time \[s\].
    pub t: Vec<f64>,
    /// Measured outputs per channel.
    pub measured: Vec<Vec<f64>>,
    /// Simulated (free-run) outputs per channel.
    pub simulated: Vec<Vec<f64>>,
}

impl FileSeries {
    /// Most samples a series keeps: a plot is a few thousand pixels wide.
    pub const MAX_POINTS: usize = 20_000;

    /// Every k-th sample (k = ⌈n / [`FileSeries::MAX_POINTS`]⌉) of `rec`'s time and measured
    /// v, ω, and of `simulated` (one series per channel, n samples each).
    pub fn thinned(source: PathBuf, rec: &Recording, simulated: Vec<Vec<f64>>) -> Self {
        let step = rec.len().div_ceil(Self::MAX_POINTS).max(1);
        let thin = |x: &[f64]| -> Vec<f64> { x.iter().step_by(step).copied().collect() };
        Self {
            source,
            t: thin(&rec.t),
            measured: vec![thin(&rec.v), thin(&rec.w)],
            simulated: if step == 1 {
                simulated
            } else {
                simulated.iter().map(|y| thin(y)).collect()
            },
        }
    }
}

/// The result of an identification run.
#[derive(Debug, Clone)]
pub struct Identification {
    /// Model name.
    pub model: String,
    /// Solver name.
    pub solver: String,
    /// Parameter names.
    pub param_names: Vec<String>,
    /// Parameter units.
    pub param_units: Vec<String>,
    /// The estimator whose answer `theta` is: the one asked for, or the best valid one when
    /// it gave no model (`warnings` says why); its name.
    pub estimator: String,
    /// What the answer cannot say, in words: a fallback from the estimator asked for, a lag
    /// shorter than a sample, a poor free-run fit (pointing at `wheelid diagnose`).
    pub warnings: Vec<String>,
    /// θ̂.
    pub theta: Vec<f64>,
    /// Standard errors of θ̂ (least squares and IV: Newey–West over the filter's correlation
    /// length; output error: sandwich from the Jacobian, see `wheelid_solvers::oe`).
    pub std_err: Vec<f64>,
    /// Every estimator run: least squares always (it is the start), the chosen one, and with
    /// `compare` all of them, least squares first, then in the registry's order.
    pub estimates: Vec<EstimateReport>,
    /// How far θ moved from the least-squares answer, (θ̂ − θ̂_LS)/θ̂_LS in % per parameter:
    /// a large shift means the regression was biased (noise in the regressors, coarse sampling).
    pub ls_shift_percent: Vec<f64>,
    /// Output-error residual standard deviation per channel (the measurement noise if the
    /// model is right), when output error ran.
    pub noise_std: Option<Vec<f64>>,
    /// Per-parameter bound state.
    pub bound_state: Vec<BoundState>,
    /// Cut-off used \[Hz\].
    pub cutoff_hz: f64,
    /// How it was chosen.
    pub cutoff_choice: CutoffChoice,
    /// Filter order used.
    pub filter_order: usize,
    /// Total samples.
    pub samples: usize,
    /// Per-channel quality.
    pub channels: Vec<ChannelReport>,
    /// Per-file details.
    pub files: Vec<FileReport>,
    /// θ4 from steady forward segments, if any.
    pub steady_theta4: Option<SteadyStateEstimate>,
    /// θ6 from steady turning segments, if any.
    pub steady_theta6: Option<SteadyStateEstimate>,
    /// Measured vs simulated series, for plots.
    pub series: Vec<FileSeries>,
    /// Stacked regressions per channel, for the regression plots: every k-th row of a long
    /// run (at most 20,000 rows a channel).
    pub regressions: Vec<ChannelRegression>,
    /// The stamping convention the output-error fit used, stated or estimated (`None` when
    /// output error did not run).
    pub timing: Option<TimingReport>,
}

/// Runs an identification of `model` with `solver` on `recordings` (one multi-experiment
/// problem: each recording conditioned on its own, regressions stacked), with the built-in
/// estimators ([`crate::estimators::built_in`]); [`identify_with`] takes others too.
///
/// # Errors
/// [`IdentifyError`] for unreadable or too-short data, a rank-deficient or infeasible problem.
pub fn identify(
    recordings: &[Recording],
    model: &dyn RegressorModel,
    solver: &dyn Solver,
    settings: &IdentifySettings,
) -> Result<Identification, IdentifyError> {
    identify_with(
        recordings,
        model,
        solver,
        &crate::estimators::built_in(),
        settings,
    )
}

/// [`identify`] with the refining estimators `estimators` (built-ins and plugins', in report
/// order, as [`crate::registry::Registry::estimators`] lists them): `settings.estimator`
/// names least squares (`ls`) or one of them; with `settings.compare` every one runs.
///
/// # Errors
/// [`IdentifyError::Setting`] for an estimator name not among them (listing the known ones);
/// otherwise as [`identify`].
pub fn identify_with(
    recordings: &[Recording],
    model: &dyn RegressorModel,
    solver: &dyn Solver,
    estimators: &[Box<dyn Estimator>],
    settings: &IdentifySettings,
) -> Result<Identification, IdentifyError> {
    check_settings(recordings, model, settings)?;
    check_estimator(&settings.estimator, estimators)?;
    // 1. condition
    let data = prepare::prepare(recordings, settings)?;
    // 2.–3. model and fit: least squares, then the refining estimators asked for.
    let ls = estimators::least_squares(model, solver, &data, settings)?;
    // A constant command whose channel least squares still solved (noise makes the
    // regressors full rank) is no information either.
    checks::check_excitation(recordings)?;
    let Refined {
        mut estimates,
        free_runs,
        noise_std,
        timing,
    } = refine_all(estimators, model, &data, &ls.report, settings)?;
    // Never a nonsense answer: the estimate asked for, or the best valid one.
    // A plugin's model that does not extend eq. 2.19 gets the finiteness and covariance
    // checks only.
    let eq_2_19 = wheelid_core::extends_eq_2_19(model.params());
    for e in &mut estimates {
        e.invalid = checks::invalid(e, &e.bound_state, eq_2_19);
    }
    let (estimator, mut warnings) =
        checks::choose(&estimates, &settings.estimator, settings.allow_invalid)?;
    let chosen = estimates
        .iter()
        .find(|e| e.estimator == estimator)
        .ok_or_else(|| IdentifyError::Setting("the chosen estimate is missing".into()))?;
    let (theta, std_err, bound_state) = (
        chosen.theta.clone(),
        chosen.std_err.clone(),
        chosen.bound_state.clone(),
    );
    let ls_shift_percent = theta
        .iter()
        .zip(&ls.report.theta)
        .map(|(t, l)| 100.0 * (t - l) / l.abs())
        .collect();
    // 4. validate: free-run simulation per recording, as the chosen estimator fitted them.
    let free_run = free_runs.into_iter().find(|(e, _)| *e == estimator);
    let validation::Validation {
        files,
        series,
        channels,
    } = validation::validate_free_run(model, &theta, &data, free_run.map(|(_, f)| f), &ls.quality)?;
    let (steady_theta4, steady_theta6) = steady_state(&data.conditioned, &theta);
    let dt = files.iter().map(|f| f.dt).fold(f64::INFINITY, f64::min);
    if eq_2_19 {
        warnings.extend(checks::lag_notices(&theta, dt));
    }
    warnings.extend(checks::poor_fit(&channels, recordings));
    Ok(Identification {
        model: model.name().into(),
        solver: solver.name().into(),
        estimator,
        warnings,
        estimates,
        ls_shift_percent,
        noise_std,
        param_names: model.params().iter().map(|q| q.name.to_owned()).collect(),
        param_units: model.params().iter().map(|q| q.unit.to_owned()).collect(),
        theta,
        std_err,
        bound_state,
        cutoff_hz: data.cutoff_hz,
        cutoff_choice: data.cutoff_choice,
        filter_order: settings.condition.order,
        samples: data.conditioned.iter().map(Conditioned::len).sum(),
        channels,
        files,
        steady_theta4,
        steady_theta6,
        series,
        regressions: ls.regressions,
        timing,
    })
}

/// Every estimate of a run, least squares' first, with what the refining estimators add.
struct Refined {
    estimates: Vec<EstimateReport>,
    /// Each refining estimator's free run (its name with it), when it gave one.
    free_runs: Vec<(String, wheelid_core::FreeRun)>,
    /// Output error's residual standard deviations, when it ran.
    noise_std: Option<Vec<f64>>,
    /// The stamping convention output error used, when it ran.
    timing: Option<TimingReport>,
}

/// Runs the refining estimators asked for (`settings.estimator`, or all with
/// `settings.compare`) from least squares' answer `ls`.
///
/// # Errors
/// As [`estimators::refine`].
fn refine_all(
    estimators: &[Box<dyn Estimator>],
    model: &dyn RegressorModel,
    data: &prepare::Prepared<'_>,
    ls: &EstimateReport,
    settings: &IdentifySettings,
) -> Result<Refined, IdentifyError> {
    let mut out = Refined {
        estimates: vec![ls.clone()],
        free_runs: Vec::new(),
        noise_std: None,
        timing: None,
    };
    for estimator in estimators {
        if estimator.name() != settings.estimator && !settings.compare {
            continue;
        }
        let (report, refined) =
            estimators::refine(estimator.as_ref(), model, data, &ls.theta, settings)?;
        out.noise_std = refined.noise_std.or(out.noise_std);
        out.timing = refined.timing.or(out.timing);
        out.free_runs
            .extend(refined.free_run.map(|f| (report.estimator.clone(), f)));
        out.estimates.push(report);
    }
    Ok(out)
}

/// `name` is least squares or one of `estimators`.
fn check_estimator(name: &str, estimators: &[Box<dyn Estimator>]) -> Result<(), IdentifyError> {
    let known: Vec<&str> = std::iter::once(crate::estimators::LEAST_SQUARES)
        .chain(estimators.iter().map(|e| e.name()))
        .collect();
    crate::estimators::check_name(name, &known).map_err(IdentifyError::Setting)
}

/// At least one recording, and bounds (when given) for each of the model's parameters.
fn check_settings(
    recordings: &[Recording],
    model: &dyn RegressorModel,
    settings: &IdentifySettings,
) -> Result<(), IdentifyError> {
    if recordings.is_empty() {
        return Err(IdentifyError::Setting("no recording given".into()));
    }
    match &settings.bounds {
        Some(b) if b.len() != model.params().len() => Err(IdentifyError::Setting(format!(
            "{} bounds given for the {} parameters of model `{}`",
            b.len(),
            model.params().len(),
            model.name()
        ))),
        _ => Ok(()),
    }
}

/// θ4 and θ6 from constant-command segments (thesis §4.1): in a segment where v_ref and ω_ref
/// stay constant, after 3 time constants (θ1/θ4 resp. θ2/θ6 from the regression, at least 0.5 s)
/// the model's steady state gives θ4 = (v_ref + θ3 ω²)/v and θ6 = (ω_ref − θ5 v ω)/ω; the
/// θ3, θ5 corrections vanish on straight or pure-turn segments, which is the thesis's setting.
/// Segments need ≥ 1 s of settled data and |v| ≥ 0.05 m/s (|ω| ≥ 0.05 rad/s).
fn steady_state(
    data: &[Conditioned<'_>],
    theta: &[f64],
) -> (Option<SteadyStateEstimate>, Option<SteadyStateEstimate>) {
    // A time constant that is not finite (θ4 or θ6 at 0) or longer than a minute leaves no
    // settled segment to use.
    let tau = |a: f64, b: f64| Some((a / b).abs().max(0.5)).filter(|t| *t <= 60.0);
    let (Some(tau_v), Some(tau_w)) = (tau(theta[0], theta[3]), tau(theta[1], theta[5])) else {
        return (None, None);
    };
    let mut acc = [(0.0, 0usize, 0.0), (0.0, 0usize, 0.0)];
    for c in data {
        let rec = &c.recording;
        let n = rec.len();
        // Samples to settle (3 time constants) per channel, and a second's worth.
        let settle_in = [tau_v, tau_w].map(|tau| (3.0 * tau / c.dt).ceil() as usize);
        let second = (1.0 / c.dt) as usize;
        let mut start = 0;
        while start < n {
            let mut end = start + 1;
            while end < n
                && (rec.v_ref[end] - rec.v_ref[start]).abs() < 1e-9
                && (rec.w_ref[end] - rec.w_ref[start]).abs() < 1e-9
            {
                end += 1;
            }
            for (ch, settle_in) in settle_in.into_iter().enumerate() {
                let settle = start + settle_in;
                if settle + second > end {
                    continue;
                }
                let m = (end - settle) as f64;
                let v = rec.v[settle..end].iter().sum::<f64>() / m;
                let w = rec.w[settle..end].iter().sum::<f64>() / m;
                let (num, den) = if ch == 0 {
                    (rec.v_ref[start] + theta[2] * w * w, v)
                } else {
                    (rec.w_ref[start] - theta[4] * v * w, w)
                };
                if den.abs() < 0.05 {
                    continue;
                }
                let secs = m * c.dt;
                acc[ch].0 += num / den * secs;
                acc[ch].1 += 1;
                acc[ch].2 += secs;
            }
            start = end;
        }
    }
    let out = |(sum, segs, secs): (f64, usize, f64)| {
        (segs > 0).then(|| SteadyStateEstimate {
            value: sum / secs,
            segments: segs,
            seconds: secs,
        })
    };
    (out(acc[0]), out(acc[1]))
}
