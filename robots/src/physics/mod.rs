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
use wheelid_core::{
    Error, Odometry, Pose, Recording, Result, Robot, RobotError, Timing, VelocitySampling,
};

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

/// The physics robot as a host drives it: sample, send, advance to the next sample instant.
///
/// As a [`Robot`] (read, then send): `read` reports at the current sample instant — v, ω from
/// the wheels, instants under (a), window averages since the last report under (b) and (c)
/// (through the trait a report cannot wait for the window after the command, so a run records
/// (c) as (b): [`Robot::timing`] says which); `send` queues the command (after the latency
/// effect) and advances the physics to the next sample instant. The clock is the simulation's.
pub struct PhysicsRobot {
    p: PhysicalProfile,
    s: PhysicsSettings,
    engine: Engine,
    drive: Drive,
    steps: Vec<usize>,
    /// Index of the current sample instant in `steps`, and the current physics step.
    k: usize,
    j: usize,
    queue: std::collections::VecDeque<(f64, (f64, f64))>,
    command: (f64, f64),
    setpoint: (f64, f64),
    angle: [f64; 2],
    rates: [f64; 2],
    /// Reported wheel angles at the last read (for window averages) and its time.
    last_read: Option<(f64, [f64; 2])>,
    noise: Option<(ChaCha8Rng, Normal<f64>)>,
}

impl std::fmt::Debug for PhysicsRobot {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PhysicsRobot")
            .field("profile", &self.p.name)
            .field("t", &self.time())
            .finish_non_exhaustive()
    }
}

impl PhysicsRobot {
    /// The robot at rest at the origin; sample instants for `s.duration_s` (a robot driven by
    /// `wheelid run` longer than that keeps sampling at the nominal period).
    ///
    /// # Errors
    /// [`Error::InvalidSetting`] for a bad profile or settings (see
    /// [`simulate_physics_recording`]).
    pub fn new(p: &PhysicalProfile, s: &PhysicsSettings) -> Result<Self> {
        validate(p, s)?;
        let engine = Engine::new(p, s.effects.floor_mu.unwrap_or(FLOOR_MU));
        let mut rng = ChaCha8Rng::seed_from_u64(s.seed);
        let n = (s.duration_s / p.period_s).floor() as usize + 2;
        let steps = sample_steps(n, p.period_s, p.physics_step_s, s.jitter, &mut rng);
        let noise = (s.wheel_noise_std > 0.0)
            .then(|| Normal::new(0.0, s.wheel_noise_std).ok())
            .flatten()
            .map(|n| (ChaCha8Rng::seed_from_u64(s.seed.wrapping_add(0x5eed)), n));
        let rates = engine.wheel_rates();
        Ok(Self {
            p: p.clone(),
            s: s.clone(),
            drive: Drive::new(p),
            engine,
            steps,
            k: 0,
            j: 0,
            queue: Default::default(),
            command: (0.0, 0.0),
            setpoint: (0.0, 0.0),
            angle: [0.0; 2],
            rates,
            last_read: None,
            noise,
        })
    }

    /// Simulation time [s].
    pub fn time(&self) -> f64 {
        self.j as f64 * self.p.physics_step_s
    }

    /// The physical profile.
    pub fn profile(&self) -> &PhysicalProfile {
        &self.p
    }

    /// The step index of the sample instant after the current one.
    fn next_sample_step(&self) -> usize {
        match self.steps.get(self.k + 1) {
            Some(&j) => j,
            None => self.j + (self.p.period_s / self.p.physics_step_s).round().max(1.0) as usize,
        }
    }

    /// What the host sees now: wheel angles (quantised if encoders are on), rates, pose.
    fn sample(&self) -> Raw {
        let tick = 2.0 * std::f64::consts::PI / self.p.ticks_per_rev;
        let body = self.engine.body();
        Raw {
            t: self.time(),
            command: self.command,
            angle: if self.s.encoders {
                self.angle.map(|a| (a / tick).floor() * tick)
            } else {
                self.angle
            },
            rate: self.rates,
            pose: [body.x, body.y, body.heading],
        }
    }

    /// Sends `u` at the current sample instant and advances to the next one.
    fn advance(&mut self, u: (f64, f64)) {
        let h = self.p.physics_step_s;
        let latency = self.s.effects.latency_s.unwrap_or(0.0);
        self.queue.push_back((self.time() + latency, u));
        let until = self.next_sample_step();
        let fx = self.s.effects.clone();
        while self.j < until {
            let t = self.time();
            while self.queue.front().is_some_and(|(at, _)| *at <= t + 0.5 * h) {
                if let Some((_, c)) = self.queue.pop_front() {
                    self.command = c;
                }
            }
            self.setpoint = fx.limit_rate(self.setpoint, self.command, h);
            let mid = self.drive.midpoint(self.rates);
            let v = self.drive.voltages(self.setpoint, mid, h);
            let v = fx.amplify(v, t / self.s.duration_s.max(h));
            let tau = self.drive.torques(v, mid);
            let fr = fx.friction(mid);
            self.engine.step([tau[0] + fr[0], tau[1] + fr[1]]);
            let new = self.engine.wheel_rates();
            for ((a, r0), r1) in self.angle.iter_mut().zip(self.rates).zip(new) {
                *a += 0.5 * h * (r0 + r1);
            }
            self.rates = new;
            self.j += 1;
        }
        self.k += 1;
    }

    /// A reported wheel speed [m/s] from a wheel rate [rad/s], with the noise if any.
    fn wheel_speed(&mut self, rate: f64) -> f64 {
        let noise = match &mut self.noise {
            Some((rng, n)) => n.sample(rng),
            None => 0.0,
        };
        rate * self.p.r + noise
    }
}

impl Robot for PhysicsRobot {
    fn name(&self) -> &str {
        "physics"
    }
    fn period_s(&self) -> f64 {
        self.p.period_s
    }
    fn velocity_sampling(&self) -> VelocitySampling {
        self.s.timing.velocity_sampling()
    }
    fn timing(&self) -> Option<Timing> {
        Some(match self.s.timing {
            Timing::Instant => Timing::Instant,
            Timing::WindowEnd | Timing::WindowMiddle => Timing::WindowEnd,
        })
    }
    fn send(&mut self, v_ref: f64, w_ref: f64) -> std::result::Result<(f64, f64), RobotError> {
        if !(v_ref.is_finite() && w_ref.is_finite()) {
            return Err(RobotError::Setting(format!(
                "command ({v_ref}, {w_ref}) is not finite"
            )));
        }
        self.advance((v_ref, w_ref));
        Ok((v_ref, w_ref))
    }
    fn read(&mut self) -> std::result::Result<Odometry, RobotError> {
        let raw = self.sample();
        let rates = match (self.s.timing, self.last_read) {
            (Timing::Instant, _) | (_, None) => raw.rate,
            (_, Some((t0, a0))) => [0, 1].map(|i| (raw.angle[i] - a0[i]) / (raw.t - t0)),
        };
        self.last_read = Some((raw.t, raw.angle));
        let (vr, vl) = (self.wheel_speed(rates[0]), self.wheel_speed(rates[1]));
        Ok(Odometry {
            t: raw.t,
            v: 0.5 * (vr + vl),
            w: (vr - vl) / self.p.d,
            pose: Pose {
                x: raw.pose[0],
                y: raw.pose[1],
                heading: raw.pose[2],
            },
        })
    }
}

/// Runs the robot under `excitation` from rest and returns what the host saw at each sample.
fn run_host(p: &PhysicalProfile, exc: &Excitation, s: &PhysicsSettings) -> Result<Vec<Raw>> {
    let mut robot = PhysicsRobot::new(p, s)?;
    let n = robot.steps.len();
    let mut raws = Vec::with_capacity(n);
    for _ in 0..n {
        let mut raw = robot.sample();
        let u = exc.at(raw.t);
        raw.command = u;
        raws.push(raw);
        robot.advance(u);
    }
    Ok(raws)
}

/// Checks a profile and settings.
fn validate(profile: &PhysicalProfile, s: &PhysicsSettings) -> Result<()> {
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
    Ok(())
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
    let raws = run_host(profile, excitation, s)?;
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
