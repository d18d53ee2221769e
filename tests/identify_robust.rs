//! `wheelid identify` never gives a silent nonsense answer (issue 17, item 3): a static-gain
//! recording with a BOM, CRLF line ends and comment lines is identified with the lag said to
//! be shorter than a sample; the README's dead-time + rate-limit recording gives no unstable
//! answer with zero errors and points at `diagnose`; bags are read directly; a closed pipe
//! loses nothing; constant commands and unknown formats are errors that name the file.

use std::io::Write;
use std::path::Path;
use std::process::{Command, Output, Stdio};

fn wheelid(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_wheelid"))
        .args(args)
        .output()
        .expect("runs wheelid")
}

fn json(o: &Output) -> serde_json::Value {
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    serde_json::from_slice(&o.stdout).expect("stdout is JSON")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A static gain (v = 0.95 v_ref, ω = 0.9 ω_ref within the sample, as a host that stamps the
/// window's middle sees it), commands held 1 s, 800 rows at 20 Hz, deterministic noise.
fn static_gain_csv(path: &Path) {
    let mut state = 12345u64;
    let mut uniform = || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    let mut text =
        String::from("\u{feff}# robot: bench\r\n# source: a static gain\r\nt,v_ref,w_ref,v,w\r\n");
    let (mut vr, mut wr) = (0.0, 0.0);
    for k in 0..800 {
        if k % 20 == 0 {
            vr = 0.6 * uniform();
            wr = 2.0 * uniform();
        }
        let v = 0.95 * vr + 0.004 * uniform();
        let w = 0.9 * wr + 0.02 * uniform();
        text.push_str(&format!(
            "{:.3},{vr:.4},{wr:.4},{v:.4},{w:.4}\r\n",
            0.05 * k as f64
        ));
        if k == 400 {
            text.push_str("# the operator's note in the middle of the log\r\n\r\n");
        }
    }
    std::fs::write(path, text).expect("write");
}

#[test]
fn a_static_gain_with_bom_crlf_and_comments_is_identified_with_its_lag_said() {
    let dir = tempfile::tempdir().expect("tmp");
    let csv = dir.path().join("static.csv");
    static_gain_csv(&csv);
    let v = json(&wheelid(&[
        "identify",
        csv.to_str().expect("utf8"),
        "--json",
    ]));
    assert_eq!(
        v["samples"].as_u64(),
        Some(800),
        "every row, comments skipped"
    );
    // The static gains: θ4 = 1/0.95, θ6 = 1/0.9 (errors in variables aside: within 1 %).
    let theta: Vec<f64> = (0..6).map(|i| v["theta"][i].as_f64().expect("θ")).collect();
    assert!(
        (theta[3] - 1.0 / 0.95).abs() < 0.01 / 0.95,
        "θ4 {}",
        theta[3]
    );
    assert!((theta[5] - 1.0 / 0.9).abs() < 0.01 / 0.9, "θ6 {}", theta[5]);
    for ch in ["v", "w"] {
        let fit = v["channels"][ch]["fit_percent"].as_f64().expect("fit");
        assert!(fit > 95.0, "{ch} fit {fit}");
    }
    let warnings: Vec<&str> = v["warnings"]
        .as_array()
        .expect("warnings")
        .iter()
        .filter_map(|w| w.as_str())
        .collect();
    assert!(
        warnings
            .iter()
            .any(|w| w.starts_with("θ1 below") && w.contains("shorter than one sample")),
        "{warnings:?}"
    );
}

#[test]
fn the_readme_dead_time_and_rate_limit_give_no_unstable_answer_and_point_at_diagnose() {
    let dir = tempfile::tempdir().expect("tmp");
    let config = dir.path().join("sim.toml");
    std::fs::write(
        &config,
        "robot = \"khepera3\"\n[excitation]\ntype = \"random_multisine\"\nseed = 4\n\
         v_offset = 0.1\nv_amp = 0.1\nw_amp = 1.5\nf_max_hz = 2.0\n[simulation]\n\
         duration_s = 120.0\n[simulation.effects.input_delay]\ndelay_s = 0.25\n\
         [simulation.effects.acceleration_limit]\nv_accel_max = 0.5\nw_accel_max = 3.0\n",
    )
    .expect("write");
    let csv = dir.path().join("dr.csv");
    let csv = csv.to_str().expect("utf8");
    let o = wheelid(&[
        "simulate",
        "--config",
        config.to_str().expect("utf8"),
        "--out",
        csv,
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v = json(&wheelid(&["identify", csv, "--json"]));
    let th: Vec<f64> = (0..6).map(|i| v["theta"][i].as_f64().expect("θ")).collect();
    let se: Vec<f64> = (0..6)
        .map(|i| v["std_err"][i].as_f64().expect("σ"))
        .collect();
    assert!(th[3] / th[0] > 0.0 && th[5] / th[1] > 0.0, "stable: {th:?}");
    assert!(se.iter().all(|s| s.is_finite() && *s > 0.0), "{se:?}");
    // Least squares comes out unstable here: it is flagged and not the answer.
    let ls = &v["estimates"][0];
    assert_eq!(ls["estimator"], "ls");
    assert!(
        ls["invalid"]
            .as_str()
            .is_some_and(|w| w.contains("unstable")),
        "{ls}"
    );
    assert_eq!(v["estimator"], "oe");
    let warnings = v["warnings"].to_string();
    assert!(
        warnings.contains("wheelid diagnose") && warnings.contains("free-run fit of v"),
        "{warnings}"
    );
}

#[test]
fn bags_are_read_directly_and_unknown_formats_are_named() {
    let dir = tempfile::tempdir().expect("tmp");
    let bag = dir.path().join("k.mcap");
    let bag_s = bag.to_str().expect("utf8");
    let o = wheelid(&[
        "simulate",
        "--robot",
        "khepera3",
        "--excitation",
        "multisine",
        "--duration",
        "60",
        "--out",
        bag_s,
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v = json(&wheelid(&["identify", bag_s, "--json"]));
    // The built-in Khepera III's θ1 = 0.0228 s, θ6 = 0.998 (robots::profile).
    let t1 = v["theta"][0].as_f64().expect("θ1");
    assert!((t1 - 0.0228).abs() < 0.05 * 0.0228, "θ1 {t1}");
    // The same bag under another extension: told by its magic bytes.
    let renamed = dir.path().join("k.bin");
    std::fs::copy(&bag, &renamed).expect("copy");
    let w = json(&wheelid(&[
        "identify",
        renamed.to_str().expect("utf8"),
        "--json",
        "--estimator",
        "ls",
    ]));
    assert_eq!(w["samples"], v["samples"]);
    let o = wheelid(&["diagnose", bag_s, "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    // Bytes that are neither text nor MCAP.
    let junk = dir.path().join("junk.dat");
    std::fs::write(&junk, [0x89u8, 0xff, 0x00, 0xfe, 0x10, 0x80, 0x81, 0x82]).expect("write");
    let o = wheelid(&["identify", junk.to_str().expect("utf8")]);
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(e.contains("junk.dat: neither a recording CSV"), "{e}");
    assert!(!e.contains("panicked"), "{e}");
}

#[test]
fn a_closed_pipe_loses_nothing_and_does_not_panic() {
    let dir = tempfile::tempdir().expect("tmp");
    let out = dir.path().join("m.toml");
    let mut child = Command::new(env!("CARGO_BIN_EXE_wheelid"))
        .args(["identify", "--out", out.to_str().expect("utf8")])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawns");
    // The reader goes away before the report is printed (as `| head -0` does).
    drop(child.stdout.take());
    let o = child.wait_with_output().expect("waits");
    let e = stderr(&o);
    assert!(o.status.success(), "{e}");
    assert!(!e.contains("panicked"), "{e}");
    let model = std::fs::read_to_string(&out).expect("the model file is written");
    assert!(model.contains("theta = ["), "{model}");
}

#[test]
fn constant_commands_are_an_error_naming_the_file() {
    let dir = tempfile::tempdir().expect("tmp");
    let csv = dir.path().join("parked.csv");
    let mut f = std::fs::File::create(&csv).expect("create");
    writeln!(f, "t,v_ref,w_ref,v,w").expect("write");
    for k in 0..500 {
        let noise = ((k * 7919) % 13) as f64 * 1e-4;
        writeln!(
            f,
            "{},0.2,0.5,{},{}",
            0.02 * k as f64,
            0.19 + noise,
            0.45 - noise
        )
        .expect("write");
    }
    drop(f);
    for cmd in ["identify", "diagnose"] {
        let o = wheelid(&[cmd, csv.to_str().expect("utf8")]);
        assert!(!o.status.success(), "{cmd}");
        let e = stderr(&o);
        assert!(
            e.contains("parked.csv: v_ref is constant") && e.contains("θ1, θ3, θ4"),
            "{cmd}: {e}"
        );
    }
}

#[test]
fn every_command_has_a_one_sentence_summary() {
    let o = wheelid(&["--help"]);
    let text = String::from_utf8_lossy(&o.stdout).into_owned();
    let commands: Vec<&str> = text
        .lines()
        .skip_while(|l| !l.starts_with("Commands:"))
        .skip(1)
        .take_while(|l| !l.trim().is_empty())
        .collect();
    assert!(commands.len() >= 7, "{text}");
    for line in commands {
        // Each summary fits a terminal line and is whole (no sentence cut by clap).
        assert!(line.chars().count() <= 100, "{line}");
    }
    let o = wheelid(&["identify", "--help"]);
    let first = String::from_utf8_lossy(&o.stdout)
        .lines()
        .next()
        .unwrap_or_default()
        .to_owned();
    assert!(first.ends_with("(CSV or ROS 2 bags)."), "{first}");
}

#[test]
fn inputs_the_fuzzers_crashed_on_are_clear_errors() {
    // fuzz/regressions/<reader>/: every crash a fuzzer found (fuzz/README.md), kept so that it
    // stays fixed. mcap: attachments shorter than their own header, an uncompressed chunk's
    // record running past the chunk (mcap 0.26 panicked on both).
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/regressions");
    let mut n = 0;
    for reader in std::fs::read_dir(&dir).expect("fuzz/regressions") {
        for case in std::fs::read_dir(reader.expect("dir").path()).expect("cases") {
            let path = case.expect("case").path();
            let o = wheelid(&["identify", path.to_str().expect("utf8")]);
            let e = stderr(&o);
            assert!(!o.status.success(), "{}", path.display());
            assert!(!e.contains("panicked"), "{}: {e}", path.display());
            let name = path.file_name().and_then(|n| n.to_str()).expect("name");
            assert!(e.contains(name), "the error names the file: {e}");
            n += 1;
        }
    }
    assert!(n >= 2, "{n} regression inputs");
}
