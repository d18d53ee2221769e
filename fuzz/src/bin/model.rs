//! Fuzz target: the model file reader (`ModelFile::read`, what `track --model`,
//! `simulate --model`, `migrate` and `export` read) and the bounds file reader.

fn main() {
    let path = wheelid_fuzz::scratch_path("toml");
    afl::fuzz!(|data: &[u8]| {
        if std::fs::write(&path, data).is_ok() {
            if let Ok(m) = wheelid::files::ModelFile::read(&path) {
                let _ = wheelid::export::ros2_yaml(&m, None, "fuzz.toml");
            }
            let _ = wheelid::files::read_bounds(&path, "vw-pd");
            let _ = wheelid::files::read_bounds(&path, "wheel-pd");
        }
    });
}
