//! The host's stamping convention: stated by a recording, or estimated with θ.
//!
//! Hosts stamp rows differently (`wheelid_core::Timing`, `shared/data/RECORDING_FORMAT.md`):
//! (a) velocity at t, command from t; (b) velocity averaged over the window ending at t,
//! command from t; (c) t at the window's middle, the command sent at the window's start. Read
//! under the wrong convention, a robot seems to answer up to a sample early or late, and a fit
//! absorbs that into θ1, θ2 (tens of % at robot sample rates). So:
//!
//! * a recording that states its convention (metadata `timing`, or the older
//!   `velocity_sampling`, which meant (a) or (b)) is used as stated — (c) restamped to (b)
//!   (`wheelid_core::condition::restamp`);
//! * otherwise the output-error fit finds which convention the recording follows, in two
//!   stages. (1) Each of (a), (b), (c) is a hypothesis — velocities instants or window
//!   averages, (c) restamped to window ends — fitted with θ and the initial states; the
//!   hypothesis of highest Gaussian likelihood wins,
//!
//!   ```text
//!   −2 ln L = N Σ_c ln σ̂_c²    (N samples per channel, σ̂_c the residual std of channel c)
//!   ```
//!
//!   with instants handicapped by [`INSTANT_MARGIN`] per residual (encoder odometry reports
//!   window averages; instants must explain the data clearly better). (2) Under the winner, a
//!   signed residual offset δ ∈ [−1.5 Δ, +1.5 Δ] (`wheelid_models::CommandOffset`: the
//!   commands act from t_k + δ — a latency, a host clock off by part of a sample) is fitted,
//!   and kept only if it exceeds both 3 standard errors and [`MIN_OFFSET_SAMPLES`] of a
//!   sample: a free δ trades against θ1, θ2 and would absorb unmodelled fast dynamics (on the
//!   physics backend's Pioneer, a free δ of −5 ms moved θ1 by 1.5 %). The report names the
//!   convention and the residual offset; one at the edge of the search is a dead time for
//!   `wheelid diagnose`.
//!
//! Non-uniform recordings are fitted on their own stamps: the commands switch and the windows
//! average where the stamps say, never interpolated onto a grid.

use wheelid_core::condition;
use wheelid_core::{DynamicModel, Recording, SolveError, Timing, VelocitySampling};
use wheelid_models::CommandOffset;
use wheelid_solvers::OutputError;
use wheelid_solvers::oe::OutputErrorFit;

/// Largest offset searched, in sample periods (either sign).
pub const MAX_OFFSET_SAMPLES: f64 = 1.5;

/// Smallest residual offset, in sample periods, that is fitted rather than held at zero (and
/// it must also exceed 3 standard errors): below it unmodelled fast dynamics (a filtered
/// derivative, a motor's electrical lag) would be traded against θ1, θ2.
pub const MIN_OFFSET_SAMPLES: f64 = 0.1;

/// How much lower, per residual, −2 ln L of the instant-sampling hypothesis must be to win
/// over window averages (about a 1 % smaller residual variance). Encoder odometry reports
/// window averages; and read with a command lead of Δ/2, instants mimic a window-middle stamp
/// up to the window's sinc attenuation (second order in ωΔ), which quantisation noise can hide
/// while it still moves θ1 by ~1 % at the Khepera's 23 ms and 50 Hz.
pub const INSTANT_MARGIN: f64 = 0.01;

pub use wheelid_core::estimator::{TimingReport, TimingSource};

/// The output of [`fit_with_timing`]: the fit (θ followed by δ when estimated), the recordings
/// as fitted (their sampling set), and the report.
#[derive(Debug, Clone)]
pub struct TimedFit {
    /// The output-error fit; when estimated, its θ, standard errors and covariance carry δ as
    /// the last parameter.
    pub fit: OutputErrorFit,
    /// The recordings as they were fitted (restamped, with the chosen output sampling).
    pub recordings: Vec<Recording>,
    /// The residual offset δ \[s\] when it was fitted (then the last entry of `fit.theta`).
    pub offset: Option<f64>,
    /// What timing was used.
    pub timing: TimingReport,
}

/// Longest median sample period over `recs` \[s\].
fn period(recs: &[Recording]) -> f64 {
    recs.iter()
        .map(|r| r.sampling().dt_median)
        .fold(0.0, f64::max)
}

/// Fits `model` by output error from `theta0` on `recordings` (already restamped), with the
/// timing stated or estimated (module docs). `oe.bounds`, if set, are the model's θ bounds;
/// the offset's are added.
///
/// # Errors
/// As [`OutputError::fit`] (every hypothesis failing gives the first hypothesis's error).
pub fn fit_with_timing(
    model: &dyn DynamicModel,
    recordings: &[Recording],
    theta0: &[f64],
    oe: &OutputError,
) -> Result<TimedFit, SolveError> {
    let dt = period(recordings);
    let start = physical_start(model, theta0, dt);
    match fit_from(model, recordings, &start, oe, dt) {
        Err(_) if start != theta0 => fit_from(model, recordings, theta0, oe, dt),
        Err(_) if start == theta0 => match fallback(model, theta0, dt) {
            Some(f) => fit_from(model, recordings, &f, oe, dt),
            None => fit_from(model, recordings, theta0, oe, dt),
        },
        other => other,
    }
}

/// `theta0`, or [`fallback`] when its time constants or gains (θ1, θ2, θ4, θ6 of an eq. 2.19
/// model) are not positive: least squares on badly stamped or jittered data can come out so.
fn physical_start(model: &dyn DynamicModel, theta0: &[f64], dt: f64) -> Vec<f64> {
    let sane = six_theta(model) && [0, 1, 3, 5].iter().all(|&i| theta0[i] > 0.0);
    if sane || !six_theta(model) {
        return theta0.to_vec();
    }
    fallback(model, theta0, dt).unwrap_or_else(|| theta0.to_vec())
}

/// Whether the model's first six parameters are θ1…θ6 of eq. 2.19.
fn six_theta(model: &dyn DynamicModel) -> bool {
    wheelid_core::extends_eq_2_19(model.params())
}

/// Unit gains and time constants of three periods (θ = 3Δ, 3Δ, 0, 1, 0, 1; any further
/// parameters as in `theta0`), for an eq. 2.19 model.
fn fallback(model: &dyn DynamicModel, theta0: &[f64], dt: f64) -> Option<Vec<f64>> {
    six_theta(model).then(|| {
        let mut f = theta0.to_vec();
        f[..6].copy_from_slice(&[3.0 * dt, 3.0 * dt, 0.0, 1.0, 0.0, 1.0]);
        f
    })
}

/// `oe` with the first sample of every window-averaged recording left out of the cost (added
/// to its mask): that window lies before the recording began, under commands the recording does
/// not hold, so it is not a residual of the model (one such sample can dominate the residual
/// variance of a quiet recording and so the choice between conventions).
fn without_first_windows(oe: &OutputError, recs: &[Recording]) -> OutputError {
    if recs
        .iter()
        .all(|r| r.velocity_sampling() == VelocitySampling::Instant)
    {
        return oe.clone();
    }
    let mut mask: Vec<Vec<bool>> = match &oe.mask {
        Some(m) if m.len() == recs.len() => m.clone(),
        _ => recs.iter().map(|r| vec![true; r.len()]).collect(),
    };
    for (m, r) in mask.iter_mut().zip(recs) {
        if r.velocity_sampling() == VelocitySampling::WindowAverage
            && let Some(first) = m.first_mut()
        {
            *first = false;
        }
    }
    OutputError {
        mask: Some(mask),
        ..oe.clone()
    }
}

/// [`fit_with_timing`] from one start.
fn fit_from(
    model: &dyn DynamicModel,
    recordings: &[Recording],
    theta0: &[f64],
    oe: &OutputError,
    dt: f64,
) -> Result<TimedFit, SolveError> {
    if let Some(fit) = fit_as_stated(model, recordings, theta0, oe, dt) {
        return fit;
    }
    let params = CommandOffset::params_of(model);
    let wrapped = CommandOffset::new(model, &params)
        .map_err(|e| SolveError::InvalidProblem(e.to_string()))?;
    let mut bounds = oe
        .bounds
        .clone()
        .unwrap_or_else(|| vec![(f64::NEG_INFINITY, f64::INFINITY); theta0.len()]);
    bounds.push((-MAX_OFFSET_SAMPLES * dt, MAX_OFFSET_SAMPLES * dt));
    let oe7 = OutputError {
        bounds: Some(bounds),
        ..oe.clone()
    };
    // 1. Each convention as a hypothesis, its offset pinned at zero: the likeliest wins.
    let (pinned, recs, h, hypotheses) = likeliest_convention(model, recordings, theta0, oe)?;
    // 2. A residual offset under the winner, used only where it is one.
    let mut start = pinned.theta.clone();
    start.push(0.0);
    let free = without_first_windows(&oe7, &recs)
        .fit(&wrapped, &recs, &start)
        .ok();
    let residual = free.as_ref().map(|f| {
        let last = f.theta.len() - 1;
        (f.theta[last], f.std_err[last])
    });
    let real = residual.is_some_and(|(d, sd)| d.abs() > (3.0 * sd).max(MIN_OFFSET_SAMPLES * dt));
    let timing = estimated_report(h, residual, real, dt, hypotheses);
    match (real, free) {
        (true, Some(fit)) => {
            let offset = residual.map(|(d, _)| d);
            Ok(TimedFit {
                fit,
                recordings: recs,
                timing,
                offset,
            })
        }
        _ => Ok(TimedFit {
            fit: pinned,
            recordings: recs,
            timing,
            offset: None,
        }),
    }
}

/// The fit under the conventions the recordings state, when every one states one (`None`
/// otherwise: the convention is then estimated).
fn fit_as_stated(
    model: &dyn DynamicModel,
    recordings: &[Recording],
    theta0: &[f64],
    oe: &OutputError,
    dt: f64,
) -> Option<Result<TimedFit, SolveError>> {
    let stated: Vec<Option<Timing>> = recordings.iter().map(Recording::timing).collect();
    let first = stated.first().copied().flatten()?;
    if !stated.iter().all(Option::is_some) {
        return None;
    }
    let fit = match without_first_windows(oe, recordings).fit(model, recordings, theta0) {
        Ok(fit) => fit,
        Err(e) => return Some(Err(e)),
    };
    let same = stated.iter().all(|s| *s == Some(first));
    let timing = TimingReport {
        source: TimingSource::Stated,
        stated: same.then_some(first),
        sampling: first.velocity_sampling(),
        offset_s: 0.0,
        offset_std_s: 0.0,
        period_s: dt,
        hypotheses: Vec::new(),
        likely: same.then_some(first),
        summary: format!(
            "timing: stated ({}), used as stated",
            if same { first.name() } else { "per recording" }
        ),
    };
    Some(Ok(TimedFit {
        fit,
        recordings: recordings.to_vec(),
        timing,
        offset: None,
    }))
}

/// The likeliest convention's fit, its recordings and the convention, and every hypothesis
/// with its −2 log-likelihood.
type Likeliest = (OutputErrorFit, Vec<Recording>, Timing, Vec<(Timing, f64)>);

/// Each stamping convention as a hypothesis, its offset pinned at zero: the likeliest fit
/// (instants must win by [`INSTANT_MARGIN`] per residual), its recordings and convention, and
/// every hypothesis's −2 log-likelihood.
///
/// # Errors
/// The first hypothesis's error when none could be fitted.
fn likeliest_convention(
    model: &dyn DynamicModel,
    recordings: &[Recording],
    theta0: &[f64],
    oe: &OutputError,
) -> Result<Likeliest, SolveError> {
    let mut best: Option<(f64, OutputErrorFit, Vec<Recording>, Timing)> = None;
    let mut hypotheses = Vec::new();
    let mut first_err = None;
    for h in Timing::ALL {
        let Some(recs) = under(recordings, h)? else {
            continue;
        };
        match without_first_windows(oe, &recs).fit(model, &recs, theta0) {
            Ok(fit) => {
                let score = neg2_log_likelihood(&fit);
                hypotheses.push((h, score));
                // The prior: window averages must merely tie; instants must win clearly.
                let handicap = match h {
                    Timing::Instant => INSTANT_MARGIN * fit.residuals as f64,
                    _ => 0.0,
                };
                if best.as_ref().is_none_or(|b| score + handicap < b.0) {
                    best = Some((score + handicap, fit, recs, h));
                }
            }
            Err(e) => {
                first_err.get_or_insert(e);
            }
        }
    }
    let Some((_, pinned, recs, h)) = best else {
        return Err(first_err.unwrap_or_else(|| {
            SolveError::InvalidProblem("no timing hypothesis could be fitted".into())
        }));
    };
    Ok((pinned, recs, h, hypotheses))
}

/// The recordings read under convention `h`: those that state theirs keep it; the others get
/// `h`'s output sampling, restamped to window ends for (c). `None` when a recording states a
/// sampling that contradicts `h` (then `h` is not a hypothesis of this set).
fn under(recordings: &[Recording], h: Timing) -> Result<Option<Vec<Recording>>, SolveError> {
    let mut out = Vec::with_capacity(recordings.len());
    for r in recordings {
        if r.timing().is_some() {
            if r.velocity_sampling() != h.velocity_sampling() {
                return Ok(None);
            }
            out.push(r.clone());
            continue;
        }
        let mut x = r.clone();
        x.set_timing(h);
        let x = condition::restamp(&x).map_err(|e| SolveError::InvalidProblem(e.to_string()))?;
        out.push(x.into_owned());
    }
    Ok(Some(out))
}

/// −2 ln L of a fit with Gaussian residuals of per-channel variance σ̂_c² (module docs).
fn neg2_log_likelihood(fit: &OutputErrorFit) -> f64 {
    let nch = fit.noise_std.len().max(1) as f64;
    let n = fit.residuals as f64 / nch;
    fit.noise_std
        .iter()
        .map(|s| n * (s * s).max(1e-300).ln())
        .sum()
}

/// The report of an estimated timing, in one sentence.
fn estimated_report(
    h: Timing,
    residual: Option<(f64, f64)>,
    real: bool,
    dt: f64,
    hypotheses: Vec<(Timing, f64)>,
) -> TimingReport {
    let verdict = match h {
        Timing::Instant => "velocity at t, command from t (a)".to_string(),
        Timing::WindowEnd => {
            "velocity averaged over the window ending at t, command from t (b)".to_string()
        }
        Timing::WindowMiddle => format!(
            "stamped at window middle? (c): velocities averaged over the window around t, \
             commands act {:.1} ms before their stamps",
            500.0 * dt
        ),
    };
    let (delta, sd) = residual.unwrap_or((0.0, 0.0));
    let rest = match (residual, real) {
        (None, _) => "residual offset not fitted".to_string(),
        (Some(_), false) => format!(
            "residual offset {:+.2} ± {:.2} ms ({:+.3} samples) not significant, held at 0",
            1e3 * delta,
            1e3 * sd,
            delta / dt
        ),
        (Some(_), true) if delta.abs() >= 0.999 * MAX_OFFSET_SAMPLES * dt => format!(
            "and the commands act at least {:.1} ms {} (the edge of the ±{} sample search): a \
             dead time beyond the stamping — `wheelid diagnose` models it",
            1e3 * delta.abs(),
            if delta < 0.0 { "early" } else { "late" },
            MAX_OFFSET_SAMPLES
        ),
        (Some(_), true) => format!(
            "plus an offset of {:+.2} ± {:.2} ms ({:+.2} samples): a latency or a clock offset, \
             fitted",
            1e3 * delta,
            1e3 * sd,
            delta / dt
        ),
    };
    TimingReport {
        source: TimingSource::Estimated,
        stated: None,
        sampling: h.velocity_sampling(),
        offset_s: if real { delta } else { 0.0 },
        offset_std_s: sd,
        period_s: dt,
        hypotheses,
        likely: Some(h),
        summary: format!("timing: estimated (no metadata) — {verdict}; {rest}"),
    }
}
