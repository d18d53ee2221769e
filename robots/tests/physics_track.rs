//! Tracking on the rigid-body robot through the `Robot` trait ([`track_robot`]).
//!
//! The independent source: eq. 2.19 with the θ that `models::physical` maps from the robot's
//! constants is the thesis's claim about the robot. If that holds, the inverse-dynamics
//! controller seeded with that θ tracks the figure eight on the rigid-body robot as it does on
//! the eq.-2.19 simulator with the same θ; a wrong map, a wrong engine set-up or a wrong loop
//! (time base, anchoring, command recording) shows as a different error.

use wheelid_robots::physics::{PhysicalProfile, PhysicsRobot, PhysicsSettings};
use wheelid_robots::{Start, TrackResult, TrackSettings, TrajectorySpec, track, track_robot};

/// Tracking of the figure eight for `secs` on the physics robot `name` and on the eq.-2.19
/// simulator with the mapped θ, both with θ̂(0) = `theta_hat`, no adaptation, exact sensors on
/// the simulator's side off (encoders on both).
fn both(name: &str, theta_hat: [f64; 6], secs: f64) -> (TrackResult, TrackResult) {
    let p = PhysicalProfile::by_name(name).expect("built-in profile");
    let model = p.model_profile();
    let s = TrackSettings {
        duration_s: secs,
        theta_hat0: theta_hat,
        ..TrackSettings::default()
    };
    let ps = PhysicsSettings {
        duration_s: secs,
        ..PhysicsSettings::default()
    };
    let mut robot = PhysicsRobot::new(&p, &ps).expect("physics robot");
    let traj = TrajectorySpec::for_profile(&model, false);
    let phys = track_robot(&mut robot, &traj, &s, [model.v_max, model.w_max]).expect("tracks");
    let sim = track(&model, &s).expect("tracks");
    (phys, sim)
}

/// With θ̂ = the mapped θ, the physics robot tracks as the eq.-2.19 simulator does: RMS error
/// over the second half within 10 % of the simulator's (measured: Khepera 4.13 vs 4.14 mm,
/// Pioneer 2.41 vs 2.51 mm), and the run is on the robot's own time base and ground truth.
#[test]
fn physics_tracks_as_the_model_with_the_mapped_theta() {
    for (name, secs) in [("khepera3", 40.0), ("pioneer3dx", 60.0)] {
        let th = PhysicalProfile::by_name(name).expect("profile").theta();
        let (phys, sim) = both(name, th, secs);
        let e_phys = phys.summary_between(secs / 2.0, secs + 1.0).rms;
        let e_sim = sim.summary_between(secs / 2.0, secs + 1.0).rms;
        println!("{name}: RMS physics {e_phys:.5} m, simulator {e_sim:.5} m");
        assert!(
            (e_phys / e_sim - 1.0).abs() < 0.10,
            "{name}: physics {e_phys} m against the model's {e_sim} m"
        );
        assert!(phys.ground_truth, "the physics robot knows its true pose");
        assert_eq!(phys.robot, "physics");
        assert_eq!(phys.t[0], 0.0, "time from the first report");
        let period = PhysicalProfile::by_name(name).expect("profile").period_s;
        assert!((phys.t[1] - period).abs() < 1e-9, "one report a period");
        assert!((phys.t.last().copied().unwrap_or(0.0) - secs).abs() < period);
    }
}

/// The trajectory is anchored at the robot's first pose: the robot starts at the origin heading
/// +x, the figure eight at its own start heading; the first command is the simulator's (whose
/// robot is placed on the start pose), so there is no heading error to correct.
#[test]
fn trajectory_is_anchored_at_the_robot_start() {
    let th = PhysicalProfile::khepera3().theta();
    let (phys, sim) = both("khepera3", th, 1.0);
    for i in 0..2 {
        assert!(
            (phys.command[0][i] - sim.command[0][i]).abs() < 1e-12,
            "first command {:?} against {:?}",
            phys.command[0],
            sim.command[0]
        );
    }
    assert_eq!(phys.desired[0], sim.desired[0]);
    assert!(phys.error[0] < 1e-12);
}

/// A robot backend starts where it is, at rest: the thesis's "perfect initial conditions" need
/// the simulator.
#[test]
fn on_trajectory_start_is_refused_on_a_robot() {
    let p = PhysicalProfile::khepera3();
    let mut robot = PhysicsRobot::new(&p, &PhysicsSettings::default()).expect("robot");
    let s = TrackSettings {
        start: Start::OnTrajectory,
        ..TrackSettings::default()
    };
    let traj = TrajectorySpec::for_profile(&p.model_profile(), false);
    let e = track_robot(&mut robot, &traj, &s, [p.v_max, p.w_max]).expect_err("refused");
    assert!(e.to_string().contains("at rest"), "{e}");
}
