//! The host: when it samples, what it sends, and how it stamps the rows it writes.
//!
//! It samples at instants s_k = kΔ + e_k, e_k uniform in ±JΔ (seeded; J = `jitter` < ½, e_0 = 0),
//! rounded to the physics grid — the actual instants: the command u_k = excitation(s_k) is sent
//! at s_k and the encoders are read there. With a_k the encoder angles at s_k and
//! ω̄_k = (a_k − a_{k−1})/(s_k − s_{k−1}) the tick-counted window averages, the recording's row k
//! under each convention of `wheelid_core::Timing` is
//!
//! ```text
//! (a) instant:        (s_k,                 u_k, instantaneous wheel rates at s_k)
//! (b) window_end:     (s_k,                 u_k, ω̄_k)                (row 0: the instants)
//! (c) window_middle:  ((s_k + s_{k+1})/2,   u_k, ω̄_{k+1})
//! ```
//!
//! then v = (v_r + v_l)/2, ω = (v_r − v_l)/d from the wheel speeds v_i = r ω_i (+ noise), with
//! the profile's nominal r and d (the host does not know a worn tyre). The pose columns are the
//! chassis's true axle-centre pose at the end of the row's window (at s_k under (a), (b)).

use rand::Rng;
use rand_chacha::ChaCha8Rng;
use wheelid_core::{Recording, Result, Timing};

use super::encoder::Encoders;
use super::robot::PhysicsRobot;
use super::{PhysicalProfile, PhysicsSettings};
use crate::excitation::Excitation;

/// What the host saw at one sample instant.
#[derive(Debug, Clone, Copy)]
pub(super) struct Raw {
    /// The sample instant s_k \[s\].
    pub t: f64,
    /// The command sent at s_k (v_ref [m/s], ω_ref [rad/s]).
    pub command: (f64, f64),
    /// Wheel angles (right, left) as the encoders report them \[rad\].
    pub angle: [f64; 2],
    /// Instantaneous wheel rates [rad/s].
    pub rate: [f64; 2],
    /// True axle-centre pose (x \[m\], y \[m\], heading \[rad\]).
    pub pose: [f64; 3],
}

/// Sample instants s_k on the physics grid: kΔ plus uniform jitter of ± `jitter`·Δ, as step
/// indices of `h` (strictly increasing; `n` of them).
pub(super) fn sample_steps(
    n: usize,
    period: f64,
    h: f64,
    jitter: f64,
    rng: &mut ChaCha8Rng,
) -> Vec<usize> {
    let mut out: Vec<usize> = Vec::with_capacity(n);
    for k in 0..n {
        let e = if k == 0 || jitter == 0.0 {
            0.0
        } else {
            rng.random_range(-jitter..=jitter)
        };
        let step = ((k as f64 + e) * period / h).round() as usize;
        let step = match out.last() {
            Some(&l) if step <= l => l + 1,
            _ => step,
        };
        out.push(step);
    }
    out
}

/// Runs the robot under `excitation` from rest and returns what the host saw at each sample.
fn run_host(p: &PhysicalProfile, exc: &Excitation, s: &PhysicsSettings) -> Result<Vec<Raw>> {
    let mut robot = PhysicsRobot::new(p, s)?;
    let n = robot.steps.len();
    let mut raws = Vec::with_capacity(n);
    for _ in 0..n {
        let mut raw = robot.sample();
        let u = exc.at(raw.t);
        raw.command = u;
        raws.push(raw);
        robot.advance(u);
    }
    Ok(raws)
}

/// One row under `timing` from the samples: (t, command, wheel rates (right, left), pose).
fn row(raws: &[Raw], k: usize, timing: Timing) -> (f64, (f64, f64), [f64; 2], [f64; 3]) {
    let window = |a: &Raw, b: &Raw| [0, 1].map(|i| (b.angle[i] - a.angle[i]) / (b.t - a.t));
    let r = &raws[k];
    match timing {
        Timing::Instant => (r.t, r.command, r.rate, r.pose),
        Timing::WindowEnd if k == 0 => (r.t, r.command, r.rate, r.pose),
        Timing::WindowEnd => (r.t, r.command, window(&raws[k - 1], r), r.pose),
        Timing::WindowMiddle => {
            let next = &raws[k + 1];
            (0.5 * (r.t + next.t), r.command, window(r, next), next.pose)
        }
    }
}

/// Simulates `profile` under `excitation` from rest and returns the recording the host writes
/// under `s.timing` (module docs): columns t, v_ref, w_ref, v, w, x, y, phi, one row per
/// sample instant but the last. Metadata: `robot`, `source`, `model` (`wheel-pd` or `vw-pd`),
/// `pose_source: ground_truth` (the pose columns are the chassis's true pose), `theta_map`
/// (θ1…θ6 the map of `wheelid_models::physical` gives for the constants; with a payload, for
/// the robot as it starts), `effects` (`none` or the settings), `jitter`, `command_hold: zoh`,
/// `timing` and `velocity_sampling`.
///
/// # Errors
/// [`wheelid_core::Error::InvalidSetting`] for a bad profile or setting (duration ≤ 0, jitter
/// ∉ [0, 0.5), negative noise, an effect out of range), or an invalid recording (the engine
/// diverged).
pub fn simulate_physics_recording(
    profile: &PhysicalProfile,
    excitation: &Excitation,
    s: &PhysicsSettings,
) -> Result<Recording> {
    let raws = run_host(profile, excitation, s)?;
    // The noise stream is the encoders' own; quantisation happened at the samples.
    let mut enc = Encoders::new(profile.ticks_per_rev, false, s.wheel_noise_std, s.seed)?;
    let mut cols: [Vec<f64>; 8] = Default::default();
    for k in 0..raws.len() - 1 {
        let (t, u, rates, pose) = row(&raws, k, s.timing);
        let (vr, vl) = (
            enc.speed(rates[0], profile.r),
            enc.speed(rates[1], profile.r),
        );
        let values = [t, u.0, u.1, 0.5 * (vr + vl), (vr - vl) / profile.d];
        for (c, x) in cols.iter_mut().zip(values.into_iter().chain(pose)) {
            c.push(x);
        }
    }
    let [t, vref, wref, v, w, x, y, phi] = cols;
    let mut rec = Recording::new(format!("<physics {}>", profile.name), t, vref, wref, v, w)?;
    rec.x = Some(x);
    rec.y = Some(y);
    rec.phi = Some(phi);
    rec.set_meta("robot", profile.name.clone());
    rec.set_meta("track", format!("{} m", profile.d));
    rec.set_meta(
        "source",
        format!("wheelid physics backend (rapier3d-f64), seed {}", s.seed),
    );
    // The pose columns are the chassis's true pose, not the encoders' integral.
    rec.set_meta(wheelid_core::POSE_SOURCE, "ground_truth");
    rec.set_meta("model", profile.model_name());
    rec.set_meta("theta_map", format!("{:?}", profile.theta()));
    let effects = if s.effects.active().is_empty() {
        "none".to_string()
    } else {
        format!("{:?}", s.effects)
    };
    rec.set_meta("effects", effects);
    rec.set_meta("jitter", format!("{}", s.jitter));
    rec.set_meta("command_hold", "zoh");
    rec.set_timing(s.timing);
    Ok(rec)
}
