//! Step 3 of [`super::identify`]: the estimators. Least squares (Laut 2011 eq. 4.3–4.7) always
//! runs — it is every other estimator's start — and each refining estimator
//! ([`wheelid_core::Estimator`]: the built-ins of [`crate::estimators`] and plugins') is run
//! by [`refine`] when asked for or compared.

use std::time::Instant;

use wheelid_core::{
    BoundState, ChannelRegression, Estimate, Estimator, EstimatorInput, LinearFit, LinearProblem,
    RegressorModel, SolveStatus, Solver, metrics,
};

use super::prepare::Prepared;
use super::{EstimateReport, IdentifyError, IdentifySettings};
use crate::estimators::LEAST_SQUARES;

/// Least squares' answer with what the report needs of its regression.
pub(super) struct LeastSquares {
    /// The estimate (θ, Newey–West standard errors, bound states).
    pub report: EstimateReport,
    /// Per channel: R² of the filtered regression, condition number, samples.
    pub quality: Vec<(f64, f64, usize)>,
    /// The stacked regressions per channel, thinned to at most [`PLOT_ROWS`] rows (for the
    /// regression plots).
    pub regressions: Vec<ChannelRegression>,
}

/// Rows of each channel's regression kept for the plots (every k-th row of a longer run: a
/// 1e6-row run keeps 20,000 instead of the whole 1e6 × 3 matrix).
pub(super) const PLOT_ROWS: usize = 20_000;

/// Builds each recording's regression (eq. 4.2), stacks them per channel and solves each
/// channel with `solver` (eq. 4.3–4.7, within `settings.bounds` when given).
///
/// # Errors
/// [`IdentifyError::Core`] from the model's regression, [`IdentifyError::Solve`] naming the
/// channel whose problem could not be solved.
pub(super) fn least_squares(
    model: &dyn RegressorModel,
    solver: &dyn Solver,
    data: &Prepared<'_>,
    settings: &IdentifySettings,
) -> Result<LeastSquares, IdentifyError> {
    let per_file: Vec<Vec<ChannelRegression>> = data
        .conditioned
        .iter()
        .map(|c| model.regression(c))
        .collect::<Result<_, _>>()?;
    let regressions = ChannelRegression::stack(per_file);
    let p = model.params().len();
    let names: Vec<&str> = model.params().iter().map(|q| q.name).collect();
    let mut theta = vec![0.0; p];
    let mut std_err = vec![0.0; p];
    let mut bound_state = vec![BoundState::Free; p];
    let clock = Instant::now();
    // The channels' problems are independent: solved at once, on the available cores.
    let solve = |reg: &ChannelRegression| -> Result<(LinearFit, (f64, f64, usize)), IdentifyError> {
        let ch_names: Vec<&str> = reg.params.iter().map(|&i| names[i]).collect();
        let ch_bounds: Option<Vec<(f64, f64)>> = settings
            .bounds
            .as_ref()
            .map(|b| reg.params.iter().map(|&i| b[i]).collect());
        let problem = LinearProblem {
            x: &reg.x,
            y: &reg.y,
            names: &ch_names,
            bounds: ch_bounds.as_deref(),
            correlation_lags: data.lags,
        };
        let fit = solver
            .solve(&problem)
            .map_err(|source| IdentifyError::Solve {
                channel: reg.channel.into(),
                source,
            })?;
        let yhat = &reg.x * &fit.theta;
        let quality = (
            metrics::r_squared(reg.y.as_slice(), yhat.as_slice()),
            fit.condition_number,
            reg.y.len(),
        );
        Ok((fit, quality))
    };
    let fits: Vec<(LinearFit, (f64, f64, usize))> = {
        use rayon::prelude::*;
        regressions
            .par_iter()
            .map(solve)
            .collect::<Result<_, _>>()?
    };
    let mut quality = Vec::with_capacity(fits.len());
    for (reg, (fit, q)) in regressions.iter().zip(fits) {
        for (j, &i) in reg.params.iter().enumerate() {
            theta[i] = fit.theta[j];
            std_err[i] = fit.std_err[j];
            bound_state[i] = fit.bound_state[j];
        }
        quality.push(q);
    }
    Ok(LeastSquares {
        report: EstimateReport {
            estimator: LEAST_SQUARES.into(),
            theta,
            std_err,
            status: SolveStatus::Solved,
            bound_state,
            invalid: None,
            iterations: 1,
            seconds: clock.elapsed().as_secs_f64(),
        },
        quality,
        regressions: regressions
            .into_iter()
            .map(|r| r.thinned(PLOT_ROWS))
            .collect(),
    })
}

/// Runs `estimator` on the prepared data from least squares' `ls_theta`, and times it.
///
/// # Errors
/// [`IdentifyError::Solve`] naming the estimator when its problem cannot be solved.
pub(super) fn refine(
    estimator: &dyn Estimator,
    model: &dyn RegressorModel,
    data: &Prepared<'_>,
    ls_theta: &[f64],
    settings: &IdentifySettings,
) -> Result<(EstimateReport, Estimate), IdentifyError> {
    let clock = Instant::now();
    let input = EstimatorInput {
        model,
        recordings: &data.restamped,
        conditioned: &data.conditioned,
        start: ls_theta,
        bounds: settings.bounds.as_deref(),
        cutoff_hz: data.cutoff_hz,
        condition: &settings.condition,
        lags: data.lags,
    };
    let name = estimator.name().to_owned();
    let mut estimate = estimator
        .estimate(&input)
        .map_err(|source| IdentifyError::Solve {
            channel: name.clone(),
            source,
        })?;
    let p = model.params().len();
    if estimate.theta.len() != p || estimate.std_err.len() != p || estimate.bound_state.len() != p {
        return Err(IdentifyError::Setting(format!(
            "estimator `{name}` returned {} values of θ, {} standard errors and {} bound states \
             for the {p} parameters of model `{}`",
            estimate.theta.len(),
            estimate.std_err.len(),
            estimate.bound_state.len(),
            model.name()
        )));
    }
    let report = EstimateReport {
        estimator: name,
        theta: std::mem::take(&mut estimate.theta),
        std_err: std::mem::take(&mut estimate.std_err),
        status: estimate.status,
        bound_state: std::mem::take(&mut estimate.bound_state),
        invalid: None,
        iterations: estimate.iterations,
        seconds: clock.elapsed().as_secs_f64(),
    };
    Ok((report, estimate))
}
