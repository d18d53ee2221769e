//! The six-θ model with a dead time on the commands — a model whose seventh parameter enters
//! non-linearly, fitted by output error through finite differences of its simulation:
//!
//! ```text
//! v̇(t) = (θ3/θ1) ω² − (θ4/θ1) v + (1/θ1) v_ref(t − τ_d)
//! ω̇(t) = −(θ5/θ2) v ω − (θ6/θ2) ω + (1/θ2) ω_ref(t − τ_d)
//! ```
//!
//! The delayed commands keep the recording's hold (a held staircase shifted by τ_d switches
//! inside the sample windows), so the simulation runs on the merged grid {t_k} ∪ {t_j + τ_d}
//! and maps back: instant outputs are read at t_k, window averages are the length-weighted
//! means of the sub-window averages — exact for any τ_d, not rounded to whole samples.
//! Before the first sample the command is the one that holds the initial state in steady state
//! (zero for a robot at rest, as the simulator's); τ_d < 0 (a lead) is accepted so that finite
//! differences at τ_d = 0 exist.

use wheelid_core::{
    ChannelInfo, CommandHold, DynamicModel, Error, ParamInfo, Recording, Result, Simulation,
    VelocitySampling,
};

use crate::{dynamics, regressor};

/// θ1…θ6 of eq. 2.19, then the dead time.
pub static PARAMS: [ParamInfo; 7] = [
    regressor::PARAMS[0],
    regressor::PARAMS[1],
    regressor::PARAMS[2],
    regressor::PARAMS[3],
    regressor::PARAMS[4],
    regressor::PARAMS[5],
    ParamInfo {
        name: "delay",
        unit: "s",
        description: "dead time between a command and its effect on the drive",
    },
];

/// The command that holds (v0, ω0) in steady state under eq. 2.19:
/// (θ4 v0 − θ3 ω0², θ5 v0 ω0 + θ6 ω0); zero for a robot at rest.
pub(crate) fn holding_command(theta: &[f64], initial: &[f64]) -> (f64, f64) {
    match (theta, initial) {
        ([_, _, t3, t4, t5, t6, ..], [v0, w0, ..]) => {
            (t4 * v0 - t3 * w0 * w0, t5 * v0 * w0 + t6 * w0)
        }
        _ => (0.0, 0.0),
    }
}

/// The sample instants merged with the command switches t_j + `delay` and the `extra` instants
/// that fall inside the recording; returns the merged times and the position of each t_k in
/// them.
///
/// Points closer than the rounding of the time stamps are one point (a switch landing on a
/// sample instant); anything larger is a real sub-interval, however short, so that finite
/// differences in τ_d of 1e-8 s still see the switch move.
///
/// # Errors
/// [`Error::InvalidSetting`] for an empty recording or time stamps too close to merge.
pub(crate) fn merged_grid(
    rec: &Recording,
    delay: f64,
    extra: &[f64],
) -> Result<(Vec<f64>, Vec<usize>)> {
    let n = rec.len();
    if n == 0 {
        return Err(Error::InvalidSetting("the recording is empty".into()));
    }
    let tmax = rec.t.iter().fold(0.0f64, |a, t| a.max(t.abs()));
    let eps = 64.0 * f64::EPSILON * tmax.max(1.0);
    let inside = |x: &f64| *x > rec.t[0] && *x < rec.t[n - 1];
    if delay == 0.0 && !extra.iter().any(inside) {
        return Ok((rec.t.clone(), (0..n).collect()));
    }
    // Three sorted lists merged in linear time: the samples, the delayed samples, the extras.
    let shifted: Vec<f64> = rec.t.iter().map(|&t| t + delay).filter(inside).collect();
    let mut others: Vec<f64> = extra.iter().copied().filter(inside).collect();
    others.sort_by(f64::total_cmp);
    let mut grid = merge_sorted(&merge_sorted(&rec.t, &shifted), &others);
    grid.dedup_by(|a, b| (*a - *b).abs() <= eps);
    // Sample instants must come out exactly: a switch within eps of t_k (dedup may have kept
    // either) is replaced by t_k itself.
    let mut merged_t = Vec::with_capacity(grid.len());
    let mut index = Vec::with_capacity(n);
    let mut k = 0;
    for &g in &grid {
        if k < n && (g - rec.t[k]).abs() <= eps {
            index.push(merged_t.len());
            merged_t.push(rec.t[k]);
            k += 1;
        } else {
            merged_t.push(g);
        }
    }
    if index.len() != n {
        return Err(Error::InvalidSetting(
            "recording times are too close together to merge with the delay grid".into(),
        ));
    }
    Ok((merged_t, index))
}

/// The sorted union (with repeats) of two sorted lists.
fn merge_sorted(a: &[f64], b: &[f64]) -> Vec<f64> {
    let mut out = Vec::with_capacity(a.len() + b.len());
    let (mut i, mut j) = (0, 0);
    while i < a.len() && j < b.len() {
        if a[i] <= b[j] {
            out.push(a[i]);
            i += 1;
        } else {
            out.push(b[j]);
            j += 1;
        }
    }
    out.extend_from_slice(&a[i..]);
    out.extend_from_slice(&b[j..]);
    out
}

/// Eq. 2.19 with an input dead time τ_d = θ7 \[s\] (`delayed`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct InputDelay;

impl InputDelay {
    /// The command held at time `tau` (staircase or linear as the recording says); before the
    /// first sample it is `before`, after the last the last one.
    pub(crate) fn command_at(rec: &Recording, tau: f64, before: (f64, f64)) -> (f64, f64) {
        let t = &rec.t;
        if tau < t[0] {
            return before;
        }
        let n = t.len();
        if tau >= t[n - 1] {
            return (rec.v_ref[n - 1], rec.w_ref[n - 1]);
        }
        // Last j with t_j ≤ τ.
        let j = t.partition_point(|&x| x <= tau) - 1;
        match rec.command_hold() {
            CommandHold::Zoh => (rec.v_ref[j], rec.w_ref[j]),
            CommandHold::Sampled => {
                let a = (tau - t[j]) / (t[j + 1] - t[j]);
                (
                    rec.v_ref[j] + a * (rec.v_ref[j + 1] - rec.v_ref[j]),
                    rec.w_ref[j] + a * (rec.w_ref[j + 1] - rec.w_ref[j]),
                )
            }
        }
    }
}

impl DynamicModel for InputDelay {
    fn name(&self) -> &str {
        "delayed"
    }
    fn params(&self) -> &[ParamInfo] {
        &PARAMS
    }
    fn channels(&self) -> &[ChannelInfo] {
        &regressor::CHANNELS
    }
    fn simulate(&self, theta: &[f64], rec: &Recording, initial: &[f64]) -> Result<Simulation> {
        let (&delay, th) = theta.split_last().ok_or_else(|| {
            Error::InvalidSetting("θ of the delayed model has 7 values, got 0".into())
        })?;
        if th.len() != 6 || !delay.is_finite() {
            return Err(Error::InvalidSetting(format!(
                "θ of the delayed model has 7 finite values, got {theta:?}"
            )));
        }
        let n = rec.len();
        let (merged_t, index) = merged_grid(rec, delay, &[])?;
        // A held command is read at the middle of its sub-interval, so that rounding of
        // t_j + τ_d − τ_d cannot pick the neighbouring sample.
        let zoh = rec.command_hold() == CommandHold::Zoh;
        let hold = holding_command(th, initial);
        let (vr, wr): (Vec<f64>, Vec<f64>) = (0..merged_t.len())
            .map(|i| {
                let t = match merged_t.get(i + 1) {
                    Some(next) if zoh => 0.5 * (merged_t[i] + next),
                    _ => merged_t[i],
                };
                Self::command_at(rec, t - delay, hold)
            })
            .unzip();
        let m = merged_t.len();
        let mut fine = Recording::new(
            rec.source.clone(),
            merged_t.clone(),
            vr,
            wr,
            vec![0.0; m],
            vec![0.0; m],
        )?;
        let avg = rec.velocity_sampling() == VelocitySampling::WindowAverage;
        fine.set_meta(
            "command_hold",
            match rec.command_hold() {
                CommandHold::Zoh => "zoh",
                CommandHold::Sampled => "sampled",
            },
        );
        fine.set_meta(
            "velocity_sampling",
            if avg { "window_average" } else { "instant" },
        );
        let [v, w] = dynamics::simulate(th, &fine, initial)?;
        let mut out = [Vec::with_capacity(n), Vec::with_capacity(n)];
        for (kk, &i) in index.iter().enumerate() {
            for (o, y) in out.iter_mut().zip([&v, &w]) {
                if !avg || kk == 0 {
                    o.push(y[i]);
                } else {
                    let i0 = index[kk - 1];
                    let total: f64 = (i0 + 1..=i)
                        .map(|j| (merged_t[j] - merged_t[j - 1]) * y[j])
                        .sum();
                    o.push(total / (merged_t[i] - merged_t[i0]));
                }
            }
        }
        Ok(Vec::from(out))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn recording(avg: bool) -> Recording {
        let n = 60;
        let t: Vec<f64> = (0..n).map(|k| k as f64 * 0.1).collect();
        let vr: Vec<f64> = t.iter().map(|&x| 0.3 + 0.2 * (1.1 * x).sin()).collect();
        let wr: Vec<f64> = t.iter().map(|&x| 0.8 * (0.6 * x).cos()).collect();
        let mut rec = Recording::new("d", t, vr, wr, vec![0.0; n], vec![0.0; n]).expect("valid");
        rec.set_meta("command_hold", "zoh");
        if avg {
            rec.set_meta("velocity_sampling", "window_average");
        }
        rec
    }

    const THETA: [f64; 6] = [0.26, 0.25, -0.05, 0.9965, 0.08, 1.0768];

    #[test]
    fn zero_delay_is_the_plain_model_and_one_sample_is_a_shifted_command() {
        for avg in [false, true] {
            let rec = recording(avg);
            let x0 = [0.1, 0.05];
            let plain = dynamics::simulate(&THETA, &rec, &x0).expect("sim");
            let mut th7 = THETA.to_vec();
            th7.push(0.0);
            let d0 = InputDelay.simulate(&th7, &rec, &x0).expect("sim");
            for ch in 0..2 {
                for k in 0..rec.len() {
                    approx::assert_abs_diff_eq!(d0[ch][k], plain[ch][k], epsilon = 1e-12);
                }
            }
            // τ_d = one period: the same as the commands shifted by one sample by hand.
            let mut shifted = rec.clone();
            shifted.v_ref.rotate_right(1);
            shifted.w_ref.rotate_right(1);
            // Before the recording, the command that holds x0 in steady state.
            let hold = holding_command(&THETA, &x0);
            shifted.v_ref[0] = hold.0;
            shifted.w_ref[0] = hold.1;
            let want = dynamics::simulate(&THETA, &shifted, &x0).expect("sim");
            th7[6] = 0.1;
            let d1 = InputDelay.simulate(&th7, &rec, &x0).expect("sim");
            for ch in 0..2 {
                for k in 0..rec.len() {
                    approx::assert_abs_diff_eq!(d1[ch][k], want[ch][k], epsilon = 1e-12);
                }
            }
        }
    }

    #[test]
    fn outputs_move_continuously_with_a_fractional_delay() {
        // Finite differences in τ_d need continuity: ±1 µs around 0.05 s moves the outputs by
        // O(1e-6), while the 0.05 s delay itself moves them by O(1e-2).
        let rec = recording(true);
        let x0 = [0.0, 0.0];
        let sim = |d: f64| {
            let mut th = THETA.to_vec();
            th.push(d);
            InputDelay.simulate(&th, &rec, &x0).expect("sim")
        };
        let (a, m) = (sim(0.0), sim(0.05));
        let (m1, m2) = (sim(0.05 + 1e-6), sim(0.05 - 1e-6));
        let mut moved = 0.0f64;
        for k in 0..rec.len() {
            for ch in 0..2 {
                assert!((m1[ch][k] - m2[ch][k]).abs() < 1e-5, "k {k}");
                moved = moved.max((m[ch][k] - a[ch][k]).abs());
            }
        }
        assert!(
            moved > 1e-3,
            "a 50 ms delay moved the outputs by only {moved}"
        );
    }
}
