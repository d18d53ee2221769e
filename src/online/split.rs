//! How a held command's effect over a period splits between u_k and u_{k−1} in the sampled
//! difference equation (module docs of [`super`]), and each channel's recursive estimator of
//! it.
//!
//! With the split free, the regression has four parameters (a, β0, β1, c). Where eq. 2.19
//! holds, the split is fixed by a and the stamping (K = 1/θ4, γ(a) = (1 − a)/(−ln a) = (τ/T)(1 − a)):
//!
//! ```text
//! instants (a):          β0 = K (1 − a),   β1 = 0
//! window averages (b):   β0 = K (1 − γ),   β1 = K (γ − a)
//! ```
//!
//! On a robot whose response is not exactly first order the free split absorbs part of the
//! mismatch and moves a — and θ1 = −θ4 T/ln a — where the batch output-error fit, which
//! simulates eq. 2.19 with the split fixed, does not (the rigid-body Pioneer-like robot: θ1
//! 0.28 % from the batch answer with it free). With the split fixed the channel's regression
//! has three parameters (a, s, c), s = β0 + β1 = K (1 − a), on the regressor
//! [y_k, w0(â) u_k + w1(â) u_{k−1}, n̄_k] with w0 + w1 = 1 — the weights taken at the current
//! estimate â (a pseudo-linear regression; the regressor's scale does not move with â).

use wheelid_core::{Result, Timing};
use wheelid_solvers::recursive::{Rls, RlsSettings, RlsUpdate};

/// How the command's effect over a period splits between u_k and u_{k−1} (module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Split {
    /// Both coefficients free (any stamping, four parameters a channel).
    #[default]
    Free,
    /// Velocities at the instants of the samples (timing convention (a)): β1 = 0.
    Instant,
    /// Velocities averaged over the period ending at the sample (convention (b)).
    WindowAverage,
}

impl Split {
    /// The split fixed by a recording's stamping where it is known: instants (a) →
    /// [`Split::Instant`], window ends (b) → [`Split::WindowAverage`]; window middles (c) and
    /// unknown stamping → [`Split::Free`].
    pub fn of_timing(timing: Option<Timing>) -> Self {
        match timing {
            Some(Timing::Instant) => Self::Instant,
            Some(Timing::WindowEnd) => Self::WindowAverage,
            Some(Timing::WindowMiddle) | None => Self::Free,
        }
    }
}

/// The share a of the period's response kept from the last sample, where â is not yet one
/// (0 < â < 1 not met): a starting guess for the shares.
const A_START: f64 = 0.5;

/// The weights (w0, w1) of u_k and u_{k−1} (w0 + w1 = 1: β0 = s w0(a), β1 = s w1(a), s =
/// β0 + β1 = K (1 − a)), and their derivatives by a.
fn shares(split: Split, a: f64) -> ([f64; 2], [f64; 2]) {
    match split {
        Split::Instant | Split::Free => ([1.0, 0.0], [0.0, 0.0]),
        Split::WindowAverage => {
            let ln = a.ln();
            let gamma = (1.0 - a) / -ln;
            let d_gamma = (ln + (1.0 - a) / a) / (ln * ln);
            let w0 = (1.0 - gamma) / (1.0 - a);
            let d_w0 = ((1.0 - gamma) - d_gamma * (1.0 - a)) / ((1.0 - a) * (1.0 - a));
            ([w0, 1.0 - w0], [d_w0, -d_w0])
        }
    }
}

/// One channel's recursive estimator: four free parameters, or three with the split fixed;
/// with (a, β0, β1, c) and the next update's weights kept from its last update (read several
/// times a sample: one logarithm an update instead of one a reading).
#[derive(Debug, Clone)]
pub(super) struct ChannelRls {
    form: Form,
    /// (a, β0, β1, c) at the estimate.
    theta: [f64; 4],
    /// (w0, w1) at â where it is a share (0 < â < 1), else at [`A_START`].
    weights: [f64; 2],
}

#[derive(Debug, Clone)]
enum Form {
    Free(Rls<4>),
    Fixed(Rls<3>, Split),
}

impl ChannelRls {
    /// # Errors
    /// As [`Rls::new`].
    pub(super) fn new(split: Split, settings: RlsSettings) -> Result<Self> {
        let form = match split {
            Split::Free => Form::Free(Rls::new(settings, [0.0; 4])?),
            fixed => Form::Fixed(Rls::new(settings, [0.0; 3])?, fixed),
        };
        let mut c = Self {
            form,
            theta: [0.0; 4],
            weights: [1.0, 0.0],
        };
        c.refresh();
        Ok(c)
    }

    /// (a, β0, β1, c) and the weights from the estimate.
    fn refresh(&mut self) {
        match &self.form {
            Form::Free(r) => self.theta = r.theta(),
            Form::Fixed(r, s) => {
                let [a, sum, c] = r.theta();
                let (w, _) = shares(*s, a);
                self.theta = [a, sum * w[0], sum * w[1], c];
                self.weights = if a > 0.0 && a < 1.0 {
                    w
                } else {
                    shares(*s, A_START).0
                };
            }
        }
    }

    /// The three-parameter regressor of a four-parameter row [y_k, u_k, u_{k−1}, n̄_k] under
    /// the weights `w`.
    fn reduce([w0, w1]: [f64; 2], row: &[f64; 4]) -> [f64; 3] {
        [row[0], w0 * row[1] + w1 * row[2], row[3]]
    }

    /// Least-squares update on `row` = [y_k, u_k, u_{k−1}, n̄_k] toward `y` = y_{k+1}.
    pub(super) fn update(&mut self, row: &[f64; 4], y: f64) -> RlsUpdate {
        let step = match &mut self.form {
            Form::Free(r) => r.update(row, y),
            Form::Fixed(r, _) => r.update(&Self::reduce(self.weights, row), y),
        };
        self.refresh();
        step
    }

    /// Instrumental-variables update ([`Rls::update_iv`]) with instruments `zeta` (a row of
    /// the same form).
    pub(super) fn update_iv(&mut self, row: &[f64; 4], zeta: &[f64; 4], y: f64) -> RlsUpdate {
        let w = self.weights;
        let step = match &mut self.form {
            Form::Free(r) => r.update_iv(row, zeta, y),
            Form::Fixed(r, _) => r.update_iv(&Self::reduce(w, row), &Self::reduce(w, zeta), y),
        };
        self.refresh();
        step
    }

    /// (a, β0, β1, c).
    pub(super) fn theta(&self) -> [f64; 4] {
        self.theta
    }

    /// The covariance of (a, β0, β1, c) (with the split fixed: J C Jᵀ, J = ∂(a, β0, β1, c)/
    /// ∂(a, s, c)).
    pub(super) fn covariance(&self) -> [[f64; 4]; 4] {
        match &self.form {
            Form::Free(r) => r.covariance(),
            Form::Fixed(r, s) => {
                let [a, sum, _] = r.theta();
                let ([w0, w1], [d0, d1]) = shares(*s, a);
                let j = [
                    [1.0, 0.0, 0.0],
                    [sum * d0, w0, 0.0],
                    [sum * d1, w1, 0.0],
                    [0.0, 0.0, 1.0],
                ];
                let c = r.covariance();
                std::array::from_fn(|p| {
                    std::array::from_fn(|q| {
                        let mut x = 0.0;
                        for (m, jm) in j[p].iter().enumerate() {
                            for (n, jn) in j[q].iter().enumerate() {
                                x += jm * c[m][n] * jn;
                            }
                        }
                        x
                    })
                })
            }
        }
    }

    /// Alarms raised so far.
    pub(super) fn changes(&self) -> u64 {
        match &self.form {
            Form::Free(r) => r.changes(),
            Form::Fixed(r, _) => r.changes(),
        }
    }
}
