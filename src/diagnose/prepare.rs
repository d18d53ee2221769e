//! Step 1 of the diagnosis: prepare the data once — uniform recordings, the training and
//! validation blocks, the wheel track, the measured accelerations, the channel weights.

use super::*;

/// Everything the search needs about the data.
pub(super) struct Data {
    pub(super) recs: Vec<Recording>,
    /// Training flags.
    pub(super) train: Vec<Vec<bool>>,
    /// Validation flags.
    pub(super) valid: Vec<Vec<bool>>,
    /// The training samples that place a change time: all of them, but for an excerpt's
    /// lead-ins, which fit their window's initial state and say next to nothing of which
    /// dynamics are in force ([`super::excerpt`]).
    pub(super) placing: Vec<Vec<bool>>,
    pub(super) dt: f64,
    /// Blocks of each recording (an excerpt's window is one block).
    pub(super) blocks: Vec<usize>,
    pub(super) track: Option<f64>,
    /// 1/σ_c of the nominal fit.
    pub(super) weight: [f64; 2],
    /// Measured accelerations (smoothed derivative) per recording.
    pub(super) accel: Outputs,
    /// The measurement noise floor σ_n per channel [channel unit] ([`noise_floor`]).
    pub(super) noise_floor: [f64; 2],
    /// The candidates another sensor measures on the whole drive, with what it measures
    /// ([`wheelid_core::Effect::measured`]; an excerpt keeps the drive's).
    pub(super) measured: Vec<(Candidate, wheelid_core::Measurement)>,
}

impl Data {
    pub(super) fn model(&self, candidates: &[Candidate]) -> Extended {
        // A missing track only matters to wheel_asymmetry, which is skipped then.
        Extended::new(candidates, self.track.unwrap_or(1.0)).expect("candidates are distinct")
    }
    pub(super) fn frame(&self) -> Frame<'_> {
        Frame {
            recs: &self.recs,
            mask: &self.train,
            weight: self.weight,
        }
    }
    /// The rows that place a change time ([`Data::placing`]).
    pub(super) fn placing_frame(&self) -> Frame<'_> {
        Frame {
            recs: &self.recs,
            mask: &self.placing,
            weight: self.weight,
        }
    }
    /// The validation samples of both channels discounted for the autocorrelation of the
    /// residual `y − sim`: Σ_c n_c (1 − ρ_c)/(1 + ρ_c), ρ_c its lag-1 autocorrelation on
    /// the validation blocks clamped to [0, 0.999] (the effective size of an AR(1) sample).
    pub(super) fn effective_samples(&self, sim: &Outputs) -> f64 {
        self.effective_samples_on(sim, &self.valid)
    }

    /// [`Data::effective_samples`] over the samples flagged in `mask`.
    pub(super) fn effective_samples_on(&self, sim: &Outputs, mask: &[Vec<bool>]) -> f64 {
        (0..2)
            .map(|c| {
                let (mut n, mut s0, mut s1) = (0usize, 0.0, 0.0);
                for ((rec, m), out) in self.recs.iter().zip(mask).zip(sim) {
                    let y = if c == 0 { &rec.v } else { &rec.w };
                    let e = |k: usize| y[k] - out[c][k];
                    for k in (0..rec.len()).filter(|&k| m[k]) {
                        n += 1;
                        s0 += e(k) * e(k);
                        if k > 0 && m[k - 1] {
                            s1 += e(k) * e(k - 1);
                        }
                    }
                }
                let rho = if s0 > 0.0 {
                    (s1 / s0).clamp(0.0, 0.999)
                } else {
                    0.0
                };
                n as f64 * (1.0 - rho) / (1.0 + rho)
            })
            .sum()
    }

    /// The validation samples on which `models` are judged alike: every validation sample
    /// outside the models' unidentified intervals ([`Data::unidentified`]).
    pub(super) fn judged(&self, models: &[&Current]) -> Vec<Vec<bool>> {
        let gaps: Vec<(f64, f64)> = models.iter().flat_map(|m| self.unidentified(m)).collect();
        self.judged_outside(&gaps)
    }

    /// Every validation sample outside the time intervals `gaps` \[s\].
    pub(super) fn judged_outside(&self, gaps: &[(f64, f64)]) -> Vec<Vec<bool>> {
        self.recs
            .iter()
            .zip(&self.valid)
            .map(|(rec, m)| {
                rec.t
                    .iter()
                    .zip(m)
                    .map(|(t, &v)| v && !gaps.iter().any(|g| (g.0..=g.1).contains(t)))
                    .collect()
            })
            .collect()
    }

    /// The time intervals a model leaves open: a change time's flat minimum, θ ± its half
    /// width ([`Search::ChangeTime`]) \[s\]. Where it spans a validation block the training
    /// blocks cannot place the change inside it, so the validation samples there judge a
    /// guess, not a fit (seen: a payload set down at 75.9 s of 120 s, in the validation block
    /// 72–96 s, fitted at its middle, 84 s, and refused for the 8 s between).
    pub(super) fn unidentified(&self, cur: &Current) -> Vec<(f64, f64)> {
        let mut at = 6;
        let mut out = Vec::new();
        for c in &cur.candidates {
            if c.effect().search() == Search::ChangeTime {
                let (t, half) = (cur.theta[at], cur.std_err[at]);
                if half.is_finite() && half > 0.0 {
                    out.push((t - half, t + half));
                }
            }
            at += c.params().len();
        }
        out
    }

    /// Validation fits and cost of simulated outputs on the samples flagged in `mask`.
    pub(super) fn validate_on(&self, sim: &Outputs, mask: &[Vec<bool>]) -> (Channels, f64) {
        let mut y = [Vec::new(), Vec::new()];
        let mut s = [Vec::new(), Vec::new()];
        for ((rec, m), out) in self.recs.iter().zip(mask).zip(sim) {
            for k in (0..rec.len()).filter(|&k| m[k]) {
                y[0].push(rec.v[k]);
                y[1].push(rec.w[k]);
                s[0].push(out[0][k]);
                s[1].push(out[1][k]);
            }
        }
        let fit = |c: usize| {
            let rms = (y[c]
                .iter()
                .zip(&s[c])
                .map(|(a, b)| (a - b).powi(2))
                .sum::<f64>()
                / y[c].len().max(1) as f64)
                .sqrt();
            let fit_percent = metrics::fit_percent(&y[c], &s[c]);
            // ‖y − ȳ‖/√n from fit % = 100 (1 − rms/spread).
            let spread = rms / (1.0 - fit_percent / 100.0);
            let beyond_noise = (rms.powi(2) - self.noise_floor[c].powi(2)).max(0.0).sqrt();
            ChannelFit {
                fit_percent,
                rms,
                noise_ratio: rms / self.noise_floor[c].max(1e-12),
                noise_corrected_fit_percent: if rms == 0.0 {
                    fit_percent
                } else {
                    100.0 * (1.0 - beyond_noise / spread)
                },
            }
        };
        let cost = (0..2)
            .map(|c| {
                y[c].iter()
                    .zip(&s[c])
                    .map(|(a, b)| ((a - b) * self.weight[c]).powi(2))
                    .sum::<f64>()
            })
            .sum();
        (
            Channels {
                v: fit(0),
                w: fit(1),
            },
            cost,
        )
    }
    /// Earliest and latest time over the recordings \[s\].
    pub(super) fn span(&self) -> (f64, f64) {
        let lo = self
            .recs
            .iter()
            .map(|r| r.t[0])
            .fold(f64::INFINITY, f64::min);
        let hi = self
            .recs
            .iter()
            .map(|r| r.t[r.len() - 1])
            .fold(f64::NEG_INFINITY, f64::max);
        (lo, hi)
    }
    /// Shortest block \[samples\].
    pub(super) fn block(&self) -> usize {
        self.recs
            .iter()
            .zip(&self.blocks)
            .map(|(r, b)| r.len() / b)
            .min()
            .unwrap_or(1)
            .max(1)
    }
    /// Lags of the correlation tests: `max_lag_s`, at most half a block.
    pub(super) fn max_lag(&self, settings: &DiagnoseSettings) -> usize {
        ((settings.max_lag_s / self.dt).round() as usize).clamp(1, (self.block() / 2).max(1))
    }
    /// Lag window of the fingerprints' long-run variance: the Newey–West rule, but at least a
    /// second (free-run residuals stay correlated over the robot's time constants and
    /// longer), at most a quarter block.
    pub(super) fn hac_lags(&self) -> usize {
        let n = self.recs.iter().map(Recording::len).max().unwrap_or(0);
        let rule = (4.0 * (n as f64 / 100.0).powf(2.0 / 9.0)).floor() as usize;
        rule.max((1.0 / self.dt).round() as usize)
            .min((self.block() / 4).max(1))
    }
}

/// The wheel track from the metadata: `track`, a `kinematics` line with `track X`, or the
/// built-in profile named by `robot`.
pub(super) fn track_from_meta(rec: &Recording) -> Option<f64> {
    let valid = |x: f64| (x.is_finite() && x > 0.0).then_some(x);
    if let Some(t) = rec
        .meta("track")
        .and_then(|s| s.split_whitespace().next()?.parse().ok())
        .and_then(valid)
    {
        return Some(t);
    }
    if let Some(k) = rec.meta("kinematics") {
        let mut it = k.split_whitespace();
        while let Some(w) = it.next() {
            if w == "track"
                && let Some(x) = it
                    .next()
                    .and_then(|s| s.trim_end_matches(',').parse().ok())
                    .and_then(valid)
            {
                return Some(x);
            }
        }
    }
    rec.meta("robot")
        .and_then(wheelid_robots::RobotProfile::by_name)
        .map(|p| p.track)
}

impl Data {
    /// What an effect's probe reads of the data ([`wheelid_core::effect::Effect::probe`]) at
    /// the model in hand `cur`: its θ1…θ6 and, where it has effects, its free-run outputs.
    pub(super) fn probe_data<'a>(&'a self, cur: &'a Current) -> ProbeData<'a> {
        ProbeData {
            recordings: &self.recs,
            accel: &self.accel,
            theta: &cur.theta[..6],
            simulated: (!cur.candidates.is_empty()).then_some(cur.sim.as_slice()),
            dt: self.dt,
            track: self.track,
        }
    }

    /// The report's view of a model in hand: its name, θ, validation fits and cost.
    /// Judged on the validation samples flagged in `mask`.
    pub(super) fn stage(&self, cur: &Current, mask: &[Vec<bool>]) -> Stage {
        let (channels, validation_cost) = self.validate_on(&cur.sim, mask);
        let model = self.model(&cur.candidates);
        // Held parameters (a limit's idle channel at "never binds") are not reported.
        let shown: Vec<usize> = (0..cur.theta.len())
            .filter(|i| !cur.pinned.contains(i) || self.scanned(cur, *i))
            .collect();
        Stage {
            model: std::iter::once("nominal")
                .chain(cur.candidates.iter().map(|c| c.name()))
                .collect::<Vec<_>>()
                .join(" + "),
            theta: shown.iter().map(|&i| cur.theta[i]).collect(),
            std_err: shown.iter().map(|&i| cur.std_err[i]).collect(),
            names: shown
                .iter()
                .map(|&i| model.params()[i].name.to_owned())
                .collect(),
            channels,
            validation_cost,
        }
    }

    /// Whether parameter `i` of the model in hand is a change time (held in the fits, found by
    /// its own scan).
    fn scanned(&self, cur: &Current, i: usize) -> bool {
        let mut at = 6;
        for c in &cur.candidates {
            if i == at && c.effect().search() == Search::ChangeTime {
                return true;
            }
            at += c.params().len();
        }
        false
    }
}

/// Training (even blocks) and validation (odd blocks) flags of every recording.
fn split(recs: &[Recording], blocks: usize) -> Result<SplitMasks, DiagnoseError> {
    let mut train = Vec::new();
    let mut valid = Vec::new();
    for r in recs {
        let n = r.len();
        if n < 10 * blocks {
            return Err(DiagnoseError::Setting(format!(
                "{}: {n} samples are too few to split into {blocks} blocks",
                r.source.display(),
            )));
        }
        let m: Vec<bool> = (0..n).map(|k| (k * blocks / n).is_multiple_of(2)).collect();
        valid.push(m.iter().map(|b| !b).collect::<Vec<bool>>());
        train.push(m);
    }
    Ok((train, valid))
}

/// Training and validation flags.
type SplitMasks = (Vec<Vec<bool>>, Vec<Vec<bool>>);

/// The nominal θ by output error on the training blocks, started from least squares (or,
/// where least squares comes out unphysical — a long dead time makes the regression's θ1
/// negative — from unit gains and time constants of 3 periods).
fn nominal_fit(
    recs: &[Recording],
    train: &[Vec<bool>],
    dt: f64,
    model: &dyn RegressorModel,
    settings: &DiagnoseSettings,
) -> Result<OutputErrorFit, DiagnoseError> {
    let ls = identify(
        recs,
        model,
        &Ols::default(),
        &IdentifySettings {
            condition: settings.condition.clone(),
            estimator: crate::estimators::LEAST_SQUARES.into(),
            allow_invalid: true,
            ..IdentifySettings::default()
        },
    )?;
    let oe = OutputError {
        mask: Some(train.to_vec()),
        tolerance: NOMINAL_TOLERANCE,
        ..OutputError::default()
    };
    let fallback = [3.0 * dt, 3.0 * dt, 0.0, 1.0, 0.0, 1.0];
    let sane = [0, 1, 3, 5].iter().all(|&i| ls.theta[i] > 0.0);
    // A plugin's model that extends eq. 2.19 (its first six parameters θ1…θ6, then its own)
    // starts the diagnosis from its θ1…θ6: the search extends eq. 2.19 with the candidates,
    // which may find the plugin's own physics again.
    let nominal;
    let (model, start): (&dyn DynamicModel, &[f64]) = if ls.theta.len() == 6 {
        (model, &ls.theta)
    } else {
        nominal = Extended::new(&[], 1.0).map_err(DiagnoseError::Core)?;
        (&nominal, &ls.theta[..6])
    };
    Ok(
        match oe.fit(model, recs, if sane { start } else { &fallback }) {
            Err(_) if sane => oe.fit(model, recs, &fallback)?,
            other => other?,
        },
    )
}

/// Errors unless the model's first six parameters are θ1…θ6 of eq. 2.19 (the built-in
/// parameterizations, or a plugin's model that extends them): the candidates extend eq. 2.19.
pub(super) fn check_model(model: &dyn RegressorModel) -> Result<(), DiagnoseError> {
    let p = model.params();
    if wheelid_core::extends_eq_2_19(p) {
        Ok(())
    } else {
        Err(DiagnoseError::Setting(format!(
            "model `{}` cannot be diagnosed: the candidates extend eq. 2.19, so its first six \
             parameters must be theta1…theta6 (it has {})",
            model.name(),
            p.iter().map(|q| q.name).collect::<Vec<_>>().join(", ")
        )))
    }
}

/// Measured accelerations: the derivative of the zero-phase filtered response (zeros where
/// the recording cannot be filtered); and the noise floor of each channel ([`noise_floor`]).
fn accelerations(recs: &[Recording], settings: &DiagnoseSettings) -> (Outputs, [f64; 2]) {
    let cutoff = condition::suggest_cutoff(&recs.iter().collect::<Vec<_>>())
        .map(|(f, _)| f)
        .ok();
    let mut floor = NoiseFloor::default();
    let accel = recs
        .iter()
        .map(|r| {
            let c =
                cutoff.and_then(|fc| condition::condition(r, None, fc, &settings.condition).ok());
            if let Some(c) = &c {
                floor.add(c, r);
            }
            let d =
                c.and_then(|c| Some([c.differentiate(c.v()).ok()?, c.differentiate(c.w()).ok()?]));
            d.unwrap_or_else(|| [vec![0.0; r.len()], vec![0.0; r.len()]])
        })
        .collect();
    (accel, floor.sigma())
}

/// The measurement noise floor σ_n of each channel: the RMS of what the zero-phase low-pass
/// of the conditioning removes from the *measured* series (y − filtfilt(y), inside the valid
/// range), scaled up by 1/√(1 − f_c/f_N) for the white noise the filter lets through (f_N the
/// Nyquist frequency). Response content above the cut-off counts as noise too, and noise that
/// lives at high frequencies (a differenced encoder count: lag-1 autocorrelation −½) is
/// scaled as if white: the floor errs high (by 1.17 × for differenced counts at f_c = 0.3 f_N).
///
/// The series is the recording's own, the one the residual y − ŷ is taken of — not the
/// conditioning's aligned copy, whose half-sample average of window-average measurements
/// (0.5 (y_k + y_{k+1})) halves differenced-count noise and would put the floor at half the
/// residual of a perfect model (measured on the Khepera-like physics robot: floor 3.8e-4 m/s
/// against 6.9e-4 of true quantisation noise).
#[derive(Default)]
struct NoiseFloor {
    sum: [f64; 2],
    n: usize,
    kept: f64,
}

impl NoiseFloor {
    /// Adds recording `r` through its conditioning `c` (same samples).
    fn add(&mut self, c: &wheelid_core::Conditioned<'_>, r: &Recording) {
        let (Ok(sv), Ok(sw)) = (c.smooth(&r.v), c.smooth(&r.w)) else {
            return;
        };
        for k in c.valid_range() {
            self.sum[0] += (r.v[k] - sv[k]).powi(2);
            self.sum[1] += (r.w[k] - sw[k]).powi(2);
            self.n += 1;
        }
        self.kept = (1.0 - c.filter.cutoff_hz / (0.5 * c.filter.fs_hz)).clamp(0.05, 1.0);
    }
    fn sigma(&self) -> [f64; 2] {
        if self.n == 0 {
            return [0.0; 2];
        }
        self.sum.map(|s| (s / self.n as f64 / self.kept).sqrt())
    }
}

/// Step 1 and the nominal fit: the data prepared once for every later step, and the nominal
/// output-error fit on the training blocks.
///
/// # Errors
/// [`DiagnoseError`] for recordings that cannot be made uniform or split, or a failed fit.
pub(super) fn prepare(
    recordings: &[Recording],
    model: &dyn RegressorModel,
    settings: &DiagnoseSettings,
) -> Result<(Data, OutputErrorFit), DiagnoseError> {
    // Window-middle stamps (c) rewritten to window ends (b), which the models simulate.
    let recs: Vec<Recording> = recordings
        .iter()
        .map(|r| {
            let r = condition::restamp(r)?;
            condition::make_uniform(&r).map(|(u, _)| u.into_owned())
        })
        .collect::<Result<_, _>>()?;
    let (train, valid) = split(&recs, settings.blocks)?;
    let dt = recs
        .iter()
        .map(|r| r.sampling().dt_median)
        .fold(f64::INFINITY, f64::min);
    let fit = nominal_fit(&recs, &train, dt, model, settings)?;
    let track = settings
        .track_m
        .or_else(|| recs.iter().find_map(track_from_meta));
    let (accel, noise_floor) = accelerations(&recs, settings);
    let weight = [0, 1].map(|c| 1.0 / fit.noise_std[c].max(1e-12));
    let measured = settings
        .candidates
        .iter()
        .filter_map(|&c| c.effect().measured(&recs, track).map(|m| (c, m)))
        .collect();
    let data = Data {
        recs,
        placing: train.clone(),
        train,
        valid,
        dt,
        blocks: vec![settings.blocks; recordings.len()],
        track,
        weight,
        accel,
        noise_floor,
        measured,
    };
    Ok((data, fit))
}

/// The nominal model in hand: the nominal `fit` on `data`, simulated over every recording.
///
/// # Errors
/// [`DiagnoseError::Setting`] where the fitted θ does not simulate.
pub(super) fn nominal_current(data: &Data, fit: &OutputErrorFit) -> Result<Current, DiagnoseError> {
    let sim = simulate_all(&data.model(&[]), &fit.theta, &data.recs, &fit.initial)
        .ok_or_else(|| DiagnoseError::Setting("the nominal model does not simulate".into()))?;
    Ok(Current {
        candidates: Vec::new(),
        pinned: Vec::new(),
        theta: fit.theta.clone(),
        std_err: fit.std_err.clone(),
        covariance: fit.covariance.clone(),
        initial: fit.initial.clone(),
        sim,
        jacobian: fit.jacobian.as_ref().map(|j| data.frame().weigh(j)),
    })
}
