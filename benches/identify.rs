//! Criterion benchmark: `identify` (condition → regress → solve → free-run validation) on a
//! 1,000,000-row recording of the simulated Pioneer 3-DX (10 Hz, thesis excitation, encoder
//! noise), least squares (OLS) with the default cut-off rule — the thesis's estimator; the
//! output-error and IV estimators are timed in `benches/estimators.rs`.
//!
//! Run: `cargo bench --bench identify`. The same work in Python (scipy butter + filtfilt,
//! numpy gradient, lstsq) is `benches/identify_scipy.py`.

use criterion::{Criterion, criterion_group, criterion_main};
use wheelid::identify::{IdentifySettings, identify};
use wheelid::models::VwPd;
use wheelid::robots::{Excitation, RobotProfile, SimSettings, simulate_recording};
use wheelid::solvers::Ols;

fn bench_identify(c: &mut Criterion) {
    let robot = RobotProfile::pioneer3dx();
    let settings = SimSettings {
        duration_s: 99_999.95,
        substeps: 4,
        ..SimSettings::default()
    };
    let rec =
        simulate_recording(&robot, &Excitation::thesis_pioneer(), &settings).expect("simulates");
    assert_eq!(rec.len(), 1_000_000);
    if let Ok(path) = std::env::var("WHEELID_BENCH_CSV") {
        rec.write_csv(&path)
            .expect("writes the recording for the scipy comparison");
    }
    let ls = IdentifySettings {
        estimator: "ls".into(),
        ..IdentifySettings::default()
    };
    let mut group = c.benchmark_group("identify");
    group.sample_size(10);
    group.bench_function("vw-pd ols, 1e6 rows", |b| {
        b.iter(|| {
            identify(std::slice::from_ref(&rec), &VwPd, &Ols::default(), &ls).expect("identifies")
        })
    });
    group.finish();
}

criterion_group! {
    name = benches;
    // Criterion's HTML plots would use the workspace's plotters build, which has no system font.
    config = Criterion::default().without_plots();
    targets = bench_identify
}
criterion_main!(benches);
