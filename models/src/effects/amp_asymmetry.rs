//! `amp_asymmetry`: one wheel's amplifier (or motor constant) off the other's — the right
//! wheel's whole effort, proportional and derivative terms alike, scaled by a: inside a
//! high-gain speed loop it barely moves the static gains and shows in the transients, where the
//! robot turns off the commanded heading as it accelerates. A setpoint ratio
//! (`wheel_asymmetry`) cannot express it. Its fingerprint: ω's residual follows v's
//! acceleration.
//!
//! With E_v, E_ω the speed loop's efforts of eq. 2.19 and the wheels' e_R,L = E_v ± (d/2) E_ω
//! ([`wheelid_core::WheelTerms`], the wheel-PD geometry; an `effort_clamp` fitted beside it
//! sets the mixing):
//!
//! ```text
//! θ1 v̇ = (a e_R + e_L)/2       − (θ4 − 1) v + θ3 ω² …
//! θ2 ω̇ = (a e_R − e_L)/d       − (θ6 − 1) ω − θ5 v ω …
//! ```

use wheelid_core::effect::{FitData, Probe, ProbeData, Terms};
use wheelid_core::{Effect, EffectChannels, Error, ParamInfo, Result, WheelTerms};

use super::ratio_plausible;

static PARAMS: [ParamInfo; 1] = [ParamInfo {
    name: "right_gain",
    unit: "-",
    description: "right wheel's effort gain relative to the left's",
}];

/// Right/left effort gain a (`Terms::wheels`); null 1, fitted within [0.2, 5], plausible
/// within [0.5, 2]; needs the wheel track.
#[derive(Debug, Clone, Copy)]
pub struct AmpAsymmetry;

impl Effect for AmpAsymmetry {
    fn name(&self) -> &'static str {
        "amp_asymmetry"
    }
    fn quantity(&self) -> Option<&'static str> {
        Some(super::WHEEL_IMBALANCE)
    }
    fn params(&self) -> &'static [ParamInfo] {
        &PARAMS
    }
    fn channels(&self) -> EffectChannels {
        EffectChannels::Both
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
        "ω's residual follows v's acceleration"
    }
    fn plausible(
        &self,
        j: usize,
        x: f64,
        se: f64,
        _fit: &FitData<'_>,
    ) -> std::result::Result<(), String> {
        ratio_plausible(&PARAMS[j], x, se, 0.5..=2.0, "a right/left effort gain")
    }
    fn apply(&self, p: &[f64], terms: &mut Terms) -> Result<()> {
        if p[0] <= 0.0 {
            return Err(Error::InvalidSetting("right_gain must be > 0".into()));
        }
        // × rather than =: beside a larger tyre the two act on one wheel together.
        terms
            .wheels
            .get_or_insert_with(WheelTerms::default)
            .right_gain *= p[0];
        Ok(())
    }
}
