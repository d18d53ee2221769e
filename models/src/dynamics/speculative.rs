//! The free run of a long recording on several threads, bit for bit the serial one.
//!
//! The free-run simulation is a recursion over the samples,
//!
//! ```text
//! x_k = F_k(x_{k−1}),   y_k = G_k(x_{k−1})          (k = 1 … n − 1, x_0 = (v0, ω0))
//! ```
//!
//! ([`FreeRun::step`]: one sample interval of eq. 2.19 under the recording's commands), serial
//! by nature. A stable model forgets its initial state: two runs under the same commands from
//! different states approach each other as e^{−t/τ}, and in floating point they meet — the same
//! bits in both components — after some tens of time constants, from where they are one run.
//!
//! So the recording is cut into parts, one per thread. Part 0 runs from the initial state, every
//! later part from a guess (the measured velocities at its start), all at once; each later part
//! keeps its first [`CHECK`] states. Then, part by part, the exact run goes on from the previous
//! part's exact end into the next part, replacing its outputs, until its state equals the
//! part's own state bit for bit: from there the part's outputs and its end are the serial run's.
//! A part the exact run does not meet within its check window (an unstable θ, or one that
//! forgets too slowly) is run on to its end by the exact run: the serial cost, never another
//! answer. The output is the serial simulation's whatever θ, bit for bit (tests).

use super::FreeRun;

/// Samples from which a free run is split into parts.
pub(super) const MIN_SAMPLES: usize = 50_000;
/// Parts a thread runs side by side ([`FreeRun::step_lanes`]).
pub(super) const LANES: usize = 4;
/// Most parts a free run is split into: [`LANES`] a thread on up to 8 threads.
pub(super) const MAX_PARTS: usize = 8 * LANES;
/// States kept at the start of each later part: the exact run must meet the part within this
/// many samples (2¹⁶: 22 min at 50 Hz) or goes on alone to its end.
const CHECK: usize = 1 << 16;

/// One part's run: its last state and its first states (for a later part).
struct Part {
    end: [f64; 2],
    checks: Vec<[f64; 2]>,
}

/// The outputs (v, ω), each of length `run.len()`, of the free run in `parts` parts (1: the
/// serial recursion) — the same bits whatever `parts`.
pub(crate) fn free_run(run: &FreeRun<'_>, parts: usize) -> [Vec<f64>; 2] {
    free_run_counted(run, parts).0
}

/// [`free_run`], with the number of later parts the exact run met (the rest it ran through).
fn free_run_counted(run: &FreeRun<'_>, parts: usize) -> ([Vec<f64>; 2], usize) {
    let n = run.len();
    let parts = parts.clamp(1, n.max(1));
    let bounds: Vec<usize> = (0..=parts).map(|j| j * n / parts).collect();
    let mut v = vec![0.0; n];
    let mut w = vec![0.0; n];
    let runs: Vec<Part> = {
        use rayon::prelude::*;
        let mut slices = Vec::with_capacity(parts);
        let (mut v_rest, mut w_rest) = (v.as_mut_slice(), w.as_mut_slice());
        for j in 0..parts {
            let len = bounds[j + 1] - bounds[j];
            let (va, vb) = v_rest.split_at_mut(len);
            let (wa, wb) = w_rest.split_at_mut(len);
            slices.push(Slot {
                start: bounds[j],
                vs: va,
                ws: wa,
            });
            (v_rest, w_rest) = (vb, wb);
        }
        // LANES parts a thread, interleaved; a last group of fewer, one by one.
        let mut groups: Vec<Vec<Slot<'_>>> = Vec::new();
        let mut rest = slices.into_iter().peekable();
        while rest.peek().is_some() {
            groups.push(rest.by_ref().take(LANES).collect());
        }
        groups
            .into_par_iter()
            .flat_map_iter(|group| run_group(run, group))
            .collect()
    };
    let mut exact_end = runs[0].end;
    let mut met = 0;
    for (j, part) in runs.iter().enumerate().skip(1) {
        let mut x = exact_end;
        let mut joined = false;
        for k in bounds[j]..bounds[j + 1] {
            let y = run.step(k, &mut x);
            (v[k], w[k]) = (y[0], y[1]);
            if part
                .checks
                .get(k - bounds[j])
                .is_some_and(|c| c.map(f64::to_bits) == x.map(f64::to_bits))
            {
                joined = true;
                break;
            }
        }
        met += usize::from(joined);
        exact_end = if joined { part.end } else { x };
    }
    ([v, w], met)
}

/// One part's place: its first sample and its outputs.
struct Slot<'a> {
    start: usize,
    vs: &'a mut [f64],
    ws: &'a mut [f64],
}

/// A part's run under way: its slot, its state and the states kept so far.
struct Lane<'a> {
    slot: Slot<'a>,
    x: [f64; 2],
    /// Next sample to write (index in the part).
    i: usize,
    keep: usize,
    checks: Vec<[f64; 2]>,
}

impl<'a> Lane<'a> {
    /// From the initial state when the part starts at sample 0 (whose output it writes), else
    /// from a guess, keeping its first [`CHECK`] states.
    fn new(run: &FreeRun<'_>, slot: Slot<'a>) -> Self {
        let start = slot.start;
        let keep = if start == 0 {
            0
        } else {
            CHECK.min(slot.vs.len())
        };
        let mut lane = Self {
            x: if start == 0 {
                run.initial()
            } else {
                run.guess(start - 1)
            },
            i: 0,
            keep,
            checks: Vec::with_capacity(keep),
            slot,
        };
        if start == 0 && !lane.slot.vs.is_empty() {
            let x = lane.x;
            lane.write(x);
        }
        lane
    }

    fn left(&self) -> usize {
        self.slot.vs.len() - self.i
    }

    /// Writes output `y` of the next sample and keeps the state if still checking.
    fn write(&mut self, y: [f64; 2]) {
        (self.slot.vs[self.i], self.slot.ws[self.i]) = (y[0], y[1]);
        self.i += 1;
        if self.checks.len() < self.keep {
            self.checks.push(self.x);
        }
    }

    fn finish(mut self, run: &FreeRun<'_>) -> Part {
        while self.left() > 0 {
            let y = run.step(self.slot.start + self.i, &mut self.x);
            self.write(y);
        }
        Part {
            end: self.x,
            checks: self.checks,
        }
    }
}

/// Parts run side by side on one thread: [`LANES`] of them in lock step
/// ([`FreeRun::step_lanes`]) while each has samples left, the rest (and a smaller group) one by
/// one; each gives what [`FreeRun::step`] sample after sample gives.
fn run_group<'a>(run: &FreeRun<'_>, group: Vec<Slot<'a>>) -> Vec<Part> {
    let mut lanes: Vec<Lane<'a>> = group.into_iter().map(|s| Lane::new(run, s)).collect();
    if let Ok(four) = <&mut [Lane<'a>; LANES]>::try_from(lanes.as_mut_slice()) {
        let common = four.iter().map(Lane::left).min().unwrap_or(0);
        for _ in 0..common {
            let ks = std::array::from_fn(|l| four[l].slot.start + four[l].i);
            let mut xs = std::array::from_fn(|l| four[l].x);
            let ys = run.step_lanes::<LANES>(ks, &mut xs);
            for ((lane, x), y) in four.iter_mut().zip(xs).zip(ys) {
                lane.x = x;
                lane.write(y);
            }
        }
    }
    lanes.into_iter().map(|l| l.finish(run)).collect()
}

#[cfg(test)]
mod tests {
    use super::super::setup;
    use super::*;
    use wheelid_core::Recording;

    /// A 200,000-sample turning drive at 50 Hz, with the measured velocities off the model's
    /// (so every guess is wrong), held or interpolated commands, instants or window averages.
    fn drive(avg: bool, sampled: bool) -> Recording {
        let n = 200_000;
        let t: Vec<f64> = (0..n).map(|k| k as f64 * 0.02).collect();
        let vr: Vec<f64> = t.iter().map(|t| 0.1 + 0.08 * (1.3 * t).sin()).collect();
        let wr: Vec<f64> = t.iter().map(|t| 0.9 * (0.7 * t).cos()).collect();
        let v: Vec<f64> = t.iter().map(|t| 0.3 * (0.1 * t).cos()).collect();
        let w: Vec<f64> = t.iter().map(|t| -0.5 * (0.2 * t).sin()).collect();
        let mut rec = Recording::new("drive", t, vr, wr, v, w).expect("valid");
        rec.set_meta("command_hold", if sampled { "sampled" } else { "zoh" });
        if avg {
            rec.set_meta("velocity_sampling", "window_average");
        }
        rec
    }

    #[test]
    fn parts_give_the_serial_run_bit_for_bit_and_meet_on_a_stable_model() {
        // The Khepera III (RK4 sub-steps) and a stiff θ (ETDRK4), every sampling: 2, 3 and 8
        // parts return exactly the serial numbers, each later part met by the exact run.
        for (avg, sampled) in [(false, false), (true, false), (true, true)] {
            let rec = drive(avg, sampled);
            for theta in [
                [0.0228, 0.0568, -0.0001, 1.003, 0.0732, 0.9981],
                [0.0004, 0.0009, -0.0001, 1.01, 0.07, 0.99],
            ] {
                let setup = setup(&theta, &rec, &[0.05, -0.2]).expect("valid");
                let run = FreeRun::new(&setup, &rec);
                let (serial, _) = free_run_counted(&run, 1);
                for parts in [2, 3, 8] {
                    let (split, met) = free_run_counted(&run, parts);
                    assert!(
                        split == serial,
                        "{parts} parts differ (avg {avg}, θ {theta:?})"
                    );
                    assert_eq!(met, parts - 1, "{parts} parts (avg {avg}, θ {theta:?})");
                }
            }
        }
    }

    #[test]
    fn parts_side_by_side_on_jittered_stamps_give_the_serial_run() {
        // Stamps 20 ms ± 5 ms apart: neighbouring intervals take 4 to 6 RK4 sub-steps, so the
        // parts run side by side often differ in their plans and are stepped one by one there.
        let mut rec = drive(true, false);
        let mut t = 0.0;
        for (k, tk) in rec.t.iter_mut().enumerate() {
            *tk = t;
            t += 0.02 + 0.005 * (((k * 7919) % 11) as f64 - 5.0) / 5.0;
        }
        let theta = [0.0228, 0.0568, -0.0001, 1.003, 0.0732, 0.9981];
        let setup = setup(&theta, &rec, &[0.05, -0.2]).expect("valid");
        let run = FreeRun::new(&setup, &rec);
        let counts: std::collections::BTreeSet<usize> = (1..1000)
            .map(|k| run.planner.plan(rec.t[k] - rec.t[k - 1]).equal)
            .collect();
        assert!(counts.len() >= 2, "{counts:?}");
        let (serial, _) = free_run_counted(&run, 1);
        let (split, met) = free_run_counted(&run, 8);
        assert!(split == serial);
        assert_eq!(met, 7);
    }

    #[test]
    fn a_model_that_does_not_forget_is_run_through_with_the_same_answer() {
        // θ4 = θ6 = 0: v and ω integrate their commands and never forget a wrong start; the
        // exact run meets no part and runs through each, with the serial numbers.
        let rec = drive(false, false);
        let theta = [0.0228, 0.0568, 0.0, 0.0, 0.0, 0.0];
        let setup = setup(&theta, &rec, &[0.05, -0.2]).expect("valid");
        let run = FreeRun::new(&setup, &rec);
        let (serial, _) = free_run_counted(&run, 1);
        let (split, met) = free_run_counted(&run, 4);
        assert_eq!(met, 0);
        assert!(split == serial);
    }
}
