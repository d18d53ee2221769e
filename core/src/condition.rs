//! Conditioning: from a recording to signals a regression can use.
//!
//! Steps, in order (each stated in the report):
//! 1. **Resample** a non-uniformly sampled recording onto a uniform grid at its median period
//!    ([`Recording::resample_uniform`]: commands by zero-order hold, measurements linearly).
//! 2. **Align** samples to instants. A zero-order-held command u_k acts on [t_k, t_{k+1}); its
//!    mean over [t_k − Δt/2, t_k + Δt/2] is (u_{k−1} + u_k)/2, which is the value consistent with
//!    point samples of v, ω and central-difference derivatives at t_k (to O(Δt²)). Without this
//!    half-sample correction the held command leads the response by Δt/2, which a first-order
//!    model absorbs into θ1 (≈ 20 % bias for the Pioneer at 10 Hz). Likewise, window-averaged
//!    velocities m_k (mean over [t_{k−1}, t_k]) become (m_k + m_{k+1})/2.
//! 3. **Filter**: a zero-phase Butterworth low-pass ([`crate::signal::sosfiltfilt`]). wheelid
//!    filters *every* column of the regression, including the command side, with the same filter
//!    ("parallel filtering"). Because the filter is linear, filt(u) = θ1·filt(v̇) + … holds
//!    exactly whatever the cut-off, so the cut-off only trades noise against excitation; the
//!    thesis filtered the velocities alone, which biases θ by the filter's attenuation at the
//!    excitation frequencies. Models call [`Conditioned::smooth`] and
//!    [`Conditioned::differentiate`].
//!
//! # Default cut-off rule
//! With no `cutoff_hz`, f_c = 2·f₉₅, where f₉₅ is the frequency below which 95 % of the variance
//! of the (mean-removed) commands lies — the larger of the `v_ref` and `w_ref` values, taken
//! over all recordings of a run — clamped to [5/T, f_s/5] (T the shortest recording's duration).
//! Rationale: the response of a velocity-input robot has no content the commands lack
//! beyond its own roll-off, so twice the command band keeps the signal while rejecting the
//! encoder noise above it; f_s/5 keeps the derivative stencil accurate.

use std::borrow::Cow;
use std::path::PathBuf;

use crate::error::{Error, Result};
use crate::recording::{CommandHold, Recording, Timing, VelocitySampling};
use crate::signal::{self, Butterworth, Sos, Stencil};

/// Settings for [`condition`].
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ConditionSettings {
    /// Low-pass cut-off \[Hz\]; `None` chooses it by the documented rule ([`suggest_cutoff`]).
    pub cutoff_hz: Option<f64>,
    /// Butterworth order of one pass (the zero-phase result has twice the roll-off).
    pub order: usize,
    /// Derivative stencil.
    pub stencil: Stencil,
    /// Edge transient length, in periods of the cut-off, dropped at each end of every
    /// recording's regression ([`Conditioned::valid_range`]).
    pub edge_periods: f64,
}

impl Default for ConditionSettings {
    fn default() -> Self {
        Self {
            cutoff_hz: None,
            order: 4,
            stencil: Stencil::Central4,
            edge_periods: 2.0,
        }
    }
}

/// How the cut-off was chosen.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
#[serde(rename_all = "snake_case", tag = "rule")]
pub enum CutoffChoice {
    /// Given by the user.
    Given,
    /// f_c = 2·f₉₅ of the commands, clamped (see module docs).
    CommandBandwidth {
        /// f₉₅ of the commands \[Hz\] (`None` if every command was constant).
        f95_hz: Option<f64>,
        /// Whether the clamp changed the value.
        clamped: bool,
    },
}

/// A recording made ready for regression: uniform, aligned, with its filter. It borrows the
/// recording when that was uniform already (no copy of a long run), and owns the resampled one
/// otherwise.
#[derive(Debug, Clone)]
pub struct Conditioned<'a> {
    /// Where the data came from.
    pub source: PathBuf,
    /// The uniform recording as used (resampled if it was not uniform): the free-run simulation
    /// is driven by its commands and compared with its measurements.
    pub recording: Cow<'a, Recording>,
    /// Sample period Δt \[s\].
    pub dt: f64,
    /// Median period before resampling \[s\], if the recording had to be resampled.
    pub resampled_from: Option<f64>,
    /// The aligned columns v_ref, w_ref, v, ω (module docs, step 2), made on first use: a
    /// caller that reads them sample by sample ([`Conditioned::v_at`] and the others, the blocked
    /// regression) never holds them.
    aligned: std::sync::OnceLock<[Vec<f64>; 4]>,
    /// The recording's command hold and velocity sampling (read once from its metadata).
    hold: CommandHold,
    sampling: VelocitySampling,
    /// The zero-phase low-pass filter used.
    pub filter: Butterworth,
    sos: Vec<Sos<f64>>,
    stencil: Stencil,
    edge_periods: f64,
}

impl Conditioned<'_> {
    /// Number of samples n.
    pub fn len(&self) -> usize {
        self.recording.len()
    }

    /// True if there are no samples.
    pub fn is_empty(&self) -> bool {
        self.recording.is_empty()
    }

    /// The forward-velocity command aligned to the sample instants (module docs, step 2),
    /// length n \[m/s\].
    pub fn v_ref(&self) -> &[f64] {
        &self.aligned()[0]
    }

    /// The aligned angular-velocity command, length n \[rad/s\].
    pub fn w_ref(&self) -> &[f64] {
        &self.aligned()[1]
    }

    /// The measured forward velocity at the sample instants, length n \[m/s\].
    pub fn v(&self) -> &[f64] {
        &self.aligned()[2]
    }

    /// The measured angular velocity at the sample instants, length n \[rad/s\].
    pub fn w(&self) -> &[f64] {
        &self.aligned()[3]
    }

    /// [`Conditioned::v_ref`]\[k\] without making the column.
    #[inline]
    pub fn v_ref_at(&self, k: usize) -> f64 {
        align_command(&self.recording.v_ref, self.hold, k)
    }

    /// [`Conditioned::w_ref`]\[k\] without making the column.
    #[inline]
    pub fn w_ref_at(&self, k: usize) -> f64 {
        align_command(&self.recording.w_ref, self.hold, k)
    }

    /// [`Conditioned::v`]\[k\] without making the column.
    #[inline]
    pub fn v_at(&self, k: usize) -> f64 {
        align_measurement(&self.recording.v, self.sampling, k)
    }

    /// [`Conditioned::w`]\[k\] without making the column.
    #[inline]
    pub fn w_at(&self, k: usize) -> f64 {
        align_measurement(&self.recording.w, self.sampling, k)
    }

    fn aligned(&self) -> &[Vec<f64>; 4] {
        self.aligned.get_or_init(|| {
            let n = self.len();
            [
                (0..n).map(|k| self.v_ref_at(k)).collect(),
                (0..n).map(|k| self.w_ref_at(k)).collect(),
                (0..n).map(|k| self.v_at(k)).collect(),
                (0..n).map(|k| self.w_at(k)).collect(),
            ]
        })
    }

    /// [`crate::signal::sosfiltfilt_blocks`] with this recording's filter, the lookahead of
    /// [`Conditioned::head_samples`] and `halo` neighbours a side: the S signals `inputs`
    /// (each filling the samples asked for, [`signal::BlockInput`]) filtered zero-phase and
    /// handed to `consume` block by block.
    ///
    /// # Errors
    /// [`Error::TooShort`] naming the recording; the first error of `consume`.
    pub fn smooth_blocks<const S: usize>(
        &self,
        inputs: [signal::BlockInput<'_>; S],
        halo: usize,
        consume: impl FnMut(signal::FilteredBlock<'_, S>) -> Result<()>,
    ) -> Result<()> {
        let plan = signal::BlockPlan::for_lookahead(self.head_samples(), halo);
        signal::sosfiltfilt_blocks(&self.sos, self.len(), inputs, plan, consume)
            .map_err(|e| self.name_error(e))
    }

    /// Rows of the regression that are free of the filter's edge transients: the first and last
    /// `edge_samples` samples, within `edge_periods / f_c` seconds of either end, are dropped.
    /// At the edges the odd extension that zero-phase filtering pads with is not a response of
    /// the robot to the extended command, so filt(u) = θ·filt(Φ) fails there (≈ 3 % bias in θ1 on
    /// a recording that starts from rest, if kept).
    pub fn valid_range(&self) -> std::ops::Range<usize> {
        let k = self.edge_samples().min(self.len() / 4);
        k..self.len() - k
    }

    /// Samples dropped at each end by [`Conditioned::valid_range`].
    pub fn edge_samples(&self) -> usize {
        (self.edge_periods / (self.filter.cutoff_hz * self.dt)).ceil() as usize
    }

    /// The zero-phase low-pass filter applied to `x` (length n).
    ///
    /// # Errors
    /// [`Error::TooShort`] naming the recording if `x` is shorter than the filter's padding.
    pub fn smooth(&self, x: &[f64]) -> Result<Vec<f64>> {
        signal::sosfiltfilt(&self.sos, x).map_err(|e| self.name_error(e))
    }

    /// [`Conditioned::smooth`] of each of `xs`, in order, the signals shared out over the
    /// available cores when they are long (they are independent; each result is the one
    /// [`Conditioned::smooth`] gives, bit for bit).
    ///
    /// # Errors
    /// As [`Conditioned::smooth`], for the first signal that fails.
    pub fn smooth_all(&self, xs: &[&[f64]]) -> Result<Vec<Vec<f64>>> {
        const PARALLEL_MIN_SAMPLES: usize = 100_000;
        if xs.iter().map(|x| x.len()).sum::<usize>() < PARALLEL_MIN_SAMPLES {
            return xs.iter().map(|x| self.smooth(x)).collect();
        }
        use rayon::prelude::*;
        xs.par_iter().map(|x| self.smooth(x)).collect()
    }

    /// The smoothed initial state (v0, ω0): the first samples of [`Conditioned::smooth`] of
    /// the measured v and ω, computed from the recording's first [`Conditioned::head_samples`]
    /// samples only — the zero-phase filter's backward pass forgets the rest (its weight is
    /// below e⁻⁶⁵ of theirs), so the values are the whole signal's to rounding (test), at a cost
    /// that does not grow with the recording.
    ///
    /// # Errors
    /// As [`Conditioned::smooth`].
    pub fn initial_state(&self) -> Result<[f64; 2]> {
        let head = self.head_samples().min(self.len());
        // The head's aligned samples only: the whole columns are not made for this.
        let (v, w): (Vec<f64>, Vec<f64>) = (0..head).map(|k| (self.v_at(k), self.w_at(k))).unzip();
        let [v, w]: [Vec<f64>; 2] = self
            .smooth_all(&[&v, &w])?
            .try_into()
            .map_err(|_| Error::InvalidSetting("two smoothed signals".into()))?;
        Ok([v[0], w[0]])
    }

    /// Samples that [`Conditioned::initial_state`] smooths: 80 periods of the cut-off. The
    /// slowest pole of an order-N Butterworth decays at 2π f_c sin(π/2N) ≥ 0.82 f_c per second
    /// (N ≤ 12), so after 80 periods the backward pass keeps less than e⁻⁶⁵ of a sample's weight.
    pub fn head_samples(&self) -> usize {
        (80.0 / (self.filter.cutoff_hz * self.dt)).ceil() as usize
    }

    /// The derivative d/dt of `x` (length n) with the configured stencil.
    ///
    /// # Errors
    /// [`Error::TooShort`] for fewer than three samples.
    pub fn differentiate(&self, x: &[f64]) -> Result<Vec<f64>> {
        signal::derivative(x, self.dt, self.stencil).map_err(|e| self.name_error(e))
    }

    fn name_error(&self, e: Error) -> Error {
        match e {
            Error::TooShort {
                samples,
                needed,
                why,
                ..
            } => Error::TooShort {
                file: self.source.clone(),
                samples,
                needed,
                why,
            },
            other => other,
        }
    }
}

/// A recording stamped at its windows' middles (`timing: window_middle`, convention (c))
/// rewritten to window-end stamps (b), which the models simulate; any other recording is
/// returned as it is.
///
/// Under (c) row k's window is [s_k, s_{k+1}], t_k = (s_k + s_{k+1})/2, and its command was
/// sent at s_k. The window ends are recovered as t'_k = (t_k + t_{k+1})/2 — exact on a uniform
/// grid, and off by a quarter of the jitter's second difference on a jittered one — the last
/// one extrapolated by half a period; the command sent at t'_k is row k+1's (the last row's is
/// held). Metadata: `timing: window_end`, plus `restamped_from: window_middle`.
///
/// # Errors
/// [`Error::TooShort`] for fewer than two samples of a window-middle recording.
pub fn restamp(rec: &Recording) -> Result<Cow<'_, Recording>> {
    if rec.timing() != Some(Timing::WindowMiddle) {
        return Ok(Cow::Borrowed(rec));
    }
    let n = rec.len();
    if n < 2 {
        return Err(Error::TooShort {
            file: rec.source.clone(),
            samples: n,
            needed: 2,
            why: "restamping window middles to window ends needs two samples".into(),
        });
    }
    let mut out = rec.clone();
    for k in 0..n - 1 {
        out.t[k] = 0.5 * (rec.t[k] + rec.t[k + 1]);
    }
    out.t[n - 1] = rec.t[n - 1] + 0.5 * (rec.t[n - 1] - rec.t[n - 2]);
    for col in [&mut out.v_ref, &mut out.w_ref] {
        col.rotate_left(1);
        col[n - 1] = col[n - 2];
    }
    out.set_timing(Timing::WindowEnd);
    out.set_meta("restamped_from", Timing::WindowMiddle.name());
    Ok(Cow::Owned(out))
}

/// Minimum number of samples a recording needs for a filter of this order.
pub fn min_samples(order: usize) -> usize {
    // sosfiltfilt pads 3·(2·⌈N/2⌉ + 1) samples and needs strictly more.
    3 * (2 * order.div_ceil(2) + 1) + 1
}

/// Makes `rec` uniform (resampling if needed; a uniform one is borrowed, not copied); returns
/// it with the original median period if it was resampled.
///
/// # Errors
/// [`Error::TooShort`] for fewer than two samples.
pub fn make_uniform(rec: &Recording) -> Result<(Cow<'_, Recording>, Option<f64>)> {
    uniform(rec).map(|u| (u.recording, u.resampled_from))
}

/// A recording on a uniform grid with its period, measured once: what
/// [`suggest_cutoff_uniform`] and [`condition_uniform`] read (the median period of a 1e6-row
/// recording is a selection over its 1e6 intervals).
#[derive(Debug, Clone)]
pub struct Uniform<'a> {
    /// The uniform recording: the caller's, borrowed, or the resampled one.
    pub recording: Cow<'a, Recording>,
    /// The original median period \[s\] if it was resampled.
    pub resampled_from: Option<f64>,
    /// Its sample period Δt \[s\] (the median interval, which every interval is within 1e-6 of).
    pub dt: f64,
}

/// [`make_uniform`] with the period: `rec` as it is when uniform, else resampled.
///
/// # Errors
/// [`Error::TooShort`] for fewer than two samples.
pub fn uniform(rec: &Recording) -> Result<Uniform<'_>> {
    if rec.len() < 2 {
        return Err(Error::TooShort {
            file: rec.source.clone(),
            samples: rec.len(),
            needed: 2,
            why: "a recording needs at least two samples".into(),
        });
    }
    let s = rec.sampling();
    if s.uniform {
        Ok(Uniform {
            recording: Cow::Borrowed(rec),
            resampled_from: None,
            dt: s.dt_median,
        })
    } else {
        let resampled = rec.resample_uniform(s.dt_median)?;
        Ok(Uniform {
            dt: resampled.sampling().dt_median,
            recording: Cow::Owned(resampled),
            resampled_from: Some(s.dt_median),
        })
    }
}

/// The default cut-off rule (module docs) over uniform recordings; returns f_c \[Hz\] and how it
/// was chosen.
///
/// # Errors
/// [`Error::TooShort`] if `recs` is empty.
pub fn suggest_cutoff(recs: &[&Recording]) -> Result<(f64, CutoffChoice)> {
    let sampled: Vec<(&Recording, f64)> =
        recs.iter().map(|r| (*r, r.sampling().dt_median)).collect();
    cutoff_rule(&sampled)
}

/// [`suggest_cutoff`] over recordings made uniform by [`uniform`], with their periods.
///
/// # Errors
/// As [`suggest_cutoff`].
pub fn suggest_cutoff_uniform(recs: &[Uniform<'_>]) -> Result<(f64, CutoffChoice)> {
    let sampled: Vec<(&Recording, f64)> = recs.iter().map(|u| (&*u.recording, u.dt)).collect();
    cutoff_rule(&sampled)
}

/// The default cut-off rule over recordings with their sample periods \[s\].
fn cutoff_rule(recs: &[(&Recording, f64)]) -> Result<(f64, CutoffChoice)> {
    let Some((_, dt_first)) = recs.first() else {
        return Err(Error::InvalidSetting(
            "no recording to choose a cut-off from".into(),
        ));
    };
    let fs = 1.0 / dt_first;
    let t_min = recs
        .iter()
        .map(|(r, _)| r.duration())
        .fold(f64::INFINITY, f64::min);
    // One spectrum at a time: a 1e6-sample command's transform holds ~24 MB while it runs,
    // which two cores at once would double at the run's peak (the FFT itself takes ~20 ms).
    let columns: Vec<(&[f64], f64)> = recs
        .iter()
        .flat_map(|(r, dt)| {
            let fs_r = 1.0 / dt;
            [(&r.v_ref[..], fs_r), (&r.w_ref[..], fs_r)]
        })
        .collect();
    let mut planner = realfft::RealFftPlanner::new();
    let f95 = columns
        .iter()
        .filter_map(|(col, fs_r)| signal::power_quantile_hz_with(&mut planner, col, *fs_r, 0.95))
        .reduce(f64::max);
    let raw = f95.map_or(fs / 10.0, |f| 2.0 * f);
    let lo = (5.0 / t_min).min(fs / 5.0);
    let fc = raw.clamp(lo, fs / 5.0);
    Ok((
        fc,
        CutoffChoice::CommandBandwidth {
            f95_hz: f95,
            clamped: fc != raw,
        },
    ))
}

/// Conditions a uniform recording (see module docs) with the given cut-off.
///
/// # Errors
/// [`Error::InvalidSetting`] for a bad filter; [`Error::TooShort`] (naming the file) if the
/// recording has fewer than [`min_samples`] samples.
pub fn condition<'a>(
    rec: &'a Recording,
    resampled_from: Option<f64>,
    cutoff_hz: f64,
    settings: &ConditionSettings,
) -> Result<Conditioned<'a>> {
    condition_cow(Cow::Borrowed(rec), resampled_from, cutoff_hz, settings)
}

/// [`condition`] of a recording borrowed or owned: an owned one (resampled, restamped) moves
/// into the result instead of being copied.
///
/// # Errors
/// As [`condition`].
pub fn condition_cow<'a>(
    rec: Cow<'a, Recording>,
    resampled_from: Option<f64>,
    cutoff_hz: f64,
    settings: &ConditionSettings,
) -> Result<Conditioned<'a>> {
    let s = rec.sampling();
    if !s.uniform {
        return Err(Error::InvalidSetting(format!(
            "{}: condition() needs uniform sampling; call make_uniform first",
            rec.source.display()
        )));
    }
    condition_uniform(
        Uniform {
            recording: rec,
            resampled_from,
            dt: s.dt_median,
        },
        cutoff_hz,
        settings,
    )
}

/// [`condition_cow`] of a recording made uniform by [`uniform`] (its period not measured
/// again).
///
/// # Errors
/// As [`condition`].
pub fn condition_uniform<'a>(
    u: Uniform<'a>,
    cutoff_hz: f64,
    settings: &ConditionSettings,
) -> Result<Conditioned<'a>> {
    let Uniform {
        recording: rec,
        resampled_from,
        dt,
    } = u;
    let filter = Butterworth {
        order: settings.order,
        cutoff_hz,
        fs_hz: 1.0 / dt,
    };
    let sos = filter.sos()?;
    let needed = signal::sos_padlen(&sos) + 1;
    if rec.len() < needed.max(5) {
        return Err(Error::TooShort {
            file: rec.source.clone(),
            samples: rec.len(),
            needed: needed.max(5),
            why: format!(
                "a zero-phase Butterworth of order {} pads each end by {} samples",
                settings.order,
                needed - 1
            ),
        });
    }
    Ok(Conditioned {
        source: rec.source.clone(),
        dt,
        resampled_from,
        aligned: std::sync::OnceLock::new(),
        hold: rec.command_hold(),
        sampling: rec.velocity_sampling(),
        recording: rec,
        filter,
        sos,
        stencil: settings.stencil,
        edge_periods: settings.edge_periods,
    })
}

/// Command `u` at sample k aligned to the instant (module docs, step 2): a zero-order-held
/// command's mean over the half periods around t_k, (u_{k−1} + u_k)/2 (u_0 at k = 0); a
/// sampled command as it is.
fn align_command(u: &[f64], hold: CommandHold, k: usize) -> f64 {
    match hold {
        CommandHold::Sampled => u[k],
        CommandHold::Zoh if k == 0 => u[0],
        CommandHold::Zoh => 0.5 * (u[k - 1] + u[k]),
    }
}

/// Measurement `m` at sample k at the instant (module docs, step 2): window averages m_k over
/// [t_{k−1}, t_k] become (m_k + m_{k+1})/2 (the last one kept); instant samples as they are.
fn align_measurement(m: &[f64], sampling: VelocitySampling, k: usize) -> f64 {
    match sampling {
        VelocitySampling::WindowAverage if k + 1 < m.len() => 0.5 * (m[k] + m[k + 1]),
        _ => m[k],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn restamp_moves_window_middles_to_window_ends_and_commands_one_row_earlier() {
        let t = vec![0.01, 0.03, 0.05, 0.07];
        let mut r = Recording::new(
            "c.csv",
            t,
            vec![1.0, 2.0, 3.0, 4.0],
            vec![-1.0, -2.0, -3.0, -4.0],
            vec![0.1; 4],
            vec![0.2; 4],
        )
        .expect("valid");
        r.set_timing(Timing::WindowMiddle);
        let b = restamp(&r).expect("restamps");
        for (got, want) in b.t.iter().zip([0.02, 0.04, 0.06, 0.08]) {
            approx::assert_abs_diff_eq!(*got, want, epsilon = 1e-15);
        }
        assert_eq!(b.v_ref, vec![2.0, 3.0, 4.0, 4.0]);
        assert_eq!(b.w_ref, vec![-2.0, -3.0, -4.0, -4.0]);
        assert_eq!(b.v, r.v);
        assert_eq!(b.timing(), Some(Timing::WindowEnd));
        assert_eq!(b.meta("restamped_from"), Some("window_middle"));
        // Any other convention is left alone.
        r.set_timing(Timing::Instant);
        assert_eq!(*restamp(&r).expect("as is"), r);
    }

    fn rec(n: usize, dt: f64) -> Recording {
        let t: Vec<f64> = (0..n).map(|k| k as f64 * dt).collect();
        let u: Vec<f64> = t.iter().map(|t| (0.3 * t).sin()).collect();
        Recording::new("r.csv", t, u.clone(), u.clone(), u.clone(), u).expect("valid")
    }

    #[test]
    fn too_short_names_the_file() {
        let r = rec(10, 0.1);
        let e = condition(&r, None, 0.5, &ConditionSettings::default()).expect_err("must fail");
        assert!(
            e.to_string()
                .starts_with("r.csv: 10 samples, but 16 are needed"),
            "{e}"
        );
        assert_eq!(min_samples(4), 16);
    }

    #[test]
    fn zoh_commands_are_averaged_over_the_half_samples() {
        let mut r = rec(40, 0.1);
        r.v_ref = (0..40).map(|k| k as f64).collect();
        let c = condition(&r, None, 1.0, &ConditionSettings::default()).expect("ok");
        assert_eq!(c.v_ref()[0], 0.0);
        assert_eq!(c.v_ref()[5], 4.5);
        r.set_meta("command_hold", "sampled");
        let c = condition(&r, None, 1.0, &ConditionSettings::default()).expect("ok");
        assert_eq!(c.v_ref()[5], 5.0);
    }

    #[test]
    fn cutoff_rule_doubles_the_command_band_and_clamps() {
        let r = rec(3000, 0.1); // 0.3 rad/s sine (0.048 Hz, leaking over 1/300 Hz bins); 5/T = 0.0167 Hz
        let (fc, how) = suggest_cutoff(&[&r]).expect("ok");
        approx::assert_abs_diff_eq!(fc, 2.0 * 0.3 / (2.0 * std::f64::consts::PI), epsilon = 0.02);
        assert!(matches!(
            how,
            CutoffChoice::CommandBandwidth { clamped: false, .. }
        ));
    }

    #[test]
    fn initial_state_from_the_head_is_the_whole_signals_smoothed_first_sample() {
        // 100,000 samples of a noisy drive whose later samples are large (a step of 50 after
        // the head): the head's smoothed first sample equals the whole signal's to rounding,
        // for orders 2, 4 and 12 and the slowest cut-off the rule allows here.
        let dt = 0.02;
        let mut r = rec(100_000, dt);
        let mut state = 12345u64;
        for (k, (v, w)) in r.v.iter_mut().zip(r.w.iter_mut()).enumerate() {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let noise = (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5;
            *v += 0.05 * noise + if k > 40_000 { 50.0 } else { 0.0 };
            *w -= 0.03 * noise;
        }
        for (order, fc) in [(2, 0.2), (4, 0.64), (12, 0.2)] {
            let settings = ConditionSettings {
                order,
                ..ConditionSettings::default()
            };
            let c = condition(&r, None, fc, &settings).expect("ok");
            assert!(c.head_samples() < 40_000, "{}", c.head_samples());
            let whole = [
                c.smooth(c.v()).expect("v")[0],
                c.smooth(c.w()).expect("w")[0],
            ];
            let head = c.initial_state().expect("head");
            for (h, w) in head.iter().zip(whole) {
                // Measured: 0 to 5e-15, 1.4e-13 for order 12 (the narrow filter's own rounding).
                approx::assert_abs_diff_eq!(*h, w, epsilon = 1e-12);
            }
        }
    }
}
