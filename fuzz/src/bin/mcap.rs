//! Fuzz target: the ROS 2 bag reader (`read_mcap`, as `identify x.mcap` and the replay
//! backend use it) on any bytes written to a `.mcap` file, with both clocks and a command
//! timeout. A crash is any panic (or an allocation the record length limit should stop).

use wheelid_robots::replay::{BagTopics, TimeSource, read_mcap};

fn main() {
    let path = wheelid_fuzz::scratch_path("mcap");
    let topics = BagTopics::default();
    afl::fuzz!(|data: &[u8]| {
        if std::fs::write(&path, data).is_ok() {
            let _ = read_mcap(&path, &topics, TimeSource::LogTime, None);
            let _ = read_mcap(&path, &topics, TimeSource::HeaderStamp, Some(0.5));
        }
    });
}
