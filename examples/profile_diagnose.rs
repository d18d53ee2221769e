//! Times `diagnose` on the cases of `benches/diagnose.rs` (10 minutes of the simulated
//! Khepera III at 50 Hz) and prints when each step began, from the observer's messages: a rough
//! profile of where a diagnosis spends its time (the benchmark is `cargo bench --bench
//! diagnose`).
//!
//! Run: `cargo run --release --example profile_diagnose [--search-samples=N] [CASE…]` (no
//! case: all of them; `--search-samples`: `DiagnoseSettings::search_samples`); with
//! `PROFILE_REPORT` set in the environment each case's text report follows its profile.

use std::sync::Mutex;
use std::time::Instant;

use wheelid::core::Recording;
use wheelid::diagnose::{DiagnoseSettings, diagnose_observed};
use wheelid::models::VwPd;
use wheelid::observer::Observer;
use wheelid::robots::effects::{
    AccelerationLimit, CoulombFriction, Effects, GainDrift, InputDelay, PayloadChange, Slip,
    VelocitySaturation, WheelAsymmetry,
};
use wheelid::robots::{RobotProfile, SimSettings, simulate_recording};

/// Prints each new message with the time since the diagnosis began.
struct Clock {
    start: Instant,
    last: Mutex<String>,
}

impl Observer for Clock {
    fn progress(&self, message: &str, _done: u64, _total: u64) {
        let mut last = self.last.lock().unwrap_or_else(|e| e.into_inner());
        if *last != message {
            println!("  {:7.3} s  {message}", self.start.elapsed().as_secs_f64());
            message.clone_into(&mut last);
        }
    }
}

fn recording(effects: Effects) -> Recording {
    let robot = RobotProfile::khepera3();
    let exc = robot.multisine(3).expect("valid multisine");
    let s = SimSettings {
        duration_s: 600.0,
        seed: 3,
        effects,
        ..SimSettings::default()
    };
    simulate_recording(&robot, &exc, &s).expect("simulates")
}

/// The bench's cases (`benches/diagnose.rs`), by name.
fn cases() -> Vec<(&'static str, Effects)> {
    let robot = RobotProfile::khepera3();
    let (va, wa) = (0.25 * robot.v_max, 0.25 * robot.w_max);
    let delay = InputDelay { delay_s: 0.08 };
    let saturation = VelocitySaturation {
        v_max: 1.4 * va,
        w_max: 0.55 * wa,
    };
    let accel = AccelerationLimit {
        v_accel_max: 0.1,
        w_accel_max: 2.26,
    };
    let asymmetry = WheelAsymmetry { ratio: 1.08 };
    let e = Effects::default;
    vec![
        ("clean", e()),
        (
            "dead_time",
            Effects {
                input_delay: Some(delay),
                ..e()
            },
        ),
        (
            "acceleration_limit",
            Effects {
                acceleration_limit: Some(accel),
                ..e()
            },
        ),
        (
            "velocity_saturation",
            Effects {
                velocity_saturation: Some(saturation),
                ..e()
            },
        ),
        (
            "coulomb_friction",
            Effects {
                coulomb_friction: Some(CoulombFriction {
                    v_coulomb: 0.08 * va,
                    w_coulomb: 0.08 * wa,
                }),
                ..e()
            },
        ),
        (
            "wheel_asymmetry",
            Effects {
                wheel_asymmetry: Some(asymmetry),
                ..e()
            },
        ),
        (
            "payload_change",
            Effects {
                payload_change: Some(PayloadChange::scaled(300.0, robot.theta, 1.5)),
                ..e()
            },
        ),
        (
            "gain_drift",
            Effects {
                gain_drift: Some(GainDrift {
                    rate_per_s: -0.3 / 600.0,
                }),
                ..e()
            },
        ),
        (
            "slip",
            Effects {
                slip: Some(Slip { k_v: 0.3, k_w: 0.3 }),
                ..e()
            },
        ),
        (
            "dead_time+saturation",
            Effects {
                input_delay: Some(delay),
                velocity_saturation: Some(saturation),
                ..e()
            },
        ),
        (
            "acceleration_limit+asymmetry",
            Effects {
                acceleration_limit: Some(accel),
                wheel_asymmetry: Some(asymmetry),
                ..e()
            },
        ),
    ]
}

fn main() {
    let mut settings = DiagnoseSettings::default();
    let mut wanted: Vec<String> = Vec::new();
    for arg in std::env::args().skip(1) {
        match arg.strip_prefix("--search-samples=") {
            Some(n) => match n.parse() {
                Ok(n) => settings.search_samples = n,
                Err(e) => {
                    eprintln!("--search-samples={n}: {e}");
                    std::process::exit(2);
                }
            },
            None => wanted.push(arg),
        }
    }
    for (name, effects) in cases() {
        if !wanted.is_empty() && !wanted.iter().any(|w| w == name) {
            continue;
        }
        let rec = recording(effects);
        println!("{name}:");
        let clock = Clock {
            start: Instant::now(),
            last: Mutex::new(String::new()),
        };
        match diagnose_observed(std::slice::from_ref(&rec), &VwPd, &settings, &clock) {
            Ok(d) => {
                let found: Vec<&str> = d.findings.iter().map(|f| f.effect.as_str()).collect();
                println!(
                    "  {:7.3} s  done: {found:?}; rejected {:?}",
                    clock.start.elapsed().as_secs_f64(),
                    d.rejected
                        .iter()
                        .map(|r| r.effect.as_str())
                        .collect::<Vec<_>>()
                );
                if std::env::var_os("PROFILE_REPORT").is_some() {
                    println!("{}", wheelid::report::diagnosis_text(&d));
                }
            }
            Err(e) => println!("  error: {e}"),
        }
    }
}
