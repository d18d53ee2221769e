//! Fuzz target: the model file reader (`ModelFile::read`, what `track --model`,
//! `simulate --model`, `migrate` and `export` read) and the bounds file reader.

fn main() {
    let dir = if std::path::Path::new("/dev/shm").is_dir() {
        std::path::PathBuf::from("/dev/shm")
    } else {
        std::env::temp_dir()
    };
    let path = dir.join(format!("wheelid-fuzz-{}.toml", std::process::id()));
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
