//! Trajectory-tracking control of Laut 2011: the kinematic law of eq. 4.8, the inverse-dynamics
//! controller of eqs. 3.8–3.13 and the adaptive update law of eq. 3.21 with the projection of
//! eq. 4.9.
//!
//! # Kinematic law (eq. 4.8, tracked point on the axle)
//!
//! ```text
//! v_ref^k = v_d cos φ̃ + k1 (x̃ cos φ + ỹ sin φ)
//! ω_ref^k = ω_d + k2 v_d (sin φ̃ / φ̃) (ỹ cos φ − x̃ sin φ) + k3 φ̃
//! x̃ = x_d − x,  ỹ = y_d − y,  φ̃ = φ_d − φ  (wrapped to (−π, π]; sin φ̃/φ̃ → 1 at φ̃ = 0)
//! ```
//!
//! # Inverse dynamics (eqs. 3.8–3.13)
//!
//! ```text
//! v_ref = G θ̂,   G = ⎡σ1  0  −ω²  v  0   0⎤
//!                    ⎣ 0  σ2  0   0  vω  ω⎦
//! σ1 = v̇_ref^k + k_v ṽ,  σ2 = ω̇_ref^k + k_ω ω̃,  ṽ = v_ref^k − v,  ω̃ = ω_ref^k − ω
//! ```
//!
//! With θ̂ = θ the velocity errors obey ṽ̇ = −K ṽ (eq. 3.18 with θ̃ = 0).
//!
//! # Adaptation (eq. 3.21) and projection (eq. 4.9)
//!
//! ```text
//! θ̂̇_i = γ_i g_iᵀ ṽ, except 0 when θ̂_i ≥ θ_i,max and γ_i g_iᵀ ṽ > 0
//!                          or θ̂_i ≤ θ_i,min and γ_i g_iᵀ ṽ < 0
//! ```
//!
//! with g_i the i-th column of G and ṽ = (ṽ, ω̃), from an adaptation start time on, with a
//! diagonal γ (per-parameter gains; γ_i = 0 or listing i in `frozen` holds θ̂_i, as §4.4
//! holds θ̂4, θ̂6). The Lyapunov function V = ½ ṽᵀDṽ + ½ θ̃ᵀγ⁻¹θ̃ (eq. 3.19) then has
//! V̇ = −ṽᵀDKṽ ≤ 0 (eq. 3.22).
//!
//! The controller is a sampled-data one, as on a robot: it runs once per period Δt, v̇_ref^k and
//! ω̇_ref^k are backward differences of the kinematic commands (zero at the first step), and θ̂
//! is integrated by forward Euler and kept inside its bounds.

use serde::{Deserialize, Serialize};
use wheelid_core::{Error, Result};

use crate::trajectory::DesiredState;

/// Gains of the kinematic law (eq. 4.8).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct KinematicLaw {
    /// k1 [1/s]: along-track position gain.
    pub k1: f64,
    /// k2 [1/m²]: cross-track position gain.
    pub k2: f64,
    /// k3 [1/s]: heading gain.
    pub k3: f64,
}

impl Default for KinematicLaw {
    /// k1 = 1 s⁻¹, k2 = 4 m⁻², k3 = 2 s⁻¹ (the thesis does not give its gains).
    fn default() -> Self {
        Self {
            k1: 1.0,
            k2: 4.0,
            k3: 2.0,
        }
    }
}

/// φ wrapped to (−π, π].
pub fn wrap_angle(phi: f64) -> f64 {
    use std::f64::consts::PI;
    let w = (phi + PI).rem_euclid(2.0 * PI) - PI;
    if w <= -PI { w + 2.0 * PI } else { w }
}

/// sin(x)/x with its limit 1 at 0.
#[inline]
fn sinc(x: f64) -> f64 {
    if x.abs() < 1e-6 {
        1.0 - x * x / 6.0
    } else {
        x.sin() / x
    }
}

impl KinematicLaw {
    /// (v_ref^k [m/s], ω_ref^k [rad/s]) of eq. 4.8 for the desired state `d` and the pose
    /// (x \[m\], y \[m\], φ \[rad\]).
    pub fn command(&self, d: &DesiredState, x: f64, y: f64, phi: f64) -> [f64; 2] {
        let (ex, ey) = (d.x - x, d.y - y);
        let ephi = wrap_angle(d.phi - phi);
        let (s, c) = phi.sin_cos();
        [
            d.v * ephi.cos() + self.k1 * (ex * c + ey * s),
            d.w + self.k2 * d.v * sinc(ephi) * (ey * c - ex * s) + self.k3 * ephi,
        ]
    }
}

/// Settings of the inverse-dynamics controller and its adaptation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AdaptiveSettings {
    /// k_v [1/s] (eq. 3.10).
    pub k_v: f64,
    /// k_ω [1/s] (eq. 3.11).
    pub k_w: f64,
    /// Adaptation gains γ1…γ6 (diagonal of γ, eq. 3.21); all zero: no adaptation.
    pub gamma: [f64; 6],
    /// Adaptation starts at this time \[s\].
    pub start_s: f64,
    /// Parameters held fixed, 1-based (e.g. `[4, 6]`, §4.4).
    pub frozen: Vec<usize>,
    /// Lower bounds θ_min of the projection (eq. 4.9); `None`: unbounded.
    pub lower: Option<[f64; 6]>,
    /// Upper bounds θ_max of the projection (eq. 4.9); `None`: unbounded.
    pub upper: Option<[f64; 6]>,
}

impl Default for AdaptiveSettings {
    /// k_v = k_ω = 4 s⁻¹, γ = 0 (no adaptation), start 0, nothing frozen, no bounds.
    fn default() -> Self {
        Self {
            k_v: 4.0,
            k_w: 4.0,
            gamma: [0.0; 6],
            start_s: 0.0,
            frozen: Vec::new(),
            lower: None,
            upper: None,
        }
    }
}

impl AdaptiveSettings {
    /// Checks gains ≥ 0 and finite, frozen indices in 1…6, bounds ordered.
    ///
    /// # Errors
    /// [`Error::InvalidSetting`] naming the field.
    pub fn validate(&self) -> Result<()> {
        let bad = |what: String| Err(Error::InvalidSetting(what));
        for (name, x) in [
            ("k_v", self.k_v),
            ("k_w", self.k_w),
            ("start_s", self.start_s),
        ] {
            if !x.is_finite() || (name != "start_s" && x < 0.0) {
                return bad(format!("adaptation: {name} = {x}"));
            }
        }
        for (i, g) in self.gamma.iter().enumerate() {
            if !(g.is_finite() && *g >= 0.0) {
                return bad(format!("adaptation: gamma{} = {g} must be ≥ 0", i + 1));
            }
        }
        if let Some(i) = self.frozen.iter().find(|&&i| !(1..=6).contains(&i)) {
            return bad(format!("adaptation: frozen parameter {i} is not in 1…6"));
        }
        if let (Some(lo), Some(hi)) = (self.lower, self.upper) {
            for i in 0..6 {
                if lo[i] > hi[i] || lo[i].is_nan() || hi[i].is_nan() {
                    return bad(format!(
                        "adaptation: bounds of theta{}: [{}, {}]",
                        i + 1,
                        lo[i],
                        hi[i]
                    ));
                }
            }
        }
        Ok(())
    }

    /// The effective gains: γ with the frozen parameters zeroed.
    pub fn effective_gamma(&self) -> [f64; 6] {
        let mut g = self.gamma;
        for &i in &self.frozen {
            if (1..=6).contains(&i) {
                g[i - 1] = 0.0;
            }
        }
        g
    }
}

/// The rows of G (eq. 3.12) for σ = (σ1, σ2) and the measured (v, ω).
#[inline]
pub fn regressor_g(sigma: [f64; 2], v: f64, w: f64) -> [[f64; 6]; 2] {
    [
        [sigma[0], 0.0, -w * w, v, 0.0, 0.0],
        [0.0, sigma[1], 0.0, 0.0, v * w, w],
    ]
}

/// The inverse-dynamics controller with adaptive θ̂ (eqs. 3.8–3.13, 3.21, 4.9): the fitted
/// state of a run, built from [`AdaptiveSettings`] and an initial θ̂.
#[derive(Debug, Clone, PartialEq)]
pub struct AdaptiveController {
    settings: AdaptiveSettings,
    gamma: [f64; 6],
    theta_hat: [f64; 6],
    prev_kinematic: Option<[f64; 2]>,
}

impl AdaptiveController {
    /// A controller starting from θ̂ = `theta_hat0`.
    ///
    /// # Errors
    /// [`Error::InvalidSetting`] for invalid settings or a non-finite θ̂.
    pub fn new(settings: AdaptiveSettings, theta_hat0: [f64; 6]) -> Result<Self> {
        settings.validate()?;
        if theta_hat0.iter().any(|x| !x.is_finite()) {
            return Err(Error::InvalidSetting(format!(
                "initial θ̂ {theta_hat0:?} is not finite"
            )));
        }
        Ok(Self {
            gamma: settings.effective_gamma(),
            settings,
            theta_hat: theta_hat0,
            prev_kinematic: None,
        })
    }

    /// The current estimate θ̂.
    pub fn theta_hat(&self) -> [f64; 6] {
        self.theta_hat
    }

    /// Replaces θ̂ — e.g. with an online estimate (`wheelid::online`) after a detected payload
    /// change — clamped into the projection's bounds (eq. 4.9) where they are set. Non-finite
    /// entries (an online estimate not yet mapped to θ) leave their θ̂_i as it is. Returns the
    /// θ̂ now in use.
    pub fn set_theta_hat(&mut self, theta: [f64; 6]) -> [f64; 6] {
        for (i, (th, x)) in self.theta_hat.iter_mut().zip(theta).enumerate() {
            if x.is_finite() {
                let hi = self.settings.upper.map_or(f64::INFINITY, |b| b[i]);
                let lo = self.settings.lower.map_or(f64::NEG_INFINITY, |b| b[i]);
                *th = x.clamp(lo, hi);
            }
        }
        self.theta_hat
    }

    /// One controller step at time `t` \[s\] with period `dt` \[s\]: from the kinematic commands
    /// `kinematic` = (v_ref^k, ω_ref^k) and the measured (v, ω), returns the command
    /// (v_ref [m/s], ω_ref [rad/s]) = G θ̂ and then advances θ̂ by one Euler step of the
    /// projected adaptive law (if `t` ≥ the start time).
    pub fn step(&mut self, t: f64, dt: f64, kinematic: [f64; 2], v: f64, w: f64) -> [f64; 2] {
        let kdot = match self.prev_kinematic {
            Some(p) if dt > 0.0 => [(kinematic[0] - p[0]) / dt, (kinematic[1] - p[1]) / dt],
            _ => [0.0, 0.0],
        };
        self.prev_kinematic = Some(kinematic);
        let err = [kinematic[0] - v, kinematic[1] - w];
        let sigma = [
            kdot[0] + self.settings.k_v * err[0],
            kdot[1] + self.settings.k_w * err[1],
        ];
        let g = regressor_g(sigma, v, w);
        let th = &self.theta_hat;
        let u = [0, 1].map(|r| (0..6).map(|i| g[r][i] * th[i]).sum::<f64>());
        if t >= self.settings.start_s {
            for i in 0..6 {
                if self.gamma[i] == 0.0 {
                    continue;
                }
                let rate = self.gamma[i] * (g[0][i] * err[0] + g[1][i] * err[1]);
                let hi = self.settings.upper.map_or(f64::INFINITY, |b| b[i]);
                let lo = self.settings.lower.map_or(f64::NEG_INFINITY, |b| b[i]);
                let th = &mut self.theta_hat[i];
                if (*th >= hi && rate > 0.0) || (*th <= lo && rate < 0.0) {
                    continue;
                }
                *th = (*th + dt * rate).clamp(lo, hi);
            }
        }
        u
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    fn desired(x: f64, y: f64, phi: f64, v: f64, w: f64) -> DesiredState {
        DesiredState {
            x,
            y,
            phi,
            v,
            w,
            alpha: 0.0,
            vx: v * phi.cos(),
            vy: v * phi.sin(),
        }
    }

    #[test]
    fn kinematic_law_matches_eq_4_8_by_hand() {
        let law = KinematicLaw {
            k1: 1.5,
            k2: 3.0,
            k3: 0.7,
        };
        let d = desired(1.0, 2.0, 0.5, 0.4, 0.2);
        let (x, y, phi) = (0.8, 2.3, 0.3);
        let [vk, wk] = law.command(&d, x, y, phi);
        let (ex, ey, ep) = (0.2_f64, -0.3_f64, 0.2_f64);
        let v_exp = 0.4 * ep.cos() + 1.5 * (ex * phi.cos() + ey * phi.sin());
        let w_exp =
            0.2 + 3.0 * 0.4 * (ep.sin() / ep) * (ey * phi.cos() - ex * phi.sin()) + 0.7 * ep;
        assert_relative_eq!(vk, v_exp, epsilon = 1e-14);
        assert_relative_eq!(wk, w_exp, epsilon = 1e-14);
        // On the trajectory: the feed-forward alone (sin φ̃/φ̃ → 1, no 0/0).
        let [vk, wk] = law.command(&d, 1.0, 2.0, 0.5);
        assert_eq!([vk, wk], [0.4, 0.2]);
        // The heading error is wrapped: φ_d = π − 0.1, φ = −π + 0.1 is 0.2 rad apart.
        let d = desired(0.0, 0.0, std::f64::consts::PI - 0.1, 0.0, 0.0);
        let [_, wk] = law.command(&d, 0.0, 0.0, -std::f64::consts::PI + 0.1);
        assert_relative_eq!(wk, 0.7 * -0.2, epsilon = 1e-12);
    }

    #[test]
    fn inverse_dynamics_with_true_theta_is_eq_3_8() {
        let th = [0.2604, 0.2509, -0.0004, 0.9965, 0.0026, 1.0768];
        let mut c = AdaptiveController::new(AdaptiveSettings::default(), th).expect("valid");
        // First step: no derivative yet, σ = K ṽ.
        let (v, w) = (0.3, -0.5);
        let u = c.step(0.0, 0.1, [0.4, -0.2], v, w);
        let s1 = 4.0 * (0.4 - v);
        let s2 = 4.0 * (-0.2 - w);
        assert_relative_eq!(
            u[0],
            th[0] * s1 - th[2] * w * w + th[3] * v,
            epsilon = 1e-14
        );
        assert_relative_eq!(
            u[1],
            th[1] * s2 + th[4] * v * w + th[5] * w,
            epsilon = 1e-14
        );
        // Second step: σ gains the backward difference of the kinematic commands.
        let u = c.step(0.1, 0.1, [0.5, -0.2], v, w);
        let s1 = (0.5 - 0.4) / 0.1 + 4.0 * (0.5 - v);
        assert_relative_eq!(
            u[0],
            th[0] * s1 - th[2] * w * w + th[3] * v,
            epsilon = 1e-12
        );
        assert_eq!(c.theta_hat(), th, "γ = 0 keeps θ̂");
    }

    #[test]
    fn adaptive_law_is_eq_3_21_with_projection_4_9_and_freezing() {
        let settings = AdaptiveSettings {
            k_v: 2.0,
            k_w: 3.0,
            gamma: [1.0, 2.0, 3.0, 4.0, 5.0, 6.0],
            frozen: vec![4, 6],
            upper: Some([10.0, 10.0, 10.0, 10.0, 0.5, 10.0]),
            lower: Some([-10.0; 6]),
            ..AdaptiveSettings::default()
        };
        let th0 = [0.3, 0.3, 0.0, 1.0, 0.5, 1.0];
        let mut c = AdaptiveController::new(settings, th0).expect("valid");
        let (v, w, dt) = (0.2, 0.4, 0.01);
        let err = [0.5 - v, 0.6 - w];
        let sigma = [2.0 * err[0], 3.0 * err[1]];
        c.step(0.0, dt, [0.5, 0.6], v, w);
        let g = regressor_g(sigma, v, w);
        let th = c.theta_hat();
        for (i, gi) in [1.0, 2.0, 3.0].iter().enumerate() {
            let rate = gi * (g[0][i] * err[0] + g[1][i] * err[1]);
            assert_relative_eq!(th[i], th0[i] + dt * rate, epsilon = 1e-14);
        }
        assert_eq!(th[3], 1.0, "θ4 frozen");
        assert_eq!(th[5], 1.0, "θ6 frozen");
        // θ5 sits at its upper bound and its update (5·vω·ω̃ > 0) points outward: held.
        assert!(g[1][4] * err[1] > 0.0);
        assert_eq!(th[4], 0.5);
    }

    #[test]
    fn a_set_theta_hat_is_projected_and_skips_nan() {
        let settings = AdaptiveSettings {
            upper: Some([1.0; 6]),
            lower: Some([0.1; 6]),
            ..AdaptiveSettings::default()
        };
        let mut c = AdaptiveController::new(settings, [0.3; 6]).expect("valid");
        let th = c.set_theta_hat([0.5, 2.0, 0.0, f64::NAN, 0.2, 1.0]);
        assert_eq!(th, [0.5, 1.0, 0.1, 0.3, 0.2, 1.0]);
        assert_eq!(c.theta_hat(), th);
    }

    #[test]
    fn adaptation_waits_for_its_start_time() {
        let settings = AdaptiveSettings {
            gamma: [1.0; 6],
            start_s: 5.0,
            ..AdaptiveSettings::default()
        };
        let th0 = [0.3; 6];
        let mut c = AdaptiveController::new(settings, th0).expect("valid");
        c.step(4.9, 0.1, [0.5, 0.6], 0.1, 0.1);
        assert_eq!(c.theta_hat(), th0);
        c.step(5.0, 0.1, [0.5, 0.6], 0.1, 0.1);
        assert_ne!(c.theta_hat(), th0);
    }

    #[test]
    fn invalid_settings_are_errors() {
        let s = AdaptiveSettings {
            frozen: vec![7],
            ..AdaptiveSettings::default()
        };
        assert!(AdaptiveController::new(s, [1.0; 6]).is_err());
        let s = AdaptiveSettings {
            gamma: [-1.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            ..AdaptiveSettings::default()
        };
        assert!(AdaptiveController::new(s, [1.0; 6]).is_err());
    }

    #[test]
    fn wrap_angle_is_in_range() {
        use std::f64::consts::PI;
        assert_relative_eq!(wrap_angle(3.0 * PI), PI, epsilon = 1e-12);
        assert_relative_eq!(wrap_angle(-PI), PI, epsilon = 1e-12);
        assert_relative_eq!(wrap_angle(0.1 - 4.0 * PI), 0.1, epsilon = 1e-12);
    }
}
