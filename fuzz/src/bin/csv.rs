//! Fuzz target: the recording CSV reader (`Recording::from_csv_str`), on any bytes that are
//! UTF-8 text, and the file reader (`Recording::read_csv`) on every input, text or not.
//! A crash is any panic; an error is a correct answer.

fn main() {
    let path = wheelid_fuzz::scratch_path("csv");
    afl::fuzz!(|data: &[u8]| {
        if let Ok(text) = std::str::from_utf8(data) {
            let _ = wheelid_core::Recording::from_csv_str(text, "fuzz.csv");
        }
        if std::fs::write(&path, data).is_ok() {
            let _ = wheelid_core::Recording::read_csv(&path);
        }
    });
}
