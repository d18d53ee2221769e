//! A recording of any [`DynamicModel`] of (v, ω) — an identified or diagnosed model, with
//! whatever effects it carries (`wheelid_models::Extended`: an effort clamp, a traction limit,
//! a tyre mismatch, …) — driven open loop by an excitation and measured through the simulated
//! robot's encoders: what `wheelid simulate --model` writes.
//!
//! The commands are sampled every period Δt (t_k = k Δt) and held (zero-order hold). The
//! model's free-run simulation from rest gives, with encoders, each period's window averages
//! v̄_k, ω̄_k, so that each wheel turns by exactly (v̄_k ± d ω̄_k / 2) Δt / r over the period;
//! the encoders ([`crate::simulator`]'s measurement model: whole ticks, noise, the reported
//! resolution, odometry of eq. 3.2–3.3) turn that into the recorded v, ω and pose. Without
//! encoders the model's instants are recorded and the pose follows by the same second-order
//! Runge–Kutta odometry on the exact increments (trapezoid of v, ω over each period).

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::Distribution;
use wheelid_core::{DynamicModel, Error, Recording, Result, Timing};

use crate::excitation::Excitation;
use crate::profile::RobotProfile;
use crate::simulator::{Encoders, SimSettings};

/// Simulates `model` at parameters `theta` on the robot `profile` (period, wheels, encoders)
/// under `excitation` from rest at the origin, for `s.duration_s`, with the encoder model when
/// `s.measurement_noise` (seeded by `s.seed`) and the extra white noise of the
/// `measurement_noise` effect if `s.effects` has it. The recording has t, v_ref, ω_ref, v, ω,
/// x, y, φ; metadata `command_hold: zoh`, `timing: window_end` (encoders) or `instant`,
/// `robot`, `source`, `model`, `theta_true` (the model's whole parameter vector).
///
/// # Errors
/// [`Error::InvalidSetting`] for a duration that is not > 0, a model whose channels are not
/// (v, ω), any other simulator effect in `s.effects` (the model's own effects are the
/// physics: the simulator's would be applied twice), or a bad robot profile; the model's
/// own errors (a bad θ); an invalid recording (e.g. a non-finite output of an unstable θ).
pub fn simulate_model_recording(
    profile: &RobotProfile,
    model: &dyn DynamicModel,
    theta: &[f64],
    excitation: &Excitation,
    s: &SimSettings,
) -> Result<Recording> {
    check(model, s)?;
    let wheel_noise = profile.measurement()?;
    let dt = profile.period_s;
    let n = (s.duration_s / dt).floor() as usize + 1;
    let t: Vec<f64> = (0..n).map(|k| k as f64 * dt).collect();
    let (v_ref, w_ref): (Vec<f64>, Vec<f64>) = t.iter().map(|&tk| excitation.at(tk)).unzip();
    let timing = if s.measurement_noise {
        Timing::WindowEnd
    } else {
        Timing::Instant
    };
    let mut rec = Recording::new(
        format!("<simulated {} model {}>", profile.name, model.name()),
        t,
        v_ref,
        w_ref,
        vec![0.0; n],
        vec![0.0; n],
    )?;
    rec.set_meta("command_hold", "zoh");
    rec.set_timing(timing);
    let y = model.simulate(theta, &rec, &[0.0, 0.0])?;
    let [v, w, x, y, phi] = measure(profile, s, &wheel_noise, &y[0], &y[1]);
    let mut out = Recording::new(rec.source.clone(), rec.t, rec.v_ref, rec.w_ref, v, w)?;
    out.x = Some(x);
    out.y = Some(y);
    out.phi = Some(phi);
    out.set_meta("robot", profile.name.clone());
    out.set_meta(
        "source",
        format!(
            "wheelid simulator (model {}), seed {}",
            model.name(),
            s.seed
        ),
    );
    let names: Vec<&str> = model.params().iter().map(|p| p.name).collect();
    out.set_meta("model", names.join(" "));
    out.set_meta("theta_true", format!("{theta:?}"));
    out.set_meta("command_hold", "zoh");
    out.set_timing(timing);
    Ok(out)
}

/// The settings `simulate_model_recording` accepts.
fn check(model: &dyn DynamicModel, s: &SimSettings) -> Result<()> {
    s.check_duration()?;
    let channels: Vec<&str> = model.channels().iter().map(|c| c.name).collect();
    if channels != ["v", "w"] {
        return Err(Error::InvalidSetting(format!(
            "model {}: channels {channels:?}, not [v, w]",
            model.name()
        )));
    }
    let mut others = s.effects.active();
    others.retain(|e| *e != "measurement_noise");
    if !others.is_empty() {
        return Err(Error::InvalidSetting(format!(
            "effects {}: a model's recording takes its physics from the model, not from the \
             simulator's effects",
            others.join(", ")
        )));
    }
    Ok(())
}

/// The recorded (v, ω, x, y, φ) of the model's outputs `v`, `w` (window averages with
/// encoders, instants without), each wheel's speed with `wheel_noise` [m/s].
fn measure(
    profile: &RobotProfile,
    s: &SimSettings,
    wheel_noise: &rand_distr::Normal<f64>,
    v: &[f64],
    w: &[f64],
) -> [Vec<f64>; 5] {
    let dt = profile.period_s;
    let (r, d, a) = (profile.wheel_radius, profile.track, profile.a);
    let mut rng = ChaCha8Rng::seed_from_u64(s.seed);
    let mut enc = Encoders::default();
    enc.odom = [-a, 0.0, 0.0];
    let n = v.len();
    let mut out: [Vec<f64>; 5] = std::array::from_fn(|_| Vec::with_capacity(n));
    let mut push = |m: [f64; 5]| out.iter_mut().zip(m).for_each(|(c, x)| c.push(x));
    push([v[0], w[0], 0.0, 0.0, 0.0]);
    for k in 1..n {
        let mut m = if s.measurement_noise {
            enc.ang[0] += (v[k] + 0.5 * d * w[k]) * dt / r;
            enc.ang[1] += (v[k] - 0.5 * d * w[k]) * dt / r;
            enc.read(profile, dt, &mut rng, wheel_noise)
        } else {
            // Exact increments: the trapezoid of v, ω; odometry as eq. 3.2–3.3.
            let ds = 0.5 * (v[k - 1] + v[k]) * dt;
            let dth = 0.5 * (w[k - 1] + w[k]) * dt;
            let o = &mut enc.odom;
            let mid = o[2] + 0.5 * dth;
            o[0] += ds * mid.cos();
            o[1] += ds * mid.sin();
            o[2] += dth;
            [
                v[k],
                w[k],
                o[0] + a * o[2].cos(),
                o[1] + a * o[2].sin(),
                o[2],
            ]
        };
        if let Some(noise) = s.effects.measurement_noise {
            let z: [f64; 2] = [0, 1].map(|_| rand_distr::StandardNormal.sample(&mut rng));
            m[0] += noise.v_std * z[0];
            m[1] += noise.w_std * z[1];
        }
        push(m);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulator::simulate_recording;

    /// The six-θ model through this path and the eq.-2.19 simulator with the same θ, seed and
    /// encoders record the same robot: v, ω within one reported resolution of each other (a
    /// tick or a rounding apart: different integrators), the pose within 0.1 mm after 20 s.
    #[test]
    fn the_six_theta_model_records_as_the_simulator_does() {
        let profile = RobotProfile::pioneer3dx();
        let excitation = Excitation::thesis_pioneer();
        let s = SimSettings {
            duration_s: 20.0,
            ..SimSettings::default()
        };
        let model = wheelid_models::Extended::new(&[], profile.track).expect("model");
        let here = simulate_model_recording(&profile, &model, &profile.theta, &excitation, &s)
            .expect("simulates");
        let sim = simulate_recording(&profile, &excitation, &s).expect("simulates");
        assert_eq!(here.len(), sim.len());
        let worst = |a: &[f64], b: &[f64]| {
            a.iter()
                .zip(b)
                .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()))
        };
        // Measured: v 0.5 mm/s, ω one resolution step / d, x 11 µm apart at worst.
        let res = profile.speed_resolution;
        let dv = worst(&here.v, &sim.v);
        assert!(dv <= 1.01 * res, "v differs by {dv}");
        let dw = worst(&here.w, &sim.w);
        assert!(dw <= 1.01 * res / profile.track, "ω differs by {dw}");
        let dx = worst(
            here.x.as_deref().unwrap_or(&[]),
            sim.x.as_deref().unwrap_or(&[]),
        );
        assert!(dx < 1e-4, "x differs by {dx}");
        assert_eq!(here.timing(), Some(Timing::WindowEnd));
    }

    #[test]
    fn the_simulators_own_effects_are_refused_beside_a_model() {
        let profile = RobotProfile::pioneer3dx();
        let mut s = SimSettings::default();
        s.effects.input_delay = Some(crate::effects::InputDelay { delay_s: 0.1 });
        let model = wheelid_models::Extended::new(&[], profile.track).expect("model");
        let e = simulate_model_recording(
            &profile,
            &model,
            &profile.theta,
            &Excitation::thesis_pioneer(),
            &s,
        )
        .expect_err("refused")
        .to_string();
        assert!(e.contains("input_delay"), "{e}");
    }
}
