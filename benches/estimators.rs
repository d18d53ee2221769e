//! Criterion benchmark of the unbiased estimators (issue 4): the output-error fit of a
//! 10-minute 50 Hz recording of the simulated Khepera III (30,001 samples, random multisine to
//! 2 Hz, encoder noise), started from the least-squares θ as `identify` starts it; the same for
//! the 10 Hz Pioneer 3-DX; and the refined IV on the Khepera recording.
//!
//! Run: `cargo bench --bench estimators`.

use criterion::{Criterion, criterion_group, criterion_main};
use wheelid::core::condition::{self, ConditionSettings};
use wheelid::core::{Conditioned, Recording};
use wheelid::identify::{IdentifySettings, identify};
use wheelid::models::VwPd;
use wheelid::robots::{RobotProfile, SimSettings, simulate_recording};
use wheelid::solvers::{InstrumentalVariables, Ols, OutputError};

fn recording(robot: &RobotProfile) -> Recording {
    let exc = robot.multisine(1).expect("valid multisine");
    let s = SimSettings {
        duration_s: 600.0,
        ..SimSettings::default()
    };
    simulate_recording(robot, &exc, &s).expect("simulates")
}

fn least_squares(rec: &Recording) -> (Vec<f64>, f64) {
    let ls = IdentifySettings {
        estimator: "ls".into(),
        ..IdentifySettings::default()
    };
    let id = identify(std::slice::from_ref(rec), &VwPd, &Ols::default(), &ls).expect("ls");
    (id.theta, id.cutoff_hz)
}

fn bench_estimators(c: &mut Criterion) {
    let mut group = c.benchmark_group("estimators");
    group.sample_size(10);
    for robot in [RobotProfile::khepera3(), RobotProfile::pioneer3dx()] {
        let rec = recording(&robot);
        let (theta0, cutoff) = least_squares(&rec);
        let label = format!(
            "oe {} 10 min at {} Hz ({} samples)",
            robot.name,
            (1.0 / robot.period_s).round(),
            rec.len()
        );
        group.bench_function(label, |b| {
            b.iter(|| {
                OutputError::default()
                    .fit(&VwPd, std::slice::from_ref(&rec), &theta0)
                    .expect("fits")
            })
        });
        if robot.name == "khepera3" {
            let settings = ConditionSettings::default();
            let c: Conditioned<'_> =
                condition::condition(&rec, None, cutoff, &settings).expect("conditions");
            let lags = (1.0 / (c.dt * cutoff)).ceil() as usize;
            group.bench_function("iv khepera3 10 min at 50 Hz", |b| {
                b.iter(|| {
                    InstrumentalVariables::default()
                        .fit(
                            &VwPd,
                            std::slice::from_ref(&c),
                            &theta0,
                            cutoff,
                            &settings,
                            lags,
                        )
                        .expect("fits")
                })
            });
        }
    }
    group.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default().without_plots();
    targets = bench_estimators
}
criterion_main!(benches);
