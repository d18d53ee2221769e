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
//!
//! **Jitter.** A host samples at instants s_k that are not exactly T apart. Over the held
//! command's period T_k = s_{k+1} − s_k the response keeps a_k = a^{ρ_k}, ρ_k = T_k/T, and
//! window averages over the periods T_k and T_{k−1} give, with γ(x, ρ) = (1 − x)/(−ρ ln a),
//! γ_k = γ(a_k, ρ_k):
//!
//! ```text
//! instants (a):          y_{k+1} = a_k y_k + K (1 − a_k) u_k + c (1 − a_k)/(1 − a) n̄_k
//! window averages (b):   y_{k+1} = A_k y_k + K (1 − γ_k) u_k + K (γ_k − A_k) u_{k−1}
//!                                  + c (1 − A_k)/(1 − a) n̄_k,     A_k = γ_k a_{k−1}/γ_{k−1}
//! ```
//!
//! (the free split takes the instants' form with both coefficients). Each channel still
//! regresses on the nominal-period row; the difference d_k between the two right-hand sides,
//! taken at the current estimate from the measured signals ([`ChannelRls::jitter_correction`]),
//! passes through the same prefilter (linear and time-invariant in k, it leaves the equation as
//! it is) and comes off the target: a pseudo-linear regression whose fixed point is the
//! robot's θ at any stamping, and which reduces to the nominal one where ρ_k = 1.

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
/// β0 + β1 = K (1 − a)), and their derivatives by a; `ln` = ln a, `inv_m` = 1/(1 − a).
fn shares(split: Split, a: f64, ln: f64, inv_m: f64) -> ([f64; 2], [f64; 2]) {
    match split {
        Split::Instant | Split::Free => ([1.0, 0.0], [0.0, 0.0]),
        Split::WindowAverage => {
            // Two divisions here (1/(1 − a) is the caller's); the rest multiplies.
            let m = 1.0 - a;
            let (inv_ln, inv_a) = (1.0 / ln, 1.0 / a);
            let gamma = -m * inv_ln;
            let d_gamma = (ln + m * inv_a) * inv_ln * inv_ln;
            let w0 = (1.0 - gamma) * inv_m;
            let d_w0 = ((1.0 - gamma) - d_gamma * m) * inv_m * inv_m;
            ([w0, 1.0 - w0], [d_w0, -d_w0])
        }
    }
}

/// A channel's continuous-time rates at its estimate ([`ChannelRls::rates`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Rates {
    /// r = 1/τ \[1/s\].
    pub pole: f64,
    /// K.
    pub gain: f64,
    /// C.
    pub coupling: f64,
}

/// The sampled equation's step over the periods the samples actually spanned, at a channel's
/// current estimate ([`ChannelRls::jittered`]; module docs, "Jitter"): y_{k+1} = `pole` y_k +
/// `forced` + `coupling` n̄_k, with `pole` = a_k (instants, free split) or A_k (window
/// averages). Both of a sample's uses — the target's correction d_k
/// ([`ChannelRls::jitter_correction`]) and the instruments' auxiliary model
/// ([`ChannelRls::step`]) — take it from the same y-free coefficients (the same commands u_k,
/// u_{k−1}), so the period factors a^{ρ_k}, a^{ρ_{k−1}} are taken once a sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Jittered {
    /// a_k or A_k: the share of y_k kept over the period.
    pub pole: f64,
    /// The commands' part: (1 − a_k)/(1 − a) (β0 u_k + β1 u_{k−1}) (instants: K (1 − a_k)
    /// u_k; the free split with both coefficients), or K ((1 − γ_k) u_k + (γ_k − A_k) u_{k−1})
    /// (window averages).
    pub forced: f64,
    /// The coupling's coefficient, c (1 − a_k)/(1 − a) or c (1 − A_k)/(1 − a).
    pub coupling: f64,
}

/// One channel's recursive estimator: four free parameters, or three with the split fixed;
/// with (a, β0, β1, c), ln â, 1/(1 − â) and the next update's weights kept from its last update
/// (read several times a sample: one logarithm and one division an update instead of one a
/// reading).
#[derive(Debug, Clone)]
pub(super) struct ChannelRls {
    form: Form,
    /// (a, β0, β1, c) at the estimate.
    theta: [f64; 4],
    /// (w0, w1) at â where it is a share (0 < â < 1), else at [`A_START`], and their
    /// derivatives by a there.
    weights: [f64; 2],
    d_weights: [f64; 2],
    /// ln â with the split fixed (NaN where â ≤ 0; free: not kept, NaN).
    ln_a: f64,
    /// 1/(1 − â) with the split fixed (free: not kept, NaN).
    inv_m: f64,
    /// The split the stamping fixes (the jitter correction's form; `Free` for the free
    /// four-parameter regression).
    split: Split,
    /// ψ = ∂ŷ/∂(a, β0, β1, c) (free) or ∂ŷ/∂(a, s, c) (fixed, first three) of the output-error
    /// form's simulated output at the last sample; zero where the last update was not in that
    /// form.
    psi: [f64; 4],
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
            d_weights: [0.0; 2],
            ln_a: f64::NAN,
            inv_m: f64::NAN,
            split,
            psi: [0.0; 4],
        };
        c.refresh();
        Ok(c)
    }

    /// (a, β0, β1, c), ln â, 1/(1 − â) and the weights from the estimate.
    fn refresh(&mut self) {
        match &self.form {
            Form::Free(r) => self.theta = r.theta(),
            Form::Fixed(r, s) => {
                let [a, sum, c] = r.theta();
                self.ln_a = a.ln();
                self.inv_m = 1.0 / (1.0 - a);
                let (w, dw) = shares(*s, a, self.ln_a, self.inv_m);
                self.theta = [a, sum * w[0], sum * w[1], c];
                (self.weights, self.d_weights) = if a > 0.0 && a < 1.0 {
                    (w, dw)
                } else {
                    shares(*s, A_START, A_START.ln(), 1.0 / (1.0 - A_START))
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

    /// Starts the output-error form's gradient ψ afresh (its simulation starts).
    pub(super) fn reset_gradient(&mut self) {
        self.psi = [0.0; 4];
    }

    /// Advances the output-error form's gradient over the simulated output's step from `sim`
    /// = (ŷ_k, n̂̄_k) under `u` = (u_k, u_{k−1}): ψ_{k+1} = â ψ_k + ∂(step)/∂θ at the estimate,
    /// by the sampled equation (the coupling n̂ taken as given; module docs of [`super`],
    /// "Output error").
    pub(super) fn advance_gradient(&mut self, sim: [f64; 2], u: [f64; 2]) {
        let [a, b0, b1, _] = self.theta;
        let [y_hat, n] = sim;
        let g = match &self.form {
            Form::Free(_) => [y_hat, u[0], u[1], n],
            Form::Fixed(..) => {
                let (w, dw) = (self.weights, self.d_weights);
                [
                    y_hat + (b0 + b1) * (dw[0] * u[0] + dw[1] * u[1]),
                    w[0] * u[0] + w[1] * u[1],
                    n,
                    0.0,
                ]
            }
        };
        for (p, g) in self.psi.iter_mut().zip(g) {
            *p = a * *p + g;
        }
    }

    /// Output-error update: a Gauss–Newton step on `error` = y_{k+1} − ŷ_{k+1} along the
    /// gradient of [`ChannelRls::advance_gradient`] ([`Rls::update_gradient`]); the change
    /// detector reads the prefiltered equation's one-step error on `row` toward `y`.
    pub(super) fn update_output_error(&mut self, error: f64, row: &[f64; 4], y: f64) -> RlsUpdate {
        let psi = self.psi;
        let step = match &mut self.form {
            Form::Free(r) => r.update_gradient(&psi, error, (row, y)),
            Form::Fixed(r, _) => r.update_gradient(
                &[psi[0], psi[1], psi[2]],
                error,
                (&Self::reduce(self.weights, row), y),
            ),
        };
        self.refresh();
        step
    }

    /// The channel's continuous-time rates at the estimate, for samples 1/`inv_dt` \[s\] apart: the
    /// pole r = 1/τ = −ln â/T, the gain K = s/(1 − â) and the coupling's C = c/(1 − â) of
    /// ẏ = r (K u + C n − y) (v: K = 1/θ4, C = θ3/θ4; ω: K = 1/θ6, C = −θ5/θ6); `None` where
    /// the estimate does not map (0 < â < 1, s > 0).
    pub(super) fn rates(&self, inv_dt: f64) -> Option<Rates> {
        let [a, b0, b1, c] = self.theta;
        let s = b0 + b1;
        if !(a > 0.0 && a < 1.0 && s > 0.0) {
            return None;
        }
        let inv = self.inv_m();
        Some(Rates {
            pole: -self.ln_a() * inv_dt,
            gain: s * inv,
            coupling: c * inv,
        })
    }

    /// ln â (kept from the last update where the split is fixed).
    pub(super) fn ln_a(&self) -> f64 {
        match self.form {
            Form::Free(_) => self.theta[0].ln(),
            Form::Fixed(..) => self.ln_a,
        }
    }

    /// 1/(1 − â) (kept from the last update where the split is fixed).
    fn inv_m(&self) -> f64 {
        match self.form {
            Form::Free(_) => 1.0 / (1.0 - self.theta[0]),
            Form::Fixed(..) => self.inv_m,
        }
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
                let ([w0, w1], [d0, d1]) = shares(*s, a, self.ln_a, self.inv_m);
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

    /// d_k: what the sampled equation at the periods the samples actually spanned adds to
    /// the one at the nominal period T, at the current estimate (module docs, "Jitter"), from
    /// that step's coefficients `jittered` ([`ChannelRls::jittered`]); `y` = y_k, `u` = (u_k,
    /// u_{k−1}), `n` = n̄_k, all as measured (unfiltered). Where there is no such step (â not
    /// a share, or the periods nominal) d_k is zero and the caller does not ask.
    pub(super) fn jitter_correction(
        &self,
        jittered: &Jittered,
        y: f64,
        u: [f64; 2],
        n: f64,
    ) -> f64 {
        let (p, q) = self.step(Some(jittered), y, u);
        let (p0, q0) = self.step(None, y, u);
        p + q * n - (p0 + q0 * n)
    }

    /// The coefficients of the sampled equation's step at the current estimate over the periods
    /// `rho` = (T_k/T, T_{k−1}/T) under `u` = (u_k, u_{k−1}) (module docs, "Jitter", instants
    /// (a) and window averages (b): a_k = â^{ρ_k}, and for window averages a_{k−1} =
    /// â^{ρ_{k−1}}, γ_k and A_k); `None` where â is not a share
    /// (0 < â < 1), where the nominal equation stands. The caller has found the periods not
    /// nominal.
    pub(super) fn jittered(&self, rho: [f64; 2], u: [f64; 2]) -> Option<Jittered> {
        let [a, b0, b1, c] = self.theta;
        if !(a > 0.0 && a < 1.0) {
            return None;
        }
        let ln = self.ln_a();
        let a_k = (rho[0] * ln).exp();
        // Three divisions (1/(1 − a), kept where the split is fixed; for window averages
        // 1/(ρ_k ln a) and one for A_k): the jittered path is otherwise division-bound.
        let inv_m = self.inv_m();
        Some(match self.split {
            Split::Free | Split::Instant => {
                let scale = (1.0 - a_k) * inv_m;
                Jittered {
                    pole: a_k,
                    forced: scale * (b0 * u[0] + b1 * u[1]),
                    coupling: scale * c,
                }
            }
            Split::WindowAverage => {
                let a_prev = (rho[1] * ln).exp();
                // γ(x, ρ) = (1 − x)/(−ρ ln a); A_k = γ_k a_{k−1}/γ_{k−1}, where ln a cancels.
                let g_k = (1.0 - a_k) / (-rho[0] * ln);
                let big_a = a_prev * (1.0 - a_k) * rho[1] / (rho[0] * (1.0 - a_prev));
                let gain = (b0 + b1) * inv_m;
                Jittered {
                    pole: big_a,
                    forced: gain * ((1.0 - g_k) * u[0] + (g_k - big_a) * u[1]),
                    coupling: c * (1.0 - big_a) * inv_m,
                }
            }
        })
    }

    /// The sampled equation's step at the current estimate from y_k = `y` under `u` = (u_k,
    /// u_{k−1}), as (p, q): y_{k+1} = p + q n̄_k — over the periods the samples spanned where
    /// `jittered` holds that step's coefficients ([`ChannelRls::jittered`]), else the nominal
    /// equation (module docs, "Jitter").
    pub(super) fn step(&self, jittered: Option<&Jittered>, y: f64, u: [f64; 2]) -> (f64, f64) {
        match jittered {
            Some(j) => (j.pole * y + j.forced, j.coupling),
            None => {
                let [a, b0, b1, c] = self.theta;
                (a * y + b0 * u[0] + b1 * u[1], c)
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
