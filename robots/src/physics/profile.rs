//! Physical profiles: a robot described by its physical constants only (no θ).
//!
//! The constants are those of `wheelid_models::physical` (Laut 2011 §2.2 and Appendix A.3) —
//! total mass m, yaw inertia I_z about the centre of mass G, G's offset b ahead of the axle,
//! wheel radius r, track d, per-wheel motor (k_a, k_b, R_a, viscous B_e, spin inertia I_e of
//! motor, gearbox and wheel) and the onboard controller's gains — plus what the engine and the
//! host need: wheel mass, caster, encoder ticks, host period, physics step. The map of
//! `wheelid_models::physical` gives the θ these constants imply ([`PhysicalProfile::theta`]);
//! the physics backend never uses it.

use serde::{Deserialize, Serialize};
use wheelid_core::{Error, Result};
use wheelid_models::physical::{
    Parameterization, VwPdConstants, VwPdMap, WheelPdConstants, WheelPdMap,
};

/// The onboard velocity controller and its gains (SI units).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "kebab-case", deny_unknown_fields)]
pub enum Controller {
    /// PD on each wheel's angular velocity (§2.2, Khepera III):
    /// u_i = k_P (ω_i,ref − ω_i) − k_D ω̇_i.
    WheelPd {
        /// k_P [V·s/rad].
        k_p: f64,
        /// k_D [V·s²/rad].
        k_d: f64,
    },
    /// PD on v and ω (Appendix A.3, Pioneer 3-DX): (u_r + u_l)/2 = K_PT (v_ref − v) − K_DT v̇,
    /// (u_r − u_l)/2 = K_PR (ω_ref − ω) − K_DR ω̇.
    VwPd {
        /// K_PT [V·s/m].
        k_pt: f64,
        /// K_DT [V·s²/m].
        k_dt: f64,
        /// K_PR [V·s/rad].
        k_pr: f64,
        /// K_DR [V·s²/rad].
        k_dr: f64,
    },
}

/// A differential-drive robot as the physics backend builds it. SI units throughout.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PhysicalProfile {
    /// Name, e.g. `khepera3`.
    pub name: String,
    /// Total mass m \[kg\] (chassis and wheels).
    pub m: f64,
    /// Total yaw inertia I_z about the centre of mass G [kg·m²].
    pub i_z: f64,
    /// Offset b of G ahead of the wheel axle \[m\] (non-zero: the caster sits on G's side).
    pub b: f64,
    /// Wheel radius r \[m\] (also the tyre radius R_t: the wheel is a rigid sphere in contact).
    pub r: f64,
    /// Track d \[m\].
    pub d: f64,
    /// Mass of one wheel \[kg\] (part of m).
    pub wheel_mass: f64,
    /// Spin inertia of motor, gearbox and wheel reflected to the wheel, I_e [kg·m²].
    pub i_e: f64,
    /// Torque constant × gear ratio k_a [N·m/A].
    pub k_a: f64,
    /// Back-EMF constant × gear ratio k_b [V·s/rad].
    pub k_b: f64,
    /// Armature resistance R_a \[Ω\].
    pub r_a: f64,
    /// Viscous friction of motor, gearbox and wheel B_e [N·m·s/rad].
    pub b_e: f64,
    /// The onboard controller.
    pub controller: Controller,
    /// Distance of the caster ahead of the axle \[m\] (on G's side of the axle).
    pub caster_x: f64,
    /// Caster ball radius \[m\].
    pub caster_radius: f64,
    /// Encoder ticks per wheel revolution.
    pub ticks_per_rev: f64,
    /// Host sample period Δ \[s\].
    pub period_s: f64,
    /// Physics step \[s\], ≤ 1 ms (and ≤ a tenth of the host period).
    pub physics_step_s: f64,
    /// The onboard controller's own period \[s\], a whole number of physics steps; absent: it
    /// runs at every physics step, as a continuous controller (the maps' assumption).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub controller_period_s: Option<f64>,
    /// Largest forward speed [m/s] (for excitations).
    pub v_max: f64,
    /// Largest angular speed [rad/s] (for excitations).
    pub w_max: f64,
}

impl PhysicalProfile {
    /// A Pioneer 3-DX-like robot (v/ω-PD, 10 Hz host). Published: m = 9 kg, r = 97.5 mm
    /// (thesis §4.3), 128 ticks/mm (ARIA `p3dx.p`), 100 ms cycle (ARIA). Effective (chosen so
    /// that the map lands near the thesis's θ1 ≈ 0.26 s, θ2 ≈ 0.25 s, θ4, θ6 ≈ 1): track 0.33 m,
    /// I_z = 0.2 kg·m², b = 2 cm, motor k_a = k_b = 0.0287, R_a = 1 Ω, I_e = 10⁻³ kg·m², gains
    /// K_PT = 66, K_DT = 1.5, K_PR = 9.4, K_DR = 0.2.
    pub fn pioneer3dx() -> Self {
        let r = 0.0975;
        Self {
            name: "pioneer3dx".into(),
            m: 9.0,
            i_z: 0.2,
            b: 0.02,
            r,
            d: 0.33,
            wheel_mass: 0.5,
            i_e: 1e-3,
            k_a: 0.0287,
            k_b: 0.0287,
            r_a: 1.0,
            b_e: 0.0,
            controller: Controller::VwPd {
                k_pt: 66.0,
                k_dt: 1.5,
                k_pr: 9.4,
                k_dr: 0.2,
            },
            caster_x: 0.15,
            caster_radius: 0.03,
            ticks_per_rev: 128_000.0 * 2.0 * std::f64::consts::PI * r,
            period_s: 0.1,
            physics_step_s: 1e-3,
            controller_period_s: None,
            v_max: 1.2,
            w_max: 2.0,
        }
    }

    /// A Khepera III-like robot (wheel-PD, 50 Hz host). Published: m = 0.742 kg, r = 20.5 mm,
    /// d = 88.5 mm, 2764 ticks/rev (thesis §4.3). Effective (map near θ1 ≈ 0.023 s,
    /// θ2 ≈ 0.057 s, θ4, θ6 ≈ 1): I_z = 0.0036 kg·m², b = 1 cm, k_a = k_b = 0.01, R_a = 4.81 Ω,
    /// I_e = 2·10⁻⁵ kg·m², k_P = 3.33, k_D = 0.002.
    pub fn khepera3() -> Self {
        Self {
            name: "khepera3".into(),
            m: 0.742,
            i_z: 0.0036,
            b: 0.01,
            r: 0.0205,
            d: 0.0885,
            wheel_mass: 0.01,
            i_e: 2e-5,
            k_a: 0.01,
            k_b: 0.01,
            r_a: 4.81,
            b_e: 0.0,
            controller: Controller::WheelPd {
                k_p: 3.33,
                k_d: 0.002,
            },
            caster_x: 0.04,
            caster_radius: 0.005,
            ticks_per_rev: 2764.0,
            period_s: 0.02,
            physics_step_s: 2.5e-4,
            controller_period_s: None,
            v_max: 0.5,
            w_max: 6.0,
        }
    }

    /// A TurtleBot3 Burger-like robot (wheel-PD, 25 Hz host). Published: m ≈ 1 kg, r = 33 mm,
    /// d = 160 mm, 4096 ticks/rev (Dynamixel XL430), ball caster behind the axle. Effective:
    /// I_z = 0.006 kg·m², b = −2 cm, k_a = k_b = 0.05, R_a = 2 Ω, I_e = 10⁻⁴ kg·m², k_P = 0.6,
    /// k_D = 0.002 (θ1 ≈ 0.046 s, θ4 ≈ 1.08).
    pub fn burger() -> Self {
        Self {
            name: "burger".into(),
            m: 1.0,
            i_z: 0.006,
            b: -0.02,
            r: 0.033,
            d: 0.16,
            wheel_mass: 0.03,
            i_e: 1e-4,
            k_a: 0.05,
            k_b: 0.05,
            r_a: 2.0,
            b_e: 0.0,
            controller: Controller::WheelPd {
                k_p: 0.6,
                k_d: 0.002,
            },
            caster_x: -0.08,
            caster_radius: 0.01,
            ticks_per_rev: 4096.0,
            period_s: 0.04,
            physics_step_s: 5e-4,
            controller_period_s: None,
            v_max: 0.22,
            w_max: 2.8,
        }
    }

    /// Names of the built-in profiles.
    pub const NAMES: [&'static str; 3] = ["pioneer3dx", "khepera3", "burger"];

    /// The built-in profile called `name`.
    pub fn by_name(name: &str) -> Option<Self> {
        match name {
            "pioneer3dx" => Some(Self::pioneer3dx()),
            "khepera3" => Some(Self::khepera3()),
            "burger" => Some(Self::burger()),
            _ => None,
        }
    }

    /// The robot as eq. 2.19 sees it: θ from [`PhysicalProfile::theta`], r, d, period, ticks,
    /// mass and limits from these constants (no speed resolution, no noise: those are the
    /// physics run's settings). Used to pick a tracking trajectory and to report beside the
    /// true θ.
    pub fn model_profile(&self) -> crate::profile::RobotProfile {
        crate::profile::RobotProfile {
            name: self.name.clone(),
            theta: self.theta(),
            wheel_radius: self.r,
            track: self.d,
            period_s: self.period_s,
            ticks_per_rev: self.ticks_per_rev,
            speed_resolution: 0.0,
            wheel_noise_std: 0.0,
            a: 0.0,
            mass_kg: self.m,
            v_max: self.v_max,
            w_max: self.w_max,
        }
    }

    /// The identification excitation used on this robot throughout wheelid (the CLI's default,
    /// the accuracy and diagnosis tests): random-phase multisines ([`Excitation::random_multisine`],
    /// phases from `seed`) up to 1.5× the robot's bandwidth 1/(2π max(θ1, θ2)) (clamped to
    /// [0.2 Hz, a fifth of the sample rate]), v_ref = 0.1 v_max ± 0.3 v_max, ω_ref = ±0.35 ω_max.
    ///
    /// # Errors
    /// As [`Excitation::random_multisine`].
    ///
    /// [`Excitation::random_multisine`]: crate::excitation::Excitation::random_multisine
    pub fn random_multisine(&self, seed: u64) -> Result<crate::excitation::Excitation> {
        let th = self.theta();
        let f_bw = 1.0 / (2.0 * std::f64::consts::PI * th[0].max(th[1]));
        let f_max = (1.5 * f_bw).clamp(0.2, 0.2 / self.period_s);
        crate::excitation::Excitation::random_multisine(
            seed,
            0.1 * self.v_max,
            0.3 * self.v_max,
            0.35 * self.w_max,
            f_max,
        )
    }

    /// The model name whose parameterization this controller follows (`wheel-pd`, `vw-pd`).
    pub fn model_name(&self) -> &'static str {
        match self.controller {
            Controller::WheelPd { .. } => "wheel-pd",
            Controller::VwPd { .. } => "vw-pd",
        }
    }

    /// θ1…θ6 that `wheelid_models::physical` derives from these constants (tyre radius = r).
    pub fn theta(&self) -> [f64; 6] {
        match self.controller {
            Controller::WheelPd { k_p, k_d } => WheelPdMap::theta(&WheelPdConstants {
                m: self.m,
                i_z: self.i_z,
                b: self.b,
                r: self.r,
                d: self.d,
                r_t: self.r,
                r_a: self.r_a,
                k_a: self.k_a,
                k_b: self.k_b,
                i_e: self.i_e,
                b_e: self.b_e,
                k_p,
                k_d,
            }),
            Controller::VwPd {
                k_pt,
                k_dt,
                k_pr,
                k_dr,
            } => VwPdMap::theta(&VwPdConstants {
                m: self.m,
                i_z: self.i_z,
                b: self.b,
                r: self.r,
                d: self.d,
                r_t: self.r,
                r_a: self.r_a,
                k_a: self.k_a,
                k_b: self.k_b,
                i_e: self.i_e,
                b_e: self.b_e,
                k_pt,
                k_dt,
                k_pr,
                k_dr,
            }),
        }
    }

    /// Share of the weight on the driven wheels, 1 − b/x_c [-]: the statics of the chassis on
    /// its three contacts, the caster at x_c carrying b/x_c. On a floor of friction μ the
    /// wheels pass the body at most μ g (1 − b/x_c) of acceleration from rest.
    pub fn wheel_load_share(&self) -> f64 {
        1.0 - self.b / self.caster_x
    }

    /// Load moved onto the driven wheels per unit of the floor's traction force on them,
    /// (r + 2 I_e/(m r))/x_c [-], while they roll (× μ: `traction_limit`'s `load_transfer`).
    ///
    /// Moments about the centre of mass, which sits at the axle's height r: the traction
    /// F = m a acts r below it, and the wheels' spin momentum 2 I_e v/r grows at 2 I_e a/r;
    /// the load ΔN shifted between the wheels and the caster x_c away balances both,
    /// x_c ΔN = F r + 2 I_e a/r (the motors' torque on the wheels). The spin term is 2.3 % of
    /// the whole on the Pioneer-like profile and 12.8 % on the Khepera-like one; the engine's
    /// contact forces bear it out (`engine`'s tests). Here all of I_e spins with the wheel;
    /// on a real robot a rotor geared N : 1 carries only 1/N of the momentum of its share of
    /// I_e (and may turn the other way).
    pub fn load_transfer_per_force(&self) -> f64 {
        (self.r + 2.0 * self.i_e / (self.m * self.r)) / self.caster_x
    }

    /// Physics steps per controller period (1 without a controller period).
    pub fn controller_steps(&self) -> usize {
        self.controller_period_s
            .map_or(1, |t| (t / self.physics_step_s).round().max(1.0) as usize)
    }

    /// Checks the constants.
    ///
    /// # Errors
    /// [`Error::InvalidSetting`] naming the first constant that is not finite and positive
    /// (b and caster_x: finite, non-zero, same sign; B_e and derivative gains: ≥ 0), or a
    /// physics step above 1 ms or above a tenth of the host period.
    pub fn validate(&self) -> Result<()> {
        let positive = [
            ("m", self.m),
            ("i_z", self.i_z),
            ("r", self.r),
            ("d", self.d),
            ("wheel_mass", self.wheel_mass),
            ("i_e", self.i_e),
            ("k_a", self.k_a),
            ("k_b", self.k_b),
            ("r_a", self.r_a),
            ("caster_radius", self.caster_radius),
            ("ticks_per_rev", self.ticks_per_rev),
            ("period_s", self.period_s),
            ("physics_step_s", self.physics_step_s),
        ];
        for (name, x) in positive {
            if !(x.is_finite() && x > 0.0) {
                return Err(bad(&self.name, name, x, "must be finite and > 0"));
            }
        }
        if !(self.b.is_finite() && self.b != 0.0) {
            return Err(bad(&self.name, "b", self.b, "must be finite and non-zero"));
        }
        if !(self.caster_x.is_finite() && self.caster_x * self.b > 0.0) {
            return Err(bad(
                &self.name,
                "caster_x",
                self.caster_x,
                "must lie on the centre of mass's side of the axle (same sign as b)",
            ));
        }
        if self.caster_x.abs() <= self.b.abs() {
            return Err(bad(
                &self.name,
                "caster_x",
                self.caster_x,
                "must be beyond b",
            ));
        }
        if 2.0 * self.wheel_mass >= self.m {
            return Err(bad(
                &self.name,
                "wheel_mass",
                self.wheel_mass,
                "must be below m/2",
            ));
        }
        if !(self.b_e.is_finite() && self.b_e >= 0.0) {
            return Err(bad(&self.name, "b_e", self.b_e, "must be finite and ≥ 0"));
        }
        if self.physics_step_s > 1e-3 || self.physics_step_s > 0.1 * self.period_s {
            return Err(bad(
                &self.name,
                "physics_step_s",
                self.physics_step_s,
                "must be ≤ 1 ms and ≤ a tenth of period_s",
            ));
        }
        if let Some(t) = self.controller_period_s {
            let n = t / self.physics_step_s;
            if !(t.is_finite() && n >= 0.999 && (n - n.round()).abs() < 1e-6 && t <= self.period_s)
            {
                return Err(bad(
                    &self.name,
                    "controller_period_s",
                    t,
                    "must be a whole number of physics steps, at most period_s",
                ));
            }
        }
        Ok(())
    }
}

fn bad(profile: &str, name: &str, x: f64, why: &str) -> Error {
    Error::InvalidSetting(format!("physical profile `{profile}`: {name} = {x} {why}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn built_in_profiles_are_valid_and_land_near_the_thesis_theta() {
        for name in PhysicalProfile::NAMES {
            let p = PhysicalProfile::by_name(name).expect("built in");
            p.validate().expect("valid");
            let th = p.theta();
            assert!(th.iter().all(|x| x.is_finite()), "{name}: {th:?}");
            assert!(
                th[0] > 0.0 && th[1] > 0.0 && th[3] >= 1.0 && th[5] >= 1.0,
                "{name}"
            );
        }
        let k = PhysicalProfile::khepera3().theta();
        assert!((k[0] - 0.0228).abs() < 0.01, "{k:?}");
        let p = PhysicalProfile::pioneer3dx().theta();
        assert!(
            (p[0] - 0.26).abs() < 0.05 && (p[1] - 0.25).abs() < 0.06,
            "{p:?}"
        );
    }

    #[test]
    fn a_caster_on_the_wrong_side_is_refused() {
        let mut p = PhysicalProfile::khepera3();
        p.caster_x = -0.04;
        let e = p.validate().expect_err("refused").to_string();
        assert!(e.contains("caster_x"), "{e}");
    }
}
