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
/// fitted them (its recordings, initial states and timing offset) when it gave one, else
/// from the smoothed first samples of the recordings as stamped.
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
    let (recordings, initial, offset) = match &free_run {
        Some(f) => (
            &f.recordings[..],
            f.initial.iter().cloned().map(Some).collect(),
            f.offset,
        ),
        None => (
            &data.restamped[..],
            vec![None; data.conditioned.len()],
            None,
        ),
    };
    validate(
        model,
        theta,
        &data.conditioned,
        recordings,
        initial,
        offset,
        quality,
    )
}

/// Simulates `theta` on `recordings` (one per conditioned recording `conditioned`), from the
/// estimated `initial` states when the estimator gave them (else the smoothed first samples),
/// with the timing `offset` when one was fitted; `quality` is least squares' (R², condition
/// number, samples) per channel.
///
/// # Errors
/// [`IdentifyError::Core`] when a simulation or the smoothing fails.
fn validate(
    model: &dyn RegressorModel,
    theta: &[f64],
    conditioned: &[Conditioned<'_>],
    recordings: &[Recording],
    initial: Vec<Option<Vec<f64>>>,
    offset: Option<f64>,
    quality: &[(f64, f64, usize)],
) -> Result<Validation, IdentifyError> {
    let nch = model.channels().len();
    let mut series = Vec::new();
    let mut files = Vec::new();
    // Samples left out at each file's start (see `skip` below).
    let mut skips = Vec::new();
    let offset_params = CommandOffset::params_of(model);
    let with_offset = CommandOffset::new(model, &offset_params)?;
    for ((c, x0), rec) in conditioned.iter().zip(initial).zip(recordings) {
        let measured = vec![rec.v.clone(), rec.w.clone()];
        let x0_estimated = x0.is_some();
        let initial = match x0 {
            Some(x) => x,
            None => c.initial_state()?.to_vec(),
        };
        let simulated = match offset {
            Some(d) => {
                let mut th = theta.to_vec();
                th.push(d);
                with_offset.simulate(&th, rec, &initial)?
            }
            None => model.simulate(theta, rec, &initial)?,
        };
        // A window-averaged recording's first sample averages over a window before it began,
        // under commands it does not hold: out of output error's cost, so out of the fit too
        // (its estimated initial state is free to miss it).
        let skip =
            usize::from(rec.velocity_sampling() == VelocitySampling::WindowAverage && x0_estimated);
        let fits: Vec<f64> = (0..nch)
            .map(|ch| metrics::fit_percent(&measured[ch][skip..], &simulated[ch][skip..]))
            .collect();
        skips.push(skip);
        files.push(FileReport {
            source: c.source.clone(),
            samples: rec.len(),
            dt: c.dt,
            resampled_from: c.resampled_from,
            fit_percent: fits,
            initial,
        });
        series.push(FileSeries {
            source: c.source.clone(),
            t: rec.t.clone(),
            measured,
            simulated,
        });
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
                &series
                    .iter()
                    .zip(&skips)
                    .map(|(s, &k)| (&s.measured[ch][k..], &s.simulated[ch][k..]))
                    .collect::<Vec<_>>(),
            ),
            condition_number: cond,
            samples: n,
        })
        .collect();
    Ok(Validation {
        files,
        series,
        channels,
    })
}
