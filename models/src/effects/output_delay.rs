//! `output_delay`: a dead time of the measurements — the encoders' readings reach the host
//! late (a serial or CAN link, a driver's buffer, an odometry pipeline that stamps on
//! arrival), so the row stamped t carries the wheels' speeds of t − τ_o:
//!
//! ```text
//! y(t) = x(t − τ_o)
//! ```
//!
//! Every stage of eq. 2.19's extension but a payload change and a drive-gain drift is
//! time-invariant, and a dead time commutes with a time-invariant system: from the commands
//! and the encoders alone a dead time of the measurements *is* one of the commands
//! (`input_delay`) of the same length — the two are one quantity, "dead time". They part where
//! a second sensor is not delayed with the encoders: a heading measured independently of them
//! ([`Recording::independent_heading`]: ground truth, motion capture, lidar scan matching)
//! turns at the chassis's own time, and the encoders' turn follows it by τ_o. So this effect
//! is never searched from the dynamics (no fingerprint); it is measured ([`heading_lag`]) and,
//! where the lag is significant, named whatever the dynamics show, in place of the dead time
//! of the commands — which the search then looks for beside it (a robot may have both; the
//! dynamics see their sum).
//!
//! In the extended model ([`wheelid_core::Terms::output_delay`]) it adds to the commands'
//! dead time and moves a payload change's time and a drift's clock by τ_o, so that a payload
//! change is reported at the instant it happened, not when the encoders showed it.

use wheelid_core::effect::{FitData, Probe, ProbeData, Search, Terms};
use wheelid_core::{Effect, Measurement, ParamInfo, Recording, Result, VelocitySampling};

use super::input_delay::dead_time_plausible;

static PARAMS: [ParamInfo; 1] = [ParamInfo {
    name: "delay_s",
    unit: "s",
    description: "dead time of the measurements (the encoders' readings)",
}];

/// Longest lag [`heading_lag`] looks for \[s\].
pub const MAX_LAG_S: f64 = 1.0;

/// Standard errors by which the measured lag must exceed 0 to be named (as a larger tyre's
/// [`super::MEASURED_Z`]).
pub const LAG_Z: f64 = 4.0;

/// Robust standard deviations beyond which a window's residual is dropped ([`trim`]).
const TRIM_Z: f64 = 2.5;

/// Most passes of [`trim`]: it repeats until a pass drops no window (three, before 2026-11-29,
/// left a Khepera-like robot's lag 30–47 % short where the wheels slip on half the samples).
const MAX_TRIMS: usize = 20;

/// Periods either side of the lag that a pass of [`trim`] searches again ([`heading_lag`]).
const TRIM_SPAN: f64 = 2.0;

/// Steps of the lag grid per sample period (then a parabola through the best three).
const GRID_PER_PERIOD: f64 = 10.0;

/// Dead time τ_o \[s\] of the measurements (`Terms::output_delay`); null 0, fitted within
/// [0, 2] s; named only where measured ([`heading_lag`]).
#[derive(Debug, Clone, Copy)]
pub struct OutputDelay;

impl Effect for OutputDelay {
    fn name(&self) -> &'static str {
        "output_delay"
    }
    fn params(&self) -> &'static [ParamInfo] {
        &PARAMS
    }
    fn null(&self, _theta: &[f64], _t_mid: f64) -> Vec<f64> {
        vec![0.0]
    }
    fn bounds(&self, _t_range: (f64, f64)) -> Vec<(f64, f64)> {
        vec![(0.0, 2.0)]
    }
    fn search(&self) -> Search {
        Search::DeadTime
    }
    /// None: the encoders alone cannot tell it from `input_delay` (module docs).
    fn probe(&self, _data: &ProbeData<'_>) -> Option<Probe> {
        None
    }
    fn evidence(&self) -> &'static str {
        "the encoders' turn lags a heading measured independently of them"
    }
    fn plausible(
        &self,
        j: usize,
        x: f64,
        se: f64,
        fit: &FitData<'_>,
    ) -> std::result::Result<(), String> {
        dead_time_plausible(&PARAMS[j], x, se, fit)
    }
    fn apply(&self, p: &[f64], terms: &mut Terms) -> Result<()> {
        terms.output_delay = p[0];
        Ok(())
    }
    fn measured(&self, recordings: &[Recording], _track: Option<f64>) -> Option<Measurement> {
        let (lag, se) = heading_lag(recordings)?;
        let period = recordings
            .first()
            .map(|r| r.duration() / (r.len().max(2) - 1) as f64)?;
        if lag < super::input_delay::MIN_PERIODS * period || lag < LAG_Z * se {
            return None;
        }
        Some(Measurement {
            values: vec![lag],
            std_err: vec![se],
            bounds: vec![((lag - 3.0 * se).max(0.0), lag + 3.0 * se)],
            evidence: format!(
                "the encoders' turn lags the chassis heading (a pose independent of the \
                 encoders) by {:.1} ± {:.1} ms",
                1e3 * lag,
                1e3 * se
            ),
        })
    }
    fn quantity(&self) -> Option<&'static str> {
        Some(super::DEAD_TIME)
    }
}

/// One recording's sample windows: the turn the encoders report over each, as columns
/// (∫ω dt, ∫v dt) [rad, m], and the window's ends \[s\]; the heading's cumulative turn at each
/// sample (unwrapped) \[rad\].
struct Windows {
    cols: Vec<[f64; 2]>,
    ends: Vec<(f64, f64)>,
    t: Vec<f64>,
    turn: Vec<f64>,
    /// The windows the regression uses (all, until [`trim`] drops the outliers).
    keep: Vec<bool>,
}

impl Windows {
    /// The windows of `r`, if it has an independent heading. Window k is (t_{k−1}, t_k]: under
    /// window averages the row's speeds are its mean (whatever the stamps: the pose is taken
    /// at the window's end), under instants the trapezoid of the two rows' speeds.
    fn of(r: &Recording) -> Option<Self> {
        let phi = r.independent_heading()?;
        let avg = r.velocity_sampling() == VelocitySampling::WindowAverage;
        let mut turn = Vec::with_capacity(r.len());
        let mut acc = 0.0;
        for k in 0..r.len() {
            if k > 0 {
                let d = phi[k] - phi[k - 1];
                acc += d - std::f64::consts::TAU * (d / std::f64::consts::TAU).round();
            }
            turn.push(acc);
        }
        let (mut cols, mut ends) = (Vec::new(), Vec::new());
        for k in 1..r.len() {
            let dt = r.t[k] - r.t[k - 1];
            let (w, v) = if avg {
                (r.w[k], r.v[k])
            } else {
                (0.5 * (r.w[k - 1] + r.w[k]), 0.5 * (r.v[k - 1] + r.v[k]))
            };
            cols.push([w * dt, v * dt]);
            ends.push((r.t[k - 1], r.t[k]));
        }
        Some(Self {
            keep: vec![true; cols.len()],
            cols,
            ends,
            t: r.t.clone(),
            turn,
        })
    }

    /// The heading's cumulative turn at instant `s` (linear between samples; `None` outside).
    fn at(&self, s: f64) -> Option<f64> {
        let n = self.t.len();
        if s < self.t[0] || s > self.t[n - 1] {
            return None;
        }
        let i = self.t.partition_point(|&x| x <= s).clamp(1, n - 1);
        let (a, b) = (self.t[i - 1], self.t[i]);
        let f = if b > a { (s - a) / (b - a) } else { 0.0 };
        Some(self.turn[i - 1] + f * (self.turn[i] - self.turn[i - 1]))
    }
}

/// The windows of `w` used at any lag: kept, their moved ends inside the recording after
/// `skip.0` \[s\] and before `skip.1` \[s\] from its end (the same windows for every lag).
fn used(w: &Windows, skip: (f64, f64)) -> impl Iterator<Item = usize> + '_ {
    let (first, last) = (w.t[0] + skip.0, w.t[w.t.len() - 1] - skip.1);
    (0..w.cols.len()).filter(move |&k| w.keep[k] && w.ends[k].0 >= first && w.ends[k].1 <= last)
}

/// The heading's turn over window `k` of `w` moved back by `lag`.
fn moved_turn(w: &Windows, k: usize, lag: f64) -> Option<f64> {
    let (a, b) = w.ends[k];
    Some(w.at(b - lag)? - w.at(a - lag)?)
}

/// Least squares of the heading's turn over each used window moved back by `lag` on the
/// encoders' (∫ω dt, ∫v dt) of that window (no intercept; the v column takes a larger tyre's
/// share): (sum of squares, windows, coefficients).
fn fit_at(windows: &[Windows], lag: f64, skip: (f64, f64)) -> Option<(f64, usize, [f64; 2])> {
    let (mut xtx, mut xty, mut yty, mut n) = ([[0.0; 2]; 2], [0.0; 2], 0.0, 0usize);
    for w in windows {
        for k in used(w, skip) {
            let (x, y) = (w.cols[k], moved_turn(w, k, lag)?);
            for i in 0..2 {
                xty[i] += x[i] * y;
                for j in 0..2 {
                    xtx[i][j] += x[i] * x[j];
                }
            }
            yty += y * y;
            n += 1;
        }
    }
    let det = xtx[0][0] * xtx[1][1] - xtx[0][1] * xtx[1][0];
    if n < 10 || det <= 1e-12 * xtx[0][0] * xtx[1][1] {
        return None;
    }
    let a = (xtx[1][1] * xty[0] - xtx[0][1] * xty[1]) / det;
    let b = (xtx[0][0] * xty[1] - xtx[1][0] * xty[0]) / det;
    Some(((yty - a * xty[0] - b * xty[1]).max(0.0), n, [a, b]))
}

/// The lag on `lags` (spaced `step`) with the least sum of squares, refined by a parabola
/// through it and its neighbours.
fn grid_min(windows: &[Windows], lags: &[f64], step: f64, skip: (f64, f64)) -> Option<f64> {
    let sse: Vec<f64> = lags
        .iter()
        .map(|&l| fit_at(windows, l, skip).map(|s| s.0))
        .collect::<Option<_>>()?;
    let best = (0..sse.len()).min_by(|&a, &b| sse[a].total_cmp(&sse[b]))?;
    if best == 0 || best + 1 == sse.len() {
        return Some(lags[best]);
    }
    let (a, b, c) = (sse[best - 1], sse[best], sse[best + 1]);
    let curv = a - 2.0 * b + c;
    Some(
        lags[best]
            + if curv > 0.0 {
                0.5 * step * (a - c) / curv
            } else {
                0.0
            },
    )
}

/// Drops from the regression the windows whose residual at `lag` is beyond [`TRIM_Z`] robust
/// standard deviations (1.4826 × the median absolute residual): where the wheels slip, the
/// encoders' turn runs ahead of the body's, and those windows would pull the lag negative.
/// Returns how many windows it dropped.
fn trim(windows: &mut [Windows], lag: f64, skip: (f64, f64)) -> Option<usize> {
    let (_, _, [a, b]) = fit_at(windows, lag, skip)?;
    let resid = |w: &Windows, k: usize| {
        moved_turn(w, k, lag).map(|y| y - a * w.cols[k][0] - b * w.cols[k][1])
    };
    // Each used window's residual, once: for the median, then against the limit.
    let resids: Vec<Vec<(usize, Option<f64>)>> = windows
        .iter()
        .map(|w| used(w, skip).map(|k| (k, resid(w, k))).collect())
        .collect();
    let mut abs: Vec<f64> = resids
        .iter()
        .flatten()
        .filter_map(|&(_, r)| r.map(f64::abs))
        .collect();
    abs.sort_by(f64::total_cmp);
    let limit = TRIM_Z * 1.4826 * *abs.get(abs.len() / 2)?;
    let mut dropped = 0;
    for (w, rs) in windows.iter_mut().zip(&resids) {
        for &(k, r) in rs {
            if r.is_none_or(|r| r.abs() > limit) {
                w.keep[k] = false;
                dropped += 1;
            }
        }
    }
    Some(dropped)
}

/// The lag of the encoders' turn behind a heading measured independently of them, (τ̂ \[s\],
/// its standard error), from the recordings with such a heading
/// ([`Recording::independent_heading`]). Over every sample window the heading's turn moved
/// back by τ is regressed on what the encoders report for the window; τ̂ minimises the sum of
/// squares on a grid of a tenth of a sample period over [−1 period, [`MAX_LAG_S`]], refined by
/// a parabola, then again without the windows whose residual is an outlier (slipping wheels)
/// until none is, and its standard error is the Gauss–Newton one, σ̂ / ‖∂r/∂τ‖. `None`
/// without such a heading or where the turns do not determine the regression (no turning).
pub fn heading_lag(recordings: &[Recording]) -> Option<(f64, f64)> {
    let mut windows: Vec<Windows> = recordings.iter().filter_map(Windows::of).collect();
    let first = windows.first()?;
    let period = (first.t[first.t.len() - 1] - first.t[0]) / (first.t.len().max(2) - 1) as f64;
    if period.is_nan() || period <= 0.0 {
        return None;
    }
    let step = period / GRID_PER_PERIOD;
    let skip = (MAX_LAG_S + period, 2.0 * period);
    let lags: Vec<f64> = (0..)
        .map(|i| -period + i as f64 * step)
        .take_while(|&l| l <= MAX_LAG_S + 1e-12)
        .collect();
    let mut lag = grid_min(&windows, &lags, step, skip)?;
    // A pass moves the lag by a fraction of a period: the passes search the grid within
    // [`TRIM_SPAN`] periods of it, and the windows kept at the end are searched over all of it.
    let mut trimmed = false;
    for _ in 0..MAX_TRIMS {
        if trim(&mut windows, lag, skip)? == 0 {
            break;
        }
        trimmed = true;
        let near = lags.partition_point(|&l| l < lag - TRIM_SPAN * period)
            ..lags.partition_point(|&l| l <= lag + TRIM_SPAN * period);
        lag = grid_min(&windows, &lags[near], step, skip)?;
    }
    if trimmed {
        lag = grid_min(&windows, &lags, step, skip)?;
    }
    let (s0, n, _) = fit_at(&windows, lag, skip)?;
    // ‖∂r/∂τ‖² from the sum of squares' curvature: SSE(τ ± h) ≈ SSE(τ) + h² ‖∂r/∂τ‖².
    let h = 0.5 * step;
    let (sp, sm) = (
        fit_at(&windows, lag + h, skip)?.0,
        fit_at(&windows, lag - h, skip)?.0,
    );
    let grad2 = (0.5 * (sp + sm) - s0) / (h * h);
    let sigma2 = s0 / (n - 3) as f64;
    (grad2 > 0.0).then(|| (lag, (sigma2 / grad2).sqrt()))
}
