//! # wheelid-robots
//!
//! Robot backends and what drives them: [`profile`] (the Pioneer 3-DX and Khepera III of
//! Laut 2011), [`excitation`] (the thesis's sum-of-sines commands) and [`simulator`] (the
//! simulated robot that generates recordings, with an encoder measurement model).

pub mod excitation;
pub mod profile;
pub mod simulator;
pub mod trajectory;

pub use excitation::{Excitation, SumOfSines};
pub use profile::RobotProfile;
pub use simulator::{SimSettings, simulate_recording};
