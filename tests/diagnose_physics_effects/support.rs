//! What the tests of this binary share: recordings of the rigid-body robot with effects
//! realised where they act, their diagnosis, and assertions on what it names.

pub use wheelid::diagnose::{DiagnoseSettings, Diagnosis, diagnose};
pub use wheelid::robots::physics::{
    Controller, PhysicalProfile, PhysicsSettings, simulate_physics_recording,
};

/// 60 s of `p` under a random multisine (seeded), with `effects` applied by `tweak`, diagnosed
/// with the model its controller implies.
pub fn diagnosed(
    p: &PhysicalProfile,
    seed: u64,
    tweak: impl Fn(&mut PhysicsSettings),
) -> Diagnosis {
    let mut s = PhysicsSettings {
        duration_s: 60.0,
        seed,
        ..PhysicsSettings::default()
    };
    tweak(&mut s);
    let e = p.random_multisine(seed).expect("excitation");
    let rec = simulate_physics_recording(p, &e, &s).expect("runs");
    let model = wheelid::models::by_name(p.model_name()).expect("model");
    diagnose(&[rec], model.as_ref(), &DiagnoseSettings::default()).expect("diagnoses")
}

/// The diagnosis of one recording with the default settings and the names it gives, sorted.
pub fn diagnosed_named(
    rec: &wheelid::core::Recording,
    model: &dyn wheelid::core::RegressorModel,
) -> (Diagnosis, Vec<String>) {
    let d = diagnose(
        std::slice::from_ref(rec),
        model,
        &DiagnoseSettings::default(),
    )
    .expect("diagnoses");
    let mut named: Vec<String> = d.findings.iter().map(|f| f.effect.clone()).collect();
    named.sort();
    (d, named)
}

/// The Pioneer-like robot's recording of the physics harness's seed `seed` (its random
/// multisine, the default 120 s and window-end stamps, the chassis's true heading) with the
/// effects `tweak` sets, and the model its controller implies.
pub fn pioneer_recording(
    seed: u64,
    tweak: impl Fn(&mut PhysicsSettings),
) -> (
    wheelid::core::Recording,
    Box<dyn wheelid::core::RegressorModel>,
) {
    let p = PhysicalProfile::pioneer3dx();
    let mut s = PhysicsSettings {
        seed,
        ..PhysicsSettings::default()
    };
    tweak(&mut s);
    let e = p.random_multisine(seed).expect("excitation");
    let rec = simulate_physics_recording(&p, &e, &s).expect("runs");
    let model = wheelid::models::by_name(p.model_name()).expect("model");
    (rec, model)
}

/// The Pioneer-like profile's v-loop proportional gain K_PT \[V s/m\]: an effort (clamp,
/// dead band) in volts over K_PT is the model's level in m/s.
pub fn pioneer_k_pt() -> f64 {
    match PhysicalProfile::pioneer3dx().controller {
        Controller::VwPd { k_pt, .. } => k_pt,
        Controller::WheelPd { .. } => panic!("the Pioneer-like profile has a v/ω loop"),
    }
}

/// The wheels' split of the turn loop's effort relative to d/2 (`dead_zone`'s and
/// `effort_clamp`'s `mix`): 1 for a loop per wheel, (K_PR/K_PT)/(d/2) for a v/ω loop.
pub fn wheel_split(p: &PhysicalProfile) -> f64 {
    match p.controller {
        Controller::WheelPd { .. } => 1.0,
        Controller::VwPd { k_pt, k_pr, .. } => k_pr / k_pt / (p.d / 2.0),
    }
}

/// Parameter `name` of finding `effect` in `d`.
///
/// # Panics
/// Where `d` names no `effect` with that parameter.
pub fn finding_param(d: &Diagnosis, effect: &str, name: &str) -> f64 {
    (d.findings.iter())
        .find(|f| f.effect == effect)
        .and_then(|f| f.parameters.get(name).copied())
        .unwrap_or_else(|| panic!("no {effect}.{name}"))
}

/// The named effects of `d` and the parameter `param` of `effect`, printing the report when
/// `want` is not exactly what was named.
pub fn named_param(d: &Diagnosis, want: &str, param: &str) -> Option<f64> {
    let named: Vec<&str> = d.findings.iter().map(|x| x.effect.as_str()).collect();
    if named != [want] {
        print!("{}", wheelid::report::diagnosis_text(d));
    }
    assert_eq!(named, [want]);
    d.findings[0].parameters.get(param).copied()
}

/// Asserts that the diagnosis of `rec` names exactly `other` and `tyre_asymmetry`, the tyre's
/// departure from 1 within the share `tol` of the true `tyre`'s.
pub fn assert_tyre_named_with(
    rec: &wheelid::core::Recording,
    model: &dyn wheelid::core::RegressorModel,
    other: &str,
    tyre: f64,
    tol: f64,
) {
    let (d, named) = diagnosed_named(rec, model);
    let text = wheelid::report::diagnosis_text(&d);
    assert_eq!(named, [other, "tyre_asymmetry"], "{text}");
    let rho = finding_param(&d, "tyre_asymmetry", "right_radius");
    assert!(
        ((rho - 1.0) / (tyre - 1.0) - 1.0).abs() < tol,
        "right_radius {rho} vs {tyre}"
    );
}

/// Asserts that `d` names exactly `want` (sorted), printing the report where it does not.
pub fn assert_named_sorted(d: &Diagnosis, want: &[&str]) {
    let mut named: Vec<&str> = d.findings.iter().map(|f| f.effect.as_str()).collect();
    named.sort_unstable();
    let text = wheelid::report::diagnosis_text(d);
    assert_eq!(named, want, "{text}");
}
