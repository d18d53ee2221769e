//! The TOML files that identification writes and reads: the identified model (`--out`) and
//! bounds on θ (`--bounds`).
//!
//! Identified model:
//! ```toml
//! model = "vw-pd"
//! theta = [0.2604, 0.2509, -0.0005, 0.9965, 0.0026, 1.0768]
//! std_err = [0.001, 0.001, 0.0001, 0.002, 0.0004, 0.003]
//! cutoff_hz = 0.64
//! [channels.v]
//! r2 = 0.999
//! fit_percent = 97.1
//! # from `wheelid diagnose --out`: the effects found, in their units
//! [effects.input_delay]
//! delay_s = 0.149
//! [effects_std_err.input_delay]
//! delay_s = 0.002
//! ```
//!
//! Bounds, either on θ directly or as intervals on the physical constants of the chosen model
//! (`wheelid_models::physical`), which are turned into exact θ bounds:
//! ```toml
//! theta_lower = [0.1, 0.1, -0.1, 0.8, -0.1, 0.8]
//! theta_upper = [0.5, 0.5,  0.1, 1.2,  0.1, 1.2]
//! # or
//! [physical.lower]
//! m = 8.0
//! # … every constant of the model
//! [physical.upper]
//! m = 9.0
//! ```

use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};
use wheelid_models::{Parameterization, VwPdMap, WheelPdMap};

use wheelid_core::{Columns, Recording};

use crate::identify::Identification;

/// Why a recording could not be read ([`read_recording`]); every case names the file.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    /// A CSV recording: unreadable, or bad content (with line and column).
    #[error(transparent)]
    Csv(#[from] wheelid_core::Error),
    /// A bag: unreadable, not MCAP, a missing topic, a message that does not decode; or a file
    /// that is neither format.
    #[error(transparent)]
    Bag(#[from] wheelid_core::RobotError),
}

/// Reads one recording for `identify` and `diagnose`: a CSV (RECORDING_FORMAT.md) or a ROS 2
/// bag (`.mcap`, or a rosbag2 folder: `/cmd_vel` and `/odom`, timed by log time, as
/// `wheelid simulate --out x.mcap` writes and [`wheelid_robots::replay::read_mcap`] reads);
/// the format from the extension, else from the content (MCAP magic bytes, else text). A CSV
/// keeps the columns of `columns` ([`Columns::Required`] for `identify`, which uses no pose or
/// wheel column; [`Columns::All`] for `diagnose`, whose `tyre_asymmetry` reads an independent
/// heading, [`wheelid_core::POSE_SOURCE`]); a bag has the required ones only.
///
/// # Errors
/// [`ReadError`], naming the file.
pub fn read_recording(path: &Path, columns: Columns) -> Result<Recording, ReadError> {
    use wheelid_robots::replay::{ReplayFormat, ReplaySettings};
    let mut settings = ReplaySettings::new(path);
    // Told once (a sniff reads the file's head), then kept for the load.
    let format = settings.resolved_format()?;
    settings.format = Some(format);
    match format {
        ReplayFormat::Csv => Ok(Recording::read_csv_columns(path, columns)?),
        ReplayFormat::Mcap => Ok(settings.load()?),
    }
}

/// Per-channel quality in the model file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChannelQuality {
    /// R² of the regression.
    pub r2: f64,
    /// Free-run fit %.
    pub fit_percent: f64,
}

/// An identified model as written by `--out` and read back by later commands.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelFile {
    /// Model name (`wheel-pd`, `vw-pd`).
    pub model: String,
    /// The robot it was identified on (the recordings' `# robot:`, or the built-in profile's
    /// name); using the model on another robot is a warning (`wheelid migrate`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub robot: Option<String>,
    /// Estimator that gave θ (`ls`, `iv`, `oe`); absent in files written before estimators.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub estimator: Option<String>,
    /// θ1…θ6.
    pub theta: Vec<f64>,
    /// Standard errors.
    pub std_err: Vec<f64>,
    /// Cut-off used \[Hz\].
    pub cutoff_hz: f64,
    /// Samples used.
    pub samples: usize,
    /// Per-channel quality.
    pub channels: BTreeMap<String, ChannelQuality>,
    /// Effects a diagnosis added (`wheelid diagnose --out`), by name, with their fitted
    /// parameters in the effect's units (`[effects.input_delay] delay_s = 0.15`; a limit's
    /// channel that never bound is absent). The names and parameters are those of
    /// `wheelid_models::effects` and of the simulator's `[simulation.effects.*]`.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub effects: BTreeMap<String, BTreeMap<String, f64>>,
    /// Standard errors of `effects`, same shape.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub effects_std_err: BTreeMap<String, BTreeMap<String, f64>>,
}

impl ModelFile {
    /// Records the robot the `recordings` came from: their `# robot:` when they all state the
    /// same one, else `fallback` (a built-in profile's name), else none.
    #[must_use]
    pub fn on_robot_of(mut self, recordings: &[Recording], fallback: Option<&str>) -> Self {
        let mut names = recordings.iter().map(|r| r.meta("robot"));
        let first = names.next().flatten();
        let same = first.is_some() && names.all(|n| n == first);
        self.robot = if same { first } else { fallback }.map(str::to_owned);
        self
    }

    /// The file content of an identification.
    pub fn from_identification(id: &Identification) -> Self {
        Self {
            model: id.model.clone(),
            robot: None,
            estimator: Some(id.estimator.clone()),
            theta: id.theta.clone(),
            std_err: id.std_err.clone(),
            cutoff_hz: id.cutoff_hz,
            samples: id.samples,
            channels: id
                .channels
                .iter()
                .map(|c| {
                    (
                        c.name.clone(),
                        ChannelQuality {
                            r2: c.r2,
                            fit_percent: c.fit_percent,
                        },
                    )
                })
                .collect(),
            effects: BTreeMap::new(),
            effects_std_err: BTreeMap::new(),
        }
    }

    /// The file content of a diagnosis of the `model` parameterization: θ1…θ6 of its final
    /// (extended) model, its validation fits (R² not computed: NaN is not written, 0), and the
    /// effects it found with their parameters. `cutoff_hz` is 0: the fit is output error on
    /// the raw samples.
    pub fn from_diagnosis(d: &crate::diagnose::Diagnosis, model: &str) -> Self {
        let table = |f: &dyn Fn(&crate::diagnose::Finding) -> &BTreeMap<String, f64>| {
            (d.findings.iter())
                .map(|x| (x.effect.clone(), f(x).clone()))
                .collect()
        };
        Self::from_stage(
            &d.final_stage,
            model,
            d.series.iter().map(|s| s.t.len()).sum(),
            table(&|f| &f.parameters),
            table(&|f| &f.std_err),
        )
    }

    /// The file content of a saved model refitted on recordings
    /// ([`crate::diagnose::refit_saved`]) of the `model` parameterization: θ1…θ6 and the
    /// effects as refitted, with their validation fits (R² 0, as [`Self::from_diagnosis`]).
    pub fn from_saved_refit(r: &crate::diagnose::SavedRefit, model: &str) -> Self {
        Self::from_stage(
            &r.refitted,
            model,
            r.samples,
            r.effects.clone(),
            r.effects_std_err.clone(),
        )
    }

    /// An output-error model file (estimator `oe`, cut-off 0) of the extended model `stage`
    /// fitted on `samples`, with its `effects` and their standard errors.
    fn from_stage(
        stage: &crate::diagnose::Stage,
        model: &str,
        samples: usize,
        effects: BTreeMap<String, BTreeMap<String, f64>>,
        effects_std_err: BTreeMap<String, BTreeMap<String, f64>>,
    ) -> Self {
        let quality = |c: &crate::diagnose::ChannelFit| ChannelQuality {
            r2: 0.0,
            fit_percent: c.fit_percent,
        };
        Self {
            model: model.to_owned(),
            robot: None,
            estimator: Some("oe".into()),
            theta: stage.theta[..6].to_vec(),
            std_err: stage.std_err[..6].to_vec(),
            cutoff_hz: 0.0,
            samples,
            channels: BTreeMap::from([
                ("v".to_owned(), quality(&stage.channels.v)),
                ("w".to_owned(), quality(&stage.channels.w)),
            ]),
            effects,
            effects_std_err,
        }
    }

    /// θ1…θ6 of the file read from `path`.
    ///
    /// # Errors
    /// A `theta` of other than six values, naming `path`.
    pub fn theta6(&self, path: &Path) -> anyhow::Result<[f64; 6]> {
        use anyhow::Context;
        self.theta.as_slice().try_into().with_context(|| {
            format!(
                "{}: theta has {} values, not 6",
                path.display(),
                self.theta.len()
            )
        })
    }

    /// Writes the file atomically.
    ///
    /// # Errors
    /// I/O or serialisation errors, naming the path.
    pub fn write(&self, path: &Path) -> anyhow::Result<()> {
        let text = toml::to_string(self)?;
        wheelid_core::recording::write_atomic(path, text.as_bytes())?;
        Ok(())
    }

    /// Reads a model file.
    ///
    /// # Errors
    /// I/O errors or TOML errors with the file, line and column.
    pub fn read(path: &Path) -> anyhow::Result<Self> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
        let m: Self = toml::from_str(&text)
            .map_err(|e| anyhow::anyhow!("{}: {}", path.display(), toml_msg(&text, &e)))?;
        if m.theta.len() != 6 {
            anyhow::bail!(
                "{}: theta must have 6 values, has {}",
                path.display(),
                m.theta.len()
            );
        }
        Ok(m)
    }
}

/// A TOML error as `line L, column C: message`.
pub fn toml_msg(text: &str, e: &toml::de::Error) -> String {
    match e.span() {
        Some(span) => {
            let before = &text[..span.start.min(text.len())];
            let line = before.matches('\n').count() + 1;
            let col = before.len() - before.rfind('\n').map_or(0, |i| i + 1) + 1;
            format!("line {line}, column {col}: {}", e.message())
        }
        None => e.message().to_owned(),
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct BoundsFile {
    theta_lower: Option<Vec<f64>>,
    theta_upper: Option<Vec<f64>>,
    physical: Option<PhysicalBounds>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct PhysicalBounds {
    lower: toml::Value,
    upper: toml::Value,
}

/// Reads a bounds file for `model` and returns (lower, upper) per θ.
///
/// # Errors
/// I/O, TOML (with line and column), wrong lengths, or physical intervals that do not fit the
/// model's constants.
pub fn read_bounds(path: &Path, model: &str) -> anyhow::Result<Vec<(f64, f64)>> {
    let text =
        std::fs::read_to_string(path).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    let f: BoundsFile = toml::from_str(&text)
        .map_err(|e| anyhow::anyhow!("{}: {}", path.display(), toml_msg(&text, &e)))?;
    let ctx = |m: String| anyhow::anyhow!("{}: {m}", path.display());
    match (f.theta_lower, f.theta_upper, f.physical) {
        (Some(lo), Some(hi), None) => {
            if lo.len() != 6 || hi.len() != 6 {
                return Err(ctx("theta_lower and theta_upper need 6 values each".into()));
            }
            Ok(lo.into_iter().zip(hi).collect())
        }
        (None, None, Some(p)) => {
            let b = match model {
                "vw-pd" => VwPdMap::theta_bounds(
                    &p.lower.try_into().map_err(|e: toml::de::Error| {
                        ctx(format!("[physical.lower]: {}", e.message()))
                    })?,
                    &p.upper.try_into().map_err(|e: toml::de::Error| {
                        ctx(format!("[physical.upper]: {}", e.message()))
                    })?,
                ),
                "wheel-pd" => WheelPdMap::theta_bounds(
                    &p.lower.try_into().map_err(|e: toml::de::Error| {
                        ctx(format!("[physical.lower]: {}", e.message()))
                    })?,
                    &p.upper.try_into().map_err(|e: toml::de::Error| {
                        ctx(format!("[physical.upper]: {}", e.message()))
                    })?,
                ),
                other => {
                    return Err(ctx(format!(
                        "model `{other}` has no physical parameterization"
                    )));
                }
            }
            .map_err(|e| ctx(e.to_string()))?;
            Ok(b.to_vec())
        }
        _ => Err(ctx(
            "give either theta_lower and theta_upper, or [physical.lower] and [physical.upper]"
                .into(),
        )),
    }
}
