//! `tyre_asymmetry`: the right tyre's radius ρ times the left's while the host converts both
//! wheels' encoder counts with the same nominal radius. The speed loop holds each wheel's
//! *encoder* rate, so the static gains barely move; what changes is how the chassis answers
//! that wheel. With m_R,L = v ± (d/2) ω the rim speeds the encoders report, the right
//! contact moves at ρ m_R, and the force the right motor's effort puts on the chassis is that
//! effort over ρ. With B the map from wheel efforts to the rim speeds' accelerations of eq.
//! 2.19 (its right-hand side divided by θ1, θ2, in wheel coordinates) and S = diag(1/ρ, 1):
//!
//! ```text
//! ṁ = S B (S e − …)        (nominal: ṁ = B (e − …))
//! ```
//!
//! — the right wheel's effort column scaled by 1/ρ (as `amp_asymmetry` scales it) *and* its
//! row: the chassis inertia seen through a larger tyre grows by ρ² on its own wheel and by ρ
//! across. The losses (θ4 − 1, θ6 − 1, θ3, θ5) are scaled with the row, a second-order
//! simplification for a few percent of radius. Where `amp_asymmetry` scales only the column,
//! a fit of it to a larger tyre leaves the row's part in the residual (its fingerprint stays).
//! Source: rigid-body kinematics of a differential drive with unequal wheel radii
//! (Siegwart & Nourbakhsh, *Introduction to Autonomous Mobile Robots*, 2011, §3.2.1: each
//! contact's speed is its radius times its wheel rate); the effort mapping is the wheel-PD
//! geometry of §2.2 of the thesis.
//!
//! The stage has no sensitivity equations: its fits take their Jacobian by differences.

use wheelid_core::effect::{FitData, Probe, ProbeData, Terms};
use wheelid_core::{Effect, EffectChannels, Error, ParamInfo, Result, WheelTerms};

use super::ratio_plausible;

static PARAMS: [ParamInfo; 1] = [ParamInfo {
    name: "right_radius",
    unit: "-",
    description: "right tyre's radius relative to the left's",
}];

/// Right/left tyre radius ratio ρ (`Terms::wheels` right gain × 1/ρ and `Terms::right_row` =
/// 1/ρ); null 1, fitted within [0.5, 2], plausible within [0.8, 1.25]; needs the wheel track.
#[derive(Debug, Clone, Copy)]
pub struct TyreAsymmetry;

impl Effect for TyreAsymmetry {
    fn name(&self) -> &'static str {
        "tyre_asymmetry"
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
        vec![(0.5, 2.0)]
    }
    fn probe(&self, data: &ProbeData<'_>) -> Option<Probe> {
        data.track?;
        Some(Probe::Gradient(vec![(0, 1e-3)]))
    }
    fn evidence(&self) -> &'static str {
        "one wheel answers its effort more slowly than the other"
    }
    fn plausible(
        &self,
        j: usize,
        x: f64,
        se: f64,
        _fit: &FitData<'_>,
    ) -> std::result::Result<(), String> {
        ratio_plausible(
            &PARAMS[j],
            x,
            se,
            0.8..=1.25,
            "a right/left tyre radius ratio",
        )
    }
    fn apply(&self, p: &[f64], terms: &mut Terms) -> Result<()> {
        if !(p[0] > 0.0 && p[0].is_finite()) {
            return Err(Error::InvalidSetting("right_radius must be > 0".into()));
        }
        let wheels = terms.wheels.get_or_insert_with(WheelTerms::default);
        wheels.right_gain /= p[0];
        terms.right_row = Some(terms.right_row.unwrap_or(1.0) / p[0]);
        Ok(())
    }
}
