//! Desired trajectories of Laut 2011, Appendix A: the figure eight (A.1) and the figure eight
//! with a dither (A.13–A.28), with every quantity a trajectory-tracking controller needs —
//! position, heading, forward and angular velocity and angular acceleration — in closed form.
//!
//! # Figure eight (§A.1)
//!
//! With f in rad/s (so the path repeats after 2π/f):
//!
//! * x_d = A_x sin 2ft, y_d = A_y sin ft (A.1);
//! * ẋ_d = 2fA_x cos 2ft, ẏ_d = fA_y cos ft (A.2, A.3); v_d = √(ẋ_d² + ẏ_d²) (A.4);
//!   φ_d = atan2(ẏ_d, ẋ_d) (A.5);
//! * ẍ_d = −4f²A_x sin 2ft, ÿ_d = −f²A_y sin ft (A.6, A.7);
//!   x⃛_d = −8f³A_x cos 2ft, y⃛_d = −f³A_y cos ft (A.9, A.10);
//! * ω_d = (ÿ_d ẋ_d − ẍ_d ẏ_d)/(ẋ_d² + ẏ_d²) (A.11);
//! * α_d = [(y⃛_d ẋ_d − x⃛_d ẏ_d)(ẋ_d² + ẏ_d²) − (ÿ_d ẋ_d − ẍ_d ẏ_d)(2ẋ_d ẍ_d + 2ẏ_d ÿ_d)]
//!   / (ẋ_d² + ẏ_d²)² (A.12).
//!
//! The speed never vanishes when A_x, A_y ≠ 0 (ẏ_d = 0 forces cos 2ft = −1, so ẋ_d = −2fA_x);
//! it is largest, f√(4A_x² + A_y²), at the crossing (t = 0) and the heading turns fastest where
//! the lobes are flattest.
//!
//! # Figure eight with dither (§A.2)
//!
//! * d = g sin(ht) cos(kt) e^{lt} (A.13), with ḋ and d̈ as printed (A.14–A.16; A.16 checked —
//!   it is right) and d⃛ (needed below, not in the thesis), all from the Leibniz rule;
//! * x = x_d + d sin φ_d, y = y_d + d cos φ_d (A.17–A.21), exactly as printed. Note that
//!   (sin φ_d, cos φ_d) is the direction at angle π/2 − φ_d: it is perpendicular to the heading
//!   (cos φ_d, sin φ_d) only when sin 2φ_d = 0, so the dither is not purely lateral;
//! * ẋ = ẋ_d + ḋ sin φ_d + d ω_d cos φ_d, ẏ = ẏ_d + ḋ cos φ_d − d ω_d sin φ_d (A.22, A.23, as
//!   printed); v (A.24) and φ = atan2(ẏ, ẋ) (A.25);
//! * **Correction to A.26, A.27.** Differentiating d ω_d cos φ_d gives the three terms
//!   ḋ ω_d cos φ_d, d α_d cos φ_d and −d ω_d² sin φ_d; the printed equations drop the d α_d
//!   term (and likewise −d α_d sin φ_d in ÿ). Used here:
//!
//!   ẍ = ẍ_d + d̈ sin φ_d + 2ḋ ω_d cos φ_d **+ d α_d cos φ_d** − d ω_d² sin φ_d,
//!
//!   ÿ = ÿ_d + d̈ cos φ_d − 2ḋ ω_d sin φ_d **− d α_d sin φ_d** − d ω_d² cos φ_d;
//! * ω of the dithered path by A.28 (the A.11 form on the dithered derivatives) and α by the
//!   A.12 form on them, which needs x⃛, y⃛ of the dithered path, hence d⃛ and
//!   α̇_d = dα_d/dt of the base path (from its fourth derivatives x⁗_d = 16f⁴A_x sin 2ft,
//!   y⁗_d = f⁴A_y sin ft). All analytic; the tests check them against finite differences.
//!
//! With l > 0 the dither grows without bound (e^{lt}); l < 0 fades it out.
//!
//! The thesis gives no amplitudes or frequencies; the presets ([`FigureEight::pioneer`],
//! [`FigureEight::khepera`], [`FigureEightDither::pioneer`], [`FigureEightDither::khepera`])
//! document their own choices.

use serde::{Deserialize, Serialize};
use wheelid_core::Error;

/// The desired state of a robot at one instant.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DesiredState {
    /// Position x \[m\].
    pub x: f64,
    /// Position y \[m\].
    pub y: f64,
    /// Heading φ = atan2(ẏ, ẋ) \[rad\], in (−π, π] (A.5 / A.25).
    pub phi: f64,
    /// Forward speed v = √(ẋ² + ẏ²) [m/s] (A.4 / A.24).
    pub v: f64,
    /// Angular velocity ω = dφ/dt [rad/s] (A.11 / A.28).
    pub w: f64,
    /// Angular acceleration α = dω/dt [rad/s²] (A.12, and its analogue for the dithered path).
    pub alpha: f64,
    /// Velocity ẋ [m/s] (A.2 / A.22).
    pub vx: f64,
    /// Velocity ẏ [m/s] (A.3 / A.23).
    pub vy: f64,
}

/// A desired trajectory: the desired state as a function of time.
pub trait Trajectory {
    /// The desired state at time `t` \[s\].
    fn at(&self, t: f64) -> DesiredState;
}

impl<T: Trajectory + ?Sized> Trajectory for &T {
    fn at(&self, t: f64) -> DesiredState {
        (**self).at(t)
    }
}

impl<T: Trajectory + ?Sized> Trajectory for Box<T> {
    fn at(&self, t: f64) -> DesiredState {
        (**self).at(t)
    }
}

/// Value and first three time derivatives of a scalar.
type Jet = [f64; 4];

/// Leibniz rule: derivatives 0…3 of a·b.
fn leibniz(a: &Jet, b: &Jet) -> Jet {
    [
        a[0] * b[0],
        a[1] * b[0] + a[0] * b[1],
        a[2] * b[0] + 2.0 * a[1] * b[1] + a[0] * b[2],
        a[3] * b[0] + 3.0 * a[2] * b[1] + 3.0 * a[1] * b[2] + a[0] * b[3],
    ]
}

/// The state of a planar path from derivatives 0…3 of x and y (A.4, A.5, A.11, A.12).
fn state_from(x: &Jet, y: &Jet) -> DesiredState {
    let (xd, yd, xdd, ydd, x3, y3) = (x[1], y[1], x[2], y[2], x[3], y[3]);
    let d = xd * xd + yd * yd;
    let n = ydd * xd - xdd * yd;
    DesiredState {
        x: x[0],
        y: y[0],
        phi: yd.atan2(xd),
        v: d.sqrt(),
        w: n / d,
        alpha: ((y3 * xd - x3 * yd) * d - n * (2.0 * xd * xdd + 2.0 * yd * ydd)) / (d * d),
        vx: xd,
        vy: yd,
    }
}

fn finite(what: &str, pairs: &[(&str, f64)]) -> Result<(), Error> {
    for (name, x) in pairs {
        if !x.is_finite() {
            return Err(Error::InvalidSetting(format!(
                "{what}: {name} = {x} is not finite"
            )));
        }
    }
    Ok(())
}

/// The figure eight of eq. A.1: x_d = A_x sin(2ft), y_d = A_y sin(ft).
///
/// The path passes through the origin at t = 0 heading atan2(A_y, 2A_x), reaches (0, ±A_y) at
/// ft = ±π/2 and closes after 2π/f. Serde: a table `{ ax, ay, f }`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FigureEight {
    /// Amplitude A_x in x \[m\] (half the width of each lobe's span in x).
    pub ax: f64,
    /// Amplitude A_y in y \[m\] (each lobe spans 0…±A_y).
    pub ay: f64,
    /// Base frequency f [rad/s]; the period is 2π/f.
    pub f: f64,
}

impl FigureEight {
    /// Pioneer 3-DX preset (our choice; the thesis gives none): A_x = 1.0 m, A_y = 2.0 m,
    /// f = 0.15 rad/s. A 2 m × 4 m footprint, period 2π/0.15 = 41.9 s; v_d from 0.198 to
    /// 0.424 m/s (= 0.15·√8, at the crossing), |ω_d| ≤ 0.476 rad/s. A_y = 2A_x makes the lobes
    /// nearly round: at the same peak speed, A_x = A_y would turn 2.3 times faster.
    pub fn pioneer() -> Self {
        Self {
            ax: 1.0,
            ay: 2.0,
            f: 0.15,
        }
    }

    /// Khepera III preset (our choice): A_x = 0.25 m, A_y = 0.5 m, f = 0.2 rad/s. A
    /// 0.5 m × 1 m footprint, period 31.4 s; v_d from 0.066 to 0.141 m/s (= 0.2·√0.5),
    /// |ω_d| ≤ 0.634 rad/s.
    pub fn khepera() -> Self {
        Self {
            ax: 0.25,
            ay: 0.5,
            f: 0.2,
        }
    }

    /// Period 2π/f \[s\].
    pub fn period_s(&self) -> f64 {
        2.0 * std::f64::consts::PI / self.f
    }

    /// Checks the numbers are finite, A_x, A_y ≠ 0 (else the speed vanishes and the heading is
    /// undefined) and f > 0.
    ///
    /// # Errors
    /// [`Error::InvalidSetting`] naming the offending field.
    pub fn validate(&self) -> Result<(), Error> {
        finite(
            "figure eight",
            &[("ax", self.ax), ("ay", self.ay), ("f", self.f)],
        )?;
        if self.ax == 0.0 || self.ay == 0.0 {
            return Err(Error::InvalidSetting(
                "figure eight: ax and ay must be non-zero".into(),
            ));
        }
        if self.f <= 0.0 {
            return Err(Error::InvalidSetting(format!(
                "figure eight: f = {} must be > 0",
                self.f
            )));
        }
        Ok(())
    }

    /// Derivatives 0…4 of x_d and y_d (A.1–A.3, A.6, A.7, A.9, A.10 and the fourth).
    fn derivatives(&self, t: f64) -> ([f64; 5], [f64; 5]) {
        let Self { ax, ay, f } = *self;
        let (s2, c2) = (2.0 * f * t).sin_cos();
        let (s1, c1) = (f * t).sin_cos();
        let (f2, f3, f4) = (f * f, f * f * f, f * f * f * f);
        (
            [
                ax * s2,
                2.0 * f * ax * c2,
                -4.0 * f2 * ax * s2,
                -8.0 * f3 * ax * c2,
                16.0 * f4 * ax * s2,
            ],
            [
                ay * s1,
                f * ay * c1,
                -f2 * ay * s1,
                -f3 * ay * c1,
                f4 * ay * s1,
            ],
        )
    }

    /// (state, α̇_d): the state and the derivative of α_d [rad/s³], from the derivatives
    /// up to fourth order.
    fn state_and_jerk(&self, t: f64) -> (DesiredState, f64) {
        let (x, y) = self.derivatives(t);
        let s = state_from(&[x[0], x[1], x[2], x[3]], &[y[0], y[1], y[2], y[3]]);
        // ω = N/D, α = Ṅ/D − ωḊ/D, α̇ = N̈/D − ṄḊ/D² − αḊ/D − ωD̈/D + ωḊ²/D².
        let d = x[1] * x[1] + y[1] * y[1];
        let nd = y[3] * x[1] - x[3] * y[1];
        let ndd = y[4] * x[1] + y[3] * x[2] - x[4] * y[1] - x[3] * y[2];
        let dd = 2.0 * (x[1] * x[2] + y[1] * y[2]);
        let ddd = 2.0 * (x[2] * x[2] + x[1] * x[3] + y[2] * y[2] + y[1] * y[3]);
        let jerk = ndd / d - nd * dd / (d * d) - s.alpha * dd / d - s.w * ddd / d
            + s.w * dd * dd / (d * d);
        (s, jerk)
    }
}

impl Trajectory for FigureEight {
    fn at(&self, t: f64) -> DesiredState {
        let (x, y) = self.derivatives(t);
        state_from(&[x[0], x[1], x[2], x[3]], &[y[0], y[1], y[2], y[3]])
    }
}

/// The figure eight with dither of §A.2: the base path displaced by
/// d = g sin(ht) cos(kt) e^{lt} along (sin φ_d, cos φ_d) (A.13, A.18, A.21), with A.26/A.27
/// corrected (see the module documentation).
///
/// Serde: a table `{ base = { ax, ay, f }, g, h, k, l }`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FigureEightDither {
    /// The figure eight being dithered.
    pub base: FigureEight,
    /// Dither amplitude g \[m\].
    pub g: f64,
    /// Dither carrier frequency h [rad/s].
    pub h: f64,
    /// Dither envelope frequency k [rad/s] (the cos(kt) beat).
    pub k: f64,
    /// Dither growth rate l [1/s] (e^{lt}; 0 for a steady dither, < 0 to fade out).
    pub l: f64,
}

impl FigureEightDither {
    /// Pioneer 3-DX preset (our choice): [`FigureEight::pioneer`] with g = 0.05 m,
    /// h = 1.0 rad/s, k = 0.2 rad/s, l = 0. Over 30 base periods v runs from 0.164 to
    /// 0.474 m/s and |ω| ≤ 0.91 rad/s (the tests check v ∈ [0.16, 0.48] m/s, |ω| ≤ 0.95 rad/s
    /// over 10 base periods).
    pub fn pioneer() -> Self {
        Self {
            base: FigureEight::pioneer(),
            g: 0.05,
            h: 1.0,
            k: 0.2,
            l: 0.0,
        }
    }

    /// Khepera III preset (our choice): [`FigureEight::khepera`] with g = 0.008 m,
    /// h = 1.0 rad/s, k = 0.2 rad/s, l = 0. Over 30 base periods v runs from 0.064 to
    /// 0.149 m/s and |ω| ≤ 0.78 rad/s (the tests check v ∈ [0.06, 0.15] m/s, |ω| ≤ 0.8 rad/s
    /// over 10 base periods).
    pub fn khepera() -> Self {
        Self {
            base: FigureEight::khepera(),
            g: 0.008,
            h: 1.0,
            k: 0.2,
            l: 0.0,
        }
    }

    /// Checks the base path ([`FigureEight::validate`]) and that g, h, k, l are finite. (A large
    /// g can still make the dithered speed vanish; that is not checked.)
    ///
    /// # Errors
    /// [`Error::InvalidSetting`] naming the offending field.
    pub fn validate(&self) -> Result<(), Error> {
        self.base.validate()?;
        finite(
            "figure eight dither",
            &[("g", self.g), ("h", self.h), ("k", self.k), ("l", self.l)],
        )
    }

    /// The dither and its derivatives [d, ḋ, d̈, d⃛] at `t` \[s\] (units m, m/s, m/s², m/s³):
    /// A.13, the ḋ and d̈ of A.14–A.16, and d⃛, by the Leibniz rule on
    /// sin(ht) · cos(kt) · e^{lt}.
    pub fn dither(&self, t: f64) -> [f64; 4] {
        let (h, k, l) = (self.h, self.k, self.l);
        let (sh, ch) = (h * t).sin_cos();
        let (sk, ck) = (k * t).sin_cos();
        let e = (l * t).exp();
        let a = [sh, h * ch, -h * h * sh, -h * h * h * ch];
        let b = [ck, -k * sk, -k * k * ck, k * k * k * sk];
        let c = [e, l * e, l * l * e, l * l * l * e];
        leibniz(&leibniz(&a, &b), &c).map(|v| self.g * v)
    }
}

impl Trajectory for FigureEightDither {
    fn at(&self, t: f64) -> DesiredState {
        let (x, y) = self.base.derivatives(t);
        let (b, zeta) = self.base.state_and_jerk(t);
        let (s, c) = (b.vy / b.v, b.vx / b.v); // sin φ_d, cos φ_d
        let (w, a) = (b.w, b.alpha);
        // Derivatives of sin φ_d and cos φ_d (φ̇ = ω, ω̇ = α, α̇ = ζ).
        let sin_phi = [
            s,
            w * c,
            a * c - w * w * s,
            zeta * c - 3.0 * a * w * s - w * w * w * c,
        ];
        let cos_phi = [
            c,
            -w * s,
            -a * s - w * w * c,
            -zeta * s - 3.0 * a * w * c + w * w * w * s,
        ];
        let d = self.dither(t);
        let dx = leibniz(&d, &sin_phi);
        let dy = leibniz(&d, &cos_phi);
        let xj = [x[0] + dx[0], x[1] + dx[1], x[2] + dx[2], x[3] + dx[3]];
        let yj = [y[0] + dy[0], y[1] + dy[1], y[2] + dy[2], y[3] + dy[3]];
        state_from(&xj, &yj)
    }
}

/// A trajectory as configured (e.g. in TOML), internally tagged by `type`:
///
/// ```toml
/// [trajectory]
/// type = "figure_eight_dither"
/// base = { ax = 1.0, ay = 2.0, f = 0.15 }
/// g = 0.05
/// h = 1.0
/// k = 0.2
/// l = 0.0
/// ```
///
/// or `type = "figure_eight"` with `ax`, `ay`, `f`. It implements [`Trajectory`] itself.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
pub enum TrajectorySpec {
    /// [`FigureEight`] (A.1–A.12).
    FigureEight(FigureEight),
    /// [`FigureEightDither`] (A.13–A.28, corrected).
    FigureEightDither(FigureEightDither),
}

impl TrajectorySpec {
    /// The figure eight (with the dither or not) preset for a robot: the Khepera III's (at most
    /// 0.15 m/s) for a profile whose name starts with `khepera` or whose top speed is below
    /// 0.3 m/s (a TurtleBot3 Burger's 0.22 m/s), the Pioneer 3-DX's otherwise.
    pub fn for_profile(profile: &crate::profile::RobotProfile, dither: bool) -> Self {
        let khepera = profile.name.starts_with("khepera") || profile.v_max < 0.3;
        match (khepera, dither) {
            (true, false) => FigureEight::khepera().into(),
            (true, true) => FigureEightDither::khepera().into(),
            (false, false) => FigureEight::pioneer().into(),
            (false, true) => FigureEightDither::pioneer().into(),
        }
    }

    /// Validates the parameters ([`FigureEight::validate`], [`FigureEightDither::validate`]).
    ///
    /// # Errors
    /// [`Error::InvalidSetting`] naming the offending field.
    pub fn validate(&self) -> Result<(), Error> {
        match self {
            Self::FigureEight(p) => p.validate(),
            Self::FigureEightDither(p) => p.validate(),
        }
    }

    /// The validated trajectory as a boxed trait object.
    ///
    /// # Errors
    /// As [`TrajectorySpec::validate`].
    pub fn build(&self) -> Result<Box<dyn Trajectory + Send + Sync>, Error> {
        self.validate()?;
        Ok(match *self {
            Self::FigureEight(p) => Box::new(p),
            Self::FigureEightDither(p) => Box::new(p),
        })
    }
}

impl Trajectory for TrajectorySpec {
    fn at(&self, t: f64) -> DesiredState {
        match self {
            Self::FigureEight(p) => p.at(t),
            Self::FigureEightDither(p) => p.at(t),
        }
    }
}

impl From<FigureEight> for TrajectorySpec {
    fn from(p: FigureEight) -> Self {
        Self::FigureEight(p)
    }
}

impl From<FigureEightDither> for TrajectorySpec {
    fn from(p: FigureEightDither) -> Self {
        Self::FigureEightDither(p)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use std::f64::consts::PI;

    /// Central difference of `g` at `t` with step `h`, fourth order (Richardson).
    fn diff(g: impl Fn(f64) -> f64, t: f64, h: f64) -> f64 {
        (8.0 * (g(t + h) - g(t - h)) - (g(t + 2.0 * h) - g(t - 2.0 * h))) / (12.0 * h)
    }

    /// Unwraps `b` to the branch nearest `a`.
    fn near(a: f64, b: f64) -> f64 {
        b + 2.0 * PI * ((a - b) / (2.0 * PI)).round()
    }

    /// Checks v, vx, vy, φ, ω, α of `traj` against finite differences over [0, t_end].
    fn check_consistency(traj: &dyn Trajectory, t_end: f64, n: usize) -> (f64, f64, f64) {
        let h = 1e-3;
        let (mut vmin, mut vmax, mut wmax) = (f64::INFINITY, 0.0f64, 0.0f64);
        let (mut scale_v, mut scale_w, mut scale_a) = (0.0f64, 0.0f64, 0.0f64);
        let pts: Vec<f64> = (0..n)
            .map(|i| t_end * (i as f64 + 0.37) / n as f64)
            .collect();
        for &t in &pts {
            let s = traj.at(t);
            scale_v = scale_v.max(s.v);
            scale_w = scale_w.max(s.w.abs());
            scale_a = scale_a.max(s.alpha.abs());
        }
        for &t in &pts {
            let s = traj.at(t);
            let vx = diff(|u| traj.at(u).x, t, h);
            let vy = diff(|u| traj.at(u).y, t, h);
            let w = diff(|u| near(s.phi, traj.at(u).phi), t, h);
            let a = diff(|u| traj.at(u).w, t, h);
            let tol = 1e-6;
            assert!(
                (vx - s.vx).abs() <= tol * scale_v,
                "t = {t}: ẋ {vx} vs {}",
                s.vx
            );
            assert!(
                (vy - s.vy).abs() <= tol * scale_v,
                "t = {t}: ẏ {vy} vs {}",
                s.vy
            );
            assert_relative_eq!(s.v, vx.hypot(vy), max_relative = tol);
            assert!(
                (near(s.phi, vy.atan2(vx)) - s.phi).abs() <= tol,
                "t = {t}: φ"
            );
            assert!(
                (w - s.w).abs() <= tol * scale_w,
                "t = {t}: ω {w} vs {}",
                s.w
            );
            assert!(
                (a - s.alpha).abs() <= tol * scale_a,
                "t = {t}: α {a} vs {}",
                s.alpha
            );
            vmin = vmin.min(s.v);
            vmax = vmax.max(s.v);
            wmax = wmax.max(s.w.abs());
        }
        (vmin, vmax, wmax)
    }

    #[test]
    fn figure_eight_at_zero_matches_closed_form() {
        let p = FigureEight {
            ax: 1.3,
            ay: 0.7,
            f: 0.4,
        };
        let s = p.at(0.0);
        assert_eq!((s.x, s.y), (0.0, 0.0));
        assert_relative_eq!(s.vx, 2.0 * 0.4 * 1.3, max_relative = 1e-15);
        assert_relative_eq!(s.vy, 0.4 * 0.7, max_relative = 1e-15);
        assert_relative_eq!(
            s.phi,
            (0.4f64 * 0.7).atan2(2.0 * 0.4 * 1.3),
            max_relative = 1e-15
        );
        assert_relative_eq!(
            s.v,
            0.4 * (4.0f64 * 1.3 * 1.3 + 0.7 * 0.7).sqrt(),
            max_relative = 1e-15
        );
        // ẍ = ÿ = 0 at t = 0, so ω = 0; α = 6f²AxAy/(4Ax² + Ay²) (from A.12).
        assert_eq!(s.w, 0.0);
        assert_relative_eq!(
            s.alpha,
            6.0 * 0.16 * 1.3 * 0.7 / (4.0 * 1.69 + 0.49),
            max_relative = 1e-14
        );
        // At the top of the eight, ft = π/2: (0, Ay), heading π, ω = f Ay / (2 Ax).
        let s = p.at(PI / 2.0 / 0.4);
        assert!(s.x.abs() < 1e-15);
        assert_relative_eq!(s.y, 0.7, max_relative = 1e-15);
        assert_relative_eq!(s.phi.abs(), PI, max_relative = 1e-12);
        assert_relative_eq!(s.v, 2.0 * 0.4 * 1.3, max_relative = 1e-12);
        assert_relative_eq!(s.w, 0.4 * 0.7 / (2.0 * 1.3), max_relative = 1e-12);
    }

    #[test]
    fn figure_eight_derivatives_agree_with_finite_differences() {
        for p in [
            FigureEight::pioneer(),
            FigureEight::khepera(),
            FigureEight {
                ax: 1.0,
                ay: 1.0,
                f: 0.2,
            },
        ] {
            check_consistency(&p, 2.0 * p.period_s(), 400);
        }
    }

    #[test]
    fn figure_eight_closes_after_one_period() {
        for p in [FigureEight::pioneer(), FigureEight::khepera()] {
            let per = p.period_s();
            for i in 0..50 {
                let t = 0.731 * i as f64;
                let (a, b) = (p.at(t), p.at(t + per));
                for (u, v) in [
                    (a.x, b.x),
                    (a.y, b.y),
                    (a.v, b.v),
                    (a.w, b.w),
                    (a.alpha, b.alpha),
                    (a.vx, b.vx),
                    (a.vy, b.vy),
                ] {
                    assert!((u - v).abs() < 1e-12, "t = {t}: {u} vs {v}");
                }
                assert!((near(a.phi, b.phi) - a.phi).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn presets_respect_their_documented_speeds() {
        let scan = |traj: &dyn Trajectory, per: f64| {
            let n = 100_000;
            (0..n).fold((f64::INFINITY, 0.0f64, 0.0f64), |(lo, hi, w), i| {
                let s = traj.at(per * i as f64 / n as f64);
                (lo.min(s.v), hi.max(s.v), w.max(s.w.abs()))
            })
        };
        let p = FigureEight::pioneer();
        let (lo, hi, w) = scan(&p, p.period_s());
        assert_relative_eq!(hi, 0.15 * 8f64.sqrt(), max_relative = 1e-9);
        assert!(
            (0.197..0.199).contains(&lo) && hi <= 0.5 && (0.47..0.48).contains(&w),
            "{lo} {hi} {w}"
        );
        let p = FigureEight::khepera();
        let (lo, hi, w) = scan(&p, p.period_s());
        assert_relative_eq!(hi, 0.2 * 0.5f64.sqrt(), max_relative = 1e-9);
        assert!(
            (0.065..0.067).contains(&lo) && hi <= 0.15 && (0.63..0.64).contains(&w),
            "{lo} {hi} {w}"
        );
        // Dithered presets, over 10 base periods (the dither is not commensurate).
        let p = FigureEightDither::pioneer();
        let (lo, hi, w) = scan(&p, 10.0 * p.base.period_s());
        assert!(lo >= 0.16 && hi <= 0.48 && w <= 0.95, "{lo} {hi} {w}");
        let p = FigureEightDither::khepera();
        let (lo, hi, w) = scan(&p, 10.0 * p.base.period_s());
        assert!(lo >= 0.06 && hi <= 0.15 && w <= 0.8, "{lo} {hi} {w}");
    }

    #[test]
    fn dither_derivatives_match_a16_and_finite_differences() {
        let p = FigureEightDither {
            base: FigureEight::pioneer(),
            g: 0.07,
            h: 1.3,
            k: 0.4,
            l: -0.02,
        };
        let (g, h, k, l) = (p.g, p.h, p.k, p.l);
        for i in 0..200 {
            let t = 0.173 * i as f64;
            let d = p.dither(t);
            let (sh, ch, sk, ck, e) = (
                (h * t).sin(),
                (h * t).cos(),
                (k * t).sin(),
                (k * t).cos(),
                (l * t).exp(),
            );
            // A.13, the printed ḋ and the printed A.16.
            assert_relative_eq!(d[0], g * sh * ck * e, epsilon = 1e-15);
            let d1 = g * (h * ch * ck - k * sh * sk + l * sh * ck) * e;
            let d2 = g
                * ((l * l - h * h - k * k) * sh * ck - 2.0 * h * k * ch * sk
                    + 2.0 * h * l * ch * ck
                    - 2.0 * k * l * sh * sk)
                * e;
            assert_relative_eq!(d[1], d1, epsilon = 1e-14);
            assert_relative_eq!(d[2], d2, epsilon = 1e-14);
            // d⃛ against a finite difference of d̈.
            let d3 = diff(|u| p.dither(u)[2], t, 1e-3);
            assert!((d[3] - d3).abs() < 1e-9, "t = {t}: {} vs {d3}", d[3]);
        }
    }

    #[test]
    fn dithered_position_is_as_printed_and_derivatives_are_consistent() {
        for p in [
            FigureEightDither::pioneer(),
            FigureEightDither::khepera(),
            FigureEightDither {
                base: FigureEight::pioneer(),
                g: 0.1,
                h: 1.5,
                k: 0.15,
                l: -0.005,
            },
        ] {
            // A.18, A.21 with the base's φ_d.
            for i in 0..100 {
                let t = 0.61 * i as f64;
                let (b, s, d) = (p.base.at(t), p.at(t), p.dither(t)[0]);
                assert_relative_eq!(s.x, b.x + d * b.phi.sin(), epsilon = 1e-14);
                assert_relative_eq!(s.y, b.y + d * b.phi.cos(), epsilon = 1e-14);
            }
            check_consistency(&p, 2.0 * p.base.period_s(), 400);
        }
    }

    #[test]
    fn printed_a26_a27_miss_the_d_alpha_terms() {
        // ẍ of the dithered path by finite differences of the analytic ẋ (A.22) equals the
        // corrected A.26, and differs from the printed one by d α_d cos φ_d.
        let p = FigureEightDither {
            base: FigureEight::pioneer(),
            g: 0.1,
            h: 1.0,
            k: 0.2,
            l: 0.0,
        };
        let mut worst_printed = 0.0f64;
        for i in 0..100 {
            let t = 0.417 * i as f64 + 0.1;
            let b = p.base.at(t);
            let (x, y) = p.base.derivatives(t);
            let d = p.dither(t);
            let (s, c) = (b.phi.sin(), b.phi.cos());
            let xdd_num = diff(|u| p.at(u).vx, t, 1e-3);
            let ydd_num = diff(|u| p.at(u).vy, t, 1e-3);
            let printed_x = x[2] + d[2] * s + 2.0 * d[1] * b.w * c - d[0] * b.w * b.w * s;
            let printed_y = y[2] + d[2] * c - 2.0 * d[1] * b.w * s - d[0] * b.w * b.w * c;
            let fixed_x = printed_x + d[0] * b.alpha * c;
            let fixed_y = printed_y - d[0] * b.alpha * s;
            assert!((xdd_num - fixed_x).abs() < 1e-9, "t = {t}");
            assert!((ydd_num - fixed_y).abs() < 1e-9, "t = {t}");
            worst_printed = worst_printed.max((xdd_num - printed_x).abs());
        }
        assert!(worst_printed > 1e-4, "{worst_printed}");
    }

    #[test]
    fn specs_round_trip_through_toml_and_build() {
        #[derive(Debug, PartialEq, Serialize, Deserialize)]
        struct Config {
            trajectory: TrajectorySpec,
        }
        for spec in [
            TrajectorySpec::from(FigureEight::pioneer()),
            TrajectorySpec::from(FigureEightDither::khepera()),
        ] {
            let cfg = Config { trajectory: spec };
            let text = toml::to_string(&cfg).expect("serialises");
            let back: Config = toml::from_str(&text).expect("parses");
            assert_eq!(back, cfg, "{text}");
            let built = back.trajectory.build().expect("valid");
            assert_eq!(built.at(3.3), spec.at(3.3));
        }
        let text = r#"
            [trajectory]
            type = "figure_eight_dither"
            base = { ax = 1.0, ay = 2.0, f = 0.15 }
            g = 0.05
            h = 1.0
            k = 0.2
            l = 0.0
        "#;
        let cfg: Config = toml::from_str(text).expect("parses");
        assert_eq!(cfg.trajectory, FigureEightDither::pioneer().into());
        for bad in [
            "[trajectory]\ntype = \"figure_eight\"\nax = 1.0\nay = 1.0\nf = 0.2\ng = 1.0\n",
            "[trajectory]\ntype = \"circle\"\nr = 1.0\n",
            "[trajectory]\ntype = \"figure_eight\"\nax = 1.0\nay = 1.0\n",
        ] {
            assert!(toml::from_str::<Config>(bad).is_err(), "{bad}");
        }
        let zero = TrajectorySpec::FigureEight(FigureEight {
            ax: 0.0,
            ay: 1.0,
            f: 0.2,
        });
        assert!(zero.build().is_err());
        let neg = TrajectorySpec::FigureEight(FigureEight {
            ax: 1.0,
            ay: 1.0,
            f: -0.2,
        });
        assert!(neg.validate().is_err());
    }
}
