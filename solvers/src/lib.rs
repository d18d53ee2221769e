//! # wheelid-solvers
//!
//! Implementations of [`wheelid_core::Solver`]:
//! * [`Ols`] (`ols`): least squares by SVD of the column-normalised regressor, with standard
//!   errors (classical or Newey–West), condition number, rank, and an error naming the
//!   parameters the data cannot separate;
//! * [`BoxLs`] (`box`): least squares with bounds lb ≤ θ ≤ ub through Clarabel — the thesis's
//!   parameter projection (§4.1).

mod boxls;
mod ols;

pub use boxls::BoxLs;
pub use ols::Ols;

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
