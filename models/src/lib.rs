//! # wheelid-models
//!
//! The velocity-input dynamic model of a differential-drive robot (Laut 2011, eq. 2.19):
//!
//! ```text
//! v̇ = (θ3/θ1) ω² − (θ4/θ1) v + (1/θ1) v_ref
//! ω̇ = −(θ5/θ2) v ω − (θ6/θ2) ω + (1/θ2) ω_ref
//! ```
//!
//! linear in θ when written as eq. 4.1–4.2 ([`regressor`]), in two parameterizations that share
//! that regressor but give θ different physical meanings ([`physical`]):
//! * [`WheelPd`] (`wheel-pd`): PD control on each wheel's velocity (§2.2, Khepera III);
//! * [`VwPd`] (`vw-pd`): PD control on v and ω (Appendix A.3, Pioneer 3-DX).
//!
//! Both simulate their own (v, ω) response to (v_ref, ω_ref) ([`dynamics`]), with analytic
//! output sensitivities for output-error fitting.
//!
//! Extended models — the six θ plus physics that enters non-linearly, fitted by output error
//! only: [`InputDelay`] (`delayed`, a dead time on the commands, [`delay`]) and [`Extended`]
//! (any set of the diagnosis's [`Candidate`] physics, [`extended`]). [`CommandOffset`] gives any
//! model a signed command-to-response timing offset ([`offset`]): how the host stamped its rows.

pub mod delay;
pub mod dynamics;
pub mod effects;
pub mod extended;
pub mod offset;
pub mod physical;
pub mod regressor;

use wheelid_core::{
    ChannelInfo, ChannelRegression, Conditioned, DynamicModel, ParamInfo, Recording,
    RegressorModel, Result, Sensitivities, Simulation,
};

pub use delay::InputDelay;
pub use extended::{Candidate, Extended};
pub use offset::CommandOffset;
pub use physical::{Parameterization, VwPdConstants, VwPdMap, WheelPdConstants, WheelPdMap};

macro_rules! six_theta_model {
    ($(#[$m:meta])* $ty:ident, $name:literal, $map:ty) => {
        $(#[$m])*
        #[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
        pub struct $ty;

        impl $ty {
            /// θ from the robot's physical constants (see [`physical`]).
            pub fn theta_from(c: &<$map as Parameterization>::Constants) -> [f64; 6] {
                <$map>::theta(c)
            }

            /// Bounds on θ from intervals on the physical constants (see [`physical`]).
            ///
            /// # Errors
            /// As [`Parameterization::theta_bounds`].
            pub fn theta_bounds(
                lo: &<$map as Parameterization>::Constants,
                hi: &<$map as Parameterization>::Constants,
            ) -> Result<[(f64, f64); 6]> {
                <$map>::theta_bounds(lo, hi)
            }
        }

        impl DynamicModel for $ty {
            fn name(&self) -> &str {
                $name
            }
            fn params(&self) -> &[ParamInfo] {
                &regressor::PARAMS
            }
            fn channels(&self) -> &[ChannelInfo] {
                &regressor::CHANNELS
            }
            fn simulate(&self, theta: &[f64], rec: &Recording, initial: &[f64]) -> Result<Simulation> {
                Ok(Vec::from(dynamics::simulate(theta, rec, initial)?))
            }
            fn simulate_with_sensitivities(
                &self,
                theta: &[f64],
                rec: &Recording,
                initial: &[f64],
            ) -> Result<Option<(Simulation, Sensitivities)>> {
                let (y, s) = dynamics::simulate_with_sensitivities(theta, rec, initial)?;
                Ok(Some((Vec::from(y), s)))
            }
        }

        impl RegressorModel for $ty {
            fn regression(&self, data: &Conditioned<'_>) -> Result<Vec<ChannelRegression>> {
                regressor::regression(data)
            }
            fn regression_blocks(
                &self,
                data: &Conditioned<'_>,
                sink: &mut dyn FnMut(Vec<ChannelRegression>) -> Result<()>,
            ) -> Result<()> {
                regressor::regression_blocks(data, sink)
            }
        }
    };
}

six_theta_model!(
    /// The 6-θ model with PD control on each wheel (Laut 2011 §2.2), `wheel-pd`.
    WheelPd, "wheel-pd", WheelPdMap
);
six_theta_model!(
    /// The 6-θ model with PD control on v and ω (Laut 2011 Appendix A.3), `vw-pd`.
    VwPd, "vw-pd", VwPdMap
);

/// Names of the built-in models.
pub const MODEL_NAMES: [&str; 2] = ["wheel-pd", "vw-pd"];

/// The built-in model called `name`, or `None`.
pub fn by_name(name: &str) -> Option<Box<dyn RegressorModel>> {
    match name {
        "wheel-pd" => Some(Box::new(WheelPd)),
        "vw-pd" => Some(Box::new(VwPd)),
        _ => None,
    }
}
