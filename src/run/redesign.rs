//! The commands of a drive, and re-designing them on the way (issue 18, sequential
//! identification; a run config's `[design]` table).
//!
//! A drive asks its [`CommandSource`] for the command at each sample. A fixed excitation
//! answers from its own clock. A [`Redesigner`] starts from a design ([`crate::design`]) for a
//! prior θ, and every `every_s` of driving, once the online estimator is settled, designs again
//! from the current θ̂ on another thread; the new commands take over `lag_s` of drive time
//! after the design started (the drive waits for the design there if it is not done: on a
//! simulated robot the run is then the same whatever the machine's speed; a real robot's
//! loop is never held while the design runs). A new design keeps the robot inside the given
//! rectangle (centred on the start, along its heading) from the pose and speeds the robot will
//! have when it takes over ([`DesignSettings::start_pose`], [`DesignSettings::start_velocity`]:
//! eq. 2.19 with θ̂ run under the commands in force for the lag). Where no design
//! fits (near a wall), the commands in force go on. With slope limits the commands are rate
//! limited, so a switch never steps beyond them.

use std::sync::Arc;
use std::thread::JoinHandle;

use serde::Deserialize;
use wheelid_core::{Odometry, Pose, RegressorModel};
use wheelid_robots::Excitation;

use crate::design::{DesignSettings, design};
use crate::online::OnlineTheta;

/// What a drive sends: the command at drive time `t` \[s\] (from the first sample), given
/// the online estimator (if any) and what the robot reported there.
pub trait CommandSource {
    /// (v_ref [m/s], ω_ref [rad/s]) at `t`.
    fn command(&mut self, t: f64, online: Option<&OnlineTheta>, o: &Odometry) -> (f64, f64);
}

impl CommandSource for Excitation {
    fn command(&mut self, t: f64, _online: Option<&OnlineTheta>, _o: &Odometry) -> (f64, f64) {
        self.at(t)
    }
}

/// `[design]` in a run config: the excitation designed from a prior and re-designed on the
/// way from the online θ̂ (needs `stop_when = "accuracy"`, whose `accuracy` the designs aim
/// at for θ1, θ2, θ4, θ6).
///
/// ```toml
/// [design]
/// prior = [0.26, 0.25, 0.0, 1.0, 0.0, 1.08]  # θ of the first design (without [excitation])
/// command_max = [0.4, 1.2]                   # largest |v_ref| [m/s], |ω_ref| [rad/s]
/// space_m = [3.0, 3.0]                       # floor rectangle centred on the start [m]
/// every_s = 10.0                             # re-design period of drive time [s]
/// ```
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DesignSection {
    /// θ1…θ6 of the first design; without it the run's `[excitation]` is driven until the
    /// first re-design.
    pub prior: Option<[f64; 6]>,
    /// Largest |v_ref| \[m/s\] and |ω_ref| \[rad/s\].
    pub command_max: [f64; 2],
    /// Largest slopes |v̇_ref| \[m/s²\], |ω̇_ref| \[rad/s²\] (default: none).
    #[serde(default = "no_slope_limit")]
    pub slope_max: [f64; 2],
    /// The floor rectangle's sides along x, y \[m\], centred on the start (default 4 × 4).
    #[serde(default = "four_metres")]
    pub space_m: [f64; 2],
    /// White noise of the measured v \[m/s\] and ω \[rad/s\] the designs assume (default
    /// [`DesignSettings::for_robot`]'s).
    pub noise_std: Option<[f64; 2]>,
    /// Drive time between re-designs \[s\] (default 10 s, the designs' period).
    #[serde(default = "ten_seconds")]
    pub every_s: f64,
    /// Drive time from a design's start to its commands taking over \[s\] (default 1 s).
    #[serde(default = "one_second")]
    pub lag_s: f64,
}

fn no_slope_limit() -> [f64; 2] {
    [f64::INFINITY; 2]
}
fn four_metres() -> [f64; 2] {
    [4.0, 4.0]
}
fn ten_seconds() -> f64 {
    10.0
}
fn one_second() -> f64 {
    1.0
}

/// The design settings of `section` aiming at `accuracy` for a robot sampled every `dt_s`,
/// for θ `theta` (from the space's centre, facing +x, at rest).
fn settings(section: &DesignSection, accuracy: f64, dt_s: f64, theta: [f64; 6]) -> DesignSettings {
    let mut s = DesignSettings::for_robot(theta, dt_s, section.command_max);
    s.slope_max = section.slope_max;
    s.space_m = section.space_m;
    // The run's accuracy is a 95 % half-width; the design's a relative standard error.
    s.accuracy = accuracy / 1.96;
    if let Some(n) = section.noise_std {
        s.noise_std = n;
    }
    s
}

/// One re-design of a drive.
#[derive(Debug, Clone, PartialEq)]
pub struct RedesignEvent {
    /// Drive time the design started \[s\].
    pub started_s: f64,
    /// The θ̂ it was designed for.
    pub theta: [f64; 6],
    /// Where it started in the space: x, y \[m\] from the centre, ψ \[rad\].
    pub start_pose: [f64; 3],
    /// Drive time its commands took over \[s\], and the highest line \[Hz\]; or why there was
    /// no new design (the commands in force went on).
    pub outcome: Result<(f64, f64), String>,
}

/// A design running on another thread: when it started, for which θ̂, from where.
struct Pending {
    started_s: f64,
    theta: [f64; 6],
    start_pose: [f64; 3],
    handle: JoinHandle<wheelid_core::Result<crate::design::Design>>,
}

/// A [`CommandSource`] that re-designs its excitation on the way (module docs).
pub struct Redesigner {
    section: DesignSection,
    accuracy: f64,
    dt_s: f64,
    model: Arc<dyn RegressorModel>,
    /// The commands in force and the drive time they started \[s\].
    current: (Excitation, f64),
    next_s: f64,
    pending: Option<Pending>,
    /// The start pose (the space's centre), once known.
    start: Option<Pose>,
    last: Option<(f64, f64, f64)>,
    /// Every re-design so far.
    pub events: Vec<RedesignEvent>,
}

impl Redesigner {
    /// The re-designer of `section` aiming at `accuracy` for a robot sampled every `dt_s`,
    /// designing for `model`; it starts with `initial` (a run's `[excitation]`) or, with a
    /// prior, the design for it.
    ///
    /// # Errors
    /// Neither a prior nor an initial excitation; a design for the prior that fails (its
    /// settings, or no excitation fits the space); `every_s` or `lag_s` not positive, or
    /// `lag_s` ≥ `every_s`.
    pub fn new(
        section: DesignSection,
        accuracy: f64,
        dt_s: f64,
        model: Arc<dyn RegressorModel>,
        initial: Option<Excitation>,
    ) -> anyhow::Result<Self> {
        let (e, l) = (section.every_s, section.lag_s);
        if !(e.is_finite() && l.is_finite() && l > 0.0 && l < e) {
            anyhow::bail!("[design]: every_s = {e} and lag_s = {l} need 0 < lag_s < every_s");
        }
        let first = match (section.prior, initial) {
            (Some(prior), _) => {
                let s = settings(&section, accuracy, dt_s, prior);
                design(model.as_ref(), &s)?.excitation
            }
            (None, Some(e)) => e,
            (None, None) => anyhow::bail!("[design]: no prior and no [excitation] to start from"),
        };
        Ok(Self {
            accuracy,
            dt_s,
            model,
            current: (first, 0.0),
            next_s: e,
            pending: None,
            start: None,
            last: None,
            events: Vec::new(),
            section,
        })
    }

    /// The pose in the space's frame (centred on the start, x along its heading): x, y \[m\],
    /// ψ \[rad\].
    fn in_space(&self, pose: &Pose) -> [f64; 3] {
        let start = self.start.unwrap_or(*pose);
        let (sn, cs) = start.heading.sin_cos();
        let (dx, dy) = (pose.x - start.x, pose.y - start.y);
        [
            dx * cs + dy * sn,
            -dx * sn + dy * cs,
            pose.heading - start.heading,
        ]
    }

    /// The robot's pose (x, y, ψ in the space's frame) and (v, ω) `lag_s` after `t`, predicted
    /// by eq. 2.19 with `theta` from the report `o` under the commands in force (RK2 on a tenth
    /// of the period; the unicycle pose by its midpoint heading).
    fn at_takeover(&self, t: f64, theta: &[f64; 6], o: &Odometry) -> ([f64; 3], [f64; 2]) {
        let [mut x, mut y, mut psi] = self.in_space(&o.pose);
        let (mut v, mut w) = (o.v, o.w);
        let (e, origin) = &self.current;
        let h = 0.1 * self.dt_s;
        let steps = (self.section.lag_s / h).ceil() as usize;
        for i in 0..steps {
            let tau = t + i as f64 * h;
            let (ur, wr) = e.at(tau - origin);
            let (a1, b1) = wheelid_models::dynamics::accel(theta, v, w, ur, wr);
            let (vm, wm) = (v + 0.5 * h * a1, w + 0.5 * h * b1);
            let (a2, b2) = wheelid_models::dynamics::accel(theta, vm, wm, ur, wr);
            let mid = psi + 0.5 * h * wm;
            x += h * vm * mid.cos();
            y += h * vm * mid.sin();
            psi += h * wm;
            v += h * a2;
            w += h * b2;
        }
        ([x, y, psi], [v, w])
    }

    /// Starts a design from the online θ̂ when one is due and usable.
    fn launch(&mut self, t: f64, online: &OnlineTheta, o: &Odometry) {
        let theta = online.theta();
        if !(online.settled() && theta.iter().all(|x| x.is_finite()) && theta[0] > 0.0) {
            return;
        }
        self.next_s = t + self.section.every_s;
        let mut s = settings(&self.section, self.accuracy, self.dt_s, theta);
        (s.start_pose, s.start_velocity) = self.at_takeover(t, &theta, o);
        let start_pose = s.start_pose;
        let model = Arc::clone(&self.model);
        let handle = std::thread::spawn(move || design(model.as_ref(), &s));
        self.pending = Some(Pending {
            started_s: t,
            theta,
            start_pose,
            handle,
        });
    }

    /// Takes the pending design over once its lag has passed (waiting for it if needed).
    fn take_over(&mut self, t: f64) {
        let due = self
            .pending
            .as_ref()
            .is_some_and(|p| t >= p.started_s + self.section.lag_s);
        let Some(p) = due.then(|| self.pending.take()).flatten() else {
            return;
        };
        let outcome = match p.handle.join() {
            Ok(Ok(d)) => {
                let f = d.f_max_hz;
                self.current = (d.excitation, t);
                Ok((t, f))
            }
            Ok(Err(e)) => Err(e.to_string()),
            Err(_) => Err("the design panicked".into()),
        };
        self.events.push(RedesignEvent {
            started_s: p.started_s,
            theta: p.theta,
            start_pose: p.start_pose,
            outcome,
        });
    }

    /// The commands rate limited to the slope limits from the last ones sent.
    fn limited(&mut self, t: f64, (v, w): (f64, f64)) -> (f64, f64) {
        let slew = |from: f64, to: f64, rate: f64, h: f64| {
            if rate.is_finite() {
                from + (to - from).clamp(-rate * h, rate * h)
            } else {
                to
            }
        };
        let out = match self.last {
            Some((t0, v0, w0)) => {
                let h = (t - t0).max(0.0);
                let [sv, sw] = self.section.slope_max;
                (slew(v0, v, sv, h), slew(w0, w, sw, h))
            }
            None => (v, w),
        };
        self.last = Some((t, out.0, out.1));
        out
    }
}

impl CommandSource for Redesigner {
    fn command(&mut self, t: f64, online: Option<&OnlineTheta>, o: &Odometry) -> (f64, f64) {
        self.start.get_or_insert(o.pose);
        self.take_over(t);
        if let Some(est) = online
            && self.pending.is_none()
            && t >= self.next_s
        {
            self.launch(t, est, o);
        }
        let (e, origin) = &self.current;
        let u = e.at(t - origin);
        self.limited(t, u)
    }
}

impl Drop for Redesigner {
    /// A design still running is waited for (it owns nothing but its settings).
    fn drop(&mut self) {
        if let Some(p) = self.pending.take() {
            let _ = p.handle.join();
        }
    }
}
