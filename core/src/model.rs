//! The model traits.
//!
//! [`DynamicModel`]: a model that simulates its outputs from a recording's commands (free run),
//!
//! ```text
//! ŷ(t_k) = G(θ, x0; u(t), t ≤ t_k)      u = (v_ref, ω_ref), y = (v, ω),
//! ```
//!
//! and may give the output sensitivities ∂ŷ/∂θ, ∂ŷ/∂x0 that output-error fitting needs (forward
//! sensitivity equations; the fitter falls back to finite differences). Any such model can be
//! fitted by simulation error, including models whose parameters enter non-linearly (a dead
//! time, a rate limit, a saturation level).
//!
//! [`RegressorModel`]: a dynamic model that is also linear in its parameters,
//!
//! ```text
//! y_c = Φ_c(signals) · θ_c      for each output channel c,
//! ```
//!
//! where y_c is a (filtered) command, Φ_c the n × p_c regressor built from conditioned
//! measurements, and θ_c the slice of the full parameter vector θ that channel c uses
//! (Laut 2011 eq. 4.1–4.2 splits the six θ of eq. 2.19 into two 3-parameter channels).

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

/// Whether a model's parameters begin with θ1…θ6 of eq. 2.19 (`theta1` … `theta6`): the
/// built-in parameterizations, and a plugin's model that extends them with its own. Stability,
/// physical starts and the diagnosis's candidates are defined on those six.
pub fn extends_eq_2_19(params: &[ParamInfo]) -> bool {
    params.len() >= 6
        && params
            .iter()
            .take(6)
            .enumerate()
            .all(|(i, q)| q.name == format!("theta{}", i + 1))
}

/// One output channel of a model.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct ChannelInfo {
    /// Channel name, the measured column it predicts: `v` or `w`.
    pub name: &'static str,
    /// The command that drives it (the regressand of a regressor model): `v_ref` or `w_ref`.
    pub command: &'static str,
    /// Indices into θ of the parameters in this channel's equation (regressor-column order for
    /// a [`RegressorModel`]).
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

impl ChannelRegression {
    /// Every k-th row from the first, k = ⌈n / `max_rows`⌉: at most `max_rows` rows (all of
    /// them when n ≤ `max_rows`, moved, not copied) — what a plot of a long run needs.
    pub fn thinned(self, max_rows: usize) -> Self {
        let n = self.y.len();
        if n <= max_rows.max(1) {
            return self;
        }
        let step = n.div_ceil(max_rows.max(1));
        let rows: Vec<usize> = (0..n).step_by(step).collect();
        ChannelRegression {
            channel: self.channel,
            params: self.params,
            x: self.x.select_rows(&rows),
            y: self.y.select_rows(&rows),
        }
    }

    /// Stacks per-recording regressions channel by channel (rows of recording 1, then 2, …):
    /// one multi-experiment problem. `per_file[r][c]` is recording r's channel c; every
    /// recording must list the same channels with the same columns. One recording's
    /// regressions are returned as they are (moved, not copied).
    pub fn stack(mut per_file: Vec<Vec<ChannelRegression>>) -> Vec<ChannelRegression> {
        if per_file.len() == 1 {
            return per_file.pop().unwrap_or_default();
        }
        let Some(first) = per_file.first() else {
            return Vec::new();
        };
        first
            .iter()
            .enumerate()
            .map(|(ch, proto)| {
                let n: usize = per_file.iter().map(|f| f[ch].y.len()).sum();
                let k = proto.x.ncols();
                let mut x = DMatrix::zeros(n, k);
                let mut y = DVector::zeros(n);
                let mut row = 0;
                for f in &per_file {
                    let r = &f[ch];
                    x.view_mut((row, 0), (r.y.len(), k)).copy_from(&r.x);
                    y.rows_mut(row, r.y.len()).copy_from(&r.y);
                    row += r.y.len();
                }
                ChannelRegression {
                    channel: proto.channel,
                    params: proto.params.clone(),
                    x,
                    y,
                }
            })
            .collect()
    }
}

/// Free-run output of a model: one simulated series per channel, in channel order.
pub type Simulation = Vec<Vec<f64>>;

/// Output sensitivities of a free-run simulation, per channel c, on the recording's time base:
/// `theta[c]` is n × p with entries ∂ŷ_c(t_k)/∂θ_j, `initial[c]` is n × s with entries
/// ∂ŷ_c(t_k)/∂x0_i (s = number of channels: the initial state is one value per channel).
#[derive(Debug, Clone, PartialEq)]
pub struct Sensitivities {
    /// ∂ŷ_c/∂θ, one n × p matrix per channel.
    pub theta: Vec<DMatrix<f64>>,
    /// ∂ŷ_c/∂x0, one n × s matrix per channel.
    pub initial: Vec<DMatrix<f64>>,
}

/// A model that simulates its outputs from the commands of a recording.
///
/// Implementations: `wheelid_models::WheelPd` and `wheelid_models::VwPd` (Laut 2011 eq. 2.19,
/// with analytic sensitivities). Models are plain data, shared by the fitters' worker threads
/// (`Send + Sync`).
pub trait DynamicModel: Send + Sync {
    /// Model name as used on the command line and in files, e.g. `vw-pd`.
    fn name(&self) -> &str;

    /// The parameters θ, in order.
    fn params(&self) -> &[ParamInfo];

    /// The output channels (also the state the simulation starts from: one value each).
    fn channels(&self) -> &[ChannelInfo];

    /// Free-run simulation of the channels from the recording's commands (applied as the
    /// recording says: held or sampled), starting from `initial` (one value per channel), on the
    /// recording's time base; outputs follow the recording's velocity sampling (instant values or
    /// window averages).
    ///
    /// # Errors
    /// If `theta` has the wrong length or makes the model singular.
    fn simulate(&self, theta: &[f64], rec: &Recording, initial: &[f64]) -> Result<Simulation>;

    /// The same simulation with its output sensitivities, or `None` if the model does not
    /// provide them (fitters then use finite differences of [`DynamicModel::simulate`]).
    ///
    /// # Errors
    /// As [`DynamicModel::simulate`].
    fn simulate_with_sensitivities(
        &self,
        theta: &[f64],
        rec: &Recording,
        initial: &[f64],
    ) -> Result<Option<(Simulation, Sensitivities)>> {
        let _ = (theta, rec, initial);
        Ok(None)
    }
}

/// A dynamic model linear in its parameters: each channel's command is a regressor times θ.
///
/// Implementations: `wheelid_models::WheelPd` (Laut 2011 §2.2) and `wheelid_models::VwPd`
/// (Appendix A.3).
pub trait RegressorModel: DynamicModel {
    /// Builds each channel's regression from a conditioned recording.
    ///
    /// # Errors
    /// Conditioning errors (recording too short for the filter).
    fn regression(&self, data: &Conditioned<'_>) -> Result<Vec<ChannelRegression>>;

    /// The rows of [`RegressorModel::regression`] handed to `sink` block by block, in order:
    /// each call one block of consecutive rows, one [`ChannelRegression`] per channel (the
    /// channels' blocks may differ in length). Stacked, the blocks are the whole regression.
    /// A long recording's least squares runs on these (a QR factor updated block by block),
    /// never holding a whole regressor. The default hands over the whole regression as one
    /// block; the built-in eq. 2.19 models filter block by block
    /// ([`Conditioned::smooth_blocks`]).
    ///
    /// # Errors
    /// As [`RegressorModel::regression`]; the first error of `sink` (which ends the run).
    fn regression_blocks(
        &self,
        data: &Conditioned<'_>,
        sink: &mut dyn FnMut(Vec<ChannelRegression>) -> Result<()>,
    ) -> Result<()> {
        sink(self.regression(data)?)
    }
}
