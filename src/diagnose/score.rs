//! Fingerprints: does the residual carry the pattern a candidate physics would imprint on it?
//!
//! For a candidate with parameters β (null value β₀, where the extended model is the current
//! one), its pattern is the change it makes to the free-run output, S = ∂ŷ/∂β at β₀ (forward
//! differences), or, for a limit whose null is at infinity (`velocity_saturation`,
//! `acceleration_limit`), S = ŷ(β_probe) − ŷ(∞) with a probe level read off the data. Part of
//! S can be absorbed by θ and the initial states, so only what is left after projecting out
//! the current model's Jacobian J counts:
//!
//! ```text
//! S⊥ = (I − J J⁺) S,   g = S⊥ᵀ e,   β̂ = (S⊥ᵀ S⊥)⁻¹ g,   ẽ = e − S⊥ β̂,   W = gᵀ V⁻¹ g ~ χ²(q),
//! V = Σ_r n_r/((n_r − L) (L + 1)) Σ_t B_t B_tᵀ,  B_t = Σ_{k=t}^{t+L} g̃_k,   g̃_k = S⊥,kᵀ ẽ_k,
//! ```
//!
//! with rows weighted by 1/σ_c: the test of β = β₀ in the Gauss–Newton regression of e on S⊥
//! (a score test's g, Engle 1984), V the Bartlett-kernel (Newey–West) estimate of the scores'
//! long-run covariance over L instants within each recording, computed as overlapping batch
//! means of L + 1 instants (equal up to edge terms), so that coloured residuals do not pass for
//! structure. V is estimated from the step's residual ẽ (a HAC Wald test of β̂), not from e:
//! under an alternative e carries the pattern, V grows with it, and a null-residual estimate
//! leaves the statistic small however strong the effect (Vogelsang 1999, J. Econometrics 88,
//! on the non-monotonic power of tests with HAC variances); under the null β̂ ≈ 0 and the two
//! agree. The scores of ẽ sum to zero, so V's mean is (1 − b) of the long-run covariance
//! (b = (L + 1)/n_r), and its variance ≈ (4/3) b of its square (Meketon & Schmeiser 1984): W
//! is referred to F(q, ν) as (1 − b̄) W/q with ν = Σ_r 3 n_r/(2 (L + 1)) equivalent degrees of
//! freedom, not to χ²(q) (unit tests: sizes at 5 %). β̂ is one Gauss–Newton step from β₀: the
//! candidate's first guess.
//! `payload_change` has a time that is not identified under the null; its statistic is the
//! largest over a grid of times, with a Bonferroni factor for the grid (Davies 1987).

use nalgebra::{DMatrix, DVector};
use statrs::distribution::{ContinuousCDF, FisherSnedecor};
use wheelid_core::{DynamicModel, Recording};

/// Simulated outputs of every recording: per recording (v̂, ω̂).
pub(crate) type Outputs = Vec<[Vec<f64>; 2]>;

/// Simulates `model` at `theta` over every recording (on the available cores, in order);
/// `None` if a simulation fails or is not finite.
pub(crate) fn simulate_all(
    model: &dyn DynamicModel,
    theta: &[f64],
    recs: &[Recording],
    initial: &[Vec<f64>],
) -> Option<Outputs> {
    use rayon::prelude::*;
    recs.par_iter()
        .zip(initial)
        .map(|(r, x0)| checked(model.simulate(theta, r, x0).ok()?, r))
        .collect()
}

/// A simulation of `rec` as two channels, `None` unless both are finite and as long as it.
pub(crate) fn checked(y: wheelid_core::Simulation, rec: &Recording) -> Option<[Vec<f64>; 2]> {
    let [v, w]: [Vec<f64>; 2] = y.try_into().ok()?;
    (v.iter().chain(&w).all(|x| x.is_finite()) && v.len() == rec.len()).then_some([v, w])
}

/// The rows of a fit: the training samples of each recording, both channels, weighted 1/σ_c.
pub(crate) struct Frame<'a> {
    pub recs: &'a [Recording],
    pub mask: &'a [Vec<bool>],
    pub weight: [f64; 2],
}

impl Frame<'_> {
    /// Number of rows (training samples × 2).
    pub fn rows(&self) -> usize {
        2 * self.mask.iter().flatten().filter(|&&b| b).count()
    }

    /// The weighted training rows of per-recording outputs (or residuals).
    pub fn flatten(&self, ys: &Outputs) -> DVector<f64> {
        let mut out = Vec::with_capacity(self.rows());
        for (y, m) in ys.iter().zip(self.mask) {
            for k in (0..m.len()).filter(|&k| m[k]) {
                out.push(self.weight[0] * y[0][k]);
                out.push(self.weight[1] * y[1][k]);
            }
        }
        DVector::from_vec(out)
    }

    /// The frame's weighting applied to unweighted rows in its order (sample, then channel),
    /// such as [`OutputErrorFit::jacobian`](wheelid_solvers::OutputErrorFit::jacobian) of a
    /// fit on the same training rows.
    pub fn weigh(&self, rows: &DMatrix<f64>) -> DMatrix<f64> {
        let mut out = rows.clone();
        for (i, mut row) in out.row_iter_mut().enumerate() {
            row *= self.weight[i % 2];
        }
        out
    }

    /// Weighted training residuals y − ŷ.
    pub fn residuals(&self, sim: &Outputs) -> DVector<f64> {
        let e: Outputs = self
            .recs
            .iter()
            .zip(sim)
            .map(|(r, s)| {
                [
                    r.v.iter().zip(&s[0]).map(|(a, b)| a - b).collect(),
                    r.w.iter().zip(&s[1]).map(|(a, b)| a - b).collect(),
                ]
            })
            .collect();
        self.flatten(&e)
    }

    /// Row ranges of each recording (for the per-recording long-run covariance).
    fn spans(&self) -> Vec<std::ops::Range<usize>> {
        let mut at = 0;
        self.mask
            .iter()
            .map(|m| {
                let n = 2 * m.iter().filter(|&&b| b).count();
                at += n;
                at - n..at
            })
            .collect()
    }
}

/// Difference quotient (a − b)/h of two output sets.
pub(crate) fn difference(a: &Outputs, b: &Outputs, h: f64) -> Outputs {
    a.iter()
        .zip(b)
        .map(|(x, y)| [0, 1].map(|c| x[c].iter().zip(&y[c]).map(|(p, q)| (p - q) / h).collect()))
        .collect()
}

/// Jacobian of the weighted training outputs with respect to θ and each recording's initial
/// state (columns: θ, then (v0, ω0) per recording): the model's sensitivities, or forward
/// differences of its simulation if it has none; `None` if a simulation fails.
pub(crate) fn jacobian(
    model: &dyn DynamicModel,
    theta: &[f64],
    initial: &[Vec<f64>],
    base: &Outputs,
    frame: &Frame<'_>,
) -> Option<DMatrix<f64>> {
    let p = theta.len();
    let nrec = frame.recs.len();
    let mut cols: Vec<DVector<f64>> = Vec::with_capacity(p + 2 * nrec);
    // The model's own sensitivities where it has them.
    let mut sens = Vec::with_capacity(nrec);
    for (rec, x0) in frame.recs.iter().zip(initial) {
        match model.simulate_with_sensitivities(theta, rec, x0) {
            Ok(Some((_, s))) => sens.push(s),
            Ok(None) => break,
            Err(_) => return None,
        }
    }
    if sens.len() == nrec {
        let zeros = || -> Outputs {
            frame
                .recs
                .iter()
                .map(|rec| [vec![0.0; rec.len()], vec![0.0; rec.len()]])
                .collect()
        };
        for j in 0..p {
            let d: Outputs = sens
                .iter()
                .map(|s| [0, 1].map(|c| s.theta[c].column(j).iter().copied().collect()))
                .collect();
            cols.push(frame.flatten(&d));
        }
        for (r, s) in sens.iter().enumerate() {
            for i in 0..2 {
                let mut d = zeros();
                d[r] = [0, 1].map(|c| s.initial[c].column(i).iter().copied().collect());
                cols.push(frame.flatten(&d));
            }
        }
        let j = DMatrix::from_columns(&cols);
        return j.iter().all(|x| x.is_finite()).then_some(j);
    }
    for j in 0..p {
        let h = 1e-6 * theta[j].abs().max(1e-3);
        let mut th = theta.to_vec();
        th[j] += h;
        let y = simulate_all(model, &th, frame.recs, initial)?;
        cols.push(frame.flatten(&difference(&y, base, h)));
    }
    for r in 0..nrec {
        for c in 0..2 {
            let h = 1e-6 * initial[r][c].abs().max(1e-3);
            let mut x0 = initial[r].clone();
            x0[c] += h;
            let y = model.simulate(theta, &frame.recs[r], &x0).ok()?;
            let mut d: Outputs = frame
                .recs
                .iter()
                .map(|rec| [vec![0.0; rec.len()], vec![0.0; rec.len()]])
                .collect();
            for ch in 0..2 {
                for k in 0..frame.recs[r].len() {
                    d[r][ch][k] = (y[ch][k] - base[r][ch][k]) / h;
                }
            }
            cols.push(frame.flatten(&d));
        }
    }
    Some(DMatrix::from_columns(&cols))
}

/// An orthonormal basis of the column space of J (thin SVD, relative tolerance 1e-10).
pub(crate) fn basis(j: &DMatrix<f64>) -> DMatrix<f64> {
    // Scale the columns first: θ and initial states have unrelated units.
    let mut js = j.clone();
    for mut c in js.column_iter_mut() {
        let n = c.norm();
        if n > 0.0 {
            c /= n;
        }
    }
    let svd = js.svd(true, false);
    let Some(u) = svd.u else {
        return DMatrix::zeros(j.nrows(), 0);
    };
    let smax = svd.singular_values.max();
    let keep: Vec<usize> = (0..svd.singular_values.len())
        .filter(|&i| svd.singular_values[i] > 1e-10 * smax)
        .collect();
    u.select_columns(keep.iter())
}

/// The result of one score test.
#[derive(Debug, Clone)]
pub(crate) struct Score {
    /// LM statistic.
    pub stat: f64,
    /// Degrees of freedom (independent pattern columns).
    pub dof: usize,
    /// p-value (χ² upper tail).
    pub p_value: f64,
    /// One Gauss–Newton step per column.
    pub beta: Vec<f64>,
    /// What that step would take off ‖e‖² (the weighted training residual's sum of squares
    /// along the pattern net of `q`: gᵀ (SₚᵀSₚ)⁻¹ g) — the effect size the pattern still
    /// explains, in the units of the training cost.
    pub explained: f64,
}

/// The test of the pattern columns `s` (rows as `frame`) against weighted residuals `e`
/// (module doc: g, β̂ and V from the Gauss–Newton step's residual), given an orthonormal basis
/// `q` of what θ and the initial states absorb; `lags` instants of Newey–West weights. `None`
/// if the pattern vanishes after the projection.
pub(crate) fn score(
    frame: &Frame<'_>,
    q: &DMatrix<f64>,
    s: &DMatrix<f64>,
    e: &DVector<f64>,
    lags: usize,
) -> Option<Score> {
    let proj = q.transpose() * s;
    let sp = s - q * proj;
    let k = sp.ncols();
    // Drop columns that θ absorbs entirely.
    let keep: Vec<usize> = (0..k)
        .filter(|&j| sp.column(j).norm() > 1e-6 * s.column(j).norm().max(1e-300))
        .collect();
    if keep.is_empty() {
        return None;
    }
    let sp = sp.select_columns(keep.iter());
    let k = sp.ncols();
    let g_total = sp.transpose() * e;
    let bread = (sp.transpose() * &sp).pseudo_inverse(1e-14).ok()?;
    let beta_kept = &bread * &g_total;
    // The long-run variance from the step's residual (module doc): from `e`, a Khepera clamp
    // whose fit takes 66 % off the validation cost scored χ² = 4.8 (seed 1023, window stamps).
    let e_step = e - &sp * &beta_kept;
    let mut meat = DMatrix::zeros(k, k);
    // The estimate's degrees of freedom and its mean over the true variance, summed and
    // weighted over the spans (module doc).
    let (mut dof, mut mean, mut instants) = (0.0, 0.0, 0.0);
    for span in frame.spans() {
        let n = span.len() / 2;
        // Per-instant scores g_t (row-major n × k), and their running sums (n + 1 rows).
        let mut pre = vec![0.0; (n + 1) * k];
        for t in 0..n {
            let r = span.start + 2 * t;
            for j in 0..k {
                let g = sp[(r, j)] * e_step[r] + sp[(r + 1, j)] * e_step[r + 1];
                pre[(t + 1) * k + j] = pre[t * k + j] + g;
            }
        }
        // Overlapping batch means over windows of m = L + 1 instants: the Bartlett-kernel
        // estimate of Var(Σ g_k) up to edge terms, in O(n k²) instead of O(n L k²).
        // (A span no longer than L + 1 instants: the plain sum of outer products, m = 1.)
        let m = if n > lags + 1 { lags + 1 } else { 1 };
        let windows = (n + 1).saturating_sub(m);
        let mut acc = DMatrix::<f64>::zeros(k, k);
        let mut b = vec![0.0; k];
        for t in 0..windows {
            for (j, bj) in b.iter_mut().enumerate() {
                *bj = pre[(t + m) * k + j] - pre[t * k + j];
            }
            for i in 0..k {
                for j in 0..=i {
                    acc[(i, j)] += b[i] * b[j];
                }
            }
        }
        for i in 0..k {
            for j in 0..i {
                acc[(j, i)] = acc[(i, j)];
            }
        }
        meat += acc * (n as f64 / (windows.max(1) as f64 * m as f64));
        let b = m as f64 / n.max(1) as f64;
        dof += if m > 1 { 1.5 / b } else { n as f64 };
        mean += n as f64 * (1.0 - b);
        instants += n as f64;
    }
    let meat_inv = meat.clone().pseudo_inverse(1e-12 * meat.max().abs()).ok()?;
    let stat = (g_total.transpose() * &meat_inv * &g_total)[(0, 0)].max(0.0);
    let mean = if instants > 0.0 { mean / instants } else { 1.0 };
    let explained = g_total.dot(&beta_kept).max(0.0);
    let mut beta = vec![0.0; s.ncols()];
    for (a, &j) in keep.iter().enumerate() {
        beta[j] = beta_kept[a];
    }
    let p_value =
        FisherSnedecor::new(k as f64, dof.max(1.0)).map_or(1.0, |d| d.sf(mean * stat / k as f64));
    Some(Score {
        stat,
        dof: k,
        p_value,
        beta,
        explained,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, StandardNormal};

    /// One standard normal draw.
    fn normal(rng: &mut ChaCha8Rng) -> f64 {
        StandardNormal.sample(rng)
    }

    /// A frame of one recording's `instants` (two rows each), every row weighted 1.
    fn frame(mask: &[Vec<bool>]) -> Frame<'_> {
        Frame {
            recs: &[],
            mask,
            weight: [1.0, 1.0],
        }
    }

    /// A pattern that acts in bursts (a limit binding on a tenth of the instants).
    fn bursts(rows: usize) -> DVector<f64> {
        DVector::from_fn(rows, |i, _| {
            let t = i / 2;
            if t % 100 < 10 {
                1.0 + 0.1 * (t % 7) as f64
            } else {
                0.0
            }
        })
    }

    /// A strong effect in the residual is found with the strength it has: e = 3 s + white
    /// noise (σ = 1) over 1,000 instants, s in bursts, 50 lags. The Gauss–Newton regression's
    /// statistic is then ≈ (3 ‖s‖)² (‖s‖² ≈ 240): above 1,000 here, where a long-run variance
    /// from the null's residual (e itself) caps it near instants/lags (measured: 10.8).
    #[test]
    fn a_strong_pattern_scores_as_strong() {
        let rows = 2000;
        let mask = vec![vec![true; rows / 2]];
        let s = bursts(rows);
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let e = DVector::from_fn(rows, |i, _| 3.0 * s[i] + normal(&mut rng));
        let q = DMatrix::<f64>::zeros(rows, 0);
        let sm = DMatrix::from_column_slice(rows, 1, s.as_slice());
        let got = score(&frame(&mask), &q, &sm, &e, 50).expect("a pattern");
        let ideal = (3.0 * s.norm()).powi(2);
        assert!(
            got.stat > 1000.0 && got.stat < 3.0 * ideal,
            "χ² = {} (ideal {ideal})",
            got.stat
        );
        assert!((got.beta[0] - 3.0).abs() < 0.2, "β̂ = {}", got.beta[0]);
    }

    /// Rejections at 5 % of `draws` null residuals (white noise independent of `s`), one
    /// recording of 1,000 instants, 50 lags.
    fn size(s: &DVector<f64>, draws: usize, seed: u64) -> f64 {
        let rows = s.len();
        let mask = vec![vec![true; rows / 2]];
        let q = DMatrix::<f64>::zeros(rows, 0);
        let sm = DMatrix::from_column_slice(rows, 1, s.as_slice());
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let rejected = (0..draws)
            .filter(|_| {
                let e = DVector::from_fn(rows, |_, _| normal(&mut rng));
                score(&frame(&mask), &q, &sm, &e, 50)
                    .expect("a pattern")
                    .p_value
                    < 0.05
            })
            .count();
        rejected as f64 / draws as f64
    }

    /// Under the null the test keeps its size with the estimate's degrees of freedom and mean
    /// (module doc), 2,000 draws each: a smooth pattern rejects 4.7 % at 5 % (the plain χ²
    /// reference: 6.0 %); a pattern in bursts, whose scores are few events, 9.6 % (χ²: 11.3 %)
    /// — liberal, as a limit's pattern is: the acceptance rules, not this size, keep clean
    /// runs clean. Bounds: the binomial 99.9 % range around those.
    #[test]
    fn under_the_null_the_size_holds() {
        let smooth = DVector::from_fn(2000, |i, _| (0.37 * (i / 2) as f64).sin());
        let share = size(&smooth, 2000, 11);
        assert!((0.035..=0.065).contains(&share), "smooth: size {share}");
        let share = size(&bursts(2000), 2000, 13);
        assert!((0.075..=0.12).contains(&share), "bursts: size {share}");
    }
}
