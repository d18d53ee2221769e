//! Evaluation harness (issue 15): how well `wheelid diagnose` names the physics that the
//! independent rigid-body backend (`wheelid_robots::physics`, rapier3d) adds — physics the
//! candidates did not write. This is the measuring instrument, not the method: it changes
//! nothing in the diagnosis, it only runs it and counts.
//!
//! For each (profile, timing convention, case, seed) it
//! 1. draws the effect magnitudes from the seed ([`draw_effects`], ranges documented there,
//!    each effect from its own stream, so a pair carries the same magnitudes as its singles),
//! 2. simulates a random multisine ([`excitation`]) with `simulate_physics_recording`
//!    (encoders on, no wheel noise, jitter as given),
//! 3. runs `wheelid::diagnose::diagnose` with the model the profile's controller implies
//!    (`PhysicalProfile::model_name`) and the default settings (the track set to the d the host
//!    converts with),
//! 4. scores the named effects against the truth through [`TRUTH`], and the magnitudes where
//!    they are comparable ([`magnitudes`]).
//!
//! It prints a markdown report ([`report`]): confusion matrices, the share of runs exactly
//! right overall / per profile / per convention, the false-alarm rate on clean runs with a
//! 95 % Clopper–Pearson interval, magnitude errors, fits and times; `--json FILE` writes one
//! JSON record per run ([`Record`]); with `DIAGNOSE_PHYSICS_REPORTS` set in the environment
//! every run's text report goes to stderr.
//!
//! Run through `scripts/diagnose_physics.sh` (seed split in its header), e.g.
//! `scripts/diagnose_physics.sh --seeds 1..20 --cases all --threads 2`.
//! The smoke test `tests/diagnose_physics_smoke.rs` includes this file as a module.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::fmt::Write as _;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use clap::Parser;
use serde::Serialize;
use statrs::distribution::{Beta, ContinuousCDF};
use wheelid::core::{Recording, Timing};
use wheelid::diagnose::{DiagnoseSettings, diagnose};
use wheelid::robots::Excitation;
use wheelid::robots::physics::{
    Controller, Payload, PhysicalProfile, PhysicsEffects, PhysicsSettings, RateLimit,
    simulate_physics_recording,
};

/// THE table: for each physics effect (`PhysicsEffects::active` names), the diagnosis
/// candidate names that count as naming it right. Today's candidates
/// (`wheelid_models::Candidate::names`) are listed beside the actuator-level names planned
/// for later, so the table holds for both.
///
/// A voltage clamp is named right only as `effort_clamp` (each wheel's effort clamped; until
/// that candidate existed an `acceleration_limit` was accepted as its stand-in); a sagging or
/// decaying battery scales the drive's gain over the run (`gain_drift`, the loop's effort
/// scaled); one weak amplifier scales its wheel's whole effort (`amp_asymmetry`; the setpoint
/// ratio `wheel_asymmetry` was its stand-in before); one larger tyre makes the wheels unequal
/// (`wheel_asymmetry`), and from encoder data alone it cannot be told from a weak amplifier:
/// the loop holds the wheel's rate whatever its radius, and the larger tyre shows only as that
/// wheel's share of the chassis inertia growing, i.e. its effort acting weaker in transients
/// (`amp_asymmetry` is accepted for it; the pose would tell them apart, the encoders do not); dry friction in the wheel joints is a
/// Coulomb term (`coulomb_friction`); on a slippery floor the wheels run ahead of the body at
/// high demand (`traction_limit`; the older setpoint-level `slip` is still accepted).
pub const TRUTH: [(&str, &[&str]); 10] = [
    ("latency", &["input_delay", "latency"]),
    ("rate_limit", &["acceleration_limit"]),
    ("voltage_clamp", &["effort_clamp"]),
    ("gain_sag", &["gain_sag", "gain_drift"]),
    ("gain_decay", &["gain_sag", "gain_drift"]),
    ("amp_gain_right", &["amp_asymmetry"]),
    (
        "tyre_radius_right",
        &["tyre_asymmetry", "wheel_asymmetry", "amp_asymmetry"],
    ),
    ("dry_friction", &["wheel_friction", "coulomb_friction"]),
    ("floor_mu", &["traction_limit", "slip"]),
    ("payload", &["payload_change"]),
];

/// The physics effects, in [`TRUTH`] order.
pub fn effect_names() -> Vec<&'static str> {
    TRUTH.iter().map(|(e, _)| *e).collect()
}

/// The candidate names that count as naming physics effect `effect` right.
pub fn acceptable(effect: &str) -> &'static [&'static str] {
    TRUTH
        .iter()
        .find(|(e, _)| *e == effect)
        .map_or(&[], |(_, names)| names)
}

/// Exactly right: the named candidates and the true effects pair off one to one, each pair
/// acceptable by [`TRUTH`] (nothing named for a clean run). A candidate that stands for two
/// true effects does not count twice.
pub fn exactly_right(truth: &[&str], named: &[String]) -> bool {
    fn assign(truth: &[&str], named: &[String], used: &mut Vec<bool>) -> bool {
        let Some((first, rest)) = truth.split_first() else {
            return true;
        };
        for j in 0..named.len() {
            if !used[j] && acceptable(first).contains(&named[j].as_str()) {
                used[j] = true;
                if assign(rest, named, used) {
                    return true;
                }
                used[j] = false;
            }
        }
        false
    }
    truth.len() == named.len() && assign(truth, named, &mut vec![false; named.len()])
}

/// One run: a profile under one timing convention with a set of effects and a seed.
#[derive(Debug, Clone, PartialEq)]
pub struct RunSpec {
    /// Built-in physical profile (`khepera3`, `pioneer3dx`).
    pub profile: String,
    /// How the host stamps its rows.
    pub timing: Timing,
    /// The physics effects on ([`TRUTH`] names, table order); empty: a clean run.
    pub effects: Vec<&'static str>,
    /// Seed of the excitation, the magnitudes and the simulation.
    pub seed: u64,
    /// Duration \[s\].
    pub duration_s: f64,
    /// Host timing jitter (fraction of the period).
    pub jitter: f64,
    /// Diagnosis candidates by name (`None`: every registered one).
    pub candidates: Option<Vec<String>>,
    /// Directory of simulated recordings to reuse (`None`: always simulate).
    pub cache: Option<PathBuf>,
}

impl RunSpec {
    /// `clean`, `latency`, or `latency+payload`.
    pub fn case(&self) -> String {
        if self.effects.is_empty() {
            "clean".into()
        } else {
            self.effects.join("+")
        }
    }

    /// `clean`, `single` or `pair`.
    pub fn kind(&self) -> &'static str {
        match self.effects.len() {
            0 => "clean",
            1 => "single",
            _ => "pair",
        }
    }
}

/// The default duration for a profile: 60 s for the Khepera-like robot (3000 samples at
/// 50 Hz), 120 s otherwise (1200 samples at 10 Hz for the Pioneer-like robot).
pub fn default_duration(profile: &str) -> f64 {
    if profile == "khepera3" { 60.0 } else { 120.0 }
}

/// A comparison of an estimated magnitude with the truth.
#[derive(Debug, Clone, Serialize)]
pub struct Magnitude {
    /// The physics effect.
    pub effect: String,
    /// What is compared (`latency_s vs delay_s`), or `n/a`.
    pub quantity: String,
    /// The true value (as the candidate would see it).
    pub truth: Option<f64>,
    /// The estimate, when a matching candidate was named.
    pub estimate: Option<f64>,
    /// Relative error (estimate − truth)/truth; for ratios, of the deviation from 1.
    pub rel_error: Option<f64>,
}

/// Validation fit % of both channels.
#[derive(Debug, Clone, Copy, Serialize, Default)]
pub struct Fits {
    /// Forward velocity [%].
    pub v: f64,
    /// Angular velocity [%].
    pub w: f64,
}

/// What one run gave.
#[derive(Debug, Clone, Serialize)]
pub struct Record {
    /// Profile.
    pub profile: String,
    /// Timing convention.
    pub timing: String,
    /// `clean`, `single`, `pair`.
    pub kind: String,
    /// `clean`, `latency`, `latency+payload`.
    pub case: String,
    /// Seed.
    pub seed: u64,
    /// Duration \[s\].
    pub duration_s: f64,
    /// Jitter.
    pub jitter: f64,
    /// The true physics effects.
    pub truth: Vec<String>,
    /// Their settings and how strongly they were predicted to act (per effect).
    pub truth_params: BTreeMap<String, BTreeMap<String, f64>>,
    /// The candidates the diagnosis named (findings, in order).
    pub named: Vec<String>,
    /// Their fitted parameters.
    pub named_params: BTreeMap<String, BTreeMap<String, f64>>,
    /// Their standard errors (a change time: the half width of its interval).
    pub named_std_err: BTreeMap<String, BTreeMap<String, f64>>,
    /// Whether a mismatch was declared.
    pub mismatch: bool,
    /// Channels of the unexplained structure, if any.
    pub unexplained: Option<Vec<String>>,
    /// Named set equals the truth through [`TRUTH`] ([`exactly_right`]); a clean run also
    /// needs nothing unexplained.
    pub exactly_right: bool,
    /// Nominal model's validation fit.
    pub fit_nominal: Fits,
    /// Final model's validation fit.
    pub fit_final: Fits,
    /// Magnitude comparisons, one or more per true effect.
    pub magnitudes: Vec<Magnitude>,
    /// How visible the effects are: RMS of (this run − the clean run of the same profile,
    /// convention and seed) over the clean run's RMS about its mean, per channel [%] (0 for a
    /// clean run).
    pub visibility: Fits,
    /// Largest speed of the chassis from the pose columns [m/s].
    pub pose_speed_max: f64,
    /// Largest |v| the encoders report [m/s].
    pub encoder_speed_max: f64,
    /// The chassis moved far faster than its wheels ever turned (pose speed > 1.5 × the
    /// encoders' largest |v| + 5 % of v_max): the backend did not realise the effect physically.
    pub unphysical: bool,
    /// Pairs only: each effect's marginal visibility — RMS of (this run − the run with the
    /// other effect alone) over that run's RMS about its mean, per channel [%].
    pub marginal_visibility: BTreeMap<String, Fits>,
    /// Pairs only: the effects whose marginal visibility is below [`MASKED_PERCENT`] on both
    /// channels — the other effect keeps them from acting, so the recording is a single-effect
    /// one and no diagnosis can name both. Such runs are still counted in every figure and
    /// also reported apart.
    pub masked: Vec<String>,
    /// Simulation wall time \[s\].
    pub simulate_s: f64,
    /// Diagnosis wall time \[s\].
    pub diagnose_s: f64,
    /// The error, if the run failed (then nothing else is meaningful).
    pub error: Option<String>,
}

/// splitmix64: a small, well-mixed generator (the root package has no `rand`).
pub fn splitmix64(mut x: u64) -> u64 {
    x = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = x;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A uniform number in [0, 1) for (seed, stream, draw): stream = the effect's index in
/// [`TRUTH`], so each effect's magnitude depends on the seed only, not on the case.
pub fn uniform(seed: u64, stream: u64, draw: u64) -> f64 {
    let h = splitmix64(splitmix64(splitmix64(seed) ^ stream.wrapping_mul(0x100_0001)) ^ draw);
    (h >> 11) as f64 / (1u64 << 53) as f64
}

/// The excitation of a run: the physics excitation rule, [`PhysicalProfile::random_multisine`]
/// seeded by the seed.
///
/// # Errors
/// Invalid multisine settings.
pub fn excitation(p: &PhysicalProfile, seed: u64) -> Result<Excitation> {
    Ok(p.random_multisine(seed)?)
}

/// What the excitation demands of the clean robot, per host period, estimated from the map's
/// θ (v and ω follow their commands through first-order lags θ1/θ4, θ2/θ6 under the
/// zero-order-held commands) and the rigid body: wheel forces F_r,l = m v̇/2 ± I ω̇/d
/// (I = I_z + m b² about the axle centre), torques r F + I_e ω̇_i + B_e ω_i, voltages
/// k_b ω_i + R_a τ_i/k_a, friction coefficients |(F_i, m v ω/2)| / (m g (1 − b/x_c)/2). The
/// peaks are at the start of each period (the largest acceleration after a command step).
#[derive(Debug, Clone)]
pub struct Demand {
    /// |Δv_ref|/Δ per period [m/s²].
    pub slope_v: Vec<f64>,
    /// |Δω_ref|/Δ per period [rad/s²].
    pub slope_w: Vec<f64>,
    /// Peak |voltage| over both wheels per period \[V\].
    pub volts: Vec<f64>,
    /// Peak friction coefficient needed over both wheels per period [-].
    pub mu: Vec<f64>,
}

/// [`Demand`] of excitation `exc` on `p` over `duration` seconds.
pub fn demand(p: &PhysicalProfile, exc: &Excitation, duration: f64) -> Demand {
    let th = p.theta();
    let dt = p.period_s;
    let (tau_v, tau_w) = (th[0] / th[3], th[1] / th[5]);
    let i_ax = p.i_z + p.m * p.b * p.b;
    let n_wheels = p.m * 9.81 * (1.0 - p.b / p.caster_x) / 2.0;
    let n = (duration / dt).floor() as usize;
    let (mut v, mut w) = (0.0, 0.0);
    let mut prev = exc.at(0.0);
    let mut out = Demand {
        slope_v: Vec::with_capacity(n),
        slope_w: Vec::with_capacity(n),
        volts: Vec::with_capacity(n),
        mu: Vec::with_capacity(n),
    };
    for k in 0..n {
        let (vr, wr) = exc.at(k as f64 * dt);
        out.slope_v.push((vr - prev.0).abs() / dt);
        out.slope_w.push((wr - prev.1).abs() / dt);
        prev = (vr, wr);
        let (v_ss, w_ss) = (vr / th[3], wr / th[5]);
        let (dv, dw) = ((v_ss - v) / tau_v, (w_ss - w) / tau_w);
        let (mut volts, mut mu) = (0.0f64, 0.0f64);
        for s in [1.0, -1.0] {
            let rate = (v + s * p.d * w / 2.0) / p.r;
            let acc = (dv + s * p.d * dw / 2.0) / p.r;
            let force = p.m * dv / 2.0 + s * i_ax * dw / p.d;
            let torque = p.r * force + p.i_e * acc + p.b_e * rate;
            volts = volts.max((p.k_b * rate + p.r_a * torque / p.k_a).abs());
            mu = mu.max(force.hypot(p.m * v * w / 2.0) / n_wheels);
        }
        out.volts.push(volts);
        out.mu.push(mu);
        v = v_ss + (v - v_ss) * (-dt / tau_v).exp();
        w = w_ss + (w - w_ss) * (-dt / tau_w).exp();
    }
    out
}

/// The q-quantile of `x` (nearest rank).
pub fn quantile(x: &[f64], q: f64) -> f64 {
    let mut s: Vec<f64> = x.iter().copied().filter(|v| v.is_finite()).collect();
    if s.is_empty() {
        return f64::NAN;
    }
    s.sort_by(f64::total_cmp);
    let i = ((q * (s.len() - 1) as f64).round() as usize).min(s.len() - 1);
    s[i]
}

/// Share of `x` above `level`.
fn share_above(x: &[f64], level: f64) -> f64 {
    x.iter().filter(|&&v| v > level).count() as f64 / x.len().max(1) as f64
}

/// Steady losses of speed per N·m of dry friction in each wheel joint, from the drive's torque
/// balance (rigid body, no load): (Δv [m/s] driving straight, Δω [rad/s] turning on the spot).
/// Wheel-PD: Δω_i = R_a F/(k_a (k_P + k_b) + R_a B_e) per wheel; v/ω-PD: Δv = R_a F/(k_a K_PT +
/// (k_a k_b + R_a B_e)/r), Δω = R_a F/(k_a K_PR + (k_a k_b + R_a B_e) d/(2r)).
pub fn friction_loss_per_nm(p: &PhysicalProfile) -> (f64, f64) {
    let back = p.k_a * p.k_b + p.r_a * p.b_e;
    match p.controller {
        Controller::WheelPd { k_p, .. } => {
            let dw_wheel = p.r_a / (p.k_a * k_p + back);
            (p.r * dw_wheel, 2.0 * p.r * dw_wheel / p.d)
        }
        Controller::VwPd { k_pt, k_pr, .. } => (
            p.r_a / (p.k_a * k_pt + back / p.r),
            p.r_a / (p.k_a * k_pr + back * p.d / (2.0 * p.r)),
        ),
    }
}

/// The effects of `spec` with magnitudes drawn from its seed, and per effect its settings and
/// predicted strength (for the records). Ranges (u: a uniform draw of the effect's stream):
///
/// | effect | magnitude |
/// | --- | --- |
/// | latency | (0.5 + 2.5u) host periods |
/// | rate_limit | (0.2 + 0.3u) × the 95th percentile of the command's slope \|Δu\|/Δ, v and ω alike |
/// | voltage_clamp | the (0.80 + 0.15u)-quantile of the per-period peak voltage ([`Demand`]): binds in ~5–20 % of the periods |
/// | gain_sag | fraction 0.1 + 0.2u lost by the run's end |
/// | gain_decay | τ such that 0.1 + 0.2u is lost by the run's end |
/// | amp_gain_right | 0.90 + 0.05u or 1.05 + 0.05u (even/odd second draw) |
/// | tyre_radius_right | 1.02 + 0.03u |
/// | dry_friction_nm | the torque whose steady loss driving straight is (3 + 7u) % of v_amp = 0.3 v_max ([`friction_loss_per_nm`]) |
/// | floor_mu | (0.4 + 0.2u) × the 95th percentile of the per-period peak friction coefficient needed ([`Demand`]; the estimate runs high: the Khepera-like robot slips on ~5–20 % of the rows) |
/// | payload | (0.3 + 0.7u) m, set down at (30 + 40u) % of the run, (0.25 + 0.5u) x_caster ahead of the axle, a cube of side d/3 |
///
/// # Errors
/// An unknown effect name.
#[allow(clippy::type_complexity)]
pub fn draw_effects(
    p: &PhysicalProfile,
    exc: &Excitation,
    spec: &RunSpec,
) -> Result<(PhysicsEffects, BTreeMap<String, BTreeMap<String, f64>>)> {
    let mut fx = PhysicsEffects::default();
    let mut params = BTreeMap::new();
    let need_demand = spec
        .effects
        .iter()
        .any(|e| matches!(*e, "rate_limit" | "voltage_clamp" | "floor_mu"));
    let dem = need_demand.then(|| demand(p, exc, spec.duration_s));
    let dem = dem.as_ref();
    for &name in &spec.effects {
        let stream = TRUTH
            .iter()
            .position(|(e, _)| *e == name)
            .with_context(|| format!("unknown physics effect {name}"))? as u64;
        let u = |k| uniform(spec.seed, stream, k);
        let mut m = BTreeMap::new();
        match (name, dem) {
            ("latency", _) => {
                let periods = 0.5 + 2.5 * u(0);
                fx.latency_s = Some(periods * p.period_s);
                m.insert("latency_s".into(), periods * p.period_s);
                m.insert("periods".into(), periods);
            }
            ("rate_limit", Some(d)) => {
                let frac = 0.2 + 0.3 * u(0);
                let (sv, sw) = (quantile(&d.slope_v, 0.95), quantile(&d.slope_w, 0.95));
                let (a_v, a_w) = (frac * sv, frac * sw);
                fx.rate_limit = Some(RateLimit {
                    v_accel: a_v,
                    w_accel: a_w,
                });
                m.insert("v_accel".into(), a_v);
                m.insert("w_accel".into(), a_w);
                m.insert("fraction_of_p95_slope".into(), frac);
                m.insert("binds_share_v".into(), share_above(&d.slope_v, a_v));
                m.insert("binds_share_w".into(), share_above(&d.slope_w, a_w));
            }
            ("voltage_clamp", Some(d)) => {
                let q = 0.80 + 0.15 * u(0);
                let volts = quantile(&d.volts, q);
                fx.voltage_clamp = Some(volts);
                m.insert("volts".into(), volts);
                // In the effort_clamp's units (its module docs): V r/k_P, V/K_PT.
                let effort = match p.controller {
                    Controller::WheelPd { k_p, .. } => volts * p.r / k_p,
                    Controller::VwPd { k_pt, .. } => volts / k_pt,
                };
                m.insert("effort_max".into(), effort);
                m.insert("quantile".into(), q);
                m.insert("binds_share".into(), share_above(&d.volts, volts));
            }
            ("gain_sag", _) => {
                let f = 0.1 + 0.2 * u(0);
                fx.gain_sag = Some(f);
                m.insert("fraction".into(), f);
                m.insert("rate_per_s".into(), -f / spec.duration_s);
            }
            ("gain_decay", _) => {
                let f = 0.1 + 0.2 * u(0);
                let tau = spec.duration_s / -(1.0 - f).ln();
                fx.gain_decay_tau_s = Some(tau);
                m.insert("tau_s".into(), tau);
                m.insert("fraction_lost".into(), f);
                // The mean rate over the run (a straight line through e^(−t/τ)'s ends).
                m.insert("rate_per_s".into(), -f / spec.duration_s);
            }
            ("amp_gain_right", _) => {
                let g = if u(1) < 0.5 {
                    0.90 + 0.05 * u(0)
                } else {
                    1.05 + 0.05 * u(0)
                };
                fx.amp_gain_right = Some(g);
                m.insert("gain".into(), g);
            }
            ("tyre_radius_right", _) => {
                let f = 1.02 + 0.03 * u(0);
                fx.tyre_radius_right = Some(f);
                m.insert("factor".into(), f);
            }
            ("dry_friction", _) => {
                let share = 0.03 + 0.07 * u(0);
                let (dv, dw) = friction_loss_per_nm(p);
                let f = share * 0.3 * p.v_max / dv;
                fx.dry_friction_nm = Some(f);
                m.insert("torque_nm".into(), f);
                m.insert("loss_share_of_v_amp".into(), share);
                m.insert("steady_loss_v".into(), f * dv);
                m.insert("steady_loss_w".into(), f * dw);
            }
            ("floor_mu", Some(d)) => {
                let frac = 0.4 + 0.2 * u(0);
                let mu = frac * quantile(&d.mu, 0.95);
                fx.floor_mu = Some(mu);
                m.insert("mu".into(), mu);
                m.insert("fraction_of_p95_demand".into(), frac);
                m.insert("slips_share".into(), share_above(&d.mu, mu));
            }
            ("payload", _) => {
                let pl = Payload {
                    mass_kg: (0.3 + 0.7 * u(0)) * p.m,
                    at_s: (0.3 + 0.4 * u(1)) * spec.duration_s,
                    x_m: (0.25 + 0.5 * u(2)) * p.caster_x,
                    size_m: p.d / 3.0,
                };
                fx.payload = Some(pl);
                m.insert("mass_kg".into(), pl.mass_kg);
                m.insert("at_s".into(), pl.at_s);
                m.insert("x_m".into(), pl.x_m);
                m.insert("size_m".into(), pl.size_m);
                m.insert("theta1_loaded_map".into(), pl.loaded(p).theta()[0]);
            }
            _ => bail!("unknown physics effect {name}"),
        }
        params.insert(name.to_string(), m);
    }
    Ok((fx, params))
}

/// Magnitude comparisons for every true effect of a run: latency vs `delay_s`; rate limits vs
/// `v_accel_max`, `w_accel_max` (a channel held at its null, ≥ 10⁵, is skipped); the right
/// amplifier's gain or tyre factor vs `ratio` (error of the deviation from 1); dry friction vs
/// `v_coulomb`, `w_coulomb` and `wheel_friction`'s `c_wheel` (the map's θ4, θ6 × the
/// closed-form steady loss, [`friction_loss_per_nm`]; `coulomb_friction` acts on v and ω, not
/// per wheel, so its values are a looser match); payload time vs `time_s` and the loaded map's θ1 vs
/// `theta1_after`; a slippery floor's μ g (1 − b/x_c) (the driven wheels' share of the weight)
/// vs `accel_max`. Everything else is `n/a`.
pub fn magnitudes(
    p: &PhysicalProfile,
    truth: &BTreeMap<String, BTreeMap<String, f64>>,
    named: &BTreeMap<String, BTreeMap<String, f64>>,
) -> Vec<Magnitude> {
    let th = p.theta();
    let mut out = Vec::new();
    for (effect, t) in truth {
        let est = |param: &str| {
            acceptable(effect)
                .iter()
                .find_map(|c| named.get(*c).and_then(|m| m.get(param)).copied())
        };
        let mut push = |quantity: &str, truth: f64, estimate: Option<f64>, ratio: bool| {
            let estimate = estimate.filter(|x| x.is_finite() && x.abs() < 1e5);
            let rel_error = estimate.map(|e| {
                if ratio {
                    ((e - 1.0) - (truth - 1.0)) / (truth - 1.0)
                } else {
                    (e - truth) / truth
                }
            });
            out.push(Magnitude {
                effect: effect.clone(),
                quantity: quantity.into(),
                truth: Some(truth),
                estimate,
                rel_error,
            });
        };
        let g = |k: &str| t.get(k).copied().unwrap_or(f64::NAN);
        match effect.as_str() {
            "latency" => push(
                "latency_s vs delay_s",
                g("latency_s"),
                est("delay_s"),
                false,
            ),
            "rate_limit" => {
                push(
                    "v_accel vs v_accel_max",
                    g("v_accel"),
                    est("v_accel_max"),
                    false,
                );
                push(
                    "w_accel vs w_accel_max",
                    g("w_accel"),
                    est("w_accel_max"),
                    false,
                );
            }
            "gain_sag" | "gain_decay" => {
                push(
                    "−fraction/T vs rate_per_s",
                    g("rate_per_s"),
                    est("rate_per_s"),
                    false,
                );
            }
            "voltage_clamp" => {
                push(
                    "V r/k_P (V/K_PT) vs effort_max",
                    g("effort_max"),
                    est("effort_max"),
                    false,
                );
            }
            "amp_gain_right" => push(
                "gain vs right_gain (−1)",
                g("gain"),
                est("right_gain"),
                true,
            ),
            "tyre_radius_right" => {
                push(
                    "factor vs right_radius (−1)",
                    g("factor"),
                    est("right_radius"),
                    true,
                );
                push("factor vs ratio (−1)", g("factor"), est("ratio"), true);
            }
            "dry_friction" => {
                push(
                    "θ4·Δv vs v_coulomb",
                    th[3] * g("steady_loss_v"),
                    est("v_coulomb"),
                    false,
                );
                push(
                    "θ6·Δω vs w_coulomb",
                    th[5] * g("steady_loss_w"),
                    est("w_coulomb"),
                    false,
                );
                push(
                    "θ4·Δv vs c_wheel",
                    th[3] * g("steady_loss_v"),
                    est("c_wheel"),
                    false,
                );
            }
            // The driven wheels carry the weight less the caster's share b/x_c (statics of
            // the chassis on its three contacts): the floor passes at most μ g (1 − b/x_c).
            "floor_mu" => push(
                "μ g (1 − b/x_c) vs accel_max",
                g("mu") * 9.81 * (1.0 - p.b / p.caster_x),
                est("accel_max"),
                false,
            ),
            "payload" => {
                push("at_s vs time_s", g("at_s"), est("time_s"), false);
                push(
                    "loaded θ1 vs theta1_after",
                    g("theta1_loaded_map"),
                    est("theta1_after"),
                    false,
                );
            }
            _ => out.push(Magnitude {
                effect: effect.clone(),
                quantity: "n/a".into(),
                truth: None,
                estimate: None,
                rel_error: None,
            }),
        }
    }
    out
}

/// The twins' (v, ω) by (profile, convention, seed, duration, jitter, effects): the clean run
/// and, for pairs, each single-effect run, simulated once per batch and shared by its runs to
/// measure how visible each effect is.
pub type CleanRuns =
    Mutex<HashMap<(String, &'static str, u64, u64, u64, String), Arc<[Vec<f64>; 2]>>>;

/// The twin of `spec` with only the physics effects `effects` on (none: the clean run; same
/// profile, convention, seed, duration, jitter, and the same magnitudes, drawn per effect),
/// simulated once per batch.
fn twin(
    p: &PhysicalProfile,
    exc: &Excitation,
    spec: &RunSpec,
    effects: &[&'static str],
    cache: &CleanRuns,
) -> Result<Arc<[Vec<f64>; 2]>> {
    let key = (
        spec.profile.clone(),
        spec.timing.name(),
        spec.seed,
        spec.duration_s.to_bits(),
        spec.jitter.to_bits(),
        effects.join("+"),
    );
    if let Some(x) = cache.lock().ok().and_then(|c| c.get(&key).cloned()) {
        return Ok(x);
    }
    let other = RunSpec {
        effects: effects.to_vec(),
        ..spec.clone()
    };
    let (fx, _) = draw_effects(p, exc, &other)?;
    let rec = recording(p, exc, &other, fx)?;
    let x = Arc::new([rec.v, rec.w]);
    if let Ok(mut c) = cache.lock() {
        c.insert(key, x.clone());
    }
    Ok(x)
}

/// Marginal visibility [%] below which, on both channels, an effect of a pair counts as
/// masked by the other: the recording with both differs from the one with the other alone by
/// less than this share of the signal's spread ([`visibility`]). On tuning seed 3 the masked
/// ones were 0.000 % (a rate limit keeps the clamp and the floor from ever binding) and
/// 0.17/0.37 % (the Pioneer-like robot's floor keeps its clamp from binding); the least
/// visible single effects named right there were 1.2/3.9 % (a weak amplifier).
pub const MASKED_PERCENT: f64 = 0.5;

/// The recording of `spec` with `effects`: read from `spec.cache` when it holds it, else
/// simulated (and written there). CSV keeps every f64 exactly (shortest round-trip digits), so a
/// cached run diagnoses as the simulated one does.
fn recording(
    p: &PhysicalProfile,
    exc: &Excitation,
    spec: &RunSpec,
    effects: PhysicsEffects,
) -> Result<Recording> {
    let path = spec.cache.as_ref().map(|dir| {
        dir.join(format!(
            "{}_{}_{}_{}_{}s_j{}.csv",
            spec.profile,
            spec.timing.name(),
            spec.case(),
            spec.seed,
            spec.duration_s,
            spec.jitter
        ))
    });
    if let Some(path) = path.as_ref().filter(|p| p.exists()) {
        return Recording::read_csv(path).with_context(|| format!("cached {}", path.display()));
    }
    let rec = simulate_physics_recording(p, exc, &settings(spec, effects))?;
    if let Some(path) = &path {
        std::fs::create_dir_all(path.parent().unwrap_or(Path::new(".")))?;
        rec.write_csv(path)?;
    }
    Ok(rec)
}

/// The physics settings of `spec` with `effects`: encoders on, no wheel noise.
fn settings(spec: &RunSpec, effects: PhysicsEffects) -> PhysicsSettings {
    PhysicsSettings {
        duration_s: spec.duration_s,
        seed: spec.seed,
        timing: spec.timing,
        jitter: spec.jitter,
        encoders: true,
        wheel_noise_std: 0.0,
        effects,
    }
}

/// RMS of x − y over the RMS of y about its mean [%].
fn visibility(x: &[f64], y: &[f64]) -> f64 {
    let n = x.len().min(y.len()).max(1) as f64;
    let mean = y.iter().sum::<f64>() / y.len().max(1) as f64;
    let diff = x.iter().zip(y).map(|(a, b)| (a - b).powi(2)).sum::<f64>() / n;
    let spread = y.iter().map(|b| (b - mean).powi(2)).sum::<f64>() / y.len().max(1) as f64;
    100.0 * (diff / spread).sqrt()
}

/// Runs one case: draw, simulate, diagnose, score. Failures are recorded, never raised.
/// `cache` holds the clean twins (a fresh one will do).
pub fn run_one(spec: &RunSpec, cache: &CleanRuns) -> Record {
    let mut rec = Record {
        profile: spec.profile.clone(),
        timing: spec.timing.name().into(),
        kind: spec.kind().into(),
        case: spec.case(),
        seed: spec.seed,
        duration_s: spec.duration_s,
        jitter: spec.jitter,
        truth: spec.effects.iter().map(|e| e.to_string()).collect(),
        truth_params: BTreeMap::new(),
        named: Vec::new(),
        named_params: BTreeMap::new(),
        named_std_err: BTreeMap::new(),
        mismatch: false,
        unexplained: None,
        exactly_right: false,
        fit_nominal: Fits::default(),
        fit_final: Fits::default(),
        magnitudes: Vec::new(),
        visibility: Fits::default(),
        pose_speed_max: f64::NAN,
        encoder_speed_max: f64::NAN,
        unphysical: false,
        marginal_visibility: BTreeMap::new(),
        masked: Vec::new(),
        simulate_s: 0.0,
        diagnose_s: 0.0,
        error: None,
    };
    if let Err(e) = run_into(spec, cache, &mut rec) {
        rec.error = Some(format!("{e:#}"));
    }
    rec
}

fn run_into(spec: &RunSpec, cache: &CleanRuns, rec: &mut Record) -> Result<()> {
    let p = PhysicalProfile::by_name(&spec.profile)
        .with_context(|| format!("unknown physical profile {}", spec.profile))?;
    let exc = excitation(&p, spec.seed)?;
    let (effects, truth_params) = draw_effects(&p, &exc, spec)?;
    rec.truth_params = truth_params;
    let clock = Instant::now();
    let recording = recording(&p, &exc, spec, effects)?;
    rec.simulate_s = clock.elapsed().as_secs_f64();
    if !spec.effects.is_empty() {
        let clean = twin(&p, &exc, spec, &[], cache)?;
        rec.visibility = Fits {
            v: visibility(&recording.v, &clean[0]),
            w: visibility(&recording.w, &clean[1]),
        };
    }
    if let [a, b] = spec.effects[..] {
        for (effect, other) in [(a, b), (b, a)] {
            let alone = twin(&p, &exc, spec, &[other], cache)?;
            let marginal = Fits {
                v: visibility(&recording.v, &alone[0]),
                w: visibility(&recording.w, &alone[1]),
            };
            if marginal.v < MASKED_PERCENT && marginal.w < MASKED_PERCENT {
                rec.masked.push(effect.to_string());
            }
            rec.marginal_visibility.insert(effect.to_string(), marginal);
        }
    }
    if let (Some(x), Some(y)) = (&recording.x, &recording.y) {
        rec.pose_speed_max = (1..x.len())
            .map(|k| {
                (x[k] - x[k - 1]).hypot(y[k] - y[k - 1]) / (recording.t[k] - recording.t[k - 1])
            })
            .fold(0.0, f64::max);
    }
    rec.encoder_speed_max = recording.v.iter().fold(0.0, |m, v| m.max(v.abs()));
    rec.unphysical = rec.pose_speed_max > 1.5 * rec.encoder_speed_max + 0.05 * p.v_max;
    let model = wheelid::models::by_name(p.model_name())
        .with_context(|| format!("no model {}", p.model_name()))?;
    // Default settings; the track is the d the host converted ω with (the metadata's `robot`
    // would look up the simulator's profile of the same name, whose track may differ).
    let mut ds = DiagnoseSettings {
        track_m: Some(p.d),
        ..DiagnoseSettings::default()
    };
    if let Some(names) = &spec.candidates {
        ds.candidates = names
            .iter()
            .map(|n| {
                wheelid::models::Candidate::by_name(n)
                    .with_context(|| format!("--candidates {n}: unknown"))
            })
            .collect::<Result<_>>()?;
    }
    let clock = Instant::now();
    let d = diagnose(&[recording], model.as_ref(), &ds)?;
    rec.diagnose_s = clock.elapsed().as_secs_f64();
    // For looking at a case: the full text report on stderr.
    if std::env::var_os("DIAGNOSE_PHYSICS_REPORTS").is_some() {
        eprintln!(
            "=== {} {} {:?} seed {}\n{}",
            spec.profile,
            spec.timing.name(),
            spec.effects,
            spec.seed,
            wheelid::report::diagnosis_text(&d)
        );
    }
    rec.named = d.findings.iter().map(|f| f.effect.clone()).collect();
    rec.named_params = d
        .findings
        .iter()
        .map(|f| (f.effect.clone(), f.parameters.clone()))
        .collect();
    rec.named_std_err = d
        .findings
        .iter()
        .map(|f| (f.effect.clone(), f.std_err.clone()))
        .collect();
    rec.mismatch = d.mismatch;
    rec.unexplained = d.unexplained.as_ref().map(|u| u.channels.clone());
    rec.fit_nominal = Fits {
        v: d.nominal.channels.v.fit_percent,
        w: d.nominal.channels.w.fit_percent,
    };
    rec.fit_final = Fits {
        v: d.final_stage.channels.v.fit_percent,
        w: d.final_stage.channels.w.fit_percent,
    };
    // A clean run is right only with nothing named and nothing left unexplained.
    rec.exactly_right = exactly_right(&spec.effects, &rec.named)
        && (!spec.effects.is_empty() || rec.unexplained.is_none());
    rec.magnitudes = magnitudes(&p, &rec.truth_params, &rec.named_params);
    Ok(())
}

/// Which cases to run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Cases {
    /// Each effect alone.
    pub single: bool,
    /// Each pair of effects.
    pub pairs: bool,
    /// No effect.
    pub clean: bool,
}

impl Cases {
    /// `single`, `pairs`, `clean`, `all`, or a comma-separated list of them.
    ///
    /// # Errors
    /// An unknown word.
    pub fn parse(s: &str) -> Result<Self> {
        let mut c = Cases {
            single: false,
            pairs: false,
            clean: false,
        };
        for w in s.split(',').map(str::trim) {
            match w {
                "single" => c.single = true,
                "pairs" => c.pairs = true,
                "clean" => c.clean = true,
                "all" => (c.single, c.pairs, c.clean) = (true, true, true),
                _ => bail!("--cases {w}: expected single, pairs, clean or all"),
            }
        }
        Ok(c)
    }
}

/// The effect sets of `cases` over `effects`: clean, then singles, then pairs.
pub fn effect_sets(cases: Cases, effects: &[&'static str]) -> Vec<Vec<&'static str>> {
    let mut out = Vec::new();
    if cases.clean {
        out.push(Vec::new());
    }
    if cases.single {
        out.extend(effects.iter().map(|e| vec![*e]));
    }
    if cases.pairs {
        for i in 0..effects.len() {
            for j in i + 1..effects.len() {
                out.push(vec![effects[i], effects[j]]);
            }
        }
    }
    out
}

/// Seeds from `A..B` (both ends included, as in "seeds 1–20"), `A..=B`, `A`, or a comma list
/// of those.
///
/// # Errors
/// A malformed range.
pub fn parse_seeds(s: &str) -> Result<Vec<u64>> {
    let mut out = Vec::new();
    for part in s.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        if let Some((a, b)) = part.split_once("..") {
            let b = b.trim_start_matches('=');
            let (a, b): (u64, u64) = (a.trim().parse()?, b.trim().parse()?);
            if b < a {
                bail!("--seeds {part}: empty range");
            }
            out.extend(a..=b);
        } else {
            out.push(part.parse()?);
        }
    }
    if out.is_empty() {
        bail!("--seeds {s}: no seed");
    }
    Ok(out)
}

/// Runs `specs` on `threads` workers (each run's diagnosis has its own inner threads),
/// calling `done` as each finishes; the records come back in `specs` order.
pub fn run_all(
    specs: &[RunSpec],
    threads: usize,
    done: &(dyn Fn(usize, &Record) + Sync),
) -> Vec<Record> {
    let next = AtomicUsize::new(0);
    let cache = CleanRuns::default();
    let slots: Mutex<Vec<Option<Record>>> = Mutex::new(vec![None; specs.len()]);
    std::thread::scope(|scope| {
        for _ in 0..threads.max(1) {
            scope.spawn(|| {
                loop {
                    let i = next.fetch_add(1, Ordering::Relaxed);
                    let Some(spec) = specs.get(i) else { break };
                    let r = run_one(spec, &cache);
                    done(i, &r);
                    if let Ok(mut s) = slots.lock() {
                        s[i] = Some(r);
                    }
                }
            });
        }
    });
    slots
        .into_inner()
        .unwrap_or_else(|e| e.into_inner())
        .into_iter()
        .flatten()
        .collect()
}

/// Two-sided 95 % Clopper–Pearson interval of x successes in n trials.
pub fn clopper_pearson(x: usize, n: usize) -> (f64, f64) {
    if n == 0 {
        return (0.0, 1.0);
    }
    let (xf, nf) = (x as f64, n as f64);
    let q = |a: f64, b: f64, p: f64| Beta::new(a, b).map_or(f64::NAN, |d| d.inverse_cdf(p));
    let lo = if x == 0 {
        0.0
    } else {
        q(xf, nf - xf + 1.0, 0.025)
    };
    let hi = if x == n {
        1.0
    } else {
        q(xf + 1.0, nf - xf, 0.975)
    };
    (lo, hi)
}

fn pct(x: usize, n: usize) -> String {
    if n == 0 {
        return "—".into();
    }
    let (lo, hi) = clopper_pearson(x, n);
    format!(
        "{x}/{n} = {:.1} % [{:.1}, {:.1}]",
        100.0 * x as f64 / n as f64,
        100.0 * lo,
        100.0 * hi
    )
}

fn median(x: &mut [f64]) -> f64 {
    if x.is_empty() {
        return f64::NAN;
    }
    x.sort_by(f64::total_cmp);
    let n = x.len();
    if n % 2 == 1 {
        x[n / 2]
    } else {
        0.5 * (x[n / 2 - 1] + x[n / 2])
    }
}

/// A markdown confusion matrix of `recs` (rows: true effects incl. `clean`, a pair counting in
/// both its rows; columns: each named candidate, `nothing`, `unexplained`), with the rows' runs,
/// exactly-right counts and mean validation fits.
fn confusion(out: &mut String, recs: &[&Record], title: &str) {
    if recs.is_empty() {
        return;
    }
    let mut cols: BTreeSet<String> = wheelid::models::Candidate::names()
        .into_iter()
        .map(String::from)
        .collect();
    for r in recs {
        cols.extend(r.named.iter().cloned());
    }
    let cols: Vec<String> = cols.into_iter().collect();
    let mut rows: Vec<String> = vec!["clean".into()];
    rows.extend(effect_names().into_iter().map(String::from));
    let _ = writeln!(out, "\n### Confusion matrix — {title}\n");
    let _ = writeln!(
        out,
        "Rows: true effect (a pair counts in both its rows); columns: runs naming that candidate \
         (a run naming two counts in two columns), naming nothing, leaving something unexplained; \
         failed runs are left out.\n"
    );
    let mut head = String::from("| true \\ named | runs | right |");
    let mut rule = String::from("| --- | ---: | ---: |");
    for c in cols
        .iter()
        .map(String::as_str)
        .chain(["nothing", "unexplained"])
    {
        let _ = write!(head, " {c} |");
        rule.push_str(" ---: |");
    }
    head.push_str(" fit v nominal→final | fit ω nominal→final |");
    rule.push_str(" ---: | ---: |");
    let _ = writeln!(out, "{head}\n{rule}");
    for row in &rows {
        let in_row: Vec<&&Record> = recs
            .iter()
            .filter(|r| {
                r.error.is_none()
                    && (if row == "clean" {
                        r.truth.is_empty()
                    } else {
                        r.truth.contains(row)
                    })
            })
            .collect();
        if in_row.is_empty() {
            continue;
        }
        let n = in_row.len();
        let right = in_row.iter().filter(|r| r.exactly_right).count();
        let mut line = format!("| {row} | {n} | {right} |");
        for c in &cols {
            let k = in_row.iter().filter(|r| r.named.contains(c)).count();
            let _ = write!(
                line,
                " {} |",
                if k == 0 { ".".into() } else { k.to_string() }
            );
        }
        let nothing = in_row.iter().filter(|r| r.named.is_empty()).count();
        let unexpl = in_row.iter().filter(|r| r.unexplained.is_some()).count();
        let mean = |f: &dyn Fn(&Record) -> f64| in_row.iter().map(|r| f(r)).sum::<f64>() / n as f64;
        let _ = writeln!(
            line,
            " {nothing} | {unexpl} | {:.1}→{:.1} | {:.1}→{:.1} |",
            mean(&|r| r.fit_nominal.v),
            mean(&|r| r.fit_final.v),
            mean(&|r| r.fit_nominal.w),
            mean(&|r| r.fit_final.w)
        );
        out.push_str(&line);
    }
}

/// How each effect was realised on the single runs: its visibility against the clean twin, the
/// predicted binding share (limits, clamp, floor) and the runs the backend did not realise
/// physically.
fn realised(out: &mut String, recs: &[&Record]) {
    let singles: Vec<&&Record> = recs.iter().filter(|r| r.kind == "single").collect();
    if singles.is_empty() {
        return;
    }
    let _ = writeln!(
        out,
        "\n### Effects as realised (single runs)\n\nVisibility: RMS(run − clean run of the same \
         seed)/RMS(clean about its mean), per channel, median (min–max) [%]; predicted share: \
         where a limit, the clamp or the floor was predicted to bind (median); unphysical: the \
         chassis outran its wheels (pose speed > 1.5 × the encoders' largest |v|).\n\n\
         | effect | runs | visibility v | visibility ω | predicted share | unphysical |\n\
         | --- | ---: | ---: | ---: | ---: | ---: |"
    );
    for effect in effect_names() {
        let rs: Vec<&&&Record> = singles.iter().filter(|r| r.truth == [effect]).collect();
        if rs.is_empty() {
            continue;
        }
        let spread = |f: &dyn Fn(&Record) -> f64| {
            let mut x: Vec<f64> = rs.iter().map(|r| f(r)).collect();
            let (lo, hi) = (
                x.iter().copied().fold(f64::INFINITY, f64::min),
                x.iter().copied().fold(f64::NEG_INFINITY, f64::max),
            );
            format!("{:.2} ({lo:.2}–{hi:.2})", median(&mut x))
        };
        let mut shares: Vec<f64> = rs
            .iter()
            .filter_map(|r| {
                let m = r.truth_params.get(effect)?;
                ["binds_share", "binds_share_v", "slips_share"]
                    .iter()
                    .find_map(|k| m.get(*k).copied())
            })
            .collect();
        let share = if shares.is_empty() {
            "—".to_string()
        } else {
            format!("{:.0} %", 100.0 * median(&mut shares))
        };
        let _ = writeln!(
            out,
            "| {effect} | {} | {} | {} | {share} | {} |",
            rs.len(),
            spread(&|r| r.visibility.v),
            spread(&|r| r.visibility.w),
            rs.iter().filter(|r| r.unphysical).count()
        );
    }
}

/// The markdown report of `recs` (`wall_s`: the whole run's wall time).
pub fn report(recs: &[Record], wall_s: f64) -> String {
    let mut out = String::new();
    let ok: Vec<&Record> = recs.iter().filter(|r| r.error.is_none()).collect();
    let failed = recs.len() - ok.len();
    let count = |k: &str| recs.iter().filter(|r| r.kind == k).count();
    let _ = writeln!(out, "## Diagnosis on the rigid-body backend\n");
    let _ = writeln!(
        out,
        "{} runs ({} clean, {} single, {} pairs), {failed} failed, {} not realised physically; wall time {:.1} s; per run: \
         simulation {:.2} s, diagnosis {:.2} s on average (max {:.1} s).",
        recs.len(),
        count("clean"),
        count("single"),
        count("pair"),
        recs.iter().filter(|r| r.unphysical).count(),
        wall_s,
        ok.iter().map(|r| r.simulate_s).sum::<f64>() / ok.len().max(1) as f64,
        ok.iter().map(|r| r.diagnose_s).sum::<f64>() / ok.len().max(1) as f64,
        ok.iter()
            .map(|r| r.simulate_s + r.diagnose_s)
            .fold(0.0, f64::max)
    );
    for r in recs.iter().filter(|r| r.error.is_some()) {
        let _ = writeln!(
            out,
            "- FAILED {} {} {} seed {}: {}",
            r.profile,
            r.timing,
            r.case,
            r.seed,
            r.error.as_deref().unwrap_or("")
        );
    }
    let singles: Vec<&Record> = ok.iter().copied().filter(|r| r.kind != "pair").collect();
    let pairs: Vec<&Record> = ok.iter().copied().filter(|r| r.kind == "pair").collect();
    confusion(&mut out, &singles, "single effects and clean runs");
    confusion(&mut out, &pairs, "pairs");
    realised(&mut out, &singles);

    let _ = writeln!(
        out,
        "\n### Exactly right\n\nNamed set = true set through the table TRUTH (clean: nothing \
         named and nothing unexplained); failed runs count as wrong. 95 % Clopper–Pearson.\n"
    );
    let _ = writeln!(out, "| group | exactly right |\n| --- | --- |");
    let right = |r: &Record| r.error.is_none() && r.exactly_right;
    let mut groups: Vec<(String, Vec<&Record>)> = vec![("all".into(), recs.iter().collect())];
    for kind in ["clean", "single", "pair"] {
        groups.push((
            format!("kind {kind}"),
            recs.iter().filter(|r| r.kind == kind).collect(),
        ));
    }
    let profiles: BTreeSet<&str> = recs.iter().map(|r| r.profile.as_str()).collect();
    for p in &profiles {
        groups.push((
            format!("profile {p}"),
            recs.iter().filter(|r| r.profile == *p).collect(),
        ));
    }
    let timings: BTreeSet<&str> = recs.iter().map(|r| r.timing.as_str()).collect();
    for t in &timings {
        groups.push((
            format!("convention {t}"),
            recs.iter().filter(|r| r.timing == *t).collect(),
        ));
    }
    groups.push((
        "physically realised runs".into(),
        recs.iter().filter(|r| !r.unphysical).collect(),
    ));
    if recs.iter().any(|r| r.kind == "pair") {
        groups.push((
            format!("pairs where both effects act (marginal visibility ≥ {MASKED_PERCENT} %)"),
            recs.iter()
                .filter(|r| r.kind == "pair" && r.masked.is_empty())
                .collect(),
        ));
    }
    for (name, g) in &groups {
        if !g.is_empty() {
            let _ = writeln!(
                out,
                "| {name} | {} |",
                pct(g.iter().filter(|r| right(r)).count(), g.len())
            );
        }
    }
    let masked: Vec<&Record> = recs.iter().filter(|r| !r.masked.is_empty()).collect();
    if !masked.is_empty() {
        let _ = writeln!(
            out,
            "\nPairs with a masked effect (marginal visibility < {MASKED_PERCENT} % on both \
             channels; counted above in every group but the last):\n"
        );
        for r in masked {
            let vis: Vec<String> = r
                .masked
                .iter()
                .map(|e| {
                    let m = r.marginal_visibility.get(e).copied().unwrap_or_default();
                    format!("{e} {:.3}/{:.3} %", m.v, m.w)
                })
                .collect();
            let _ = writeln!(
                out,
                "* {} {} {} seed {}: masked {}; named [{}]",
                r.profile,
                r.timing,
                r.case,
                r.seed,
                vis.join(", "),
                r.named.join(", ")
            );
        }
    }

    let clean: Vec<&Record> = ok.iter().copied().filter(|r| r.kind == "clean").collect();
    if !clean.is_empty() {
        let n = clean.len();
        let named = clean.iter().filter(|r| !r.named.is_empty()).count();
        let unexpl = clean.iter().filter(|r| r.unexplained.is_some()).count();
        let either = clean
            .iter()
            .filter(|r| !r.named.is_empty() || r.unexplained.is_some())
            .count();
        let mismatch = clean.iter().filter(|r| r.mismatch).count();
        let _ = writeln!(
            out,
            "\n### False alarms on clean runs (95 % Clopper–Pearson)\n\n| what | rate |\n| --- | --- |\n\
             | named an effect | {} |\n| left something unexplained | {} |\n| either (false alarm) | {} |\n\
             | declared a mismatch | {} |",
            pct(named, n),
            pct(unexpl, n),
            pct(either, n),
            pct(mismatch, n)
        );
    }

    let mut mags: BTreeMap<(String, String), (usize, Vec<f64>)> = BTreeMap::new();
    for r in &ok {
        for m in &r.magnitudes {
            let e = mags
                .entry((m.effect.clone(), m.quantity.clone()))
                .or_default();
            e.0 += 1;
            if let Some(x) = m.rel_error {
                e.1.push(x.abs());
            }
        }
    }
    if !mags.is_empty() {
        let _ = writeln!(
            out,
            "\n### Magnitudes\n\nRelative error |estimate − truth|/truth over the runs whose \
             true effect was named by an acceptable candidate (ratios: of the deviation from 1).\n\n\
             | effect | quantity | runs | estimated | median error | within 20 % | worst |\n\
             | --- | --- | ---: | ---: | ---: | ---: | ---: |"
        );
        for ((effect, quantity), (n, errs)) in &mut mags {
            if quantity == "n/a" {
                let _ = writeln!(out, "| {effect} | n/a | {n} | — | n/a | n/a | n/a |");
                continue;
            }
            let k = errs.len();
            let within = errs.iter().filter(|&&x| x <= 0.2).count();
            let worst = errs.iter().copied().fold(f64::NAN, f64::max);
            let med = median(errs);
            let f = |x: f64| {
                if x.is_finite() {
                    format!("{:.1} %", 100.0 * x)
                } else {
                    "—".into()
                }
            };
            let _ = writeln!(
                out,
                "| {effect} | {quantity} | {n} | {k} | {} | {within}/{k} | {} |",
                f(med),
                f(worst)
            );
        }
    }
    out
}

/// Command-line arguments.
#[derive(Debug, Parser)]
#[command(about = "Measure `wheelid diagnose` on the rigid-body physics backend (issue 15)")]
pub struct Args {
    /// Seeds: `A..B` (both ends included), `A..=B`, `A`, or a comma list of those.
    #[arg(long, default_value = "1..3")]
    pub seeds: String,
    /// Physical profiles, comma-separated.
    #[arg(long, default_value = "khepera3,pioneer3dx")]
    pub profiles: String,
    /// Timing conventions, comma-separated (instant, window_end, window_middle).
    #[arg(long, default_value = "instant,window_end,window_middle")]
    pub conventions: String,
    /// single, pairs, clean, all (or a comma list).
    #[arg(long, default_value = "all")]
    pub cases: String,
    /// Only these physics effects in the single and pair cases (default: all of TRUTH).
    #[arg(long)]
    pub effects: Option<String>,
    /// Duration \[s\] for every profile (default: 60 for khepera3, 120 otherwise).
    #[arg(long)]
    pub duration: Option<f64>,
    /// Host timing jitter, fraction of the period (< 0.5).
    #[arg(long, default_value_t = 0.0)]
    pub jitter: f64,
    /// Write one JSON record per run to this file (JSON lines, in completion order).
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Runs at once.
    #[arg(long, default_value_t = 1)]
    pub threads: usize,
    /// Diagnosis candidates, comma-separated (default: every registered one) — for looking
    /// at what one candidate does on a case, not for the reported figures.
    #[arg(long, value_delimiter = ',')]
    pub candidates: Option<Vec<String>>,
    /// Keep every simulated recording (and clean twin) as CSV in this directory and read it
    /// back instead of simulating when it is there: comparing two versions of the diagnosis
    /// on the same recordings costs the diagnoses only. The file name holds profile,
    /// convention, case, seed, duration and jitter; a harness whose physics changed needs a
    /// fresh directory.
    #[arg(long)]
    pub cache: Option<PathBuf>,
}

/// The runs `a` asks for: profile × convention × case × seed.
///
/// # Errors
/// Unknown profiles, conventions, cases or effects, or bad seeds.
pub fn plan(a: &Args) -> Result<Vec<RunSpec>> {
    let seeds = parse_seeds(&a.seeds)?;
    let cases = Cases::parse(&a.cases)?;
    let all = effect_names();
    let effects: Vec<&'static str> = match &a.effects {
        None => all.clone(),
        Some(list) => list
            .split(',')
            .map(str::trim)
            .map(|e| {
                all.iter()
                    .copied()
                    .find(|x| *x == e)
                    .with_context(|| format!("--effects {e}: known are {}", all.join(", ")))
            })
            .collect::<Result<_>>()?,
    };
    let mut specs = Vec::new();
    for profile in a.profiles.split(',').map(str::trim) {
        if PhysicalProfile::by_name(profile).is_none() {
            bail!(
                "--profiles {profile}: known are {:?}",
                PhysicalProfile::NAMES
            );
        }
        for conv in a.conventions.split(',').map(str::trim) {
            let timing = Timing::parse(conv).with_context(|| {
                format!("--conventions {conv}: expected instant, window_end or window_middle")
            })?;
            for set in effect_sets(cases, &effects) {
                for &seed in &seeds {
                    specs.push(RunSpec {
                        profile: profile.to_string(),
                        timing,
                        effects: set.clone(),
                        seed,
                        duration_s: a.duration.unwrap_or_else(|| default_duration(profile)),
                        jitter: a.jitter,
                        candidates: a.candidates.clone(),
                        cache: a.cache.clone(),
                    });
                }
            }
        }
    }
    Ok(specs)
}

fn main() -> Result<()> {
    let a = Args::parse();
    let specs = plan(&a)?;
    let json = match &a.json {
        Some(path) => Some(Mutex::new(std::io::BufWriter::new(
            std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?,
        ))),
        None => None,
    };
    eprintln!("{} runs on {} thread(s)", specs.len(), a.threads.max(1));
    let clock = Instant::now();
    let finished = AtomicUsize::new(0);
    let done = |_: usize, r: &Record| {
        let k = finished.fetch_add(1, Ordering::Relaxed) + 1;
        let verdict = match (&r.error, r.exactly_right) {
            (Some(e), _) => format!("FAILED: {e}"),
            (None, true) => "right".into(),
            (None, false) => "wrong".into(),
        };
        eprintln!(
            "[{k}/{}] {} {} {} seed {}: named [{}]{} — {verdict} ({:.1} s + {:.1} s)",
            specs.len(),
            r.profile,
            r.timing,
            r.case,
            r.seed,
            r.named.join(", "),
            r.unexplained.as_ref().map_or(String::new(), |c| format!(
                ", unexplained [{}]",
                c.join(", ")
            )),
            r.simulate_s,
            r.diagnose_s
        );
        if let Some(j) = &json
            && let (Ok(line), Ok(mut w)) = (serde_json::to_string(r), j.lock())
        {
            let _ = writeln!(w, "{line}");
            let _ = w.flush();
        }
    };
    let recs = run_all(&specs, a.threads, &done);
    print!("{}", report(&recs, clock.elapsed().as_secs_f64()));
    Ok(())
}
