//! Criterion benchmark: closed-loop controller steps per second (kinematic law, inverse
//! dynamics, adaptive law with projection, and the simulated robot advanced one period).
//!
//! * `thesis 4.2`: the §4.2 setting — Pioneer, exact states, 10 ms period, 2 RK4 sub-steps;
//! * `lab pioneer`: the §4.4 setting — 100 ms period, encoders and odometry, 50 sub-steps.
//!
//! Run: `cargo bench --bench tracking`; the throughput line reads in steps per second.

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use wheelid::robots::{AdaptiveSettings, RobotProfile, SimSettings, Start, TrackSettings, track};

fn bench_tracking(c: &mut Criterion) {
    let mut group = c.benchmark_group("closed loop");
    let adaptation = AdaptiveSettings {
        gamma: [1.0; 6],
        ..AdaptiveSettings::default()
    };
    let thesis = TrackSettings {
        duration_s: 1000.0,
        theta_hat0: [0.4, 0.1, 0.7, 0.3, 0.1, 0.6],
        adaptation: adaptation.clone(),
        start: Start::OnTrajectory,
        control_period_s: Some(0.01),
        simulation: SimSettings {
            measurement_noise: false,
            substeps: 2,
            ..SimSettings::default()
        },
        ..TrackSettings::default()
    };
    let lab = TrackSettings {
        duration_s: 10_000.0,
        theta_hat0: RobotProfile::pioneer3dx().theta,
        adaptation,
        ..TrackSettings::default()
    };
    for (name, s) in [("thesis 4.2", thesis), ("lab pioneer", lab)] {
        let robot = RobotProfile::pioneer3dx();
        let steps = track(&robot, &s).expect("runs").t.len();
        group.throughput(Throughput::Elements(steps as u64));
        group.sample_size(10);
        group.bench_function(format!("{name}, {steps} steps"), |b| {
            b.iter(|| track(&robot, &s).expect("runs"))
        });
    }
    group.finish();
}

criterion_group!(benches, bench_tracking);
criterion_main!(benches);
