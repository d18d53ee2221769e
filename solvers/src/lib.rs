//! # wheelid-solvers
//!
//! Implementations of [`wheelid_core::Solver`]:
//! * [`Ols`] (`ols`): least squares by SVD of the column-normalised regressor, with standard
//!   errors (classical or Newey–West), condition number, rank, and an error naming the
//!   parameters the data cannot separate;
//! * [`BoxLs`] (`box`): least squares with bounds lb ≤ θ ≤ ub through Clarabel — the thesis's
//!   parameter projection (§4.1).
//!
//! and the estimators that remove the errors-in-variables bias of the regression (the command
//! is exact; the regressors carry the noise):
//! * [`oe`]: output error — θ that makes any [`wheelid_core::DynamicModel`]'s free-run
//!   simulation match the measurements (Levenberg–Marquardt, bounds, sandwich intervals);
//! * [`iv`]: instrumental variables with instruments from the model's own noise-free
//!   simulation, iterated — linear and fast;
//!
//! least squares over a regression that arrives in blocks ([`streaming`]: a QR factor and
//! the window moments of the Newey–West errors, updated block by block in one pass), and one
//! online
//! estimator:
//! * [`recursive`]: recursive least squares with forgetting and a change detector — per
//!   sample, no allocation.

mod boxls;
pub mod iv;
pub mod oe;
mod ols;
pub mod recursive;
pub mod streaming;

pub use boxls::BoxLs;

pub use iv::{InstrumentalVariables, IvFit};
pub use oe::{OutputError, OutputErrorFit};
pub use ols::{NeweyWest, Ols};
pub use recursive::{ChangeDetection, Rls, RlsSettings, RlsUpdate};

/// Names of the built-in solvers.
pub const SOLVER_NAMES: [&str; 2] = ["ols", "box"];

/// The built-in solver called `name` with default settings, or `None`.
pub fn by_name(name: &str) -> Option<Box<dyn wheelid_core::Solver>> {
    match name {
        "ols" => Some(Box::new(Ols::default())),
        "box" => Some(Box::new(BoxLs::default())),
        _ => None,
    }
}
