//! Step 3 of [`super::identify`]: the estimators. Least squares (Laut 2011 eq. 4.3–4.7) always
//! runs — it is every other estimator's start — and each refining estimator
//! ([`wheelid_core::Estimator`]: the built-ins of [`crate::estimators`] and plugins') is run
//! by [`refine`] when asked for or compared.

use std::time::Instant;

use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;
use wheelid_core::{
    BoundState, ChannelRegression, Estimate, Estimator, EstimatorInput, LinearFit, LinearProblem,
    RegressorModel, SolveError, SolveStatus, Solver,
};
use wheelid_solvers::streaming::{self, QrRows, WindowMoments};

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
/// channel with `solver` (eq. 4.3–4.7, within `settings.bounds` when given), in one pass
/// over the model's regression blocks ([`RegressorModel::regression_blocks`]) that never holds
/// a whole regressor (`wheelid_solvers::streaming`): each channel's rows are compressed into
/// their QR factor, which the solver solves, and into the window moments that give the
/// Newey–West meat at the θ̂ solved afterwards ([`WindowMoments`]); R² from the QR's residual
/// sum of squares and the regressand's sums; every k-th row kept for the plots.
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
    let clock = Instant::now();
    let channels = compress(model, data)?;
    let p = model.params().len();
    let names: Vec<&str> = model.params().iter().map(|q| q.name).collect();
    // The channels' compressed problems are independent and tiny.
    let mut fits = Vec::with_capacity(channels.len());
    for ch in &channels {
        fits.push(solve_compressed(solver, ch, &names, settings)?);
    }
    let mut theta = vec![0.0; p];
    let mut std_err = vec![0.0; p];
    let mut bound_state = vec![BoundState::Free; p];
    let mut quality = Vec::with_capacity(fits.len());
    for (ch, fit) in channels.iter().zip(&fits) {
        let ch_names: Vec<&str> = ch.params.iter().map(|&i| names[i]).collect();
        let (xc, _) = ch.qr.compressed();
        let meat = (data.lags > 0).then(|| {
            let theta: Vec<f64> = fit.theta.iter().copied().collect();
            ch.moments.as_ref().map_or_else(
                || DMatrix::zeros(theta.len(), theta.len()),
                |m| m.meat(&theta, &streaming::column_norms(&xc)),
            )
        });
        let cov = streaming::covariance(&xc, ch.qr.rows(), &ch_names, meat, fit.rss).map_err(
            |source| IdentifyError::Solve {
                channel: ch.name.into(),
                source,
            },
        )?;
        for (j, &i) in ch.params.iter().enumerate() {
            theta[i] = fit.theta[j];
            std_err[i] = cov[(j, j)].max(0.0).sqrt();
            bound_state[i] = fit.bound_state[j];
        }
        let tss = ch.tss();
        let r2 = if tss > 0.0 {
            1.0 - fit.rss / tss
        } else {
            f64::NAN
        };
        quality.push((r2, fit.condition_number, ch.qr.rows()));
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
        regressions: channels
            .into_iter()
            .map(|c| c.plot.into_regression())
            .collect(),
    })
}

/// One channel's rows in pass 1: its QR factor, its window moments (the Newey–West meat at
/// the θ̂ solved afterwards), the sums of its regressand about its first block's mean, and the
/// rows kept for the plots.
struct Channel {
    name: &'static str,
    params: Vec<usize>,
    qr: QrRows,
    /// Made at the first block, around that block's least squares (the pilot).
    moments: Option<WindowMoments>,
    lags: usize,
    /// The shift c (the first block's mean), Σ (y − c) and Σ (y − c)².
    shift: Option<f64>,
    sum_y: f64,
    sum_y2: f64,
    plot: PlotRows,
}

impl Channel {
    /// Adds a block's rows to every sum.
    ///
    /// # Errors
    /// [`IdentifyError::Solve`] naming the channel for a block the QR factor refuses.
    fn push(&mut self, b: &ChannelRegression) -> Result<(), IdentifyError> {
        self.qr
            .push(&b.x, &b.y)
            .map_err(|source| IdentifyError::Solve {
                channel: self.name.into(),
                source,
            })?;
        let moments = self.moments.get_or_insert_with(|| {
            // The pilot: least squares on the first block (zeros if it does not determine θ).
            let (x, y) = self.qr.compressed();
            let k = x.ncols();
            let names = vec![""; k];
            let problem = LinearProblem {
                x: &x,
                y: &y,
                names: &names,
                bounds: None,
                correlation_lags: 0,
            };
            let pilot = wheelid_solvers::Ols::default()
                .solve(&problem)
                .map(|f| f.theta.iter().copied().collect())
                .unwrap_or_else(|_| vec![0.0; k]);
            // The rows are whitened by the same rows' triangular factor.
            WindowMoments::new(self.lags, &pilot, Some(&x.rows(0, k).into_owned()))
        });
        moments.push(&b.x, &b.y);
        let c = *self
            .shift
            .get_or_insert_with(|| if b.y.is_empty() { 0.0 } else { b.y.mean() });
        for y in b.y.iter() {
            self.sum_y += y - c;
            self.sum_y2 += (y - c) * (y - c);
        }
        self.plot.take(b);
        Ok(())
    }

    /// Σ (y_t − ȳ)² over the rows pushed.
    fn tss(&self) -> f64 {
        let n = self.qr.rows().max(1) as f64;
        (self.sum_y2 - self.sum_y * self.sum_y / n).max(0.0)
    }
}

/// Pass 1: every recording's regression blocks into each channel's QR factor.
///
/// # Errors
/// As [`least_squares`].
fn compress(
    model: &dyn RegressorModel,
    data: &Prepared<'_>,
) -> Result<Vec<Channel>, IdentifyError> {
    // Rows expected (the eq. 2.19 models' count; a plugin's may differ, which only changes
    // how many rows the plots keep).
    let expected: usize = data.conditioned.iter().map(|c| c.valid_range().len()).sum();
    let step = expected.div_ceil(PLOT_ROWS).max(1);
    let mut channels: Vec<Channel> = Vec::new();
    let mut failed: Option<IdentifyError> = None;
    for c in &data.conditioned {
        model
            .regression_blocks(c, &mut |blocks| {
                if channels.is_empty() {
                    channels = blocks
                        .iter()
                        .map(|b| Channel {
                            name: b.channel,
                            params: b.params.clone(),
                            qr: QrRows::new(b.x.ncols()),
                            moments: None,
                            lags: data.lags,
                            shift: None,
                            sum_y: 0.0,
                            sum_y2: 0.0,
                            plot: PlotRows::new(b, step),
                        })
                        .collect();
                }
                let pushed = channels
                    .par_iter_mut()
                    .zip(blocks.par_iter())
                    .try_for_each(|(ch, b)| ch.push(b));
                pushed.map_err(|e: IdentifyError| {
                    let message = e.to_string();
                    failed = Some(e);
                    wheelid_core::Error::InvalidSetting(message)
                })
            })
            .map_err(|e| failed.take().unwrap_or(IdentifyError::Core(e)))?;
    }
    Ok(channels)
}

/// Solves one channel's compressed problem with `solver` (its errors are not the data's:
/// [`spread`] gives those).
///
/// # Errors
/// [`IdentifyError::Solve`] naming the channel.
fn solve_compressed(
    solver: &dyn Solver,
    ch: &Channel,
    names: &[&str],
    settings: &IdentifySettings,
) -> Result<LinearFit, IdentifyError> {
    let fail = |source| IdentifyError::Solve {
        channel: ch.name.into(),
        source,
    };
    let k = ch.params.len();
    if ch.qr.rows() <= k {
        return Err(fail(SolveError::InvalidProblem(format!(
            "{} samples cannot determine {k} parameters",
            ch.qr.rows()
        ))));
    }
    let ch_names: Vec<&str> = ch.params.iter().map(|&i| names[i]).collect();
    let ch_bounds: Option<Vec<(f64, f64)>> = settings
        .bounds
        .as_ref()
        .map(|b| ch.params.iter().map(|&i| b[i]).collect());
    let (x, y) = ch.qr.compressed();
    let problem = LinearProblem {
        x: &x,
        y: &y,
        names: &ch_names,
        bounds: ch_bounds.as_deref(),
        correlation_lags: 0,
    };
    solver.solve(&problem).map_err(fail)
}

/// Every `step`-th row of a channel's stacked regression, for the plots.
struct PlotRows {
    channel: &'static str,
    params: Vec<usize>,
    step: usize,
    /// Rows seen so far (of the whole stacked regression).
    seen: usize,
    x: Vec<f64>,
    y: Vec<f64>,
}

impl PlotRows {
    fn new(proto: &ChannelRegression, step: usize) -> Self {
        Self {
            channel: proto.channel,
            params: proto.params.clone(),
            step,
            seen: 0,
            x: Vec::new(),
            y: Vec::new(),
        }
    }

    fn take(&mut self, b: &ChannelRegression) {
        let first = (self.step - self.seen % self.step) % self.step;
        for t in (first..b.y.len()).step_by(self.step) {
            self.x.extend(b.x.row(t).iter());
            self.y.push(b.y[t]);
        }
        self.seen += b.y.len();
    }

    fn into_regression(self) -> ChannelRegression {
        let (m, k) = (self.y.len(), self.params.len());
        ChannelRegression {
            channel: self.channel,
            params: self.params,
            x: DMatrix::from_row_slice(m, k, &self.x),
            y: DVector::from_vec(self.y),
        }
    }
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
