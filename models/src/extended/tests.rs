//! Tests of the extended model (module docs of [`super`]): closed forms, the simulator's
//! equations and sensitivities against differences.

use super::*;
use crate::delay::InputDelay;
use wheelid_core::WheelTerms;

const THETA: [f64; 6] = [0.26, 0.25, -0.05, 0.9965, 0.08, 1.0768];

fn recording(avg: bool, n: usize, f: impl Fn(f64) -> (f64, f64)) -> Recording {
    recording_at(avg, n, 0.1, f)
}

/// `n` samples `dt` \[s\] apart of the commands `f`(t), held, the velocities zero; window
/// averages with `avg`, else instants.
pub(super) fn recording_at(
    avg: bool,
    n: usize,
    dt: f64,
    f: impl Fn(f64) -> (f64, f64),
) -> Recording {
    let t: Vec<f64> = (0..n).map(|k| k as f64 * dt).collect();
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
        let e = Extended::new(&[Candidate::INPUT_DELAY], 0.34).expect("model");
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
    let e = Extended::new(&[Candidate::VELOCITY_SATURATION], 0.34).expect("model");
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
    let e = Extended::new(&[Candidate::ACCELERATION_LIMIT], 0.34).expect("model");
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

/// A step on both wheels that clamps them, with the loop's derivative term δ = 0 and 0.05 s
/// (`derivative_s`, gone while clamped): (θ1 − δ) v̇ = c − (θ4 − 1) v while the wheels'
/// voltage u − v − δ v̇ exceeds c, i.e. v = c/(θ4 − 1)(1 − e^{−(θ4−1)t/(θ1−δ)}) up to v1 where
/// u − v1 − δ (c − (θ4 − 1) v1)/(θ1 − δ) = c, at t1, then the plain lag towards u/θ4 (its
/// θ1 whole: the derivative term is part of it); a turn on the spot clamps both wheels
/// opposite: (θ2 − δ) ω̇ = c/κ − (θ6 − 1) ω.
#[test]
fn effort_clamp_matches_its_closed_form() {
    let (c, track, mu) = (0.2, 0.3, 1.5);
    let kappa = mu * track / 2.0;
    let e = Extended::new(&[Candidate::EFFORT_CLAMP], track).expect("model");
    for delta in [0.0, 0.05] {
        let mut th = THETA.to_vec();
        th.extend([c, mu, delta]);
        let (u, a4) = (1.0, THETA[3] - 1.0);
        let rec = recording(false, 101, |_| (u, 0.0));
        let [v, _] = <[Vec<f64>; 2]>::try_from(e.simulate(&th, &rec, &[0.0, 0.0]).expect("sim"))
            .expect("two channels");
        let inertia = THETA[0] - delta;
        let clamped = |t: f64| c / a4 * (1.0 - (-a4 * t / inertia).exp());
        let v1 = (u - c - delta * c / inertia) / (1.0 - delta * a4 / inertia);
        let t1 = -inertia / a4 * (1.0 - a4 * v1 / c).ln();
        let tau = THETA[0] / THETA[3];
        for (k, vk) in v.iter().enumerate() {
            let t = rec.t[k];
            let want = if t <= t1 {
                clamped(t)
            } else {
                u / THETA[3] + (v1 - u / THETA[3]) * (-(t - t1) / tau).exp()
            };
            approx::assert_abs_diff_eq!(*vk, want, epsilon = 2e-4);
        }
        // Spin: ω_ref = 6 rad/s, the wheels' voltages ±κ (6 − ω − δ ω̇) stay above c over the
        // 1 s. (θ3 = θ5 = 0: no coupling through v.)
        let rec = recording(false, 11, |_| (0.0, 6.0));
        th[2] = 0.0;
        th[4] = 0.0;
        let [_, w] = <[Vec<f64>; 2]>::try_from(e.simulate(&th, &rec, &[0.0, 0.0]).expect("sim"))
            .expect("two channels");
        let (a6, inertia) = (THETA[5] - 1.0, THETA[1] - delta);
        for (k, wk) in w.iter().enumerate() {
            let t = rec.t[k];
            let want = c / kappa / a6 * (1.0 - (-a6 * t / inertia).exp());
            let accel = (c / kappa - a6 * want) / inertia;
            assert!(kappa * (6.0 - want - delta * accel) > c);
            approx::assert_abs_diff_eq!(*wk, want, epsilon = 1e-8);
        }
    }
}

/// A dead band β on a straight command u from rest (both wheels' efforts u − v − δ v̇ beyond
/// it): θ1 v̇ = u − β − θ4 v, v = (u − β)/θ4 (1 − e^(−θ4 t/θ1)), whether or not the loop has
/// a derivative term δ (a wheel beyond its band keeps it) and whatever the wheels' split (a
/// straight run has no turn effort to split); a command within the band does not move the
/// robot.
#[test]
fn a_dead_band_matches_its_closed_form() {
    let (u, beta, track) = (0.4, 0.07, 0.3);
    // 1.2 s: the efforts stay beyond the band (with θ4 < 1 the steady effort u − v falls
    // inside it, past 1.4 s).
    let rec = recording(false, 13, |_| (u, 0.0));
    let cases: [(&[Candidate], Vec<f64>); 2] = [
        (&[Candidate::DEAD_ZONE], vec![beta, 0.7]),
        // A clamp no effort reaches, with its derivative term.
        (
            &[Candidate::EFFORT_CLAMP, Candidate::DEAD_ZONE],
            vec![100.0, 1.0, 0.05, beta, 1.0],
        ),
    ];
    for (cands, extra) in cases {
        let e = Extended::new(cands, track).expect("model");
        let mut th = THETA.to_vec();
        th.extend(&extra);
        let [v, w] = <[Vec<f64>; 2]>::try_from(e.simulate(&th, &rec, &[0.0, 0.0]).expect("sim"))
            .expect("two channels");
        for (k, vk) in v.iter().enumerate() {
            let want = (u - beta) / THETA[3] * (1.0 - (-THETA[3] * rec.t[k] / THETA[0]).exp());
            approx::assert_abs_diff_eq!(*vk, want, epsilon = 1e-7);
            approx::assert_abs_diff_eq!(w[k], 0.0, epsilon = 1e-12);
        }
        let within = recording(false, 11, |_| (0.5 * beta, 0.0));
        let y = e.simulate(&th, &within, &[0.0, 0.0]).expect("sim");
        assert!(
            y[0].iter().all(|x| x.abs() < 1e-12),
            "{cands:?}: {:?}",
            y[0]
        );
    }
}

/// A right wheel with effort gain a on a straight command u: the steady state solves
/// 0 = ((a+1)/2) E_v + ((a−1)/2) κ E_ω − (θ4 − 1) v and
/// 0 = ((a−1)/(2κ)) E_v + ((a+1)/2) E_ω − (θ6 − 1) ω, E_v = u − v, E_ω = −ω (θ3 = θ5 = 0):
/// inside the high-gain loop v stays near u/θ4 and the steady turn is small, the turn while
/// accelerating is not.
/// The clamp's closed form (as above) with θ1 = 3 ms at 10 Hz, where the integration is
/// ETDRK4 (the plan says so): the window average over the first 0.1 s, which holds the
/// clamped ramp (12 ms) and the 3 ms lag after it, against the closed form's mean by the
/// trapezoid rule on 1e5 points. The clamp lets go inside a 5 ms step whose linear part
/// is still the clamped one: 2.2e-4 (RK4 at τ/5 is within 2e-4 of the kink above).
#[test]
fn a_stiff_effort_clamp_matches_its_closed_form_in_window_averages() {
    let (c, track, mu, u) = (0.2, 0.3, 1.5, 1.0);
    let mut theta = THETA;
    theta[0] = 0.003;
    assert!(dynamics::plan(&theta, 0.1).exponential());
    let e = Extended::new(&[Candidate::EFFORT_CLAMP], track).expect("model");
    let mut th = theta.to_vec();
    th.extend([c, mu, 0.0]);
    let rec = recording(true, 4, |_| (u, 0.0));
    let [v, _] = <[Vec<f64>; 2]>::try_from(e.simulate(&th, &rec, &[0.0, 0.0]).expect("sim"))
        .expect("two channels");
    let a4 = theta[3] - 1.0;
    let t1 = -theta[0] / a4 * (1.0 - a4 * (u - c) / c).ln();
    let tau = theta[0] / theta[3];
    let want = |t: f64| {
        if t <= t1 {
            c / a4 * (1.0 - (-a4 * t / theta[0]).exp())
        } else {
            u / theta[3] + (u - c - u / theta[3]) * (-(t - t1) / tau).exp()
        }
    };
    let m = 100_000;
    let dt = 0.1 / m as f64;
    let mean = (0..m)
        .map(|i| 0.5 * (want(i as f64 * dt) + want((i + 1) as f64 * dt)) * dt)
        .sum::<f64>()
        / 0.1;
    approx::assert_abs_diff_eq!(v[1], mean, epsilon = 3e-4);
    approx::assert_abs_diff_eq!(v[3], u / theta[3], epsilon = 1e-9);
}

#[test]
fn amp_asymmetry_steady_state_solves_the_wheel_equations() {
    let (a, track, u) = (0.8, 0.3, 0.5);
    let kappa = track / 2.0;
    let e = Extended::new(&[Candidate::AMP_ASYMMETRY], track).expect("model");
    let mut th = THETA.to_vec();
    th[2] = 0.0;
    th[4] = 0.0;
    th.push(a);
    let rec = recording(false, 400, |_| (u, 0.0));
    let [v, w] = <[Vec<f64>; 2]>::try_from(e.simulate(&th, &rec, &[0.0, 0.0]).expect("sim"))
        .expect("two channels");
    let (p, q) = ((a + 1.0) / 2.0, (a - 1.0) / 2.0);
    // Rows in (v, ω): [p + θ4 − 1, q κ; q/κ, p + θ6 − 1] (v, ω) = (p u, q u/κ).
    let m = nalgebra::Matrix2::new(p + THETA[3] - 1.0, q * kappa, q / kappa, p + THETA[5] - 1.0);
    let rhs = nalgebra::Vector2::new(p * u, q * u / kappa);
    let x = m.lu().solve(&rhs).expect("regular");
    approx::assert_abs_diff_eq!(v[399], x[0], epsilon = 1e-9);
    approx::assert_abs_diff_eq!(w[399], x[1], epsilon = 1e-9);
    // Inside the high-gain loop the static turn is small; the transient's is not.
    let peak = w[..20].iter().fold(0.0f64, |m, x| m.max(x.abs()));
    assert!((v[399] - u / THETA[3]).abs() < 0.01 * u, "{}", v[399]);
    assert!(peak > 5.0 * w[399].abs(), "{peak} vs {}", w[399]);
}

#[test]
fn analytic_sensitivities_match_central_differences_with_every_candidate() {
    // A rich command with a start at speed (the holding command matters before the first
    // delayed sample and where the rate limit starts).
    let x0 = [0.15, 0.3];
    let cases: Vec<(Vec<Candidate>, Vec<f64>)> = vec![
        (vec![], vec![]),
        (vec![Candidate::INPUT_DELAY], vec![0.23]),
        (vec![Candidate::VELOCITY_SATURATION], vec![0.35, 0.6]),
        (vec![Candidate::ACCELERATION_LIMIT], vec![0.8, 2.0]),
        (vec![Candidate::COULOMB_FRICTION], vec![0.02, 0.05]),
        (vec![Candidate::WHEEL_ASYMMETRY], vec![1.1]),
        (
            vec![Candidate::PAYLOAD_CHANGE],
            vec![3.3, 0.3, 0.3, -0.04, 0.1],
        ),
        (vec![Candidate::GAIN_DRIFT], vec![0.01]),
        (vec![Candidate::OUTPUT_DELAY], vec![0.23]),
        (vec![Candidate::DEAD_ZONE], vec![0.05, 0.8]),
        (
            vec![Candidate::EFFORT_CLAMP, Candidate::DEAD_ZONE],
            vec![0.12, 1.3, 0.03, 0.02, 0.9],
        ),
        (
            vec![Candidate::OUTPUT_DELAY, Candidate::PAYLOAD_CHANGE],
            vec![0.23, 3.3, 0.3, 0.3, -0.04, 0.1],
        ),
        (vec![Candidate::SLIP], vec![0.05, 0.1]),
        (vec![Candidate::WHEEL_FRICTION], vec![0.03]),
        (vec![Candidate::EFFORT_CLAMP], vec![0.12, 1.3, 0.0]),
        (vec![Candidate::EFFORT_CLAMP], vec![0.12, 1.3, 0.03]),
        (vec![Candidate::AMP_ASYMMETRY], vec![0.9]),
        (
            vec![Candidate::AMP_ASYMMETRY, Candidate::EFFORT_CLAMP],
            vec![1.1, 0.12, 1.3, 0.03],
        ),
        (
            vec![Candidate::GAIN_DRIFT, Candidate::EFFORT_CLAMP],
            vec![-0.01, 0.12, 0.8, 0.03],
        ),
        (
            vec![Candidate::COULOMB_FRICTION, Candidate::WHEEL_FRICTION],
            vec![0.02, 0.05, 0.03],
        ),
        (
            vec![
                Candidate::INPUT_DELAY,
                Candidate::ACCELERATION_LIMIT,
                Candidate::VELOCITY_SATURATION,
            ],
            vec![0.17, 0.8, 2.0, 0.35, 0.6],
        ),
    ];
    for avg in [false, true] {
        let rec = recording(avg, 80, |x| {
            (
                0.3 + 0.25 * (1.3 * x).sin() + 0.1 * (3.1 * x).cos(),
                0.8 * (0.7 * x).cos() - 0.3 * (2.3 * x).sin(),
            )
        });
        for (cands, extra) in &cases {
            let e = Extended::new(cands, 0.34).expect("model");
            let mut th = THETA.to_vec();
            th.extend_from_slice(extra);
            let (y, sens) = e
                .simulate_with_sensitivities(&th, &rec, &x0)
                .expect("simulates")
                .expect("has sensitivities");
            let plain = e.simulate(&th, &rec, &x0).expect("simulates");
            for c in 0..2 {
                assert_eq!(
                    y[c], plain[c],
                    "{cands:?}: the pass's outputs are the simulation's"
                );
            }
            let central = |j: usize| -> Vec<Vec<f64>> {
                let (mut up, mut dn) = (th.clone(), th.clone());
                let (mut xu, mut xd) = (x0.to_vec(), x0.to_vec());
                let h = 1e-6
                    * if j < th.len() {
                        th[j].abs().max(1e-2)
                    } else {
                        1.0
                    };
                if j < th.len() {
                    up[j] += h;
                    dn[j] -= h;
                } else {
                    xu[j - th.len()] += h;
                    xd[j - th.len()] -= h;
                }
                let a = e.simulate(&up, &rec, &xu).expect("simulates");
                let b = e.simulate(&dn, &rec, &xd).expect("simulates");
                (0..2)
                    .map(|c| {
                        a[c].iter()
                            .zip(&b[c])
                            .map(|(p, q)| (p - q) / (2.0 * h))
                            .collect()
                    })
                    .collect()
            };
            // θ1…θ6 and the initial state (the candidates' columns are differences already).
            for j in (0..6).chain(th.len()..th.len() + 2) {
                let want = central(j);
                for (c, want_c) in want.iter().enumerate() {
                    let got: Vec<f64> = if j < th.len() {
                        sens.theta[c].column(j).iter().copied().collect()
                    } else {
                        sens.initial[c]
                            .column(j - th.len())
                            .iter()
                            .copied()
                            .collect()
                    };
                    let scale = want_c.iter().fold(0.0f64, |a, x| a.max(x.abs()));
                    let err = got
                        .iter()
                        .zip(want_c)
                        .fold(0.0f64, |a, (g, w)| a.max((g - w).abs()));
                    assert!(
                        err <= 1e-5 * scale + 1e-9,
                        "{cands:?} avg={avg} column {j} channel {c}: error {err:.3e} of {scale:.3e}"
                    );
                }
            }
        }
    }
}

/// A larger right tyre (`tyre_asymmetry`, ρ) is the amplifier asymmetry a = 1/ρ with the right
/// wheel's row scaled by 1/ρ: at any state the wheels' accelerations ṁ_R,L = v̇ ± (d/2) ω̇ are
/// the amplifier's with ṁ_R × 1/ρ (and the Jacobian's rows likewise), and the steady state is
/// the amplifier's (a row scale moves no equilibrium).
#[test]
fn a_larger_tyre_is_the_amplifier_asymmetry_with_its_wheels_row_scaled() {
    let (rho, track) = (1.05, 0.3);
    let h = 0.5 * track;
    let tyre = Terms {
        wheels: Some(WheelTerms {
            right_lever: 1.0 / rho,
            ..WheelTerms::default()
        }),
        right_row: Some(1.0 / rho),
        ..Terms::default()
    };
    let amp = Terms {
        wheels: Some(WheelTerms {
            right_gain: 1.0 / rho,
            ..WheelTerms::default()
        }),
        right_row: None,
        ..tyre
    };
    let inv = [1.0 / THETA[0], 1.0 / THETA[1]];
    let c = Cmd::<0>::at([0.4, -0.7], [[]; 2], false);
    let (ft, fa) = (
        Field::new(&Vec::new(), track, &tyre),
        Field::new(&Vec::new(), track, &amp),
    );
    for (v, w) in [(0.0, 0.0), (0.3, 0.5), (-0.2, 1.1)] {
        let lt = ft.local(&THETA, &inv, (v, w), &c, true);
        let la = fa.local(&THETA, &inv, (v, w), &c, true);
        let wheels = |f: [f64; 2]| [f[0] + h * f[1], f[0] - h * f[1]];
        let (mt, ma) = (wheels(lt.f), wheels(la.f));
        approx::assert_abs_diff_eq!(mt[0], ma[0] / rho, epsilon = 1e-12);
        approx::assert_abs_diff_eq!(mt[1], ma[1], epsilon = 1e-12);
        for col in 0..2 {
            let (jt, ja) = (
                wheels([lt.a[0][col], lt.a[1][col]]),
                wheels([la.a[0][col], la.a[1][col]]),
            );
            approx::assert_abs_diff_eq!(jt[0], ja[0] / rho, epsilon = 1e-12);
            approx::assert_abs_diff_eq!(jt[1], ja[1], epsilon = 1e-12);
        }
    }
    // Steady state: the amplifier's at a = 1/ρ; the candidate's own parameter sets both.
    let rec = recording(false, 400, |_| (0.5, 0.2));
    let et = Extended::new(&[Candidate::TYRE_ASYMMETRY], track).expect("model");
    let ea = Extended::new(&[Candidate::AMP_ASYMMETRY], track).expect("model");
    let mut th = THETA.to_vec();
    th.push(rho);
    let yt = et.simulate(&th, &rec, &[0.0, 0.0]).expect("sim");
    th[6] = 1.0 / rho;
    let ya = ea.simulate(&th, &rec, &[0.0, 0.0]).expect("sim");
    for ch in 0..2 {
        approx::assert_abs_diff_eq!(yt[ch][399], ya[ch][399], epsilon = 1e-9);
        // …but not the transient.
        assert!((yt[ch][1] - ya[ch][1]).abs() > 1e-4, "{ch}");
    }
}

/// A clamped wheel with a larger tyre pushes the chassis 1/ρ as hard; a weak amplifier's
/// clamped wheel as hard as the other (the supply clamps the voltage after the amplifier's
/// gain and before the tyre's lever). Demanding 1 m/s of effort on both wheels, clamped at
/// 0.1: the tyre gives Ē_v = (0.1/ρ + 0.1)/2, Ē_ω = (0.1/ρ − 0.1)/(2κ); the amplifier
/// Ē_v = 0.1, Ē_ω = 0. Unclamped (0.01 m/s) the two are the same 1/ρ. And a weak amplifier
/// beside a larger tyre multiply, in either order of the effects.
#[test]
fn a_larger_tyre_acts_after_the_clamp_and_beside_an_amplifier() {
    let (rho, cl, kappa) = (1.05, 0.1, 0.2);
    let tyre = WheelTerms {
        effort_max: cl,
        mix: kappa,
        right_lever: 1.0 / rho,
        ..WheelTerms::default()
    };
    let amp = WheelTerms {
        right_gain: 1.0 / rho,
        right_lever: 1.0,
        ..tyre
    };
    let correction = |wt: &WheelTerms, e: [f64; 2]| {
        let f = wheels::proportional(wt, 1.0, e);
        (f.d, f.dx)
    };
    let (dt, _) = correction(&tyre, [1.0, 0.0]);
    approx::assert_relative_eq!(1.0 + dt[0], 0.5 * (cl / rho + cl), epsilon = 1e-12);
    approx::assert_relative_eq!(dt[1], (cl / rho - cl) / (2.0 * kappa), epsilon = 1e-12);
    let (da, _) = correction(&amp, [1.0, 0.0]);
    approx::assert_relative_eq!(1.0 + da[0], cl, epsilon = 1e-12);
    approx::assert_abs_diff_eq!(da[1], 0.0, epsilon = 1e-12);
    let small = [0.01, 0.0];
    let ((ft, jt), (fa, ja)) = (correction(&tyre, small), correction(&amp, small));
    for r in 0..2 {
        approx::assert_relative_eq!(ft[r], fa[r], epsilon = 1e-15);
        for k in 0..2 {
            approx::assert_relative_eq!(jt[r][k], ja[r][k], epsilon = 1e-15);
        }
    }
    use crate::effects::Candidate;
    let apply = |order: &[(Candidate, f64)]| {
        let mut terms = Terms::default();
        for (c, p) in order {
            c.effect().apply(&[*p], &mut terms).expect("applies");
        }
        terms.wheels.expect("wheel terms")
    };
    let (a, t) = (
        (Candidate::AMP_ASYMMETRY, 0.95),
        (Candidate::TYRE_ASYMMETRY, rho),
    );
    for w in [apply(&[a, t]), apply(&[t, a])] {
        approx::assert_relative_eq!(w.right_gain, 0.95, epsilon = 1e-15);
        approx::assert_relative_eq!(w.right_lever, 1.0 / rho, epsilon = 1e-15);
    }
}

/// A drive gain drifting over the drive (`gain_drift`, g = 1 + r (t − t_drive)) counts from the
/// drive's start in a window cut from it ([`Recording::window`]): the window, started from the
/// whole run's state at its first sample, is the whole run's simulation there (to the
/// integration's rounding); counted from the window's own start, it would be off by the gain
/// the drive has lost by then (r · 5 s = 10 % here).
#[test]
fn a_drift_counts_from_the_drives_start_in_a_window() {
    let rec = recording(false, 120, |x| {
        (0.3 + 0.2 * (1.1 * x).sin(), 0.8 * (0.6 * x).cos())
    });
    let e = Extended::new(&[Candidate::GAIN_DRIFT], 0.34).expect("model");
    let mut th = THETA.to_vec();
    th.push(-0.02);
    let whole = e.simulate(&th, &rec, &[0.1, 0.05]).expect("sim");
    let start = 50;
    let window = rec.window(start..120);
    assert_eq!(window.drive_start(), 0.0);
    let x0 = [whole[0][start], whole[1][start]];
    let part = e.simulate(&th, &window, &x0).expect("sim");
    for ch in 0..2 {
        for k in 0..window.len() {
            approx::assert_abs_diff_eq!(part[ch][k], whole[ch][start + k], epsilon = 1e-9);
        }
    }
    let mut own = window.clone();
    own.meta.retain(|(key, _)| key != wheelid_core::DRIVE_START);
    let off = e.simulate(&th, &own, &x0).expect("sim");
    let gap = (0..own.len())
        .map(|k| (off[0][k] - whole[0][start + k]).abs())
        .fold(0.0, f64::max);
    assert!(gap > 1e-3, "counted from the window's start: {gap}");
}

/// A dead time of the measurements τ_o is one of the commands with the time-varying stages'
/// clocks moved by τ_o: the outputs with `output_delay` τ_o and a payload change at T are those
/// with `input_delay` τ_o and the change at T + τ_o, and differ from those with it at T.
#[test]
fn an_output_delay_is_an_input_delay_with_the_clocks_moved() {
    let (tau, ts) = (0.23, 3.3);
    let after = [0.3, 0.3, -0.04, 0.1];
    for avg in [false, true] {
        let rec = recording(avg, 80, |x| {
            (0.3 + 0.2 * (1.1 * x).sin(), 0.8 * (0.6 * x).cos())
        });
        let x0 = [0.1, 0.05];
        let run = |cands: &[Candidate], p: &[f64]| {
            let mut th = THETA.to_vec();
            th.extend_from_slice(p);
            Extended::new(cands, 0.34)
                .expect("model")
                .simulate(&th, &rec, &x0)
                .expect("sim")
        };
        let with = |d: f64, t: f64| [&[d, t][..], &after[..]].concat();
        let out = run(
            &[Candidate::OUTPUT_DELAY, Candidate::PAYLOAD_CHANGE],
            &with(tau, ts),
        );
        let moved = run(
            &[Candidate::INPUT_DELAY, Candidate::PAYLOAD_CHANGE],
            &with(tau, ts + tau),
        );
        let unmoved = run(
            &[Candidate::INPUT_DELAY, Candidate::PAYLOAD_CHANGE],
            &with(tau, ts),
        );
        let mut apart = 0.0_f64;
        for ch in 0..2 {
            for k in 0..rec.len() {
                approx::assert_abs_diff_eq!(out[ch][k], moved[ch][k], epsilon = 1e-12);
                apart = apart.max((out[ch][k] - unmoved[ch][k]).abs());
            }
        }
        assert!(apart > 1e-3, "the payload's clock moved: {apart}");
    }
}
