//! The subcommands, one file each: its arguments and what it runs. The binary's modules (the
//! library is `wheelid`); shared helpers (`out!`, the progress bar, plot listing) are in
//! `main.rs`.

pub(crate) mod design;
pub(crate) mod diagnose;
pub(crate) mod export;
pub(crate) mod identify;
pub(crate) mod migrate;
pub(crate) mod run;
pub(crate) mod simulate;
pub(crate) mod track;
