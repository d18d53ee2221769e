//! Online identification (issue 18, `wheelid::online`) on physics the model did not write: the
//! rigid-body backend (rapier3d-f64), its recordings stamped as hosts stamp them (velocities
//! averaged over the period ending at the stamp, encoder ticks), against the θ its physical
//! map derives from the same constants and against the batch output-error answer.

use wheelid::identify::{IdentifySettings, identify};
use wheelid::models;
use wheelid::online::{OnlineSettings, OnlineTheta, Split};
use wheelid::robots::physics::{
    Payload, PhysicalProfile, PhysicsEffects, PhysicsSettings, simulate_physics_recording,
};
use wheelid::solvers::Ols;
use wheelid_core::{Recording, Timing};

fn record(p: &PhysicalProfile, seed: u64, duration_s: f64, effects: PhysicsEffects) -> Recording {
    record_jittered(p, seed, duration_s, effects, 0.0)
}

/// As [`record`], the host's sample instants jittered by up to ± `jitter` of the period.
fn record_jittered(
    p: &PhysicalProfile,
    seed: u64,
    duration_s: f64,
    effects: PhysicsEffects,
    jitter: f64,
) -> Recording {
    let s = PhysicsSettings {
        duration_s,
        seed,
        timing: Timing::WindowEnd,
        effects,
        jitter,
        ..PhysicsSettings::default()
    };
    simulate_physics_recording(p, &p.random_multisine(seed).expect("excitation"), &s)
        .expect("simulates")
}

/// The estimator run over `rec`, with θ̂ after every sample.
fn online(rec: &Recording, settings: OnlineSettings) -> (OnlineTheta, Vec<[f64; 6]>) {
    let dt = (rec.t[rec.len() - 1] - rec.t[0]) / (rec.len() - 1) as f64;
    let mut est = OnlineTheta::new(settings.for_timing(rec.timing()), dt).expect("settings");
    let path = (0..rec.len())
        .map(|k| {
            est.update(rec.t[k], rec.v_ref[k], rec.w_ref[k], rec.v[k], rec.w[k]);
            est.theta()
        })
        .collect();
    (est, path)
}

fn pct(a: f64, b: f64) -> f64 {
    100.0 * (a - b) / b
}

/// Both robots, one recording each: θ1, θ2, θ4, θ6 online within 1 % of the batch
/// output-error answer and of the physical map and within 1.96 of their standard errors of the
/// batch answer (the split of u_k and u_{k−1} fixed by the recording's stamping), and no
/// change alarm on a steady robot. Measured (seed 1, the output-error form): Pioneer-like
/// −0.07, +0.02, +0.13, −0.58 standard errors; Khepera-like +0.19, −0.23, −0.11, +0.09 (the
/// instruments: +0.11, +1.08, +0.49, −0.21 and +0.53, −0.02, −0.07, +0.06).
#[test]
fn online_theta_converges_to_the_batch_answer_on_physics() {
    for (name, duration) in [("pioneer3dx", 150.0), ("khepera3", 60.0)] {
        let p = PhysicalProfile::by_name(name).expect("profile");
        let rec = record(&p, 1, duration, PhysicsEffects::default());
        let model = models::by_name(p.model_name()).expect("model");
        let batch = identify(
            std::slice::from_ref(&rec),
            model.as_ref(),
            &Ols::default(),
            &IdentifySettings::default(),
        )
        .expect("identifies");
        let (est, _) = online(&rec, OnlineSettings::default());
        let (th, se) = (est.theta(), est.std_err());
        eprintln!(
            "{name}: map {:.5?}\n  batch {:.5?}\n  online {th:.5?}\n  ± {se:.5?}, alarms {:?}",
            p.theta(),
            batch.theta,
            est.changes()
        );
        for i in [0, 1, 3, 5] {
            let (to_batch, to_map) = (pct(th[i], batch.theta[i]), pct(th[i], p.theta()[i]));
            let z = (th[i] - batch.theta[i]) / se[i];
            eprintln!(
                "  θ{}: {to_batch:+.3} % of batch, {to_map:+.3} % of map, {z:+.2} standard \
                 errors from batch",
                i + 1,
            );
            assert!(
                to_batch.abs() < 1.0 && to_map.abs() < 1.0,
                "{name} θ{}",
                i + 1
            );
            // Within its 95 % interval of the batch answer, on both robots, with the split of
            // u_k and u_{k−1} fixed by the stamping (free, the Pioneer-like robot's θ1 lands
            // 0.28 %, 7–50 standard errors, from the batch fit: README, online section).
            assert!(z.abs() < 1.96, "{name} θ{}: {z:+.2} standard errors", i + 1);
        }
        assert_eq!(
            est.changes(),
            [0, 0],
            "{name}: a steady robot raised an alarm"
        );
    }
}

/// The batch output-error answer and the online estimate's distance from it in its standard
/// errors for θ1, θ2, θ4, θ6, on one recording.
fn z_from_batch(p: &PhysicalProfile, rec: &Recording) -> [f64; 4] {
    let model = models::by_name(p.model_name()).expect("model");
    let batch = identify(
        std::slice::from_ref(rec),
        model.as_ref(),
        &Ols::default(),
        &IdentifySettings::default(),
    )
    .expect("identifies");
    let (est, _) = online(rec, OnlineSettings::default());
    let (th, se) = (est.theta(), est.std_err());
    eprintln!(
        "  θ1, θ2, θ4, θ6 {:+.3?} % of batch, alarms {:?}",
        [0, 1, 3, 5].map(|i| pct(th[i], batch.theta[i])),
        est.changes()
    );
    [0, 1, 3, 5].map(|i| (th[i] - batch.theta[i]) / se[i])
}

/// Seeds of the jitter proof: `WHEELID_ONLINE_SEEDS` of them (default 3) from
/// `WHEELID_ONLINE_FIRST_SEED` (default 41).
fn jitter_seeds() -> std::ops::Range<u64> {
    let var = |k: &str, d: u64| {
        std::env::var(k)
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or(d)
    };
    let first = var("WHEELID_ONLINE_FIRST_SEED", 41);
    first..first + var("WHEELID_ONLINE_SEEDS", 3)
}

/// Host jitter of ± 10 % of the period (the batch fit simulates at the recording's stamps):
/// the online θ1, θ2, θ4, θ6 within 1.96 of their standard errors of the batch answer on both
/// robots. `scripts/online_spread.sh` runs more seeds: over 41–60 (never looked at while
/// building the jitter correction and the output-error form, tuned on 1–10) the worst |z| is
/// 0.53 (Pioneer-like) and 0.51 (Khepera-like); the instruments read 2.13 and 0.66 there, and
/// before the jitter correction 2.44 and 4.39 on 1–10.
#[test]
fn online_theta_converges_to_the_batch_answer_under_host_jitter() {
    let mut worst_of = Vec::new();
    for (name, duration) in [("pioneer3dx", 150.0), ("khepera3", 60.0)] {
        let p = PhysicalProfile::by_name(name).expect("profile");
        let mut worst = 0.0f64;
        for seed in jitter_seeds() {
            let rec = record_jittered(&p, seed, duration, PhysicsEffects::default(), 0.1);
            let z = z_from_batch(&p, &rec);
            eprintln!("{name} seed {seed}: {z:+.2?} standard errors from batch");
            worst = z.iter().fold(worst, |w, z| w.max(z.abs()));
        }
        eprintln!(
            "{name}: worst |z| {worst:.2} over seeds {:?}",
            jitter_seeds()
        );
        worst_of.push((name, worst));
    }
    for (name, worst) in worst_of {
        assert!(worst < 1.96, "{name}: worst |z| {worst:.2}");
    }
}

/// The Pioneer-like robot with 60 % of its mass set down 1.2 b ahead of the axle at 80 s of
/// 150 s: the change is detected and θ1, θ2 are within 5 % of the loaded robot's map 5 s after
/// the payload is down (and stay there to the end).
#[test]
fn online_theta_tracks_a_payload_step_within_5_s() {
    let p = PhysicalProfile::pioneer3dx();
    let payload = Payload {
        mass_kg: 0.6 * p.m,
        at_s: 80.0,
        x_m: 0.5 * p.caster_x,
        size_m: p.d / 3.0,
    };
    let effects = PhysicsEffects {
        payload: Some(payload),
        ..PhysicsEffects::default()
    };
    let rec = record(&p, 2, 150.0, effects);
    let (before, after) = (p.theta(), payload.loaded(&p).theta());
    let (est, path) = online(&rec, OnlineSettings::default());
    let at = |t: f64| rec.t.iter().position(|&x| x >= t).expect("in the run");
    eprintln!(
        "θ before {before:.4?}, after {after:.4?}\n  online at 79 s {:.4?}\n  at 85 s {:.4?}\n  \
         at the end {:.4?}, alarms {:?}",
        path[at(79.0)],
        path[at(85.0)],
        est.theta(),
        est.changes()
    );
    // The first sample from which θ1 and θ2 stay within 5 % of the loaded map.
    let near = |k: usize| (0..2).all(|i| pct(path[k][i], after[i]).abs() < 5.0);
    let settled = (at(payload.at_s)..rec.len())
        .rev()
        .take_while(|&k| near(k))
        .last()
        .expect("within 5 % at the end");
    let delay = rec.t[settled] - payload.at_s;
    eprintln!("  θ1, θ2 within 5 % of the loaded map {delay:.2} s after the payload is down");
    for i in [0, 1] {
        assert!(
            pct(path[at(79.0)][i], before[i]).abs() < 2.0,
            "θ{} before",
            i + 1
        );
    }
    assert!(delay <= 5.0, "{delay} s");
    assert!(est.changes().iter().any(|&c| c >= 1));
}

/// Errors in variables on physics: 5 mm/s of white noise on each wheel's speed (added to the
/// rigid-body Khepera-like robot's recordings, three seeds). Recursive least squares puts θ1
/// 4.8–7.9 % high; with the auxiliary model's instruments, and with the split fixed in the
/// output-error form (the default), θ1 is within 1 % of the map and every one of θ1, θ2, θ4, θ6
/// within 2.5 of its standard errors. (Seeds 1, 11, 12 were the ones looked at while building
/// the instruments: tuning data.)
#[test]
fn instruments_remove_the_noise_bias_on_physics() {
    use wheelid::online::OnlineForm;
    let p = PhysicalProfile::khepera3();
    for seed in [1u64, 11, 12] {
        let mut rec = record(&p, seed, 60.0, PhysicsEffects::default());
        let mut s = seed.wrapping_mul(2_654_435_761).max(1);
        let mut uniform = move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            ((s >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0) * 3f64.sqrt()
        };
        for k in 0..rec.len() {
            let (left, right) = (0.005 * uniform(), 0.005 * uniform());
            rec.v[k] += 0.5 * (left + right);
            rec.w[k] += (right - left) / p.d;
        }
        let run = |form, split| {
            online(
                &rec,
                OnlineSettings {
                    form,
                    split,
                    ..OnlineSettings::default()
                },
            )
            .0
        };
        let map = p.theta();
        // The split free (as for a recording of unknown stamping), then fixed by the stamping;
        // with it fixed, the output-error form too (free, it runs the instruments).
        for (split, ls_bias) in [(Some(Split::Free), 3.0), (None, 0.0)] {
            let ls = run(OnlineForm::LeastSquares, split);
            assert!(pct(ls.theta()[0], map[0]) > ls_bias, "the bias is there");
            let forms = match split {
                None => &[OnlineForm::InstrumentalVariables, OnlineForm::OutputError][..],
                Some(_) => &[OnlineForm::InstrumentalVariables][..],
            };
            for &form in forms {
                let est = run(form, split);
                let (th, se) = (est.theta(), est.std_err());
                eprintln!(
                    "seed {seed}, split {split:?}: θ1 least squares {:+.2} %, {form:?} {:+.2} % \
                     of the map",
                    pct(ls.theta()[0], map[0]),
                    pct(th[0], map[0])
                );
                assert!(pct(th[0], map[0]).abs() < 1.0, "seed {seed}: θ1 {}", th[0]);
                for i in [0, 1, 3, 5] {
                    let z = (th[i] - map[i]) / se[i];
                    eprintln!("  θ{}: {z:+.2} standard errors from the map", i + 1);
                    assert!(
                        z.abs() < 2.5,
                        "seed {seed} {form:?} θ{}: {z:+.2} standard errors",
                        i + 1
                    );
                }
                assert_eq!(est.changes(), [0, 0], "seed {seed} {form:?}");
            }
        }
    }
}
