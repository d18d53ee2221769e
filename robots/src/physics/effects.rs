//! Effects realised where they act on a robot — on the host's commands, inside the onboard
//! controller, at the amplifier, in the wheel joints, at the floor — never as edits of
//! eq. 2.19. All off by default; in TOML one table each, e.g. `[effects.voltage_clamp]`.
//!
//! | effect | where | what it does |
//! | --- | --- | --- |
//! | `latency_s` | host → robot link | a command reaches the controller `latency_s` after it was sent |
//! | `rate_limit` | onboard setpoint | v and ω setpoints move toward the command at most `v_accel`, `w_accel` per second (Pioneer TransAccel/RotAccel) |
//! | `voltage_clamp` | amplifier | each wheel's voltage is clamped to ±`volts`; back-EMF still acts |
//! | `gain_sag` | amplifier (battery) | output voltage × (1 − `fraction` · t/T) over the run (T: the run's duration) |
//! | `gain_decay_tau_s` | amplifier (battery) | output voltage × e^(−t/τ) |
//! | `amp_gain_right` | right amplifier | its voltage × the factor (one amplifier off by a few %) |
//! | `tyre_radius_right` | right tyre | its radius × the factor (the host still converts with r) |
//! | `dry_friction_nm` | wheel joints | Coulomb torque −F·tanh(ω_i/0.01 rad/s) |
//! | `floor_mu` | floor contact | wheel–floor friction (low: the wheels slip; encoders see the wheels) |
//! | `dead_band_v` | amplifier | a voltage asked below `dead_band_v` in size gives none, one above it that much less (before the clamp) |
//! | `sensor_delay_s` | encoders → host | the host reads the encoders' angles and rates as they were `sensor_delay_s` ago (a serial link, a driver's buffer); the true pose is not delayed |
//! | `payload` | chassis | a body set down at time T and held by a fixed joint ([`super::payload`]) |
//!
//! Encoder quantisation, wheel-speed noise and host jitter are [`super::PhysicsSettings`].

use serde::{Deserialize, Serialize};
use wheelid_core::{Error, Result};

use super::PhysicalProfile;
use super::payload::Payload;

/// The setpoint rate limit (onboard, on the v and ω setpoints).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RateLimit {
    /// Largest forward acceleration of the setpoint [m/s²].
    pub v_accel: f64,
    /// Largest angular acceleration of the setpoint [rad/s²].
    pub w_accel: f64,
}

/// The physics the 6-θ model leaves out, realised where it acts (module docs).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PhysicsEffects {
    /// Command latency from host to controller \[s\].
    pub latency_s: Option<f64>,
    /// Onboard setpoint rate limiter.
    pub rate_limit: Option<RateLimit>,
    /// Amplifier voltage clamp, per wheel \[V\].
    pub voltage_clamp: Option<f64>,
    /// Drive-gain sag: fraction of the amplifier gain lost, linearly, by the end of the run.
    pub gain_sag: Option<f64>,
    /// Drive-gain decay: the amplifier gain falls as e^(−t/τ), τ in seconds.
    pub gain_decay_tau_s: Option<f64>,
    /// Right amplifier's gain relative to the left's (e.g. 0.95).
    pub amp_gain_right: Option<f64>,
    /// Right tyre's radius relative to the nominal r (e.g. 1.03: worn left or oversized right).
    pub tyre_radius_right: Option<f64>,
    /// Coulomb friction torque in each wheel joint [N·m].
    pub dry_friction_nm: Option<f64>,
    /// Wheel–floor friction coefficient (default 1).
    pub floor_mu: Option<f64>,
    /// A payload set down on the chassis mid-run.
    pub payload: Option<Payload>,
    /// Amplifier dead band \[V\]: a voltage asked below it in size gives none, one above it
    /// that much less (a motor driver's dead band, before the clamp).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dead_band_v: Option<f64>,
    /// Dead time of the encoders' readings on their way to the host \[s\] (the true pose is
    /// not delayed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sensor_delay_s: Option<f64>,
}

impl PhysicsEffects {
    /// Names of the effects that are on.
    pub fn active(&self) -> Vec<&'static str> {
        let mut v = Vec::new();
        let on = [
            ("latency", self.latency_s.is_some()),
            ("rate_limit", self.rate_limit.is_some()),
            ("voltage_clamp", self.voltage_clamp.is_some()),
            ("gain_sag", self.gain_sag.is_some()),
            ("gain_decay", self.gain_decay_tau_s.is_some()),
            ("amp_gain_right", self.amp_gain_right.is_some()),
            ("tyre_radius_right", self.tyre_radius_right.is_some()),
            ("dry_friction", self.dry_friction_nm.is_some()),
            ("floor_mu", self.floor_mu.is_some()),
            ("payload", self.payload.is_some()),
            ("sensor_delay", self.sensor_delay_s.is_some()),
            ("dead_band", self.dead_band_v.is_some()),
        ];
        for (name, is) in on {
            if is {
                v.push(name);
            }
        }
        v
    }

    /// Checks every value (the payload against the robot `p` it is put on).
    ///
    /// # Errors
    /// [`Error::InvalidSetting`] naming the effect whose value is out of range.
    pub fn validate(&self, p: &PhysicalProfile) -> Result<()> {
        let check = |name: &str, x: Option<f64>, ok: &dyn Fn(f64) -> bool| match x {
            Some(x) if !(x.is_finite() && ok(x)) => Err(Error::InvalidSetting(format!(
                "physics effect {name} = {x} is out of range"
            ))),
            _ => Ok(()),
        };
        check("latency_s", self.latency_s, &|x| x >= 0.0)?;
        check("sensor_delay_s", self.sensor_delay_s, &|x| x >= 0.0)?;
        check("dead_band_v", self.dead_band_v, &|x| x >= 0.0)?;
        check("voltage_clamp", self.voltage_clamp, &|x| x > 0.0)?;
        check("gain_sag", self.gain_sag, &|x| (0.0..1.0).contains(&x))?;
        check("gain_decay_tau_s", self.gain_decay_tau_s, &|x| x > 0.0)?;
        check("amp_gain_right", self.amp_gain_right, &|x| x > 0.0)?;
        check("tyre_radius_right", self.tyre_radius_right, &|x| {
            (0.5..2.0).contains(&x)
        })?;
        check("dry_friction_nm", self.dry_friction_nm, &|x| x >= 0.0)?;
        check("floor_mu", self.floor_mu, &|x| x > 0.0)?;
        if let Some(r) = self.rate_limit {
            check("rate_limit.v_accel", Some(r.v_accel), &|x| x > 0.0)?;
            check("rate_limit.w_accel", Some(r.w_accel), &|x| x > 0.0)?;
        }
        if let Some(pl) = &self.payload {
            pl.validate(p)?;
        }
        Ok(())
    }

    /// The setpoint after the rate limiter, one step of `h` seconds from `prev` toward `cmd`.
    pub fn limit_rate(&self, prev: (f64, f64), cmd: (f64, f64), h: f64) -> (f64, f64) {
        match self.rate_limit {
            None => cmd,
            Some(r) => {
                let step = |p: f64, c: f64, a: f64| p + (c - p).clamp(-a * h, a * h);
                (
                    step(prev.0, cmd.0, r.v_accel),
                    step(prev.1, cmd.1, r.w_accel),
                )
            }
        }
    }

    /// The amplifier's output voltages (right, left) \[V\] for the controller's `u` \[V\] at time
    /// `t` \[s\] of a run of `duration` \[s\]: gain sag (linear, held after the run's end) or
    /// decay, right-amplifier gain, dead band, clamp.
    pub fn amplify(&self, u: [f64; 2], t: f64, duration: f64) -> [f64; 2] {
        let progress = (t / duration).clamp(0.0, 1.0);
        let sag = (1.0 - self.gain_sag.unwrap_or(0.0) * progress)
            * self.gain_decay_tau_s.map_or(1.0, |tau| (-t / tau).exp());
        let gains = [self.amp_gain_right.unwrap_or(1.0) * sag, sag];
        [0, 1].map(|i| {
            let mut x = u[i] * gains[i];
            if let Some(b) = self.dead_band_v {
                x = x.signum() * (x.abs() - b).max(0.0);
            }
            match self.voltage_clamp {
                Some(c) => x.clamp(-c, c),
                None => x,
            }
        })
    }

    /// Dry-friction torques (right, left) [N·m] on the wheels at their rates [rad/s].
    pub fn friction(&self, rates: [f64; 2]) -> [f64; 2] {
        match self.dry_friction_nm {
            None => [0.0; 2],
            Some(f) => rates.map(|w| -f * (w / 0.01).tanh()),
        }
    }
}
