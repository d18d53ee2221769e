//! TOML configurations of `wheelid simulate` and `wheelid track`.
//!
//! Both name a robot (`robot = "khepera3"`, one of
//! [`RobotProfile::NAMES`](wheelid_robots::RobotProfile::NAMES)) or give a whole `[profile]`
//! table, and a `[simulation]` table ([`SimSettings`]: `duration_s`, `seed`, `substeps`,
//! `measurement_noise` and `[simulation.effects.*]`). A simulation adds an `[excitation]`; a
//! tracking run a `[track]` table ([`TrackSettings`]) and optionally `model = "FILE"`, an
//! identified model whose θ seeds θ̂(0). Unknown keys are errors naming the line and column.
//!
//! ```toml
//! robot = "khepera3"
//! model = "khepera.toml"          # θ̂(0) from `wheelid identify --out khepera.toml`
//!
//! [track]
//! duration_s = 120.0
//! trajectory = { type = "figure_eight", ax = 0.25, ay = 0.5, f = 0.2 }
//!
//! [track.adaptation]
//! gamma = [1.0, 1.0, 1.0, 0.0, 1.0, 0.0]
//! start_s = 3.0
//!
//! [track.simulation.effects.payload_change]
//! time_s = 60.0
//! theta_after = [0.0456, 0.1136, -0.0002, 1.003, 0.1464, 0.9981]
//! ```

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use serde::{Deserialize, Serialize};
use wheelid_robots::{Excitation, RobotProfile, SimSettings, TrackSettings};

use crate::files::toml_msg;

/// The excitation of a simulation, by `type`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
pub enum ExcitationConfig {
    /// The thesis's Pioneer excitation (§4.4.2).
    ThesisPioneer,
    /// The thesis's Khepera excitation (§4.4.1).
    ThesisKhepera,
    /// The thesis's simulated regression excitation (§4.2).
    ThesisRegression,
    /// Random-phase multisines on interleaved lines
    /// ([`Excitation::random_multisine`]).
    RandomMultisine {
        /// Phase seed.
        seed: u64,
        /// v_ref offset [m/s].
        v_offset: f64,
        /// v_ref peak deviation [m/s].
        v_amp: f64,
        /// ω_ref peak [rad/s].
        w_amp: f64,
        /// Highest line \[Hz\].
        f_max_hz: f64,
    },
    /// Any pair of signals ([`wheelid_robots::Signal`]).
    Signals(Box<Excitation>),
}

impl ExcitationConfig {
    /// The preset for a robot: the thesis's Khepera excitation for a Khepera, the Pioneer's
    /// otherwise.
    pub fn for_robot(profile: &RobotProfile) -> Self {
        if profile.name.starts_with("khepera") {
            Self::ThesisKhepera
        } else {
            Self::ThesisPioneer
        }
    }

    /// The excitation.
    ///
    /// # Errors
    /// Invalid multisine settings or signals.
    pub fn build(&self) -> Result<Excitation> {
        let e = match self {
            Self::ThesisPioneer => Excitation::thesis_pioneer(),
            Self::ThesisKhepera => Excitation::thesis_khepera(),
            Self::ThesisRegression => Excitation::thesis_regression(),
            Self::RandomMultisine {
                seed,
                v_offset,
                v_amp,
                w_amp,
                f_max_hz,
            } => Excitation::random_multisine(*seed, *v_offset, *v_amp, *w_amp, *f_max_hz)?,
            Self::Signals(e) => {
                e.v_ref.validate()?;
                e.w_ref.validate()?;
                (**e).clone()
            }
        };
        Ok(e)
    }
}

/// `wheelid simulate --config FILE`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimulateConfig {
    /// Built-in robot name (default `pioneer3dx`).
    pub robot: Option<String>,
    /// A whole robot profile instead of a built-in one.
    pub profile: Option<RobotProfile>,
    /// Excitation (default: the thesis's preset for the robot).
    pub excitation: Option<ExcitationConfig>,
    /// Duration, seed, sub-steps, encoder model, effects.
    #[serde(default)]
    pub simulation: SimSettings,
    /// The physics backend's settings (`--backend physics`): duration, seed, stamping
    /// convention, jitter, encoders, noise, effects.
    #[serde(default)]
    pub physics: wheelid_robots::physics::PhysicsSettings,
}

/// `wheelid track --config FILE`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrackConfig {
    /// Built-in robot name (default `pioneer3dx`).
    pub robot: Option<String>,
    /// A whole robot profile instead of a built-in one.
    pub profile: Option<RobotProfile>,
    /// An identified model file whose θ is θ̂(0) (overrides `track.theta_hat0`); relative to
    /// the configuration file.
    pub model: Option<PathBuf>,
    /// The tracking run. Without a `trajectory`, the figure eight preset for the robot.
    #[serde(default)]
    pub track: TrackSettings,
    /// The physics backend's settings (`wheelid track --backend physics`): seed, stamping
    /// convention, jitter, encoders, effects (its duration is the run's).
    #[serde(default)]
    pub physics: wheelid_robots::physics::PhysicsSettings,
}

/// Reads and parses a TOML file into `T`, with errors naming the file, line and column.
///
/// # Errors
/// I/O and TOML errors.
pub fn read_toml<T: for<'de> Deserialize<'de>>(path: &Path) -> Result<T> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    toml::from_str(&text)
        .map_err(|e| anyhow::anyhow!("{}: {}", path.display(), toml_msg(&text, &e)))
}

/// The configuration at `path` and the directory its relative paths are resolved against, or
/// the defaults and the current directory when no path is given.
///
/// # Errors
/// As [`read_toml`].
pub fn read_toml_or_default<T: for<'de> Deserialize<'de> + Default>(
    path: Option<&Path>,
) -> Result<(T, PathBuf)> {
    match path {
        Some(p) => Ok((
            read_toml(p)?,
            p.parent().map(PathBuf::from).unwrap_or_default(),
        )),
        None => Ok((T::default(), PathBuf::new())),
    }
}

/// The robot: the built-in `flag` (a command-line choice) if given, else a whole `profile`
/// from the config, else the config's built-in `name` (default `pioneer3dx`).
///
/// # Errors
/// An unknown name, listing the known ones.
pub fn robot_profile(
    flag: Option<&str>,
    name: Option<&str>,
    profile: Option<&RobotProfile>,
) -> Result<RobotProfile> {
    if let (None, Some(p)) = (flag, profile) {
        return Ok(p.clone());
    }
    let name = flag.or(name).unwrap_or("pioneer3dx");
    match RobotProfile::by_name(name) {
        Some(p) => Ok(p),
        None => bail!(
            "unknown robot {name:?}; known robots: {}",
            RobotProfile::NAMES.join(", ")
        ),
    }
}

/// A diagnosis described in TOML (`wheelid diagnose --config FILE`); every key is optional and
/// the command-line flags override it. Files are relative to the configuration's directory.
///
/// ```toml
/// files = ["../shared/data/real/husky_drive_wetgrass/husky_wetgrass_seg1.csv"]
/// model = "vw-pd"
/// candidates = ["input_delay", "acceleration_limit", "velocity_saturation"]
/// blocks = 5          # per recording; the 2nd, 4th, … are held out for validation
/// alpha = 0.01        # family-wise level (Holm)
/// max_lag_s = 2.0     # correlation lags tested
/// min_improvement = 0.05
/// max_effects = 3
/// track_m = 0.555     # wheel track for wheel_asymmetry
/// search_samples = 3600  # the default: a longer recording is searched on an excerpt, then refitted whole
/// plot = "diagnosis"  # directory for the PNGs
/// ```
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DiagnoseConfig {
    /// Recording CSV files.
    pub files: Vec<PathBuf>,
    /// Model parameterization (`vw-pd`, `wheel-pd`).
    pub model: Option<String>,
    /// The candidate library searched (default: all).
    pub candidates: Option<Vec<wheelid_models::Candidate>>,
    /// Blocks per recording.
    pub blocks: Option<usize>,
    /// Family-wise level of the tests.
    pub alpha: Option<f64>,
    /// Largest correlation lag \[s\].
    pub max_lag_s: Option<f64>,
    /// Smallest relative drop of the validation cost that counts (30 % of it for a candidate
    /// nominated at p < 10⁻¹²; see `DiagnoseSettings::min_improvement`).
    pub min_improvement: Option<f64>,
    /// Most effects added.
    pub max_effects: Option<usize>,
    /// Wheel track \[m\].
    pub track_m: Option<f64>,
    /// Most samples per recording the search runs on (`DiagnoseSettings::search_samples`).
    pub search_samples: Option<usize>,
    /// Directory for the plots.
    pub plot: Option<PathBuf>,
}

impl DiagnoseConfig {
    /// The settings this configuration gives, over the defaults.
    pub fn settings(&self) -> crate::diagnose::DiagnoseSettings {
        let mut s = crate::diagnose::DiagnoseSettings::default();
        if let Some(c) = &self.candidates {
            s.candidates.clone_from(c);
        }
        s.blocks = self.blocks.unwrap_or(s.blocks);
        s.alpha = self.alpha.unwrap_or(s.alpha);
        s.max_lag_s = self.max_lag_s.unwrap_or(s.max_lag_s);
        s.min_improvement = self.min_improvement.unwrap_or(s.min_improvement);
        s.max_effects = self.max_effects.unwrap_or(s.max_effects);
        s.track_m = self.track_m.or(s.track_m);
        s.search_samples = self.search_samples.unwrap_or(s.search_samples);
        s
    }
}
