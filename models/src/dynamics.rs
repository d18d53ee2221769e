//! The velocity dynamics of Laut 2011 eq. 2.19 (rows 4–5) and their free-run simulation.
//!
//! ```text
//! v̇ = (θ3/θ1) ω² − (θ4/θ1) v + (1/θ1) v_ref
//! ω̇ = −(θ5/θ2) v ω − (θ6/θ2) ω + (1/θ2) ω_ref
//! ```
//!
//! The simulation integrates with classical fourth-order Runge–Kutta at a sub-step of a fifth
//! of the model's faster time constant ([`substep`]), with the commands held (zero-order hold)
//! or linearly interpolated between samples as the recording says, and reports instantaneous
//! values or window averages (the integral of the velocity over the sample period, divided by
//! it) likewise.
//!
//! # Sensitivities
//! With x = (v, ω) and p = (θ1…θ6, v0, ω0), the output sensitivities S = ∂x/∂p (2 × 8) obey the
//! forward sensitivity equations, integrated alongside x by the same RK4 steps
//! ([`simulate_with_sensitivities`]):
//!
//! ```text
//! Ṡ = A S + [B | 0],   S(0) = [0 | I₂],
//! A = ∂f/∂x = [ −θ4/θ1        2θ3ω/θ1       ]
//!             [ −θ5ω/θ2      −(θ5v + θ6)/θ2 ]
//! B = ∂f/∂θ = [ −v̇/θ1  0       ω²/θ1  −v/θ1  0        0     ]
//!             [ 0      −ω̇/θ2   0      0      −vω/θ2  −ω/θ2 ]
//! ```
//!
//! and window-averaged outputs have the window average of S as their sensitivity.

use nalgebra::DMatrix;
use wheelid_core::{CommandHold, Error, Recording, Result, Sensitivities, VelocitySampling};

/// Longest integration sub-step [s].
pub const MAX_SUBSTEP: f64 = 0.02;
/// Shortest integration sub-step [s]: time constants below a millisecond are not a robot's;
/// a θ that asks for them (a fitter's trial step) integrates unstably and is rejected as a
/// non-finite simulation instead of taking millions of sub-steps.
pub const MIN_SUBSTEP: f64 = 1e-4;

/// (v̇, ω̇) of eq. 2.19 for θ (length 6), state (v, ω) and commands (v_ref, ω_ref).
#[inline]
pub fn accel(theta: &[f64; 6], v: f64, w: f64, v_ref: f64, w_ref: f64) -> (f64, f64) {
    let [t1, t2, t3, t4, t5, t6] = *theta;
    (
        (t3 * w * w - t4 * v + v_ref) / t1,
        (-t5 * v * w - t6 * w + w_ref) / t2,
    )
}

/// A command that varies linearly over an integration step: what [`rk4_step`] needs of it.
pub trait StepCommand: Copy {
    /// The command halfway between `self` and `other`.
    fn midpoint(&self, other: &Self) -> Self;
}

impl StepCommand for (f64, f64) {
    #[inline(always)]
    fn midpoint(&self, other: &Self) -> Self {
        ((self.0 + other.0) * 0.5, (self.1 + other.1) * 0.5)
    }
}

/// One classical RK4 step of ẋ = f(x, u) of length `h`, with the command varying linearly from
/// `u0` to `u1` over the step (its midpoint for the middle stages); adds ∫x over the step, by the
/// same stages, to `q` — window averages to the same order as the state. `x`, `q`: N state
/// components in their own units; `h` in seconds. Components that fall below 1e-200 are set
/// to zero (they would stall as slow subnormal numbers). Model plugins integrate with it too.
#[inline(always)]
pub fn rk4_step<const N: usize, U: StepCommand>(
    f: impl Fn(&[f64; N], U) -> [f64; N],
    x: &mut [f64; N],
    q: &mut [f64; N],
    u0: U,
    u1: U,
    h: f64,
) {
    let um = u0.midpoint(&u1);
    let k1 = f(x, u0);
    let x2: [f64; N] = std::array::from_fn(|i| x[i] + 0.5 * h * k1[i]);
    let k2 = f(&x2, um);
    let x3: [f64; N] = std::array::from_fn(|i| x[i] + 0.5 * h * k2[i]);
    let k3 = f(&x3, um);
    let x4: [f64; N] = std::array::from_fn(|i| x[i] + h * k3[i]);
    let k4 = f(&x4, u1);
    for i in 0..N {
        q[i] += h / 6.0 * (x[i] + 2.0 * x2[i] + 2.0 * x3[i] + x4[i]);
        x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
        // A decaying component (the sensitivity to the initial state, a velocity at rest)
        // would otherwise stall in the subnormal range, where RK4's increment rounds to
        // nothing, and make every later step ~10× slower: below 1e-200 it is zero.
        if x[i].abs() < FLUSH {
            x[i] = 0.0;
        }
    }
}

/// Magnitude under which [`rk4_step`] sets a state component to zero (any unit: far below
/// every physical value, far above the subnormal range that starts at 2.2e-308).
const FLUSH: f64 = 1e-200;

/// Calls `step(u0, u1, h)` for the equal sub-steps (at most `h_max` long) of the interval
/// [t_{k−1}, t_k], with the command held or linearly interpolated as `hold` says; returns the
/// interval's length.
fn for_each_substep(
    rec: &Recording,
    k: usize,
    hold: CommandHold,
    h_max: f64,
    mut step: impl FnMut((f64, f64), (f64, f64), f64),
) -> f64 {
    let span = rec.t[k] - rec.t[k - 1];
    let m = (span / h_max).ceil().max(1.0) as usize;
    let h = span / m as f64;
    let ua = (rec.v_ref[k - 1], rec.w_ref[k - 1]);
    let ub = match hold {
        CommandHold::Zoh => ua,
        CommandHold::Sampled => (rec.v_ref[k], rec.w_ref[k]),
    };
    let at = |f: f64| (ua.0 + f * (ub.0 - ua.0), ua.1 + f * (ub.1 - ua.1));
    for j in 0..m {
        step(at(j as f64 / m as f64), at((j + 1) as f64 / m as f64), h);
    }
    span
}

/// Integration sub-step for θ: a fifth of the faster time constant (θ1/θ4, θ2/θ6), at most
/// [`MAX_SUBSTEP`] and at least [`MIN_SUBSTEP`]. RK4's error per step of e^{−h/τ} at h = τ/5 is
/// 2.5e-6 of the state, so a step response stays within 1e-5 of its final value (test), far
/// below any measurement's noise.
pub fn substep(theta: &[f64; 6]) -> f64 {
    let tau = (theta[0] / theta[3]).abs().min((theta[1] / theta[5]).abs());
    if tau.is_finite() && tau > 0.0 {
        (tau / 5.0).clamp(MIN_SUBSTEP, MAX_SUBSTEP)
    } else {
        MAX_SUBSTEP
    }
}

/// Checks θ: six finite values with θ1, θ2 ≠ 0.
///
/// # Errors
/// [`Error::InvalidSetting`] otherwise.
pub fn check_theta(theta: &[f64]) -> Result<[f64; 6]> {
    let th: [f64; 6] = theta
        .try_into()
        .map_err(|_| Error::InvalidSetting(format!("θ must have 6 values, got {}", theta.len())))?;
    if th.iter().any(|x| !x.is_finite()) || th[0] == 0.0 || th[1] == 0.0 {
        return Err(Error::InvalidSetting(format!(
            "θ must be finite with θ1, θ2 ≠ 0, got {th:?}"
        )));
    }
    Ok(th)
}

/// What both simulations check and read first.
struct Setup {
    th: [f64; 6],
    v0: f64,
    w0: f64,
    n: usize,
    hold: CommandHold,
    avg: bool,
}

/// Checks θ, the initial state and the recording, and reads how it holds and samples.
fn setup(theta: &[f64], rec: &Recording, initial: &[f64]) -> Result<Setup> {
    let th = check_theta(theta)?;
    let &[v0, w0] = initial else {
        return Err(Error::InvalidSetting(format!(
            "initial state must be [v, ω], got {} values",
            initial.len()
        )));
    };
    let n = rec.len();
    if n == 0 {
        return Err(Error::InvalidSetting("the recording is empty".into()));
    }
    Ok(Setup {
        th,
        v0,
        w0,
        n,
        hold: rec.command_hold(),
        avg: rec.velocity_sampling() == VelocitySampling::WindowAverage,
    })
}

/// Free-run simulation of (v, ω) on the recording's time base from its commands, starting at
/// `initial = [v0, ω0]`.
///
/// Output samples follow the recording's velocity sampling: instantaneous values at t_k, or,
/// for window averages, the mean over [t_{k−1}, t_k] (the first sample is the initial state).
///
/// # Errors
/// [`Error::InvalidSetting`] for a bad θ or initial state, or an empty recording.
pub fn simulate(theta: &[f64], rec: &Recording, initial: &[f64]) -> Result<[Vec<f64>; 2]> {
    let Setup {
        th,
        v0,
        w0,
        n,
        hold,
        avg,
    } = setup(theta, rec, initial)?;
    let mut v_out = Vec::with_capacity(n);
    let mut w_out = Vec::with_capacity(n);
    let h_max = substep(&th);
    let [t1, t2, t3, t4, t5, t6] = th;
    let (i1, i2) = (1.0 / t1, 1.0 / t2);
    // eq. 2.19 as `accel`, multiplying by 1/θ1, 1/θ2 (the step's critical path).
    let f = |x: &[f64; 2], u: (f64, f64)| {
        let [v, w] = *x;
        [
            (t3 * w * w - t4 * v + u.0) * i1,
            (-t5 * v * w - t6 * w + u.1) * i2,
        ]
    };
    let mut x = [v0, w0];
    v_out.push(v0);
    w_out.push(w0);
    for k in 1..n {
        let mut q = [0.0; 2];
        let span = for_each_substep(rec, k, hold, h_max, |u0, u1, h| {
            rk4_step(f, &mut x, &mut q, u0, u1, h);
        });
        let y = if avg { q.map(|i| i / span) } else { x };
        v_out.push(y[0]);
        w_out.push(y[1]);
    }
    Ok([v_out, w_out])
}

/// Number of sensitivity columns: θ1…θ6, then v0, ω0.
const NS: usize = 8;
/// Augmented state: v, ω, then S row-major (∂v/∂p, ∂ω/∂p).
const NZ: usize = 2 + 2 * NS;

/// Derivative of the augmented state z = (v, ω, S) for commands u.
#[inline]
fn augmented_rhs(theta: &[f64; 6], inv: [f64; 2], z: &[f64; NZ], u: (f64, f64)) -> [f64; NZ] {
    let [_, _, t3, t4, t5, t6] = *theta;
    let [i1, i2] = inv;
    let (v, w) = (z[0], z[1]);
    let (dv, dw) = (
        (t3 * w * w - t4 * v + u.0) * i1,
        (-t5 * v * w - t6 * w + u.1) * i2,
    );
    let a = [
        [-t4 * i1, 2.0 * t3 * w * i1],
        [-t5 * w * i2, -(t5 * v + t6) * i2],
    ];
    let mut out = [0.0; NZ];
    out[0] = dv;
    out[1] = dw;
    for j in 0..NS {
        let (sv, sw) = (z[2 + j], z[2 + NS + j]);
        out[2 + j] = a[0][0] * sv + a[0][1] * sw;
        out[2 + NS + j] = a[1][0] * sv + a[1][1] * sw;
    }
    out[2] += -dv * i1;
    out[2 + 2] += w * w * i1;
    out[2 + 3] += -v * i1;
    out[2 + NS + 1] += -dw * i2;
    out[2 + NS + 4] += -v * w * i2;
    out[2 + NS + 5] += -w * i2;
    out
}

/// Free-run simulation as [`simulate`], with the output sensitivities to θ (n × 6 per channel)
/// and to the initial state (n × 2 per channel), from the forward sensitivity equations in the
/// module doc, integrated by the same RK4 sub-steps.
///
/// # Errors
/// As [`simulate`].
pub fn simulate_with_sensitivities(
    theta: &[f64],
    rec: &Recording,
    initial: &[f64],
) -> Result<([Vec<f64>; 2], Sensitivities)> {
    let Setup {
        th,
        v0,
        w0,
        n,
        hold,
        avg,
    } = setup(theta, rec, initial)?;
    let h_max = substep(&th);
    let mut z = [0.0; NZ];
    z[0] = v0;
    z[1] = w0;
    z[2 + 6] = 1.0; // ∂v/∂v0
    z[2 + NS + 7] = 1.0; // ∂ω/∂ω0
    let mut y = [Vec::with_capacity(n), Vec::with_capacity(n)];
    let mut sens = [DMatrix::zeros(n, NS), DMatrix::zeros(n, NS)];
    let store = |k: usize,
                 x: &[f64; NZ],
                 scale: f64,
                 y: &mut [Vec<f64>; 2],
                 sens: &mut [DMatrix<f64>; 2]| {
        for ch in 0..2 {
            y[ch].push(x[ch] * scale);
            for j in 0..NS {
                sens[ch][(k, j)] = x[2 + ch * NS + j] * scale;
            }
        }
    };
    store(0, &z, 1.0, &mut y, &mut sens);
    let inv = [1.0 / th[0], 1.0 / th[1]];
    let f = |z: &[f64; NZ], u: (f64, f64)| augmented_rhs(&th, inv, z, u);
    for k in 1..n {
        let mut q = [0.0; NZ];
        let span = for_each_substep(rec, k, hold, h_max, |u0, u1, h| {
            rk4_step(f, &mut z, &mut q, u0, u1, h);
        });
        if avg {
            store(k, &q, 1.0 / span, &mut y, &mut sens);
        } else {
            store(k, &z, 1.0, &mut y, &mut sens);
        }
    }
    let [sv, sw] = sens;
    let split = |s: DMatrix<f64>| (s.columns(0, 6).into_owned(), s.columns(6, 2).into_owned());
    let (tv, iv) = split(sv);
    let (tw, iw) = split(sw);
    Ok((
        y,
        Sensitivities {
            theta: vec![tv, tw],
            initial: vec![iv, iw],
        },
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Straight-drive step response (ω = 0): θ1 v̇ = u − θ4 v → v(t) = (u/θ4)(1 − e^{−θ4 t/θ1}).
    /// Returns the largest error relative to the final value u/θ4, checking ω stays 0.
    fn step_error(theta: [f64; 6], dt: f64, u: f64) -> f64 {
        let t: Vec<f64> = (0..=20).map(|k| k as f64 * dt).collect();
        let n = t.len();
        let rec = Recording::new(
            "step",
            t.clone(),
            vec![u; n],
            vec![0.0; n],
            vec![0.0; n],
            vec![0.0; n],
        )
        .expect("valid");
        let [v, w] = simulate(&theta, &rec, &[0.0, 0.0]).expect("sim");
        assert!(w.iter().all(|x| *x == 0.0));
        let final_value = u / theta[3];
        t.iter()
            .zip(&v)
            .map(|(tk, vk)| {
                (vk - final_value * (1.0 - (-theta[3] * tk / theta[0]).exp())).abs() / final_value
            })
            .fold(0.0f64, f64::max)
    }

    #[test]
    fn a_decaying_state_reaches_zero_instead_of_stalling_subnormal() {
        // ẋ = −x/τ from 1 with h = τ/5: RK4 follows e^{−t/τ} (its per-step factor, to 1e-12),
        // and once below the flush level the state is exactly 0 — never a subnormal number,
        // where it would otherwise stay (the increment rounds to nothing there).
        let (tau, h): (f64, f64) = (0.02, 0.004);
        let mut x = [1.0];
        let mut q = [0.0];
        let z = h / tau;
        let factor = 1.0 - z + z * z / 2.0 - z.powi(3) / 6.0 + z.powi(4) / 24.0;
        for k in 1..=5000 {
            rk4_step(
                |x: &[f64; 1], _u: (f64, f64)| [-x[0] / tau],
                &mut x,
                &mut q,
                (0.0, 0.0),
                (0.0, 0.0),
                h,
            );
            assert!(x[0] == 0.0 || x[0].is_normal(), "step {k}: {:e}", x[0]);
            if k == 100 {
                let expect = factor.powi(100);
                assert!((x[0] / expect - 1.0).abs() < 1e-12, "{} vs {expect}", x[0]);
            }
        }
        assert_eq!(x[0], 0.0);
    }

    #[test]
    fn step_response_of_a_straight_drive_is_first_order() {
        // Pioneer θ (τ = 0.26 s) at 10 Hz: sub-step capped at 20 ms, error below 1e-6.
        let worst = step_error([0.26, 0.25, -0.0005, 0.9965, 0.0026, 1.0768], 0.1, 0.5);
        assert!(worst < 1e-6, "{worst:e}");
    }

    #[test]
    fn a_fast_robot_at_a_fifth_of_its_time_constant_stays_within_1e_5() {
        // Khepera III θ: τ = θ1/θ4 = 23 ms, sampled at 20 ms → 5 RK4 sub-steps of 4.5 ms.
        let worst = step_error([0.0228, 0.0568, -0.0001, 1.0030, 0.0732, 0.9981], 0.02, 0.3);
        assert!(worst < 1e-5, "{worst:e}");
        // And it is not a trivially tiny error: h = τ/5 leaves a measurable one.
        assert!(worst > 1e-8, "{worst:e}");
    }

    #[test]
    fn sensitivities_match_central_differences() {
        // A turning, accelerating recording so that every θ (also θ3, θ5) acts.
        let theta = [0.26, 0.25, -0.05, 0.9965, 0.08, 1.0768];
        let n = 80;
        let t: Vec<f64> = (0..n).map(|k| k as f64 * 0.1).collect();
        let vr: Vec<f64> = t.iter().map(|&x| 0.4 + 0.3 * (1.3 * x).sin()).collect();
        let wr: Vec<f64> = t.iter().map(|&x| 1.2 * (0.7 * x).cos()).collect();
        for avg in [false, true] {
            let mut rec = Recording::new(
                "s",
                t.clone(),
                vr.clone(),
                wr.clone(),
                vec![0.0; n],
                vec![0.0; n],
            )
            .expect("valid");
            rec.set_meta("command_hold", "zoh");
            if avg {
                rec.set_meta("velocity_sampling", "window_average");
            }
            let x0 = [0.1, -0.2];
            let (y, s) = simulate_with_sensitivities(&theta, &rec, &x0).expect("sim");
            let plain = simulate(&theta, &rec, &x0).expect("sim");
            for ch in 0..2 {
                for k in 0..n {
                    approx::assert_abs_diff_eq!(y[ch][k], plain[ch][k], epsilon = 1e-12);
                }
            }
            // Central differences with the integration grid held fixed (h scaled with θ).
            for j in 0..8 {
                let mut p: Vec<f64> = theta.iter().chain(&x0).copied().collect();
                let h = 1e-6 * p[j].abs().max(1e-2);
                p[j] += h;
                let up = simulate(&p[..6], &rec, &p[6..]).expect("sim");
                p[j] -= 2.0 * h;
                let dn = simulate(&p[..6], &rec, &p[6..]).expect("sim");
                for ch in 0..2 {
                    for k in 0..n {
                        let fd = (up[ch][k] - dn[ch][k]) / (2.0 * h);
                        let an = if j < 6 {
                            s.theta[ch][(k, j)]
                        } else {
                            s.initial[ch][(k, j - 6)]
                        };
                        assert!(
                            (fd - an).abs() <= 1e-6 * (1.0 + fd.abs()),
                            "avg {avg} ch {ch} k {k} p {j}: fd {fd} analytic {an}"
                        );
                    }
                }
            }
        }
    }
}
