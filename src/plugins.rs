//! Loading external plugins: shared libraries that add robots, models, solvers and estimators
//! (`plugins = ["…/libfoo.so"]` in a run config, `--plugin LIB` on a command line). The plugin side is
//! [`wheelid_core::plugin`]; this is the host side.
//!
//! For each path, in this order — and nothing of the library runs before step 3 passes except
//! its loader-level initialisers, which a Rust cdylib does not have:
//!
//! 1. the file must exist (else [`PluginError::Missing`]);
//! 2. it must load as a shared library ([`PluginError::NotALibrary`]) and export
//!    `WHEELID_PLUGIN` ([`PluginError::NoDeclaration`]);
//! 3. the declaration's API version, then compiler and core version must be this build's
//!    ([`PluginError::Incompatible`]);
//! 4. its `register` fills a [`Registrar`] under the plugin's own `catch_unwind`
//!    ([`PluginError::Registration`] if it panicked), and its names must not clash with a
//!    built-in or an earlier plugin ([`PluginError::Duplicate`]).
//!
//! A loaded library is never unloaded: the objects its factories make point into its code,
//! and `dlclose` under them is undefined behaviour (inventory#1, bevy#11969), so each
//! [`libloading::Library`] is kept for the life of the process.

use std::path::{Path, PathBuf};
use std::sync::Mutex;

use wheelid_core::plugin::{
    DECLARATION_SYMBOL, EstimatorFactory, ModelFactory, PluginDeclaration, Registered, Registrar,
    Registrations, RobotFactory, SolverFactory,
};
use wheelid_core::{Estimator, RegressorModel, Robot, Solver};

/// Why a plugin could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum PluginError {
    /// No such file.
    #[error("plugin {0}: no such file")]
    Missing(PathBuf),
    /// The file is not a loadable shared library.
    #[error("plugin {path}: not a loadable shared library: {message}")]
    NotALibrary {
        /// The file.
        path: PathBuf,
        /// The loader's message.
        message: String,
    },
    /// The library exports no `WHEELID_PLUGIN` declaration.
    #[error(
        "plugin {0}: not a wheelid plugin (it exports no `WHEELID_PLUGIN`; write `wheelid_core::export_plugin!(register)` in it)"
    )]
    NoDeclaration(PathBuf),
    /// The declaration does not match this build.
    #[error("plugin {path}: incompatible: {message}")]
    Incompatible {
        /// The file.
        path: PathBuf,
        /// What differs.
        message: String,
    },
    /// The plugin's registration failed.
    #[error("plugin {path}: registration failed: {message}")]
    Registration {
        /// The file.
        path: PathBuf,
        /// Why (the plugin's panic message).
        message: String,
    },
    /// A name is registered twice.
    #[error("plugin {path}: {kind} type `{name}` is already {by}")]
    Duplicate {
        /// The file.
        path: PathBuf,
        /// `robot`, `model`, `solver` or `estimator`.
        kind: &'static str,
        /// The name.
        name: String,
        /// `built in` or `registered by <other plugin>`.
        by: String,
    },
}

/// The libraries loaded so far, kept (never unloaded) until the process ends.
static LIBRARIES: Mutex<Vec<libloading::Library>> = Mutex::new(Vec::new());

/// A factory registered by a plugin, and the plugin's path.
pub struct PluginEntry<F, T: ?Sized> {
    /// The library it came from.
    pub path: PathBuf,
    factory: Registered<F, T>,
}

impl<F: Copy, T: ?Sized> PluginEntry<F, T> {
    /// Makes the object from its config table (TOML text).
    ///
    /// # Errors
    /// The plugin's message (its factory's error or panic).
    pub fn make(&self, toml: &str) -> Result<Box<T>, String> {
        self.factory.make(toml)
    }
}

/// The robots, models, solvers and estimators that the loaded plugins registered.
#[derive(Default)]
pub struct Plugins {
    robots: Vec<(String, PluginEntry<RobotFactory, dyn Robot>)>,
    models: Vec<(String, PluginEntry<ModelFactory, dyn RegressorModel>)>,
    solvers: Vec<(String, PluginEntry<SolverFactory, dyn Solver>)>,
    estimators: Vec<(String, PluginEntry<EstimatorFactory, dyn Estimator>)>,
}

/// Built-in type names that a plugin may not take.
pub struct BuiltIn<'a> {
    /// Robot types.
    pub robots: &'a [&'a str],
    /// Model types.
    pub models: &'a [&'a str],
    /// Solver types.
    pub solvers: &'a [&'a str],
    /// Estimator names.
    pub estimators: &'a [&'a str],
}

impl Plugins {
    /// Loads the plugin at `path` (steps 1–4 of the module doc) and adds what it registers.
    ///
    /// # Errors
    /// A [`PluginError`] naming the file; nothing is added then.
    pub fn load(&mut self, path: &Path, builtin: &BuiltIn<'_>) -> Result<(), PluginError> {
        if !path.is_file() {
            return Err(PluginError::Missing(path.to_owned()));
        }
        let library = open(path)?;
        let registrar = register(&library, path)?;
        // Names first, so that a clash adds nothing.
        let Registrations {
            robots,
            models,
            solvers,
            estimators,
        } = registrar.into_parts();
        check(path, "robot", &names(&robots), builtin.robots, &self.robots)?;
        check(path, "model", &names(&models), builtin.models, &self.models)?;
        check(
            path,
            "solver",
            &names(&solvers),
            builtin.solvers,
            &self.solvers,
        )?;
        check(
            path,
            "estimator",
            &names(&estimators),
            builtin.estimators,
            &self.estimators,
        )?;
        self.robots.extend(entries(path, robots));
        self.models.extend(entries(path, models));
        self.solvers.extend(entries(path, solvers));
        self.estimators.extend(entries(path, estimators));
        // Kept for the life of the process (module doc).
        if let Ok(mut libs) = LIBRARIES.lock() {
            libs.push(library);
        } else {
            std::mem::forget(library);
        }
        Ok(())
    }

    /// The robot type `name`, if a plugin registered it.
    pub fn robot(&self, name: &str) -> Option<&PluginEntry<RobotFactory, dyn Robot>> {
        self.robots.iter().find(|(n, _)| n == name).map(|(_, e)| e)
    }
    /// The model type `name`, if a plugin registered it.
    pub fn model(&self, name: &str) -> Option<&PluginEntry<ModelFactory, dyn RegressorModel>> {
        self.models.iter().find(|(n, _)| n == name).map(|(_, e)| e)
    }
    /// The solver type `name`, if a plugin registered it.
    pub fn solver(&self, name: &str) -> Option<&PluginEntry<SolverFactory, dyn Solver>> {
        self.solvers.iter().find(|(n, _)| n == name).map(|(_, e)| e)
    }
    /// The estimator `name`, if a plugin registered it.
    pub fn estimator(&self, name: &str) -> Option<&PluginEntry<EstimatorFactory, dyn Estimator>> {
        self.estimators
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, e)| e)
    }
    /// Names of the plugin robots, models, solvers and estimators.
    pub fn names(&self) -> [Vec<String>; 4] {
        [
            names(&self.robots),
            names(&self.models),
            names(&self.solvers),
            names(&self.estimators),
        ]
    }
}

/// The names of registrations.
fn names<X>(v: &[(String, X)]) -> Vec<String> {
    v.iter().map(|(n, _)| n.clone()).collect()
}

/// Registrations of the plugin at `path` as entries.
fn entries<F, T: ?Sized>(
    path: &Path,
    v: Vec<(String, Registered<F, T>)>,
) -> impl Iterator<Item = (String, PluginEntry<F, T>)> {
    v.into_iter().map(move |(name, factory)| {
        (
            name,
            PluginEntry {
                path: path.to_owned(),
                factory,
            },
        )
    })
}

/// Refuses a `kind` name of `path` that is built in, registered by an earlier plugin, or twice
/// by this one.
fn check<F, T: ?Sized>(
    path: &Path,
    kind: &'static str,
    new: &[String],
    built: &[&str],
    loaded: &[(String, PluginEntry<F, T>)],
) -> Result<(), PluginError> {
    for (i, name) in new.iter().enumerate() {
        let by = if built.contains(&name.as_str()) {
            "built in".to_owned()
        } else if let Some((_, e)) = loaded.iter().find(|(n, _)| n == name) {
            format!("registered by {}", e.path.display())
        } else if new[..i].contains(name) {
            "registered by this plugin".to_owned()
        } else {
            continue;
        };
        return Err(PluginError::Duplicate {
            path: path.to_owned(),
            kind,
            name: name.clone(),
            by,
        });
    }
    Ok(())
}

// The only unsafe code of wheelid: opening a library and reading its declaration.
#[allow(unsafe_code)]
fn open(path: &Path) -> Result<libloading::Library, PluginError> {
    // SAFETY: loading runs the library's initialisers. A wheelid plugin is a Rust cdylib,
    // which has none of its own; the path is the user's explicit choice in the config.
    unsafe { libloading::Library::new(path) }.map_err(|e| PluginError::NotALibrary {
        path: path.to_owned(),
        message: e.to_string(),
    })
}

#[allow(unsafe_code)]
fn register(library: &libloading::Library, path: &Path) -> Result<Registrar, PluginError> {
    // SAFETY: `WHEELID_PLUGIN` is, by the plugin API, a `PluginDeclaration` static (a C-layout
    // struct of plain data and one `extern "C"` function pointer), read here only through a
    // shared reference while the library stays loaded (it is never unloaded).
    let decl: &PluginDeclaration = unsafe {
        let symbol = library
            .get::<*const PluginDeclaration>(DECLARATION_SYMBOL.as_bytes())
            .map_err(|_| PluginError::NoDeclaration(path.to_owned()))?;
        let ptr: *const PluginDeclaration = *symbol;
        ptr.as_ref()
            .ok_or_else(|| PluginError::NoDeclaration(path.to_owned()))?
    };
    // The API version is compared before any other field is looked at.
    decl.check().map_err(|message| PluginError::Incompatible {
        path: path.to_owned(),
        message,
    })?;
    let mut registrar = Registrar::default();
    let code = (decl.register)(&mut registrar);
    if code != 0 {
        return Err(PluginError::Registration {
            path: path.to_owned(),
            message: registrar
                .failure
                .take()
                .unwrap_or_else(|| format!("its entry point returned {code}")),
        });
    }
    Ok(registrar)
}

#[cfg(test)]
mod tests {
    use super::*;

    const NONE: BuiltIn<'static> = BuiltIn {
        robots: &[],
        models: &[],
        solvers: &[],
        estimators: &[],
    };

    #[test]
    fn a_missing_file_and_a_file_that_is_no_library_are_clear_errors() {
        let mut p = Plugins::default();
        let e = p
            .load(Path::new("/nonexistent/libnothing.so"), &NONE)
            .expect_err("missing");
        assert_eq!(
            e.to_string(),
            "plugin /nonexistent/libnothing.so: no such file"
        );
        let dir = tempfile::tempdir().expect("tempdir");
        let fake = dir.path().join("libfake.so");
        std::fs::write(&fake, b"not an ELF file").expect("write");
        let e = p.load(&fake, &NONE).expect_err("not a library");
        assert!(matches!(e, PluginError::NotALibrary { .. }), "{e}");
        assert!(
            e.to_string()
                .contains("libfake.so: not a loadable shared library"),
            "{e}"
        );
    }
}
