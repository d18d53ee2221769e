//! A change time the training blocks cannot place is placed with every sample, as soon as
//! the search accepts it (later fits hold it) and again in the report.
//!
//! A change (`payload_change`) inside a validation block leaves the training cost flat while
//! its time sweeps that block: the fit reports the flat interval's middle and the interval as
//! its uncertainty ([`Data::unidentified`]), and the validation judges the model outside it.
//! Once the effect is accepted, the time is placed by the cost over every sample (training and
//! validation) inside that interval: the flat minimum of that cost (the profile likelihood's
//! 95 % interval, n_eff ln(J(t)/J_min) ≤ χ²₁(0.95), n_eff every sample discounted for the
//! residual's autocorrelation), on 33 times across the interval. The search's later
//! comparisons then judge every validation sample (the time, one parameter, was read off
//! them); the final model is still judged outside the training interval as its finding
//! reported it ([`super::assemble`]), so the validation fit it reports never saw the samples
//! that placed the time.

use super::*;
use wheelid_models::extended::Trace;

/// χ²₁ at 0.95.
const CHI2_1_95: f64 = 3.841;

/// Places each change time of `cur` whose training interval (± the standard error
/// `reported` for it when it was found, else the current one) is wider than two sample
/// periods by every sample (module docs); updates θ, its standard error (half the new flat
/// interval, at least half the fine scan's step and half a period) and the simulation. Returns, per moved time, the
/// candidate, the training interval \[s\] and the new standard error \[s\].
pub(super) fn change_times(
    data: &Data,
    cur: &mut Current,
    reported: impl Fn(Candidate) -> Option<f64>,
) -> Vec<(Candidate, (f64, f64), f64)> {
    let mut moved = Vec::new();
    let model = data.model(&cur.candidates);
    let all: Vec<Vec<bool>> = data.recs.iter().map(|r| vec![true; r.len()]).collect();
    let mut at = 6;
    for c in cur.candidates.clone() {
        let n = c.params().len();
        // The training interval as the finding reported it (a later refit may hold the time).
        let half = reported(c).unwrap_or(cur.std_err[at]);
        let t = cur.theta[at];
        if c.effect().search() == Search::ChangeTime && half.is_finite() && half > 2.0 * data.dt {
            let runs = TimeScan::new(&model, &cur.theta, at, &data.recs, &cur.initial);
            let cost = |time: f64, window: (f64, f64)| {
                runs.at(time, window)
                    .map_or(f64::INFINITY, |y| all_samples_cost(data, &y))
            };
            let n_eff = data.effective_samples_on(&cur.sim, &all).max(1.0);
            let tolerance = (CHI2_1_95 / n_eff).exp_m1();
            // A coarse scan across the interval, then a fine one around its flat minimum.
            let scan = |from: f64, to: f64| {
                let times = (0..=32).map(move |i| from + (to - from) * i as f64 / 32.0);
                fit::flat_minimum(times, |t| cost(t, (from, to)), tolerance)
            };
            let (mut from, mut to) = (t - half, t + half);
            let (mut lo, mut hi) = scan(from, to);
            // A least cost at the interval's edge: every sample puts the change elsewhere
            // (the training fit chose the wrong validation block); the whole span is scanned.
            if lo <= from || hi >= to {
                let (t_lo, t_hi) = data.span();
                let margin = 0.05 * (t_hi - t_lo);
                (from, to) = (t_lo + margin, t_hi - margin);
                (lo, hi) = scan(from, to);
            }
            let step = (to - from) / 32.0;
            let (lo, hi) = scan(lo - step, hi + step);
            let fine = (hi - lo + 2.0 * step) / 32.0;
            let mut th = cur.theta.clone();
            th[at] = 0.5 * (lo + hi);
            if let Some(sim) = simulate_all(&model, &th, &data.recs, &cur.initial) {
                cur.theta = th;
                cur.std_err[at] = (0.5 * (hi - lo)).max(0.5 * fine).max(0.5 * data.dt);
                cur.sim = sim;
                moved.push((c, (t - half, t + half), cur.std_err[at]));
            }
        }
        at += n;
    }
    moved
}

/// Simulations of a model whose change time (θ's parameter `at`) is scanned: each recording's
/// run at θ is traced once, and a run with the time moved is resumed from it
/// ([`Extended::resumed`]: the whole simulation to the bit, integrated only from before the
/// scanned window to where the two runs' states meet again after it; a 10-minute drive
/// scanned over a validation block integrates about a tenth of it per time).
pub(super) struct TimeScan<'a> {
    model: &'a Extended,
    theta: &'a [f64],
    at: usize,
    recs: &'a [Recording],
    initial: &'a [Vec<f64>],
    /// Per recording, the trace of the run at θ (`None`: simulated whole).
    traces: Vec<Option<Trace>>,
}

impl<'a> TimeScan<'a> {
    /// The scan of parameter `at` of `theta` (a change time \[s\]) of `model` on `recs` from
    /// `initial` (one state per recording).
    pub(super) fn new(
        model: &'a Extended,
        theta: &'a [f64],
        at: usize,
        recs: &'a [Recording],
        initial: &'a [Vec<f64>],
    ) -> Self {
        use rayon::prelude::*;
        let traces = recs
            .par_iter()
            .zip(initial)
            .map(|(r, x0)| model.traced(theta, r, x0).ok().and_then(|(_, t)| t))
            .collect();
        Self {
            model,
            theta,
            at,
            recs,
            initial,
            traces,
        }
    }

    /// The outputs with the change at `time` \[s\], scanned within `window` (widened to hold
    /// θ's own time and `time`), as [`simulate_all`] gives them: `None` where a recording
    /// does not simulate finitely.
    pub(super) fn at(&self, time: f64, window: (f64, f64)) -> Option<Outputs> {
        use rayon::prelude::*;
        let mut th = self.theta.to_vec();
        th[self.at] = time;
        let own = self.theta[self.at];
        let window = (window.0.min(own).min(time), window.1.max(own).max(time));
        self.recs
            .par_iter()
            .zip(self.initial)
            .zip(&self.traces)
            .map(|((r, x0), trace)| {
                let y = match trace {
                    Some(tr) => self.model.resumed(&th, r, x0, tr, window),
                    None => self.model.simulate(&th, r, x0),
                };
                score::checked(y.ok()?, r)
            })
            .collect()
    }
}

/// Σ_c w_c² Σ_k (y − ŷ)² over every sample of every recording.
fn all_samples_cost(data: &Data, sim: &Outputs) -> f64 {
    data.recs
        .iter()
        .zip(sim)
        .map(|(rec, out)| {
            [&rec.v, &rec.w]
                .iter()
                .enumerate()
                .map(|(c, y)| {
                    let w2 = data.weight[c] * data.weight[c];
                    y.iter()
                        .zip(&out[c])
                        .map(|(a, b)| w2 * (a - b).powi(2))
                        .sum::<f64>()
                })
                .sum::<f64>()
        })
        .sum()
}
