//! Residual analysis: is what the model leaves over noise, or structure (Ljung, *System
//! Identification*, 2nd ed., §16.6)?
//!
//! For residuals ε(t) and an input u(t), t = 1…N, both with their means removed,
//!
//! ```text
//! R̂_ε(τ)  = (1/N) Σ_t ε(t + τ) ε(t)           r̂_ε(τ)  = R̂_ε(τ) / R̂_ε(0)
//! R̂_εu(τ) = (1/N) Σ_t ε(t + τ) u(t)           r̂_εu(τ) = R̂_εu(τ) / √(R̂_ε(0) R̂_u(0))
//! ```
//!
//! * **whiteness**: if ε is white, √N r̂_ε(τ) is asymptotically N(0, 1) for each τ ≥ 1, and the
//!   Ljung–Box statistic Q = N(N + 2) Σ_{τ=1}^{M} r̂_ε(τ)²/(N − τ) is χ²(M);
//! * **independence of the input**: if ε is independent of u, √N r̂_εu(τ) is asymptotically
//!   N(0, P) with P = Σ_k r_ε(k) r_u(k) (Ljung eq. 16.66; P = 1 when either is white). A peak at
//!   τ > 0 means the input's past still explains the residual (missed dynamics, a delay); at
//!   τ < 0 it means feedback or a model that anticipates.
//!
//! A family of such tests over channels and lags is corrected for multiplicity with Holm's
//! step-down method ([`holm`]), so that a mismatch is declared only on evidence that survives
//! it.

use statrs::distribution::{ChiSquared, ContinuousCDF, Normal};

/// Mean-removed copy.
fn centred(x: &[f64]) -> Vec<f64> {
    let m = x.iter().sum::<f64>() / x.len().max(1) as f64;
    x.iter().map(|v| v - m).collect()
}

/// R̂_xy(τ) = (1/N) Σ_t x(t + τ) y(t) over the overlap, for centred x, y of equal length.
fn covariance_at(x: &[f64], y: &[f64], tau: isize) -> f64 {
    let n = x.len().min(y.len());
    let s: f64 = if tau >= 0 {
        let t = tau as usize;
        (0..n.saturating_sub(t)).map(|i| x[i + t] * y[i]).sum()
    } else {
        let t = tau.unsigned_abs();
        (0..n.saturating_sub(t)).map(|i| x[i] * y[i + t]).sum()
    };
    s / n.max(1) as f64
}

/// Normalised autocorrelation r̂(τ) for τ = 0…`max_lag` (r̂(0) = 1; all 0 for a constant x).
pub fn autocorrelation(x: &[f64], max_lag: usize) -> Vec<f64> {
    let c = centred(x);
    let r0 = covariance_at(&c, &c, 0);
    (0..=max_lag)
        .map(|t| {
            if r0 > 0.0 {
                covariance_at(&c, &c, t as isize) / r0
            } else {
                0.0
            }
        })
        .collect()
}

/// Normalised cross-correlation r̂_εu(τ) for τ = −`max_lag`…`max_lag` (index τ + max_lag);
/// positive τ: ε after u.
pub fn cross_correlation(e: &[f64], u: &[f64], max_lag: usize) -> Vec<f64> {
    let (ce, cu) = (centred(e), centred(u));
    let den = (covariance_at(&ce, &ce, 0) * covariance_at(&cu, &cu, 0)).sqrt();
    let m = max_lag as isize;
    (-m..=m)
        .map(|t| {
            if den > 0.0 {
                covariance_at(&ce, &cu, t) / den
            } else {
                0.0
            }
        })
        .collect()
}

/// Result of the whiteness test of one residual series.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Whiteness {
    /// r̂_ε(τ), τ = 0…M.
    pub r: Vec<f64>,
    /// The 99 % band ±2.576/√N for a single lag.
    pub bound: f64,
    /// Ljung–Box Q over lags 1…M.
    pub q: f64,
    /// P(χ²(M) ≥ Q).
    pub p_value: f64,
}

/// Ljung–Box whiteness test over lags 1…`max_lag` (needs N > max_lag + 1).
pub fn whiteness(e: &[f64], max_lag: usize) -> Whiteness {
    let n = e.len() as f64;
    let r = autocorrelation(e, max_lag);
    let q = n
        * (n + 2.0)
        * (1..=max_lag)
            .map(|t| r[t] * r[t] / (n - t as f64).max(1.0))
            .sum::<f64>();
    let p_value = ChiSquared::new(max_lag.max(1) as f64)
        .map(|d| d.sf(q))
        .unwrap_or(f64::NAN);
    Whiteness {
        r,
        bound: 2.576 / n.sqrt(),
        q,
        p_value,
    }
}

/// Result of the independence test of residuals against one input.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Independence {
    /// r̂_εu(τ), τ = −M…M (index τ + M).
    pub r: Vec<f64>,
    /// The 99 % band ±2.576 √(P/N) for a single lag.
    pub bound: f64,
    /// The lag of the largest |r̂_εu(τ)|.
    pub peak_lag: isize,
    /// That largest |r̂_εu| in units of its standard deviation √(P/N).
    pub peak_z: f64,
    /// Bonferroni-corrected p-value of the peak over the 2M + 1 lags.
    pub p_value: f64,
}

/// Cross-correlation test of residuals `e` against input `u` over lags −M…M, with the variance
/// P/N of Ljung eq. 16.66 (P from both autocorrelations up to lag M, so coloured residuals do
/// not raise false alarms).
pub fn independence(e: &[f64], u: &[f64], max_lag: usize) -> Independence {
    let n = e.len().min(u.len()) as f64;
    let r = cross_correlation(e, u, max_lag);
    let (re, ru) = (autocorrelation(e, max_lag), autocorrelation(u, max_lag));
    let p = (re[0] * ru[0] + 2.0 * (1..=max_lag).map(|k| re[k] * ru[k]).sum::<f64>()).max(1e-3);
    let sd = (p / n).sqrt();
    let (mut peak_lag, mut peak) = (0isize, 0.0f64);
    for (i, x) in r.iter().enumerate() {
        if x.abs() > peak {
            peak = x.abs();
            peak_lag = i as isize - max_lag as isize;
        }
    }
    let z = peak / sd;
    let tail = 2.0 * Normal::standard().sf(z);
    Independence {
        bound: 2.576 * sd,
        peak_lag,
        peak_z: z,
        p_value: (tail * r.len() as f64).min(1.0),
        r,
    }
}

/// Holm's step-down correction: which of the hypotheses with these p-values are rejected at
/// family-wise error rate `alpha` (Holm 1979). NaN p-values are never rejected.
pub fn holm(p_values: &[f64], alpha: f64) -> Vec<bool> {
    let m = p_values.len();
    let mut order: Vec<usize> = (0..m).collect();
    order.sort_by(|&a, &b| p_values[a].total_cmp(&p_values[b]));
    let mut reject = vec![false; m];
    for (rank, &i) in order.iter().enumerate() {
        let p = p_values[i];
        if p.is_nan() || p > alpha / (m - rank) as f64 {
            break;
        }
        reject[i] = true;
    }
    reject
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A deterministic white sequence (xorshift, uniform on [−1, 1]).
    fn white(n: usize, seed: u64) -> Vec<f64> {
        let mut s = seed.max(1);
        (0..n)
            .map(|_| {
                s ^= s << 13;
                s ^= s >> 7;
                s ^= s << 17;
                (s >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
            })
            .collect()
    }

    #[test]
    fn a_delayed_copy_peaks_at_its_delay_with_correlation_one() {
        let u = white(2000, 3);
        let d = 4;
        // ε(t) = u(t − d): r̂_εu(d) = 1 up to the end effects (d of N samples missing).
        let e: Vec<f64> = (0..u.len())
            .map(|t| if t >= d { u[t - d] } else { 0.0 })
            .collect();
        let t = independence(&e, &u, 10);
        assert_eq!(t.peak_lag, d as isize);
        approx::assert_abs_diff_eq!(t.r[10 + d], 1.0, epsilon = 0.01);
        assert!(t.p_value < 1e-12);
    }

    #[test]
    fn white_noise_passes_and_a_moving_average_fails_whiteness() {
        let e = white(5000, 7);
        let w = whiteness(&e, 20);
        assert!(w.p_value > 0.01, "p = {}", w.p_value);
        assert_eq!(w.r[0], 1.0);
        // ε(t) + ε(t−1): r(1) = 1/2 exactly in expectation.
        let ma: Vec<f64> = (1..e.len()).map(|t| e[t] + e[t - 1]).collect();
        let w = whiteness(&ma, 20);
        approx::assert_abs_diff_eq!(w.r[1], 0.5, epsilon = 0.03);
        assert!(w.p_value < 1e-12);
        // Independent white inputs: no alarm.
        let t = independence(&e, &white(5000, 11), 20);
        assert!(t.p_value > 0.01, "p = {}", t.p_value);
    }

    #[test]
    fn holm_rejects_step_down() {
        // m = 4, α = 0.05: thresholds 0.0125, 0.0167, 0.025, 0.05 in p order.
        let p = [0.01, 0.04, 0.016, 0.5];
        assert_eq!(holm(&p, 0.05), vec![true, false, true, false]);
        assert_eq!(holm(&[0.02, 0.02], 0.05), vec![true, true]);
        assert_eq!(holm(&[0.03, 0.03], 0.05), vec![false, false]);
        assert_eq!(holm(&[f64::NAN, 0.001], 0.05), vec![false, true]);
    }
}
