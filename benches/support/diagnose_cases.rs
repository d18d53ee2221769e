//! The cases of the diagnosis benchmark (`benches/diagnose.rs`), shared with
//! `examples/profile_diagnose.rs` (which includes this file by path): a 10-minute, 50 Hz
//! recording of the simulated Khepera III with one concealed effect or a pair.

use wheelid::core::Recording;
use wheelid::robots::effects::{
    AccelerationLimit, CoulombFriction, Effects, GainDrift, InputDelay, PayloadChange, Slip,
    VelocitySaturation, WheelAsymmetry,
};
use wheelid::robots::{RobotProfile, SimSettings, simulate_recording};

/// The 10-minute, 50 Hz recording of the simulated Khepera III (seed 3, multisine 3) with
/// `effects` concealed.
pub fn recording(effects: Effects) -> Recording {
    let robot = RobotProfile::khepera3();
    let exc = robot.multisine(3).expect("valid multisine");
    let s = SimSettings {
        duration_s: 600.0,
        seed: 3,
        effects,
        ..SimSettings::default()
    };
    simulate_recording(&robot, &exc, &s).expect("simulates")
}

/// The cases by name: `clean`, `dead_time`, then the other candidates one at a time and
/// two pairs, at magnitudes inside the ranges of `tests/diagnose.rs`.
pub fn cases() -> Vec<(&'static str, Effects)> {
    let robot = RobotProfile::khepera3();
    let (va, wa) = (0.25 * robot.v_max, 0.25 * robot.w_max);
    let delay = InputDelay { delay_s: 0.08 };
    let saturation = VelocitySaturation {
        v_max: 1.4 * va,
        w_max: 0.55 * wa,
    };
    let accel = AccelerationLimit {
        v_accel_max: 0.1,
        w_accel_max: 2.26,
    };
    let asymmetry = WheelAsymmetry { ratio: 1.08 };
    let e = Effects::default;
    vec![
        ("clean", e()),
        (
            "dead_time",
            Effects {
                input_delay: Some(delay),
                ..e()
            },
        ),
        (
            "acceleration_limit",
            Effects {
                acceleration_limit: Some(accel),
                ..e()
            },
        ),
        (
            "velocity_saturation",
            Effects {
                velocity_saturation: Some(saturation),
                ..e()
            },
        ),
        (
            "coulomb_friction",
            Effects {
                coulomb_friction: Some(CoulombFriction {
                    v_coulomb: 0.08 * va,
                    w_coulomb: 0.08 * wa,
                }),
                ..e()
            },
        ),
        (
            "wheel_asymmetry",
            Effects {
                wheel_asymmetry: Some(asymmetry),
                ..e()
            },
        ),
        (
            "payload_change",
            Effects {
                payload_change: Some(PayloadChange::scaled(300.0, robot.theta, 1.5)),
                ..e()
            },
        ),
        (
            "gain_drift",
            Effects {
                gain_drift: Some(GainDrift {
                    rate_per_s: -0.3 / 600.0,
                }),
                ..e()
            },
        ),
        (
            "slip",
            Effects {
                slip: Some(Slip { k_v: 0.3, k_w: 0.3 }),
                ..e()
            },
        ),
        (
            "dead_time+saturation",
            Effects {
                input_delay: Some(delay),
                velocity_saturation: Some(saturation),
                ..e()
            },
        ),
        (
            "acceleration_limit+asymmetry",
            Effects {
                acceleration_limit: Some(accel),
                wheel_asymmetry: Some(asymmetry),
                ..e()
            },
        ),
    ]
}

/// The candidates a diagnosis of case `name` must name, sorted: its effects, `+`-separated,
/// the pairs' short names (`dead_time`, `saturation`, `asymmetry`) spelled as candidates.
pub fn expected(name: &'static str) -> Vec<&'static str> {
    let mut want: Vec<&'static str> = (name.split('+'))
        .filter(|n| *n != "clean")
        .map(|n| match n {
            "dead_time" => "input_delay",
            "saturation" => "velocity_saturation",
            "asymmetry" => "wheel_asymmetry",
            other => other,
        })
        .collect();
    want.sort_unstable();
    want
}
