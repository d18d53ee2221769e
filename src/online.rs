//! Online identification of θ1…θ6 (Laut 2011 eq. 2.19) on board, one sample at a time, by
//! recursive least squares on prefiltered regressors — then the recursive prediction-error form
//! of the output-error fit, or recursive instrumental variables — with forgetting and a change
//! detector (`wheelid_solvers::recursive`).
//!
//! The batch pipeline filters forward and backward and differentiates numerically; neither
//! runs causally, and a causal derivative of sampled data is biased when the period is not
//! small against θ1 (the Khepera III: θ1 ≈ 26 ms at 20 ms). Each channel of eq. 2.19 is
//! instead written exactly at the samples. The v channel, θ1 v̇ = v_ref − θ4 v + θ3 ω², with
//! the command held over each period T and the coupling n = ω² taken as its trapezoidal mean
//! n̄_k = (n_k + n_{k+1})/2 over it, gives
//!
//! ```text
//! y_{k+1} = a y_k + β0 u_k + β1 u_{k−1} + c n̄_k,     a = e^{−θ4 T/θ1},
//! β0 + β1 = (1 − a)/θ4,   c = θ3 (1 − a)/θ4
//! ```
//!
//! with β1 = 0 for instantaneous velocities (timing convention (a)) and β1 ≠ 0 for velocities
//! averaged over the period (conventions (b), (c): the average of an exponential over a held
//! command; issue 7), so one regressor [y_k, u_k, u_{k−1}, n̄_k] serves every convention.
//! The ω channel is the same with (θ2, θ6, −θ5) and n = v ω. Back to θ:
//!
//! ```text
//! θ4 = (1 − a)/(β0 + β1),   θ1 = −θ4 T / ln a,   θ3 = c/(β0 + β1)
//! ```
//!
//! (undefined, reported as NaN, until 0 < a < 1 and β0 + β1 > 0). Where the recording's
//! stamping is known the split of β0 and β1 is fixed by it ([`Split`], [`OnlineSettings::split`],
//! module `split`): three parameters a channel (a, β0 + β1, c); left free, it absorbs part of a
//! robot's departure from a first-order response and moves θ1 (0.28 % on the rigid-body
//! Pioneer-like robot, 7–50 standard errors from the batch output-error answer; fixed: within
//! 1.8). Standard errors by the
//! delta method from the RLS covariance P M P (long-run, for coloured equation errors:
//! `wheelid_solvers::recursive`). Every signal first passes through the same causal low-pass
//! L(q) = ((1 − p)/(1 − p q⁻¹))², p = e^{−2π f_c T}: a linear time-invariant filter leaves the
//! difference equation as it is and weighs down the high band, where the measurement noise in
//! the regressor y_k lives. Stamps that are not T apart (a host's jitter) change the sampled
//! equation; each channel's target carries the change at the current estimate (module `split`,
//! "Jitter").
//!
//! **Instruments.** Noise in the regressors y_k and n̄_k still biases least squares (errors in
//! variables: +5–8 % on θ1 of the rigid-body Khepera with 5 mm/s of wheel-speed noise). With
//! [`OnlineForm::InstrumentalVariables`], once a channel's estimate maps to θ and
//! has run `warmup_s` (from the start or its last change alarm), it is updated by recursive
//! instrumental variables ([`wheelid_solvers::recursive::Rls::update_iv`]): ζ_k is φ_k with every measured output replaced
//! by an auxiliary model's — the sampled eq. 2.19 run at the current estimates on the commands
//! alone, v̂_{k+1} = â v̂_k + β̂0 u_k + β̂1 u_{k−1} + ĉ ω̂_k² (and ω̂ alike with v̂ ω̂), filtered
//! by L — uncorrelated with the measurement noise (Young 1976; Söderström & Stoica 1983).
//!
//! **Output error** ([`OnlineForm::OutputError`], the default). Both the equation-error and
//! the instrumental forms fit the sampled difference equation, whose coupling term is the
//! product of window averages at the ends of a period; on the rigid-body Pioneer-like robot,
//! whose ω channel the coupling θ5 v ω damps by a fifth, that puts θ2 3·10⁻⁴ (1.3–2.1 of its
//! standard errors) from the batch output-error answer on every drive. The recursive
//! prediction-error form of the output-error fit (Ljung & Söderström 1983, §3.7; Ljung 1999
//! §11.3) minimises the batch fit's own criterion: once both channels have run `warmup_s`,
//! eq. 2.19 is simulated at θ̂ on the commands alone over each period the stamps span (module
//! `flow`: RK4, as the batch fit), and each channel takes a Gauss–Newton step
//! ([`wheelid_solvers::recursive::Rls::update_gradient`]) on the output error y_{k+1} − ŷ_{k+1}
//! (unfiltered) along its gradient ψ_{k+1} = â ψ_k + ∂(the sampled step)/∂(a, s, c), the
//! coupling taken as given. For five time constants after the simulation starts (its start
//! from the measured velocities, and ψ from zero, to die out) the channels stay on least
//! squares. The change detector reads the prefiltered equation's one-step error throughout
//! (an output error is coloured by the model's own dynamics). It needs the split fixed (the
//! stamping known: the simulation reports what the host stamps); with it free this form runs
//! the instruments.

use wheelid_core::{Error, Result};
use wheelid_solvers::recursive::{ChangeDetection, RlsSettings};

mod flow;
mod split;
use flow::Flow;
pub use split::Split;
use split::{ChannelRls, Jittered};

/// Settings of the online estimator.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct OnlineSettings {
    /// f_c: the prefilter's corner \[Hz\]; `None`: p = 1/2, f_c = ln 2/(2π T) ≈ 0.11/T.
    pub cutoff_hz: Option<f64>,
    /// T_mem: the memory of the forgetting factor λ = 1 − T/T_mem \[s\].
    pub memory_s: f64,
    /// p_0: start and reset covariance of each channel's RLS.
    pub initial_variance: f64,
    /// The change detector (a payload put on or taken off): on an alarm the channel's
    /// covariance is reset and θ re-converges as from a fresh start.
    pub detection: Option<ChangeDetection>,
    /// Seconds of a channel's warm-up (the estimate's first convergence) before it goes on
    /// in `form`, from the start or its last alarm; its change detector then learns for two
    /// more before it arms (`wheelid_solvers::recursive`, "Change detection") \[s\].
    pub warmup_s: f64,
    /// The estimator after the warm-up (module docs).
    pub form: OnlineForm,
    /// How the held command's effect splits between u_k and u_{k−1} ([`Split`]); `None`:
    /// free, unless a caller that knows the recording's stamping fills it in
    /// ([`OnlineSettings::for_timing`]; `wheelid run` does, from the robot's).
    pub split: Option<Split>,
}

impl OnlineSettings {
    /// These settings with the split fixed by the stamping `timing` ([`Split::of_timing`])
    /// where none is set.
    pub fn for_timing(self, timing: Option<wheelid_core::Timing>) -> Self {
        Self {
            split: Some(self.split.unwrap_or(Split::of_timing(timing))),
            ..self
        }
    }
}

/// The estimator a channel runs after its warm-up (module docs, "Instruments").
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum OnlineForm {
    /// Recursive least squares on the prefiltered difference equation throughout.
    LeastSquares,
    /// Recursive instrumental variables with an auxiliary model's outputs as instruments.
    InstrumentalVariables,
    /// The recursive prediction-error form of the output-error fit: eq. 2.19 simulated at θ̂
    /// against the measured outputs, unfiltered (module docs, "Output error"); with the split
    /// free, as [`OnlineForm::InstrumentalVariables`].
    OutputError,
}

impl Default for OnlineSettings {
    fn default() -> Self {
        Self {
            cutoff_hz: None,
            memory_s: 60.0,
            initial_variance: 1e4,
            detection: Some(ChangeDetection::default()),
            warmup_s: 10.0,
            form: OnlineForm::OutputError,
            split: None,
        }
    }
}

/// The filtered signals: u and y of each channel, n (ω², v ω), each channel's jitter
/// correction d (module `split`), and the auxiliary model's v̂, ω̂, ω̂², v̂ ω̂ (instruments).
const SIGNALS: usize = 12;

/// What one update did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OnlineUpdate {
    /// Whether the v and ω channels' change detectors raised an alarm at this sample.
    pub change: [bool; 2],
}

/// The online estimator of θ1…θ6 (module docs). Every update works on fixed-size arrays: no
/// allocation.
#[derive(Debug, Clone)]
pub struct OnlineTheta {
    /// The prefilter's pole p.
    pole: f64,
    /// Its two stages' states per signal (v_ref, ω_ref, v, ω, ω², v ω).
    state: [[f64; 2]; SIGNALS],
    /// The filtered signals of the last two samples (newest first), once there.
    last: [Option<[f64; SIGNALS]>; 2],
    /// v channel: (a, β0, β1, c) of (θ1, θ3, θ4); ω channel: of (θ2, θ5, θ6).
    rls: [ChannelRls; 2],
    /// The nominal period T \[s\] and 1/T.
    dt: f64,
    inv_dt: f64,
    /// The form after the warm-up.
    form: OnlineForm,
    /// The auxiliary model's (v̂, ω̂) at the last sample (the measured ones where a channel
    /// is still in its warm-up).
    sim: [f64; 2],
    /// The commands (v_ref, ω_ref) of the last two samples (newest first), once there.
    commands: [Option<[f64; 2]>; 2],
    /// Samples each channel has taken since the start or its last alarm.
    since_reset: [u64; 2],
    /// Samples of warm-up before `form`.
    warmup: u64,
    /// The last sample's stamp, once there \[s\], and the period that led to it in nominal
    /// periods (1 before).
    stamp: Option<f64>,
    rho: f64,
    /// The last sample as measured: (v, ω, ω², v ω).
    measured: [f64; 4],
    /// The split the stamping fixes (free where unknown).
    split: Split,
    /// The output-error form's simulated robot, while both channels run in it.
    flow: Option<Flow>,
}

impl OnlineTheta {
    /// An estimator for samples `dt_s` seconds apart, started with no prior knowledge (as
    /// eq. 4.2–4.7 need none).
    ///
    /// # Errors
    /// [`Error::InvalidSetting`] if `dt_s` is not positive and finite, the cut-off is not in
    /// (0, Nyquist), the memory is not positive, or the RLS settings are invalid
    /// ([`wheelid_solvers::recursive::Rls::new`]).
    pub fn new(settings: OnlineSettings, dt_s: f64) -> Result<Self> {
        let bad = |m: String| Err(Error::InvalidSetting(m));
        if !(dt_s > 0.0 && dt_s.is_finite()) {
            return bad(format!("sample period {dt_s} s is not positive"));
        }
        let pole = match settings.cutoff_hz {
            None => 0.5,
            Some(fc) if fc > 0.0 && fc < 0.5 / dt_s => {
                (-2.0 * std::f64::consts::PI * fc * dt_s).exp()
            }
            Some(fc) => {
                return bad(format!(
                    "cut-off {fc} Hz is not in (0, {}) Hz, the Nyquist band at {dt_s} s",
                    0.5 / dt_s
                ));
            }
        };
        if settings.memory_s.is_nan() || settings.memory_s <= dt_s {
            return bad(format!(
                "memory {} s is not longer than the period",
                settings.memory_s
            ));
        }
        let rls_settings = RlsSettings {
            forgetting: 1.0 - dt_s / settings.memory_s,
            initial_variance: settings.initial_variance,
            detection: settings.detection.map(|d| ChangeDetection {
                warmup: (settings.warmup_s / dt_s).ceil() as u64,
                ..d
            }),
        };
        Ok(Self {
            pole,
            state: [[0.0; 2]; SIGNALS],
            last: [None; 2],
            rls: [
                ChannelRls::new(settings.split.unwrap_or_default(), rls_settings)?,
                ChannelRls::new(settings.split.unwrap_or_default(), rls_settings)?,
            ],
            dt: dt_s,
            inv_dt: 1.0 / dt_s,
            // The output-error form simulates what the stamping reports: unknown, instruments.
            form: match (settings.form, settings.split.unwrap_or_default()) {
                (OnlineForm::OutputError, Split::Free) => OnlineForm::InstrumentalVariables,
                (form, _) => form,
            },
            sim: [0.0; 2],
            commands: [None; 2],
            since_reset: [0; 2],
            warmup: ((settings.warmup_s.max(0.0) / dt_s).ceil() as u64).max(1),
            stamp: None,
            rho: 1.0,
            measured: [0.0; 4],
            split: settings.split.unwrap_or_default(),
            flow: None,
        })
    }

    /// Takes the next sample, stamped `t` \[s\]: the commands `v_ref` \[m/s\], `w_ref`
    /// \[rad/s\] applied from it on, and the measured `v` \[m/s\], `w` \[rad/s\] it carries.
    /// Stamps that are not `dt` apart (host jitter) enter the sampled equation (module
    /// `split`, "Jitter"); a stamp not after the last one is read as `dt` after it. The first
    /// two samples only fill the filters. A non-finite sample is skipped.
    pub fn update(&mut self, t: f64, v_ref: f64, w_ref: f64, v: f64, w: f64) -> OnlineUpdate {
        let quiet = OnlineUpdate { change: [false; 2] };
        if ![t, v_ref, w_ref, v, w].iter().all(|x| x.is_finite()) {
            return quiet;
        }
        let rho = self.period_ratios(t);
        let raw = [v_ref, w_ref, v, w, w * w, v * w];
        let refined = [self.refined(0), self.refined(1)];
        let jittered = self.jittered(rho);
        let corrections = self.jitter_corrections(&jittered, [w * w, v * w]);
        let before = self.sim;
        self.sim = match (self.flow_step(refined, rho), self.form) {
            (Some(sim), _) => sim,
            (None, OnlineForm::InstrumentalVariables) => self.simulate([v, w], refined, &jittered),
            (None, _) => [v, w],
        };
        let [vh, wh] = self.sim;
        let p = self.pole;
        let mut now = [0.0; SIGNALS];
        let signals = raw
            .into_iter()
            .chain(corrections)
            .chain([vh, wh, wh * wh, vh * wh]);
        // The auxiliary model's signals are the instruments alone.
        let used = match self.form {
            OnlineForm::InstrumentalVariables => SIGNALS,
            _ => SIGNALS - 4,
        };
        for ((s, x), f) in self.state[..used].iter_mut().zip(signals).zip(&mut now) {
            s[0] = p * s[0] + (1.0 - p) * x;
            s[1] = p * s[1] + (1.0 - p) * s[0];
            *f = s[1];
        }
        // (u_k, u_{k−1}) of the step to this sample.
        let held = self.commands.map(|c| c.unwrap_or([0.0; 2]));
        self.commands = [Some([v_ref, w_ref]), self.commands[0]];
        (self.stamp, self.rho) = (Some(t), rho[0]);
        self.measured = [v, w, w * w, v * w];
        let [Some(q), Some(o)] = self.last else {
            self.last = [Some(now), self.last[0]];
            return quiet;
        };
        self.last = [Some(now), Some(q)];
        // [y_k, u_k, u_{k−1}, n̄_k] → y_{k+1} − d_k per channel; its instruments with the
        // auxiliary model's v̂_k (ω̂_k) and n̄_k.
        let change: [bool; 2] = std::array::from_fn(|i| {
            let row = [q[2 + i], q[i], o[i], 0.5 * (q[4 + i] + now[4 + i])];
            let target = now[2 + i] - now[6 + i];
            let step = match (refined[i], self.form) {
                (false, _) | (_, OnlineForm::LeastSquares) => self.rls[i].update(&row, target),
                (true, OnlineForm::InstrumentalVariables) => {
                    let zeta = [q[8 + i], q[i], o[i], 0.5 * (q[10 + i] + now[10 + i])];
                    self.rls[i].update_iv(&row, &zeta, target)
                }
                (true, OnlineForm::OutputError) => {
                    let [v1, w1] = self.sim;
                    let n = if i == 0 {
                        0.5 * (before[1] * before[1] + w1 * w1)
                    } else {
                        0.5 * (before[0] * before[1] + v1 * w1)
                    };
                    self.rls[i].advance_gradient([before[i], n], [held[0][i], held[1][i]]);
                    if self.flow.as_ref().is_some_and(Flow::settled) {
                        let error = [v, w][i] - self.sim[i];
                        self.rls[i].update_output_error(error, &row, target)
                    } else {
                        self.rls[i].update(&row, target)
                    }
                }
            };
            self.since_reset[i] = if step.change {
                0
            } else {
                self.since_reset[i] + 1
            };
            step.change
        });
        OnlineUpdate { change }
    }

    /// The output-error form's simulated outputs at this sample ([`Flow`]), where both channels
    /// run in that form, the stamping fixes the split and θ̂ maps; `None` (and the flow
    /// stopped) otherwise.
    fn flow_step(&mut self, refined: [bool; 2], rho: [f64; 2]) -> Option<[f64; 2]> {
        let runs = self.form == OnlineForm::OutputError
            && refined == [true, true]
            && self.split != Split::Free;
        let inv_dt = self.inv_dt;
        let rates = match (runs, self.commands[0]) {
            (true, Some(u)) => self.rls[0]
                .rates(inv_dt)
                .zip(self.rls[1].rates(inv_dt))
                .map(|r| (r, u)),
            _ => None,
        };
        let Some(((v, w), u)) = rates else {
            self.flow = None;
            return None;
        };
        if self.flow.is_none() {
            self.rls.iter_mut().for_each(ChannelRls::reset_gradient);
        }
        let (sim, dt) = (self.sim, self.dt);
        let flow = self
            .flow
            .get_or_insert_with(|| Flow::start(sim, [v, w], dt));
        Some(flow.advance([v, w], u, rho[0] * dt, self.split))
    }

    /// (T_k/T, T_{k−1}/T): the period from the last sample to the one stamped `t` and the one
    /// before it, in nominal periods (1 where a stamp is missing or not after the last).
    fn period_ratios(&self, t: f64) -> [f64; 2] {
        let rho = match self.stamp {
            Some(e) if t > e => (t - e) / self.dt,
            _ => 1.0,
        };
        [rho, self.rho]
    }

    /// The commands (u_k, u_{k−1}) of the step from the last sample to this one, once there
    /// (u_{k−1} = u_k at the second sample).
    fn held(&self) -> Option<[[f64; 2]; 2]> {
        let [Some(u0), u1] = self.commands else {
            return None;
        };
        Some([u0, u1.unwrap_or(u0)])
    }

    /// Each channel's step over the periods `rho` the samples spanned
    /// ([`ChannelRls::jittered`]), taken once a sample for both its uses; `None` where the
    /// periods are nominal (|ρ − 1| < 10⁻⁹), there are no commands yet, or â is not a share.
    fn jittered(&self, rho: [f64; 2]) -> [Option<Jittered>; 2] {
        match self.held() {
            Some([u0, u1]) if !rho.iter().all(|r| (r - 1.0).abs() < 1e-9) => {
                std::array::from_fn(|i| self.rls[i].jittered(rho, [u0[i], u1[i]]))
            }
            _ => [None; 2],
        }
    }

    /// Each channel's jitter correction d_k for the step from the last sample to this one, from
    /// its step over the periods spanned (`jittered`; zero where there is none) (`n_now`: this
    /// sample's measured ω², v ω).
    fn jitter_corrections(&self, jittered: &[Option<Jittered>; 2], n_now: [f64; 2]) -> [f64; 2] {
        let Some([u0, u1]) = self.held() else {
            return [0.0; 2];
        };
        std::array::from_fn(|i| {
            let Some(j) = &jittered[i] else {
                return 0.0;
            };
            let n = 0.5 * (self.measured[2 + i] + n_now[i]);
            self.rls[i].jitter_correction(j, self.measured[i], [u0[i], u1[i]], n)
        })
    }

    /// Whether channel `i` takes its instruments at this sample: after the warm-up from its
    /// start or last alarm, while its estimate maps to θ.
    fn refined(&self, i: usize) -> bool {
        self.form != OnlineForm::LeastSquares
            && self.since_reset[i] >= self.warmup
            && self.difference_equation(i).is_some()
    }

    /// The auxiliary model's (v̂, ω̂) at this sample (module docs, "Instruments"): one step of
    /// each instrumented channel's difference equation from the last sample (the coupling held
    /// at its value there: instruments need only be correlated with the regressors), over the
    /// periods the samples spanned where `jittered` holds that step ([`OnlineTheta::jittered`]);
    /// the measured value where a channel is not instrumented (so that its model starts from
    /// the robot).
    fn simulate(
        &self,
        measured: [f64; 2],
        refined: [bool; 2],
        jittered: &[Option<Jittered>; 2],
    ) -> [f64; 2] {
        let Some([r0, r1]) = self.held() else {
            return measured;
        };
        let [vh, wh] = self.sim;
        let held = [wh * wh, vh * wh];
        std::array::from_fn(|i| {
            if !refined[i] {
                return measured[i];
            }
            let (p, q) = self.rls[i].step(jittered[i].as_ref(), self.sim[i], [r0[i], r1[i]]);
            p + q * held[i]
        })
    }

    /// θ̂1…θ̂6 (the units of `wheelid_models::regressor::PARAMS`; NaN while a channel's
    /// difference equation does not map to θ: 0 < a < 1 and β0 + β1 > 0 not yet met).
    pub fn theta(&self) -> [f64; 6] {
        let (v, w) = (self.channel(0), self.channel(1));
        [v[0], w[0], v[1], v[2], w[1], w[2]]
    }

    /// Standard errors of θ̂1…θ̂6 (delta method from each channel's [`wheelid_solvers::recursive::Rls::covariance`], robust
    /// to coloured equation errors; NaN where θ̂ is).
    pub fn std_err(&self) -> [f64; 6] {
        let (v, w) = (self.channel_std_err(0), self.channel_std_err(1));
        [v[0], w[0], v[1], v[2], w[1], w[2]]
    }

    /// Channel `i`'s (a, β0 + β1, c), if they map to θ (0 < a < 1, β0 + β1 > 0), and the
    /// sign of its coupling term (+θ3 for v, −θ5 for ω).
    fn difference_equation(&self, i: usize) -> Option<(f64, f64, f64, f64)> {
        let [a, b0, b1, c] = self.rls[i].theta();
        let s = b0 + b1;
        let sign = if i == 0 { 1.0 } else { -1.0 };
        (a > 0.0 && a < 1.0 && s > 0.0).then_some((a, s, c, sign))
    }

    /// Channel `i`'s (lag, coupling, gain): (θ1, θ3, θ4) or (θ2, θ5, θ6).
    fn channel(&self, i: usize) -> [f64; 3] {
        let Some((a, s, c, sign)) = self.difference_equation(i) else {
            return [f64::NAN; 3];
        };
        let gain = (1.0 - a) / s;
        [-gain * self.dt / self.rls[i].ln_a(), sign * c / s, gain]
    }

    /// Standard errors of [`OnlineTheta::channel`] by the delta method.
    fn channel_std_err(&self, i: usize) -> [f64; 3] {
        let Some((a, s, c, sign)) = self.difference_equation(i) else {
            return [f64::NAN; 3];
        };
        let (t, ln) = (self.dt, self.rls[i].ln_a());
        let gain = (1.0 - a) / s;
        let coupling = sign * c / s;
        // Jacobians by (a, β0, β1, c); β0 and β1 enter through their sum alone.
        let d_gain = [-1.0 / s, -gain / s, -gain / s, 0.0];
        let d_lag = [
            -t * d_gain[0] / ln + gain * t / (a * ln * ln),
            -t * d_gain[1] / ln,
            -t * d_gain[2] / ln,
            0.0,
        ];
        let d_coupling = [0.0, -coupling / s, -coupling / s, sign / s];
        let cov = self.rls[i].covariance();
        let se = |g: &[f64; 4]| {
            let mut q = 0.0;
            for (j, gj) in g.iter().enumerate() {
                for (k, gk) in g.iter().enumerate() {
                    q += gj * cov[j][k] * gk;
                }
            }
            q.max(0.0).sqrt()
        };
        [se(&d_lag), se(&d_coupling), se(&d_gain)]
    }

    /// Whether both channels have run their warm-up since the start or their last alarm and
    /// map to θ: from then on the intervals of [`OnlineTheta::std_err`] mean what they say.
    pub fn settled(&self) -> bool {
        (0..2).all(|i| self.since_reset[i] >= self.warmup && self.difference_equation(i).is_some())
    }

    /// The largest relative half-width of the 95 % intervals of θ1, θ2, θ4, θ6,
    /// max 1.96 σ̂_i/|θ̂_i| \[-\]; infinite while any of them is undefined.
    pub fn relative_half_width(&self) -> f64 {
        let (th, se) = (self.theta(), self.std_err());
        [0, 1, 3, 5]
            .iter()
            .map(|&i| 1.96 * se[i] / th[i].abs())
            .map(|w| if w.is_finite() { w } else { f64::INFINITY })
            .fold(0.0, f64::max)
    }

    /// Alarms raised so far by the v and ω channels' detectors.
    pub fn changes(&self) -> [u64; 2] {
        [self.rls[0].changes(), self.rls[1].changes()]
    }

    /// The form after the warm-up: the settings' (module docs), but the instruments where the
    /// output-error form was asked for with the split free.
    pub fn form(&self) -> OnlineForm {
        self.form
    }

    /// The sample period \[s\].
    pub fn dt(&self) -> f64 {
        self.dt
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const THETA: [f64; 6] = [0.26, 0.25, 0.005, 1.0, 0.2, 1.0];

    /// θ̂ after 4000 noise-free samples `dt` apart of eq. 2.19 with [`THETA`] under held
    /// multisine commands (Euler on `sub` sub-steps a period), the estimator's split `split`,
    /// the velocities as instants or (`average`) as window averages over the period ending at
    /// the sample (convention (b): the command sent after reading it).
    fn estimate(dt: f64, sub: usize, split: Option<Split>, average: bool) -> [f64; 6] {
        let h = dt / sub as f64;
        let settings = OnlineSettings {
            detection: None,
            memory_s: 1e9,
            split,
            ..OnlineSettings::default()
        };
        let mut est = OnlineTheta::new(settings, dt).expect("settings");
        let (mut v, mut w) = (0.0f64, 0.0f64);
        let (mut v_avg, mut w_avg) = (0.0, 0.0);
        for k in 0..4000 {
            let t = k as f64 * dt;
            let u = [
                0.3 + 0.2 * (1.3 * t).sin() + 0.1 * (4.1 * t).sin(),
                0.5 * (0.9 * t).sin() + 0.3 * (3.3 * t).sin(),
            ];
            let (mv, mw) = if average { (v_avg, w_avg) } else { (v, w) };
            est.update(t, u[0], u[1], mv, mw);
            (v_avg, w_avg) = (0.0, 0.0);
            for _ in 0..sub {
                let dv = (THETA[2] * w * w - THETA[3] * v + u[0]) / THETA[0];
                let dw = (-THETA[4] * v * w - THETA[5] * w + u[1]) / THETA[1];
                let (v1, w1) = (v + h * dv, w + h * dw);
                v_avg += 0.5 * (v + v1) / sub as f64;
                w_avg += 0.5 * (w + w1) / sub as f64;
                (v, w) = (v1, w1);
            }
        }
        est.theta()
    }

    /// Noise-free samples of eq. 2.19 under held commands, with the velocities as instants
    /// and the split free (the default): all six θ back to 10⁻³.
    #[test]
    fn the_difference_equation_gives_theta_back() {
        let got = estimate(0.05, 500, None, false);
        for i in 0..6 {
            assert!(
                (got[i] - THETA[i]).abs() < 1e-3 * THETA[i].abs().max(1.0),
                "θ{} = {} vs {}",
                i + 1,
                got[i],
                THETA[i]
            );
        }
    }

    /// Noise-free window averages of eq. 2.19 at T = 0.1 s: θ1, θ2, θ4, θ6 back to 2·10⁻³
    /// with the split fixed to the window average, and with it free (where eq. 2.19 holds both
    /// forms are exact but for the coupling's trapezoidal mean); instants with the split fixed
    /// to instants likewise. Window averages read with the instants' split put θ1 more than
    /// 5 % off: the split is not a detail.
    #[test]
    fn a_fixed_split_gives_theta_back() {
        for (split, average) in [
            (Split::WindowAverage, true),
            (Split::Free, true),
            (Split::Instant, false),
        ] {
            let got = estimate(0.1, 1000, Some(split), average);
            for i in [0, 1, 3, 5] {
                assert!(
                    (got[i] - THETA[i]).abs() < 2e-3 * THETA[i].abs(),
                    "{split:?}: θ{} = {} vs {}",
                    i + 1,
                    got[i],
                    THETA[i]
                );
            }
        }
        let wrong = estimate(0.1, 1000, Some(Split::Instant), true);
        let off = (wrong[0] - THETA[0]).abs() / THETA[0];
        assert!(
            off > 0.05,
            "the instants' split on averages: θ1 only {off} off"
        );
    }

    #[test]
    fn bad_settings_are_errors() {
        let s = OnlineSettings::default();
        assert!(OnlineTheta::new(s, 0.0).is_err());
        let fast = OnlineSettings {
            cutoff_hz: Some(30.0),
            ..s
        };
        assert!(OnlineTheta::new(fast, 0.02).is_err());
        assert!(OnlineTheta::new(s, 0.02).is_ok());
        assert!(OnlineTheta::new(s, 0.02).expect("ok").theta()[0].is_nan());
    }
}
