//! Step 4 of [`super::identify`]: the answer simulated free-run from each recording's commands
//! and compared with its measurements (fit %, as MATLAB's `compare`).

use wheelid_core::{
    Conditioned, DynamicModel, Recording, RegressorModel, VelocitySampling, metrics,
};
use wheelid_models::CommandOffset;

use super::prepare::Prepared;
use super::{ChannelReport, FileReport, FileSeries, IdentifyError};

/// The validation's outcome: per file, its series, and per channel over all files.
pub(super) struct Validation {
    pub files: Vec<FileReport>,
    pub series: Vec<FileSeries>,
    pub channels: Vec<ChannelReport>,
}

/// [`validate`] of `theta` on the prepared recordings, as the chosen estimator's `free_run`
/// fitted them (its recordings, initial states and timing offset — and its own simulation of
/// them when it handed that over) when it gave one, else from the smoothed first samples of
/// the recordings as stamped.
///
/// # Errors
/// As [`validate`].
pub(super) fn validate_free_run(
    model: &dyn RegressorModel,
    theta: &[f64],
    data: &Prepared<'_>,
    free_run: Option<wheelid_core::FreeRun>,
    quality: &[(f64, f64, usize)],
) -> Result<Validation, IdentifyError> {
    let mut free_run = free_run;
    // Moved out, not copied (16 MB a channel on a 1e6-row file).
    let outputs = free_run.as_mut().and_then(|f| f.outputs.take());
    let (recordings, initial, offset, outputs) = match &free_run {
        Some(f) => (
            &f.recordings[..],
            f.initial.iter().cloned().map(Some).collect(),
            f.offset,
            outputs,
        ),
        None => (
            &data.restamped[..],
            vec![None; data.conditioned.len()],
            None,
            None,
        ),
    };
    let run = FreeRunOf {
        recordings,
        initial,
        offset,
        outputs,
    };
    validate(model, theta, &data.conditioned, run, quality)
}

/// What the validation simulates: the recordings, the initial states when the estimator gave
/// them, the timing offset when one was fitted, and the estimator's own free run when it has it.
struct FreeRunOf<'r> {
    recordings: &'r [Recording],
    initial: Vec<Option<Vec<f64>>>,
    offset: Option<f64>,
    outputs: Option<Vec<wheelid_core::Simulation>>,
}

/// Simulates `theta` on the run's recordings (one per conditioned recording `conditioned`),
/// from the estimated initial states when the estimator gave them (else the smoothed first
/// samples), with the timing offset when one was fitted — or takes the estimator's own free
/// run of exactly that when it handed it over; `quality` is least squares' (R², condition
/// number, samples) per channel.
///
/// # Errors
/// [`IdentifyError::Core`] when a simulation or the smoothing fails.
fn validate(
    model: &dyn RegressorModel,
    theta: &[f64],
    conditioned: &[Conditioned<'_>],
    run: FreeRunOf<'_>,
    quality: &[(f64, f64, usize)],
) -> Result<Validation, IdentifyError> {
    let FreeRunOf {
        recordings,
        initial,
        offset,
        outputs,
    } = run;
    let mut outputs = outputs.map(Vec::into_iter);
    let nch = model.channels().len();
    let mut files = Vec::new();
    // Per file: its recording, the samples left out at its start (see `skip` below) and its
    // simulation.
    let mut runs: Vec<(&Recording, usize, wheelid_core::Simulation)> = Vec::new();
    let offset_params = CommandOffset::params_of(model);
    let with_offset = CommandOffset::new(model, &offset_params)?;
    for ((c, x0), rec) in conditioned.iter().zip(initial).zip(recordings) {
        let measured = [&rec.v, &rec.w];
        let x0_estimated = x0.is_some();
        let initial = match x0 {
            Some(x) => x,
            None => c.initial_state()?.to_vec(),
        };
        let given = outputs.as_mut().and_then(Iterator::next);
        let simulated = match (given, offset) {
            (Some(sim), _) if sim.len() == nch && sim.iter().all(|y| y.len() == rec.len()) => sim,
            (_, Some(d)) => {
                let mut th = theta.to_vec();
                th.push(d);
                with_offset.simulate(&th, rec, &initial)?
            }
            (_, None) => model.simulate(theta, rec, &initial)?,
        };
        // A window-averaged recording's first sample averages over a window before it began,
        // under commands it does not hold: out of output error's cost, so out of the fit too
        // (its estimated initial state is free to miss it).
        let skip =
            usize::from(rec.velocity_sampling() == VelocitySampling::WindowAverage && x0_estimated);
        let fits: Vec<f64> = (0..nch)
            .map(|ch| metrics::fit_percent(&measured[ch][skip..], &simulated[ch][skip..]))
            .collect();
        files.push(FileReport {
            source: c.source.clone(),
            samples: rec.len(),
            dt: c.dt,
            resampled_from: c.resampled_from,
            fit_percent: fits,
            initial,
        });
        runs.push((rec, skip, simulated));
    }
    let channels: Vec<ChannelReport> = model
        .channels()
        .iter()
        .zip(quality)
        .enumerate()
        .map(|(ch, (info, &(r2, cond, n)))| ChannelReport {
            name: info.name.into(),
            r2,
            fit_percent: metrics::fit_percent_parts(
                &runs
                    .iter()
                    .map(|(rec, k, sim)| (&[&rec.v, &rec.w][ch][*k..], &sim[ch][*k..]))
                    .collect::<Vec<_>>(),
            ),
            condition_number: cond,
            samples: n,
        })
        .collect();
    let series = conditioned
        .iter()
        .zip(runs)
        .map(|(c, (rec, _, sim))| FileSeries::thinned(c.source.clone(), rec, sim))
        .collect();
    Ok(Validation {
        files,
        series,
        channels,
    })
}
