//! # wheelid-robots
//!
//! Robot backends and what drives them: [`profile`] (the Pioneer 3-DX and Khepera III of
//! Laut 2011), [`excitation`] (sums of sines, steps, chirps and multisines), [`trajectory`]
//! (the figure eights of Appendix A) and [`simulator`] (the simulated robot that generates
//! recordings, with an encoder measurement model).

pub mod excitation;
pub mod profile;
pub mod simulator;
pub mod trajectory;

pub use excitation::{Excitation, Multisine, MultisineSpec, Phases, Signal, SumOfSines};
pub use profile::RobotProfile;
pub use simulator::{SimSettings, simulate_recording};
pub use trajectory::{DesiredState, FigureEight, FigureEightDither, Trajectory, TrajectorySpec};
