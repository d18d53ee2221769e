//! Tyres and amplifiers: a larger tyre the chassis's heading measures and a weak amplifier it
//! cannot, alone and beside other effects.

use super::support::*;

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
