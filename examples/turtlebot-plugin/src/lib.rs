//! # An example wheelid plugin: a TurtleBot3 Burger and a friction model
//!
//! A **plugin** is a shared library that adds robots, models, solvers and estimators to a
//! wheelid binary that knows nothing of them, at run time. This crate adds three:
//!
//! * the robot `turtlebot3` ([`robot`]): a simulated ROBOTIS TurtleBot3 Burger — a robot
//!   wheelid does not ship — with its physical data and the documented choices behind its
//!   parameters in [`burger`];
//! * the model `vw-pd-coulomb` ([`model`]): Laut 2011 eq. 2.19 plus a dry (Coulomb) friction
//!   per channel, eight parameters, linear in them, so that wheelid's least-squares
//!   estimators fit it like its own models;
//! * the estimator `huber` ([`huber`]): Huber's robust regression on the filtered regression,
//!   with block-jackknife standard errors — `wheelid identify --plugin … --estimator huber`,
//!   or beside the built-in ones with `--compare`.
//!
//! It depends on `wheelid-core` alone (and nalgebra, serde, toml): its integrator, its random
//! numbers and its physics are its own, as any third party's would be.
//!
//! ## How a plugin plugs in
//! Rust has no stable ABI, so the host and the plugin agree on a *same-compiler contract*
//! ([`wheelid_core::plugin`]). The library exports one plain-data static, `WHEELID_PLUGIN`
//! (a [`PluginDeclaration`](wheelid_core::plugin::PluginDeclaration): API version, compiler,
//! core version, and an entry point). The host reads it first and refuses the library unless
//! all three match its own; only then does it call the entry point, which runs [`register`]
//! under the plugin's own `catch_unwind`:
//!
//! ```ignore
//! pub fn register(r: &mut Registrar) {
//!     r.robot("turtlebot3", make_robot);      // fn(&str) -> Result<Box<dyn Robot>, String>
//!     r.model("vw-pd-coulomb", make_model);   // fn(&str) -> Result<Box<dyn RegressorModel>, String>
//!     r.estimator("huber", make_huber);       // fn(&str) -> Result<Box<dyn Estimator>, String>
//! }
//! wheelid_core::export_plugin!(register);
//! ```
//!
//! When a config's `[robot]` (or `[model]`, `[solver]`) table has a `type` that no built-in
//! has, the host hands the whole table, as TOML text with its `type` key, to the factory
//! registered under that name. Every call into the plugin — the registration, each factory,
//! each method of what they make — runs under the plugin's `catch_unwind`, so a panic in here
//! comes back to the host as an error, never as an unwinding across the library boundary.
//!
//! ## Building it
//! The host and the plugin must come from the same compiler and the same `wheelid-core`, so
//! build both in this workspace:
//!
//! ```text
//! cargo build -p wheelid-turtlebot-plugin     # → target/debug/libwheelid_turtlebot_plugin.so
//! cargo build                                 # → target/debug/wheelid
//! ```
//!
//! (`.dylib` on macOS, `.dll` on Windows.) The crate is both a `cdylib`, the library the host
//! loads, and an `rlib`, so that its own tests can use it directly.
//!
//! ## Loading it
//! A run config names the library (relative to the config file) and uses its types:
//!
//! ```toml
//! plugins = ["target/debug/libwheelid_turtlebot_plugin.so"]
//! duration_s = 120.0
//!
//! [robot]
//! type = "turtlebot3"       # every other key optional: the Burger by default
//! seed = 7
//! encoder_noise_std = 0.001 # m/s per wheel
//!
//! [excitation]              # sized for the Burger (the default, the Pioneer's, would be
//! type = "random_multisine" # clipped to 0.22 m/s most of the time)
//! seed = 1
//! v_offset = 0.0            # zero-mean: v changes sign, so the friction shows
//! v_amp = 0.15
//! w_amp = 1.0
//! f_max_hz = 2.0
//!
//! [model]
//! type = "vw-pd-coulomb"
//!
//! [identify]
//! estimator = "ls"
//! ```
//!
//! and `wheelid run that.toml` drives the simulated Burger, records it, and fits θ1…θ6,
//! `v_coulomb` and `w_coulomb` (`plugins` paths are relative to the config file). The
//! robot's keys are [`TurtleBotSettings`]'; a misspelt key is an error naming it, which the
//! host places on its line. The model takes no keys besides `type`.
//!
//! How well that works is checked inside this crate (`tests/identify.rs`): 120 s of such a
//! multisine, wheelid's conditioning, this model's regression and ordinary least squares give
//! the Burger's time constants back within 2 % (0.8–1.8 % low, a bias of the sampled-data
//! regression at 30 Hz), its steady-state gains within 0.5 % and its friction within a few
//! per cent.
//!
//! ## Failure builds
//! The features `fault-api-version`, `fault-rustc-version`, `fault-no-declaration`,
//! `fault-panic-in-register` and `fault-panic-in-factory` build a deliberately broken plugin
//! for the host's failure tests (a declaration with `API_VERSION + 1`, one from another
//! compiler, no `WHEELID_PLUGIN` at all, a registration that panics, a `turtlebot3` factory
//! that panics). At most one may be on; never use them otherwise.

use wheelid_core::plugin::Registrar;
#[cfg(any(feature = "fault-api-version", feature = "fault-rustc-version"))]
use wheelid_core::plugin::{CORE_VERSION, PluginDeclaration};
use wheelid_core::{Estimator, RegressorModel, Robot};

pub mod burger;
pub mod huber;
pub mod model;
pub mod robot;

pub use huber::Huber;
pub use model::VwPdCoulomb;
pub use robot::{TurtleBot, TurtleBotSettings};

/// At most one fault feature (each builds a differently broken plugin).
const _: () = assert!(
    (cfg!(feature = "fault-api-version") as u8
        + cfg!(feature = "fault-rustc-version") as u8
        + cfg!(feature = "fault-no-declaration") as u8
        + cfg!(feature = "fault-panic-in-register") as u8
        + cfg!(feature = "fault-panic-in-factory") as u8)
        <= 1,
    "wheelid-turtlebot-plugin: enable at most one fault-* feature"
);

/// Registers the robot `turtlebot3`, the model `vw-pd-coulomb` and the estimator `huber` (with
/// `fault-panic-in-register`: panics instead).
pub fn register(r: &mut Registrar) {
    if cfg!(feature = "fault-panic-in-register") {
        panic!("fault-panic-in-register: this build's registration panics on purpose");
    }
    r.robot(TurtleBot::NAME, make_robot);
    r.model(VwPdCoulomb::NAME, make_model);
    r.estimator(Huber::NAME, make_huber);
}

/// The `huber` factory: [`Huber`] (it has no settings).
///
/// # Errors
/// None; the signature is the registrar's.
pub fn make_huber(_toml: &str) -> Result<Box<dyn Estimator>, String> {
    Ok(Box::new(Huber))
}

/// The `turtlebot3` factory: a [`TurtleBot`] from its `[robot]` table as TOML text (with
/// `fault-panic-in-factory`: panics instead).
///
/// # Errors
/// A message naming the bad or unknown key ([`TurtleBotSettings::from_toml`]).
pub fn make_robot(toml: &str) -> Result<Box<dyn Robot>, String> {
    if cfg!(feature = "fault-panic-in-factory") {
        panic!("fault-panic-in-factory: this build's turtlebot3 factory panics on purpose");
    }
    let bot = TurtleBot::from_toml(toml).map_err(robot::error_message)?;
    Ok(Box::new(bot))
}

/// A TOML error in a factory's table, for the host to place: the message without the toml
/// crate's snippet (its line numbers count in the table text the host re-serialised, not in
/// the user's file), with the key it concerns in backquotes first, which the host looks up
/// in the file to name the line.
pub(crate) fn table_error(what: &str, text: &str, e: &toml::de::Error) -> String {
    let message = e.message();
    let key = e
        .span()
        .and_then(|span| {
            let start = span.start.min(text.len());
            let line_start = text[..start].rfind('\n').map_or(0, |i| i + 1);
            let line = text[line_start..].lines().next()?;
            let (key, _) = line.split_once('=')?;
            let key = key.trim().trim_matches('"');
            (!key.is_empty() && !key.contains(['[', ' '])).then(|| key.to_owned())
        })
        .filter(|k| !message.contains(&format!("`{k}`")));
    match key {
        Some(k) => format!("{what}: `{k}`: {message}"),
        None => format!("{what}: {message}"),
    }
}

/// The `[model]` table of `type = "vw-pd-coulomb"`: no keys besides `type`.
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct ModelTable {
    /// The table's `type` key, accepted and not otherwise used.
    #[serde(rename = "type")]
    _kind: Option<String>,
}

/// The `vw-pd-coulomb` factory: the model [`VwPdCoulomb`]; its table takes no keys besides
/// `type`.
///
/// # Errors
/// A message naming an unknown key.
pub fn make_model(toml: &str) -> Result<Box<dyn RegressorModel>, String> {
    let _: ModelTable =
        toml::from_str(toml).map_err(|e| table_error(VwPdCoulomb::NAME, toml, &e))?;
    Ok(Box::new(VwPdCoulomb))
}

#[cfg(not(any(
    feature = "fault-api-version",
    feature = "fault-rustc-version",
    feature = "fault-no-declaration"
)))]
wheelid_core::export_plugin!(register);

/// The API version the faulty declaration claims.
#[cfg(any(feature = "fault-api-version", feature = "fault-rustc-version"))]
const DECLARED_API: u32 = if cfg!(feature = "fault-api-version") {
    wheelid_core::plugin::API_VERSION + 1
} else {
    wheelid_core::plugin::API_VERSION
};

/// The compiler the faulty declaration claims.
#[cfg(any(feature = "fault-api-version", feature = "fault-rustc-version"))]
const DECLARED_RUSTC: &str = if cfg!(feature = "fault-rustc-version") {
    "rustc 0.0.0 (000000000 1970-01-01) wheelid-fault-test"
} else {
    wheelid_core::plugin::RUSTC_VERSION
};

/// A faulty declaration, written by hand (a fault feature is on).
#[cfg(any(feature = "fault-api-version", feature = "fault-rustc-version"))]
#[allow(unsafe_code)] // `no_mangle` exports the symbol, as `export_plugin!` does.
#[unsafe(no_mangle)]
pub static WHEELID_PLUGIN: PluginDeclaration =
    PluginDeclaration::with_versions(DECLARED_API, DECLARED_RUSTC, CORE_VERSION, faulty_entry);

/// The faulty declaration's entry point (never called by a host that checks it).
#[cfg(any(feature = "fault-api-version", feature = "fault-rustc-version"))]
extern "C" fn faulty_entry(registrar: *mut Registrar) -> i32 {
    wheelid_core::plugin::run_registration(registrar, register)
}

#[cfg(test)]
mod tests {
    use super::*;
    use wheelid_core::plugin::run_registration;

    #[cfg(not(any(
        feature = "fault-api-version",
        feature = "fault-rustc-version",
        feature = "fault-no-declaration",
        feature = "fault-panic-in-register",
        feature = "fault-panic-in-factory"
    )))]
    #[test]
    fn the_declaration_checks_and_registers_both_types() {
        assert_eq!(WHEELID_PLUGIN.check(), Ok(()));
        let mut r = Registrar::default();
        assert_eq!((WHEELID_PLUGIN.register)(&mut r), 0);
        let robots: Vec<&str> = r.robots().iter().map(|(n, _)| n.as_str()).collect();
        let models: Vec<&str> = r.models().iter().map(|(n, _)| n.as_str()).collect();
        assert_eq!(
            (robots, models),
            (vec!["turtlebot3"], vec!["vw-pd-coulomb"])
        );
        // Through the registrar's trampolines, as the host calls them.
        let mut bot = r.robots()[0]
            .1
            .make("type = \"turtlebot3\"\nseed = 5\n")
            .expect("robot");
        assert_eq!(bot.name(), "turtlebot3");
        assert!(bot.read().is_ok());
        let e = r.robots()[0]
            .1
            .make("type = \"turtlebot3\"\nperiod = 0.1\n")
            .err()
            .unwrap_or_default();
        assert!(e.contains("unknown field `period`"), "{e}");
        let m = r.models()[0]
            .1
            .make("type = \"vw-pd-coulomb\"\n")
            .expect("model");
        assert_eq!(m.name(), "vw-pd-coulomb");
        assert_eq!(m.params().len(), 8);
        let e = r.models()[0]
            .1
            .make("type = \"vw-pd-coulomb\"\neps = 1\n")
            .err();
        assert!(e.unwrap_or_default().contains("unknown field `eps`"));
    }

    #[cfg(feature = "fault-panic-in-register")]
    #[test]
    fn the_registration_panics_into_an_error() {
        let mut r = Registrar::default();
        assert_eq!(run_registration(&mut r, register), 1);
        assert!(
            r.failure
                .unwrap_or_default()
                .contains("fault-panic-in-register")
        );
    }

    #[cfg(feature = "fault-panic-in-factory")]
    #[test]
    fn the_robot_factory_panics_into_an_error() {
        let mut r = Registrar::default();
        assert_eq!(run_registration(&mut r, register), 0);
        let e = r.robots()[0].1.make("type = \"turtlebot3\"\n").err();
        assert!(e.unwrap_or_default().contains("fault-panic-in-factory"));
    }

    #[cfg(any(feature = "fault-api-version", feature = "fault-rustc-version"))]
    #[test]
    fn the_faulty_declaration_is_refused() {
        let e = WHEELID_PLUGIN.check().expect_err("refused");
        let want = if cfg!(feature = "fault-api-version") {
            "plugin API version"
        } else {
            "rustc 0.0.0"
        };
        assert!(e.contains(want), "{e}");
    }

    #[test]
    fn registration_runs_under_catch_unwind() {
        let mut r = Registrar::default();
        let code = run_registration(&mut r, register);
        assert_eq!(
            code,
            u8::from(cfg!(feature = "fault-panic-in-register")).into()
        );
    }
}
