//! The simulated robot: the 5-state model of eq. 2.19 integrated at a fine step, driven by
//! commands held (zero-order hold) over the robot's period, measured through its encoders.
//!
//! ```text
//! ẋ = v cos ψ − a ω sin ψ      ẏ = v sin ψ + a ω cos ψ      ψ̇ = ω
//! v̇ = (θ3/θ1) ω² − (θ4/θ1) v + (1/θ1) v_ref
//! ω̇ = −(θ5/θ2) v ω − (θ6/θ2) ω + (1/θ2) ω_ref                         (eq. 2.19)
//! ```
//!
//! (x, y) is the point h at distance `a` ahead of the axle ([`RobotProfile::a`]), ψ the
//! heading. The state is advanced with classical fourth-order Runge–Kutta at `substeps` steps
//! per period, and the optional [`Effects`] act inside that loop (see [`crate::effects`]).
//!
//! Measurement model ([`SimSettings::measurement_noise`] = true), per period Δt: each wheel's
//! angle is integrated exactly (trapezoid of the sub-step wheel speeds (v ± dω/2)/r), turned into
//! whole encoder ticks, and the tick difference over the period gives the wheel speed averaged
//! over the period (as a base controller computes it); Gaussian noise is added and the result
//! rounded to the reported resolution (1 mm/s for a Pioneer SIP). v = (v_r + v_l)/2 and
//! ω = (v_r − v_l)/d follow. Pose by odometry from the same ticks (eq. 3.2–3.3, with the
//! second-order Runge–Kutta heading φ̄ = φ + Δφ/2). Without the measurement model the robot
//! reports its exact v, ω and pose.

use std::collections::VecDeque;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};
use wheelid_core::{Error, Odometry, Pose, Recording, Result, Robot, RobotError};

use crate::effects::Effects;
use crate::excitation::Excitation;
use crate::profile::RobotProfile;

/// Simulation settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SimSettings {
    /// Duration \[s\] (for [`simulate_recording`]).
    pub duration_s: f64,
    /// Random seed for the noise and jitter.
    pub seed: u64,
    /// Integration sub-steps per period.
    pub substeps: usize,
    /// Whether to apply the encoder model and noise (false: exact instantaneous v, ω, pose;
    /// the `measurement_noise` effect, if on, still adds its noise to v, ω).
    pub measurement_noise: bool,
    /// Optional physics the 6-θ model leaves out (all off by default).
    pub effects: Effects,
}

impl Default for SimSettings {
    fn default() -> Self {
        Self {
            duration_s: 150.0,
            seed: 1,
            substeps: 50,
            measurement_noise: true,
            effects: Effects::default(),
        }
    }
}

impl SimSettings {
    /// Checks `duration_s` is finite and > 0 (what [`simulate_recording`] and
    /// [`crate::simulate_model_recording`] drive for).
    ///
    /// # Errors
    /// [`Error::InvalidSetting`] naming it.
    pub fn check_duration(&self) -> Result<()> {
        if self.duration_s.is_finite() && self.duration_s > 0.0 {
            Ok(())
        } else {
            Err(Error::InvalidSetting(format!(
                "duration_s = {} must be > 0",
                self.duration_s
            )))
        }
    }
}

/// What the robot reports at one sample instant.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Sample {
    /// Time \[s\].
    pub t: f64,
    /// Measured forward velocity [m/s] (window average over the last period with encoders).
    pub v: f64,
    /// Measured angular velocity [rad/s].
    pub w: f64,
    /// Pose x of the point h \[m\] (odometry with encoders).
    pub x: f64,
    /// Pose y of the point h \[m\].
    pub y: f64,
    /// Heading \[rad\] (unwrapped).
    pub phi: f64,
}

/// Smoothing of the Coulomb friction's sign: 2 mm/s and 0.01 rad/s.
const FRICTION_EPS: [f64; 2] = [0.002, 0.01];

/// A simulated differential-drive robot: send (v_ref, ω_ref), advance one period, read what its
/// sensors report. Deterministic for a given seed.
#[derive(Debug, Clone)]
pub struct SimRobot {
    profile: RobotProfile,
    effects: Effects,
    substeps: usize,
    encoders: bool,
    rng: ChaCha8Rng,
    wheel_noise: Normal<f64>,
    /// Current sample index and time \[s\].
    k: usize,
    t: f64,
    /// True state (x, y, ψ, v, ω), (x, y) the point h.
    s: [f64; 5],
    /// Wheel angles, ticks and odometry.
    enc: Encoders,
    /// Commands waiting for their delay: (time they take effect, v_ref, ω_ref).
    queue: VecDeque<(f64, f64, f64)>,
    /// The command in force after the delay.
    command: [f64; 2],
    /// The (rate-limited) setpoint the base follows.
    setpoint: [f64; 2],
    last: Sample,
    /// The command last given through [`Robot::send`].
    sent: (f64, f64),
}

impl SimRobot {
    /// A robot at rest with the point h at the origin, heading 0; its odometry starts there too
    /// (the axle centre `a` behind h, at (−a, 0)), so the first samples measure the true pose.
    ///
    /// # Errors
    /// [`Error::InvalidSetting`] for a bad θ, profile number, sub-step count or effect.
    pub fn new(profile: &RobotProfile, settings: &SimSettings) -> Result<Self> {
        wheelid_models::dynamics::check_theta(&profile.theta)?;
        settings.effects.validate()?;
        let wheel_noise = profile.measurement()?;
        if settings.substeps == 0 {
            return Err(Error::InvalidSetting("substeps must be ≥ 1".into()));
        }
        let mut robot = Self {
            profile: profile.clone(),
            effects: settings.effects.clone(),
            substeps: settings.substeps,
            encoders: settings.measurement_noise,
            rng: ChaCha8Rng::seed_from_u64(settings.seed),
            wheel_noise,
            k: 0,
            t: 0.0,
            s: [0.0; 5],
            enc: Encoders::default(),
            queue: VecDeque::new(),
            command: [0.0; 2],
            setpoint: [0.0; 2],
            last: Sample {
                t: 0.0,
                v: 0.0,
                w: 0.0,
                x: 0.0,
                y: 0.0,
                phi: 0.0,
            },
            sent: (0.0, 0.0),
        };
        robot.enc.odom = robot.axle_pose(&robot.s);
        robot.t = robot.jitter(0);
        robot.last.t = robot.t;
        Ok(robot)
    }

    /// Places the robot: the point h at (x, y), heading ψ \[rad\], velocities v [m/s], ω [rad/s];
    /// odometry restarts from there, and the setpoint in force is the one that holds (v, ω)
    /// steady (θ4 v − θ3 ω², θ6 ω + θ5 v ω), so a rate limit does not brake a robot placed at
    /// speed. Call before the first [`SimRobot::step`].
    pub fn set_state(&mut self, state: [f64; 5]) {
        self.s = state;
        let [x, y, psi, v, w] = state;
        let th = self.theta_at(self.t);
        self.command = [th[3] * v - th[2] * w * w, th[5] * w + th[4] * v * w];
        self.setpoint = self.command;
        self.enc.odom = self.axle_pose(&state);
        self.last = Sample {
            t: self.t,
            v,
            w,
            x,
            y,
            phi: psi,
        };
    }

    /// The pose (x, y, ψ) of the axle centre in `state`, whose (x, y) is the point h `a` ahead
    /// of it: where the odometry starts.
    fn axle_pose(&self, state: &[f64; 5]) -> [f64; 3] {
        let [x, y, psi, ..] = *state;
        let a = self.profile.a;
        [x - a * psi.cos(), y - a * psi.sin(), psi]
    }

    /// The robot's profile.
    pub fn profile(&self) -> &RobotProfile {
        &self.profile
    }

    /// Nominal sample period \[s\].
    pub fn period_s(&self) -> f64 {
        self.profile.period_s
    }

    /// The true state (x, y, ψ, v, ω) at the current sample instant.
    pub fn true_state(&self) -> [f64; 5] {
        self.s
    }

    /// What the sensors reported at the current sample instant.
    pub fn sample(&self) -> Sample {
        self.last
    }

    /// The θ in force at time `t` (the payload changes it).
    pub fn theta_at(&self, t: f64) -> [f64; 6] {
        match self.effects.payload_change {
            Some(p) if t >= p.time_s => p.theta_after,
            _ => self.profile.theta,
        }
    }

    /// Sample instant k: kΔt plus the jitter (one draw per call when jitter is on).
    fn jitter(&mut self, k: usize) -> f64 {
        let dt = self.profile.period_s;
        let e = match self.effects.sample_jitter {
            Some(j) if j.std_s > 0.0 => {
                let z: f64 = rand_distr::StandardNormal.sample(&mut self.rng);
                (z * j.std_s).clamp(-0.45 * dt, 0.45 * dt)
            }
            _ => 0.0,
        };
        k as f64 * dt + e
    }

    /// The setpoint the velocity loop follows at time `tau`, after delay, saturation, rate
    /// limit (over a sub-step `h`), wheel asymmetry and gain drift.
    fn setpoint_at(&mut self, tau: f64, h: f64) -> [f64; 2] {
        while let Some(&(t_on, v, w)) = self.queue.front() {
            if t_on > tau + 1e-9 * self.profile.period_s {
                break;
            }
            self.command = [v, w];
            self.queue.pop_front();
        }
        let mut target = self.command;
        if let Some(s) = self.effects.velocity_saturation {
            target[0] = target[0].clamp(-s.v_max, s.v_max);
            target[1] = target[1].clamp(-s.w_max, s.w_max);
        }
        // The rate-limited setpoint slews over the sub-step; the sub-step is driven by its mean
        // (the ramp's midpoint value), second-order accurate like the RK4 around it.
        let [mut uv, mut uw] = match self.effects.acceleration_limit {
            Some(l) => {
                let before = self.setpoint;
                for (i, a) in [l.v_accel_max, l.w_accel_max].into_iter().enumerate() {
                    self.setpoint[i] += (target[i] - self.setpoint[i]).clamp(-a * h, a * h);
                }
                [0, 1].map(|i| 0.5 * (before[i] + self.setpoint[i]))
            }
            None => {
                self.setpoint = target;
                target
            }
        };
        if let Some(a) = self.effects.wheel_asymmetry {
            let d = self.profile.track;
            let (gr, gl) = (2.0 * a.ratio / (1.0 + a.ratio), 2.0 / (1.0 + a.ratio));
            let (vr, vl) = (gr * (uv + d * uw / 2.0), gl * (uv - d * uw / 2.0));
            uv = (vr + vl) / 2.0;
            uw = (vr - vl) / d;
        }
        [uv, uw]
    }

    /// The drive gain g at time `tau` \[s\] (`gain_drift`: 1 + rate_per_s · τ; else 1).
    fn drive_gain(&self, tau: f64) -> f64 {
        self.effects
            .gain_drift
            .map_or(1.0, |g| 1.0 + g.rate_per_s * tau)
    }

    /// Derivative of the state under setpoint `u`, parameters `th` and drive gain `g` (the
    /// loop's effort g (u − v), g (u_ω − ω); module docs).
    #[inline]
    fn f(&self, s: &[f64; 5], u: [f64; 2], th: &[f64; 6], g: f64) -> [f64; 5] {
        let [_, _, psi, v, w] = *s;
        let (sn, cs) = psi.sin_cos();
        let a = self.profile.a;
        let mut fv = g * u[0] + th[2] * w * w - (th[3] - 1.0 + g) * v;
        let mut fw = g * u[1] - th[4] * v * w - (th[5] - 1.0 + g) * w;
        if let Some(c) = self.effects.coulomb_friction {
            fv -= c.v_coulomb * (v / FRICTION_EPS[0]).tanh();
            fw -= c.w_coulomb * (w / FRICTION_EPS[1]).tanh();
        }
        if let Some(sl) = self.effects.slip {
            fv -= th[3] * sl.k_v * v * w.abs();
            fw -= th[5] * sl.k_w * v.abs() * w;
        }
        [
            v * cs - a * w * sn,
            v * sn + a * w * cs,
            w,
            fv / th[0],
            fw / th[1],
        ]
    }

    /// Sends the command (v_ref [m/s], ω_ref [rad/s]) at the current sample instant, holds it
    /// for one period, and returns what the sensors report at the next instant.
    pub fn step(&mut self, v_ref: f64, w_ref: f64) -> Sample {
        let t0 = self.t;
        let t1 = self.jitter(self.k + 1);
        let delay = self.effects.input_delay.map_or(0.0, |d| d.delay_s);
        self.queue.push_back((t0 + delay, v_ref, w_ref));
        let h = (t1 - t0) / self.substeps as f64;
        let (r, d) = (self.profile.wheel_radius, self.profile.track);
        for i in 0..self.substeps {
            let tau = t0 + i as f64 * h;
            let u = self.setpoint_at(tau, h);
            let th = self.theta_at(tau);
            let g = self.drive_gain(tau + 0.5 * h);
            let s = self.s;
            let k1 = self.f(&s, u, &th, g);
            let s2 = std::array::from_fn(|j| s[j] + 0.5 * h * k1[j]);
            let k2 = self.f(&s2, u, &th, g);
            let s3 = std::array::from_fn(|j| s[j] + 0.5 * h * k2[j]);
            let k3 = self.f(&s3, u, &th, g);
            let s4 = std::array::from_fn(|j| s[j] + h * k3[j]);
            let k4 = self.f(&s4, u, &th, g);
            let s1: [f64; 5] = std::array::from_fn(|j| {
                s[j] + h / 6.0 * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j])
            });
            if self.encoders {
                let (v0, w0, v1, w1) = (s[3], s[4], s1[3], s1[4]);
                self.enc.ang[0] += h * 0.5 * ((v0 + d * w0 / 2.0) + (v1 + d * w1 / 2.0)) / r;
                self.enc.ang[1] += h * 0.5 * ((v0 - d * w0 / 2.0) + (v1 - d * w1 / 2.0)) / r;
            }
            self.s = s1;
        }
        self.t = t1;
        self.k += 1;
        self.last = self.measure(t1 - t0);
        self.last
    }

    /// The sensor reading at the current instant, `dt` after the previous one.
    fn measure(&mut self, dt: f64) -> Sample {
        let [x, y, psi, v, w] = self.s;
        let mut out = Sample {
            t: self.t,
            v,
            w,
            x,
            y,
            phi: psi,
        };
        if self.encoders {
            let m = self
                .enc
                .read(&self.profile, dt, &mut self.rng, &self.wheel_noise);
            [out.v, out.w, out.x, out.y, out.phi] = m;
        }
        if let Some(n) = self.effects.measurement_noise {
            let z: [f64; 2] = [0, 1].map(|_| rand_distr::StandardNormal.sample(&mut self.rng));
            out.v += n.v_std * z[0];
            out.w += n.w_std * z[1];
        }
        out
    }
}

/// The encoders and the odometry of the module docs' measurement model: each wheel's angle
/// (right, left) \[rad\] as the caller integrates it, the whole ticks counted at the last
/// sample, and the odometry pose (x, y, φ) of the axle centre (eq. 3.2–3.3).
#[derive(Debug, Clone, Default)]
pub(crate) struct Encoders {
    /// Wheel angles (right, left) \[rad\].
    pub(crate) ang: [f64; 2],
    /// Ticks counted at the last sample.
    ticks: [f64; 2],
    /// Odometry pose of the axle centre (x [m], y [m], φ [rad]).
    pub(crate) odom: [f64; 3],
}

impl Encoders {
    /// The reading `dt` [s] after the previous one on the robot `p`: wheel speeds from the
    /// tick differences (window averages), with Gaussian `noise` [m/s] (right, then left,
    /// drawn from `rng`) and rounded to `p.speed_resolution`; returns (v [m/s], ω [rad/s],
    /// x [m], y [m], φ [rad]) with the pose of the point h, `p.a` ahead of the axle.
    pub(crate) fn read(
        &mut self,
        p: &RobotProfile,
        dt: f64,
        rng: &mut ChaCha8Rng,
        noise: &Normal<f64>,
    ) -> [f64; 5] {
        let (r, d) = (p.wheel_radius, p.track);
        let rad_per_tick = 2.0 * std::f64::consts::PI / p.ticks_per_rev;
        let ticks = self.ang.map(|a| (a / rad_per_tick).floor());
        let dphi = [0, 1].map(|i| (ticks[i] - self.ticks[i]) * rad_per_tick);
        self.ticks = ticks;
        let quant = |x: f64| {
            if p.speed_resolution > 0.0 {
                (x / p.speed_resolution).round() * p.speed_resolution
            } else {
                x
            }
        };
        let sr = quant(dphi[0] * r / dt + noise.sample(rng));
        let sl = quant(dphi[1] * r / dt + noise.sample(rng));
        // Odometry, eq. 3.2–3.3.
        let ds = r * (dphi[0] + dphi[1]) / 2.0;
        let dth = r * (dphi[0] - dphi[1]) / d;
        let mid = self.odom[2] + dth / 2.0;
        self.odom[0] += ds * mid.cos();
        self.odom[1] += ds * mid.sin();
        self.odom[2] += dth;
        let [ox, oy, oth] = self.odom;
        [
            (sr + sl) / 2.0,
            (sr - sl) / d,
            ox + p.a * oth.cos(),
            oy + p.a * oth.sin(),
            oth,
        ]
    }
}

/// The simulator as a robot backend (`[robot] type = "simulator"`): `read` advances one period
/// ([`SimRobot::step`]) under the command last sent (zero before the first `send`) and reports
/// what the encoders measured, stamped with the simulation's time (the first `read` reports
/// t_1 ≈ Δt, the robot having started at t_0 = 0 at rest); `send` holds the command for the next
/// `read` and returns it unchanged: the simulated base acts on exactly what it is given (its
/// [`Effects`] — saturation, delay, rate limit, … — are physics to identify, not a protocol's
/// rounding).
impl Robot for SimRobot {
    fn name(&self) -> &str {
        "simulator"
    }
    fn period_s(&self) -> f64 {
        self.profile.period_s
    }
    /// Window averages with the encoder model, instants without it.
    fn velocity_sampling(&self) -> wheelid_core::VelocitySampling {
        if self.encoders {
            wheelid_core::VelocitySampling::WindowAverage
        } else {
            wheelid_core::VelocitySampling::Instant
        }
    }
    /// The simulated state's (x, y, φ) of the point h.
    fn true_pose(&self) -> Option<Pose> {
        let [x, y, heading, _, _] = self.s;
        Some(Pose { x, y, heading })
    }
    /// Holds (v_ref, ω_ref) for the next period and returns it unchanged.
    fn send(&mut self, v_ref: f64, w_ref: f64) -> std::result::Result<(f64, f64), RobotError> {
        self.sent = (v_ref, w_ref);
        Ok(self.sent)
    }
    fn read(&mut self) -> std::result::Result<Odometry, RobotError> {
        let s = self.step(self.sent.0, self.sent.1);
        Ok(Odometry {
            t: s.t,
            v: s.v,
            w: s.w,
            pose: Pose {
                x: s.x,
                y: s.y,
                heading: s.phi,
            },
        })
    }
}

/// Simulates `profile` under `excitation` from rest at the origin and returns the recording
/// (t, v_ref, ω_ref, v, ω, x, y, φ at each sample instant; the command at t_k is held until
/// t_{k+1}). The metadata name the robot, seed, true θ and active effects, with
/// `command_hold: zoh` and `timing: window_end` (encoders; `velocity_sampling:
/// window_average`) or `timing: instant`.
///
/// # Errors
/// As [`SimRobot::new`], or if the recording is invalid (e.g. a non-finite state from an
/// unstable θ).
pub fn simulate_recording(
    profile: &RobotProfile,
    excitation: &Excitation,
    s: &SimSettings,
) -> Result<Recording> {
    s.check_duration()?;
    let mut robot = SimRobot::new(profile, s)?;
    let n = (s.duration_s / profile.period_s).floor() as usize + 1;
    let mut cols: [Vec<f64>; 8] = std::array::from_fn(|_| Vec::with_capacity(n));
    let mut m = robot.sample();
    for k in 0..n {
        let (vr, wr) = excitation.at(m.t);
        for (c, val) in cols
            .iter_mut()
            .zip([m.t, vr, wr, m.v, m.w, m.x, m.y, m.phi])
        {
            c.push(val);
        }
        if k + 1 < n {
            m = robot.step(vr, wr);
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
    let active = s.effects.active();
    rec.set_meta(
        "effects",
        if active.is_empty() {
            "none".to_string()
        } else {
            format!("{:?}", s.effects)
        },
    );
    rec.set_meta("command_hold", "zoh");
    // Encoders count over the period that ends at the sample, and the command sent at the
    // sample holds until the next: convention (b); exact states are (a).
    rec.set_timing(if s.measurement_noise {
        wheelid_core::Timing::WindowEnd
    } else {
        wheelid_core::Timing::Instant
    });
    Ok(rec)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn as_a_robot_it_steps_like_step_with_the_command_it_returned() {
        let profile = RobotProfile::pioneer3dx();
        let settings = SimSettings::default();
        let mut direct = SimRobot::new(&profile, &settings).expect("robot");
        let mut boxed: Box<dyn Robot> =
            Box::new(SimRobot::new(&profile, &settings).expect("robot"));
        assert_eq!(boxed.name(), "simulator");
        assert_eq!(boxed.period_s(), profile.period_s);
        // Read, then decide, then send: report k answers the command sent after report k − 1
        // (zero before the first send).
        let mut command = (0.0, 0.0);
        for k in 1..=30 {
            let o = boxed.read().expect("read");
            let s = direct.step(command.0, command.1);
            assert_eq!((o.t, o.v, o.w), (s.t, s.v, s.w), "k = {k}");
            assert_eq!((o.pose.x, o.pose.y, o.pose.heading), (s.x, s.y, s.phi));
            assert!((o.t - k as f64 * profile.period_s).abs() < 1e-12);
            let (v_ref, w_ref) = (0.3 * (k as f64 * 0.2).sin(), 0.5);
            command = boxed.send(v_ref, w_ref).expect("send");
            assert_eq!(
                command,
                (v_ref, w_ref),
                "the simulator acts on the command as sent"
            );
        }
        assert!(
            direct.true_state()[2] > 0.5,
            "it turned: {:?}",
            direct.true_state()
        );
        // The command holds until the next send; stop sends zero.
        boxed.stop().expect("stop");
        for _ in 0..100 {
            boxed.read().expect("read");
        }
        let o = boxed.read().expect("read");
        assert!(o.v.abs() < 0.01 && o.w.abs() < 0.02, "{o:?}");
    }

    /// With the tracked point h ahead of the axle (a ≠ 0), the odometry starts where the true
    /// state is: the first samples of a robot at rest, then driving straight ahead, measure the
    /// true x, y to the encoder resolution (no jump by `a` at the first sample).
    #[test]
    fn odometry_starts_at_the_true_pose_when_h_is_ahead_of_the_axle() {
        let profile = RobotProfile {
            a: 0.1,
            ..RobotProfile::pioneer3dx()
        };
        let tick = 2.0 * std::f64::consts::PI * profile.wheel_radius / profile.ticks_per_rev;
        for settings in [
            SimSettings::default(),
            SimSettings {
                seed: 5,
                ..SimSettings::default()
            },
        ] {
            let mut robot = SimRobot::new(&profile, &settings).expect("robot");
            let close = |robot: &SimRobot, k: usize| {
                let (s, m) = (robot.true_state(), robot.sample());
                // One tick per wheel of travel, and the heading it makes over the lever a.
                let tol = 2.0 * tick * (1.0 + profile.a / profile.track);
                assert!(
                    (m.x - s[0]).abs() <= tol && (m.y - s[1]).abs() <= tol,
                    "sample {k}: measured ({}, {}), true ({}, {})",
                    m.x,
                    m.y,
                    s[0],
                    s[1]
                );
            };
            close(&robot, 0);
            for k in 1..=5 {
                robot.step(0.0, 0.0);
                close(&robot, k);
            }
            for k in 6..=30 {
                robot.step(0.3, 0.0);
                close(&robot, k);
            }
            assert!(robot.true_state()[0] > 0.1, "{:?}", robot.true_state());
        }
    }
}
