//! Config-driven runs (`wheelid run CONFIG.toml`): one TOML file describes a whole
//! identification — robot backend, excitation, duration, model, solver and bounds,
//! conditioning, outputs — and the run walks the layers once: **drive** the robot (read, then
//! send, once per period; optionally estimating θ̂ online as it goes) → **record** →
//! **identify** → **write** the recording (CSV), the identified model (TOML) and the report
//! (text and JSON).
//!
//! ```toml
//! plugins = ["wheelid_turtlebot_plugin"]  # optional: a name beside the executable, or a path
//! duration_s = 120.0
//! stop_when = "duration"  # or "accuracy": until the online 95 % intervals of θ1, θ2, θ4, θ6
//! # accuracy = 0.01       #   are within this of θ̂, at most duration_s ([`StopWhen`])
//! # accuracy_of = "batch" #   or the batch answer's, identified every 10 s ([`AccuracyOf`])
//! # accuracy_every_s = 5.0 #  (the batch checks' period)
//!
//! [robot]                 # type: simulator | replay | pioneer | khepera | a plugin's
//! type = "simulator"
//! robot = "pioneer3dx"    # built-in profile (or a whole [robot.profile] table)
//! [robot.simulation]
//! seed = 3
//!
//! [excitation]            # the commands sent (a replayed log keeps its own)
//! type = "thesis_pioneer"
//!
//! # [design]              # optional, with stop_when = "accuracy": the excitation designed
//! # prior = [0.26, 0.25, 0.0, 1.0, 0.0, 1.08]   # (wheelid::design) and re-designed every
//! # command_max = [0.5, 1.2]                    # every_s from the online θ̂ ([`DesignSection`])
//! # space_m = [3.0, 3.0]
//!
//! [model]                 # type: vw-pd | wheel-pd | a plugin's
//! type = "vw-pd"
//!
//! [solver]                # type: ols | box (with bounds) | a plugin's
//! type = "box"
//! theta_lower = [0.05, 0.05, -0.1, 0.5, -0.5, 0.5]
//! theta_upper = [1.0, 1.0, 0.1, 1.5, 0.5, 1.5]
//!
//! [identify]              # estimator (ls | iv | oe) and conditioning
//! estimator = "ls"
//! cutoff_hz = 1.0
//!
//! [online]                # optional (or `run --online`): θ̂ while driving, online.csv
//! memory_s = 60.0         # wheelid::online::OnlineSettings
//! form = "instrumental_variables"   # or "least_squares"
//!
//! [output]
//! dir = "run-out"         # recording.csv, model.toml, report.txt, report.json
//! ```
//!
//! Built-in robots, models and solvers are chosen by their `type` through typetag
//! ([`RobotSpec`], [`ModelSpec`], [`SolverSpec`]); a `type` that no built-in has goes to the
//! plugins ([`crate::plugins`]), which get the table as TOML text. An unknown `type` is an
//! error listing the known ones; a misspelled key is an error naming its line.
//!
//! The Pioneer and Khepera backends accept `port = "loopback"`: the run then starts the
//! project's protocol server on top of the simulator ([`wheelid_robots::pioneer::ArcosServer`],
//! [`wheelid_robots::khepera::KheperaServer`]) on a free loopback port, in lock-step, and
//! drives the robot through it — the whole protocol stack without hardware.

use std::fmt::Debug;
use std::path::{Path, PathBuf};

use anyhow::{Context as _, Result, anyhow, bail};
use serde::Deserialize;
use wheelid_core::{ConditionSettings, Recording, RegressorModel, Robot, Solver};

use crate::config::ExcitationConfig;
use crate::files::{ModelFile, toml_msg};
use crate::identify::{Identification, IdentifySettings, identify_with};
use crate::observer::Observer;
use crate::online::{OnlineSettings, OnlineTheta};
use crate::plugins::Plugins;
use crate::registry::Registry;

mod batch_stop;
mod drive;
mod redesign;
mod specs;
pub use batch_stop::{BatchCheck, BatchStop, Identify, half_width as batch_half_width};
pub use drive::{Online, OnlineTrace, drive, drive_online};
pub use redesign::{CommandSource, DesignSection, RedesignEvent, Redesigner};
pub use specs::{BoxSpec, OlsSpec, PhysicsSpec, SimulatorSpec, VwPdSpec, WheelPdSpec};

/// Where a spec's relative paths are resolved.
pub struct RunContext<'a> {
    /// The configuration file's directory.
    pub base: &'a Path,
    /// The run's duration \[s\] (`duration_s`, default 150 s), for backends that plan ahead.
    pub duration_s: f64,
}

/// A built-in robot backend's config table (`[robot] type = "…"`).
#[typetag::deserialize(tag = "type")]
pub trait RobotSpec: Debug {
    /// Connects to (or starts) the robot.
    ///
    /// # Errors
    /// The backend's, naming the port or file.
    fn connect(&self, cx: &RunContext<'_>) -> Result<Box<dyn Robot>>;
}

/// A built-in model's config table (`[model] type = "…"`).
#[typetag::deserialize(tag = "type")]
pub trait ModelSpec: Debug {
    /// The model.
    fn build(&self) -> Box<dyn RegressorModel>;
}

/// A solver and the bounds on θ it keeps (if any).
pub type SolverWithBounds = (Box<dyn Solver>, Option<Vec<(f64, f64)>>);

/// A built-in solver's config table (`[solver] type = "…"`).
#[typetag::deserialize(tag = "type")]
pub trait SolverSpec: Debug {
    /// The solver, and the bounds on θ it keeps (if any).
    ///
    /// # Errors
    /// Inconsistent bounds.
    fn build(&self) -> Result<SolverWithBounds>;
}

pub use crate::registry::{MODEL_TYPES, ROBOT_TYPES, SOLVER_TYPES};

/// `[identify]`: the estimator and the conditioning.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct IdentifySection {
    /// `oe` (default), `iv`, `ls` or a plugin's estimator.
    pub estimator: Option<toml::Spanned<String>>,
    /// Low-pass cut-off \[Hz\] (default: chosen from the data).
    pub cutoff_hz: Option<f64>,
    /// Butterworth order of one pass.
    pub order: Option<usize>,
}

/// `[output]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OutputSection {
    /// Directory for recording.csv, model.toml, report.txt and report.json (relative to the
    /// config file).
    pub dir: PathBuf,
}

/// The file as read: the three pluggable tables are kept as spanned TOML until their `type`
/// says who reads them.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RunFile {
    #[serde(default)]
    plugins: Vec<PathBuf>,
    duration_s: Option<f64>,
    robot: toml::Spanned<toml::Table>,
    excitation: Option<ExcitationConfig>,
    #[serde(default = "default_model")]
    model: toml::Spanned<toml::Table>,
    #[serde(default = "default_solver")]
    solver: toml::Spanned<toml::Table>,
    #[serde(default)]
    identify: IdentifySection,
    /// `[online]`: θ̂ estimated while driving ([`crate::online`]).
    online: Option<OnlineSettings>,
    #[serde(default)]
    stop_when: StopWhen,
    /// With `stop_when = "accuracy"`: the relative half-width of the 95 % intervals to reach.
    accuracy: Option<f64>,
    /// With `stop_when = "accuracy"`: whose intervals (the online estimator's, or the batch
    /// identification's of the recording so far).
    #[serde(default)]
    accuracy_of: AccuracyOf,
    /// With `accuracy_of = "batch"`: drive time between the checks \[s\] (default
    /// [`BATCH_EVERY_S`]).
    accuracy_every_s: Option<f64>,
    /// `[design]`: the excitation designed and re-designed on the way ([`DesignSection`]).
    design: Option<DesignSection>,
    output: OutputSection,
}

/// When a run stops driving (`stop_when` in a run config).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StopWhen {
    /// After `duration_s` (a replayed log: at its end).
    #[default]
    Duration,
    /// Once the online estimator is settled ([`OnlineTheta::settled`]) and the 95 % intervals
    /// of θ1, θ2, θ4, θ6 are within `accuracy` of θ̂ ([`OnlineTheta::relative_half_width`]),
    /// or with `accuracy_of = "batch"` once the batch identification's are ([`BatchStop`]);
    /// at most `duration_s` (default 300 s). Turns the online estimator on.
    Accuracy,
}

/// Whose intervals `stop_when = "accuracy"` watches (`accuracy_of` in a run config).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AccuracyOf {
    /// The online estimator's ([`OnlineTheta::relative_half_width`]), at every sample.
    #[default]
    Online,
    /// The batch identification's of the recording so far, the run's own (model, solver,
    /// estimator, conditioning), every `accuracy_every_s` ([`BATCH_EVERY_S`]) of drive time on
    /// another thread ([`BatchStop`]); needs a model extending eq. 2.19.
    Batch,
}

/// Drive time between the batch checks of `accuracy_of = "batch"` by default \[s\]
/// (`accuracy_every_s`).
pub const BATCH_EVERY_S: f64 = 10.0;
/// Drive time from a batch check's start to its answer being taken \[s\], at most (half the
/// checks' period where that is shorter; the drive waits for the answer there if it is not
/// done).
pub const BATCH_LAG_S: f64 = 2.0;

fn typed(name: &str) -> toml::Spanned<toml::Table> {
    let mut t = toml::Table::new();
    t.insert("type".into(), toml::Value::String(name.into()));
    toml::Spanned::new(0..0, t)
}
fn default_model() -> toml::Spanned<toml::Table> {
    typed("vw-pd")
}
fn default_solver() -> toml::Spanned<toml::Table> {
    typed("ols")
}

/// What a run produced.
pub struct RunOutput {
    /// The recording driven out of the robot.
    pub recording: Recording,
    /// The identification.
    pub identification: Identification,
    /// θ̂ as the online estimator followed it while driving, when asked for.
    pub online: Option<OnlineTrace>,
    /// The files written.
    pub files: Vec<PathBuf>,
}

/// How a run is asked for beyond its file.
#[derive(Debug, Clone, Copy, Default)]
pub struct RunOptions {
    /// Estimate θ̂ online while driving ([`crate::online`]), with the file's `[online]`
    /// settings or the defaults.
    pub online: bool,
}

/// One pluggable table: its `type`, its text, and where it sits in the file.
struct Table<'a> {
    section: &'static str,
    table: &'a toml::Spanned<toml::Table>,
    file: &'a Path,
    text: &'a str,
}

impl Table<'_> {
    fn kind(&self) -> Result<String> {
        match self.table.get_ref().get("type") {
            Some(toml::Value::String(s)) => Ok(s.clone()),
            Some(_) => Err(self.error("`type` must be a string")),
            None => Err(self.error("missing `type`")),
        }
    }
    /// 1-based line of the table header, or of `key` inside the table (or its sub-tables)
    /// when found there.
    fn line(&self, key: Option<&str>) -> usize {
        let start = self.table.span().start.min(self.text.len());
        let mut at = start;
        if let Some(k) = key {
            let own = format!("[{}.", self.section);
            let mut offset = 0;
            for (i, line) in self.text[start..].split_inclusive('\n').enumerate() {
                let head = line.trim_start();
                // The next top-level table ends this one.
                if i > 0 && head.starts_with('[') && !head.starts_with(&own) {
                    break;
                }
                if head.starts_with(k) && head[k.len()..].trim_start().starts_with('=') {
                    at = start + offset;
                    break;
                }
                offset += line.len();
            }
        }
        self.text[..at].matches('\n').count() + 1
    }
    fn error(&self, message: &str) -> anyhow::Error {
        // serde names an unknown or invalid key in backquotes: point at its line.
        let key = message.split('`').nth(1).filter(|k| {
            self.table.get_ref().contains_key(*k) || message.starts_with("unknown field")
        });
        anyhow!(
            "{}: line {}: [{}]: {message}",
            self.file.display(),
            self.line(key),
            self.section
        )
    }
    fn toml_text(&self) -> String {
        toml::to_string(self.table.get_ref()).unwrap_or_default()
    }
    fn built_in<T: ?Sized>(&self) -> Result<Box<T>>
    where
        Box<T>: for<'de> Deserialize<'de>,
    {
        let value = toml::Value::Table(self.table.get_ref().clone());
        Box::<T>::deserialize(value).map_err(|e| self.error(e.message()))
    }
    fn unknown(&self, kind: &str, built: &[&str], plugins: &[String]) -> anyhow::Error {
        let known: Vec<&str> = built
            .iter()
            .copied()
            .chain(plugins.iter().map(String::as_str))
            .collect();
        self.error(&format!(
            "unknown {} type `{kind}`; known: {}",
            self.section,
            known.join(", ")
        ))
    }
}

/// Where a `plugins` entry points: a bare library name (no directory, no extension, e.g.
/// `"wheelid_turtlebot_plugin"`) is the platform's library file of that name
/// (`libNAME.so`, `libNAME.dylib`, `NAME.dll`) beside the running `wheelid` executable — where
/// `cargo build [--release] -p …` puts a workspace plugin, whichever profile both were built
/// in; anything else is a path relative to the config file's directory `base`.
pub fn plugin_path(base: &Path, entry: &Path) -> PathBuf {
    let bare = entry.components().count() == 1 && entry.extension().is_none();
    let beside_exe = std::env::current_exe()
        .ok()
        .and_then(|exe| exe.parent().map(Path::to_path_buf));
    match (bare, beside_exe) {
        (true, Some(dir)) => dir.join(format!(
            "{}{}{}",
            std::env::consts::DLL_PREFIX,
            entry.display(),
            std::env::consts::DLL_SUFFIX
        )),
        _ => base.join(entry),
    }
}

/// Parses a run config's `text` (as read from `path`, which names it in errors) without
/// loading plugins or driving anything: what `wheelid run` checks first (unknown keys, types,
/// sections), with the line and column of the first error.
///
/// # Errors
/// TOML and schema errors naming `path`, line and column.
pub fn parse_config(text: &str, path: &Path) -> Result<()> {
    toml::from_str::<RunFile>(text)
        .map(drop)
        .map_err(|e| anyhow!("{}: {}", path.display(), toml_msg(text, &e)))
}

/// Runs the job described by the config file at `path`, reporting the drive's progress to
/// `observer` ([`drive`]).
///
/// # Errors
/// Config errors (file, line, section), plugin errors, robot errors, identification errors,
/// output errors. The drive's recording is written as soon as the robot stops (an
/// identification that fails never loses it); the model and the reports only after the
/// identification succeeded; each file atomically.
pub fn run(path: &Path, observer: &dyn Observer) -> Result<RunOutput> {
    run_with(path, observer, RunOptions::default())
}

/// [`run`] with `options`: with `online` (or an `[online]` table in the file) θ̂ is also
/// estimated while driving ([`crate::online`]) and written to `online.csv` and plotted in
/// `online.png` (against the batch θ) beside the other outputs; the observer's message then carries the current θ̂.
///
/// # Errors
/// As [`run`]; invalid `[online]` settings.
pub fn run_with(path: &Path, observer: &dyn Observer, options: RunOptions) -> Result<RunOutput> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let file: RunFile = toml::from_str(&text)
        .map_err(|e| anyhow!("{}: {}", path.display(), toml_msg(&text, &e)))?;
    let base = path.parent().unwrap_or(Path::new(""));
    let cx = RunContext {
        base,
        duration_s: file.duration_s.unwrap_or(150.0),
    };
    // Plugins first: they may provide any of the four.
    let registry = Registry::load(base, &file.plugins)?;
    let plugins = registry.plugins();
    let [plugin_robots, ..] = plugins.names();
    let table = |section, table| Table {
        section,
        table,
        file: path,
        text: &text,
    };
    let (model, (solver, bounds)) = model_and_solver(
        &table("model", &file.model),
        &table("solver", &file.solver),
        &registry,
    )?;
    let estimator = estimator_named(file.identify.estimator.as_ref(), &registry, path, &text)?;
    let robot_t = table("robot", &file.robot);
    let kind = robot_t.kind()?;
    let mut robot = connect_table(&robot_t, plugins, &plugin_robots, &cx)?;
    let model: std::sync::Arc<dyn RegressorModel> = model.into();
    let solver: std::sync::Arc<dyn Solver> = solver.into();
    let estimators = std::sync::Arc::new(registry.estimators()?);
    let settings = identify_settings(&file.identify, bounds, estimator);
    let identify = identify_fn(&model, &solver, &estimators, &settings);
    let duration = run_duration(&file, &kind, path)?;
    let stamping = (robot.period_s(), robot.timing());
    let mut online = online_estimator(&file, options, stamping, path, &identify)?;
    if online.as_ref().is_some_and(|on| on.batch.is_some())
        && !wheelid_core::extends_eq_2_19(model.params())
    {
        bail!(
            "{}: accuracy_of = \"batch\" watches θ1, θ2, θ4, θ6: the model {} does not extend \
             eq. 2.19",
            path.display(),
            model.name()
        );
    }
    let mut commands = commands_of(&file, &model, robot.period_s(), path)?;
    let recording = drive_online(
        robot.as_mut(),
        commands.as_mut(),
        duration,
        observer,
        online.as_mut(),
    )
    .with_context(|| format!("driving the {} robot", robot.name()))?;
    let mut online = online.map(|on| on.trace);
    if let (Some(trace), Some(r)) = (online.as_mut(), commands.redesigner()) {
        trace.redesigns = std::mem::take(&mut r.events);
    }
    // The drive is written before it is identified: a robot's run is never lost to an
    // identification that fails.
    let dir = base.join(&file.output.dir);
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let files = vec![
        dir.join("recording.csv"),
        dir.join("model.toml"),
        dir.join("report.txt"),
        dir.join("report.json"),
    ];
    recording.write_csv(&files[0])?;
    let identification = identify_with(
        std::slice::from_ref(&recording),
        model.as_ref(),
        solver.as_ref(),
        &estimators,
        &settings,
    )
    .with_context(|| format!("identifying (the drive is kept in {})", files[0].display()))?;
    write_outputs(&files, &recording, &identification)?;
    let mut files = files;
    if let Some(trace) = &online {
        files.push(dir.join("online.csv"));
        trace.write_csv(&files[4])?;
        let png = crate::plot::write_online_plot(trace, &identification.theta, &dir)?;
        files.push(png);
    }
    Ok(RunOutput {
        recording,
        identification,
        online,
        files,
    })
}

/// The identification settings of a run: its `[identify]` section's conditioning, the
/// solver's `bounds` and the `estimator` named (default: output error).
fn identify_settings(
    section: &IdentifySection,
    bounds: Option<Vec<(f64, f64)>>,
    estimator: Option<String>,
) -> IdentifySettings {
    IdentifySettings {
        bounds,
        estimator: estimator.unwrap_or_else(|| IdentifySettings::default().estimator),
        condition: ConditionSettings {
            cutoff_hz: section.cutoff_hz,
            order: section.order.unwrap_or(ConditionSettings::default().order),
            ..ConditionSettings::default()
        },
        ..IdentifySettings::default()
    }
}

/// The run's identification as a function of a recording (for the batch checks on the way,
/// [`BatchStop`]): `model`, `solver`, `estimators` and `settings` shared with it.
fn identify_fn(
    model: &std::sync::Arc<dyn RegressorModel>,
    solver: &std::sync::Arc<dyn Solver>,
    estimators: &std::sync::Arc<Vec<Box<dyn wheelid_core::Estimator>>>,
    settings: &IdentifySettings,
) -> Identify {
    let (model, solver) = (std::sync::Arc::clone(model), std::sync::Arc::clone(solver));
    let (estimators, settings) = (std::sync::Arc::clone(estimators), settings.clone());
    std::sync::Arc::new(move |rec: &Recording| {
        let id = identify_with(
            std::slice::from_ref(rec),
            model.as_ref(),
            solver.as_ref(),
            &estimators,
            &settings,
        )?;
        Ok(id)
    })
}

/// What a run sends: its `[excitation]` (default: the thesis's Pioneer signal), or with
/// `[design]` a [`Redesigner`] starting from the design for its prior (else from the
/// `[excitation]`) and aiming at `accuracy`, for a robot sampled every `period_s`.
///
/// # Errors
/// A bad excitation; `[design]` without `stop_when = "accuracy"`, or its own errors
/// ([`Redesigner::new`]); naming the file.
fn commands_of(
    file: &RunFile,
    model: &std::sync::Arc<dyn RegressorModel>,
    period_s: f64,
    path: &Path,
) -> Result<Commands> {
    let excitation = file.excitation.as_ref().map(|e| e.build()).transpose()?;
    let Some(section) = &file.design else {
        let e = match excitation {
            Some(e) => e,
            None => ExcitationConfig::ThesisPioneer.build()?,
        };
        return Ok(Commands::Fixed(Box::new(e)));
    };
    let (StopWhen::Accuracy, Some(accuracy)) = (file.stop_when, file.accuracy) else {
        bail!(
            "{}: [design] re-designs toward an accuracy: it needs stop_when = \"accuracy\"",
            path.display()
        );
    };
    let r = Redesigner::new(
        section.clone(),
        accuracy,
        period_s,
        std::sync::Arc::clone(model),
        excitation,
    )
    .with_context(|| format!("{}: [design]", path.display()))?;
    Ok(Commands::Redesigned(Box::new(r)))
}

/// The commands of a run ([`commands_of`]).
enum Commands {
    Fixed(Box<wheelid_robots::Excitation>),
    Redesigned(Box<Redesigner>),
}

impl Commands {
    fn as_mut(&mut self) -> &mut dyn CommandSource {
        match self {
            Commands::Fixed(e) => e.as_mut(),
            Commands::Redesigned(r) => r.as_mut(),
        }
    }
    fn redesigner(&mut self) -> Option<&mut Redesigner> {
        match self {
            Commands::Fixed(_) => None,
            Commands::Redesigned(r) => Some(r),
        }
    }
}

/// How long a run drives: `duration_s`; else a replayed log to its end, a live robot 150 s,
/// or at most 300 s with `stop_when = "accuracy"`.
///
/// # Errors
/// A duration that is not positive, naming the file.
fn run_duration(file: &RunFile, kind: &str, path: &Path) -> Result<Option<f64>> {
    let duration = match (file.duration_s, kind, file.stop_when) {
        (Some(d), _, _) => Some(d),
        (None, "replay", _) => None,
        (None, _, StopWhen::Accuracy) => Some(300.0),
        (None, _, StopWhen::Duration) => Some(150.0),
    };
    if let Some(d) = duration
        && !(d.is_finite() && d > 0.0)
    {
        bail!("{}: duration_s = {d} must be > 0", path.display());
    }
    Ok(duration)
}

/// The online estimator a run asks for (its file's `[online]` table, or the defaults with
/// `options.online` or `stop_when = "accuracy"`) for a robot sampled every `period_s` under
/// the stamping `timing` (which fixes the split where `[online]` does not: [`crate::online::Split`]), with
/// an empty trace (carrying the accuracy target), and with `accuracy_of = "batch"` the batch
/// check running `identify`; `None` when not asked for.
///
/// # Errors
/// Invalid `[online]` settings; `stop_when = "accuracy"` without an `accuracy` in (0, 1), or
/// an `accuracy` or `accuracy_of = "batch"` without it; naming the file.
fn online_estimator(
    file: &RunFile,
    options: RunOptions,
    (period_s, timing): (f64, Option<wheelid_core::Timing>),
    path: &Path,
    identify: &Identify,
) -> Result<Option<Online>> {
    let accuracy = match (file.stop_when, file.accuracy) {
        (StopWhen::Accuracy, Some(a)) if a > 0.0 && a < 1.0 => Some(a),
        (StopWhen::Accuracy, a) => bail!(
            "{}: stop_when = \"accuracy\" needs accuracy in (0, 1) (e.g. 0.01), has {a:?}",
            path.display()
        ),
        (StopWhen::Duration, Some(_)) => bail!(
            "{}: accuracy is read only with stop_when = \"accuracy\"",
            path.display()
        ),
        (StopWhen::Duration, None) if file.accuracy_of == AccuracyOf::Batch => bail!(
            "{}: accuracy_of is read only with stop_when = \"accuracy\"",
            path.display()
        ),
        (StopWhen::Duration, None) => None,
    };
    let settings = match (file.online, options.online || accuracy.is_some()) {
        (Some(o), _) => o,
        (None, true) => OnlineSettings::default(),
        (None, false) => return Ok(None),
    };
    let est = OnlineTheta::new(settings.for_timing(timing), period_s)
        .with_context(|| format!("{}: [online]", path.display()))?;
    let trace = OnlineTrace {
        accuracy: accuracy.map(|a| (a, None)),
        form: Some(est.form()),
        ..OnlineTrace::default()
    };
    let batch = match (accuracy, file.accuracy_of, file.accuracy_every_s) {
        (Some(a), AccuracyOf::Batch, every) => {
            let every = every.unwrap_or(BATCH_EVERY_S);
            let lag = BATCH_LAG_S.min(0.5 * every);
            let stop = BatchStop::new(a, every, lag, std::sync::Arc::clone(identify));
            Some(stop.with_context(|| format!("{}: accuracy_every_s", path.display()))?)
        }
        (_, AccuracyOf::Online, Some(_)) => bail!(
            "{}: accuracy_every_s is read only with accuracy_of = \"batch\"",
            path.display()
        ),
        _ => None,
    };
    Ok(Some(Online {
        estimator: est,
        trace,
        batch,
    }))
}

/// The model and the solver (with its bounds) the config's `[model]` and `[solver]` tables
/// name, built-in or a plugin's.
///
/// # Errors
/// An unknown type or bad settings, with the file, line and column; bounds that do not match
/// the model's parameters.
fn model_and_solver(
    model_t: &Table<'_>,
    solver_t: &Table<'_>,
    registry: &Registry,
) -> Result<(Box<dyn RegressorModel>, SolverWithBounds)> {
    let plugins = registry.plugins();
    let [_, plugin_models, plugin_solvers, _] = plugins.names();
    let kind = model_t.kind()?;
    let model: Box<dyn RegressorModel> = if MODEL_TYPES.contains(&kind.as_str()) {
        model_t.built_in::<dyn ModelSpec>()?.build()
    } else if let Some(e) = plugins.model(&kind) {
        e.make(&model_t.toml_text())
            .map_err(|m| model_t.error(&m))?
    } else {
        return Err(model_t.unknown(&kind, &MODEL_TYPES, &plugin_models));
    };
    let kind = solver_t.kind()?;
    let (solver, bounds): (Box<dyn Solver>, _) = if SOLVER_TYPES.contains(&kind.as_str()) {
        solver_t
            .built_in::<dyn SolverSpec>()?
            .build()
            .map_err(|e| solver_t.error(&e.to_string()))?
    } else if let Some(e) = plugins.solver(&kind) {
        (
            e.make(&solver_t.toml_text())
                .map_err(|m| solver_t.error(&m))?,
            None,
        )
    } else {
        return Err(solver_t.unknown(&kind, &SOLVER_TYPES, &plugin_solvers));
    };
    if let Some(b) = &bounds
        && b.len() != model.params().len()
    {
        return Err(solver_t.error(&format!(
            "{} bounds for the {} parameters of model `{}`",
            b.len(),
            model.params().len(),
            model.name()
        )));
    }
    Ok((model, (solver, bounds)))
}

/// Writes the model file and the text and JSON reports of `identification` into `files[1..4]`
/// (the drive is `files[0]`, written before), each atomically.
///
/// # Errors
/// The file that could not be written.
fn write_outputs(files: &[PathBuf], recording: &Recording, id: &Identification) -> Result<()> {
    ModelFile::from_identification(id)
        .on_robot_of(std::slice::from_ref(recording), None)
        .write(&files[1])?;
    let write = |p: &Path, s: String| {
        wheelid_core::recording::write_atomic(p, s.as_bytes())
            .with_context(|| format!("writing {}", p.display()))
    };
    write(&files[2], crate::report::to_text(id, None))?;
    write(
        &files[3],
        serde_json::to_string_pretty(&crate::report::to_json(id, None))?,
    )
}

/// The `[identify] estimator` of the config `text` (read from `path`), checked against the
/// registry before anything is driven.
///
/// # Errors
/// An unknown name, with the file, line and column of its value and the known names.
fn estimator_named(
    name: Option<&toml::Spanned<String>>,
    registry: &Registry,
    path: &Path,
    text: &str,
) -> Result<Option<String>> {
    let Some(name) = name else { return Ok(None) };
    registry.check_estimator(name.get_ref()).map_err(|e| {
        let before = &text[..name.span().start.min(text.len())];
        let line = before.matches('\n').count() + 1;
        let column = before.chars().rev().take_while(|&c| c != '\n').count() + 1;
        anyhow!(
            "{}: line {line}, column {column}: [identify] estimator: {e}",
            path.display()
        )
    })?;
    Ok(Some(name.get_ref().clone()))
}

/// The robot of a `[robot]` table: a built-in backend or a plugin's.
fn connect_table(
    robot_t: &Table<'_>,
    plugins: &Plugins,
    plugin_robots: &[String],
    cx: &RunContext<'_>,
) -> Result<Box<dyn Robot>> {
    let kind = robot_t.kind()?;
    if ROBOT_TYPES.contains(&kind.as_str()) {
        robot_t
            .built_in::<dyn RobotSpec>()?
            .connect(cx)
            .map_err(|e| robot_t.error(&format!("{e:#}")))
    } else if let Some(e) = plugins.robot(&kind) {
        e.make(&robot_t.toml_text()).map_err(|m| robot_t.error(&m))
    } else {
        Err(robot_t.unknown(&kind, &ROBOT_TYPES, plugin_robots))
    }
}

/// A config file's `[robot]` table and its `plugins`; other sections are ignored (a `wheelid
/// run` config serves).
#[derive(Deserialize)]
struct RobotOnly {
    #[serde(default)]
    plugins: Vec<PathBuf>,
    robot: toml::Spanned<toml::Table>,
}

/// Connects (or starts) the robot of the config file at `path` — its `[robot]` table, a
/// built-in backend (`simulator`, `physics`, `replay`, `pioneer`, `khepera`, with
/// `port = "loopback"` for the protocol servers) or a plugin's — as `wheelid run` does, for a
/// run of `duration_s` seconds. Used by `wheelid migrate --robot`.
///
/// # Errors
/// The file's TOML errors (file, line, column), unknown types, plugin and backend errors.
pub fn connect_robot(path: &Path, duration_s: f64) -> Result<Box<dyn Robot>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let file: RobotOnly = toml::from_str(&text)
        .map_err(|e| anyhow!("{}: {}", path.display(), toml_msg(&text, &e)))?;
    let base = path.parent().unwrap_or(Path::new(""));
    let cx = RunContext { base, duration_s };
    let registry = Registry::load(base, &file.plugins)?;
    let plugins = registry.plugins();
    let [plugin_robots, _, _, _] = plugins.names();
    let robot_t = Table {
        section: "robot",
        table: &file.robot,
        file: path,
        text: &text,
    };
    connect_table(&robot_t, plugins, &plugin_robots, &cx)
}
