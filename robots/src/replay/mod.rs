//! The replay backend: a recorded drive as a robot.
//!
//! A [`Replay`] plays back a [`Recording`] — read from our CSV format
//! (`shared/data/RECORDING_FORMAT.md`) or from a ROS 2 bag in MCAP ([`read_mcap`]) — one
//! sample per [`Robot::read`], then [`RobotError::Ended`]. It cannot act on commands: `send`
//! is accepted but changes nothing (the requests are kept, see [`Replay::sent`]), and it
//! returns the command the log recorded at the sample last read — the one the robot acted on
//! from that sample to the next — so a run identifies the robot from what it was really
//! commanded. [`write_mcap`] writes a recording as a ROS 2 bag, for tests and for tools that
//! read bags.
//!
//! [`ReplaySettings`] in TOML:
//!
//! ```toml
//! path = "drive.mcap"          # or a .csv; or a rosbag2 folder holding one .mcap
//! command_topic = "/cmd_vel"   # Twist or TwistStamped, detected from the schema
//! odometry_topic = "/odom"     # nav_msgs/msg/Odometry
//! command_timeout_s = 0.5      # optional: a command older than this counts as zero
//! ```

mod bag;
pub mod ros;

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use wheelid_core::{Odometry, Pose, Recording, Robot, RobotError};

pub use bag::{BagTopics, CommandType, read_mcap, write_mcap};

/// The file format of a replayed recording.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ReplayFormat {
    /// Recording CSV, version 1 (`.csv`).
    Csv,
    /// A ROS 2 bag, one MCAP file (`.mcap`) or a rosbag2 folder holding one.
    Mcap,
}

/// Which clock times the messages of a bag.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TimeSource {
    /// When the recorder received each message (MCAP `log_time`): one clock for every topic,
    /// including `Twist` commands, which carry no stamp. Includes transport delay.
    #[default]
    LogTime,
    /// The message's `header.stamp`: when the robot took the data, on the sender's clock (sim
    /// time under `use_sim_time`). Needs `TwistStamped` commands.
    HeaderStamp,
}

impl TimeSource {
    /// The name used in settings and metadata (`log_time`, `header_stamp`).
    pub fn as_str(self) -> &'static str {
        match self {
            TimeSource::LogTime => "log_time",
            TimeSource::HeaderStamp => "header_stamp",
        }
    }
}

/// The format of a file whose extension does not tell: MCAP by its magic bytes
/// (`0x89 MCAP0 \\r\\n`, MCAP specification), CSV if its first 64 KiB are UTF-8 text.
fn sniff_format(path: &Path) -> Result<ReplayFormat, RobotError> {
    use std::io::Read;
    // Neither the extension nor (unreadable) the content tells: the setting is missing.
    let io = |e: std::io::Error| {
        RobotError::Setting(format!(
            "{}: cannot tell the format from the extension, nor from the content ({e}); set \
             format = \"csv\" or \"mcap\"",
            path.display()
        ))
    };
    let mut head = Vec::with_capacity(65536);
    std::fs::File::open(path)
        .map_err(io)?
        .take(65536)
        .read_to_end(&mut head)
        .map_err(io)?;
    if head.starts_with(b"\x89MCAP0\r\n") {
        return Ok(ReplayFormat::Mcap);
    }
    // A multi-byte character cut at the end of the window is still text.
    match std::str::from_utf8(&head) {
        Ok(_) => Ok(ReplayFormat::Csv),
        Err(e) if e.error_len().is_none() => Ok(ReplayFormat::Csv),
        Err(_) => Err(RobotError::Setting(format!(
            "{}: neither a recording CSV (it is not UTF-8 text) nor an MCAP bag (no MCAP magic \
             bytes); see RECORDING_FORMAT.md",
            path.display()
        ))),
    }
}

/// Settings of the replay backend: which recording, and for a bag, which topics.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReplaySettings {
    /// The recording: a `.csv`, a `.mcap`, or a rosbag2 folder holding one `.mcap`.
    pub path: PathBuf,
    /// The format; by default from the extension (`.csv`, `.mcap`; a folder is a bag).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub format: Option<ReplayFormat>,
    /// The command topic of a bag (default `/cmd_vel`).
    #[serde(default = "default_command_topic")]
    pub command_topic: String,
    /// The odometry topic of a bag (default `/odom`).
    #[serde(default = "default_odometry_topic")]
    pub odometry_topic: String,
    /// The clock that times a bag's messages (default `log_time`).
    #[serde(default)]
    pub time_source: TimeSource,
    /// A command older than this \[s\] counts as zero, as a ROS base controller stops on a stale
    /// `cmd_vel` (diff_drive_controller's `cmd_vel_timeout`); default none: commands hold until
    /// the next one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub command_timeout_s: Option<f64>,
    /// Skip the first `start_s` seconds of the recording (default 0).
    #[serde(default)]
    pub start_s: f64,
    /// Replay at most this many seconds from `start_s` (default: to the end).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub duration_s: Option<f64>,
}

fn default_command_topic() -> String {
    BagTopics::default().command
}

fn default_odometry_topic() -> String {
    BagTopics::default().odometry
}

impl ReplaySettings {
    /// Settings for `path` with every default.
    pub fn new(path: impl Into<PathBuf>) -> Self {
        Self {
            path: path.into(),
            format: None,
            command_topic: default_command_topic(),
            odometry_topic: default_odometry_topic(),
            time_source: TimeSource::default(),
            command_timeout_s: None,
            start_s: 0.0,
            duration_s: None,
        }
    }

    /// The format: `format` if set, else from the extension of `path` (`.csv`, `.mcap`; a
    /// folder is a rosbag2 bag), else from the content: the MCAP magic bytes make a bag, UTF-8
    /// text a CSV.
    ///
    /// # Errors
    /// [`RobotError::Setting`], naming the file, if a file of another extension cannot be read
    /// or is neither an MCAP bag nor text.
    pub fn resolved_format(&self) -> Result<ReplayFormat, RobotError> {
        if let Some(f) = self.format {
            return Ok(f);
        }
        let ext = self.path.extension().and_then(|e| e.to_str());
        match ext.map(str::to_ascii_lowercase).as_deref() {
            Some("csv") => Ok(ReplayFormat::Csv),
            Some("mcap") => Ok(ReplayFormat::Mcap),
            _ if self.path.is_dir() => Ok(ReplayFormat::Mcap),
            _ => sniff_format(&self.path),
        }
    }

    /// Reads the recording (CSV or bag) and keeps the window `start_s`, `duration_s`.
    ///
    /// Times keep their origin (a bag's first odometry message is t = 0): the window is
    /// t_0 + start_s ≤ t ≤ t_0 + start_s + duration_s.
    ///
    /// # Errors
    /// [`RobotError::Io`] if the file cannot be read; [`RobotError::Protocol`] for invalid
    /// content (naming the file, and the line or message); [`RobotError::Setting`] for a bad
    /// setting, an unknown format, a missing topic, or a window with no sample. See
    /// [`read_mcap`].
    pub fn load(&self) -> Result<Recording, RobotError> {
        let rec = match self.resolved_format()? {
            ReplayFormat::Csv => Recording::read_csv(&self.path).map_err(core_error)?,
            ReplayFormat::Mcap => {
                let topics = BagTopics {
                    command: self.command_topic.clone(),
                    odometry: self.odometry_topic.clone(),
                    command_type: CommandType::default(),
                };
                let file = bag_file(&self.path)?;
                read_mcap(&file, &topics, self.time_source, self.command_timeout_s)?
            }
        };
        self.window(rec)
    }

    /// Keeps the samples in [t_0 + start_s, t_0 + start_s + duration_s].
    fn window(&self, mut rec: Recording) -> Result<Recording, RobotError> {
        let start = self.start_s;
        if !(start.is_finite() && start >= 0.0) {
            return Err(RobotError::Setting(format!(
                "start_s = {start} must be ≥ 0"
            )));
        }
        if let Some(d) = self.duration_s
            && !(d.is_finite() && d > 0.0)
        {
            return Err(RobotError::Setting(format!("duration_s = {d} must be > 0")));
        }
        if start == 0.0 && self.duration_s.is_none() {
            return Ok(rec);
        }
        let t0 = rec.t.first().copied().unwrap_or(0.0);
        let end = self.duration_s.map_or(f64::INFINITY, |d| start + d);
        let keep: Vec<bool> = rec
            .t
            .iter()
            .map(|t| (start..=end).contains(&(t - t0)))
            .collect();
        let pick = |c: &mut Vec<f64>| {
            let mut k = keep.iter();
            c.retain(|_| k.next().copied().unwrap_or(false));
        };
        for col in [
            &mut rec.t,
            &mut rec.v_ref,
            &mut rec.w_ref,
            &mut rec.v,
            &mut rec.w,
        ] {
            pick(col);
        }
        for col in [
            &mut rec.x,
            &mut rec.y,
            &mut rec.phi,
            &mut rec.wl,
            &mut rec.wr,
        ]
        .into_iter()
        .flatten()
        {
            pick(col);
        }
        if rec.is_empty() {
            return Err(RobotError::Setting(format!(
                "{}: no sample between {start} s and {end} s after the start",
                self.path.display()
            )));
        }
        rec.set_meta("replay_window_s", format!("{start}..{end}"));
        Ok(rec)
    }
}

/// The `.mcap` file of a bag: `path` itself, or the one `.mcap` in a rosbag2 folder.
fn bag_file(path: &Path) -> Result<PathBuf, RobotError> {
    if !path.is_dir() {
        return Ok(path.to_owned());
    }
    let entries = std::fs::read_dir(path)
        .map_err(|e| RobotError::io(format!("{}: listing the bag", path.display()), e))?;
    let mut files: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "mcap"))
        .collect();
    match files.len() {
        1 => Ok(files.remove(0)),
        n => Err(RobotError::Setting(format!(
            "{}: a bag folder must hold exactly one .mcap file, found {n}",
            path.display()
        ))),
    }
}

/// A recording played back as a robot.
///
/// `read` returns sample k = 0, 1, … of the recording: t_k on the log's clock (the robot's
/// clock of [`Odometry::t`]), v_k, ω_k and the pose (x_k, y_k, φ_k; zero where the recording
/// has no pose columns); after the last sample, [`RobotError::Ended`], every time.
///
/// `send` cannot change a recording: the request is kept in [`Replay::sent`], and `send`
/// returns the **logged** command (v_ref_k, ω_ref_k) of the sample k last read, whatever was
/// requested — the command the robot acted on from t_k to t_{k+1} (held under
/// `command_hold: zoh`). Before the first `read` it returns sample 0's command, and after the
/// end the last sample's.
#[derive(Debug, Clone)]
pub struct Replay {
    rec: Recording,
    period_s: f64,
    next: usize,
    sent: Vec<(f64, f64)>,
}

impl Replay {
    /// Plays back `rec`.
    ///
    /// # Errors
    /// [`RobotError::Protocol`] if `rec` is invalid (columns of different lengths, a
    /// non-finite value, time not strictly increasing); [`RobotError::Setting`] if it has
    /// fewer than two samples (no period).
    pub fn new(rec: Recording) -> Result<Self, RobotError> {
        check_recording(&rec)?;
        if rec.len() < 2 {
            return Err(RobotError::Setting(format!(
                "{}: a replay needs at least two samples, the recording has {}",
                rec.source.display(),
                rec.len()
            )));
        }
        let period_s = rec.sampling().dt_median;
        Ok(Self {
            rec,
            period_s,
            next: 0,
            sent: Vec::new(),
        })
    }

    /// Opens the recording that `settings` name ([`ReplaySettings::load`]).
    ///
    /// # Errors
    /// As [`ReplaySettings::load`] and [`Replay::new`].
    pub fn open(settings: &ReplaySettings) -> Result<Self, RobotError> {
        Self::new(settings.load()?)
    }

    /// The whole recording, for a run that takes it at once.
    pub fn recording(&self) -> &Recording {
        &self.rec
    }

    /// The commands (v_ref [m/s], ω_ref [rad/s]) requested so far, in order, one per `send`
    /// (including `stop`'s (0, 0)); what `send` returned is the log's, not these.
    pub fn sent(&self) -> &[(f64, f64)] {
        &self.sent
    }
}

impl Robot for Replay {
    fn name(&self) -> &str {
        "replay"
    }

    /// The recording's median sample period \[s\].
    fn period_s(&self) -> f64 {
        self.period_s
    }

    /// As the log says (its `velocity_sampling` metadata; instants when it says nothing).
    fn velocity_sampling(&self) -> wheelid_core::VelocitySampling {
        self.recording().velocity_sampling()
    }

    /// As the log says (`timing` or `velocity_sampling` metadata), or `None`: a log that does
    /// not say is not claimed to be anything, and identification estimates it.
    fn timing(&self) -> Option<wheelid_core::Timing> {
        self.recording().timing()
    }

    /// Keeps the request in [`Replay::sent`] (a recording does not change) and returns the
    /// logged command (v_ref_k, ω_ref_k) of the sample k last read (sample 0 before any read).
    fn send(&mut self, v_ref: f64, w_ref: f64) -> Result<(f64, f64), RobotError> {
        self.sent.push((v_ref, w_ref));
        // `Replay::new` guarantees at least two samples, and `next` never exceeds their count.
        let k = self.next.saturating_sub(1);
        Ok((self.rec.v_ref[k], self.rec.w_ref[k]))
    }

    fn read(&mut self) -> Result<Odometry, RobotError> {
        let k = self.next;
        if k >= self.rec.len() {
            return Err(RobotError::Ended);
        }
        self.next += 1;
        let r = &self.rec;
        let at = |c: &Option<Vec<f64>>| c.as_ref().map_or(0.0, |c| c[k]);
        Ok(Odometry {
            t: r.t[k],
            v: r.v[k],
            w: r.w[k],
            pose: Pose {
                x: at(&r.x),
                y: at(&r.y),
                heading: at(&r.phi),
            },
        })
    }
}

/// Checks that every column has the length of `t`, every value is finite and `t` strictly
/// increases (what [`Recording`]'s constructors check, for a recording built field by field).
pub(crate) fn check_recording(rec: &Recording) -> Result<(), RobotError> {
    let file = rec.source.display();
    let n = rec.len();
    let columns = [
        ("t", Some(&rec.t)),
        ("v_ref", Some(&rec.v_ref)),
        ("w_ref", Some(&rec.w_ref)),
        ("v", Some(&rec.v)),
        ("w", Some(&rec.w)),
        ("x", rec.x.as_ref()),
        ("y", rec.y.as_ref()),
        ("phi", rec.phi.as_ref()),
        ("wl", rec.wl.as_ref()),
        ("wr", rec.wr.as_ref()),
    ];
    for (name, col) in columns {
        let Some(col) = col else { continue };
        if col.len() != n {
            return Err(RobotError::Protocol(format!(
                "{file}: column `{name}` has {} samples, `t` has {n}",
                col.len()
            )));
        }
        if let Some(k) = col.iter().position(|x| !x.is_finite()) {
            return Err(RobotError::Protocol(format!(
                "{file}: column `{name}`, sample {k}: {} is not finite",
                col[k]
            )));
        }
    }
    if let Some(k) = rec.t.windows(2).position(|p| p[1] <= p[0]) {
        return Err(RobotError::Protocol(format!(
            "{file}: time does not increase at sample {}: {} after {}",
            k + 1,
            rec.t[k + 1],
            rec.t[k]
        )));
    }
    Ok(())
}

/// A core error as a robot error: I/O stays I/O, bad content is a protocol error.
pub(crate) fn core_error(e: wheelid_core::Error) -> RobotError {
    match e {
        wheelid_core::Error::Io { path, source } => {
            RobotError::io(format!("{}", path.display()), source)
        }
        e => RobotError::Protocol(e.to_string()),
    }
}
