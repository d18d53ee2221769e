//! Any model with a signed command-to-response timing offset: the host's stamping convention
//! made a parameter.
//!
//! A recording pairs each command with a measurement, but hosts stamp them differently
//! (`wheelid_core::Timing`): the command of row k may act from its stamp t_k (conventions (a),
//! (b)) or half a sample before it (c, stamped at the window's middle), and a host's clock may
//! sit a fraction of a sample off the robot's. [`CommandOffset`] wraps a [`DynamicModel`] and
//! lets its commands act from t_k + δ instead of t_k:
//!
//! ```text
//! u(t) = u_k    for t ∈ [t_k + δ, t_{k+1} + δ)          (zero-order hold shifted by δ)
//! ŷ_k  = y(t_k)                                          (instant sampling)
//! ŷ_k  = (1/(t_k − t_{k−1})) ∫_{t_{k−1}}^{t_k} y(t) dt    (window-average sampling)
//! ```
//!
//! δ < 0: the commands act before their stamps (−Δ/2 … −Δ for a window-middle stamp read as
//! window-end); δ > 0: after (a latency). The output windows stay where the stamps put them,
//! so a non-uniform recording is simulated on its own stamps: commands switch and windows
//! average where the stamps say. The wrapped model runs on the merged grid {t_k} ∪ {t_j + δ}
//! (as [`crate::InputDelay`] does, exact for any δ, not rounded to whole samples) and its
//! outputs are mapped back: instants read at t_k, window averages as the length-weighted means
//! of the sub-window averages. Before the first command takes effect the first command holds.
//!
//! Sensitivities: the wrapped model's (∂ŷ/∂θ, ∂ŷ/∂x0), mapped back the same way, plus ∂ŷ/∂δ by
//! central differences of the simulation (step 1e-6 of the median period).

use nalgebra::DMatrix;
use wheelid_core::{
    ChannelInfo, CommandHold, DynamicModel, Error, ParamInfo, Recording, Result, Sensitivities,
    Simulation, VelocitySampling,
};

use crate::delay::{InputDelay, merged_grid};

/// The offset parameter's description (appended to the wrapped model's parameters).
pub static OFFSET_PARAM: ParamInfo = ParamInfo {
    name: "offset",
    unit: "s",
    description: "when a row's command acts, relative to its stamp (negative: before it)",
};

/// A [`DynamicModel`] whose commands act `δ` seconds after their stamps; θ = (wrapped θ…, δ).
#[derive(Clone, Copy)]
pub struct CommandOffset<'a> {
    inner: &'a dyn DynamicModel,
    params: &'a [ParamInfo],
}

impl std::fmt::Debug for CommandOffset<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CommandOffset")
            .field("inner", &self.inner.name())
            .finish()
    }
}

impl<'a> CommandOffset<'a> {
    /// Wraps `inner`; `params` must be `inner`'s parameters followed by [`OFFSET_PARAM`]
    /// (see [`CommandOffset::params_of`]), kept by the caller so that the wrapper borrows only.
    ///
    /// # Errors
    /// [`Error::InvalidSetting`] if `params` is not that list.
    pub fn new(inner: &'a dyn DynamicModel, params: &'a [ParamInfo]) -> Result<Self> {
        let p = inner.params();
        if params.len() != p.len() + 1 || params[..p.len()] != *p || params[p.len()] != OFFSET_PARAM
        {
            return Err(Error::InvalidSetting(format!(
                "CommandOffset of `{}`: parameters must be the model's followed by `offset`",
                inner.name()
            )));
        }
        Ok(Self { inner, params })
    }

    /// The parameter list of the wrapped `inner`: its own, then the offset δ \[s\].
    pub fn params_of(inner: &dyn DynamicModel) -> Vec<ParamInfo> {
        let mut p = inner.params().to_vec();
        p.push(OFFSET_PARAM);
        p
    }

    /// The recording on the merged grid with the shifted commands, and where each t_k is in it.
    fn fine(&self, rec: &Recording, delta: f64) -> Result<(Recording, Vec<usize>)> {
        let (merged_t, index) = merged_grid(rec, delta, &[])?;
        let zoh = rec.command_hold() == CommandHold::Zoh;
        let before = (rec.v_ref[0], rec.w_ref[0]);
        // A held command is read at the middle of its sub-interval, so that rounding of
        // t_j + δ − δ cannot pick the neighbouring sample.
        let (vr, wr): (Vec<f64>, Vec<f64>) = (0..merged_t.len())
            .map(|i| {
                let t = match merged_t.get(i + 1) {
                    Some(next) if zoh => 0.5 * (merged_t[i] + next),
                    _ => merged_t[i],
                };
                InputDelay::command_at(rec, t - delta, before)
            })
            .unzip();
        let m = merged_t.len();
        let mut fine = Recording::new(
            rec.source.clone(),
            merged_t,
            vr,
            wr,
            vec![0.0; m],
            vec![0.0; m],
        )?;
        fine.set_meta("command_hold", if zoh { "zoh" } else { "sampled" });
        fine.set_meta(
            "velocity_sampling",
            match rec.velocity_sampling() {
                VelocitySampling::Instant => "instant",
                VelocitySampling::WindowAverage => "window_average",
            },
        );
        Ok((fine, index))
    }

    fn split<'t>(&self, theta: &'t [f64]) -> Result<(&'t [f64], f64)> {
        match theta.split_last() {
            Some((&d, th)) if th.len() == self.inner.params().len() && d.is_finite() => Ok((th, d)),
            _ => Err(Error::InvalidSetting(format!(
                "θ of `{}` with an offset has {} finite values, got {theta:?}",
                self.inner.name(),
                self.params.len()
            ))),
        }
    }
}

/// Rows of a fine-grid series mapped back to the recording's samples: picked at t_k (instant)
/// or averaged over [t_{k−1}, t_k] by sub-window length (window average).
fn map_back(y: &[f64], t: &[f64], index: &[usize], avg: bool) -> Vec<f64> {
    index
        .iter()
        .enumerate()
        .map(|(kk, &i)| {
            if !avg || kk == 0 {
                return y[i];
            }
            let i0 = index[kk - 1];
            let total: f64 = (i0 + 1..=i).map(|j| (t[j] - t[j - 1]) * y[j]).sum();
            total / (t[i] - t[i0])
        })
        .collect()
}

/// The same mapping for each column of a fine-grid sensitivity matrix.
fn map_back_matrix(s: &DMatrix<f64>, t: &[f64], index: &[usize], avg: bool) -> DMatrix<f64> {
    let mut out = DMatrix::zeros(index.len(), s.ncols());
    for j in 0..s.ncols() {
        let col: Vec<f64> = s.column(j).iter().copied().collect();
        for (k, v) in map_back(&col, t, index, avg).into_iter().enumerate() {
            out[(k, j)] = v;
        }
    }
    out
}

impl DynamicModel for CommandOffset<'_> {
    fn name(&self) -> &str {
        self.inner.name()
    }
    fn params(&self) -> &[ParamInfo] {
        self.params
    }
    fn channels(&self) -> &[ChannelInfo] {
        self.inner.channels()
    }
    fn simulate(&self, theta: &[f64], rec: &Recording, initial: &[f64]) -> Result<Simulation> {
        let (th, delta) = self.split(theta)?;
        if rec.is_empty() {
            return Err(Error::InvalidSetting("the recording is empty".into()));
        }
        let (fine, index) = self.fine(rec, delta)?;
        let y = self.inner.simulate(th, &fine, initial)?;
        let avg = rec.velocity_sampling() == VelocitySampling::WindowAverage;
        Ok(y.iter()
            .map(|yc| map_back(yc, &fine.t, &index, avg))
            .collect())
    }

    fn simulate_with_sensitivities(
        &self,
        theta: &[f64],
        rec: &Recording,
        initial: &[f64],
    ) -> Result<Option<(Simulation, Sensitivities)>> {
        let (th, delta) = self.split(theta)?;
        if rec.len() < 2 {
            return Err(Error::InvalidSetting(
                "a recording needs two samples".into(),
            ));
        }
        let (fine, index) = self.fine(rec, delta)?;
        let Some((y, s)) = self.inner.simulate_with_sensitivities(th, &fine, initial)? else {
            return Ok(None);
        };
        let avg = rec.velocity_sampling() == VelocitySampling::WindowAverage;
        let t = &fine.t;
        let ys: Simulation = y.iter().map(|yc| map_back(yc, t, &index, avg)).collect();
        // ∂ŷ/∂δ by central differences.
        let h = 1e-6 * rec.sampling().dt_median;
        let mut plus = theta.to_vec();
        let mut minus = theta.to_vec();
        let last = theta.len() - 1;
        plus[last] = delta + h;
        minus[last] = delta - h;
        let (yp, ym) = (
            self.simulate(&plus, rec, initial)?,
            self.simulate(&minus, rec, initial)?,
        );
        let n = rec.len();
        let mut theta_s = Vec::with_capacity(ys.len());
        let mut init_s = Vec::with_capacity(ys.len());
        for c in 0..ys.len() {
            let st = map_back_matrix(&s.theta[c], t, &index, avg);
            let mut full = DMatrix::zeros(n, st.ncols() + 1);
            full.columns_mut(0, st.ncols()).copy_from(&st);
            for k in 0..n {
                full[(k, st.ncols())] = (yp[c][k] - ym[c][k]) / (2.0 * h);
            }
            theta_s.push(full);
            init_s.push(map_back_matrix(&s.initial[c], t, &index, avg));
        }
        Ok(Some((
            ys,
            Sensitivities {
                theta: theta_s,
                initial: init_s,
            },
        )))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::VwPd;

    const THETA: [f64; 6] = [0.26, 0.25, -0.05, 0.9965, 0.08, 1.0768];

    fn recording(avg: bool, jitter: bool) -> Recording {
        let n = 80;
        let t: Vec<f64> = (0..n)
            .map(|k| {
                k as f64 * 0.1
                    + if jitter {
                        0.01 * ((k * 7 % 5) as f64 - 2.0)
                    } else {
                        0.0
                    }
            })
            .collect();
        let vr: Vec<f64> = t.iter().map(|&x| 0.3 + 0.2 * (1.1 * x).sin()).collect();
        let wr: Vec<f64> = t.iter().map(|&x| 0.8 * (0.6 * x).cos()).collect();
        let mut rec = Recording::new("o", t, vr, wr, vec![0.0; n], vec![0.0; n]).expect("valid");
        if avg {
            rec.set_meta("velocity_sampling", "window_average");
        }
        rec
    }

    #[test]
    fn offset_zero_is_the_model_and_minus_one_sample_is_the_next_rows_command() {
        let params = CommandOffset::params_of(&VwPd);
        let m = CommandOffset::new(&VwPd, &params).expect("wraps");
        for avg in [false, true] {
            let rec = recording(avg, false);
            let x0 = [0.1, 0.05];
            let plain = VwPd.simulate(&THETA, &rec, &x0).expect("sim");
            let mut th = THETA.to_vec();
            th.push(0.0);
            let same = m.simulate(&th, &rec, &x0).expect("sim");
            // δ = −Δ: row k's command acts over [t_{k−1}, t_k), i.e. the commands moved one
            // row earlier by hand (the last one held).
            let mut early = rec.clone();
            early.v_ref.rotate_left(1);
            early.w_ref.rotate_left(1);
            let n = rec.len();
            early.v_ref[n - 1] = rec.v_ref[n - 1];
            early.w_ref[n - 1] = rec.w_ref[n - 1];
            let want = VwPd.simulate(&THETA, &early, &x0).expect("sim");
            th[6] = -0.1;
            let lead = m.simulate(&th, &rec, &x0).expect("sim");
            // δ = +Δ: row k's command acts over [t_{k+1}, t_{k+2}) (the first one before).
            let mut late = rec.clone();
            late.v_ref.rotate_right(1);
            late.w_ref.rotate_right(1);
            late.v_ref[0] = rec.v_ref[0];
            late.w_ref[0] = rec.w_ref[0];
            let want_late = VwPd.simulate(&THETA, &late, &x0).expect("sim");
            th[6] = 0.1;
            let lag = m.simulate(&th, &rec, &x0).expect("sim");
            for ch in 0..2 {
                for k in 0..n {
                    approx::assert_abs_diff_eq!(same[ch][k], plain[ch][k], epsilon = 1e-12);
                    approx::assert_abs_diff_eq!(lead[ch][k], want[ch][k], epsilon = 1e-9);
                    approx::assert_abs_diff_eq!(lag[ch][k], want_late[ch][k], epsilon = 1e-9);
                }
            }
        }
    }

    #[test]
    fn sensitivities_match_central_differences_on_jittered_stamps() {
        let params = CommandOffset::params_of(&VwPd);
        let m = CommandOffset::new(&VwPd, &params).expect("wraps");
        let rec = recording(true, true);
        let x0 = [0.05, -0.02];
        let mut th = THETA.to_vec();
        th.push(-0.037);
        let (_, s) = m
            .simulate_with_sensitivities(&th, &rec, &x0)
            .expect("sim")
            .expect("has sensitivities");
        for j in 0..7 {
            let h = 1e-6 * th[j].abs().max(1e-3);
            let (mut a, mut b) = (th.clone(), th.clone());
            a[j] += h;
            b[j] -= h;
            let (ya, yb) = (
                m.simulate(&a, &rec, &x0).expect("sim"),
                m.simulate(&b, &rec, &x0).expect("sim"),
            );
            for ch in 0..2 {
                for k in 0..rec.len() {
                    let fd = (ya[ch][k] - yb[ch][k]) / (2.0 * h);
                    let an = s.theta[ch][(k, j)];
                    assert!(
                        (fd - an).abs() <= 1e-5 * (1.0 + fd.abs()),
                        "param {j} ch {ch} k {k}: {an} vs {fd}"
                    );
                }
            }
        }
    }

    #[test]
    fn refuses_a_parameter_list_that_is_not_the_models_plus_offset() {
        assert!(CommandOffset::new(&VwPd, VwPd.params()).is_err());
        let params = CommandOffset::params_of(&VwPd);
        let m = CommandOffset::new(&VwPd, &params).expect("wraps");
        assert!(
            m.simulate(&THETA, &recording(false, false), &[0.0, 0.0])
                .is_err()
        );
    }
}
