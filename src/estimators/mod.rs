//! The built-in estimators that refine least squares' θ, one file each, behind
//! [`wheelid_core::Estimator`]: instrumental variables ([`iv`]) and output error ([`oe`]).
//! Least squares itself (Laut 2011 eq. 4.3–4.7) is every estimator's start and is run by the
//! identification itself under the name [`LEAST_SQUARES`]; plugins add estimators with
//! `Registrar::estimator`, and [`crate::registry::Registry`] lists them all.

use wheelid_core::Estimator;

pub mod iv;
pub mod oe;

/// The name of the least-squares answer (the thesis's method, run first by every
/// identification).
pub const LEAST_SQUARES: &str = "ls";

/// The built-in estimator names in report order, least squares first.
pub const BUILT_IN: [&str; 3] = [LEAST_SQUARES, iv::NAME, oe::NAME];

/// Checks that `name` is one of the estimators `known` (least squares among them), for every
/// place that takes an estimator's name (`identify --estimator`, a run config, the library).
///
/// # Errors
/// The message naming the known estimators.
pub fn check_name(name: &str, known: &[&str]) -> Result<(), String> {
    if known.contains(&name) {
        return Ok(());
    }
    Err(format!(
        "unknown estimator `{name}`; known estimators: {} (a plugin's with --plugin LIB)",
        known.join(", ")
    ))
}

/// The built-in refining estimators, in report order (after least squares).
pub fn built_in() -> Vec<Box<dyn Estimator>> {
    vec![Box::new(iv::Iv), Box::new(oe::Oe)]
}
