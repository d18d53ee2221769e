//! The `wheelid` command as a user runs it: the JSON shape, the model file, plots, and every
//! bad input giving a clear error (file, line, column) and a non-zero exit, never a panic.

use std::path::Path;
use std::process::{Command, Output};

fn wheelid(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_wheelid"))
        .args(args)
        .output()
        .expect("runs wheelid")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn json_has_the_documented_shape() {
    let o = wheelid(&["identify", "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("stdout is JSON only");
    assert_eq!(v["model"], "vw-pd");
    for key in ["theta", "std_err"] {
        let a = v[key].as_array().expect(key);
        assert_eq!(a.len(), 6);
        assert!(a.iter().all(|x| x.as_f64().is_some_and(f64::is_finite)));
    }
    assert!(v["cutoff_hz"].as_f64().is_some_and(|f| f > 0.0));
    assert_eq!(v["samples"].as_u64(), Some(1501));
    for ch in ["v", "w"] {
        assert!(
            v["channels"][ch]["r2"].as_f64().is_some_and(|r| r > 0.99),
            "{ch}"
        );
        assert!(
            v["channels"][ch]["fit_percent"]
                .as_f64()
                .is_some_and(|f| f > 90.0),
            "{ch}"
        );
    }
    // The embedded default recovers θ1 within 2 % of the thesis's simulation value.
    let t1 = v["theta"][0].as_f64().expect("theta1");
    assert!((t1 - 0.2604).abs() < 0.02 * 0.2604, "{t1}");
}

#[test]
fn model_file_round_trips_and_plots_are_written() {
    let dir = tempfile::tempdir().expect("tmp");
    let out = dir.path().join("params.toml");
    let plots = dir.path().join("plots");
    let o = wheelid(&[
        "identify",
        "--model",
        "wheel-pd",
        "--out",
        out.to_str().expect("utf8"),
        "--plot",
        plots.to_str().expect("utf8"),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let m = wheelid::files::ModelFile::read(&out).expect("reads back");
    assert_eq!(m.model, "wheel-pd");
    assert_eq!(m.theta.len(), 6);
    assert!((m.theta[3] - 0.9965).abs() < 0.01);
    for f in ["regression.png", "response__simulated_pioneer3dx_.png"] {
        let p = plots.join(f);
        let bytes = std::fs::read(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
        assert_eq!(&bytes[1..4], b"PNG", "{f}");
    }
}

fn write(dir: &Path, name: &str, text: &str) -> String {
    let p = dir.join(name);
    std::fs::write(&p, text).expect("write");
    p.to_str().expect("utf8").to_owned()
}

fn good_rows(n: usize) -> String {
    (0..n)
        .map(|k| format!("{},{},{},{},{}\n", k as f64 * 0.1, 0.3, 0.2, 0.29, 0.19))
        .collect()
}

#[test]
fn bad_inputs_are_clear_errors_not_panics() {
    let dir = tempfile::tempdir().expect("tmp");
    let cases: Vec<(String, &str)> = vec![
        (
            dir.path()
                .join("absent.csv")
                .to_str()
                .expect("utf8")
                .to_owned(),
            "absent.csv",
        ),
        (
            write(
                dir.path(),
                "nocol.csv",
                "# robot: x\nt,v_ref,v,w\n0,1,2,3\n",
            ),
            "nocol.csv:2: missing required column `w_ref`",
        ),
        (
            write(
                dir.path(),
                "nan.csv",
                &format!("t,v_ref,w_ref,v,w\n{}0.5,0.3,NaN,0.2,0.1\n", good_rows(5)),
            ),
            "nan.csv:7:3 (column `w_ref`)",
        ),
        (
            write(
                dir.path(),
                "text.csv",
                &format!("t,v_ref,w_ref,v,w\n{}0.5,0.3,0.2,fast,0.1\n", good_rows(5)),
            ),
            "text.csv:7:4 (column `v`)",
        ),
        (
            write(
                dir.path(),
                "time.csv",
                &format!("t,v_ref,w_ref,v,w\n{}0.3,0.3,0.2,0.2,0.1\n", good_rows(5)),
            ),
            "time.csv:7:1 (column `t`)",
        ),
        (
            write(
                dir.path(),
                "short.csv",
                &format!("t,v_ref,w_ref,v,w\n{}", good_rows(8)),
            ),
            "short.csv: 8 samples, but 16 are needed",
        ),
        (
            write(
                dir.path(),
                "ragged.csv",
                &format!("t,v_ref,w_ref,v,w\n{}0.8,1\n", good_rows(8)),
            ),
            "ragged.csv:10",
        ),
    ];
    for (path, want) in cases {
        let o = wheelid(&["identify", &path]);
        let err = stderr(&o);
        assert!(!o.status.success(), "{path} should fail");
        assert!(
            err.contains(want),
            "{path}: stderr {err:?} should contain {want:?}"
        );
        assert!(!err.contains("panicked"), "{path}: {err}");
    }
}

#[test]
fn bounds_file_errors_name_the_line_and_physical_bounds_work() {
    let dir = tempfile::tempdir().expect("tmp");
    let bad = write(
        dir.path(),
        "b.toml",
        "theta_lower = [0, 0, 0, 0, 0, 0]\ntheta_uper = [1, 1, 1, 1, 1, 1]\n",
    );
    let o = wheelid(&["identify", "--solver", "box", "--bounds", &bad]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("b.toml: line 2, column 1"),
        "{}",
        stderr(&o)
    );
    let phys = write(
        dir.path(),
        "p.toml",
        "[physical.lower]\nm = 8.0\ni_z = 0.1\nb = -0.02\nr = 0.095\nd = 0.37\nr_t = 0.095\nr_a = 0.6\nk_a = 0.5\nk_b = 0.5\ni_e = 0.004\nb_e = 0.01\nk_pt = 35.0\nk_dt = 1.0\nk_pr = 25.0\nk_dr = 0.5\n\
         [physical.upper]\nm = 9.0\ni_z = 0.2\nb = 0.04\nr = 0.1\nd = 0.39\nr_t = 0.1\nr_a = 0.8\nk_a = 0.7\nk_b = 0.7\ni_e = 0.006\nb_e = 0.03\nk_pt = 45.0\nk_dt = 2.0\nk_pr = 35.0\nk_dr = 1.0\n",
    );
    let o = wheelid(&["identify", "--solver", "box", "--bounds", &phys, "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("json");
    // The physical intervals bound θ1 well below the simulated Pioneer's 0.26 s: it sits on its bound.
    assert_eq!(v["bound_state"][0], "at_upper");
}
