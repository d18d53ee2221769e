//! The effects the mismatch diagnosis searches, one file each, and their registry
//! ([`EFFECTS`]). A new effect is a file here implementing [`wheelid_core::Effect`] and one
//! line in [`EFFECTS`]; a library user can also hand their own to the diagnosis through
//! [`Candidate::new`] (its physics must fit the stages of [`wheelid_core::Terms`]).

mod acceleration_limit;
mod amp_asymmetry;
mod coulomb_friction;
mod dead_zone;
mod effort_clamp;
mod gain_drift;
mod input_delay;
mod output_delay;
mod payload_change;
mod slip;
mod traction_limit;
mod tyre_asymmetry;
mod velocity_saturation;
mod vw_friction;
mod wheel_asymmetry;
mod wheel_friction;

use serde::{Deserialize, Deserializer, Serialize, Serializer};
use wheelid_core::{Effect, ParamInfo};

pub use acceleration_limit::{AccelerationLimit, slew_binding};
pub use amp_asymmetry::AmpAsymmetry;
pub use coulomb_friction::CoulombFriction;
pub use dead_zone::DeadZone;
pub use effort_clamp::EffortClamp;
pub use gain_drift::GainDrift;
pub use input_delay::InputDelay;
pub use output_delay::{LAG_Z, MAX_LAG_S, OutputDelay, heading_lag};
pub use payload_change::PayloadChange;
pub use slip::Slip;
pub use traction_limit::TractionLimit;
pub use tyre_asymmetry::{
    CALM_SHARE, FAR_SHARE, HEADING_SHARE, MEASURED_Z, SLIP_Z, TRAPEZOID_BETTER, TyreAsymmetry,
    heading_ratio,
};
pub use velocity_saturation::VelocitySaturation;
pub use vw_friction::VwFriction;
pub use wheel_asymmetry::WheelAsymmetry;
pub use wheel_friction::WheelFriction;

/// The registry: every built-in effect, in the order the diagnosis reports them.
pub static EFFECTS: [&dyn Effect; 16] = [
    &InputDelay,
    &AccelerationLimit,
    &VelocitySaturation,
    &CoulombFriction,
    &WheelAsymmetry,
    &PayloadChange,
    &GainDrift,
    &Slip,
    &WheelFriction,
    &EffortClamp,
    &AmpAsymmetry,
    &TractionLimit,
    &TyreAsymmetry,
    &VwFriction,
    &OutputDelay,
    &DeadZone,
];

/// [`Effect::quantity`] of the effects that make one wheel act weaker than the other
/// (`wheel_asymmetry`, `amp_asymmetry`, `tyre_asymmetry`): the loop holds each wheel's encoder
/// rate, so a weak amplifier, a larger tyre and a setpoint ratio differ only in how that wheel
/// answers in transients, which encoder data do not tell apart.
pub const WHEEL_IMBALANCE: &str = "wheel imbalance";
/// [`Effect::quantity`] of dry friction, as one term on (v, ω) (`coulomb_friction`) or per
/// wheel, met by each wheel's loop (`wheel_friction`) or by v and ω loops (`vw_friction`).
pub const DRY_FRICTION: &str = "dry friction";
/// [`Effect::quantity`] of the wheels slipping on the floor, as losses (`slip`) or as a
/// traction limit (`traction_limit`).
pub const FLOOR_SLIP: &str = "floor slip";
/// [`Effect::quantity`] of a dead time between the commands and the measurements, of the
/// commands (`input_delay`) or of the measurements (`output_delay`): a dead time commutes with
/// a time-invariant robot, so the encoders alone see only their sum.
pub const DEAD_TIME: &str = "dead time";

/// A value far beyond any command: a limit at this level never binds (a limit's null).
pub const NEVER: f64 = 1e6;

/// A limit's level is significant (its standard error below a third of it) and binds on at
/// least 1 % of the samples (`binding`: the fraction where it does).
///
/// # Errors
/// The reason for the report.
pub fn limit_plausible(
    info: &ParamInfo,
    x: f64,
    se: f64,
    binding: f64,
) -> std::result::Result<(), String> {
    let rel = if x > 0.0 { se / x } else { f64::INFINITY };
    if se <= 0.0 || rel.is_nan() || rel >= 1.0 / 3.0 {
        return Err(format!(
            "{} = {x:.4} ± {se:.4} is not significant",
            info.name
        ));
    }
    if binding < 0.01 {
        return Err(format!(
            "{} = {x:.4} binds on only {:.2} % of the samples",
            info.name,
            100.0 * binding
        ));
    }
    Ok(())
}

/// A ratio of the right wheel to the left (null 1) is significant (at least 3 standard errors
/// from 1), inside the `plausible` range and at least [`MIN_RATIO_EFFECT`] from 1; `what` names it in the report, e.g. "a
/// right/left tyre radius ratio".
///
/// # Errors
/// The reason for the report.
pub fn ratio_plausible(
    info: &ParamInfo,
    x: f64,
    se: f64,
    plausible: std::ops::RangeInclusive<f64>,
    what: &str,
) -> std::result::Result<(), String> {
    wheelid_core::effect::significant(info, x, se, 1.0)?;
    if !plausible.contains(&x) {
        return Err(format!("{what} of {x:.3} is not plausible"));
    }
    if (x - 1.0).abs() < MIN_RATIO_EFFECT {
        return Err(format!(
            "{what} of {x:.4} is within {:.0} % of equal wheels: no asymmetry worth naming",
            100.0 * MIN_RATIO_EFFECT
        ));
    }
    Ok(())
}

/// The smallest left/right ratio effect named, |ρ − 1| \[-\]: 1 %. Wheel radii and
/// amplifier gains of one model differ by about that much anyway (tyre wear and pressure,
/// component tolerances); odometry calibration (Borenstein & Feng's UMBmark, 1996) corrects
/// such errors, and a diagnosis naming them beside a real effect names a fitting artefact
/// (seen: a 0.35 % `amp_asymmetry` added to a fitted tyre mismatch on the Pioneer-like robot,
/// where the tyre's effort map is the controller's, not the wheels').
pub const MIN_RATIO_EFFECT: f64 = 0.01;

/// One effect the diagnosis can search: a handle on an [`Effect`], compared, hashed and
/// (de)serialised by name.
#[derive(Clone, Copy)]
pub struct Candidate(&'static dyn Effect);

impl Candidate {
    /// Dead time of the commands ([`InputDelay`]).
    pub const INPUT_DELAY: Candidate = Candidate(&InputDelay);
    /// Rate limit on the setpoint ([`AccelerationLimit`]).
    pub const ACCELERATION_LIMIT: Candidate = Candidate(&AccelerationLimit);
    /// Clip of the setpoint ([`VelocitySaturation`]).
    pub const VELOCITY_SATURATION: Candidate = Candidate(&VelocitySaturation);
    /// Dry friction ([`CoulombFriction`]).
    pub const COULOMB_FRICTION: Candidate = Candidate(&CoulombFriction);
    /// Left/right wheel gain mismatch ([`WheelAsymmetry`]).
    pub const WHEEL_ASYMMETRY: Candidate = Candidate(&WheelAsymmetry);
    /// θ1, θ2, θ3, θ5 change at a time ([`PayloadChange`]).
    pub const PAYLOAD_CHANGE: Candidate = Candidate(&PayloadChange);
    /// Gains change slowly over the run ([`GainDrift`]).
    pub const GAIN_DRIFT: Candidate = Candidate(&GainDrift);
    /// Losses growing with v·|ω| ([`Slip`]).
    pub const SLIP: Candidate = Candidate(&Slip);
    /// Dry friction per wheel ([`WheelFriction`]).
    pub const WHEEL_FRICTION: Candidate = Candidate(&WheelFriction);
    /// Per-wheel effort clamp ([`EffortClamp`]).
    pub const EFFORT_CLAMP: Candidate = Candidate(&EffortClamp);
    /// Right/left effort gain mismatch ([`AmpAsymmetry`]).
    pub const AMP_ASYMMETRY: Candidate = Candidate(&AmpAsymmetry);
    /// Each wheel's grip on the floor limited ([`TractionLimit`]).
    pub const TRACTION_LIMIT: Candidate = Candidate(&TractionLimit);
    /// Right/left tyre radius mismatch ([`TyreAsymmetry`]).
    pub const TYRE_ASYMMETRY: Candidate = Candidate(&TyreAsymmetry);
    /// Dry friction per wheel met by v and ω loops ([`VwFriction`]).
    pub const VW_FRICTION: Candidate = Candidate(&VwFriction);
    /// Dead time of the measurements ([`OutputDelay`]).
    pub const OUTPUT_DELAY: Candidate = Candidate(&OutputDelay);
    /// Each wheel's dead band ([`DeadZone`]).
    pub const DEAD_ZONE: Candidate = Candidate(&DeadZone);

    /// A candidate for any effect (a built-in one of [`EFFECTS`] or the caller's own).
    pub fn new(effect: &'static dyn Effect) -> Self {
        Self(effect)
    }

    /// Every registered effect, in [`EFFECTS`] order.
    pub fn all() -> Vec<Candidate> {
        EFFECTS.iter().map(|&e| Candidate(e)).collect()
    }

    /// Every registered effect's name.
    pub fn names() -> Vec<&'static str> {
        EFFECTS.iter().map(|e| e.name()).collect()
    }

    /// The registered effect called `name`.
    pub fn by_name(name: &str) -> Option<Self> {
        EFFECTS
            .iter()
            .find(|e| e.name() == name)
            .map(|&e| Candidate(e))
    }

    /// The effect.
    pub fn effect(self) -> &'static dyn Effect {
        self.0
    }

    /// Its name (`input_delay`, …).
    pub fn name(self) -> &'static str {
        self.0.name()
    }

    /// Its parameters (appended after θ in the extended model).
    pub fn params(self) -> &'static [ParamInfo] {
        self.0.params()
    }
}

impl std::fmt::Debug for Candidate {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl PartialEq for Candidate {
    fn eq(&self, other: &Self) -> bool {
        self.name() == other.name()
    }
}

impl Eq for Candidate {}

impl std::hash::Hash for Candidate {
    fn hash<H: std::hash::Hasher>(&self, state: &mut H) {
        self.name().hash(state);
    }
}

impl Serialize for Candidate {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.name())
    }
}

impl<'de> Deserialize<'de> for Candidate {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let name = String::deserialize(d)?;
        Candidate::by_name(&name).ok_or_else(|| {
            serde::de::Error::custom(format!(
                "unknown effect `{name}` (known: {})",
                Candidate::names().join(", ")
            ))
        })
    }
}

/// A one-effect [`wheelid_core::effect::FitData`] over `rec` for the plausibility tests: θ1…θ6 and the
/// effect's parameter at 0, zero covariance, the parameter at index 6; `f` gets it.
#[cfg(test)]
fn with_fit_data<R>(
    rec: wheelid_core::Recording,
    track: Option<f64>,
    f: impl FnOnce(&wheelid_core::effect::FitData<'_>) -> R,
) -> R {
    let recordings = [rec];
    let theta = [0.0; 7];
    let covariance = nalgebra::DMatrix::zeros(7, 7);
    f(&wheelid_core::effect::FitData {
        recordings: &recordings,
        theta: &theta,
        covariance: &covariance,
        base: 6,
        track,
    })
}
