//! `acceleration_limit`: the setpoints slew toward the commands at most at a rate (an onboard
//! rate limiter, as the Pioneer's TransAccel/RotAccel). Its fingerprint: the measured
//! acceleration tops out while the commands step faster.

use wheelid_core::effect::{FitData, Probe, ProbeData, Search, Terms, abs_quantile};
use wheelid_core::{Effect, EffectChannels, ParamInfo, Recording, Result};

use super::{NEVER, limit_plausible};

static PARAMS: [ParamInfo; 2] = [
    ParamInfo {
        name: "v_accel_max",
        unit: "m/s²",
        description: "largest rate of change of the v setpoint",
    },
    ParamInfo {
        name: "w_accel_max",
        unit: "rad/s²",
        description: "largest rate of change of the ω setpoint",
    },
];

/// Largest rates of change of the v and ω setpoints (stage 3 of [`Terms`]); null: a rate no
/// command reaches.
#[derive(Debug, Clone, Copy)]
pub struct AccelerationLimit;

/// Fraction of the samples during which a setpoint slewing at `rate` toward command `ch`
/// (v_ref, ω_ref, held between samples) has not caught up with it.
pub fn slew_binding(recs: &[Recording], ch: usize, rate: f64) -> f64 {
    let (mut bound, mut total) = (0usize, 0usize);
    for r in recs {
        let u = if ch == 0 { &r.v_ref } else { &r.w_ref };
        let mut s = u[0];
        for k in 1..u.len() {
            let step = rate * (r.t[k] - r.t[k - 1]);
            let gap = u[k - 1] - s;
            s += gap.clamp(-step, step);
            bound += usize::from(gap.abs() > step);
            total += 1;
        }
    }
    bound as f64 / total.max(1) as f64
}

impl Effect for AccelerationLimit {
    fn name(&self) -> &'static str {
        "acceleration_limit"
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
        Search::Limit { rate: true }
    }
    /// Levels in setpoint units: the 99.5 % quantile of the measured acceleration × θ4 (θ6),
    /// where a setpoint slewing at that rate lags its command on ≥ 1 % of the samples.
    fn probe(&self, data: &ProbeData<'_>) -> Option<Probe> {
        let gain = [data.theta[3], data.theta[5]];
        let mut levels = Vec::new();
        let mut words = Vec::new();
        for (ch, name) in ["v", "ω"].into_iter().enumerate() {
            let a = abs_quantile(data.accel.iter().flat_map(|a| a[ch].iter().copied()), 0.995);
            let level = gain[ch].abs() * a;
            let over = slew_binding(data.recordings, ch, level);
            if over >= 0.01 && level > 0.0 {
                words.push(format!(
                    "{name}'s measured acceleration tops out at {a:.3} while the commands step \
                     faster on {:.1} % of the samples",
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
        "the measured acceleration tops out while the commands step faster"
    }
    fn binding(&self, recordings: &[Recording], ch: usize, level: f64) -> Option<f64> {
        Some(slew_binding(recordings, ch, level))
    }
    fn plausible(
        &self,
        j: usize,
        x: f64,
        se: f64,
        fit: &FitData<'_>,
    ) -> std::result::Result<(), String> {
        limit_plausible(&PARAMS[j], x, se, slew_binding(fit.recordings, j, x))
    }
    fn apply(&self, p: &[f64], terms: &mut Terms) -> Result<()> {
        terms.accel = Some([p[0].abs(), p[1].abs()]);
        Ok(())
    }
}
