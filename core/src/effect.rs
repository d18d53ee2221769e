//! Effects: the physics that the six-θ model (Laut 2011 eq. 2.19) leaves out, as the mismatch
//! diagnosis sees them. An effect is one type implementing [`Effect`]: its parameters (with
//! units, null values and fit bounds), which channels it acts on, how it extends the dynamics
//! ([`Effect::apply`] into [`Terms`]), how its fingerprint is probed ([`Probe`]), how its fit
//! is started ([`Search`]) and which fitted values are physically plausible.
//!
//! The extended dynamics (`wheelid_models::Extended`) apply the terms in this order, with u
//! the recorded command held between samples:
//!
//! ```text
//! 1. u(t − delay)                                   Terms::delay        [s]
//! 2. clip to ±sat                                   Terms::sat          [m/s, rad/s]
//! 3. slew at most at accel                          Terms::accel        [m/s², rad/s²]
//! 4. wheel setpoints v ± dω/2 × 2ρ/(1+ρ), 2/(1+ρ)   Terms::ratio        [-]
//! 5. drive gain g = 1 + drift (t − t0)              Terms::drift        [1/s]
//! θ1 v̇ = g (u_v − v) − (θ4 − 1) v + θ3 ω² − c_v tanh(v/ε_v) − θ4 k_v v |ω|
//! θ2 ω̇ = g (u_ω − ω) − (θ6 − 1) ω − θ5 v ω − c_ω tanh(ω/ε_ω) − θ6 k_w |v| ω
//!                                                   Terms::coulomb, Terms::slip
//! each wheel's effort scaled, clamped (g (u − v))   Terms::wheels       [-, m/s]
//! θ1, θ2, θ3, θ5 replaced from a time on            Terms::payload
//! each wheel's grip on the floor limited             Terms::traction     [m/s², -, -]
//! ```
//!
//! The traction stage splits the inertia: a share ε of θ1, θ2 turns with the wheels (what the
//! encoders see), the rest is the body, and each wheel passes the body at most a limited force
//! ([`Traction`]; in grip it is eq. 2.19 exactly).
//!
//! plus any state-dependent generalised [`Force`] an effect adds to the right-hand sides
//! ([`Effect::force`], e.g. dry friction per wheel, sign(v ± dω/2)). An effect whose physics fits
//! these stages or is a force is one file and one line in the registry
//! (`wheelid_models::effects::EFFECTS`); an effect that needs a new stage (a command transform,
//! a time-varying θ) adds it here and in the integrator.

use crate::{ParamInfo, Recording, Result};

/// The stages of the extended dynamics that effects fill in (module docs). The default is the
/// six-θ model: no delay, no limits, no friction, no payload change.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Terms {
    /// Dead time of the commands \[s\].
    pub delay: f64,
    /// Dead time of the measurements \[s\]: the outputs stamped t are the robot's at t − this
    /// (a sensor or transport delay). Every stage but a payload change and a drive-gain drift
    /// is time-invariant, so it acts as a dead time of the commands added to `delay`, with
    /// the change's time and the drift's clock moved by it.
    pub output_delay: f64,
    /// Largest rate of change of the (v, ω) setpoints [m/s², rad/s²].
    pub accel: Option<[f64; 2]>,
    /// Largest |v|, |ω| setpoint [m/s, rad/s].
    pub sat: Option<[f64; 2]>,
    /// Dry friction in command units [m/s, rad/s].
    pub coulomb: [f64; 2],
    /// Right/left wheel gain ratio ρ.
    pub ratio: Option<f64>,
    /// Change time \[s\] and θ1, θ2, θ3, θ5 after it.
    pub payload: Option<(f64, [f64; 4])>,
    /// Relative change of the drive gain per second [1/s]: the loop's effort × (1 + drift (t − t0)).
    pub drift: f64,
    /// Losses per unit v·|ω| [s/rad] and |v|·ω [s/m].
    pub slip: [f64; 2],
    /// Per-wheel efforts: a gain on the right wheel's, a clamp ([`WheelTerms`]).
    pub wheels: Option<WheelTerms>,
    /// Each wheel's grip on the floor limited ([`Traction`]).
    pub traction: Option<Traction>,
    /// The right wheel's row of the dynamics scaled: with the wheels' accelerations
    /// ṁ_R,L = v̇ ± (d/2) ω̇ (d the wheel track), ṁ_R × this factor [-] (a larger right tyre,
    /// whose share of the chassis inertia grows as the encoders see it; `None`: 1). Beside a
    /// [`Traction`] stage the tyre acts at its contact instead: ρ = 1/this is read there, and
    /// the row and the effort's 1/ρ are not applied to the wheels' own inertia.
    pub right_row: Option<f64>,
}

impl Terms {
    /// The dead time between a command and the output it shows in \[s\]: the commands' and
    /// the measurements' together.
    pub fn dead_time(&self) -> f64 {
        self.delay + self.output_delay
    }
}

/// A traction limit (`traction_limit`): the wheels and the body as two inertias, θ1, θ2 split
/// into a share `wheel_share` ε on the wheels' side and 1 − ε on the body's, coupled at each
/// wheel's contact by a force that saturates at the floor's grip. With (v_w, ω_w) the wheels'
/// speeds (the encoders'), (v_b, ω_b) the body's, f = (f_v, f_ω) eq. 2.19's right-hand side at
/// the wheels' speeds and T = (T_v, T_ω) the force passed to the body:
///
/// ```text
/// ε θ1 v̇_w = f_v − T_v        (1 − ε) θ1 v̇_b = T_v
/// ε θ2 ω̇_w = f_ω − T_ω        (1 − ε) θ2 ω̇_b = T_ω
/// t_R,L = T_v ± κ T_ω = (c + p T_v) tanh(s_R,L / s0),   s_R,L = (v_w − v_b) ± (d/2)(ω_w − ω_b)
/// ```
///
/// with c = (1 − ε) θ1 a_max (a straight run accelerates at most at `accel_max`), κ = `mix` ×
/// d/2, the slip scale s0 of [`TRACTION_SLIP_SHARE`] and p = `load_transfer`: the body's
/// acceleration pitches it and moves weight between the wheels and the caster, so each wheel's
/// limit grows with the force T_v it passes (solved, (c + p T_v) = c/(1 − p ḡ), ḡ the mean of
/// the two tanh). For a centre of mass at height h and a caster at x_c from the axle,
/// p = μ (h + 2 I_e/(m r))/x_c (the wheels' spin momentum, I_e each, adds to the pitching
/// moment), positive where the caster is ahead (pulling forward loads the wheels): on the
/// physics backend's Khepera-like robot on a floor of μ ≈ 0.2, p ≈ 0.1 — 10 % more grip
/// accelerating, 10 % less braking (the axle loads of a vehicle under traction: J. Y. Wong,
/// *Theory of Ground Vehicles*, 4th ed. (2008) §3.1). In grip (s → 0) the sum of each pair
/// is eq. 2.19. Source: the rigid-wheel/Coulomb-contact picture of Siegwart & Nourbakhsh,
/// *Introduction to Autonomous Mobile Robots* (2011) §3.2 (a wheel rolls without slipping only
/// while the floor can pass its force), with the thesis's eq. 2.19 as the gripping limit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Traction {
    /// Largest straight-line body acceleration the floor passes, μ g × the driven wheels' share
    /// of the weight [m/s²].
    pub accel_max: f64,
    /// Share ε of θ1, θ2 on the wheels' side of the contact (wheels, gears, rotors) [-].
    pub wheel_share: f64,
    /// κ relative to d/2 [-] (each wheel's share of the ω force, as [`WheelTerms::mix`]).
    pub mix: f64,
    /// Load transfer p [-]: each wheel's limit grows by p × the body's traction force T_v
    /// (μ × centre-of-mass height / caster distance from the axle; 0: no pitch).
    pub load_transfer: f64,
}

/// The grip's compliance: a wheel's traction reaches tanh(1) ≈ 76 % of its limit c at the slip
/// speed s0 = a_max × this × τ, τ = min(θ1/θ4, θ2/θ6) [-]. In grip the wheels then lead the
/// body by about 2 % of τ (s ≈ 0.02 τ v̇), and the grip relaxes 1/(0.02 ε) times faster than
/// τ: stiff, but bounded whatever the limit.
pub const TRACTION_SLIP_SHARE: f64 = 0.02;

/// The speed loop's effort per wheel (`amp_asymmetry`, `effort_clamp`): with E_v = u_v − g v,
/// E_ω = u_ω − g ω the loop's efforts in eq. 2.19, the wheels' e_R,L = E_v ± κ E_ω
/// (κ = `mix` · d/2); the right one is scaled by `right_gain`, both are clamped to
/// ±`effort_max`, the right one's clamped effort is scaled by `right_lever`, and they are
/// recombined, (ē_R + ē_L)/2 and (ē_R − ē_L)/(2κ), in place of E_v, E_ω. An effect scales or
/// sets its own fields and leaves the others (a weak amplifier and a larger tyre on one wheel
/// multiply).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WheelTerms {
    /// Right wheel's effort gain relative to the left's [-].
    pub right_gain: f64,
    /// Largest |wheel effort| [m/s of rim speed error] (infinite: no clamp).
    pub effort_max: f64,
    /// Each wheel's dead band [m/s of rim speed error]: an effort e within ±this drives
    /// nothing, one beyond it drives e ∓ this (a motor driver's dead band; applied before the
    /// clamp; 0: none).
    pub effort_dead: f64,
    /// κ relative to the wheel-PD loop's d/2 [-]. Each effect that carries a mix
    /// (`effort_clamp`, `dead_zone`) multiplies it, so one at its null 1 leaves it as it is.
    pub mix: f64,
    /// Right wheel's clamped effort's share on the chassis [-]: a larger tyre's 1/ρ, which
    /// acts after the amplifier's supply clamps its voltage (the clamped wheel pushes the
    /// chassis 1/ρ as hard).
    pub right_lever: f64,
    /// The speed loop's derivative gain over its proportional gain, K_D/K_P \[s\]: the share
    /// of θ1, θ2 that a clamped wheel loses with its feedback (0: none; §2.2, Appendix A.3).
    pub derivative: f64,
}

impl Default for WheelTerms {
    fn default() -> Self {
        Self {
            right_gain: 1.0,
            effort_max: f64::INFINITY,
            effort_dead: 0.0,
            mix: 1.0,
            right_lever: 1.0,
            derivative: 0.0,
        }
    }
}

/// A generalised force an effect adds to eq. 2.19's right-hand sides, θ1 v̇ = … + f_v and
/// θ2 ω̇ = … + f_ω, in command units (m/s, rad/s), with its Jacobian ∂(f_v, f_ω)/∂(v, ω).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Force {
    /// (f_v [m/s], f_ω [rad/s]).
    pub f: [f64; 2],
    /// ∂f/∂(v, ω): rows f_v, f_ω; columns v, ω.
    pub jacobian: [[f64; 2]; 2],
}

/// The channels an effect acts on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EffectChannels {
    /// Both v and ω, through all its parameters.
    Both,
    /// Only ω.
    Omega,
    /// Parameter 0 acts on v, 1 on ω; each channel is fitted only where its own pattern asks
    /// for it (`positive`: only where the residual asks for a positive value) and kept only
    /// where it is significant.
    Each {
        /// Whether the parameter can only be positive (a loss, a friction).
        positive: bool,
    },
}

/// How an effect's fit is started from its fingerprint.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Search {
    /// A Gauss–Newton step from the null, shortened by a line search on the training cost.
    Smooth,
    /// A limit read off the data: its level scaled on a grid; `rate` (a setpoint rate limit)
    /// also tries the lags shortened, which a nominal fit lengthens to imitate the limit.
    Limit {
        /// Whether the limit is on the rate of the setpoint.
        rate: bool,
    },
    /// A dead time: a geometric grid from half a sample to 1.5 s first.
    DeadTime,
    /// Parameter 0 is a change time: held while the rest is fitted, then scanned on a fine
    /// grid (its standard error is the width of the flat minimum).
    ChangeTime,
}

impl Search {
    /// Whether this is [`Search::Limit`] (a setpoint rate limit or not): a level read off the
    /// data, whose fit the diagnosis starts, judges and continues apart from the others.
    pub fn is_limit(self) -> bool {
        matches!(self, Self::Limit { .. })
    }
}

/// How an effect's fingerprint (the score test's pattern) is probed at its null.
#[derive(Debug, Clone, PartialEq)]
pub enum Probe {
    /// Finite-difference columns of the outputs: (parameter, step).
    Gradient(Vec<(usize, f64)>),
    /// A limit at levels read off the data: (parameter, level) for the channels where it
    /// binds, and what the data show.
    Levels {
        /// (parameter, level in its unit) per binding channel.
        levels: Vec<(usize, f64)>,
        /// What the data show, for the report.
        evidence: String,
    },
    /// Parameter `time` is a change time probed at `n` evenly spaced interior times; at each,
    /// finite-difference columns of the other parameters with steps relative to their value.
    TimeGrid {
        /// Index of the time parameter.
        time: usize,
        /// Interior times.
        n: usize,
        /// (parameter, relative step).
        columns: Vec<(usize, f64)>,
    },
}

/// What an effect may read off the data to probe its fingerprint.
#[derive(Debug, Clone, Copy)]
pub struct ProbeData<'a> {
    /// The recordings (uniform).
    pub recordings: &'a [Recording],
    /// Measured accelerations (v̇, ω̇) per recording (smoothed derivative).
    pub accel: &'a [[Vec<f64>; 2]],
    /// θ1…θ6 of the model in hand.
    pub theta: &'a [f64],
    /// The model in hand's free-run outputs (v̂ [m/s], ω̂ [rad/s]) per recording, on its
    /// samples, where it extends eq. 2.19 by effects found before: what that model asks of the
    /// robot (a rate limit in it shapes the commands before they reach the wheels). `None` for
    /// eq. 2.19 alone, whose accelerations are read in closed form at the measured speeds.
    pub simulated: Option<&'a [[Vec<f64>; 2]]>,
    /// Sample period \[s\].
    pub dt: f64,
    /// Wheel track d \[m\], if known.
    pub track: Option<f64>,
}

impl ProbeData<'_> {
    /// Command `ch` (0: v_ref, 1: ω_ref) over every recording.
    pub fn command(&self, ch: usize) -> impl Iterator<Item = f64> + '_ {
        self.recordings.iter().flat_map(move |r| {
            if ch == 0 {
                r.v_ref.iter()
            } else {
                r.w_ref.iter()
            }
            .copied()
        })
    }
    /// Measured channel `ch` (0: v, 1: ω) over every recording.
    pub fn measured(&self, ch: usize) -> impl Iterator<Item = f64> + '_ {
        self.recordings
            .iter()
            .flat_map(move |r| if ch == 0 { r.v.iter() } else { r.w.iter() }.copied())
    }
}

/// What a sensor other than the encoders measures of an effect ([`Effect::measured`]): its
/// parameters' values (one per [`Effect::params`] entry, in its units) with their standard
/// errors, the bounds within which the encoders' dynamics may show them (an inertia the
/// tyre does not carry makes a tyre look smaller to the dynamics than to the heading), and
/// what measured them, for the report.
#[derive(Debug, Clone, PartialEq)]
pub struct Measurement {
    /// The measured values, one per parameter.
    pub values: Vec<f64>,
    /// Their standard errors.
    pub std_err: Vec<f64>,
    /// (lower, upper) bounds of each parameter in a fit of the dynamics.
    pub bounds: Vec<(f64, f64)>,
    /// What measured them ("the chassis heading …").
    pub evidence: String,
}

/// What a fitted effect is checked against.
#[derive(Debug, Clone, Copy)]
pub struct FitData<'a> {
    /// The recordings.
    pub recordings: &'a [Recording],
    /// The whole fitted θ (θ1…θ6, then every effect's parameters).
    pub theta: &'a [f64],
    /// Its covariance (held parameters: 0).
    pub covariance: &'a nalgebra::DMatrix<f64>,
    /// Where this effect's parameters start in `theta`.
    pub base: usize,
    /// Wheel track d \[m\], if known.
    pub track: Option<f64>,
}

impl FitData<'_> {
    /// Largest |command| on channel `ch` (0: v_ref, 1: ω_ref).
    pub fn command_max(&self, ch: usize) -> f64 {
        self.recordings
            .iter()
            .flat_map(|r| {
                if ch == 0 {
                    r.v_ref.iter()
                } else {
                    r.w_ref.iter()
                }
            })
            .fold(0.0f64, |a, x| a.max(x.abs()))
    }
    /// Longest drive \[s\]: from a recording's drive start ([`Recording::drive_start`]) to its
    /// last sample.
    pub fn span_s(&self) -> f64 {
        self.recordings
            .iter()
            .map(|r| r.t[r.len() - 1] - r.drive_start())
            .fold(0.0f64, f64::max)
    }
    /// The longest mean sample period over the recordings \[s\] (0 without two samples).
    pub fn period_s(&self) -> f64 {
        self.recordings
            .iter()
            .filter(|r| r.len() > 1)
            .map(|r| (r.t[r.len() - 1] - r.t[0]) / (r.len() - 1) as f64)
            .fold(0.0f64, f64::max)
    }
    /// Standard error of θ\[i\].
    pub fn std_err(&self, i: usize) -> f64 {
        self.covariance[(i, i)].max(0.0).sqrt()
    }
}

/// The q quantile of |x| (0 for no data).
pub fn abs_quantile(x: impl Iterator<Item = f64>, q: f64) -> f64 {
    let mut v: Vec<f64> = x.map(f64::abs).collect();
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * q).round() as usize]
}

/// z = |x − null| / σ, 0 when σ is not positive.
pub fn z_score(x: f64, null: f64, se: f64) -> f64 {
    if se > 0.0 { (x - null).abs() / se } else { 0.0 }
}

/// `Err` unless x is at least 3 standard errors from `null`.
///
/// # Errors
/// The sentence for the report.
pub fn significant(
    info: &ParamInfo,
    x: f64,
    se: f64,
    null: f64,
) -> std::result::Result<(), String> {
    if z_score(x, null, se) < 3.0 {
        Err(format!(
            "{} = {x:.4} ± {se:.4} is not significant (< 3 σ from {null})",
            info.name
        ))
    } else {
        Ok(())
    }
}

/// A physics the six-θ model leaves out (module docs). Implementations are unit structs
/// registered in `wheelid_models::effects::EFFECTS`.
pub trait Effect: Send + Sync + std::fmt::Debug {
    /// The name in reports and configs (`input_delay`, …).
    fn name(&self) -> &'static str;
    /// Its parameters, appended after θ in the extended model: name, unit, meaning.
    fn params(&self) -> &'static [ParamInfo];
    /// The channels it acts on.
    fn channels(&self) -> EffectChannels {
        EffectChannels::Both
    }
    /// Parameter values at which the effect is absent, given θ1…θ6 and the middle of the
    /// recordings' time span \[s\].
    fn null(&self, theta: &[f64], t_mid: f64) -> Vec<f64>;
    /// Bounds of its parameters in a fit, given the span of allowed change times \[s\].
    fn bounds(&self, t_range: (f64, f64)) -> Vec<(f64, f64)>;
    /// How its fit starts.
    fn search(&self) -> Search {
        Search::Smooth
    }
    /// Its fingerprint's probe on these data, `None` if it cannot act on them (a limit that
    /// never binds, a wheel asymmetry without a track).
    fn probe(&self, data: &ProbeData<'_>) -> Option<Probe>;
    /// One sentence: what the residual shows when the effect is there.
    fn evidence(&self) -> &'static str;
    /// For a limit at `level` on channel `ch`: the fraction of the samples where it binds;
    /// `None` for effects that are not limits.
    fn binding(&self, _recordings: &[Recording], _ch: usize, _level: f64) -> Option<f64> {
        None
    }
    /// Whether fitted parameter `j` (value `x`, standard error `se`) is significant and
    /// physically plausible.
    ///
    /// # Errors
    /// The reason for the report.
    fn plausible(
        &self,
        j: usize,
        x: f64,
        se: f64,
        fit: &FitData<'_>,
    ) -> std::result::Result<(), String>;
    /// A check over all its parameters together (default: none).
    ///
    /// # Errors
    /// The reason for the report.
    fn plausible_together(&self, _fit: &FitData<'_>) -> std::result::Result<(), String> {
        Ok(())
    }
    /// Fills its stage of the extended dynamics from its parameters `p` (an effect that acts
    /// only through [`Effect::force`] leaves `terms` as they are).
    ///
    /// # Errors
    /// [`crate::Error::InvalidSetting`] for values the dynamics cannot use.
    fn apply(&self, p: &[f64], terms: &mut Terms) -> Result<()>;
    /// Whether it adds a [`Force`] (then [`Effect::force`] is called at every evaluation of the
    /// right-hand side).
    fn has_force(&self) -> bool {
        false
    }
    /// Whether its stage has no sensitivity equations, so that a model with it has its
    /// sensitivities by forward differences (one simulation per parameter and iteration, as
    /// the traction stage, [`Terms::traction`]): diagnose fits it only where its screened start
    /// already lowers the training cost by its `min_improvement`, never as a rival, and with a
    /// smaller iteration budget.
    fn differenced(&self) -> bool {
        false
    }
    /// Its parameters that the data may not separate from the others until those are fitted
    /// (the clamp's derivative term, which trades with its level on one θ1), each (index, a
    /// start inside its bounds for θ1…θ6 = `theta`): the diagnosis fits the effect with them
    /// held at their null first, then frees them from that fit — from the null and from the
    /// start — and keeps the cheaper refit where it costs less. Default: none.
    fn secondary(&self, _theta: &[f64]) -> Vec<(usize, f64)> {
        Vec::new()
    }
    /// Its parameters held (at their values in hand) while the effects named `others` are in
    /// the model beside it: one physical quantity two effects both carry, which the data
    /// cannot give to both (the wheels' mix κ of a dead band beside a clamp's). Default: none.
    fn held_beside(&self, _others: &[&str]) -> Vec<usize> {
        Vec::new()
    }
    /// Its parameters that, where a fit runs them out of their plausible range
    /// ([`Effect::plausible`]), are held at their null and the effect fitted again from its
    /// start, in place of refusing it: a split that the data pin down alone but not beside an
    /// effect they have not fitted yet (the clamp's wheel mix κ beside a dead band, which the
    /// fit ran to 0.05 ± 1.0). Default: none.
    fn held_when_implausible(&self) -> Vec<usize> {
        Vec::new()
    }
    /// What a sensor other than the encoders measures of it on `recordings` (wheel track
    /// `track` \[m\] if known), where it does: an independent heading measures a larger
    /// tyre's ratio by kinematics ([`Recording::independent_heading`]). The diagnosis then
    /// names it whatever the dynamics show — in the final model in place of the effects of
    /// its [`Effect::quantity`], its parameters within [`Measurement::bounds`] — and searches
    /// those effects beside it (a weak amplifier beside the tyre). Default: `None`, the
    /// encoders alone see it.
    fn measured(&self, _recordings: &[Recording], _track: Option<f64>) -> Option<Measurement> {
        None
    }
    /// The quantity the encoders see it move, where other effects move the same one (`None`:
    /// its own). Effects of one quantity are alternatives the encoders cannot tell apart (a
    /// weak amplifier, a larger tyre and a setpoint ratio all make one wheel act weaker): the
    /// diagnosis names at most one of them, and does not search the others once one is in the
    /// model.
    fn quantity(&self) -> Option<&'static str> {
        None
    }
    /// The force it adds at state (v [m/s], ω [rad/s]) with parameters `p` on a robot of wheel
    /// track `track` \[m\] (independent of θ); the default adds none.
    fn force(&self, _p: &[f64], _v: f64, _w: f64, _track: f64) -> Force {
        Force::default()
    }
}
