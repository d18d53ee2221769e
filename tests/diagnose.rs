//! Mismatch diagnosis against recordings whose concealed physics is known: the simulator
//! (`wheelid simulate`'s code) with each effect of `wheelid_robots::effects` at a random
//! magnitude, alone and in pairs, on both robots, under random multisines (not the thesis's
//! excitation). The diagnosis must name the effect, give its magnitude within 20 %, and raise
//! the validation fit; on clean recordings it must add nothing (false alarms counted over 100
//! seeds).

use wheelid::core::Recording;
use wheelid::diagnose::{DiagnoseSettings, Diagnosis, diagnose};
use wheelid::models::VwPd;
use wheelid::robots::effects::{
    AccelerationLimit, CoulombFriction, Effects, GainDrift, InputDelay, PayloadChange, Slip,
    VelocitySaturation, WheelAsymmetry,
};
use wheelid::robots::{Excitation, RobotProfile, SimSettings, simulate_recording};

/// Uniform numbers in [0, 1) from a seed (splitmix64): the magnitudes are random but
/// reproducible.
struct Draw(u64);

impl Draw {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }
    fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next()
    }
}

/// The excitation of every case: random-phase multisines to 2 Hz around a quarter of the
/// robot's speed (as `wheelid simulate --excitation multisine`).
fn excitation(robot: &RobotProfile, seed: u64) -> Excitation {
    robot.multisine(seed).expect("valid multisine")
}

fn record(robot: &RobotProfile, seed: u64, duration_s: f64, effects: Effects) -> Recording {
    simulate_recording(
        robot,
        &excitation(robot, seed),
        &SimSettings {
            duration_s,
            seed,
            effects,
            ..SimSettings::default()
        },
    )
    .expect("simulates")
}

/// 95th percentile of |du/dt| of a command under the excitation (for rate limits that bind).
fn rate_p95(robot: &RobotProfile, seed: u64, ch: usize) -> f64 {
    let rec = record(robot, seed, 60.0, Effects::default());
    let u = if ch == 0 { &rec.v_ref } else { &rec.w_ref };
    let mut r: Vec<f64> = u
        .windows(2)
        .zip(rec.t.windows(2))
        .map(|(u, t)| ((u[1] - u[0]) / (t[1] - t[0])).abs())
        .collect();
    r.sort_by(f64::total_cmp);
    r[(0.95 * (r.len() - 1) as f64) as usize]
}

/// One concealed effect at a random magnitude; returns its name, the simulator setting and
/// the parameters the diagnosis must find.
fn effect(
    name: &str,
    robot: &RobotProfile,
    seed: u64,
    duration_s: f64,
    draw: &mut Draw,
    effects: &mut Effects,
) -> Vec<(&'static str, f64)> {
    let (va, wa) = (0.25 * robot.v_max, 0.25 * robot.w_max);
    match name {
        "input_delay" => {
            // 0.1–0.5 s on the Pioneer, 40–200 ms on the Khepera.
            let d = draw.uniform(1.0, 5.0) * if robot.period_s < 0.05 { 0.04 } else { 0.1 };
            effects.input_delay = Some(InputDelay { delay_s: d });
            vec![("delay_s", d)]
        }
        "acceleration_limit" => {
            let a = [0, 1].map(|ch| draw.uniform(0.3, 0.6) * rate_p95(robot, seed, ch));
            effects.acceleration_limit = Some(AccelerationLimit {
                v_accel_max: a[0],
                w_accel_max: a[1],
            });
            vec![("v_accel_max", a[0]), ("w_accel_max", a[1])]
        }
        "velocity_saturation" => {
            let v = va + draw.uniform(0.2, 0.6) * va;
            let w = draw.uniform(0.4, 0.7) * wa;
            effects.velocity_saturation = Some(VelocitySaturation { v_max: v, w_max: w });
            vec![("v_max", v), ("w_max", w)]
        }
        "coulomb_friction" => {
            let c = [draw.uniform(0.05, 0.12) * va, draw.uniform(0.05, 0.12) * wa];
            effects.coulomb_friction = Some(CoulombFriction {
                v_coulomb: c[0],
                w_coulomb: c[1],
            });
            vec![("v_coulomb", c[0]), ("w_coulomb", c[1])]
        }
        "wheel_asymmetry" => {
            let sign = if draw.next() < 0.5 { -1.0 } else { 1.0 };
            let r = 1.0 + sign * draw.uniform(0.05, 0.12);
            effects.wheel_asymmetry = Some(WheelAsymmetry { ratio: r });
            vec![("ratio", r)]
        }
        "payload_change" => {
            let f = draw.uniform(1.3, 1.8);
            let t = draw.uniform(0.3, 0.7) * duration_s;
            let p = PayloadChange::scaled(t, robot.theta, f);
            effects.payload_change = Some(p);
            vec![
                ("time_s", t),
                ("theta1_after", p.theta_after[0]),
                ("theta2_after", p.theta_after[1]),
            ]
        }
        "gain_drift" => {
            let r = -draw.uniform(0.2, 0.4) / duration_s;
            effects.gain_drift = Some(GainDrift { rate_per_s: r });
            vec![("rate_per_s", r)]
        }
        "slip" => {
            let k = [draw.uniform(0.2, 0.4), draw.uniform(0.2, 0.4)];
            effects.slip = Some(Slip {
                k_v: k[0],
                k_w: k[1],
            });
            vec![("k_v", k[0]), ("k_w", k[1])]
        }
        other => panic!("unknown effect {other}"),
    }
}

struct Case {
    robot: RobotProfile,
    names: Vec<&'static str>,
    truth: Vec<(&'static str, f64)>,
    duration_s: f64,
    d: Diagnosis,
}

fn case(robot: RobotProfile, names: &[&'static str], seed: u64) -> Case {
    let duration_s = if robot.period_s < 0.05 { 120.0 } else { 300.0 };
    let mut draw = Draw(seed * 7919 + names.len() as u64);
    let mut effects = Effects::default();
    let truth: Vec<(&'static str, f64)> = names
        .iter()
        .flat_map(|n| effect(n, &robot, seed, duration_s, &mut draw, &mut effects))
        .collect();
    let rec = record(&robot, seed, duration_s, effects);
    let d = diagnose(&[rec], &VwPd, &DiagnoseSettings::default()).expect("diagnosis runs");
    Case {
        robot,
        names: names.to_vec(),
        truth,
        duration_s,
        d,
    }
}

/// Checks a case; returns a description of what went wrong, if anything.
fn verdict(c: &Case) -> Option<String> {
    let found: Vec<&str> = c.d.findings.iter().map(|f| f.effect.as_str()).collect();
    let mut sorted_found = found.clone();
    sorted_found.sort_unstable();
    let mut want = c.names.clone();
    want.sort_unstable();
    let tag = format!("{} {:?}", c.robot.name, c.names);
    if sorted_found != want {
        return Some(format!(
            "{tag}: found {found:?}; rejected {:?}",
            c.d.rejected
                .iter()
                .map(|r| format!("{}: {}", r.effect, r.reason))
                .collect::<Vec<_>>()
        ));
    }
    for &(p, want) in &c.truth {
        let got =
            c.d.findings
                .iter()
                .find_map(|f| f.parameters.get(p).copied());
        let Some(got) = got else {
            // A turning loss −θ6 k_w |v| ω is θ5's v·ω when v keeps its sign (as under these
            // excitations): then it must show up in θ5 instead.
            if p == "k_w" {
                let shift = c.robot.theta[5] * want;
                let got = c.d.final_stage.theta[4] - c.robot.theta[4];
                if ((got - shift) / shift).abs() <= 0.2 {
                    continue;
                }
            }
            return Some(format!("{tag}: {p} not reported"));
        };
        let ok = if p == "time_s" {
            // A change inside a validation block can be placed only within that block.
            (got - want).abs() <= c.duration_s / c.d.split.blocks as f64
        } else {
            ((got - want) / want).abs() <= 0.2
        };
        if !ok {
            return Some(format!("{tag}: {p} = {got:.5}, true {want:.5}"));
        }
    }
    let (n, f) = (&c.d.nominal.channels, &c.d.final_stage.channels);
    let rise = (f.v.fit_percent - n.v.fit_percent).max(f.w.fit_percent - n.w.fit_percent);
    if rise <= 0.5
        || f.v.fit_percent < n.v.fit_percent - 1.0
        || f.w.fit_percent < n.w.fit_percent - 1.0
    {
        return Some(format!(
            "{tag}: validation fit v {:.1} → {:.1}, ω {:.1} → {:.1}",
            n.v.fit_percent, f.v.fit_percent, n.w.fit_percent, f.w.fit_percent
        ));
    }
    None
}

fn run(names: &[&'static str], seeds: std::ops::Range<u64>) {
    let mut failures = Vec::new();
    for seed in seeds {
        for robot in [RobotProfile::pioneer3dx(), RobotProfile::khepera3()] {
            let c = case(robot, names, seed);
            if let Some(why) = verdict(&c) {
                failures.push(format!("seed {seed}: {why}"));
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn names_a_dead_time() {
    run(&["input_delay"], 1..3);
}

#[test]
fn names_an_acceleration_limit() {
    run(&["acceleration_limit"], 1..3);
}

#[test]
fn names_a_velocity_saturation() {
    run(&["velocity_saturation"], 1..3);
}

#[test]
fn names_dry_friction() {
    run(&["coulomb_friction"], 1..3);
}

#[test]
fn names_a_wheel_asymmetry() {
    run(&["wheel_asymmetry"], 1..3);
}

#[test]
fn names_a_payload_change() {
    run(&["payload_change"], 1..3);
}

#[test]
fn names_a_gain_drift() {
    run(&["gain_drift"], 1..3);
}

#[test]
fn names_slip() {
    run(&["slip"], 1..3);
}

#[test]
fn names_pairs_of_effects() {
    for (i, pair) in [
        ["input_delay", "velocity_saturation"],
        ["acceleration_limit", "wheel_asymmetry"],
        ["coulomb_friction", "gain_drift"],
        ["payload_change", "input_delay"],
    ]
    .iter()
    .enumerate()
    {
        run(pair, 10 + i as u64..11 + i as u64);
    }
}

/// Clean recordings: nothing may be added. The false-alarm rate over 100 seeds (50 per robot)
/// must be at most 1 %.
#[test]
fn clean_recordings_add_nothing_in_at_least_99_of_100() {
    let mut alarms = Vec::new();
    for seed in 100..150 {
        for robot in [RobotProfile::pioneer3dx(), RobotProfile::khepera3()] {
            let duration = if robot.period_s < 0.05 { 60.0 } else { 180.0 };
            let rec = record(&robot, seed, duration, Effects::default());
            let d = diagnose(&[rec], &VwPd, &DiagnoseSettings::default()).expect("runs");
            if !d.findings.is_empty() {
                alarms.push(format!(
                    "{} seed {seed}: {:?}",
                    robot.name,
                    d.findings.iter().map(|f| &f.effect).collect::<Vec<_>>()
                ));
            }
        }
    }
    eprintln!("false alarms: {} of 100 {alarms:?}", alarms.len());
    assert!(alarms.len() <= 1, "false alarms: {alarms:?}");
}

/// The real Husky A200 (four wet-grass segments): its base limits the yaw rate near ±1 rad/s
/// and ramps its setpoints; the diagnosis must find both and lift ω's validation fit above
/// 90 %. Skipped when `../shared` is absent.
#[test]
fn husky_yaw_rate_limit_and_ramps_lift_the_turn_fit_above_90_percent() {
    let dir = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data/real/husky_drive_wetgrass");
    if !dir.is_dir() {
        eprintln!(
            "SKIP: {} not found (shared/ sits beside the clone in CI)",
            dir.display()
        );
        return;
    }
    let recs: Vec<Recording> = (1..=4)
        .map(|i| {
            Recording::read_csv(dir.join(format!("husky_wetgrass_seg{i}.csv"))).expect("reads")
        })
        .collect();
    let d = diagnose(&recs, &VwPd, &DiagnoseSettings::default()).expect("runs");
    let (n, f) = (&d.nominal.channels, &d.final_stage.channels);
    eprintln!(
        "Husky: v {:.1} → {:.1} %, ω {:.1} → {:.1} %, findings {:?}",
        n.v.fit_percent,
        f.v.fit_percent,
        n.w.fit_percent,
        f.w.fit_percent,
        d.findings
            .iter()
            .map(|x| (&x.effect, &x.parameters))
            .collect::<Vec<_>>()
    );
    assert!(d.mismatch);
    assert!(n.w.fit_percent < 75.0 && f.w.fit_percent > 90.0);
    assert!(f.v.fit_percent >= n.v.fit_percent);
    let w_max = d
        .findings
        .iter()
        .find(|x| x.effect == "velocity_saturation")
        .and_then(|x| x.parameters.get("w_max").copied())
        .expect("a yaw-rate limit");
    // The measured |ω| never exceeds 1.00 rad/s while commands reach 1.77 rad/s.
    assert!((w_max - 1.0).abs() < 0.05, "w_max = {w_max}");
    let ramp = d
        .findings
        .iter()
        .find(|x| x.effect == "acceleration_limit")
        .and_then(|x| x.parameters.get("w_accel_max").copied())
        .expect("a ramp");
    assert!((1.0..4.0).contains(&ramp), "w_accel_max = {ramp}");
}

#[test]
fn names_an_acceleration_limit_the_nominal_lag_absorbed() {
    // Ten minutes of the Khepera III at 50 Hz, both setpoints ramped at 0.45 of the commands'
    // 95th-percentile rate: the nominal fit trades the ramps for a lag 20× too slow (θ1 0.45 s
    // against 0.023 s), where a limit hardly binds. Started only from there the fit stopped at
    // v_accel_max 2.7× too high with v's validation fit at 60 %; the second start, with the
    // lag shortened, finds both limits.
    let robot = RobotProfile::khepera3();
    let seed = 3;
    let a = [0, 1].map(|ch| 0.45 * rate_p95(&robot, seed, ch));
    let effects = Effects {
        acceleration_limit: Some(AccelerationLimit {
            v_accel_max: a[0],
            w_accel_max: a[1],
        }),
        ..Effects::default()
    };
    let duration_s = 600.0;
    let rec = record(&robot, seed, duration_s, effects);
    let d = diagnose(&[rec], &VwPd, &DiagnoseSettings::default()).expect("diagnosis runs");
    let c = Case {
        robot,
        names: vec!["acceleration_limit"],
        truth: vec![("v_accel_max", a[0]), ("w_accel_max", a[1])],
        duration_s,
        d,
    };
    assert_eq!(verdict(&c), None);
    let f = &c.d.findings[0];
    for (p, want) in &c.truth {
        let got = f.parameters[*p];
        assert!(
            ((got - want) / want).abs() < 0.02,
            "{p} = {got}, true {want}"
        );
    }
    for fit in [f.fit_percent_after["v"], f.fit_percent_after["w"]] {
        assert!(fit > 90.0, "validation fit {fit} %");
    }
}

/// The Warthog DRIVE runs (`../shared/data/real/warthog_drive`): a model that explains a fifth
/// of a channel is a mismatch whatever the candidates say. Grass: ω's validation fit is 21.6 %
/// and no test survives Holm; the verdict names ω unexplained with where its misfit lives
/// (measured: 60 % of its power below 0.1 Hz). Asphalt: dry friction on ω (0.25 rad/s) lifts
/// ω from 52.9 % to 66.1 %, and both channels stay unexplained below 70 %.
#[test]
fn warthog_low_fits_are_never_no_mismatch() {
    let dir = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data/real/warthog_drive");
    if !dir.is_dir() {
        eprintln!(
            "SKIP: {} not found (shared/ sits beside the clone in CI)",
            dir.display()
        );
        return;
    }
    let read = |f: &str| Recording::read_csv(dir.join(f)).expect("reads");
    let grass: Vec<Recording> = (1..=3)
        .map(|i| read(&format!("warthog_grass_seg{i}.csv")))
        .collect();
    let d = diagnose(&grass, &VwPd, &DiagnoseSettings::default()).expect("runs");
    assert!(d.final_stage.channels.w.fit_percent < 70.0);
    assert!(d.mismatch, "a 21.6 % fit is a mismatch");
    let u = d.unexplained.as_ref().expect("ω unexplained");
    assert!(u.channels.contains(&"w".to_string()), "{u:?}");
    assert!(
        u.location.iter().any(|l| l.contains("validation fit")),
        "{u:?}"
    );
    let asphalt = [read("warthog_asphalt_seg1.csv")];
    let d = diagnose(&asphalt, &VwPd, &DiagnoseSettings::default()).expect("runs");
    let f = &d.final_stage.channels;
    assert!(d.mismatch);
    if f.v.fit_percent < 70.0 || f.w.fit_percent < 70.0 {
        assert!(d.unexplained.is_some(), "a low fit left silent: {f:?}");
    }
}

/// The excerpt (`search_samples = 3600`, the default) on 10 minutes at 50 Hz of the Khepera III
/// whose drive gain sags by 30 % over the run: searched on 72 s in fifteen windows, the sag is
/// named `gain_drift` with its rate within 5 % and the report says what was searched. (A
/// drift counted from each window's own start named it `payload_change`; this checks the
/// pipeline's plumbing on the simulator's own equations, the method's accuracy is measured on
/// the rigid-body backend, README.)
#[test]
fn the_excerpt_names_a_battery_sag_over_ten_minutes() {
    let robot = RobotProfile::khepera3();
    let rate = -0.3 / 600.0;
    let effects = Effects {
        gain_drift: Some(GainDrift { rate_per_s: rate }),
        ..Effects::default()
    };
    let rec = record(&robot, 3, 600.0, effects);
    let settings = DiagnoseSettings {
        search_samples: 3600,
        ..DiagnoseSettings::default()
    };
    let d = diagnose(&[rec], &VwPd, &settings).expect("diagnosis runs");
    let named: Vec<&str> = d.findings.iter().map(|f| f.effect.as_str()).collect();
    assert_eq!(named, ["gain_drift"]);
    let got = d.findings[0].parameters["rate_per_s"];
    assert!(
        ((got - rate) / rate).abs() < 0.05,
        "rate {got}, true {rate}"
    );
    assert!(
        (d.split.searched_s - 72.0).abs() < 1e-6,
        "searched {} s",
        d.split.searched_s
    );
    assert!(d.split.training_s + d.split.validation_s > 599.0);
}

/// The rate limit + wheel asymmetry case of `benches/diagnose.rs` (10 minutes of the Khepera
/// III at 50 Hz under the bench's multisine, seed 3): both are named, and the voltage clamp
/// nominated beside the wheel asymmetry in the second round, whose screened start leaves the
/// model in hand's training cost as it was (the clamp never binds), is not fitted
/// (`INERT_START`, src/diagnose/budget.rs). Fitted, it took 0.25 s of the case's 1.04 s and was
/// refused at −0.1 %. The first round's clamp, fitted before anything was accepted, still is.
#[test]
fn an_inert_rival_is_not_fitted() {
    let robot = RobotProfile::khepera3();
    let exc = robot.multisine(3).expect("valid multisine");
    let s = SimSettings {
        duration_s: 600.0,
        seed: 3,
        effects: Effects {
            acceleration_limit: Some(AccelerationLimit {
                v_accel_max: 0.1,
                w_accel_max: 2.26,
            }),
            wheel_asymmetry: Some(WheelAsymmetry { ratio: 1.08 }),
            ..Effects::default()
        },
        ..SimSettings::default()
    };
    let rec = simulate_recording(&robot, &exc, &s).expect("simulates");
    let d = diagnose(&[rec], &VwPd, &DiagnoseSettings::default()).expect("diagnosis runs");
    let named: Vec<&str> = d.findings.iter().map(|f| f.effect.as_str()).collect();
    assert_eq!(named, ["acceleration_limit", "wheel_asymmetry"]);
    let clamp: Vec<&str> = d
        .rejected
        .iter()
        .filter(|r| r.effect == "effort_clamp")
        .map(|r| r.reason.as_str())
        .collect();
    assert_eq!(clamp.len(), 2, "{clamp:?}");
    assert!(!clamp[0].contains("never acts"), "{}", clamp[0]);
    assert!(clamp[1].contains("never acts"), "{}", clamp[1]);
}
