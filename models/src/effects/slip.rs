//! `slip`: losses growing with the lateral load of a turn, θ1 v̇ = … − θ4 k_v v |ω|,
//! θ2 ω̇ = … − θ6 k_ω |v| ω.

use wheelid_core::effect::{FitData, Probe, ProbeData, Terms, significant};
use wheelid_core::{Effect, EffectChannels, ParamInfo, Result};

static PARAMS: [ParamInfo; 2] = [
    ParamInfo {
        name: "k_v",
        unit: "s/rad",
        description: "forward slip per unit v·|ω|",
    },
    ParamInfo {
        name: "k_w",
        unit: "s/m",
        description: "turning slip per unit |v|·ω",
    },
];

/// Slip losses (k_v, k_ω) ≥ 0; null 0.
#[derive(Debug, Clone, Copy)]
pub struct Slip;

impl Effect for Slip {
    fn name(&self) -> &'static str {
        "slip"
    }
    fn quantity(&self) -> Option<&'static str> {
        Some(super::FLOOR_SLIP)
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
    fn probe(&self, _data: &ProbeData<'_>) -> Option<Probe> {
        Some(Probe::Gradient(vec![(0, 1e-3), (1, 1e-3)]))
    }
    fn evidence(&self) -> &'static str {
        "the residual grows with |v·ω|"
    }
    fn plausible(
        &self,
        j: usize,
        x: f64,
        se: f64,
        _fit: &FitData<'_>,
    ) -> std::result::Result<(), String> {
        significant(&PARAMS[j], x, se, 0.0)
    }
    fn apply(&self, p: &[f64], terms: &mut Terms) -> Result<()> {
        terms.slip = [p[0], p[1]];
        Ok(())
    }
}
