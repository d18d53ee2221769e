//! Robot profiles: the identified θ and the physical facts a simulator needs.

use serde::{Deserialize, Serialize};

/// A differential-drive robot as the simulator sees it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotProfile {
    /// Profile name, e.g. `pioneer3dx`.
    pub name: String,
    /// True θ1…θ6 of eq. 2.19 (units as `wheelid_models::regressor::PARAMS`).
    pub theta: [f64; 6],
    /// Wheel radius r \[m\].
    pub wheel_radius: f64,
    /// Track width d \[m\].
    pub track: f64,
    /// Control and sampling period \[s\].
    pub period_s: f64,
    /// Encoder ticks per wheel revolution.
    pub ticks_per_rev: f64,
    /// Resolution of the reported wheel speeds [m/s] (0 for none).
    pub speed_resolution: f64,
    /// Standard deviation of the wheel-speed measurement noise [m/s] per wheel.
    pub wheel_noise_std: f64,
    /// Distance a \[m\] of the tracked point h ahead of the wheel axle (eq. 2.19; 0 puts h on
    /// the axle, as the kinematic law of eq. 4.8 assumes).
    #[serde(default)]
    pub a: f64,
    /// Mass \[kg\] (§4.3); informative, the dynamics are in θ.
    pub mass_kg: f64,
    /// Largest forward speed [m/s] (§4.3), the default level of the velocity-saturation effect.
    pub v_max: f64,
    /// Largest angular speed [rad/s], the default level of the velocity-saturation effect.
    pub w_max: f64,
}

impl RobotProfile {
    /// The multisine `wheelid simulate --excitation multisine` drives this robot with, and the
    /// benchmarks, profiles and diagnosis tests on it: random-phase lines up to 2 Hz
    /// ([`Excitation::random_multisine`], phases from `seed`), v_ref = v_max/4 ± v_max/4 (peak),
    /// ω_ref = 0 ± ω_max/4.
    ///
    /// # Errors
    /// As [`Excitation::random_multisine`] (a profile whose v_max or ω_max is not finite).
    ///
    /// [`Excitation::random_multisine`]: crate::excitation::Excitation::random_multisine
    pub fn multisine(&self, seed: u64) -> wheelid_core::Result<crate::excitation::Excitation> {
        crate::excitation::Excitation::random_multisine(
            seed,
            0.25 * self.v_max,
            0.25 * self.v_max,
            0.25 * self.w_max,
            2.0,
        )
    }

    /// The white noise of each reported wheel speed ([`RobotProfile::wheel_noise_std`],
    /// negative read as 0), after checking the period, wheels and encoders are > 0: what the
    /// simulator's measurement model needs.
    ///
    /// # Errors
    /// [`wheelid_core::Error::InvalidSetting`] naming the robot and the first bad number.
    pub fn measurement(&self) -> wheelid_core::Result<rand_distr::Normal<f64>> {
        let positive = [
            ("period_s", self.period_s),
            ("wheel_radius", self.wheel_radius),
            ("track", self.track),
            ("ticks_per_rev", self.ticks_per_rev),
        ];
        if let Some((name, x)) = positive.iter().find(|(_, x)| !(x.is_finite() && *x > 0.0)) {
            return Err(wheelid_core::Error::InvalidSetting(format!(
                "robot {}: {name} = {x} must be > 0",
                self.name
            )));
        }
        rand_distr::Normal::new(0.0, self.wheel_noise_std.max(0.0))
            .map_err(|e| wheelid_core::Error::InvalidSetting(format!("wheel_noise_std: {e}")))
    }

    /// Pioneer 3-DX with the thesis's simulation θ (§4.2, Tables 4.1–4.2 "true" column, the
    /// values of Martins et al. for a Pioneer 3-DX):
    /// θ = (0.2604, 0.2509, −0.000499, 0.9965, 0.00263, 1.0768).
    /// Wheel radius 97.5 mm, track 34 cm, mass 9 kg, 1.4 m/s (§4.3); 300 °/s turn rate (ARIA
    /// default); ARIA's 100 ms cycle; 128 encoder ticks per mm of travel (ARIA `p3dx.p`,
    /// `TicksMM`); wheel speeds reported in whole mm/s as in the ARCOS standard SIP; 2 mm/s of
    /// wheel-speed noise.
    pub fn pioneer3dx() -> Self {
        let r = 0.0975;
        Self {
            name: "pioneer3dx".into(),
            theta: [0.2604, 0.2509, -0.000499, 0.9965, 0.00263, 1.0768],
            wheel_radius: r,
            track: 0.34,
            period_s: 0.1,
            ticks_per_rev: 128_000.0 * 2.0 * std::f64::consts::PI * r,
            speed_resolution: 0.001,
            wheel_noise_std: 0.002,
            a: 0.0,
            mass_kg: 9.0,
            v_max: 1.4,
            w_max: 300f64.to_radians(),
        }
    }

    /// The Pioneer 3-DX of Laut's lab, with the θ the thesis identified on it (§4.4.2):
    /// θ = (0.2183, 0.1918, −0.0050, 0.9993, −0.0279, 1.0142); otherwise as
    /// [`RobotProfile::pioneer3dx`].
    pub fn pioneer3dx_laut() -> Self {
        Self {
            name: "pioneer3dx_laut".into(),
            theta: [0.2183, 0.1918, -0.0050, 0.9993, -0.0279, 1.0142],
            ..Self::pioneer3dx()
        }
    }

    /// Khepera III with the θ identified in the thesis (§4.4.1):
    /// θ = (0.0228, 0.0568, −0.0001, 1.0030, 0.0732, 0.9981); wheel radius 20.5 mm, track
    /// 88.5 mm (§4.3: 89 mm), mass 742 g, 0.5 m/s (§4.3) and so 2·0.5/0.0885 = 11.3 rad/s;
    /// 20 ms period (§4.3), 2764 ticks per wheel revolution, 0.5 mm/s wheel-speed noise.
    pub fn khepera3() -> Self {
        Self {
            name: "khepera3".into(),
            theta: [0.0228, 0.0568, -0.0001, 1.0030, 0.0732, 0.9981],
            wheel_radius: 0.0205,
            track: 0.0885,
            period_s: 0.02,
            ticks_per_rev: 2764.0,
            speed_resolution: 0.0,
            wheel_noise_std: 0.0005,
            a: 0.0,
            mass_kg: 0.742,
            v_max: 0.5,
            w_max: 2.0 * 0.5 / 0.0885,
        }
    }

    /// The names [`RobotProfile::by_name`] knows.
    pub const NAMES: [&'static str; 3] = ["pioneer3dx", "pioneer3dx_laut", "khepera3"];

    /// The built-in profile called `name` (one of [`RobotProfile::NAMES`]).
    pub fn by_name(name: &str) -> Option<Self> {
        match name {
            "pioneer3dx" => Some(Self::pioneer3dx()),
            "pioneer3dx_laut" => Some(Self::pioneer3dx_laut()),
            "khepera3" => Some(Self::khepera3()),
            _ => None,
        }
    }
}
