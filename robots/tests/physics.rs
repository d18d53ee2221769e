//! The rigid-body backend against the maps and closed forms: noise-free runs identify the θ
//! the physical constants imply (output error); steady turns settle where the maps say; the
//! conventions write what they claim; effects change the recording the way the physics says.

use wheelid_core::{Recording, Robot, Timing};
use wheelid_models::{VwPd, WheelPd};
use wheelid_robots::Excitation;
use wheelid_robots::excitation::Signal;
use wheelid_robots::physics::{
    Controller, Payload, PhysicalProfile, PhysicsEffects, PhysicsRobot, PhysicsSettings,
    simulate_physics_recording,
};
use wheelid_solvers::OutputError;

/// Constant commands (v_ref, ω_ref).
fn constant(v: f64, w: f64) -> Excitation {
    Excitation {
        v_ref: Signal::Constant { value: v },
        w_ref: Signal::Constant { value: w },
    }
}

fn settings(timing: Timing, duration: f64) -> PhysicsSettings {
    PhysicsSettings {
        duration_s: duration,
        timing,
        encoders: false,
        ..PhysicsSettings::default()
    }
}

#[test]
fn the_three_conventions_write_the_same_motion_as_they_claim() {
    let p = PhysicalProfile::khepera3();
    let exc = Excitation::random_multisine(2, 0.05, 0.15, 2.0, 1.0).expect("excitation");
    let rec = |t| simulate_physics_recording(&p, &exc, &settings(t, 4.0)).expect("simulates");
    let (a, b, c) = (
        rec(Timing::Instant),
        rec(Timing::WindowEnd),
        rec(Timing::WindowMiddle),
    );
    assert_eq!(a.timing(), Some(Timing::Instant));
    assert_eq!(c.timing(), Some(Timing::WindowMiddle));
    let dt = p.period_s;
    let swing = a.v.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    for k in 1..a.len() - 2 {
        // (b) is the window mean ending at t_k: after the start (k ≥ 25), the trapezoid of the
        // instants within 1 % of the swing (the instants are samples, the window a true mean).
        let trap = 0.5 * (a.v[k - 1] + a.v[k]);
        if k >= 25 {
            assert!(
                (b.v[k] - trap).abs() < 0.01 * swing,
                "k {k}: {} vs {trap}",
                b.v[k]
            );
        }
        // (c) is (b) of the next row, stamped half a window earlier, with this row's command.
        approx::assert_abs_diff_eq!(c.t[k], b.t[k] + 0.5 * dt, epsilon = 1e-9);
        approx::assert_abs_diff_eq!(c.v[k], b.v[k + 1], epsilon = 1e-12);
        assert_eq!(c.v_ref[k], b.v_ref[k]);
    }
}

#[test]
fn a_voltage_clamp_caps_the_top_speed_at_the_back_emf_balance() {
    // Saturated amplifier (the P term asks for far more than U): per wheel
    // (m r²/2 + I_e) ω̇ = (k_a/R_a)(U − k_b ω) − B_e ω, so with B_e = 0
    // ω(t) = (U/k_b)(1 − e^(−t/τ)), τ = R_a (m r²/2 + I_e)/(k_a k_b), and v = r ω.
    let p = PhysicalProfile::khepera3();
    let volts = 1.0;
    let mut s = settings(Timing::Instant, 6.0);
    s.effects = PhysicsEffects {
        voltage_clamp: Some(volts),
        ..PhysicsEffects::default()
    };
    let rec = simulate_physics_recording(&p, &constant(5.0, 0.0), &s).expect("simulates");
    let tau = p.r_a * (0.5 * p.m * p.r * p.r + p.i_e) / (p.k_a * p.k_b);
    let v_top = p.r * volts / p.k_b;
    for t_check in [1.0, 3.0, 6.0] {
        let k = rec
            .t
            .iter()
            .position(|&t| t >= t_check - 1e-9)
            .unwrap_or(rec.len() - 1);
        let want = v_top * (1.0 - (-rec.t[k] / tau).exp());
        assert!(
            (rec.v[k] - want).abs() < 0.01 * want,
            "t {}: {} vs {want} (top speed {v_top}, τ {tau})",
            rec.t[k],
            rec.v[k]
        );
    }
}

#[test]
fn a_setpoint_rate_limit_ramps_at_its_slope() {
    let p = PhysicalProfile::pioneer3dx();
    let mut s = settings(Timing::Instant, 3.0);
    s.effects = PhysicsEffects {
        rate_limit: Some(wheelid_robots::physics::RateLimit {
            v_accel: 0.3,
            w_accel: 1.0,
        }),
        ..PhysicsEffects::default()
    };
    let rec = simulate_physics_recording(&p, &constant(0.6, 0.0), &s).expect("simulates");
    // After the lag θ1/θ4 settles, v follows the ramp 0.3 t delayed by about θ1/θ4.
    let th = p.theta();
    let lag = th[0] / th[3];
    let k = rec.t.iter().position(|&t| t >= 1.5).expect("1.5 s");
    let want = 0.3 * (rec.t[k] - lag) / th[3];
    assert!(
        (rec.v[k] - want).abs() < 0.02 * want,
        "{} vs {want}",
        rec.v[k]
    );
}

#[test]
fn on_a_slippery_floor_the_body_accelerates_at_the_traction_limit() {
    // Wheels that slip push with μ·N; N on the wheels is m g (1 − b/x_c) (the caster carries
    // the rest), so the body's acceleration is at most μ g (1 − b/x_c) while the encoders see
    // the spinning wheels run ahead.
    let p = PhysicalProfile::khepera3();
    let mu = 0.05;
    let mut s = settings(Timing::Instant, 0.3);
    s.effects = PhysicsEffects {
        floor_mu: Some(mu),
        ..PhysicsEffects::default()
    };
    let rec = simulate_physics_recording(&p, &constant(0.4, 0.0), &s).expect("simulates");
    let x = rec.x.as_ref().expect("pose");
    let k = rec.len() - 1;
    let t = rec.t[k];
    let a_max = mu * 9.81 * p.wheel_load_share();
    let body_v = (x[k] - x[k - 1]) / (rec.t[k] - rec.t[k - 1]);
    assert!(
        body_v <= 1.05 * a_max * t,
        "body {body_v} vs μ·g·t {}",
        a_max * t
    );
    assert!(
        rec.v[k] > 1.5 * body_v,
        "encoders {} vs body {body_v}",
        rec.v[k]
    );
}

/// The Pioneer-like robot's v/ω-PD loop on a slippery floor: its unloaded wheels must stay
/// on their setpoints while the body lags behind at the traction limit — what a real robot's
/// encoders show when it slips. With too light a derivative filter (`drive`'s module docs:
/// the midpoint extrapolation doubles the derivative's gain at the Nyquist frequency) the
/// wheels went unstable: the controller asked 64 kV, both wheels spun at 78 m/s and the
/// encoders read v ≈ 78 m/s, ω = 0 for a command of (0.2 m/s, 0.5 rad/s).
#[test]
fn a_slipping_pioneer_keeps_its_wheels_on_their_setpoints() {
    let p = PhysicalProfile::pioneer3dx();
    let mu = 0.02;
    let mut s = settings(Timing::Instant, 2.0);
    s.effects = PhysicsEffects {
        floor_mu: Some(mu),
        ..PhysicsEffects::default()
    };
    let (v_ref, w_ref) = (0.2, 0.5);
    let rec = simulate_physics_recording(&p, &constant(v_ref, w_ref), &s).expect("simulates");
    // After the first 0.3 s the wheels are near their setpoints (the clean loop's lag is
    // θ1/θ4 ≈ 0.26 s; unloaded wheels are faster) and never far above them.
    for k in (0..rec.len()).filter(|&k| rec.t[k] >= 0.3) {
        assert!(
            (0.5 * v_ref..1.2 * v_ref).contains(&rec.v[k]),
            "t = {}: encoders' v {} for v_ref {v_ref}",
            rec.t[k],
            rec.v[k]
        );
        assert!(
            (0.5 * w_ref..1.2 * w_ref).contains(&rec.w[k]),
            "t = {}: encoders' ω {} for ω_ref {w_ref}",
            rec.t[k],
            rec.w[k]
        );
    }
    // …while the body slips: at 0.5 s it has covered less than the wheels' rims.
    let (x, y) = (rec.x.as_ref().expect("pose"), rec.y.as_ref().expect("pose"));
    let k = at(&rec, 0.5);
    let body = x[k].hypot(y[k]);
    let rims: f64 = (1..=k)
        .map(|i| 0.5 * (rec.v[i] + rec.v[i - 1]) * (rec.t[i] - rec.t[i - 1]))
        .sum();
    assert!(body < 0.7 * rims, "body {body} m vs the rims' {rims} m");
}

/// Steady turns against the map's steady state: with constant commands eq. 2.19 settles at
/// v = (v_ref + θ3 ω²)/θ4, ω = ω_ref/(θ6 + θ5 v). The engine's set-up (contact stiffness tied
/// to the step) is what makes this hold: at 3 kHz contacts and h = 1 ms the Pioneer-like robot
/// yawed while driving straight and its turns missed the map by 0.1–0.2 %.
#[test]
fn steady_turns_settle_where_the_maps_theta_says() {
    for name in PhysicalProfile::NAMES {
        let p = PhysicalProfile::by_name(name).expect("built in");
        let th = p.theta();
        let (v0, w0) = (0.3 * p.v_max, 0.3 * p.w_max);
        for (vr, wr) in [(0.0, w0), (v0, 0.0), (v0, w0), (v0, -w0), (-v0, w0)] {
            let rec =
                simulate_physics_recording(&p, &constant(vr, wr), &settings(Timing::Instant, 3.0))
                    .expect("simulates");
            let k = rec.len() - 1;
            let (mut v, mut w) = (vr / th[3], wr / th[5]);
            for _ in 0..50 {
                v = (vr + th[2] * w * w) / th[3];
                w = wr / (th[5] + th[4] * v);
            }
            eprintln!(
                "{name} ({vr:+.3}, {wr:+.3}): physics v {:+.6} ω {:+.6}, map v {v:+.6} ω {w:+.6}",
                rec.v[k], rec.w[k]
            );
            assert!(
                (rec.v[k] - v).abs() < 1e-4 * p.v_max,
                "{name}: v {} vs {v}",
                rec.v[k]
            );
            assert!(
                (rec.w[k] - w).abs() < 1e-4 * p.w_max,
                "{name}: ω {} vs {w}",
                rec.w[k]
            );
        }
    }
}

/// A random multisine up to about 1.5× the robot's bandwidth, inside its speed limits.
fn excitation(p: &PhysicalProfile, seed: u64) -> Excitation {
    p.random_multisine(seed).expect("excitation")
}

/// θ by output error on the profile's own model, started 10 % off the map's θ.
fn identify(p: &PhysicalProfile, rec: &Recording) -> Vec<f64> {
    let start: Vec<f64> = p.theta().iter().map(|x| 1.1 * x).collect();
    let recs = std::slice::from_ref(rec);
    let fit = match p.controller {
        Controller::WheelPd { .. } => OutputError::default().fit(&WheelPd, recs, &start),
        Controller::VwPd { .. } => OutputError::default().fit(&VwPd, recs, &start),
    };
    fit.expect("output error fits").theta
}

fn rms(x: impl Iterator<Item = f64>) -> f64 {
    let (s, n) = x.fold((0.0, 0usize), |(s, n), v| (s + v * v, n + 1));
    (s / n.max(1) as f64).sqrt()
}

/// Errors of θ1, θ2, θ4, θ6 in % of the map's, and of θ3, θ5 as their effect on the output:
/// Δθ3·rms(ω²)/θ4 in % of rms(v), Δθ5·rms(vω)/θ6 in % of rms(ω) (their steady-state shares).
fn theta_errors(th: &[f64], map: &[f64; 6], rec: &Recording) -> [f64; 6] {
    let rel = |i: usize| 100.0 * (th[i] - map[i]) / map[i];
    let w2 = rms(rec.w.iter().map(|w| w * w));
    let vw = rms(rec.v.iter().zip(&rec.w).map(|(v, w)| v * w));
    let e3 = 100.0 * (th[2] - map[2]) * w2 / map[3] / rms(rec.v.iter().copied());
    let e5 = 100.0 * (th[4] - map[4]) * vw / map[5] / rms(rec.w.iter().copied());
    [rel(0), rel(1), e3, rel(3), e5, rel(5)]
}

/// Issue 14's check of the maps and the engine set-up: noise-free runs (instants, no encoders,
/// no jitter) identify θ1, θ2, θ4, θ6 within 1 % of the map's θ, and θ3, θ5 within 1 % of
/// their effect on the output.
#[test]
fn noise_free_runs_identify_the_maps_theta() {
    for (name, duration) in [("khepera3", 60.0), ("pioneer3dx", 120.0)] {
        let p = PhysicalProfile::by_name(name).expect("built in");
        let rec = simulate_physics_recording(
            &p,
            &excitation(&p, 1),
            &settings(Timing::Instant, duration),
        )
        .expect("simulates");
        let map = p.theta();
        let th = identify(&p, &rec);
        let e = theta_errors(&th, &map, &rec);
        eprintln!(
            "{name} ({duration} s at {} Hz, h = {} ms):",
            1.0 / p.period_s,
            1e3 * p.physics_step_s
        );
        eprintln!("  param        map   identified   error %");
        for i in 0..6 {
            let how = if i == 2 || i == 4 {
                " (of the output)"
            } else {
                ""
            };
            eprintln!(
                "  θ{}   {:>10.6}   {:>10.6}   {:+.3}{how}",
                i + 1,
                map[i],
                th[i],
                e[i]
            );
        }
        for (i, x) in e.iter().enumerate() {
            assert!(x.abs() < 1.0, "{name}: θ{} off by {x:.3} %", i + 1);
        }
    }
}

/// The rigid-body steady state of a wheel-PD robot, from the physics (not from θ): per wheel
/// (k_a/R_a)(g_i k_P (ω_i,ref − ω_i) − k_b ω_i) − B_e ω_i − F_c sign ω_i = r F_i, with the
/// body's F_r + F_l = −m b ω², F_r − F_l = 2 m b v ω/d, v = r (ω_r + ω_l)/2, ω = r (ω_r − ω_l)/d.
/// Returns (v, ω) measured by the wheels.
fn wheel_pd_steady(
    p: &PhysicalProfile,
    g: [f64; 2],
    f_c: f64,
    v_ref: f64,
    w_ref: f64,
) -> (f64, f64) {
    let Controller::WheelPd { k_p, .. } = p.controller else {
        panic!("a wheel-PD profile")
    };
    let refs = [
        (v_ref + p.d * w_ref / 2.0) / p.r,
        (v_ref - p.d * w_ref / 2.0) / p.r,
    ];
    let (mut v, mut w) = (v_ref, w_ref);
    for _ in 0..200 {
        let (sum, diff) = (-p.m * p.b * w * w, 2.0 * p.m * p.b * v * w / p.d);
        let f = [(sum + diff) / 2.0, (sum - diff) / 2.0];
        let om = [0, 1].map(|i| {
            let load = p.r_a / p.k_a * (p.r * f[i] + f_c * refs[i].signum());
            (g[i] * k_p * refs[i] - load) / (g[i] * k_p + p.k_b + p.r_a * p.b_e / p.k_a)
        });
        (v, w) = (p.r * (om[0] + om[1]) / 2.0, p.r * (om[0] - om[1]) / p.d);
    }
    (v, w)
}

/// The Khepera-like robot with a weak P gain, so that the back-EMF share k_b/(g k_P) makes an
/// amplifier's gain visible in the steady state (θ1 ≈ 0.43 s).
fn soft_khepera() -> PhysicalProfile {
    let mut p = PhysicalProfile::khepera3();
    p.controller = Controller::WheelPd { k_p: 0.2, k_d: 0.0 };
    p
}

fn with_effects(timing: Timing, duration: f64, effects: PhysicsEffects) -> PhysicsSettings {
    PhysicsSettings {
        effects,
        ..settings(timing, duration)
    }
}

/// Index of the first row at or after `t`.
fn at(rec: &Recording, t: f64) -> usize {
    rec.t
        .iter()
        .position(|&x| x >= t - 1e-9)
        .unwrap_or(rec.len() - 1)
}

#[test]
fn dry_friction_in_the_wheel_joints_lowers_the_steady_speed_by_its_torque() {
    let p = PhysicalProfile::khepera3();
    let f_c = 0.0025;
    let s = with_effects(
        Timing::Instant,
        2.0,
        PhysicsEffects {
            dry_friction_nm: Some(f_c),
            ..PhysicsEffects::default()
        },
    );
    let rec = simulate_physics_recording(&p, &constant(0.15, 0.0), &s).expect("simulates");
    let (v, _) = wheel_pd_steady(&p, [1.0; 2], f_c, 0.15, 0.0);
    let (v0, _) = wheel_pd_steady(&p, [1.0; 2], 0.0, 0.15, 0.0);
    let k = rec.len() - 1;
    eprintln!(
        "dry friction {f_c} N·m: v {:.6} (closed form {v:.6}, without {v0:.6})",
        rec.v[k]
    );
    assert!(
        (rec.v[k] - v).abs() < 2e-3 * (v0 - v).abs().max(1e-3 * v),
        "{} vs {v}",
        rec.v[k]
    );
    assert!(v0 - v > 0.02 * v0, "the friction shows");
}

#[test]
fn one_weak_amplifier_turns_the_robot_as_the_torque_balance_says() {
    let p = soft_khepera();
    let s = with_effects(
        Timing::Instant,
        12.0,
        PhysicsEffects {
            amp_gain_right: Some(0.9),
            ..PhysicsEffects::default()
        },
    );
    let rec = simulate_physics_recording(&p, &constant(0.15, 0.0), &s).expect("simulates");
    let (v, w) = wheel_pd_steady(&p, [0.9, 1.0], 0.0, 0.15, 0.0);
    let k = rec.len() - 1;
    eprintln!(
        "right amplifier ×0.9: v {:.6} ω {:.6} (closed form {v:.6}, {w:.6})",
        rec.v[k], rec.w[k]
    );
    assert!((rec.v[k] - v).abs() < 1e-3 * v, "v {} vs {v}", rec.v[k]);
    assert!(
        (rec.w[k] - w).abs() < 0.01 * w.abs(),
        "ω {} vs {w}",
        rec.w[k]
    );
}

#[test]
fn a_sagging_battery_slows_the_robot_as_its_gain_falls() {
    // Gain g(t) = 1 − 0.5 t/T; the loop follows the slow sag a time constant late,
    // τ(g) = R_a (m r²/2 + I_e)/(k_a (g k_P + k_b)) (0.43 s at g = 1, 0.74 s at g = 0.525).
    let p = soft_khepera();
    let duration = 20.0;
    let s = with_effects(
        Timing::Instant,
        duration,
        PhysicsEffects {
            gain_sag: Some(0.5),
            ..PhysicsEffects::default()
        },
    );
    let rec = simulate_physics_recording(&p, &constant(0.15, 0.0), &s).expect("simulates");
    let Controller::WheelPd { k_p, .. } = p.controller else {
        panic!("wheel-PD")
    };
    let gain = |t: f64| 1.0 - 0.5 * t / duration;
    for t in [5.0, 10.0, 19.0] {
        let k = at(&rec, t);
        let tau =
            p.r_a * (0.5 * p.m * p.r * p.r + p.i_e) / (p.k_a * (gain(rec.t[k]) * k_p + p.k_b));
        let (v, _) = wheel_pd_steady(&p, [gain(rec.t[k] - tau); 2], 0.0, 0.15, 0.0);
        let (v_now, _) = wheel_pd_steady(&p, [gain(rec.t[k]); 2], 0.0, 0.15, 0.0);
        eprintln!(
            "gain sag at {t} s (g = {:.3}, τ = {tau:.2} s): v {:.6}, steady state a τ earlier {v:.6} (at g(t): {v_now:.6})",
            gain(rec.t[k]),
            rec.v[k]
        );
        assert!(
            (rec.v[k] - v).abs() < 5e-4 * v,
            "t {t}: {} vs {v}",
            rec.v[k]
        );
    }
}

#[test]
fn a_larger_right_tyre_curves_the_path_the_encoders_call_straight() {
    // The host converts with the nominal r; the body turns at (1.03 v_r − v_l)/d with v_r, v_l
    // the wheel speeds the host reports.
    let p = PhysicalProfile::khepera3();
    let f = 1.03;
    let s = with_effects(
        Timing::Instant,
        3.0,
        PhysicsEffects {
            tyre_radius_right: Some(f),
            ..PhysicsEffects::default()
        },
    );
    let rec = simulate_physics_recording(&p, &constant(0.15, 0.0), &s).expect("simulates");
    let phi = rec.phi.as_ref().expect("pose");
    let (k0, k1) = (at(&rec, 2.0), rec.len() - 1);
    let body_w = (phi[k1] - phi[k0]) / (rec.t[k1] - rec.t[k0]);
    let (vr, vl) = (
        rec.v[k1] + rec.w[k1] * p.d / 2.0,
        rec.v[k1] - rec.w[k1] * p.d / 2.0,
    );
    let want = (f * vr - vl) / p.d;
    eprintln!(
        "right tyre ×{f}: body ω {body_w:.5} rad/s, (f v_r − v_l)/d {want:.5}, encoders' ω {:.2e}",
        rec.w[k1]
    );
    assert!((body_w - want).abs() < 0.01 * want, "{body_w} vs {want}");
    assert!(
        rec.w[k1].abs() < 0.05 * want,
        "the encoders see (nearly) straight driving"
    );
}

#[test]
fn command_latency_shifts_the_response_by_the_latency() {
    let p = PhysicalProfile::khepera3();
    let exc = excitation(&p, 4);
    let lag = 3;
    let latency = lag as f64 * p.period_s;
    let base =
        simulate_physics_recording(&p, &exc, &settings(Timing::Instant, 10.0)).expect("simulates");
    let s = with_effects(
        Timing::Instant,
        10.0,
        PhysicsEffects {
            latency_s: Some(latency),
            ..PhysicsEffects::default()
        },
    );
    let late = simulate_physics_recording(&p, &exc, &s).expect("simulates");
    // Cross-correlation of the two v series over shifts 0..8: its peak is at the latency.
    let xcorr = |l: usize| {
        (20..base.len() - 10)
            .map(|k| late.v[k] * base.v[k - l])
            .sum::<f64>()
    };
    let best = (0..8)
        .max_by(|&a, &b| xcorr(a).total_cmp(&xcorr(b)))
        .expect("shifts");
    let swing = rms(base.v.iter().copied());
    let diff = (20..base.len())
        .map(|k| (late.v[k] - base.v[k - lag]).abs())
        .fold(0.0, f64::max);
    eprintln!(
        "latency {latency} s: cross-correlation peak at {best} samples, shifted difference {:.2e} of rms v",
        diff / swing
    );
    assert_eq!(best, lag);
    assert!(diff < 1e-3 * swing, "{diff}");
}

#[test]
fn a_payload_set_down_mid_run_moves_the_turn_to_the_loaded_maps_steady_state() {
    let p = PhysicalProfile::khepera3();
    let payload = Payload {
        mass_kg: 0.3,
        at_s: 2.0,
        x_m: 0.02,
        size_m: 0.03,
    };
    let s = with_effects(
        Timing::Instant,
        5.0,
        PhysicsEffects {
            payload: Some(payload),
            ..PhysicsEffects::default()
        },
    );
    let (vr, wr) = (0.15, 1.8);
    let rec = simulate_physics_recording(&p, &constant(vr, wr), &s).expect("simulates");
    for (profile, t) in [(p.clone(), 1.95), (payload.loaded(&p), 4.9)] {
        let th = profile.theta();
        let (mut v, mut w) = (vr, wr);
        for _ in 0..50 {
            v = (vr + th[2] * w * w) / th[3];
            w = wr / (th[5] + th[4] * v);
        }
        let k = at(&rec, t);
        eprintln!(
            "{} at {t} s: ω {:.6}, map {w:.6} (θ5 {:.4})",
            profile.name, rec.w[k], th[4]
        );
        assert!(
            (rec.w[k] - w).abs() < 1e-4 * p.w_max,
            "{}: {} vs {w}",
            profile.name,
            rec.w[k]
        );
        assert!(
            (rec.v[k] - v).abs() < 1e-4 * p.v_max,
            "{}: {} vs {v}",
            profile.name,
            rec.v[k]
        );
    }
}

#[test]
fn a_payload_raises_theta_as_the_map_of_the_loaded_robot_says() {
    let p = PhysicalProfile::khepera3();
    let payload = Payload {
        mass_kg: 0.3,
        at_s: 0.0,
        x_m: 0.02,
        size_m: 0.03,
    };
    let s = with_effects(
        Timing::Instant,
        40.0,
        PhysicsEffects {
            payload: Some(payload),
            ..PhysicsEffects::default()
        },
    );
    let rec = simulate_physics_recording(&p, &excitation(&p, 5), &s).expect("simulates");
    let loaded = payload.loaded(&p);
    let map = loaded.theta();
    let th = identify(&loaded, &rec);
    let e = theta_errors(&th, &map, &rec);
    eprintln!(
        "payload 0.3 kg: unloaded θ {:.5?}\n  loaded map {map:.5?}\n  identified {th:.5?}\n  error % {e:.3?}",
        p.theta()
    );
    // The mass raises θ1 by a third; set near the centre it raises θ2 (yaw inertia) by 4 %,
    // and m·b, θ3 and θ5, by four fifths.
    let th0 = p.theta();
    assert!(map[0] > 1.3 * th0[0] && map[1] > 1.03 * th0[1] && map[4] > 1.5 * th0[4]);
    for (i, x) in e.iter().enumerate() {
        assert!(x.abs() < 1.0, "θ{} off by {x:.3} %", i + 1);
    }
}

#[test]
fn encoder_ticks_quantise_the_window_averages() {
    let p = PhysicalProfile::khepera3();
    let s = PhysicsSettings {
        encoders: true,
        ..settings(Timing::WindowEnd, 4.0)
    };
    let rec = simulate_physics_recording(&p, &excitation(&p, 6), &s).expect("simulates");
    // Each wheel speed is a whole number of ticks per window: r q n / Δ, q = 2π/ticks.
    let unit = p.r * 2.0 * std::f64::consts::PI / p.ticks_per_rev / p.period_s;
    let mut moving = 0;
    for k in 1..rec.len() {
        for x in [
            rec.v[k] + rec.w[k] * p.d / 2.0,
            rec.v[k] - rec.w[k] * p.d / 2.0,
        ] {
            let n = x / unit;
            assert!((n - n.round()).abs() < 1e-6, "row {k}: {n} ticks");
            moving += usize::from(n.round() != 0.0);
        }
    }
    assert!(moving > rec.len(), "the wheels turned");
}

#[test]
fn under_jitter_window_averages_are_the_motion_over_the_actual_windows() {
    // Straight driving: each (b) row's v is the axle's displacement over the actual (jittered)
    // window divided by its length; (c) is (b) of the next row stamped at the window's middle.
    let p = PhysicalProfile::khepera3();
    let exc = Excitation {
        v_ref: excitation(&p, 7).v_ref,
        w_ref: Signal::Constant { value: 0.0 },
    };
    let s = |timing| PhysicsSettings {
        jitter: 0.2,
        ..settings(timing, 4.0)
    };
    let b = simulate_physics_recording(&p, &exc, &s(Timing::WindowEnd)).expect("simulates");
    let c = simulate_physics_recording(&p, &exc, &s(Timing::WindowMiddle)).expect("simulates");
    let x = b.x.as_ref().expect("pose");
    let swing = rms(b.v.iter().copied());
    let (mut dt_min, mut dt_max) = (f64::MAX, 0.0f64);
    for k in 1..b.len() - 1 {
        let dt = b.t[k] - b.t[k - 1];
        (dt_min, dt_max) = (dt_min.min(dt), dt_max.max(dt));
        assert!((b.t[k] - k as f64 * p.period_s).abs() <= 0.2 * p.period_s + p.physics_step_s);
        let moved = (x[k] - x[k - 1]) / dt;
        assert!(
            (b.v[k] - moved).abs() < 1e-3 * swing,
            "row {k}: {} vs {moved}",
            b.v[k]
        );
        approx::assert_abs_diff_eq!(c.t[k], 0.5 * (b.t[k] + b.t[k + 1]), epsilon = 1e-12);
        approx::assert_abs_diff_eq!(c.v[k], b.v[k + 1], epsilon = 1e-12);
        assert_eq!(c.v_ref[k], b.v_ref[k]);
    }
    eprintln!(
        "jitter ±20 %: windows {:.1}–{:.1} ms",
        1e3 * dt_min,
        1e3 * dt_max
    );
    assert!(
        dt_max - dt_min > 0.5 * 0.4 * p.period_s,
        "the instants wander"
    );
}

#[test]
fn the_robot_trait_reads_what_the_recording_writes() {
    // Read, then send: report k averages the window ending at s_k; the command sent after it
    // holds until s_{k+1} — row k of the (b) recording.
    let p = PhysicalProfile::khepera3();
    let exc = excitation(&p, 8);
    let s = PhysicsSettings {
        encoders: true,
        jitter: 0.1,
        ..settings(Timing::WindowEnd, 2.0)
    };
    let rec = simulate_physics_recording(&p, &exc, &s).expect("simulates");
    let mut robot = PhysicsRobot::new(&p, &s).expect("robot");
    for k in 0..rec.len() {
        let o = robot.read().expect("reads");
        let (v, w) = exc.at(o.t);
        assert_eq!(robot.send(v, w).expect("sends"), (v, w));
        approx::assert_abs_diff_eq!(o.t, rec.t[k], epsilon = 1e-12);
        approx::assert_abs_diff_eq!(o.v, rec.v[k], epsilon = 1e-12);
        approx::assert_abs_diff_eq!(o.w, rec.w[k], epsilon = 1e-12);
    }
    assert_eq!(robot.timing(), Some(Timing::WindowEnd));
}

#[test]
fn settings_and_profiles_read_from_toml_and_refuse_unknown_keys() {
    let s: PhysicsSettings = toml::from_str(
        r#"
        duration_s = 30.0
        timing = "window_middle"
        jitter = 0.1
        [effects]
        latency_s = 0.02
        voltage_clamp = 6.0
        gain_sag = 0.1
        gain_decay_tau_s = 600.0
        amp_gain_right = 0.97
        tyre_radius_right = 1.02
        dry_friction_nm = 0.001
        floor_mu = 0.3
        rate_limit = { v_accel = 0.3, w_accel = 1.0 }
        payload = { mass_kg = 0.2, at_s = 10.0, x_m = 0.02, size_m = 0.03 }
        "#,
    )
    .expect("parses");
    assert_eq!(s.timing, Timing::WindowMiddle);
    assert_eq!(s.effects.active().len(), 10);
    PhysicsRobot::new(&PhysicalProfile::khepera3(), &s).expect("valid for the Khepera-like robot");
    // A payload that moves the centre of mass past the caster is refused.
    let mut heavy = s.clone();
    heavy.effects.payload = Some(Payload {
        mass_kg: 5.0,
        at_s: 0.0,
        x_m: 0.06,
        size_m: 0.03,
    });
    let e = PhysicsRobot::new(&PhysicalProfile::khepera3(), &heavy).expect_err("refused");
    assert!(e.to_string().contains("payload"), "{e}");
    assert!(toml::from_str::<PhysicsSettings>("[effects]\nlatency = 0.1").is_err());
    let p: PhysicalProfile =
        toml::from_str(&toml::to_string(&PhysicalProfile::pioneer3dx()).expect("writes"))
            .expect("reads");
    assert_eq!(p, PhysicalProfile::pioneer3dx());
}

#[test]
fn a_slow_onboard_controller_shortens_theta_by_half_its_period() {
    // A digital controller at T_c = 2 ms samples and holds: the feedback lags T_c/2 on
    // average, so θ1 ≈ θ1,map − θ4 T_c/2 and θ2 ≈ θ2,map − θ6 T_c/2 (−3.8 % and −1.7 % here).
    let mut p = PhysicalProfile::khepera3();
    let t_c = 2e-3;
    p.controller_period_s = Some(t_c);
    let rec = simulate_physics_recording(&p, &excitation(&p, 9), &settings(Timing::Instant, 30.0))
        .expect("simulates");
    let map = p.theta();
    let th = identify(&p, &rec);
    let want = [map[0] - map[3] * t_c / 2.0, map[1] - map[5] * t_c / 2.0];
    eprintln!(
        "controller at {} ms: θ1 {:.6} (map {:.6}, map − θ4 T_c/2 {:.6}), θ2 {:.6} (map {:.6}, − θ6 T_c/2 {:.6})",
        1e3 * t_c,
        th[0],
        map[0],
        want[0],
        th[1],
        map[1],
        want[1]
    );
    for i in 0..2 {
        let shift = map[i] - want[i];
        assert!(
            (th[i] - want[i]).abs() < 0.1 * shift,
            "θ{}: {} vs {}",
            i + 1,
            th[i],
            want[i]
        );
    }
}

/// A sensor delay on the physics backend: the encoders' readings reach the host 1.3 periods
/// late while the true pose does not; `heading_lag` reads the lag off the heading under every
/// convention, within 5 % of the truth, and reads none on the clean twin (|τ̂| under a tenth of
/// a period). With the encoders' quantisation and noise on (the harness's recordings).
#[test]
fn a_sensor_delay_is_read_off_the_true_heading_under_every_convention() {
    for p in [PhysicalProfile::khepera3(), PhysicalProfile::pioneer3dx()] {
        let exc = p.random_multisine(3).expect("excitation");
        let delay = 1.3 * p.period_s;
        for timing in Timing::ALL {
            let mut s = PhysicsSettings {
                duration_s: 40.0,
                timing,
                ..PhysicsSettings::default()
            };
            let clean = simulate_physics_recording(&p, &exc, &s).expect("simulates");
            s.effects.sensor_delay_s = Some(delay);
            let late = simulate_physics_recording(&p, &exc, &s).expect("simulates");
            let (l0, se0) = wheelid_models::effects::heading_lag(&[clean]).expect("clean lag");
            let (l1, se1) = wheelid_models::effects::heading_lag(&[late]).expect("late lag");
            eprintln!(
                "{} {timing:?}: clean {:.2} ± {:.2} ms, delayed {:.2} ± {:.2} ms (true {:.1})",
                p.name,
                1e3 * l0,
                1e3 * se0,
                1e3 * l1,
                1e3 * se1,
                1e3 * delay
            );
            assert!(
                l0.abs() < 0.1 * p.period_s,
                "{} {timing:?}: clean {l0}",
                p.name
            );
            assert!(
                (l1 - delay).abs() < 0.05 * delay,
                "{} {timing:?}: {l1}",
                p.name
            );
        }
    }
}

/// A sensor delay on a slippery floor: where the wheels slip the encoders' turn runs ahead
/// of the body's, and those windows pull the heading's lag short. `heading_lag` drops them
/// (trimming until no window is an outlier) and reads 2.2 periods within 10 % on the
/// Khepera-like robot with the wheels slipping on about half of a 60 s drive: 41.8 ms for 44.0
/// (three trims, the rule before 2026-11-29, read 34.3 ms here and 30–47 % short on the
/// harness's seeds 1081, 1082).
#[test]
fn a_sensor_delay_is_read_off_the_true_heading_where_the_wheels_slip() {
    let p = PhysicalProfile::khepera3();
    let exc = p.random_multisine(3).expect("excitation");
    let delay = 2.2 * p.period_s;
    let mut s = PhysicsSettings {
        duration_s: 60.0,
        timing: Timing::WindowEnd,
        ..PhysicsSettings::default()
    };
    s.effects.floor_mu = Some(0.15);
    s.effects.sensor_delay_s = Some(delay);
    let rec = simulate_physics_recording(&p, &exc, &s).expect("simulates");
    let (lag, se) = wheelid_models::effects::heading_lag(&[rec]).expect("lag");
    eprintln!(
        "slipping: {:.2} ± {:.2} ms (true {:.1})",
        1e3 * lag,
        1e3 * se,
        1e3 * delay
    );
    assert!((lag - delay).abs() < 0.1 * delay, "{lag} vs {delay}");
}

/// An amplifier dead band b on the Khepera-like robot's wheel-PD loop: driving straight at a
/// constant command, each wheel settles where k_P (ω_ref − ω) − b = (k_b + R_a B_e/k_a) ω
/// (the loop's voltage less the band covers the back-EMF and the viscous loss), 30 % of the
/// clean robot's voltage taken off by the band: the speed drops by r b/(k_P + c), within 5 %
/// (0.09 % of the speed: the loop's gain is high, and a band shows in transients and slow
/// turns rather than in a straight run's speed).
#[test]
fn an_amplifier_dead_band_lowers_the_steady_speed_as_the_closed_form_says() {
    let p = PhysicalProfile::khepera3();
    let Controller::WheelPd { k_p, .. } = p.controller else {
        panic!("a wheel-PD profile");
    };
    let v_ref = 0.1;
    let w_ref = v_ref / p.r;
    let c = p.k_b + p.r_a * p.b_e / p.k_a;
    let band = 0.3 * c * k_p * w_ref / (k_p + c);
    let mut s = settings(Timing::Instant, 3.0);
    let steady = |s: &PhysicsSettings| {
        let rec = simulate_physics_recording(&p, &constant(v_ref, 0.0), s).expect("simulates");
        rec.v[rec.len() - 1]
    };
    let clean = steady(&s);
    s.effects.dead_band_v = Some(band);
    let banded = steady(&s);
    let want = |b: f64| p.r * (k_p * w_ref - b) / (k_p + c);
    let (drop, want_drop) = (clean - banded, want(0.0) - want(band));
    eprintln!(
        "clean {clean:.7} vs {:.7}; drop {drop:.3e} vs {want_drop:.3e}",
        want(0.0)
    );
    assert!((clean / want(0.0) - 1.0).abs() < 1e-4, "clean {clean}");
    assert!(
        (drop / want_drop - 1.0).abs() < 0.05,
        "drop {drop} vs {want_drop}"
    );
}
