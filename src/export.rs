//! Hand-off of an identified (and diagnosed) model to ROS 2 (issue 16): a parameter YAML for
//! `diff_drive_controller` and the Nav2 MPPI controller, plus the response lag.
//!
//! Parameter names are the upstream ones:
//! * `diff_drive_controller` — ros-controls/ros2_controllers,
//!   `diff_drive_controller/src/diff_drive_controller_parameter.yaml`: `wheel_separation`,
//!   `wheel_radius`, `linear.x.{has_velocity_limits, max_velocity, min_velocity,
//!   has_acceleration_limits, max_acceleration, min_acceleration}` and the same under
//!   `angular.z`;
//! * Nav2 MPPI — docs.nav2.org `configuration/packages/configuring-mppic.rst`: `vx_max`,
//!   `vx_min`, `wz_max`, `ax_max`, `ax_min`, `az_max` (of the controller plugin, here under
//!   `controller_server.ros__parameters.FollowPath`).
//!
//! Limits: a diagnosed `velocity_saturation` (`v_max`, `w_max`) or the built-in profile's top
//! speeds; accelerations only from a diagnosed `acceleration_limit` (an acceleration not
//! measured is not written). The response lag: the time constants θ1/θ4 and θ2/θ6 of eq. 2.19
//! \[s\] and a diagnosed `input_delay` \[s\], under `wheelid_response` (not read by either node).

use std::fmt::Write as _;

use crate::files::ModelFile;
use wheelid_robots::RobotProfile;

/// What the export knows and where each value came from.
#[derive(Debug, Clone, PartialEq)]
struct Limits {
    v_max: Option<(f64, &'static str)>,
    w_max: Option<(f64, &'static str)>,
    a_v: Option<f64>,
    a_w: Option<f64>,
}

fn limits(model: &ModelFile, profile: Option<&RobotProfile>) -> Limits {
    let get = |e: &str, p: &str| model.effects.get(e).and_then(|m| m.get(p)).copied();
    let pick = |found: Option<f64>, built_in: Option<f64>| {
        found
            .map(|x| (x, "diagnosed velocity_saturation"))
            .or(built_in.map(|x| (x, "the built-in profile")))
    };
    Limits {
        v_max: pick(
            get("velocity_saturation", "v_max"),
            profile.map(|p| p.v_max),
        ),
        w_max: pick(
            get("velocity_saturation", "w_max"),
            profile.map(|p| p.w_max),
        ),
        a_v: get("acceleration_limit", "v_accel_max"),
        a_w: get("acceleration_limit", "w_accel_max"),
    }
}

/// One `linear.x` / `angular.z` block of `diff_drive_controller`.
fn ddc_axis(s: &mut String, axis: &str, sub: &str, v: Option<(f64, &str)>, a: Option<f64>) {
    let _ = writeln!(s, "    {axis}:\n      {sub}:");
    let _ = writeln!(s, "        has_velocity_limits: {}", v.is_some());
    if let Some((x, from)) = v {
        let _ = writeln!(s, "        max_velocity: {x}  # {from}");
        let _ = writeln!(s, "        min_velocity: {}", -x);
    }
    let _ = writeln!(s, "        has_acceleration_limits: {}", a.is_some());
    if let Some(x) = a {
        let _ = writeln!(
            s,
            "        max_acceleration: {x}  # diagnosed acceleration_limit"
        );
        let _ = writeln!(s, "        min_acceleration: {}", -x);
    }
}

/// The ROS 2 parameter YAML of `model` (module docs); `profile`: the robot's built-in profile
/// for its wheel geometry and top speeds, when known; `source`: what to name in the header.
///
/// Shape: `diff_drive_controller.ros__parameters.{wheel_separation, wheel_radius, linear.x.*,
/// angular.z.*}`, `controller_server.ros__parameters.FollowPath.{vx_max, vx_min, wz_max,
/// ax_max, ax_min, az_max}` (each only where known), `wheelid_response.{theta,
/// time_constant_v_s, time_constant_w_s, delay_s}`.
pub fn ros2_yaml(model: &ModelFile, profile: Option<&RobotProfile>, source: &str) -> String {
    let l = limits(model, profile);
    let mut s = format!(
        "# wheelid export --format ros2 {source} (robot: {})\n",
        model.robot.as_deref().unwrap_or("not recorded")
    );
    s.push_str("diff_drive_controller:\n  ros__parameters:\n");
    if let Some(p) = profile {
        let _ = writeln!(s, "    wheel_separation: {}  # m", p.track);
        let _ = writeln!(s, "    wheel_radius: {}  # m", p.wheel_radius);
    }
    ddc_axis(&mut s, "linear", "x", l.v_max, l.a_v);
    ddc_axis(&mut s, "angular", "z", l.w_max, l.a_w);
    s.push_str("controller_server:\n  ros__parameters:\n    FollowPath:  # nav2_mppi_controller\n");
    if let Some((v, _)) = l.v_max {
        let _ = writeln!(s, "      vx_max: {v}\n      vx_min: {}", -v);
    }
    if let Some((w, _)) = l.w_max {
        let _ = writeln!(s, "      wz_max: {w}");
    }
    if let Some(a) = l.a_v {
        let _ = writeln!(s, "      ax_max: {a}\n      ax_min: {}", -a);
    }
    if let Some(a) = l.a_w {
        let _ = writeln!(s, "      az_max: {a}");
    }
    let th = &model.theta;
    let theta: Vec<String> = th.iter().map(|x| format!("{x}")).collect();
    let _ = writeln!(
        s,
        "wheelid_response:  # eq. 2.19; not read by the nodes above\n  theta: [{}]",
        theta.join(", ")
    );
    if th.len() == 6 {
        let _ = writeln!(s, "  time_constant_v_s: {}", th[0] / th[3]);
        let _ = writeln!(s, "  time_constant_w_s: {}", th[1] / th[5]);
    }
    // The dead time between a command and what the encoders show: the commands' and the
    // measurements' together.
    let delay: f64 = ["input_delay", "output_delay"]
        .iter()
        .filter_map(|e| model.effects.get(*e).and_then(|m| m.get("delay_s")))
        .sum();
    let _ = writeln!(s, "  delay_s: {delay}");
    s
}
