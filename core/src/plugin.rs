//! The plugin API: how a separately compiled library (`cdylib`) adds robots, models, solvers
//! and estimators to wheelid.
//!
//! Rust has no stable ABI, and typetag's registry cannot see registrations made inside a
//! dynamically loaded library (typetag#94). So a plugin declares itself through one exported
//! static, [`PluginDeclaration`] under the symbol `WHEELID_PLUGIN`, that the host reads **before
//! anything else of the library runs**:
//!
//! ```text
//! api_version    u32        must equal the host's API_VERSION
//! rustc_version  [u8; 128]  "rustc 1.95.0 (59807616e 2026-04-14) x86_64-unknown-linux-gnu"
//! core_version   [u8; 32]   this crate's version: the types that cross are this crate's
//! register       extern "C" fn(*mut Registrar) -> i32
//! ```
//!
//! Only when all three match (the *same-compiler contract* of Zenoh's and Michael-F-Bryan's
//! plugin designs) does the host call `register`, which fills a [`Registrar`] with factories:
//! `type` name → `fn(toml_table_text) -> Result<Box<dyn …>, String>`. The host then routes a
//! config's `[robot]`, `[model]` or `[solver]` table whose `type` it does not know itself to
//! the factory registered under that name, passing the table as TOML text; an estimator name
//! it does not know (`--estimator NAME`, a config's `estimator = "NAME"`) goes to the
//! estimator factory of that name with `type = "NAME"`.
//!
//! **Panics never cross.** A cdylib carries its own copy of std, and a panic unwinding from
//! the plugin's std into the host's is a foreign exception that aborts the process. So every
//! call into the plugin runs under `catch_unwind` *on the plugin's side*: the registration
//! ([`export_plugin!`](crate::export_plugin)), each factory (a trampoline stored with it, compiled into the
//! plugin), and every method of the objects the factories return ([`PanicGuard`], wrapped
//! around them inside the plugin). A panic becomes an error naming the plugin's message.
//!
//! Writing a plugin (see `examples/turtlebot-plugin` and the README):
//!
//! ```ignore
//! fn register(r: &mut wheelid_core::plugin::Registrar) {
//!     r.robot("turtlebot3", |toml| Ok(Box::new(TurtleBot::from_toml(toml)?)));
//!     r.model("vw-pd-coulomb", |_| Ok(Box::new(VwPdCoulomb)));
//!     r.estimator("huber", |_| Ok(Box::new(Huber)));
//! }
//! wheelid_core::export_plugin!(register);
//! ```

use std::panic::{AssertUnwindSafe, catch_unwind};

use crate::{
    ChannelInfo, ChannelRegression, Conditioned, DynamicModel, Error, Estimate, Estimator,
    EstimatorInput, LinearFit, LinearProblem, Odometry, ParamInfo, Recording, RegressorModel,
    Result, Robot, RobotError, Sensitivities, Simulation, SolveError, Solver,
};

/// Version of this API (the declaration's layout, the registrar and the factory types); a
/// plugin built against another is refused.
pub const API_VERSION: u32 = 2;

/// The compiler that built this crate, with its host triple (from `rustc -vV`).
pub const RUSTC_VERSION: &str = env!("WHEELID_RUSTC_VERSION");

/// This crate's version.
pub const CORE_VERSION: &str = env!("CARGO_PKG_VERSION");

/// The symbol under which a plugin exports its [`PluginDeclaration`].
pub const DECLARATION_SYMBOL: &str = "WHEELID_PLUGIN";

/// Makes a robot from its config table (TOML text, `type` key included).
pub type RobotFactory = fn(&str) -> std::result::Result<Box<dyn Robot>, String>;
/// Makes a model from its config table.
pub type ModelFactory = fn(&str) -> std::result::Result<Box<dyn RegressorModel>, String>;
/// Makes a solver from its config table.
pub type SolverFactory = fn(&str) -> std::result::Result<Box<dyn Solver>, String>;
/// Makes an estimator from its config table (`type = "name"` and the plugin's keys).
pub type EstimatorFactory = fn(&str) -> std::result::Result<Box<dyn Estimator>, String>;

/// A factory with the trampoline that calls it under the plugin's own `catch_unwind` and
/// wraps what it makes in a [`PanicGuard`] (both compiled into the plugin).
pub struct Registered<F, T: ?Sized> {
    factory: F,
    trampoline: fn(F, &str) -> std::result::Result<Box<T>, String>,
}

impl<F: Copy, T: ?Sized> Registered<F, T> {
    /// Calls the factory with the config table `toml`.
    ///
    /// # Errors
    /// The factory's message, or the panic's.
    pub fn make(&self, toml: &str) -> std::result::Result<Box<T>, String> {
        (self.trampoline)(self.factory, toml)
    }
}

/// Named robot factories.
pub type Robots = Vec<(String, Registered<RobotFactory, dyn Robot>)>;
/// Named model factories.
pub type Models = Vec<(String, Registered<ModelFactory, dyn RegressorModel>)>;
/// Named solver factories.
pub type Solvers = Vec<(String, Registered<SolverFactory, dyn Solver>)>;
/// Named estimator factories.
pub type Estimators = Vec<(String, Registered<EstimatorFactory, dyn Estimator>)>;

/// Everything one plugin registered, by kind.
#[derive(Default)]
pub struct Registrations {
    /// Robot backends.
    pub robots: Robots,
    /// Models.
    pub models: Models,
    /// Least-squares solvers.
    pub solvers: Solvers,
    /// Estimators ([`crate::estimator`]).
    pub estimators: Estimators,
}

/// What a plugin registers: named factories of robots, models, solvers and estimators.
#[derive(Default)]
pub struct Registrar {
    robots: Robots,
    models: Models,
    solvers: Solvers,
    estimators: Estimators,
    /// Set when the registration itself failed (a panic inside it).
    pub failure: Option<String>,
}

impl Registrar {
    /// Registers a robot backend under the config `type` `name`.
    pub fn robot(&mut self, name: &str, factory: RobotFactory) {
        let trampoline = |f: RobotFactory, toml: &str| {
            guarded(|| f(toml)).and_then(|r| r).map(|r| {
                Box::new(PanicGuard {
                    inner: r,
                    name: String::new(),
                }) as Box<dyn Robot>
            })
        };
        self.robots.push((
            name.to_owned(),
            Registered {
                factory,
                trampoline,
            },
        ));
    }

    /// Registers a model under the config `type` `name`.
    pub fn model(&mut self, name: &str, factory: ModelFactory) {
        let trampoline = |f: ModelFactory, toml: &str| {
            guarded(|| f(toml)).and_then(|r| r).map(|m| {
                let name = m.name().to_owned();
                Box::new(PanicGuard { inner: m, name }) as Box<dyn RegressorModel>
            })
        };
        self.models.push((
            name.to_owned(),
            Registered {
                factory,
                trampoline,
            },
        ));
    }

    /// Registers a solver under the config `type` `name`.
    pub fn solver(&mut self, name: &str, factory: SolverFactory) {
        let trampoline = |f: SolverFactory, toml: &str| {
            guarded(|| f(toml)).and_then(|r| r).map(|s| {
                let name = s.name().to_owned();
                Box::new(PanicGuard { inner: s, name }) as Box<dyn Solver>
            })
        };
        self.solvers.push((
            name.to_owned(),
            Registered {
                factory,
                trampoline,
            },
        ));
    }

    /// Registers an estimator of θ under the name `name` (what `--estimator` and a config's
    /// `estimator` give).
    pub fn estimator(&mut self, name: &str, factory: EstimatorFactory) {
        let trampoline = |f: EstimatorFactory, toml: &str| {
            guarded(|| f(toml)).and_then(|r| r).map(|e| {
                let name = e.name().to_owned();
                Box::new(PanicGuard { inner: e, name }) as Box<dyn Estimator>
            })
        };
        self.estimators.push((
            name.to_owned(),
            Registered {
                factory,
                trampoline,
            },
        ));
    }

    /// The registrations, taken apart by kind.
    pub fn into_parts(self) -> Registrations {
        Registrations {
            robots: self.robots,
            models: self.models,
            solvers: self.solvers,
            estimators: self.estimators,
        }
    }

    /// The robots registered, by name.
    pub fn robots(&self) -> &[(String, Registered<RobotFactory, dyn Robot>)] {
        &self.robots
    }
    /// The models registered, by name.
    pub fn models(&self) -> &[(String, Registered<ModelFactory, dyn RegressorModel>)] {
        &self.models
    }
    /// The solvers registered, by name.
    pub fn solvers(&self) -> &[(String, Registered<SolverFactory, dyn Solver>)] {
        &self.solvers
    }
    /// The estimators registered, by name.
    pub fn estimators(&self) -> &[(String, Registered<EstimatorFactory, dyn Estimator>)] {
        &self.estimators
    }
}

/// The declaration a plugin exports as `WHEELID_PLUGIN` ([`export_plugin!`](crate::export_plugin) writes it).
/// Plain data in a C layout, so the host can read and check it before calling anything.
#[repr(C)]
pub struct PluginDeclaration {
    /// [`API_VERSION`] of the core the plugin was built against.
    pub api_version: u32,
    /// [`RUSTC_VERSION`], NUL-padded.
    pub rustc_version: [u8; 128],
    /// [`CORE_VERSION`], NUL-padded.
    pub core_version: [u8; 32],
    /// Fills the registrar; 0 on success, else the registrar's `failure` says why.
    pub register: extern "C" fn(*mut Registrar) -> i32,
}

/// `s` NUL-padded into N bytes (cut at N − 1).
const fn padded<const N: usize>(s: &str) -> [u8; N] {
    let b = s.as_bytes();
    let mut out = [0u8; N];
    let mut i = 0;
    while i < b.len() && i + 1 < N {
        out[i] = b[i];
        i += 1;
    }
    out
}

/// The text of a NUL-padded field.
fn unpadded(b: &[u8]) -> String {
    let end = b.iter().position(|&c| c == 0).unwrap_or(b.len());
    String::from_utf8_lossy(&b[..end]).into_owned()
}

impl PluginDeclaration {
    /// The declaration of a plugin built now, with `register`.
    pub const fn new(register: extern "C" fn(*mut Registrar) -> i32) -> Self {
        Self {
            api_version: API_VERSION,
            rustc_version: padded(RUSTC_VERSION),
            core_version: padded(CORE_VERSION),
            register,
        }
    }
    /// A declaration with the given versions: for testing the host's checks (a plugin
    /// "built" by another compiler, or against another API).
    pub const fn with_versions(
        api_version: u32,
        rustc_version: &str,
        core_version: &str,
        register: extern "C" fn(*mut Registrar) -> i32,
    ) -> Self {
        Self {
            api_version,
            rustc_version: padded(rustc_version),
            core_version: padded(core_version),
            register,
        }
    }
    /// The compiler the plugin was built with.
    pub fn rustc_version(&self) -> String {
        unpadded(&self.rustc_version)
    }
    /// The core version the plugin was built against.
    pub fn core_version(&self) -> String {
        unpadded(&self.core_version)
    }
    /// Checks the declaration against this build: the API version first, then the compiler
    /// and the core version.
    ///
    /// # Errors
    /// A message naming what differs and both values.
    pub fn check(&self) -> std::result::Result<(), String> {
        if self.api_version != API_VERSION {
            return Err(format!(
                "plugin API version {} (this wheelid speaks {API_VERSION})",
                self.api_version
            ));
        }
        if self.rustc_version() != RUSTC_VERSION {
            return Err(format!(
                "built by `{}`, this wheelid by `{RUSTC_VERSION}` (rebuild the plugin with the same compiler)",
                self.rustc_version()
            ));
        }
        if self.core_version() != CORE_VERSION {
            return Err(format!(
                "built against wheelid-core {}, this wheelid has {CORE_VERSION}",
                self.core_version()
            ));
        }
        Ok(())
    }
}

/// Runs the plugin's registration under `catch_unwind` (called by [`export_plugin!`](crate::export_plugin)'s entry
/// point, inside the plugin): 0 on success, 1 if it panicked (the message in
/// `registrar.failure`), 2 for a null registrar.
#[allow(clippy::not_unsafe_ptr_arg_deref)] // the one pointer the entry point receives
pub fn run_registration(registrar: *mut Registrar, register: fn(&mut Registrar)) -> i32 {
    // SAFETY: the host passes a pointer to a live `Registrar` it owns and does not touch
    // while the call lasts; under the same-compiler contract (checked before the call) its
    // layout is this crate's.
    #[allow(unsafe_code)]
    let Some(r) = (unsafe { registrar.as_mut() }) else {
        return 2;
    };
    match guarded(|| register(r)) {
        Ok(()) => 0,
        Err(message) => {
            r.failure = Some(message);
            1
        }
    }
}

/// Exports a plugin: `export_plugin!(register)` with `fn register(&mut Registrar)` writes the
/// `WHEELID_PLUGIN` declaration and its entry point.
#[macro_export]
macro_rules! export_plugin {
    ($register:path) => {
        /// The wheelid plugin declaration (read by the host before anything else).
        #[allow(unsafe_code)]
        #[unsafe(no_mangle)]
        pub static WHEELID_PLUGIN: $crate::plugin::PluginDeclaration =
            $crate::plugin::PluginDeclaration::new(__wheelid_plugin_register);

        extern "C" fn __wheelid_plugin_register(registrar: *mut $crate::plugin::Registrar) -> i32 {
            $crate::plugin::run_registration(registrar, $register)
        }
    };
}

/// `f()` with a panic turned into its message.
fn guarded<T>(f: impl FnOnce() -> T) -> std::result::Result<T, String> {
    catch_unwind(AssertUnwindSafe(f)).map_err(|p| {
        let what = p
            .downcast_ref::<&str>()
            .map(|s| (*s).to_owned())
            .or_else(|| p.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "a panic without a message".into());
        format!("the plugin panicked: {what}")
    })
}

/// A plugin's object with every method run under the plugin's `catch_unwind`: a panic
/// becomes the method's error (or, for the infallible accessors, an empty answer).
pub struct PanicGuard<T: ?Sized> {
    name: String,
    inner: Box<T>,
}

impl Robot for PanicGuard<dyn Robot> {
    fn name(&self) -> &str {
        match guarded(|| self.inner.name()) {
            Ok(n) => n,
            Err(_) => "plugin robot",
        }
    }
    fn period_s(&self) -> f64 {
        guarded(|| self.inner.period_s()).unwrap_or(f64::NAN)
    }
    fn velocity_sampling(&self) -> crate::VelocitySampling {
        guarded(|| self.inner.velocity_sampling()).unwrap_or_default()
    }
    fn timing(&self) -> Option<crate::Timing> {
        guarded(|| self.inner.timing()).unwrap_or(None)
    }
    fn true_pose(&self) -> Option<crate::Pose> {
        guarded(|| self.inner.true_pose()).unwrap_or(None)
    }
    fn send(&mut self, v_ref: f64, w_ref: f64) -> std::result::Result<(f64, f64), RobotError> {
        guarded(|| self.inner.send(v_ref, w_ref)).map_err(RobotError::Setting)?
    }
    fn read(&mut self) -> std::result::Result<Odometry, RobotError> {
        guarded(|| self.inner.read()).map_err(RobotError::Setting)?
    }
    fn stop(&mut self) -> std::result::Result<(), RobotError> {
        guarded(|| self.inner.stop()).map_err(RobotError::Setting)?
    }
}

impl DynamicModel for PanicGuard<dyn RegressorModel> {
    fn name(&self) -> &str {
        &self.name
    }
    fn params(&self) -> &[ParamInfo] {
        guarded(|| self.inner.params()).unwrap_or(&[])
    }
    fn channels(&self) -> &[ChannelInfo] {
        guarded(|| self.inner.channels()).unwrap_or(&[])
    }
    fn simulate(&self, theta: &[f64], rec: &Recording, initial: &[f64]) -> Result<Simulation> {
        guarded(|| self.inner.simulate(theta, rec, initial)).map_err(Error::InvalidSetting)?
    }
    fn simulate_with_sensitivities(
        &self,
        theta: &[f64],
        rec: &Recording,
        initial: &[f64],
    ) -> Result<Option<(Simulation, Sensitivities)>> {
        guarded(|| self.inner.simulate_with_sensitivities(theta, rec, initial))
            .map_err(Error::InvalidSetting)?
    }
}

impl RegressorModel for PanicGuard<dyn RegressorModel> {
    fn regression(&self, data: &Conditioned<'_>) -> Result<Vec<ChannelRegression>> {
        guarded(|| self.inner.regression(data)).map_err(Error::InvalidSetting)?
    }
}

impl Estimator for PanicGuard<dyn Estimator> {
    fn name(&self) -> &str {
        &self.name
    }
    fn estimate(&self, input: &EstimatorInput<'_>) -> std::result::Result<Estimate, SolveError> {
        guarded(|| self.inner.estimate(input)).map_err(SolveError::Numerical)?
    }
}

impl Solver for PanicGuard<dyn Solver> {
    fn name(&self) -> &str {
        &self.name
    }
    fn solve(&self, problem: &LinearProblem<'_>) -> std::result::Result<LinearFit, SolveError> {
        guarded(|| self.inner.solve(problem)).map_err(SolveError::Numerical)?
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Panicky;
    impl Robot for Panicky {
        fn name(&self) -> &str {
            "panicky"
        }
        fn period_s(&self) -> f64 {
            0.1
        }
        fn send(&mut self, _: f64, _: f64) -> std::result::Result<(f64, f64), RobotError> {
            panic!("motor on fire")
        }
        fn read(&mut self) -> std::result::Result<Odometry, RobotError> {
            Err(RobotError::Ended)
        }
    }

    #[test]
    fn declarations_check_the_api_version_first_then_the_compiler_and_core() {
        extern "C" fn reg(_: *mut Registrar) -> i32 {
            0
        }
        let good = PluginDeclaration::new(reg);
        assert_eq!(good.check(), Ok(()));
        assert_eq!(good.rustc_version(), RUSTC_VERSION);
        assert!(RUSTC_VERSION.starts_with("rustc "), "{RUSTC_VERSION}");
        let mut bad = PluginDeclaration::new(reg);
        bad.api_version = API_VERSION + 1;
        bad.rustc_version = padded("rustc 0.0.0");
        let e = bad.check().expect_err("refused");
        assert!(e.contains("plugin API version 3"), "{e}");
        let mut bad = PluginDeclaration::new(reg);
        bad.rustc_version = padded("rustc 0.0.0 (abc) x86_64");
        let e = bad.check().expect_err("refused");
        assert!(e.contains("rustc 0.0.0 (abc) x86_64"), "{e}");
        let mut bad = PluginDeclaration::new(reg);
        bad.core_version = padded("9.9.9");
        let e = bad.check().expect_err("refused");
        assert!(e.contains("wheelid-core 9.9.9"), "{e}");
    }

    #[test]
    fn panics_in_registration_factories_and_methods_become_errors() {
        let mut r = Registrar::default();
        assert_eq!(run_registration(&mut r, |_| panic!("bad registration")), 1);
        assert_eq!(
            r.failure.as_deref(),
            Some("the plugin panicked: bad registration")
        );
        assert_eq!(run_registration(std::ptr::null_mut(), |_| {}), 2);
        let mut r = Registrar::default();
        let code = run_registration(&mut r, |r| {
            r.robot("panicky", |_| Ok(Box::new(Panicky)));
            r.robot("broken", |toml| panic!("cannot parse {toml}"));
        });
        assert_eq!(code, 0);
        assert_eq!(r.robots().len(), 2);
        let e = r.robots()[1].1.make("x = 1").err();
        assert_eq!(
            e.as_deref(),
            Some("the plugin panicked: cannot parse x = 1")
        );
        let mut robot = r.robots()[0].1.make("").expect("made");
        assert_eq!(robot.name(), "panicky");
        let e = robot.send(0.1, 0.0).expect_err("panic is an error");
        assert_eq!(e.to_string(), "the plugin panicked: motor on fire");
        assert!(matches!(robot.read(), Err(RobotError::Ended)));
    }

    struct Broken;
    impl Solver for Broken {
        fn name(&self) -> &str {
            "broken"
        }
        fn solve(&self, _: &LinearProblem<'_>) -> std::result::Result<LinearFit, SolveError> {
            panic!("singular by design")
        }
    }

    #[test]
    fn solvers_register_and_their_panics_become_solve_errors() {
        let mut r = Registrar::default();
        assert_eq!(
            run_registration(&mut r, |r| r.solver("broken", |_| Ok(Box::new(Broken)))),
            0
        );
        let Registrations {
            robots,
            models,
            solvers,
            estimators,
        } = r.into_parts();
        assert!(robots.is_empty() && models.is_empty() && estimators.is_empty());
        assert_eq!(solvers.len(), 1);
        assert_eq!(solvers[0].0, "broken");
        let solver = solvers[0].1.make("type = \"broken\"").expect("made");
        assert_eq!(solver.name(), "broken");
        let (x, y) = (nalgebra::DMatrix::zeros(3, 1), nalgebra::DVector::zeros(3));
        let problem = LinearProblem {
            x: &x,
            y: &y,
            names: &["a"],
            bounds: None,
            correlation_lags: 0,
        };
        assert_eq!(
            solver.solve(&problem).err(),
            Some(SolveError::Numerical(
                "the plugin panicked: singular by design".into()
            ))
        );
    }

    struct PanickyEstimator;
    impl Estimator for PanickyEstimator {
        fn name(&self) -> &str {
            "panicky"
        }
        fn estimate(&self, _: &EstimatorInput<'_>) -> std::result::Result<Estimate, SolveError> {
            panic!("diverged on purpose")
        }
    }

    /// A model with no parameters, enough to pose an estimator's input.
    struct Empty;
    impl DynamicModel for Empty {
        fn name(&self) -> &str {
            "empty"
        }
        fn params(&self) -> &[ParamInfo] {
            &[]
        }
        fn channels(&self) -> &[ChannelInfo] {
            &[]
        }
        fn simulate(&self, _: &[f64], _: &Recording, _: &[f64]) -> Result<Simulation> {
            Ok(Vec::new())
        }
    }
    impl RegressorModel for Empty {
        fn regression(&self, _: &Conditioned<'_>) -> Result<Vec<ChannelRegression>> {
            Ok(Vec::new())
        }
    }

    #[test]
    fn estimators_register_by_name_and_their_panics_become_solve_errors() {
        let mut r = Registrar::default();
        let code = run_registration(&mut r, |r| {
            r.estimator("panicky", |_| Ok(Box::new(PanickyEstimator)));
        });
        assert_eq!(code, 0);
        assert_eq!(r.estimators().len(), 1);
        assert_eq!(r.estimators()[0].0, "panicky");
        let estimator = r.estimators()[0]
            .1
            .make("type = \"panicky\"")
            .expect("made");
        assert_eq!(estimator.name(), "panicky");
        let input = EstimatorInput {
            model: &Empty,
            recordings: &[],
            conditioned: &[],
            start: &[],
            bounds: None,
            cutoff_hz: 1.0,
            condition: &crate::ConditionSettings::default(),
            lags: 0,
        };
        assert_eq!(
            estimator.estimate(&input).err(),
            Some(SolveError::Numerical(
                "the plugin panicked: diverged on purpose".into()
            ))
        );
    }
}
