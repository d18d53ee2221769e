//! Records the compiler's full version (`rustc -vV`) for the plugin entry point: a plugin
//! built by another compiler is refused before anything of it runs.

use std::process::Command;

fn main() {
    let rustc = std::env::var("RUSTC").unwrap_or_else(|_| "rustc".into());
    let version = Command::new(&rustc)
        .arg("-vV")
        .output()
        .ok()
        .and_then(|o| String::from_utf8(o.stdout).ok())
        .map(|s| {
            // "rustc 1.95.0 (59807616e 2026-04-14)" plus the host triple.
            let release = s.lines().next().unwrap_or("").trim().to_owned();
            let host = s
                .lines()
                .find_map(|l| l.strip_prefix("host: "))
                .unwrap_or("")
                .trim()
                .to_owned();
            format!("{release} {host}")
        })
        .unwrap_or_else(|| "unknown".into());
    println!("cargo:rustc-env=WHEELID_RUSTC_VERSION={version}");
    println!("cargo:rerun-if-env-changed=RUSTC");
}
