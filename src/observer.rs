//! What a long library call reports while it runs, as argmin's observers: the binary draws a
//! progress bar from it (`indicatif`, in `main.rs`), the library draws nothing. Used by the
//! diagnosis ([`crate::diagnose::diagnose_observed`]) and by a robot's drive
//! ([`crate::run::drive`], [`crate::run::run`]).

/// Receives a long call's progress.
pub trait Observer: Sync {
    /// `message` says what runs now; `done` of `total` units of work are finished (the total
    /// may grow as the work is found, as a diagnosis nominates candidates to fit; 0 when it is
    /// not known, as for a replayed log driven to its end).
    fn progress(&self, _message: &str, _done: u64, _total: u64) {}
}

/// An [`Observer`] that ignores everything.
#[derive(Debug, Clone, Copy, Default)]
pub struct Silent;

impl Observer for Silent {}
