//! An independent rigid-body robot: motors, onboard controller, wheels with ground contact and a
//! caster on a real physics engine (rapier3d-f64), driven and sampled by a host — **not** eq.
//! 2.19. Recordings from it test identification and diagnosis on physics the model did not
//! write.
//!
//! The layers, each in its file:
//! * [`profile`]: the robot as physical constants only ([`PhysicalProfile`]; built-in
//!   Pioneer 3-DX-like, Khepera III-like and TurtleBot3 Burger-like robots), with the θ that
//!   `wheelid_models::physical` derives from them (the backend itself never uses θ);
//! * [`engine`]: the bodies, joints and contacts (and the set-up details that bias θ);
//! * [`drive`]: the onboard controller (wheel-PD §2.2 or v/ω-PD App. A.3) and the DC motors,
//!   run at the physics step:
//!
//! ```text
//! wheel-PD:  u_i = k_P (ω_i,ref − ω_i) − k_D ω̇_i                 ω_r,l,ref = (v_ref ± d ω_ref/2)/r
//! v/ω-PD:    u_r,l = [K_PT (v_ref − v) − K_DT v̇] ± [K_PR (ω_ref − ω) − K_DR ω̇]
//! motor:     τ_i = (k_a/R_a)(u_i − k_b ω_i) − B_e ω_i             (on wheel i, −τ_i on the chassis)
//! ```
//!
//! * [`encoder`]: tick quantisation and wheel-speed noise;
//! * [`effects`] and [`payload`]: physics the 6-θ model leaves out, where it acts on the robot;
//! * [`robot`]: [`PhysicsRobot`], the plant stepped between the host's samples (a
//!   `wheelid_core::Robot`);
//! * [`host`]: sample instants with jitter and the three stamping conventions of
//!   `wheelid_core::Timing` ([`simulate_physics_recording`]).
//!
//! Accuracy (noise-free runs identified by output error against the maps' θ, steady turns
//! against the maps' steady states, closed forms for the effects): `robots/tests/physics.rs`.

pub mod drive;
pub mod effects;
pub mod encoder;
pub mod engine;
pub mod host;
pub mod payload;
pub mod profile;
pub mod robot;

pub use effects::{PhysicsEffects, RateLimit};
pub use host::simulate_physics_recording;
pub use payload::Payload;
pub use profile::{Controller, PhysicalProfile};
pub use robot::PhysicsRobot;

use serde::{Deserialize, Serialize};
use wheelid_core::{Error, Result, Timing};

/// Settings of a physics run (the robot is a [`PhysicalProfile`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PhysicsSettings {
    /// Duration \[s\].
    pub duration_s: f64,
    /// Seed of the jitter and the noise.
    pub seed: u64,
    /// How the host stamps its rows.
    pub timing: Timing,
    /// Host timing jitter: each sample instant moves by up to ± this fraction of the period
    /// (uniform), < 0.5.
    pub jitter: f64,
    /// Quantise the wheel angles to encoder ticks (window conventions) — off: exact angles.
    pub encoders: bool,
    /// Standard deviation of white noise on each reported wheel speed [m/s].
    pub wheel_noise_std: f64,
    /// Effects (all off by default).
    pub effects: PhysicsEffects,
}

impl Default for PhysicsSettings {
    fn default() -> Self {
        Self {
            duration_s: 120.0,
            seed: 1,
            timing: Timing::WindowEnd,
            jitter: 0.0,
            encoders: true,
            wheel_noise_std: 0.0,
            effects: PhysicsEffects::default(),
        }
    }
}

/// Checks a profile and settings.
pub(crate) fn validate(profile: &PhysicalProfile, s: &PhysicsSettings) -> Result<()> {
    profile.validate()?;
    s.effects.validate(profile)?;
    if !(s.duration_s.is_finite() && s.duration_s > 0.0) {
        return Err(Error::InvalidSetting(format!(
            "duration_s = {} must be > 0",
            s.duration_s
        )));
    }
    if !(0.0..0.5).contains(&s.jitter) {
        return Err(Error::InvalidSetting(format!(
            "jitter = {} must be in [0, 0.5)",
            s.jitter
        )));
    }
    if !(s.wheel_noise_std.is_finite() && s.wheel_noise_std >= 0.0) {
        return Err(Error::InvalidSetting(format!(
            "wheel_noise_std = {} must be ≥ 0",
            s.wheel_noise_std
        )));
    }
    Ok(())
}
