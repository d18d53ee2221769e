//! # wheelid-core
//!
//! The bottom layer of wheelid: the data (recordings, conditioned signals), the traits that the
//! other crates implement ([`DynamicModel`], [`RegressorModel`], [`Solver`], [`Robot`]) and the errors.
//!
//! A run walks the layers once:
//! **read** ([`recording`]) → **condition** ([`condition`], [`signal`]: resample, align, filter,
//! differentiate) → **model** ([`RegressorModel`]: regressor; [`DynamicModel`]: simulate; in `wheelid-models`) →
//! **fit** ([`Solver`], in `wheelid-solvers`) → **report** (the `wheelid` crate).

pub mod condition;
pub mod effect;
pub mod error;
pub mod estimator;
pub mod metrics;
pub mod model;
pub mod plugin;
pub mod recording;
pub mod residual;
pub mod robot;
pub mod signal;
pub mod solver;

pub use condition::{ConditionSettings, Conditioned, CutoffChoice};
pub use effect::{
    Effect, EffectChannels, Force, Measurement, Probe, Search, TRACTION_SLIP_SHARE, Terms,
    Traction, WheelTerms,
};
pub use error::{Error, Location, Result};
pub use estimator::{Estimate, Estimator, EstimatorInput, FreeRun, TimingReport, TimingSource};
pub use model::{
    ChannelInfo, ChannelRegression, DynamicModel, ParamInfo, RegressorModel, Sensitivities,
    Simulation, extends_eq_2_19,
};
pub use recording::{
    Columns, CommandHold, DRIVE_START, POSE_SOURCE, Recording, Timing, VelocitySampling,
};
pub use robot::{Odometry, Pose, Robot, RobotError};
pub use solver::{BoundState, LinearFit, LinearProblem, SolveError, SolveStatus, Solver};
