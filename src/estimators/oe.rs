//! Output error (`wheelid_solvers::oe`): θ whose free-run simulation matches the measurements,
//! on the recordings' own stamps, with the timing offset where a recording does not state its
//! stamping ([`crate::timing`]). No filter, no derivative, no cut-off in the answer.

use wheelid_core::{Estimate, Estimator, EstimatorInput, FreeRun, SolveError};
use wheelid_solvers::OutputError;

use crate::timing::fit_with_timing;

/// Its name.
pub const NAME: &str = "oe";

/// Output error, started from least squares' θ.
#[derive(Debug, Clone, Copy, Default)]
pub struct Oe;

impl Estimator for Oe {
    fn name(&self) -> &str {
        NAME
    }

    fn estimate(&self, input: &EstimatorInput<'_>) -> Result<Estimate, SolveError> {
        let oe = OutputError {
            bounds: input.bounds.map(<[_]>::to_vec),
            // identify reports θ̂ and its errors; no n × P Jacobian is needed.
            keep_jacobian: false,
            ..OutputError::default()
        };
        let timed = fit_with_timing(input.model, input.recordings, input.start, &oe)?;
        let fit = timed.fit;
        let p = input.model.params().len();
        Ok(Estimate {
            theta: fit.theta[..p].to_vec(),
            std_err: fit.std_err[..p].to_vec(),
            status: fit.status,
            bound_state: fit.bound_state[..p].to_vec(),
            iterations: fit.evaluations,
            free_run: Some(FreeRun {
                initial: fit.initial,
                offset: timed.offset,
                recordings: timed.recordings,
                outputs: Some(fit.simulated),
            }),
            noise_std: Some(fit.noise_std),
            timing: Some(timed.timing),
        })
    }
}
