//! Diagnosis on physics the candidates did not write (issue 15): effects realised where they act
//! on the rigid-body robot (`wheelid_robots::physics`), named and measured by `diagnose`.
//!
//! Seeds: the method was built looking at seeds 1–3, 101–103 and 201–203 (seed 103 showed the
//! "fingerprint stays" rule failing a near-perfect fit — now an effect-size rule in
//! `diagnose::accept`; seed 201 a strong friction whose fit stopped short — now a continued fit
//! and a joint regression start in `diagnose::screen`); these tests run seeds 301–303, first
//! run after those changes and not tuned on.

use wheelid::diagnose::{DiagnoseSettings, Diagnosis, diagnose};
use wheelid::robots::physics::{
    Controller, PhysicalProfile, PhysicsSettings, simulate_physics_recording,
};

/// 60 s of `p` under a random multisine (seeded), with `effects` applied by `tweak`, diagnosed
/// with the model its controller implies.
fn diagnosed(p: &PhysicalProfile, seed: u64, tweak: impl Fn(&mut PhysicsSettings)) -> Diagnosis {
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

/// A dry friction torque F in each wheel joint of a wheel-PD robot is, in steady state, a
/// setpoint offset of c = F R_a r / (k_a k_P) in wheel rim speed (the PD's proportional
/// voltage must cover the friction's R_a F / k_a).
fn c_wheel(p: &PhysicalProfile, f: f64) -> f64 {
    let Controller::WheelPd { k_p, .. } = p.controller else {
        panic!("a wheel-PD profile");
    };
    f * p.r_a * p.r / (p.k_a * k_p)
}

/// Dry friction in the wheel joints of the Khepera-like robot, 4–10 % of its top speed in
/// setpoint terms, is named `wheel_friction` — per wheel, against each wheel's own direction —
/// and nothing else, with c within 20 % of the closed form, and the clean runs of the same
/// seeds name nothing. (The Burger-like robot is not asserted yet: on tuning seed 201 a friction
/// of 9.8 % of its top speed was named `input_delay`; see the issue 15 note.)
#[test]
fn dry_friction_in_the_wheel_joints_is_named_wheel_friction() {
    for p in [PhysicalProfile::khepera3()] {
        for seed in 301..=303u64 {
            // A torque whose offset is 4–10 % of the top speed, drawn from the seed.
            let frac = 0.04 + 0.06 * ((seed * 2_654_435_761) % 1000) as f64 / 1000.0;
            let f = frac * p.v_max / c_wheel(&p, 1.0);
            let want = c_wheel(&p, f);
            let d = diagnosed(&p, seed, |s| s.effects.dry_friction_nm = Some(f));
            let named: Vec<&str> = d.findings.iter().map(|x| x.effect.as_str()).collect();
            let c = d
                .findings
                .iter()
                .find(|x| x.effect == "wheel_friction")
                .and_then(|x| x.parameters.get("c_wheel").copied());
            println!(
                "{} seed {seed}: F = {f:.5} N·m, c = {c:?} (closed form {want:.5}), named {named:?}",
                p.name
            );
            if named != ["wheel_friction"] {
                print!("{}", wheelid::report::diagnosis_text(&d));
            }
            assert_eq!(named, ["wheel_friction"], "{} seed {seed}", p.name);
            let c = c.expect("c_wheel");
            assert!((c / want - 1.0).abs() < 0.2, "c = {c}, closed form {want}");
            let clean = diagnosed(&p, seed, |_| {});
            assert!(
                clean.findings.is_empty() && clean.unexplained.is_none(),
                "{} seed {seed} clean: {:?}",
                p.name,
                clean.findings
            );
        }
    }
}

/// A dry friction torque F in each wheel joint of a v/ω-PD robot (thesis Appendix A.3) is, in
/// steady state, a setpoint offset of c_v = R_a F / (k_a K_PT) in v and c_ω = R_a F / (k_a K_PR)
/// in ω: the v loop balances the friction's common part, the ω loop its difference, each with
/// its own gain (the proportional voltage must cover R_a F / k_a per wheel).
fn c_vw(p: &PhysicalProfile, f: f64) -> (f64, f64) {
    let Controller::VwPd { k_pt, k_pr, .. } = p.controller else {
        panic!("a v/ω-PD profile");
    };
    let volts = f * p.r_a / p.k_a;
    (volts / k_pt, volts / k_pr)
}

/// Dry friction in the wheel joints of the Pioneer-like robot (v/ω-PD), 4–10 % of its top
/// speed in v's setpoint terms, is named `vw_friction` — per wheel, met by the v and ω loops —
/// and nothing else, with c_v and c_ω within 20 % of the closed forms: their ratio is
/// K_PT/K_PR = 7.0, where a per-wheel loop (`wheel_friction`) would meet 2/d = 6.1. Seeds
/// 311–313: on its first run seed 311 was refused as implausible (c_ω = 0.68 rad/s, right
/// within 1 %, above half the largest ω command — the bound `wheel_friction` has); the bound is
/// now the largest command, and the three seeds pass.
#[test]
fn dry_friction_behind_a_v_and_w_loop_is_named_vw_friction() {
    let p = PhysicalProfile::pioneer3dx();
    for seed in 311..=313u64 {
        let frac = 0.04 + 0.06 * ((seed * 2_654_435_761) % 1000) as f64 / 1000.0;
        let f = frac * p.v_max / c_vw(&p, 1.0).0;
        let (want_v, want_w) = c_vw(&p, f);
        let d = diagnosed(&p, seed, |s| s.effects.dry_friction_nm = Some(f));
        let named: Vec<&str> = d.findings.iter().map(|x| x.effect.as_str()).collect();
        let got = |name: &str| {
            d.findings
                .iter()
                .find(|x| x.effect == "vw_friction")
                .and_then(|x| x.parameters.get(name).copied())
        };
        println!(
            "{} seed {seed}: F = {f:.4} N·m, c_v = {:?}, c_w = {:?} (closed forms {want_v:.5}, \
             {want_w:.5}), named {named:?}",
            p.name,
            got("c_v"),
            got("c_w")
        );
        if named != ["vw_friction"] {
            print!("{}", wheelid::report::diagnosis_text(&d));
        }
        assert_eq!(named, ["vw_friction"], "{} seed {seed}", p.name);
        for (name, want) in [("c_v", want_v), ("c_w", want_w)] {
            let x = got(name).expect("fitted");
            assert!(
                (x / want - 1.0).abs() < 0.2,
                "{name} = {x}, closed form {want}"
            );
        }
    }
}

/// Clean rigid-body runs of both built-in profiles under every stamping convention (stated in
/// the metadata) declare no mismatch — nothing named, nothing unexplained (the first round's
/// tests may still flag structure that no candidate takes up: Khepera-like window_middle on
/// this seed; the model is then kept): window-middle stamps are restamped before the fit, and
/// residual structure at the 0.1 % level of a 99.9 % fit is no practical mismatch (before these
/// two changes, 5 of 6 such runs on tuning seed 1 left "unexplained" or named an effect).
/// Seed 401, not looked at before.
#[test]
fn clean_runs_under_every_convention_declare_nothing() {
    use wheelid::core::Timing;
    for p in [PhysicalProfile::khepera3(), PhysicalProfile::pioneer3dx()] {
        for timing in [Timing::Instant, Timing::WindowEnd, Timing::WindowMiddle] {
            let d = diagnosed(&p, 401, |s| s.timing = timing);
            let f = &d.nominal.channels;
            println!(
                "{} {}: fits v {:.2} %, ω {:.2} %, mismatch {}",
                p.name,
                timing.name(),
                f.v.fit_percent,
                f.w.fit_percent,
                d.mismatch
            );
            assert!(
                !d.mismatch && d.findings.is_empty() && d.unexplained.is_none(),
                "{} {}: {:?} {:?}",
                p.name,
                timing.name(),
                d.findings,
                d.unexplained
            );
            // The Khepera-like robot's window-averaged encoders (2764 ticks/rev, 20 ms) leave a
            // perfect model a residual of differenced tick counts, lag-1 autocorrelation −½.
            // The floor taken of the measured series counts that noise as white above
            // f_c = 0.3 f_N, so it errs high by √(((1 − a) + sin(πa)/π)/(1 − a)) = 1.17 at
            // a = 0.3: the residual is 0.85 × the floor (1.8 × when the floor was taken of the
            // conditioning's half-sample average, which halves such noise), and beyond the
            // noise the model explains all of v.
            if p.name == "khepera3" && timing != Timing::Instant {
                assert!(
                    (0.75..=1.0).contains(&f.v.noise_ratio),
                    "{}: v residual {:.2} × the floor",
                    timing.name(),
                    f.v.noise_ratio
                );
                assert!(f.v.fit_percent < 99.0 && f.v.noise_corrected_fit_percent > 99.9);
            }
        }
    }
}

/// The diagnosis of one recording with the default settings and the names it gives, sorted.
fn diagnosed_named(
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
fn pioneer_recording(
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

/// The wheels' split of the turn loop's effort relative to d/2 (`dead_zone`'s and
/// `effort_clamp`'s `mix`): 1 for a loop per wheel, (K_PR/K_PT)/(d/2) for a v/ω loop.
fn wheel_split(p: &PhysicalProfile) -> f64 {
    match p.controller {
        Controller::WheelPd { .. } => 1.0,
        Controller::VwPd { k_pt, k_pr, .. } => k_pr / k_pt / (p.d / 2.0),
    }
}

/// Parameter `name` of finding `effect` in `d`.
///
/// # Panics
/// Where `d` names no `effect` with that parameter.
fn finding_param(d: &Diagnosis, effect: &str, name: &str) -> f64 {
    (d.findings.iter())
        .find(|f| f.effect == effect)
        .and_then(|f| f.parameters.get(name).copied())
        .unwrap_or_else(|| panic!("no {effect}.{name}"))
}

/// The named effects of `d` and the parameter `param` of `effect`, printing the report when
/// `want` is not exactly what was named.
fn named_param(d: &Diagnosis, want: &str, param: &str) -> Option<f64> {
    let named: Vec<&str> = d.findings.iter().map(|x| x.effect.as_str()).collect();
    if named != [want] {
        print!("{}", wheelid::report::diagnosis_text(d));
    }
    assert_eq!(named, [want]);
    d.findings[0].parameters.get(param).copied()
}

/// Actuator effects on seed 1001 (the method was built on tuning seeds 1–2 of
/// `scripts/diagnose_physics.sh`; seed 1001's hold-out report then showed voltage clamps
/// missed, which led to the noise-floor nominees — so this seed is no longer unseen: the
/// README's hold-out report is on seeds 1003–1004, run after that last change): a battery losing 20 % of the
/// amplifier's gain over the run is named `gain_drift` with its rate within 10 % of −0.2/T
/// (the loop's whole effort scaled, not the setpoint); one amplifier 7 % weak is named
/// `amp_asymmetry` with its gain within 20 % of the deviation; an amplifier clamped at its
/// supply voltage is named `effort_clamp` with the clamp within 15 % of V r/k_P.
#[test]
fn actuator_effects_are_named_where_they_act() {
    let p = PhysicalProfile::khepera3();
    let (seed, t) = (1001u64, 60.0);
    let d = diagnosed(&p, seed, |s| s.effects.gain_sag = Some(0.2));
    let rate = named_param(&d, "gain_drift", "rate_per_s").expect("rate");
    println!("gain sag: rate {rate:.3e}/s vs {:.3e}", -0.2 / t);
    assert!((rate / (-0.2 / t) - 1.0).abs() < 0.1, "rate {rate}");

    let d = diagnosed(&p, seed, |s| s.effects.amp_gain_right = Some(0.93));
    let a = named_param(&d, "amp_asymmetry", "right_gain").expect("gain");
    println!("amplifier: right_gain {a:.4} vs 0.93");
    assert!(
        ((a - 1.0) / (0.93 - 1.0) - 1.0).abs() < 0.2,
        "right_gain {a}"
    );

    // A clamp at 6 V binds in the fast transients of this excitation (k_P = 3.33 V/(rad/s)).
    let volts = 6.0;
    let d = diagnosed(&p, seed, |s| s.effects.voltage_clamp = Some(volts));
    let c = named_param(&d, "effort_clamp", "effort_max").expect("clamp");
    let Controller::WheelPd { k_p, .. } = p.controller else {
        panic!("a wheel-PD profile");
    };
    let want = volts * p.r / k_p;
    println!("clamp: effort_max {c:.4} vs V r/k_P = {want:.4}");
    assert!((c / want - 1.0).abs() < 0.15, "effort_max {c}, want {want}");
}

/// A right tyre 4 % larger on the Khepera-like robot (the host converts both wheels with the
/// nominal radius) is named `tyre_asymmetry`, with ρ − 1 within 20 % of 0.04: the amplifier
/// asymmetry a = 1/ρ plus that wheel's row of the dynamics (the chassis inertia seen through
/// the larger tyre). Seed 1001 (the tyre candidate was built looking at tuning seed 3 of
/// `scripts/diagnose_physics.sh`; seed 1001 was not looked at with it). The weak amplifier of
/// `actuator_effects_are_named_where_they_act`, same seed, stays `amp_asymmetry`. The
/// backend's heading is the chassis's true one: it shows the ratio within 10⁻³, and the report
/// says so.
#[test]
fn a_larger_tyre_is_named_tyre_asymmetry() {
    let p = PhysicalProfile::khepera3();
    let d = diagnosed(&p, 1001, |s| s.effects.tyre_radius_right = Some(1.04));
    let rho = named_param(&d, "tyre_asymmetry", "right_radius").expect("radius");
    println!("tyre: right_radius {rho:.4} vs 1.04");
    assert!(((rho - 1.0) / 0.04 - 1.0).abs() < 0.2, "right_radius {rho}");
    let h = d.heading.as_ref().expect("the heading shows the tyre");
    assert!((h.ratio - 1.04).abs() < 1e-3 && h.modelled, "{h:?}");
    assert!(wheelid::report::diagnosis_text(&d).contains("+4.0 % more ground"));
}

/// A payload set down inside a validation block (19 s of a 60 s drive cut in five 12 s blocks:
/// the 2nd, 12–24 s, is held out) leaves the training cost flat across that block; once the
/// change is accepted its time is placed with every sample (`diagnose::place`). Measured on
/// seed 304 (first run with the placement): 19.006 s for 19.0 s; before it, a change inside a
/// validation block was reported at the block's middle (hold-out seed 1021: 17.8 s for
/// 23.1 s, 22.8 % off).
#[test]
fn a_payload_inside_a_validation_block_is_placed_with_every_sample() {
    use wheelid::robots::physics::Payload;
    let p = PhysicalProfile::khepera3();
    let d = diagnosed(&p, 304, |s| {
        s.effects.payload = Some(Payload {
            mass_kg: 0.26,
            at_s: 19.0,
            x_m: 0.028,
            size_m: 0.0295,
        })
    });
    let t = named_param(&d, "payload_change", "time_s").expect("a payload named");
    println!("payload: time_s {t:.3} vs 19.0");
    assert!((t - 19.0).abs() < 0.19, "time_s {t}");
    let f = d.findings.iter().find(|f| f.effect == "payload_change");
    let evidence = f.map_or("", |f| f.evidence.as_str());
    assert!(evidence.contains("placed with every sample"), "{evidence}");
}

/// A weak right amplifier beside a sagging battery on the Pioneer-like robot (the physics
/// harness's seed 1037, window-end stamps, its magnitudes): from the encoders alone a larger
/// right tyre explained the validation blocks as well (information −27.77 against the
/// amplifier's −27.71) and was named. The backend's heading is the chassis's true one
/// (`pose_source: ground_truth`) and turns as equal tyres do, so the tyre is refused and the
/// amplifier named, beside the battery's `gain_drift`; with the heading marked as odometry it
/// is not used, and the tyre comes back.
#[test]
fn a_weak_amplifier_is_not_named_a_larger_tyre_the_heading_does_not_show() {
    let (mut rec, model) = pioneer_recording(1037, |s| {
        s.effects.amp_gain_right = Some(0.927_889_096_257_528_9);
        s.effects.gain_sag = Some(0.206_279_621_009_177_07);
    });
    assert_eq!(rec.meta(wheelid::core::POSE_SOURCE), Some("ground_truth"));
    let run = |rec: &wheelid::core::Recording| diagnosed_named(rec, model.as_ref());
    let (d, named) = run(&rec);
    assert_eq!(
        named,
        ["amp_asymmetry", "gain_drift"],
        "{}",
        wheelid::report::diagnosis_text(&d)
    );
    let refused = d
        .rejected
        .iter()
        .find(|r| r.effect == "tyre_asymmetry")
        .expect("the tyre was fitted");
    assert!(refused.reason.contains("heading"), "{}", refused.reason);
    let gain = finding_param(&d, "amp_asymmetry", "right_gain");
    assert!((gain / 0.927_889 - 1.0).abs() < 0.02, "right_gain {gain}");
    assert!(d.heading.is_none(), "equal tyres: {:?}", d.heading);
    rec.set_meta(wheelid::core::POSE_SOURCE, "odometry");
    let (_, named) = run(&rec);
    assert_eq!(named, ["gain_drift", "tyre_asymmetry"]);
}

/// A weak right amplifier (gain 0.930) beside a larger right tyre (1.0414) on the
/// Pioneer-like robot, the magnitudes of tuning seed 1029's pair: from the encoders they are
/// one right wheel acting weaker, and alone they are named one imbalance. The backend's
/// heading (`pose_source: ground_truth`) measures the tyre: it is named first, with the
/// heading as its evidence. Fitted within its measurement's bounds the tyre went to their far
/// end (1.0499) and stood for part of the amplifier, named 0.950 (28 % short of its departure
/// from 1); pushed to that end it is now held at the heading's ratio, and the amplifier
/// searched beside it is named within 20 % of its departure. With the heading marked as
/// odometry, one imbalance is named.
#[test]
fn a_larger_tyre_the_heading_measures_is_named_beside_a_weak_amplifier() {
    let (amp, rho) = (0.930_313_033_110_953_7, 1.041_426_744_526_988_7);
    let (mut rec, model) = pioneer_recording(1029, |s| {
        s.effects.amp_gain_right = Some(amp);
        s.effects.tyre_radius_right = Some(rho);
    });
    let run = |rec: &wheelid::core::Recording| diagnosed_named(rec, model.as_ref());
    let (d, named) = run(&rec);
    let text = wheelid::report::diagnosis_text(&d);
    assert_eq!(named, ["amp_asymmetry", "tyre_asymmetry"], "{text}");
    let param = |effect: &str, name: &str| finding_param(&d, effect, name);
    let tyre = d.findings.iter().find(|f| f.effect == "tyre_asymmetry");
    assert!(
        tyre.is_some_and(|f| f.evidence.contains("measured")),
        "{text}"
    );
    let radius = param("tyre_asymmetry", "right_radius");
    let heading = d.heading.as_ref().expect("the heading shows the tyre");
    assert!((heading.ratio - rho).abs() < 1e-3, "{heading:?}");
    assert!(
        (radius - heading.ratio).abs() < 1e-9,
        "right_radius {radius}"
    );
    let gain = param("amp_asymmetry", "right_gain");
    println!("right_gain {gain:.4} for {amp:.4}");
    assert!(
        ((1.0 - gain) / (1.0 - amp) - 1.0).abs() < 0.2,
        "right_gain {gain}"
    );
    rec.set_meta(wheelid::core::POSE_SOURCE, "odometry");
    let (_, named) = run(&rec);
    let imbalances = ["amp_asymmetry", "tyre_asymmetry", "wheel_asymmetry"];
    let n = named
        .iter()
        .filter(|e| imbalances.contains(&e.as_str()))
        .count();
    assert_eq!(n, 1, "{named:?}");
}

/// A sagging battery (12.8 % lost by the end) beside a payload set down inside a validation
/// block (73.55 s of 120 s: the 4th of five blocks, 72–96 s, is held out) on the Pioneer-like
/// robot, the magnitudes of tuning seed 1017's pair. The training blocks place the payload
/// anywhere in 71.9–95.6 s; held at that interval's middle (83.8 s), it weighed against itself
/// once the next refit closed the interval, and the payload alone was named. Its time is now
/// placed with every sample as soon as it is accepted, and the battery is named beside it.
#[test]
fn a_sagging_battery_is_named_beside_a_payload_set_down_in_a_validation_block() {
    use wheelid::robots::physics::Payload;
    let (fraction, at_s) = (0.128_300_735_442_876_73, 73.553_669_021_120_53);
    let (rec, model) = pioneer_recording(1017, |s| {
        s.effects.gain_sag = Some(fraction);
        s.effects.payload = Some(Payload {
            mass_kg: 3.529_258_634_492_408_4,
            at_s,
            x_m: 0.089_469_567_447_771_67,
            size_m: 0.11,
        });
    });
    let (d, named) = diagnosed_named(&rec, model.as_ref());
    let text = wheelid::report::diagnosis_text(&d);
    assert_eq!(named, ["gain_drift", "payload_change"], "{text}");
    let param = |effect: &str, name: &str| finding_param(&d, effect, name);
    // The sag's mean rate over the run, −fraction/T.
    let rate = param("gain_drift", "rate_per_s");
    let want = -fraction / PhysicsSettings::default().duration_s;
    println!("rate_per_s {rate:.3e} vs {want:.3e}");
    assert!((rate / want - 1.0).abs() < 0.2, "rate_per_s {rate}");
    let t = param("payload_change", "time_s");
    assert!((t - at_s).abs() < 0.2, "time_s {t}");
}

/// A voltage clamp beside a larger right tyre (1.0388) on the Pioneer-like robot, hold-out
/// seed 1041's pair (looked at after its report). The heading measures the tyre, which was
/// held within its bounds; what the hold left showed as a weak amplifier's fingerprint (χ² =
/// 1129), and under the lowered gate of an overwhelming fingerprint an amplifier of 0.965 was
/// named for a 1.7 % drop of the validation cost: beside a measured effect the whole gate
/// stands. Since the tyre's lever acts after the clamp (the clamped wheel pushes the chassis
/// 1/ρ as hard), the search names the tyre itself beside the clamp (1.035). The clamp and the
/// tyre are named alone, the tyre within 20 % of its departure from 1.
#[test]
fn no_amplifier_is_named_beside_a_measured_tyre_for_what_its_hold_leaves() {
    let tyre = 1.038_844_303_112_316;
    let (rec, model) = pioneer_recording(1041, |s| {
        s.effects.voltage_clamp = Some(10.844_620_044_398_127);
        s.effects.tyre_radius_right = Some(tyre);
    });
    assert_tyre_named_with(&rec, model.as_ref(), "effort_clamp", tyre, 0.2);
}

/// A command latency of one host period (0.104 s) beside a slippery floor on the Pioneer-like
/// robot, hold-out seed 1042's pair (looked at after its report): named nothing, its verdict
/// `unexplained`. The traction limit's fingerprint was overwhelming (p = 6.6e-25) but its
/// screened start, linearised beside an unmodelled dead time, raised the training cost by
/// 3.5 %, so it was never fitted; the dead time alone kept the floor's misfit as its
/// fingerprint. Where the model in hand is above the noise floor, an overwhelming fingerprint
/// is now fitted whatever its start: both are named, the delay within 20 %.
#[test]
fn a_latency_beside_a_slippery_floor_is_named_with_it() {
    assert_pioneer_latency_and_floor_named(
        1042,
        0.104_399_207_407_454_23,
        0.047_716_284_873_124_04,
    );
}

/// The Pioneer-like robot's recording of seed `seed` with a command latency `latency` \[s\]
/// and floor friction `mu`, diagnosed: `input_delay` and `traction_limit` are named, and the
/// delay is within 20 % of `latency`.
///
/// # Panics
/// Where they are not.
fn assert_pioneer_latency_and_floor_named(seed: u64, latency: f64, mu: f64) {
    let (rec, model) = pioneer_recording(seed, |s| {
        s.effects.latency_s = Some(latency);
        s.effects.floor_mu = Some(mu);
    });
    let (d, named) = diagnosed_named(&rec, model.as_ref());
    let text = wheelid::report::diagnosis_text(&d);
    assert_eq!(named, ["input_delay", "traction_limit"], "{text}");
    let delay = finding_param(&d, "input_delay", "delay_s");
    assert!((delay / latency - 1.0).abs() < 0.2, "delay_s {delay}");
}

/// A command latency of 1.3 host periods (25.5 ms) beside a slippery floor on the
/// Khepera-like robot, hold-out seed 1052's pair (looked at after its report): named nothing,
/// its verdict `unexplained`. The dead time alone fits where the floor lets it (13.8 ms,
/// validation cost −29.5 %) and its fingerprint still explains 16.9 % of what it took off;
/// counted as staying (over 10 %) it was refused, and the floor's start alone raised the cost.
/// A non-limit's fingerprint now counts as gone at ≤ 20 % (`accept::SHARE_LEFT`): the dead
/// time is kept, the floor follows, and the final refit puts the delay within 20 %.
#[test]
fn a_sub_two_period_latency_beside_a_slippery_floor_is_named_with_it() {
    let p = PhysicalProfile::khepera3();
    let latency = 0.025_549_140_971_856_496;
    let d = diagnosed(&p, 1052, |s| {
        s.effects.latency_s = Some(latency);
        s.effects.floor_mu = Some(0.163_405_017_810_615_7);
    });
    assert_named_sorted(&d, &["input_delay", "traction_limit"]);
    let delay = finding_param(&d, "input_delay", "delay_s");
    assert!((delay / latency - 1.0).abs() < 0.2, "delay_s {delay}");
}

/// A command latency of one host period (19.3 ms) beside a slippery floor (μ = 0.146) on the
/// Khepera-like robot, hold-out seed 1065's pair (looked at after its report): named nothing,
/// `unexplained` at v 90.2 %, ω 77.3 %. Each effect fitted alone buys one channel with the
/// other: the dead time took 14.6 % off the validation cost while ω fell 77.3 → 76.1 %, the
/// traction limit 16.5 % while v fell 90.2 → 87.7 %, and each was refused for its channel's
/// fall. A fall of more than a point is now excused where the cost drops by ≥ 10 %
/// (`accept::FALL_EXCUSED_DROP`): the floor is accepted, the dead time follows within 20 %, and
/// both channels end above 95 %.
#[test]
fn a_latency_beside_a_floor_each_buying_one_channel_is_named_with_it() {
    let latency = 0.019_303_120_777_975_115;
    let d = diagnosed(&PhysicalProfile::khepera3(), 1065, |s| {
        s.effects.latency_s = Some(latency);
        s.effects.floor_mu = Some(0.146_113_022_025_886_55);
    });
    assert_named_sorted(&d, &["input_delay", "traction_limit"]);
    let delay = finding_param(&d, "input_delay", "delay_s");
    assert!((delay / latency - 1.0).abs() < 0.2, "delay_s {delay}");
    let fits = &d.final_stage.channels;
    assert!(
        fits.v.fit_percent > 95.0 && fits.w.fit_percent > 95.0,
        "{}",
        wheelid::report::diagnosis_text(&d)
    );
}

/// A command latency of 0.84 host periods (88 ms) beside a slippery floor (μ = 0.056) on the
/// Pioneer-like robot, hold-out seed 1061's pair (looked at after its report): named nothing.
/// Fitted alone, the dead time kept 80 % of its fingerprint and was refused; the floor's start,
/// linearised beside the unmodelled dead time, raised the training cost (its fingerprint at
/// p = 4.2e-9, not below the overwhelming 1e-12), so it was never fitted. A round that accepts
/// nothing while the model is above the noise floor now fits such a skipped candidate as a
/// last resort (`search::last_resort`): the floor is accepted, the dead time follows, and the
/// delay is within 20 %.
#[test]
fn a_latency_beside_a_floor_no_start_favours_is_named_with_it() {
    assert_pioneer_latency_and_floor_named(
        1061,
        0.087_700_379_365_971_51,
        0.056_422_408_308_908_16,
    );
}

/// A command latency of 0.54 host periods (53.5 ms) beside a voltage clamp on the Pioneer-like
/// robot, hold-out seed 1057's pair (looked at after its report): the first round's rate limit
/// outscored the dead time on the information criterion, the dead time fitted beside it
/// landed at 21.6 ms and was refused, and the greedy search ended at v 95.2 %, ω 92.6 % with
/// a rate limit and the clamp, `unexplained`. Where the greedy search ends above the noise
/// floor, the search from the first round's runner-up is tried (`paths::second_path`): from
/// the dead time the clamp follows, both within 5 %, at fits of 99.9 % and more.
#[test]
fn a_latency_beside_a_clamp_is_found_from_the_first_rounds_runner_up() {
    let latency = 0.053_513_193_594_547_27;
    let volts = 9.096_434_408_192_838;
    let (rec, model) = pioneer_recording(1057, |s| {
        s.effects.latency_s = Some(latency);
        s.effects.voltage_clamp = Some(volts);
    });
    let (d, named) = diagnosed_named(&rec, model.as_ref());
    let text = wheelid::report::diagnosis_text(&d);
    assert_eq!(named, ["effort_clamp", "input_delay"], "{text}");
    let delay = finding_param(&d, "input_delay", "delay_s");
    assert!((delay / latency - 1.0).abs() < 0.05, "delay_s {delay}");
    let p = PhysicalProfile::pioneer3dx();
    let Controller::VwPd { k_pt, .. } = p.controller else {
        panic!("a v/ω-PD profile");
    };
    let truth = volts / k_pt;
    let c = finding_param(&d, "effort_clamp", "effort_max");
    assert!((c / truth - 1.0).abs() < 0.05, "effort_max {c} vs {truth}");
    assert!(
        d.final_stage.channels.v.fit_percent > 99.9 && d.final_stage.channels.w.fit_percent > 99.8,
        "{text}"
    );
}

/// An amplifier dead band beside a setpoint rate limit on the Pioneer-like robot (hold-out seed
/// 1087's magnitudes, looked at after its report: 0.217 V, the limit binding on half the
/// samples). Fitted with the band from a split of 1, the wheels' mix ran to 0.084, a second
/// minimum, and the band was refused as no drive's; fitted once the band is (`secondary`,
/// from 1 and from 0.5), it comes to the v/ω loop's 0.863. Named with the rate limit, the band
/// within 10 % of V/K_PT and the split within 5 %.
#[test]
fn a_dead_band_beside_a_rate_limit_is_named_with_the_loops_split() {
    let volts = 0.216_945_544_252_306_28;
    let (rec, model) = pioneer_recording(1087, |s| {
        s.effects.rate_limit = Some(wheelid::robots::physics::RateLimit {
            v_accel: 0.253_506_230_616_158_9,
            w_accel: 0.513_394_377_339_458_5,
        });
        s.effects.dead_band_v = Some(volts);
    });
    let d = diagnose(&[rec], model.as_ref(), &DiagnoseSettings::default()).expect("diagnoses");
    assert_named_sorted(&d, &["acceleration_limit", "dead_zone"]);
    let p = PhysicalProfile::pioneer3dx();
    let Controller::VwPd { k_pt, .. } = p.controller else {
        panic!("a v/ω-PD profile");
    };
    let (beta, kappa) = (
        finding_param(&d, "dead_zone", "effort_dead"),
        finding_param(&d, "dead_zone", "mix"),
    );
    let (band, split) = (volts / k_pt, wheel_split(&p));
    println!("effort_dead {beta:.5} vs {band:.5}; mix {kappa:.4} vs {split:.4}");
    assert!((beta / band - 1.0).abs() < 0.1, "effort_dead {beta}");
    assert!((kappa / split - 1.0).abs() < 0.05, "mix {kappa}");
}

/// A voltage clamp beside a setpoint rate limit on the Khepera-like robot (hold-out seed
/// 1043's magnitudes, looked at after its report: the clamp binds on 9 % of the samples) is
/// named with it, its effort limit within 20 % of V r/k_P. Fitted within 2 % of it beside the
/// rate limit, the clamp takes only 1.4 % off the validation cost at p = 4.8e-20: the drop
/// gate an overwhelming fingerprint asks falls with the evidence's order of magnitude
/// (`accept::required_drop`), where a flat 1.5 % turned it down.
#[test]
fn a_clamp_beside_a_rate_limit_is_named_with_it() {
    let p = PhysicalProfile::khepera3();
    let volts = 5.155_118_574_899_077_5;
    let d = diagnosed(&p, 1043, |s| {
        s.effects.rate_limit = Some(wheelid::robots::physics::RateLimit {
            v_accel: 0.592_637_921_370_241_8,
            w_accel: 7.594_338_538_518_978,
        });
        s.effects.voltage_clamp = Some(volts);
    });
    assert_named_sorted(&d, &["acceleration_limit", "effort_clamp"]);
    let Controller::WheelPd { k_p, .. } = p.controller else {
        panic!("a wheel-PD profile");
    };
    let truth = volts * p.r / k_p;
    let c = finding_param(&d, "effort_clamp", "effort_max");
    assert!((c / truth - 1.0).abs() < 0.2, "effort_max {c} vs {truth}");
}

/// A strong right amplifier (1.063) beside a larger right tyre (1.033) on the Khepera-like
/// robot (hold-out seed 1044's magnitudes, looked at after its report): in the dynamics the
/// two nearly cancel (the nominal fit is at the encoders' noise floor), but the chassis
/// heading measures the tyre. Held, the tyre has no standard error of the dynamics' own; it
/// takes the heading's, and both are named (before, the tyre was refused as "1.0220 ± 0.0000
/// not significant" and nothing was named). Pushed to its measurement's near bound, the tyre
/// is held at the heading's ratio, and the amplifier is named within 20 % of its departure.
#[test]
fn a_measured_tyre_held_at_its_bound_is_named_beside_a_strong_amplifier() {
    let p = PhysicalProfile::khepera3();
    let amp = 1.063_452_227_956_585_4;
    let d = diagnosed(&p, 1044, |s| {
        s.effects.amp_gain_right = Some(amp);
        s.effects.tyre_radius_right = Some(1.033_013_056_610_346_4);
    });
    assert_named_sorted(&d, &["amp_asymmetry", "tyre_asymmetry"]);
    let tyre = finding_param(&d, "tyre_asymmetry", "right_radius");
    let tyre_se = (d.findings.iter())
        .find(|f| f.effect == "tyre_asymmetry")
        .and_then(|f| f.std_err.get("right_radius").copied())
        .expect("a standard error");
    assert!(tyre > 1.01 && tyre_se > 0.0, "{tyre} ± {tyre_se}");
    let heading = d.heading.as_ref().expect("the heading shows the tyre");
    assert!(
        (tyre - heading.ratio).abs() < 1e-9,
        "right_radius {tyre} vs {heading:?}"
    );
    let gain = finding_param(&d, "amp_asymmetry", "right_gain");
    println!("right_gain {gain:.4} for {amp:.4}, right_radius {tyre:.4}");
    assert!(
        ((gain - 1.0) / (amp - 1.0) - 1.0).abs() < 0.2,
        "right_gain {gain}"
    );
}

/// A sagging battery beside dry friction on the Pioneer-like robot (hold-out seed 1045's
/// magnitudes, looked at after its report) is named `gain_drift` and `vw_friction`, without
/// the 0.6 % payload step that took what they leave (a payload is named from 2 % of θ1 or
/// θ2 on, `payload_change::MIN_PAYLOAD_EFFECT`).
#[test]
fn no_payload_is_named_for_what_a_battery_beside_dry_friction_leaves() {
    let (rec, model) = pioneer_recording(1045, |s| {
        s.effects.gain_sag = Some(0.264_249_323_895_480_06);
        s.effects.dry_friction_nm = Some(0.066_746_710_419_559_54);
    });
    let (d, named) = diagnosed_named(&rec, model.as_ref());
    let text = wheelid::report::diagnosis_text(&d);
    assert_eq!(named, ["gain_drift", "vw_friction"], "{text}");
    let rate = finding_param(&d, "gain_drift", "rate_per_s");
    let truth = -0.264_249_323_895_480_06 / 120.0;
    assert!(
        (rate / truth - 1.0).abs() < 0.2,
        "rate_per_s {rate} vs {truth}"
    );
}

/// A sagging battery (16.6 % by the end) beside a larger right tyre (1.0416) on the
/// Pioneer-like robot, hold-out seed 1063's pair (looked at after its report). The search
/// named `gain_drift`, then a weak amplifier for the tyre, then a turning loss (`slip`,
/// k_ω = 0.045 s/m) for what the amplifier left; the heading then measured the tyre and it
/// replaced the amplifier, but the turning loss stayed: a third, false effect. Once a measured
/// effect is placed, the effects found beside its stand-in are tested for redundancy
/// (`paths::path`): without the turning loss the validation cost rises by 3.8 % only, and the
/// battery and the tyre are named alone, the drift's rate and the tyre within 20 %.
#[test]
fn no_turning_loss_is_kept_for_what_a_replaced_amplifier_left() {
    let (fraction, tyre) = (0.165_857_339_009_011_28, 1.041_642_477_082_216_1);
    let (rec, model) = pioneer_recording(1063, |s| {
        s.effects.gain_sag = Some(fraction);
        s.effects.tyre_radius_right = Some(tyre);
    });
    let (d, named) = diagnosed_named(&rec, model.as_ref());
    let text = wheelid::report::diagnosis_text(&d);
    assert_eq!(named, ["gain_drift", "tyre_asymmetry"], "{text}");
    let rate = finding_param(&d, "gain_drift", "rate_per_s");
    let truth = -fraction / 120.0;
    assert!(
        (rate / truth - 1.0).abs() < 0.2,
        "rate_per_s {rate} vs {truth}"
    );
    let rho = finding_param(&d, "tyre_asymmetry", "right_radius");
    assert!(
        ((rho - 1.0) / (tyre - 1.0) - 1.0).abs() < 0.2,
        "right_radius {rho}"
    );
}

/// A larger right tyre (1.0495) on a slippery floor (μ = 0.053) on the Pioneer-like robot
/// (hold-out seed 1043's pair, looked at after its report). The tyre acts at its contact: the
/// right contact runs at ρ times its rim and turns the wheel back by ρ times its force, while
/// the motor's effort turns the wheel whole. Composed as the tyre alone (the effort over ρ,
/// the chassis row scaled) inside the traction stage, the slipping wheel answered the motor as
/// a weak one, and a false amplifier of 0.972 was named beside the tyre and the floor. Now
/// both are named alone, the tyre within 5 % of its departure from 1.
#[test]
fn a_larger_tyre_on_a_slippery_floor_is_named_without_an_amplifier() {
    let tyre = 1.049_538_385_232_156_7;
    let (rec, model) = pioneer_recording(1043, |s| {
        s.effects.tyre_radius_right = Some(tyre);
        s.effects.floor_mu = Some(0.053_347_648_321_123_056);
    });
    assert_tyre_named_with(&rec, model.as_ref(), "traction_limit", tyre, 0.05);
}

/// A slippery floor alone on the Pioneer-like robot (μ = 0.0494, slipping on 45 % of the rows;
/// hold-out seed 1101's draw, looked at after its report). Its wheels spin up ahead of the
/// body, so over all chunks the chassis heading turned as a right/left tyre ratio of about
/// 0.94: a smaller right tyre was measured and named, with an amplifier beside it that
/// cancelled it in the dynamics. The calmest third of the chunks turns as equal tyres; now the
/// floor is named alone.
#[test]
fn a_slippery_floor_is_not_named_a_smaller_tyre_by_its_slipping_wheels() {
    let (rec, model) = pioneer_recording(1101, |s| {
        s.effects.floor_mu = Some(0.049_417_845_357_963_605);
    });
    let d = PhysicalProfile::pioneer3dx().d;
    let (rho, _) =
        wheelid::models::effects::heading_ratio(std::slice::from_ref(&rec), d).expect("a heading");
    assert!((rho - 1.0).abs() < 0.01, "heading ratio {rho}");
    let (d, _) = diagnosed_named(&rec, model.as_ref());
    assert!(named_param(&d, "traction_limit", "accel_max").is_some());
}

/// A voltage clamp beside a larger right tyre (1.0342) on the Pioneer-like robot (hold-out
/// seed 1047's pair, looked at after its report). The supply clamps the voltage before the
/// tyre's lever acts, so the clamped wheel pushes the chassis 1/ρ as hard; the tyre's 1/ρ was
/// applied before the clamp, and an amplifier fitted beside the measured tyre (whose apply
/// replaced the tyre's effort factor instead of multiplying it) made up the difference: a
/// false 0.974 amplifier. Now the clamp and the tyre are named alone, the tyre within 10 % of
/// its departure from 1.
#[test]
fn a_clamped_wheel_with_a_larger_tyre_is_named_without_an_amplifier() {
    let tyre = 1.034_157_040_023_514_7;
    let (rec, model) = pioneer_recording(1047, |s| {
        s.effects.voltage_clamp = Some(9.633_201_611_856_562);
        s.effects.tyre_radius_right = Some(tyre);
    });
    assert_tyre_named_with(&rec, model.as_ref(), "effort_clamp", tyre, 0.1);
}

/// A voltage clamp (8.12 V) beside a payload (3.19 kg set down at 60.6 s) on the Pioneer-like
/// robot, hold-out seed 1048's pair (looked at after its report). The loop's derivative term
/// (K_DT/K_PT = 1.5/66 s, 9 % of θ1) vanishes while a wheel is clamped, so the clamp in effort
/// units came out c/(1 − K_DT/(K_PT θ1)), 10 % high, and once the payload moved θ1 that ratio
/// moved: a drive gain drifting +0.0002/s was named beside them. With the derivative term in
/// the clamp (`derivative_s`, freed beside the payload) the two are named alone, the clamp
/// within 5 % of V/K_PT and the derivative term within 20 % of K_DT/K_PT.
#[test]
fn a_clamp_beside_a_payload_is_named_with_its_loops_derivative_term() {
    use wheelid::robots::physics::Payload;
    let volts = 8.118_364_003_527_573;
    let (rec, model) = pioneer_recording(1048, |s| {
        s.effects.voltage_clamp = Some(volts);
        s.effects.payload = Some(Payload {
            mass_kg: 3.193_100_519_178_434,
            at_s: 60.567_872_169_946_72,
            x_m: 0.038_328_007_346_050_956,
            size_m: 0.11,
        });
    });
    let (d, named) = diagnosed_named(&rec, model.as_ref());
    let text = wheelid::report::diagnosis_text(&d);
    assert_eq!(named, ["effort_clamp", "payload_change"], "{text}");
    let Controller::VwPd { k_pt, k_dt, .. } = PhysicalProfile::pioneer3dx().controller else {
        panic!("the Pioneer-like profile has a v/ω loop");
    };
    let (c, delta) = (
        finding_param(&d, "effort_clamp", "effort_max"),
        finding_param(&d, "effort_clamp", "derivative_s"),
    );
    println!(
        "effort_max {c:.4} vs {:.4}, derivative_s {delta:.4} vs {:.4}",
        volts / k_pt,
        k_dt / k_pt
    );
    assert!((c / (volts / k_pt) - 1.0).abs() < 0.05, "effort_max {c}");
    assert!(
        (delta / (k_dt / k_pt) - 1.0).abs() < 0.2,
        "derivative_s {delta}"
    );
}

/// Asserts that the diagnosis of `rec` names exactly `other` and `tyre_asymmetry`, the tyre's
/// departure from 1 within the share `tol` of the true `tyre`'s.
fn assert_tyre_named_with(
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
fn assert_named_sorted(d: &Diagnosis, want: &[&str]) {
    let mut named: Vec<&str> = d.findings.iter().map(|f| f.effect.as_str()).collect();
    named.sort_unstable();
    let text = wheelid::report::diagnosis_text(d);
    assert_eq!(named, want, "{text}");
}

/// The encoders' readings reaching the host 1.7 periods late (a sensor delay; seed 1301, first
/// run with the `output_delay` effect): with the chassis's true heading in the recording the
/// lag is measured and named `output_delay`, within 5 % of the truth; without that heading the
/// encoders alone see it as a dead time of the commands, named `input_delay` at the same
/// length (a dead time commutes with a time-invariant robot); beside a command latency of
/// 0.8 period both are named, each within 10 %.
#[test]
fn a_sensor_delay_is_named_output_delay_where_a_true_heading_shows_it() {
    let p = PhysicalProfile::khepera3();
    let (sensor, latency) = (1.7 * p.period_s, 0.8 * p.period_s);
    let late = |s: &mut PhysicsSettings| s.effects.sensor_delay_s = Some(sensor);
    let d = diagnosed(&p, 1301, late);
    let tau = named_param(&d, "output_delay", "delay_s").expect("delay");
    println!("sensor delay: output_delay {tau:.4} s vs {sensor:.4}");
    assert!((tau / sensor - 1.0).abs() < 0.05, "output_delay {tau}");
    // The same drive without its heading: the encoders' own story.
    let mut s = PhysicsSettings {
        duration_s: 60.0,
        seed: 1301,
        ..PhysicsSettings::default()
    };
    late(&mut s);
    let mut rec =
        simulate_physics_recording(&p, &p.random_multisine(1301).expect("exc"), &s).expect("runs");
    rec.set_meta(wheelid::core::POSE_SOURCE, "odometry");
    let model = wheelid::models::by_name(p.model_name()).expect("model");
    let (d, _) = diagnosed_named(&rec, model.as_ref());
    let tau = named_param(&d, "input_delay", "delay_s").expect("delay");
    println!("without the heading: input_delay {tau:.4} s");
    assert!((tau / sensor - 1.0).abs() < 0.05, "input_delay {tau}");
    // Both delays: the heading measures the sensor's, the dynamics the sum.
    let d = diagnosed(&p, 1301, |s| {
        late(s);
        s.effects.latency_s = Some(latency);
    });
    let names: Vec<&str> = d.findings.iter().map(|f| f.effect.as_str()).collect();
    if names.len() != 2 {
        print!("{}", wheelid::report::diagnosis_text(&d));
    }
    let (tin, tout) = (
        finding_param(&d, "input_delay", "delay_s"),
        finding_param(&d, "output_delay", "delay_s"),
    );
    println!("both: input_delay {tin:.4} s vs {latency:.4}, output_delay {tout:.4} vs {sensor:.4}");
    assert_eq!(names.len(), 2, "{names:?}");
    assert!((tin / latency - 1.0).abs() < 0.1, "input_delay {tin}");
    assert!((tout / sensor - 1.0).abs() < 0.1, "output_delay {tout}");
}

/// A sensor delay of 2.9 periods on a slippery floor (μ = 0.143; tuning seed 10 of the
/// twelve-effect harness): the heading's lag, read where the wheels grip, is 56 ms for 58.7,
/// and the traction limit the search fitted beside a dead time of the commands stays as it
/// was when the measured delay takes that dead time's place. Named `traction_limit` and
/// `output_delay` alone, the delay within 10 % and ω's validation fit above 95 % (before
/// 2026-11-29: the lag read 42 ms, a dead time of the commands was named beside it for the
/// rest; with the lag right, the delay's refit from the limit refitted without a dead time ran
/// to the limit's bounds, ω 77.6 %).
#[test]
fn a_sensor_delay_on_a_slippery_floor_is_named_with_it() {
    let p = PhysicalProfile::khepera3();
    let sensor = 2.935 * p.period_s;
    let d = diagnosed(&p, 10, |s| {
        s.timing = wheelid::core::Timing::WindowEnd;
        s.effects.sensor_delay_s = Some(sensor);
        s.effects.floor_mu = Some(0.1433);
    });
    assert_named_sorted(&d, &["output_delay", "traction_limit"]);
    let tau = finding_param(&d, "output_delay", "delay_s");
    let fit_w = d.final_stage.channels.w.fit_percent;
    println!("output_delay {tau:.4} s vs {sensor:.4}; ω validation fit {fit_w:.1} %");
    assert!((tau / sensor - 1.0).abs() < 0.1, "output_delay {tau}");
    assert!(fit_w > 95.0, "ω {fit_w}");
}

/// A sensor delay of half a period (0.538 periods, 10.75 ms) on the Khepera-like robot, beside
/// a dead time of the commands (2.99 periods) or an amplifier clamped at 7.23 V (spent
/// hold-out seed 1084, window-end stamps). The heading measures the short delay to 10.8 ±
/// 0.0 ms; it is named `output_delay` within 10 % beside `input_delay` or `effort_clamp`.
/// Before 2026-11-29 the dynamics' standard error (± 5.2 ms) refused it as "not significant"
/// beside the dead time, and beside the clamp the refit without the dead time that stood for
/// it failed on rank (the clamp's derivative time had nothing left to fit): a dead time of
/// the commands was named in its place both times.
#[test]
fn a_sensor_delay_of_half_a_period_is_named_where_the_heading_measures_it() {
    let p = PhysicalProfile::khepera3();
    let sensor = 0.5376015087253159 * p.period_s;
    let late = |s: &mut PhysicsSettings| {
        s.timing = wheelid::core::Timing::WindowEnd;
        s.effects.sensor_delay_s = Some(sensor);
    };
    for (other, name) in [("latency", "input_delay"), ("clamp", "effort_clamp")] {
        let d = diagnosed(&p, 1084, |s| {
            late(s);
            match other {
                "latency" => s.effects.latency_s = Some(2.9898592883848427 * p.period_s),
                _ => s.effects.voltage_clamp = Some(7.234060095881812),
            }
        });
        let mut want = vec!["output_delay", name];
        want.sort_unstable();
        assert_named_sorted(&d, &want);
        let tau = finding_param(&d, "output_delay", "delay_s");
        println!("beside {other}: output_delay {tau:.4} s vs {sensor:.4}");
        assert!((tau / sensor - 1.0).abs() < 0.1, "beside {other}: {tau}");
    }
}

/// An amplifier dead band on each robot (seed 1302, first run with the `dead_zone` effect):
/// a voltage below the band gives none, one above it that much less. Named `dead_zone` and
/// nothing else — not `wheel_friction`, whose steady offset it shares — with the band within
/// 10 % of V r/k_P (wheel PD) or V/K_PT (v/ω PD), the clamp's effort units, and the wheels'
/// split within 5 % of the controller's: `mix` 1 for a loop per wheel, (K_PR/K_PT)/(d/2) =
/// 0.863 for the v/ω loop. Before `dead_zone` carried a mix (2026-11-29) the Pioneer-like
/// band was read at the default split 1 and ω's validation fit ended at 99.0–99.3 % (harness
/// runs); with it, above 99.8 % (the Khepera-like robot's encoders bound its ω fit near 97 %:
/// above 96 % there).
#[test]
fn an_amplifier_dead_band_is_named_dead_zone() {
    for (p, effort, least_w) in [
        (PhysicalProfile::khepera3(), 0.004, 96.0),
        (PhysicalProfile::pioneer3dx(), 0.008, 99.8),
    ] {
        let volts = match p.controller {
            Controller::WheelPd { k_p, .. } => effort * k_p / p.r,
            Controller::VwPd { k_pt, .. } => effort * k_pt,
        };
        let mix = wheel_split(&p);
        let d = diagnosed(&p, 1302, |s| s.effects.dead_band_v = Some(volts));
        let beta = named_param(&d, "dead_zone", "effort_dead").expect("band");
        // Held at 1 where the data do not place it 3 σ away (its `secondary` fit).
        let kappa = (d.findings.iter().find(|f| f.effect == "dead_zone"))
            .and_then(|f| f.parameters.get("mix").copied())
            .unwrap_or(1.0);
        let fit_w = d.final_stage.channels.w.fit_percent;
        println!(
            "{}: effort_dead {beta:.5} vs {effort:.5} ({volts:.3} V); mix {kappa:.4} vs \
             {mix:.4}; ω validation fit {fit_w:.2} %",
            p.name
        );
        assert!((beta / effort - 1.0).abs() < 0.1, "{}: {beta}", p.name);
        assert!((kappa / mix - 1.0).abs() < 0.05, "{}: mix {kappa}", p.name);
        assert!(fit_w > least_w, "{}: ω {fit_w}", p.name);
    }
}
