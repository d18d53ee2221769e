//! `vw_friction`: dry (Coulomb) friction in each wheel's drive, met by a controller that
//! closes its loops on v and ω (the Pioneer 3-DX's, thesis Appendix A.3) rather than on each
//! wheel. The friction still acts per wheel, against each wheel's own direction of turning;
//! but its common part is balanced by the v loop (gain K_PT) and its difference by the ω
//! loop (gain K_PR), so in command units the ω loop meets c_ω = c_v K_PT/K_PR, which is not
//! the 2 c_v/d a wheel-PD loop meets (`wheel_friction`). With the rim speeds
//! v_R = v + dω/2, v_L = v − dω/2 and τ_i = tanh(v_i/ε), ε = 2 mm/s (`wheel_friction`'s):
//!
//! ```text
//! θ1 v̇ = … − c_v (τ_R + τ_L)/2
//! θ2 ω̇ = … − c_ω (τ_R − τ_L)/2
//! ```
//!
//! On a wheel-PD robot c_ω = 2 c_v/d and this is `wheel_friction` with one parameter more.
//! On the physics backend's Pioneer-like robot (K_PT = 66, K_PR = 9.4, d = 0.33 m) the ω loss
//! of a dry friction is K_PT/K_PR = 7.02 times the v loss, against 2/d = 6.06: the 16 % that
//! `wheel_friction` leaves in ω was taken up by a `slip` beside it.

use wheelid_core::effect::{FitData, Force, Probe, ProbeData, Terms, abs_quantile, significant};
use wheelid_core::{Effect, ParamInfo, Result};

static PARAMS: [ParamInfo; 2] = [
    ParamInfo {
        name: "c_v",
        unit: "m/s",
        description: "dry friction per wheel as the v loop meets it, in forward command units",
    },
    ParamInfo {
        name: "c_w",
        unit: "rad/s",
        description: "dry friction per wheel as the ω loop meets it, in turning command units",
    },
];

/// Dry friction per wheel met by v and ω loops, (c_v, c_ω) ≥ 0 (a [`Force`]); null 0;
/// plausible up to the largest command of each channel; needs the wheel track.
#[derive(Debug, Clone, Copy)]
pub struct VwFriction;

impl Effect for VwFriction {
    fn name(&self) -> &'static str {
        "vw_friction"
    }
    fn quantity(&self) -> Option<&'static str> {
        Some(super::DRY_FRICTION)
    }
    fn params(&self) -> &'static [ParamInfo] {
        &PARAMS
    }
    fn null(&self, _theta: &[f64], _t_mid: f64) -> Vec<f64> {
        vec![0.0, 0.0]
    }
    fn bounds(&self, _t_range: (f64, f64)) -> Vec<(f64, f64)> {
        vec![(0.0, f64::INFINITY); 2]
    }
    /// Steps of 10⁻³ of the commands' 90 % quantiles.
    fn probe(&self, data: &ProbeData<'_>) -> Option<Probe> {
        data.track?;
        let step = |ch| 1e-3 * abs_quantile(data.command(ch), 0.9).max(1e-4);
        Some(Probe::Gradient(vec![(0, step(0)), (1, step(1))]))
    }
    fn evidence(&self) -> &'static str {
        "the residual opposes each wheel's direction of turning, in v and ω by their own loops"
    }
    fn plausible(
        &self,
        j: usize,
        x: f64,
        se: f64,
        fit: &FitData<'_>,
    ) -> std::result::Result<(), String> {
        significant(&PARAMS[j], x, se, 0.0)?;
        // A friction the loop never overcomes stalls the channel: at most the largest command
        // (not half of it, as `wheel_friction`: the ω loop's gain is often several times lower
        // than the v loop's, and meets the same friction as a larger offset — 7× on the
        // Pioneer, where a friction of 8 % of the top speed in v is 34 % of it in ω).
        if x > fit.command_max(j).max(1e-9) {
            return Err(format!(
                "{} = {x:.4} is more than the largest command",
                PARAMS[j].name
            ));
        }
        Ok(())
    }
    fn apply(&self, _p: &[f64], _terms: &mut Terms) -> Result<()> {
        Ok(())
    }
    fn has_force(&self) -> bool {
        true
    }
    fn force(&self, p: &[f64], v: f64, w: f64, track: f64) -> Force {
        let (cv, cw) = (p[0], p[1]);
        let half = 0.5 * track;
        let [tr, tl, sr, sl] = super::wheel_friction::directions(v, w, track);
        Force {
            f: [-0.5 * cv * (tr + tl), -0.5 * cw * (tr - tl)],
            jacobian: [
                [-0.5 * cv * (sr + sl), -0.5 * cv * (sr - sl) * half],
                [-0.5 * cw * (sr - sl), -0.5 * cw * (sr + sl) * half],
            ],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::effects::WheelFriction;

    /// With c_ω = 2 c_v/d it is `wheel_friction` (force and Jacobian), at rim speeds of both
    /// signs and inside the smoothing.
    #[test]
    fn with_the_wheel_pd_ratio_it_is_the_per_wheel_friction() {
        let (c, d) = (0.015, 0.33);
        for (v, w) in [(0.3, 0.5), (0.05, -1.0), (0.001, 0.004), (-0.2, 0.1)] {
            let a = VwFriction.force(&[c, 2.0 * c / d], v, w, d);
            let b = WheelFriction.force(&[c], v, w, d);
            for r in 0..2 {
                assert!((a.f[r] - b.f[r]).abs() < 1e-15, "f[{r}] at ({v}, {w})");
                for k in 0..2 {
                    let (x, y) = (a.jacobian[r][k], b.jacobian[r][k]);
                    assert!((x - y).abs() <= 1e-12 * y.abs().max(1.0), "J[{r}][{k}]");
                }
            }
        }
    }

    /// The Jacobian is the force's derivative (central differences).
    #[test]
    fn the_jacobian_is_the_derivative() {
        let (p, d) = ([0.015, 0.09], 0.33);
        let h = 1e-7;
        for (v, w) in [(0.3, 0.5), (0.002, 0.01), (-0.1, -0.3)] {
            let j = VwFriction.force(&p, v, w, d).jacobian;
            let dv = |s: f64| VwFriction.force(&p, v + s, w, d).f;
            let dw = |s: f64| VwFriction.force(&p, v, w + s, d).f;
            for (r, row) in j.iter().enumerate() {
                let nv = (dv(h)[r] - dv(-h)[r]) / (2.0 * h);
                let nw = (dw(h)[r] - dw(-h)[r]) / (2.0 * h);
                assert!((row[0] - nv).abs() <= 1e-5 * nv.abs().max(1.0), "∂f{r}/∂v");
                assert!((row[1] - nw).abs() <= 1e-5 * nw.abs().max(1.0), "∂f{r}/∂ω");
            }
        }
    }
}
