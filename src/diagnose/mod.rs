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
//!    independence (cross-correlation at lags −L…L with Ljung's bounds,
//!    `wheelid_core::residual`), free-run fit %; on the training blocks: each candidate's
//!    fingerprint, a score test of its pattern ([`score`]; a limit probed at three fractions of
//!    the level read off the data, a payload change at five times, Bonferroni for each grid). A mismatch is declared only on
//!    tests that survive Holm's correction over the whole family (independence and
//!    fingerprints), never on whiteness alone;
//! 3. **locate** — per channel, the residual by lag, frequency band, operating region and time
//!    window ([`locate`]);
//! 4. **name** — the candidates whose fingerprint survives the correction are nominated, the
//!    strongest first: `input_delay`, `acceleration_limit`, `velocity_saturation`,
//!    `coulomb_friction`, `wheel_asymmetry`, `payload_change`, `gain_drift`, `slip`
//!    (`wheelid_models::Candidate`). A two-channel candidate acts on the channels whose own
//!    pattern is significant; the other channel's parameter is held at its null;
//! 5. **model and accept** — the extended model is fitted by output error; the candidate is
//!    kept only if the validation cost Σ_c Σ_k e²/σ_c² drops by at least
//!    [`DiagnoseSettings::min_improvement`] with no channel's validation fit falling by more
//!    than a point, its parameters are significant (≥ 3 standard errors from the null; a limit
//!    must bind on ≥ 1 % of the samples) and physically plausible, and its fingerprint is gone
//!    (the pattern that nominated it, net of the other nominees, no longer fits the new
//!    residual or is at least halved — for an effect smooth in its parameter this nearly
//!    follows from the fit; it bites for the limits, whose pattern is a probe at a level read
//!    off the data, and for a candidate standing in for another effect; the validation cost
//!    is the main guard). Then the search starts
//!    again from the extended model (forward selection, at most
//!    [`DiagnoseSettings::max_effects`]). What stays significant is reported as
//!    [`Unexplained`], with where it lives;
//! 6. **show** — before/after fit % per channel on the validation blocks
//!    (`crate::report::diagnosis_text`, `crate::plot::write_diagnosis_plots`, JSON).

mod locate;
mod score;

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Instant;

use indicatif::{ProgressBar, ProgressStyle};
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
use score::{Frame, Outputs, simulate_all};

use crate::identify::{Estimator, IdentifySettings, identify};

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
    /// Largest lag of the correlation tests [s].
    pub max_lag_s: f64,
    /// Smallest relative drop of the validation cost that counts as a clear improvement [-].
    pub min_improvement: f64,
    /// Most effects added.
    pub max_effects: usize,
    /// The candidate library searched.
    pub candidates: Vec<Candidate>,
    /// Wheel track d [m] for `wheel_asymmetry`; `None`: from the recording's metadata
    /// (`track`, `kinematics: … track X m`, or a built-in `robot`), else the candidate is
    /// skipped.
    pub track_m: Option<f64>,
    /// Show a progress bar on standard error (when it is a terminal).
    pub progress: bool,
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
            progress: false,
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
    /// θ: θ1…θ6, then the candidates' parameters.
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
    /// Score statistic (χ² with `dof` degrees of freedom).
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
    /// Time [s].
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
    /// Whether a mismatch was declared.
    pub mismatch: bool,
    /// Where the nominal model's misfit lives (step 3).
    pub location: Location,
    /// Fingerprints per round (step 4).
    pub fingerprints: Vec<Vec<Fingerprint>>,
    /// Effects added, in order (step 5).
    pub findings: Vec<Finding>,
    /// Nominated candidates that were fitted and rejected.
    pub rejected: Vec<Rejected>,
    /// Structure no candidate explains.
    pub unexplained: Option<Unexplained>,
    /// The final model.
    #[serde(rename = "final")]
    pub final_stage: Stage,
    /// Where the final model's misfit lives.
    pub final_location: Location,
    /// Wall time [s].
    pub seconds: f64,
    /// Series for the plots.
    #[serde(skip)]
    pub series: Vec<DiagnosisSeries>,
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

/// The extended model with some parameters held: the fitter sees only the free ones.
struct Pinned<'a> {
    inner: &'a Extended,
    free: Vec<usize>,
    full: Vec<f64>,
    params: Vec<ParamInfo>,
}

impl<'a> Pinned<'a> {
    fn new(inner: &'a Extended, full: Vec<f64>, pinned: &[usize]) -> Self {
        let free: Vec<usize> = (0..full.len()).filter(|i| !pinned.contains(i)).collect();
        let params = free.iter().map(|&i| inner.params()[i]).collect();
        Self {
            inner,
            free,
            full,
            params,
        }
    }
    fn expand(&self, theta: &[f64]) -> Vec<f64> {
        let mut f = self.full.clone();
        for (&i, &x) in self.free.iter().zip(theta) {
            f[i] = x;
        }
        f
    }
    fn free_values(&self) -> Vec<f64> {
        self.free.iter().map(|&i| self.full[i]).collect()
    }
}

impl DynamicModel for Pinned<'_> {
    fn name(&self) -> &str {
        self.inner.name()
    }
    fn params(&self) -> &[ParamInfo] {
        &self.params
    }
    fn channels(&self) -> &[ChannelInfo] {
        self.inner.channels()
    }
    fn simulate(&self, theta: &[f64], rec: &Recording, initial: &[f64]) -> CoreResult<Simulation> {
        self.inner.simulate(&self.expand(theta), rec, initial)
    }
    fn simulate_with_sensitivities(
        &self,
        theta: &[f64],
        rec: &Recording,
        initial: &[f64],
    ) -> CoreResult<Option<(Simulation, Sensitivities)>> {
        self.inner
            .sensitivities_of(&self.expand(theta), rec, initial, &self.free)
            .map(Some)
    }
}

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

/// Everything the search needs about the data.
struct Data {
    recs: Vec<Recording>,
    /// Training flags.
    train: Vec<Vec<bool>>,
    /// Validation flags.
    valid: Vec<Vec<bool>>,
    dt: f64,
    /// Blocks per recording.
    blocks: usize,
    track: Option<f64>,
    /// 1/σ_c of the nominal fit.
    weight: [f64; 2],
    /// Measured accelerations (smoothed derivative) per recording.
    accel: Outputs,
}

impl Data {
    fn model(&self, candidates: &[Candidate]) -> Extended {
        // A missing track only matters to wheel_asymmetry, which is skipped then.
        Extended::new(candidates, self.track.unwrap_or(1.0)).expect("candidates are distinct")
    }
    fn frame(&self) -> Frame<'_> {
        Frame {
            recs: &self.recs,
            mask: &self.train,
            weight: self.weight,
        }
    }
    /// Validation fits and cost of simulated outputs.
    fn validate(&self, sim: &Outputs) -> (Channels, f64) {
        let mut y = [Vec::new(), Vec::new()];
        let mut s = [Vec::new(), Vec::new()];
        for ((rec, m), out) in self.recs.iter().zip(&self.valid).zip(sim) {
            for k in (0..rec.len()).filter(|&k| m[k]) {
                y[0].push(rec.v[k]);
                y[1].push(rec.w[k]);
                s[0].push(out[0][k]);
                s[1].push(out[1][k]);
            }
        }
        let fit = |c: usize| ChannelFit {
            fit_percent: metrics::fit_percent(&y[c], &s[c]),
            rms: (y[c]
                .iter()
                .zip(&s[c])
                .map(|(a, b)| (a - b).powi(2))
                .sum::<f64>()
                / y[c].len().max(1) as f64)
                .sqrt(),
        };
        let cost = (0..2)
            .map(|c| {
                y[c].iter()
                    .zip(&s[c])
                    .map(|(a, b)| ((a - b) * self.weight[c]).powi(2))
                    .sum::<f64>()
            })
            .sum();
        (
            Channels {
                v: fit(0),
                w: fit(1),
            },
            cost,
        )
    }
    /// Earliest and latest time over the recordings [s].
    fn span(&self) -> (f64, f64) {
        let lo = self
            .recs
            .iter()
            .map(|r| r.t[0])
            .fold(f64::INFINITY, f64::min);
        let hi = self
            .recs
            .iter()
            .map(|r| r.t[r.len() - 1])
            .fold(f64::NEG_INFINITY, f64::max);
        (lo, hi)
    }
    /// Shortest block [samples].
    fn block(&self) -> usize {
        self.recs
            .iter()
            .map(|r| r.len() / self.blocks)
            .min()
            .unwrap_or(1)
            .max(1)
    }
    /// Lags of the correlation tests: `max_lag_s`, at most half a block.
    fn max_lag(&self, settings: &DiagnoseSettings) -> usize {
        ((settings.max_lag_s / self.dt).round() as usize).clamp(1, (self.block() / 2).max(1))
    }
    /// Lag window of the fingerprints' long-run variance: the Newey–West rule, but at least a
    /// second (free-run residuals stay correlated over the robot's time constants and
    /// longer), at most a quarter block.
    fn hac_lags(&self) -> usize {
        let n = self.recs.iter().map(Recording::len).max().unwrap_or(0);
        let rule = (4.0 * (n as f64 / 100.0).powf(2.0 / 9.0)).floor() as usize;
        rule.max((1.0 / self.dt).round() as usize)
            .min((self.block() / 4).max(1))
    }
}

/// The wheel track from the metadata: `track`, a `kinematics` line with `track X`, or the
/// built-in profile named by `robot`.
fn track_from_meta(rec: &Recording) -> Option<f64> {
    let valid = |x: f64| (x.is_finite() && x > 0.0).then_some(x);
    if let Some(t) = rec
        .meta("track")
        .and_then(|s| s.split_whitespace().next()?.parse().ok())
        .and_then(valid)
    {
        return Some(t);
    }
    if let Some(k) = rec.meta("kinematics") {
        let mut it = k.split_whitespace();
        while let Some(w) = it.next() {
            if w == "track"
                && let Some(x) = it
                    .next()
                    .and_then(|s| s.trim_end_matches(',').parse().ok())
                    .and_then(valid)
            {
                return Some(x);
            }
        }
    }
    rec.meta("robot")
        .and_then(wheelid_robots::RobotProfile::by_name)
        .map(|p| p.track)
}

/// Bounds of the whole θ of the model with `candidates`: θ1…θ6 free, then each candidate's.
fn model_bounds(candidates: &[Candidate], t_range: (f64, f64)) -> Vec<(f64, f64)> {
    let mut b = vec![(f64::NEG_INFINITY, f64::INFINITY); 6];
    for c in candidates {
        b.extend(c.effect().bounds(t_range));
    }
    b
}

/// A candidate's pattern columns and the guesses they come with.
struct Pattern {
    candidate: Candidate,
    /// Columns per candidate parameter (None: not probed).
    s: DMatrix<f64>,
    /// Which candidate parameter each column belongs to.
    param_of_col: Vec<usize>,
    /// Parameter values: the probe levels or null + β̂ after the test.
    guess: Vec<f64>,
    /// Parameters held at their null (inactive channels).
    inactive: Vec<usize>,
    /// Description for the report.
    evidence: String,
    /// Bonferroni factor (grid of payload times).
    grid: usize,
}

/// Builds the fingerprints of `c` at the current model from its [`Probe`]; `None` if the
/// candidate cannot act on these data (no probe level binds, no track for the asymmetry).
fn patterns(c: Candidate, data: &Data, cur: &Current) -> Option<Vec<Pattern>> {
    let frame = data.frame();
    let mut cands = cur.candidates.clone();
    cands.push(c);
    let model = data.model(&cands);
    let th6 = &cur.theta[..6];
    let (t_lo, t_hi) = data.span();
    let null = c.effect().null(th6, 0.5 * (t_lo + t_hi));
    let with = |vals: &[f64]| {
        let mut th = cur.theta.clone();
        th.extend_from_slice(vals);
        simulate_all(&model, &th, &data.recs, &cur.initial)
    };
    let fd = |vals: &[f64], j: usize, h: f64| -> Option<nalgebra::DVector<f64>> {
        let mut v = vals.to_vec();
        v[j] += h;
        let y = with(&v)?;
        Some(frame.flatten(&score::difference(&y, &cur.sim, h)))
    };
    let single =
        |cols: Vec<nalgebra::DVector<f64>>, params: Vec<usize>, evidence: String| Pattern {
            candidate: c,
            s: DMatrix::from_columns(&cols),
            param_of_col: params,
            guess: null.clone(),
            inactive: Vec::new(),
            evidence,
            grid: 1,
        };
    let probe_data = ProbeData {
        recordings: &data.recs,
        accel: &data.accel,
        theta: th6,
        dt: data.dt,
        track: data.track,
    };
    match c.effect().probe(&probe_data)? {
        Probe::Gradient(steps) => {
            let cols = steps
                .iter()
                .map(|&(j, h)| fd(&null, j, h))
                .collect::<Option<Vec<_>>>()?;
            let params = steps.iter().map(|&(j, _)| j).collect();
            Some(vec![single(cols, params, c.effect().evidence().into())])
        }
        // The level read off a nominal fit that has absorbed part of the limit sits above the
        // true one: probed at a few fractions of it, the best taken (Bonferroni).
        Probe::Levels { levels, evidence } => {
            let params: Vec<usize> = levels.iter().map(|&(j, _)| j).collect();
            let mut out = Vec::new();
            for f in PROBE_FRACTIONS {
                let mut v = null.clone();
                for &(j, level) in &levels {
                    v[j] = f * level;
                }
                let cols = params
                    .iter()
                    .map(|&j| {
                        let mut one = null.clone();
                        one[j] = v[j];
                        with(&one).map(|y| frame.flatten(&score::difference(&y, &cur.sim, 1.0)))
                    })
                    .collect::<Option<Vec<_>>>()?;
                let mut p = single(cols, params.clone(), evidence.clone());
                p.guess = v;
                p.grid = PROBE_FRACTIONS.len();
                out.push(p);
            }
            Some(out)
        }
        // A grid of change times over the middle of the run, one thread per time.
        Probe::TimeGrid { time, n, columns } => {
            let pattern_at = |g: usize| {
                let ts = t_lo + (t_hi - t_lo) * g as f64 / (n + 1) as f64;
                let mut vals = null.clone();
                vals[time] = ts;
                let cols = columns
                    .iter()
                    .map(|&(j, rel)| fd(&vals, j, rel * vals[j].abs().max(1e-3)))
                    .collect::<Option<Vec<_>>>()?;
                let params = columns.iter().map(|&(j, _)| j).collect();
                let mut p = single(
                    cols,
                    params,
                    format!("the dynamics change around t = {ts:.1} s"),
                );
                p.guess = vals;
                p.grid = n;
                Some(p)
            };
            std::thread::scope(|scope| {
                let handles: Vec<_> = (1..=n)
                    .map(|g| {
                        let pattern_at = &pattern_at;
                        scope.spawn(move || pattern_at(g))
                    })
                    .collect();
                handles
                    .into_iter()
                    .map(|h| h.join().ok().flatten())
                    .collect::<Option<Vec<_>>>()
            })
        }
    }
}

/// One candidate's fingerprint at the current model: the best pattern (over the payload
/// grid) with its score.
struct Nominee {
    pattern: Pattern,
    score: score::Score,
    p_value: f64,
}

fn fingerprint(
    c: Candidate,
    data: &Data,
    cur: &Current,
    q: &DMatrix<f64>,
    e: &nalgebra::DVector<f64>,
) -> Option<Nominee> {
    let frame = data.frame();
    let lags = data.hac_lags();
    let mut best: Option<Nominee> = None;
    for mut pattern in patterns(c, data, cur)? {
        let Some(s) = score::score(&frame, q, &pattern.s, e, lags) else {
            continue;
        };
        let p_value = (s.p_value * pattern.grid as f64).min(1.0);
        // Channels: columns whose own z is large; the others stay at their null.
        if let EffectChannels::Each { positive } = c.effect().channels() {
            // Every channel the pattern reaches is fitted (a friction or a loss only where the
            // residual asks for a positive one); insignificant ones are dropped after the fit.
            let active: Vec<usize> = pattern
                .param_of_col
                .iter()
                .zip(&s.beta)
                .filter(|(_, b)| !positive || **b > 0.0)
                .map(|(&j, _)| j)
                .collect();
            pattern.inactive = (0..2).filter(|j| !active.contains(j)).collect();
        }
        // First guess: the probe level, or one Gauss–Newton step from the null.
        if !matches!(c.effect().search(), Search::Limit { .. }) {
            for (col, &j) in pattern.param_of_col.iter().enumerate() {
                pattern.guess[j] += s.beta[col];
            }
        }
        let better = best
            .as_ref()
            .is_none_or(|b| p_value < b.p_value || (p_value == b.p_value && s.stat > b.score.stat));
        if better {
            best = Some(Nominee {
                pattern,
                score: s,
                p_value,
            });
        }
    }
    best
}

/// The channels a candidate acts on ([`EffectChannels`]): for a per-channel one, those whose
/// parameter is `active`.
fn channels_of(c: Candidate, active: impl Fn(usize) -> bool) -> Vec<String> {
    match c.effect().channels() {
        EffectChannels::Each { .. } => (0..2)
            .filter(|&j| active(j))
            .map(|j| ["v", "w"][j].to_owned())
            .collect(),
        EffectChannels::Omega => vec!["w".into()],
        EffectChannels::Both => vec!["v".into(), "w".into()],
    }
}

/// Where a candidate's fit starts: θ, bounds, held parameters, and the training cost there
/// (the screen that orders the fits).
struct Start {
    theta: Vec<f64>,
    bounds: Vec<(f64, f64)>,
    pinned: Vec<usize>,
    cost: f64,
}

/// The start of `nominee`'s fit from its fingerprint's guess: dead times by a grid, Gauss–
/// Newton steps shortened by a line search, inactive channels held at their null. `Err` if the
/// guess is no such physics.
fn start_candidate(
    data: &Data,
    cur: &Current,
    nominee: &Nominee,
) -> std::result::Result<Start, String> {
    let c = nominee.pattern.candidate;
    let mut cands = cur.candidates.clone();
    cands.push(c);
    let model = data.model(&cands);
    let base = cur.theta.len();
    let mut guess = nominee.pattern.guess.clone();
    let (t_lo, t_hi) = data.span();
    let margin = 0.05 * (t_hi - t_lo);
    let mut bounds = model_bounds(&cur.candidates, (t_lo + margin, t_hi - margin));
    let cb = c.effect().bounds((t_lo + margin, t_hi - margin));
    let search = c.effect().search();
    for (g, &(lo, hi)) in guess.iter_mut().zip(&cb) {
        let span = if hi.is_finite() && lo.is_finite() {
            1e-3 * (hi - lo)
        } else {
            1e-6
        };
        *g = g.clamp(lo + span, hi - span);
    }
    // A friction or a loss that the residual asks to be negative is no such physics.
    if c.effect().channels() == (EffectChannels::Each { positive: true })
        && nominee.pattern.inactive.len() == 2
    {
        return Err(format!(
            "its pattern asks for negative {} and {} ({:.3e}, {:.3e})",
            c.params()[0].name,
            c.params()[1].name,
            nominee.pattern.guess[0],
            nominee.pattern.guess[1]
        ));
    }
    let frame = data.frame();
    let mut theta = cur.theta.clone();
    theta.extend_from_slice(&guess);
    let training_cost = |th: &[f64]| {
        simulate_all(&model, th, &data.recs, &cur.initial)
            .map_or(f64::INFINITY, |y| frame.residuals(&y).norm_squared())
    };
    // A Gauss–Newton step from the null can overshoot far (a pattern nearly absorbed by θ):
    // it is shortened to the best of a few fractions by the training cost.
    if matches!(search, Search::Smooth | Search::ChangeTime) {
        let null = c.effect().null(&cur.theta, theta[base]);
        let step: Vec<f64> = (0..null.len())
            .map(|j| {
                if nominee.pattern.inactive.contains(&j) {
                    0.0
                } else {
                    theta[base + j] - null[j]
                }
            })
            .collect();
        let mut best = (f64::INFINITY, 1.0);
        for frac in [1.0, 0.5, 0.25, 0.1, 0.03, 0.01] {
            let mut th = theta.clone();
            for j in 0..null.len() {
                th[base + j] = null[j] + frac * step[j];
            }
            let cost = training_cost(&th);
            if cost < best.0 {
                best = (cost, frac);
            }
        }
        for j in 0..null.len() {
            theta[base + j] = null[j] + best.1 * step[j];
        }
    }
    // A limit's probe level is a rough reading of the data: scaled on a grid first.
    if matches!(search, Search::Limit { .. }) {
        let active: Vec<usize> = (0..2)
            .filter(|j| !nominee.pattern.inactive.contains(j))
            .collect();
        theta = level_grid(&theta, base, &active, &training_cost);
    }
    // A dead time is searched on a grid first: its cost has many local minima.
    if search == Search::DeadTime {
        let mut best = (f64::INFINITY, guess[0]);
        let mut d = 0.5 * data.dt;
        let mut grid = vec![guess[0]];
        while d <= 1.5 {
            grid.push(d);
            d *= 1.4;
        }
        for d in grid {
            theta[base] = d;
            let cost = training_cost(&theta);
            if cost < best.0 {
                best = (cost, d);
            }
        }
        theta[base] = best.1;
    }
    bounds.extend(cb);
    let mut pinned = cur.pinned.clone();
    for &j in &nominee.pattern.inactive {
        pinned.push(base + j);
        theta[base + j] = c.effect().null(&cur.theta, 0.0)[j];
    }
    // A change time is not fitted by gradient: the training cost is flat while it sweeps a
    // validation block. It is held, θ fitted, then the time scanned on a fine grid with that θ
    // (the middle of the flat minimum taken), and θ fitted again if it moved.
    if search == Search::ChangeTime {
        pinned.push(base);
    }
    let cost = training_cost(&theta);
    Ok(Start {
        theta,
        bounds,
        pinned,
        cost,
    })
}

/// θ with a limit's `active` channels (0: v, 1: ω) scaled: their level (θ[base + j], unless
/// it never binds) by `level`, their θ1 or θ2 (θ[j]) by `lag`.
fn scaled(theta: &[f64], base: usize, active: &[usize], level: f64, lag: f64) -> Vec<f64> {
    let mut th = theta.to_vec();
    for &j in active {
        if th[base + j] < NEVER {
            th[base + j] *= level;
        }
        th[j] *= lag;
    }
    th
}

/// A limit's level scaled by the best of a few factors (0.5…2) by `cost`.
fn level_grid(
    theta: &[f64],
    base: usize,
    active: &[usize],
    cost: &dyn Fn(&[f64]) -> f64,
) -> Vec<f64> {
    let mut best = (cost(theta), 1.0);
    for f in [0.5, 0.7, 0.85, 1.2, 1.5, 2.0] {
        let c = cost(&scaled(theta, base, active, f, 1.0));
        if c < best.0 {
            best = (c, f);
        }
    }
    scaled(theta, base, active, best.1, 1.0)
}

/// Fits the current model plus `nominee` on the training blocks from `start`; returns the new
/// state and the fit.
fn fit_candidate(
    data: &Data,
    cur: &Current,
    nominee: &Nominee,
    start: Start,
) -> std::result::Result<(Current, OutputErrorFit), String> {
    let c = nominee.pattern.candidate;
    let mut cands = cur.candidates.clone();
    cands.push(c);
    let model = data.model(&cands);
    let base = cur.theta.len();
    let Start {
        mut theta,
        bounds,
        mut pinned,
        ..
    } = start;
    let frame = data.frame();
    let (t_lo, t_hi) = data.span();
    let margin = 0.05 * (t_hi - t_lo);
    let run = |theta: &[f64], pinned: &[usize]| fit_pinned(data, &model, theta, pinned, &bounds);
    let search = c.effect().search();
    let two = matches!(c.effect().channels(), EffectChannels::Each { .. });
    let both_free = (0..2).all(|j| !pinned.contains(&(base + j)));
    // Compared at the common (nominal) weights: each fit's own cost is weighted by its own
    // noise levels.
    let cost = |r: &PinnedFit| {
        (0..2)
            .map(|c| (r.0.noise_std[c] * data.weight[c]).powi(2))
            .sum::<f64>()
    };
    let mut first = run(&theta, &pinned);
    // A rate limit the nominal model lacks is traded for a slower lag (θ1, θ2 too large, a
    // limit then hardly binds): the fit also runs from the active channels' θ1, θ2 shortened
    // (a coarse grid with the level, then the level's grid), the better fit kept. Not in the
    // screen: a fast lag with a ramp also imitates a dead time, which must still rank first
    // where it is one.
    let active: Vec<usize> = (0..2).filter(|j| !pinned.contains(&(base + j))).collect();
    let alternative = (search == Search::Limit { rate: true }).then(|| {
        let training_cost = |th: &[f64]| {
            simulate_all(&model, th, &data.recs, &cur.initial)
                .map_or(f64::INFINITY, |y| frame.residuals(&y).norm_squared())
        };
        let mut best = (f64::INFINITY, 1.0, 1.0);
        for lag in [0.3, 0.1, 0.03] {
            for level in [0.5, 1.0, 2.0] {
                let cost = training_cost(&scaled(&theta, base, &active, level, lag));
                if cost < best.0 {
                    best = (cost, level, lag);
                }
            }
        }
        let from = scaled(&theta, base, &active, best.1, best.2);
        level_grid(&from, base, &active, &training_cost)
    });
    if let Some(alt) = alternative
        && let Ok(r) = run(&alt, &pinned)
        && first.as_ref().map_or(true, |f| cost(&r) < cost(f))
    {
        first = Ok(r);
        theta = alt;
    }
    let (mut fit, mut full, mut free) = match first {
        Ok(r) => r,
        // Both channels cannot be told apart (one never acts): each alone, the better kept.
        Err(first) if two && both_free => {
            let mut best: Option<(PinnedFit, Vec<usize>)> = None;
            for j in 0..2 {
                let mut p = pinned.clone();
                p.push(base + j);
                let mut th = theta.clone();
                th[base + j] = c.effect().null(&cur.theta, 0.0)[j];
                if let Ok(r) = run(&th, &p)
                    && best.as_ref().is_none_or(|b| cost(&r) < cost(&b.0))
                {
                    best = Some((r, p));
                }
            }
            let (r, p) = best.ok_or(first)?;
            pinned = p;
            r
        }
        Err(e) => return Err(e),
    };
    let mut time_resolution = 0.0;
    if search == Search::ChangeTime {
        let step = (t_hi - t_lo) / (nominee.pattern.grid + 1) as f64;
        let t0 = full[base];
        let scan: Vec<(f64, f64)> = (-16..=16)
            .map(|i| {
                let mut th = full.clone();
                th[base] = (t0 + step * i as f64 / 16.0).clamp(t_lo + margin, t_hi - margin);
                let cost = simulate_all(&model, &th, &data.recs, &fit.initial)
                    .map_or(f64::INFINITY, |y| frame.residuals(&y).norm_squared());
                (th[base], cost)
            })
            .collect();
        // The contiguous run of near-minimal points around the least one.
        let (arg, least) =
            scan.iter().enumerate().fold(
                (0, f64::INFINITY),
                |a, (i, x)| if x.1 < a.1 { (i, x.1) } else { a },
            );
        let near = |i: usize| scan[i].1 <= least * (1.0 + 1e-6) + 1e-12;
        let (mut a, mut b) = (arg, arg);
        while a > 0 && near(a - 1) {
            a -= 1;
        }
        while b + 1 < scan.len() && near(b + 1) {
            b += 1;
        }
        let (lo, hi) = (scan[a].0, scan[b].0);
        time_resolution = 0.5 * (hi - lo) + step / 32.0;
        let t_best = 0.5 * (lo + hi);
        if (t_best - t0).abs() > 1e-9 {
            let mut th = full.clone();
            th[base] = t_best;
            (fit, full, free) = run(&th, &pinned)?;
        }
    }
    // A two-channel candidate keeps only the channels where it is significant.
    if two {
        // The weakest channel is dropped while more than one is fitted and one is weak (a
        // parameter that another absorbs, e.g. a turning loss |v|·ω that θ5 v·ω stands for when
        // v keeps its sign, also blurs its partner).
        loop {
            let z: Vec<(usize, f64)> = (0..2)
                .filter_map(|j| {
                    let a = free.iter().position(|&i| i == base + j)?;
                    let (x, se) = (full[base + j], fit.std_err[a]);
                    // A limit that hardly binds counts as weak whatever its interval.
                    let idle = c
                        .effect()
                        .binding(&data.recs, j, x)
                        .is_some_and(|f| f < 0.01);
                    Some((j, if se > 0.0 && !idle { x.abs() / se } else { 0.0 }))
                })
                .collect();
            let Some(&(j, zmin)) = z.iter().min_by(|a, b| a.1.total_cmp(&b.1)) else {
                break;
            };
            if z.len() < 2 || zmin >= 3.0 {
                break;
            }
            // From the start again: the weak pair may have wandered along their valley.
            let mut th = theta.clone();
            pinned.push(base + j);
            th[base + j] = c.effect().null(&cur.theta, 0.0)[j];
            (fit, full, free) = run(&th, &pinned)?;
        }
    }
    let mut new = current_of(&model, cands, pinned, &fit, full, &free, data)?;
    if search == Search::ChangeTime {
        // The change time's uncertainty is the width of its flat minimum.
        new.std_err[base] = time_resolution;
    }
    Ok((new, fit))
}

/// An output-error fit of some parameters: the fit, the full θ, the free indices.
type PinnedFit = (OutputErrorFit, Vec<f64>, Vec<usize>);

/// Fits `model` on the training blocks from `theta` with the `pinned` parameters held
/// (`bounds` for the full θ).
fn fit_pinned(
    data: &Data,
    model: &Extended,
    theta: &[f64],
    pinned: &[usize],
    bounds: &[(f64, f64)],
) -> std::result::Result<PinnedFit, String> {
    let restricted = Pinned::new(model, theta.to_vec(), pinned);
    let oe = OutputError {
        bounds: Some(restricted.free.iter().map(|&i| bounds[i]).collect()),
        mask: Some(data.train.clone()),
        patience: 10,
        tolerance: 1e-5,
        forward_differences: true,
        ..OutputError::default()
    };
    let fit = oe
        .fit(&restricted, &data.recs, &restricted.free_values())
        .map_err(|e| format!("the fit failed: {e}"))?;
    let full = restricted.expand(&fit.theta);
    Ok((fit, full, restricted.free))
}

/// The search state after a fit: standard errors and covariance spread back onto the full θ
/// (held parameters 0), and the fitted model's simulation.
fn current_of(
    model: &Extended,
    candidates: Vec<Candidate>,
    pinned: Vec<usize>,
    fit: &OutputErrorFit,
    full: Vec<f64>,
    free: &[usize],
    data: &Data,
) -> std::result::Result<Current, String> {
    let p = full.len();
    let mut std_err = vec![0.0; p];
    let mut covariance = DMatrix::zeros(p, p);
    for (a, &i) in free.iter().enumerate() {
        std_err[i] = fit.std_err[a];
        for (b, &j) in free.iter().enumerate() {
            covariance[(i, j)] = fit.covariance[(a, b)];
        }
    }
    let sim = simulate_all(model, &full, &data.recs, &fit.initial)
        .ok_or("the fitted model does not simulate")?;
    Ok(Current {
        candidates,
        pinned,
        theta: full,
        std_err,
        covariance,
        initial: fit.initial.clone(),
        sim,
        jacobian: Some(data.frame().weigh(&fit.jacobian)),
    })
}

/// The current model without its `k`-th candidate, refitted on the training blocks.
fn remove_candidate(data: &Data, cur: &Current, k: usize) -> std::result::Result<Current, String> {
    let offset = 6 + cur.candidates[..k]
        .iter()
        .map(|c| c.params().len())
        .sum::<usize>();
    let len = cur.candidates[k].params().len();
    let mut cands = cur.candidates.clone();
    cands.remove(k);
    let mut theta = cur.theta.clone();
    theta.drain(offset..offset + len);
    let pinned: Vec<usize> = cur
        .pinned
        .iter()
        .filter(|&&i| i < offset || i >= offset + len)
        .map(|&i| if i >= offset { i - len } else { i })
        .collect();
    let (t_lo, t_hi) = data.span();
    let margin = 0.05 * (t_hi - t_lo);
    let bounds = model_bounds(&cands, (t_lo + margin, t_hi - margin));
    let model = data.model(&cands);
    let (fit, full, free) = fit_pinned(data, &model, &theta, &pinned, &bounds)?;
    current_of(&model, cands, pinned, &fit, full, &free, data)
}

/// Significance and plausibility of a fitted candidate ([`wheelid_core::Effect::plausible`]
/// for each free parameter, then together); `Err` says why not.
fn check_candidate(data: &Data, new: &Current, c: Candidate) -> std::result::Result<(), String> {
    let base = new.theta.len() - c.params().len();
    let fit = FitData {
        recordings: &data.recs,
        theta: &new.theta,
        covariance: &new.covariance,
        base,
    };
    for j in (0..c.params().len()).filter(|j| !new.pinned.contains(&(base + j))) {
        c.effect()
            .plausible(j, new.theta[base + j], new.std_err[base + j], &fit)?;
    }
    c.effect().plausible_together(&fit)
}

/// Runs a diagnosis of `recordings` with the nominal `model` (its θ seeds every extended
/// model).
///
/// # Errors
/// [`DiagnoseError`] for unreadable or too-short data, or a nominal fit that fails.
pub fn diagnose(
    recordings: &[Recording],
    model: &dyn RegressorModel,
    settings: &DiagnoseSettings,
) -> Result<Diagnosis, DiagnoseError> {
    let clock = Instant::now();
    if recordings.is_empty() {
        return Err(DiagnoseError::Setting("no recording given".into()));
    }
    let bad = |what: String| Err(DiagnoseError::Setting(what));
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
    if let Some(t) = settings.track_m
        && !(t.is_finite() && t > 0.0)
    {
        return bad(format!("track = {t} m must be > 0"));
    }
    let bar = if settings.progress {
        ProgressBar::new(4)
    } else {
        ProgressBar::hidden()
    };
    bar.set_style(
        ProgressStyle::with_template("{spinner} diagnose [{bar:30}] {pos}/{len} {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    bar.set_message("fitting the nominal model");
    // 1. fit
    let recs: Vec<Recording> = recordings
        .iter()
        .map(|r| condition::make_uniform(r).map(|(u, _)| u))
        .collect::<Result<_, _>>()?;
    let mut train = Vec::new();
    let mut valid = Vec::new();
    for r in &recs {
        let n = r.len();
        if n < 10 * settings.blocks {
            return Err(DiagnoseError::Setting(format!(
                "{}: {n} samples are too few to split into {} blocks",
                r.source.display(),
                settings.blocks
            )));
        }
        let m: Vec<bool> = (0..n)
            .map(|k| (k * settings.blocks / n).is_multiple_of(2))
            .collect();
        valid.push(m.iter().map(|b| !b).collect::<Vec<bool>>());
        train.push(m);
    }
    let dt = recs
        .iter()
        .map(|r| r.sampling().dt_median)
        .fold(f64::INFINITY, f64::min);
    let seconds = |m: &[Vec<bool>]| m.iter().flatten().filter(|&&b| b).count() as f64 * dt;
    let split = Split {
        blocks: settings.blocks,
        training_s: seconds(&train),
        validation_s: seconds(&valid),
    };
    let ls = identify(
        &recs,
        model,
        &Ols::default(),
        &IdentifySettings {
            condition: settings.condition.clone(),
            estimator: Estimator::Ls,
            ..IdentifySettings::default()
        },
    )?;
    let oe = OutputError {
        mask: Some(train.clone()),
        tolerance: NOMINAL_TOLERANCE,
        ..OutputError::default()
    };
    // Least squares can come out unphysical (a long dead time makes the regression's θ1
    // negative); then output error starts from unit gains and a time constant of 3 periods.
    let fallback = [3.0 * dt, 3.0 * dt, 0.0, 1.0, 0.0, 1.0];
    let sane = [0, 1, 3, 5].iter().all(|&i| ls.theta[i] > 0.0);
    let nominal_fit = match oe.fit(model, &recs, if sane { &ls.theta } else { &fallback }) {
        Err(_) if sane => oe.fit(model, &recs, &fallback)?,
        other => other?,
    };
    let track = settings
        .track_m
        .or_else(|| recs.iter().find_map(track_from_meta));
    // Measured accelerations: derivative of the zero-phase filtered response.
    let cutoff = condition::suggest_cutoff(&recs.iter().collect::<Vec<_>>())
        .map(|(f, _)| f)
        .ok();
    let accel: Outputs = recs
        .iter()
        .map(|r| {
            let d = cutoff
                .and_then(|fc| condition::condition(r, None, fc, &settings.condition).ok())
                .and_then(|c| Some([c.differentiate(&c.v).ok()?, c.differentiate(&c.w).ok()?]));
            d.unwrap_or_else(|| [vec![0.0; r.len()], vec![0.0; r.len()]])
        })
        .collect();
    let weight = [0, 1].map(|c| 1.0 / nominal_fit.noise_std[c].max(1e-12));
    let data = Data {
        recs,
        train,
        valid,
        dt,
        blocks: settings.blocks,
        track,
        weight,
        accel,
    };
    let nominal_model = data.model(&[]);
    let sim = simulate_all(
        &nominal_model,
        &nominal_fit.theta,
        &data.recs,
        &nominal_fit.initial,
    )
    .ok_or_else(|| DiagnoseError::Setting("the nominal model does not simulate".into()))?;
    let mut cur = Current {
        candidates: Vec::new(),
        pinned: Vec::new(),
        theta: nominal_fit.theta.clone(),
        std_err: nominal_fit.std_err.clone(),
        covariance: nominal_fit.covariance.clone(),
        initial: nominal_fit.initial.clone(),
        sim,
        jacobian: Some(data.frame().weigh(&nominal_fit.jacobian)),
    };
    let stage = |cur: &Current| {
        let (channels, validation_cost) = data.validate(&cur.sim);
        let model = data.model(&cur.candidates);
        Stage {
            model: std::iter::once("nominal")
                .chain(cur.candidates.iter().map(|c| c.name()))
                .collect::<Vec<_>>()
                .join(" + "),
            theta: cur.theta.clone(),
            std_err: cur.std_err.clone(),
            names: model.params().iter().map(|p| p.name.to_owned()).collect(),
            channels,
            validation_cost,
        }
    };
    let nominal = stage(&cur);
    bar.inc(1);
    // 2.–3. test and locate
    bar.set_message("testing the residuals");
    let max_lag = data.max_lag(settings);
    let location = locate::locate(&data.recs, &cur.sim, &data.valid, dt, max_lag);
    // 4.–5. name, model, accept; then look again.
    let mut findings = Vec::new();
    let mut rejected = Vec::new();
    let mut rounds = Vec::new();
    let mut tests = Vec::new();
    let mut mismatch = false;
    let mut tried: Vec<Candidate> = Vec::new();
    for round in 0..=settings.max_effects {
        let frame = data.frame();
        let e = frame.residuals(&cur.sim);
        let cur_model = data.model(&cur.candidates);
        let free: Vec<usize> = (0..cur.theta.len())
            .filter(|i| !cur.pinned.contains(i))
            .collect();
        let pinned_model = Pinned::new(&cur_model, cur.theta.clone(), &cur.pinned);
        // The fit's own Jacobian at θ̂ where it gave one, else the sensitivities anew.
        let fresh;
        let j = match &cur.jacobian {
            Some(j) => j,
            None => {
                let Some(x) = score::jacobian(
                    &pinned_model,
                    &free.iter().map(|&i| cur.theta[i]).collect::<Vec<_>>(),
                    &cur.initial,
                    &cur.sim,
                    &frame,
                ) else {
                    break;
                };
                fresh = x;
                &fresh
            }
        };
        let q = score::basis(j);
        let pending: Vec<Candidate> = settings
            .candidates
            .iter()
            .copied()
            .filter(|c| !cur.candidates.contains(c) && !tried.contains(c))
            .collect();
        // One thread per candidate: each fingerprint is a handful of simulations.
        let nominees: Vec<Nominee> = std::thread::scope(|scope| {
            let handles: Vec<_> = pending
                .iter()
                .map(|&c| {
                    let (data, cur, q, e) = (&data, &cur, &q, &e);
                    scope.spawn(move || fingerprint(c, data, cur, q, e))
                })
                .collect();
            handles
                .into_iter()
                .filter_map(|h| h.join().ok().flatten())
                .collect()
        });
        // The family: residual–command independence (validation) and the fingerprints.
        let here = if round == 0 {
            location.clone()
        } else {
            locate::locate(&data.recs, &cur.sim, &data.valid, dt, max_lag)
        };
        let mut p_values = here.p_values();
        p_values.extend(nominees.iter().map(|n| n.p_value));
        let decisions = holm(&p_values, settings.alpha);
        if round == 0 {
            let names = ["v_ref", "w_ref"];
            for (i, ch) in ["v", "w"].iter().enumerate() {
                for (k, u) in names.iter().enumerate() {
                    tests.push(TestResult {
                        name: format!("{ch} residual independent of {u}"),
                        p_value: p_values[2 * i + k],
                        significant: decisions[2 * i + k],
                    });
                }
            }
            for (n, (&p, &d)) in nominees
                .iter()
                .zip(p_values[4..].iter().zip(&decisions[4..]))
            {
                tests.push(TestResult {
                    name: format!("fingerprint of {}", n.pattern.candidate.name()),
                    p_value: p,
                    significant: d,
                });
            }
            mismatch = decisions.iter().any(|&d| d);
        }
        let nominated: Vec<bool> = decisions[4..].to_vec();
        rounds.push(
            nominees
                .iter()
                .zip(&nominated)
                .map(|(n, &d)| Fingerprint {
                    effect: n.pattern.candidate.name().into(),
                    channels: channels_of(n.pattern.candidate, |j| {
                        !n.pattern.inactive.contains(&j)
                    }),
                    stat: n.score.stat,
                    dof: n.score.dof,
                    p_value: n.p_value,
                    nominated: d,
                    evidence: n.pattern.evidence.clone(),
                })
                .collect::<Vec<_>>(),
        );
        if round == settings.max_effects || !mismatch {
            break;
        }
        let mut order: Vec<usize> = (0..nominees.len()).filter(|&i| nominated[i]).collect();
        order.sort_by(|&a, &b| {
            let (na, nb) = (&nominees[a], &nominees[b]);
            na.p_value.total_cmp(&nb.p_value).then(
                (nb.score.stat / nb.score.dof as f64)
                    .total_cmp(&(na.score.stat / na.score.dof as f64)),
            )
        });
        bar.set_length(bar.position() + order.len() as u64 + 1);
        let (_, cost_before) = data.validate(&cur.sim);
        let before = data.validate(&cur.sim).0;
        // Screen: every nominee's start (cheap), in parallel; then fit them in the order of
        // their training cost there, and add the first that passes.
        let starts: Vec<(usize, std::result::Result<Start, String>)> = std::thread::scope(|sc| {
            let handles: Vec<_> = order
                .iter()
                .map(|&i| {
                    let (data, cur, n) = (&data, &cur, &nominees[i]);
                    sc.spawn(move || (i, start_candidate(data, cur, n)))
                })
                .collect();
            handles.into_iter().filter_map(|h| h.join().ok()).collect()
        });
        let mut ready = Vec::new();
        for (i, st) in starts {
            tried.push(nominees[i].pattern.candidate);
            match st {
                Ok(st) => ready.push((i, st)),
                Err(reason) => rejected.push(Rejected {
                    effect: nominees[i].pattern.candidate.name().into(),
                    reason,
                }),
            }
        }
        ready.sort_by(|a, b| a.1.cost.total_cmp(&b.1.cost));
        let mut accepted: Option<(&Nominee, Current, Channels, f64)> = None;
        for (i, st) in ready {
            let n = &nominees[i];
            let c = n.pattern.candidate;
            bar.set_message(format!("fitting {}", c.name()));
            bar.inc(1);
            let verdict = fit_candidate(&data, &cur, n, st).and_then(|(new, _)| {
                let (after, cost) = data.validate(&new.sim);
                let drop = 1.0 - cost / cost_before;
                if drop < settings.min_improvement {
                    return Err(format!(
                        "the validation cost drops by {:.1} % only (< {:.0} %)",
                        100.0 * drop,
                        100.0 * settings.min_improvement
                    ));
                }
                for (name, b, a) in [
                    ("v", before.v.fit_percent, after.v.fit_percent),
                    ("ω", before.w.fit_percent, after.w.fit_percent),
                ] {
                    // A channel constant over the validation blocks has no fit % (NaN).
                    if b.is_finite() && (a.is_nan() || a < b - 1.0) {
                        return Err(format!(
                            "{name}'s validation fit falls from {b:.1} % to {a:.1} %"
                        ));
                    }
                }
                check_candidate(&data, &new, c)?;
                // The fingerprint must be gone from the new residual.
                let e_new = frame.residuals(&new.sim);
                // Gone: no longer significant, or at least halved (another effect still
                // present may leave a trace along it).
                // Judged net of the other nominees' patterns: with two effects present, the
                // other one leaves a trace along this one's pattern.
                let others: Vec<&DMatrix<f64>> = nominees
                    .iter()
                    .zip(&nominated)
                    .filter(|(m, d)| **d && m.pattern.candidate != c)
                    .map(|(m, _)| &m.pattern.s)
                    .collect();
                let q_net = if others.is_empty() {
                    q.clone()
                } else {
                    let mut cols: Vec<nalgebra::DVector<f64>> =
                        j.column_iter().map(|x| x.into_owned()).collect();
                    for m in others {
                        cols.extend(m.column_iter().map(|x| x.into_owned()));
                    }
                    score::basis(&DMatrix::from_columns(&cols))
                };
                if let Some(s) = score::score(&frame, &q_net, &n.pattern.s, &e_new, data.hac_lags())
                    && s.p_value * (n.pattern.grid as f64) < settings.alpha
                    && s.stat > FINGERPRINT_LEFT * n.score.stat
                {
                    return Err(format!(
                        "its fingerprint stays (χ²({}) = {:.1} of {:.1}, p = {:.1e})",
                        s.dof, s.stat, n.score.stat, s.p_value
                    ));
                }
                Ok((new, after, drop))
            });
            match verdict {
                Ok((new, after, drop)) => {
                    accepted = Some((n, new, after, drop));
                    break;
                }
                Err(reason) => rejected.push(Rejected {
                    effect: c.name().into(),
                    reason,
                }),
            }
        }
        let Some((n, new, after, drop)) = accepted else {
            break;
        };
        let c = n.pattern.candidate;
        let base = new.theta.len() - c.params().len();
        let mut parameters = BTreeMap::new();
        let mut std_err = BTreeMap::new();
        for (j, info) in c.params().iter().enumerate() {
            // The change time is held during the fit but found by its own scan.
            let scanned = c.effect().search() == Search::ChangeTime && j == 0;
            if scanned || !new.pinned.contains(&(base + j)) {
                parameters.insert(info.name.to_owned(), new.theta[base + j]);
                std_err.insert(info.name.to_owned(), new.std_err[base + j]);
            }
        }
        let channels = channels_of(c, |j| !new.pinned.contains(&(base + j)));
        findings.push(Finding {
            effect: c.name().into(),
            channels,
            parameters,
            std_err,
            evidence: format!(
                "fingerprint χ²({}) = {:.1}, p = {:.1e}: {}; validation cost −{:.1} %",
                n.score.dof,
                n.score.stat,
                n.p_value,
                n.pattern.evidence,
                100.0 * drop
            ),
            fit_percent_after: BTreeMap::from([
                ("v".to_owned(), after.v.fit_percent),
                ("w".to_owned(), after.w.fit_percent),
            ]),
            validation_cost_drop_percent: 100.0 * drop,
        });
        cur = new;
        tried.clear();
        // Backward step: an effect added earlier that the new one makes redundant goes.
        if cur.candidates.len() >= 2 {
            let (_, cost_with) = data.validate(&cur.sim);
            for k in (0..cur.candidates.len() - 1).rev() {
                let Ok(without) = remove_candidate(&data, &cur, k) else {
                    continue;
                };
                let (_, cost_without) = data.validate(&without.sim);
                let rise = cost_without / cost_with - 1.0;
                if rise < settings.min_improvement {
                    let name = cur.candidates[k].name();
                    findings.retain(|f| f.effect != name);
                    rejected.push(Rejected {
                        effect: name.into(),
                        reason: format!(
                            "redundant once {} is in: without it the validation cost rises by \
                             {:.1} % only",
                            c.name(),
                            100.0 * rise
                        ),
                    });
                    cur = without;
                    tried.push(Candidate::by_name(name).unwrap_or(c));
                    break;
                }
            }
        }
    }
    bar.set_message("done");
    bar.finish_and_clear();
    // Every finding's parameters as the final model has them (the later fits refit them all).
    let mut at = 6;
    for c in &cur.candidates {
        if let Some(f) = findings.iter_mut().find(|f| f.effect == c.name()) {
            for (j, info) in c.params().iter().enumerate() {
                if let Some(v) = f.parameters.get_mut(info.name) {
                    *v = cur.theta[at + j];
                }
                if let Some(v) = f.std_err.get_mut(info.name)
                    && !(c.effect().search() == Search::ChangeTime && j == 0)
                {
                    *v = cur.std_err[at + j];
                }
            }
        }
        at += c.params().len();
    }
    let final_location = if findings.is_empty() {
        location.clone()
    } else {
        locate::locate(&data.recs, &cur.sim, &data.valid, dt, max_lag)
    };
    let final_p = final_location.p_values();
    let left = holm(&final_p, settings.alpha);
    let unexplained = if mismatch && left.iter().any(|&b| b) {
        let channels: Vec<usize> = (0..2).filter(|&c| left[2 * c] || left[2 * c + 1]).collect();
        Some(Unexplained {
            channels: channels.iter().map(|&c| ["v", "w"][c].to_owned()).collect(),
            location: channels
                .iter()
                .map(|&c| format!("{}: {}", ["v", "ω"][c], final_location.summary(c)))
                .collect(),
        })
    } else {
        None
    };
    let final_stage = stage(&cur);
    let nominal_sim = simulate_all(
        &nominal_model,
        &nominal_fit.theta,
        &data.recs,
        &nominal_fit.initial,
    )
    .unwrap_or_else(|| cur.sim.clone());
    let series = data
        .recs
        .iter()
        .enumerate()
        .map(|(r, rec)| DiagnosisSeries {
            source: rec.source.clone(),
            t: rec.t.clone(),
            validation: data.valid[r].clone(),
            measured: [rec.v.clone(), rec.w.clone()],
            nominal: nominal_sim[r].clone(),
            extended: cur.sim[r].clone(),
        })
        .collect();
    Ok(Diagnosis {
        nominal,
        split,
        tests,
        mismatch,
        location,
        fingerprints: rounds,
        findings,
        rejected,
        unexplained,
        final_stage,
        final_location,
        seconds: clock.elapsed().as_secs_f64(),
        series,
    })
}
