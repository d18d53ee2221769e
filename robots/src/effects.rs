//! Physics that real robots have and the 6-θ model of eq. 2.19 leaves out, as optional effects
//! of the simulated robot. Every effect is off by default (`None`); each has the magnitude a
//! diagnosis would report, with the names of the candidate library of the mismatch diagnosis.
//!
//! With u = (v_ref, ω_ref) the command the robot receives at its sample instants (held between
//! them), the simulator applies, in this order, at every integration sub-step τ:
//!
//! 1. `input_delay`: u(τ − delay_s) (before the first command arrives, the setpoint that holds
//!    the initial state: zero for a robot at rest);
//! 2. `velocity_saturation`: the setpoint clipped to ±v_max, ±w_max (the base refuses faster
//!    setpoints, as ARIA's `TransVelMax`/`RotVelMax` do), so the response saturates while the
//!    command goes on;
//! 3. `acceleration_limit`: the setpoint slews towards that value at most at v_accel_max
//!    [m/s²], w_accel_max [rad/s²] (a base's velocity ramp, ARIA's `TransAccel`/`RotAccel`);
//! 4. `wheel_asymmetry`: wheel setpoints v_ref ± d ω_ref / 2 scaled by 2ρ/(1 + ρ) (right) and
//!    2/(1 + ρ) (left), ρ = `ratio`, so v_ref leaks into ω by 2(ρ − 1)/((1 + ρ) d) · v_ref;
//!
//! and then integrates
//!
//! ```text
//! θ1 v̇ = g (u_v − v) − (θ4 − 1) v + θ3 ω² − c_v tanh(v / ε_v) + θ4 v̄ˢ
//! θ2 ω̇ = g (u_ω − ω) − (θ6 − 1) ω − θ5 v ω − c_ω tanh(ω / ε_ω) + θ6 ω̄ˢ
//! ```
//!
//! where g = 1 + rate_per_s · τ is the drive gain of `gain_drift` (1 without it): a draining
//! battery (rate < 0) scales the amplifier's output, i.e. the whole proportional effort of the
//! speed loop, while back-EMF and viscous losses (θ4 − 1, θ6 − 1) and inertia stay (the share of
//! θ1, θ2 that is the loop's derivative gain is taken as small);
//!
//! with θ switched to `payload_change.theta_after` from `time_s` on; `coulomb_friction` gives
//! c_v, c_ω in command units (dry friction smoothed over ε_v = 2 mm/s, ε_ω = 0.01 rad/s, so that
//! small commands barely move the robot: a dead zone); `slip` gives the slip velocities of
//! eq. 2.8 as they enter eqs. 2.17–2.18, v̄ˢ = −k_v v |ω| and ω̄ˢ = (v_rˢ − v_lˢ)/d = −k_w |v| ω,
//! skid losses growing with v·ω. `measurement_noise` adds white Gaussian noise to the reported
//! v, ω (on top of the encoder model), and `sample_jitter` moves each sample instant by a
//! Gaussian error (clipped to ±0.45 period), so the recording's time stamps are uneven.

use serde::{Deserialize, Serialize};
use wheelid_core::{Error, Result};

/// Dead time between the command and the robot acting on it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InputDelay {
    /// Delay \[s\] (≥ 0).
    pub delay_s: f64,
}

/// Rate limit on the setpoint the base's velocity loop follows.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AccelerationLimit {
    /// Largest |d v_setpoint / dt| [m/s²] (> 0).
    pub v_accel_max: f64,
    /// Largest |d ω_setpoint / dt| [rad/s²] (> 0).
    pub w_accel_max: f64,
}

/// Clip on the setpoint.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VelocitySaturation {
    /// Largest |v_ref| [m/s] (> 0).
    pub v_max: f64,
    /// Largest |ω_ref| [rad/s] (> 0).
    pub w_max: f64,
}

/// Dry (Coulomb) friction, in command units.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CoulombFriction {
    /// Forward friction level [m/s of command] (≥ 0).
    pub v_coulomb: f64,
    /// Turning friction level [rad/s of command] (≥ 0).
    pub w_coulomb: f64,
}

/// Left–right wheel gain mismatch.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WheelAsymmetry {
    /// Right-wheel gain over left-wheel gain ρ (> 0; 1 is symmetric).
    pub ratio: f64,
}

/// A payload put on the robot at a time: θ1, θ2, θ3, θ5 (mass, inertia, centre of mass;
/// thesis §4.4) change.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PayloadChange {
    /// When the payload is added \[s\].
    pub time_s: f64,
    /// θ1…θ6 from then on.
    pub theta_after: [f64; 6],
}

impl PayloadChange {
    /// A payload that multiplies the mass-dependent θ1, θ2, θ3, θ5 of `theta` by `factor`
    /// (their mass and inertia terms dominate, §2.2) and keeps θ4, θ6, from `time_s` on.
    pub fn scaled(time_s: f64, theta: [f64; 6], factor: f64) -> Self {
        let mut after = theta;
        for i in [0, 1, 2, 4] {
            after[i] *= factor;
        }
        Self {
            time_s,
            theta_after: after,
        }
    }
}

/// Slow change of the drive (amplifier) gain over the run: the speed loop's effort is scaled by
/// g = 1 + rate_per_s · τ (module docs).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GainDrift {
    /// Relative drive-gain change per second [1/s] (a draining battery is negative).
    pub rate_per_s: f64,
}

/// Skid losses (slip velocities of eq. 2.8) growing with v·ω.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Slip {
    /// Forward loss coefficient k_v [s/rad]: v̄ˢ = −k_v v |ω|.
    pub k_v: f64,
    /// Turning loss coefficient k_w [s/m]: ω̄ˢ = −k_w |v| ω.
    pub k_w: f64,
}

/// Extra white measurement noise on the reported velocities.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MeasurementNoise {
    /// Standard deviation on v [m/s].
    pub v_std: f64,
    /// Standard deviation on ω [rad/s].
    pub w_std: f64,
}

/// Uneven sample instants.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SampleJitter {
    /// Standard deviation of each sample instant's error \[s\].
    pub std_s: f64,
}

/// The optional effects of a simulated robot (see the module documentation). All `None` by
/// default. In TOML, one table each: `[effects.input_delay] delay_s = 0.3`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Effects {
    /// Command dead time.
    pub input_delay: Option<InputDelay>,
    /// Rate limit on the setpoint.
    pub acceleration_limit: Option<AccelerationLimit>,
    /// Clip on the setpoint.
    pub velocity_saturation: Option<VelocitySaturation>,
    /// Dry friction / dead zone.
    pub coulomb_friction: Option<CoulombFriction>,
    /// Left–right wheel mismatch.
    pub wheel_asymmetry: Option<WheelAsymmetry>,
    /// Payload added at a time.
    pub payload_change: Option<PayloadChange>,
    /// Actuator gain drift.
    pub gain_drift: Option<GainDrift>,
    /// Skid losses.
    pub slip: Option<Slip>,
    /// Extra noise on v, ω.
    pub measurement_noise: Option<MeasurementNoise>,
    /// Uneven sample instants.
    pub sample_jitter: Option<SampleJitter>,
}

fn check(ok: bool, what: &str, value: f64) -> Result<()> {
    if ok && value.is_finite() {
        Ok(())
    } else {
        Err(Error::InvalidSetting(format!("effects: {what} = {value}")))
    }
}

impl Effects {
    /// The names of the effects that are on, in the order of the fields.
    pub fn active(&self) -> Vec<&'static str> {
        let mut names = Vec::new();
        let on = [
            ("input_delay", self.input_delay.is_some()),
            ("acceleration_limit", self.acceleration_limit.is_some()),
            ("velocity_saturation", self.velocity_saturation.is_some()),
            ("coulomb_friction", self.coulomb_friction.is_some()),
            ("wheel_asymmetry", self.wheel_asymmetry.is_some()),
            ("payload_change", self.payload_change.is_some()),
            ("gain_drift", self.gain_drift.is_some()),
            ("slip", self.slip.is_some()),
            ("measurement_noise", self.measurement_noise.is_some()),
            ("sample_jitter", self.sample_jitter.is_some()),
        ];
        for (name, is_on) in on {
            if is_on {
                names.push(name);
            }
        }
        names
    }

    /// Checks every magnitude is finite and in its range.
    ///
    /// # Errors
    /// [`Error::InvalidSetting`] naming the effect and field.
    pub fn validate(&self) -> Result<()> {
        if let Some(e) = self.input_delay {
            check(e.delay_s >= 0.0, "input_delay.delay_s", e.delay_s)?;
        }
        if let Some(e) = self.acceleration_limit {
            check(
                e.v_accel_max > 0.0,
                "acceleration_limit.v_accel_max",
                e.v_accel_max,
            )?;
            check(
                e.w_accel_max > 0.0,
                "acceleration_limit.w_accel_max",
                e.w_accel_max,
            )?;
        }
        if let Some(e) = self.velocity_saturation {
            check(e.v_max > 0.0, "velocity_saturation.v_max", e.v_max)?;
            check(e.w_max > 0.0, "velocity_saturation.w_max", e.w_max)?;
        }
        if let Some(e) = self.coulomb_friction {
            check(
                e.v_coulomb >= 0.0,
                "coulomb_friction.v_coulomb",
                e.v_coulomb,
            )?;
            check(
                e.w_coulomb >= 0.0,
                "coulomb_friction.w_coulomb",
                e.w_coulomb,
            )?;
        }
        if let Some(e) = self.wheel_asymmetry {
            check(e.ratio > 0.0, "wheel_asymmetry.ratio", e.ratio)?;
        }
        if let Some(e) = self.payload_change {
            check(true, "payload_change.time_s", e.time_s)?;
            wheelid_models::dynamics::check_theta(&e.theta_after).map_err(|err| {
                Error::InvalidSetting(format!("effects: payload_change.theta_after: {err}"))
            })?;
        }
        if let Some(e) = self.gain_drift {
            check(true, "gain_drift.rate_per_s", e.rate_per_s)?;
        }
        if let Some(e) = self.slip {
            check(e.k_v >= 0.0, "slip.k_v", e.k_v)?;
            check(e.k_w >= 0.0, "slip.k_w", e.k_w)?;
        }
        if let Some(e) = self.measurement_noise {
            check(e.v_std >= 0.0, "measurement_noise.v_std", e.v_std)?;
            check(e.w_std >= 0.0, "measurement_noise.w_std", e.w_std)?;
        }
        if let Some(e) = self.sample_jitter {
            check(e.std_s >= 0.0, "sample_jitter.std_s", e.std_s)?;
        }
        Ok(())
    }
}
