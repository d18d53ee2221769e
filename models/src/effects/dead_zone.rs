//! `dead_zone`: each wheel's drive has a dead band — a motor driver that gives no voltage for
//! a small duty cycle, an H-bridge's dead time, a motor's brushes and cogging that a small
//! voltage does not turn. With e_i each wheel's effort (the speed loop's, in m/s of rim speed
//! error, as [`super::EffortClamp`]'s) and β the band:
//!
//! ```text
//! ē_i = 0                   |e_i| < β
//! ē_i = e_i − β sign(e_i)   beyond
//! ```
//!
//! before the clamp ([`wheelid_core::WheelTerms::effort_dead`]; the wheel stage's module docs
//! in `extended::wheels`). In a straight run at constant speed it is a dry friction's offset
//! (the loop's error grows by β/gain); it parts from dry friction (`wheel_friction`, against
//! each wheel's *motion*) where the effort and the motion have opposite signs — braking,
//! where a dead band takes braking effort away and a friction adds braking — and at low
//! efforts, where a wheel within its band gets nothing at all. Source: the dead-zone
//! nonlinearity of actuators, G. Tao & P. V. Kokotović, *Adaptive control of systems with
//! actuator and sensor nonlinearities* (Wiley, 1996), ch. 2.

use wheelid_core::effect::{FitData, Probe, ProbeData, Search, Terms, abs_quantile, significant};
use wheelid_core::{Effect, EffectChannels, ParamInfo, Result, WheelTerms};

static PARAMS: [ParamInfo; 1] = [ParamInfo {
    name: "effort_dead",
    unit: "m/s",
    description: "each wheel's dead band, in wheel rim speed error (effort) units",
}];

/// Each wheel's dead band β ≥ 0 [m/s] (`Terms::wheels`); null 0; plausible up to half the
/// largest forward command; needs the wheel track.
#[derive(Debug, Clone, Copy)]
pub struct DeadZone;

impl Effect for DeadZone {
    fn name(&self) -> &'static str {
        "dead_zone"
    }
    fn params(&self) -> &'static [ParamInfo] {
        &PARAMS
    }
    fn channels(&self) -> EffectChannels {
        EffectChannels::Both
    }
    fn null(&self, _theta: &[f64], _t_mid: f64) -> Vec<f64> {
        vec![0.0]
    }
    fn bounds(&self, _t_range: (f64, f64)) -> Vec<(f64, f64)> {
        vec![(0.0, f64::INFINITY)]
    }
    fn search(&self) -> Search {
        Search::Smooth
    }
    /// A step of 10⁻³ of the forward command's 90 % quantile (as `wheel_friction`'s).
    fn probe(&self, data: &ProbeData<'_>) -> Option<Probe> {
        data.track?;
        let step = 1e-3 * abs_quantile(data.command(0), 0.9).max(1e-4);
        Some(Probe::Gradient(vec![(0, step)]))
    }
    fn evidence(&self) -> &'static str {
        "the residual opposes each wheel's effort"
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
                "effort_dead = {x:.4} m/s is more than half the largest forward command"
            ));
        }
        Ok(())
    }
    fn apply(&self, p: &[f64], terms: &mut Terms) -> Result<()> {
        terms
            .wheels
            .get_or_insert_with(WheelTerms::default)
            .effort_dead = p[0].max(0.0);
        Ok(())
    }
}
