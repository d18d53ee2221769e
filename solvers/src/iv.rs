//! Instrumental variables with instruments from the model's own noise-free simulation.
//!
//! The regression of a [`RegressorModel`] (Laut 2011 eq. 4.2) puts the measurement noise in
//! the regressors — filtered v, ω, their products and derivatives — so least squares is biased
//! (errors in variables). Instrumental variables keep the regression but replace, in the normal
//! equations, the regressor Φ by an instrument Z built the same way from a signal that is
//! correlated with the true outputs and not with the noise: the model's free-run simulation
//! from the recorded commands, conditioned exactly as the measurements were (same filter, same
//! derivative, same alignment). Per channel c,
//!
//! ```text
//! θ̂_c = (Z_cᵀ Φ_c)⁻¹ Z_cᵀ y_c,     Z_c = Φ_c( condition( simulate(θ̂, commands) ) ),
//! ```
//!
//! the auxiliary-model IV of Young (1970) and Söderström & Stoica, *System Identification*
//! (1989) §8, whose instruments approach the noise-free regressors as θ̂ converges.
//!
//! Instruments remove the noise bias but not the regression's *deterministic* error — the
//! derivative of sampled data, the filtering of a held command as if it were a smooth signal,
//! window-averaged velocities — which at 10 Hz with commands up to 2 Hz moves θ1 by ~6 %. The
//! same error is in the regression of the noise-free simulation, so the refinement matches the
//! two (simulation-based bias correction, as indirect inference: Gouriéroux, Monfort & Renault
//! 1993):
//!
//! ```text
//! θ_{k+1} = θ_k + ( θ̂_IV(data; Z(θ_k)) − θ̂_IV(sim(θ_k); Z(θ_k)) ),
//! ```
//!
//! whose fixed point makes the data's IV estimate equal the one the model at θ would produce.
//! The map has a Jacobian near the identity (the error is a few %), so a handful of iterations
//! from the least-squares θ converge; every step is linear. What the correction cannot remove
//! is what the simulation does not share with the data (unmodelled physics), and its accuracy
//! still depends on the derivative being informative, which is why [`crate::oe`] stays the
//! reference estimator.
//!
//! Covariance: Cov(θ̂_c) = A (Σ_l w_l Σ_t g_t g_{t+l}ᵀ) Aᵀ · n/(n − p), A = (ZᵀΦ)⁻¹,
//! g_t = Z\[t,:\]ᵀ e_t, e = y − Φθ̂, with Bartlett weights over the given correlation length.

use nalgebra::{DMatrix, DVector};
use wheelid_core::condition::{self, ConditionSettings};
use wheelid_core::{ChannelRegression, Conditioned, RegressorModel, SolveError, SolveStatus};

/// Settings of the instrumental-variable estimator (the result is an [`IvFit`]).
#[derive(Debug, Clone, PartialEq)]
pub struct InstrumentalVariables {
    /// Most iterations (simulate → instruments → solve).
    pub max_iterations: usize,
    /// Stop when no θ_i moves by more than this, relative to max(|θ_i|, 1e-3·‖θ‖∞).
    pub tolerance: f64,
}

impl Default for InstrumentalVariables {
    fn default() -> Self {
        Self {
            max_iterations: 20,
            tolerance: 1e-7,
        }
    }
}

/// A fitted instrumental-variable model.
#[derive(Debug, Clone, PartialEq)]
pub struct IvFit {
    /// θ̂, one per model parameter.
    pub theta: Vec<f64>,
    /// Standard errors of θ̂.
    pub std_err: Vec<f64>,
    /// Covariance of θ̂, p × p (block-diagonal over channels).
    pub covariance: DMatrix<f64>,
    /// Iterations done.
    pub iterations: usize,
    /// [`SolveStatus::Solved`] if θ̂ settled within the tolerance, else
    /// [`SolveStatus::IterationLimit`].
    pub status: SolveStatus,
}

impl InstrumentalVariables {
    /// Fits `model` by instrumental variables on conditioned recordings, starting from
    /// `theta0`. Each recording is simulated from its commands on its uniform grid
    /// (`Conditioned::recording`), starting from its smoothed first sample, then conditioned
    /// with `cutoff_hz` and `settings` — the same as the measurements.
    ///
    /// # Errors
    /// [`SolveError::InvalidProblem`] if a simulation or conditioning fails or the shapes do
    /// not match; [`SolveError::RankDeficient`] if ZᵀΦ is singular (the instruments do not
    /// excite some parameter).
    pub fn fit<M: RegressorModel + ?Sized>(
        &self,
        model: &M,
        data: &[Conditioned<'_>],
        theta0: &[f64],
        cutoff_hz: f64,
        settings: &ConditionSettings,
        correlation_lags: usize,
    ) -> Result<IvFit, SolveError> {
        let p = model.params().len();
        if theta0.len() != p {
            return Err(SolveError::InvalidProblem(format!(
                "θ0 has {} values, model `{}` has {p} parameters",
                theta0.len(),
                model.name()
            )));
        }
        if data.is_empty() {
            return Err(SolveError::InvalidProblem("no recording".into()));
        }
        let invalid = |e: wheelid_core::Error| SolveError::InvalidProblem(e.to_string());
        let per_file = data
            .iter()
            .map(|c| model.regression(c))
            .collect::<Result<Vec<_>, _>>()
            .map_err(invalid)?;
        let regressions = ChannelRegression::stack(per_file);
        let initial: Vec<Vec<f64>> = data
            .iter()
            .map(|c| Ok(c.initial_state()?.to_vec()))
            .collect::<Result<_, wheelid_core::Error>>()
            .map_err(invalid)?;
        if regressions
            .iter()
            .any(|r| r.y.len() != regressions[0].y.len())
        {
            return Err(SolveError::InvalidProblem(
                "channels have different numbers of rows".into(),
            ));
        }
        let mut theta = theta0.to_vec();
        let mut covariance = DMatrix::zeros(p, p);
        let mut status = SolveStatus::IterationLimit;
        let mut iterations = 0;
        while iterations < self.max_iterations {
            iterations += 1;
            // Instruments: the regression of the conditioned noise-free simulation.
            let mut inst_files = Vec::with_capacity(data.len());
            for (c, x0) in data.iter().zip(&initial) {
                let sim = model.simulate(&theta, &c.recording, x0).map_err(invalid)?;
                let mut rec = c.recording.clone().into_owned();
                let (Some(v), Some(w)) = (sim.first(), sim.get(1)) else {
                    return Err(SolveError::InvalidProblem(
                        "IV needs a model with (v, ω) outputs".into(),
                    ));
                };
                if v.iter().chain(w).any(|x| !x.is_finite()) {
                    return Err(SolveError::Numerical(format!(
                        "the model diverges at θ = {theta:?}"
                    )));
                }
                rec.v.clone_from(v);
                rec.w.clone_from(w);
                let cs = condition::condition(&rec, c.resampled_from, cutoff_hz, settings)
                    .map_err(invalid)?;
                inst_files.push(model.regression(&cs).map_err(invalid)?);
            }
            let instruments = ChannelRegression::stack(inst_files);
            let mut next = theta.clone();
            for (reg, inst) in regressions.iter().zip(&instruments) {
                let names: Vec<&str> = reg.params.iter().map(|&i| model.params()[i].name).collect();
                let (th_data, cov) = solve_iv(reg, &inst.x, &names, correlation_lags)?;
                let (th_sim, _) = solve_iv(inst, &inst.x, &names, 0)?;
                for (j, &i) in reg.params.iter().enumerate() {
                    next[i] = theta[i] + th_data[j] - th_sim[j];
                    for (l, &m) in reg.params.iter().enumerate() {
                        covariance[(i, m)] = cov[(j, l)];
                    }
                }
            }
            let scale = 1e-3 * next.iter().fold(0.0f64, |a, x| a.max(x.abs()));
            let moved = next
                .iter()
                .zip(&theta)
                .map(|(a, b)| (a - b).abs() / a.abs().max(scale).max(f64::MIN_POSITIVE))
                .fold(0.0f64, f64::max);
            theta = next;
            if moved <= self.tolerance {
                status = SolveStatus::Solved;
                break;
            }
        }
        Ok(IvFit {
            std_err: (0..p).map(|i| covariance[(i, i)].max(0.0).sqrt()).collect(),
            covariance,
            theta,
            iterations,
            status,
        })
    }
}

/// θ̂ = (ZᵀΦ)⁻¹ Zᵀy for one channel, and its covariance (module doc).
fn solve_iv(
    reg: &ChannelRegression,
    z: &DMatrix<f64>,
    names: &[&str],
    lags: usize,
) -> Result<(DVector<f64>, DMatrix<f64>), SolveError> {
    let (n, k) = reg.x.shape();
    if z.shape() != (n, k) || n <= k {
        return Err(SolveError::InvalidProblem(format!(
            "instruments are {}×{}, regressor {n}×{k}",
            z.nrows(),
            z.ncols()
        )));
    }
    // Column scaling keeps ZᵀΦ well conditioned across parameters of different units.
    let sx: Vec<f64> = reg.x.column_iter().map(|c| c.norm().max(1e-300)).collect();
    let sz: Vec<f64> = z.column_iter().map(|c| c.norm().max(1e-300)).collect();
    let m = DMatrix::from_fn(k, k, |i, j| {
        z.column(i).dot(&reg.x.column(j)) / (sz[i] * sx[j])
    });
    let svd = m.clone().svd(true, true);
    let smax = svd.singular_values.max();
    if svd.singular_values.min() <= 1e-10 * smax {
        return Err(SolveError::RankDeficient {
            names: names.iter().map(|s| (*s).to_owned()).collect(),
            rank: svd.rank(1e-10 * smax),
            p: k,
        });
    }
    let Some(minv) = m.try_inverse() else {
        return Err(SolveError::Numerical("ZᵀΦ is not invertible".into()));
    };
    // A = (ZᵀΦ)⁻¹ in original units: D_x⁻¹ M⁻¹ D_z⁻¹.
    let a = DMatrix::from_fn(k, k, |i, j| minv[(i, j)] / (sx[i] * sz[j]));
    let theta = &a * (z.transpose() * &reg.y);
    let e = &reg.y - &reg.x * &theta;
    let g = DMatrix::from_fn(n, k, |t, j| z[(t, j)] * e[t]);
    let mut meat = crate::ols::bartlett_meat(&g, lags);
    meat *= n as f64 / (n - k) as f64;
    let cov = &a * meat * a.transpose();
    Ok((theta, cov))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exactly_determined_iv_recovers_a_line_and_the_textbook_variance() {
        // y = 2 x + noise-free: any valid instrument gives θ = 2 exactly, residual 0.
        let n = 50;
        let x = DMatrix::from_fn(n, 1, |t, _| (t as f64 * 0.3).sin() + 1.5);
        let y = x.column(0) * 2.0;
        let z = DMatrix::from_fn(n, 1, |t, _| (t as f64 * 0.3).sin());
        let reg = ChannelRegression {
            channel: "v",
            params: vec![0],
            x,
            y,
        };
        let (th, cov) = solve_iv(&reg, &z, &["a"], 0).expect("solves");
        approx::assert_relative_eq!(th[0], 2.0, max_relative = 1e-12);
        assert!(cov[(0, 0)] < 1e-20);
        // With Z = X, IV is least squares: Var = σ² (XᵀX)⁻¹ by the White form with equal e².
        let xs = DMatrix::from_column_slice(4, 1, &[1.0, 2.0, 3.0, 4.0]);
        let ys = DVector::from_column_slice(&[1.0, 3.0, 2.0, 5.0]);
        let reg = ChannelRegression {
            channel: "v",
            params: vec![0],
            x: xs.clone(),
            y: ys,
        };
        let (th, cov) = solve_iv(&reg, &xs, &["a"], 0).expect("solves");
        // θ = Σxy/Σx² = (1 + 6 + 6 + 20)/30 = 1.1; e = (−0.1, 0.8, −1.3, 0.6);
        // Cov = Σ x²e² / (Σx²)² · n/(n−1) = (0.01 + 2.56 + 15.21 + 5.76)/900 · 4/3.
        approx::assert_relative_eq!(th[0], 1.1, max_relative = 1e-12);
        approx::assert_relative_eq!(cov[(0, 0)], 23.54 / 900.0 * 4.0 / 3.0, max_relative = 1e-12);
    }
}
