//! Shared by the fuzz targets: where a target writes its input when the reader under test
//! takes a path.

/// A per-process scratch file with extension `ext`, in memory-backed /dev/shm when there is
/// one, else the temporary directory.
pub fn scratch_path(ext: &str) -> std::path::PathBuf {
    let dir = if std::path::Path::new("/dev/shm").is_dir() {
        std::path::PathBuf::from("/dev/shm")
    } else {
        std::env::temp_dir()
    };
    dir.join(format!("wheelid-fuzz-{}.{ext}", std::process::id()))
}
