//! Criterion benchmark: 120 s of the Khepera III-like robot of the rigid-body backend
//! (`wheelid_robots::physics`, rapier3d-f64) at its physics step (0.25 ms: 480,000 steps of
//! chassis, two wheels on revolute joints, a caster, motors and wheel PD loops), 50 Hz host with
//! encoders, a random multisine. For scale: an independent MuJoCo model of the same robot runs
//! 120 s in 3.5–4 s on one core. Measured: median 6.69 s (95 % CI 6.51–6.84 s) on a 2-core
//! machine with another build running (10.6 s with the earlier 3 kHz contacts); rapier's
//! joint and contact solver is ~60 % of it (perf). The same robot at h = 0.5 ms identifies as
//! well (θ within 0.011 % of the map) at half the cost.
//!
//! Run: `cargo bench --bench physics`.

use criterion::{Criterion, criterion_group, criterion_main};
use wheelid::robots::Excitation;
use wheelid::robots::physics::{PhysicalProfile, PhysicsSettings, simulate_physics_recording};

fn bench_physics(c: &mut Criterion) {
    let p = PhysicalProfile::khepera3();
    let exc = Excitation::random_multisine(1, 0.05, 0.15, 2.1, 6.0).expect("excitation");
    let s = PhysicsSettings {
        duration_s: 120.0,
        ..PhysicsSettings::default()
    };
    let mut g = c.benchmark_group("physics");
    g.sample_size(10);
    g.bench_function("khepera3_120s_at_0.25ms", |b| {
        b.iter(|| simulate_physics_recording(&p, &exc, &s).expect("simulates"))
    });
    g.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default().without_plots();
    targets = bench_physics
}
criterion_main!(benches);
