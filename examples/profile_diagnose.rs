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

use wheelid::diagnose::{DiagnoseSettings, diagnose_observed};
use wheelid::models::VwPd;
use wheelid::observer::Observer;

#[path = "../benches/support/diagnose_cases.rs"]
mod diagnose_cases;
use diagnose_cases::{cases, expected, recording};

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
                let mut sorted = found.clone();
                sorted.sort_unstable();
                if sorted != expected(name) {
                    println!("  (the bench expects {:?})", expected(name));
                }
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
