//! Identification proven on physics the model did not write: recordings from the rigid-body
//! backend (`wheelid::robots::physics`, rapier3d-f64 — motors, PD loops, wheel contacts, a
//! caster) against the θ that `wheelid_models::physical` derives from the same constants.
//!
//! 1. Noise-free runs (instants, no encoders, no jitter) check the maps and the engine set-up:
//!    θ1, θ2, θ4, θ6 within 1 % of the map.
//! 2. Recordings with encoders, random multisines, each stamping convention (a)–(c), with and
//!    without ±10 % host jitter, and their timing metadata removed: the default `identify`
//!    gives θ1, θ2, θ4, θ6 within 1 % and names the convention.
//!
//! CI runs one seed per case; `scripts/physics_accuracy.sh` runs more.

use wheelid::identify::{IdentifySettings, identify};
use wheelid::models;
use wheelid::robots::Excitation;
use wheelid::robots::physics::{PhysicalProfile, PhysicsSettings, simulate_physics_recording};
use wheelid::solvers::Ols;
use wheelid_core::{Recording, Timing};

/// Seeds per case (env `WHEELID_PHYSICS_SEEDS`, default 1).
fn seeds() -> u64 {
    std::env::var("WHEELID_PHYSICS_SEEDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1)
}

/// A random multisine up to about the robot's bandwidth, inside its speed limits.
fn excitation(p: &PhysicalProfile, seed: u64) -> Excitation {
    p.random_multisine(seed).expect("excitation")
}

fn duration(p: &PhysicalProfile) -> f64 {
    if p.period_s >= 0.05 { 150.0 } else { 60.0 }
}

fn errors(theta: &[f64], truth: &[f64; 6]) -> [f64; 4] {
    [0, 1, 3, 5].map(|i| 100.0 * (theta[i] - truth[i]) / truth[i])
}

fn identify_default(rec: &Recording, model: &str) -> wheelid::identify::Identification {
    let m = models::by_name(model).expect("model");
    identify(
        std::slice::from_ref(rec),
        m.as_ref(),
        &Ols::default(),
        &IdentifySettings::default(),
    )
    .expect("identifies")
}

#[test]
fn noise_free_physics_identifies_the_maps_theta_within_one_percent() {
    for (name, tol) in [("khepera3", 1.0), ("pioneer3dx", 1.0), ("burger", 1.0)] {
        let p = PhysicalProfile::by_name(name).expect("profile");
        let s = PhysicsSettings {
            duration_s: duration(&p),
            seed: 1,
            timing: Timing::Instant,
            encoders: false,
            ..PhysicsSettings::default()
        };
        let rec = simulate_physics_recording(&p, &excitation(&p, 1), &s).expect("simulates");
        let id = identify_default(&rec, p.model_name());
        let truth = p.theta();
        let e = errors(&id.theta, &truth);
        eprintln!(
            "{name}: map θ {truth:.5?}\n   identified {:.5?}\n   error θ1 θ2 θ4 θ6 % {e:.3?}",
            id.theta
        );
        for (x, which) in e.iter().zip(["θ1", "θ2", "θ4", "θ6"]) {
            assert!(x.abs() < tol, "{name}: {which} off by {x:.3} %");
        }
    }
}

fn strip_timing(rec: &Recording) -> Recording {
    let mut r = rec.clone();
    r.meta
        .retain(|(k, _)| k != "timing" && k != "velocity_sampling");
    r
}

/// One profile under every convention, with and without ±10 % jitter, encoders on, no timing
/// metadata: θ1, θ2, θ4, θ6 within `tol_percent` of the map, and the convention named.
fn conventions_identify(name: &str, tol_percent: f64) {
    let p = PhysicalProfile::by_name(name).expect("profile");
    let truth = p.theta();
    for seed in 1..=seeds() {
        for jitter in [0.0, 0.1] {
            for timing in Timing::ALL {
                let s = PhysicsSettings {
                    duration_s: duration(&p),
                    seed: 10 + seed,
                    timing,
                    jitter,
                    encoders: true,
                    ..PhysicsSettings::default()
                };
                let rec = simulate_physics_recording(&p, &excitation(&p, 10 + seed), &s)
                    .expect("simulates");
                let id = identify_default(&strip_timing(&rec), p.model_name());
                let e = errors(&id.theta, &truth);
                let t = id.timing.as_ref().expect("output error ran");
                eprintln!(
                    "{name} seed {seed} {:<13} jitter {jitter:.1}: θ1 θ2 θ4 θ6 error % {e:.3?}; {}",
                    timing.name(),
                    t.summary
                );
                for (x, which) in e.iter().zip(["θ1", "θ2", "θ4", "θ6"]) {
                    assert!(
                        x.abs() < tol_percent,
                        "{name} {timing:?} jitter {jitter}: {which} off by {x:.3} %"
                    );
                }
                assert_eq!(t.likely, Some(timing), "{name}: {}", t.summary);
            }
        }
    }
}

#[test]
fn khepera_identifies_under_every_convention_without_metadata() {
    conventions_identify("khepera3", 1.0);
}

#[test]
fn pioneer_identifies_under_every_convention_without_metadata() {
    conventions_identify("pioneer3dx", 1.0);
}

#[test]
fn burger_identifies_under_every_convention_without_metadata() {
    conventions_identify("burger", 1.0);
}
