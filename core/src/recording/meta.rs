//! A recording's metadata: the `# key: value` lines before the header, and what wheelid reads
//! from them — the command hold, the velocity sampling and the stamping convention ([`Timing`];
//! module docs of [`crate::recording`]), where a cut drive started ([`DRIVE_START`]) and whether
//! the pose is independent of the encoders ([`POSE_SOURCE`]).

use super::{CommandHold, Recording, Timing, VelocitySampling};

/// Metadata key of [`Recording::drive_start`] (seconds, in the recording's time base).
pub const DRIVE_START: &str = "drive_start_s";

/// Metadata key naming where the pose columns `x`, `y`, `phi` come from. The format calls them
/// odometry, which may be the wheel encoders' own integral and then tells nothing the encoders
/// do not; a source independent of the encoders — `ground_truth` (a simulator's chassis),
/// `mocap`, `icp` (lidar scan matching), `gnss`, `imu` — measures how the chassis really
/// turned, which a tyre's radius changes and a motor's effort does not
/// ([`Recording::independent_heading`]). Absent, `odometry` or `wheel_odometry`: not independent.
pub const POSE_SOURCE: &str = "pose_source";

impl Recording {
    /// The value of metadata `key`, if present (the last one wins).
    pub fn meta(&self, key: &str) -> Option<&str> {
        self.meta
            .iter()
            .rev()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }

    /// The first instant of the drive this recording was cut from \[s\]: the metadata
    /// [`DRIVE_START`] where a cut set it ([`Recording::window`]), else the first sample's time
    /// (NaN for an empty recording). A drift over the drive (a battery's sagging gain) counts
    /// from it.
    pub fn drive_start(&self) -> f64 {
        self.meta(DRIVE_START)
            .and_then(|s| s.trim().parse().ok())
            .filter(|x: &f64| x.is_finite())
            .or_else(|| self.t.first().copied())
            .unwrap_or(f64::NAN)
    }

    /// The heading column `phi` \[rad\] (one per sample) where metadata [`POSE_SOURCE`] names a
    /// source independent of the wheel encoders; `None` where there is no heading, or it may
    /// be the encoders' own integral (no [`POSE_SOURCE`], or `odometry`, `wheel_odometry`).
    pub fn independent_heading(&self) -> Option<&[f64]> {
        let source = self.meta(POSE_SOURCE)?.trim();
        let derived = source.is_empty()
            || source.eq_ignore_ascii_case("odometry")
            || source.eq_ignore_ascii_case("wheel_odometry");
        (!derived).then_some(self.phi.as_deref()).flatten()
    }

    /// Sets (or replaces) metadata `key`.
    pub fn set_meta(&mut self, key: &str, value: impl Into<String>) {
        let value = value.into();
        if let Some(slot) = self.meta.iter_mut().find(|(k, _)| k == key) {
            slot.1 = value;
        } else {
            self.meta.push((key.to_owned(), value));
        }
    }

    /// How commands were applied (metadata `command_hold`, default zero-order hold).
    pub fn command_hold(&self) -> CommandHold {
        match self.meta("command_hold") {
            Some("sampled") => CommandHold::Sampled,
            _ => CommandHold::Zoh,
        }
    }

    /// What the velocity samples stand for: as metadata `timing` says, else metadata
    /// `velocity_sampling`, default instant.
    pub fn velocity_sampling(&self) -> VelocitySampling {
        if let Some(timing) = self.meta("timing").and_then(Timing::parse) {
            return timing.velocity_sampling();
        }
        match self.meta("velocity_sampling") {
            Some("window_average") => VelocitySampling::WindowAverage,
            _ => VelocitySampling::Instant,
        }
    }

    /// The host's stamping convention, if the recording states it: metadata `timing`
    /// ([`Timing`]), else metadata `velocity_sampling` read as the convention it has always
    /// meant in this format (`instant` → (a), `window_average` → (b): commands from `t` on).
    /// `None` when neither is there (or their values are unknown): when the commands act is then
    /// left to the fit.
    pub fn timing(&self) -> Option<Timing> {
        if let Some(t) = self.meta("timing").and_then(Timing::parse) {
            return Some(t);
        }
        match self.meta("velocity_sampling").map(str::trim) {
            Some("instant") => Some(Timing::Instant),
            Some("window_average") => Some(Timing::WindowEnd),
            _ => None,
        }
    }

    /// Whether the recording says what its velocity samples stand for (metadata `timing` or
    /// `velocity_sampling`): the same as `self.timing().is_some()`.
    pub fn states_velocity_sampling(&self) -> bool {
        self.timing().is_some()
    }

    /// States the stamping convention: sets metadata `timing` and the matching
    /// `velocity_sampling` (for readers that know only that key).
    pub fn set_timing(&mut self, timing: Timing) {
        self.set_meta("timing", timing.name());
        self.set_meta(
            "velocity_sampling",
            match timing.velocity_sampling() {
                VelocitySampling::Instant => "instant",
                VelocitySampling::WindowAverage => "window_average",
            },
        );
    }
}
