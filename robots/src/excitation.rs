//! Excitation signals.

use serde::{Deserialize, Serialize};

/// u(t) = offset + Σ a_i sin(ω_i t).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SumOfSines {
    /// Constant offset.
    pub offset: f64,
    /// Terms (amplitude, angular frequency [rad/s]).
    pub terms: Vec<(f64, f64)>,
}

impl SumOfSines {
    /// Value at time `t` [s].
    pub fn at(&self, t: f64) -> f64 {
        self.offset
            + self
                .terms
                .iter()
                .map(|(a, w)| a * (w * t).sin())
                .sum::<f64>()
    }
}

/// A pair of commands (v_ref [m/s], ω_ref [rad/s]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Excitation {
    /// Forward-velocity command.
    pub v_ref: SumOfSines,
    /// Angular-velocity command.
    pub w_ref: SumOfSines,
}

impl Excitation {
    /// The thesis's Pioneer 3-DX excitation (§4.4.2):
    /// v_ref = 0.4 + 0.1 sin 2t + 0.1 sin t + 0.1 sin(t/3) + 0.1 sin(t/11),
    /// ω_ref = 0.75 + 0.25 sin(3t/2) + 0.25 sin t + 0.25 sin(t/2) + 0.25 sin(t/5).
    pub fn thesis_pioneer() -> Self {
        Self {
            v_ref: SumOfSines {
                offset: 0.4,
                terms: vec![(0.1, 2.0), (0.1, 1.0), (0.1, 1.0 / 3.0), (0.1, 1.0 / 11.0)],
            },
            w_ref: SumOfSines {
                offset: 0.75,
                terms: vec![(0.25, 1.5), (0.25, 1.0), (0.25, 0.5), (0.25, 0.2)],
            },
        }
    }

    /// The thesis's Khepera III excitation (§4.4.1):
    /// v_ref = 0.1 + 0.05 sin 2t + 0.05 sin t + 0.05 sin(t/3) + 0.05 sin(t/11),
    /// ω_ref = 1.5 + 0.5 sin(3t/2) + 0.5 sin t + 0.25 sin(t/2) + 0.25 sin(t/5).
    pub fn thesis_khepera() -> Self {
        Self {
            v_ref: SumOfSines {
                offset: 0.1,
                terms: vec![
                    (0.05, 2.0),
                    (0.05, 1.0),
                    (0.05, 1.0 / 3.0),
                    (0.05, 1.0 / 11.0),
                ],
            },
            w_ref: SumOfSines {
                offset: 1.5,
                terms: vec![(0.5, 1.5), (0.5, 1.0), (0.25, 0.5), (0.25, 0.2)],
            },
        }
    }

    /// Commands at time `t` [s].
    pub fn at(&self, t: f64) -> (f64, f64) {
        (self.v_ref.at(t), self.w_ref.at(t))
    }
}
