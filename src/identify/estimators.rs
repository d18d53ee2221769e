//! Step 3 of [`super::identify`]: the estimators. Least squares (Laut 2011 eq. 4.3–4.7) always
//! runs — it is every other estimator's start — and each refining estimator is one
//! [`Refiner`] in [`REFINERS`], run when asked for or compared.

use std::time::Instant;

use wheelid_core::{
    BoundState, ChannelRegression, LinearProblem, Recording, RegressorModel, SolveStatus, Solver,
    metrics,
};
use wheelid_solvers::{InstrumentalVariables, OutputError};

use super::prepare::Prepared;
use super::{EstimateReport, Estimator, IdentifyError, IdentifySettings};
use crate::timing::{TimingReport, fit_with_timing};

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
    let mut quality = Vec::new();
    let clock = Instant::now();
    for reg in &regressions {
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
        for (j, &i) in reg.params.iter().enumerate() {
            theta[i] = fit.theta[j];
            std_err[i] = fit.std_err[j];
            bound_state[i] = fit.bound_state[j];
        }
        let yhat = &reg.x * &fit.theta;
        quality.push((
            metrics::r_squared(reg.y.as_slice(), yhat.as_slice()),
            fit.condition_number,
            reg.y.len(),
        ));
    }
    Ok(LeastSquares {
        report: EstimateReport {
            estimator: Estimator::Ls,
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

/// How an output-error answer is simulated: its estimated initial states, timing offset and the
/// recordings on the stamps it fitted.
pub(super) struct FreeRun {
    /// (v0, ω0) per recording.
    pub initial: Vec<Vec<f64>>,
    /// The command-to-response offset δ [s] it estimated, if it did.
    pub offset: Option<f64>,
    /// The recordings as it fitted them (restamped, on their own stamps).
    pub recordings: Vec<Recording>,
}

/// A refining estimator's answer.
pub(super) struct Refined {
    /// The estimate.
    pub report: EstimateReport,
    /// How to simulate it, when it differs from the recordings as conditioned.
    pub free_run: Option<FreeRun>,
    /// Residual standard deviation per channel, when the estimator measures it.
    pub noise_std: Option<Vec<f64>>,
    /// The stamping convention used, stated or estimated.
    pub timing: Option<TimingReport>,
}

/// An estimator that starts from least squares' θ and removes its errors-in-variables bias.
pub(super) trait Refiner: Sync {
    /// Which estimator this is.
    fn estimator(&self) -> Estimator;

    /// Its answer for `model` on `data`, started from the least-squares `ls_theta`.
    ///
    /// # Errors
    /// [`IdentifyError::Solve`] naming the estimator when its problem cannot be solved.
    fn refine(
        &self,
        model: &dyn RegressorModel,
        data: &Prepared<'_>,
        ls_theta: &[f64],
        settings: &IdentifySettings,
    ) -> Result<Refined, IdentifyError>;
}

/// The refining estimators, in report order ([`Estimator::ALL`] after least squares).
pub(super) const REFINERS: [&dyn Refiner; 2] = [&Iv, &Oe];

/// Instrumental variables (`wheelid_solvers::iv`), projected onto the bounds when given.
struct Iv;

impl Refiner for Iv {
    fn estimator(&self) -> Estimator {
        Estimator::Iv
    }

    fn refine(
        &self,
        model: &dyn RegressorModel,
        data: &Prepared<'_>,
        ls_theta: &[f64],
        settings: &IdentifySettings,
    ) -> Result<Refined, IdentifyError> {
        let clock = Instant::now();
        let fit = InstrumentalVariables::default()
            .fit(
                model,
                &data.conditioned,
                ls_theta,
                data.cutoff_hz,
                &settings.condition,
                data.lags,
            )
            .map_err(|source| IdentifyError::Solve {
                channel: "iv".into(),
                source,
            })?;
        let mut theta = fit.theta.clone();
        let mut bound_state = vec![BoundState::Free; theta.len()];
        if let Some(b) = &settings.bounds {
            for (i, (t, s)) in theta.iter_mut().zip(&mut bound_state).enumerate() {
                if *t < b[i].0 {
                    *t = b[i].0;
                    *s = BoundState::AtLower;
                } else if *t > b[i].1 {
                    *t = b[i].1;
                    *s = BoundState::AtUpper;
                }
            }
        }
        Ok(Refined {
            report: EstimateReport {
                estimator: Estimator::Iv,
                theta,
                std_err: fit.std_err,
                status: fit.status,
                bound_state,
                invalid: None,
                iterations: fit.iterations,
                seconds: clock.elapsed().as_secs_f64(),
            },
            free_run: None,
            noise_std: None,
            timing: None,
        })
    }
}

/// Output error (`wheelid_solvers::oe`) on the recordings' own stamps, with the timing offset
/// where a recording does not state its stamping ([`crate::timing`]).
struct Oe;

impl Refiner for Oe {
    fn estimator(&self) -> Estimator {
        Estimator::Oe
    }

    fn refine(
        &self,
        model: &dyn RegressorModel,
        data: &Prepared<'_>,
        ls_theta: &[f64],
        settings: &IdentifySettings,
    ) -> Result<Refined, IdentifyError> {
        let oe = OutputError {
            bounds: settings.bounds.clone(),
            ..OutputError::default()
        };
        let timed = fit_with_timing(model, &data.restamped, ls_theta, &oe).map_err(|source| {
            IdentifyError::Solve {
                channel: "oe".into(),
                source,
            }
        })?;
        let fit = timed.fit;
        let p = model.params().len();
        Ok(Refined {
            report: EstimateReport {
                estimator: Estimator::Oe,
                theta: fit.theta[..p].to_vec(),
                std_err: fit.std_err[..p].to_vec(),
                status: fit.status,
                bound_state: fit.bound_state[..p].to_vec(),
                invalid: None,
                iterations: fit.evaluations,
                seconds: fit.seconds,
            },
            free_run: Some(FreeRun {
                initial: fit.initial,
                offset: timed.offset,
                recordings: timed.recordings,
            }),
            noise_std: Some(fit.noise_std),
            timing: Some(timed.timing),
        })
    }
}
