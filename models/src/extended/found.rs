//! The extended model a diagnosis saved: a model file's `[effects.*]` tables (effect name →
//! parameter name → value, in the units of each effect's [`wheelid_core::ParamInfo`]) back to
//! an [`Extended`] and its parameter vector, so that the model can be simulated as it was
//! fitted (`wheelid simulate --model`).

use std::collections::BTreeMap;

use wheelid_core::{Error, Result};

use super::{Candidate, Extended};
use crate::effects::EFFECTS;

/// Effects found, as a model file stores them: effect name → parameter name → value.
pub type Found = BTreeMap<String, BTreeMap<String, f64>>;

impl Extended {
    /// The extended model of θ1…θ6 = `theta` with the effects `found`, on a track `track_m`
    /// \[m\], and its full parameter vector (θ1…θ6, then each effect's parameters in
    /// registry order, [`EFFECTS`]). A parameter the file leaves out — a limit's channel
    /// that never bound, one the fit held — takes the effect's null
    /// ([`wheelid_core::Effect::null`]: a limit at [`crate::effects::NEVER`], a ratio at 1).
    ///
    /// # Errors
    /// [`Error::InvalidSetting`] naming an unknown effect, an unknown parameter of a known
    /// one, a value outside the effect's bounds ([`wheelid_core::Effect::bounds`]), or a set of values the effect refuses
    /// ([`wheelid_core::Effect::apply`]), as [`Extended::new`] for the track.
    pub fn from_found(theta: &[f64; 6], found: &Found, track_m: f64) -> Result<(Self, Vec<f64>)> {
        if let Some(name) = found.keys().find(|n| Candidate::by_name(n).is_none()) {
            return Err(Error::InvalidSetting(format!(
                "effect {name}: no such effect (known: {})",
                Candidate::names().join(", ")
            )));
        }
        let mut candidates = Vec::new();
        let mut params = theta.to_vec();
        for effect in EFFECTS.iter().filter(|e| found.contains_key(e.name())) {
            let given = &found[effect.name()];
            let infos = effect.params();
            if let Some(k) = given.keys().find(|k| !infos.iter().any(|i| i.name == *k)) {
                let known: Vec<&str> = infos.iter().map(|i| i.name).collect();
                return Err(Error::InvalidSetting(format!(
                    "effect {}: no parameter {k} (known: {})",
                    effect.name(),
                    known.join(", ")
                )));
            }
            let null = effect.null(theta, 0.0);
            let bounds = effect.bounds((f64::NEG_INFINITY, f64::INFINITY));
            for ((info, null), (lo, hi)) in infos.iter().zip(null).zip(bounds) {
                let x = given.get(info.name).copied().unwrap_or(null);
                if !(x.is_finite() && (lo..=hi).contains(&x)) {
                    return Err(Error::InvalidSetting(format!(
                        "effect {}: {} = {x} {} is outside [{lo}, {hi}]",
                        effect.name(),
                        info.name,
                        info.unit
                    )));
                }
                params.push(x);
            }
            candidates.push(Candidate::new(*effect));
        }
        let model = Extended::new(&candidates, track_m)?;
        // The effects' own checks (and θ's), before anything is simulated.
        model.physics(&params).map_err(|e| match e {
            Error::InvalidSetting(m) => Error::InvalidSetting(format!("saved model: {m}")),
            other => other,
        })?;
        Ok((model, params))
    }
}

#[cfg(test)]
mod tests {
    use wheelid_core::DynamicModel;

    use super::*;

    fn found(entries: &[(&str, &[(&str, f64)])]) -> Found {
        entries
            .iter()
            .map(|(e, ps)| {
                let ps = ps.iter().map(|(k, x)| (k.to_string(), *x)).collect();
                (e.to_string(), ps)
            })
            .collect()
    }

    const THETA: [f64; 6] = [0.26, 0.25, -0.0005, 0.99, 0.0026, 1.08];

    #[test]
    fn parameters_follow_the_registry_and_missing_ones_take_the_null() {
        let f = found(&[
            ("velocity_saturation", &[("w_max", 1.0)]),
            ("input_delay", &[("delay_s", 0.15)]),
        ]);
        let (m, p) = Extended::from_found(&THETA, &f, 0.33).expect("builds");
        let names: Vec<&str> = m.params().iter().map(|i| i.name).collect();
        // input_delay before velocity_saturation (registry order), v_max at NEVER.
        assert_eq!(
            names[6..],
            ["delay_s", "v_max", "w_max"],
            "parameter order {names:?}"
        );
        assert_eq!(p[6..], [0.15, crate::effects::NEVER, 1.0]);
        assert_eq!(p[..6], THETA);
    }

    #[test]
    fn unknown_effects_parameters_and_bad_values_are_named() {
        let err = |f: Found| {
            Extended::from_found(&THETA, &f, 0.33)
                .expect_err("refused")
                .to_string()
        };
        let e = err(found(&[("warp_drive", &[("c", 1.0)])]));
        assert!(e.contains("warp_drive") && e.contains("input_delay"), "{e}");
        let e = err(found(&[("input_delay", &[("delay", 0.1)])]));
        assert!(
            e.contains("no parameter delay") && e.contains("delay_s"),
            "{e}"
        );
        let e = err(found(&[("input_delay", &[("delay_s", f64::NAN)])]));
        assert!(e.contains("delay_s = NaN"), "{e}");
        let e = err(found(&[("input_delay", &[("delay_s", -0.1)])]));
        assert!(e.contains("delay_s = -0.1 s is outside [0, 2]"), "{e}");
    }

    /// A per-wheel effort clamp from rest under a straight step: the loop's effort u − v is
    /// held at the clamp c while it binds, so θ1 v̇ = c − (θ4 − 1) v (module docs of
    /// [`super`]): the first 20 ms rise at c/θ1, not u/θ1.
    #[test]
    fn a_saved_clamp_limits_the_first_acceleration_to_its_level() {
        let f = found(&[("effort_clamp", &[("effort_max", 0.1)])]);
        let (m, p) = Extended::from_found(&THETA, &f, 0.33).expect("builds");
        let t: Vec<f64> = (0..=10).map(|k| 0.01 * k as f64).collect();
        let n = t.len();
        let mut rec = wheelid_core::Recording::new(
            "step",
            t,
            vec![0.5; n],
            vec![0.0; n],
            vec![0.0; n],
            vec![0.0; n],
        )
        .expect("recording");
        rec.set_timing(wheelid_core::Timing::Instant);
        rec.set_meta("command_hold", "zoh");
        let y = m.simulate(&p, &rec, &[0.0, 0.0]).expect("simulates");
        let slope = y[0][2] / 0.02;
        let want = 0.1 / THETA[0];
        assert!(
            (slope / want - 1.0).abs() < 0.01,
            "v̇ {slope} vs c/θ1 {want}"
        );
    }
}
