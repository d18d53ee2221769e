//! Mismatch diagnosis: when the six-θ model (Laut 2011 eq. 2.19) and a recording disagree,
//! find where, name the physics left out, model it and show the fit improve.
//!
//! One walk through the layers, each step visible in the [`Diagnosis`]:
//!
//! 1. **fit** — every recording is cut into [`DiagnoseSettings::blocks`] equal blocks; the odd
//!    ones (2nd, 4th, …) are held out for validation and never enter a fit. θ is fitted by
//!    output error (`wheelid_solvers::oe`, started from least squares, to a relative 1e-6 in
//!    cost and step — the candidates' fits stop at 1e-5 — far inside its standard errors) on
//!    the rest, the model simulated free-run over the whole recording;
//! 2. **test** — on the validation blocks: residual whiteness (Ljung–Box) and residual–command
//!    independence (cross-correlation at lags −L…L, each lag's sum of products over its
//!    Newey–West long-run variance, which keeps its level when the residual's size follows
//!    the commands; `wheelid_core::residual`), free-run fit % and the residual over the
//!    measured series' noise floor; on the training blocks: each candidate's
//!    fingerprint, a test of its pattern's Gauss–Newton step with a HAC variance from that
//!    step's residual (`score`; a limit probed at three fractions of
//!    the level read off the data, a payload change at five times, Bonferroni for each grid).
//!    A mismatch is declared on tests that survive Holm's correction over the whole family
//!    (independence and fingerprints), or where a channel's validation residual is more than
//!    [`NOISE_FLOOR_FACTOR`] times its measurement noise floor, and only where some channel's
//!    validation fit is below [`PRACTICAL_FIT_PERCENT`] (or below [`SEARCH_FIT_PERCENT`] with
//!    its residual above that multiple of the floor); never on whiteness alone;
//! 3. **locate** — per channel, the residual by lag, frequency band, operating region and time
//!    window (`locate`);
//! 4. **name** — the candidates whose fingerprint survives the correction are nominated (when
//!    none does but a residual is above the noise floor, or the model in hand leaves what
//!    step 5 would report as unexplained: the four strongest, p < 0.5), the strongest first —
//!    every effect of `wheelid_models::effects::EFFECTS` (`input_delay`,
//!    `acceleration_limit`, `velocity_saturation`, `coulomb_friction`, `wheel_asymmetry`,
//!    `payload_change`, `gain_drift`, `slip`, `wheel_friction`, `effort_clamp`,
//!    `amp_asymmetry`, `traction_limit`, `tyre_asymmetry`, `vw_friction`). A two-channel candidate acts on
//!    the channels whose own pattern is significant; the other channel's parameter is held at
//!    its null;
//! 5. **model and accept** — the extended model is fitted by output error; the candidate is
//!    kept only if the validation cost Σ_c Σ_k e²/σ_c² drops by at least
//!    [`DiagnoseSettings::min_improvement`] (30 % of it where the fingerprint that nominated
//!    it stands at p < 10⁻¹²: on a cost that is mostly the encoders' quantisation a real second
//!    effect takes off only 1.5–5 %) with no channel's validation fit falling by more
//!    than a point (excused where the cost drops by ≥ 10 %, `accept::FALL_EXCUSED_DROP`: two
//!    effects may each buy one channel with the other), its parameters are significant (≥ 3
//!    standard errors from the null; a limit must bind on ≥ 1 % of the samples) and
//!    physically plausible, and its fingerprint is gone
//!    (the pattern that nominated it, net of the other nominees, no longer fits the new
//!    residual or is at least halved — for an effect smooth in its parameter this nearly
//!    follows from the fit; it bites for the limits, whose pattern is a probe at a level read
//!    off the data, and for a candidate standing in for another effect; the validation cost
//!    is the main guard; not asked once every channel's validation fit is at least
//!    [`PRACTICAL_FIT_PERCENT`], where the scale-free statistic keeps its size on a residual a
//!    hundred times smaller). The first candidate that passes and up to two more (those
//!    whose screened start's training cost is within three times the first's; never a
//!    candidate fitted by differences, which is fitted only where its start already lowers the
//!    training cost by `min_improvement`, or at all where the model in hand leaves a channel
//!    above the noise floor; there, if nothing else is accepted, the ones skipped from a start
//!    at most twice the cost are fitted as a last resort) compete on Akaike's criterion over the validation
//!    blocks, n_eff ln(J₁/J₀) + 2k, n_eff discounted for the residual's lag-1
//!    autocorrelation. A change time (`payload_change`) is placed by a scan of the training
//!    cost; its interval is the profile likelihood's 95 % one, n_eff ln(J(t)/J_min) ≤ χ²₁.
//!    Where that interval spans validation samples the training blocks cannot place the
//!    change inside it: the model that adds the change is judged, as the one without it, on
//!    the validation samples outside it; once accepted, the time is placed with every sample
//!    inside the interval (`place`) and held, so that later comparisons judge every
//!    validation sample against a change where it happened (one parameter read off them),
//!    while the final fits are still reported outside the interval. Then the search starts again from the extended
//!    model (forward selection, at most [`DiagnoseSettings::max_effects`], until every channel
//!    is fitted to [`SEARCH_FIT_PERCENT`]; after each round a backward step removes every
//!    earlier effect made redundant, `backward::backward_step`; effects that move one quantity the encoders see,
//!    [`wheelid_core::Effect::quantity`], are alternatives: once one is in, the others are
//!    not searched). Forward selection is greedy: where its final model leaves a channel above
//!    the noise floor, the search from the first round's runner-up (the best candidate that
//!    passed and was outscored) is run too, and its final model replaces the greedy one where
//!    it explains the validation blocks better for its parameters (Akaike's criterion;
//!    `paths`; naming the same effects, it is a better fit of the same explanation). An effect that a sensor other than the encoders measures
//!    ([`wheelid_core::Effect::measured`]: a larger tyre in a heading independent of the
//!    encoders) is then in the model whatever the dynamics show — in place of the candidates
//!    of its quantity, fitted within the bounds its measurement allows, held, and named with
//!    the measurement as its evidence; an effect it makes redundant is dropped (one found
//!    for what the stand-in it replaced left, `paths`) — and the search goes on for the
//!    effects the encoders cannot tell from it alone (a weak amplifier beside the tyre;
//!    `measured`), under the whole drop gate (what the measured effect's hold leaves shows as
//!    their fingerprint). What stays significant or above the noise floor in a channel
//!    fitted below [`PRACTICAL_FIT_PERCENT`] once the noise floor is taken out of its residual
//!    ([`ChannelFit::noise_corrected_fit_percent`]: the sensor's own noise is no unexplained
//!    physics), and any channel below [`LOW_FIT_PERCENT`], is reported as [`Unexplained`],
//!    with where it lives;
//! 6. **show** — before/after fit % per channel on the validation blocks
//!    (`crate::report::diagnosis_text`, `crate::plot::write_diagnosis_plots`, JSON).
//!
//! A recording longer than [`DiagnoseSettings::search_samples`] (default 3 600) is searched
//! (steps 2–5) on an excerpt: three windows per block spread over the drive, each a recording
//! of its own whose first samples fit its initial state, a drift counted from the drive's
//! start ([`wheelid_core::Recording::drive_start`]). The model found is refitted on every
//! training block of the whole drive, which step 6 judges (`excerpt`). On the unseen
//! 10-minute recordings of the physics backend's seed 1035 (window-end stamps) it named
//! 101/112 right; searched whole, the Pioneer-like runs named the same 52/56 and the first 44
//! Khepera-like runs two more (41/44 against 39/44: a second effect whose validation drop was
//! 3–4 % on the excerpt and over the 5 % gate on the whole drive), at 3.4× the diagnosis time
//! (the Pioneer-like runs at 1.4×; a slippery floor's pairs take minutes each searched
//! whole). `usize::MAX` searches every recording whole.

mod accept;
mod assemble;
mod backward;
mod budget;
mod excerpt;
mod fingerprint;
mod fit;
mod locate;
mod measured;
mod paths;
mod place;
mod prepare;
mod saved;
mod score;
mod screen;
mod search;

use accept::*;
use assemble::structure_unexplained;
pub use assemble::{
    LOW_FIT_PERCENT, NOISE_FLOOR_FACTOR, PRACTICAL_FIT_PERCENT, SEARCH_FIT_PERCENT,
};
use fingerprint::*;
use fit::*;
use prepare::*;
use screen::*;

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Instant;

use nalgebra::DMatrix;
use serde::Serialize;
use wheelid_core::condition::{self, ConditionSettings};
use wheelid_core::effect::{EffectChannels, FitData, Probe, ProbeData, Search};
use wheelid_core::residual::holm;
use wheelid_core::{
    ChannelInfo, DynamicModel, ParamInfo, Recording, RegressorModel, Result as CoreResult,
    Sensitivities, Simulation, metrics,
};
use wheelid_models::effects::NEVER;
use wheelid_models::{Candidate, Extended};
use wheelid_solvers::{Ols, OutputError, OutputErrorFit};

pub use locate::{Band, ChannelLocation, Location, Share};
pub use saved::{SavedRefit, refit_saved};
use score::{Frame, Outputs, simulate_all};

use crate::identify::{IdentifySettings, identify};

/// Errors of a diagnosis.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum DiagnoseError {
    /// Reading or conditioning a recording failed.
    #[error(transparent)]
    Core(#[from] wheelid_core::Error),
    /// The nominal identification failed.
    #[error(transparent)]
    Identify(#[from] crate::identify::IdentifyError),
    /// The nominal output-error fit failed.
    #[error("nominal output-error fit: {0}")]
    Fit(#[from] wheelid_core::SolveError),
    /// Bad settings or data too short to split.
    #[error("{0}")]
    Setting(String),
}

/// Settings of a diagnosis (the result is a [`Diagnosis`]).
#[derive(Debug, Clone, PartialEq)]
pub struct DiagnoseSettings {
    /// Conditioning of the least-squares start and of the measured accelerations.
    pub condition: ConditionSettings,
    /// Equal blocks per recording; the 2nd, 4th, … are the validation blocks (≥ 3).
    pub blocks: usize,
    /// Family-wise level of the tests (Holm) [-].
    pub alpha: f64,
    /// Largest lag of the correlation tests \[s\].
    pub max_lag_s: f64,
    /// Smallest relative drop of the validation cost that counts as a clear improvement [-]
    /// (15–30 % of it for a candidate nominated at p < 10⁻¹², `accept::required_drop`, unless
    /// it is searched beside a measured effect of its quantity).
    pub min_improvement: f64,
    /// Most effects added: rounds of the forward selection, a round whose effect a later
    /// backward step removed not counted (at most 2 × this many rounds in all).
    pub max_effects: usize,
    /// The candidate library searched.
    pub candidates: Vec<Candidate>,
    /// Wheel track d \[m\] for `wheel_asymmetry`; `None`: from the recording's metadata
    /// (`track`, `kinematics: … track X m`, or a built-in `robot`), else the candidate is
    /// skipped.
    pub track_m: Option<f64>,
    /// Most samples per recording the search screens and fits candidates on: a longer
    /// recording is searched on an excerpt of this many samples, in windows spread over it,
    /// and the model found is refitted on the whole recording (module docs; ≥ 100 per block).
    /// Default 3 600 (72 s at 50 Hz): each case of the 10-minute bench 3–7× faster than
    /// searched whole (README); `usize::MAX` searches every recording whole. On the unseen 10-minute
    /// physics recordings of seed 1035 the whole-drive search named two Khepera-like pairs
    /// right that the excerpt missed (a second effect whose validation drop was 3–4 % on the
    /// excerpt, over 5 % on the whole drive), the Pioneer-like runs alike.
    pub search_samples: usize,
}

impl Default for DiagnoseSettings {
    fn default() -> Self {
        Self {
            condition: ConditionSettings::default(),
            blocks: 5,
            alpha: 0.01,
            max_lag_s: 2.0,
            min_improvement: 0.05,
            max_effects: 3,
            candidates: Candidate::all(),
            track_m: None,
            search_samples: 3600,
        }
    }
}

/// Free-run fit of one channel on the validation blocks.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct ChannelFit {
    /// Fit % (100 (1 − ‖y − ŷ‖/‖y − ȳ‖)).
    pub fit_percent: f64,
    /// RMS of y − ŷ [channel unit].
    pub rms: f64,
    /// `rms` over the measurement noise floor σ_n (the RMS of what the conditioning's
    /// zero-phase low-pass removes from the measurement, corrected for the white noise it
    /// passes): near 1, the model explains all but the noise.
    pub noise_ratio: f64,
    /// Fit % of the part of the residual beyond the noise floor σ_n:
    /// 100 (1 − √max(0, rms² − σ_n²) / ‖y − ȳ‖_rms). What a noise-free sensor would show of
    /// the model's misfit (an encoder's count quantisation caps the plain fit % of a perfect
    /// model: 98.5 % on the Khepera-like robot's v at 20 ms); ≥ the plain fit %.
    pub noise_corrected_fit_percent: f64,
}

/// Both channels' validation fits.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Channels {
    /// Forward velocity.
    pub v: ChannelFit,
    /// Angular velocity.
    pub w: ChannelFit,
}

/// A fitted model and how it does on the validation blocks.
#[derive(Debug, Clone, Serialize)]
pub struct Stage {
    /// `nominal`, or the candidates added (`nominal + input_delay + …`).
    pub model: String,
    /// θ: θ1…θ6, then the candidates' parameters (those held at their null — a limit's idle
    /// channel — left out; `names` says which are here).
    pub theta: Vec<f64>,
    /// Standard errors of θ (output error, sandwich).
    pub std_err: Vec<f64>,
    /// Parameter names.
    pub names: Vec<String>,
    /// Validation fits.
    pub channels: Channels,
    /// Σ_c Σ_k e²/σ_c² over the validation samples, σ_c the nominal residual std.
    pub validation_cost: f64,
}

/// One test of the family and its Holm decision.
#[derive(Debug, Clone, Serialize)]
pub struct TestResult {
    /// What was tested.
    pub name: String,
    /// Its p-value.
    pub p_value: f64,
    /// Significant after Holm's correction at [`DiagnoseSettings::alpha`].
    pub significant: bool,
}

/// A candidate's fingerprint in one round of the search.
#[derive(Debug, Clone, Serialize)]
pub struct Fingerprint {
    /// Candidate name.
    pub effect: String,
    /// Channels whose own pattern is significant (|z| ≥ 2.5).
    pub channels: Vec<String>,
    /// Wald statistic of the pattern's Gauss–Newton step (≈ χ² with `dof` degrees of freedom;
    /// its p-value from F with the HAC estimate's equivalent degrees of freedom).
    pub stat: f64,
    /// Degrees of freedom.
    pub dof: usize,
    /// p-value (with the grid's Bonferroni factor for `payload_change`).
    pub p_value: f64,
    /// Survived Holm's correction: the candidate is nominated.
    pub nominated: bool,
    /// What the data show, in words.
    pub evidence: String,
}

/// An effect that was added.
#[derive(Debug, Clone, Serialize)]
pub struct Finding {
    /// Candidate name (`input_delay`, …).
    pub effect: String,
    /// Channels it acts on.
    pub channels: Vec<String>,
    /// Its parameters in the final model [units of `wheelid_models::Candidate::params`].
    pub parameters: BTreeMap<String, f64>,
    /// Their standard errors.
    pub std_err: BTreeMap<String, f64>,
    /// Why it was named and kept.
    pub evidence: String,
    /// Validation fit % per channel with it.
    pub fit_percent_after: BTreeMap<String, f64>,
    /// Relative drop of the validation cost it brought [%].
    pub validation_cost_drop_percent: f64,
}

/// A nominated candidate that was fitted and not kept.
#[derive(Debug, Clone, Serialize)]
pub struct Rejected {
    /// Candidate name.
    pub effect: String,
    /// Why not.
    pub reason: String,
}

/// Structure left in the residuals that no candidate explains.
#[derive(Debug, Clone, Serialize)]
pub struct Unexplained {
    /// Channels with a significant residual–command correlation after Holm.
    pub channels: Vec<String>,
    /// Where it lives, per channel.
    pub location: Vec<String>,
}

/// Per-recording series for the plots: measured, nominal and final simulated outputs.
#[derive(Debug, Clone)]
pub struct DiagnosisSeries {
    /// Where it came from.
    pub source: PathBuf,
    /// Time \[s\].
    pub t: Vec<f64>,
    /// Validation sample flags.
    pub validation: Vec<bool>,
    /// Measured (v, ω).
    pub measured: [Vec<f64>; 2],
    /// Nominal model (v̂, ω̂).
    pub nominal: [Vec<f64>; 2],
    /// Final model (v̂, ω̂).
    pub extended: [Vec<f64>; 2],
}

/// The result of a diagnosis (settings: [`DiagnoseSettings`]).
#[derive(Debug, Clone, Serialize)]
pub struct Diagnosis {
    /// The nominal model's fit (step 1) and validation (step 2).
    pub nominal: Stage,
    /// Training and validation seconds.
    pub split: Split,
    /// The first round's test family with Holm decisions (step 2).
    pub tests: Vec<TestResult>,
    /// The verdict: whether the model was extended or something is left unexplained (first-
    /// round evidence that no candidate takes up and that leaves the residual independent of the
    /// commands keeps the model; `tests` shows it).
    pub mismatch: bool,
    /// Where the nominal model's misfit lives (step 3).
    pub location: Location,
    /// Fingerprints per round scored (step 4).
    pub fingerprints: Vec<Vec<Fingerprint>>,
    /// Why the search's next round was not scored, where it ended on a model that misses no
    /// relevant share of a channel (its fits then: the fingerprints could not extend it);
    /// `None` where it ended on a scored round.
    pub unscored_round: Option<String>,
    /// Effects added, in order (step 5).
    pub findings: Vec<Finding>,
    /// Nominated candidates that were fitted and rejected.
    pub rejected: Vec<Rejected>,
    /// Structure no candidate explains.
    pub unexplained: Option<Unexplained>,
    /// What a heading independent of the encoders shows of the tyres, where it shows them
    /// unequal ([`HeadingCheck`]); `None` without such a heading, or where it turns as equal
    /// tyres do.
    pub heading: Option<HeadingCheck>,
    /// The final model.
    #[serde(rename = "final")]
    pub final_stage: Stage,
    /// Where the final model's misfit lives.
    pub final_location: Location,
    /// Wall time \[s\].
    pub seconds: f64,
    /// Series for the plots.
    #[serde(skip)]
    pub series: Vec<DiagnosisSeries>,
}

/// The right/left tyre radius ratio a heading independent of the encoders shows
/// (`wheelid_models::effects::heading_ratio`: the heading's change regressed on the encoders'
/// rim distances, as UMBmark measures a wheel-diameter ratio), reported where it departs from 1
/// by at least `wheelid_models::effects::MIN_RATIO_EFFECT` (1 %) and three standard errors. A
/// larger tyre makes the encoders' odometry misread that wheel's travel whatever the dynamics
/// show: beside a weak amplifier of the opposite sign it can leave no dynamic trace at all.
#[derive(Debug, Clone, Serialize)]
pub struct HeadingCheck {
    /// Right/left tyre radius ratio ρ \[-\].
    pub ratio: f64,
    /// Its standard error (delta method).
    pub std_err: f64,
    /// Whether the final model holds `tyre_asymmetry`.
    pub modelled: bool,
}

/// How the samples were split.
#[derive(Debug, Clone, Serialize)]
pub struct Split {
    /// Blocks per recording.
    pub blocks: usize,
    /// Seconds used for fitting.
    pub training_s: f64,
    /// Seconds held out for validation.
    pub validation_s: f64,
    /// Seconds the search screened and fitted the candidates on (less than the whole when a
    /// recording is longer than [`DiagnoseSettings::search_samples`]; the final model is
    /// refitted on every training block).
    pub searched_s: f64,
}

/// Share of its score statistic a fingerprint may keep after its candidate is added and still
/// count as gone when it stays significant: with two effects present, the other one leaves a
/// trace along the first one's pattern, so "gone" means at least halved.
const FINGERPRINT_LEFT: f64 = 0.5;

/// Most blocks a recording is cut into.
const MAX_BLOCKS: usize = 50;

/// Fractions of a limit's data-read level at which its fingerprint is probed.
const PROBE_FRACTIONS: [f64; 3] = [0.7, 0.85, 1.0];

/// Relative tolerance (cost and step) of the nominal output-error fit: its θ moves by far
/// less than a standard error below it, and the score tests project the fit's Jacobian out.
const NOMINAL_TOLERANCE: f64 = 1e-6;

/// The model in hand during the search.
#[derive(Debug, Clone)]
struct Current {
    candidates: Vec<Candidate>,
    /// Indices of θ held at their null (inactive channels).
    pinned: Vec<usize>,
    theta: Vec<f64>,
    std_err: Vec<f64>,
    covariance: DMatrix<f64>,
    initial: Vec<Vec<f64>>,
    sim: Outputs,
    /// The fit's sensitivities to the free parameters and the initial states over the training
    /// rows, weighted as the frame weights them (the score tests' J), when the fit gave them.
    jacobian: Option<DMatrix<f64>>,
}

pub use crate::observer::{Observer, Silent};

/// Counts the units of work done and passes them to an [`Observer`].
struct Progress<'a> {
    observer: &'a dyn Observer,
    done: std::sync::atomic::AtomicU64,
    total: std::sync::atomic::AtomicU64,
}

impl<'a> Progress<'a> {
    fn new(observer: &'a dyn Observer, total: u64) -> Self {
        Self {
            observer,
            done: 0.into(),
            total: total.into(),
        }
    }
    fn add_work(&self, n: u64) {
        self.total
            .fetch_add(n, std::sync::atomic::Ordering::Relaxed);
    }
    fn step(&self, message: &str, finished: u64) {
        use std::sync::atomic::Ordering::Relaxed;
        let done = self.done.fetch_add(finished, Relaxed) + finished;
        self.observer
            .progress(message, done, self.total.load(Relaxed));
    }
}

/// Runs a diagnosis of `recordings` with the nominal `model` (its θ seeds every extended
/// model), silently. See [`diagnose_observed`].
///
/// # Errors
/// [`DiagnoseError`] for unreadable or too-short data, or a nominal fit that fails.
pub fn diagnose(
    recordings: &[Recording],
    model: &dyn RegressorModel,
    settings: &DiagnoseSettings,
) -> Result<Diagnosis, DiagnoseError> {
    diagnose_observed(recordings, model, settings, &Silent)
}

/// Runs a diagnosis (module docs: fit, test, locate, name, model and accept, show), reporting
/// progress to `observer`.
///
/// # Errors
/// [`DiagnoseError`] for unreadable or too-short data, or a nominal fit that fails.
pub fn diagnose_observed(
    recordings: &[Recording],
    model: &dyn RegressorModel,
    settings: &DiagnoseSettings,
    observer: &dyn Observer,
) -> Result<Diagnosis, DiagnoseError> {
    let clock = Instant::now();
    validate_settings(recordings, settings)?;
    prepare::check_model(model)?;
    let progress = Progress::new(observer, 4);
    progress.step("fitting the nominal model", 0);
    let (data, nominal_fit) = prepare(recordings, model, settings)?;
    let cur = nominal_current(&data, &nominal_fit)?;
    // The report compares the final model with this simulation (simulated once).
    let nominal_sim = cur.sim.clone();
    let nominal = data.stage(&cur, &data.valid);
    progress.step("testing the residuals", 1);
    let max_lag = data.max_lag(settings);
    let location = locate::locate(&data.recs, &cur.sim, &data.valid, data.dt, max_lag);
    let search = excerpt::search_on(&data, cur, settings, &location, &progress)?;
    progress.step("done", 1);
    Ok(assemble::assemble(
        &data,
        settings,
        nominal,
        location,
        search,
        &nominal_sim,
        clock.elapsed().as_secs_f64(),
    ))
}

/// Checks the settings against the recordings.
fn validate_settings(
    recordings: &[Recording],
    settings: &DiagnoseSettings,
) -> Result<(), DiagnoseError> {
    let bad = |what: String| Err(DiagnoseError::Setting(what));
    if recordings.is_empty() {
        return bad("no recording given".into());
    }
    if !(3..=MAX_BLOCKS).contains(&settings.blocks) {
        return bad(format!(
            "blocks = {} must be 3 to {MAX_BLOCKS}",
            settings.blocks
        ));
    }
    if !(settings.alpha > 0.0 && settings.alpha < 1.0) {
        return bad(format!("alpha = {} must be in (0, 1)", settings.alpha));
    }
    if !(settings.min_improvement.is_finite() && settings.min_improvement >= 0.0) {
        return bad(format!(
            "min_improvement = {} must be finite and ≥ 0",
            settings.min_improvement
        ));
    }
    if !(settings.max_lag_s.is_finite() && settings.max_lag_s > 0.0) {
        return bad(format!("max_lag_s = {} must be > 0", settings.max_lag_s));
    }
    if settings.search_samples < 100 * settings.blocks {
        return bad(format!(
            "search_samples = {} must be at least 100 per block ({})",
            settings.search_samples,
            100 * settings.blocks
        ));
    }
    if let Some(t) = settings.track_m
        && !(t.is_finite() && t > 0.0)
    {
        return bad(format!("track = {t} m must be > 0"));
    }
    Ok(())
}
