//! Step 4 of the diagnosis: each candidate's fingerprint — the pattern its effect would leave
//! in the residual ([`wheelid_core::Probe`]) and its score test at the model in hand.

use super::*;

/// A candidate's pattern columns and the guesses they come with.
pub(super) struct Pattern {
    pub(super) candidate: Candidate,
    /// Columns per candidate parameter (None: not probed).
    pub(super) s: DMatrix<f64>,
    /// Which candidate parameter each column belongs to.
    pub(super) param_of_col: Vec<usize>,
    /// Parameter values: the probe levels or null + β̂ after the test.
    pub(super) guess: Vec<f64>,
    /// Parameters held at their null (inactive channels).
    pub(super) inactive: Vec<usize>,
    /// Description for the report.
    pub(super) evidence: String,
    /// Bonferroni factor (grid of payload times).
    pub(super) grid: usize,
    /// The candidate's values the probe simulated as they are, with the training cost ‖e‖² of
    /// the model in hand beside them there (a limit probed at one level: one per probe
    /// fraction, the guess among them): the screen's level grid takes a scale's cost from here
    /// where its θ is one of them to the bit ([`super::screen::level_grid`]).
    pub(super) probed: Vec<(Vec<f64>, f64)>,
}

/// Builds the fingerprints of `c` at the current model from its [`Probe`]; `None` if the
/// candidate cannot act on these data (no probe level binds, no track for the asymmetry).
pub(super) fn patterns(c: Candidate, data: &Data, cur: &Current) -> Option<Vec<Pattern>> {
    let mut cands = cur.candidates.clone();
    cands.push(c);
    let (t_lo, t_hi) = data.span();
    let at = Probing {
        c,
        data,
        cur,
        model: data.model(&cands),
        null: c.effect().null(&cur.theta[..6], 0.5 * (t_lo + t_hi)),
    };
    match c.effect().probe(&data.probe_data(cur))? {
        Probe::Gradient(steps) => {
            let cols = steps
                .iter()
                .map(|&(j, h)| at.difference(&at.null, j, h))
                .collect::<Option<Vec<_>>>()?;
            let params = steps.iter().map(|&(j, _)| j).collect();
            Some(vec![at.single(cols, params, c.effect().evidence().into())])
        }
        Probe::Levels { levels, evidence } => at.levels(&levels, &evidence),
        Probe::TimeGrid { time, n, columns } => at.time_grid(time, n, &columns),
    }
}

/// Candidate `c` probed at the model in hand `cur`: the model extended by it and its null
/// values ([`patterns`]).
struct Probing<'a> {
    c: Candidate,
    data: &'a Data,
    cur: &'a Current,
    model: Extended,
    null: Vec<f64>,
}

impl Probing<'_> {
    /// The simulation of every recording with the candidate's values `vals`.
    fn with(&self, vals: &[f64]) -> Option<Outputs> {
        let mut th = self.cur.theta.clone();
        th.extend_from_slice(vals);
        simulate_all(&self.model, &th, &self.data.recs, &self.cur.initial)
    }

    /// The flattened pattern of a step `h` of parameter `j` from `vals`: (ŷ − ŷ_now)/h.
    fn difference(&self, vals: &[f64], j: usize, h: f64) -> Option<nalgebra::DVector<f64>> {
        let mut v = vals.to_vec();
        v[j] += h;
        let y = self.with(&v)?;
        Some(
            self.data
                .frame()
                .flatten(&score::difference(&y, &self.cur.sim, h)),
        )
    }

    /// A pattern of columns `cols` (parameters `params`) guessed at the null.
    fn single(
        &self,
        cols: Vec<nalgebra::DVector<f64>>,
        params: Vec<usize>,
        evidence: String,
    ) -> Pattern {
        Pattern {
            candidate: self.c,
            s: DMatrix::from_columns(&cols),
            param_of_col: params,
            guess: self.null.clone(),
            inactive: Vec::new(),
            evidence,
            grid: 1,
            probed: Vec::new(),
        }
    }

    /// The level read off a nominal fit that has absorbed part of the limit sits above the
    /// true one: probed at a few fractions of it ([`PROBE_FRACTIONS`]), the best taken
    /// (Bonferroni). The fractions' simulations on the pool's threads (a traction probe's is
    /// the longest of a round), collected in order.
    fn levels(&self, levels: &[(usize, f64)], evidence: &str) -> Option<Vec<Pattern>> {
        use rayon::prelude::*;
        let frame = self.data.frame();
        let params: Vec<usize> = levels.iter().map(|&(j, _)| j).collect();
        let at = |f: f64| -> Option<Pattern> {
            let mut v = self.null.clone();
            for &(j, level) in levels {
                v[j] = f * level;
            }
            // One level probed alone: its column's simulation is the guess's own.
            let mut probed = Vec::new();
            let cols = params
                .iter()
                .map(|&j| {
                    let mut one = self.null.clone();
                    one[j] = v[j];
                    let y = self.with(&one)?;
                    if params.len() == 1 {
                        probed.push((one, frame.residuals(&y).norm_squared()));
                    }
                    Some(frame.flatten(&score::difference(&y, &self.cur.sim, 1.0)))
                })
                .collect::<Option<Vec<_>>>()?;
            let mut p = self.single(cols, params.clone(), evidence.into());
            p.guess = v;
            p.grid = PROBE_FRACTIONS.len();
            p.probed = probed;
            Some(p)
        };
        let mut all = PROBE_FRACTIONS
            .par_iter()
            .map(|&f| at(f))
            .collect::<Option<Vec<_>>>()?;
        // Each fraction's pattern carries every fraction's simulated cost.
        let probed: Vec<(Vec<f64>, f64)> =
            all.iter().flat_map(|p| p.probed.iter().cloned()).collect();
        all.iter_mut().for_each(|p| p.probed.clone_from(&probed));
        Some(all)
    }

    /// A grid of `n` change times (parameter `time`) over the middle of the run, `columns`
    /// (parameter, relative step) differenced at each; on the pool's threads, a time whose
    /// simulation panics is no pattern.
    fn time_grid(&self, time: usize, n: usize, columns: &[(usize, f64)]) -> Option<Vec<Pattern>> {
        use rayon::prelude::*;
        let (t_lo, t_hi) = self.data.span();
        let pattern_at = |g: usize| {
            let ts = t_lo + (t_hi - t_lo) * g as f64 / (n + 1) as f64;
            let mut vals = self.null.clone();
            vals[time] = ts;
            let cols = columns
                .iter()
                .map(|&(j, rel)| self.difference(&vals, j, rel * vals[j].abs().max(1e-3)))
                .collect::<Option<Vec<_>>>()?;
            let params = columns.iter().map(|&(j, _)| j).collect();
            let mut p = self.single(
                cols,
                params,
                format!("the dynamics change around t = {ts:.1} s"),
            );
            p.guess = vals;
            p.grid = n;
            Some(p)
        };
        (1..=n)
            .into_par_iter()
            .map(|g| {
                std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| pattern_at(g)))
                    .ok()
                    .flatten()
            })
            .collect::<Option<Vec<_>>>()
    }
}

/// One candidate's fingerprint at the current model: the best pattern (over the payload
/// grid) with its score.
pub(super) struct Nominee {
    pub(super) pattern: Pattern,
    pub(super) score: score::Score,
    pub(super) p_value: f64,
}

pub(super) fn fingerprint(
    c: Candidate,
    data: &Data,
    cur: &Current,
    q: &DMatrix<f64>,
    e: &nalgebra::DVector<f64>,
) -> Option<Nominee> {
    let frame = data.frame();
    let lags = data.hac_lags();
    let mut best: Option<Nominee> = None;
    for mut pattern in patterns(c, data, cur)? {
        let Some(s) = score::score(&frame, q, &pattern.s, e, lags) else {
            continue;
        };
        let p_value = (s.p_value * pattern.grid as f64).min(1.0);
        // Channels: columns whose own z is large; the others stay at their null.
        if let EffectChannels::Each { positive } = c.effect().channels() {
            // Every channel the pattern reaches is fitted (a friction or a loss only where the
            // residual asks for a positive one); insignificant ones are dropped after the fit.
            let active: Vec<usize> = pattern
                .param_of_col
                .iter()
                .zip(&s.beta)
                .filter(|(_, b)| !positive || **b > 0.0)
                .map(|(&j, _)| j)
                .collect();
            pattern.inactive = (0..2).filter(|j| !active.contains(j)).collect();
        }
        // First guess: the probe level, or one Gauss–Newton step from the null.
        if !c.effect().search().is_limit() {
            for (col, &j) in pattern.param_of_col.iter().enumerate() {
                pattern.guess[j] += s.beta[col];
            }
        }
        let better = best
            .as_ref()
            .is_none_or(|b| p_value < b.p_value || (p_value == b.p_value && s.stat > b.score.stat));
        if better {
            best = Some(Nominee {
                pattern,
                score: s,
                p_value,
            });
        }
    }
    best
}

/// The channels a candidate acts on ([`EffectChannels`]): for a per-channel one, those whose
/// parameter is `active`.
pub(super) fn channels_of(c: Candidate, active: impl Fn(usize) -> bool) -> Vec<String> {
    match c.effect().channels() {
        EffectChannels::Each { .. } => (0..2)
            .filter(|&j| active(j))
            .map(|j| ["v", "w"][j].to_owned())
            .collect(),
        EffectChannels::Omega => vec!["w".into()],
        EffectChannels::Both => vec!["v".into(), "w".into()],
    }
}
