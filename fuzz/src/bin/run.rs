//! Fuzz target: the configuration readers — a `wheelid run` config (parsed and checked, not
//! driven) and the `simulate`/`track`/`diagnose` configs — on any text.

use wheelid::config::{DiagnoseConfig, SimulateConfig, TrackConfig};

fn main() {
    afl::fuzz!(|data: &[u8]| {
        if let Ok(text) = std::str::from_utf8(data) {
            let _ = wheelid::run::parse_config(text, std::path::Path::new("fuzz.toml"));
            let _ = toml::from_str::<SimulateConfig>(text);
            let _ = toml::from_str::<TrackConfig>(text);
            let _ = toml::from_str::<DiagnoseConfig>(text);
        }
    });
}
