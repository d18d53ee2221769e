//! Instrumental variables (`wheelid_solvers::iv`): linear and fast; removes the noise bias of
//! the filtered regression, not the discretization error of its derivatives. Projected onto
//! the run's bounds when it has them.

use wheelid_core::{BoundState, Estimate, Estimator, EstimatorInput, SolveError};
use wheelid_solvers::InstrumentalVariables;

/// Its name.
pub const NAME: &str = "iv";

/// Instrumental variables with simulated noise-free instruments, iterated.
#[derive(Debug, Clone, Copy, Default)]
pub struct Iv;

impl Estimator for Iv {
    fn name(&self) -> &str {
        NAME
    }

    fn estimate(&self, input: &EstimatorInput<'_>) -> Result<Estimate, SolveError> {
        let fit = InstrumentalVariables::default().fit(
            input.model,
            input.conditioned,
            input.start,
            input.cutoff_hz,
            input.condition,
            input.lags,
        )?;
        let mut estimate = Estimate::new(fit.theta, fit.std_err, fit.status, fit.iterations);
        if let Some(b) = input.bounds {
            let pairs = estimate.theta.iter_mut().zip(&mut estimate.bound_state);
            for (i, (t, s)) in pairs.enumerate() {
                if *t < b[i].0 {
                    *t = b[i].0;
                    *s = BoundState::AtLower;
                } else if *t > b[i].1 {
                    *t = b[i].1;
                    *s = BoundState::AtUpper;
                }
            }
        }
        Ok(estimate)
    }
}
