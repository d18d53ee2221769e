//! The model `vw-pd-coulomb`: Laut 2011 eq. 2.19 with a dry (Coulomb) friction per channel.
//!
//! ```text
//! θ1 v̇ = v_ref + θ3 ω² − θ4 v − θ7 sgn_ε(v)          sgn_ε(x) = tanh(x/ε)
//! θ2 ω̇ = ω_ref − θ5 v ω − θ6 ω − θ8 sgn_ε(ω)         ε = 2 mm/s, 0.01 rad/s
//! ```
//!
//! θ7 = `v_coulomb` [m/s] and θ8 = `w_coulomb` [rad/s] are the friction in command units: the
//! command the robot needs before it moves. The smoothing ε is wheelid's (its simulator's
//! `coulomb_friction` effect and its `Extended` model use the same), so a recording of either
//! is fitted by this model without a model error.
//!
//! # Regression
//! The model is linear in θ, channel by channel, as VwPd's eq. 4.1–4.2 plus one column:
//! ```text
//! v_ref = [ v̇  −ω²  v  sgn_ε(v) ] · [θ1 θ3 θ4 θ7]ᵀ
//! ω_ref = [ ω̇  v·ω  ω  sgn_ε(ω) ] · [θ2 θ5 θ6 θ8]ᵀ
//! ```
//! built from a [`Conditioned`] recording as `wheelid_models::regressor` builds VwPd's: every
//! column and the command pass through the same zero-phase filter F, on the rows of
//! [`Conditioned::valid_range`], and the non-linear columns are formed from the aligned
//! measurements before filtering, like VwPd's ω² and v·ω: the sign column is F(sgn_ε(v)).
//! The friction terms are the least well determined: their information is in the zero
//! crossings, where the measurement noise also goes through tanh's steep slope (an
//! errors-in-variables effect that tends to pull them low). On the simulated Burger
//! (`tests/identify.rs`, seeds 1–6 and 11) ordinary least squares put them within −6…+1 % at
//! its 1 mm/s of velocity noise per wheel, within −11…+5 % at 3 mm/s. (The sign of the
//! filtered velocity, tried instead, did no better: the filter's own error at the crossings
//! costs as much.)
//!
//! # Simulation
//! [`simulate`] integrates with the host's classical RK4 (`wheelid_models::dynamics::rk4_step`)
//! at a fifth of the fastest time constant — θ1/θ4, θ2/θ6, and the friction's θ1 ε/θ7, θ2 ε/θ8
//! near zero speed — at most 20 ms and at least 0.1 ms; commands are held (zero-order hold) or linearly interpolated as the recording says,
//! and the outputs are instantaneous values or window averages likewise: the semantics of
//! `wheelid_models::dynamics`.

use nalgebra::{DMatrix, DVector};
use wheelid_core::{
    ChannelInfo, ChannelRegression, CommandHold, Conditioned, DynamicModel, Error, ParamInfo,
    Recording, RegressorModel, Result, Simulation, VelocitySampling,
};
use wheelid_models::dynamics::rk4_step;

/// Smoothing ε of the friction's sign: [2 mm/s, 0.01 rad/s] (wheelid's value).
pub const FRICTION_EPS: [f64; 2] = [0.002, 0.01];
/// Longest integration sub-step \[s\].
pub const MAX_SUBSTEP: f64 = 0.02;
/// Shortest integration sub-step \[s\] (a θ that asks for less is not a robot's).
pub const MIN_SUBSTEP: f64 = 1e-4;

/// The eight parameters: eq. 2.19's six (as VwPd names them), then the two friction terms.
pub const PARAMS: [ParamInfo; 8] = [
    ParamInfo {
        name: "theta1",
        unit: "s",
        description: "forward inertia time constant (mass, actuator inertia, PD gains)",
    },
    ParamInfo {
        name: "theta2",
        unit: "s",
        description: "rotational inertia time constant (I_z + m b², actuator inertia, PD gains)",
    },
    ParamInfo {
        name: "theta3",
        unit: "s·m/rad²",
        description: "centripetal coupling ω² → v (mass × centre-of-mass offset b)",
    },
    ParamInfo {
        name: "theta4",
        unit: "-",
        description: "forward damping: v_ref/v in steady state (≈ 1)",
    },
    ParamInfo {
        name: "theta5",
        unit: "s/m",
        description: "coupling v·ω → ω (mass × centre-of-mass offset b)",
    },
    ParamInfo {
        name: "theta6",
        unit: "-",
        description: "rotational damping: ω_ref/ω in steady state (≈ 1)",
    },
    ParamInfo {
        name: "v_coulomb",
        unit: "m/s",
        description: "dry friction of the forward channel, in command units (θ7)",
    },
    ParamInfo {
        name: "w_coulomb",
        unit: "rad/s",
        description: "dry friction of the rotational channel, in command units (θ8)",
    },
];

/// The two channels: v uses (θ1, θ3, θ4, θ7), ω uses (θ2, θ5, θ6, θ8), in regressor-column
/// order.
pub const CHANNELS: [ChannelInfo; 2] = [
    ChannelInfo {
        name: "v",
        command: "v_ref",
        params: &[0, 2, 3, 6],
    },
    ChannelInfo {
        name: "w",
        command: "w_ref",
        params: &[1, 4, 5, 7],
    },
];

/// The smoothed sign tanh(x/ε).
#[inline]
pub fn sgn(x: f64, eps: f64) -> f64 {
    (x / eps).tanh()
}

/// (v̇ [m/s²], ω̇ [rad/s²]) of the model for θ (eight values), state (v, ω) and commands
/// (v_ref, ω_ref).
#[inline]
pub fn accel(theta: &[f64; 8], v: f64, w: f64, v_ref: f64, w_ref: f64) -> (f64, f64) {
    let [t1, t2, t3, t4, t5, t6, t7, t8] = *theta;
    (
        (v_ref + t3 * w * w - t4 * v - t7 * sgn(v, FRICTION_EPS[0])) / t1,
        (w_ref - t5 * v * w - t6 * w - t8 * sgn(w, FRICTION_EPS[1])) / t2,
    )
}

/// Checks θ: eight finite values with θ1, θ2 ≠ 0.
///
/// # Errors
/// [`Error::InvalidSetting`] otherwise.
pub fn check_theta(theta: &[f64]) -> Result<[f64; 8]> {
    let th: [f64; 8] = theta.try_into().map_err(|_| {
        Error::InvalidSetting(format!(
            "vw-pd-coulomb: θ must have 8 values (θ1…θ6, v_coulomb, w_coulomb), got {}",
            theta.len()
        ))
    })?;
    if th.iter().any(|x| !x.is_finite()) || th[0] == 0.0 || th[1] == 0.0 {
        return Err(Error::InvalidSetting(format!(
            "vw-pd-coulomb: θ must be finite with θ1, θ2 ≠ 0, got {th:?}"
        )));
    }
    Ok(th)
}

/// Integration sub-step for θ \[s\]: a fifth of the fastest of θ1/θ4, θ2/θ6 and the friction's
/// θ1 ε_v/θ7, θ2 ε_ω/θ8 (its slope at zero speed), within [[`MIN_SUBSTEP`], [`MAX_SUBSTEP`]].
pub fn substep(theta: &[f64; 8]) -> f64 {
    let [t1, t2, _, t4, _, t6, t7, t8] = theta.map(f64::abs);
    let tau = [
        t1 / t4,
        t2 / t6,
        t1 * FRICTION_EPS[0] / t7,
        t2 * FRICTION_EPS[1] / t8,
    ]
    .into_iter()
    .fold(f64::INFINITY, f64::min);
    if tau.is_finite() && tau > 0.0 {
        (tau / 5.0).clamp(MIN_SUBSTEP, MAX_SUBSTEP)
    } else {
        MAX_SUBSTEP
    }
}

/// Free-run simulation of (v, ω) on the recording's time base from its commands, starting at
/// `initial = [v0 [m/s], ω0 [rad/s]]`: two series of length n. With window-averaged velocities
/// sample k is the mean over [t_{k−1}, t_k] (sample 0 is the initial state).
///
/// # Errors
/// [`Error::InvalidSetting`] for a bad θ or initial state, or an empty recording.
pub fn simulate(theta: &[f64], rec: &Recording, initial: &[f64]) -> Result<[Vec<f64>; 2]> {
    let th = check_theta(theta)?;
    let &[v0, w0] = initial else {
        return Err(Error::InvalidSetting(format!(
            "vw-pd-coulomb: initial state must be [v, ω], got {} values",
            initial.len()
        )));
    };
    let n = rec.len();
    if n == 0 {
        return Err(Error::InvalidSetting("the recording is empty".into()));
    }
    let sampled = rec.command_hold() == CommandHold::Sampled;
    let average = rec.velocity_sampling() == VelocitySampling::WindowAverage;
    let h_max = substep(&th);
    let f = |x: &[f64; 2], u: (f64, f64)| {
        let (dv, dw) = accel(&th, x[0], x[1], u.0, u.1);
        [dv, dw]
    };
    let mut x = [v0, w0];
    let mut out = [Vec::with_capacity(n), Vec::with_capacity(n)];
    out[0].push(v0);
    out[1].push(w0);
    for k in 1..n {
        let span = rec.t[k] - rec.t[k - 1];
        let m = (span / h_max).ceil().max(1.0) as usize;
        let h = span / m as f64;
        let ua = (rec.v_ref[k - 1], rec.w_ref[k - 1]);
        let ub = if sampled {
            (rec.v_ref[k], rec.w_ref[k])
        } else {
            ua
        };
        let at = |s: f64| (ua.0 + s * (ub.0 - ua.0), ua.1 + s * (ub.1 - ua.1));
        let mut q = [0.0; 2];
        for j in 0..m {
            let (s0, s1) = (j as f64 / m as f64, (j + 1) as f64 / m as f64);
            rk4_step(f, &mut x, &mut q, at(s0), at(s1), h);
        }
        let y = if average { q.map(|i| i / span) } else { x };
        out[0].push(y[0]);
        out[1].push(y[1]);
    }
    Ok(out)
}

/// The two filtered regressions of the module docs from conditioned data, on the rows of
/// [`Conditioned::valid_range`]: per channel an n × 4 regressor and the filtered, aligned
/// command.
///
/// # Errors
/// [`Error::TooShort`] if the recording is shorter than the filter padding.
pub fn regression(data: &Conditioned<'_>) -> Result<Vec<ChannelRegression>> {
    let keep = data.valid_range();
    let n = keep.len();
    let vf = data.smooth(data.v())?;
    let wf = data.smooth(data.w())?;
    let dv = data.differentiate(&vf)?;
    let dw = data.differentiate(&wf)?;
    let w2: Vec<f64> = data.w().iter().map(|w| -w * w).collect();
    let vw: Vec<f64> = data.v().iter().zip(data.w()).map(|(v, w)| v * w).collect();
    let sv: Vec<f64> = data.v().iter().map(|&v| sgn(v, FRICTION_EPS[0])).collect();
    let sw: Vec<f64> = data.w().iter().map(|&w| sgn(w, FRICTION_EPS[1])).collect();
    let w2f = data.smooth(&w2)?;
    let vwf = data.smooth(&vw)?;
    let svf = data.smooth(&sv)?;
    let swf = data.smooth(&sw)?;
    let yv = data.smooth(data.v_ref())?;
    let yw = data.smooth(data.w_ref())?;
    let mat = |cols: [&Vec<f64>; 4]| DMatrix::from_fn(n, 4, |i, j| cols[j][keep.start + i]);
    let kept = |y: &[f64]| DVector::from_column_slice(&y[keep.clone()]);
    Ok(vec![
        ChannelRegression {
            channel: "v",
            params: CHANNELS[0].params.to_vec(),
            x: mat([&dv, &w2f, &vf, &svf]),
            y: kept(&yv),
        },
        ChannelRegression {
            channel: "w",
            params: CHANNELS[1].params.to_vec(),
            x: mat([&dw, &vwf, &wf, &swf]),
            y: kept(&yw),
        },
    ])
}

/// The model `vw-pd-coulomb` (module docs): eight parameters, channels v and w.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct VwPdCoulomb;

impl VwPdCoulomb {
    /// The name under which the plugin registers it (the `[model] type`).
    pub const NAME: &'static str = "vw-pd-coulomb";
}

impl DynamicModel for VwPdCoulomb {
    fn name(&self) -> &str {
        Self::NAME
    }
    fn params(&self) -> &[ParamInfo] {
        &PARAMS
    }
    fn channels(&self) -> &[ChannelInfo] {
        &CHANNELS
    }
    fn simulate(&self, theta: &[f64], rec: &Recording, initial: &[f64]) -> Result<Simulation> {
        Ok(simulate(theta, rec, initial)?.to_vec())
    }
}

impl RegressorModel for VwPdCoulomb {
    fn regression(&self, data: &Conditioned<'_>) -> Result<Vec<ChannelRegression>> {
        regression(data)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;
    use wheelid_core::ConditionSettings;
    use wheelid_core::condition::condition;

    /// The Burger's θ with its friction (see `crate::burger`).
    fn burger() -> [f64; 8] {
        let [t1, t2, t3, t4, t5, t6] = crate::burger::BURGER.theta();
        let [vc, wc] = crate::burger::BURGER.coulomb();
        [t1, t2, t3, t4, t5, t6, vc, wc]
    }

    fn straight(n: usize, dt: f64, u: f64, average: bool) -> Recording {
        let t: Vec<f64> = (0..n).map(|k| k as f64 * dt).collect();
        let mut rec = Recording::new(
            "straight",
            t,
            vec![u; n],
            vec![0.0; n],
            vec![0.0; n],
            vec![0.0; n],
        )
        .expect("valid");
        if average {
            rec.set_meta("velocity_sampling", "window_average");
        }
        rec
    }

    /// Straight line, ω = 0, constant v_ref above the friction: for v ≫ ε the sign is 1 and
    /// θ1 v̇ = v_ref − θ7 − θ4 v, so v(t) = v∞ + (v0 − v∞) e^{−θ4 t/θ1}, v∞ = (v_ref − θ7)/θ4.
    #[test]
    fn straight_drive_follows_the_closed_form() {
        let th = burger();
        let (dt, u) = (1.0 / 30.0, 0.2);
        let a = th[3] / th[0];
        let v_inf = (u - th[6]) / th[3];
        let rec = straight(91, dt, u, false);
        // From v0 = 5 cm/s (25 ε: tanh = 1 to machine precision) the closed form is exact.
        let v0 = 0.05;
        let [v, w] = simulate(&th, &rec, &[v0, 0.0]).expect("sim");
        assert!(w.iter().all(|x| *x == 0.0), "ω stays 0: sgn_ε(0) = 0");
        for (tk, vk) in rec.t.iter().zip(&v) {
            let want = v_inf + (v0 - v_inf) * (-a * tk).exp();
            assert_abs_diff_eq!(*vk, want, epsilon = 1e-7);
        }
        // From rest, v(t) = (v_ref − θ7)/θ4 (1 − e^{−θ4 t/θ1}) but for the first millimetres
        // per second, where tanh(v/ε) < 1 lets the robot start a little sooner: the lead is
        // about (θ7/θ1)·(ε/v̇(0)) = (0.013 m/s²)·(1.5 ms) ≈ 2e-5 m/s, 1e-4 of v∞.
        let [v, _] = simulate(&th, &rec, &[0.0, 0.0]).expect("sim");
        let mut worst = 0.0f64;
        for (tk, vk) in rec.t.iter().zip(&v) {
            let want = v_inf * (1.0 - (-a * tk).exp());
            assert!(
                *vk >= want - 1e-12,
                "the smoothed sign only helps: t = {tk}"
            );
            worst = worst.max((vk - want).abs() / v_inf);
        }
        assert!(worst < 2e-4 && worst > 1e-7, "{worst:e}");
        // Window averages: the mean of the closed form over each period.
        let rec = straight(91, dt, u, true);
        let [v, _] = simulate(&th, &rec, &[v0, 0.0]).expect("sim");
        for (vk, t) in v.iter().skip(1).zip(rec.t.windows(2)) {
            let mean = v_inf + (v0 - v_inf) * ((-a * t[0]).exp() - (-a * t[1]).exp()) / (a * dt);
            assert_abs_diff_eq!(*vk, mean, epsilon = 1e-7);
        }
        // Below the friction the robot creeps at most ε-ish: v_ref = θ7/2 holds v ≈ 0.
        let rec = straight(91, dt, th[6] / 2.0, false);
        let [v, _] = simulate(&th, &rec, &[0.0, 0.0]).expect("sim");
        assert!(v.iter().all(|x| x.abs() < FRICTION_EPS[0]), "{v:?}");
    }

    #[test]
    fn bad_theta_and_initial_state_are_errors() {
        let rec = straight(10, 0.1, 0.1, false);
        let th = burger();
        assert!(simulate(&th[..6], &rec, &[0.0, 0.0]).is_err());
        let mut bad = th;
        bad[0] = 0.0;
        assert!(simulate(&bad, &rec, &[0.0, 0.0]).is_err());
        bad = th;
        bad[7] = f64::NAN;
        assert!(simulate(&bad, &rec, &[0.0, 0.0]).is_err());
        assert!(simulate(&th, &rec, &[0.0]).is_err());
        assert_eq!(VwPdCoulomb.params().len(), 8);
        assert_eq!(VwPdCoulomb.params()[6].name, "v_coulomb");
        assert_eq!(VwPdCoulomb.params()[7].unit, "rad/s");
    }

    /// A hand-built case where every column is known in closed form: v a ramp (filtered and
    /// differentiated exactly by a zero-phase, unit-DC-gain filter and a central stencil),
    /// ω constant and negative, commands built from the model so that Φθ = y.
    #[test]
    fn regression_columns_on_a_hand_built_ramp() {
        let th = [0.15, 0.12, -0.01, 1.05, 0.02, 0.98, 0.004, 0.03];
        let (n, dt) = (300, 0.05);
        let t: Vec<f64> = (0..n).map(|k| k as f64 * dt).collect();
        let (v0, slope, w0) = (0.05, 0.01, -0.4);
        let v: Vec<f64> = t.iter().map(|t| v0 + slope * t).collect();
        let w = vec![w0; n];
        // Model: v_ref = θ1 v̇ − θ3 ω² + θ4 v + θ7 sgn(v); ω_ref = θ2·0 + θ5 v ω + θ6 ω + θ8 sgn(ω).
        let v_ref: Vec<f64> = v
            .iter()
            .map(|v| th[0] * slope - th[2] * w0 * w0 + th[3] * v + th[6])
            .collect();
        let w_ref: Vec<f64> = v
            .iter()
            .map(|v| th[4] * v * w0 + th[5] * w0 - th[7])
            .collect();
        let mut rec =
            Recording::new("ramp", t.clone(), v_ref.clone(), w_ref.clone(), v, w).expect("ok");
        rec.set_meta("command_hold", "sampled");
        let data = condition(&rec, None, 1.0, &ConditionSettings::default()).expect("ok");
        let regs = VwPdCoulomb.regression(&data).expect("regression");
        let keep = data.valid_range();
        assert!(keep.len() > 200, "{keep:?}");
        let [rv, rw] = [&regs[0], &regs[1]];
        assert_eq!((rv.channel, rw.channel), ("v", "w"));
        assert_eq!(rv.params, vec![0, 2, 3, 6]);
        assert_eq!(rw.params, vec![1, 4, 5, 7]);
        assert_eq!(
            (rv.x.shape(), rw.x.shape()),
            ((keep.len(), 4), (keep.len(), 4))
        );
        let mut worst = 0.0f64;
        for (i, k) in keep.enumerate() {
            let vk = v0 + slope * t[k];
            let want_v = [slope, -w0 * w0, vk, 1.0];
            let want_w = [0.0, vk * w0, w0, -1.0];
            for j in 0..4 {
                worst = worst.max((rv.x[(i, j)] - want_v[j]).abs());
                worst = worst.max((rw.x[(i, j)] - want_w[j]).abs());
            }
            worst = worst.max((rv.y[i] - v_ref[k]).abs());
            worst = worst.max((rw.y[i] - w_ref[k]).abs());
        }
        // Exact but for the zero-phase filter's edge transient on a ramp (its odd extension
        // matches the ramp, its initial state only a constant), decayed to < 1e-5 two cut-off
        // periods inside the ends.
        assert!(worst < 1e-5, "{worst:e}");
        // And the columns carry θ: Φ_c θ_c = y_c.
        for r in &regs {
            let theta_c = DVector::from_iterator(4, r.params.iter().map(|&p| th[p]));
            let res = (&r.x * theta_c - &r.y).amax();
            assert!(res < 1e-5, "{}: {res:e}", r.channel);
        }
    }

    #[test]
    fn substep_resolves_the_friction_near_zero_speed() {
        let th = burger();
        let h = substep(&th);
        // θ1/θ4 = 0.144 s, friction θ1 ε/θ7 = 0.153 s, θ2 ε/θ8 = 0.061 s → 12 ms.
        assert_abs_diff_eq!(h, th[1] * FRICTION_EPS[1] / th[7] / 5.0, epsilon = 1e-12);
        let mut no_friction = th;
        no_friction[6] = 0.0;
        no_friction[7] = 0.0;
        // Then θ1/θ4/5 = 29 ms, capped at 20 ms.
        assert_eq!(substep(&no_friction), MAX_SUBSTEP);
        no_friction[0] = 0.05;
        assert_abs_diff_eq!(substep(&no_friction), 0.05 / th[3] / 5.0, epsilon = 1e-12);
    }
}
