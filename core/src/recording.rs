//! Recordings: one drive of a differential-drive robot, in the CSV format of
//! `shared/data/RECORDING_FORMAT.md` (version 1).
//!
//! ```text
//! # robot: pioneer3dx
//! # command_hold: zoh
//! t,v_ref,w_ref,v,w,x,y,phi
//! 0.000,0.4000,0.7500,0.0000,0.0000,0.0000,0.0000,0.0000
//! ```
//!
//! * `#` lines before the header are metadata, `key: value`.
//! * Required columns (SI units): `t` \[s\] strictly increasing, `v_ref` [m/s], `w_ref` [rad/s],
//!   `v` [m/s], `w` [rad/s]. Optional: `x`, `y` \[m\], `phi` \[rad\], `wl`, `wr` [rad/s].
//!   Column order is free; other columns are ignored.
//!
//! Two metadata keys that wheelid writes and reads say how the samples relate to continuous
//! time (both optional):
//! * `command_hold: zoh` (default) — each command sample was held until the next one
//!   (zero-order hold), as every digital robot interface does; `command_hold: sampled` — the
//!   command column holds instantaneous samples of a continuous signal.
//! * `velocity_sampling: instant` (default) — `v`, `w` are instantaneous values at `t`;
//!   `velocity_sampling: window_average` — they are averages over the preceding sample period
//!   (encoder ticks counted over one cycle, as Pioneer and most base controllers report).
//! * `timing: instant | window_end | window_middle` — the host's stamping convention (a), (b)
//!   or (c) of the format ([`Timing`]): what `t` names, what the velocities average, and when the
//!   row's command acts. It implies `velocity_sampling`. Without it, identification estimates
//!   the command-to-response offset itself.

use std::io::Write;
use std::path::{Path, PathBuf};

use crate::error::{Error, Location, Result};

mod csv_read;
mod meta;
pub use csv_read::Columns;
pub use meta::{DRIVE_START, POSE_SOURCE};

/// How the recorded commands were applied between samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CommandHold {
    /// Each command was held constant until the next sample (zero-order hold).
    #[default]
    Zoh,
    /// Samples of a continuous command signal.
    Sampled,
}

/// What a measured velocity sample stands for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum VelocitySampling {
    /// The instantaneous velocity at `t`.
    #[default]
    Instant,
    /// The average velocity over the sample period that ends at `t`.
    WindowAverage,
}

/// How a host stamped a recording's rows: which instant `t` names, what the velocities
/// average, and when the row's command took effect (`shared/data/RECORDING_FORMAT.md`,
/// "Timing"; metadata key `timing`).
///
/// With Δ the sample period, and a sample window [s_k, s_{k+1}] of the host's cycle:
///
/// | value | `t_k` | `v_k`, `ω_k` | command of row k acts from |
/// | --- | --- | --- | --- |
/// | `instant` (a) | the sample instant | instantaneous at `t_k` | `t_k` |
/// | `window_end` (b) | the window's end s_{k+1} | mean over [t_k − Δ, t_k] | `t_k` |
/// | `window_middle` (c) | the window's middle | mean over [t_k − Δ/2, t_k + Δ/2] | `t_k − Δ/2` (window start) |
///
/// Under (c) the commands seem to act half a sample *before* their stamps; read as (a) or (b),
/// a fit absorbs that lead into θ1, θ2 (tens of % at robot sample rates).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Timing {
    /// (a) velocity at `t`, command from `t` on.
    Instant,
    /// (b) velocity averaged over the window ending at `t`, command from `t` on.
    WindowEnd,
    /// (c) `t` at the window's middle, velocity averaged over the window, command sent at the
    /// window's start.
    WindowMiddle,
}

impl Timing {
    /// Every convention, in the order (a), (b), (c).
    pub const ALL: [Timing; 3] = [Timing::Instant, Timing::WindowEnd, Timing::WindowMiddle];

    /// The metadata value: `instant`, `window_end` or `window_middle`.
    pub fn name(self) -> &'static str {
        match self {
            Timing::Instant => "instant",
            Timing::WindowEnd => "window_end",
            Timing::WindowMiddle => "window_middle",
        }
    }

    /// The convention named `s` (a metadata value), if any.
    pub fn parse(s: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|t| t.name() == s.trim())
    }

    /// What the velocity samples stand for under this convention.
    pub fn velocity_sampling(self) -> VelocitySampling {
        match self {
            Timing::Instant => VelocitySampling::Instant,
            Timing::WindowEnd | Timing::WindowMiddle => VelocitySampling::WindowAverage,
        }
    }
}

/// One drive: commands and measured velocities on a common time base.
///
/// All columns have the same length `n`. Units are SI: seconds, m/s, rad/s, m, rad.
#[derive(Debug, Clone, PartialEq)]
pub struct Recording {
    /// Where the recording came from (a file path, or a name for generated data).
    pub source: PathBuf,
    /// Metadata `key: value` pairs, in file order.
    pub meta: Vec<(String, String)>,
    /// Time \[s\], strictly increasing.
    pub t: Vec<f64>,
    /// Commanded forward velocity [m/s].
    pub v_ref: Vec<f64>,
    /// Commanded angular velocity [rad/s].
    pub w_ref: Vec<f64>,
    /// Measured forward velocity [m/s].
    pub v: Vec<f64>,
    /// Measured angular velocity [rad/s].
    pub w: Vec<f64>,
    /// Optional odometry pose x \[m\].
    pub x: Option<Vec<f64>>,
    /// Optional odometry pose y \[m\].
    pub y: Option<Vec<f64>>,
    /// Optional heading \[rad\].
    pub phi: Option<Vec<f64>>,
    /// Optional left wheel angular velocity [rad/s].
    pub wl: Option<Vec<f64>>,
    /// Optional right wheel angular velocity [rad/s].
    pub wr: Option<Vec<f64>>,
}

const REQUIRED: [&str; 5] = ["t", "v_ref", "w_ref", "v", "w"];
const OPTIONAL: [&str; 5] = ["x", "y", "phi", "wl", "wr"];

/// How the sampling of a recording looks.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SamplingInfo {
    /// Median sample period \[s\].
    pub dt_median: f64,
    /// Smallest sample period \[s\].
    pub dt_min: f64,
    /// Largest sample period \[s\].
    pub dt_max: f64,
    /// Whether the sampling counts as uniform: every period within 1e-6 relative of the median.
    pub uniform: bool,
}

impl Recording {
    /// Builds a recording from the five required columns.
    ///
    /// # Errors
    /// [`Error::LengthMismatch`] if the columns differ in length; [`Error::BadValue`] for a
    /// non-finite value; [`Error::TimeNotIncreasing`] if `t` is not strictly increasing.
    pub fn new(
        source: impl Into<PathBuf>,
        t: Vec<f64>,
        v_ref: Vec<f64>,
        w_ref: Vec<f64>,
        v: Vec<f64>,
        w: Vec<f64>,
    ) -> Result<Self> {
        let rec = Self {
            source: source.into(),
            meta: Vec::new(),
            t,
            v_ref,
            w_ref,
            v,
            w,
            x: None,
            y: None,
            phi: None,
            wl: None,
            wr: None,
        };
        rec.check()?;
        Ok(rec)
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.t.len()
    }

    /// True when the recording has no samples.
    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }

    /// The first `n` samples (all of them when `n ≥ len`), with the same source and metadata:
    /// the head of a long drive, e.g. for a quick fit to start a long one from.
    pub fn head(&self, n: usize) -> Self {
        self.window(0..n)
    }

    /// The samples `range` (clipped to the recording), with the same source and metadata and
    /// their own times: an excerpt of a long drive, e.g. the windows a diagnosis searches on.
    /// A window that starts after the first sample records the drive's start
    /// ([`Recording::drive_start`]) in its metadata, so that a drift keeps its origin.
    pub fn window(&self, range: std::ops::Range<usize>) -> Self {
        let end = range.end.min(self.len());
        let start = range.start.min(end);
        let cut = |c: &[f64]| c[start..end].to_vec();
        let cut_opt = |c: &Option<Vec<f64>>| c.as_deref().map(cut);
        let mut meta = self.meta.clone();
        if start > 0 && self.meta(DRIVE_START).is_none() {
            meta.push((DRIVE_START.to_owned(), format!("{}", self.drive_start())));
        }
        Self {
            source: self.source.clone(),
            meta,
            t: cut(&self.t),
            v_ref: cut(&self.v_ref),
            w_ref: cut(&self.w_ref),
            v: cut(&self.v),
            w: cut(&self.w),
            x: cut_opt(&self.x),
            y: cut_opt(&self.y),
            phi: cut_opt(&self.phi),
            wl: cut_opt(&self.wl),
            wr: cut_opt(&self.wr),
        }
    }

    /// Duration t\[n−1\] − t\[0\] \[s\] (0 for fewer than two samples).
    pub fn duration(&self) -> f64 {
        match (self.t.first(), self.t.last()) {
            (Some(a), Some(b)) => b - a,
            _ => 0.0,
        }
    }

    /// Sample-period statistics. Needs at least two samples (returns zeros otherwise).
    pub fn sampling(&self) -> SamplingInfo {
        let mut dts: Vec<f64> = self.t.windows(2).map(|w| w[1] - w[0]).collect();
        if dts.is_empty() {
            return SamplingInfo {
                dt_median: 0.0,
                dt_min: 0.0,
                dt_max: 0.0,
                uniform: true,
            };
        }
        let dt_min = dts.iter().copied().fold(f64::INFINITY, f64::min);
        let dt_max = dts.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let mid = dts.len() / 2;
        let dt_median = *dts.select_nth_unstable_by(mid, f64::total_cmp).1;
        let tol = 1e-6 * dt_median;
        SamplingInfo {
            dt_median,
            dt_min,
            dt_max,
            uniform: (dt_max - dt_median) <= tol && (dt_median - dt_min) <= tol,
        }
    }

    /// Resamples onto the uniform grid t0, t0 + dt, … ≤ t_last.
    ///
    /// Commands are resampled by zero-order hold (the last command sent at or before each grid
    /// time), because that is how a robot applies them; measured velocities, pose and wheel
    /// speeds by linear interpolation. Metadata is kept, plus `resampled_from: <median dt>`.
    ///
    /// # Errors
    /// [`Error::InvalidSetting`] if `dt` is not positive and finite, or the recording has
    /// fewer than two samples.
    pub fn resample_uniform(&self, dt: f64) -> Result<Self> {
        if !(dt.is_finite() && dt > 0.0) {
            return Err(Error::InvalidSetting(format!(
                "resampling period must be positive, got {dt}"
            )));
        }
        if self.len() < 2 {
            return Err(Error::InvalidSetting(
                "cannot resample fewer than two samples".into(),
            ));
        }
        let t0 = self.t[0];
        let span = self.duration();
        // Round so that a grid point that lands on t_last within rounding is kept.
        let n = (span / dt + 1e-9).floor() as usize + 1;
        let grid: Vec<f64> = (0..n).map(|k| t0 + k as f64 * dt).collect();
        let idx = bracket(&self.t, &grid);
        let hold = |col: &[f64]| idx.iter().map(|&(i, _)| col[i]).collect::<Vec<_>>();
        let lin = |col: &[f64]| {
            idx.iter()
                .map(|&(i, a)| {
                    if a == 0.0 {
                        col[i]
                    } else {
                        col[i] + a * (col[i + 1] - col[i])
                    }
                })
                .collect::<Vec<_>>()
        };
        let mut out = Self {
            source: self.source.clone(),
            meta: self.meta.clone(),
            t: grid,
            v_ref: hold(&self.v_ref),
            w_ref: hold(&self.w_ref),
            v: lin(&self.v),
            w: lin(&self.w),
            x: self.x.as_deref().map(lin),
            y: self.y.as_deref().map(lin),
            phi: self.phi.as_deref().map(lin),
            wl: self.wl.as_deref().map(lin),
            wr: self.wr.as_deref().map(lin),
        };
        out.set_meta("resampled_from", format!("{}", self.sampling().dt_median));
        Ok(out)
    }

    /// Checks lengths, finiteness and strictly increasing time.
    fn check(&self) -> Result<()> {
        let n = self.t.len();
        let cols: [(&str, Option<&Vec<f64>>); 10] = [
            ("v_ref", Some(&self.v_ref)),
            ("w_ref", Some(&self.w_ref)),
            ("v", Some(&self.v)),
            ("w", Some(&self.w)),
            ("x", self.x.as_ref()),
            ("y", self.y.as_ref()),
            ("phi", self.phi.as_ref()),
            ("wl", self.wl.as_ref()),
            ("wr", self.wr.as_ref()),
            ("t", Some(&self.t)),
        ];
        for (name, col) in cols {
            let Some(col) = col else { continue };
            if col.len() != n {
                return Err(Error::LengthMismatch {
                    column: name.into(),
                    len: col.len(),
                    expected: n,
                });
            }
            if let Some(i) = col.iter().position(|x| !x.is_finite()) {
                return Err(Error::BadValue {
                    at: Location {
                        file: self.source.clone(),
                        line: i as u64 + 1,
                        column: Some((0, name.into())),
                    },
                    message: format!("value {} is not finite (sample {i})", col[i]),
                });
            }
        }
        if let Some(i) = self.t.windows(2).position(|w| w[1] <= w[0]) {
            return Err(Error::TimeNotIncreasing {
                at: Location {
                    file: self.source.clone(),
                    line: i as u64 + 2,
                    column: Some((0, "t".into())),
                },
                t: self.t[i + 1],
                previous: self.t[i],
            });
        }
        Ok(())
    }

    /// Reads a recording CSV file, every column of the format it has. Streaming (the file is
    /// never held whole in memory); a file of more than a few MB is parsed in parts, one per
    /// core, split at line ends.
    ///
    /// # Errors
    /// [`Error::Io`] if the file cannot be read; otherwise as [`Recording::from_csv_str`] (the
    /// same error, file, line and column whether or not the file was parsed in parts).
    pub fn read_csv(path: impl AsRef<Path>) -> Result<Self> {
        Self::read_csv_columns(path, Columns::All)
    }

    /// [`Recording::read_csv`] keeping only `columns` ([`Columns::Required`]: the five an
    /// identification needs, the others skipped unparsed — less time and memory on long files).
    ///
    /// # Errors
    /// As [`Recording::read_csv`].
    pub fn read_csv_columns(path: impl AsRef<Path>, columns: Columns) -> Result<Self> {
        csv_read::read_file(path.as_ref(), columns)
    }

    /// [`Recording::read_csv_columns`] with the rows split into `parts` parts whatever the
    /// file's size (1: the sequential reader): for tests and fuzzing of the split reader, whose
    /// answer must be the sequential one, error included.
    ///
    /// # Errors
    /// As [`Recording::read_csv`].
    #[doc(hidden)]
    pub fn read_csv_in_parts(
        path: impl AsRef<Path>,
        columns: Columns,
        parts: usize,
    ) -> Result<Self> {
        csv_read::read_file_in(path.as_ref(), columns, parts, 0)
    }

    /// Parses recording CSV text; `source` names it in errors. A UTF-8 byte-order mark, CRLF
    /// line ends, blank lines and `#` comment lines among the rows are accepted (spreadsheet
    /// exports, hand-annotated logs); line numbers in errors count every line of the file.
    ///
    /// # Errors
    /// [`Error::MissingColumn`], [`Error::Malformed`] (ragged rows, text that is not UTF-8),
    /// [`Error::BadValue`] (not a number, NaN, ±Inf), [`Error::TimeNotIncreasing`], each
    /// naming the file, line and column; [`Error::TooShort`] if there is no data row.
    pub fn from_csv_str(text: &str, source: impl Into<PathBuf>) -> Result<Self> {
        csv_read::parse(
            text.as_bytes(),
            source.into(),
            &csv_read::Lines::Text(text.as_bytes()),
            Columns::All,
        )
    }

    /// Renders the recording as CSV text (metadata lines, header, rows with full precision).
    pub fn to_csv_string(&self) -> String {
        let mut out = String::new();
        for (k, v) in &self.meta {
            out.push_str(&format!("# {k}: {v}\n"));
        }
        let mut cols: Vec<(&str, &[f64])> = vec![
            ("t", &self.t),
            ("v_ref", &self.v_ref),
            ("w_ref", &self.w_ref),
            ("v", &self.v),
            ("w", &self.w),
        ];
        for (name, col) in OPTIONAL
            .iter()
            .zip([&self.x, &self.y, &self.phi, &self.wl, &self.wr])
        {
            if let Some(c) = col {
                cols.push((name, c));
            }
        }
        let header: Vec<&str> = cols.iter().map(|(n, _)| *n).collect();
        out.push_str(&header.join(","));
        out.push('\n');
        for i in 0..self.len() {
            let row: Vec<String> = cols.iter().map(|(_, c)| format!("{}", c[i])).collect();
            out.push_str(&row.join(","));
            out.push('\n');
        }
        out
    }

    /// Writes the recording as CSV, atomically: to a temporary file beside `path`, then renamed,
    /// so that a failure never leaves a half-written file.
    ///
    /// # Errors
    /// [`Error::Io`] naming `path`.
    pub fn write_csv(&self, path: impl AsRef<Path>) -> Result<()> {
        write_atomic(path.as_ref(), self.to_csv_string().as_bytes())
    }
}

/// Writes `bytes` to `path` atomically: to a uniquely named temporary file in the same
/// directory (`tempfile`), synced, then renamed over `path`; on failure the temporary file is
/// removed and `path` is left as it was. Safe for concurrent writers of the same `path`, in
/// one process or several: each renames a complete file, the last one wins. (The temporary
/// name was once the process id alone; two threads caching one recording renamed the same
/// file and the second failed with "No such file or directory", hold-out seed 1052.)
///
/// # Errors
/// [`Error::Io`] naming `path`.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let io = |source| Error::Io {
        path: path.to_owned(),
        source,
    };
    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let mut tmp = tempfile::NamedTempFile::new_in(dir).map_err(io)?;
    tmp.write_all(bytes).map_err(io)?;
    tmp.as_file().sync_all().map_err(io)?;
    tmp.persist(path).map_err(|e| io(e.error))?;
    Ok(())
}

/// For each grid time, the index i with t[i] ≤ g < t[i+1] and the fraction a ∈ [0, 1).
fn bracket(t: &[f64], grid: &[f64]) -> Vec<(usize, f64)> {
    let mut i = 0;
    grid.iter()
        .map(|&g| {
            while i + 1 < t.len() && t[i + 1] <= g {
                i += 1;
            }
            if i + 1 >= t.len() {
                (t.len() - 1, 0.0)
            } else {
                (i, ((g - t[i]) / (t[i + 1] - t[i])).clamp(0.0, 1.0))
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = "# robot: test\n# command_hold: zoh\nt,v_ref,w_ref,v,w,extra\n0,1,2,3,4,x\n0.1,1,2,3,4,y\n0.2,1,2,3,4,z\n";

    #[test]
    fn reads_metadata_columns_and_ignores_extras() {
        let r = Recording::from_csv_str(GOOD, "g.csv").expect("parses");
        assert_eq!(r.len(), 3);
        assert_eq!(r.meta("robot"), Some("test"));
        assert_eq!(r.command_hold(), CommandHold::Zoh);
        assert_eq!(r.v, vec![3.0; 3]);
        assert!(r.x.is_none());
    }

    /// A window keeps its samples' times and the drive's start (set once, by the first cut
    /// that leaves the first sample out; the head keeps the metadata as it was), and a window
    /// of a window keeps the first cut's start.
    #[test]
    fn a_window_keeps_its_times_and_the_drives_start() {
        let t: Vec<f64> = (0..10).map(|k| 5.0 + 0.5 * f64::from(k)).collect();
        let r = Recording::new(
            "d",
            t.clone(),
            vec![0.0; 10],
            vec![0.0; 10],
            vec![1.0; 10],
            vec![2.0; 10],
        )
        .expect("valid");
        assert_eq!(r.drive_start(), 5.0);
        let head = r.head(4);
        assert_eq!(head.meta(DRIVE_START), None);
        assert_eq!(head.t, t[..4]);
        let w = r.window(3..7);
        assert_eq!(w.t, t[3..7]);
        assert_eq!(w.v, vec![1.0; 4]);
        assert_eq!(w.drive_start(), 5.0);
        let ww = w.window(1..3);
        assert_eq!(ww.t, t[4..6]);
        assert_eq!(ww.drive_start(), 5.0);
        assert_eq!(r.window(8..20).len(), 2);
        assert!(r.window(12..20).is_empty());
    }

    #[test]
    fn round_trips_through_csv() {
        let mut r = Recording::new(
            "m",
            vec![0.0, 0.1, 0.25],
            vec![0.1, 0.2, 0.3],
            vec![-1.0, 0.0, 1.0],
            vec![0.123456789012345, 0.0, 1e-17],
            vec![1.0, 2.0, 3.0],
        )
        .expect("valid");
        r.phi = Some(vec![0.0, 0.5, 1.0]);
        r.set_meta("robot", "pioneer3dx");
        let back = Recording::from_csv_str(&r.to_csv_string(), "m").expect("parses");
        assert_eq!(back, r);
    }

    #[test]
    fn missing_column_names_file_line_and_column() {
        let e = Recording::from_csv_str("# a: b\nt,v_ref,v,w\n0,1,2,3\n", "f.csv")
            .expect_err("must fail");
        let s = e.to_string();
        assert!(
            s.starts_with("f.csv:2: missing required column `w_ref`"),
            "{s}"
        );
    }

    #[test]
    fn nan_and_text_cells_name_line_and_column() {
        let text = "# m: 1\nt,v_ref,w_ref,v,w\n0,1,2,3,4\n0.1,1,NaN,3,4\n";
        let s = Recording::from_csv_str(text, "f.csv")
            .expect_err("must fail")
            .to_string();
        assert!(s.starts_with("f.csv:4:3 (column `w_ref`)"), "{s}");
        let text = "t,v_ref,w_ref,v,w\n0,1,2,3,4\n0.1,1,2,abc,4\n";
        let s = Recording::from_csv_str(text, "f.csv")
            .expect_err("must fail")
            .to_string();
        assert!(s.starts_with("f.csv:3:4 (column `v`)"), "{s}");
        let text = "t,v_ref,w_ref,v,w\n0,1,2,3,inf\n";
        let s = Recording::from_csv_str(text, "f.csv")
            .expect_err("must fail")
            .to_string();
        assert!(s.starts_with("f.csv:2:5 (column `w`)"), "{s}");
    }

    #[test]
    fn bom_crlf_and_comment_lines_are_read_and_lines_still_counted() {
        let text = "\u{feff}# robot: test\r\nt,v_ref,w_ref,v,w\r\n0,1,2,3,4\r\n# note\r\n\r\n0.1,1,2,3,4\r\n0.2,1,2,3,4\r\n";
        let r = Recording::from_csv_str(text, "b.csv").expect("parses");
        assert_eq!(r.len(), 3);
        assert_eq!(r.meta("robot"), Some("test"));
        assert_eq!(r.t, [0.0, 0.1, 0.2]);
        // The bad cell is on line 6 of the file (metadata, header, row, comment, blank, row).
        let bad = text.replace("0.1,1,2,3,4", "0.1,1,x,3,4");
        let e = Recording::from_csv_str(&bad, "b.csv")
            .expect_err("bad cell")
            .to_string();
        assert!(e.contains("b.csv:6") && e.contains("w_ref"), "{e}");
    }

    /// A recording file of more than `PARALLEL_MIN_BYTES`, parsed in parts: with a BOM, CRLF,
    /// comment and blank lines and pose columns; `edit` changes row `k`'s text.
    fn big_file(dir: &Path, edit: impl Fn(usize, String) -> String) -> (PathBuf, String) {
        let mut text = String::from("\u{feff}# robot: big\r\nt,v_ref,w_ref,v,w,x,y,phi\r\n");
        for k in 0..120_000 {
            if k % 9_999 == 0 {
                text.push_str("# a note\r\n\r\n");
            }
            let t = k as f64 * 0.02;
            let row = format!(
                "{t:.2},{:.6},{:.6},{:.9},{:.9},{:.4},{:.4},{:.4}\r\n",
                (t * 0.7).sin(),
                (t * 0.3).cos(),
                (t * 0.7).sin() * 0.9,
                (t * 0.3).cos() * 0.8,
                t,
                -t,
                0.5 * t
            );
            text.push_str(&edit(k, row));
        }
        let path = dir.join("big.csv");
        std::fs::write(&path, &text).expect("writes");
        (path, text)
    }

    #[test]
    fn a_big_file_read_in_parts_equals_the_sequential_parse_even_in_its_errors() {
        let dir = tempfile::tempdir().expect("tmp");
        let (path, text) = big_file(dir.path(), |_, row| row);
        assert!(text.len() as u64 > csv_read::PARALLEL_MIN_BYTES);
        let whole = Recording::from_csv_str(&text, &path).expect("parses");
        let split = || csv_read::SPLIT_READS.load(std::sync::atomic::Ordering::Relaxed);
        let before = split();
        let parts = Recording::read_csv(&path).expect("reads");
        assert!(split() > before, "the file was not read in parts");
        assert_eq!(parts.len(), 120_000);
        assert_eq!(parts.meta, whole.meta);
        for (a, b) in [
            (&parts.t, &whole.t),
            (&parts.v_ref, &whole.v_ref),
            (&parts.w_ref, &whole.w_ref),
            (&parts.v, &whole.v),
            (&parts.w, &whole.w),
        ] {
            assert!(a == b);
        }
        assert_eq!(parts.phi, whole.phi);
        assert!(parts.x.is_some() && parts.wl.is_none());
        let required = Recording::read_csv_columns(&path, Columns::Required).expect("reads");
        assert!(required.x.is_none() && required.phi.is_none());
        assert_eq!(required.w, whole.w);
        // Errors anywhere (past the split, near it, a quote left open across it) are the sequential
        // parse's, file, line and column.
        type Edit = fn(String) -> String;
        let cases: [(usize, Edit); 4] = [
            (100_000, |r| r.replacen(",", ",x", 2)),
            (60_000, |r| r.replacen("1200.00", "1199.98", 1)),
            (59_990, |r| format!("\"{r}")),
            (119_999, |r| r.replacen(",", ",,", 1)),
        ];
        for (at, edit) in cases {
            let (path, text) = big_file(dir.path(), |k, row| if k == at { edit(row) } else { row });
            let seq = Recording::from_csv_str(&text, &path).map(|r| r.len());
            let par = Recording::read_csv(&path).map(|r| r.len());
            assert_eq!(
                par.as_ref().map_err(ToString::to_string),
                seq.as_ref().map_err(ToString::to_string),
                "row {at}"
            );
            assert!(seq.is_err(), "row {at}: the edit must break the file");
        }
    }

    #[test]
    fn a_quoted_line_end_in_an_ignored_column_reads_as_one_row_in_parts_too() {
        // Read sequentially, the quoted `note` holds a line end, so the second line is part of
        // the first row; a split reader that took lines for rows would see three rows.
        let text =
            "t,v_ref,w_ref,v,w,note\n0,1,1,1,1,\"x\n1,1,1,1,1,y\"\n2,1,1,1,1,z\n3,1,1,1,1,z\n";
        let dir = tempfile::tempdir().expect("tmp");
        let path = dir.path().join("q.csv");
        std::fs::write(&path, text).expect("writes");
        let whole = Recording::read_csv_in_parts(&path, Columns::All, 1).expect("reads");
        assert_eq!(whole.t, [0.0, 2.0, 3.0]);
        for parts in 2..=4 {
            let split = Recording::read_csv_in_parts(&path, Columns::All, parts).expect("reads");
            assert_eq!(split, whole, "{parts} parts");
        }
    }

    #[test]
    fn generated_inputs_with_every_irregularity_read_the_same_in_parts() {
        // A differential test of the split reader's line splitter against the csv crate: 3,000
        // files of rows built from cells and separators with what the fast path must either
        // read exactly as the csv crate does or hand back — CRLF, lone CR, blank and comment
        // lines (at the start of a line and not), quotes, a BOM mid-file, blanks around
        // numbers, inf/NaN, words, empty cells, a missing last line end (after a comment too: the csv crate
        // reads that as a record, which a fuzzer found) — each read whole
        // and in 2, 3 and 5 parts: the same recording or the same error.
        let mut state = 0x9E37_79B9_7F4A_7C15u64;
        let mut next = |n: usize| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state % n as u64) as usize
        };
        let cells = [
            "0.5", "-1.25e-3", " 2", "3 ", "inf", "NaN", "x", "", "+4.", "\"\"", "7",
        ];
        let ends = [
            "\n",
            "\r\n",
            "\r",
            "\n\n",
            "\r\r\n",
            "\n# note\n",
            "\n# a\rb\n",
            "\n#\r\n",
            "\n #x\n",
            "\n\u{feff}",
            "\n\t\n",
        ];
        let dir = tempfile::tempdir().expect("tmp");
        let path = dir.path().join("g.csv");
        let (mut agree_ok, before) = (
            0,
            csv_read::SPLIT_READS.load(std::sync::atomic::Ordering::Relaxed),
        );
        for case in 0..3000 {
            let mut text = String::from("t,v_ref,w_ref,v,w,x\n");
            let rows = 2 + next(40);
            for k in 0..rows {
                // Mostly regular rows, so that the split path has whole files to read; an
                // irregular row is irregular in one way: its cells, its length or its end.
                let kind = if next(8) == 0 { 1 + next(3) } else { 0 };
                text.push_str(&format!("{}", k as f64 * 0.1));
                let more = if kind == 2 { 1 + next(7) } else { 5 };
                for _ in 0..more {
                    text.push(',');
                    text.push_str(if kind == 1 {
                        cells[next(cells.len())]
                    } else {
                        "1.5"
                    });
                }
                let last = k + 1 == rows && next(4) == 0;
                if !last {
                    text.push_str(if kind == 3 {
                        ends[next(ends.len())]
                    } else {
                        "\n"
                    });
                } else if next(2) == 0 {
                    // A last line with no line end after a comment or a blank.
                    text.push_str(["\n# end", "\n#", "\n# x\r", "\n\r", "\n "][next(5)]);
                }
            }
            std::fs::write(&path, &text).expect("writes");
            let whole = Recording::read_csv_in_parts(&path, Columns::All, 1);
            // With the required columns only, the last (`x`) is skipped unparsed, whole or
            // in parts.
            let required = Recording::read_csv_in_parts(&path, Columns::Required, 1);
            for parts in [2, 3, 5] {
                for (columns, whole) in [(Columns::All, &whole), (Columns::Required, &required)] {
                    let split = Recording::read_csv_in_parts(&path, columns, parts);
                    assert_eq!(
                        split.as_ref().map_err(ToString::to_string),
                        whole.as_ref().map_err(ToString::to_string),
                        "case {case} in {parts} parts, {columns:?}: {text:?}"
                    );
                }
            }
            agree_ok += usize::from(whole.is_ok());
        }
        // Both answers were exercised, and the fast path read files itself.
        assert!((500..2900).contains(&agree_ok), "{agree_ok} of 3,000 read");
        assert!(csv_read::SPLIT_READS.load(std::sync::atomic::Ordering::Relaxed) - before > 500);
    }

    #[test]
    fn every_csv_input_a_fuzzer_found_reads_the_same_in_parts() {
        // fuzz/regressions/csv/: inputs on which the split reader disagreed with the sequential
        // one (the first: carriage returns and a tab after the header, which the csv parser
        // reads as more records and the split reader had trimmed away).
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../fuzz/regressions/csv");
        let mut n = 0;
        for case in std::fs::read_dir(&dir).expect("fuzz/regressions/csv") {
            let path = case.expect("case").path();
            let whole = Recording::read_csv_in_parts(&path, Columns::All, 1);
            for parts in 2..=4 {
                let split = Recording::read_csv_in_parts(&path, Columns::All, parts);
                assert_eq!(
                    split.as_ref().map_err(ToString::to_string),
                    whole.as_ref().map_err(ToString::to_string),
                    "{} in {parts} parts",
                    path.display()
                );
            }
            n += 1;
        }
        assert!(n >= 2, "{n} inputs");
    }

    #[test]
    fn time_must_increase() {
        let text = "t,v_ref,w_ref,v,w\n0,1,2,3,4\n0.1,1,2,3,4\n0.1,1,2,3,4\n";
        let s = Recording::from_csv_str(text, "f.csv")
            .expect_err("must fail")
            .to_string();
        assert!(s.starts_with("f.csv:4:1 (column `t`)"), "{s}");
    }

    #[test]
    fn ragged_row_is_malformed_with_line() {
        let text = "t,v_ref,w_ref,v,w\n0,1,2,3,4\n0.1,1,2\n";
        let e = Recording::from_csv_str(text, "f.csv").expect_err("must fail");
        assert!(
            matches!(e, Error::Malformed { ref at, .. } if at.line == 3),
            "{e}"
        );
    }

    #[test]
    fn timing_metadata_round_trips_and_implies_velocity_sampling() {
        let text = "# timing: window_middle\nt,v_ref,w_ref,v,w\n0,0,0,0,0\n0.1,1,0,0.5,0\n";
        let r = Recording::from_csv_str(text, "x.csv").expect("parses");
        assert_eq!(r.timing(), Some(Timing::WindowMiddle));
        assert_eq!(r.velocity_sampling(), VelocitySampling::WindowAverage);
        assert!(r.states_velocity_sampling());
        let mut plain =
            Recording::from_csv_str("t,v_ref,w_ref,v,w\n0,0,0,0,0\n0.1,1,0,0.5,0\n", "y")
                .expect("parses");
        assert_eq!(plain.timing(), None);
        assert!(!plain.states_velocity_sampling());
        plain.set_timing(Timing::Instant);
        let back = Recording::from_csv_str(&plain.to_csv_string(), "y").expect("parses");
        assert_eq!(back.timing(), Some(Timing::Instant));
        assert_eq!(back.meta("velocity_sampling"), Some("instant"));
        assert_eq!(Timing::parse("window_end"), Some(Timing::WindowEnd));
        assert_eq!(Timing::parse("middle"), None);
    }

    #[test]
    fn resampling_holds_commands_and_interpolates_measurements() {
        let r = Recording::new(
            "j",
            vec![0.0, 0.09, 0.21, 0.3],
            vec![1.0, 2.0, 3.0, 4.0],
            vec![0.0; 4],
            vec![0.0, 0.9, 2.1, 3.0],
            vec![0.0; 4],
        )
        .expect("valid");
        assert!(!r.sampling().uniform);
        let u = r.resample_uniform(0.1).expect("resamples");
        assert_eq!(u.len(), 4);
        // t = 0.1 and 0.2: the last command sent (at 0.09) is 2; v = 10 t interpolates exactly.
        assert_eq!(u.v_ref, vec![1.0, 2.0, 2.0, 4.0]);
        for (v, t) in u.v.iter().zip(&u.t) {
            approx::assert_abs_diff_eq!(*v, 10.0 * t, epsilon = 1e-12);
        }
        assert!(u.sampling().uniform);
    }

    #[test]
    fn atomic_write_leaves_no_partial_file_on_failure() {
        let dir = tempfile::tempdir().expect("tmp");
        let missing = dir.path().join("no_such_dir").join("r.csv");
        let r = Recording::from_csv_str(GOOD, "g").expect("parses");
        assert!(matches!(r.write_csv(&missing), Err(Error::Io { .. })));
        let ok = dir.path().join("r.csv");
        r.write_csv(&ok).expect("writes");
        assert_eq!(std::fs::read_dir(dir.path()).expect("ls").count(), 1);
    }

    /// Eight threads writing one path at once (as a batch caching a shared clean twin does)
    /// all succeed, leave one complete file and no temporary ones: with a temporary name per
    /// process, all but the first rename failed with "No such file or directory".
    #[test]
    fn concurrent_atomic_writes_of_one_path_all_succeed() {
        let dir = tempfile::tempdir().expect("tmp");
        let path = dir.path().join("r.csv");
        let texts: Vec<String> = (0..8).map(|k| format!("{k}\n").repeat(20_000)).collect();
        std::thread::scope(|s| {
            let handles: Vec<_> = texts
                .iter()
                .map(|t| s.spawn(|| write_atomic(&path, t.as_bytes())))
                .collect();
            for h in handles {
                h.join().expect("joins").expect("writes");
            }
        });
        let written = std::fs::read_to_string(&path).expect("reads");
        assert!(texts.contains(&written), "a complete text of one writer");
        assert_eq!(std::fs::read_dir(dir.path()).expect("ls").count(), 1);
    }
}
