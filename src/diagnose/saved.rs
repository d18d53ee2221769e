//! A saved extended model refitted on new recordings (`wheelid identify --model model.toml`):
//! the structure a diagnosis found — θ1…θ6 of eq. 2.19 and its effects, as `wheelid diagnose
//! --out` writes them — fitted again, every parameter from its saved value, so that an effect
//! found on one day's drive is measured on the next one's without searching again.
//!
//! The data are prepared as a diagnosis prepares them (step 1 of the [module docs](super):
//! the recordings cut into [`DiagnoseSettings::blocks`] blocks, the 2nd, 4th, … held out), the
//! nominal model is fitted on the training blocks for comparison, and the extended model
//!
//! ```text
//! min over (θ, p)  Σ_c Σ_k∈train (y_c,k − ŷ_c,k(θ, p))² / σ_c²      (output error, free run)
//! ```
//!
//! is fitted from the file's (θ, p) within each effect's bounds; σ_c are the nominal fit's
//! residual standard deviations. Parameters the file leaves out (a limit's channel that never
//! bound) stay at the effect's null, a change time (`payload_change`) stays at its saved
//! instant (times are the recordings' own), and parameters the data cannot separate are held
//! at their saved values (standard error 0, "held" in the report). Both models are judged on
//! the validation blocks (free-run fit %, [`Stage`]).

use super::*;
use wheelid_models::extended::Found;

/// A saved extended model refitted on recordings ([`refit_saved`]).
#[derive(Debug, Clone, Serialize)]
pub struct SavedRefit {
    /// The nominal model (eq. 2.19 alone) fitted on the same training blocks.
    pub nominal: Stage,
    /// The saved structure refitted: θ1…θ6 then the effects' free parameters.
    pub refitted: Stage,
    /// The effects' parameters as refitted, in the model file's shape (effect → parameter →
    /// value, in the effect's units); a parameter held at its null is left out, as the file
    /// left it.
    pub effects: Found,
    /// Standard errors of `effects`, same shape (0: held, the data cannot separate it).
    pub effects_std_err: Found,
    /// The channels (`v`, `w`) the refitted model leaves misfitted: a validation residual
    /// above [`NOISE_FLOOR_FACTOR`] times the noise floor with the fit beyond the floor under
    /// [`PRACTICAL_FIT_PERCENT`], or a plain fit under [`LOW_FIT_PERCENT`] — the thresholds
    /// of a diagnosis's `unexplained` (without its independence tests): the saved effects do
    /// not explain this drive, and a diagnosis of it searches again.
    pub misfit: Vec<String>,
    /// Samples of all recordings (made uniform).
    pub samples: usize,
    /// How the samples were split (`searched_s` 0: nothing is searched).
    pub split: Split,
    /// Wall time \[s\].
    pub seconds: f64,
}

/// Refits the saved model — θ1…θ6 `theta` with the `effects` of a model file — on
/// `recordings` (module docs), the nominal `model` fitted beside it for comparison.
///
/// # Errors
/// [`DiagnoseError::Setting`] for bad settings, an unknown effect or parameter, a value
/// outside its effect's bounds (naming them), or a fit that fails; as [`diagnose`] for
/// recordings that cannot be prepared.
pub fn refit_saved(
    recordings: &[Recording],
    model: &dyn RegressorModel,
    theta: &[f64; 6],
    effects: &Found,
    settings: &DiagnoseSettings,
) -> Result<SavedRefit, DiagnoseError> {
    let clock = Instant::now();
    validate_settings(recordings, settings)?;
    prepare::check_model(model)?;
    let (data, nominal_fit) = prepare(recordings, model, settings)?;
    let nominal = nominal_current(&data, &nominal_fit)?;
    let (saved, start) = Extended::from_found(theta, effects, data.track.unwrap_or(1.0))
        .map_err(|e| DiagnoseError::Setting(format!("saved model: {e}")))?;
    let candidates = saved.candidates().to_vec();
    let pinned = held_params(&candidates, effects);
    let refitted = refit_holding(&data, candidates, &start, pinned)
        .map_err(|e| DiagnoseError::Setting(format!("refitting the saved model: {e}")))?;
    let (effects, effects_std_err) = effect_tables(&refitted);
    let seconds_of = |m: &[Vec<bool>]| m.iter().flatten().filter(|&&b| b).count() as f64 * data.dt;
    let refitted = data.stage(&refitted, &data.valid);
    let misses = |f: &ChannelFit| {
        (f.noise_ratio > NOISE_FLOOR_FACTOR && assemble::misses_beyond_noise(f))
            || f.fit_percent < LOW_FIT_PERCENT
    };
    let misfit = [("v", &refitted.channels.v), ("w", &refitted.channels.w)]
        .into_iter()
        .filter(|(_, f)| misses(f))
        .map(|(c, _)| c.to_owned())
        .collect();
    Ok(SavedRefit {
        nominal: data.stage(&nominal, &data.valid),
        refitted,
        misfit,
        effects,
        effects_std_err,
        samples: data.recs.iter().map(Recording::len).sum(),
        split: Split {
            blocks: settings.blocks,
            training_s: seconds_of(&data.train),
            validation_s: seconds_of(&data.valid),
            searched_s: 0.0,
        },
        seconds: clock.elapsed().as_secs_f64(),
    })
}

/// Indices (into θ1…θ6 then each candidate's parameters) the refit holds: those `found`
/// leaves out (at the effect's null) and change times (at their saved instant).
fn held_params(candidates: &[Candidate], found: &Found) -> Vec<usize> {
    let mut held = Vec::new();
    let mut at = 6;
    for c in candidates {
        let given = found.get(c.name());
        for (j, info) in c.params().iter().enumerate() {
            let absent = given.is_none_or(|g| !g.contains_key(info.name));
            let time = j == 0 && c.effect().search() == Search::ChangeTime;
            if absent || time {
                held.push(at + j);
            }
        }
        at += c.params().len();
    }
    held
}

/// The refitted effects' parameters and standard errors in a model file's shape: every
/// parameter the refit did not hold at its null (a change time, held at its saved instant,
/// is kept with a standard error of 0).
fn effect_tables(cur: &Current) -> (Found, Found) {
    let (mut values, mut errors) = (Found::new(), Found::new());
    let mut at = 6;
    for c in &cur.candidates {
        let (v, e) = (
            values.entry(c.name().to_owned()).or_default(),
            errors.entry(c.name().to_owned()).or_default(),
        );
        for (j, info) in c.params().iter().enumerate() {
            let i = at + j;
            let time = j == 0 && c.effect().search() == Search::ChangeTime;
            if time || !cur.pinned.contains(&i) {
                v.insert(info.name.to_owned(), cur.theta[i]);
                e.insert(info.name.to_owned(), cur.std_err[i]);
            }
        }
        at += c.params().len();
    }
    (values, errors)
}
