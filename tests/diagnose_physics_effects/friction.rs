//! Dry friction where it acts: in the wheel joints of a wheel-PD robot, behind a v/ω loop,
//! and beside a sagging battery.

use super::support::*;

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
