//! # wheelid
//!
//! Identifies the velocity-input dynamics of differential-drive robots from recordings
//! (Laut 2011, *A Dynamic Parameter Identification Method for Migrating Control Strategies
//! Between Heterogeneous Wheeled Mobile Robots*), as a library and the `wheelid` command.
//!
//! The crates, bottom up:
//! * [`core`] (`wheelid-core`): recordings, conditioning, the `RegressorModel` and `Solver`
//!   traits, errors;
//! * [`models`] (`wheelid-models`): the 6-θ model of eq. 2.19 in its wheel-PD and v/ω-PD
//!   parameterizations;
//! * [`solvers`] (`wheelid-solvers`): OLS and box-bounded least squares;
//! * [`robots`] (`wheelid-robots`): robot profiles, excitations, the simulator;
//! * this crate: the identification run ([`identify`]), its files ([`files`]), reports
//!   ([`report`]) and plots ([`plot`]); the stamping convention, stated or estimated
//!   ([`timing`]); config-driven runs ([`run`]) and external plugins
//!   ([`plugins`]); controller migration between robots ([`migrate`]); the ROS 2 hand-off
//!   ([`export`]); online identification on board, one sample at a time ([`online`]).
//!
//! ```
//! use wheelid::{identify::{identify, IdentifySettings}, models::VwPd, solvers::Ols};
//! use wheelid::robots::{Excitation, RobotProfile, SimSettings, simulate_recording};
//!
//! let robot = RobotProfile::pioneer3dx();
//! let rec = simulate_recording(&robot, &Excitation::thesis_pioneer(), &SimSettings::default())?;
//! let id = identify(&[rec], &VwPd, &Ols::default(), &IdentifySettings::default())?;
//! assert!((id.theta[0] - robot.theta[0]).abs() < 0.02 * robot.theta[0]);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod config;
pub mod design;
pub mod diagnose;
pub mod estimators;
pub mod export;
pub mod files;
pub mod identify;
pub mod migrate;
pub mod observer;
pub mod online;
pub mod plot;
pub mod plugins;
pub mod registry;
pub mod report;
pub mod run;
pub mod timing;

pub use wheelid_core as core;
pub use wheelid_models as models;
pub use wheelid_robots as robots;
pub use wheelid_solvers as solvers;
