//! The search's excerpt of a long drive (module docs, steps 2–5): every recording longer than
//! [`DiagnoseSettings::search_samples`] N is searched on N/B samples of each of its B blocks,
//! so that the screens and the candidates' fits cost what N samples cost while a change or a
//! drift over the drive stays in view; the model the search ends with is refitted on every
//! training block of the whole drive, which the report then judges.
//!
//! The drive is cut into 3B equal slots, and each slot gives one window of N/(3B) samples,
//! at a place in the slot that steps by the golden ratio (evenly spaced windows alias with a
//! periodic excitation: every 40 s of a 60 s multisine saw three of its phases and missed
//! where v_ref peaks, so a velocity limit was fitted on ω alone). Each window is a recording
//! of its own with its times and flags kept, started in the model in hand's free run; its
//! first [`LEAD_SAMPLES`] are flagged for training, so that a fit can estimate its initial
//! state (a window of validation samples alone would leave it free). Those lead-ins do not
//! place a change time (`Data::placing`): a payload dropped at 370.6 s inside a validation
//! block was placed at 464.7 s by lead-ins at 413 s and 447 s, and its validation cost rose by
//! 51 %. A drift counts from the drive's start, which each window carries
//! ([`wheelid_core::Recording::drive_start`]; counted from each window's own start, a sagging
//! battery was named a payload change). Ten minutes at 50 Hz in five blocks, searched on
//! 3 600 samples: fifteen windows of 4.8 s, one in every 40 s.

use super::*;

/// The excerpt's data and where each of its recordings comes from.
pub(super) struct Excerpt {
    pub(super) data: Data,
    /// Per excerpt recording: (the whole drive's recording, its first sample there).
    origin: Vec<(usize, usize)>,
}

impl Data {
    /// The excerpt of at most `cap` samples per recording (module docs), or `None` when no
    /// recording is longer.
    pub(super) fn excerpt(&self, cap: usize) -> Option<Excerpt> {
        if self.recs.iter().all(|r| r.len() <= cap) {
            return None;
        }
        let mut data = Data {
            recs: Vec::new(),
            train: Vec::new(),
            valid: Vec::new(),
            placing: Vec::new(),
            dt: self.dt,
            blocks: Vec::new(),
            track: self.track,
            weight: self.weight,
            accel: Vec::new(),
            noise_floor: self.noise_floor,
            measured: self.measured.clone(),
        };
        let mut origin = Vec::new();
        for (i, rec) in self.recs.iter().enumerate() {
            let (n, blocks) = (rec.len(), self.blocks[i]);
            // (samples, blocks spanned, lead-in samples flagged for training)
            let windows: Vec<(std::ops::Range<usize>, usize, usize)> = if n <= cap {
                vec![(0..n, blocks, 0)]
            } else {
                let k = WINDOWS_PER_BLOCK * blocks;
                let w = cap / k;
                (0..k)
                    .map(|j| {
                        // The j-th of k equal slots, the window at a fraction of the slot's
                        // free length that steps by the golden ratio: evenly spaced windows
                        // alias with a periodic excitation (every 40 s of a 60 s multisine
                        // saw three of its phases, and missed where v_ref peaks).
                        let slot = (j * n / k, (j + 1) * n / k);
                        let free = (slot.1 - slot.0).saturating_sub(w);
                        let at = ((j + 1) as f64 * GOLDEN).fract();
                        let start = slot.0 + (at * free as f64) as usize;
                        (start..(start + w).min(n), 1, LEAD_SAMPLES)
                    })
                    .collect()
            };
            for (range, blocks, lead) in windows {
                let flag = |mask: &[bool], lead_flag: bool| -> Vec<bool> {
                    mask[range.clone()]
                        .iter()
                        .enumerate()
                        .map(|(k, &m)| if k < lead { lead_flag } else { m })
                        .collect()
                };
                data.recs.push(rec.window(range.clone()));
                data.train.push(flag(&self.train[i], true));
                data.placing.push(self.placing[i][range.clone()].to_vec());
                data.valid.push(flag(&self.valid[i], false));
                data.accel
                    .push([0, 1].map(|c| self.accel[i][c][range.clone()].to_vec()));
                data.blocks.push(blocks);
                origin.push((i, range.start));
            }
        }
        Some(Excerpt { data, origin })
    }
}

/// Windows per block ([`Data::excerpt`]).
const WINDOWS_PER_BLOCK: usize = 3;

/// The golden ratio's fraction (√5 − 1)/2: the windows' places in their slots
/// ([`Data::excerpt`]) step by it, the most evenly spread sequence mod any period.
const GOLDEN: f64 = 0.618_033_988_749_894_8;

/// Samples at a window's start flagged for training (the fits estimate its initial state
/// from them; module docs).
const LEAD_SAMPLES: usize = 10;

impl Excerpt {
    /// The nominal model in hand `cur` (fitted on the whole drive) on the excerpt: each window
    /// started from `cur`'s free run at its first sample (the nominal model's state is the
    /// two outputs), simulated, its sensitivities left to be computed on the excerpt; `None`
    /// if it does not simulate.
    pub(super) fn nominal(&self, cur: &Current) -> Option<Current> {
        let initial: Vec<Vec<f64>> = self
            .origin
            .iter()
            .map(|&(i, start)| match start {
                0 => cur.initial[i].clone(),
                k => vec![cur.sim[i][0][k], cur.sim[i][1][k]],
            })
            .collect();
        let model = self.data.model(&cur.candidates);
        let sim = simulate_all(&model, &cur.theta, &self.data.recs, &initial)?;
        Some(Current {
            initial,
            sim,
            jacobian: None,
            ..cur.clone()
        })
    }

    /// The search's final model `cur` (fitted on the excerpt) refitted on every training block
    /// of the whole drive `full` from its θ, its change times held where the search put them
    /// (the report places them on the whole drive, `place`) with their intervals;
    /// `nominal` (the whole drive's) when the search added nothing. Where the refit fails,
    /// `cur`'s θ simulated on the whole drive from `nominal`'s initial states.
    pub(super) fn refit(full: &Data, cur: Current, nominal: &Current) -> Current {
        if cur.candidates.is_empty() {
            return nominal.clone();
        }
        let mut held = cur.pinned.clone();
        let mut at = 6;
        for c in &cur.candidates {
            if c.effect().search() == Search::ChangeTime {
                held.push(at);
            }
            at += c.params().len();
        }
        let (t_lo, t_hi) = full.span();
        let margin = 0.05 * (t_hi - t_lo);
        let bounds = model_bounds(&cur.candidates, (t_lo + margin, t_hi - margin));
        let model = full.model(&cur.candidates);
        let refitted =
            fit_pinned(full, &model, &cur.theta, &held, &bounds).and_then(|(fit, theta, free)| {
                current_of(
                    &model,
                    cur.candidates.clone(),
                    cur.pinned.clone(),
                    &fit,
                    theta,
                    &free,
                    full,
                )
            });
        match refitted {
            Ok(mut new) => {
                for &i in held.iter().filter(|i| !cur.pinned.contains(i)) {
                    new.std_err[i] = cur.std_err[i];
                }
                new
            }
            Err(_) => match simulate_all(&model, &cur.theta, &full.recs, &nominal.initial) {
                Some(sim) => Current {
                    initial: nominal.initial.clone(),
                    sim,
                    jacobian: None,
                    ..cur
                },
                None => nominal.clone(),
            },
        }
    }
}

/// Steps 2–5 of the diagnosis from the whole drive's nominal model `cur`: on the excerpt of
/// `data` where a recording is longer than [`DiagnoseSettings::search_samples`] (the final
/// model refitted on the whole drive, [`Excerpt::refit`]), else on `data` itself with the
/// nominal `location`.
pub(super) fn search_on(
    data: &Data,
    cur: Current,
    settings: &DiagnoseSettings,
    location: &Location,
    progress: &Progress<'_>,
) -> Result<search::Outcome, DiagnoseError> {
    let Some(x) = data.excerpt(settings.search_samples) else {
        return paths::run(data, cur, settings, location, progress);
    };
    let start = x
        .nominal(&cur)
        .ok_or_else(|| DiagnoseError::Setting("the nominal model does not simulate".into()))?;
    let here = locate::locate(
        &x.data.recs,
        &start.sim,
        &x.data.valid,
        x.data.dt,
        x.data.max_lag(settings),
    );
    let mut out = paths::run(&x.data, start, settings, &here, progress)?;
    progress.step("refitting on the whole drive", 0);
    out.cur = Excerpt::refit(data, out.cur, &cur);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Ten minutes at 50 Hz of a drive (a 60 s periodic command), five blocks.
    fn long_drive() -> Data {
        let n = 30_000;
        let t: Vec<f64> = (0..n).map(|k| 0.02 * k as f64).collect();
        let v_ref = t
            .iter()
            .map(|x| 0.1 * (x * std::f64::consts::TAU / 60.0).sin())
            .collect();
        let w_ref = t
            .iter()
            .map(|x| 0.5 * (x * std::f64::consts::TAU / 20.0).cos())
            .collect();
        let mut rec =
            Recording::new("d", t, v_ref, w_ref, vec![0.0; n], vec![0.0; n]).expect("valid");
        rec.set_meta("command_hold", "zoh");
        let train: Vec<bool> = (0..n).map(|k| (k * 5 / n).is_multiple_of(2)).collect();
        Data {
            valid: vec![train.iter().map(|b| !b).collect()],
            placing: vec![train.clone()],
            train: vec![train],
            dt: 0.02,
            blocks: vec![5],
            track: Some(0.09),
            weight: [1.0; 2],
            accel: vec![[vec![0.0; n], vec![0.0; n]]],
            noise_floor: [1e-3; 2],
            measured: Vec::new(),
            recs: vec![rec],
        }
    }

    /// 3 600 samples of 30 000 in five blocks: fifteen windows of 240, one in each fifteenth
    /// of the drive, their first ten samples flagged for training (but not for placing a
    /// change time) and the rest as in the drive; their middles cover a 60 s period with no gap over 12 s (evenly spaced ones
    /// would sit at three phases); a drive of 3 600 samples is searched whole.
    #[test]
    fn the_windows_spread_over_the_drive_and_start_in_training() {
        let data = long_drive();
        let x = data.excerpt(3600).expect("longer than the cap");
        assert_eq!(x.data.recs.len(), 15);
        let mut phases = Vec::new();
        for (j, (rec, &(i, start))) in x.data.recs.iter().zip(&x.origin).enumerate() {
            assert_eq!((i, rec.len(), x.data.blocks[j]), (0, 240, 1));
            assert!(
                start >= j * 2000 && start + 240 <= (j + 1) * 2000,
                "window {j} at {start}"
            );
            assert_eq!(rec.t[0], data.recs[0].t[start]);
            for k in 0..240 {
                // A lead-in fits the initial state; it never places a change time.
                assert_eq!(x.data.placing[j][k], data.train[0][start + k]);
                let (tr, va) = (x.data.train[j][k], x.data.valid[j][k]);
                if k < LEAD_SAMPLES {
                    assert!(tr && !va);
                } else {
                    assert_eq!(
                        (tr, va),
                        (data.train[0][start + k], data.valid[0][start + k])
                    );
                }
            }
            phases.push((start + 120) % 3000);
        }
        phases.sort_unstable();
        let mut gaps: Vec<usize> = phases.windows(2).map(|p| p[1] - p[0]).collect();
        gaps.push(phases[0] + 3000 - phases[14]);
        assert!(gaps.iter().all(|&g| g < 600), "phase gaps {gaps:?}");
        assert!(data.excerpt(30_000).is_none());
    }

    /// The nominal model on the excerpt, each window started from the whole run's state at
    /// its first sample, is the whole run's simulation there.
    #[test]
    fn the_nominal_model_on_the_excerpt_is_the_whole_run_there() {
        let data = long_drive();
        let theta = vec![0.05, 0.06, 0.0, 1.0, 0.05, 1.0];
        let initial = vec![vec![0.01, -0.02]];
        let model = data.model(&[]);
        let sim = simulate_all(&model, &theta, &data.recs, &initial).expect("simulates");
        let cur = Current {
            candidates: Vec::new(),
            pinned: Vec::new(),
            std_err: vec![0.0; 6],
            covariance: DMatrix::zeros(6, 6),
            theta,
            initial,
            sim,
            jacobian: None,
        };
        let x = data.excerpt(3600).expect("longer than the cap");
        let on = x.nominal(&cur).expect("simulates");
        for (j, &(_, start)) in x.origin.iter().enumerate() {
            for c in 0..2 {
                for k in 0..x.data.recs[j].len() {
                    let (a, b) = (on.sim[j][c][k], cur.sim[0][c][start + k]);
                    assert!(
                        (a - b).abs() < 1e-9,
                        "window {j} channel {c} sample {k}: {a} vs {b}"
                    );
                }
            }
        }
    }
}
