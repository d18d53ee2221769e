//! `velocity_saturation`: the base clips its setpoints to ±v_max, ±ω_max. Its fingerprint: the
//! measured speed stays within a level while the commands exceed it.

use wheelid_core::effect::{FitData, Probe, ProbeData, Search, Terms, abs_quantile};
use wheelid_core::{Effect, EffectChannels, ParamInfo, Recording, Result};

use super::{NEVER, limit_plausible};

static PARAMS: [ParamInfo; 2] = [
    ParamInfo {
        name: "v_max",
        unit: "m/s",
        description: "largest |v| setpoint the base accepts",
    },
    ParamInfo {
        name: "w_max",
        unit: "rad/s",
        description: "largest |ω| setpoint the base accepts",
    },
];

/// Largest |v|, |ω| setpoints (stage 2 of [`Terms`]); null: a level no command reaches.
#[derive(Debug, Clone, Copy)]
pub struct VelocitySaturation;

/// Fraction of the samples whose command `ch` exceeds `level` in magnitude.
fn over(recs: &[Recording], ch: usize, level: f64) -> f64 {
    let (over, n) = recs
        .iter()
        .flat_map(|r| {
            if ch == 0 {
                r.v_ref.iter()
            } else {
                r.w_ref.iter()
            }
        })
        .fold((0usize, 0usize), |(a, n), x| {
            (a + usize::from(x.abs() > level), n + 1)
        });
    over as f64 / n.max(1) as f64
}

impl Effect for VelocitySaturation {
    fn name(&self) -> &'static str {
        "velocity_saturation"
    }
    fn params(&self) -> &'static [ParamInfo] {
        &PARAMS
    }
    fn channels(&self) -> EffectChannels {
        EffectChannels::Each { positive: false }
    }
    fn null(&self, _theta: &[f64], _t_mid: f64) -> Vec<f64> {
        vec![NEVER, NEVER]
    }
    fn bounds(&self, _t_range: (f64, f64)) -> Vec<(f64, f64)> {
        vec![(1e-6, f64::INFINITY); 2]
    }
    fn search(&self) -> Search {
        Search::Limit { rate: false }
    }
    /// Levels in setpoint units: the 99.5 % quantile of the measured speed × θ4 (θ6), where the
    /// command exceeds 1.05 × that on ≥ 1 % of the samples.
    fn probe(&self, data: &ProbeData<'_>) -> Option<Probe> {
        let gain = [data.theta[3], data.theta[5]];
        let mut levels = Vec::new();
        let mut words = Vec::new();
        for (ch, name) in ["v", "ω"].into_iter().enumerate() {
            let y = abs_quantile(data.measured(ch), 0.995);
            let level = gain[ch].abs() * y;
            let over = over(data.recordings, ch, 1.05 * level);
            if over >= 0.01 && level > 0.0 {
                words.push(format!(
                    "|{name}| stays within {y:.3} while the command exceeds the matching \
                     setpoint {level:.3} on {:.1} % of the samples",
                    100.0 * over
                ));
                levels.push((ch, level));
            }
        }
        (!levels.is_empty()).then(|| Probe::Levels {
            levels,
            evidence: words.join("; "),
        })
    }
    fn evidence(&self) -> &'static str {
        "the measured speed stays within a level while the commands exceed it"
    }
    fn binding(&self, recordings: &[Recording], ch: usize, level: f64) -> Option<f64> {
        Some(over(recordings, ch, level))
    }
    fn plausible(
        &self,
        j: usize,
        x: f64,
        se: f64,
        fit: &FitData<'_>,
    ) -> std::result::Result<(), String> {
        limit_plausible(&PARAMS[j], x, se, over(fit.recordings, j, x))
    }
    fn apply(&self, p: &[f64], terms: &mut Terms) -> Result<()> {
        terms.sat = Some([p[0].abs(), p[1].abs()]);
        Ok(())
    }
}
