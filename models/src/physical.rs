//! What θ means physically: the maps from a robot's physical constants to θ1…θ6 for the two
//! low-level controller structures of Laut 2011, re-derived, and θ bounds from intervals on the
//! constants (the thesis's "parameter projection", §4.1).
//!
//! # Derivation (no slip, no external forces)
//! Forward and yaw balance (eq. 2.6, with lateral velocity v̄ = b·ω, eq. A.36):
//! ```text
//! m (v̇ − b ω²)          = F_r + F_l
//! (I_z + m b²) ω̇ + m b v ω = (d/2)(F_r − F_l)
//! ```
//! Wheel/motor (eq. 2.9–2.10), with ω_{r,l} = (v ± d ω/2)/r:
//! `F_i = [ (k_a/R_a)(u_i − k_b ω_i) − I_e ω̇_i − B_e ω_i ] / R_t`.
//!
//! **wheel-PD** (§2.2): u_i = k_P (ω_i,ref − ω_i) − k_D ω̇_i, with wheel references from
//! (v_ref, ω_ref) by the same kinematics. Dividing the forward balance by 2 k_a k_P/(r R_a) and the
//! yaw balance by d² k_a k_P/(2 r R_a R_t) gives eq. 2.19 with
//! ```text
//! θ1 = (R_a R_t r m + 2 k_a k_D + 2 I_e R_a) / (2 k_a k_P)
//! θ2 = (k_a k_D d² + I_e R_a d² + 2 R_a R_t r (m b² + I_z)) / (k_a k_P d²)
//! θ3 = R_a R_t r m b / (2 k_a k_P)
//! θ4 = (k_a (k_P + k_b) + R_a B_e) / (k_a k_P)
//! θ5 = 2 R_a R_t r m b / (k_a k_P d²)
//! θ6 = (k_a (k_P + k_b) + R_a B_e) / (k_a k_P)          (= θ4)
//! ```
//! Typos in the thesis's §2.2 list, corrected here (each checked by units and by the numerical
//! test below): θ1 lacks the factor r on R_a R_t m (units would be s/m, not s); θ3 lacks b (the
//! ω² term comes from the lateral velocity b·ω, and A.3's θ3 has it); θ4 reads
//! (k_a(k_P+k_b) + 2R_aB_e)/(2k_ak_P), which would make θ4 ≈ ½ instead of ≈ 1 as §4.1 expects;
//! θ6 has R_a R_t where k_a belongs. Eq. 2.11 also prints +k_D ω̇; the PD on the error
//! ω_ref − ω with the reference's derivative neglected gives −k_D ω̇, which eq. 2.15 then uses.
//!
//! **vw-PD** (Appendix A.3, Pioneer 3-DX): (u_r + u_l)/2 = K_PT (v_ref − v) − K_DT v̇ and
//! (u_r − u_l)/2 = K_PR (ω_ref − ω) − K_DR ω̇ (eq. A.29–A.31). Then
//! ```text
//! θ1 = [ (R_a/k_a)(m R_t r + 2 I_e) + 2 r K_DT ] / (2 r K_PT)
//! θ2 = [ (R_a/k_a)(I_e d² + 2 R_t r (I_z + m b²)) + 2 r d K_DR ] / (2 r d K_PR)
//! θ3 = (R_a/k_a) m b R_t / (2 K_PT)
//! θ4 = (R_a/k_a)(k_a k_b/R_a + B_e) / (r K_PT) + 1
//! θ5 = (R_a/k_a) m b R_t / (d K_PR)
//! θ6 = (R_a/k_a)(k_a k_b/R_a + B_e) d / (2 r K_PR) + 1
//! ```
//! The thesis prints θ1 = (R_a/k_a)/(2 r k_PT), dropping the factor (m R_t r + 2 I_e) and the
//! derivative-gain term 2 r K_DT; the form above is the re-derivation, and agrees with Martins
//! et al.'s published model. The other five agree with the thesis.
//!
//! # Bounds from intervals
//! Each θ is, in each constant separately, monotone on any interval (of the forms αx + β,
//! α/x + β, (αx + β)/(γx)) except θ2 in b (α b² + β). The exact range over a box of constants
//! is therefore attained at its vertices, with b = 0 added as a candidate when b's interval
//! contains 0; [`Parameterization::theta_bounds`] enumerates those candidates.

use serde::{Deserialize, Serialize};
use wheelid_core::{Error, Result};

/// A controller structure whose θ has a physical meaning.
pub trait Parameterization {
    /// The physical constants, in SI units.
    type Constants: Clone + std::fmt::Debug + Serialize + for<'de> Deserialize<'de>;

    /// θ1…θ6 from the constants.
    fn theta(c: &Self::Constants) -> [f64; 6];

    /// The constants as a flat array (field order), and back.
    fn to_vec(c: &Self::Constants) -> Vec<f64>;

    /// Inverse of [`Parameterization::to_vec`].
    fn from_vec(x: &[f64]) -> Self::Constants;

    /// Index of the centre-of-mass offset b in [`Parameterization::to_vec`].
    const B_INDEX: usize;

    /// Exact bounds (lower, upper) on each θ when each constant lies in [lo, hi].
    ///
    /// # Errors
    /// [`Error::InvalidSetting`] if some lo > hi, a value is not finite, or a bound would divide
    /// by zero (a gain or k_a interval containing 0).
    fn theta_bounds(lo: &Self::Constants, hi: &Self::Constants) -> Result<[(f64, f64); 6]> {
        let (l, h) = (Self::to_vec(lo), Self::to_vec(hi));
        let mut cands: Vec<Vec<f64>> = Vec::with_capacity(l.len());
        for (i, (&a, &b)) in l.iter().zip(&h).enumerate() {
            if !(a.is_finite() && b.is_finite()) || a > b {
                return Err(Error::InvalidSetting(format!(
                    "physical interval {i} is [{a}, {b}]: need finite lo ≤ hi"
                )));
            }
            let mut c = vec![a];
            if b > a {
                c.push(b);
            }
            if i == Self::B_INDEX && a < 0.0 && b > 0.0 {
                c.push(0.0);
            }
            cands.push(c);
        }
        let mut out = [(f64::INFINITY, f64::NEG_INFINITY); 6];
        let mut idx = vec![0usize; cands.len()];
        loop {
            let x: Vec<f64> = idx.iter().zip(&cands).map(|(&i, c)| c[i]).collect();
            let th = Self::theta(&Self::from_vec(&x));
            for (o, t) in out.iter_mut().zip(th) {
                if !t.is_finite() {
                    return Err(Error::InvalidSetting(format!(
                        "θ is not finite at constants {x:?} (a gain or k_a interval touches 0?)"
                    )));
                }
                o.0 = o.0.min(t);
                o.1 = o.1.max(t);
            }
            // Odometer increment over the candidate sets.
            let mut k = 0;
            loop {
                if k == idx.len() {
                    return Ok(out);
                }
                idx[k] += 1;
                if idx[k] < cands[k].len() {
                    break;
                }
                idx[k] = 0;
                k += 1;
            }
        }
    }
}

macro_rules! constants {
    ($(#[$m:meta])* $name:ident { $($(#[$fm:meta])* $f:ident),* $(,)? }) => {
        $(#[$m])*
        #[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
        #[serde(deny_unknown_fields)]
        pub struct $name { $($(#[$fm])* pub $f: f64,)* }
        impl $name {
            fn to_vec(self) -> Vec<f64> { vec![$(self.$f),*] }
            fn from_vec(x: &[f64]) -> Self {
                let mut it = x.iter().copied();
                Self { $($f: it.next().unwrap_or(f64::NAN),)* }
            }
        }
    };
}

constants!(
    /// Physical constants of a robot with PD control on each wheel's angular velocity
    /// (Laut 2011 §2.2, Khepera III). SI units.
    WheelPdConstants {
        /// Mass m \[kg\].
        m,
        /// Moment of inertia about the vertical axis through G, I_z [kg·m²].
        i_z,
        /// Distance from the wheel axle to the centre of mass G, b \[m\] (signed, forward positive).
        b,
        /// Wheel radius r \[m\] (kinematics).
        r,
        /// Track width, distance between the driving wheels, d \[m\].
        d,
        /// Tyre radius R_t \[m\] (force arm; usually = r).
        r_t,
        /// Armature resistance R_a \[Ω\].
        r_a,
        /// Torque constant × gear ratio, k_a [N·m/A].
        k_a,
        /// Back-EMF constant × gear ratio, k_b [V·s/rad].
        k_b,
        /// Inertia of motor, gearbox and wheel, I_e [kg·m²].
        i_e,
        /// Viscous friction of motor, gearbox and wheel, B_e [N·m·s/rad].
        b_e,
        /// Wheel PD proportional gain k_P [V·s/rad].
        k_p,
        /// Wheel PD derivative gain k_D [V·s²/rad].
        k_d,
    }
);

constants!(
    /// Physical constants of a robot with PD control on forward and angular velocity
    /// (Laut 2011 Appendix A.3, Pioneer 3-DX). SI units.
    VwPdConstants {
        /// Mass m \[kg\].
        m,
        /// Moment of inertia about the vertical axis through G, I_z [kg·m²].
        i_z,
        /// Distance from the wheel axle to the centre of mass G, b \[m\] (signed, forward positive).
        b,
        /// Wheel radius r \[m\].
        r,
        /// Track width d \[m\].
        d,
        /// Tyre radius R_t \[m\].
        r_t,
        /// Armature resistance R_a \[Ω\].
        r_a,
        /// Torque constant × gear ratio, k_a [N·m/A].
        k_a,
        /// Back-EMF constant × gear ratio, k_b [V·s/rad].
        k_b,
        /// Inertia of motor, gearbox and wheel, I_e [kg·m²].
        i_e,
        /// Viscous friction of motor, gearbox and wheel, B_e [N·m·s/rad].
        b_e,
        /// Forward-velocity PD proportional gain K_PT [V·s/m].
        k_pt,
        /// Forward-velocity PD derivative gain K_DT [V·s²/m].
        k_dt,
        /// Angular-velocity PD proportional gain K_PR [V·s/rad].
        k_pr,
        /// Angular-velocity PD derivative gain K_DR [V·s²/rad].
        k_dr,
    }
);

/// The wheel-PD parameterization (§2.2, corrected as in the module docs).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct WheelPdMap;

impl Parameterization for WheelPdMap {
    type Constants = WheelPdConstants;
    const B_INDEX: usize = 2;

    fn theta(c: &WheelPdConstants) -> [f64; 6] {
        let WheelPdConstants {
            m,
            i_z,
            b,
            r,
            d,
            r_t,
            r_a,
            k_a,
            k_b,
            i_e,
            b_e,
            k_p,
            k_d,
        } = *c;
        let damp = (k_a * (k_p + k_b) + r_a * b_e) / (k_a * k_p);
        [
            (r_a * r_t * r * m + 2.0 * k_a * k_d + 2.0 * i_e * r_a) / (2.0 * k_a * k_p),
            (k_a * k_d * d * d + i_e * r_a * d * d + 2.0 * r_a * r_t * r * (m * b * b + i_z))
                / (k_a * k_p * d * d),
            r_a * r_t * r * m * b / (2.0 * k_a * k_p),
            damp,
            2.0 * r_a * r_t * r * m * b / (k_a * k_p * d * d),
            damp,
        ]
    }
    fn to_vec(c: &WheelPdConstants) -> Vec<f64> {
        c.to_vec()
    }
    fn from_vec(x: &[f64]) -> WheelPdConstants {
        WheelPdConstants::from_vec(x)
    }
}

/// The v/ω-PD parameterization (Appendix A.3, θ1 corrected as in the module docs).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct VwPdMap;

impl Parameterization for VwPdMap {
    type Constants = VwPdConstants;
    const B_INDEX: usize = 2;

    fn theta(c: &VwPdConstants) -> [f64; 6] {
        let VwPdConstants {
            m,
            i_z,
            b,
            r,
            d,
            r_t,
            r_a,
            k_a,
            k_b,
            i_e,
            b_e,
            k_pt,
            k_dt,
            k_pr,
            k_dr,
        } = *c;
        let ra_ka = r_a / k_a;
        let fric = ra_ka * (k_a * k_b / r_a + b_e);
        [
            (ra_ka * (m * r_t * r + 2.0 * i_e) + 2.0 * r * k_dt) / (2.0 * r * k_pt),
            (ra_ka * (i_e * d * d + 2.0 * r_t * r * (i_z + m * b * b)) + 2.0 * r * d * k_dr)
                / (2.0 * r * d * k_pr),
            ra_ka * m * b * r_t / (2.0 * k_pt),
            fric / (r * k_pt) + 1.0,
            ra_ka * m * b * r_t / (d * k_pr),
            fric * d / (2.0 * r * k_pr) + 1.0,
        ]
    }
    fn to_vec(c: &VwPdConstants) -> Vec<f64> {
        c.to_vec()
    }
    fn from_vec(x: &[f64]) -> VwPdConstants {
        VwPdConstants::from_vec(x)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    /// Accelerations (v̇, ω̇) from the *unreduced* physics: force and moment balances, motors,
    /// wheels and the PD law, solved as a 2×2 linear system in (v̇, ω̇). `pd` returns the two
    /// wheel voltages (u_r, u_l) given (v, ω, v̇, ω̇).
    #[allow(clippy::too_many_arguments)]
    fn physics_accel(
        m: f64,
        i_z: f64,
        b: f64,
        r: f64,
        d: f64,
        r_t: f64,
        r_a: f64,
        k_a: f64,
        k_b: f64,
        i_e: f64,
        b_e: f64,
        v: f64,
        w: f64,
        pd: &dyn Fn(f64, f64) -> (f64, f64),
    ) -> (f64, f64) {
        // residuals of the two balances at trial accelerations (dv, dw): linear in them.
        let res = |dv: f64, dw: f64| {
            let (wr, wl) = ((v + d * w / 2.0) / r, (v - d * w / 2.0) / r);
            let (dwr, dwl) = ((dv + d * dw / 2.0) / r, (dv - d * dw / 2.0) / r);
            let (ur, ul) = pd(dv, dw);
            let f = |u: f64, om: f64, dom: f64| {
                ((k_a / r_a) * (u - k_b * om) - i_e * dom - b_e * om) / r_t
            };
            let (fr, fl) = (f(ur, wr, dwr), f(ul, wl, dwl));
            (
                m * (dv - b * w * w) - (fr + fl),
                (i_z + m * b * b) * dw + m * b * v * w - d / 2.0 * (fr - fl),
            )
        };
        let r0 = res(0.0, 0.0);
        let r1 = res(1.0, 0.0);
        let r2 = res(0.0, 1.0);
        let (a11, a21, a12, a22) = (r1.0 - r0.0, r1.1 - r0.1, r2.0 - r0.0, r2.1 - r0.1);
        let det = a11 * a22 - a12 * a21;
        (
            (-r0.0 * a22 + a12 * r0.1) / det,
            (-a11 * r0.1 + a21 * r0.0) / det,
        )
    }

    fn model_accel(th: [f64; 6], v: f64, w: f64, vr: f64, wr: f64) -> (f64, f64) {
        crate::dynamics::accel(&th, v, w, vr, wr)
    }

    #[test]
    fn wheel_pd_theta_reproduces_the_unreduced_physics() {
        let c = WheelPdConstants {
            m: 0.69,
            i_z: 0.0012,
            b: 0.012,
            r: 0.0205,
            d: 0.0885,
            r_t: 0.021,
            r_a: 4.6,
            k_a: 0.06,
            k_b: 0.05,
            i_e: 2e-5,
            b_e: 1e-4,
            k_p: 3.0,
            k_d: 0.05,
        };
        let th = WheelPdMap::theta(&c);
        for &(v, w, vr, wr) in &[
            (0.1, 1.5, 0.12, 1.2),
            (-0.2, -0.7, 0.3, 2.0),
            (0.05, 3.0, 0.0, -1.0),
        ] {
            let pd = |dv: f64, dw: f64| {
                let (wrr, wlr) = ((vr + c.d * wr / 2.0) / c.r, (vr - c.d * wr / 2.0) / c.r);
                let (om_r, om_l) = ((v + c.d * w / 2.0) / c.r, (v - c.d * w / 2.0) / c.r);
                let (dr, dl) = ((dv + c.d * dw / 2.0) / c.r, (dv - c.d * dw / 2.0) / c.r);
                (
                    c.k_p * (wrr - om_r) - c.k_d * dr,
                    c.k_p * (wlr - om_l) - c.k_d * dl,
                )
            };
            let want = physics_accel(
                c.m, c.i_z, c.b, c.r, c.d, c.r_t, c.r_a, c.k_a, c.k_b, c.i_e, c.b_e, v, w, &pd,
            );
            let got = model_accel(th, v, w, vr, wr);
            assert_relative_eq!(got.0, want.0, max_relative = 1e-9);
            assert_relative_eq!(got.1, want.1, max_relative = 1e-9);
        }
    }

    #[test]
    fn vw_pd_theta_reproduces_the_unreduced_physics() {
        let c = VwPdConstants {
            m: 9.0,
            i_z: 0.16,
            b: 0.03,
            r: 0.0975,
            d: 0.381,
            r_t: 0.0975,
            r_a: 0.71,
            k_a: 0.6,
            k_b: 0.6,
            i_e: 0.005,
            b_e: 0.02,
            k_pt: 40.0,
            k_dt: 1.5,
            k_pr: 30.0,
            k_dr: 0.8,
        };
        let th = VwPdMap::theta(&c);
        for &(v, w, vr, wr) in &[
            (0.4, 0.75, 0.5, 0.6),
            (-0.3, -1.2, 0.0, 1.0),
            (1.0, 0.1, 0.9, -0.5),
        ] {
            let pd = |dv: f64, dw: f64| {
                let uv = c.k_pt * (vr - v) - c.k_dt * dv;
                let uw = c.k_pr * (wr - w) - c.k_dr * dw;
                (uv + uw, uv - uw)
            };
            let want = physics_accel(
                c.m, c.i_z, c.b, c.r, c.d, c.r_t, c.r_a, c.k_a, c.k_b, c.i_e, c.b_e, v, w, &pd,
            );
            let got = model_accel(th, v, w, vr, wr);
            assert_relative_eq!(got.0, want.0, max_relative = 1e-9);
            assert_relative_eq!(got.1, want.1, max_relative = 1e-9);
        }
    }

    #[test]
    fn vw_pd_theta_against_hand_computation() {
        // Round numbers: R_a = 2, k_a = 1 (R_a/k_a = 2), m = 10, R_t = r = 0.1, I_e = 0.01, d = 0.4, b = 0.05,
        // I_z = 0.2, k_b = 0.5 (so k_a k_b/R_a = 0.25), B_e = 0.05, K_PT = 5, K_DT = 0.1,
        // K_PR = 4, K_DR = 0.2.
        // θ1 = [2(10·0.1·0.1 + 0.02) + 2·0.1·0.1] / (2·0.1·5) = (0.24 + 0.02)/1 = 0.26
        // θ2 = [2(0.01·0.16 + 2·0.1·0.1·(0.2 + 10·0.0025)) + 2·0.1·0.4·0.2] / (2·0.1·0.4·4)
        //    = [2(0.0016 + 0.0045) + 0.016] / 0.32 = 0.0282 / 0.32 = 0.088125
        // θ3 = 2·10·0.05·0.1 / (2·5) = 0.01
        // θ4 = 2(0.25 + 0.05)/(0.1·5) + 1 = 0.6/0.5 + 1 = 2.2
        // θ5 = 2·10·0.05·0.1 / (0.4·4) = 0.1/1.6 = 0.0625
        // θ6 = 2(0.3)·0.4/(2·0.1·4) + 1 = 0.24/0.8 + 1 = 1.3
        let c = VwPdConstants {
            m: 10.0,
            i_z: 0.2,
            b: 0.05,
            r: 0.1,
            d: 0.4,
            r_t: 0.1,
            r_a: 2.0,
            k_a: 1.0,
            k_b: 0.5,
            i_e: 0.01,
            b_e: 0.05,
            k_pt: 5.0,
            k_dt: 0.1,
            k_pr: 4.0,
            k_dr: 0.2,
        };
        let th = VwPdMap::theta(&c);
        let want = [0.26, 0.088125, 0.01, 2.2, 0.0625, 1.3];
        for (g, w) in th.iter().zip(want) {
            assert_relative_eq!(*g, w, max_relative = 1e-12);
        }
    }

    #[test]
    fn wheel_pd_theta_against_hand_computation() {
        // R_a = 2, k_a = 1, R_t = r = 0.1, m = 10, I_e = 0.01, k_P = 5, k_D = 0.1, k_b = 0.5,
        // B_e = 0.05, d = 0.4, b = 0.05, I_z = 0.2.
        // θ1 = (2·0.1·0.1·10 + 2·1·0.1 + 2·0.01·2)/(2·1·5) = (0.2 + 0.2 + 0.04)/10 = 0.044
        // θ2 = (1·0.1·0.16 + 0.01·2·0.16 + 2·2·0.1·0.1·(10·0.0025 + 0.2))/(1·5·0.16)
        //    = (0.016 + 0.0032 + 0.009)/0.8 = 0.03525
        // θ3 = 2·0.1·0.1·10·0.05/(2·5) = 0.001
        // θ4 = θ6 = (1·5.5 + 2·0.05)/5 = 1.12
        // θ5 = 2·2·0.1·0.1·10·0.05/(1·5·0.16) = 0.02/0.8 = 0.025
        let c = WheelPdConstants {
            m: 10.0,
            i_z: 0.2,
            b: 0.05,
            r: 0.1,
            d: 0.4,
            r_t: 0.1,
            r_a: 2.0,
            k_a: 1.0,
            k_b: 0.5,
            i_e: 0.01,
            b_e: 0.05,
            k_p: 5.0,
            k_d: 0.1,
        };
        let th = WheelPdMap::theta(&c);
        for (g, w) in th.iter().zip([0.044, 0.03525, 0.001, 1.12, 0.025, 1.12]) {
            assert_relative_eq!(*g, w, max_relative = 1e-12);
        }
    }

    #[test]
    fn bounds_enclose_every_sample_and_are_attained() {
        let lo = VwPdConstants {
            m: 8.0,
            i_z: 0.1,
            b: -0.02,
            r: 0.095,
            d: 0.37,
            r_t: 0.095,
            r_a: 0.6,
            k_a: 0.5,
            k_b: 0.5,
            i_e: 0.004,
            b_e: 0.01,
            k_pt: 35.0,
            k_dt: 1.0,
            k_pr: 25.0,
            k_dr: 0.5,
        };
        let hi = VwPdConstants {
            m: 9.0,
            i_z: 0.2,
            b: 0.04,
            r: 0.1,
            d: 0.39,
            r_t: 0.1,
            r_a: 0.8,
            k_a: 0.7,
            k_b: 0.7,
            i_e: 0.006,
            b_e: 0.03,
            k_pt: 45.0,
            k_dt: 2.0,
            k_pr: 35.0,
            k_dr: 1.0,
        };
        let bounds = VwPdMap::theta_bounds(&lo, &hi).expect("bounds");
        // θ2's lower bound uses b = 0 (inside [−0.02, 0.04]); θ3 and θ5 change sign with b.
        assert!(bounds[2].0 < 0.0 && bounds[2].1 > 0.0);
        let (l, h) = (VwPdMap::to_vec(&lo), VwPdMap::to_vec(&hi));
        let mut seed = 12345u64;
        for _ in 0..2000 {
            let x: Vec<f64> = l
                .iter()
                .zip(&h)
                .map(|(a, b)| {
                    seed = seed
                        .wrapping_mul(6364136223846793005)
                        .wrapping_add(1442695040888963407);
                    a + (b - a) * ((seed >> 11) as f64 / (1u64 << 53) as f64)
                })
                .collect();
            let th = VwPdMap::theta(&VwPdMap::from_vec(&x));
            for (t, (lb, ub)) in th.iter().zip(bounds) {
                assert!(*t >= lb - 1e-15 && *t <= ub + 1e-15);
            }
        }
        let bad = VwPdConstants { m: 10.0, ..lo };
        assert!(VwPdMap::theta_bounds(&bad, &hi).is_err());
    }
}
