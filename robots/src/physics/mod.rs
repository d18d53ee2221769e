//! An independent rigid-body robot: motors, onboard controller, wheels with ground contact and a
//! caster on a real physics engine (rapier3d-f64), driven and sampled by a host — **not** eq.
//! 2.19. Recordings from it test identification and diagnosis on physics the model did not
//! write.
//!
//! The layers, each in its file:
//! * [`profile`]: the robot as physical constants only ([`PhysicalProfile`]; built-in
//!   Pioneer 3-DX-like, Khepera III-like and TurtleBot3 Burger-like robots), with the θ that
//!   `wheelid_models::physical` derives from them;
//! * [`engine`]: the bodies, joints and contacts (and the set-up details that bias θ);
//! * [`drive`]: the onboard controller (wheel-PD §2.2 or v/ω-PD App. A.3) and the DC motors,
//!   run at the physics step;
//! * [`effects`]: physics the 6-θ model leaves out, where it acts on the robot;
//! * this module: the host — it samples at instants s_k = kΔ + jitter, sends the command
//!   u_k = excitation(s_k) at s_k, reads the encoders, and writes the recording under one of the
//!   stamping conventions of `wheelid_core::Timing`:
//!
//! ```text
//! (a) instant:        row k = (s_k,                 u_k, wheel-speed v, ω at s_k)
//! (b) window_end:     row k = (s_k,                 u_k, ticks over [s_{k−1}, s_k] / (s_k − s_{k−1}))
//! (c) window_middle:  row k = ((s_k + s_{k+1})/2,   u_k, ticks over [s_k, s_{k+1}] / (s_{k+1} − s_k))
//! ```
//!
//! with v = r (ω_r + ω_l)/2, ω = r (ω_r − ω_l)/d from the wheels (the encoders see the wheels,
//! not the body: a slipping wheel is measured as turning). Sample instants fall on physics
//! steps. The pose columns are the chassis's true axle-centre pose.

pub mod drive;
pub mod effects;
pub mod engine;
pub mod profile;

pub use effects::{PhysicsEffects, RateLimit};
pub use profile::{Controller, PhysicalProfile};

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};
use wheelid_core::{Error, Recording, Result, Timing};

use crate::excitation::Excitation;
use drive::Drive;
use engine::{Engine, FLOOR_MU};

/// Settings of a physics run (the robot is a [`PhysicalProfile`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PhysicsSettings {
    /// Duration [s].
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

/// What the host saw at one sample instant.
#[derive(Debug, Clone, Copy)]
struct Raw {
    t: f64,
    command: (f64, f64),
    /// Wheel angles (right, left) as the encoders report them [rad].
    angle: [f64; 2],
    /// Instantaneous wheel rates [rad/s].
    rate: [f64; 2],
    pose: [f64; 3],
}

/// Sample instants s_k on the physics grid: kΔ plus uniform jitter of ± `jitter`·Δ, as step
/// indices (strictly increasing).
fn sample_steps(n: usize, period: f64, h: f64, jitter: f64, rng: &mut ChaCha8Rng) -> Vec<usize> {
    let mut out = Vec::with_capacity(n);
    let mut last = None;
    for k in 0..n {
        let e = if k == 0 || jitter == 0.0 {
            0.0
        } else {
            rng.random_range(-jitter..=jitter)
        };
        let step = ((k as f64 + e) * period / h).round() as usize;
        let step = match last {
            Some(l) if step <= l => l + 1,
            _ => step,
        };
        out.push(step);
        last = Some(step);
    }
    out
}

/// Runs the robot under `excitation` from rest and returns what the host saw at each sample.
fn run_host(p: &PhysicalProfile, exc: &Excitation, s: &PhysicsSettings) -> Vec<Raw> {
    let h = p.physics_step_s;
    let fx = &s.effects;
    let mut engine = Engine::new(p, fx.floor_mu.unwrap_or(FLOOR_MU));
    let mut drive = Drive::new(p);
    let mut rng = ChaCha8Rng::seed_from_u64(s.seed);
    let n = (s.duration_s / p.period_s).floor() as usize + 2;
    let steps = sample_steps(n, p.period_s, h, s.jitter, &mut rng);
    let total = steps.last().copied().unwrap_or(0);
    let tick = 2.0 * std::f64::consts::PI / p.ticks_per_rev;
    let latency = fx.latency_s.unwrap_or(0.0);
    // Commands in flight: (time they reach the controller, command).
    let mut queue: std::collections::VecDeque<(f64, (f64, f64))> = Default::default();
    let mut command = (0.0, 0.0);
    let mut setpoint = (0.0, 0.0);
    let mut angle = [0.0; 2];
    let mut rates = engine.wheel_rates();
    let mut raws = Vec::with_capacity(n);
    let mut next = 0;
    for j in 0..=total {
        let t = j as f64 * h;
        if next < steps.len() && steps[next] == j {
            let u = exc.at(t);
            queue.push_back((t + latency, u));
            let body = engine.body();
            let reported = if s.encoders {
                angle.map(|a| (a / tick).floor() * tick)
            } else {
                angle
            };
            raws.push(Raw {
                t,
                command: u,
                angle: reported,
                rate: rates,
                pose: [body.x, body.y, body.heading],
            });
            next += 1;
        }
        if j == total {
            break;
        }
        while queue.front().is_some_and(|(at, _)| *at <= t + 0.5 * h) {
            if let Some((_, u)) = queue.pop_front() {
                command = u;
            }
        }
        setpoint = fx.limit_rate(setpoint, command, h);
        let u = drive.voltages(setpoint, rates, h);
        let u = fx.amplify(u, t / s.duration_s.max(h));
        let tau = drive.torques(u, rates);
        let fr = fx.friction(rates);
        engine.step([tau[0] + fr[0], tau[1] + fr[1]]);
        let new = engine.wheel_rates();
        for i in 0..2 {
            angle[i] += 0.5 * h * (rates[i] + new[i]);
        }
        rates = new;
    }
    raws
}

/// Simulates `profile` under `excitation` from rest and returns the recording the host writes
/// under `settings.timing` (module docs). Metadata: `robot`, `source`, `theta_map` (the map's
/// θ of the constants), `model` (`wheel-pd` or `vw-pd`), `effects`, `command_hold: zoh`,
/// `timing` and `velocity_sampling`.
///
/// # Errors
/// [`Error::InvalidSetting`] for a bad profile or setting (duration ≤ 0, jitter ∉ [0, 0.5),
/// negative noise, an effect out of range), or an invalid recording (the engine diverged).
pub fn simulate_physics_recording(
    profile: &PhysicalProfile,
    excitation: &Excitation,
    s: &PhysicsSettings,
) -> Result<Recording> {
    profile.validate()?;
    s.effects.validate()?;
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
    let raws = run_host(profile, excitation, s);
    let mut rng = ChaCha8Rng::seed_from_u64(s.seed.wrapping_add(0x5eed));
    let noise = Normal::new(0.0, s.wheel_noise_std.max(1e-300))
        .map_err(|e| Error::InvalidSetting(e.to_string()))?;
    let mut wheel = |w: f64| {
        w * profile.r
            + if s.wheel_noise_std > 0.0 {
                noise.sample(&mut rng)
            } else {
                0.0
            }
    };
    let d = profile.d;
    let window = |a: &Raw, b: &Raw| [0, 1].map(|i| (b.angle[i] - a.angle[i]) / (b.t - a.t));
    let mut cols: [Vec<f64>; 8] = Default::default();
    let m = raws.len() - 1;
    for k in 0..m {
        let (t, u, rates, pose) = match s.timing {
            Timing::Instant => (raws[k].t, raws[k].command, raws[k].rate, raws[k].pose),
            Timing::WindowEnd => {
                let rates = if k == 0 {
                    raws[0].rate
                } else {
                    window(&raws[k - 1], &raws[k])
                };
                (raws[k].t, raws[k].command, rates, raws[k].pose)
            }
            Timing::WindowMiddle => (
                0.5 * (raws[k].t + raws[k + 1].t),
                raws[k].command,
                window(&raws[k], &raws[k + 1]),
                raws[k + 1].pose,
            ),
        };
        let (vr, vl) = (wheel(rates[0]), wheel(rates[1]));
        for (c, x) in cols.iter_mut().zip([
            t,
            u.0,
            u.1,
            0.5 * (vr + vl),
            (vr - vl) / d,
            pose[0],
            pose[1],
            pose[2],
        ]) {
            c.push(x);
        }
    }
    let [t, vref, wref, v, w, x, y, phi] = cols;
    let mut rec = Recording::new(format!("<physics {}>", profile.name), t, vref, wref, v, w)?;
    rec.x = Some(x);
    rec.y = Some(y);
    rec.phi = Some(phi);
    rec.set_meta("robot", profile.name.clone());
    rec.set_meta(
        "source",
        format!("wheelid physics backend (rapier3d-f64), seed {}", s.seed),
    );
    rec.set_meta("model", profile.model_name());
    rec.set_meta("theta_map", format!("{:?}", profile.theta()));
    let active = s.effects.active();
    rec.set_meta(
        "effects",
        if active.is_empty() {
            "none".to_string()
        } else {
            format!("{:?}", s.effects)
        },
    );
    rec.set_meta("jitter", format!("{}", s.jitter));
    rec.set_meta("command_hold", "zoh");
    rec.set_timing(s.timing);
    Ok(rec)
}
