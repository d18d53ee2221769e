//! The identification run: recordings in, θ with its uncertainty and the fit out.
//!
//! One walk through the layers, each crossed once:
//! 1. **condition** every recording on its own (`wheelid_core::condition`: restamp a
//!    window-middle recording to window ends, resample, align, filter — with one cut-off for
//!    the run, chosen by the documented rule unless given);
//! 2. **model**: build each recording's regression (eq. 4.2) and stack them per channel;
//! 3. **fit** each channel's stacked problem with the solver (eq. 4.3–4.7, by SVD or
//!    with bounds) — the least-squares answer — and then, unless least squares was asked for,
//!    remove its errors-in-variables bias with the chosen [`Estimator`]: output error
//!    (`wheelid_solvers::oe`, the default) or instrumental variables (`wheelid_solvers::iv`),
//!    both started from the least-squares θ; output error runs on the recordings' own stamps
//!    (non-uniform ones included) and, where a recording does not state how its host stamped
//!    it, estimates the command-to-response offset with θ ([`crate::timing`]);
//! 4. **validate**: simulate the identified model free-run from each recording's commands and
//!    compare with the measurements (fit %, as MATLAB's `compare`); estimate θ4 and θ6 from
//!    steady constant-command segments as the thesis's §4.1 suggests.

use std::borrow::Cow;
use std::path::PathBuf;

use serde::{Deserialize, Serialize};
use wheelid_core::DynamicModel;
use wheelid_core::condition::{self, ConditionSettings, CutoffChoice};
use wheelid_core::{
    BoundState, ChannelRegression, Conditioned, LinearProblem, Recording, RegressorModel,
    SolveError, SolveStatus, Solver, metrics,
};
use wheelid_models::CommandOffset;
use wheelid_solvers::{InstrumentalVariables, OutputError};

use crate::timing::{TimingReport, fit_with_timing};

mod checks;
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
#[derive(Debug, Clone, PartialEq, Default)]
pub struct IdentifySettings {
    /// Conditioning (cut-off, filter order, derivative stencil).
    pub condition: ConditionSettings,
    /// Bounds on θ (lower, upper) for bounded solvers, one per parameter (kept by the
    /// bounded least-squares solver and by output error; the IV answer is projected onto them).
    pub bounds: Option<Vec<(f64, f64)>>,
    /// The estimator whose θ is the answer.
    pub estimator: Estimator,
    /// Also run the other estimators and report every θ side by side.
    pub compare: bool,
    /// Return the estimate asked for even when no estimate is a model (flagged in
    /// `warnings` and `estimates[..].invalid`) instead of [`IdentifyError::NoModel`]: for a
    /// caller that only starts from it (the diagnosis starts its own fit from least squares).
    pub allow_invalid: bool,
}

/// How θ is estimated from the recordings.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum Estimator {
    /// Least squares on the filtered regression (Laut 2011 eq. 4.3–4.7): fast, but biased when
    /// the regressors are noisy or coarsely sampled (errors in variables).
    Ls,
    /// Instrumental variables with simulated noise-free instruments, iterated
    /// (`wheelid_solvers::iv`): linear and fast; removes the noise bias, not the
    /// discretization error of the derivatives.
    Iv,
    /// Output error: θ whose free-run simulation matches the measurements
    /// (`wheelid_solvers::oe`): no filter, no derivative, no cut-off in the answer.
    #[default]
    Oe,
}

impl Estimator {
    /// Every estimator, in report order.
    pub const ALL: [Estimator; 3] = [Estimator::Ls, Estimator::Iv, Estimator::Oe];

    /// Short name (`ls`, `iv`, `oe`).
    pub fn name(self) -> &'static str {
        match self {
            Estimator::Ls => "ls",
            Estimator::Iv => "iv",
            Estimator::Oe => "oe",
        }
    }
}

/// One estimator's answer, for the side-by-side report.
#[derive(Debug, Clone, Serialize)]
pub struct EstimateReport {
    /// Which estimator.
    pub estimator: Estimator,
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
    /// Wall time [s].
    pub seconds: f64,
}

/// One recording's part in the run.
#[derive(Debug, Clone, Serialize)]
pub struct FileReport {
    /// Where it came from.
    pub source: PathBuf,
    /// Samples used (after resampling).
    pub samples: usize,
    /// Sample period [s].
    pub dt: f64,
    /// Median period before resampling [s], if it was resampled onto a uniform grid.
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
    /// Total settled time used [s].
    pub seconds: f64,
}

/// Data behind the plots: one recording's measured and simulated outputs.
#[derive(Debug, Clone)]
pub struct FileSeries {
    /// Source.
    pub source: PathBuf,
    /// Time [s].
    pub t: Vec<f64>,
    /// Measured outputs per channel.
    pub measured: Vec<Vec<f64>>,
    /// Simulated (free-run) outputs per channel.
    pub simulated: Vec<Vec<f64>>,
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
    /// it gave no model (`warnings` says why).
    pub estimator: Estimator,
    /// What the answer cannot say, in words: a fallback from the estimator asked for, a lag
    /// shorter than a sample, a poor free-run fit (pointing at `wheelid diagnose`).
    pub warnings: Vec<String>,
    /// θ̂.
    pub theta: Vec<f64>,
    /// Standard errors of θ̂ (least squares and IV: Newey–West over the filter's correlation
    /// length; output error: sandwich from the Jacobian, see `wheelid_solvers::oe`).
    pub std_err: Vec<f64>,
    /// Every estimator run: least squares always (it is the start), the chosen one, and with
    /// `compare` all of them, in [`Estimator::ALL`] order.
    pub estimates: Vec<EstimateReport>,
    /// How far θ moved from the least-squares answer, (θ̂ − θ̂_LS)/θ̂_LS in % per parameter:
    /// a large shift means the regression was biased (noise in the regressors, coarse sampling).
    pub ls_shift_percent: Vec<f64>,
    /// Output-error residual standard deviation per channel (the measurement noise if the
    /// model is right), when output error ran.
    pub noise_std: Option<Vec<f64>>,
    /// Per-parameter bound state.
    pub bound_state: Vec<BoundState>,
    /// Cut-off used [Hz].
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
    /// Stacked regressions per channel (for the regression plots).
    pub regressions: Vec<ChannelRegression>,
    /// The stamping convention the output-error fit used, stated or estimated (`None` when
    /// output error did not run).
    pub timing: Option<TimingReport>,
}

/// Runs an identification of `model` with `solver` on `recordings` (one multi-experiment
/// problem: each recording conditioned on its own, regressions stacked).
///
/// # Errors
/// [`IdentifyError`] for unreadable or too-short data, a rank-deficient or infeasible problem.
pub fn identify(
    recordings: &[Recording],
    model: &dyn RegressorModel,
    solver: &dyn Solver,
    settings: &IdentifySettings,
) -> Result<Identification, IdentifyError> {
    if recordings.is_empty() {
        return Err(IdentifyError::Setting("no recording given".into()));
    }
    if let Some(b) = &settings.bounds
        && b.len() != model.params().len()
    {
        return Err(IdentifyError::Setting(format!(
            "{} bounds given for the {} parameters of model `{}`",
            b.len(),
            model.params().len(),
            model.name()
        )));
    }
    // 1. condition
    // Copies only where a recording changes (restamped, resampled): a 1e6-row run holds its
    // columns once.
    let restamped: Cow<'_, [Recording]> = if recordings
        .iter()
        .any(|r| r.timing() == Some(wheelid_core::Timing::WindowMiddle))
    {
        Cow::Owned(
            recordings
                .iter()
                .map(|r| condition::restamp(r).map(Cow::into_owned))
                .collect::<Result<_, _>>()?,
        )
    } else {
        Cow::Borrowed(recordings)
    };
    let uniform: Vec<(Cow<'_, Recording>, Option<f64>)> = restamped
        .iter()
        .map(condition::make_uniform)
        .collect::<Result<_, _>>()?;
    let (cutoff_hz, cutoff_choice) = match settings.condition.cutoff_hz {
        Some(fc) => (fc, CutoffChoice::Given),
        None => {
            condition::suggest_cutoff(&uniform.iter().map(|(r, _)| r.as_ref()).collect::<Vec<_>>())?
        }
    };
    let conditioned: Vec<Conditioned> = uniform
        .iter()
        .map(|(r, from)| condition::condition(r, *from, cutoff_hz, &settings.condition))
        .collect::<Result<_, _>>()?;
    // 2. model
    let per_file: Vec<Vec<ChannelRegression>> = conditioned
        .iter()
        .map(|c| model.regression(c))
        .collect::<Result<_, _>>()?;
    let regressions = ChannelRegression::stack(&per_file);
    // 3. fit: least squares, then the chosen estimator from there.
    let p = model.params().len();
    let names: Vec<&str> = model.params().iter().map(|q| q.name).collect();
    let mut theta = vec![0.0; p];
    let mut std_err = vec![0.0; p];
    let mut bound_state = vec![BoundState::Free; p];
    let mut channel_quality = Vec::new();
    // Residuals of filtered data are correlated over about one filter time constant.
    let lags = conditioned
        .iter()
        .map(|c| (1.0 / (c.dt * cutoff_hz)).ceil() as usize)
        .max()
        .unwrap_or(0);
    let clock = std::time::Instant::now();
    for reg in &regressions {
        let ch_names: Vec<&str> = reg.params.iter().map(|&i| names[i]).collect();
        let ch_bounds: Option<Vec<(f64, f64)>> = settings
            .bounds
            .as_ref()
            .map(|b| reg.params.iter().map(|&i| b[i]).collect());
        let problem = LinearProblem {
            x: &reg.x,
            y: &reg.y,
            names: &ch_names,
            bounds: ch_bounds.as_deref(),
            correlation_lags: lags,
        };
        let fit = solver
            .solve(&problem)
            .map_err(|source| IdentifyError::Solve {
                channel: reg.channel.into(),
                source,
            })?;
        for (j, &i) in reg.params.iter().enumerate() {
            theta[i] = fit.theta[j];
            std_err[i] = fit.std_err[j];
            bound_state[i] = fit.bound_state[j];
        }
        let yhat = &reg.x * &fit.theta;
        channel_quality.push((
            metrics::r_squared(reg.y.as_slice(), yhat.as_slice()),
            fit.condition_number,
            reg.y.len(),
        ));
    }
    // A constant command whose channel least squares still solved (noise makes the
    // regressors full rank) is no information either.
    checks::check_excitation(recordings)?;
    let ls = EstimateReport {
        estimator: Estimator::Ls,
        theta: theta.clone(),
        std_err: std_err.clone(),
        status: SolveStatus::Solved,
        bound_state: bound_state.clone(),
        invalid: None,
        iterations: 1,
        seconds: clock.elapsed().as_secs_f64(),
    };
    let mut estimates = vec![ls.clone()];
    let mut initial: Vec<Option<Vec<f64>>> = vec![None; conditioned.len()];
    let mut noise_std = None;
    let mut timing = None;
    // The offset δ and the recordings as output error fitted them (restamped, on their own
    // stamps), which the validation below simulates.
    let mut offset: Option<f64> = None;
    let mut fitted_recordings: Cow<'_, [Recording]> = Cow::Borrowed(&restamped);
    let refined = |e: Estimator| e == settings.estimator || settings.compare;
    if refined(Estimator::Iv) {
        let clock = std::time::Instant::now();
        let fit = InstrumentalVariables::default()
            .fit(
                model,
                &conditioned,
                &ls.theta,
                cutoff_hz,
                &settings.condition,
                lags,
            )
            .map_err(|source| IdentifyError::Solve {
                channel: "iv".into(),
                source,
            })?;
        let mut th = fit.theta.clone();
        let mut bs = vec![BoundState::Free; p];
        if let Some(b) = &settings.bounds {
            for i in 0..p {
                if th[i] < b[i].0 {
                    th[i] = b[i].0;
                    bs[i] = BoundState::AtLower;
                } else if th[i] > b[i].1 {
                    th[i] = b[i].1;
                    bs[i] = BoundState::AtUpper;
                }
            }
        }
        if settings.estimator == Estimator::Iv {
            theta.clone_from(&th);
            std_err.clone_from(&fit.std_err);
            bound_state.clone_from(&bs);
        }
        estimates.push(EstimateReport {
            estimator: Estimator::Iv,
            theta: th,
            std_err: fit.std_err,
            status: fit.status,
            bound_state: bs,
            invalid: None,
            iterations: fit.iterations,
            seconds: clock.elapsed().as_secs_f64(),
        });
    }
    if refined(Estimator::Oe) {
        let oe = OutputError {
            bounds: settings.bounds.clone(),
            ..OutputError::default()
        };
        let timed = fit_with_timing(model, &restamped, &ls.theta, &oe).map_err(|source| {
            IdentifyError::Solve {
                channel: "oe".into(),
                source,
            }
        })?;
        let fit = timed.fit;
        if settings.estimator == Estimator::Oe {
            theta = fit.theta[..p].to_vec();
            std_err = fit.std_err[..p].to_vec();
            bound_state = fit.bound_state[..p].to_vec();
            initial = fit.initial.iter().cloned().map(Some).collect();
            offset = timed.offset;
            fitted_recordings = Cow::Owned(timed.recordings);
        }
        noise_std = Some(fit.noise_std.clone());
        timing = Some(timed.timing);
        estimates.push(EstimateReport {
            estimator: Estimator::Oe,
            theta: fit.theta[..p].to_vec(),
            std_err: fit.std_err[..p].to_vec(),
            status: fit.status,
            bound_state: fit.bound_state[..p].to_vec(),
            invalid: None,
            iterations: fit.evaluations,
            seconds: fit.seconds,
        });
    }
    // Never a nonsense answer: the estimate asked for, or the best valid one.
    // A plugin's model that does not extend eq. 2.19 gets the finiteness and covariance
    // checks only.
    let eq_2_19 = wheelid_core::extends_eq_2_19(model.params());
    for e in &mut estimates {
        e.invalid = checks::invalid(e, &e.bound_state, eq_2_19);
    }
    let (estimator, mut warnings) =
        checks::choose(&estimates, settings.estimator, settings.allow_invalid)?;
    if estimator != settings.estimator {
        let e = estimates
            .iter()
            .find(|e| e.estimator == estimator)
            .ok_or_else(|| IdentifyError::Setting("the fallback estimate is missing".into()))?;
        theta.clone_from(&e.theta);
        std_err.clone_from(&e.std_err);
        bound_state.clone_from(&e.bound_state);
        if estimator != Estimator::Oe {
            initial = vec![None; conditioned.len()];
            offset = None;
            fitted_recordings = Cow::Borrowed(&restamped);
        }
    }
    let ls_shift_percent = theta
        .iter()
        .zip(&ls.theta)
        .map(|(t, l)| 100.0 * (t - l) / l.abs())
        .collect();
    // 4. validate: free-run simulation per recording.
    let nch = model.channels().len();
    let mut series = Vec::new();
    let mut files = Vec::new();
    let mut all_meas = vec![Vec::new(); nch];
    let mut all_sim = vec![Vec::new(); nch];
    let offset_params = CommandOffset::params_of(model);
    let with_offset = CommandOffset::new(model, &offset_params)?;
    for ((c, x0), rec) in conditioned
        .iter()
        .zip(initial)
        .zip(fitted_recordings.iter())
    {
        let measured = vec![rec.v.clone(), rec.w.clone()];
        let x0_estimated = x0.is_some();
        let initial = match x0 {
            Some(x) => x,
            None => vec![c.smooth(&c.v)?[0], c.smooth(&c.w)?[0]],
        };
        let simulated = match offset {
            Some(d) => {
                let mut th = theta.clone();
                th.push(d);
                with_offset.simulate(&th, rec, &initial)?
            }
            None => model.simulate(&theta, rec, &initial)?,
        };
        // A window-averaged recording's first sample averages over a window before it began,
        // under commands it does not hold: out of output error's cost, so out of the fit too
        // (its estimated initial state is free to miss it).
        let skip = usize::from(
            rec.velocity_sampling() == wheelid_core::VelocitySampling::WindowAverage
                && x0_estimated,
        );
        let fits: Vec<f64> = (0..nch)
            .map(|ch| metrics::fit_percent(&measured[ch][skip..], &simulated[ch][skip..]))
            .collect();
        for ch in 0..nch {
            all_meas[ch].extend_from_slice(&measured[ch][skip..]);
            all_sim[ch].extend_from_slice(&simulated[ch][skip..]);
        }
        files.push(FileReport {
            source: c.source.clone(),
            samples: rec.len(),
            dt: c.dt,
            resampled_from: c.resampled_from,
            fit_percent: fits,
            initial,
        });
        series.push(FileSeries {
            source: c.source.clone(),
            t: rec.t.clone(),
            measured,
            simulated,
        });
    }
    let channels: Vec<ChannelReport> = model
        .channels()
        .iter()
        .zip(&channel_quality)
        .enumerate()
        .map(|(ch, (info, &(r2, cond, n)))| ChannelReport {
            name: info.name.into(),
            r2,
            fit_percent: metrics::fit_percent(&all_meas[ch], &all_sim[ch]),
            condition_number: cond,
            samples: n,
        })
        .collect();
    let (steady_theta4, steady_theta6) = steady_state(&conditioned, &theta);
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
        param_names: names.iter().map(|s| (*s).to_owned()).collect(),
        param_units: model.params().iter().map(|q| q.unit.to_owned()).collect(),
        theta,
        std_err,
        bound_state,
        cutoff_hz,
        cutoff_choice,
        filter_order: settings.condition.order,
        samples: conditioned.iter().map(Conditioned::len).sum(),
        channels,
        files,
        steady_theta4,
        steady_theta6,
        series,
        regressions,
        timing,
    })
}

/// θ4 and θ6 from constant-command segments (thesis §4.1): in a segment where v_ref and ω_ref
/// stay constant, after 3 time constants (θ1/θ4 resp. θ2/θ6 from the regression, at least 0.5 s)
/// the model's steady state gives θ4 = (v_ref + θ3 ω²)/v and θ6 = (ω_ref − θ5 v ω)/ω; the
/// θ3, θ5 corrections vanish on straight or pure-turn segments, which is the thesis's setting.
/// Segments need ≥ 1 s of settled data and |v| ≥ 0.05 m/s (|ω| ≥ 0.05 rad/s).
fn steady_state(
    data: &[Conditioned],
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
        let mut start = 0;
        while start < n {
            let mut end = start + 1;
            while end < n
                && (rec.v_ref[end] - rec.v_ref[start]).abs() < 1e-9
                && (rec.w_ref[end] - rec.w_ref[start]).abs() < 1e-9
            {
                end += 1;
            }
            for (ch, tau) in [(0usize, tau_v), (1, tau_w)] {
                let settle = start + (3.0 * tau / c.dt).ceil() as usize;
                if settle + (1.0 / c.dt) as usize > end {
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
