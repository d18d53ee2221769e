//! The built-in robot backends, models and solvers a run config names by `type`
//! ([`super::RobotSpec`], [`super::ModelSpec`], [`super::SolverSpec`], through typetag): the
//! simulator of eq. 2.19, the rigid-body backend, a replayed log, the Pioneer (ARCOS) and
//! Khepera (serial) protocols — on a port, or on `"loopback"` against the project's own server
//! on top of the simulator — the `vw-pd` and `wheel-pd` models, and the `ols` and `box`
//! solvers.

use super::*;
use crate::config::robot_profile;
use wheelid_core::RobotError;
use wheelid_robots::khepera::{Khepera, KheperaServer, KheperaSettings};
use wheelid_robots::physics::{PhysicalProfile, PhysicsRobot, PhysicsSettings};
use wheelid_robots::pioneer::{ArcosServer, Pioneer, PioneerSettings};
use wheelid_robots::replay::{Replay, ReplaySettings};
use wheelid_robots::{RobotProfile, SimRobot, SimSettings};
/// `[robot] type = "simulator"`: the simulated robot of eq. 2.19 with encoders and optional
/// effects.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimulatorSpec {
    /// Built-in profile name (default `pioneer3dx`).
    pub robot: Option<String>,
    /// A whole profile instead.
    pub profile: Option<RobotProfile>,
    /// Seed, sub-steps, encoder model, effects (`duration_s` is the run's).
    #[serde(default)]
    pub simulation: SimSettings,
}

#[typetag::deserialize(name = "simulator")]
impl RobotSpec for SimulatorSpec {
    fn connect(&self, _: &RunContext<'_>) -> Result<Box<dyn Robot>> {
        let profile = robot_profile(None, self.robot.as_deref(), self.profile.as_ref())?;
        Ok(Box::new(SimRobot::new(&profile, &self.simulation)?))
    }
}

/// `[robot] type = "physics"`: the independent rigid-body robot (`wheelid_robots::physics`).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PhysicsSpec {
    /// Built-in physical profile name (`pioneer3dx`, `khepera3`, `burger`; default `khepera3`).
    pub robot: Option<String>,
    /// A whole physical profile instead.
    pub profile: Option<PhysicalProfile>,
    /// Seed, stamping convention, jitter, encoders, noise, effects (`duration_s` is the run's).
    #[serde(default)]
    pub physics: PhysicsSettings,
}

#[typetag::deserialize(name = "physics")]
impl RobotSpec for PhysicsSpec {
    fn connect(&self, cx: &RunContext<'_>) -> Result<Box<dyn Robot>> {
        let profile = match (&self.profile, self.robot.as_deref()) {
            (Some(p), _) => p.clone(),
            (None, name) => {
                let name = name.unwrap_or("khepera3");
                PhysicalProfile::by_name(name).with_context(|| {
                    format!(
                        "unknown physical profile `{name}` (known: {})",
                        PhysicalProfile::NAMES.join(", ")
                    )
                })?
            }
        };
        let settings = PhysicsSettings {
            duration_s: cx.duration_s,
            ..self.physics.clone()
        };
        Ok(Box::new(PhysicsRobot::new(&profile, &settings)?))
    }
}

#[typetag::deserialize(name = "replay")]
impl RobotSpec for ReplaySettings {
    fn connect(&self, cx: &RunContext<'_>) -> Result<Box<dyn Robot>> {
        let mut s = self.clone();
        s.path = cx.base.join(&s.path);
        Ok(Box::new(Replay::open(&s)?))
    }
}

/// A robot and the loopback server it talks to (stopped when the robot is dropped).
struct WithServer<R, H> {
    robot: R,
    _server: H,
}

impl<R: Robot, H> Robot for WithServer<R, H> {
    fn name(&self) -> &str {
        self.robot.name()
    }
    fn period_s(&self) -> f64 {
        self.robot.period_s()
    }
    fn velocity_sampling(&self) -> wheelid_core::VelocitySampling {
        self.robot.velocity_sampling()
    }
    fn timing(&self) -> Option<wheelid_core::Timing> {
        self.robot.timing()
    }
    fn send(&mut self, v_ref: f64, w_ref: f64) -> Result<(f64, f64), RobotError> {
        self.robot.send(v_ref, w_ref)
    }
    fn read(&mut self) -> Result<wheelid_core::Odometry, RobotError> {
        self.robot.read()
    }
    fn stop(&mut self) -> Result<(), RobotError> {
        self.robot.stop()
    }
}

/// The robot connected to a loopback `server`, kept together (the server stops when the
/// robot is dropped).
fn with_server<R: Robot + 'static, H: 'static>(
    server: H,
    robot: Result<R, RobotError>,
) -> Result<Box<dyn Robot>> {
    Ok(Box::new(WithServer {
        robot: robot?,
        _server: server,
    }))
}

/// The port value that starts the project's loopback server.
const LOOPBACK: &str = "loopback";

#[typetag::deserialize(name = "pioneer")]
impl RobotSpec for PioneerSettings {
    fn connect(&self, _: &RunContext<'_>) -> Result<Box<dyn Robot>> {
        if self.port == LOOPBACK {
            let server = ArcosServer::spawn(
                RobotProfile::pioneer3dx(),
                SimSettings::default(),
                wheelid_robots::pioneer::Pacing::LockStep,
            )
            .context("starting the ARCOS loopback server")?;
            let port = server.url();
            return with_server(
                server,
                Pioneer::connect(&PioneerSettings {
                    port,
                    ..self.clone()
                }),
            );
        }
        Ok(Box::new(Pioneer::connect(self)?))
    }
}

#[typetag::deserialize(name = "khepera")]
impl RobotSpec for KheperaSettings {
    fn connect(&self, _: &RunContext<'_>) -> Result<Box<dyn Robot>> {
        if self.port == LOOPBACK {
            let server = KheperaServer::spawn(
                RobotProfile::khepera3(),
                SimSettings::default(),
                wheelid_robots::khepera::Pacing::LockStep,
            )
            .context("starting the Khepera loopback server")?;
            // Lock-step: the server advances one period per read, no wall clock to keep.
            let settings = KheperaSettings {
                port: server.url(),
                realtime: false,
                ..self.clone()
            };
            return with_server(server, Khepera::connect(&settings));
        }
        Ok(Box::new(Khepera::connect(self)?))
    }
}

/// `[model] type = "vw-pd"`: eq. 2.19 with PD control on v and ω (Appendix A.3).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VwPdSpec {}

#[typetag::deserialize(name = "vw-pd")]
impl ModelSpec for VwPdSpec {
    fn build(&self) -> Box<dyn RegressorModel> {
        Box::new(wheelid_models::VwPd)
    }
}

/// `[model] type = "wheel-pd"`: eq. 2.19 with PD control on each wheel (§2.2).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WheelPdSpec {}

#[typetag::deserialize(name = "wheel-pd")]
impl ModelSpec for WheelPdSpec {
    fn build(&self) -> Box<dyn RegressorModel> {
        Box::new(wheelid_models::WheelPd)
    }
}

/// `[solver] type = "ols"`: ordinary least squares.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OlsSpec {}

#[typetag::deserialize(name = "ols")]
impl SolverSpec for OlsSpec {
    fn build(&self) -> Result<SolverWithBounds> {
        Ok((Box::new(wheelid_solvers::Ols::default()), None))
    }
}

/// `[solver] type = "box"`: least squares with θ kept in [lower, upper] (Clarabel).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BoxSpec {
    /// Lower bounds, one per θ.
    pub theta_lower: Vec<f64>,
    /// Upper bounds, one per θ.
    pub theta_upper: Vec<f64>,
}

#[typetag::deserialize(name = "box")]
impl SolverSpec for BoxSpec {
    fn build(&self) -> Result<SolverWithBounds> {
        if self.theta_lower.len() != self.theta_upper.len() {
            bail!(
                "theta_lower has {} values, theta_upper {}",
                self.theta_lower.len(),
                self.theta_upper.len()
            );
        }
        let bounds: Vec<(f64, f64)> = self
            .theta_lower
            .iter()
            .copied()
            .zip(self.theta_upper.iter().copied())
            .collect();
        if let Some(i) = bounds.iter().position(|(lo, hi)| {
            !matches!(
                lo.partial_cmp(hi),
                Some(std::cmp::Ordering::Less | std::cmp::Ordering::Equal)
            )
        }) {
            bail!(
                "θ{}: lower {} is above upper {}",
                i + 1,
                bounds[i].0,
                bounds[i].1
            );
        }
        Ok((Box::new(wheelid_solvers::BoxLs::default()), Some(bounds)))
    }
}
