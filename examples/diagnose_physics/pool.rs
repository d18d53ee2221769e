//! Reading `--json` files back (`--pool`): the report of several runs' records pooled, e.g. a
//! declared report run in parts (pairs and singles, seed ranges, sessions).
//!
//! serde_json writes a non-finite `f64` (NaN, ±∞: an undefined standard error, a fit of a
//! flat channel) as `null`; the fields that can hold one read `null` back as NaN, so a record
//! reads back with every finite number exact (serde_json round-trips `f64` to the bit) and
//! every non-finite one as NaN.

use std::collections::BTreeMap;
use std::io::BufRead as _;
use std::path::Path;

use anyhow::{Context, Result};
use serde::{Deserialize, Deserializer};

use crate::Record;

/// `f64`, `null` read as NaN.
pub fn f64_or_nan<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
}

/// `[f64; 2]`, `null` entries read as NaN.
pub fn pair_or_nan<'de, D: Deserializer<'de>>(d: D) -> Result<[f64; 2], D::Error> {
    let [a, b] = <[Option<f64>; 2]>::deserialize(d)?;
    Ok([a.unwrap_or(f64::NAN), b.unwrap_or(f64::NAN)])
}

/// Parameters by effect and name, `null` values read as NaN.
pub fn params_or_nan<'de, D: Deserializer<'de>>(
    d: D,
) -> Result<BTreeMap<String, BTreeMap<String, f64>>, D::Error> {
    let raw = BTreeMap::<String, BTreeMap<String, Option<f64>>>::deserialize(d)?;
    Ok(raw
        .into_iter()
        .map(|(k, m)| {
            let m = m
                .into_iter()
                .map(|(n, x)| (n, x.unwrap_or(f64::NAN)))
                .collect();
            (k, m)
        })
        .collect())
}

/// Every record of the JSON-lines files `paths`, in order (blank lines skipped).
///
/// # Errors
/// A file that cannot be read, or a line that is not a record (named by file and line).
pub fn read_records(paths: &[impl AsRef<Path>]) -> Result<Vec<Record>> {
    let mut recs = Vec::new();
    for path in paths {
        let path = path.as_ref();
        let file =
            std::fs::File::open(path).with_context(|| format!("opening {}", path.display()))?;
        for (i, line) in std::io::BufReader::new(file).lines().enumerate() {
            let line = line.with_context(|| format!("reading {}", path.display()))?;
            if line.trim().is_empty() {
                continue;
            }
            let rec: Record = serde_json::from_str(&line)
                .with_context(|| format!("{}:{}: not a harness record", path.display(), i + 1))?;
            recs.push(rec);
        }
    }
    Ok(recs)
}
