//! Experiment design (issue 18, `wheelid::design`) proven on the rigid-body backend: a
//! D-optimal multisine for each robot, designed from the physical map's θ and the wheel-speed
//! noise, driven on the physics robot (window-averaged encoder speeds plus that noise) over
//! 20 seeds and identified by the default output error: θ1, θ2, θ4, θ6 within 2 % in ≤ 45 s,
//! the pose inside the floor space, and the predicted standard errors against the spread
//! over the seeds. The thesis's own excitation cut to the same length is run beside it.

use wheelid::design::{DesignSettings, design};
use wheelid::identify::{IdentifySettings, identify};
use wheelid::models;
use wheelid::robots::Excitation;
use wheelid::robots::physics::{PhysicalProfile, PhysicsSettings, simulate_physics_recording};
use wheelid::solvers::Ols;
use wheelid_core::{RegressorModel, Timing};

/// Seeds (env `WHEELID_DESIGN_SEEDS`; CI's sample 6; 20 for the figure; the spread's
/// proof 80: `scripts/design_spread.sh`, i.e. `WHEELID_DESIGN_SEEDS=80
/// WHEELID_DESIGN_FIRST_SEED=41 cargo test --release --test design -- a_designed_drive`).
fn seeds() -> u64 {
    std::env::var("WHEELID_DESIGN_SEEDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(6)
}

/// The first seed (env `WHEELID_DESIGN_FIRST_SEED`, default 1; seeds 1–6 were looked at while
/// choosing the design's settings, 21 on were not).
fn first_seed() -> u64 {
    std::env::var("WHEELID_DESIGN_FIRST_SEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1)
}

/// θ from `seeds` drives of `exc` for `duration_s`, with white noise of `wheel_noise` \[m/s\]
/// on each reported wheel speed; and the largest |x|, |y| of the recorded pose.
fn drive(
    p: &PhysicalProfile,
    model: &dyn RegressorModel,
    exc: &Excitation,
    duration_s: f64,
    wheel_noise: f64,
) -> (Vec<Vec<f64>>, [f64; 2]) {
    let mut extent = [0.0f64; 2];
    let thetas = (first_seed()..first_seed() + seeds())
        .map(|seed| {
            let s = PhysicsSettings {
                duration_s,
                seed,
                timing: Timing::WindowEnd,
                wheel_noise_std: wheel_noise,
                ..PhysicsSettings::default()
            };
            let rec = simulate_physics_recording(p, exc, &s).expect("simulates");
            let (x, y) = (rec.x.as_ref().expect("pose"), rec.y.as_ref().expect("pose"));
            for (a, b) in x.iter().zip(y) {
                extent = [
                    extent[0].max((a - x[0]).abs()),
                    extent[1].max((b - y[0]).abs()),
                ];
            }
            identified(&rec, model)
        })
        .collect();
    (thetas, extent)
}

/// θ of `rec` by the default identification (output error) of `model`.
fn identified(rec: &wheelid_core::Recording, model: &dyn RegressorModel) -> Vec<f64> {
    identify(
        std::slice::from_ref(rec),
        model,
        &Ols::default(),
        &IdentifySettings::default(),
    )
    .expect("identifies")
    .theta
}

/// Mean and sample standard deviation of θ_i over the runs.
fn spread(thetas: &[Vec<f64>], i: usize) -> (f64, f64) {
    let n = thetas.len() as f64;
    let mean = thetas.iter().map(|t| t[i]).sum::<f64>() / n;
    let var = thetas.iter().map(|t| (t[i] - mean).powi(2)).sum::<f64>() / (n - 1.0).max(1.0);
    (mean, var.sqrt())
}

/// The design settings of the tests for the robot `p` with white noise `wheel_noise` [m/s]
/// on each wheel speed: 80 % of its limits, a 3 m × 3 m space, within 2 % at four standard
/// errors (the worst of 20 seeds, and the model's own bias on the robot, with room).
fn settings(p: &PhysicalProfile, wheel_noise: f64) -> DesignSettings {
    let mut s = DesignSettings::for_robot(p.theta(), p.period_s, [0.8 * p.v_max, 0.8 * p.w_max]);
    // v = (v_r + v_l)/2, ω = (v_r − v_l)/d: the wheels' noise in v and ω.
    s.noise_std = [wheel_noise / 2f64.sqrt(), wheel_noise * 2f64.sqrt() / p.d];
    s.space_m = [3.0, 3.0];
    s.accuracy = 0.02 / 4.0;
    s
}

/// The prediction where eq. 2.19 holds exactly: the design `d` driven on the eq.-2.19
/// simulator with the map's θ and the same white noise `noise_std` on v, ω (no encoder
/// model), over the seeds; asserts within 2 % on every seed and returns the spread / predicted
/// ratio of θ1, θ2, θ4, θ6 (the caller judges them by [`spread_band`] once every figure is
/// printed). The prediction is the model's output-error Cramér–Rao bound: here it holds
/// exactly but for the fit's own errors, so the ratios show how far 20 seeds read it (README:
/// 0.61–1.65 over five windows of 20 seeds).
fn eq_2_19_spread(
    p: &PhysicalProfile,
    model: &dyn RegressorModel,
    d: &wheelid::design::Design,
    noise_std: [f64; 2],
) -> [(usize, f64); 4] {
    use wheelid::robots::effects::MeasurementNoise;
    use wheelid::robots::{SimSettings, simulate_recording};
    let robot = p.model_profile();
    let thetas: Vec<Vec<f64>> = (first_seed()..first_seed() + seeds())
        .map(|seed| {
            let mut sim = SimSettings {
                duration_s: d.duration_s,
                seed,
                measurement_noise: false,
                ..SimSettings::default()
            };
            sim.effects.measurement_noise = Some(MeasurementNoise {
                v_std: noise_std[0],
                w_std: noise_std[1],
            });
            let rec = simulate_recording(&robot, &d.excitation, &sim).expect("simulates");
            identified(&rec, model)
        })
        .collect();
    let ratios = [0, 1, 3, 5].map(|i| {
        let ratio = spread(&thetas, i).1 / d.predicted_std_err[i];
        eprintln!(
            "  eq. 2.19 simulator: θ{}: spread / predicted {ratio:.2}",
            i + 1
        );
        (i, ratio)
    });
    for (i, _) in ratios {
        let truth = p.theta()[i];
        for t in &thetas {
            assert!(((t[i] - truth) / truth).abs() < 0.02, "θ{}", i + 1);
        }
    }
    ratios
}

/// The band in which the spread / predicted ratio of `n` seeds lies for an exact prediction
/// but one time in a thousand, widened to the issue's ±30 %: the two-sided 99.9 % band of
/// s/σ = √(χ²ₖ/k), k = n − 1 (Wilson–Hilferty: χ²ₖ/k ≈ (1 − 2/(9k) + z √(2/(9k)))³, z =
/// 3.29). At 20 seeds it is 0.50–1.56: a sample of 20 reads an exact prediction outside
/// ±30 % with P ≈ 0.06 a ratio, on one of θ1, θ2, θ4, θ6 about one time in four, so ±30 % there
/// would be a test that fails by chance; from 65 seeds on the band lies inside ±30 %, and ±30 %
/// is what is asserted (`scripts/design_spread.sh` runs 80).
fn spread_band(n: u64) -> (f64, f64) {
    let k = n.saturating_sub(1).max(1) as f64;
    let c = 2.0 / (9.0 * k);
    let q = |z: f64| (1.0 - c + z * c.sqrt()).max(0.0).powi(3).sqrt();
    (q(-3.29).min(0.7), q(3.29).max(1.3))
}

/// On 20 seeds or more, θ`i+1`'s spread / predicted `ratio` within [`spread_band`] (6 are too
/// few to judge a spread).
fn assert_spread(i: usize, ratio: f64) {
    if seeds() >= 20 {
        let (lo, hi) = spread_band(seeds());
        assert!(
            (lo..=hi).contains(&ratio),
            "θ{}: spread / predicted {ratio:.2} outside {lo:.2}–{hi:.2} ({} seeds)",
            i + 1,
            seeds()
        );
    }
}

/// [`spread_band`]'s Wilson–Hilferty quantile against the χ² table (19 degrees of freedom:
/// 2.5 % and 97.5 % quantiles 8.907 and 32.852), and its band at 20 and 80 seeds.
#[test]
fn the_spread_band_follows_the_chi_square_table() {
    let k = 19.0;
    let c = 2.0 / (9.0 * k);
    let q = |z: f64| k * (1.0 - c + z * f64::sqrt(c)).powi(3);
    assert!((q(-1.96) / 8.907 - 1.0).abs() < 0.005, "{}", q(-1.96));
    assert!((q(1.96) / 32.852 - 1.0).abs() < 0.005, "{}", q(1.96));
    let (lo, hi) = spread_band(20);
    assert!(
        (lo - 0.50).abs() < 0.01 && (hi - 1.56).abs() < 0.01,
        "{lo} {hi}"
    );
    assert_eq!(spread_band(80), (0.7, 1.3));
}

/// Designs for `name`, drives the design and the thesis's signal of the same length over the
/// seeds; asserts θ1, θ2, θ4, θ6 within 2 % on every seed in ≤ 45 s inside a 3 m × 3 m space,
/// and the spread against the predicted standard errors within [`spread_band`] on 20 seeds or
/// more (6 are too few to judge a spread; ±30 % from 65 seeds on).
fn designed_drive(name: &str) {
    let wheel_noise = 0.01;
    {
        let p = PhysicalProfile::by_name(name).expect("profile");
        let model = models::by_name(p.model_name()).expect("model");
        let s = settings(&p, wheel_noise);
        let d = design(model.as_ref(), &s).expect("designs");
        let twin = eq_2_19_spread(&p, model.as_ref(), &d, s.noise_std);
        eprintln!(
            "{name}: {} s on lines to {:.2} Hz, predicted se {:.5?}, extent {:.2?} m, {} \
             candidates",
            d.duration_s, d.f_max_hz, d.predicted_std_err, d.extent_m, d.evaluations
        );
        assert!(d.duration_s <= 45.0, "{} s", d.duration_s);
        let (thetas, extent) = drive(&p, model.as_ref(), &d.excitation, d.duration_s, wheel_noise);
        eprintln!("  recorded pose extent {extent:.2?} m");
        assert!(
            extent[0] <= 1.5 && extent[1] <= 1.5,
            "left the 3 m × 3 m space"
        );
        let thesis = if name == "khepera3" {
            Excitation::thesis_khepera()
        } else {
            Excitation::thesis_pioneer()
        };
        let (th_thesis, _) = drive(&p, model.as_ref(), &thesis, d.duration_s, wheel_noise);
        let mut ratios = Vec::new();
        for i in [0, 1, 3, 5] {
            let truth = p.theta()[i];
            let worst = |ts: &[Vec<f64>]| {
                ts.iter()
                    .map(|t| 100.0 * ((t[i] - truth) / truth).abs())
                    .fold(0.0f64, f64::max)
            };
            let (mean, sd) = spread(&thetas, i);
            eprintln!(
                "  θ{} mean error {:+.2} %",
                i + 1,
                100.0 * (mean - truth) / truth
            );
            let ratio = sd / d.predicted_std_err[i];
            eprintln!(
                "  θ{}: worst error {:.2} % (thesis signal, same length: {:.2} %), spread {sd:.5} \
                 vs predicted {:.5} (ratio {ratio:.2})",
                i + 1,
                worst(&thetas),
                worst(&th_thesis),
                d.predicted_std_err[i]
            );
            assert!(worst(&thetas) < 2.0, "θ{}", i + 1);
            ratios.push((i, ratio));
        }
        // Both spreads are judged once every figure is printed.
        for (i, ratio) in twin.into_iter().chain(ratios) {
            assert_spread(i, ratio);
        }
    }
}

#[test]
fn a_designed_drive_identifies_the_pioneer_within_two_percent_in_45_s() {
    designed_drive("pioneer3dx");
}

/// The rigid-body Khepera-like robot: on lines to half its bandwidth (the default band) the
/// designed drive is 40 s. (On lines to twice it, the design before 2026-11-25, a 20 s drive
/// left θ1 −2 % and θ6 +7 %: the model's bias, excited above the bandwidth.)
#[test]
fn a_designed_drive_identifies_the_khepera_within_two_percent_in_45_s() {
    designed_drive("khepera3");
}

/// `wheelid design --out plan.toml` writes a run config's `duration_s` and `[excitation]`
/// that `wheelid run` drives as it is (with a robot and an output added); a bad accuracy is a
/// clear error.
#[test]
fn the_cli_plan_drives_a_robot_through_run() {
    let exe = env!("CARGO_BIN_EXE_wheelid");
    let dir = tempfile::tempdir().expect("tempdir");
    let plan = dir.path().join("plan.toml");
    let o = std::process::Command::new(exe)
        .args([
            "design",
            "--robot",
            "pioneer3dx",
            "--accuracy",
            "1%",
            "--out",
        ])
        .arg(&plan)
        .arg("--plot")
        .arg(dir.path())
        .output()
        .expect("runs");
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{text} {}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(text.contains("predicted standard error"), "{text}");
    assert!(dir.path().join("design.png").exists());
    let mut cfg = std::fs::read_to_string(&plan).expect("plan written");
    cfg.push_str(
        "\n[robot]\ntype = \"simulator\"\nrobot = \"pioneer3dx\"\n\n[output]\ndir = \"out\"\n",
    );
    let run_cfg = dir.path().join("run.toml");
    std::fs::write(&run_cfg, cfg).expect("config");
    let o = std::process::Command::new(exe)
        .arg("run")
        .arg(&run_cfg)
        .output()
        .expect("runs");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let rec =
        wheelid_core::Recording::read_csv(dir.path().join("out/recording.csv")).expect("recording");
    let duration: f64 = toml::from_str::<toml::Table>(&std::fs::read_to_string(&plan).unwrap())
        .expect("toml")["duration_s"]
        .as_float()
        .expect("duration");
    assert!(
        (rec.t[rec.len() - 1] - rec.t[0] - duration).abs() <= 0.2,
        "{duration} s planned"
    );
    let o = std::process::Command::new(exe)
        .args(["design", "--accuracy", "150%"])
        .output()
        .expect("runs");
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("--accuracy 150%"));
}
