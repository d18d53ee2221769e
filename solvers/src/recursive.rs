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
//! **Noise.** σ̂² is an exponentially weighted mean of the normalised innovation ε² λ/s
//! (whose mean is σ² when the model holds), each term clipped at [`ChangeDetection::clip`] σ̂²
//! so that a change does not inflate it before it is detected; the change detector reads it.
//!
//! **Intervals.** σ̂² P is Cov(θ̂) only for white equation errors and no forgetting. With
//! h_k = φ_k e_k (e the equation error), θ̂_t − θ ≈ P_t Σ_k λ^{t−k} h_k, so
//!
//! ```text
//! Cov(θ̂_t) = P_t M_t P_t,    M_t = Var(Σ_k λ^{t−k} h_k) ≈ w_t Ω,    w_t = λ² w_{t−1} + 1
//! ```
//!
//! with Ω the long-run covariance of h (Σ over every lag of its autocovariances): equation
//! errors of a prefiltered, sampled model of a real robot are coloured, and Ω is then many
//! times the white-noise Γ_0. Ω is estimated recursively by the AR(1) plug-in of Andrews
//! (1991, *Econometrica* 59: 817–858), e_k taken as the a-posteriori error ε_k λ/s_k (the
//! a-priori one carries the start's transient into the sums): Γ_0 and each component's
//! lag-one correlation ρ_i as λ-weighted means, Ω_ij = Γ_0,ij √(f_i f_j), f_i = (1 + ρ_i)/(1 − ρ_i), |ρ_i| ≤ 0.97
//! (positive semi-definite as Γ_0 is). O(N²) per sample; a covariance reset clears it.
//!
//! **Change detection.** The squared innovation z_k = ε_k² λ/s_k has a steady mean σ̄² while
//! θ holds. After its warm-up the detector learns, raising no alarm, for two more warm-ups:
//! σ̄² as the plain mean of z over the first; then a one-sided CUSUM
//! g_k = max(0, g_{k−1} + z_k/σ̄² − 1 − ν) over the second, its largest excursion g_max kept.
//! Armed, g goes on against σ̄² (held) and raises an alarm at g_k > ĥ = max(h, c g_max) ([`ChangeDetection::calibration`]); then P is reset to P_0 (the
//! estimate re-converges at the rate of a fresh start), g to 0, and no alarm is raised for a
//! warm-up. ν ([`ChangeDetection::drift`]) and h ([`ChangeDetection::threshold`]) trade the
//! delay against false alarms. A real robot's one-step errors come in bursts at every command
//! step whose transient the model misses in part: against a clipped running σ̂² (this
//! detector before 2026-11-26) their mean is far above 1 and a fixed h raised an alarm at
//! nearly every step (Husky A200 on wet grass: 89 and 86 in 167 s, never settled); the plain
//! mean takes the bursts in, and the learned level their size. σ̂² (the clipped running mean,
//! [`Rls::noise_variance`]) is kept for the report.
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
    /// Samples of the warm-up (the estimate's own convergence from its start; ≥ 1); the
    /// detector then learns for two more warm-ups before it arms, and waits one after each
    /// alarm.
    pub warmup: u64,
    /// A squared innovation enters the reported σ̂² ([`Rls::noise_variance`]) clipped at this
    /// many σ̂² [-] (the detector's own reference is the plain mean it learned).
    pub clip: f64,
    /// Forgetting factor of the reported σ̂² (its memory in samples is 1/(1 − this)) [-].
    pub noise_forgetting: f64,
    /// c: the level that raises an alarm is max(h, c × the largest excursion of the CUSUM
    /// while it learns) [-] (module docs, "Change detection"; learning takes two more
    /// `warmup`s after the warm-up). A real robot's innovations come in bursts at every
    /// large command step where the model misses part of the transient; a level below the
    /// bursts of a steady drive raises an alarm at every step.
    pub calibration: f64,
}

impl Default for ChangeDetection {
    fn default() -> Self {
        Self {
            drift: 2.0,
            threshold: 60.0,
            warmup: 500,
            clip: 4.0,
            noise_forgetting: 0.995,
            calibration: 2.0,
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

/// aᵀ b.
fn dot<const N: usize>(a: &[f64; N], b: &[f64; N]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// aᵀ P b.
fn quadratic<const N: usize>(a: &[f64; N], p: &[[f64; N]; N], b: &[f64; N]) -> f64 {
    a.iter().zip(p).map(|(x, row)| x * dot(row, b)).sum()
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
    /// The CUSUM's largest excursion while the detector learns ([`ChangeDetection::calibration`]).
    excursion: f64,
    /// σ̄²: the mean of z the detector learned, its CUSUM's reference (NaN before).
    reference: f64,
    /// Σ z while σ̄² is learned (over `warmup` samples: σ̄² = this / `warmup`).
    learned: f64,
    /// The last sample of the quiet warm-up after an alarm (the estimate re-converging from
    /// P_0 is no change).
    quiet_until: u64,
    samples: u64,
    changes: u64,
    /// The long-run covariance's running sums (module docs, "Intervals").
    hac: LongRun<N>,
}

/// λ-weighted sums behind the AR(1) plug-in estimate of the long-run covariance Ω of
/// h_k = φ_k ε_k, and w = Σ λ^{2(t−k)} (module docs, "Intervals").
#[derive(Debug, Clone)]
struct LongRun<const N: usize> {
    /// Σ λ^{t−k} h_k h_kᵀ.
    gamma0: [[f64; N]; N],
    /// Σ λ^{t−k} h_k,i h_{k−1},i and Σ λ^{t−k} h_{k−1},i², per component.
    lag1: [f64; N],
    lag0: [f64; N],
    /// Σ λ^{t−k}: the weights of the sums above.
    weight: f64,
    /// w_t = λ² w_{t−1} + 1.
    w2: f64,
    /// h_{k−1}, once there.
    prev: Option<[f64; N]>,
}

/// |ρ| of a component of h at most this in the AR(1) plug-in (Andrews 1991's guard).
const RHO_MAX: f64 = 0.97;

impl<const N: usize> LongRun<N> {
    fn new() -> Self {
        Self {
            gamma0: [[0.0; N]; N],
            lag1: [0.0; N],
            lag0: [0.0; N],
            weight: 0.0,
            w2: 0.0,
            prev: None,
        }
    }

    /// Takes h_k = φ_k ε_k with the step's λ.
    fn push(&mut self, h: &[f64; N], lambda: f64) {
        for i in 0..N {
            for j in i..N {
                self.gamma0[i][j] = lambda * self.gamma0[i][j] + h[i] * h[j];
            }
        }
        if let Some(prev) = self.prev {
            for i in 0..N {
                self.lag1[i] = lambda * self.lag1[i] + h[i] * prev[i];
                self.lag0[i] = lambda * self.lag0[i] + prev[i] * prev[i];
            }
        }
        self.weight = lambda * self.weight + 1.0;
        self.w2 = lambda * lambda * self.w2 + 1.0;
        self.prev = Some(*h);
    }

    /// M = w Ω (N × N); zero before a sample.
    fn meat(&self) -> [[f64; N]; N] {
        if self.weight <= 0.0 {
            return [[0.0; N]; N];
        }
        let root_f: [f64; N] = std::array::from_fn(|i| {
            let rho = if self.lag0[i] > 0.0 {
                (self.lag1[i] / self.lag0[i]).clamp(-RHO_MAX, RHO_MAX)
            } else {
                0.0
            };
            ((1.0 + rho) / (1.0 - rho)).sqrt()
        });
        let scale = self.w2 / self.weight;
        std::array::from_fn(|i| {
            std::array::from_fn(|j| {
                let (a, b) = if i <= j { (i, j) } else { (j, i) };
                scale * self.gamma0[a][b] * root_f[i] * root_f[j]
            })
        })
    }
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
                && d.noise_forgetting < 1.0
                && d.calibration >= 0.0
                && d.calibration.is_finite()
                && d.warmup >= 1)
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
            excursion: 0.0,
            reference: f64::NAN,
            learned: 0.0,
            quiet_until: 0,
            samples: 0,
            changes: 0,
            hac: LongRun::new(),
        })
    }

    /// Takes one sample: regressor `phi` (N) and measurement `y`. A non-finite sample is
    /// skipped (returned with a NaN error).
    pub fn update(&mut self, phi: &[f64; N], y: f64) -> RlsUpdate {
        self.step(phi, None, y, (None, None))
    }

    /// Takes one sample by recursive instrumental variables (Ljung 1999 eq. 11.51; Young's
    /// RIV): regressor `phi` (N), instruments `zeta` (N: correlated with `phi`, not with the
    /// equation error — e.g. `phi` with each measured output replaced by an auxiliary model's
    /// simulated one) and measurement `y`:
    ///
    /// ```text
    /// s_k = λ + φ_kᵀ P_{k−1} ζ_k,  θ̂_k = θ̂_{k−1} + P_{k−1} ζ_k ε_k / s_k,
    /// P_k = (P_{k−1} − P_{k−1} ζ_k φ_kᵀ P_{k−1} / s_k) / λ
    /// ```
    ///
    /// P is then not symmetric; [`Rls::covariance`] is P M Pᵀ with h_k = ζ_k ε_k. With
    /// `zeta` = `phi` this is [`Rls::update`]. A non-finite sample is skipped.
    pub fn update_iv(&mut self, phi: &[f64; N], zeta: &[f64; N], y: f64) -> RlsUpdate {
        if zeta.iter().any(|x| !x.is_finite()) {
            return RlsUpdate {
                error: f64::NAN,
                change: false,
            };
        }
        self.step(phi, Some(zeta), y, (None, None))
    }

    /// Takes one sample by a recursive prediction-error method (Ljung 1999 §11.3, Gauss–Newton
    /// direction; Ljung & Söderström 1983, *Theory and Practice of Recursive Identification*):
    /// the model's prediction error `error` = y_k − ŷ_k(θ̂) and its gradient `psi` = ∂ŷ_k/∂θ at
    /// θ̂ (N), e.g. an output-error model's simulated output and its sensitivities:
    ///
    /// ```text
    /// s_k = λ + ψ_kᵀ P_{k−1} ψ_k,  θ̂_k = θ̂_{k−1} + P_{k−1} ψ_k ε_k / s_k,
    /// P_k = (P_{k−1} − P_{k−1} ψ_k ψ_kᵀ P_{k−1} / s_k) / λ
    /// ```
    ///
    /// The intervals take h_k = ψ_k ε_k. An output error is coloured by the model's own
    /// dynamics, so the change detector reads instead the one-step prediction error of the
    /// linear regression `detect` = (φ_k, y_k) at the same θ̂ (near white while θ holds),
    /// normalised by λ + φ_kᵀ P_{k−1} φ_k. A non-finite sample is skipped.
    pub fn update_gradient(
        &mut self,
        psi: &[f64; N],
        error: f64,
        detect: (&[f64; N], f64),
    ) -> RlsUpdate {
        let (phi, y) = detect;
        if !error.is_finite() || !y.is_finite() || phi.iter().any(|x| !x.is_finite()) {
            return RlsUpdate {
                error: f64::NAN,
                change: false,
            };
        }
        let innovation = y - dot(phi, &self.theta);
        // The step normalises it with its own λ (taken once).
        let detect = (innovation, quadratic(phi, &self.p, phi));
        let step = self.step(psi, None, error, (Some(error), Some(detect)));
        RlsUpdate {
            error: innovation,
            ..step
        }
    }

    /// The step's forgetting factor: λ, or 1 while trace P is above its start (windup guard).
    fn lambda(&self) -> f64 {
        let trace: f64 = (0..N).map(|i| self.p[i][i]).sum();
        if trace > self.trace0 {
            1.0
        } else {
            self.settings.forgetting
        }
    }

    /// One step of [`Rls::update`] (`zeta` none: P stays symmetric), [`Rls::update_iv`] or
    /// [`Rls::update_gradient`] (`given`: the prediction error, where it is not y − φᵀθ̂;
    /// `detect`: the change detector's innovation e and φᵀ P φ of its regressor, where they are
    /// not this step's own: it reads e² λ/(λ + φᵀ P φ)).
    fn step(
        &mut self,
        phi: &[f64; N],
        zeta: Option<&[f64; N]>,
        y: f64,
        (given, detect): (Option<f64>, Option<(f64, f64)>),
    ) -> RlsUpdate {
        if !y.is_finite() || phi.iter().any(|x| !x.is_finite()) {
            return RlsUpdate {
                error: f64::NAN,
                change: false,
            };
        }
        let z = zeta.unwrap_or(phi);
        // P ζ, and φᵀ P (the same vector while P is symmetric and ζ = φ).
        let mut pz = [0.0; N];
        for (i, row) in self.p.iter().enumerate() {
            pz[i] = row.iter().zip(z).map(|(a, b)| a * b).sum();
        }
        let php = match zeta {
            None => pz,
            Some(_) => std::array::from_fn(|j| (0..N).map(|i| phi[i] * self.p[i][j]).sum()),
        };
        // Windup guard: no forgetting while P is above its start size.
        let lambda = self.lambda();
        let s = lambda + phi.iter().zip(&pz).map(|(a, b)| a * b).sum::<f64>();
        let error = match given {
            Some(e) => e,
            None => y - dot(phi, &self.theta),
        };
        // Two divisions a step; the rest multiplies.
        let (inv_s, inv_lambda) = (1.0 / s, 1.0 / lambda);
        let gain = error * inv_s;
        for (t, k) in self.theta.iter_mut().zip(&pz) {
            *t += k * gain;
        }
        if zeta.is_none() {
            for i in 0..N {
                let pi = pz[i] * inv_s;
                for (j, pj) in pz.iter().enumerate().skip(i) {
                    let x = (self.p[i][j] - pi * pj) * inv_lambda;
                    self.p[i][j] = x;
                    self.p[j][i] = x;
                }
            }
        } else {
            for (i, row) in self.p.iter_mut().enumerate() {
                let pi = pz[i] * inv_s;
                for (j, x) in row.iter_mut().enumerate() {
                    *x = (*x - pi * php[j]) * inv_lambda;
                }
            }
        }
        self.samples += 1;
        // h with the a-posteriori error ε λ/s (the a-priori one carries the start's
        // transient into Γ_0).
        let after = error * lambda * inv_s;
        self.hac
            .push(&std::array::from_fn(|i| z[i] * after), lambda);
        let normalised = match detect {
            Some((e, q)) => e * e * lambda / (lambda + q),
            None => error * after,
        };
        let change = self.detect(normalised);
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
        self.noise_var =
            d.noise_forgetting * var + (1.0 - d.noise_forgetting) * z.min(d.clip * var);
        // Learning, two more warm-ups, no alarm: the reference σ̄²,
        // the plain mean of z (bursts and all); then the CUSUM on z/σ̄² − 1 − ν, its largest
        // excursion kept for the level. Armed, the CUSUM goes on against σ̄² (held).
        let (reference_known, armed) = (2 * d.warmup, 3 * d.warmup);
        if self.samples <= reference_known {
            self.learned += z;
            if self.samples == reference_known {
                self.reference = self.learned / d.warmup as f64;
            }
            return false;
        }
        let normalised = z / self.reference.max(f64::MIN_POSITIVE);
        self.cusum = (self.cusum + normalised - 1.0 - d.drift).max(0.0);
        if self.samples <= armed {
            self.excursion = self.excursion.max(self.cusum);
            if self.samples == armed {
                self.cusum = 0.0;
            }
            return false;
        }
        // After an alarm the estimate re-converges from P_0: no change for a warm-up.
        if self.samples <= self.quiet_until {
            self.cusum = 0.0;
            return false;
        }
        if self.cusum > self.alarm_level() {
            self.cusum = 0.0;
            self.changes += 1;
            self.quiet_until = self.samples + d.warmup;
            self.hac = LongRun::new();
            for (i, row) in self.p.iter_mut().enumerate() {
                row.fill(0.0);
                row[i] = self.settings.initial_variance;
            }
            return true;
        }
        false
    }

    /// The CUSUM level that raises an alarm: max(h, c × the largest excursion while the
    /// detector learned) ([`ChangeDetection::calibration`]); +∞ without a detector.
    pub fn alarm_level(&self) -> f64 {
        self.settings.detection.map_or(f64::INFINITY, |d| {
            d.threshold.max(d.calibration * self.excursion)
        })
    }

    /// θ̂ (N).
    pub fn theta(&self) -> [f64; N] {
        self.theta
    }

    /// P (N × N): the inverse of the λ-weighted information Σ λ^{t−k} φ_k φ_kᵀ (plus the
    /// decayed prior; Σ λ^{t−k} ζ_k φ_kᵀ with instruments, then not symmetric); σ̂² P is
    /// Cov(θ̂) only for white errors, λ = 1 and no instruments.
    pub fn p(&self) -> [[f64; N]; N] {
        self.p
    }

    /// σ̂²: the noise variance of y (the unit of y, squared); NaN before the first sample.
    pub fn noise_variance(&self) -> f64 {
        self.noise_var
    }

    /// Cov(θ̂) = P M Pᵀ (N × N, the unit of θ squared): robust to coloured equation errors
    /// and exact under forgetting (module docs, "Intervals"; with instruments, h = ζ ε); NaN
    /// before the first sample.
    pub fn covariance(&self) -> [[f64; N]; N] {
        if self.samples == 0 {
            return [[f64::NAN; N]; N];
        }
        let m = self.hac.meat();
        let mut pm = [[0.0; N]; N];
        for (i, row) in pm.iter_mut().enumerate() {
            for (j, x) in row.iter_mut().enumerate() {
                *x = (0..N).map(|k| self.p[i][k] * m[k][j]).sum();
            }
        }
        std::array::from_fn(|i| {
            std::array::from_fn(|j| (0..N).map(|k| pm[i][k] * self.p[j][k]).sum())
        })
    }

    /// Standard errors of θ̂, the square roots of [`Rls::covariance`]'s diagonal (N; NaN
    /// before the first sample).
    pub fn std_err(&self) -> [f64; N] {
        let c = self.covariance();
        std::array::from_fn(|i| c[i][i].max(0.0).sqrt())
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

    /// A steady system whose errors come in bursts (every 200 samples, 10 samples of 20 times
    /// the noise: a model that misses part of each command step's transient, as on a real
    /// robot): the detector, having learned its reference and the bursts' excursion over the
    /// two warm-ups after its own (500 samples each), raises no alarm, where the bare level
    /// h = 60 (c = 0) raises more than 20; a step in θ (the bursts going on) is still caught
    /// within 10 samples, and only once (no cascade while the estimate re-converges).
    #[test]
    fn bursts_of_a_steady_drive_raise_no_alarm_once_calibrated() {
        let run = |calibration: f64| {
            let settings = RlsSettings {
                forgetting: 0.999,
                detection: Some(ChangeDetection {
                    calibration,
                    ..ChangeDetection::default()
                }),
                ..RlsSettings::default()
            };
            let mut rls = Rls::<2>::new(settings, [0.0; 2]).expect("valid");
            let mut u = stream(5);
            let mut alarms = Vec::new();
            for k in 0..20_000 {
                let theta = if k < 15_000 { [1.0, 2.0] } else { [1.5, 2.0] };
                let phi = [u(), 1.0];
                let burst = if k % 200 < 10 { 20.0 } else { 1.0 };
                let y = theta[0] * phi[0] + theta[1] * phi[1] + 0.01 * burst * u();
                if rls.update(&phi, y).change {
                    alarms.push(k);
                }
            }
            (alarms, rls.alarm_level())
        };
        let (fixed, level) = run(0.0);
        assert_eq!(level, 60.0);
        assert!(fixed.len() > 20, "{fixed:?}");
        let (calibrated, level) = run(2.0);
        assert!(level > 60.0, "{level}");
        assert_eq!(calibrated.len(), 1, "{calibrated:?} (level {level})");
        assert!((15_000..15_010).contains(&calibrated[0]), "{calibrated:?}");
    }

    /// Monte Carlo against the intervals: y = θ1 x + θ2 + e with x and e both AR(1) at 0.8, so
    /// h = φ ε is coloured (x e has lag-l correlation 0.64^l: a long-run variance 4.6 times
    /// Γ_0). Over 300 runs the spread of θ̂1 matches its mean standard error within 12 %, with
    /// and without forgetting; the white-noise σ̂² P would put it 2.1× too narrow (λ = 1).
    #[test]
    fn standard_errors_match_the_spread_under_coloured_errors_and_forgetting() {
        for (forgetting, n) in [(1.0, 4000), (0.995, 4000)] {
            let settings = RlsSettings {
                forgetting,
                initial_variance: 1e4,
                detection: None,
            };
            let (mut ests, mut ses, mut white) = (Vec::new(), Vec::new(), Vec::new());
            for seed in 1..=300u64 {
                let mut rls = Rls::<2>::new(settings, [0.0; 2]).expect("valid");
                let mut u = stream(seed * 7919);
                let (mut x, mut e) = (0.0, 0.0);
                for _ in 0..n {
                    x = 0.8 * x + 0.6 * u();
                    e = 0.8 * e + 0.6 * u();
                    rls.update(&[x, 1.0], 0.5 * x - 0.3 + e);
                }
                ests.push(rls.theta()[0]);
                ses.push(rls.std_err()[0]);
                white.push((rls.noise_variance() * rls.p()[0][0]).sqrt());
            }
            let m = ests.iter().sum::<f64>() / 300.0;
            let spread = (ests.iter().map(|t| (t - m).powi(2)).sum::<f64>() / 299.0).sqrt();
            let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
            let ratio = spread / mean(&ses);
            eprintln!(
                "λ = {forgetting}: spread / standard error {ratio:.3}, spread / white σ̂ √P {:.3}",
                spread / mean(&white)
            );
            assert!(
                (ratio - 1.0).abs() < 0.12,
                "λ = {forgetting}: spread {spread:.3e}, standard error {:.3e}",
                mean(&ses)
            );
            if forgetting == 1.0 {
                assert!(spread / mean(&white) > 1.8, "{spread} vs {}", mean(&white));
            }
        }
    }

    /// Errors in variables, closed form: x_{k+1} = 0.9 x_k + 0.5 u_k measured as y = x + n
    /// (n white, σ_n = 0.5, u white in ±1, so σ_x² = 0.25/3/0.19 = 0.44). Least squares on
    /// [y_k, u_k] shrinks â towards 0.9 σ_x²/(σ_x² + σ_n²) = 0.573; instrumental variables with
    /// ζ = [u_{k−1}, u_k] are consistent. Over 200 runs of 3,000 samples: the IV mean within
    /// 2 standard errors of the mean of 0.9, its spread within 15 % of its mean standard error.
    #[test]
    fn instrumental_variables_remove_the_errors_in_variables_bias() {
        let settings = RlsSettings {
            forgetting: 1.0,
            initial_variance: 1e4,
            detection: None,
        };
        let (mut iv, mut ses, mut ls) = (Vec::new(), Vec::new(), Vec::new());
        for seed in 1..=200u64 {
            let mut a = Rls::<2>::new(settings, [0.0; 2]).expect("valid");
            let mut b = Rls::<2>::new(settings, [0.0; 2]).expect("valid");
            let mut r = stream(seed * 104_729);
            let (mut x, mut y_prev, mut u_prev, mut u_prev2) = (0.0, 0.0, 0.0, 0.0);
            for k in 0..3000 {
                let u = r();
                x = 0.9 * x + 0.5 * u_prev;
                let y = x + 0.5 * 3f64.sqrt() * r();
                if k >= 2 {
                    a.update_iv(&[y_prev, u_prev], &[u_prev2, u_prev], y);
                    b.update(&[y_prev, u_prev], y);
                }
                (y_prev, u_prev2, u_prev) = (y, u_prev, u);
            }
            iv.push(a.theta()[0]);
            ses.push(a.std_err()[0]);
            ls.push(b.theta()[0]);
        }
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
        let (m, m_ls, se) = (mean(&iv), mean(&ls), mean(&ses));
        let spread = (iv.iter().map(|t| (t - m).powi(2)).sum::<f64>() / 199.0).sqrt();
        eprintln!(
            "â: IV {m:.4} (spread {spread:.4}, standard error {se:.4}), least squares {m_ls:.4}"
        );
        assert!((m_ls - 0.573).abs() < 0.01, "least squares {m_ls}");
        assert!((m - 0.9).abs() < 2.0 * spread / 200f64.sqrt(), "IV {m}");
        assert!((spread / se - 1.0).abs() < 0.15, "{spread} vs {se}");
    }

    /// The prediction-error step: along ψ = φ with the error y − φᵀθ̂ it is the least-squares
    /// step (θ̂ and P to 1e-12); on an output-error system y_k = x_k + e_k, x_{k+1} = 0.8 x_k +
    /// 0.5 u_k (white e, σ = 0.3), the recursion on the simulated output and its gradient
    /// ψ_{k+1} = â ψ_k + (x̂_k, u_k) finds (0.8, 0.5) within 3 standard errors, where least
    /// squares on the measured y_k (errors in variables) lands more than 10 away.
    #[test]
    fn the_prediction_error_step_fits_an_output_error_system() {
        let settings = RlsSettings {
            forgetting: 1.0,
            initial_variance: 1e3,
            detection: None,
        };
        let (mut u, mut e) = (stream(5), stream(6));
        let (mut ls, mut same) = (
            Rls::<2>::new(settings, [0.0; 2]).expect("ok"),
            Rls::<2>::new(settings, [0.0; 2]).expect("ok"),
        );
        for _ in 0..200 {
            let (phi, y) = ([u(), u()], u());
            ls.update(&phi, y);
            let error = y - dot(&phi, &same.theta());
            same.update_gradient(&phi, error, (&phi, y));
        }
        for i in 0..2 {
            assert!((ls.theta()[i] - same.theta()[i]).abs() < 1e-12);
            for j in 0..2 {
                assert!((ls.p()[i][j] - same.p()[i][j]).abs() < 1e-12);
            }
        }
        let mut pem = Rls::<2>::new(settings, [0.5, 0.0]).expect("ok");
        let mut ls = Rls::<2>::new(settings, [0.0; 2]).expect("ok");
        let (mut x, mut x_hat, mut psi) = (0.0, 0.0, [0.0; 2]);
        let (mut y_last, mut u_last) = (0.0, 0.0);
        for _ in 0..20_000 {
            let uk = u().signum();
            let y = x + 0.3 * 3f64.sqrt() * e();
            ls.update(&[y_last, u_last], y);
            let [a, b] = pem.theta();
            psi = [a * psi[0] + x_hat, a * psi[1] + u_last];
            x_hat = a * x_hat + b * u_last;
            pem.update_gradient(&psi, y - x_hat, (&[y_last, u_last], y));
            (y_last, u_last) = (y, uk);
            x = 0.8 * x + 0.5 * uk;
        }
        let z = |r: &Rls<2>, i: usize| (r.theta()[i] - [0.8, 0.5][i]) / r.std_err()[i];
        for i in 0..2 {
            assert!(
                z(&pem, i).abs() < 3.0,
                "θ{i}: {:?} ({:+.1} s.e.)",
                pem.theta(),
                z(&pem, i)
            );
        }
        assert!(z(&ls, 0).abs() > 10.0, "least squares {:?}", ls.theta());
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
        // A detector learns its reference over its warm-ups: none is no detector (with 0 it
        // raised an alarm from the first sample on).
        assert!(bad(RlsSettings {
            detection: Some(ChangeDetection {
                warmup: 0,
                ..ChangeDetection::default()
            }),
            ..RlsSettings::default()
        }));
        let mut r = Rls::<1>::new(RlsSettings::default(), [0.0]).expect("valid");
        assert!(r.update(&[f64::NAN], 1.0).error.is_nan());
        assert_eq!(r.samples(), 0);
        assert_eq!(r.theta(), [0.0]);
    }
}
