//! End to end inside the crate: drive the simulated Burger with a rich multisine for 120 s,
//! record it as a host does (read, then send), condition it with wheelid-core, build the
//! `vw-pd-coulomb` regression and solve it by ordinary least squares — and get the robot's θ
//! and friction back. This is what `wheelid run` does with the plugin loaded, minus the
//! loading.

use nalgebra::DVector;
use wheelid_core::condition::{condition, make_uniform, suggest_cutoff};
use wheelid_core::{ConditionSettings, Recording, RegressorModel, Robot};
use wheelid_turtlebot_plugin::{TurtleBot, TurtleBotSettings, VwPdCoulomb};

/// A multisine: Σ a sin(2π f t + φ) with Schroeder phases φ_i = −π i(i−1)/N (a low crest
/// factor), scaled to the given peak over [0, 120 s] (by sampling).
fn multisine(freqs: &[f64], peak: f64, offset: f64) -> impl Fn(f64) -> f64 + use<> {
    let n = freqs.len() as f64;
    let phases: Vec<f64> = (0..freqs.len())
        .map(|i| -std::f64::consts::PI * (i * (i + 1)) as f64 / n)
        .collect();
    let raw = {
        let (freqs, phases) = (freqs.to_vec(), phases.clone());
        move |t: f64| -> f64 {
            freqs
                .iter()
                .zip(&phases)
                .map(|(f, p)| (std::f64::consts::TAU * f * t + p).sin())
                .sum()
        }
    };
    let max = (0..12_000)
        .map(|k| raw(k as f64 * 0.01).abs())
        .fold(0.0f64, f64::max);
    move |t| offset + peak * raw(t) / max
}

/// Drives `bot` for `duration` seconds with (v_ref(t), ω_ref(t)): read, then send, as the
/// host's `drive` does; row k = (t_k, the command returned after report k, v_k, ω_k).
fn drive(
    bot: &mut TurtleBot,
    duration: f64,
    v: impl Fn(f64) -> f64,
    w: impl Fn(f64) -> f64,
) -> Recording {
    let n = (duration / bot.period_s()).round() as usize;
    let mut cols: [Vec<f64>; 5] = Default::default();
    for _ in 0..n {
        let o = bot.read().expect("read");
        let (vr, wr) = bot.send(v(o.t), w(o.t)).expect("send");
        for (c, x) in cols.iter_mut().zip([o.t, vr, wr, o.v, o.w]) {
            c.push(x);
        }
    }
    let [t, vr, wr, vm, wm] = cols;
    let mut rec = Recording::new("turtlebot3", t, vr, wr, vm, wm).expect("valid");
    rec.set_meta("command_hold", "zoh");
    rec
}

#[test]
fn least_squares_on_the_regression_recovers_the_burgers_theta_and_friction() {
    let mut bot = TurtleBot::new(TurtleBotSettings {
        seed: 11,
        ..TurtleBotSettings::default()
    })
    .expect("bot");
    let truth = bot.theta();
    // Zero-mean commands (so that v and ω change sign: the friction shows), rich between
    // 0.02 and 2 Hz around the Burger's 1.1 Hz corner, peaks 0.15 m/s and 1 rad/s (the wheels
    // reach their 0.227 m/s limit only at the rare joint peaks; the clamped command is what is
    // recorded).
    let v = multisine(
        &[0.024, 0.056, 0.104, 0.184, 0.328, 0.536, 0.824, 1.256, 1.84],
        0.15,
        0.0,
    );
    let w = multisine(
        &[0.04, 0.072, 0.136, 0.232, 0.424, 0.664, 1.016, 1.528, 2.0],
        1.0,
        0.0,
    );
    let rec = drive(&mut bot, 120.0, v, w);
    assert_eq!(rec.len(), 3600);
    let (rec, resampled) = make_uniform(&rec).expect("uniform");
    assert!(resampled.is_none());
    // wheelid's default cut-off rule (twice the commands' 95 % band): 4 Hz here.
    let (fc, _) = suggest_cutoff(&[&rec]).expect("cut-off");
    assert!((fc - 4.0).abs() < 1e-6, "{fc}");
    let data = condition(&rec, None, fc, &ConditionSettings::default()).expect("conditioned");
    let regs = VwPdCoulomb.regression(&data).expect("regression");
    let mut theta = [f64::NAN; 8];
    for r in &regs {
        let svd = r.x.clone().svd(true, true);
        let sol: DVector<f64> = svd.solve(&r.y, 1e-12).expect("solved");
        for (&p, x) in r.params.iter().zip(sol.iter()) {
            theta[p] = *x;
        }
    }
    let names = ["θ1", "θ2", "θ3", "θ4", "θ5", "θ6", "v_coulomb", "w_coulomb"];
    for i in 0..8 {
        eprintln!(
            "{:>9}: true {:+.6e}  estimated {:+.6e}  error {:+.2} %",
            names[i],
            truth[i],
            theta[i],
            100.0 * (theta[i] - truth[i]) / truth[i]
        );
    }
    // Measured with this seed: θ1 −0.8 %, θ2 −1.4 %, θ4 −0.3 %, θ6 −0.5 %, v_coulomb −1.8 %,
    // w_coulomb −0.4 %. Over seeds 1–6 as well, the time constants come out 0.9–1.8 % low
    // every time (the ZOH half-sample alignment and the derivative stencil at 30 Hz against a
    // 0.14 s time constant: a bias of the method, not of the plugin), the gains 0.1–0.5 % low,
    // and the friction between −6 % and +1 % (noise-limited). So: 3 % on θ1, θ2, θ4, θ6 and
    // 8 % on the friction …
    for (i, tol) in [
        (0, 0.03),
        (1, 0.03),
        (3, 0.03),
        (5, 0.03),
        (6, 0.08),
        (7, 0.08),
    ] {
        let rel = (theta[i] - truth[i]).abs() / truth[i].abs();
        assert!(
            rel < tol,
            "{}: {} vs {} ({:.2} %)",
            names[i],
            theta[i],
            truth[i],
            100.0 * rel
        );
    }
    // … and θ3, θ5, whose true values are tiny (module `burger`: −3.5e-6 and −5.4e-4), by
    // their effect: the errors in θ3 ω² and θ5 v ω stay below 1 mm/s and 0.01 rad/s at the
    // peaks driven (ω = 1 rad/s, v = 0.15 m/s).
    assert!((theta[2] - truth[2]).abs() * 1.0 < 1e-3, "θ3 {}", theta[2]);
    assert!(
        (theta[4] - truth[4]).abs() * 0.15 * 1.0 < 0.01,
        "θ5 {}",
        theta[4]
    );
}
