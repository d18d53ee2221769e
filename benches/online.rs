//! Criterion benchmark of the online estimator (issue 18, `wheelid::online`): one update per
//! sample — the prefilter, two 4-parameter RLS steps with change detection (the split free:
//! instruments after the warm-up); with the split fixed, two 3-parameter ones, by
//! instruments or (the default) the output-error form with its RK4 simulation, and the
//! latter with the stamps jittered by ± 10 % of the period (the jitter correction's
//! exponentials) — and the same with θ̂ and its standard errors read after
//! every sample, over a 10-minute 50 Hz recording of the
//! simulated Khepera III (30,001 samples). Criterion reports the time per recording; per
//! sample it is that over 30,001 (goal ≤ 200 ns).
//!
//! Run: `cargo bench --bench online`.

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use wheelid::online::{OnlineForm, OnlineSettings, OnlineTheta, Split};
use wheelid::robots::{RobotProfile, SimSettings, simulate_recording};

fn bench(c: &mut Criterion) {
    let robot = RobotProfile::khepera3();
    let exc = robot.multisine(1).expect("valid multisine");
    let s = SimSettings {
        duration_s: 600.0,
        ..SimSettings::default()
    };
    let rec = simulate_recording(&robot, &exc, &s).expect("simulates");
    let dt = rec.t[1] - rec.t[0];
    let mut g = c.benchmark_group("online");
    g.throughput(Throughput::Elements(rec.len() as u64));
    g.bench_function("update per recording", |b| {
        b.iter(|| {
            let mut est = OnlineTheta::new(OnlineSettings::default(), dt).expect("settings");
            for k in 0..rec.len() {
                est.update(rec.t[k], rec.v_ref[k], rec.w_ref[k], rec.v[k], rec.w[k]);
            }
            est.theta()
        })
    });
    // With the split of u_k and u_{k−1} fixed by the stamping (as `wheelid run` sets it):
    // three-parameter regressions; the output-error form (the default) or instruments.
    let fixed = OnlineSettings {
        split: Some(Split::WindowAverage),
        ..OnlineSettings::default()
    };
    let instruments = OnlineSettings {
        form: OnlineForm::InstrumentalVariables,
        ..fixed
    };
    let jittered: Vec<f64> = (0..rec.len())
        .map(|k| rec.t[k] + 0.1 * dt * (1.7 * k as f64).sin())
        .collect();
    for (name, settings, t) in [
        ("update per recording, split fixed", fixed, &rec.t),
        (
            "update per recording, split fixed, instruments",
            instruments,
            &rec.t,
        ),
        (
            "update per recording, split fixed, stamps jittered",
            fixed,
            &jittered,
        ),
    ] {
        g.bench_function(name, |b| {
            b.iter(|| {
                let mut est = OnlineTheta::new(settings, dt).expect("settings");
                for (k, &stamp) in t.iter().enumerate() {
                    est.update(stamp, rec.v_ref[k], rec.w_ref[k], rec.v[k], rec.w[k]);
                }
                est.theta()
            })
        });
    }
    g.bench_function("update and read per recording", |b| {
        b.iter(|| {
            let mut est = OnlineTheta::new(OnlineSettings::default(), dt).expect("settings");
            let mut sum = 0.0;
            for k in 0..rec.len() {
                est.update(rec.t[k], rec.v_ref[k], rec.w_ref[k], rec.v[k], rec.w[k]);
                sum += est.theta()[0] + est.std_err()[0];
            }
            sum
        })
    });
    g.finish();
}

criterion_group! {
    name = benches;
    // No plots: plotters needs fonts a CI machine lacks.
    config = Criterion::default().without_plots();
    targets = bench
}
criterion_main!(benches);
