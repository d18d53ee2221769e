//! Criterion benchmark of the mismatch diagnosis (issue 5) on a 10-minute, 50 Hz recording of
//! the simulated Khepera III (30,001 samples, random multisine to 2 Hz, encoder noise):
//! * `clean`: the recording as the model describes it (fit, tests, fingerprints: nothing to
//!   add);
//! * `dead_time`: the same robot with a concealed 80 ms dead time (found, fitted, accepted,
//!   then a second round of the search);
//! * group `…_each_effect`: the other candidates concealed one at a time, and two pairs, at
//!   magnitudes inside the ranges of `tests/diagnose.rs`; each case is diagnosed once before
//!   it is timed and must name exactly its effects (parameters within 20 % when measured for
//!   the README). The cases live in `support/diagnose_cases.rs`, which
//!   `examples/profile_diagnose.rs` shares.
//!
//! The settings are the defaults: the search screens and fits the candidates on a 3 600-sample
//! excerpt of the drive and refits the model found on all of it
//! (`DiagnoseSettings::search_samples`).
//!
//! Run: `cargo bench --bench diagnose` (`-- dead_time` for the case alone).

use criterion::{Criterion, criterion_group, criterion_main};
use wheelid::diagnose::{DiagnoseSettings, diagnose};
use wheelid::models::VwPd;

#[path = "support/diagnose_cases.rs"]
mod diagnose_cases;
use diagnose_cases::{cases, expected, recording};

fn bench(c: &mut Criterion) {
    let settings = DiagnoseSettings::default();
    let all = cases();
    // `clean` and `dead_time` in one group, the other cases in another (their names kept).
    let (first, rest) = all.split_at(2);
    for (group, cases) in [
        ("diagnose_khepera_10min_50hz", first),
        ("diagnose_khepera_10min_50hz_each_effect", rest),
    ] {
        let mut g = c.benchmark_group(group);
        g.sample_size(10);
        for (name, effects) in cases {
            let rec = recording(effects.clone());
            let d = diagnose(std::slice::from_ref(&rec), &VwPd, &settings).expect("runs");
            let mut found: Vec<&str> = d.findings.iter().map(|f| f.effect.as_str()).collect();
            found.sort_unstable();
            assert_eq!(
                found,
                expected(name),
                "{name}: the diagnosis must name its effects"
            );
            g.bench_function(*name, |b| {
                b.iter(|| diagnose(std::slice::from_ref(&rec), &VwPd, &settings).expect("runs"))
            });
        }
        g.finish();
    }
}

/// The residual–command independence tests of one `locate` call on the clean case's
/// validation samples: 2 residuals × 2 commands, 12,000 samples (the 2 validation blocks of 5
/// of the 10-minute recording), lags ±100 (±2 s at 50 Hz).
fn independence(c: &mut Criterion) {
    let rec = recording(wheelid::robots::effects::Effects::default());
    let n = 12_000;
    let (v, w) = (&rec.v[..n], &rec.w[..n]);
    // A stand-in residual: the measurement less a one-sample-late copy of itself.
    let ev: Vec<f64> = (1..n).map(|k| v[k] - v[k - 1]).collect();
    let ew: Vec<f64> = (1..n).map(|k| w[k] - w[k - 1]).collect();
    let (vr, wr) = (&rec.v_ref[1..n], &rec.w_ref[1..n]);
    c.bench_function("residual_independence_2x2_12000_samples_lags_100", |b| {
        b.iter(|| wheelid::core::residual::independence_all(&[&ev, &ew], &[vr, wr], 100))
    });
}

criterion_group! {
    name = benches;
    // No plots: criterion's PDF plots need a system font this machine kind lacks.
    config = Criterion::default().without_plots();
    targets = independence, bench
}
criterion_main!(benches);
