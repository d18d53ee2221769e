//! Controller migration between robots (Laut 2011, the thesis's title and §4.4: a control
//! strategy set up on one robot moved to another through the target's identified θ).
//!
//! A [`ControllerSpec`] is what an engineer tunes on a robot: the kinematic law (eq. 4.8,
//! gains k1 [1/s], k2 [1/m²], k3 [1/s]), the inverse-dynamics gains k_v, k_ω [1/s]
//! (eqs. 3.10–3.11), the adaptive law's γ (eq. 3.21) and which θ̂ adapt, the projection bounds
//! (eq. 4.9), the initial estimate θ̂(0) and the trajectory. [`migrate`] moves it from the robot
//! described by one [`RobotModel`] to another's and reports every choice with its reason
//! ([`Choice`]):
//!
//! ```text
//! θ̂(0)      = θ_to (identified), else the midpoint of the physical bounds (§4.1)
//! bounds    = θ_to ± max(4σ_i, ½|θ_i|), at least ±0.05 for θ3, θ5; θ1, θ2, θ4, θ6 ≥ θ_i/5 > 0
//! s         = v_max,to / v_max,from                  (length scale of the task)
//! path      = figure eight with lengths × s, f lowered until v ≤ ½ v_max, |ω| ≤ ½ ω_max and
//!             the path's accelerations ≤ ½ the diagnosed limits
//! k_v, k_ω  = from, but k Δt ≤ 0.5 (sampled loop) and k τ_d ≤ 0.3 (a dead time τ_d)
//! k1, k3    = from, but ≤ min(k_v, k_ω)/2 (the outer loop slower than the inner)
//! k2        = k2,from / s²                           (k2 v_d ỹ is a rate: v_d, ỹ ∝ s)
//! γ_i       = γ_i,from · (w_i,to / w_i,from) / c_i(s), w the bound half-widths,
//!             c = (s², 1, s, s², s, 1) the scale of column i of G times ṽ (eq. 3.21)
//! ```
//!
//! The migrated controller is checked by closed-loop tracking on the target ([`crate::track`],
//! [`crate::track_robot`]); the thesis shows why θ̂(0) matters (Figs 4.12 vs 4.16: adaptation
//! from θ̂ = 1 runs away on the Khepera, from the identified θ̂ it does not).

use serde::{Deserialize, Serialize};
use wheelid_core::{Error, Result};

use crate::control::{AdaptiveSettings, KinematicLaw};
use crate::profile::RobotProfile;
use crate::tracking::TrackSettings;
use crate::trajectory::{FigureEight, Trajectory, TrajectorySpec};

/// What is known of one robot for migration: its identified θ (and standard errors), its
/// sampling period and limits, and what a diagnosis found (acceleration limits, dead time).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotModel {
    /// The robot's name (a built-in profile's, or a recording's `# robot:`).
    pub robot: String,
    /// Identified θ1…θ6 (eq. 2.19); `None`: not identified (then `bounds` are needed).
    pub theta: Option<[f64; 6]>,
    /// Standard errors of `theta`; `None`: unknown (taken as 0).
    #[serde(default)]
    pub std_err: Option<[f64; 6]>,
    /// Physical bounds on θ (lower, upper), as §4.1 builds them from the robot's constants.
    #[serde(default)]
    pub bounds: Option<([f64; 6], [f64; 6])>,
    /// Control period Δt \[s\].
    pub period_s: f64,
    /// Speed limit [m/s] (a diagnosed `velocity_saturation` if lower).
    pub v_max: f64,
    /// Turn-rate limit [rad/s].
    pub w_max: f64,
    /// Acceleration limits (v̇ [m/s²], ω̇ [rad/s²]) a diagnosis found (`acceleration_limit`).
    #[serde(default)]
    pub accel_max: Option<[f64; 2]>,
    /// Dead time \[s\] a diagnosis found (`input_delay`).
    #[serde(default)]
    pub delay_s: Option<f64>,
}

impl RobotModel {
    /// A built-in profile with its θ as if identified exactly (no standard errors, no
    /// diagnosed limits).
    pub fn from_profile(p: &RobotProfile) -> Self {
        Self {
            robot: p.name.clone(),
            theta: Some(p.theta),
            std_err: None,
            bounds: None,
            period_s: p.period_s,
            v_max: p.v_max,
            w_max: p.w_max,
            accel_max: None,
            delay_s: None,
        }
    }

    /// The projection bounds (eq. 4.9) of the module docs: `bounds` if given, else around θ.
    ///
    /// # Errors
    /// [`Error::InvalidSetting`] when neither θ nor bounds are known.
    pub fn projection_bounds(&self) -> Result<([f64; 6], [f64; 6])> {
        if let Some(b) = self.bounds {
            return Ok(b);
        }
        let th = self.theta.ok_or_else(|| {
            Error::InvalidSetting(format!(
                "robot `{}`: neither an identified θ nor physical bounds",
                self.robot
            ))
        })?;
        let se = self.std_err.unwrap_or([0.0; 6]);
        let (mut lo, mut hi) = ([0.0; 6], [0.0; 6]);
        for i in 0..6 {
            let mut w = (4.0 * se[i]).max(0.5 * th[i].abs());
            if i == 2 || i == 4 {
                w = w.max(0.05);
            }
            lo[i] = th[i] - w;
            hi[i] = th[i] + w;
            if !(i == 2 || i == 4) {
                lo[i] = lo[i].max(th[i] / 5.0);
            }
        }
        Ok((lo, hi))
    }

    /// θ̂(0): the identified θ, else the midpoint of the bounds (§4.1).
    ///
    /// # Errors
    /// As [`RobotModel::projection_bounds`].
    pub fn theta_hat0(&self) -> Result<[f64; 6]> {
        match self.theta {
            Some(t) => Ok(t),
            None => {
                let (lo, hi) = self.projection_bounds()?;
                Ok(std::array::from_fn(|i| 0.5 * (lo[i] + hi[i])))
            }
        }
    }

    fn validate(&self) -> Result<()> {
        let ok = |x: f64| x.is_finite() && x > 0.0;
        if !(ok(self.period_s) && ok(self.v_max) && ok(self.w_max)) {
            return Err(Error::InvalidSetting(format!(
                "robot `{}`: period_s, v_max, w_max must be positive and finite",
                self.robot
            )));
        }
        Ok(())
    }
}

/// A trajectory-tracking controller as tuned on one robot (module docs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ControllerSpec {
    /// The robot it was set up on, if known (a warning when migrated from another).
    #[serde(default)]
    pub robot: Option<String>,
    /// Kinematic-law gains (eq. 4.8).
    pub kinematic: KinematicLaw,
    /// Inverse-dynamics gains, adaptation gains γ, frozen parameters, projection bounds.
    pub adaptation: AdaptiveSettings,
    /// Initial estimate θ̂(0).
    pub theta_hat0: [f64; 6],
    /// The trajectory.
    pub trajectory: TrajectorySpec,
}

impl ControllerSpec {
    /// The controller an engineer would set up on `model`'s robot: the default gains
    /// (k1 = 1, k2 = 4, k3 = 2, k_v = k_ω = 4), θ̂(0) = its θ, adaptation of θ1, θ2, θ3, θ5
    /// at γ = 1 inside its projection bounds (θ4, θ6 held, as §4.4), the figure eight preset
    /// for `profile`.
    ///
    /// # Errors
    /// As [`RobotModel::projection_bounds`].
    pub fn tuned_on(model: &RobotModel, profile: &RobotProfile) -> Result<Self> {
        let (lo, hi) = model.projection_bounds()?;
        Ok(Self {
            robot: Some(model.robot.clone()),
            kinematic: KinematicLaw::default(),
            adaptation: AdaptiveSettings {
                gamma: [1.0, 1.0, 1.0, 0.0, 1.0, 0.0],
                frozen: vec![4, 6],
                lower: Some(lo),
                upper: Some(hi),
                ..AdaptiveSettings::default()
            },
            theta_hat0: model.theta_hat0()?,
            trajectory: TrajectorySpec::for_profile(profile, false),
        })
    }

    /// Tracking settings for a run of `duration_s` with this controller (from rest, commands
    /// clipped to the robot's limits).
    pub fn track_settings(&self, duration_s: f64) -> TrackSettings {
        TrackSettings {
            duration_s,
            trajectory: Some(self.trajectory),
            kinematic: self.kinematic,
            theta_hat0: self.theta_hat0,
            adaptation: self.adaptation.clone(),
            ..TrackSettings::default()
        }
    }
}

/// One choice [`migrate`] made: what, the value before and after, and why.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Choice {
    /// The setting (`theta_hat0`, `k_v`, `trajectory`, …).
    pub item: String,
    /// Its value on the source.
    pub before: String,
    /// Its value on the target.
    pub after: String,
    /// Why.
    pub reason: String,
}

/// A migrated controller with the choices made and the warnings raised.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Migrated {
    /// The controller for the target.
    pub controller: ControllerSpec,
    /// Every choice with its reason, in the order of the module docs.
    pub choices: Vec<Choice>,
    /// Warnings (a controller tuned on another robot than the source model's, …).
    pub warnings: Vec<String>,
}

impl Migrated {
    fn choose(&mut self, item: &str, before: String, after: String, reason: String) {
        self.choices.push(Choice {
            item: item.into(),
            before,
            after,
            reason,
        });
    }
}

/// A figure eight in words: its lengths \[m\] and frequency [rad/s].
fn describe(t: &TrajectorySpec) -> String {
    let e = |e: &FigureEight| {
        format!(
            "figure eight A_x {:.3} m, A_y {:.3} m, f {:.3} rad/s",
            e.ax, e.ay, e.f
        )
    };
    match t {
        TrajectorySpec::FigureEight(f) => e(f),
        TrajectorySpec::FigureEightDither(d) => {
            format!("{} with dither g {:.4} m", e(&d.base), d.g)
        }
    }
}

fn fmt6(x: &[f64; 6]) -> String {
    let v: Vec<String> = x.iter().map(|x| format!("{x:.4}")).collect();
    format!("[{}]", v.join(", "))
}

/// Moves `ctrl`, set up on the robot of `from`, to the robot of `to` (module docs give every
/// rule). Does not run anything: check the result by tracking on the target.
///
/// # Errors
/// [`Error::InvalidSetting`] when a model has neither θ nor bounds, non-positive limits or
/// period, or the controller's settings are invalid.
pub fn migrate(ctrl: &ControllerSpec, from: &RobotModel, to: &RobotModel) -> Result<Migrated> {
    from.validate()?;
    to.validate()?;
    ctrl.adaptation.validate()?;
    ctrl.trajectory.validate()?;
    let mut m = Migrated {
        controller: ctrl.clone(),
        choices: Vec::new(),
        warnings: Vec::new(),
    };
    if let Some(r) = &ctrl.robot
        && r != &from.robot
    {
        m.warnings.push(format!(
            "the controller was set up on `{r}`, but the source model is `{}`'s",
            from.robot
        ));
    }
    if from.robot == to.robot {
        m.warnings.push(format!(
            "source and target are the same robot (`{}`)",
            to.robot
        ));
    }
    m.controller.robot = Some(to.robot.clone());
    migrate_theta(ctrl, from, to, &mut m)?;
    let s = to.v_max / from.v_max;
    migrate_path(ctrl, to, s, &mut m);
    migrate_gains(ctrl, to, s, &mut m);
    migrate_gamma(ctrl, from, to, s, &mut m)?;
    Ok(m)
}

/// θ̂(0) and the projection bounds.
fn migrate_theta(
    ctrl: &ControllerSpec,
    from: &RobotModel,
    to: &RobotModel,
    m: &mut Migrated,
) -> Result<()> {
    let th = to.theta_hat0()?;
    let why = if to.theta.is_some() {
        format!("the target's identified θ ({})", to.robot)
    } else {
        "no identification of the target: the midpoint of its physical bounds (§4.1)".into()
    };
    m.choose("theta_hat0", fmt6(&ctrl.theta_hat0), fmt6(&th), why);
    m.controller.theta_hat0 = th;
    let (lo, hi) = to.projection_bounds()?;
    let had = ctrl.adaptation.lower.is_some() || ctrl.adaptation.upper.is_some();
    if had || from.theta.is_some() {
        let before = match (ctrl.adaptation.lower, ctrl.adaptation.upper) {
            (Some(l), Some(h)) => format!("{} … {}", fmt6(&l), fmt6(&h)),
            _ => "none".into(),
        };
        let why = if to.bounds.is_some() {
            "the target's physical bounds".to_string()
        } else {
            "the target's θ ± max(4σ, ½|θ|) (θ3, θ5 at least ±0.05; θ1, θ2, θ4, θ6 kept > 0)"
                .to_string()
        };
        m.choose(
            "projection bounds (eq. 4.9)",
            before,
            format!("{} … {}", fmt6(&lo), fmt6(&hi)),
            why,
        );
        m.controller.adaptation.lower = Some(lo);
        m.controller.adaptation.upper = Some(hi);
    }
    Ok(())
}

/// Peak |v|, |ω|, |v̇|, |ω̇| of `traj` over `period_s`, sampled at 2000 points.
fn path_peaks(traj: &TrajectorySpec, period_s: f64) -> [f64; 4] {
    let n = 2000;
    let dt = period_s / n as f64;
    let mut peak = [0.0f64; 4];
    let mut prev = traj.at(0.0);
    for k in 1..=n {
        let d = traj.at(k as f64 * dt);
        peak[0] = peak[0].max(d.v.abs());
        peak[1] = peak[1].max(d.w.abs());
        peak[2] = peak[2].max(((d.v - prev.v) / dt).abs());
        peak[3] = peak[3].max(d.alpha.abs());
        prev = d;
    }
    peak
}

/// The figure eight's lengths scaled by `s`, then its frequency lowered until the path stays
/// within half the target's speed, turn-rate and (diagnosed) acceleration limits.
fn migrate_path(ctrl: &ControllerSpec, to: &RobotModel, s: f64, m: &mut Migrated) {
    let scale = |e: FigureEight, f: f64| FigureEight {
        ax: e.ax * s,
        ay: e.ay * s,
        f,
    };
    let base = match ctrl.trajectory {
        TrajectorySpec::FigureEight(e) => e,
        TrajectorySpec::FigureEightDither(d) => d.base,
    };
    let build = |f: f64| match ctrl.trajectory {
        TrajectorySpec::FigureEight(e) => TrajectorySpec::FigureEight(scale(e, f)),
        TrajectorySpec::FigureEightDither(mut d) => {
            d.base = scale(d.base, f);
            d.g *= s;
            TrajectorySpec::FigureEightDither(d)
        }
    };
    let mut f = base.f;
    let mut traj = build(f);
    let mut slowed = false;
    // v, ω scale with f, the accelerations with f²: one step to the limit, then re-checked.
    for _ in 0..10 {
        let p = path_peaks(&traj, 2.0 * std::f64::consts::PI / f);
        let acc = to.accel_max.unwrap_or([f64::INFINITY; 2]);
        let over = [
            p[0] / (0.5 * to.v_max),
            p[1] / (0.5 * to.w_max),
            (p[2] / (0.5 * acc[0])).sqrt(),
            (p[3] / (0.5 * acc[1])).sqrt(),
        ]
        .into_iter()
        .fold(0.0, f64::max);
        if over <= 1.0 {
            break;
        }
        f /= 1.001 * over;
        traj = build(f);
        slowed = true;
    }
    let mut why = format!(
        "lengths × {s:.3} (v_max {:.3} m/s on the target against the source's)",
        to.v_max
    );
    if slowed {
        why.push_str(&format!(
            "; f lowered from {:.3} to {f:.3} rad/s to stay within half the target's limits",
            base.f
        ));
    }
    m.choose(
        "trajectory",
        describe(&ctrl.trajectory),
        describe(&traj),
        why,
    );
    m.controller.trajectory = traj;
}

/// k_v, k_ω (sampling and dead time), k1, k3 (below the inner loop), k2 (length scale).
fn migrate_gains(ctrl: &ControllerSpec, to: &RobotModel, s: f64, m: &mut Migrated) {
    let a = &ctrl.adaptation;
    let cap_dt = 0.5 / to.period_s;
    let cap_delay = to
        .delay_s
        .filter(|d| *d > 0.0)
        .map_or(f64::INFINITY, |d| 0.3 / d);
    let cap = cap_dt.min(cap_delay);
    let reason = |k: f64| {
        if k <= cap {
            "kept: within k Δt ≤ 0.5 and k τ_d ≤ 0.3 on the target".to_string()
        } else if cap_delay < cap_dt {
            format!(
                "lowered: the target's dead time {:.3} s allows k ≤ 0.3/τ_d",
                to.delay_s.unwrap_or(0.0)
            )
        } else {
            format!(
                "lowered: the target's period {} s allows k ≤ 0.5/Δt",
                to.period_s
            )
        }
    };
    let (kv, kw) = (a.k_v.min(cap), a.k_w.min(cap));
    m.choose(
        "k_v",
        format!("{}", a.k_v),
        format!("{kv:.3}"),
        reason(a.k_v),
    );
    m.choose(
        "k_w",
        format!("{}", a.k_w),
        format!("{kw:.3}"),
        reason(a.k_w),
    );
    m.controller.adaptation.k_v = kv;
    m.controller.adaptation.k_w = kw;
    let outer = 0.5 * kv.min(kw);
    let k = ctrl.kinematic;
    let (k1, k3) = (k.k1.min(outer), k.k3.min(outer));
    let why = |before: f64| {
        if before <= outer {
            "kept: below half the inner loop's rate".to_string()
        } else {
            format!("lowered to half the inner loop's rate min(k_v, k_ω)/2 = {outer:.3}")
        }
    };
    m.choose("k1", format!("{}", k.k1), format!("{k1:.3}"), why(k.k1));
    m.choose("k3", format!("{}", k.k3), format!("{k3:.3}"), why(k.k3));
    let k2 = k.k2 / (s * s);
    m.choose(
        "k2",
        format!("{}", k.k2),
        format!("{k2:.3}"),
        format!(
            "÷ s² = {:.3}: k2 v_d ỹ is a turn rate, v_d and ỹ scale with s",
            s * s
        ),
    );
    m.controller.kinematic = KinematicLaw { k1, k2, k3 };
}

/// γ scaled to the parameters' magnitudes (bound half-widths) and the regressor's scale.
fn migrate_gamma(
    ctrl: &ControllerSpec,
    from: &RobotModel,
    to: &RobotModel,
    s: f64,
    m: &mut Migrated,
) -> Result<()> {
    let g = ctrl.adaptation.gamma;
    if g.iter().all(|&x| x == 0.0) {
        m.choose(
            "gamma",
            fmt6(&g),
            fmt6(&g),
            "no adaptation on the source: none on the target".into(),
        );
        return Ok(());
    }
    let width = |r: &RobotModel| -> Result<[f64; 6]> {
        let (lo, hi) = r.projection_bounds()?;
        Ok(std::array::from_fn(|i| 0.5 * (hi[i] - lo[i])))
    };
    let (wf, wt) = (width(from)?, width(to)?);
    let col = [s * s, 1.0, s, s * s, s, 1.0];
    let gt: [f64; 6] = std::array::from_fn(|i| g[i] * (wt[i] / wf[i]) / col[i]);
    m.choose(
        "gamma",
        fmt6(&g),
        fmt6(&gt),
        "× the ratio of the parameters' spans (target/source) ÷ the scale of G's column times ṽ \
         (s², 1, s, s², s, 1): θ̂ moves across its span as fast as on the source"
            .into(),
    );
    m.controller.adaptation.gamma = gt;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn models() -> (RobotModel, RobotModel) {
        (
            RobotModel::from_profile(&RobotProfile::pioneer3dx()),
            RobotModel::from_profile(&RobotProfile::khepera3()),
        )
    }

    #[test]
    fn pioneer_to_khepera_follows_the_documented_rules() {
        let (p, k) = models();
        let ctrl = ControllerSpec::tuned_on(&p, &RobotProfile::pioneer3dx()).unwrap();
        let m = migrate(&ctrl, &p, &k).unwrap();
        let c = &m.controller;
        assert_eq!(c.theta_hat0, RobotProfile::khepera3().theta);
        // s = 0.5/1.4; the Pioneer eight (1 m × 2 m) shrinks by s.
        let s = 0.5 / 1.4;
        let TrajectorySpec::FigureEight(e) = c.trajectory else {
            panic!("a figure eight stays one")
        };
        assert!((e.ax - s).abs() < 1e-12 && (e.ay - 2.0 * s).abs() < 1e-12);
        assert!((c.kinematic.k2 - 4.0 / (s * s)).abs() < 1e-9);
        // Khepera at 50 Hz allows k_v = 4 (cap 25/s), k1 = 1 and k3 = 2 are below k_v/2.
        assert_eq!(
            (c.adaptation.k_v, c.kinematic.k1, c.kinematic.k3),
            (4.0, 1.0, 2.0)
        );
        // θ1's bounds: the Khepera's θ1 = 0.0228 ± ½ of it.
        let (lo, hi) = (c.adaptation.lower.unwrap(), c.adaptation.upper.unwrap());
        assert!((lo[0] - 0.0114).abs() < 1e-12 && (hi[0] - 0.0342).abs() < 1e-12);
        // γ1: spans 0.0114/0.1302 over s².
        let want = (0.0114 / 0.1302) / (s * s);
        assert!((c.adaptation.gamma[0] - want).abs() < 1e-9 * want);
        assert!(m.warnings.is_empty(), "{:?}", m.warnings);
    }

    #[test]
    fn a_dead_time_and_a_slow_period_lower_the_gains_with_their_reason() {
        let (p, mut k) = models();
        k.delay_s = Some(0.15);
        k.period_s = 0.1;
        let mut ctrl = ControllerSpec::tuned_on(&p, &RobotProfile::pioneer3dx()).unwrap();
        ctrl.adaptation.k_v = 8.0;
        let m = migrate(&ctrl, &p, &k).unwrap();
        // 0.3/0.15 = 2 < 0.5/0.1 = 5.
        assert_eq!(m.controller.adaptation.k_v, 2.0);
        assert_eq!(m.controller.kinematic.k1, 1.0);
        let c = m.choices.iter().find(|c| c.item == "k_v").unwrap();
        assert!(c.reason.contains("dead time"), "{}", c.reason);
    }

    #[test]
    fn a_diagnosed_acceleration_limit_slows_the_path() {
        let (p, mut k) = models();
        k.accel_max = Some([0.01, 0.05]);
        let ctrl = ControllerSpec::tuned_on(&p, &RobotProfile::pioneer3dx()).unwrap();
        let m = migrate(&ctrl, &p, &k).unwrap();
        let f = match m.controller.trajectory {
            TrajectorySpec::FigureEight(e) => e.f,
            TrajectorySpec::FigureEightDither(d) => d.base.f,
        };
        assert!(f < 0.15, "f = {f}");
        let period = 2.0 * std::f64::consts::PI / f;
        let peaks = path_peaks(&m.controller.trajectory, period);
        assert!(
            peaks[2] <= 0.005 + 1e-9 && peaks[3] <= 0.025 + 1e-9,
            "{peaks:?}"
        );
    }

    #[test]
    fn an_unidentified_target_starts_from_the_midpoint_of_its_bounds() {
        let (p, mut k) = models();
        k.theta = None;
        let lo = [0.01, 0.02, -0.01, 0.9, 0.0, 0.9];
        let hi = [0.03, 0.08, 0.01, 1.1, 0.1, 1.1];
        k.bounds = Some((lo, hi));
        let ctrl = ControllerSpec::tuned_on(&p, &RobotProfile::pioneer3dx()).unwrap();
        let m = migrate(&ctrl, &p, &k).unwrap();
        let want: [f64; 6] = std::array::from_fn(|i| 0.5 * (lo[i] + hi[i]));
        assert_eq!(m.controller.theta_hat0, want);
        k.bounds = None;
        assert!(migrate(&ctrl, &p, &k).is_err());
    }

    #[test]
    fn a_controller_from_another_robot_is_a_warning() {
        let (p, k) = models();
        let mut ctrl = ControllerSpec::tuned_on(&p, &RobotProfile::pioneer3dx()).unwrap();
        ctrl.robot = Some("husky".into());
        let m = migrate(&ctrl, &p, &k).unwrap();
        assert_eq!(m.warnings.len(), 1);
        assert!(m.warnings[0].contains("husky"));
    }
}
