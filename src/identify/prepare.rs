//! Step 1 of [`super::identify`]: the recordings conditioned once for every estimator.

use std::borrow::Cow;

use wheelid_core::condition::{self, CutoffChoice, Uniform};
use wheelid_core::{Conditioned, Recording, Timing};

use super::{IdentifyError, IdentifySettings};

/// The recordings as every estimator of the run sees them.
pub(super) struct Prepared<'a> {
    /// Restamped to window ends where a host stamped window middles (borrowed when none was):
    /// what output error fits and the validation simulates.
    pub restamped: Cow<'a, [Recording]>,
    /// Resampled, aligned and filtered (`wheelid_core::condition`), one per recording.
    pub conditioned: Vec<Conditioned<'a>>,
    /// The run's cut-off \[Hz\] and how it was chosen.
    pub cutoff_hz: f64,
    pub cutoff_choice: CutoffChoice,
    /// Lags over which the filtered residuals are correlated (one filter time constant, in
    /// samples of the coarsest recording): the Newey–West window of LS and IV.
    pub lags: usize,
}

/// Conditions `recordings` for the run: restamp, resample onto a uniform grid, choose one
/// cut-off (the documented rule unless `settings` gives one), filter and differentiate. Copies
/// only where a recording changes (restamped, resampled), so a 1e6-row run holds its columns
/// once: the conditioned recordings borrow the caller's.
///
/// # Errors
/// [`IdentifyError::Core`] for a recording too short or too irregular to condition.
pub(super) fn prepare<'a>(
    recordings: &'a [Recording],
    settings: &IdentifySettings,
) -> Result<Prepared<'a>, IdentifyError> {
    let restamped: Cow<'_, [Recording]> = if recordings
        .iter()
        .any(|r| r.timing() == Some(Timing::WindowMiddle))
    {
        Cow::Owned(
            recordings
                .iter()
                .map(|r| condition::restamp(r).map(Cow::into_owned))
                .collect::<Result<_, _>>()?,
        )
    } else {
        Cow::Borrowed(recordings)
    };
    // Uniform recordings: the caller's, borrowed, unless restamping or resampling made new
    // ones (restamped ones stay in `restamped` for output error, so they are copied here).
    let uniform: Vec<Uniform<'a>> = match &restamped {
        Cow::Borrowed(recs) => recs
            .iter()
            .map(condition::uniform)
            .collect::<Result<_, _>>()?,
        Cow::Owned(recs) => recs
            .iter()
            .map(|r| {
                condition::uniform(r).map(|u| Uniform {
                    recording: Cow::Owned(u.recording.into_owned()),
                    ..u
                })
            })
            .collect::<Result<_, _>>()?,
    };
    let (cutoff_hz, cutoff_choice) = match settings.condition.cutoff_hz {
        Some(fc) => (fc, CutoffChoice::Given),
        None => condition::suggest_cutoff_uniform(&uniform)?,
    };
    let conditioned: Vec<Conditioned<'a>> = uniform
        .into_iter()
        .map(|u| condition::condition_uniform(u, cutoff_hz, &settings.condition))
        .collect::<Result<_, _>>()?;
    // Residuals of filtered data are correlated over about one filter time constant.
    let lags = conditioned
        .iter()
        .map(|c| (1.0 / (c.dt * cutoff_hz)).ceil() as usize)
        .max()
        .unwrap_or(0);
    Ok(Prepared {
        restamped,
        conditioned,
        cutoff_hz,
        cutoff_choice,
        lags,
    })
}
