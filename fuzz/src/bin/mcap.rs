//! Fuzz target: the ROS 2 bag reader (`read_mcap`, as `identify x.mcap` and the replay
//! backend use it) on any bytes written to a `.mcap` file, with both clocks and a command
//! timeout. A crash is any panic (or an allocation the record length limit should stop).

use wheelid_robots::replay::{BagTopics, TimeSource, read_mcap};

fn main() {
    let dir = if std::path::Path::new("/dev/shm").is_dir() {
        std::path::PathBuf::from("/dev/shm")
    } else {
        std::env::temp_dir()
    };
    let path = dir.join(format!("wheelid-fuzz-{}.mcap", std::process::id()));
    let topics = BagTopics::default();
    afl::fuzz!(|data: &[u8]| {
        if std::fs::write(&path, data).is_ok() {
            let _ = read_mcap(&path, &topics, TimeSource::LogTime, None);
            let _ = read_mcap(&path, &topics, TimeSource::HeaderStamp, Some(0.5));
        }
    });
}
