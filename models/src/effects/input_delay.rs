//! `input_delay`: a dead time of the commands, u(t − τ) — transport on the link, a controller
//! that acts one cycle late. Its fingerprint: the residual follows the commands' changes.

use wheelid_core::effect::{FitData, Probe, ProbeData, Search, Terms, significant};
use wheelid_core::{Effect, ParamInfo, Result};

static PARAMS: [ParamInfo; 1] = [ParamInfo {
    name: "delay_s",
    unit: "s",
    description: "dead time of the commands",
}];

/// Dead time τ \[s\] of the commands (stage 1 of [`Terms`]); null 0, fitted within [0, 2] s,
/// plausible up to 1.5 s.
#[derive(Debug, Clone, Copy)]
pub struct InputDelay;

impl Effect for InputDelay {
    fn name(&self) -> &'static str {
        "input_delay"
    }
    fn params(&self) -> &'static [ParamInfo] {
        &PARAMS
    }
    fn null(&self, _theta: &[f64], _t_mid: f64) -> Vec<f64> {
        vec![0.0]
    }
    fn bounds(&self, _t_range: (f64, f64)) -> Vec<(f64, f64)> {
        vec![(0.0, 2.0)]
    }
    fn search(&self) -> Search {
        Search::DeadTime
    }
    fn probe(&self, data: &ProbeData<'_>) -> Option<Probe> {
        Some(Probe::Gradient(vec![(0, 0.5 * data.dt)]))
    }
    fn evidence(&self) -> &'static str {
        "the residual follows the commands' changes"
    }
    fn plausible(
        &self,
        j: usize,
        x: f64,
        se: f64,
        _fit: &FitData<'_>,
    ) -> std::result::Result<(), String> {
        significant(&PARAMS[j], x, se, 0.0)?;
        if x > 1.5 {
            return Err(format!("a dead time of {x:.3} s is not plausible"));
        }
        Ok(())
    }
    fn apply(&self, p: &[f64], terms: &mut Terms) -> Result<()> {
        terms.delay = p[0];
        Ok(())
    }
}
