//! Smoke tests of the issue-15 harness (`examples/diagnose_physics/`, included as a module):
//! one clean and one latency run of the Khepera-like rigid-body robot, 30 s each (the runs
//! complete, the records carry the true effect sets, the latency run declares a mismatch), and
//! single runs of cases that tuning or looked-at hold-out seeds got wrong before a change of
//! the diagnosis, each test's doc naming its seed and the change. Not the ≥ 95 % the issue asks
//! for: the harness measures that (`scripts/diagnose_physics.sh`).

#[allow(dead_code)]
#[path = "../examples/diagnose_physics/main.rs"]
mod harness;

use harness::{Record, RunSpec, exactly_right, parse_seeds, read_records, report, run_all};
use wheelid::core::Timing;

/// One run of `profile` with the physics `effects` over `duration_s`, its record printed.
fn run_one(
    profile: &str,
    timing: Timing,
    effects: Vec<&'static str>,
    seed: u64,
    duration_s: f64,
) -> Record {
    let spec = RunSpec {
        profile: profile.into(),
        timing,
        effects,
        seed,
        duration_s,
        jitter: 0.0,
        candidates: None,
        cache: None,
        search_samples: None,
    };
    let r = run_all(std::slice::from_ref(&spec), 1, &|_, _| {})
        .pop()
        .expect("one record");
    eprintln!(
        "{}: named {:?} {:?}, rejected {:?}, unexplained {:?}, fit v {:.1}→{:.1} ω {:.1}→{:.1}, \
         truth {:?}",
        r.case,
        r.named,
        r.named_params,
        r.rejected,
        r.unexplained,
        r.fit_nominal.v,
        r.fit_final.v,
        r.fit_nominal.w,
        r.fit_final.w,
        r.truth_params
    );
    r
}

/// One 120 s run of the Pioneer-like robot with one physics `effect`, its record printed.
fn pioneer_run(timing: Timing, effect: &'static str, seed: u64) -> Record {
    run_one("pioneer3dx", timing, vec![effect], seed, 120.0)
}

#[test]
fn a_clean_and_a_latency_run_of_the_khepera_complete_and_the_latency_is_a_mismatch() {
    let spec = |effects: Vec<&'static str>| RunSpec {
        profile: "khepera3".into(),
        timing: Timing::WindowEnd,
        effects,
        seed: 1,
        duration_s: 30.0,
        jitter: 0.0,
        candidates: None,
        cache: None,
        search_samples: None,
    };
    let specs = [spec(vec![]), spec(vec!["latency"])];
    let recs = run_all(&specs, 2, &|_, _| {});
    assert_eq!(recs.len(), 2);
    for r in &recs {
        eprintln!(
            "{} {}: named {:?}, mismatch {}, unexplained {:?}, fit v {:.1}→{:.1} ω {:.1}→{:.1} \
             ({:.1} s + {:.1} s)",
            r.case,
            r.timing,
            r.named,
            r.mismatch,
            r.unexplained,
            r.fit_nominal.v,
            r.fit_final.v,
            r.fit_nominal.w,
            r.fit_final.w,
            r.simulate_s,
            r.diagnose_s
        );
        assert!(r.error.is_none(), "{}: {:?}", r.case, r.error);
        assert!(r.fit_nominal.v.is_finite() && r.fit_nominal.w.is_finite());
    }
    let (clean, late) = (&recs[0], &recs[1]);
    assert!(clean.truth.is_empty() && clean.case == "clean");
    assert_eq!(late.truth, ["latency"]);
    let latency = late.truth_params["latency"]["latency_s"];
    assert!(
        (0.5 * 0.02..=3.0 * 0.02).contains(&latency),
        "latency {latency} s"
    );
    assert!(late.mismatch, "a latency of {latency} s must be a mismatch");
    // The harness's own scoring.
    assert!(exactly_right(&["latency"], &["input_delay".into()]));
    assert!(!exactly_right(
        &["latency", "rate_limit"],
        &["input_delay".into()]
    ));
    assert!(exactly_right(&[], &[]));
    assert_eq!(parse_seeds("1..3").expect("seeds"), [1, 2, 3]);
    pooled_records_give_the_runs_report(&recs);
}

/// `--pool`: the records written as `--json` lines (one per file here) read back give the
/// same report as the run's own; a non-finite number (written `null`) reads back as NaN.
fn pooled_records_give_the_runs_report(recs: &[Record]) {
    let dir = std::env::temp_dir().join(format!("wheelid-pool-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let mut odd = recs[1].clone();
    odd.diagnose_s = f64::NAN;
    let paths: Vec<_> = [&recs[0], &recs[1], &odd]
        .iter()
        .enumerate()
        .map(|(i, r)| {
            let path = dir.join(format!("{i}.jsonl"));
            let line = serde_json::to_string(r).expect("record as JSON");
            std::fs::write(&path, format!("{line}\n\n")).expect("write");
            path
        })
        .collect();
    let back = read_records(&paths).expect("records read back");
    std::fs::remove_dir_all(&dir).ok();
    assert_eq!(back.len(), 3);
    assert!(back[2].diagnose_s.is_nan());
    assert_eq!(report(&back[..2], 1.0), report(recs, 1.0));
    assert_eq!(back[1].named_params, recs[1].named_params);
    assert_eq!(back[1].fit_final.w.to_bits(), recs[1].fit_final.w.to_bits());
}

/// Tuning seed 2 of the harness, the Pioneer-like robot's amplifiers clamped at the voltage the
/// harness draws (instant stamps): the `effort_clamp` fit explains both channels to ≥ 99 % of
/// the validation blocks (cost −100 %), and it must be kept. Until 2026-11-25 it was refused
/// because its fingerprint "stayed" (χ²(1) = 20.4 against 8.9 before the fit: the score
/// statistic is scale-free, so it keeps its size on a residual a hundred times smaller), and the
/// run ended with nothing named; the same held in 5 of the 8 clamp misses on tuning seeds 1–4.
#[test]
fn a_pioneer_voltage_clamp_fitted_to_99_percent_is_kept() {
    let r = &pioneer_run(Timing::Instant, "voltage_clamp", 2);
    assert!(r.error.is_none(), "{:?}", r.error);
    assert_eq!(r.named, ["effort_clamp"]);
    assert!(r.fit_final.v >= 99.0 && r.fit_final.w >= 99.0);
    assert!(r.exactly_right);
}

/// Tuning seed 2 of the harness, the Pioneer-like robot on a slippery floor (μ drawn by the
/// harness, instant stamps): the wheels run ahead of the body at high demand, which the
/// six-θ model cannot follow (validation fit ~80 % in v). Until the `traction_limit`
/// candidate (2026-11-25) no candidate modelled it and every floor run ended `unexplained`;
/// now it is named, with the top acceleration within 20 % of μ g (1 − b/x_c) (what the floor can
/// pass to the driven wheels: the caster at x_c carries the share b/x_c of the weight), the
/// load transfer within 20 % of μ (r + 2 I_e/(m r))/x_c (the centre of mass at the axle's height
/// r, and the wheels' spin momentum), and both
/// channels explained to ≥ 95 %.
#[test]
fn a_pioneer_on_a_slippery_floor_is_named_traction_limit() {
    let r = &pioneer_run(Timing::Instant, "floor_mu", 2);
    assert!(r.error.is_none(), "{:?}", r.error);
    assert_eq!(r.named, ["traction_limit"]);
    assert!(r.fit_final.v >= 95.0 && r.fit_final.w >= 95.0);
    // The nominal fit cannot follow it: its residual stands above the noise floor.
    assert!(
        r.noise_ratio_nominal[0] > 1.0,
        "{:?}",
        r.noise_ratio_nominal
    );
    let mu = r.truth_params["floor_mu"]["mu"];
    let a = r.named_params["traction_limit"]["accel_max"];
    let p = wheelid::robots::physics::PhysicalProfile::pioneer3dx();
    let limit = mu * 9.81 * p.wheel_load_share();
    assert!(
        (a - limit).abs() <= 0.2 * limit,
        "a_max {a} vs μ g (1 − b/x_c) {limit}"
    );
    // Accelerating pitches the body onto its wheels: the centre of mass at the axle's height r
    // and the wheels' spin momentum move F (r + 2 I_e/(m r))/x_c of load.
    let lt = r.named_params["traction_limit"]["load_transfer"];
    let pitch = mu * p.load_transfer_per_force();
    assert!(
        (lt - pitch).abs() <= 0.2 * pitch,
        "load_transfer {lt} vs μ (r + 2 I_e/(m r))/x_c {pitch}"
    );
}

/// Tuning seed 4 of the harness, the Pioneer-like robot with a payload set down at 44.8 s, in
/// the validation block 24–48 s (window-middle stamps). The training blocks cannot place a change
/// inside a validation block: the training cost is flat across it but for a transient that
/// reaches the next training block and lowers it by ~10⁻⁴, so a fixed 10⁻⁶ flatness put the
/// change at the block's end, the validation samples between the true time and that guess
/// judged a wrong model, and the validation cost rose by ~50 % (nothing named, `unexplained`;
/// 5 of 6 payload misses on hold-out seeds 1011–1012). Now the change time's interval is its
/// profile likelihood's, the payload is named, the validation samples inside the interval are
/// not judged, and the true time lies inside it.
#[test]
fn a_pioneer_payload_set_down_in_a_validation_block_is_named() {
    let r = &pioneer_run(Timing::WindowMiddle, "payload", 4);
    assert!(r.error.is_none(), "{:?}", r.error);
    assert_eq!(r.named, ["payload_change"]);
    assert!(r.exactly_right);
    let at = r.truth_params["payload"]["at_s"];
    assert!((24.0..48.0).contains(&at), "the drop at {at} s");
    let p = &r.named_params["payload_change"];
    let (t, half) = (p["time_s"], r.named_std_err["payload_change"]["time_s"]);
    assert!((t - at).abs() <= half, "{t} ± {half} vs {at}");
    let theta1 = r.truth_params["payload"]["theta1_loaded_map"];
    assert!((p["theta1_after"] - theta1).abs() <= 0.2 * theta1);
}

/// A slippery floor drawn behind a rate limit acts: its μ is drawn from the demand the limit
/// leaves (the setpoints it slews), below the μ the same draw gives beside a dead time. Drawn
/// from the unlimited demand (before 2026-11-26) it never bound: the pair's recording was the
/// rate limit's alone (marginal visibility 0 %), the floor reported masked, and every seed's
/// rate-limit + floor and rate-limit + clamp pairs counted wrong whatever the diagnosis said.
#[test]
fn a_floor_behind_a_rate_limit_acts() {
    let spec = |effects: Vec<&'static str>| RunSpec {
        profile: "khepera3".into(),
        timing: Timing::WindowEnd,
        effects,
        seed: 3,
        duration_s: 30.0,
        jitter: 0.0,
        candidates: None,
        cache: None,
        search_samples: None,
    };
    let specs = [
        spec(vec!["rate_limit", "floor_mu"]),
        spec(vec!["latency", "floor_mu"]),
    ];
    let recs = run_all(&specs, 2, &|_, _| {});
    for r in &recs {
        eprintln!(
            "{}: masked {:?}, marginal {:?}, named {:?}",
            r.case, r.masked, r.marginal_visibility, r.named
        );
        assert!(r.error.is_none(), "{}: {:?}", r.case, r.error);
    }
    let (behind, beside) = (&recs[0], &recs[1]);
    assert!(behind.masked.is_empty(), "{:?}", behind.masked);
    assert!(behind.marginal_visibility["floor_mu"].w > harness::MASKED_PERCENT);
    assert!(behind.marginal_visibility["rate_limit"].v > 10.0);
    let mu = |r: &Record| r.truth_params["floor_mu"]["mu"];
    assert!(
        mu(behind) < 0.8 * mu(beside),
        "{} vs {}",
        mu(behind),
        mu(beside)
    );
    assert!(beside.masked.is_empty());
    assert!(beside.marginal_visibility["floor_mu"].w > harness::MASKED_PERCENT);
}

/// The named clamp's level is within 20 % of the physics' (V r/k_P).
fn assert_clamp_level(r: &Record) {
    let level = r.named_params["effort_clamp"]["effort_max"];
    let truth = r.truth_params["voltage_clamp"]["effort_max"];
    assert!((level - truth).abs() <= 0.2 * truth, "{level} vs {truth}");
}

/// One window-end run of `profile` with the physics `effects` over the harness's default
/// duration ([`harness::default_duration`]), its record printed; it must complete.
fn pair(profile: &str, effects: [&'static str; 2], seed: u64) -> Record {
    let duration_s = harness::default_duration(profile);
    let r = run_one(
        profile,
        Timing::WindowEnd,
        effects.to_vec(),
        seed,
        duration_s,
    );
    assert!(r.error.is_none(), "{:?}", r.error);
    r
}

/// Hold-out seed 1026 (reported at d64710a, then looked at): a weak voltage clamp (binding on
/// 7 % of the samples) beside a 49 ms latency. Once the latency is fitted the clamp's
/// fingerprint is not significant over the family (p = 0.068) while ω's residual still follows
/// the commands; the run ended with the latency alone and ω reported unexplained. Now what the
/// report would call unexplained makes the strongest fingerprints fitted, and the clamp
/// is kept at its level.
#[test]
fn a_weak_clamp_beside_a_latency_is_named() {
    let r = pair("khepera3", ["latency", "voltage_clamp"], 1026);
    assert!(r.exactly_right, "{:?}", r.named);
    assert_clamp_level(&r);
}

/// Tuning seed 1017: a slippery floor behind a rate limit. Once the rate limit is fitted, the
/// traction limit's probe read the wheels' demand off the recorded command's steps — 2.90
/// m/s², 4× the floor's — and its fit, started there, never bound; and, fitted by differences,
/// it was tried only where its start lowered the training cost by 5 % (it lowered it by
/// 1.7 %). Now the demand is the one the model in hand asks (its rate-limited setpoints), and a
/// model in hand above the noise floor lets any lowering start be fitted.
#[test]
fn a_floor_behind_a_rate_limit_is_named() {
    let r = pair("khepera3", ["rate_limit", "floor_mu"], 1017);
    assert!(r.exactly_right, "{:?}", r.named);
}

/// Tuning seed 1023: the Khepera-like robot's amplifiers clamped (binding on 13 % of the
/// samples) under window-averaged stamps, where encoder quantisation keeps even a clean fit
/// at 98.5 %. The clamp's fingerprint scored χ²(1) = 4.8 (p = 0.08) while its fit takes 66 %
/// off the validation cost: the long-run variance was estimated from the residual that
/// carries the clamp. From the Gauss–Newton step's residual it scores in the tens of thousands,
/// and the clamp is named at its level.
#[test]
fn a_clamp_under_window_stamps_is_named() {
    let r = run_one(
        "khepera3",
        Timing::WindowEnd,
        vec!["voltage_clamp"],
        1023,
        60.0,
    );
    assert!(r.exactly_right, "{:?}", r.named);
    assert_clamp_level(&r);
}

/// Tuning seed 1023: a 58 ms latency on the Pioneer-like robot. Its screened start (θ held at
/// the nominal fit, which has absorbed part of the delay) ranks fifth, behind a rate limit's.
/// The rate limit used to be refused ("its fingerprint stays"); with the fingerprints' variance
/// from the step's residual it was accepted, two rivals used the round's fits, and the latency,
/// with the strongest fingerprint by far, was never fitted (all three conventions lost). The
/// strongest fingerprint is now always fitted, and wins on the information criterion.
#[test]
fn the_strongest_fingerprint_is_fitted() {
    let r = &pioneer_run(Timing::Instant, "latency", 1023);
    assert!(r.exactly_right, "{:?}", r.named);
}

/// Tuning seed 1029 (hold-out at 998fcf9, then looked at): the Pioneer-like robot's clamped
/// amplifiers beside a sagging battery. Once the battery's gain drift is fitted, v and ω fit
/// 99.8 % and 99.3 %, and the search stopped at 99 % with the clamp's fingerprint at χ²(1) =
/// 54.5. An extended model is now searched on below 99.5 %, and the clamp is named at its
/// level.
#[test]
fn a_clamp_beside_a_battery_is_searched_for_past_99_percent() {
    let r = pair("pioneer3dx", ["voltage_clamp", "gain_sag"], 1029);
    assert!(r.exactly_right, "{:?}", r.named);
    assert_clamp_level(&r);
}

/// Tuning seed 1019: a larger right tyre beside a latency on the Pioneer-like robot. Searched
/// on past 99 %, the search named the imbalance twice, `amp_asymmetry` and then
/// `tyre_asymmetry` (a weak amplifier and a larger tyre, which the encoders cannot tell
/// apart). Effects of one quantity are now alternatives: the imbalance is named once.
#[test]
fn a_wheel_imbalance_is_named_once() {
    let r = pair("pioneer3dx", ["latency", "tyre_radius_right"], 1019);
    assert!(r.exactly_right, "{:?}", r.named);
}

/// Spent hold-out seed 1099 (after its report): on the Pioneer-like robot a 287 ms sensor
/// delay beside a voltage clamp. The heading measures the delay (287.0 ± 0.1 ms); refitted in
/// the dead time's place beside the clamp, the clamp's derivative term could not be told apart
/// and was held, and then its level could not either: the fit failed, and the stand-in dead
/// time stayed named. Each rank loss now holds what it names, until the fit runs.
#[test]
fn a_sensor_delay_beside_a_clamp_is_measured_when_the_clamp_loses_rank_twice() {
    let r = pair("pioneer3dx", ["voltage_clamp", "sensor_delay"], 1099);
    assert!(r.exactly_right, "{:?} {:?}", r.named, r.rejected);
    let delay = r.named_params["output_delay"]["delay_s"];
    let truth = r.truth_params["sensor_delay"]["sensor_delay_s"];
    assert!((delay - truth).abs() <= 0.05 * truth, "{delay} vs {truth}");
}

/// `--involving` keeps the clean run and only the single and pair cases that hold one of its
/// effects, each under its own name: of the twelve effects' 1 + 12 + 66 cases, 1 clean, the
/// floor and the tyre alone, and the 11 + 11 − 1 pairs with either; an unknown effect is an
/// error naming it.
#[test]
fn involving_keeps_the_cases_that_hold_its_effects() {
    use clap::Parser as _;
    let args = |extra: &[&str]| {
        let mut v = vec!["harness", "--seeds", "7", "--profiles", "khepera3"];
        v.extend_from_slice(&["--conventions", "window_end", "--cases", "all"]);
        v.extend_from_slice(extra);
        harness::Args::try_parse_from(v).expect("parses")
    };
    let all = harness::plan(&args(&[])).expect("plans");
    assert_eq!(all.len(), 1 + 12 + 66);
    let some = harness::plan(&args(&["--involving", "floor_mu,tyre_radius_right"])).expect("plans");
    assert_eq!(some.len(), 1 + 2 + 21);
    let holds = |s: &RunSpec| {
        s.effects.is_empty()
            || s.effects
                .iter()
                .any(|e| ["floor_mu", "tyre_radius_right"].contains(e))
    };
    assert!(some.iter().all(holds));
    assert_eq!(all.iter().filter(|s| holds(s)).count(), some.len());
    let err = harness::plan(&args(&["--involving", "ice"])).expect_err("unknown");
    assert!(format!("{err}").contains("--involving ice"), "{err}");
}
