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
    /// The 99 % band of r̂_εu(τ) for a single lag, τ = −M…M (index τ + M): ±2.576 times its
    /// robust standard deviation √V(τ) / (N σ̂_ε σ̂_u) (see [`independence`]).
    pub band: Vec<f64>,
    /// The band at the peak lag.
    pub bound: f64,
    /// The lag of the largest |t(τ)| (the most significant cross-correlation).
    pub peak_lag: isize,
    /// That largest |t(τ)| = |r̂_εu(τ)| in units of its robust standard deviation.
    pub peak_z: f64,
    /// Bonferroni-corrected p-value of the peak over the 2M + 1 lags.
    pub p_value: f64,
}

/// Cross-correlation test of residuals `e` against input `u` over lags τ = −M…M
/// (M = `max_lag`), robust to a residual whose size depends on the input.
///
/// Ljung's variance P/N (eq. 16.66, P = Σ_k r_ε(k) r_u(k)) holds when ε and u are
/// *independent*. A residual whose size follows the operating point (a friction or a clamp
/// that acts at some speeds, a noise level that changes with speed) is dependent on the
/// commands without being correlated with them, and then the spread of r̂_εu exceeds P/N: with
/// ε = η u², Ljung's test rejects 11 % of uncorrelated cases at a nominal 1 % (unit test). So
/// the test statistic at lag τ is the sum of the lag products z_t = ε(t + τ) u(t) (both
/// centred) over the square root of its long-run variance, Newey–West (1987) with Bartlett
/// weights over M lags on the centred products:
///
/// ```text
/// t(τ) = Σ_t z_t / √V(τ),   V(τ) = Ĉ_0 + 2 Σ_{j=1}^{M} (1 − j/(M+1)) Ĉ_j,
/// Ĉ_j = Σ_t (z_t − z̄)(z_{t+j} − z̄)
/// ```
///
/// (the heteroscedasticity- and autocorrelation-robust cross-correlation test of Dalla,
/// Giraitis & Phillips, *Econometric Theory* 38, 2022, with a HAC long-run variance; for
/// independent ε and u it estimates the same variance as Ljung's P/N). t(τ) is
/// asymptotically N(0, 1) under no correlation at lag τ; the p-value of the largest |t(τ)| is
/// Bonferroni-corrected over the 2M + 1 lags. Σ_t z_t z_{t+j} for all τ at once is a
/// cross-correlation of the products ε(t)ε(t + j) and u(t)u(t + j), done by FFT:
/// O(M · N log N) for the whole test.
///
/// Series of different lengths are cut to the shorter; a constant series gives r = 0 and
/// p = 1. [`independence_all`] tests several residuals against several inputs at once.
pub fn independence(e: &[f64], u: &[f64], max_lag: usize) -> Independence {
    independence_all(&[e], &[u], max_lag)
        .pop()
        .and_then(|mut row| row.pop())
        .unwrap_or_else(|| test_from(vec![0.0; 2 * max_lag + 1], &[], 0.0, max_lag))
}

/// [`independence`] of every residual in `es` against every input in `us` (result\[i\]\[j\]:
/// `es[i]` against `us[j]`), all cut to the shortest series. Each series' lag products are
/// transformed once per lag j and shared by its pairs, and the lags j are shared out over the
/// available cores: the same numbers as pair by pair, at about two thirds of the transforms.
pub fn independence_all(es: &[&[f64]], us: &[&[f64]], max_lag: usize) -> Vec<Vec<Independence>> {
    let n = es.iter().chain(us).map(|x| x.len()).min().unwrap_or(0);
    let ce: Vec<Vec<f64>> = es.iter().map(|e| centred(&e[..n])).collect();
    let cu: Vec<Vec<f64>> = us.iter().map(|u| centred(&u[..n])).collect();
    let weighted = weighted_lag_products(&ce, &cu, max_lag);
    ce.iter()
        .enumerate()
        .map(|(i, e)| {
            cu.iter()
                .enumerate()
                .map(|(j, u)| {
                    let r = cross_correlation(e, u, max_lag);
                    let den = (covariance_at(e, e, 0) * covariance_at(u, u, 0)).sqrt() * n as f64;
                    let variance = centre_variance(e, u, &weighted[i * cu.len() + j], max_lag);
                    test_from(r, &variance, den, max_lag)
                })
                .collect()
        })
        .collect()
}

/// The test result from r̂_εu(τ), V(τ) and N σ̂_ε σ̂_u (`den`), τ = −M…M.
fn test_from(r: Vec<f64>, variance: &[f64], den: f64, max_lag: usize) -> Independence {
    let m = max_lag as isize;
    let (mut peak_lag, mut peak_z) = (0isize, 0.0f64);
    let mut band = Vec::with_capacity(r.len());
    for (i, tau) in (-m..=m).enumerate() {
        let sd = variance.get(i).map_or(0.0, |v| v.max(0.0).sqrt() / den);
        band.push(2.576 * sd);
        let z = if sd > 0.0 && sd.is_finite() {
            r[i].abs() / sd
        } else {
            0.0
        };
        if z > peak_z {
            (peak_lag, peak_z) = (tau, z);
        }
    }
    let tail = 2.0 * Normal::standard().sf(peak_z);
    Independence {
        bound: band.get((peak_lag + m) as usize).copied().unwrap_or(0.0),
        band,
        peak_lag,
        peak_z,
        p_value: (tail * r.len() as f64).min(1.0),
        r,
    }
}

/// The Bartlett weight of lag j in the long-run variance over M lags, both sides counted:
/// w_0 = 1, w_j = 2 (1 − j/(M + 1)).
fn bartlett_weight(j: usize, max_lag: usize) -> f64 {
    if j == 0 {
        1.0
    } else {
        2.0 * (1.0 - j as f64 / (max_lag as f64 + 1.0))
    }
}

/// Σ_{j=0}^{M} w_j S_j(τ), τ = −M…M, for every pair (residual i, input k) at index
/// i · len(cu) + k ([`bartlett_weight`]): S_j(τ) = Σ_t z_t z_{t+j} of the lag products
/// z_t = ce(t + τ) cu(t). S_j(τ) = Σ_t a_j(t + τ) b_j(t) with a_j(t) = ce(t) ce(t + j),
/// b_j(t) = cu(t) cu(t + j): a cross-correlation, A_j B̄_j in the frequency domain
/// (zero-padded so that lags ±M do not wrap). The transform is linear, so the weighted sum
/// over j is taken of the spectra and transformed back once per pair.
fn weighted_lag_products(ce: &[Vec<f64>], cu: &[Vec<f64>], max_lag: usize) -> Vec<Vec<f64>> {
    use rayon::prelude::*;
    use realfft::num_complex::Complex;
    let n = ce.first().or(cu.first()).map_or(0, Vec::len);
    let lags = 2 * max_lag + 1;
    let pairs = ce.len() * cu.len();
    if n == 0 {
        return vec![vec![0.0; lags]; pairs];
    }
    let size = (n + max_lag).next_power_of_two();
    let mut planner = realfft::RealFftPlanner::<f64>::new();
    let (r2c, c2r) = (
        planner.plan_fft_forward(size),
        planner.plan_fft_inverse(size),
    );
    let bins = size / 2 + 1;
    let zero = || vec![vec![Complex::new(0.0, 0.0); bins]; pairs];
    let spectrum = |x: &[f64], j: usize, buf: &mut [f64], out: &mut [Complex<f64>]| {
        for (t, b) in buf.iter_mut().enumerate() {
            *b = if t + j < n { x[t] * x[t + j] } else { 0.0 };
        }
        // The buffer lengths match the plan: the transform cannot fail.
        let _ = r2c.process(buf, out);
    };
    // Fixed chunks of j, each summed in order, then the chunks in order: the same bits
    // whatever the number of threads.
    let js: Vec<usize> = (0..=max_lag.min(n - 1)).collect();
    let parts: Vec<Vec<Vec<Complex<f64>>>> = js
        .par_chunks(8)
        .map(|chunk| {
            let mut acc = zero();
            let mut buf = vec![0.0; size];
            let mut fa = vec![vec![Complex::new(0.0, 0.0); bins]; ce.len()];
            let mut fb = vec![vec![Complex::new(0.0, 0.0); bins]; cu.len()];
            for &j in chunk {
                let w = bartlett_weight(j, max_lag);
                for (x, out) in ce.iter().zip(fa.iter_mut()) {
                    spectrum(x, j, &mut buf, out);
                }
                for (x, out) in cu.iter().zip(fb.iter_mut()) {
                    spectrum(x, j, &mut buf, out);
                }
                for (i, a) in fa.iter().enumerate() {
                    for (k, b) in fb.iter().enumerate() {
                        for ((o, x), y) in acc[i * cu.len() + k].iter_mut().zip(a).zip(b) {
                            *o += w * x * y.conj();
                        }
                    }
                }
            }
            acc
        })
        .collect();
    let mut total = zero();
    for part in &parts {
        for (x, y) in total.iter_mut().zip(part) {
            for (p, q) in x.iter_mut().zip(y) {
                *p += q;
            }
        }
    }
    let mut corr = vec![0.0; size];
    total
        .into_iter()
        .map(|mut spec| {
            // Real inputs: the DC and Nyquist bins of the sum are real (rounding aside).
            spec[0].im = 0.0;
            spec[bins - 1].im = 0.0;
            if c2r.process(&mut spec, &mut corr).is_err() {
                return vec![f64::NAN; lags];
            }
            (0..lags)
                .map(|l| {
                    let tau = l as isize - max_lag as isize;
                    corr[tau.rem_euclid(size as isize) as usize] / size as f64
                })
                .collect()
        })
        .collect()
}

/// V(τ) of [`independence`] from the weighted sums of lag products `weighted` (of
/// [`weighted_lag_products`]) for centred `ce`, `cu` of equal length: each lag's products
/// centred on their mean z̄, Ĉ_j = S_j − z̄ (P_j + Q_j) + (n_τ − j) z̄², with P_j, Q_j the
/// sums of z over its first and last n_τ − j terms: P_j + Q_j = 2 Σz − (head_j + tail_j),
/// the sums of its first and last j terms.
fn centre_variance(ce: &[f64], cu: &[f64], weighted: &[f64], max_lag: usize) -> Vec<f64> {
    let n = ce.len();
    let m = max_lag as isize;
    (-m..=m)
        .enumerate()
        .map(|(i, tau)| {
            let t = tau.unsigned_abs();
            let len = n.saturating_sub(t);
            // z_k = ce(k + τ) cu(k) over the overlap.
            let z = |k: usize| {
                if tau >= 0 {
                    ce[k + t] * cu[k]
                } else {
                    ce[k] * cu[k + t]
                }
            };
            let total: f64 = (0..len).map(z).sum();
            let mean = total / len.max(1) as f64;
            let (mut head, mut tail, mut correction) = (0.0, 0.0, 0.0);
            for j in 0..=max_lag.min(len.saturating_sub(1)) {
                if j > 0 {
                    head += z(j - 1);
                    tail += z(len - j);
                }
                correction += bartlett_weight(j, max_lag)
                    * (-mean * (2.0 * total - head - tail) + (len - j) as f64 * mean * mean);
            }
            weighted[i] + correction
        })
        .collect()
}

/// V(τ) for one pair (the direct path of the tests).
#[cfg(test)]
fn lag_product_variance(ce: &[f64], cu: &[f64], max_lag: usize) -> Vec<f64> {
    let w = weighted_lag_products(&[ce.to_vec()], &[cu.to_vec()], max_lag);
    centre_variance(ce, cu, &w[0], max_lag)
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

    /// An AR(1) series x(t) = a x(t−1) + w(t), w uniform on [−1, 1].
    fn ar1(n: usize, a: f64, seed: u64) -> Vec<f64> {
        let w = white(n, seed);
        let mut x = 0.0;
        w.iter()
            .map(|v| {
                x = a * x + v;
                x
            })
            .collect()
    }

    #[test]
    fn the_lag_product_variance_equals_its_direct_sum() {
        let (ce, cu) = (centred(&ar1(300, 0.7, 3)), centred(&ar1(300, 0.9, 5)));
        let m = 12usize;
        let fast = lag_product_variance(&ce, &cu, m);
        for (i, tau) in (-(m as isize)..=m as isize).enumerate() {
            let z: Vec<f64> = (0..300isize)
                .filter(|&t| (0..300).contains(&(t + tau)))
                .map(|t| ce[(t + tau) as usize] * cu[t as usize])
                .collect();
            let mean = z.iter().sum::<f64>() / z.len() as f64;
            let c = |j: usize| -> f64 {
                (0..z.len() - j)
                    .map(|t| (z[t] - mean) * (z[t + j] - mean))
                    .sum()
            };
            let direct = c(0)
                + 2.0
                    * (1..=m)
                        .map(|j| (1.0 - j as f64 / (m as f64 + 1.0)) * c(j))
                        .sum::<f64>();
            approx::assert_relative_eq!(fast[i], direct, max_relative = 1e-10);
        }
    }

    #[test]
    fn batched_tests_equal_pair_by_pair() {
        let (e0, e1) = (ar1(500, 0.5, 1), ar1(500, 0.8, 2));
        let (u0, u1) = (ar1(500, 0.9, 3), ar1(500, 0.95, 4));
        let all = independence_all(&[&e0, &e1], &[&u0, &u1], 15);
        for (i, e) in [&e0, &e1].iter().enumerate() {
            for (k, u) in [&u0, &u1].iter().enumerate() {
                assert_eq!(all[i][k], independence(e, u, 15), "pair ({i}, {k})");
            }
        }
    }

    /// Ljung's p-value (eq. 16.66, variance P/N) of the largest |r̂_εu(τ)|, Bonferroni over
    /// the lags: the test [`independence`] replaced.
    fn ljung_p(e: &[f64], u: &[f64], m: usize) -> f64 {
        let r = cross_correlation(e, u, m);
        let (re, ru) = (autocorrelation(e, m), autocorrelation(u, m));
        let p = re[0] * ru[0] + 2.0 * (1..=m).map(|k| re[k] * ru[k]).sum::<f64>();
        let z = r.iter().fold(0.0f64, |a, x| a.max(x.abs())) / (p / e.len() as f64).sqrt();
        (2.0 * Normal::standard().sf(z) * r.len() as f64).min(1.0)
    }

    #[test]
    fn a_residual_whose_size_follows_the_input_is_no_correlation() {
        // ε(t) = η(t) u(t)²: uncorrelated with u at every lag, but dependent on it (as a
        // quantised encoder's error is on the speed). For Gaussian-like u the lag-0 product's
        // variance is E u⁶ / (E u⁴ E u²) ≈ 5 times what independence gives (and more than it
        // at the lags near 0), so Ljung's test fires; the robust one keeps its level.
        // 200 seeds at α = 1 %.
        let (mut robust, mut ljung) = (0, 0);
        for seed in 0..200u64 {
            let u = ar1(1200, 0.9, 1000 + seed);
            let e: Vec<f64> = white(1200, 5000 + seed)
                .iter()
                .zip(&u)
                .map(|(h, x)| h * x * x)
                .collect();
            robust += usize::from(independence(&e, &u, 25).p_value < 0.01);
            ljung += usize::from(ljung_p(&e, &u, 25) < 0.01);
        }
        eprintln!("rejections at 1 %: robust {robust}/200, Ljung {ljung}/200");
        // Binomial(200, 0.01): P(X ≥ 7) < 0.5 %.
        assert!(robust <= 6, "robust test rejected {robust}/200");
        // Ljung: 22/200 on these seeds; under its own level P(X ≥ 15) < 1e-8.
        assert!(ljung >= 15, "Ljung's test rejected only {ljung}/200");
    }

    #[test]
    fn for_independent_coloured_series_the_robust_band_is_ljungs() {
        // Independent AR(1) series: the robust variance estimates Ljung's P/N (eq. 16.66);
        // averaged over the lags and 20 seeds the two bands agree within 10 %.
        let m = 20;
        let mut ratio = 0.0;
        for seed in 0..20u64 {
            let (e, u) = (ar1(4000, 0.6, 10 + seed), ar1(4000, 0.9, 90 + seed));
            let t = independence(&e, &u, m);
            let (re, ru) = (autocorrelation(&e, m), autocorrelation(&u, m));
            let p = re[0] * ru[0] + 2.0 * (1..=m).map(|k| re[k] * ru[k]).sum::<f64>();
            let ljung = 2.576 * (p / 4000.0).sqrt();
            ratio += t.band.iter().sum::<f64>() / t.band.len() as f64 / ljung / 20.0;
        }
        approx::assert_abs_diff_eq!(ratio, 1.0, epsilon = 0.1);
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
