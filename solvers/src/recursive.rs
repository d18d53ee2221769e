//! Recursive least squares with exponential forgetting, a covariance-windup guard and a CUSUM
//! change detector that resets the covariance (Ljung 1999 §11.2; Åström & Wittenmark,
//! *Adaptive Control*, §2.2; Gustafsson, *Adaptive Filtering and Change Detection*, §5.2).
//!
//! For y_k = φ_kᵀ θ + e_k, with forgetting factor λ ∈ (0, 1]:
//!
//! ```text
//! ε_k = y_k − φ_kᵀ θ̂_{k−1}                  (a-priori prediction error)
//! s_k = λ + φ_kᵀ P_{k−1} φ_k
//! K_k = P_{k−1} φ_k / s_k
//! θ̂_k = θ̂_{k−1} + K_k ε_k
//! P_k = (P_{k−1} − K_k φ_kᵀ P_{k−1}) / λ
//! ```
//!
//! With λ = 1 and P_0 = p_0 I, θ̂_k is exactly the regularised batch solution
//! (I/p_0 + Σ φφᵀ)⁻¹ (θ̂_0/p_0 + Σ φ y). λ = 1 − Δt/T weights the past over a memory of about
//! T seconds. Under poor excitation the division by λ blows P up ("windup"): the step keeps
//! λ = 1 while trace P exceeds its start value.
//!
//! **Noise and intervals.** σ̂² is an exponentially weighted mean of the normalised
//! innovation ε² λ/s (whose mean is σ² when the model holds), each term clipped at
//! [`ChangeDetection::clip`] σ̂² so that a change does not inflate it before it is detected;
//! Cov(θ̂) ≈ σ̂² P.
//!
//! **Change detection.** The normalised squared innovation z_k = ε_k² λ/(s_k σ̂²) has mean 1
//! while θ holds. A one-sided CUSUM g_k = max(0, g_{k−1} + z_k − 1 − ν) raises an alarm at
//! g_k > h; then P is reset to P_0 (the estimate re-converges at the rate of a fresh start)
//! and g to 0. ν ([`ChangeDetection::drift`]) and h ([`ChangeDetection::threshold`]) trade
//! the delay against false alarms.
//!
//! Every update works on fixed-size arrays: no allocation, O(N²) per sample.

use wheelid_core::{Error, Result};

/// The CUSUM change detector's settings (module docs).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ChangeDetection {
    /// ν: the rise of the normalised squared innovation above its mean of 1 that is ignored
    /// [-].
    pub drift: f64,
    /// h: the CUSUM level that raises an alarm [-].
    pub threshold: f64,
    /// Samples before the detector arms (the estimate's own convergence from its start).
    pub warmup: u64,
    /// A normalised innovation enters σ̂² clipped at this many σ̂² [-].
    pub clip: f64,
    /// Forgetting factor of σ̂² (its memory in samples is 1/(1 − this)) [-].
    pub noise_forgetting: f64,
}

impl Default for ChangeDetection {
    fn default() -> Self {
        Self {
            drift: 2.0,
            threshold: 60.0,
            warmup: 500,
            clip: 4.0,
            noise_forgetting: 0.995,
        }
    }
}

/// Settings of a recursive least-squares estimator.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RlsSettings {
    /// λ ∈ (0, 1]: 1 keeps every sample; 1 − Δt/T a memory of about T seconds [-].
    pub forgetting: f64,
    /// p_0: the start (and reset) covariance P_0 = p_0 I, in (parameter unit / regressor
    /// unit)²; large for no prior knowledge.
    pub initial_variance: f64,
    /// The change detector, or none.
    pub detection: Option<ChangeDetection>,
}

impl Default for RlsSettings {
    fn default() -> Self {
        Self {
            forgetting: 1.0,
            initial_variance: 1e4,
            detection: Some(ChangeDetection::default()),
        }
    }
}

/// What one update did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RlsUpdate {
    /// ε: the a-priori prediction error y − φᵀθ̂ (the unit of y).
    pub error: f64,
    /// Whether the change detector raised an alarm at this sample (and reset P).
    pub change: bool,
}

/// A recursive least-squares estimator of N parameters (module docs).
#[derive(Debug, Clone)]
pub struct Rls<const N: usize> {
    settings: RlsSettings,
    theta: [f64; N],
    p: [[f64; N]; N],
    trace0: f64,
    noise_var: f64,
    cusum: f64,
    samples: u64,
    changes: u64,
}

impl<const N: usize> Rls<N> {
    /// An estimator starting at θ̂ = `theta0` with P = p_0 I.
    ///
    /// # Errors
    /// [`Error::InvalidSetting`] if λ ∉ (0, 1], p_0 ≤ 0, `theta0` is not finite, or a detector
    /// setting is out of range (ν < 0, h ≤ 0, clip < 1, its forgetting ∉ (0, 1)).
    pub fn new(settings: RlsSettings, theta0: [f64; N]) -> Result<Self> {
        let bad = |m: String| Err(Error::InvalidSetting(m));
        if !(settings.forgetting > 0.0 && settings.forgetting <= 1.0) {
            return bad(format!(
                "forgetting factor {} is not in (0, 1]",
                settings.forgetting
            ));
        }
        if !(settings.initial_variance > 0.0 && settings.initial_variance.is_finite()) {
            return bad(format!(
                "initial variance {} is not positive",
                settings.initial_variance
            ));
        }
        if theta0.iter().any(|x| !x.is_finite()) {
            return bad(format!("start θ {theta0:?} is not finite"));
        }
        if let Some(d) = settings.detection
            && !(d.drift >= 0.0
                && d.threshold > 0.0
                && d.clip >= 1.0
                && d.noise_forgetting > 0.0
                && d.noise_forgetting < 1.0)
        {
            return bad(format!("change detection {d:?} is out of range"));
        }
        let mut p = [[0.0; N]; N];
        for (i, row) in p.iter_mut().enumerate() {
            row[i] = settings.initial_variance;
        }
        Ok(Self {
            settings,
            theta: theta0,
            p,
            trace0: N as f64 * settings.initial_variance,
            noise_var: f64::NAN,
            cusum: 0.0,
            samples: 0,
            changes: 0,
        })
    }

    /// Takes one sample: regressor `phi` (N) and measurement `y`. A non-finite sample is
    /// skipped (returned with a NaN error).
    pub fn update(&mut self, phi: &[f64; N], y: f64) -> RlsUpdate {
        if !y.is_finite() || phi.iter().any(|x| !x.is_finite()) {
            return RlsUpdate {
                error: f64::NAN,
                change: false,
            };
        }
        let mut pphi = [0.0; N];
        for (i, row) in self.p.iter().enumerate() {
            pphi[i] = row.iter().zip(phi).map(|(a, b)| a * b).sum();
        }
        let trace: f64 = (0..N).map(|i| self.p[i][i]).sum();
        // Windup guard: no forgetting while P is above its start size.
        let lambda = if trace > self.trace0 {
            1.0
        } else {
            self.settings.forgetting
        };
        let s = lambda + phi.iter().zip(&pphi).map(|(a, b)| a * b).sum::<f64>();
        let error = y - phi.iter().zip(&self.theta).map(|(a, b)| a * b).sum::<f64>();
        for (t, k) in self.theta.iter_mut().zip(&pphi) {
            *t += k / s * error;
        }
        for i in 0..N {
            for j in i..N {
                let x = (self.p[i][j] - pphi[i] * pphi[j] / s) / lambda;
                self.p[i][j] = x;
                self.p[j][i] = x;
            }
        }
        self.samples += 1;
        let z = error * error * lambda / s;
        let change = self.detect(z);
        RlsUpdate { error, change }
    }

    /// Updates σ̂² and the CUSUM with the normalised squared innovation `z` (× σ²); on an
    /// alarm resets P. Returns whether it raised one.
    fn detect(&mut self, z: f64) -> bool {
        let Some(d) = self.settings.detection else {
            // σ̂² over every sample.
            let k = self.samples as f64;
            self.noise_var = if k <= 1.0 {
                z
            } else {
                self.noise_var + (z - self.noise_var) / k
            };
            return false;
        };
        if self.samples <= d.warmup {
            // Warm-up: σ̂² as a forgetting mean of the unclipped innovations.
            self.noise_var = if self.noise_var.is_finite() {
                d.noise_forgetting * self.noise_var + (1.0 - d.noise_forgetting) * z
            } else {
                z
            };
            return false;
        }
        let var = self.noise_var.max(f64::MIN_POSITIVE);
        let normalised = z / var;
        self.noise_var =
            d.noise_forgetting * var + (1.0 - d.noise_forgetting) * z.min(d.clip * var);
        self.cusum = (self.cusum + normalised - 1.0 - d.drift).max(0.0);
        if self.cusum > d.threshold {
            self.cusum = 0.0;
            self.changes += 1;
            for (i, row) in self.p.iter_mut().enumerate() {
                row.fill(0.0);
                row[i] = self.settings.initial_variance;
            }
            return true;
        }
        false
    }

    /// θ̂ (N).
    pub fn theta(&self) -> [f64; N] {
        self.theta
    }

    /// P (N × N, symmetric): the covariance before scaling by the noise variance.
    pub fn p(&self) -> [[f64; N]; N] {
        self.p
    }

    /// σ̂²: the noise variance of y (the unit of y, squared); NaN before the first sample.
    pub fn noise_variance(&self) -> f64 {
        self.noise_var
    }

    /// Standard errors of θ̂, √(σ̂² P_ii) (N; NaN before the first sample).
    pub fn std_err(&self) -> [f64; N] {
        std::array::from_fn(|i| (self.noise_var * self.p[i][i]).max(0.0).sqrt())
    }

    /// Samples taken (non-finite ones not counted).
    pub fn samples(&self) -> u64 {
        self.samples
    }

    /// Alarms raised so far.
    pub fn changes(&self) -> u64 {
        self.changes
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{DMatrix, DVector};

    /// A reproducible uniform stream in [−1, 1) (xorshift).
    fn stream(seed: u64) -> impl FnMut() -> f64 {
        let mut s = seed.max(1);
        move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        }
    }

    #[test]
    fn without_forgetting_it_is_the_regularised_batch_solution() {
        let settings = RlsSettings {
            forgetting: 1.0,
            initial_variance: 10.0,
            detection: None,
        };
        let theta0 = [0.5, -0.2, 0.1];
        let mut rls = Rls::<3>::new(settings, theta0).expect("valid");
        let mut u = stream(7);
        let (mut rows, mut ys) = (Vec::new(), Vec::new());
        for _ in 0..200 {
            let phi = [u(), u(), 1.0 + 0.3 * u()];
            let y = 0.3 * phi[0] - 1.2 * phi[1] + 0.7 * phi[2] + 0.05 * u();
            rls.update(&phi, y);
            rows.extend(phi);
            ys.push(y);
        }
        // (I/p0 + ΦᵀΦ) θ = θ0/p0 + Φᵀy, solved by nalgebra.
        let phi = DMatrix::from_row_slice(ys.len(), 3, &rows);
        let a = DMatrix::identity(3, 3) / 10.0 + phi.transpose() * &phi;
        let b = DVector::from_row_slice(&theta0) / 10.0 + phi.transpose() * DVector::from_vec(ys);
        let batch = a.lu().solve(&b).expect("solvable");
        for i in 0..3 {
            assert!(
                (rls.theta()[i] - batch[i]).abs() < 1e-10,
                "{:?} vs {batch}",
                rls.theta()
            );
        }
    }

    #[test]
    fn a_step_in_theta_is_detected_and_tracked_and_a_steady_stream_raises_no_alarm() {
        let settings = RlsSettings {
            forgetting: 0.999,
            ..RlsSettings::default()
        };
        let mut rls = Rls::<2>::new(settings, [0.0; 2]).expect("valid");
        let mut u = stream(3);
        let mut alarms = Vec::new();
        for k in 0..20_000 {
            let theta = if k < 10_000 { [1.0, 2.0] } else { [1.5, 2.0] };
            let phi = [u(), 1.0];
            let y = theta[0] * phi[0] + theta[1] * phi[1] + 0.01 * u();
            if rls.update(&phi, y).change {
                alarms.push(k);
            }
            if k == 10_100 {
                assert!((rls.theta()[0] - 1.5).abs() < 0.01, "{:?}", rls.theta());
            }
        }
        assert_eq!(alarms.len(), 1, "{alarms:?}");
        assert!((10_000..10_010).contains(&alarms[0]), "{alarms:?}");
        // σ̂ of uniform noise of half-width 0.01: 0.01/√3.
        let sd = rls.noise_variance().sqrt();
        assert!((sd / (0.01 / 3f64.sqrt()) - 1.0).abs() < 0.1, "{sd}");
        assert!(rls.std_err()[0] < 1e-3);
    }

    #[test]
    fn bad_settings_are_errors_and_bad_samples_are_skipped() {
        let bad = |s: RlsSettings| Rls::<1>::new(s, [0.0]).is_err();
        assert!(bad(RlsSettings {
            forgetting: 0.0,
            ..RlsSettings::default()
        }));
        assert!(bad(RlsSettings {
            initial_variance: -1.0,
            ..RlsSettings::default()
        }));
        assert!(Rls::<1>::new(RlsSettings::default(), [f64::NAN]).is_err());
        let mut r = Rls::<1>::new(RlsSettings::default(), [0.0]).expect("valid");
        assert!(r.update(&[f64::NAN], 1.0).error.is_nan());
        assert_eq!(r.samples(), 0);
        assert_eq!(r.theta(), [0.0]);
    }
}
