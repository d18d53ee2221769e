//! The robot backend trait: what every robot — simulated, replayed from a log, or real over a
//! serial line or TCP — offers to an identification run.
//!
//! A run drives a robot one period at a time: it reads the robot's report, decides the next
//! command (v, ω) from it, and sends that command, which holds (zero-order hold) until the next
//! `send`:
//!
//! ```text
//! // read, then decide, then send: row k of a recording = (t_k, command sent after report k, v_k, ω_k, pose_k)
//! loop {
//!     let o = robot.read()?;                 // report k at t_k (answers the commands sent before it)
//!     let (v_ref, w_ref) = robot.send(v, w)?; // the command as the robot will act on it from t_k to t_{k+1}
//! }
//! robot.stop()?;                             // zero command, then release the link
//! ```
//!
//! So report k answers the commands sent before it, and the command to record in row k is the
//! one [`Robot::send`] *returns* after report k: the request (v, ω) as the robot will act on it
//! over [t_k, t_{k+1}) — after the backend's clamps and its protocol's rounding (Pioneer: whole
//! mm/s and °/s; Khepera: whole speed units per wheel), or, for a replayed log, the command the
//! log recorded whatever was requested. Units are SI throughout (m/s, rad/s, m, rad, s)
//! whatever the robot's own protocol speaks; each backend's docs name the protocol source it
//! follows and how it converts.

use std::fmt;

/// A planar pose: position of the robot's reference point and heading.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Pose {
    /// x \[m\].
    pub x: f64,
    /// y \[m\].
    pub y: f64,
    /// Heading ψ \[rad\], counter-clockwise from the x axis (unwrapped where the backend can).
    pub heading: f64,
}

/// One report of a robot: timestamped velocities and pose.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Odometry {
    /// Time of the report \[s\] on the robot's clock: the simulation's time (simulator), the
    /// log's time (replay), or, for the serial/TCP backends (Pioneer, Khepera), the reports
    /// counted × the period, t = k·Δt for the k-th report — deterministic, never the host's
    /// clock. Each backend documents its clock: `wheelid_robots::SimRobot`'s `Robot` impl,
    /// `wheelid_robots::replay::Replay`, `wheelid_robots::pioneer::Pioneer` and
    /// `wheelid_robots::khepera::Khepera`.
    pub t: f64,
    /// Forward velocity v [m/s].
    pub v: f64,
    /// Angular velocity ω [rad/s].
    pub w: f64,
    /// Pose by the robot's odometry.
    pub pose: Pose,
}

/// What can go wrong while talking to a robot.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RobotError {
    /// The link (serial port, socket, file) failed; `what` says which and while doing what.
    #[error("{what}: {source}")]
    Io {
        /// The link and the operation, e.g. `127.0.0.1:8101: reading a SIP`.
        what: String,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// The robot answered something the protocol does not allow (bad checksum, unknown reply).
    #[error("protocol error: {0}")]
    Protocol(String),
    /// No answer within the time allowed.
    #[error("timed out: {0}")]
    Timeout(String),
    /// The robot has nothing more to report (a replayed log reached its end).
    #[error("the robot has no more data (end of the log)")]
    Ended,
    /// A setting the backend cannot use (a bad period, a missing topic, …).
    #[error("{0}")]
    Setting(String),
}

impl RobotError {
    /// An [`RobotError::Io`] for `what`.
    pub fn io(what: impl fmt::Display, source: std::io::Error) -> Self {
        RobotError::Io {
            what: what.to_string(),
            source,
        }
    }
}

/// A differential-drive robot backend: send (v_ref, ω_ref), read timestamped v, ω and pose,
/// once per period.
///
/// Object safe: backends are chosen at run time from a config (`Box<dyn Robot>`).
pub trait Robot {
    /// A short name for reports (`simulator`, `replay`, `pioneer`, `khepera`, or a plugin's).
    fn name(&self) -> &str;

    /// The control period Δt \[s\]: how often the robot reports and accepts a new command.
    fn period_s(&self) -> f64;

    /// Sends the command v_ref [m/s], ω_ref [rad/s], which holds until the next `send`, and
    /// returns it **as the robot will act on it** (SI units) from the last report until the
    /// next: after the backend's clamps and its protocol's rounding, or, for a replayed log,
    /// the command the log recorded at the report last read (see the [module docs](self)).
    /// This returned command, not the request, is the one to record.
    ///
    /// # Errors
    /// [`RobotError::Io`] if the link fails; [`RobotError::Setting`] for a command the backend
    /// cannot send (e.g. not finite).
    fn send(&mut self, v_ref: f64, w_ref: f64) -> Result<(f64, f64), RobotError>;

    /// Waits for the robot's next report (about one period after the previous one) and returns it.
    ///
    /// # Errors
    /// [`RobotError::Io`], [`RobotError::Protocol`] or [`RobotError::Timeout`] on a link
    /// problem; [`RobotError::Ended`] when a replayed log has no more samples.
    fn read(&mut self) -> Result<Odometry, RobotError>;

    /// How the reported v, ω sample the motion: instants, or averages over the period that ends
    /// at the report (wheel encoder counts differenced over a period, as most base controllers
    /// report them). The default says instants.
    fn velocity_sampling(&self) -> crate::VelocitySampling {
        crate::VelocitySampling::Instant
    }

    /// How the robot's reports are stamped ([`crate::Timing`]: (a) instants, (b) window averages
    /// ending at the report, (c) stamped at the window's middle with the command sent at its
    /// start), or `None` if the backend cannot know (a log that does not say). A run writes it
    /// into the recording's metadata. The default follows [`Robot::velocity_sampling`]: (a)
    /// for instants, (b) for window averages.
    fn timing(&self) -> Option<crate::Timing> {
        Some(match self.velocity_sampling() {
            crate::VelocitySampling::Instant => crate::Timing::Instant,
            crate::VelocitySampling::WindowAverage => crate::Timing::WindowEnd,
        })
    }

    /// The true pose of the robot's reference point now (the state after the last `read`), where
    /// the backend knows it — a simulation's ground truth, never its odometry — or `None` (a real
    /// robot, a log; the default). Tracking measures its distance error against it and, without
    /// it, against the reported (odometry) pose.
    fn true_pose(&self) -> Option<Pose> {
        None
    }

    /// Stops the robot (zero command) and releases the link; the default sends (0, 0).
    ///
    /// # Errors
    /// As [`Robot::send`].
    fn stop(&mut self) -> Result<(), RobotError> {
        self.send(0.0, 0.0).map(|_| ())
    }
}
