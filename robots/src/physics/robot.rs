//! The physics robot as a host drives it, one sample period at a time: the link (command
//! latency), the onboard setpoint rate limiter, the drive (controller, amplifier, motors), the
//! wheel joints' dry friction, the engine, and the encoders.
//!
//! Within a period the host's command is held; the physics advances in steps of h, and at each
//! step
//!
//! ```text
//! command  ← the latest host command whose arrival time (sent + latency) has passed
//! setpoint ← rate-limited step toward the command (if the limiter is on)
//! u        ← controller(setpoint, wheel rates at the step's midpoint)        [V]
//!            (or, with a controller period, updated at its instants and held: `drive`)
//! u        ← amplifier(u, t): gain sag, one amplifier's gain, voltage clamp  [V]
//! τ_i      ← k_a (u_i − k_b ω_i)/R_a − B_e ω_i − dry friction(ω_i)           [N·m]
//! engine   ← τ on each wheel about its axle, −Σ τ on the chassis; one step
//! angle_i  ← angle_i + h (ω_i,old + ω_i,new)/2                               (the encoder's shaft)
//! ```
//!
//! The host reads the encoders' angles and rates as they were a sensor delay ago (none by
//! default; the last physics step at least that old) and the chassis's true pose as it is.
//!
//! A payload effect puts its body on the chassis at the first step at or after its time.

use std::collections::VecDeque;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use wheelid_core::{Odometry, Pose, Result, Robot, RobotError, Timing, VelocitySampling};

use super::drive::Drive;
use super::encoder::Encoders;
use super::engine::Engine;
use super::host::{Raw, sample_steps};
use super::{PhysicalProfile, PhysicsSettings, validate};

/// The physics robot: a rigid-body differential-drive robot with its onboard controller,
/// sampled by a host at instants s_k = kΔ + jitter (on the physics grid).
///
/// As a [`Robot`] (read, then send): `read` reports at the current sample instant — v, ω from
/// the wheels through the encoders, instants under (a), window averages since the last report
/// under (b) and (c) (through the trait a report cannot wait for the window after the command,
/// so a run records (c) as (b): [`Robot::timing`] says which); `send` queues the command
/// (after the latency effect) and advances the physics to the next sample instant. The clock
/// is the simulation's: t = (physics steps taken) × h.
pub struct PhysicsRobot {
    p: PhysicalProfile,
    s: PhysicsSettings,
    engine: Engine,
    drive: Drive,
    encoders: Encoders,
    /// Sample instants as physics-step indices.
    pub(super) steps: Vec<usize>,
    /// Index of the current sample instant in `steps`, and the current physics step.
    k: usize,
    j: usize,
    /// Commands on the link: (arrival time \[s\], (v_ref, ω_ref)).
    queue: VecDeque<(f64, (f64, f64))>,
    command: (f64, f64),
    setpoint: (f64, f64),
    /// Encoder shaft angles (right, left) \[rad\], exact.
    angle: [f64; 2],
    rates: [f64; 2],
    /// Reported wheel angles at the last read (for window averages) and its time.
    last_read: Option<(f64, [f64; 2])>,
    payload_placed: bool,
    /// With a sensor delay: (time \[s\], encoder angles, rates) at every physics step back to
    /// the delay, oldest first.
    history: VecDeque<(f64, [f64; 2], [f64; 2])>,
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
    /// The robot at rest at the origin, heading +x; sample instants for `s.duration_s` (a
    /// robot driven by `wheelid run` longer than that keeps sampling at the nominal period).
    ///
    /// # Errors
    /// [`wheelid_core::Error::InvalidSetting`] for a bad profile or settings (see
    /// [`super::simulate_physics_recording`]).
    pub fn new(p: &PhysicalProfile, s: &PhysicsSettings) -> Result<Self> {
        validate(p, s)?;
        let engine = Engine::new(p, &s.effects);
        let mut rng = ChaCha8Rng::seed_from_u64(s.seed);
        let n = (s.duration_s / p.period_s).floor() as usize + 2;
        let steps = sample_steps(n, p.period_s, p.physics_step_s, s.jitter, &mut rng);
        let encoders = Encoders::new(p.ticks_per_rev, s.encoders, s.wheel_noise_std, s.seed)?;
        let rates = engine.wheel_rates();
        Ok(Self {
            p: p.clone(),
            s: s.clone(),
            drive: Drive::new(p),
            engine,
            encoders,
            steps,
            k: 0,
            j: 0,
            queue: VecDeque::new(),
            command: (0.0, 0.0),
            setpoint: (0.0, 0.0),
            angle: [0.0; 2],
            rates,
            last_read: None,
            payload_placed: false,
            history: VecDeque::from([(0.0, [0.0; 2], rates)]),
        })
    }

    /// Simulation time \[s\].
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

    /// What the host sees now: encoder angles and instantaneous wheel rates (as they were a
    /// sensor delay ago), the true pose.
    pub(super) fn sample(&self) -> Raw {
        let body = self.engine.body();
        let (angle, rate) = self.encoder_state();
        Raw {
            t: self.time(),
            command: self.command,
            angle: self.encoders.read(angle),
            rate,
            pose: [body.x, body.y, body.heading],
        }
    }

    /// The encoders' shaft angles and rates the host reads now: the current ones, or with a
    /// sensor delay those of the last physics step at least that long ago (the first one
    /// before).
    fn encoder_state(&self) -> ([f64; 2], [f64; 2]) {
        let Some(delay) = self.s.effects.sensor_delay_s.filter(|&d| d > 0.0) else {
            return (self.angle, self.rates);
        };
        let at = self.time() - delay + 0.5 * self.p.physics_step_s;
        let i = self.history.partition_point(|e| e.0 <= at).max(1);
        let (_, angle, rate) = self.history[i - 1];
        (angle, rate)
    }

    /// Sends `u` at the current sample instant and advances to the next one.
    pub(super) fn advance(&mut self, u: (f64, f64)) {
        let latency = self.s.effects.latency_s.unwrap_or(0.0);
        self.queue.push_back((self.time() + latency, u));
        let until = self.next_sample_step();
        while self.j < until {
            self.step();
        }
        self.k += 1;
    }

    /// One physics step (module docs).
    fn step(&mut self) {
        let h = self.p.physics_step_s;
        let t = self.time();
        let fx = &self.s.effects;
        while self.queue.front().is_some_and(|(at, _)| *at <= t + 0.5 * h) {
            if let Some((_, c)) = self.queue.pop_front() {
                self.command = c;
            }
        }
        if let Some(payload) = fx
            .payload
            .filter(|pl| !self.payload_placed && pl.at_s <= t + 0.5 * h)
        {
            self.engine.place_payload(&payload);
            self.payload_placed = true;
        }
        self.setpoint = fx.limit_rate(self.setpoint, self.command, h);
        let (u, mid) = self.drive.control(self.setpoint, self.rates, h);
        let u = fx.amplify(u, t, self.s.duration_s);
        let tau = self.drive.torques(u, mid);
        let fr = fx.friction(mid);
        self.engine.step([tau[0] + fr[0], tau[1] + fr[1]]);
        let new = self.engine.wheel_rates();
        for ((a, r0), r1) in self.angle.iter_mut().zip(self.rates).zip(new) {
            *a += 0.5 * h * (r0 + r1);
        }
        self.rates = new;
        self.j += 1;
        if let Some(delay) = self.s.effects.sensor_delay_s.filter(|&d| d > 0.0) {
            self.history
                .push_back((self.time(), self.angle, self.rates));
            let keep = self.time() - delay - 2.0 * h;
            while self.history.len() > 1 && self.history[1].0 <= keep {
                self.history.pop_front();
            }
        }
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
    /// The chassis's pose at the axle centre (the engine's, exact).
    fn true_pose(&self) -> Option<Pose> {
        let b = self.engine.body();
        Some(Pose {
            x: b.x,
            y: b.y,
            heading: b.heading,
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
        let vr = self.encoders.speed(rates[0], self.p.r);
        let vl = self.encoders.speed(rates[1], self.p.r);
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
