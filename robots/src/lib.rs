//! # wheelid-robots
//!
//! Robot backends and what drives them: [`profile`] (the Pioneer 3-DX and Khepera III of
//! Laut 2011), [`excitation`] (sums of sines, steps, chirps and multisines), [`trajectory`]
//! (the figure eights of Appendix A), [`simulator`] (the simulated robot of eq. 2.19, with an
//! encoder measurement model) and [`effects`] (the physics the 6-θ model leaves out).

pub mod effects;
pub mod excitation;
pub mod profile;
pub mod simulator;
pub mod trajectory;

pub use effects::Effects;
pub use excitation::{Excitation, Multisine, MultisineSpec, Phases, Signal, SumOfSines};
pub use profile::RobotProfile;
pub use simulator::{Sample, SimRobot, SimSettings, simulate_recording};
pub use trajectory::{DesiredState, FigureEight, FigureEightDither, Trajectory, TrajectorySpec};
