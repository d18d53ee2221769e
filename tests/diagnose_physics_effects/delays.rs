//! Sensor (output) delays: measured where a true heading shows them, beside a floor and at
//! half a period.

use super::support::*;

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

/// A search whose model in hand fits both channels' validation blocks to 99.5 % or more ends
/// there: the next round is not scored (its fingerprints could not extend the model) and the
/// report says why. A command latency of 1.7 periods on the Pioneer-like robot (seed 1301;
/// the Khepera-like robot's window-averaged ticks keep its fits near 98 %).
#[test]
fn a_model_that_fits_ends_the_search_unscored() {
    let p = PhysicalProfile::pioneer3dx();
    let latency = 1.7 * p.period_s;
    let d = diagnosed(&p, 1301, |s| s.effects.latency_s = Some(latency));
    let text = wheelid::report::diagnosis_text(&d);
    let tau = finding_param(&d, "input_delay", "delay_s");
    assert!(
        (tau / latency - 1.0).abs() < 0.05,
        "input_delay {tau}\n{text}"
    );
    let fits = &d.final_stage.channels;
    assert!(
        fits.v.fit_percent >= 99.5 && fits.w.fit_percent >= 99.5,
        "v {:.2} %, ω {:.2} %",
        fits.v.fit_percent,
        fits.w.fit_percent
    );
    assert_eq!(d.fingerprints.len(), 1, "one round scored\n{text}");
    let why = d
        .unscored_round
        .as_deref()
        .expect("the second round is not scored");
    assert!(why.contains("no channel misses a relevant share"), "{why}");
    assert!(
        text.contains("round 2: not scored: the model in hand fits the validation blocks"),
        "{text}"
    );
}

/// A sensor delay of one period beside a very slippery floor on the Pioneer-like robot (μ =
/// 0.044, the wheels slipping on 52 % of the rows; the one such pair the declared report of
/// 1117–1120 missed, looked at after it): the first rounds, without the delay, named a dead
/// band for it and refused the floor (its fingerprint stayed); the measured delay then lowered
/// the fit to v 77.2 %, ω 80.8 %, and only a dead time of the commands was searched beside
/// it. Every candidate is searched again once the measured delay is in: the floor is named
/// (its `accel_max` within 2 % of μ g (1 − b/x_c)) and the dead band dropped.
#[test]
fn a_floor_hidden_by_a_sensor_delay_is_named_once_the_delay_is_measured() {
    let (mu, sensor) = (0.043_660_323_045_380_325, 0.102_288_834_036_121_38);
    let (rec, model) = pioneer_recording(1117, |s| {
        s.effects.floor_mu = Some(mu);
        s.effects.sensor_delay_s = Some(sensor);
    });
    let (d, named) = diagnosed_named(&rec, model.as_ref());
    let text = wheelid::report::diagnosis_text(&d);
    assert_eq!(named, ["output_delay", "traction_limit"], "{text}");
    let tau = finding_param(&d, "output_delay", "delay_s");
    assert!((tau / sensor - 1.0).abs() < 0.05, "output_delay {tau}");
    let p = PhysicalProfile::pioneer3dx();
    let a_max = finding_param(&d, "traction_limit", "accel_max");
    let truth = mu * 9.81 * p.wheel_load_share();
    assert!(
        (a_max / truth - 1.0).abs() < 0.02,
        "accel_max {a_max} vs {truth}"
    );
    let fits = &d.final_stage.channels;
    assert!(
        fits.v.fit_percent > 99.0 && fits.w.fit_percent > 98.0,
        "v {:.2} %, ω {:.2} %\n{text}",
        fits.v.fit_percent,
        fits.w.fit_percent
    );
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
