//! `wheelid run CONFIG` with the configs in `examples/configs/`: every robot backend (the
//! simulator, replay of a CSV and of an MCAP bag, the Pioneer and Khepera over their protocols
//! against the loopback servers) and the example plugin, each identified against the true θ of
//! the robot behind it; then every way a config or a plugin can be wrong, each a clear error.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Mutex;

use wheelid::observer::Silent;
use wheelid::run::run;

fn config(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("examples/configs")
        .join(name)
}

/// θ1, θ2, θ4, θ6 (the well-excited ones) within `tol` of `truth`.
fn assert_close(theta: &[f64], truth: &[f64], tol: f64, what: &str) {
    for i in [0, 1, 3, 5] {
        let e = (theta[i] - truth[i]) / truth[i];
        assert!(
            e.abs() < tol,
            "{what}: θ{} = {} vs true {} ({:+.2} %)",
            i + 1,
            theta[i],
            truth[i],
            100.0 * e
        );
    }
}

const PIONEER: [f64; 6] = [0.2604, 0.2509, -0.000499, 0.9965, 0.00263, 1.0768];
const KHEPERA: [f64; 6] = [0.0228, 0.0568, -0.0001, 1.0030, 0.0732, 0.9981];

/// An observer that keeps what the drive reported: (message, done, total) of each call.
#[derive(Default)]
struct Reports(Mutex<Vec<(String, u64, u64)>>);

impl wheelid::observer::Observer for Reports {
    fn progress(&self, message: &str, done: u64, total: u64) {
        if let Ok(mut r) = self.0.lock() {
            r.push((message.to_owned(), done, total));
        }
    }
}

#[test]
fn the_simulator_config_identifies_the_pioneer_and_writes_every_output() {
    let reports = Reports::default();
    let out = run(&config("run_simulator.toml"), &reports).expect("runs");
    assert_eq!(out.recording.len(), 1500);
    // The drive reported each sample to the observer, counting up to the 1,500 planned.
    let reports = reports.0.into_inner().expect("reports");
    assert_eq!(reports.len(), 1500);
    assert!(
        reports
            .iter()
            .all(|(m, _, total)| m == "driving" && *total == 1500)
    );
    assert_eq!(
        reports.iter().map(|r| r.1).collect::<Vec<_>>(),
        (1..=1500).collect::<Vec<u64>>()
    );
    assert_eq!(
        out.recording.meta("velocity_sampling"),
        Some("window_average")
    );
    assert_close(&out.identification.theta, &PIONEER, 0.005, "simulator");
    // recording.csv reads back; model.toml is the identification; the reports exist.
    let rec = wheelid::core::Recording::read_csv(&out.files[0]).expect("csv");
    assert_eq!(rec.v, out.recording.v);
    let model = wheelid::files::ModelFile::read(&out.files[1]).expect("model file");
    assert_eq!(model.theta, out.identification.theta);
    let report = std::fs::read_to_string(&out.files[2]).expect("report");
    assert!(report.contains("theta1"), "{report}");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out.files[3]).expect("json")).expect("json");
    assert_eq!(json["model"], "vw-pd");
}

/// Also `run --online` (issue 18): θ̂ estimated while driving lands within 1 % of the batch
/// answer in θ1, θ2, θ4, θ6, with no change alarm, and `online.csv` holds every sample.
#[test]
fn the_physics_config_identifies_the_rigid_body_khepera_within_one_percent_of_its_map() {
    let options = wheelid::run::RunOptions { online: true };
    let out = wheelid::run::run_with(&config("run_physics.toml"), &Silent, options).expect("runs");
    assert_eq!(out.recording.meta("timing"), Some("window_end"));
    let map = wheelid::robots::physics::PhysicalProfile::khepera3().theta();
    assert_close(&out.identification.theta, &map, 0.01, "physics khepera");
    let trace = out.online.expect("online trace");
    assert_eq!(trace.t.len(), out.recording.len());
    let last = trace.theta.last().expect("samples");
    for i in [0, 1, 3, 5] {
        let e = (last[i] - out.identification.theta[i]) / out.identification.theta[i];
        assert!(e.abs() < 0.01, "online θ{} off the batch by {e}", i + 1);
    }
    assert!(trace.change.iter().all(|c| !c[0] && !c[1]));
    let csv = out
        .files
        .iter()
        .find(|f| f.ends_with("online.csv"))
        .expect("online.csv");
    let text = std::fs::read_to_string(csv).expect("written");
    assert_eq!(text.lines().count(), trace.t.len() + 1);
    assert!(text.starts_with("t,theta1,"));
    let png = out
        .files
        .iter()
        .find(|f| f.ends_with("online.png"))
        .expect("online.png");
    assert!(std::fs::metadata(png).expect("plotted").len() > 10_000);
}

#[test]
fn the_pioneer_over_arcos_against_the_loopback_server_is_identified() {
    let out = run(&config("run_pioneer_loopback.toml"), &Silent).expect("runs");
    assert_eq!(out.recording.len(), 1200);
    // The protocol's resolution (1 mm/s, 1 °/s) costs little.
    assert_close(&out.identification.theta, &PIONEER, 0.01, "pioneer");
}

#[test]
fn the_khepera_over_its_serial_protocol_against_the_loopback_server_is_identified() {
    let out = run(&config("run_khepera_loopback.toml"), &Silent).expect("runs");
    assert_eq!(out.recording.len(), 3000);
    assert_close(&out.identification.theta, &KHEPERA, 0.01, "khepera");
}

#[test]
fn a_ros2_bag_made_by_the_simulator_replays_and_identifies() {
    // The bag the example config names is in the repository (a fresh checkout runs it); it is
    // what its comment's command makes: encoder velocities (window averages), which the bag's
    // `wheelid` metadata says, so no `--exact` is needed.
    let dir = tempfile::tempdir().expect("tempdir");
    let remade = dir.path().join("khepera_sim.mcap");
    let o = Command::new(env!("CARGO_BIN_EXE_wheelid"))
        .args([
            "simulate",
            "--robot",
            "khepera3",
            "--excitation",
            "multisine",
            "--duration",
            "40",
            "--seed",
            "1",
            "--out",
        ])
        .arg(&remade)
        .output()
        .expect("runs");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let committed = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/data/khepera_sim.mcap");
    let read = |p: &Path| {
        wheelid::files::read_recording(p, wheelid::core::Columns::All).expect("reads the bag")
    };
    let (a, b) = (read(&committed), read(&remade));
    assert_eq!((&a.t, &a.v_ref, &a.w_ref), (&b.t, &b.v_ref, &b.w_ref));
    assert_eq!((&a.v, &a.w), (&b.v, &b.w));
    let out = run(&config("run_replay_mcap.toml"), &Silent).expect("runs");
    assert_eq!(out.recording.len(), 2001);
    assert_eq!(out.recording.meta("timing"), Some("window_end"));
    assert_close(&out.identification.theta, &KHEPERA, 0.01, "mcap replay");
}

#[test]
fn a_csv_replays_the_real_husky() {
    let csv = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data/real/husky_drive_wetgrass/husky_wetgrass_seg1.csv");
    if !csv.exists() {
        eprintln!(
            "SKIP: {} not found (shared/ sits beside the clone in CI)",
            csv.display()
        );
        return;
    }
    let out = run(&config("run_replay_csv.toml"), &Silent).expect("runs");
    let direct = wheelid::core::Recording::read_csv(&csv).expect("reads");
    // Every sample comes back with its own command, and the fit is the Husky's (the
    // identification test reports v about 89 % and ω about 75 % on all four segments).
    assert_eq!(out.recording.len(), direct.len());
    assert_eq!(out.recording.v_ref, direct.v_ref);
    assert_eq!(out.recording.v, direct.v);
    let fit = |c: usize| out.identification.channels[c].fit_percent;
    assert!(fit(0) > 80.0 && fit(1) > 60.0, "fit {} {}", fit(0), fit(1));
}

/// One plugin build at a time: the fault builds overwrite the same library file.
static BUILD: Mutex<()> = Mutex::new(());

/// Builds the example plugin with `feature` (or none) and returns the library cargo left.
///
/// The build is `cargo test --workspace --no-run`, the same resolution as the workspace's test
/// run that is running this test: without a feature it is already built (nothing recompiles),
/// with one only the plugin crate does.
fn built_plugin(feature: Option<&str>) -> PathBuf {
    let mut cmd = Command::new(env!("CARGO"));
    cmd.args([
        "test",
        "--workspace",
        "--no-run",
        "--locked",
        "--message-format=json-render-diagnostics",
    ])
    .current_dir(env!("CARGO_MANIFEST_DIR"));
    if let Some(f) = feature {
        cmd.args(["--features", &format!("wheelid-turtlebot-plugin/{f}")]);
    }
    let o = cmd.output().expect("cargo runs");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8_lossy(&o.stdout)
        .lines()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .filter(|v| v["reason"] == "compiler-artifact")
        .filter(|v| v["target"]["name"] == "wheelid_turtlebot_plugin")
        .filter(|v| v["profile"]["test"] == false)
        .flat_map(|v| {
            v["filenames"]
                .as_array()
                .cloned()
                .unwrap_or_default()
                .into_iter()
                .filter_map(|f| f.as_str().map(PathBuf::from))
                .collect::<Vec<_>>()
        })
        .find(|f| f.extension().is_some_and(|e| e == "so" || e == "dylib"))
        .expect("the cdylib artifact")
}

/// Builds the example plugin with `feature` (or none) ([`built_plugin`]) and copies the library
/// to a fresh file under `dir` (a library is loaded once per path, and never unloaded).
fn build_plugin(feature: Option<&str>, dir: &Path) -> PathBuf {
    let built = built_plugin(feature);
    let copy = dir.join(format!(
        "libturtlebot_{}.so",
        feature.unwrap_or("good").replace('-', "_")
    ));
    std::fs::copy(&built, &copy).expect("copy");
    copy
}

/// The example plugin built without faults, one build at a time ([`BUILD`]), copied under `dir`.
fn good_plugin(dir: &Path) -> PathBuf {
    let _one = BUILD.lock().unwrap_or_else(|e| e.into_inner());
    build_plugin(None, dir)
}

/// The example plugin config with its `plugins` line pointing at `lib`, written under `dir`.
fn plugin_config(lib: &Path, dir: &Path) -> PathBuf {
    let text = std::fs::read_to_string(config("run_plugin.toml")).expect("example config");
    let text = text
        .lines()
        .map(|l| {
            if l.starts_with("plugins") {
                format!("plugins = [{:?}]", lib.display().to_string())
            } else if l.starts_with("dir = ") {
                "dir = \"out\"".to_owned()
            } else {
                l.to_owned()
            }
        })
        .collect::<Vec<_>>()
        .join("\n");
    let path = dir.join("run_plugin.toml");
    std::fs::write(&path, text).expect("write");
    path
}

/// `stop_when = "accuracy"` (issue 18, sequential identification): the rigid-body Khepera is
/// driven until the online 95 % intervals of θ1, θ2, θ4, θ6 are within 1 % — long before the
/// 120 s cap — and θ̂ there, and the batch answer on that drive, are within 1 % of the map.
/// Without an accuracy, or an accuracy without the rule, the config is a clear error.
#[test]
fn a_run_stops_once_the_online_intervals_reach_the_accuracy() {
    let out = run(&config("run_physics_until_accurate.toml"), &Silent).expect("runs");
    let trace = out.online.expect("online trace");
    let (target, reached) = trace.accuracy.expect("an accuracy target");
    let t = reached.expect("reached within 120 s");
    let duration = out.recording.t[out.recording.len() - 1] - out.recording.t[0];
    eprintln!("stopped at {t:.2} s (recording {duration:.2} s)");
    assert_eq!(target, 0.01);
    assert!(
        t < 60.0 && (duration - t).abs() < 0.1,
        "{t} s, {duration} s"
    );
    let map = wheelid::robots::physics::PhysicalProfile::khepera3().theta();
    let (th, se) = (
        trace.theta.last().expect("θ̂"),
        trace.std_err.last().expect("σ̂"),
    );
    for i in [0, 1, 3, 5] {
        assert!(1.96 * se[i] <= 0.01 * th[i].abs(), "θ{} interval", i + 1);
    }
    assert_close(th, &map, 0.01, "online at the stop");
    assert_close(&out.identification.theta, &map, 0.01, "batch at the stop");
    let head = "duration_s = 5.0\n[robot]\ntype = \"simulator\"\n[output]\ndir = \"o\"\n";
    let e = run_text(&format!("stop_when = \"accuracy\"\n{head}"));
    assert!(
        e.contains("bad.toml: stop_when = \"accuracy\" needs accuracy in (0, 1)"),
        "{e}"
    );
    let e = run_text(&format!("accuracy = 0.01\n{head}"));
    assert!(
        e.contains("bad.toml: accuracy is read only with stop_when"),
        "{e}"
    );
}

#[test]
fn every_example_config_is_a_run_config_and_the_plugin_one_runs_as_its_comment_says() {
    // Configs for other commands live apart (examples/diagnose/); each one here parses.
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/configs");
    let mut n = 0;
    for entry in std::fs::read_dir(&dir).expect("examples/configs") {
        let path = entry.expect("entry").path();
        let text = std::fs::read_to_string(&path).expect("reads");
        wheelid::run::parse_config(&text, &path).expect("a run config");
        n += 1;
    }
    assert!(n >= 7, "{n} configs");
    // run_plugin.toml names the plugin by its bare name, found beside the `wheelid` executable;
    // its comment says to build it first (`cargo build -p wheelid-turtlebot-plugin`), which
    // leaves the library beside the executable. The library is put there from this test run's
    // own build of the plugin (the same sources and profile): a `cargo build -p` of the plugin
    // alone resolves features for that package only, so it recompiled nalgebra, serde,
    // wheelid-core and wheelid-models in the middle of the test run (~2 min on CI's 2 cores).
    let _one = BUILD.lock().unwrap_or_else(|e| e.into_inner());
    let exe = Path::new(env!("CARGO_BIN_EXE_wheelid"));
    let beside = exe.parent().expect("the executable's folder").join(format!(
        "{}wheelid_turtlebot_plugin{}",
        std::env::consts::DLL_PREFIX,
        std::env::consts::DLL_SUFFIX
    ));
    let built = built_plugin(None);
    // Renamed into place: a library another process has mapped is replaced, never rewritten.
    let staged = beside.with_extension("staged");
    std::fs::copy(&built, &staged).expect("copy");
    std::fs::rename(&staged, &beside).expect("rename");
    let o = Command::new(env!("CARGO_BIN_EXE_wheelid"))
        .args(["run"])
        .arg(config("run_plugin.toml"))
        .output()
        .expect("runs");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stdout).contains("vw-pd-coulomb"));
}

#[test]
fn a_plugin_model_is_identified_and_diagnosed_from_the_command_line() {
    // The plugin's robot drives (as `wheelid run` does), then its model is identified and
    // diagnosed by `identify --plugin` and `diagnose --plugin`, which load the same library.
    let dir = tempfile::tempdir().expect("tempdir");
    let lib = good_plugin(dir.path());
    let out = run(&plugin_config(&lib, dir.path()), &Silent).expect("runs");
    let csv = dir.path().join("burger.csv");
    out.recording.write_csv(&csv).expect("writes");
    let wheelid = |cmd: &str| {
        let o = Command::new(env!("CARGO_BIN_EXE_wheelid"))
            .arg(cmd)
            .arg(&csv)
            .arg("--plugin")
            .arg(&lib)
            .args(["--model", "vw-pd-coulomb", "--json"])
            .output()
            .expect("runs");
        assert!(
            o.status.success(),
            "{cmd}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        serde_json::from_slice::<serde_json::Value>(&o.stdout).expect("JSON")
    };
    // The Burger's dry friction (examples/turtlebot-plugin/src/burger.rs): 1.962e-3 m/s,
    // 2.453e-2 rad/s, as the plugin model's seventh and eighth parameters.
    let id = wheelid("identify");
    assert_eq!(id["model"], "vw-pd-coulomb");
    let theta: Vec<f64> = id["theta"]
        .as_array()
        .expect("theta")
        .iter()
        .filter_map(serde_json::Value::as_f64)
        .collect();
    assert_eq!(theta.len(), 8);
    for (x, truth) in theta[6..].iter().zip([1.962e-3, 2.453e-2]) {
        assert!(
            (x - truth).abs() < 0.05 * truth,
            "identify --plugin: {x} vs {truth}"
        );
    }
    // The diagnosis extends the plugin model's θ1…θ6 (eq. 2.19) and finds its friction again.
    let d = wheelid("diagnose");
    let f = &d["findings"][0];
    assert_eq!(f["effect"], "coulomb_friction", "{d}");
    let found = [
        f["parameters"]["v_coulomb"].as_f64().expect("v"),
        f["parameters"]["w_coulomb"].as_f64().expect("w"),
    ];
    for (x, truth) in found.iter().zip([1.962e-3, 2.453e-2]) {
        assert!(
            (x - truth).abs() < 0.05 * truth,
            "diagnose --plugin: {x} vs {truth}"
        );
    }
}

#[test]
fn a_plugin_estimator_is_chosen_by_name_compared_and_resists_spikes() {
    // The example plugin's `huber` estimator (examples/turtlebot-plugin/src/huber.rs) through
    // the same registry as the built-in ones: `--estimator huber` picks it, `--compare` runs it
    // after ls, iv, oe. On a Khepera III recording with a spike in every 50th sample of v and
    // ω (±0.05 m/s, ±0.5 rad/s), its θ̂ holds the true θ within 3 of its σ and its θ5 interval
    // is at least twice as narrow as least squares' (measured σ 0.0096 vs 0.0247).
    let dir = tempfile::tempdir().expect("tempdir");
    let lib = good_plugin(dir.path());
    let csv = dir.path().join("spiky.csv");
    let bin = env!("CARGO_BIN_EXE_wheelid");
    let o = Command::new(bin)
        .args([
            "simulate",
            "--robot",
            "khepera3",
            "--excitation",
            "multisine",
        ])
        .args(["--duration", "120", "--seed", "3", "--out"])
        .arg(&csv)
        .output()
        .expect("runs");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let mut rec = wheelid::core::Recording::read_csv(&csv).expect("reads");
    for k in (25..rec.len()).step_by(50) {
        let sign = if (k / 50) % 2 == 0 { 1.0 } else { -1.0 };
        rec.v[k] += sign * 0.05;
        rec.w[k] -= sign * 0.5;
    }
    rec.write_csv(&csv).expect("writes");
    let identify = |args: &[&str]| {
        Command::new(bin)
            .arg("identify")
            .arg(&csv)
            .args(args)
            .output()
            .expect("runs")
    };
    let o = identify(&[
        "--plugin",
        lib.to_str().expect("utf-8"),
        "--compare",
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("JSON");
    let estimates = v["estimates"].as_array().expect("estimates");
    let names: Vec<&str> = estimates
        .iter()
        .filter_map(|e| e["estimator"].as_str())
        .collect();
    assert_eq!(names, ["ls", "iv", "oe", "huber"]);
    let column = |e: &serde_json::Value, key: &str| -> Vec<f64> {
        e[key]
            .as_array()
            .expect(key)
            .iter()
            .filter_map(serde_json::Value::as_f64)
            .collect()
    };
    let (huber, ls) = (&estimates[3], &estimates[0]);
    let (theta, sigma) = (column(huber, "theta"), column(huber, "std_err"));
    for i in [0, 1, 3, 4, 5] {
        assert!(
            (theta[i] - KHEPERA[i]).abs() < 3.0 * sigma[i],
            "huber θ{}: {} ± {} vs {}",
            i + 1,
            theta[i],
            sigma[i],
            KHEPERA[i]
        );
    }
    let sigma_ls = column(ls, "std_err");
    assert!(
        sigma[4] < 0.5 * sigma_ls[4],
        "θ5: huber σ {} vs least squares σ {}",
        sigma[4],
        sigma_ls[4]
    );
    // Without the plugin the name is unknown, and the error lists the built-in ones.
    let o = identify(&["--estimator", "huber"]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("unknown estimator `huber`; known estimators: ls, iv, oe"),
        "{err}"
    );
}

#[test]
fn the_example_plugin_adds_a_robot_and_a_model_that_identify() {
    let dir = tempfile::tempdir().expect("tempdir");
    let lib = good_plugin(dir.path());
    let out = run(&plugin_config(&lib, dir.path()), &Silent).expect("runs");
    let id = &out.identification;
    assert_eq!(id.model, "vw-pd-coulomb");
    // The Burger's true θ and dry friction (examples/turtlebot-plugin/src/burger.rs).
    let truth = [
        0.150240, 0.150194, -3.45e-6, 1.046490, -5.40e-4, 1.046490, 1.962e-3, 2.453e-2,
    ];
    assert_eq!(id.theta.len(), 8);
    assert_close(&id.theta, &truth, 0.03, "plugin");
    for i in [6, 7] {
        let e = (id.theta[i] - truth[i]) / truth[i];
        assert!(
            e.abs() < 0.1,
            "friction {i}: {} vs {}",
            id.theta[i],
            truth[i]
        );
    }
}

#[test]
fn every_plugin_failure_is_a_clear_error() {
    let dir = tempfile::tempdir().expect("tempdir");
    let err = |lib: &Path| -> String {
        match run(&plugin_config(lib, dir.path()), &Silent) {
            Ok(_) => panic!("{} loaded", lib.display()),
            Err(e) => format!("{e:#}"),
        }
    };
    // No file; a file that is no library.
    let e = err(&dir.path().join("libabsent.so"));
    assert!(e.contains("libabsent.so: no such file"), "{e}");
    let junk = dir.path().join("libjunk.so");
    std::fs::write(&junk, b"\x7fELF but not really").expect("write");
    let e = err(&junk);
    assert!(
        e.contains("libjunk.so: not a loadable shared library"),
        "{e}"
    );
    let _one = BUILD.lock().unwrap_or_else(|e| e.into_inner());
    let cases = [
        ("fault-no-declaration", "not a wheelid plugin"),
        ("fault-api-version", "incompatible: plugin API version 3"),
        ("fault-rustc-version", "built by `rustc 0.0.0"),
        (
            "fault-panic-in-register",
            "registration failed: the plugin panicked: fault-panic-in-register",
        ),
        (
            "fault-panic-in-factory",
            "[robot]: the plugin panicked: fault-panic-in-factory",
        ),
    ];
    for (feature, want) in cases {
        let lib = build_plugin(Some(feature), dir.path());
        let e = err(&lib);
        assert!(e.contains(want), "{feature}: {e}");
    }
    // Leave the good build where the example config expects it.
    build_plugin(None, dir.path());
}

/// `[design]` (issue 18, re-design on the way): the rigid-body Pioneer-like robot starts on
/// the design for a prior three times too slow and the design is made again every 10 s from
/// the online θ̂ (examples/configs/run_physics_redesign.toml). Measured: five re-designs, the
/// first from θ̂1, θ̂2 within 6 % of the map (−4.5 %, −5.2 %: the online estimator's
/// least-squares warm-up, split fixed by the stamping); the pose after the first take-over
/// inside the 3 m × 3 m floor (at most 1.472 m from its centre along x or y); after 60 s the
/// online intervals of θ1, θ2 3.6× and 2.3× narrower than the same drive on the prior's
/// design, the batch standard errors of θ1, θ2 2.9× and 2.3× smaller. `[design]` needs `stop_when = "accuracy"` and a
/// prior or an `[excitation]`: clear errors naming the file.
#[test]
fn a_run_re_designs_its_excitation_from_the_online_estimate() {
    let dir = tempfile::tempdir().expect("tempdir");
    // The example's drive for its first 60 s, never stopped on an accuracy (its batch checks
    // pushed beyond the drive).
    let sixty = [
        (
            "accuracy_of = \"batch\"   #",
            "accuracy_every_s = 1000.0\naccuracy_of = \"batch\"   #",
        ),
        ("duration_s = 150.0", "duration_s = 60.0"),
    ];
    let path = redesign_config(dir.path(), "on.toml", &sixty);
    let on = run(&path, &Silent).expect("runs");
    let trace = on.online.as_ref().expect("online trace");
    let map = wheelid::robots::physics::PhysicalProfile::pioneer3dx().theta();
    assert_eq!(trace.redesigns.len(), 5, "{:?}", trace.redesigns);
    assert!(trace.redesigns.iter().all(|r| r.outcome.is_ok()));
    let first = &trace.redesigns[0];
    for i in [0, 1] {
        let e = (first.theta[i] - map[i]) / map[i];
        eprintln!(
            "θ̂{} at the first re-design: {:+.2} % of the map",
            i + 1,
            100.0 * e
        );
        assert!(
            e.abs() < 0.06,
            "θ̂{} at the first re-design: {:+.3}",
            i + 1,
            e
        );
    }
    let Ok((takeover, _)) = first.outcome else {
        unreachable!()
    };
    let rec = &on.recording;
    let (x, y) = (rec.x.as_ref().expect("x"), rec.y.as_ref().expect("y"));
    let worst = (0..rec.len())
        .filter(|&k| rec.t[k] - rec.t[0] > takeover)
        .map(|k| (x[k] - x[0]).abs().max((y[k] - y[0]).abs()))
        .fold(0.0f64, f64::max);
    eprintln!("the pose at most {worst:.3} m from the centre after the first take-over");
    assert!(worst < 1.5, "the pose reached {worst} m from the centre");

    // The same drive on the prior's design alone (never re-designed).
    let mut never = sixty.to_vec();
    never.push(("every_s = 10.0", "every_s = 1000.0"));
    let off = run(&redesign_config(dir.path(), "off.toml", &never), &Silent).expect("runs");
    let off_trace = off.online.as_ref().expect("online trace");
    assert!(off_trace.redesigns.is_empty());
    let width = |t: &wheelid::run::OnlineTrace, i: usize| {
        let (th, se) = (t.theta.last().expect("θ̂"), t.std_err.last().expect("σ̂"));
        se[i] / th[i].abs()
    };
    for (i, at_least) in [(0, 3.0), (1, 2.0)] {
        let ratio = width(off_trace, i) / width(trace, i);
        eprintln!("θ{}: online interval {ratio:.2}× narrower", i + 1);
        assert!(
            ratio > at_least,
            "θ{}: online interval {ratio:.2}× narrower",
            i + 1
        );
    }
    for (i, at_least) in [(0, 2.5), (1, 2.0)] {
        let batch = off.identification.std_err[i] / on.identification.std_err[i];
        eprintln!("θ{}: batch standard error {batch:.2}× smaller", i + 1);
        assert!(
            batch > at_least,
            "θ{} batch standard error {batch:.2}× smaller",
            i + 1
        );
    }

    let design = "[design]\nprior = [0.26, 0.25, 0.0, 1.0, 0.2, 1.0]\ncommand_max = [0.5, 1.2]\n";
    let head = "duration_s = 5.0\n[robot]\ntype = \"simulator\"\n[output]\ndir = \"o\"\n";
    let e = run_text(&format!("{head}{design}"));
    assert!(
        e.contains("bad.toml: [design] re-designs toward an accuracy"),
        "{e}"
    );
    let no_prior = "[design]\ncommand_max = [0.5, 1.2]\n";
    let e = run_text(&format!(
        "stop_when = \"accuracy\"\naccuracy = 0.02\n{head}{no_prior}"
    ));
    assert!(
        e.contains("bad.toml: [design]") && e.contains("no prior"),
        "{e}"
    );
}

/// examples/configs/run_physics_redesign.toml with `edits` (from → to) and its outputs in
/// `dir/out`, written as `dir/name`.
fn redesign_config(dir: &Path, name: &str, edits: &[(&str, &str)]) -> PathBuf {
    edited_config("run_physics_redesign.toml", dir, name, edits)
}

/// The example config `example` with `edits` (from → to) and its outputs in `dir/out`,
/// written as `dir/name`.
fn edited_config(example: &str, dir: &Path, name: &str, edits: &[(&str, &str)]) -> PathBuf {
    let mut text = std::fs::read_to_string(config(example)).expect("config");
    for (from, to) in edits {
        assert!(text.contains(from), "the example has no {from:?}");
        text = text.replace(from, to);
    }
    let text: Vec<String> = text
        .lines()
        .map(|l| {
            if l.starts_with("dir = \"../../target/run/") {
                "dir = \"out\"".to_owned()
            } else {
                l.to_owned()
            }
        })
        .collect();
    let path = dir.join(name);
    std::fs::write(&path, text.join("\n")).expect("write");
    path
}

/// `accuracy_of = "batch"` (issue 18, sequential identification): the example's re-designed
/// drive of the rigid-body Pioneer-like robot stops once the run's own identification of the
/// recording so far (output error, every 10 s) has its 95 % intervals of θ1, θ2, θ4, θ6 within
/// 2 %. Measured: the checks narrow 6.0 → 2.3 → 1.72 % at 10, 20, 30 s; stop at 32.0 s (the
/// check of the first 30 s, taken 2 s later), where the prior's design driven alone stops at
/// 92 s; the answer there is within 0.7 % of the map (θ1 −0.01 %, θ2 −0.66 %, θ4 +0.10 %,
/// θ6 +0.45 %), the map inside every 95 % interval;
/// each check's width is what
/// `identify` gives on the recording's first samples (recomputed here to 1e-9); the thesis's Pioneer signal on the
/// same robot is still at ± 3.3 % after 150 s. The rigid-body Khepera-like robot checked every
/// 2 s (`accuracy_every_s`, run_physics_until_accurate.toml): ± 0.64 % after 2 s, stop at
/// 3.0 s, the answer within 1 % of the map. `accuracy_of = "batch"` without the stop rule, or
/// `accuracy_every_s` without it, is a clear error.
#[test]
fn a_run_stops_once_the_batch_intervals_reach_the_accuracy() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = run(&redesign_config(dir.path(), "on.toml", &[]), &Silent).expect("runs");
    let trace = out.online.as_ref().expect("online trace");
    let (target, reached) = trace.accuracy.expect("an accuracy target");
    let t = reached.expect("reached within 150 s");
    let checks = &trace.batch_checks;
    eprintln!("stopped at {t:.2} s after {} checks", checks.len());
    assert_eq!(target, 0.02);
    assert!((25.0..40.0).contains(&t), "stopped at {t} s");
    let widths: Vec<f64> = checks
        .iter()
        .map(|c| c.outcome.as_ref().expect("a batch answer").1)
        .collect();
    let (last, before) = widths.split_last().expect("checks");
    assert!(
        *last <= 0.02 && before.iter().all(|&w| w > 0.02),
        "{widths:?}"
    );
    assert!(widths[0] > 0.05, "{widths:?}");
    // Each check is the run's identification of the samples it had.
    let settings = wheelid::identify::IdentifySettings::default();
    for c in [&checks[0], checks.last().expect("a check")] {
        let head = out.recording.head(c.samples);
        let id = wheelid::identify::identify(
            std::slice::from_ref(&head),
            &wheelid::models::VwPd,
            &wheelid::solvers::Ols::default(),
            &settings,
        )
        .expect("identifies");
        let (_, w) = wheelid::run::batch_half_width(&id).expect("a width");
        let (_, wc) = c.outcome.as_ref().expect("an answer");
        assert!(
            (w - wc).abs() <= 1e-9 * w,
            "check at {}: {wc} vs {w}",
            c.started_s
        );
    }
    let (_, w_final) = wheelid::run::batch_half_width(&out.identification).expect("width");
    assert!(w_final <= 0.02, "the run's answer ± {w_final}");
    let map = wheelid::robots::physics::PhysicalProfile::pioneer3dx().theta();
    let (th, se) = (&out.identification.theta, &out.identification.std_err);
    for i in [0, 1, 3, 5] {
        eprintln!(
            "θ{}: {:.4} ± {:.4} (map {:.4}, {:+.2} %)",
            i + 1,
            th[i],
            1.96 * se[i],
            map[i],
            100.0 * (th[i] - map[i]) / map[i]
        );
        assert!(
            (th[i] - map[i]).abs() <= (0.02 * map[i]).min(1.96 * se[i]),
            "θ{}: not within 2 % and its interval",
            i + 1
        );
    }

    // The prior's design alone (never re-designed), same rule.
    let never = [("every_s = 10.0", "every_s = 1000.0")];
    let off = run(&redesign_config(dir.path(), "off.toml", &never), &Silent).expect("runs");
    let off_t = off.online.and_then(|o| o.accuracy).and_then(|(_, r)| r);
    eprintln!("the prior's design alone: stopped at {off_t:?} s");
    assert!(off_t.is_some_and(|o| o > 2.0 * t), "{off_t:?} s");

    // The thesis's hand-made signal on the same robot, same rule, 150 s.
    let text = std::fs::read_to_string(dir.path().join("on.toml")).expect("config");
    let (i, j) = (
        text.find("[design]").expect("[design]"),
        text.find("[model]").expect("[model]"),
    );
    let thesis = format!(
        "{}[excitation]\ntype = \"thesis_pioneer\"\n\n{}",
        &text[..i],
        &text[j..]
    );
    let thesis_path = dir.path().join("thesis.toml");
    std::fs::write(&thesis_path, thesis).expect("write");
    let th = run(&thesis_path, &Silent).expect("runs");
    let th_trace = th.online.as_ref().expect("trace");
    assert_eq!(th_trace.accuracy, Some((0.02, None)));
    let (_, w150) = wheelid::run::batch_half_width(&th.identification).expect("width");
    eprintln!("thesis signal: ± {:.2} % after 150 s", 100.0 * w150);
    assert!(w150 > 0.03, "thesis signal ± {w150} after 150 s");

    // The rigid-body Khepera-like robot of run_physics_until_accurate.toml, checked every
    // 2 s: ± 0.64 % after 2 s, stop at 3.0 s, within 1 % of the map.
    let every2 = [(
        "accuracy = 0.01\n",
        "accuracy = 0.01\naccuracy_of = \"batch\"\naccuracy_every_s = 2.0\n",
    )];
    let k = run(
        &edited_config(
            "run_physics_until_accurate.toml",
            dir.path(),
            "k.toml",
            &every2,
        ),
        &Silent,
    )
    .expect("runs");
    let k_trace = k.online.as_ref().expect("trace");
    let k_t = k_trace.accuracy.and_then(|(_, r)| r).expect("reached");
    let (_, w2) = k_trace.batch_checks[0].outcome.clone().expect("an answer");
    eprintln!(
        "khepera: ± {:.2} % after 2 s, stop at {k_t:.2} s",
        100.0 * w2
    );
    assert!((k_t - 3.0).abs() < 0.05 && w2 < 0.01, "{k_t} s, ± {w2}");
    let k_map = wheelid::robots::physics::PhysicalProfile::khepera3().theta();
    assert_close(&k.identification.theta, &k_map, 0.01, "batch at the stop");

    let head = "duration_s = 5.0\n[robot]\ntype = \"simulator\"\n[output]\ndir = \"o\"\n";
    let e = run_text(&format!("accuracy_of = \"batch\"\n{head}"));
    assert!(
        e.contains("bad.toml: accuracy_of is read only with stop_when"),
        "{e}"
    );
    let e = run_text(&format!(
        "stop_when = \"accuracy\"\naccuracy = 0.02\naccuracy_every_s = 5.0\n{head}"
    ));
    assert!(
        e.contains("bad.toml: accuracy_every_s is read only with accuracy_of = \"batch\""),
        "{e}"
    );
}

/// Writes `text` as a config in a fresh directory and runs it, expecting an error (returned).
fn run_text(text: &str) -> String {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("bad.toml");
    std::fs::write(&path, text).expect("write");
    match run(&path, &Silent) {
        Ok(_) => panic!("ran:\n{text}"),
        Err(e) => format!("{e:#}"),
    }
}

#[test]
fn unknown_types_list_the_known_ones_and_misspelt_keys_name_their_line() {
    let e = run_text("[robot]\ntype = \"roomba\"\n[output]\ndir = \"o\"\n");
    assert!(
        e.contains("line 1: [robot]: unknown robot type `roomba`; known: simulator, physics, replay, pioneer, khepera"),
        "{e}"
    );
    let e = run_text(
        "[robot]\ntype = \"simulator\"\n[model]\ntype = \"vw-pdd\"\n[output]\ndir = \"o\"\n",
    );
    assert!(
        e.contains("line 3: [model]: unknown model type `vw-pdd`; known: vw-pd, wheel-pd"),
        "{e}"
    );
    let e = run_text(
        "[robot]\ntype = \"simulator\"\nrobot = \"pioneer3dx\"\nsed = 3\n[output]\ndir = \"o\"\n",
    );
    assert!(e.contains("line 4: [robot]: unknown field `sed`"), "{e}");
    let e = run_text(
        "[robot]\ntype = \"simulator\"\n[solver]\ntype = \"box\"\ntheta_lower = [0.0]\ntheta_uper = [1.0]\n[output]\ndir = \"o\"\n",
    );
    assert!(
        e.contains("line 6: [solver]: unknown field `theta_uper`"),
        "{e}"
    );
    let e = run_text("[robot]\nrobot = \"pioneer3dx\"\n[output]\ndir = \"o\"\n");
    assert!(e.contains("line 1: [robot]: missing `type`"), "{e}");
    // A misspelt top-level key: the TOML reader's own line and column.
    let e = run_text("duration = 3\n[robot]\ntype = \"simulator\"\n[output]\ndir = \"o\"\n");
    assert!(e.contains("line 1, column 1"), "{e}");
    // An unknown estimator is refused before anything drives, at its value's line and column.
    let e = run_text(
        "[robot]\ntype = \"simulator\"\n[identify]\nestimator = \"huber\"\n[output]\ndir = \"o\"\n",
    );
    assert!(
        e.contains(
            "bad.toml: line 4, column 13: [identify] estimator: unknown estimator `huber`; known estimators: ls, iv, oe"
        ),
        "{e}"
    );
}
