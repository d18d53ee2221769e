//! Identification that does not depend on an unstated stamping convention: recordings written
//! under each of the conventions (a)–(c) of `shared/data/RECORDING_FORMAT.md`, with their
//! metadata removed, identify as well as with it, and the report names the convention.
//!
//! These recordings come from wheelid's own simulator (eq. 2.19): they check the timing code
//! path. The proof on physics the model did not write is `tests/physics_identify.rs`.

use wheelid::identify::{IdentifySettings, identify};
use wheelid::models::WheelPd;
use wheelid::robots::effects::SampleJitter;
use wheelid::robots::{Excitation, RobotProfile, SimSettings, simulate_recording};
use wheelid::solvers::Ols;
use wheelid::timing::TimingSource;
use wheelid_core::{Recording, Timing, VelocitySampling};

/// A Khepera III drive (50 Hz, encoders: window averages ending at t, commands from t).
fn khepera(seed: u64, jitter: bool) -> (Recording, [f64; 6]) {
    let robot = RobotProfile::khepera3();
    let mut s = SimSettings {
        duration_s: 60.0,
        seed,
        ..SimSettings::default()
    };
    if jitter {
        s.effects.sample_jitter = Some(SampleJitter {
            std_s: 0.05 * robot.period_s,
        });
    }
    let exc = Excitation::random_multisine(seed, 0.1, 0.08, 1.5, 6.0).expect("excitation");
    (
        simulate_recording(&robot, &exc, &s).expect("simulates"),
        robot.theta,
    )
}

/// `rec` (window averages over [t_{k−1}, t_k], command from t_k) re-stamped as a host that
/// stamps the window's middle and sends the command at the window's start would have:
/// row j = (middle of [t_j, t_{j+1}], command sent at t_j, average over that window).
fn as_window_middle(rec: &Recording) -> Recording {
    let n = rec.len() - 1;
    let t: Vec<f64> = (0..n).map(|j| 0.5 * (rec.t[j] + rec.t[j + 1])).collect();
    let mut out = Recording::new(
        rec.source.clone(),
        t,
        rec.v_ref[..n].to_vec(),
        rec.w_ref[..n].to_vec(),
        rec.v[1..].to_vec(),
        rec.w[1..].to_vec(),
    )
    .expect("valid");
    out.set_timing(Timing::WindowMiddle);
    out
}

fn strip_timing(rec: &Recording) -> Recording {
    let mut r = rec.clone();
    r.meta
        .retain(|(k, _)| k != "timing" && k != "velocity_sampling");
    r
}

fn worst_error(theta: &[f64], truth: &[f64; 6]) -> f64 {
    [0, 1, 3, 5]
        .iter()
        .map(|&i| ((theta[i] - truth[i]) / truth[i]).abs())
        .fold(0.0, f64::max)
}

#[test]
fn every_convention_identifies_without_metadata_and_is_named() {
    for jitter in [false, true] {
        let (b, truth) = khepera(3, jitter);
        let mut exact_settings = SimSettings {
            duration_s: 60.0,
            seed: 3,
            measurement_noise: false,
            ..SimSettings::default()
        };
        if jitter {
            exact_settings.effects.sample_jitter = Some(SampleJitter { std_s: 0.001 });
        }
        let exc = Excitation::random_multisine(3, 0.1, 0.08, 1.5, 6.0).expect("excitation");
        let a = simulate_recording(&RobotProfile::khepera3(), &exc, &exact_settings)
            .expect("simulates");
        let c = as_window_middle(&b);
        for (rec, want) in [
            (a, Timing::Instant),
            (b, Timing::WindowEnd),
            (c, Timing::WindowMiddle),
        ] {
            let stated = identify(
                std::slice::from_ref(&rec),
                &WheelPd,
                &Ols::default(),
                &IdentifySettings::default(),
            )
            .expect("identifies");
            let bare = strip_timing(&rec);
            let id = identify(
                &[bare],
                &WheelPd,
                &Ols::default(),
                &IdentifySettings::default(),
            )
            .expect("identifies");
            let t = id.timing.as_ref().expect("output error ran");
            eprintln!(
                "{:?} jitter {jitter}: stated {:.3} %, bare {:.3} %; {}",
                want,
                100.0 * worst_error(&stated.theta, &truth),
                100.0 * worst_error(&id.theta, &truth),
                t.summary
            );
            assert_eq!(
                stated.timing.as_ref().map(|t| t.source),
                Some(TimingSource::Stated)
            );
            assert!(worst_error(&stated.theta, &truth) < 0.01);
            assert_eq!(t.source, TimingSource::Estimated);
            assert_eq!(t.likely, Some(want), "{}", t.summary);
            assert_eq!(
                t.sampling == VelocitySampling::Instant,
                want == Timing::Instant
            );
            assert!(
                worst_error(&id.theta, &truth) < 0.01,
                "{want:?}: θ {:?} vs {truth:?}",
                id.theta
            );
        }
    }
}
