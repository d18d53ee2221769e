//! Each optional effect of the simulated robot does what `robots/src/effects.rs` documents,
//! checked against closed-form numbers.
//!
//! Most tests run without the encoder model (`measurement_noise: false`, exact instantaneous
//! v, ω) and many on a "decoupled" Pioneer (θ3 = θ5 = 0), where eq. 2.19 splits into two
//! first-order lags θ1 v̇ = u_v − θ4 v and θ2 ω̇ = u_ω − θ6 ω with exact solutions for
//! piecewise-linear setpoints. The coupled steady states (θ3 ω², θ5 v ω, slip) are solved as
//! fixed points in the tests.

use approx::assert_relative_eq;
use wheelid_core::{Error, Recording};
use wheelid_robots::effects::{
    AccelerationLimit, CoulombFriction, GainDrift, InputDelay, MeasurementNoise, PayloadChange,
    SampleJitter, Slip, VelocitySaturation, WheelAsymmetry,
};
use wheelid_robots::{
    Effects, Excitation, RobotProfile, Signal, SimRobot, SimSettings, SumOfSines,
    simulate_recording,
};

// ---------------------------------------------------------------------------------------------
// Helpers
// ---------------------------------------------------------------------------------------------

/// Exact (no encoder model) settings.
fn exact(duration_s: f64, substeps: usize, effects: Effects) -> SimSettings {
    SimSettings {
        duration_s,
        seed: 1,
        substeps,
        measurement_noise: false,
        effects,
    }
}

fn constant(v: f64, w: f64) -> Excitation {
    Excitation {
        v_ref: Signal::Constant { value: v },
        w_ref: Signal::Constant { value: w },
    }
}

fn steps(v: &[f64], w: &[f64], hold_s: f64) -> Excitation {
    Excitation {
        v_ref: Signal::Steps {
            levels: v.to_vec(),
            hold_s,
        },
        w_ref: Signal::Steps {
            levels: w.to_vec(),
            hold_s,
        },
    }
}

/// The Pioneer with θ3 = θ5 = 0: v and ω are independent first-order lags.
fn decoupled() -> RobotProfile {
    let p = RobotProfile::pioneer3dx();
    let th = p.theta;
    RobotProfile {
        name: "pioneer3dx_decoupled".into(),
        theta: [th[0], th[1], 0.0, th[3], 0.0, th[5]],
        ..p
    }
}

fn run(profile: &RobotProfile, excitation: &Excitation, settings: &SimSettings) -> Recording {
    simulate_recording(profile, excitation, settings).expect("simulation runs")
}

/// Index of the sample at time `t` on an unjittered grid of period `dt`.
fn idx(t: f64, dt: f64) -> usize {
    (t / dt).round() as usize
}

/// Solution after `tau` of a ẋ = u0 + s·τ − b x from x(0) = x0.
fn lag(a: f64, b: f64, x0: f64, u0: f64, s: f64, tau: f64) -> f64 {
    let time_const = a / b;
    let particular = |tau: f64| (u0 + s * tau) / b - s * time_const / b;
    particular(tau) + (x0 - particular(0.0)) * (-tau / time_const).exp()
}

/// a ẋ = u(t) − b x from x(0) = 0, with u piecewise linear: on segment i (from its start time
/// on), u = u0 + slope·(t − start). Segments are (start, u0, slope), the first starting at 0.
fn lag_path(a: f64, b: f64, segments: &[(f64, f64, f64)], t: f64) -> f64 {
    let mut x = 0.0;
    for (i, &(t0, u0, slope)) in segments.iter().enumerate() {
        if t <= t0 {
            break;
        }
        let t1 = segments.get(i + 1).map_or(t, |next| next.0.min(t));
        x = lag(a, b, x, u0, slope, t1 - t0);
    }
    x
}

/// Steady state of eq. 2.19 with slip losses (module docs of effects.rs):
/// 0 = u_v + θ3 ω² − θ4 v − θ4 k_v v |ω|,   0 = u_ω − θ5 v ω − θ6 ω − θ6 k_w |v| ω.
fn steady(th: &[f64; 6], uv: f64, uw: f64, k_v: f64, k_w: f64) -> (f64, f64) {
    let (mut v, mut w) = (uv / th[3], uw / th[5]);
    for _ in 0..500 {
        v = (uv + th[2] * w * w) / (th[3] * (1.0 + k_v * w.abs()));
        w = uw / (th[4] * v + th[5] * (1.0 + k_w * v.abs()));
    }
    // It is a fixed point.
    let rv = uv + th[2] * w * w - th[3] * v - th[3] * k_v * v * w.abs();
    let rw = uw - th[4] * v * w - th[5] * w - th[5] * k_w * v.abs() * w;
    assert!(
        rv.abs() < 1e-14 && rw.abs() < 1e-14,
        "fixed point: {rv}, {rw}"
    );
    (v, w)
}

/// Root of u − b x − c tanh(x / eps) = 0 (strictly decreasing in x) by bisection.
fn friction_steady(u: f64, b: f64, c: f64, eps: f64) -> f64 {
    let f = |x: f64| u - b * x - c * (x / eps).tanh();
    let (mut lo, mut hi) = (-u.abs() / b - 1.0, u.abs() / b + 1.0);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if f(mid) > 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

fn mean(x: &[f64]) -> f64 {
    x.iter().sum::<f64>() / x.len() as f64
}

fn std_dev(x: &[f64]) -> f64 {
    let m = mean(x);
    (x.iter().map(|xi| (xi - m).powi(2)).sum::<f64>() / (x.len() - 1) as f64).sqrt()
}

/// An `Effects` with every effect on.
fn all_on() -> Effects {
    Effects {
        input_delay: Some(InputDelay { delay_s: 0.3 }),
        acceleration_limit: Some(AccelerationLimit {
            v_accel_max: 0.5,
            w_accel_max: 1.25,
        }),
        velocity_saturation: Some(VelocitySaturation {
            v_max: 1.4,
            w_max: 5.25,
        }),
        coulomb_friction: Some(CoulombFriction {
            v_coulomb: 0.05,
            w_coulomb: 0.1,
        }),
        wheel_asymmetry: Some(WheelAsymmetry { ratio: 1.1 }),
        payload_change: Some(PayloadChange {
            time_s: 60.0,
            theta_after: [0.5208, 0.5018, -0.000998, 0.9965, 0.00526, 1.0768],
        }),
        gain_drift: Some(GainDrift { rate_per_s: -0.001 }),
        slip: Some(Slip { k_v: 0.2, k_w: 0.3 }),
        measurement_noise: Some(MeasurementNoise {
            v_std: 0.01,
            w_std: 0.05,
        }),
        sample_jitter: Some(SampleJitter { std_s: 0.005 }),
    }
}

// ---------------------------------------------------------------------------------------------
// input_delay
// ---------------------------------------------------------------------------------------------

/// Delay 0.3 s = 3 periods: nothing moves until 0.3 s, then the response is the undelayed one
/// shifted by exactly three samples (a varying command, so the whole sequence is delayed).
#[test]
fn input_delay_shifts_the_response_by_the_delay() {
    let p = RobotProfile::pioneer3dx();
    let ex = Excitation {
        v_ref: Signal::Steps {
            levels: vec![0.5, -0.2, 0.8, 0.0],
            hold_s: 0.7,
        },
        w_ref: Signal::SumOfSines(SumOfSines {
            offset: 0.3,
            terms: vec![(0.5, 2.0)],
        }),
    };
    let base = run(&p, &ex, &exact(10.0, 20, Effects::default()));
    let delayed = run(
        &p,
        &ex,
        &exact(
            10.0,
            20,
            Effects {
                input_delay: Some(InputDelay { delay_s: 0.3 }),
                ..Effects::default()
            },
        ),
    );
    // The recording keeps the commands as sent.
    assert_eq!(base.v_ref, delayed.v_ref);
    assert_eq!(base.w_ref, delayed.w_ref);
    for k in 0..=3 {
        assert_eq!(delayed.v[k], 0.0, "v at t = {}", delayed.t[k]);
        assert_eq!(delayed.w[k], 0.0, "ω at t = {}", delayed.t[k]);
    }
    assert!(base.v[3] > 0.2, "the undelayed robot has moved by 0.3 s");
    for k in 3..delayed.len() {
        assert!((delayed.v[k] - base.v[k - 3]).abs() < 1e-9, "v, k = {k}");
        assert!((delayed.w[k] - base.w[k - 3]).abs() < 1e-9, "ω, k = {k}");
    }
}

/// A delay that is not a whole number of periods (0.25 s at 0.1 s): a step at t = 0 gives
/// v = 0 up to 0.25 s, then v = (c/θ4)(1 − exp(−θ4 (t − 0.25)/θ1)).
#[test]
fn input_delay_between_samples_matches_the_shifted_step_response() {
    let p = RobotProfile::pioneer3dx();
    let th = p.theta;
    let c = 0.5;
    let rec = run(
        &p,
        &constant(c, 0.0),
        &exact(
            3.0,
            50,
            Effects {
                input_delay: Some(InputDelay { delay_s: 0.25 }),
                ..Effects::default()
            },
        ),
    );
    for k in 0..rec.len() {
        let t = rec.t[k];
        let expected = if t <= 0.25 {
            0.0
        } else {
            lag(th[0], th[3], 0.0, c, 0.0, t - 0.25)
        };
        assert!(
            (rec.v[k] - expected).abs() < 1e-9,
            "t = {t}: v = {}, expected {expected}",
            rec.v[k]
        );
        assert_eq!(rec.w[k], 0.0);
    }
    // At 0.3 s the robot has been driven for 0.05 s only.
    assert!(rec.v[3] > 0.0 && rec.v[3] < 0.1);
}

// ---------------------------------------------------------------------------------------------
// acceleration_limit
// ---------------------------------------------------------------------------------------------

/// Steps of the command become ramps of the setpoint at v_accel_max (0.5 m/s²) and
/// w_accel_max (1 rad/s²), up and down; the response is the first-order lag's exact response
/// to those ramps. The setpoint moves in sub-step increments, so the tolerance is one
/// sub-step of ramp, a·h/θ4.
#[test]
fn acceleration_limit_ramps_the_setpoint() {
    let p = decoupled();
    let th = p.theta;
    let substeps = 200;
    let h = p.period_s / substeps as f64;
    let (av, aw) = (0.5, 1.0);
    let rec = run(
        &p,
        &steps(&[1.0, -0.5], &[-2.0, 1.0], 6.0),
        &exact(
            12.0,
            substeps,
            Effects {
                acceleration_limit: Some(AccelerationLimit {
                    v_accel_max: av,
                    w_accel_max: aw,
                }),
                ..Effects::default()
            },
        ),
    );
    // v setpoint: 0 → 1 over 2 s, hold, 1 → −0.5 over 3 s from 6 s, hold.
    let v_segments = [
        (0.0, 0.0, av),
        (2.0, 1.0, 0.0),
        (6.0, 1.0, -av),
        (9.0, -0.5, 0.0),
    ];
    // ω setpoint: 0 → −2 over 2 s, hold, −2 → 1 over 3 s from 6 s, hold.
    let w_segments = [
        (0.0, 0.0, -aw),
        (2.0, -2.0, 0.0),
        (6.0, -2.0, aw),
        (9.0, 1.0, 0.0),
    ];
    let (tol_v, tol_w) = (av * h / th[3] + 1e-9, aw * h / th[5] + 1e-9);
    for k in 0..rec.len() {
        let t = rec.t[k];
        let ev = lag_path(th[0], th[3], &v_segments, t);
        let ew = lag_path(th[1], th[5], &w_segments, t);
        assert!(
            (rec.v[k] - ev).abs() < tol_v,
            "t = {t}: v = {}, {ev}",
            rec.v[k]
        );
        assert!(
            (rec.w[k] - ew).abs() < tol_w,
            "t = {t}: ω = {}, {ew}",
            rec.w[k]
        );
    }
    // Settled on the held levels.
    let end = rec.len() - 1;
    assert_relative_eq!(rec.v[end], -0.5 / th[3], max_relative = 1e-4);
    assert_relative_eq!(rec.w[end], 1.0 / th[5], max_relative = 1e-4);
}

/// Saturation acts before the rate limit (effects.rs, steps 2 then 3): a command of 2 m/s
/// clipped to 1 m/s ramps the setpoint to 1 (2 s at 0.5 m/s²), and when the command drops to
/// 0 the setpoint ramps down from 1 at once (not from 2).
#[test]
fn saturation_acts_before_the_acceleration_limit() {
    let p = decoupled();
    let th = p.theta;
    let substeps = 200;
    let h = p.period_s / substeps as f64;
    let (av, aw) = (0.5, 1.0);
    let rec = run(
        &p,
        &steps(&[2.0, 0.0], &[-4.0, 0.0], 6.0),
        &exact(
            12.0,
            substeps,
            Effects {
                acceleration_limit: Some(AccelerationLimit {
                    v_accel_max: av,
                    w_accel_max: aw,
                }),
                velocity_saturation: Some(VelocitySaturation {
                    v_max: 1.0,
                    w_max: 1.5,
                }),
                ..Effects::default()
            },
        ),
    );
    let v_segments = [
        (0.0, 0.0, av),
        (2.0, 1.0, 0.0),
        (6.0, 1.0, -av),
        (8.0, 0.0, 0.0),
    ];
    let w_segments = [
        (0.0, 0.0, -aw),
        (1.5, -1.5, 0.0),
        (6.0, -1.5, aw),
        (7.5, 0.0, 0.0),
    ];
    let (tol_v, tol_w) = (av * h / th[3] + 1e-9, aw * h / th[5] + 1e-9);
    for k in 0..rec.len() {
        let t = rec.t[k];
        let ev = lag_path(th[0], th[3], &v_segments, t);
        let ew = lag_path(th[1], th[5], &w_segments, t);
        assert!(
            (rec.v[k] - ev).abs() < tol_v,
            "t = {t}: v = {}, {ev}",
            rec.v[k]
        );
        assert!(
            (rec.w[k] - ew).abs() < tol_w,
            "t = {t}: ω = {}, {ew}",
            rec.w[k]
        );
    }
}

// ---------------------------------------------------------------------------------------------
// velocity_saturation
// ---------------------------------------------------------------------------------------------

/// The setpoint is clipped to ±v_max, ±w_max while the command goes on: commands
/// (2, 0.6, −3) m/s with v_max = 1 give the lag response to setpoints (1, 0.6, −1), settling
/// at 1/θ4 etc.; (−5, 0.5, 4) rad/s with w_max = 2 give (−2, 0.5, 2).
#[test]
fn velocity_saturation_clips_the_setpoint() {
    let p = decoupled();
    let th = p.theta;
    let rec = run(
        &p,
        &steps(&[2.0, 0.6, -3.0], &[-5.0, 0.5, 4.0], 5.0),
        &exact(
            15.0,
            50,
            Effects {
                velocity_saturation: Some(VelocitySaturation {
                    v_max: 1.0,
                    w_max: 2.0,
                }),
                ..Effects::default()
            },
        ),
    );
    let v_segments = [(0.0, 1.0, 0.0), (5.0, 0.6, 0.0), (10.0, -1.0, 0.0)];
    let w_segments = [(0.0, -2.0, 0.0), (5.0, 0.5, 0.0), (10.0, 2.0, 0.0)];
    for k in 0..rec.len() {
        let t = rec.t[k];
        let ev = lag_path(th[0], th[3], &v_segments, t);
        let ew = lag_path(th[1], th[5], &w_segments, t);
        assert!(
            (rec.v[k] - ev).abs() < 1e-9,
            "t = {t}: v = {}, {ev}",
            rec.v[k]
        );
        assert!(
            (rec.w[k] - ew).abs() < 1e-9,
            "t = {t}: ω = {}, {ew}",
            rec.w[k]
        );
    }
    // The command goes on unclipped in the recording; the response saturates.
    assert_eq!(rec.v_ref[idx(4.9, p.period_s)], 2.0);
    assert_relative_eq!(
        rec.v[idx(4.9, p.period_s)],
        1.0 / th[3],
        max_relative = 1e-6
    );
    assert_relative_eq!(
        rec.w[idx(4.9, p.period_s)],
        -2.0 / th[5],
        max_relative = 1e-6
    );
    assert_relative_eq!(
        rec.v[idx(14.9, p.period_s)],
        -1.0 / th[3],
        max_relative = 1e-6
    );
    assert_relative_eq!(
        rec.w[idx(14.9, p.period_s)],
        2.0 / th[5],
        max_relative = 1e-6
    );
}

// ---------------------------------------------------------------------------------------------
// coulomb_friction
// ---------------------------------------------------------------------------------------------

/// Steady states with dry friction solve u − θ4 v − c_v tanh(v/0.002) = 0 and
/// u − θ6 ω − c_ω tanh(ω/0.01) = 0: large commands settle at (u ∓ c)/θ, commands below the
/// friction level creep (a dead zone), symmetric in sign.
#[test]
fn coulomb_friction_steady_states_and_dead_zone() {
    let p = decoupled();
    let th = p.theta;
    let (cv, cw) = (0.05, 0.1);
    let v_levels = [0.5, 0.03, -0.5, -0.03];
    let w_levels = [1.0, 0.05, -1.0, -0.05];
    let hold = 8.0;
    let rec = run(
        &p,
        &steps(&v_levels, &w_levels, hold),
        &exact(
            32.0,
            50,
            Effects {
                coulomb_friction: Some(CoulombFriction {
                    v_coulomb: cv,
                    w_coulomb: cw,
                }),
                ..Effects::default()
            },
        ),
    );
    for (i, (&uv, &uw)) in v_levels.iter().zip(&w_levels).enumerate() {
        let k = idx((i + 1) as f64 * hold - 0.1, p.period_s);
        let ev = friction_steady(uv, th[3], cv, 0.002);
        let ew = friction_steady(uw, th[5], cw, 0.01);
        assert!(
            (rec.v[k] - ev).abs() < 1e-9,
            "u_v = {uv}: v = {}, {ev}",
            rec.v[k]
        );
        assert!(
            (rec.w[k] - ew).abs() < 1e-9,
            "u_ω = {uw}: ω = {}, {ew}",
            rec.w[k]
        );
        if uv.abs() > 5.0 * cv {
            // tanh saturated: the friction is a constant c.
            assert_relative_eq!(
                rec.v[k],
                (uv - cv * uv.signum()) / th[3],
                max_relative = 1e-9
            );
            assert_relative_eq!(
                rec.w[k],
                (uw - cw * uw.signum()) / th[5],
                max_relative = 1e-9
            );
        } else {
            // Dead zone: the robot creeps at a small fraction of the frictionless speed, with
            // the command's sign (v ≈ 1.3 mm/s for 30 mm/s commanded, 4.4 %; ω ≈ 0.0048
            // rad/s for 0.05 rad/s, 10 %: ε_ω/c_ω is larger than ε_v/c_v).
            assert!(rec.v[k] * uv > 0.0 && rec.v[k].abs() < 0.05 * uv.abs() / th[3]);
            assert!(rec.w[k] * uw > 0.0 && rec.w[k].abs() < 0.12 * uw.abs() / th[5]);
        }
    }
    // The creep values themselves (bisection, ε_v = 2 mm/s, ε_ω = 0.01 rad/s).
    let creep_v = friction_steady(0.03, th[3], cv, 0.002);
    assert!(creep_v > 0.0012 && creep_v < 0.0014, "{creep_v}");
    let creep_w = friction_steady(0.05, th[5], cw, 0.01);
    assert!(creep_w > 0.0045 && creep_w < 0.0050, "{creep_w}");
}

// ---------------------------------------------------------------------------------------------
// wheel_asymmetry
// ---------------------------------------------------------------------------------------------

/// Effective commands from the documented wheel model: wheel setpoints v ± d ω/2 scaled by
/// 2ρ/(1 + ρ) (right) and 2/(1 + ρ) (left), then v = (v_r + v_l)/2, ω = (v_r − v_l)/d.
fn asymmetric(uv: f64, uw: f64, rho: f64, d: f64) -> (f64, f64) {
    let vr = 2.0 * rho / (1.0 + rho) * (uv + d * uw / 2.0);
    let vl = 2.0 / (1.0 + rho) * (uv - d * uw / 2.0);
    ((vr + vl) / 2.0, (vr - vl) / d)
}

/// With ρ = 1.1 on the (coupled) Pioneer, the steady state is that of eq. 2.19 under the
/// effective commands: a pure v_ref turns the robot at ω solving
/// 0 = 2(ρ − 1)/((1 + ρ) d)·v_ref − θ5 v ω − θ6 ω.
#[test]
fn wheel_asymmetry_leaks_v_ref_into_turning() {
    let p = RobotProfile::pioneer3dx();
    let th = p.theta;
    let rho = 1.1;
    let v_levels = [0.5, 0.4];
    let w_levels = [0.0, -0.8];
    let hold = 15.0;
    let rec = run(
        &p,
        &steps(&v_levels, &w_levels, hold),
        &exact(
            30.0,
            20,
            Effects {
                wheel_asymmetry: Some(WheelAsymmetry { ratio: rho }),
                ..Effects::default()
            },
        ),
    );
    for (i, (&uv, &uw)) in v_levels.iter().zip(&w_levels).enumerate() {
        let k = idx((i + 1) as f64 * hold - 0.1, p.period_s);
        let (ev, ew) = {
            let (uv_eff, uw_eff) = asymmetric(uv, uw, rho, p.track);
            steady(&th, uv_eff, uw_eff, 0.0, 0.0)
        };
        assert!((rec.v[k] - ev).abs() < 1e-9, "v = {}, {ev}", rec.v[k]);
        assert!((rec.w[k] - ew).abs() < 1e-9, "ω = {}, {ew}", rec.w[k]);
    }
    // The pure-v_ref case, with the leak of the documentation written out.
    let k = idx(hold - 0.1, p.period_s);
    let leak = 2.0 * (rho - 1.0) / ((1.0 + rho) * p.track) * 0.5;
    let (ev, ew) = steady(&th, 0.5, leak, 0.0, 0.0);
    assert_relative_eq!(rec.v[k], ev, max_relative = 1e-9);
    assert_relative_eq!(rec.w[k], ew, max_relative = 1e-9);
    // ρ > 1: the right wheel is stronger, so the robot turns left (ω > 0), ≈ 0.13 rad/s.
    assert!(rec.w[k] > 0.12 && rec.w[k] < 0.14, "ω = {}", rec.w[k]);
}

// ---------------------------------------------------------------------------------------------
// payload_change
// ---------------------------------------------------------------------------------------------

/// Before time_s the run equals the no-payload run exactly; from then on v, ω follow the lag
/// with θ_after (time constants θ1'/θ4', θ2'/θ6' and steady states u/θ4', u/θ6').
#[test]
fn payload_change_switches_theta_at_its_time() {
    let p = decoupled();
    let th = p.theta;
    let after = [0.5, 0.4, 0.0, 1.3, 0.0, 0.7];
    let ex = steps(&[0.4, 0.8, 0.8], &[0.6, -0.3, -0.3], 5.0);
    let base = run(&p, &ex, &exact(15.0, 50, Effects::default()));
    let rec = run(
        &p,
        &ex,
        &exact(
            15.0,
            50,
            Effects {
                payload_change: Some(PayloadChange {
                    time_s: 5.0,
                    theta_after: after,
                }),
                ..Effects::default()
            },
        ),
    );
    let k5 = idx(5.0, p.period_s);
    for k in 0..=k5 {
        assert_eq!(rec.v[k], base.v[k], "k = {k}");
        assert_eq!(rec.w[k], base.w[k], "k = {k}");
    }
    // At 5 s: the old lags' values.
    assert!((rec.v[k5] - lag(th[0], th[3], 0.0, 0.4, 0.0, 5.0)).abs() < 1e-9);
    assert!((rec.w[k5] - lag(th[1], th[5], 0.0, 0.6, 0.0, 5.0)).abs() < 1e-9);
    let (v5, w5) = (rec.v[k5], rec.w[k5]);
    for k in k5..rec.len() {
        let tau = rec.t[k] - 5.0;
        let ev = lag(after[0], after[3], v5, 0.8, 0.0, tau);
        let ew = lag(after[1], after[5], w5, -0.3, 0.0, tau);
        assert!(
            (rec.v[k] - ev).abs() < 1e-9,
            "τ = {tau}: v = {}, {ev}",
            rec.v[k]
        );
        assert!(
            (rec.w[k] - ew).abs() < 1e-9,
            "τ = {tau}: ω = {}, {ew}",
            rec.w[k]
        );
    }
    let end = rec.len() - 1;
    assert_relative_eq!(rec.v[end], 0.8 / after[3], max_relative = 1e-6);
    assert_relative_eq!(rec.w[end], -0.3 / after[5], max_relative = 1e-6);
}

/// `PayloadChange::scaled` multiplies θ1, θ2, θ3, θ5 and keeps θ4, θ6; on the coupled
/// Pioneer the robot's θ switches at time_s and the steady state after it is that of θ_after.
#[test]
fn payload_change_scaled_on_the_coupled_pioneer() {
    let p = RobotProfile::pioneer3dx();
    let th = p.theta;
    let pc = PayloadChange::scaled(5.0, th, 3.0);
    assert_eq!(pc.time_s, 5.0);
    assert_eq!(
        pc.theta_after,
        [
            3.0 * th[0],
            3.0 * th[1],
            3.0 * th[2],
            th[3],
            3.0 * th[4],
            th[5]
        ]
    );
    let settings = exact(
        25.0,
        20,
        Effects {
            payload_change: Some(pc),
            ..Effects::default()
        },
    );
    let robot = SimRobot::new(&p, &settings).expect("robot");
    assert_eq!(robot.theta_at(4.999), th);
    assert_eq!(robot.theta_at(5.0), pc.theta_after);

    // A command whose steady state depends on θ3 and θ5 (large ω).
    let ex = constant(0.6, 3.0);
    let base = run(&p, &ex, &exact(25.0, 20, Effects::default()));
    let rec = run(&p, &ex, &settings);
    let k5 = idx(5.0, p.period_s);
    assert_eq!(rec.v[..=k5], base.v[..=k5]);
    assert_eq!(rec.w[..=k5], base.w[..=k5]);
    let (ev, ew) = steady(&pc.theta_after, 0.6, 3.0, 0.0, 0.0);
    let (bv, bw) = steady(&th, 0.6, 3.0, 0.0, 0.0);
    let end = rec.len() - 1;
    assert!((rec.v[end] - ev).abs() < 1e-9, "v = {}, {ev}", rec.v[end]);
    assert!((rec.w[end] - ew).abs() < 1e-9, "ω = {}, {ew}", rec.w[end]);
    assert!((base.v[end] - bv).abs() < 1e-9);
    // The payload's steady state is measurably different from the unloaded one.
    assert!((ev - bv).abs() > 1e-3 && (ew - bw).abs() > 1e-3);
}

// ---------------------------------------------------------------------------------------------
// gain_drift
// ---------------------------------------------------------------------------------------------

/// θ1 ẋ = g(t) c − (θ4 − 1 + g(t)) x, g = 1 + r t, from x(0) = 0: the integrating factor gives
/// x(t) = ∫₀ᵗ (c g(s)/θ1) exp(−[θ4 (t − s) + r (t² − s²)/2]/θ1) ds, evaluated here by
/// Simpson's rule on 4,000 intervals (error ≪ 1e-9 of c/θ4 for these time constants).
fn drive_gain_response(th1: f64, th4: f64, c: f64, r: f64, t: f64) -> f64 {
    let n = 4000;
    let h = t / n as f64;
    let f = |s: f64| {
        c * (1.0 + r * s) / th1 * (-(th4 * (t - s) + 0.5 * r * (t * t - s * s)) / th1).exp()
    };
    let inner: f64 = (1..n)
        .map(|i| if i % 2 == 1 { 4.0 } else { 2.0 } * f(i as f64 * h))
        .sum();
    h / 3.0 * (f(0.0) + inner + f(t))
}

/// The drive gain g = 1 + r·t scales the loop's effort g (u − v) (module docs of effects.rs):
/// a constant command c gives the integrating-factor solution of
/// θ1 v̇ = g c − (θ4 − 1 + g) v ([`drive_gain_response`]), on both channels. Tolerance: one
/// sub-step of drift. At 20 s with r = −0.02 the gain is 0.6 and v sits near the quasi-steady
/// 0.6 c/(θ4 − 0.4), well off the setpoint drift's 0.6 c/θ4 when θ4 is near 1.
#[test]
fn gain_drift_scales_the_drive_gain_linearly_in_time() {
    let p = decoupled();
    let th = p.theta;
    let substeps = 50;
    let h = p.period_s / substeps as f64;
    let r = -0.02;
    let (cv, cw) = (0.5, -1.0);
    let rec = run(
        &p,
        &constant(cv, cw),
        &exact(
            20.0,
            substeps,
            Effects {
                gain_drift: Some(GainDrift { rate_per_s: r }),
                ..Effects::default()
            },
        ),
    );
    let tol_v = (cv * r).abs() * h / th[3] + 1e-9;
    let tol_w = (cw * r).abs() * h / th[5] + 1e-9;
    for k in (0..rec.len()).step_by(5) {
        let t = rec.t[k];
        let ev = drive_gain_response(th[0], th[3], cv, r, t);
        let ew = drive_gain_response(th[1], th[5], cw, r, t);
        assert!(
            (rec.v[k] - ev).abs() < tol_v,
            "t = {t}: v = {}, {ev}",
            rec.v[k]
        );
        assert!(
            (rec.w[k] - ew).abs() < tol_w,
            "t = {t}: ω = {}, {ew}",
            rec.w[k]
        );
    }
    let end = rec.len() - 1;
    let quasi = 0.6 * cv / (th[3] - 0.4);
    assert!(
        (rec.v[end] - quasi).abs() < 0.02 * quasi,
        "{} vs {quasi}",
        rec.v[end]
    );
}

// ---------------------------------------------------------------------------------------------
// slip
// ---------------------------------------------------------------------------------------------

/// With slip the steady state solves
/// 0 = u_v + θ3 ω² − θ4 v − θ4 k_v v |ω| and 0 = u_ω − θ5 v ω − θ6 ω − θ6 k_w |v| ω,
/// for forward and backward driving and both turning directions (the losses oppose the
/// motion in all), and is slower than without slip.
#[test]
fn slip_steady_state_solves_the_documented_equations() {
    let p = RobotProfile::pioneer3dx();
    let th = p.theta;
    let (k_v, k_w) = (0.2, 0.3);
    let v_levels = [0.5, -0.5, 0.5];
    let w_levels = [1.0, 1.0, -1.0];
    let hold = 10.0;
    let ex = steps(&v_levels, &w_levels, hold);
    let base = run(&p, &ex, &exact(30.0, 20, Effects::default()));
    let rec = run(
        &p,
        &ex,
        &exact(
            30.0,
            20,
            Effects {
                slip: Some(Slip { k_v, k_w }),
                ..Effects::default()
            },
        ),
    );
    for (i, (&uv, &uw)) in v_levels.iter().zip(&w_levels).enumerate() {
        let k = idx((i + 1) as f64 * hold - 0.1, p.period_s);
        let (ev, ew) = steady(&th, uv, uw, k_v, k_w);
        let (bv, bw) = steady(&th, uv, uw, 0.0, 0.0);
        assert!((rec.v[k] - ev).abs() < 1e-9, "v = {}, {ev}", rec.v[k]);
        assert!((rec.w[k] - ew).abs() < 1e-9, "ω = {}, {ew}", rec.w[k]);
        assert!((base.v[k] - bv).abs() < 1e-9 && (base.w[k] - bw).abs() < 1e-9);
        // Losses: |v| drops by ≈ k_v|ω| ≈ 20 %, |ω| by ≈ k_w|v| ≈ 15 %.
        assert!(
            rec.v[k].abs() < 0.9 * base.v[k].abs(),
            "{} {}",
            rec.v[k],
            base.v[k]
        );
        assert!(
            rec.w[k].abs() < 0.9 * base.w[k].abs(),
            "{} {}",
            rec.w[k],
            base.w[k]
        );
        assert!(rec.v[k] * uv > 0.0 && rec.w[k] * uw > 0.0);
    }
}

// ---------------------------------------------------------------------------------------------
// measurement_noise
// ---------------------------------------------------------------------------------------------

/// Without the encoder model, the noisy recording minus the exact one is white noise of the
/// given standard deviations (within 10 % over 2000 samples), zero mean, v and ω independent.
#[test]
fn measurement_noise_has_the_given_std() {
    let p = RobotProfile::pioneer3dx();
    let ex = constant(0.5, 0.3);
    let (sv, sw) = (0.01, 0.05);
    let noise = Effects {
        measurement_noise: Some(MeasurementNoise {
            v_std: sv,
            w_std: sw,
        }),
        ..Effects::default()
    };
    let clean = run(&p, &ex, &exact(200.0, 10, Effects::default()));
    let noisy = run(&p, &ex, &exact(200.0, 10, noise.clone()));
    assert_eq!(noisy.t, clean.t);
    let n = clean.len();
    // Sample 0 is the initial state, reported before any measurement.
    let dv: Vec<f64> = (1..n).map(|k| noisy.v[k] - clean.v[k]).collect();
    let dw: Vec<f64> = (1..n).map(|k| noisy.w[k] - clean.w[k]).collect();
    let m = dv.len() as f64;
    assert!(
        (std_dev(&dv) / sv - 1.0).abs() < 0.1,
        "std v {}",
        std_dev(&dv)
    );
    assert!(
        (std_dev(&dw) / sw - 1.0).abs() < 0.1,
        "std ω {}",
        std_dev(&dw)
    );
    assert!(
        mean(&dv).abs() < 4.0 * sv / m.sqrt(),
        "mean v {}",
        mean(&dv)
    );
    assert!(
        mean(&dw).abs() < 4.0 * sw / m.sqrt(),
        "mean ω {}",
        mean(&dw)
    );
    let corr =
        dv.iter().zip(&dw).map(|(a, b)| a * b).sum::<f64>() / (m * std_dev(&dv) * std_dev(&dw));
    assert!(corr.abs() < 0.1, "v–ω correlation {corr}");
    // White: lag-1 autocorrelation ≈ 0.
    let r1 = dv.windows(2).map(|w| w[0] * w[1]).sum::<f64>() / (m * sv * sv);
    assert!(r1.abs() < 0.1, "lag-1 autocorrelation {r1}");

    // Same seed: identical recordings; another seed: every sample differs.
    let again = run(&p, &ex, &exact(200.0, 10, noise.clone()));
    assert_eq!(again.v, noisy.v);
    assert_eq!(again.w, noisy.w);
    let other = run(
        &p,
        &ex,
        &SimSettings {
            seed: 2,
            ..exact(200.0, 10, noise)
        },
    );
    assert!((1..n).all(|k| other.v[k] != noisy.v[k] && other.w[k] != noisy.w[k]));
}

/// With the encoder model on, the extra noise comes on top of it: in steady state the
/// reported v, ω scatter around the exact values with std ≈ √(σ² + encoder noise²) ≈ σ
/// (σ ≫ the encoder's ≈ 1.4 mm/s), while without the effect the scatter is encoder-small.
#[test]
fn measurement_noise_adds_to_the_encoder_model() {
    let p = RobotProfile::pioneer3dx();
    let ex = constant(0.5, 0.3);
    let (sv, sw) = (0.05, 0.2);
    let clean = run(&p, &ex, &exact(200.0, 10, Effects::default()));
    let encoders = |effects: Effects| {
        run(
            &p,
            &ex,
            &SimSettings {
                measurement_noise: true,
                ..exact(200.0, 10, effects)
            },
        )
    };
    let plain = encoders(Effects::default());
    let noisy = encoders(Effects {
        measurement_noise: Some(MeasurementNoise {
            v_std: sv,
            w_std: sw,
        }),
        ..Effects::default()
    });
    let from = idx(5.0, p.period_s);
    let diff = |rec: &Recording, clean_col: &[f64], col: fn(&Recording) -> &Vec<f64>| {
        (from..rec.len())
            .map(|k| col(rec)[k] - clean_col[k])
            .collect::<Vec<f64>>()
    };
    let dv = diff(&noisy, &clean.v, |r| &r.v);
    let dw = diff(&noisy, &clean.w, |r| &r.w);
    assert!(
        (std_dev(&dv) / sv - 1.0).abs() < 0.1,
        "std v {}",
        std_dev(&dv)
    );
    assert!(
        (std_dev(&dw) / sw - 1.0).abs() < 0.1,
        "std ω {}",
        std_dev(&dw)
    );
    let ev = diff(&plain, &clean.v, |r| &r.v);
    let ew = diff(&plain, &clean.w, |r| &r.w);
    assert!(std_dev(&ev) < 0.003 && std_dev(&ew) < 0.015);
}

// ---------------------------------------------------------------------------------------------
// sample_jitter
// ---------------------------------------------------------------------------------------------

/// Sample instants t_k = kΔt + e_k, e_k Gaussian of std std_s clipped to ±0.45Δt: increasing
/// time stamps, mean spacing Δt, std(e) ≈ std_s within 10 %, and the dynamics integrated over
/// the uneven intervals (v(t_k) is the step response at t_k − t_0 exactly).
#[test]
fn sample_jitter_moves_the_sample_instants() {
    let p = decoupled();
    let th = p.theta;
    let dt = p.period_s;
    let std_s = 0.01;
    let jitter = Effects {
        sample_jitter: Some(SampleJitter { std_s }),
        ..Effects::default()
    };
    let rec = run(&p, &constant(0.5, 0.3), &exact(200.0, 50, jitter.clone()));
    let n = rec.len();
    assert_eq!(n, 2001);
    assert!(rec.t.windows(2).all(|w| w[1] > w[0]), "increasing");
    let e: Vec<f64> = (0..n).map(|k| rec.t[k] - k as f64 * dt).collect();
    assert!(e.iter().all(|x| x.abs() <= 0.45 * dt + 1e-12));
    assert!(
        (std_dev(&e) / std_s - 1.0).abs() < 0.1,
        "std {}",
        std_dev(&e)
    );
    assert!(mean(&e).abs() < 4.0 * std_s / (n as f64).sqrt());
    assert!(((rec.t[n - 1] - rec.t[0]) / (n - 1) as f64 - dt).abs() < 1e-4);
    // The spacing really varies: std(t_{k+1} − t_k) ≈ √2 std_s.
    let spacing: Vec<f64> = rec.t.windows(2).map(|w| w[1] - w[0]).collect();
    assert!((std_dev(&spacing) / (2f64.sqrt() * std_s) - 1.0).abs() < 0.1);
    // The robot starts at t_0 (itself jittered) and is integrated over the true intervals.
    for k in 0..n {
        let tau = rec.t[k] - rec.t[0];
        let ev = lag(th[0], th[3], 0.0, 0.5, 0.0, tau);
        let ew = lag(th[1], th[5], 0.0, 0.3, 0.0, tau);
        assert!(
            (rec.v[k] - ev).abs() < 1e-9,
            "k = {k}: v = {}, {ev}",
            rec.v[k]
        );
        assert!(
            (rec.w[k] - ew).abs() < 1e-9,
            "k = {k}: ω = {}, {ew}",
            rec.w[k]
        );
    }
    // Reproducible by seed.
    let again = run(&p, &constant(0.5, 0.3), &exact(200.0, 50, jitter.clone()));
    assert_eq!(again.t, rec.t);
    let other = run(
        &p,
        &constant(0.5, 0.3),
        &SimSettings {
            seed: 5,
            ..exact(200.0, 50, jitter)
        },
    );
    assert!((0..n).all(|k| other.t[k] != rec.t[k]));
}

/// A jitter much larger than the period is clipped to ±0.45Δt: the errors hit the clip
/// exactly, and the time stamps stay increasing (spacing ≥ 0.1Δt).
#[test]
fn sample_jitter_is_clipped_to_045_periods() {
    let p = RobotProfile::pioneer3dx();
    let dt = p.period_s;
    let rec = run(
        &p,
        &constant(0.5, 0.3),
        &exact(
            50.0,
            5,
            Effects {
                sample_jitter: Some(SampleJitter { std_s: 1.0 }),
                ..Effects::default()
            },
        ),
    );
    let e: Vec<f64> = (0..rec.len()).map(|k| rec.t[k] - k as f64 * dt).collect();
    let max = e.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    assert!((max - 0.45 * dt).abs() < 1e-12, "max |e| = {max}");
    let clipped = e
        .iter()
        .filter(|x| (x.abs() - 0.45 * dt).abs() < 1e-12)
        .count();
    assert!(clipped > rec.len() * 9 / 10, "{clipped} of {}", rec.len());
    assert!(e.iter().any(|&x| x > 0.0) && e.iter().any(|&x| x < 0.0));
    assert!(rec.t.windows(2).all(|w| w[1] - w[0] >= 0.1 * dt - 1e-12));
}

// ---------------------------------------------------------------------------------------------
// validate, active, TOML
// ---------------------------------------------------------------------------------------------

fn invalid_message(effects: &Effects) -> String {
    match effects.validate() {
        Err(Error::InvalidSetting(msg)) => msg,
        other => panic!("{effects:?}: expected InvalidSetting, got {other:?}"),
    }
}

/// Every magnitude out of its documented range (negative, zero where > 0 is required, NaN,
/// infinite) is rejected with an error naming the effect and field; SimRobot::new and
/// simulate_recording refuse such effects; boundary values inside the ranges pass.
#[test]
fn validate_rejects_bad_magnitudes_naming_the_field() {
    let nan = f64::NAN;
    let inf = f64::INFINITY;
    let none = Effects::default;
    let mut cases: Vec<(Effects, &str)> = Vec::new();
    for x in [-0.1, nan, inf] {
        cases.push((
            Effects {
                input_delay: Some(InputDelay { delay_s: x }),
                ..none()
            },
            "input_delay.delay_s",
        ));
    }
    for x in [0.0, -1.0, nan, inf] {
        cases.push((
            Effects {
                acceleration_limit: Some(AccelerationLimit {
                    v_accel_max: x,
                    w_accel_max: 1.0,
                }),
                ..none()
            },
            "acceleration_limit.v_accel_max",
        ));
        cases.push((
            Effects {
                acceleration_limit: Some(AccelerationLimit {
                    v_accel_max: 1.0,
                    w_accel_max: x,
                }),
                ..none()
            },
            "acceleration_limit.w_accel_max",
        ));
        cases.push((
            Effects {
                velocity_saturation: Some(VelocitySaturation {
                    v_max: x,
                    w_max: 1.0,
                }),
                ..none()
            },
            "velocity_saturation.v_max",
        ));
        cases.push((
            Effects {
                velocity_saturation: Some(VelocitySaturation {
                    v_max: 1.0,
                    w_max: x,
                }),
                ..none()
            },
            "velocity_saturation.w_max",
        ));
        cases.push((
            Effects {
                wheel_asymmetry: Some(WheelAsymmetry { ratio: x }),
                ..none()
            },
            "wheel_asymmetry.ratio",
        ));
    }
    for x in [-0.01, nan, inf] {
        cases.push((
            Effects {
                coulomb_friction: Some(CoulombFriction {
                    v_coulomb: x,
                    w_coulomb: 0.0,
                }),
                ..none()
            },
            "coulomb_friction.v_coulomb",
        ));
        cases.push((
            Effects {
                coulomb_friction: Some(CoulombFriction {
                    v_coulomb: 0.0,
                    w_coulomb: x,
                }),
                ..none()
            },
            "coulomb_friction.w_coulomb",
        ));
        cases.push((
            Effects {
                slip: Some(Slip { k_v: x, k_w: 0.0 }),
                ..none()
            },
            "slip.k_v",
        ));
        cases.push((
            Effects {
                slip: Some(Slip { k_v: 0.0, k_w: x }),
                ..none()
            },
            "slip.k_w",
        ));
        cases.push((
            Effects {
                measurement_noise: Some(MeasurementNoise {
                    v_std: x,
                    w_std: 0.0,
                }),
                ..none()
            },
            "measurement_noise.v_std",
        ));
        cases.push((
            Effects {
                measurement_noise: Some(MeasurementNoise {
                    v_std: 0.0,
                    w_std: x,
                }),
                ..none()
            },
            "measurement_noise.w_std",
        ));
        cases.push((
            Effects {
                sample_jitter: Some(SampleJitter { std_s: x }),
                ..none()
            },
            "sample_jitter.std_s",
        ));
    }
    for x in [nan, inf, -inf] {
        cases.push((
            Effects {
                gain_drift: Some(GainDrift { rate_per_s: x }),
                ..none()
            },
            "gain_drift.rate_per_s",
        ));
        cases.push((
            Effects {
                payload_change: Some(PayloadChange {
                    time_s: x,
                    theta_after: RobotProfile::pioneer3dx().theta,
                }),
                ..none()
            },
            "payload_change.time_s",
        ));
    }
    let p = RobotProfile::pioneer3dx();
    for (effects, field) in &cases {
        let msg = invalid_message(effects);
        assert!(msg.contains(field), "{field}: message {msg:?}");
        let settings = exact(1.0, 5, effects.clone());
        assert!(SimRobot::new(&p, &settings).is_err(), "{field}");
        assert!(
            simulate_recording(&p, &constant(0.1, 0.1), &settings).is_err(),
            "{field}"
        );
    }

    // A bad θ after the payload is rejected too.
    for bad in [
        [0.0, 0.25, 0.0, 1.0, 0.0, 1.0],
        [0.26, 0.0, 0.0, 1.0, 0.0, 1.0],
        [0.26, 0.25, nan, 1.0, 0.0, 1.0],
    ] {
        let effects = Effects {
            payload_change: Some(PayloadChange {
                time_s: 1.0,
                theta_after: bad,
            }),
            ..none()
        };
        invalid_message(&effects);
    }

    // Boundary values inside the documented ranges pass.
    let ok = Effects {
        input_delay: Some(InputDelay { delay_s: 0.0 }),
        coulomb_friction: Some(CoulombFriction {
            v_coulomb: 0.0,
            w_coulomb: 0.0,
        }),
        gain_drift: Some(GainDrift { rate_per_s: -0.01 }),
        slip: Some(Slip { k_v: 0.0, k_w: 0.0 }),
        measurement_noise: Some(MeasurementNoise {
            v_std: 0.0,
            w_std: 0.0,
        }),
        sample_jitter: Some(SampleJitter { std_s: 0.0 }),
        payload_change: Some(PayloadChange {
            time_s: -1.0,
            theta_after: p.theta,
        }),
        ..none()
    };
    ok.validate().expect("boundary values are valid");
    all_on().validate().expect("all_on is valid");
    // The boundary values change nothing: the run equals the plain one.
    let ex = constant(0.4, 0.5);
    let plain = run(&p, &ex, &exact(3.0, 10, none()));
    let zero_effects = Effects {
        gain_drift: None,
        payload_change: None,
        ..ok
    };
    let same = run(&p, &ex, &exact(3.0, 10, zero_effects));
    assert_eq!(plain.t, same.t);
    assert_eq!(plain.v, same.v);
    assert_eq!(plain.w, same.w);
}

/// The θ check of a payload names the effect, as `Effects::validate` documents ("naming the
/// effect and field"). Ignored: the message comes from `check_theta` and reads
/// "θ must be finite with θ1, θ2 ≠ 0, …" without `payload_change.theta_after`.
#[test]
fn validate_names_the_payload_theta_field() {
    let effects = Effects {
        payload_change: Some(PayloadChange {
            time_s: 1.0,
            theta_after: [0.0, 0.25, 0.0, 1.0, 0.0, 1.0],
        }),
        ..Effects::default()
    };
    let msg = invalid_message(&effects);
    assert!(msg.contains("payload_change.theta_after"), "{msg:?}");
}

/// `active()` names the effects that are on, in field order; the recording's metadata say
/// "none" without effects and describe them otherwise.
#[test]
fn active_lists_effects_in_field_order() {
    assert!(Effects::default().active().is_empty());
    assert_eq!(
        all_on().active(),
        [
            "input_delay",
            "acceleration_limit",
            "velocity_saturation",
            "coulomb_friction",
            "wheel_asymmetry",
            "payload_change",
            "gain_drift",
            "slip",
            "measurement_noise",
            "sample_jitter",
        ]
    );
    let some = Effects {
        slip: Some(Slip { k_v: 0.1, k_w: 0.1 }),
        input_delay: Some(InputDelay { delay_s: 0.1 }),
        ..Effects::default()
    };
    assert_eq!(some.active(), ["input_delay", "slip"]);
    let p = RobotProfile::pioneer3dx();
    let ex = constant(0.3, 0.2);
    let rec = run(&p, &ex, &exact(1.0, 5, Effects::default()));
    assert_eq!(rec.meta("effects"), Some("none"));
    let rec = run(&p, &ex, &exact(1.0, 5, some));
    let meta = rec.meta("effects").expect("effects metadata");
    assert!(
        meta.contains("InputDelay") && meta.contains("Slip"),
        "{meta}"
    );
}

/// TOML: an Effects with every effect on survives a round trip; the documented one-table-each
/// form parses to the same value, at top level and as `[effects.…]` tables of SimSettings;
/// unknown fields and tables are refused.
#[test]
fn effects_toml_round_trip() {
    let all = all_on();
    let text = toml::to_string(&all).expect("serialise");
    let back: Effects = toml::from_str(&text).expect("parse back");
    assert_eq!(back, all);

    let written = r#"
[input_delay]
delay_s = 0.3

[acceleration_limit]
v_accel_max = 0.5
w_accel_max = 1.25

[velocity_saturation]
v_max = 1.4
w_max = 5.25

[coulomb_friction]
v_coulomb = 0.05
w_coulomb = 0.1

[wheel_asymmetry]
ratio = 1.1

[payload_change]
time_s = 60.0
theta_after = [0.5208, 0.5018, -0.000998, 0.9965, 0.00526, 1.0768]

[gain_drift]
rate_per_s = -0.001

[slip]
k_v = 0.2
k_w = 0.3

[measurement_noise]
v_std = 0.01
w_std = 0.05

[sample_jitter]
std_s = 0.005
"#;
    let parsed: Effects = toml::from_str(written).expect("parse written");
    assert_eq!(parsed, all);

    // Nested in SimSettings, as the Effects docs show; the other settings keep defaults.
    let settings: SimSettings =
        toml::from_str("measurement_noise = false\n\n[effects.input_delay]\ndelay_s = 0.3\n")
            .expect("settings");
    assert_eq!(
        settings.effects,
        Effects {
            input_delay: Some(InputDelay { delay_s: 0.3 }),
            ..Effects::default()
        }
    );
    assert!(!settings.measurement_noise);
    assert_eq!(settings.seed, SimSettings::default().seed);
    let settings_all = SimSettings {
        effects: all.clone(),
        ..SimSettings::default()
    };
    let text = toml::to_string(&settings_all).expect("serialise settings");
    let back: SimSettings = toml::from_str(&text).expect("parse settings back");
    assert_eq!(back, settings_all);

    // Unknown fields and effects are refused.
    assert!(toml::from_str::<Effects>("[input_delay]\ndelay = 0.3\n").is_err());
    assert!(toml::from_str::<Effects>("[input_delay]\ndelay_s = 0.3\nextra = 1\n").is_err());
    assert!(toml::from_str::<Effects>("[friction]\nv_coulomb = 0.05\n").is_err());
    assert!(toml::from_str::<Effects>("[slip]\nk_v = 0.2\n").is_err());
}
