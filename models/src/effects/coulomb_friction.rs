//! `coulomb_friction`: dry friction, a force opposing the direction of travel, in command
//! units: θ1 v̇ = … − c_v tanh(v/ε_v), θ2 ω̇ = … − c_ω tanh(ω/ε_ω) (ε: [`crate::extended::FRICTION_EPS`]).

use wheelid_core::effect::{FitData, Probe, ProbeData, Terms, abs_quantile, significant};
use wheelid_core::{Effect, EffectChannels, ParamInfo, Result};

static PARAMS: [ParamInfo; 2] = [
    ParamInfo {
        name: "v_coulomb",
        unit: "m/s",
        description: "dry friction in forward command units",
    },
    ParamInfo {
        name: "w_coulomb",
        unit: "rad/s",
        description: "dry friction in turning command units",
    },
];

/// Dry friction (c_v, c_ω) ≥ 0 in command units; null 0; plausible up to half the largest
/// command.
#[derive(Debug, Clone, Copy)]
pub struct CoulombFriction;

impl Effect for CoulombFriction {
    fn name(&self) -> &'static str {
        "coulomb_friction"
    }
    fn quantity(&self) -> Option<&'static str> {
        Some(super::DRY_FRICTION)
    }
    fn params(&self) -> &'static [ParamInfo] {
        &PARAMS
    }
    fn channels(&self) -> EffectChannels {
        EffectChannels::Each { positive: true }
    }
    fn null(&self, _theta: &[f64], _t_mid: f64) -> Vec<f64> {
        vec![0.0, 0.0]
    }
    fn bounds(&self, _t_range: (f64, f64)) -> Vec<(f64, f64)> {
        vec![(0.0, f64::INFINITY); 2]
    }
    /// Steps of 10⁻³ of the commands' 90 % quantile.
    fn probe(&self, data: &ProbeData<'_>) -> Option<Probe> {
        let step = |ch| 1e-3 * abs_quantile(data.command(ch), 0.9).max(1e-6);
        Some(Probe::Gradient(vec![(0, step(0)), (1, step(1))]))
    }
    fn evidence(&self) -> &'static str {
        "the residual opposes the direction of travel"
    }
    fn plausible(
        &self,
        j: usize,
        x: f64,
        se: f64,
        fit: &FitData<'_>,
    ) -> std::result::Result<(), String> {
        significant(&PARAMS[j], x, se, 0.0)?;
        if x > 0.5 * fit.command_max(j) {
            return Err(format!(
                "{} = {x:.4} is more than half the largest command",
                PARAMS[j].name
            ));
        }
        Ok(())
    }
    fn apply(&self, p: &[f64], terms: &mut Terms) -> Result<()> {
        terms.coulomb = [p[0], p[1]];
        Ok(())
    }
}
