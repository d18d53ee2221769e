//! The diagnosis's candidate models against the simulator: a recording simulated with one
//! effect at a known magnitude (exact states, no noise) is reproduced by the extended model with
//! the matching candidate at that magnitude — the model and the simulator's physics agree, so a
//! fit can find the magnitude. Independent source: the simulator integrates the effect with 50
//! RK4 sub-steps per period and its own setpoint pipeline; the model on its own grid.

use wheelid::core::{DynamicModel, Recording};
use wheelid::models::{Candidate, Extended};
use wheelid::robots::effects::{
    AccelerationLimit, CoulombFriction, GainDrift, InputDelay, PayloadChange, Slip,
    VelocitySaturation, WheelAsymmetry,
};
use wheelid::robots::{Effects, Excitation, RobotProfile, SimSettings, simulate_recording};

fn exact(robot: &RobotProfile, effects: Effects) -> Recording {
    let exc = Excitation::random_multisine(
        5,
        0.5 * robot.v_max,
        0.4 * robot.v_max,
        0.4 * robot.w_max,
        2.0,
    )
    .expect("valid");
    simulate_recording(
        robot,
        &exc,
        &SimSettings {
            duration_s: 60.0,
            measurement_noise: false,
            effects,
            ..SimSettings::default()
        },
    )
    .expect("simulates")
}

fn rms(x: &[f64]) -> f64 {
    (x.iter().map(|v| v * v).sum::<f64>() / x.len() as f64).sqrt()
}

#[test]
fn each_candidate_reproduces_its_simulator_effect() {
    for robot in [RobotProfile::pioneer3dx(), RobotProfile::khepera3()] {
        let th = robot.theta;
        let (vm, wm) = (robot.v_max, robot.w_max);
        let cases: Vec<(Candidate, Effects, Vec<f64>)> = vec![
            (
                Candidate::INPUT_DELAY,
                Effects {
                    input_delay: Some(InputDelay { delay_s: 0.23 }),
                    ..Effects::default()
                },
                vec![0.23],
            ),
            (
                Candidate::ACCELERATION_LIMIT,
                Effects {
                    acceleration_limit: Some(AccelerationLimit {
                        v_accel_max: 0.6 * vm,
                        w_accel_max: 0.8 * wm,
                    }),
                    ..Effects::default()
                },
                vec![0.6 * vm, 0.8 * wm],
            ),
            (
                Candidate::VELOCITY_SATURATION,
                Effects {
                    velocity_saturation: Some(VelocitySaturation {
                        v_max: 0.7 * vm,
                        w_max: 0.25 * wm,
                    }),
                    ..Effects::default()
                },
                vec![0.7 * vm, 0.25 * wm],
            ),
            (
                Candidate::COULOMB_FRICTION,
                Effects {
                    coulomb_friction: Some(CoulombFriction {
                        v_coulomb: 0.05 * vm,
                        w_coulomb: 0.03 * wm,
                    }),
                    ..Effects::default()
                },
                vec![0.05 * vm, 0.03 * wm],
            ),
            (
                Candidate::WHEEL_ASYMMETRY,
                Effects {
                    wheel_asymmetry: Some(WheelAsymmetry { ratio: 1.08 }),
                    ..Effects::default()
                },
                vec![1.08],
            ),
            (
                Candidate::PAYLOAD_CHANGE,
                Effects {
                    payload_change: Some(PayloadChange::scaled(23.37, th, 1.8)),
                    ..Effects::default()
                },
                vec![23.37, 1.8 * th[0], 1.8 * th[1], 1.8 * th[2], 1.8 * th[4]],
            ),
            (
                Candidate::GAIN_DRIFT,
                Effects {
                    gain_drift: Some(GainDrift { rate_per_s: -0.004 }),
                    ..Effects::default()
                },
                vec![-0.004],
            ),
            (
                Candidate::SLIP,
                Effects {
                    slip: Some(Slip { k_v: 0.3, k_w: 0.5 }),
                    ..Effects::default()
                },
                vec![0.3, 0.5],
            ),
        ];
        for (cand, effects, values) in cases {
            let rec = exact(&robot, effects);
            let model = Extended::new(&[cand], robot.track).expect("model");
            let theta: Vec<f64> = th.iter().copied().chain(values).collect();
            let sim = model
                .simulate(&theta, &rec, &[0.0, 0.0])
                .expect("simulates");
            // Against the six-θ model alone, so the comparison shows the effect matters.
            let plain = Extended::new(&[], robot.track)
                .expect("model")
                .simulate(&th, &rec, &[0.0, 0.0])
                .expect("simulates");
            for (c, meas) in [&rec.v, &rec.w].into_iter().enumerate() {
                let err: Vec<f64> = meas.iter().zip(&sim[c]).map(|(a, b)| a - b).collect();
                let without: Vec<f64> = meas.iter().zip(&plain[c]).map(|(a, b)| a - b).collect();
                let rel = rms(&err) / rms(meas);
                eprintln!(
                    "{} {} ch {c}: rms error {:.2e} of the signal (without the candidate {:.2e})",
                    robot.name,
                    cand.name(),
                    rel,
                    rms(&without) / rms(meas)
                );
                // The rate limit's kinks (where the setpoint reaches its target) fall inside the
                // model's sub-steps, which ramp linearly across them: O(h) there, h ≤ τ/5.
                let tol = if cand == Candidate::ACCELERATION_LIMIT {
                    5e-3
                } else {
                    1e-3
                };
                assert!(
                    rel < tol,
                    "{} {} channel {c}: {rel:.2e}",
                    robot.name,
                    cand.name()
                );
            }
        }
    }
}
