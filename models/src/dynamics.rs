//! The velocity dynamics of Laut 2011 eq. 2.19 (rows 4–5) and their free-run simulation.
//!
//! ```text
//! v̇ = (θ3/θ1) ω² − (θ4/θ1) v + (1/θ1) v_ref
//! ω̇ = −(θ5/θ2) v ω − (θ6/θ2) ω + (1/θ2) ω_ref
//! ```
//!
//! The simulation integrates with classical fourth-order Runge–Kutta at a sub-step of a
//! twentieth of the model's faster time constant ([`substep`]), with the commands held (zero-order hold) or linearly interpolated
//! between samples as the recording says, and reports instantaneous values or window averages
//! (the integral of the velocity over the sample period, divided by it) likewise.

use wheelid_core::{CommandHold, Error, Recording, Result, VelocitySampling};

/// Longest integration sub-step [s].
pub const MAX_SUBSTEP: f64 = 0.02;

/// (v̇, ω̇) of eq. 2.19 for θ (length 6), state (v, ω) and commands (v_ref, ω_ref).
#[inline]
pub fn accel(theta: &[f64; 6], v: f64, w: f64, v_ref: f64, w_ref: f64) -> (f64, f64) {
    let [t1, t2, t3, t4, t5, t6] = *theta;
    (
        (t3 * w * w - t4 * v + v_ref) / t1,
        (-t5 * v * w - t6 * w + w_ref) / t2,
    )
}

/// One RK4 step of length `h` for the state (v, ω, ∫v, ∫ω) with commands varying linearly from
/// `u0` to `u1` over the step; the integrals give window averages to the same order.
#[inline]
fn rk4(theta: &[f64; 6], s: [f64; 4], u0: (f64, f64), u1: (f64, f64), h: f64) -> [f64; 4] {
    let um = ((u0.0 + u1.0) * 0.5, (u0.1 + u1.1) * 0.5);
    let f = |v: f64, w: f64, u: (f64, f64)| {
        let (dv, dw) = accel(theta, v, w, u.0, u.1);
        [dv, dw, v, w]
    };
    let k1 = f(s[0], s[1], u0);
    let k2 = f(s[0] + 0.5 * h * k1[0], s[1] + 0.5 * h * k1[1], um);
    let k3 = f(s[0] + 0.5 * h * k2[0], s[1] + 0.5 * h * k2[1], um);
    let k4 = f(s[0] + h * k3[0], s[1] + h * k3[1], u1);
    std::array::from_fn(|i| s[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]))
}

/// Integration sub-step for θ: a twentieth of the faster time constant (θ1/θ4, θ2/θ6), at most
/// [`MAX_SUBSTEP`]; the global RK4 error of a step response is then about 2e-8 relative.
pub fn substep(theta: &[f64; 6]) -> f64 {
    let tau = (theta[0] / theta[3]).abs().min((theta[1] / theta[5]).abs());
    if tau.is_finite() && tau > 0.0 {
        (tau / 20.0).min(MAX_SUBSTEP)
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

/// Free-run simulation of (v, ω) on the recording's time base from its commands, starting at
/// `initial = [v0, ω0]`.
///
/// Output samples follow the recording's velocity sampling: instantaneous values at t_k, or,
/// for window averages, the mean over [t_{k−1}, t_k] (the first sample is the initial state).
///
/// # Errors
/// [`Error::InvalidSetting`] for a bad θ or initial state.
pub fn simulate(theta: &[f64], rec: &Recording, initial: &[f64]) -> Result<[Vec<f64>; 2]> {
    let th = check_theta(theta)?;
    let &[v0, w0] = initial else {
        return Err(Error::InvalidSetting(format!(
            "initial state must be [v, ω], got {} values",
            initial.len()
        )));
    };
    let n = rec.len();
    let hold = rec.command_hold();
    let avg = rec.velocity_sampling() == VelocitySampling::WindowAverage;
    let mut v_out = Vec::with_capacity(n);
    let mut w_out = Vec::with_capacity(n);
    let h_max = substep(&th);
    let mut s = [v0, w0, 0.0, 0.0];
    v_out.push(v0);
    w_out.push(w0);
    for k in 1..n {
        let span = rec.t[k] - rec.t[k - 1];
        let m = (span / h_max).ceil().max(1.0) as usize;
        let h = span / m as f64;
        let ua = (rec.v_ref[k - 1], rec.w_ref[k - 1]);
        let ub = match hold {
            CommandHold::Zoh => ua,
            CommandHold::Sampled => (rec.v_ref[k], rec.w_ref[k]),
        };
        s[2] = 0.0;
        s[3] = 0.0;
        for j in 0..m {
            let f0 = j as f64 / m as f64;
            let f1 = (j + 1) as f64 / m as f64;
            let u0 = (ua.0 + f0 * (ub.0 - ua.0), ua.1 + f0 * (ub.1 - ua.1));
            let u1 = (ua.0 + f1 * (ub.0 - ua.0), ua.1 + f1 * (ub.1 - ua.1));
            s = rk4(&th, s, u0, u1, h);
        }
        if avg {
            v_out.push(s[2] / span);
            w_out.push(s[3] / span);
        } else {
            v_out.push(s[0]);
            w_out.push(s[1]);
        }
    }
    Ok([v_out, w_out])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn step_response_of_a_straight_drive_is_first_order() {
        // With ω = 0: θ1 v̇ = v_ref − θ4 v → v(t) = (u/θ4)(1 − e^{−θ4 t/θ1}).
        let theta = [0.26, 0.25, -0.0005, 0.9965, 0.0026, 1.0768];
        let t: Vec<f64> = (0..=20).map(|k| k as f64 * 0.1).collect();
        let n = t.len();
        let rec = Recording::new(
            "s",
            t.clone(),
            vec![0.5; n],
            vec![0.0; n],
            vec![0.0; n],
            vec![0.0; n],
        )
        .expect("valid");
        let [v, w] = simulate(&theta, &rec, &[0.0, 0.0]).expect("sim");
        for (k, tk) in t.iter().enumerate() {
            let exact = 0.5 / theta[3] * (1.0 - (-theta[3] * tk / theta[0]).exp());
            approx::assert_abs_diff_eq!(v[k], exact, epsilon = 1e-8);
            assert_eq!(w[k], 0.0);
        }
    }
}
