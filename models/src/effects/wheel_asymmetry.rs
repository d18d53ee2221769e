//! `wheel_asymmetry`: one wheel's setpoint gain off the other's, the wheel setpoints v ± dω/2
//! scaled by 2ρ/(1 + ρ) and 2/(1 + ρ) (d: the wheel track). Its fingerprint: ω's residual
//! follows v_ref.

use wheelid_core::effect::{FitData, Probe, ProbeData, Terms};
use wheelid_core::{Effect, EffectChannels, Error, ParamInfo, Result};

use super::ratio_plausible;

static PARAMS: [ParamInfo; 1] = [ParamInfo {
    name: "ratio",
    unit: "-",
    description: "right/left wheel gain ratio",
}];

/// Right/left wheel gain ratio ρ (stage 4 of [`Terms`]); null 1, fitted within [0.2, 5],
/// plausible within [0.5, 2]; needs the wheel track.
#[derive(Debug, Clone, Copy)]
pub struct WheelAsymmetry;

impl Effect for WheelAsymmetry {
    fn name(&self) -> &'static str {
        "wheel_asymmetry"
    }
    fn quantity(&self) -> Option<&'static str> {
        Some(super::WHEEL_IMBALANCE)
    }
    fn params(&self) -> &'static [ParamInfo] {
        &PARAMS
    }
    fn channels(&self) -> EffectChannels {
        EffectChannels::Omega
    }
    fn null(&self, _theta: &[f64], _t_mid: f64) -> Vec<f64> {
        vec![1.0]
    }
    fn bounds(&self, _t_range: (f64, f64)) -> Vec<(f64, f64)> {
        vec![(0.2, 5.0)]
    }
    fn probe(&self, data: &ProbeData<'_>) -> Option<Probe> {
        data.track?;
        Some(Probe::Gradient(vec![(0, 1e-3)]))
    }
    fn evidence(&self) -> &'static str {
        "ω's residual follows v_ref"
    }
    fn plausible(
        &self,
        j: usize,
        x: f64,
        se: f64,
        _fit: &FitData<'_>,
    ) -> std::result::Result<(), String> {
        ratio_plausible(&PARAMS[j], x, se, 0.5..=2.0, "a wheel gain ratio")
    }
    fn apply(&self, p: &[f64], terms: &mut Terms) -> Result<()> {
        if p[0] <= -1.0 + 1e-9 {
            return Err(Error::InvalidSetting("wheel ratio must be > −1".into()));
        }
        terms.ratio = Some(p[0]);
        Ok(())
    }
}
