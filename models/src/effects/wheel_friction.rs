//! `wheel_friction`: dry (Coulomb) friction in each wheel's drive — bearings, gearbox, motor
//! brushes — acting per wheel, against each wheel's own direction of turning,
//! sign(v ± dω/2), not against v and ω separately. Where the wheels turn opposite ways (a small
//! robot turning on the spot, tight turns) it brakes the turn and leaves v alone, which a
//! channel-wise friction (`coulomb_friction`) cannot express.
//!
//! In command units (m/s of wheel rim speed: a PD loop on each wheel meets a friction torque
//! F with a setpoint offset c = F R_a r / (k_a k_P) in steady state), with the wheel rim speeds
//! v_R = v + dω/2, v_L = v − dω/2 and τ_i = tanh(v_i/ε), ε = 2 mm/s:
//!
//! ```text
//! θ1 v̇ = … − c (τ_R + τ_L)/2
//! θ2 ω̇ = … − c (τ_R − τ_L)/d
//! ```

use wheelid_core::effect::{FitData, Force, Probe, ProbeData, Terms, abs_quantile, significant};
use wheelid_core::{Effect, ParamInfo, Result};

static PARAMS: [ParamInfo; 1] = [ParamInfo {
    name: "c_wheel",
    unit: "m/s",
    description: "dry friction per wheel, in wheel rim speed command units",
}];

/// Smoothing of the sign of each wheel's rim speed [m/s].
const EPS: f64 = 0.002;

/// Each wheel's smoothed direction of turning at (v [m/s], ω [rad/s]) on a track \[m\],
/// τ_i = tanh(v_i/ε) with v_R = v + dω/2, v_L = v − dω/2, and its slope dτ_i/dv_i:
/// (τ_R, τ_L, τ_R', τ_L'). Shared with `vw_friction`.
pub(super) fn directions(v: f64, w: f64, track: f64) -> [f64; 4] {
    let half = 0.5 * track;
    let (tr, tl) = (
        crate::dynamics::tanh((v + half * w) / EPS),
        crate::dynamics::tanh((v - half * w) / EPS),
    );
    [tr, tl, (1.0 - tr * tr) / EPS, (1.0 - tl * tl) / EPS]
}

/// The probe of a per-wheel offset in wheel rim speed units whose null is 0 (`wheel_friction`,
/// `dead_zone`): a step of 10⁻³ of the forward command's 90 % quantile; `None` without the
/// wheel track.
pub(super) fn per_wheel_probe(data: &ProbeData<'_>) -> Option<Probe> {
    data.track?;
    let step = 1e-3 * abs_quantile(data.command(0), 0.9).max(1e-4);
    Some(Probe::Gradient(vec![(0, step)]))
}

/// Dry friction per wheel c ≥ 0 (a [`Force`]); null 0; plausible up to half the largest
/// wheel command; needs the wheel track.
#[derive(Debug, Clone, Copy)]
pub struct WheelFriction;

impl Effect for WheelFriction {
    fn name(&self) -> &'static str {
        "wheel_friction"
    }
    fn quantity(&self) -> Option<&'static str> {
        Some(super::DRY_FRICTION)
    }
    fn params(&self) -> &'static [ParamInfo] {
        &PARAMS
    }
    fn null(&self, _theta: &[f64], _t_mid: f64) -> Vec<f64> {
        vec![0.0]
    }
    fn bounds(&self, _t_range: (f64, f64)) -> Vec<(f64, f64)> {
        vec![(0.0, f64::INFINITY)]
    }
    fn probe(&self, data: &ProbeData<'_>) -> Option<Probe> {
        per_wheel_probe(data)
    }
    fn evidence(&self) -> &'static str {
        "the residual opposes each wheel's direction of turning"
    }
    fn plausible(
        &self,
        j: usize,
        x: f64,
        se: f64,
        fit: &FitData<'_>,
    ) -> std::result::Result<(), String> {
        significant(&PARAMS[j], x, se, 0.0)?;
        if x > 0.5 * fit.command_max(0).max(1e-9) {
            return Err(format!(
                "c_wheel = {x:.4} m/s is more than half the largest forward command"
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
        let c = p[0];
        let half = 0.5 * track;
        let [tr, tl, sr, sl] = directions(v, w, track);
        Force {
            f: [-0.5 * c * (tr + tl), -c * (tr - tl) / track],
            jacobian: [
                [-0.5 * c * (sr + sl), -0.5 * c * (sr - sl) * half],
                [-c * (sr - sl) / track, -0.5 * c * (sr + sl)],
            ],
        }
    }
}
