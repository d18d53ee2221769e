//! Step 8 of the diagnosis: the report — every finding's parameters as the final model has
//! them, what stays unexplained and where, the before/after series.

use super::*;

/// A channel whose validation fit stays below this [%] is a mismatch whatever the tests say:
/// a model that explains less than this share of a channel is not kept silently.
pub const LOW_FIT_PERCENT: f64 = 70.0;

/// A channel whose validation fit is at least this [%] (NRMSE ≤ 1 %) has no practically
/// relevant misfit: residual structure there is reported by the tests but is no mismatch, and
/// no effect is searched for it (on physics runs the eq.-2.19 model fits clean data to 99.9 %
/// and the tests still find structure at that level).
pub const PRACTICAL_FIT_PERCENT: f64 = 99.0;

/// Once an effect is in the model, the search goes on while a channel's validation fit is
/// below this [%], where the nominal model's mismatch needs a fit below
/// [`PRACTICAL_FIT_PERCENT`]: a second effect beside the first is often a few tenths of a
/// percent of the channel (tuning seeds on the physics backend, Pioneer-like robot: a
/// voltage clamp beside a battery's gain drift left v 99.8 %, ω 99.3 % with the clamp's
/// fingerprint at χ²(1) = 54.5; clean runs of that robot fit 99.85–99.9 %).
pub const SEARCH_FIT_PERCENT: f64 = 99.5;

/// A channel whose validation residual RMS exceeds this multiple of its measurement noise
/// floor ([`ChannelFit::noise_ratio`]) while its fit is below [`PRACTICAL_FIT_PERCENT`] holds
/// structure the model misses, whatever the tests say (tuning seeds 1–4 on the physics
/// backend, with the floor of the measured series: clean runs 0–1.8 ×, a voltage clamp on
/// the Khepera-like robot's window-averaged encoders 1.7–2.8 ×, other effects up to 140 ×).
pub const NOISE_FLOOR_FACTOR: f64 = 2.0;

/// Every finding's parameters as the final model has them (the later fits refit them all;
/// a secondary parameter held when the effect was accepted and freed by a later fit,
/// [`wheelid_core::Effect::secondary`], joins them).
fn final_parameters(findings: &mut [Finding], cur: &Current) {
    let mut at = 6;
    for c in &cur.candidates {
        if let Some(f) = findings.iter_mut().find(|f| f.effect == c.name()) {
            for (j, _) in c.effect().secondary(&cur.theta) {
                let name = c.params()[j].name.to_owned();
                if !cur.pinned.contains(&(at + j)) && !f.parameters.contains_key(&name) {
                    f.parameters.insert(name.clone(), cur.theta[at + j]);
                    f.std_err.insert(name, cur.std_err[at + j]);
                }
            }
            for (j, info) in c.params().iter().enumerate() {
                if let Some(v) = f.parameters.get_mut(info.name) {
                    *v = cur.theta[at + j];
                }
                // A change time's error is its placing's; a measured parameter held in the
                // later fits keeps its first fit's.
                if let Some(v) = f.std_err.get_mut(info.name)
                    && !(c.effect().search() == Search::ChangeTime && j == 0)
                    && !cur.pinned.contains(&(at + j))
                {
                    *v = cur.std_err[at + j];
                }
            }
        }
        at += c.params().len();
    }
}

/// Whether a channel's fit beyond the noise floor
/// ([`ChannelFit::noise_corrected_fit_percent`]) is below [`PRACTICAL_FIT_PERCENT`] (or
/// undefined).
pub(super) fn misses_beyond_noise(fit: &ChannelFit) -> bool {
    let beyond = fit.noise_corrected_fit_percent;
    beyond.is_nan() || beyond < PRACTICAL_FIT_PERCENT
}

/// Whether channel `c` (0: v, 1: ω; validation fit `fit`) holds structure the report calls
/// unexplained: its residual still depends on a command (`left`: the independence tests'
/// decisions in (channel, command) order) while it [`misses_beyond_noise`]. The search keeps
/// going while the model in hand leaves this (`search::structure_left`).
pub(super) fn structure_unexplained(left: &[bool], c: usize, fit: &ChannelFit) -> bool {
    (left[2 * c] || left[2 * c + 1]) && misses_beyond_noise(fit)
}

/// What the final model leaves unexplained: the channels whose validation fit — counting
/// only the residual beyond the measurement noise floor
/// ([`ChannelFit::noise_corrected_fit_percent`]) — is below [`PRACTICAL_FIT_PERCENT`] while
/// their residual still depends on the commands (Holm over the final location's tests, when
/// the first round found a mismatch) or stays above the noise floor ([`NOISE_FLOOR_FACTOR`]),
/// and the channels whose (plain) validation fit stays below [`LOW_FIT_PERCENT`], with where
/// the misfit lives. A residual that is the sensor's own noise is no unexplained physics,
/// whatever structure the tests find in it.
fn unexplained(
    mismatch: bool,
    location: &Location,
    final_stage: &Stage,
    alpha: f64,
) -> Option<Unexplained> {
    let left = holm(&location.p_values(), alpha);
    let ch = [final_stage.channels.v, final_stage.channels.w];
    let fits = ch.map(|f| f.fit_percent);
    let ratios = ch.map(|f| f.noise_ratio);
    let channels: Vec<usize> = (0..2)
        .filter(|&c| {
            (mismatch && structure_unexplained(&left, c, &ch[c]))
                || (ratios[c] > NOISE_FLOOR_FACTOR && misses_beyond_noise(&ch[c]))
                || fits[c] < LOW_FIT_PERCENT
        })
        .collect();
    if channels.is_empty() {
        return None;
    }
    Some(Unexplained {
        channels: channels.iter().map(|&c| ["v", "w"][c].to_owned()).collect(),
        location: channels
            .iter()
            .map(|&c| {
                let low = if fits[c] < LOW_FIT_PERCENT {
                    format!(
                        "validation fit {:.1} % (< {LOW_FIT_PERCENT:.0} %); ",
                        fits[c]
                    )
                } else {
                    format!(
                        "validation fit {:.1} %, residual {:.1} × the noise floor; ",
                        fits[c], ratios[c]
                    )
                };
                format!("{}: {low}{}", ["v", "ω"][c], location.summary(c))
            })
            .collect(),
    })
}

/// The intervals \[s\] in which the training blocks could not place the change times of
/// `cur`'s candidates, as their `findings` were found (time ± its half width,
/// [`Data::unidentified`]): the search placed those times with every sample ([`place`]), so
/// the validation samples there are not judged.
fn training_intervals(findings: &[Finding], cur: &Current) -> Vec<(f64, f64)> {
    cur.candidates
        .iter()
        .filter(|c| c.effect().search() == Search::ChangeTime)
        .filter_map(|c| {
            let f = findings.iter().find(|f| f.effect == c.name())?;
            let name = c.params().first()?.name;
            let (t, half) = (*f.parameters.get(name)?, *f.std_err.get(name)?);
            (half.is_finite() && half > 0.0).then_some((t - half, t + half))
        })
        .collect()
}

/// The [`Diagnosis`] from the search's outcome.
pub(super) fn assemble(
    data: &Data,
    settings: &DiagnoseSettings,
    mut nominal: Stage,
    location: Location,
    mut out: search::Outcome,
    nominal_sim: &Outputs,
    seconds: f64,
) -> Diagnosis {
    // The final model is judged where it makes a claim (outside its unidentified intervals),
    // and the nominal model alike; then a change time is placed with every sample inside its
    // interval (never judged there).
    let judged = data.judged_outside(&training_intervals(&out.findings, &out.cur));
    let findings = &out.findings;
    let placed = place::change_times(data, &mut out.cur, |c| {
        let f = findings.iter().find(|f| f.effect == c.name())?;
        f.std_err.get(c.params()[0].name).copied()
    });
    final_parameters(&mut out.findings, &out.cur);
    for (c, (a, b), se) in placed {
        if let Some(f) = out.findings.iter_mut().find(|f| f.effect == c.name()) {
            // The time's standard error as placed (final_parameters keeps the training one).
            if let Some(v) = f.std_err.get_mut(c.params()[0].name) {
                *v = se;
            }
            f.evidence.push_str(&format!(
                "; its time placed with every sample within [{a:.1}, {b:.1}] s, where the \
                 training blocks cannot tell"
            ));
        }
    }
    let final_location = if out.findings.is_empty() {
        location.clone()
    } else {
        let max_lag = data.max_lag(settings);
        locate::locate(&data.recs, &out.cur.sim, &judged, data.dt, max_lag)
    };
    let final_stage = data.stage(&out.cur, &judged);
    if judged != data.valid {
        (nominal.channels, nominal.validation_cost) = data.validate_on(nominal_sim, &judged);
    }
    let unexplained = unexplained(out.mismatch, &final_location, &final_stage, settings.alpha);
    let series = data
        .recs
        .iter()
        .enumerate()
        .map(|(r, rec)| DiagnosisSeries {
            source: rec.source.clone(),
            t: rec.t.clone(),
            validation: data.valid[r].clone(),
            measured: [rec.v.clone(), rec.w.clone()],
            nominal: nominal_sim[r].clone(),
            extended: out.cur.sim[r].clone(),
        })
        .collect();
    let heading = (data.track)
        .and_then(|d| wheelid_models::effects::heading_ratio(&data.recs, d))
        .filter(|(rho, se)| {
            let off = (rho - 1.0).abs();
            off >= wheelid_models::effects::MIN_RATIO_EFFECT && off >= 3.0 * se
        })
        .map(|(ratio, std_err)| HeadingCheck {
            ratio,
            std_err,
            modelled: out.cur.candidates.contains(&Candidate::TYRE_ASYMMETRY),
        });
    let seconds_of = |m: &[Vec<bool>]| m.iter().flatten().filter(|&&b| b).count() as f64 * data.dt;
    Diagnosis {
        nominal,
        split: Split {
            blocks: settings.blocks,
            training_s: seconds_of(&data.train),
            validation_s: seconds_of(&data.valid),
            searched_s: out.searched_s,
        },
        tests: out.tests,
        // The verdict: a model extended, or something left unexplained. First-round evidence
        // that no candidate takes up and that leaves the residual independent of the commands
        // is reported with the tests, but the model is kept.
        mismatch: !out.findings.is_empty() || unexplained.is_some(),
        location,
        fingerprints: out.rounds,
        unscored_round: out.unscored,
        findings: out.findings,
        rejected: out.rejected,
        unexplained,
        heading,
        final_stage,
        final_location,
        seconds,
        series,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fit(beyond: f64) -> ChannelFit {
        ChannelFit {
            fit_percent: 90.0,
            rms: 0.01,
            noise_ratio: 1.5,
            noise_corrected_fit_percent: beyond,
        }
    }

    /// Structure the report calls unexplained: a command dependence in that channel (ω's
    /// residual depends on v_ref: decision 2 of (v|v_ref, v|ω_ref, ω|v_ref, ω|ω_ref)) while the
    /// fit beyond the noise floor is below 99 % (or undefined); not v, whose tests pass.
    #[test]
    fn unexplained_structure_needs_a_command_dependence_and_a_fit_below_99_beyond_noise() {
        let left = [false, false, true, false];
        assert!(structure_unexplained(&left, 1, &fit(98.0)));
        assert!(structure_unexplained(&left, 1, &fit(f64::NAN)));
        assert!(!structure_unexplained(&left, 1, &fit(99.5)));
        assert!(!structure_unexplained(&left, 0, &fit(50.0)));
    }
}
