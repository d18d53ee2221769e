//! Signal processing: Butterworth low-pass design, zero-phase filtering and numerical
//! differentiation.
//!
//! # Filters
//! A digital Butterworth low-pass of order N, cut-off f_c at sample rate f_s, is designed
//! exactly as `scipy.signal.butter(N, f_c, fs=f_s)` does (bilinear transform with pre-warping),
//! through the `sci-rs` crate, in second-order sections (SOS) or transfer-function (b, a) form.
//!
//! Zero-phase filtering runs the filter forward, then backward over the reversed output
//! ("filtered once forward, and again in reverse", Laut 2011 §4.4.1), so the result has no lag
//! and the squared magnitude |H(e^{jω})|²:
//! * [`sosfiltfilt`] is `scipy.signal.sosfiltfilt(sos, x)` (odd extension of
//!   3·(2·n_sections + 1 − min(#b₂ = 0, #a₂ = 0)) samples, initial state from `sosfilt_zi`);
//! * [`filtfilt`] is `scipy.signal.filtfilt(b, a, x)` (odd extension of 3·max(len a, len b)
//!   samples, initial state from `lfilter_zi`).
//!
//! On the scipy 1.17 reference vectors in `shared/data/oracle/` (tested), [`sosfiltfilt`]
//! agrees to better than 1e-13 relative on every case and [`filtfilt`] to 1e-12 where the
//! transfer-function form is well conditioned. For order 6 at f_c/f_s = 0.01 the (b, a) form is
//! not: Σa ≈ 5.5e-8, so one ulp in a coefficient moves the DC gain by ~4e-8, and scipy's
//! `lfilter_zi` (a LAPACK solve of that near-singular system) is 3.3e-7 away from the exact
//! initial state, which [`filtfilt`] computes in closed form; there the two agree to 8e-8.
//! wheelid itself filters with second-order sections. Unlike `sci-rs`, which panics, both
//! return [`Error::TooShort`] when the signal is not longer than the padding.
//!
//! # Derivatives
//! [`derivative`] differentiates a uniformly sampled signal: [`Stencil::Central2`] is
//! `numpy.gradient` (second-order central differences, first-order one-sided at the ends);
//! [`Stencil::Central4`] uses the fourth-order stencil
//! ẋ_k ≈ (x_{k−2} − 8x_{k−1} + 8x_{k+1} − x_{k+2}) / (12 Δt), whose relative error on a sine of
//! frequency f is about (2πfΔt)⁴/30 instead of (2πfΔt)²/6 — 0.7 % versus 5·10⁻⁵ for the thesis's
//! fastest Pioneer excitation (2 rad/s) at the Pioneer's 10 Hz.

use sci_rs::signal::filter::design::{
    DigitalFilter, FilterBandType, FilterOutputType, SosFormatFilter, butter_dyn,
};
use sci_rs::signal::filter::sosfiltfilt_dyn;

use crate::error::{Error, Result};

mod blocks;
pub use blocks::{BlockInput, BlockPlan, FilteredBlock, sosfiltfilt_blocks};
pub use sci_rs::signal::filter::design::Sos;

/// A Butterworth low-pass specification.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Butterworth {
    /// Filter order N (1…12).
    pub order: usize,
    /// Cut-off frequency f_c \[Hz\], the −3 dB point of one pass.
    pub cutoff_hz: f64,
    /// Sample rate f_s \[Hz\].
    pub fs_hz: f64,
}

impl Butterworth {
    /// Checks the specification: 1 ≤ order ≤ 12 and 0 < f_c < f_s/2.
    ///
    /// # Errors
    /// [`Error::InvalidSetting`] naming the offending value.
    pub fn validate(&self) -> Result<()> {
        if !(1..=12).contains(&self.order) {
            return Err(Error::InvalidSetting(format!(
                "filter order must be 1..=12, got {}",
                self.order
            )));
        }
        if !(self.fs_hz.is_finite() && self.fs_hz > 0.0) {
            return Err(Error::InvalidSetting(format!(
                "sample rate must be positive, got {} Hz",
                self.fs_hz
            )));
        }
        if !(self.cutoff_hz.is_finite()
            && self.cutoff_hz > 0.0
            && self.cutoff_hz < self.fs_hz / 2.0)
        {
            return Err(Error::InvalidSetting(format!(
                "cut-off must lie in (0, f_s/2) = (0, {}) Hz, got {} Hz",
                self.fs_hz / 2.0,
                self.cutoff_hz
            )));
        }
        Ok(())
    }

    /// Second-order sections, rows `b0 b1 b2 a0 a1 a2` as scipy's `output='sos'`.
    ///
    /// # Errors
    /// As [`Butterworth::validate`].
    pub fn sos(&self) -> Result<Vec<Sos<f64>>> {
        self.validate()?;
        match butter_dyn(
            self.order,
            vec![self.cutoff_hz],
            Some(FilterBandType::Lowpass),
            Some(false),
            Some(FilterOutputType::Sos),
            Some(self.fs_hz),
        ) {
            DigitalFilter::Sos(SosFormatFilter { sos }) => Ok(sos),
            _ => Err(Error::InvalidSetting(
                "filter design returned no SOS".into(),
            )),
        }
    }

    /// Transfer-function coefficients (b, a), as scipy's default `output='ba'`.
    ///
    /// # Errors
    /// As [`Butterworth::validate`].
    pub fn ba(&self) -> Result<(Vec<f64>, Vec<f64>)> {
        self.validate()?;
        match butter_dyn(
            self.order,
            vec![self.cutoff_hz],
            Some(FilterBandType::Lowpass),
            Some(false),
            Some(FilterOutputType::Ba),
            Some(self.fs_hz),
        ) {
            // sci-rs pads b and a with trailing zeros; scipy returns order + 1 coefficients,
            // and filtfilt's padding length depends on it.
            DigitalFilter::Ba(mut ba) => {
                ba.b.truncate(self.order + 1);
                ba.a.truncate(self.order + 1);
                Ok((ba.b, ba.a))
            }
            _ => Err(Error::InvalidSetting(
                "filter design returned no (b, a)".into(),
            )),
        }
    }
}

/// Padding that [`sosfiltfilt`] applies at each end (scipy's default `padlen`).
pub fn sos_padlen(sos: &[Sos<f64>]) -> usize {
    let bzeros = sos.iter().filter(|s| s.b[2] == 0.0).count();
    let azeros = sos.iter().filter(|s| s.a[2] == 0.0).count();
    3 * (2 * sos.len() + 1 - bzeros.min(azeros))
}

/// Zero-phase filtering with second-order sections, as `scipy.signal.sosfiltfilt(sos, x)`.
///
/// Output has the length of `x`.
///
/// # Errors
/// [`Error::TooShort`] if `x.len() <= padlen` (scipy raises `ValueError` there; `sci-rs` would
/// panic).
pub fn sosfiltfilt(sos: &[Sos<f64>], x: &[f64]) -> Result<Vec<f64>> {
    let padlen = sos_padlen(sos);
    if x.len() <= padlen {
        return Err(too_short(x.len(), padlen + 1));
    }
    Ok(sosfiltfilt_dyn(x.iter(), sos))
}

/// Zero-phase filtering with transfer-function coefficients, as `scipy.signal.filtfilt(b, a, x)`
/// (odd padding of 3·max(len a, len b) samples, `lfilter_zi` initial conditions).
///
/// `b` and `a` must have the same length, with `a[0] ≠ 0`. Output has the length of `x`.
///
/// # Errors
/// [`Error::TooShort`] if `x.len() <= padlen`; [`Error::InvalidSetting`] for bad coefficients.
pub fn filtfilt(b: &[f64], a: &[f64], x: &[f64]) -> Result<Vec<f64>> {
    if b.len() != a.len() || a.is_empty() || a[0] == 0.0 {
        return Err(Error::InvalidSetting(
            "filtfilt needs b and a of equal length with a[0] != 0".into(),
        ));
    }
    let padlen = 3 * a.len().max(b.len());
    let n = x.len();
    if n <= padlen {
        return Err(too_short(n, padlen + 1));
    }
    let a0 = a[0];
    let (b, a): (Vec<f64>, Vec<f64>) = (
        b.iter().map(|v| v / a0).collect(),
        a.iter().map(|v| v / a0).collect(),
    );
    let zi = lfilter_zi(&b, &a);
    // Odd extension: 2·x0 − x[padlen..1], x, 2·x_end − x[n−2..n−2−padlen].
    let mut ext = Vec::with_capacity(n + 2 * padlen);
    ext.extend((1..=padlen).rev().map(|i| 2.0 * x[0] - x[i]));
    ext.extend_from_slice(x);
    ext.extend((1..=padlen).map(|i| 2.0 * x[n - 1] - x[n - 1 - i]));
    let mut z: Vec<f64> = zi.iter().map(|z| z * ext[0]).collect();
    let mut y = lfilter(&b, &a, &ext, &mut z);
    y.reverse();
    let mut z: Vec<f64> = zi.iter().map(|z| z * y[0]).collect();
    let mut out = lfilter(&b, &a, &y, &mut z);
    out.reverse();
    Ok(out[padlen..padlen + n].to_vec())
}

/// Initial state of [`lfilter`] for the steady state of a unit step: the solution of
/// (I − Aᵀ) z = b[1:] − a[1:]·b[0] (A the companion matrix of a) in the closed form that scipy's
/// `lfilter_zi` documents, with numpy's pairwise summation. It is exact to rounding where a LU
/// solve of the nearly singular system (scipy) is not; `sci_rs::lfilter_zi_dyn` uses the same
/// formula but sums in another order, which for Σa ≈ 1e-8 moves z₀ by 7e-8.
fn lfilter_zi(b: &[f64], a: &[f64]) -> Vec<f64> {
    let n = a.len();
    if n < 2 {
        return Vec::new();
    }
    // (I − companion(a)ᵀ)[:, 0] = [1 + a1, a2, …, a_{n−1}]
    let col0: Vec<f64> = (1..n)
        .map(|k| if k == 1 { 1.0 + a[1] } else { a[k] })
        .collect();
    let bvec: Vec<f64> = (1..n).map(|k| b[k] - a[k] * b[0]).collect();
    let z0 = numpy_sum(&bvec) / numpy_sum(&col0);
    let mut zi = vec![0.0; n - 1];
    zi[0] = z0;
    let (mut asum, mut csum) = (1.0, 0.0);
    for k in 1..n - 1 {
        asum += a[k];
        csum += b[k] - a[k] * b[0];
        zi[k] = asum * z0 - csum;
    }
    zi
}

/// numpy's pairwise summation (`pairwise_sum` in numpy's loops), so that sums match numpy's
/// rounding.
fn numpy_sum(x: &[f64]) -> f64 {
    let n = x.len();
    if n < 8 {
        x.iter().fold(0.0, |acc, v| acc + v)
    } else if n <= 128 {
        let mut r = [0.0; 8];
        r.copy_from_slice(&x[..8]);
        let mut i = 8;
        while i < n - n % 8 {
            for j in 0..8 {
                r[j] += x[i + j];
            }
            i += 8;
        }
        let mut res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]));
        for v in &x[n - n % 8..] {
            res += v;
        }
        res
    } else {
        let half = (n / 2) - (n / 2) % 8;
        numpy_sum(&x[..half]) + numpy_sum(&x[half..])
    }
}

/// Direct-form II transposed IIR filter (`scipy.signal.lfilter` with state `z`), `a[0] = 1`.
fn lfilter(b: &[f64], a: &[f64], x: &[f64], z: &mut [f64]) -> Vec<f64> {
    let m = b.len();
    x.iter()
        .map(|&xi| {
            let yi = b[0] * xi + z.first().copied().unwrap_or(0.0);
            for j in 0..m.saturating_sub(2) {
                z[j] = b[j + 1] * xi + z[j + 1] - a[j + 1] * yi;
            }
            if m >= 2 {
                z[m - 2] = b[m - 1] * xi - a[m - 1] * yi;
            }
            yi
        })
        .collect()
}

fn too_short(samples: usize, needed: usize) -> Error {
    Error::TooShort {
        file: "<signal>".into(),
        samples,
        needed,
        why: "zero-phase filtering pads each end by 3 × the filter length".into(),
    }
}

/// Finite-difference stencil for [`derivative`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Stencil {
    /// `numpy.gradient(x, dt)`: (x_{k+1} − x_{k−1})/(2Δt) inside, one-sided first order at the
    /// ends.
    Central2,
    /// Fourth-order central differences inside, second-order central one sample from the ends,
    /// second-order one-sided at the ends.
    #[default]
    Central4,
}

/// Derivative of a uniformly sampled signal with period `dt` \[s\]; output has the length of `x`.
///
/// # Errors
/// [`Error::TooShort`] for fewer than 3 samples; [`Error::InvalidSetting`] if `dt ≤ 0`.
pub fn derivative(x: &[f64], dt: f64, stencil: Stencil) -> Result<Vec<f64>> {
    let n = x.len();
    if n < 3 {
        return Err(Error::TooShort {
            file: "<signal>".into(),
            samples: n,
            needed: 3,
            why: "a derivative needs three samples".into(),
        });
    }
    if !(dt.is_finite() && dt > 0.0) {
        return Err(Error::InvalidSetting(format!(
            "sample period must be positive, got {dt}"
        )));
    }
    let mut d = vec![0.0; n];
    match stencil {
        Stencil::Central2 => {
            d[0] = (x[1] - x[0]) / dt;
            d[n - 1] = (x[n - 1] - x[n - 2]) / dt;
            for k in 1..n - 1 {
                d[k] = (x[k + 1] - x[k - 1]) / (2.0 * dt);
            }
        }
        Stencil::Central4 => {
            d[0] = (-3.0 * x[0] + 4.0 * x[1] - x[2]) / (2.0 * dt);
            d[n - 1] = (3.0 * x[n - 1] - 4.0 * x[n - 2] + x[n - 3]) / (2.0 * dt);
            for k in 1..n - 1 {
                d[k] = if k >= 2 && k + 2 < n {
                    (x[k - 2] - 8.0 * x[k - 1] + 8.0 * x[k + 1] - x[k + 2]) / (12.0 * dt)
                } else {
                    (x[k + 1] - x[k - 1]) / (2.0 * dt)
                };
            }
        }
    }
    Ok(d)
}

/// The frequency \[Hz\] below which `fraction` of a signal's variance lies (periodogram of the
/// mean-removed signal, sampled at `fs_hz`). Returns `None` for a constant signal.
///
/// Used by the default cut-off rule (see `condition`).
pub fn power_quantile_hz(x: &[f64], fs_hz: f64, fraction: f64) -> Option<f64> {
    power_quantile_hz_with(&mut realfft::RealFftPlanner::new(), x, fs_hz, fraction)
}

/// [`power_quantile_hz`] with the transforms of `planner`, which keeps them (and their
/// twiddle factors, one sine and cosine each) for the next signal of the same length.
pub fn power_quantile_hz_with(
    planner: &mut realfft::RealFftPlanner<f64>,
    x: &[f64],
    fs_hz: f64,
    fraction: f64,
) -> Option<f64> {
    let n = x.len();
    let power = periodogram_with(planner, x)?;
    let total: f64 = power[1..].iter().sum();
    if total <= f64::MIN_POSITIVE * n as f64 || !total.is_finite() {
        return None;
    }
    let mut acc = 0.0;
    for (k, p) in power[1..].iter().enumerate() {
        acc += p;
        if acc >= fraction * total {
            return Some((k + 1) as f64 * fs_hz / n as f64);
        }
    }
    Some(fs_hz / 2.0)
}

/// The periodogram of the mean-removed signal `x`: |X_k|² for k = 0 … ⌊n/2⌋, where
/// X_k = Σ_t (x_t − x̄) e^(−2πi k t / n) (unnormalised); bin k lies at k fs / n Hz. `None` for
/// fewer than 4 samples.
///
/// The real-input transform gives bins 0 … ⌊n/2⌋ of the full one at half its work and memory.
pub fn periodogram(x: &[f64]) -> Option<Vec<f64>> {
    periodogram_with(&mut realfft::RealFftPlanner::new(), x)
}

/// [`periodogram`] with the transforms of `planner` (kept for the next signal of the same
/// length).
pub fn periodogram_with(planner: &mut realfft::RealFftPlanner<f64>, x: &[f64]) -> Option<Vec<f64>> {
    let n = x.len();
    if n < 4 {
        return None;
    }
    let mean = x.iter().sum::<f64>() / n as f64;
    let mut input: Vec<f64> = x.iter().map(|v| v - mean).collect();
    let r2c = planner.plan_fft_forward(n);
    let mut spectrum = r2c.make_output_vec();
    r2c.process(&mut input, &mut spectrum).ok()?;
    Some(spectrum.iter().map(|c| c.norm_sqr()).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn derivative_is_exact_on_cubics_inside_and_quadratics_at_the_ends() {
        let dt = 0.1;
        let x: Vec<f64> = (0..20).map(|k| (k as f64 * dt).powi(3)).collect();
        let d = derivative(&x, dt, Stencil::Central4).expect("ok");
        for (k, dk) in d.iter().enumerate().take(18).skip(2) {
            let t = k as f64 * dt;
            approx::assert_relative_eq!(*dk, 3.0 * t * t, max_relative = 1e-10);
        }
        let q: Vec<f64> = (0..20).map(|k| (k as f64 * dt).powi(2)).collect();
        let d = derivative(&q, dt, Stencil::Central4).expect("ok");
        approx::assert_abs_diff_eq!(d[0], 0.0, epsilon = 1e-12);
        approx::assert_abs_diff_eq!(d[19], 2.0 * 1.9, epsilon = 1e-12);
    }

    #[test]
    fn central2_matches_numpy_gradient() {
        // numpy.gradient([1, 2, 4, 7, 11], 0.5) = [2, 3, 5, 7, 8]
        let d = derivative(&[1.0, 2.0, 4.0, 7.0, 11.0], 0.5, Stencil::Central2).expect("ok");
        assert_eq!(d, vec![2.0, 3.0, 5.0, 7.0, 8.0]);
    }

    #[test]
    fn short_signals_are_errors_not_panics() {
        let f = Butterworth {
            order: 4,
            cutoff_hz: 1.0,
            fs_hz: 50.0,
        };
        let sos = f.sos().expect("design");
        assert_eq!(sos_padlen(&sos), 15);
        assert!(matches!(
            sosfiltfilt(&sos, &[0.0; 15]),
            Err(Error::TooShort { needed: 16, .. })
        ));
        assert!(sosfiltfilt(&sos, &[0.0; 16]).is_ok());
        let (b, a) = f.ba().expect("design");
        assert!(matches!(
            filtfilt(&b, &a, &[0.0; 15]),
            Err(Error::TooShort { .. })
        ));
    }

    #[test]
    fn invalid_cutoff_is_an_error() {
        let f = Butterworth {
            order: 2,
            cutoff_hz: 30.0,
            fs_hz: 50.0,
        };
        assert!(matches!(f.sos(), Err(Error::InvalidSetting(_))));
    }

    #[test]
    fn power_quantile_finds_the_sine() {
        let fs = 20.0;
        let x: Vec<f64> = (0..2000)
            .map(|k| (2.0 * std::f64::consts::PI * 0.5 * k as f64 / fs).sin())
            .collect();
        let f = power_quantile_hz(&x, fs, 0.95).expect("non-constant");
        approx::assert_abs_diff_eq!(f, 0.5, epsilon = 0.011);
        assert_eq!(power_quantile_hz(&[1.0; 100], fs, 0.95), None);
    }

    #[test]
    fn periodogram_of_a_cosine_on_a_bin_is_its_closed_form() {
        // A cos(2π k0 t / n) + c over n samples: |X_k0|² = (A n / 2)², every other bin 0 (the
        // mean c removed), ⌊n/2⌋ + 1 bins for odd and even n.
        for n in [512usize, 501] {
            let (a, k0, c) = (1.5, 37usize, 4.0);
            let x: Vec<f64> = (0..n)
                .map(|t| a * (2.0 * std::f64::consts::PI * (k0 * t) as f64 / n as f64).cos() + c)
                .collect();
            let p = periodogram(&x).expect("long enough");
            assert_eq!(p.len(), n / 2 + 1);
            let peak = (a * n as f64 / 2.0).powi(2);
            approx::assert_relative_eq!(p[k0], peak, max_relative = 1e-12);
            let rest: f64 = p
                .iter()
                .enumerate()
                .filter(|(k, _)| *k != k0)
                .map(|(_, v)| v)
                .sum();
            assert!(rest < 1e-18 * peak, "leak {rest:e}");
        }
        assert_eq!(periodogram(&[1.0, 2.0, 3.0]), None);
    }
}
