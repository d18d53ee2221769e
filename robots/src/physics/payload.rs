//! A payload set down on the chassis mid-run: a real rigid body of mass m_p (a cube of side s)
//! that appears at time T at `x` ahead of the axle, `s/2` above the axle's height, moving with
//! the chassis (set down gently), and is held to it by a fixed joint from then on. The engine
//! integrates it like any other body: the robot's mass, centre of mass and yaw inertia change,
//! and with them the load split between the wheels and the caster.
//!
//! The loaded robot's constants ([`Payload::loaded`]) are what the map needs for its θ:
//!
//! ```text
//! m' = m + m_p,   b' = (m b + m_p x)/m',
//! I_z' = I_z + m (b − b')² + m_p (x − b')² + m_p s²/6      (a cube's own yaw inertia m_p s²/6)
//! ```

use serde::{Deserialize, Serialize};
use wheelid_core::{Error, Result};

use super::PhysicalProfile;

/// A payload put on the chassis at a given time.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Payload {
    /// Mass m_p \[kg\].
    pub mass_kg: f64,
    /// When it is set down \[s\] (0: from the start).
    pub at_s: f64,
    /// Position of its centre of mass ahead of the wheel axle \[m\] (on the axis of symmetry).
    pub x_m: f64,
    /// Side s of the cube \[m\] (its own yaw inertia is m_p s²/6).
    pub size_m: f64,
}

impl Payload {
    /// The robot with the payload on: m', b', I_z' (module docs); everything else unchanged.
    pub fn loaded(&self, p: &PhysicalProfile) -> PhysicalProfile {
        let m = p.m + self.mass_kg;
        let b = (p.m * p.b + self.mass_kg * self.x_m) / m;
        let i_z = p.i_z
            + p.m * (p.b - b).powi(2)
            + self.mass_kg * (self.x_m - b).powi(2)
            + self.own_yaw_inertia();
        PhysicalProfile {
            name: format!("{}+payload", p.name),
            m,
            b,
            i_z,
            ..p.clone()
        }
    }

    /// Load moved onto the driven wheels per unit of the floor's traction force on them with
    /// the payload on [-] (× μ: `traction_limit`'s `load_transfer`): the moment balance of
    /// [`PhysicalProfile::load_transfer_per_force`] for the loaded robot, whose centre of mass
    /// the cube (its centre s/2 above the axle) lifts by m_p s/(2 m') and whose mass m' weighs
    /// the wheels' spin term: (r + m_p s/(2 m') + 2 I_e/(m' r))/x_c. A 9 kg cube of 0.11 m on
    /// the Pioneer-like robot (m = 9 kg) raises it by 28 %.
    pub fn load_transfer_per_force(&self, p: &PhysicalProfile) -> f64 {
        let m = p.m + self.mass_kg;
        let lift = self.mass_kg * 0.5 * self.size_m / m;
        (p.r + lift + 2.0 * p.i_e / (m * p.r)) / p.caster_x
    }

    /// The cube's yaw inertia about its own centre, m_p s²/6 [kg·m²].
    pub fn own_yaw_inertia(&self) -> f64 {
        self.mass_kg * self.size_m * self.size_m / 6.0
    }

    /// Checks the values and that the loaded robot still stands on its wheels and caster (its
    /// centre of mass between the axle and the caster).
    ///
    /// # Errors
    /// [`Error::InvalidSetting`] naming the value out of range.
    pub fn validate(&self, p: &PhysicalProfile) -> Result<()> {
        let ok = self.mass_kg.is_finite()
            && self.mass_kg > 0.0
            && self.at_s.is_finite()
            && self.at_s >= 0.0
            && self.x_m.is_finite()
            && self.size_m.is_finite()
            && self.size_m > 0.0;
        if !ok {
            return Err(Error::InvalidSetting(format!(
                "payload {self:?}: need mass_kg > 0, at_s ≥ 0, size_m > 0, all finite"
            )));
        }
        self.loaded(p).validate().map_err(|e| {
            Error::InvalidSetting(format!("with the payload {self:?} on the robot: {e}"))
        })
    }
}
