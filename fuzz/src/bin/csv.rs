//! Fuzz target: the recording CSV reader (`Recording::from_csv_str`), on any bytes that are
//! UTF-8 text, and the file reader (`Recording::read_csv`) on every input, text or not — and,
//! as a differential oracle, the reader that splits the rows into parts at line ends
//! (`Recording::read_csv_in_parts`, what a file of more than a few MB goes through), whose
//! answer must be the sequential reader's, the same recording or the same error — reading
//! every column and the required ones only.
//! A crash is any panic or disagreement; an error is a correct answer.

use wheelid_core::{Columns, Recording};

fn main() {
    let path = wheelid_fuzz::scratch_path("csv");
    afl::fuzz!(|data: &[u8]| {
        if let Ok(text) = std::str::from_utf8(data) {
            let _ = Recording::from_csv_str(text, "fuzz.csv");
        }
        if std::fs::write(&path, data).is_ok() {
            // Every column, and the required ones only (what identify reads; the others are
            // skipped unparsed by both readers).
            for columns in [Columns::All, Columns::Required] {
                let whole = Recording::read_csv_in_parts(&path, columns, 1);
                for parts in [2, 3] {
                    let split = Recording::read_csv_in_parts(&path, columns, parts);
                    match (&whole, &split) {
                        (Ok(a), Ok(b)) => assert!(a == b, "{parts} parts: another recording"),
                        (Err(a), Err(b)) => {
                            assert_eq!(a.to_string(), b.to_string(), "{parts} parts")
                        }
                        _ => panic!("{parts} parts, {columns:?}: {whole:?} vs {split:?}"),
                    }
                }
            }
        }
    });
}
