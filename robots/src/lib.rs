//! # wheelid-robots
//!
//! Robot backends and what drives them: [`profile`] (the Pioneer 3-DX and Khepera III of
//! Laut 2011), [`excitation`] (sums of sines, steps, chirps and multisines), [`trajectory`]
//! (the figure eights of Appendix A), [`simulator`] (the simulated robot of eq. 2.19, with an
//! encoder measurement model) [`effects`] (the physics the 6-θ model leaves out), [`control`] (the kinematic,
//! inverse-dynamics and adaptive controllers of chapters 3–4) and [`tracking`] (the closed loop).
//! [`physics`] is an independent rigid-body robot (rapier3d-f64: motors, PD loops, wheel
//! contacts, a host that stamps its rows by any of the three conventions) to prove the methods
//! on physics eq. 2.19 did not write.

pub mod control;
pub mod effects;
pub mod excitation;
pub mod khepera;
pub mod link;
pub mod migrate;
pub mod model_recording;
pub mod physics;
pub mod pioneer;
pub mod profile;
pub mod replay;
pub mod simulator;
pub mod tracking;
pub mod trajectory;

pub use control::{AdaptiveController, AdaptiveSettings, KinematicLaw};
pub use effects::Effects;
pub use excitation::{Excitation, Multisine, MultisineSpec, Phases, Signal, SumOfSines};
pub use migrate::{Choice, ControllerSpec, Migrated, RobotModel, migrate};
pub use model_recording::simulate_model_recording;
pub use profile::RobotProfile;
pub use simulator::{Sample, SimRobot, SimSettings, simulate_recording};
pub use tracking::{Start, TrackResult, TrackSettings, track, track_robot};
pub use trajectory::{DesiredState, FigureEight, FigureEightDither, Trajectory, TrajectorySpec};
