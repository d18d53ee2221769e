//! The [`RegressorModel`] trait: models that are linear in their parameters,
//!
//! ```text
//! y_c = Φ_c(signals) · θ_c      for each output channel c,
//! ```
//!
//! where y_c is a (filtered) command, Φ_c the n × p_c regressor built from conditioned
//! measurements, and θ_c the slice of the full parameter vector θ that channel c uses
//! (Laut 2011 eq. 4.1–4.2 splits the six θ of eq. 2.19 into two 3-parameter channels).
//! A model also simulates its own output from the commands (free-run), which is how its fit
//! is judged.

use nalgebra::{DMatrix, DVector};

use crate::condition::Conditioned;
use crate::error::Result;
use crate::recording::Recording;

/// One parameter of a model.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct ParamInfo {
    /// Machine name, e.g. `theta1`.
    pub name: &'static str,
    /// Unit, e.g. `s`, `s·m/rad²`, `-`.
    pub unit: &'static str,
    /// What the parameter means.
    pub description: &'static str,
}

/// One output channel of a model.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct ChannelInfo {
    /// Channel name, the measured column it predicts: `v` or `w`.
    pub name: &'static str,
    /// The command that forms the regressand: `v_ref` or `w_ref`.
    pub command: &'static str,
    /// Indices into θ of this channel's parameters, in regressor-column order.
    pub params: &'static [usize],
}

/// The regression of one channel: y (n) ≈ x (n × p) · θ\[params\].
#[derive(Debug, Clone, PartialEq)]
pub struct ChannelRegression {
    /// Channel name.
    pub channel: &'static str,
    /// Indices into θ, one per column of `x`.
    pub params: Vec<usize>,
    /// Regressor matrix Φ, n × p.
    pub x: DMatrix<f64>,
    /// Regressand, length n.
    pub y: DVector<f64>,
}

/// Free-run output of a model: one simulated series per channel, in channel order.
pub type Simulation = Vec<Vec<f64>>;

/// A model linear in its parameters, with a free-run simulator.
///
/// Implementations: `wheelid_models::WheelPd` (Laut 2011 §2.2) and `wheelid_models::VwPd`
/// (Appendix A.3).
pub trait RegressorModel {
    /// Model name as used on the command line and in files, e.g. `vw-pd`.
    fn name(&self) -> &str;

    /// The parameters θ, in order.
    fn params(&self) -> &[ParamInfo];

    /// The output channels.
    fn channels(&self) -> &[ChannelInfo];

    /// Builds each channel's regression from a conditioned recording.
    ///
    /// # Errors
    /// Conditioning errors (recording too short for the filter).
    fn regression(&self, data: &Conditioned) -> Result<Vec<ChannelRegression>>;

    /// Free-run simulation of the channels from the recording's commands (applied as the
    /// recording says: held or sampled), starting from `initial` (one value per channel), on the
    /// recording's time base; outputs follow the recording's velocity sampling (instant values or
    /// window averages).
    ///
    /// # Errors
    /// If `theta` has the wrong length or makes the model singular.
    fn simulate(&self, theta: &[f64], rec: &Recording, initial: &[f64]) -> Result<Simulation>;
}
