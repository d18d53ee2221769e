//! Criterion benchmark of the mismatch diagnosis (issue 5) on a 10-minute, 50 Hz recording of
//! the simulated Khepera III (30,001 samples, random multisine to 2 Hz, encoder noise):
//! * `clean`: the recording as the model describes it (fit, tests, fingerprints: nothing to
//!   add);
//! * `dead_time`: the same robot with a concealed 80 ms dead time (found, fitted, accepted,
//!   then a second round of the search).
//!
//! Run: `cargo bench --bench diagnose`.

use criterion::{Criterion, criterion_group, criterion_main};
use wheelid::core::Recording;
use wheelid::diagnose::{DiagnoseSettings, diagnose};
use wheelid::models::VwPd;
use wheelid::robots::effects::{Effects, InputDelay};
use wheelid::robots::{Excitation, RobotProfile, SimSettings, simulate_recording};

fn recording(effects: Effects) -> Recording {
    let robot = RobotProfile::khepera3();
    let exc = Excitation::random_multisine(
        3,
        0.25 * robot.v_max,
        0.25 * robot.v_max,
        0.25 * robot.w_max,
        2.0,
    )
    .expect("valid multisine");
    let s = SimSettings {
        duration_s: 600.0,
        seed: 3,
        effects,
        ..SimSettings::default()
    };
    simulate_recording(&robot, &exc, &s).expect("simulates")
}

fn bench(c: &mut Criterion) {
    let clean = recording(Effects::default());
    let delayed = recording(Effects {
        input_delay: Some(InputDelay { delay_s: 0.08 }),
        ..Effects::default()
    });
    let settings = DiagnoseSettings::default();
    let mut g = c.benchmark_group("diagnose_khepera_10min_50hz");
    g.sample_size(10);
    g.bench_function("clean", |b| {
        b.iter(|| diagnose(std::slice::from_ref(&clean), &VwPd, &settings).expect("runs"))
    });
    g.bench_function("dead_time", |b| {
        b.iter(|| diagnose(std::slice::from_ref(&delayed), &VwPd, &settings).expect("runs"))
    });
    g.finish();
}

criterion_group! {
    name = benches;
    // No plots: criterion's PDF plots need a system font this machine kind lacks.
    config = Criterion::default().without_plots();
    targets = bench
}
criterion_main!(benches);
