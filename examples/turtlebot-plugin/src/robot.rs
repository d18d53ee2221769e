//! The robot `turtlebot3`: a simulated TurtleBot3 Burger.
//!
//! # Dynamics
//! The state of the axle centre, integrated by classical RK4 at `substeps` steps per period
//! under the command held since the last `send` (zero-order hold):
//! ```text
//! ẋ = v cos ψ      ẏ = v sin ψ      ψ̇ = ω      φ̇_r,l = (v ± d ω/2)/r
//! θ1 v̇ = v_ref + θ3 ω² − θ4 v − v_coulomb sgn_ε(v)
//! θ2 ω̇ = ω_ref − θ5 v ω − θ6 ω − w_coulomb sgn_ε(ω)
//! ```
//! — exactly the model `vw-pd-coulomb` ([`crate::model`]), with the Burger's θ and friction by
//! default ([`crate::burger`]).
//!
//! # Commands
//! [`Robot::send`] clamps the request as the Burger does and returns the clamped command,
//! which is the one the dynamics act on (and the one to record): v_ref to ±`v_max`, ω_ref to
//! ±`w_max` (the OpenCR firmware's `constrain` of `cmd_vel` to the published maxima), then
//! each wheel's speed reference v_ref ± d ω_ref/2 to ±`wheel_speed_max` (what the motors can
//! turn: the two published maxima are one wheel-speed limit, 0.22 m/s ≈ 2.84 rad/s × 0.08 m).
//! A non-finite request is refused.
//!
//! # Reports
//! [`Robot::read`] advances one period and reports, at t_k = k Δt (the first report at Δt,
//! the robot having started at rest at the origin, heading 0):
//! * v, ω from the two wheels' **instantaneous** speeds as the XL430 reports them in its
//!   `Present Velocity` register: the true wheel speed plus Gaussian noise of
//!   `encoder_noise_std` [m/s at the rim], rounded to the register's unit of 0.229 rev/min
//!   (0.79 mm/s at the rim); v = (v_r + v_l)/2, ω = (v_r − v_l)/d. A recording of them is
//!   `velocity_sampling: instant` (wheelid's default);
//! * the pose by odometry from the wheels' encoder ticks (4096 per revolution, the XL430's
//!   12-bit encoder): Δs = r(Δφ_r + Δφ_l)/2, Δψ = r(Δφ_r − Δφ_l)/d, advanced along the
//!   mid-period heading; the heading is never wrapped.
//!
//! Deterministic: the same settings (seed included) and commands give the same reports.

use serde::Deserialize;
use wheelid_core::{Error, Odometry, Pose, Result, Robot, RobotError};

use crate::burger::{self, BURGER};
use crate::model::{FRICTION_EPS, sgn};

/// The `[robot]` table of `type = "turtlebot3"`; every key is optional (defaults: the Burger).
///
/// ```toml
/// [robot]
/// type = "turtlebot3"
/// period_s = 0.0333333   # 30 Hz, the OpenCR firmware's motor-control rate
/// seed = 7
/// encoder_noise_std = 0.0015
/// theta = [0.15, 0.15, 0.0, 1.05, 0.0, 1.05]
/// v_coulomb = 0.002
/// w_coulomb = 0.025
/// ```
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TurtleBotSettings {
    /// The table's `type` key (`"turtlebot3"` when the host passes its table): the host
    /// routes by it; accepted here and not otherwise used.
    #[serde(rename = "type")]
    pub kind: Option<String>,
    /// Control and report period Δt \[s\] (default 1/30 s, [`burger::PERIOD_S`]).
    pub period_s: f64,
    /// Seed of the measurement noise.
    pub seed: u64,
    /// Standard deviation of the noise on each wheel's reported speed [m/s at the rim]
    /// (default 1 mm/s, about one `Present Velocity` unit; 0 for none).
    pub encoder_noise_std: f64,
    /// θ1…θ6 of eq. 2.19 [s, s, s·m/rad², -, s/m, -] (default the Burger's,
    /// [`burger::WheelPdPhysics::theta`] of [`BURGER`]).
    pub theta: [f64; 6],
    /// Dry friction of the forward channel in command units [m/s] (default the Burger's).
    pub v_coulomb: f64,
    /// Dry friction of the rotational channel in command units [rad/s] (default the Burger's).
    pub w_coulomb: f64,
    /// Largest |v_ref| accepted [m/s] (default 0.22, the Burger's maximum).
    pub v_max: f64,
    /// Largest |ω_ref| accepted [rad/s] (default 2.84, the Burger's maximum).
    pub w_max: f64,
    /// Largest wheel speed reference [m/s at the rim] (default 2.84 × 0.160/2 = 0.2272).
    pub wheel_speed_max: f64,
    /// RK4 steps per period (default 20).
    pub substeps: usize,
}

impl Default for TurtleBotSettings {
    fn default() -> Self {
        let [v_coulomb, w_coulomb] = BURGER.coulomb();
        Self {
            kind: None,
            period_s: burger::PERIOD_S,
            seed: 1,
            encoder_noise_std: 0.001,
            theta: BURGER.theta(),
            v_coulomb,
            w_coulomb,
            v_max: burger::V_MAX,
            w_max: burger::W_MAX,
            wheel_speed_max: burger::W_MAX * burger::TRACK / 2.0,
            substeps: 20,
        }
    }
}

impl TurtleBotSettings {
    /// Parses a `[robot]` table given as TOML text (its `type` key included or not).
    ///
    /// # Errors
    /// [`Error::InvalidSetting`] naming the bad or unknown key in backquotes (which the host
    /// turns into its line in the config file), or the check of
    /// [`TurtleBotSettings::validate`].
    pub fn from_toml(text: &str) -> Result<Self> {
        let s: Self = toml::from_str(text)
            .map_err(|e| Error::InvalidSetting(crate::table_error(TurtleBot::NAME, text, &e)))?;
        s.validate()?;
        Ok(s)
    }

    /// The eight parameters of the robot's dynamics, in the order of the model
    /// `vw-pd-coulomb`: θ1…θ6, v_coulomb, w_coulomb.
    pub fn model_theta(&self) -> [f64; 8] {
        let [t1, t2, t3, t4, t5, t6] = self.theta;
        [t1, t2, t3, t4, t5, t6, self.v_coulomb, self.w_coulomb]
    }

    /// Checks the settings: a positive period, maxima and sub-step count, finite θ with
    /// θ1, θ2 > 0, non-negative friction and noise.
    ///
    /// # Errors
    /// [`Error::InvalidSetting`] naming the first bad key.
    pub fn validate(&self) -> Result<()> {
        let bad = |key: &str, x: f64, need: &str| {
            Err(Error::InvalidSetting(format!(
                "turtlebot3: {key} = {x} must be {need}"
            )))
        };
        for (key, x) in [
            ("`period_s`", self.period_s),
            ("`v_max`", self.v_max),
            ("`w_max`", self.w_max),
            ("`wheel_speed_max`", self.wheel_speed_max),
            ("`theta`[0] (θ1)", self.theta[0]),
            ("`theta`[1] (θ2)", self.theta[1]),
        ] {
            if !(x.is_finite() && x > 0.0) {
                return bad(key, x, "finite and > 0");
            }
        }
        for (key, x) in [
            ("`encoder_noise_std`", self.encoder_noise_std),
            ("`v_coulomb`", self.v_coulomb),
            ("`w_coulomb`", self.w_coulomb),
        ] {
            if !(x.is_finite() && x >= 0.0) {
                return bad(key, x, "finite and ≥ 0");
            }
        }
        if let Some(i) = self.theta.iter().position(|x| !x.is_finite()) {
            return bad(&format!("`theta`[{i}]"), self.theta[i], "finite");
        }
        if self.substeps == 0 {
            return bad("`substeps`", 0.0, "≥ 1");
        }
        Ok(())
    }
}

/// The text of a settings error, for a factory's answer: the message alone (the host adds the
/// file, line and section).
pub fn error_message(e: Error) -> String {
    match e {
        Error::InvalidSetting(m) => m,
        other => other.to_string(),
    }
}

/// SplitMix64 (Steele, Lea & Flood 2014): a small, fast, seedable generator, with Gaussian
/// draws by Box–Muller. The plugin's own, so that it needs no random-number crate.
#[derive(Debug, Clone)]
struct SplitMix64(u64);

impl SplitMix64 {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform on the open interval (0, 1).
    fn uniform(&mut self) -> f64 {
        ((self.next_u64() >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }
    /// Standard normal.
    fn normal(&mut self) -> f64 {
        let (u1, u2) = (self.uniform(), self.uniform());
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }
}

/// Index of each quantity in the integrated state.
const X: usize = 0;
const Y: usize = 1;
const PSI: usize = 2;
const V: usize = 3;
const W: usize = 4;
const PHI_R: usize = 5;
const PHI_L: usize = 6;

/// The simulated TurtleBot3 Burger (module docs).
#[derive(Debug, Clone)]
pub struct TurtleBot {
    settings: TurtleBotSettings,
    theta: [f64; 8],
    rng: SplitMix64,
    /// Reports made so far.
    k: u64,
    /// True state: x, y, ψ, v, ω of the axle centre, wheel angles φ_r, φ_l \[rad\].
    state: [f64; 7],
    /// Encoder ticks (right, left) at the last report.
    ticks: [f64; 2],
    /// Odometry pose (x, y, ψ).
    odom: [f64; 3],
    /// The command in force (as clamped).
    command: (f64, f64),
}

impl TurtleBot {
    /// The name under which the plugin registers it (the `[robot] type`).
    pub const NAME: &'static str = "turtlebot3";

    /// A Burger at rest at the origin, heading 0, with zero command.
    ///
    /// # Errors
    /// As [`TurtleBotSettings::validate`].
    pub fn new(settings: TurtleBotSettings) -> Result<Self> {
        settings.validate()?;
        Ok(Self {
            theta: settings.model_theta(),
            rng: SplitMix64(settings.seed),
            settings,
            k: 0,
            state: [0.0; 7],
            ticks: [0.0; 2],
            odom: [0.0; 3],
            command: (0.0, 0.0),
        })
    }

    /// A Burger from its `[robot]` table as TOML text ([`TurtleBotSettings::from_toml`]).
    ///
    /// # Errors
    /// As [`TurtleBotSettings::from_toml`].
    pub fn from_toml(text: &str) -> Result<Self> {
        Self::new(TurtleBotSettings::from_toml(text)?)
    }

    /// The settings in use.
    pub fn settings(&self) -> &TurtleBotSettings {
        &self.settings
    }

    /// The true parameters, in the order of the model `vw-pd-coulomb` (θ1…θ6, v_coulomb,
    /// w_coulomb).
    pub fn theta(&self) -> [f64; 8] {
        self.theta
    }

    /// The true state at the last report: x \[m\], y \[m\], ψ \[rad\], v [m/s], ω [rad/s] of the
    /// axle centre.
    pub fn true_state(&self) -> [f64; 5] {
        let s = &self.state;
        [s[X], s[Y], s[PSI], s[V], s[W]]
    }

    /// The request (v_ref [m/s], ω_ref [rad/s]) as the Burger acts on it: clamped per channel,
    /// then per wheel (module docs).
    pub fn clamp(&self, v_ref: f64, w_ref: f64) -> (f64, f64) {
        let s = &self.settings;
        let half = burger::TRACK / 2.0;
        let v = v_ref.clamp(-s.v_max, s.v_max);
        let w = w_ref.clamp(-s.w_max, s.w_max);
        let lim = s.wheel_speed_max;
        let (vr, vl) = (v + half * w, v - half * w);
        if vr.abs() <= lim && vl.abs() <= lim {
            return (v, w);
        }
        let (vr, vl) = (vr.clamp(-lim, lim), vl.clamp(-lim, lim));
        (0.5 * (vr + vl), (vr - vl) / burger::TRACK)
    }

    /// Derivative of the state under the command u.
    fn rhs(&self, s: &[f64; 7], u: (f64, f64)) -> [f64; 7] {
        let [t1, t2, t3, t4, t5, t6, vc, wc] = self.theta;
        let (v, w, psi) = (s[V], s[W], s[PSI]);
        let (sn, cs) = psi.sin_cos();
        let half = burger::TRACK / 2.0;
        [
            v * cs,
            v * sn,
            w,
            (u.0 + t3 * w * w - t4 * v - vc * sgn(v, FRICTION_EPS[0])) / t1,
            (u.1 - t5 * v * w - t6 * w - wc * sgn(w, FRICTION_EPS[1])) / t2,
            (v + half * w) / burger::WHEEL_RADIUS,
            (v - half * w) / burger::WHEEL_RADIUS,
        ]
    }

    /// Advances the true state by one period under the command in force.
    fn advance(&mut self) {
        let h = self.settings.period_s / self.settings.substeps as f64;
        let u = self.command;
        for _ in 0..self.settings.substeps {
            let s = self.state;
            let k1 = self.rhs(&s, u);
            let s2 = std::array::from_fn(|i| s[i] + 0.5 * h * k1[i]);
            let k2 = self.rhs(&s2, u);
            let s3 = std::array::from_fn(|i| s[i] + 0.5 * h * k2[i]);
            let k3 = self.rhs(&s3, u);
            let s4 = std::array::from_fn(|i| s[i] + h * k3[i]);
            let k4 = self.rhs(&s4, u);
            self.state = std::array::from_fn(|i| {
                s[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
            });
        }
    }

    /// What the wheels report now: v, ω from the `Present Velocity` registers, and the
    /// odometry pose advanced by the encoder ticks since the last report.
    fn measure(&mut self) -> (f64, f64, Pose) {
        let (r, d) = (burger::WHEEL_RADIUS, burger::TRACK);
        let s = self.state;
        let unit = burger::XL430_VELOCITY_UNIT * r;
        let noise = self.settings.encoder_noise_std;
        let mut reported = |rim: f64| {
            let noisy = if noise > 0.0 {
                rim + noise * self.rng.normal()
            } else {
                rim
            };
            (noisy / unit).round() * unit
        };
        let vr = reported(s[V] + 0.5 * d * s[W]);
        let vl = reported(s[V] - 0.5 * d * s[W]);
        let rad_per_tick = std::f64::consts::TAU / burger::XL430_TICKS_PER_REV;
        let ticks = [s[PHI_R], s[PHI_L]].map(|a| (a / rad_per_tick).floor());
        let dphi = [0, 1].map(|i| (ticks[i] - self.ticks[i]) * rad_per_tick);
        self.ticks = ticks;
        let ds = r * (dphi[0] + dphi[1]) / 2.0;
        let dpsi = r * (dphi[0] - dphi[1]) / d;
        let mid = self.odom[2] + 0.5 * dpsi;
        self.odom[0] += ds * mid.cos();
        self.odom[1] += ds * mid.sin();
        self.odom[2] += dpsi;
        let pose = Pose {
            x: self.odom[0],
            y: self.odom[1],
            heading: self.odom[2],
        };
        (0.5 * (vr + vl), (vr - vl) / d, pose)
    }
}

/// The Burger as a robot backend: `read` advances one period under the command last sent
/// (zero before the first `send`) and reports at t_k = k Δt; `send` clamps (module docs),
/// holds and returns the clamped command.
impl Robot for TurtleBot {
    fn name(&self) -> &str {
        Self::NAME
    }
    fn period_s(&self) -> f64 {
        self.settings.period_s
    }
    fn send(&mut self, v_ref: f64, w_ref: f64) -> std::result::Result<(f64, f64), RobotError> {
        if !(v_ref.is_finite() && w_ref.is_finite()) {
            return Err(RobotError::Setting(format!(
                "turtlebot3: command ({v_ref}, {w_ref}) is not finite"
            )));
        }
        self.command = self.clamp(v_ref, w_ref);
        Ok(self.command)
    }
    fn read(&mut self) -> std::result::Result<Odometry, RobotError> {
        self.advance();
        self.k += 1;
        let (v, w, pose) = self.measure();
        Ok(Odometry {
            t: self.k as f64 * self.settings.period_s,
            v,
            w,
            pose,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;
    use wheelid_core::Recording;

    #[test]
    fn settings_default_to_the_burger_and_reject_unknown_keys() {
        let s = TurtleBotSettings::from_toml("type = \"turtlebot3\"\n").expect("defaults");
        assert_eq!(s.theta, BURGER.theta());
        assert_eq!(s.period_s, 1.0 / 30.0);
        // Without the type key too, and with a few keys set.
        let s = TurtleBotSettings::from_toml("seed = 9\nperiod_s = 0.05\nv_coulomb = 0.01\n")
            .expect("parses");
        assert_eq!((s.seed, s.period_s, s.v_coulomb), (9, 0.05, 0.01));
        let message = |text: &str| {
            TurtleBotSettings::from_toml(text).map_or_else(error_message, |s| format!("{s:?}"))
        };
        let msg = message("type = \"turtlebot3\"\nencoder_noise = 0.1\n");
        assert_eq!(
            msg,
            "turtlebot3: unknown field `encoder_noise`, expected one of `type`, `period_s`, \
             `seed`, `encoder_noise_std`, `theta`, `v_coulomb`, `w_coulomb`, `v_max`, `w_max`, \
             `wheel_speed_max`, `substeps`"
        );
        // A bad value names its key first, in backquotes, for the host to find its line.
        let msg = message("type = \"turtlebot3\"\nseed = \"seven\"\n");
        assert!(msg.starts_with("turtlebot3: `seed`: invalid type"), "{msg}");
        let msg = message("theta = [0.0, 0.15, 0.0, 1.0, 0.0, 1.0]");
        assert_eq!(
            msg,
            "turtlebot3: `theta`[0] (θ1) = 0 must be finite and > 0"
        );
        for bad in [
            "period_s = 0.0",
            "theta = [0.0, 0.15, 0.0, 1.0, 0.0, 1.0]",
            "v_coulomb = -0.1",
            "substeps = 0",
            "theta = [0.15, 0.15]",
            "seed = \"seven\"",
        ] {
            assert!(TurtleBotSettings::from_toml(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn send_clamps_like_the_burger_and_refuses_nan() {
        let mut bot = TurtleBot::new(TurtleBotSettings::default()).expect("bot");
        assert_eq!(bot.send(0.1, 0.5).expect("ok"), (0.1, 0.5));
        // v and ω are each within their maxima, but the outer wheel would need 0.3 m/s.
        let (v, w) = bot.send(0.2, 1.25).expect("ok");
        assert_abs_diff_eq!(v + 0.08 * w, 0.2272, epsilon = 1e-12);
        assert_abs_diff_eq!(v - 0.08 * w, 0.1, epsilon = 1e-12);
        // Per channel first: 0.5 m/s → 0.22; then the wheels.
        assert_eq!(bot.send(0.5, 0.0).expect("ok"), (0.22, 0.0));
        let (v, w) = bot.send(0.0, -9.0).expect("ok");
        assert_abs_diff_eq!(v, 0.0, epsilon = 1e-15);
        assert_abs_diff_eq!(w, -2.84, epsilon = 1e-12);
        assert!(bot.send(f64::NAN, 0.0).is_err());
        assert_eq!(bot.name(), "turtlebot3");
    }

    /// The first steps of the robot against its own model: read, then send, as a host does;
    /// the model simulates the recorded commands from rest.
    #[test]
    fn first_steps_follow_the_model() {
        let settings = TurtleBotSettings {
            encoder_noise_std: 0.0,
            ..TurtleBotSettings::default()
        };
        let mut bot = TurtleBot::new(settings).expect("bot");
        let dt = bot.period_s();
        let (mut t, mut vr, mut wr, mut v, mut w) =
            (vec![0.0], vec![], vec![], vec![0.0], vec![0.0]);
        let mut truth = vec![[0.0; 5]];
        let mut poses = vec![];
        // Row 0 is the start (t = 0, at rest); the command after it is the first send.
        let cmd = |k: usize| (0.15 + 0.05 * (0.3 * k as f64).sin(), 1.5 - 0.04 * k as f64);
        let (a, b) = bot.send(cmd(0).0, cmd(0).1).expect("send");
        vr.push(a);
        wr.push(b);
        for k in 1..=60 {
            let o = bot.read().expect("read");
            assert_abs_diff_eq!(o.t, k as f64 * dt, epsilon = 1e-12);
            let (a, b) = bot.send(cmd(k).0, cmd(k).1).expect("send");
            t.push(o.t);
            vr.push(a);
            wr.push(b);
            v.push(o.v);
            w.push(o.w);
            truth.push(bot.true_state());
            poses.push(o.pose);
        }
        let rec = Recording::new("first steps", t, vr, wr, v.clone(), w.clone()).expect("ok");
        let [sv, sw] = crate::model::simulate(&bot.theta(), &rec, &[0.0, 0.0]).expect("sim");
        let unit = burger::XL430_VELOCITY_UNIT * burger::WHEEL_RADIUS;
        for k in 0..rec.len() {
            // The true state is the model's to integration accuracy: the model steps 11 ms,
            // the robot 1.7 ms, and they part where a speed crosses the friction's ε band
            // (2 mm/s, 0.01 rad/s) in a few milliseconds — v at the start from rest, ω as its
            // command sweeps through zero — by ~1e-5 m/s and ~1e-4 rad/s, far below the noise …
            assert_abs_diff_eq!(truth[k][3], sv[k], epsilon = 2e-5);
            assert_abs_diff_eq!(truth[k][4], sw[k], epsilon = 2e-4);
            // … and the reports are it to the register's resolution (half a unit per wheel).
            assert!((v[k] - sv[k]).abs() <= 0.5 * unit + 1e-12, "k {k}");
            assert!((w[k] - sw[k]).abs() <= unit / burger::TRACK + 2e-4, "k {k}");
        }
        // A first-order response: after 2 s at ~0.15 m/s it is near (v_ref − v_c)/θ4.
        assert!(sv[60] > 0.1 && sv[60] < 0.2, "{}", sv[60]);
        // Odometry: within a few ticks of the true pose after 2 s of turning (ω through 0).
        let last = truth[60];
        let p = poses[59];
        assert!(
            (p.x - last[0]).abs() < 2e-3 && (p.y - last[1]).abs() < 2e-3,
            "{p:?} {last:?}"
        );
        assert!((p.heading - last[2]).abs() < 0.02, "{p:?} {last:?}");
        assert!(p.heading > 0.4, "it turned: {p:?}");
    }

    #[test]
    fn heading_is_unwrapped_and_runs_are_deterministic() {
        let run = |seed: u64| {
            let mut bot = TurtleBot::new(TurtleBotSettings {
                seed,
                ..TurtleBotSettings::default()
            })
            .expect("bot");
            let mut out = vec![];
            for _ in 0..300 {
                let o = bot.read().expect("read");
                bot.send(0.0, 2.5).expect("send");
                out.push(o);
            }
            out
        };
        let (a, b, c) = (run(3), run(3), run(4));
        assert_eq!(a, b);
        assert_ne!(a, c);
        // 10 s spinning at ~2.4 rad/s: about 24 rad of heading, never wrapped.
        let last = a[a.len() - 1];
        assert!(last.pose.heading > 20.0, "{last:?}");
        // The noise is there, and about as large as set (1 mm/s per wheel → ω: √2·1e-3/0.16).
        let tail: Vec<f64> = a[100..].iter().map(|o| o.w).collect();
        let mean = tail.iter().sum::<f64>() / tail.len() as f64;
        let sd = (tail.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / tail.len() as f64).sqrt();
        assert!((0.005..0.015).contains(&sd), "{sd}");
    }
}
