//! The simulated robot: eq. 2.19 integrated at a fine step, driven by zero-order-held commands
//! at the robot's period, measured through its encoders.
//!
//! Measurement model, per period Δt: each wheel's angle is integrated exactly (sub-step RK4),
//! turned into whole encoder ticks, and the tick difference over the period gives the wheel
//! speed averaged over the period (as a base controller computes it); Gaussian noise is added and
//! the result rounded to the reported resolution (1 mm/s for a Pioneer SIP). v = (v_r + v_l)/2 and
//! ω = (v_r − v_l)/d follow. The recording says `command_hold: zoh` and
//! `velocity_sampling: window_average`. Pose by odometry with the second-order Runge–Kutta
//! heading (thesis eq. 3.2–3.3).

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use wheelid_core::{Recording, Result};

use crate::excitation::Excitation;
use crate::profile::RobotProfile;

/// Simulation settings.
#[derive(Debug, Clone, PartialEq)]
pub struct SimSettings {
    /// Duration [s].
    pub duration_s: f64,
    /// Random seed for the noise.
    pub seed: u64,
    /// Integration sub-steps per period.
    pub substeps: usize,
    /// Whether to apply the encoder model and noise (false: exact instantaneous v, ω).
    pub measurement_noise: bool,
}

impl Default for SimSettings {
    fn default() -> Self {
        Self {
            duration_s: 150.0,
            seed: 1,
            substeps: 50,
            measurement_noise: true,
        }
    }
}

/// Simulates `profile` under `excitation` and returns the recording.
///
/// # Errors
/// If the resulting recording is invalid (e.g. a non-finite state from an unstable θ).
pub fn simulate_recording(
    profile: &RobotProfile,
    excitation: &Excitation,
    s: &SimSettings,
) -> Result<Recording> {
    let dt = profile.period_s;
    let n = (s.duration_s / dt).floor() as usize + 1;
    let h = dt / s.substeps as f64;
    let th = profile.theta;
    let (r, d) = (profile.wheel_radius, profile.track);
    let mut rng = ChaCha8Rng::seed_from_u64(s.seed);
    let noise = Normal::new(0.0, profile.wheel_noise_std.max(0.0))
        .map_err(|e| wheelid_core::Error::InvalidSetting(format!("noise: {e}")))?;
    let quant = |x: f64| {
        if profile.speed_resolution > 0.0 {
            (x / profile.speed_resolution).round() * profile.speed_resolution
        } else {
            x
        }
    };
    let rad_per_tick = 2.0 * std::f64::consts::PI / profile.ticks_per_rev;
    let (mut v, mut w) = (0.0f64, 0.0f64);
    let (mut ang_r, mut ang_l) = (0.0f64, 0.0f64);
    let (mut ticks_r, mut ticks_l) = (0.0f64, 0.0f64);
    let (mut x, mut y, mut phi) = (0.0f64, 0.0f64, 0.0f64);
    let mut cols: [Vec<f64>; 8] = Default::default();
    for k in 0..n {
        let t = k as f64 * dt;
        let (vr, wr) = excitation.at(t);
        let (vm, wm) = if k == 0 {
            (0.0, 0.0)
        } else if s.measurement_noise {
            let tr = (ang_r / rad_per_tick).floor();
            let tl = (ang_l / rad_per_tick).floor();
            let sr = quant((tr - ticks_r) * rad_per_tick * r / dt + noise.sample(&mut rng));
            let sl = quant((tl - ticks_l) * rad_per_tick * r / dt + noise.sample(&mut rng));
            ticks_r = tr;
            ticks_l = tl;
            ((sr + sl) / 2.0, (sr - sl) / d)
        } else {
            (v, w)
        };
        // Odometry (eq. 3.2–3.3): heading at the middle of the step.
        if k > 0 {
            x += vm * dt * (phi + wm * dt / 2.0).cos();
            y += vm * dt * (phi + wm * dt / 2.0).sin();
            phi += wm * dt;
        }
        for (c, val) in cols.iter_mut().zip([t, vr, wr, vm, wm, x, y, phi]) {
            c.push(val);
        }
        // Advance the true state over [t, t + Δt) with the held command.
        for _ in 0..s.substeps {
            let f = |v: f64, w: f64| wheelid_models::dynamics::accel(&th, v, w, vr, wr);
            let k1 = f(v, w);
            let k2 = f(v + 0.5 * h * k1.0, w + 0.5 * h * k1.1);
            let k3 = f(v + 0.5 * h * k2.0, w + 0.5 * h * k2.1);
            let k4 = f(v + h * k3.0, w + h * k3.1);
            let (dv, dw) = (
                h / 6.0 * (k1.0 + 2.0 * k2.0 + 2.0 * k3.0 + k4.0),
                h / 6.0 * (k1.1 + 2.0 * k2.1 + 2.0 * k3.1 + k4.1),
            );
            // Wheel angles: trapezoid of the wheel speeds (v ± dω/2)/r over the sub-step.
            let (v1, w1) = (v + dv, w + dw);
            ang_r += h * 0.5 * ((v + d * w / 2.0) + (v1 + d * w1 / 2.0)) / r;
            ang_l += h * 0.5 * ((v - d * w / 2.0) + (v1 - d * w1 / 2.0)) / r;
            v = v1;
            w = w1;
        }
    }
    let [t, vr, wr, vm, wm, x, y, phi] = cols;
    let mut rec = Recording::new(format!("<simulated {}>", profile.name), t, vr, wr, vm, wm)?;
    rec.x = Some(x);
    rec.y = Some(y);
    rec.phi = Some(phi);
    rec.set_meta("robot", profile.name.clone());
    rec.set_meta("source", format!("wheelid simulator, seed {}", s.seed));
    rec.set_meta("theta_true", format!("{:?}", profile.theta));
    rec.set_meta("command_hold", "zoh");
    rec.set_meta(
        "velocity_sampling",
        if s.measurement_noise {
            "window_average"
        } else {
            "instant"
        },
    );
    Ok(rec)
}
