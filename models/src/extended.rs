//! Eq. 2.19 extended by candidate physics: the models the mismatch diagnosis fits when the
//! six-θ model and a recording disagree. Each [`Candidate`] carries the name and parameters of
//! the matching simulator effect (`wheelid_robots::effects`), and the extended model applies
//! them in the simulator's order, so a recording simulated with an effect is reproduced by the
//! model with that candidate at the effect's magnitude.
//!
//! With u the recorded command (held between samples), at time t:
//!
//! 1. `input_delay` (`delay_s`): u(t − delay_s);
//! 2. `velocity_saturation` (`v_max`, `w_max`): the setpoint clipped to ±v_max, ±w_max;
//! 3. `acceleration_limit` (`v_accel_max`, `w_accel_max`): the setpoint slews towards that at
//!    most at the given rates (exact slew per integration sub-step);
//! 4. `wheel_asymmetry` (`ratio` ρ): wheel setpoints v ± dω/2 scaled by 2ρ/(1 + ρ) and
//!    2/(1 + ρ), d the track given to [`Extended::new`];
//! 5. `gain_drift` (`rate_per_s`): the setpoint scaled by 1 + rate_per_s·(t − t_0);
//!
//! then
//!
//! ```text
//! θ1 v̇ = u_v + θ3 ω² − θ4 v − v_coulomb tanh(v/ε_v) − θ4 k_v v |ω|
//! θ2 ω̇ = u_ω − θ5 v ω − θ6 ω − w_coulomb tanh(ω/ε_ω) − θ6 k_w |v| ω
//! ```
//!
//! with `coulomb_friction` (`v_coulomb`, `w_coulomb`, ε = 2 mm/s, 0.01 rad/s), `slip` (`k_v`,
//! `k_w`), and `payload_change` (`time_s`, then θ1, θ2, θ3, θ5 after it). The simulation runs on
//! the recording's grid merged with the delayed command switches and the payload time
//! ([`crate::delay`]), so that every parameter moves the outputs continuously; outputs are
//! instants or window averages as the recording says. Parameters: θ1…θ6, then each candidate's
//! in the order given. No analytic sensitivities: the output-error fitter differentiates.

use serde::{Deserialize, Serialize};
use wheelid_core::{
    ChannelInfo, CommandHold, DynamicModel, Error, ParamInfo, Recording, Result, Simulation,
    VelocitySampling,
};

use crate::delay::{InputDelay, holding_command, merged_grid};
use crate::{dynamics, regressor};

/// Shortest time constant θ1/θ4, θ2/θ6 the extended model accepts [s].
pub const MIN_TIME_CONSTANT: f64 = 1e-3;

/// Smoothing of the Coulomb friction's sign: 2 mm/s and 0.01 rad/s (as the simulator).
pub const FRICTION_EPS: [f64; 2] = [0.002, 0.01];

macro_rules! p {
    ($name:literal, $unit:literal, $desc:literal) => {
        ParamInfo {
            name: $name,
            unit: $unit,
            description: $desc,
        }
    };
}

static DELAY: [ParamInfo; 1] = [p!("delay_s", "s", "dead time of the commands")];
static ACCEL: [ParamInfo; 2] = [
    p!(
        "v_accel_max",
        "m/s²",
        "largest rate of change of the v setpoint"
    ),
    p!(
        "w_accel_max",
        "rad/s²",
        "largest rate of change of the ω setpoint"
    ),
];
static SAT: [ParamInfo; 2] = [
    p!("v_max", "m/s", "largest |v| setpoint the base accepts"),
    p!("w_max", "rad/s", "largest |ω| setpoint the base accepts"),
];
static COULOMB: [ParamInfo; 2] = [
    p!("v_coulomb", "m/s", "dry friction in forward command units"),
    p!(
        "w_coulomb",
        "rad/s",
        "dry friction in turning command units"
    ),
];
static ASYM: [ParamInfo; 1] = [p!("ratio", "-", "right/left wheel gain ratio")];
static PAYLOAD: [ParamInfo; 5] = [
    p!("time_s", "s", "when the payload changes"),
    p!("theta1_after", "s", "θ1 after the change"),
    p!("theta2_after", "s", "θ2 after the change"),
    p!("theta3_after", "s·m/rad²", "θ3 after the change"),
    p!("theta5_after", "s/m", "θ5 after the change"),
];
static DRIFT: [ParamInfo; 1] = [p!(
    "rate_per_s",
    "1/s",
    "relative change of the gains per second"
)];
static SLIP: [ParamInfo; 2] = [
    p!("k_v", "s/rad", "forward slip per unit v·|ω|"),
    p!("k_w", "s/m", "turning slip per unit |v|·ω"),
];

/// One candidate physics (the names of `wheelid_robots::effects`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Candidate {
    /// Dead time of the commands.
    InputDelay,
    /// Rate limit on the setpoint.
    AccelerationLimit,
    /// Clip of the setpoint.
    VelocitySaturation,
    /// Dry friction / dead zone.
    CoulombFriction,
    /// Left/right wheel gain mismatch.
    WheelAsymmetry,
    /// θ1, θ2, θ3, θ5 change at a time.
    PayloadChange,
    /// Gains change slowly over the run.
    GainDrift,
    /// Losses growing with v·|ω|.
    Slip,
}

impl Candidate {
    /// Every candidate.
    pub const ALL: [Candidate; 8] = [
        Candidate::InputDelay,
        Candidate::AccelerationLimit,
        Candidate::VelocitySaturation,
        Candidate::CoulombFriction,
        Candidate::WheelAsymmetry,
        Candidate::PayloadChange,
        Candidate::GainDrift,
        Candidate::Slip,
    ];

    /// Every candidate's name, in [`Candidate::ALL`] order.
    pub const NAMES: [&'static str; 8] = [
        "input_delay",
        "acceleration_limit",
        "velocity_saturation",
        "coulomb_friction",
        "wheel_asymmetry",
        "payload_change",
        "gain_drift",
        "slip",
    ];

    /// The candidate called `name` (one of [`Candidate::NAMES`]).
    pub fn by_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|c| c.name() == name)
    }

    /// The name (`input_delay`, …), as in the simulator's effects and the diagnosis report.
    pub fn name(self) -> &'static str {
        match self {
            Candidate::InputDelay => "input_delay",
            Candidate::AccelerationLimit => "acceleration_limit",
            Candidate::VelocitySaturation => "velocity_saturation",
            Candidate::CoulombFriction => "coulomb_friction",
            Candidate::WheelAsymmetry => "wheel_asymmetry",
            Candidate::PayloadChange => "payload_change",
            Candidate::GainDrift => "gain_drift",
            Candidate::Slip => "slip",
        }
    }

    /// The candidate's own parameters (appended after θ).
    pub fn params(self) -> &'static [ParamInfo] {
        match self {
            Candidate::InputDelay => &DELAY,
            Candidate::AccelerationLimit => &ACCEL,
            Candidate::VelocitySaturation => &SAT,
            Candidate::CoulombFriction => &COULOMB,
            Candidate::WheelAsymmetry => &ASYM,
            Candidate::PayloadChange => &PAYLOAD,
            Candidate::GainDrift => &DRIFT,
            Candidate::Slip => &SLIP,
        }
    }
}

/// Eq. 2.19 with a set of candidates (`extended`).
#[derive(Debug, Clone, PartialEq)]
pub struct Extended {
    candidates: Vec<Candidate>,
    params: Vec<ParamInfo>,
    track: f64,
}

/// The candidates' values parsed from θ.
#[derive(Debug, Clone, Copy, Default)]
struct Physics {
    delay: f64,
    accel: Option<[f64; 2]>,
    sat: Option<[f64; 2]>,
    coulomb: [f64; 2],
    ratio: Option<f64>,
    payload: Option<(f64, [f64; 4])>,
    drift: f64,
    slip: [f64; 2],
}

impl Extended {
    /// The six-θ model with `candidates` (each at most once); `track_m` is the wheel track d
    /// [m] that `wheel_asymmetry` needs.
    ///
    /// # Errors
    /// [`Error::InvalidSetting`] for a repeated candidate or a track that is not > 0.
    pub fn new(candidates: &[Candidate], track_m: f64) -> Result<Self> {
        for (i, c) in candidates.iter().enumerate() {
            if candidates[..i].contains(c) {
                return Err(Error::InvalidSetting(format!(
                    "candidate {} given twice",
                    c.name()
                )));
            }
        }
        if !(track_m.is_finite() && track_m > 0.0) {
            return Err(Error::InvalidSetting(format!(
                "track = {track_m} m must be > 0"
            )));
        }
        let mut params = regressor::PARAMS.to_vec();
        for c in candidates {
            params.extend_from_slice(c.params());
        }
        Ok(Self {
            candidates: candidates.to_vec(),
            params,
            track: track_m,
        })
    }

    /// The candidates, in parameter order.
    pub fn candidates(&self) -> &[Candidate] {
        &self.candidates
    }

    fn physics(&self, theta: &[f64]) -> Result<([f64; 6], Physics)> {
        if theta.len() != self.params.len() || theta.iter().any(|x| !x.is_finite()) {
            return Err(Error::InvalidSetting(format!(
                "θ of the extended model has {} finite values, got {theta:?}",
                self.params.len()
            )));
        }
        let th = dynamics::check_theta(&theta[..6])?;
        // A time constant below a millisecond is no robot's, and the integrator cannot follow
        // it: refuse it (a fitter's trial step then counts as failed).
        for (a, b) in [(th[0], th[3]), (th[1], th[5])] {
            if b != 0.0 && (a / b).abs() < MIN_TIME_CONSTANT {
                return Err(Error::InvalidSetting(format!(
                    "time constant {:.2e} s is below {MIN_TIME_CONSTANT} s",
                    (a / b).abs()
                )));
            }
        }
        let mut ph = Physics::default();
        let mut i = 6;
        for c in &self.candidates {
            let x = &theta[i..i + c.params().len()];
            match c {
                Candidate::InputDelay => ph.delay = x[0],
                Candidate::AccelerationLimit => ph.accel = Some([x[0].abs(), x[1].abs()]),
                Candidate::VelocitySaturation => ph.sat = Some([x[0].abs(), x[1].abs()]),
                Candidate::CoulombFriction => ph.coulomb = [x[0], x[1]],
                Candidate::WheelAsymmetry => ph.ratio = Some(x[0]),
                Candidate::PayloadChange => ph.payload = Some((x[0], [x[1], x[2], x[3], x[4]])),
                Candidate::GainDrift => ph.drift = x[0],
                Candidate::Slip => ph.slip = [x[0], x[1]],
            }
            i += c.params().len();
        }
        if let Some((_, a)) = ph.payload
            && (a[0] == 0.0 || a[1] == 0.0)
        {
            return Err(Error::InvalidSetting(
                "θ1, θ2 after the payload must be ≠ 0".into(),
            ));
        }
        if ph.ratio.is_some_and(|r| r <= -1.0 + 1e-9) {
            return Err(Error::InvalidSetting("wheel ratio must be > −1".into()));
        }
        Ok((th, ph))
    }
}

/// [`InputDelay::command_at`] for non-decreasing times, walking the samples instead of
/// searching them.
struct CommandCursor<'a> {
    rec: &'a Recording,
    hold: (f64, f64),
    zoh: bool,
    /// Last j with t_j ≤ the previous query.
    j: usize,
}

impl<'a> CommandCursor<'a> {
    fn new(rec: &'a Recording, hold: (f64, f64)) -> Self {
        Self {
            rec,
            hold,
            zoh: rec.command_hold() == CommandHold::Zoh,
            j: 0,
        }
    }
    fn at(&mut self, tau: f64) -> (f64, f64) {
        let t = &self.rec.t;
        let n = t.len();
        if tau < t[0] {
            return self.hold;
        }
        if tau >= t[n - 1] {
            return (self.rec.v_ref[n - 1], self.rec.w_ref[n - 1]);
        }
        if t[self.j] > tau {
            self.j = t.partition_point(|&x| x <= tau) - 1;
        }
        while t[self.j + 1] <= tau {
            self.j += 1;
        }
        let j = self.j;
        let (v, w) = (&self.rec.v_ref, &self.rec.w_ref);
        if self.zoh {
            (v[j], w[j])
        } else {
            let a = (tau - t[j]) / (t[j + 1] - t[j]);
            (v[j] + a * (v[j + 1] - v[j]), w[j] + a * (w[j + 1] - w[j]))
        }
    }
}

impl DynamicModel for Extended {
    fn name(&self) -> &str {
        "extended"
    }
    fn params(&self) -> &[ParamInfo] {
        &self.params
    }
    fn channels(&self) -> &[ChannelInfo] {
        &regressor::CHANNELS
    }
    fn simulate(&self, theta: &[f64], rec: &Recording, initial: &[f64]) -> Result<Simulation> {
        let (th0, ph) = self.physics(theta)?;
        let &[v0, w0] = initial else {
            return Err(Error::InvalidSetting(format!(
                "initial state must be [v, ω], got {} values",
                initial.len()
            )));
        };
        let extra: Vec<f64> = ph.payload.map(|(t, _)| t).into_iter().collect();
        let (grid, index) = merged_grid(rec, ph.delay, &extra)?;
        let th_after = ph
            .payload
            .map(|(_, a)| [a[0], a[1], a[2], th0[3], a[3], th0[5]]);
        let zoh = rec.command_hold() == CommandHold::Zoh;
        let avg = rec.velocity_sampling() == VelocitySampling::WindowAverage;
        let t0 = rec.t[0];
        let d = self.track;
        // Setpoint pipeline after the delay: saturation → rate limit (state) → asymmetry → drift.
        let target = |c: (f64, f64)| match ph.sat {
            Some([vm, wm]) => [c.0.clamp(-vm, vm), c.1.clamp(-wm, wm)],
            None => [c.0, c.1],
        };
        let shape = |s: [f64; 2], t: f64| {
            let [mut uv, mut uw] = s;
            if let Some(rho) = ph.ratio {
                let (gr, gl) = (2.0 * rho / (1.0 + rho), 2.0 / (1.0 + rho));
                let (vr, vl) = (gr * (uv + d * uw / 2.0), gl * (uv - d * uw / 2.0));
                uv = (vr + vl) / 2.0;
                uw = (vr - vl) / d;
            }
            let g = 1.0 + ph.drift * (t - t0);
            [uv * g, uw * g]
        };
        // Dry friction only when present: tanh dominates the cost of a step.
        let dry = ph.coulomb != [0.0, 0.0];
        // θ with the reciprocals of θ1, θ2 and its integration sub-step, before and after a
        // payload change: a step multiplies instead of dividing.
        let prepare = |th: [f64; 6]| (th, [1.0 / th[0], 1.0 / th[1]], dynamics::substep(&th));
        let (before, after) = (prepare(th0), th_after.map(prepare));
        let rhs = |th: &[f64; 6], inv: &[f64; 2], v: f64, w: f64, u: [f64; 2]| {
            let mut fv = u[0] + th[2] * w * w - th[3] * v - th[3] * ph.slip[0] * v * w.abs();
            let mut fw = u[1] - th[4] * v * w - th[5] * w - th[5] * ph.slip[1] * v.abs() * w;
            if dry {
                fv -= ph.coulomb[0] * (v / FRICTION_EPS[0]).tanh();
                fw -= ph.coulomb[1] * (w / FRICTION_EPS[1]).tanh();
            }
            [fv * inv[0], fw * inv[1]]
        };
        // The rate-limited setpoint starts where it holds the initial state (a robot at rest
        // holds zero), as the simulator's.
        let hold = holding_command(&th0, initial);
        let mut setpoint = target(InputDelay::command_at(rec, t0 - ph.delay, hold));
        if ph.accel.is_some() {
            setpoint = [hold.0, hold.1];
        }
        let fixed_setpoint = zoh && ph.accel.is_none() && ph.drift == 0.0;
        let mut cursor = CommandCursor::new(rec, hold);
        let m = grid.len();
        let mut y = [Vec::with_capacity(m), Vec::with_capacity(m)];
        let mut s = [v0, w0];
        y[0].push(v0);
        y[1].push(w0);
        for i in 1..m {
            let (ta, tb) = (grid[i - 1], grid[i]);
            let span = tb - ta;
            let (th, inv, h_max) = match (ph.payload, after) {
                (Some((ts, _)), Some(a)) if 0.5 * (ta + tb) >= ts => a,
                _ => before,
            };
            let ca = cursor.at(if zoh { 0.5 * (ta + tb) } else { ta } - ph.delay);
            let cb = if zoh { ca } else { cursor.at(tb - ph.delay) };
            let rhs_at = |x: &[f64; 2], u: (f64, f64)| rhs(&th, &inv, x[0], x[1], [u.0, u.1]);
            let steps = (span / h_max).ceil().max(1.0) as usize;
            let h = span / steps as f64;
            let mut q = [0.0; 2];
            if fixed_setpoint {
                // Held command, no rate limit, no drift: one setpoint for the whole interval.
                let u = shape(target(ca), ta);
                for _ in 0..steps {
                    dynamics::rk4_step(rhs_at, &mut s, &mut q, (u[0], u[1]), (u[0], u[1]), h);
                }
                setpoint = target(ca);
            }
            for j in (0..steps).filter(|_| !fixed_setpoint) {
                let (f0, f1) = (j as f64 / steps as f64, (j + 1) as f64 / steps as f64);
                let c_at = |f: f64| (ca.0 + f * (cb.0 - ca.0), ca.1 + f * (cb.1 - ca.1));
                let (tau0, tau1) = (ta + j as f64 * h, ta + (j + 1) as f64 * h);
                let s0 = setpoint;
                let tgt = target(c_at(f1));
                let s1 = match ph.accel {
                    Some(a) => [0, 1].map(|k| s0[k] + (tgt[k] - s0[k]).clamp(-a[k] * h, a[k] * h)),
                    None => tgt,
                };
                let s_start = if ph.accel.is_some() {
                    s0
                } else {
                    target(c_at(f0))
                };
                let u0 = shape(s_start, tau0);
                let u1 = shape(s1, tau1);
                dynamics::rk4_step(rhs_at, &mut s, &mut q, (u0[0], u0[1]), (u1[0], u1[1]), h);
                setpoint = s1;
            }
            for c in 0..2 {
                y[c].push(if avg { q[c] / span } else { s[c] });
            }
        }
        // Back to the recording's samples: instants, or length-weighted window averages.
        let mut out = [Vec::with_capacity(rec.len()), Vec::with_capacity(rec.len())];
        for (k, &i) in index.iter().enumerate() {
            for (o, yc) in out.iter_mut().zip(&y) {
                if !avg || k == 0 {
                    o.push(yc[i]);
                } else {
                    let i0 = index[k - 1];
                    let total: f64 = (i0 + 1..=i).map(|j| (grid[j] - grid[j - 1]) * yc[j]).sum();
                    o.push(total / (grid[i] - grid[i0]));
                }
            }
        }
        Ok(out.to_vec())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const THETA: [f64; 6] = [0.26, 0.25, -0.05, 0.9965, 0.08, 1.0768];

    fn recording(avg: bool, n: usize, f: impl Fn(f64) -> (f64, f64)) -> Recording {
        let t: Vec<f64> = (0..n).map(|k| k as f64 * 0.1).collect();
        let (vr, wr): (Vec<f64>, Vec<f64>) = t.iter().map(|&x| f(x)).unzip();
        let mut rec = Recording::new("x", t, vr, wr, vec![0.0; n], vec![0.0; n]).expect("valid");
        rec.set_meta("command_hold", "zoh");
        if avg {
            rec.set_meta("velocity_sampling", "window_average");
        }
        rec
    }

    #[test]
    fn without_candidates_and_with_a_delay_it_is_the_plain_and_the_delayed_model() {
        for avg in [false, true] {
            let rec = recording(avg, 80, |x| {
                (0.3 + 0.2 * (1.1 * x).sin(), 0.8 * (0.6 * x).cos())
            });
            let x0 = [0.1, 0.05];
            let plain = dynamics::simulate(&THETA, &rec, &x0).expect("sim");
            let e = Extended::new(&[], 0.34).expect("model");
            let got = e.simulate(&THETA, &rec, &x0).expect("sim");
            let mut th7 = THETA.to_vec();
            th7.push(0.137);
            let delayed = InputDelay.simulate(&th7, &rec, &x0).expect("sim");
            let e = Extended::new(&[Candidate::InputDelay], 0.34).expect("model");
            let got_d = e.simulate(&th7, &rec, &x0).expect("sim");
            for ch in 0..2 {
                for k in 0..rec.len() {
                    approx::assert_abs_diff_eq!(got[ch][k], plain[ch][k], epsilon = 1e-12);
                    approx::assert_abs_diff_eq!(got_d[ch][k], delayed[ch][k], epsilon = 1e-12);
                }
            }
        }
    }

    #[test]
    fn saturation_and_rate_limit_match_their_closed_forms() {
        // Straight drive (ω = 0), step to 1 m/s at t = 0.
        let rec = recording(false, 101, |_| (1.0, 0.0));
        let tau = THETA[0] / THETA[3];
        // Saturation at 0.4 m/s: v = (0.4/θ4)(1 − e^{−t/τ}).
        let e = Extended::new(&[Candidate::VelocitySaturation], 0.34).expect("model");
        let mut th = THETA.to_vec();
        th.extend([0.4, 5.0]);
        let [v, _] = <[Vec<f64>; 2]>::try_from(e.simulate(&th, &rec, &[0.0, 0.0]).expect("sim"))
            .expect("two channels");
        for (k, vk) in v.iter().enumerate() {
            let t = rec.t[k];
            let want = 0.4 / THETA[3] * (1.0 - (-t / tau).exp());
            approx::assert_abs_diff_eq!(*vk, want, epsilon = 1e-6);
        }
        // Rate limit 0.5 m/s² (setpoint ramps for 2 s): θ1 v̇ + θ4 v = a t →
        // v = (a/θ4)(t − τ(1 − e^{−t/τ})) while ramping.
        let e = Extended::new(&[Candidate::AccelerationLimit], 0.34).expect("model");
        let mut th = THETA.to_vec();
        th.extend([0.5, 5.0]);
        let [v, _] = <[Vec<f64>; 2]>::try_from(e.simulate(&th, &rec, &[0.0, 0.0]).expect("sim"))
            .expect("two channels");
        for (k, vk) in v.iter().enumerate().take(21) {
            let t = rec.t[k];
            let want = 0.5 / THETA[3] * (t - tau * (1.0 - (-t / tau).exp()));
            approx::assert_abs_diff_eq!(*vk, want, epsilon = 1e-6);
        }
    }
}
