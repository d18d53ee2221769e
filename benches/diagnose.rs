//! Criterion benchmark of the mismatch diagnosis (issue 5) on a 10-minute, 50 Hz recording of
//! the simulated Khepera III (30,001 samples, random multisine to 2 Hz, encoder noise):
//! * `clean`: the recording as the model describes it (fit, tests, fingerprints: nothing to
//!   add);
//! * `dead_time`: the same robot with a concealed 80 ms dead time (found, fitted, accepted,
//!   then a second round of the search);
//! * group `…_each_effect`: the other candidates concealed one at a time, and two pairs, at
//!   magnitudes inside the ranges of `tests/diagnose.rs`; each case is diagnosed once before
//!   it is timed and must name exactly its effects (parameters within 20 % when measured for
//!   the README).
//!
//! The settings are the defaults: the search screens and fits the candidates on a 3 600-sample
//! excerpt of the drive and refits the model found on all of it
//! (`DiagnoseSettings::search_samples`).
//!
//! Run: `cargo bench --bench diagnose` (`-- dead_time` for the case alone).

use criterion::{Criterion, criterion_group, criterion_main};
use wheelid::core::Recording;
use wheelid::diagnose::{DiagnoseSettings, diagnose};
use wheelid::models::VwPd;
use wheelid::robots::effects::{
    AccelerationLimit, CoulombFriction, Effects, GainDrift, InputDelay, PayloadChange, Slip,
    VelocitySaturation, WheelAsymmetry,
};
use wheelid::robots::{RobotProfile, SimSettings, simulate_recording};

fn recording(effects: Effects) -> Recording {
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

    // Magnitudes: a quarter of the robot's v_max, w_max is the multisine's amplitude (va, wa).
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
    let cases: Vec<(&str, Effects)> = vec![
        (
            "acceleration_limit",
            Effects {
                acceleration_limit: Some(accel),
                ..Effects::default()
            },
        ),
        (
            "velocity_saturation",
            Effects {
                velocity_saturation: Some(saturation),
                ..Effects::default()
            },
        ),
        (
            "coulomb_friction",
            Effects {
                coulomb_friction: Some(CoulombFriction {
                    v_coulomb: 0.08 * va,
                    w_coulomb: 0.08 * wa,
                }),
                ..Effects::default()
            },
        ),
        (
            "wheel_asymmetry",
            Effects {
                wheel_asymmetry: Some(asymmetry),
                ..Effects::default()
            },
        ),
        (
            "payload_change",
            Effects {
                payload_change: Some(PayloadChange::scaled(300.0, robot.theta, 1.5)),
                ..Effects::default()
            },
        ),
        (
            "gain_drift",
            Effects {
                gain_drift: Some(GainDrift {
                    rate_per_s: -0.3 / 600.0,
                }),
                ..Effects::default()
            },
        ),
        (
            "slip",
            Effects {
                slip: Some(Slip { k_v: 0.3, k_w: 0.3 }),
                ..Effects::default()
            },
        ),
        (
            "dead_time+saturation",
            Effects {
                input_delay: Some(delay),
                velocity_saturation: Some(saturation),
                ..Effects::default()
            },
        ),
        (
            "acceleration_limit+asymmetry",
            Effects {
                acceleration_limit: Some(accel),
                wheel_asymmetry: Some(asymmetry),
                ..Effects::default()
            },
        ),
    ];
    let mut g = c.benchmark_group("diagnose_khepera_10min_50hz_each_effect");
    g.sample_size(10);
    for (name, effects) in cases {
        let rec = recording(effects);
        let d = diagnose(std::slice::from_ref(&rec), &VwPd, &settings).expect("runs");
        let mut found: Vec<&str> = d.findings.iter().map(|f| f.effect.as_str()).collect();
        found.sort_unstable();
        let mut want: Vec<&str> = name
            .split('+')
            .map(|n| match n {
                "dead_time" => "input_delay",
                "saturation" => "velocity_saturation",
                "asymmetry" => "wheel_asymmetry",
                other => other,
            })
            .collect();
        want.sort_unstable();
        assert_eq!(found, want, "{name}: the diagnosis must name its effects");
        g.bench_function(name, |b| {
            b.iter(|| diagnose(std::slice::from_ref(&rec), &VwPd, &settings).expect("runs"))
        });
    }
    g.finish();
}

/// The residual–command independence tests of one `locate` call on the clean case's
/// validation samples: 2 residuals × 2 commands, 12,000 samples (the 2 validation blocks of 5
/// of the 10-minute recording), lags ±100 (±2 s at 50 Hz).
fn independence(c: &mut Criterion) {
    let rec = recording(Effects::default());
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
