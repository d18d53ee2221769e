//! One registry of the names a run is made of — models, solvers, estimators and robots, the
//! built-in ones and those the loaded plugins register — through which every command
//! (`identify`, `diagnose`, `run`, `track`, `migrate`) resolves the names it is given.
//!
//! A plugin's name may not shadow a built-in one or another plugin's
//! ([`crate::plugins::PluginError::Duplicate`]); an unknown name is an error that lists the
//! known ones.

use std::path::{Path, PathBuf};

use anyhow::{Result, anyhow};
use wheelid_core::{Estimator, RegressorModel};

use crate::estimators;
use crate::plugins::{BuiltIn, PluginError, Plugins};

/// The built-in robot types.
pub const ROBOT_TYPES: [&str; 5] = ["simulator", "physics", "replay", "pioneer", "khepera"];
/// The built-in model types.
pub const MODEL_TYPES: [&str; 2] = ["vw-pd", "wheel-pd"];
/// The built-in solver types.
pub const SOLVER_TYPES: [&str; 2] = ["ols", "box"];

/// The built-ins and what the loaded plugins registered.
#[derive(Default)]
pub struct Registry {
    plugins: Plugins,
}

impl Registry {
    /// The built-ins only.
    pub fn built_in() -> Self {
        Self::default()
    }

    /// The built-ins and the plugin libraries `entries` ([`crate::run::plugin_path`] against
    /// `base`: a path, or a bare library name beside the executable), refusing names that
    /// clash with a built-in or with each other.
    ///
    /// # Errors
    /// The first [`PluginError`], naming its file; nothing of it is added then.
    pub fn load(base: &Path, entries: &[PathBuf]) -> Result<Self, PluginError> {
        let mut plugins = Plugins::default();
        let builtin = BuiltIn {
            robots: &ROBOT_TYPES,
            models: &MODEL_TYPES,
            solvers: &SOLVER_TYPES,
            estimators: &estimators::BUILT_IN,
        };
        for p in entries {
            plugins.load(&crate::run::plugin_path(base, p), &builtin)?;
        }
        Ok(Self { plugins })
    }

    /// What the plugins registered.
    pub fn plugins(&self) -> &Plugins {
        &self.plugins
    }

    /// The regression model `name` with its defaults: a built-in ([`MODEL_TYPES`]) or a
    /// plugin's, made from the config table `type = "name"`.
    ///
    /// # Errors
    /// A factory's error naming the plugin, or an unknown name listing the known ones.
    pub fn model(&self, name: &str) -> Result<Box<dyn RegressorModel>> {
        if let Some(m) = wheelid_models::by_name(name) {
            return Ok(m);
        }
        match self.plugins.model(name) {
            Some(e) => e
                .make(&format!("type = {name:?}\n"))
                .map_err(|m| anyhow!("model `{name}` of {}: {m}", e.path.display())),
            None => {
                let [_, from_plugins, _, _] = self.plugins.names();
                Err(anyhow!(
                    "unknown model `{name}`; known models: {} (a plugin's with --plugin LIB)",
                    known(&MODEL_TYPES, from_plugins)
                ))
            }
        }
    }

    /// Every refining estimator in report order: the built-ins ([`estimators::built_in`]),
    /// then each plugin's, made from the table `type = "name"` (least squares, `ls`, is
    /// not among them: every identification runs it first).
    ///
    /// # Errors
    /// A plugin factory's error, naming the plugin.
    pub fn estimators(&self) -> Result<Vec<Box<dyn Estimator>>> {
        let mut all = estimators::built_in();
        let [_, _, _, names] = self.plugins.names();
        for name in names {
            if let Some(e) = self.plugins.estimator(&name) {
                all.push(
                    e.make(&format!("type = {name:?}\n"))
                        .map_err(|m| anyhow!("estimator `{name}` of {}: {m}", e.path.display()))?,
                );
            }
        }
        Ok(all)
    }

    /// Every estimator name, least squares first: what `--estimator` accepts.
    pub fn estimator_names(&self) -> Vec<String> {
        let [_, _, _, from_plugins] = self.plugins.names();
        estimators::BUILT_IN
            .iter()
            .map(|s| (*s).to_owned())
            .chain(from_plugins)
            .collect()
    }

    /// Checks that `name` is an estimator ([`Registry::estimator_names`]).
    ///
    /// # Errors
    /// An unknown name, listing the known ones.
    pub fn check_estimator(&self, name: &str) -> Result<()> {
        let names = self.estimator_names();
        let known: Vec<&str> = names.iter().map(String::as_str).collect();
        estimators::check_name(name, &known).map_err(|e| anyhow!(e))
    }
}

/// Built-in names, then plugins', comma-separated.
fn known(built_in: &[&str], from_plugins: Vec<String>) -> String {
    built_in
        .iter()
        .map(|s| (*s).to_owned())
        .chain(from_plugins)
        .collect::<Vec<_>>()
        .join(", ")
}
