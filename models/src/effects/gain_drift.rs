//! `gain_drift`: the drive (amplifier) gain changes slowly over the run — a battery sagging —
//! g = 1 + r (t − t0) scaling the speed loop's whole effort, g (u − v), g (u_ω − ω): the
//! closed loop slows down and its static gain falls a little ([`wheelid_core::Terms`]). Its
//! fingerprint: the residual grows with the tracking error as time goes on.

use wheelid_core::effect::{FitData, Probe, ProbeData, Terms, significant};
use wheelid_core::{Effect, ParamInfo, Result};

static PARAMS: [ParamInfo; 1] = [ParamInfo {
    name: "rate_per_s",
    unit: "1/s",
    description: "relative change of the drive gain per second",
}];

/// Relative drive-gain change per second r (`Terms::drift`); null 0; plausible while it moves
/// the gain by less than 50 % over the run.
#[derive(Debug, Clone, Copy)]
pub struct GainDrift;

impl Effect for GainDrift {
    fn name(&self) -> &'static str {
        "gain_drift"
    }
    fn params(&self) -> &'static [ParamInfo] {
        &PARAMS
    }
    fn null(&self, _theta: &[f64], _t_mid: f64) -> Vec<f64> {
        vec![0.0]
    }
    fn bounds(&self, _t_range: (f64, f64)) -> Vec<(f64, f64)> {
        vec![(f64::NEG_INFINITY, f64::INFINITY)]
    }
    fn probe(&self, _data: &ProbeData<'_>) -> Option<Probe> {
        Some(Probe::Gradient(vec![(0, 1e-5)]))
    }
    fn evidence(&self) -> &'static str {
        "the residual grows with the tracking error as time goes on"
    }
    fn plausible(
        &self,
        j: usize,
        x: f64,
        se: f64,
        fit: &FitData<'_>,
    ) -> std::result::Result<(), String> {
        significant(&PARAMS[j], x, se, 0.0)?;
        if x.abs() * fit.span_s() > 0.5 {
            return Err(format!(
                "a gain drift of {x:.2e}/s changes the gains by over 50 % in the run"
            ));
        }
        Ok(())
    }
    fn apply(&self, p: &[f64], terms: &mut Terms) -> Result<()> {
        terms.drift = p[0];
        Ok(())
    }
}
