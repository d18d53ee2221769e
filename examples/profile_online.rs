//! The cases of `benches/online.rs` for a fixed number of updates, to count instructions
//! (`valgrind --tool=callgrind --toggle-collect='profile_online::run*'`: the loop alone), and a
//! digest of every update's θ̂, standard errors and alarms over more cases, to compare builds
//! bit for bit (wall time on a shared machine is noise; the benchmark is `cargo bench --bench
//! online`).
//!
//! Run: `cargo run --release --example profile_online -- <case> [recordings]` with `<case>` one
//! of `default`, `fixed`, `instruments`, `jittered` (the benchmark's), `instruments-jittered`,
//! or `digest`.

use wheelid::core::Recording;
use wheelid::online::{OnlineForm, OnlineSettings, OnlineTheta, Split};
use wheelid::robots::{RobotProfile, SimSettings, simulate_recording};

/// The benchmark's recording: the simulated Khepera III, 10 minutes at 50 Hz.
fn recording() -> Recording {
    let robot = RobotProfile::khepera3();
    let exc = robot.multisine(1).expect("valid multisine");
    let s = SimSettings {
        duration_s: 600.0,
        ..SimSettings::default()
    };
    simulate_recording(&robot, &exc, &s).expect("simulates")
}

/// The benchmark's jittered stamps (± 10 % of the period).
fn jittered(rec: &Recording, dt: f64) -> Vec<f64> {
    (0..rec.len())
        .map(|k| rec.t[k] + 0.1 * dt * (1.7 * k as f64).sin())
        .collect()
}

/// One pass over the recording per repetition, updates only (what callgrind counts).
#[inline(never)]
fn run(settings: OnlineSettings, dt: f64, rec: &Recording, t: &[f64], reps: usize) -> f64 {
    let mut sum = 0.0;
    for _ in 0..reps {
        let mut est = OnlineTheta::new(settings, dt).expect("settings");
        for (k, &stamp) in t.iter().enumerate() {
            est.update(stamp, rec.v_ref[k], rec.w_ref[k], rec.v[k], rec.w[k]);
        }
        sum += est.theta()[0];
    }
    sum
}

/// FNV-1a over the bits of every update's θ̂, standard errors and alarms.
fn digest(settings: OnlineSettings, dt: f64, rec: &Recording, t: &[f64]) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325_u64;
    let mut eat = |x: u64| h = (h ^ x).wrapping_mul(0x0100_0000_01b3);
    let mut est = OnlineTheta::new(settings, dt).expect("settings");
    for (k, &stamp) in t.iter().enumerate() {
        let up = est.update(stamp, rec.v_ref[k], rec.w_ref[k], rec.v[k], rec.w[k]);
        est.theta().iter().for_each(|x| eat(x.to_bits()));
        est.std_err().iter().for_each(|x| eat(x.to_bits()));
        eat(u64::from(up.change[0]) | u64::from(up.change[1]) << 1);
    }
    h
}

fn main() {
    let mut args = std::env::args().skip(1);
    let case = args.next().unwrap_or_else(|| "digest".into());
    let reps: usize = args.next().map_or(1, |r| r.parse().expect("a count"));
    let rec = recording();
    let dt = rec.t[1] - rec.t[0];
    let jit = jittered(&rec, dt);
    let fixed = |split, form| OnlineSettings {
        split: Some(split),
        form,
        ..OnlineSettings::default()
    };
    let (oe, iv) = (OnlineForm::OutputError, OnlineForm::InstrumentalVariables);
    let (wa, sum) = (Split::WindowAverage, |x: f64| println!("{x}"));
    match case.as_str() {
        "default" => sum(run(OnlineSettings::default(), dt, &rec, &rec.t, reps)),
        "fixed" => sum(run(fixed(wa, oe), dt, &rec, &rec.t, reps)),
        "instruments" => sum(run(fixed(wa, iv), dt, &rec, &rec.t, reps)),
        "jittered" => sum(run(fixed(wa, oe), dt, &rec, &jit, reps)),
        "instruments-jittered" => sum(run(fixed(wa, iv), dt, &rec, &jit, reps)),
        "digest" => {
            for form in [oe, iv, OnlineForm::LeastSquares] {
                for split in [Split::Free, Split::Instant, wa] {
                    for (stamps, t) in [("uniform", &rec.t), ("jittered", &jit)] {
                        let d = digest(fixed(split, form), dt, &rec, t);
                        println!("{form:?} {split:?} {stamps}: {d:016x}");
                    }
                }
            }
        }
        other => panic!("unknown case {other}"),
    }
}
