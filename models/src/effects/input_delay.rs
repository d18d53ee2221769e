//! `input_delay`: a dead time of the commands, u(t − τ) — transport on the link, a controller
//! that acts one cycle late. Its fingerprint: the residual follows the commands' changes.

use wheelid_core::effect::{FitData, Probe, ProbeData, Search, Terms, significant};
use wheelid_core::{Effect, ParamInfo, Result};

static PARAMS: [ParamInfo; 1] = [ParamInfo {
    name: "delay_s",
    unit: "s",
    description: "dead time of the commands",
}];

/// The shortest dead time named, in sample periods. Below it a dead time is the size of what
/// the nominal model's stamping offset (issue 7's window-end/middle conventions, a host's
/// jitter) and the window averages' quadrature already settle to: a fit that leans on it is
/// reading timing noise (seen: 2 ms at a 20 ms period beside a traction limit), not a link's
/// or a controller's latency, which is a sizeable part of a cycle or more.
pub(super) const MIN_PERIODS: f64 = 0.25;

/// Dead time τ \[s\] of the commands (stage 1 of [`Terms`]); null 0, fitted within [0, 2] s,
/// plausible from `MIN_PERIODS` sample periods up to 1.5 s.
#[derive(Debug, Clone, Copy)]
pub struct InputDelay;

impl Effect for InputDelay {
    fn name(&self) -> &'static str {
        "input_delay"
    }
    fn params(&self) -> &'static [ParamInfo] {
        &PARAMS
    }
    fn null(&self, _theta: &[f64], _t_mid: f64) -> Vec<f64> {
        vec![0.0]
    }
    fn bounds(&self, _t_range: (f64, f64)) -> Vec<(f64, f64)> {
        vec![(0.0, 2.0)]
    }
    fn search(&self) -> Search {
        Search::DeadTime
    }
    fn probe(&self, data: &ProbeData<'_>) -> Option<Probe> {
        Some(Probe::Gradient(vec![(0, 0.5 * data.dt)]))
    }
    fn evidence(&self) -> &'static str {
        "the residual follows the commands' changes"
    }
    fn plausible(
        &self,
        j: usize,
        x: f64,
        se: f64,
        fit: &FitData<'_>,
    ) -> std::result::Result<(), String> {
        dead_time_plausible(&PARAMS[j], x, se, fit)
    }
    fn apply(&self, p: &[f64], terms: &mut Terms) -> Result<()> {
        terms.delay = p[0];
        Ok(())
    }
    /// "dead time", with `output_delay`: from the commands and the encoders alone a dead time
    /// of the measurements is one of the commands.
    fn quantity(&self) -> Option<&'static str> {
        Some(super::DEAD_TIME)
    }
}

/// A dead time `x` ± `se` \[s\] (parameter `info`) is named where it is significant, at most
/// 1.5 s, and at least [`MIN_PERIODS`] sample periods of `fit`'s recordings.
///
/// # Errors
/// The reason for the report.
pub(super) fn dead_time_plausible(
    info: &ParamInfo,
    x: f64,
    se: f64,
    fit: &FitData<'_>,
) -> std::result::Result<(), String> {
    significant(info, x, se, 0.0)?;
    if x > 1.5 {
        return Err(format!("a dead time of {x:.3} s is not plausible"));
    }
    let period = fit.period_s();
    if x < MIN_PERIODS * period {
        return Err(format!(
            "a dead time of {x:.4} s is under {MIN_PERIODS} of the {period:.4} s sample \
             period: not told apart from how the host stamps its samples"
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use wheelid_core::Recording;

    /// At a 20 ms period: 2 ms (a tenth of a period, the smoke test's spurious delay) is
    /// refused however significant, 10 ms (half a period, the harness's shortest latency) is
    /// named, 1.6 s is refused as implausible.
    #[test]
    fn dead_times_under_a_quarter_period_or_over_1_5_s_are_not_named() {
        let n = 501;
        let t: Vec<f64> = (0..n).map(|k| k as f64 * 0.02).collect();
        let rec = Recording::new(
            "r.csv",
            t,
            vec![0.1; n],
            vec![0.0; n],
            vec![0.1; n],
            vec![0.0; n],
        )
        .expect("valid");
        super::super::with_fit_data(rec, None, |fit| {
            approx::assert_relative_eq!(fit.period_s(), 0.02, max_relative = 1e-12);
            let plausible = |x: f64| InputDelay.plausible(0, x, 1e-5, fit);
            let short = plausible(0.002).expect_err("a tenth of a period");
            assert!(
                short.contains("under 0.25 of the 0.0200 s sample period"),
                "{short}"
            );
            assert!(plausible(0.0049).is_err());
            assert!(plausible(0.010).is_ok());
            assert!(plausible(1.6).is_err());
            // Not significant: refused before its size is looked at.
            assert!(InputDelay.plausible(0, 0.1, 0.05, fit).is_err());
        });
    }
}
