//! Eq. 2.19 extended by candidate physics: the models the mismatch diagnosis fits when the
//! six-θ model and a recording disagree. Each [`Candidate`] carries the name and parameters of
//! the matching simulator effect (`wheelid_robots::effects`), and the extended model applies
//! them in the simulator's order, so a recording simulated with an effect is reproduced by the
//! model with that candidate at the effect's magnitude.
//!
//! With u the recorded command (held between samples), at time t:
//!
//! 1. `input_delay` (`delay_s`): u(t − delay_s); `output_delay` (`delay_s`, τ_o) adds to it,
//!    the outputs stamped t being the robot's at t − τ_o (a payload change's time and the
//!    drift's clock move by τ_o);
//! 2. `velocity_saturation` (`v_max`, `w_max`): the setpoint clipped to ±v_max, ±w_max;
//! 3. `acceleration_limit` (`v_accel_max`, `w_accel_max`): the setpoint slews towards that at
//!    most at the given rates (exact slew per integration sub-step);
//! 4. `wheel_asymmetry` (`ratio` ρ): wheel setpoints v ± dω/2 scaled by 2ρ/(1 + ρ) and
//!    2/(1 + ρ), d the track given to [`Extended::new`];
//!
//! then, with g = 1 + rate_per_s·(t − t_0) the drive gain of `gain_drift` (`rate_per_s`; 1
//! without it: the amplifier's gain scales the speed loop's whole effort),
//!
//! ```text
//! θ1 v̇ = g (u_v − v) − (θ4 − 1) v + θ3 ω² − v_coulomb tanh(v/ε_v) − θ4 k_v v |ω|
//! θ2 ω̇ = g (u_ω − ω) − (θ6 − 1) ω − θ5 v ω − w_coulomb tanh(ω/ε_ω) − θ6 k_w |v| ω
//! ```
//!
//! with `coulomb_friction` (`v_coulomb`, `w_coulomb`, ε = 2 mm/s, 0.01 rad/s), `slip` (`k_v`,
//! `k_w`), and `payload_change` (`time_s`, then θ1, θ2, θ3, θ5 after it). The simulation runs on
//! the recording's grid merged with the delayed command switches and the payload time
//! ([`crate::delay`]), so that every parameter moves the outputs continuously; outputs are
//! instants or window averages as the recording says. Parameters: θ1…θ6, then each candidate's
//! in the order given. Sensitivities: θ and the initial state analytic, the candidates' parameters
//! by forward differences ([`Extended::sensitivities_of`]).

use wheelid_core::{
    ChannelInfo, CommandHold, DynamicModel, Error, ParamInfo, Recording, Result, Sensitivities,
    Simulation, Terms, VelocitySampling,
};

use crate::delay::{holding_command, merged_grid};
use crate::dynamics::StepCommand;
pub use crate::effects::Candidate;
use crate::{dynamics, regressor};

mod differences;
mod found;
mod resume;
mod traction;
mod wheels;

pub use found::Found;
use resume::Tape;
pub use resume::Trace;

/// Shortest time constant θ1/θ4, θ2/θ6 the extended model accepts \[s\].
pub const MIN_TIME_CONSTANT: f64 = 1e-3;

/// Smoothing of the Coulomb friction's sign: 2 mm/s and 0.01 rad/s (as the simulator).
pub const FRICTION_EPS: [f64; 2] = [0.002, 0.01];

/// Eq. 2.19 with a set of candidates (`extended`).
#[derive(Debug, Clone, PartialEq)]
pub struct Extended {
    candidates: Vec<Candidate>,
    params: Vec<ParamInfo>,
    track: f64,
}

impl Extended {
    /// The six-θ model with `candidates` (each at most once); `track_m` is the wheel track d
    /// \[m\] that `wheel_asymmetry` needs.
    ///
    /// # Errors
    /// [`Error::InvalidSetting`] for a repeated candidate or a track that is not > 0.
    pub fn new(candidates: &[Candidate], track_m: f64) -> Result<Self> {
        for (i, c) in candidates.iter().enumerate() {
            if candidates[..i].contains(c) {
                return Err(Error::InvalidSetting(format!(
                    "candidate {} given twice",
                    c.name()
                )));
            }
        }
        if !(track_m.is_finite() && track_m > 0.0) {
            return Err(Error::InvalidSetting(format!(
                "track = {track_m} m must be > 0"
            )));
        }
        let mut params = regressor::PARAMS.to_vec();
        for c in candidates {
            params.extend_from_slice(c.params());
        }
        Ok(Self {
            candidates: candidates.to_vec(),
            params,
            track: track_m,
        })
    }

    /// The candidates, in parameter order.
    pub fn candidates(&self) -> &[Candidate] {
        &self.candidates
    }

    fn physics(&self, theta: &[f64]) -> Result<([f64; 6], Terms, Forces)> {
        if theta.len() != self.params.len() || theta.iter().any(|x| !x.is_finite()) {
            return Err(Error::InvalidSetting(format!(
                "θ of the extended model has {} finite values, got {theta:?}",
                self.params.len()
            )));
        }
        let th = dynamics::check_theta(&theta[..6])?;
        // A time constant below a millisecond is no robot's, and the integrator cannot follow
        // it: refuse it (a fitter's trial step then counts as failed).
        for (a, b) in [(th[0], th[3]), (th[1], th[5])] {
            if b != 0.0 && (a / b).abs() < MIN_TIME_CONSTANT {
                return Err(Error::InvalidSetting(format!(
                    "time constant {:.2e} s is below {MIN_TIME_CONSTANT} s",
                    (a / b).abs()
                )));
            }
        }
        let mut ph = Terms::default();
        let mut forces = Forces::new();
        let mut i = 6;
        for c in &self.candidates {
            let n = c.params().len();
            let p = &theta[i..i + n];
            c.effect().apply(p, &mut ph)?;
            if c.effect().has_force() {
                forces.push((c.effect(), p.to_vec()));
            }
            i += n;
        }
        Ok((th, ph, forces))
    }
}

/// [`InputDelay::command_at`] for non-decreasing times, walking the samples instead of
/// searching them.
struct CommandCursor<'a> {
    rec: &'a Recording,
    hold: (f64, f64),
    zoh: bool,
    /// Last j with t_j ≤ the previous query.
    j: usize,
}

impl<'a> CommandCursor<'a> {
    fn new(rec: &'a Recording, hold: (f64, f64)) -> Self {
        Self {
            rec,
            hold,
            zoh: rec.command_hold() == CommandHold::Zoh,
            j: 0,
        }
    }
    fn at(&mut self, tau: f64) -> (f64, f64) {
        let t = &self.rec.t;
        let n = t.len();
        if tau < t[0] {
            return self.hold;
        }
        if tau >= t[n - 1] {
            return (self.rec.v_ref[n - 1], self.rec.w_ref[n - 1]);
        }
        if t[self.j] > tau {
            self.j = t.partition_point(|&x| x <= tau) - 1;
        }
        while t[self.j + 1] <= tau {
            self.j += 1;
        }
        let j = self.j;
        let (v, w) = (&self.rec.v_ref, &self.rec.w_ref);
        if self.zoh {
            (v[j], w[j])
        } else {
            let a = (tau - t[j]) / (t[j + 1] - t[j]);
            (v[j] + a * (v[j + 1] - v[j]), w[j] + a * (w[j + 1] - w[j]))
        }
    }
}

impl DynamicModel for Extended {
    fn name(&self) -> &str {
        "extended"
    }
    fn params(&self) -> &[ParamInfo] {
        &self.params
    }
    fn channels(&self) -> &[ChannelInfo] {
        &regressor::CHANNELS
    }
    fn simulate(&self, theta: &[f64], rec: &Recording, initial: &[f64]) -> Result<Simulation> {
        let (th0, ph, forces) = self.physics(theta)?;
        let y = match &ph.traction {
            Some(tr) => self.integrate_traction(&th0, &ph, &forces, rec, initial, tr)?,
            None => self.integrate::<2, 0>(&th0, &ph, &forces, rec, initial)?,
        };
        Ok(y.to_vec())
    }

    fn simulate_with_sensitivities(
        &self,
        theta: &[f64],
        rec: &Recording,
        initial: &[f64],
    ) -> Result<Option<(Simulation, Sensitivities)>> {
        let all: Vec<usize> = (0..self.params.len()).collect();
        self.sensitivities_of(theta, rec, initial, &all).map(Some)
    }
}

/// The effects that add a [`wheelid_core::Force`], with their parameters.
type Forces = Vec<(&'static dyn wheelid_core::Effect, Vec<f64>)>;

/// The right-hand side of the module doc's dynamics (friction and slip as fitted), with the
/// sensitivity equations when `M` = [`NS`].
struct Field {
    /// Effects that add a force, with their parameters.
    forces: Forces,
    /// Wheel track \[m\] given to the forces.
    track: f64,
    coulomb: [f64; 2],
    /// Whether dry friction is present (its tanh dominates the cost of a step).
    dry: bool,
    slip: [f64; 2],
    /// Per-wheel efforts ([`wheelid_core::WheelTerms`], κ \[m\] in place of the mix).
    wheels: Option<wheelid_core::WheelTerms>,
    /// The right wheel's row scale ([`wheelid_core::Terms::right_row`]).
    right_row: Option<f64>,
}

impl Field {
    /// The field of the effects `ph` with the force effects `forces`, on a track \[m\].
    fn new(forces: &Forces, track: f64, ph: &Terms) -> Self {
        Self {
            forces: forces.clone(),
            track,
            coulomb: ph.coulomb,
            // Dry friction only when present: tanh dominates the cost of a step.
            dry: ph.coulomb != [0.0, 0.0],
            slip: ph.slip,
            wheels: ph.wheels.map(|w| wheelid_core::WheelTerms {
                mix: w.mix * 0.5 * track,
                ..w
            }),
            right_row: ph.right_row,
        }
    }

    /// `f` (and the rows of `a`) with the right wheel's row scaled by `s`: in the wheels'
    /// accelerations ṁ_R,L = f_v ± h f_ω (h = d/2), ṁ_R × s, back to (v̇, ω̇).
    #[inline(always)]
    fn scale_right_row(&self, s: f64, f: &mut [f64; 2], a: &mut [[f64; 2]; 2]) {
        let h = 0.5 * self.track;
        let k = s - 1.0;
        // (v̇, ω̇) += k ṁ_R (1/2, 1/d) = k ṁ_R (1/2, 1/(2h)).
        let right = f[0] + h * f[1];
        f[0] += 0.5 * k * right;
        f[1] += 0.5 * k * right / h;
        let [row_v, row_w] = a;
        let r = [0, 1].map(|col| row_v[col] + h * row_w[col]);
        for (col, r) in r.into_iter().enumerate() {
            a[0][col] += 0.5 * k * r;
            a[1][col] += 0.5 * k * r / h;
        }
    }

    /// (v̇, ω̇) at (v, ω) under command `c` (θ with the reciprocals `inv` of θ1, θ2), the clamp's
    /// ∂(clamped − unclamped effort)/∂u and, with `jac`, the Jacobian ∂(v̇, ω̇)/∂(v, ω) (zeros
    /// without `jac`).
    #[inline(always)]
    fn local<const M: usize>(
        &self,
        th: &[f64; 6],
        inv: &[f64; 2],
        (v, w): (f64, f64),
        c: &Cmd<M>,
        jac: bool,
    ) -> Local {
        let [kv, kw] = self.slip;
        let u = c.u;
        // The loop's efforts E = u − g (v, ω) and every other force O (module docs).
        let e = [u[0] - c.g * v, u[1] - c.g * w];
        // Their derivatives only for the sensitivity pass (`jac`): the plain simulation uses
        // none of them.
        let mut others = wheels::Others {
            o: [
                th[2] * w * w - (th[3] - 1.0) * v - th[3] * kv * v * w.abs(),
                -th[4] * v * w - (th[5] - 1.0) * w - th[5] * kw * v.abs() * w,
            ],
            jac: [[0.0; 2]; 2],
            theta: [[0.0; 2]; 4],
        };
        if jac {
            let sign = |x: f64| if x == 0.0 { 0.0 } else { x.signum() };
            others.jac = [
                [
                    -(th[3] - 1.0) - th[3] * kv * w.abs(),
                    2.0 * th[2] * w - th[3] * kv * v * sign(w),
                ],
                [
                    -th[4] * w - th[5] * kw * sign(v) * w,
                    -th[4] * v - (th[5] - 1.0) - th[5] * kw * v.abs(),
                ],
            ];
            // ∂O/∂θ3…θ6.
            others.theta = [
                [w * w, 0.0],
                [-v * (1.0 + kv * w.abs()), 0.0],
                [0.0, -v * w],
                [0.0, -w * (1.0 + kw * v.abs())],
            ];
        }
        if self.dry {
            let (tv, tw) = (
                dynamics::tanh(v / FRICTION_EPS[0]),
                dynamics::tanh(w / FRICTION_EPS[1]),
            );
            others.o[0] -= self.coulomb[0] * tv;
            others.o[1] -= self.coulomb[1] * tw;
            if jac {
                others.jac[0][0] -= self.coulomb[0] * (1.0 - tv * tv) / FRICTION_EPS[0];
                others.jac[1][1] -= self.coulomb[1] * (1.0 - tw * tw) / FRICTION_EPS[1];
            }
        }
        for (effect, p) in &self.forces {
            let force = effect.force(p, v, w, self.track);
            for r in 0..2 {
                others.o[r] += force.f[r];
                others.jac[r][0] += force.jacobian[r][0];
                others.jac[r][1] += force.jacobian[r][1];
            }
        }
        let wheels = self
            .wheels
            .map(|wt| wheels::wheel_force(&wt, c.g, e, &others, [th[0], th[1]]));
        let (d, dx, ju, dth) = wheels.map_or(([0.0; 2], [[0.0; 2]; 2], [[0.0; 2]; 2], None), |w| {
            (w.d, w.dx, w.du, w.dth)
        });
        let mut a = [[0.0; 2]; 2];
        if jac {
            for r in 0..2 {
                for k in 0..2 {
                    let own = if r == k { -c.g } else { 0.0 };
                    a[r][k] = (own + others.jac[r][k] + dx[r][k]) * inv[r];
                }
            }
        }
        let mut f = [0, 1].map(|r| (e[r] + others.o[r] + d[r]) * inv[r]);
        if let Some(scale) = self.right_row {
            self.scale_right_row(scale, &mut f, &mut a);
        }
        Local { f, a, ju, dth }
    }

    /// ż for the state z = (v, ω, ∂v/∂p, ∂ω/∂p) under command `c`: θ with the reciprocals
    /// `inv` of θ1, θ2; `changed` after a payload change, when θ1, θ2, θ3, θ5 are no longer
    /// in force (their columns integrate without a source). Columns 0…7 are θ1…θ6, v0, ω0.
    #[inline(always)]
    fn rhs<const N: usize, const M: usize>(
        &self,
        th: &[f64; 6],
        inv: &[f64; 2],
        changed: bool,
        z: &[f64; N],
        c: &Cmd<M>,
    ) -> [f64; N] {
        let [kv, kw] = self.slip;
        let (v, w) = (z[0], z[1]);
        let Local { f, a, ju, dth } = self.local(th, inv, (v, w), c, M == NS);
        let mut out = [0.0; N];
        out[0] = f[0];
        out[1] = f[1];
        if M == NS {
            for k in 0..M {
                let (sv, sw) = (z[2 + k], z[2 + M + k]);
                out[2 + k] = a[0][0] * sv + a[0][1] * sw;
                out[2 + M + k] = a[1][0] * sv + a[1][1] * sw;
            }
            if c.live {
                for k in 0..M {
                    let (d0, d1) = (c.du[0][k], c.du[1][k]);
                    out[2 + k] += (d0 + ju[0][0] * d0 + ju[0][1] * d1) * inv[0];
                    out[2 + M + k] += (d1 + ju[1][0] * d0 + ju[1][1] * d1) * inv[1];
                }
            }
            // ∂f/∂θ: the sources of θ1…θ6's columns (v0, ω0 have none).
            let held = if changed { 0.0 } else { 1.0 };
            out[2] -= held * out[0] * inv[0];
            out[2 + M + 1] -= held * out[1] * inv[1];
            out[2 + 2] += held * w * w * inv[0];
            out[2 + 3] -= v * (1.0 + kv * w.abs()) * inv[0];
            out[2 + M + 4] -= held * v * w * inv[1];
            out[2 + M + 5] -= w * (1.0 + kw * v.abs()) * inv[1];
            if let Some(dth) = dth {
                for k in 0..6 {
                    // θ4, θ6 stay in force after a payload change.
                    let h = if k == 3 || k == 5 { 1.0 } else { held };
                    out[2 + k] += h * dth[0][k] * inv[0];
                    out[2 + M + k] += h * dth[1][k] * inv[1];
                }
            }
        }
        out
    }
}

/// The field at one state ([`Field::local`]): (v̇, ω̇) [m/s², rad/s²], its Jacobian
/// ∂(v̇, ω̇)/∂(v, ω) (rows v̇, ω̇) and the clamp's ∂(clamped − unclamped effort)/∂u.
struct Local {
    f: [f64; 2],
    a: [[f64; 2]; 2],
    ju: [[f64; 2]; 2],
    /// ∂(the wheels' correction)/∂θ1…θ6 (rows v̇, ω̇ before θ1, θ2 divide), where a wheel is
    /// clamped with a derivative term ([`wheels`]).
    dth: Option<[[f64; 6]; 2]>,
}

/// Sensitivity columns integrated analytically: θ1…θ6, v0, ω0.
const NS: usize = 8;
/// The augmented state of the sensitivity pass: v, ω, ∂v/∂p, ∂ω/∂p.
const NZ: usize = 2 + 2 * NS;

/// A command (v, ω setpoints after the pipeline) and its sensitivities to (θ1…θ6, v0, ω0):
/// `M` = 0 in a plain simulation, [`NS`] in the sensitivity pass.
/// `live` is false while `du` is zero (almost always: the command depends on (θ, x0) only before
/// the first delayed command and while a rate limit slews from the holding command), so that
/// the pass skips it. `g` is the drive gain of `gain_drift` (1 without it); `u` already
/// carries it (g × the setpoint).
#[derive(Clone, Copy)]
struct Cmd<const M: usize> {
    u: [f64; 2],
    du: [[f64; M]; 2],
    live: bool,
    g: f64,
}

impl<const M: usize> Cmd<M> {
    fn at(u: [f64; 2], du: [[f64; M]; 2], live: bool) -> Self {
        Self {
            u,
            du,
            live,
            g: 1.0,
        }
    }
    /// `self` + f (`other` − `self`).
    fn lerp(&self, other: &Self, f: f64) -> Self {
        let mut out = *self;
        out.u = [0, 1].map(|k| self.u[k] + f * (other.u[k] - self.u[k]));
        out.g = self.g + f * (other.g - self.g);
        if self.live || other.live {
            out.du = [0, 1].map(|k| {
                std::array::from_fn(|j| self.du[k][j] + f * (other.du[k][j] - self.du[k][j]))
            });
            out.live = true;
        }
        out
    }
}

impl<const M: usize> StepCommand for Cmd<M> {
    #[inline(always)]
    fn midpoint(&self, other: &Self) -> Self {
        self.lerp(other, 0.5)
    }
}

impl Extended {
    /// The simulation with its output sensitivities to the parameters `columns` (indices into
    /// θ, in that order) and to the initial state: θ1…θ6 and (v0, ω0) by the forward
    /// sensitivity equations integrated alongside the state (below), the candidates'
    /// parameters by forward differences of [`DynamicModel::simulate`] (step 1e-5 (|β| +
    /// 10⁻³ max|θ1…6|)), run on the rayon pool while the state integrates.
    ///
    /// With z = (v, ω), p = (θ1…θ6, v0, ω0), f the right-hand side of the module doc and u
    /// the command after the pipeline:
    ///
    /// ```text
    /// Ṡ = ∂f/∂z S + ∂f/∂θ + ∂f/∂u ∂u/∂p,    S(t0) = [0 | I₂]
    /// ```
    ///
    /// where u depends on p only through the command that holds the initial state (before the
    /// first delayed command, and where the rate limit starts), and the clip and the slew pass
    /// its sensitivity on where they do not bind. After a payload change θ1, θ2, θ3, θ5 are no
    /// longer in force and their columns integrate without a source.
    ///
    /// # Errors
    /// As [`DynamicModel::simulate`], or [`Error::InvalidSetting`] for a column out of range.
    pub fn sensitivities_of(
        &self,
        theta: &[f64],
        rec: &Recording,
        initial: &[f64],
        columns: &[usize],
    ) -> Result<(Simulation, Sensitivities)> {
        let (th0, ph, forces) = self.physics(theta)?;
        if let Some(&j) = columns.iter().find(|&&j| j >= self.params.len()) {
            return Err(Error::InvalidSetting(format!(
                "sensitivity column {j} of {} parameters",
                self.params.len()
            )));
        }
        // Stages without sensitivity equations: the traction's, the right wheel's row scale
        // (its θ sources are not transformed).
        if ph.traction.is_some() || ph.right_row.is_some() {
            return self.differenced(theta, rec, initial, columns);
        }
        let scale = th0.iter().fold(0.0f64, |a, x| a.max(x.abs()));
        let step = |j: usize| 1e-5 * (theta[j].abs() + 1e-3 * scale);
        // The differenced columns on the pool's threads while the state integrates (no thread
        // of its own per column: an excerpt's windows are short and already shared out); a
        // simulation that panics (inside a model) is an error.
        use rayon::prelude::*;
        let (z, fd): (_, Vec<Result<[Vec<f64>; 2]>>) = rayon::join(
            || self.integrate::<NZ, NS>(&th0, &ph, &forces, rec, initial),
            || {
                columns
                    .par_iter()
                    .filter(|&&j| j >= 6)
                    .map(|&j| {
                        guarded(|| {
                            let mut th = theta.to_vec();
                            th[j] += step(j);
                            let (t, p, f) = self.physics(&th)?;
                            self.integrate::<2, 0>(&t, &p, &f, rec, initial)
                        })
                    })
                    .collect()
            },
        );
        let za = z?;
        // Column j of (θ1…θ6, v0, ω0), channel c.
        let col = |c: usize, j: usize| &za[2 + c * NS + j];
        let z = &za;
        let n = rec.len();
        let mut fd = fd.into_iter();
        let mut sens_theta = [
            nalgebra::DMatrix::zeros(n, columns.len()),
            nalgebra::DMatrix::zeros(n, columns.len()),
        ];
        for (a, &j) in columns.iter().enumerate() {
            if j < 6 {
                for (c, m) in sens_theta.iter_mut().enumerate() {
                    for (k, x) in col(c, j).iter().enumerate() {
                        m[(k, a)] = *x;
                    }
                }
            } else {
                let up = fd
                    .next()
                    .ok_or_else(|| Error::InvalidSetting("missing difference".into()))??;
                let h = step(j);
                for c in 0..2 {
                    for k in 0..n {
                        sens_theta[c][(k, a)] = (up[c][k] - z[c][k]) / h;
                    }
                }
            }
        }
        let sens_initial =
            [0, 1].map(|c| nalgebra::DMatrix::from_fn(n, 2, |k, i| col(c, 6 + i)[k]));
        let [tv, tw] = sens_theta;
        let [iv, iw] = sens_initial;
        let y: Simulation = za.into_iter().take(2).collect();
        Ok((
            y,
            Sensitivities {
                theta: vec![tv, tw],
                initial: vec![iv, iw],
            },
        ))
    }

    /// The simulation of the module doc on the recording's samples: with `N` = 2, `M` = 0 the
    /// outputs (v̂, ω̂); with `N` = [`NZ`], `M` = [`NS`] also their sensitivities to the
    /// parameters (θ1…θ6, v0, ω0) (`M` = [`NS`]; channels 2 + c·M + j: ∂ŷ_c/∂p_j).
    fn integrate<const N: usize, const M: usize>(
        &self,
        th0: &[f64; 6],
        ph: &Terms,
        forces: &Forces,
        rec: &Recording,
        initial: &[f64],
    ) -> Result<[Vec<f64>; N]> {
        let (y, grid, index, avg) =
            self.integrate_taped::<N, M>(th0, ph, forces, rec, initial, &mut Tape::Off)?;
        Ok(to_samples(&y, &grid, &index, avg))
    }

    /// [`Self::integrate`] before [`to_samples`]: the values at every instant of the merged
    /// grid, the grid, the samples' places in it and whether they are window averages; with
    /// `tape` recording the state at every instant, or resuming from a recorded one
    /// ([`resume`]).
    #[allow(clippy::type_complexity)]
    fn integrate_taped<const N: usize, const M: usize>(
        &self,
        th0: &[f64; 6],
        ph: &Terms,
        forces: &Forces,
        rec: &Recording,
        initial: &[f64],
        tape: &mut Tape<'_, N, M>,
    ) -> Result<([Vec<f64>; N], Vec<f64>, Vec<usize>, bool)> {
        let sens = M > 0;
        let run = Run::new(self.track, th0, ph, rec, initial)?;
        let (v0, w0, hold, pipe, grid) = (run.v0, run.w0, run.hold, &run.pipe, &run.grid);
        let t0 = pipe.t0;
        // The command that holds the initial state, and its sensitivity to (θ, x0).
        let dhold = hold_sensitivity::<M>(th0, v0, w0);
        let mut cursor = CommandCursor::new(rec, hold);
        // The recorded command at τ (the holding one before the record).
        let mut command = |tau: f64| {
            let c = cursor.at(tau);
            if sens && tau < t0 {
                Cmd::at([c.0, c.1], dhold, true)
            } else {
                Cmd::at([c.0, c.1], [[0.0; M]; 2], false)
            }
        };
        // θ with the reciprocals of θ1, θ2 and its integration sub-step, before and after a
        // payload change: a step multiplies instead of dividing.
        let prepare = |th: [f64; 6], after: bool| (th, [1.0 / th[0], 1.0 / th[1]], after);
        let (before, after) = (prepare(*th0, false), run.th_after.map(|a| prepare(a, true)));
        let field = Field::new(forces, self.track, ph);
        // The rate-limited setpoint starts where it holds the initial state (a robot at rest
        // holds zero), as the simulator's.
        let mut setpoint = if ph.accel.is_some() {
            Cmd::at([hold.0, hold.1], dhold, sens)
        } else {
            pipe.target(command(t0 - ph.dead_time()))
        };
        let fixed_setpoint = run.zoh && ph.accel.is_none() && ph.drift == 0.0;
        let m = grid.len();
        // (v0, ω0); the θ columns start at 0, ∂(v, ω)/∂(v0, ω0) at I (columns 6, 7 where this
        // pass holds them).
        let mut z = [0.0; N];
        (z[0], z[1]) = (v0, w0);
        if 6 < M {
            z[2 + 6] = 1.0;
        }
        if 7 < M {
            z[2 + M + 7] = 1.0;
        }
        let mut y: [Vec<f64>; N] = std::array::from_fn(|c| {
            let mut v = Vec::with_capacity(m);
            v.push(z[c]);
            v
        });
        let first = tape.start(grid, &mut z, &mut setpoint, &mut y);
        for i in first..m {
            let (ta, tb) = (grid[i - 1], grid[i]);
            let span = tb - ta;
            let (th, inv, changed) = run.in_force(ta, tb, before, after);
            let (ca, cb) = run.commands(ta, tb, &mut command);
            let rhs_at = |x: &[f64; N], c: Cmd<M>| field.rhs(&th, &inv, changed, x, &c);
            let plan = dynamics::plan(&th, span);
            let q = if fixed_setpoint {
                // Held command, no rate limit, no drift: one setpoint for the whole interval.
                setpoint = pipe.target(ca);
                let u = pipe.shaped(&setpoint, ta);
                step_interval(rhs_at, &plan, &mut z, |_| (u, u))
            } else {
                step_interval(rhs_at, &plan, &mut z, |sub| {
                    let dynamics::Substep { f0, f1, h, t0, t1 } = sub;
                    pipe.substep(&mut setpoint, (ca, cb), (f0, f1), h, (ta + t0, ta + t1))
                })
            };
            for (c, yc) in y.iter_mut().enumerate() {
                yc.push(if run.avg { q[c] / span } else { z[c] });
            }
            if tape.after(grid, i, &z, &setpoint, &mut y) {
                break;
            }
        }
        let Run {
            grid, index, avg, ..
        } = run;
        Ok((y, grid, index, avg))
    }
}

/// `run`'s result, or an error where it panics (inside a model): a simulation run as a task
/// of the rayon pool fails alone instead of unwinding through the pool.
fn guarded<T>(run: impl FnOnce() -> Result<T>) -> Result<T> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(run))
        .unwrap_or_else(|_| Err(Error::InvalidSetting("a simulation panicked".into())))
}

/// Integrates `z` over one interval of the grid by `plan`'s sub-steps — RK4, or ETDRK4 on the
/// Jacobian's diagonal when θ is stiff for it — under the commands `commands(sub-step)` gives
/// at each sub-step's start and end; returns ∫z over the interval.
fn step_interval<const N: usize, const M: usize>(
    rhs_at: impl Fn(&[f64; N], Cmd<M>) -> [f64; N] + Copy,
    plan: &dynamics::Plan,
    z: &mut [f64; N],
    mut commands: impl FnMut(dynamics::Substep) -> (Cmd<M>, Cmd<M>),
) -> [f64; N] {
    let mut q = [0.0; N];
    for sub in plan.substeps() {
        let (u0, u1) = commands(sub);
        if plan.exponential() {
            let lin = dynamics::diagonal_jacobian(rhs_at, z, u0);
            dynamics::etdrk4_step(rhs_at, lin, z, &mut q, u0, u1, sub.h);
        } else {
            dynamics::rk4_step(rhs_at, z, &mut q, u0, u1, sub.h);
        }
    }
    q
}

/// The sensitivity to (θ, x0) of the command that holds the initial state (v0, ω0),
/// (θ4 v0 − θ3 ω0², θ5 v0 ω0 + θ6 ω0), in a pass's `M` columns (parameter j in column j < M).
fn hold_sensitivity<const M: usize>(th0: &[f64; 6], v0: f64, w0: f64) -> [[f64; M]; 2] {
    let [_, _, t3, t4, t5, t6] = *th0;
    let mut dhold = [[0.0; M]; 2];
    for (j, dv, dw) in [
        (2, -w0 * w0, 0.0),
        (3, v0, 0.0),
        (4, 0.0, v0 * w0),
        (5, 0.0, w0),
        (6, t4, t5 * w0),
        (7, -2.0 * t3 * w0, t5 * v0 + t6),
    ] {
        if j < M {
            dhold[0][j] = dv;
            dhold[1][j] = dw;
        }
    }
    dhold
}

/// What every integration of the module doc shares ([`Extended::integrate`] and the traction
/// stage's): the initial state (v0 [m/s], ω0 [rad/s]), the recording's grid merged with the
/// delayed command instants and a payload change (`index`: each sample's grid point), θ after
/// the change, the recording's conventions, the holding command and the setpoint pipeline.
struct Run<'a> {
    v0: f64,
    w0: f64,
    grid: Vec<f64>,
    index: Vec<usize>,
    th_after: Option<[f64; 6]>,
    /// Commands held over each sample interval (else interpolated).
    zoh: bool,
    /// Velocities are window averages (else instants).
    avg: bool,
    /// The command that holds the initial state.
    hold: (f64, f64),
    pipe: Setpoints<'a>,
}

impl<'a> Run<'a> {
    /// The run of θ = `th0` under the effects `ph` on `rec` from `initial` = [v0, ω0].
    ///
    /// # Errors
    /// An initial state of another length; a bad grid (`crate::delay::merged_grid`).
    fn new(
        track: f64,
        th0: &[f64; 6],
        ph: &'a Terms,
        rec: &Recording,
        initial: &[f64],
    ) -> Result<Self> {
        let &[v0, w0] = initial else {
            return Err(Error::InvalidSetting(format!(
                "initial state must be [v, ω], got {} values",
                initial.len()
            )));
        };
        // A dead time of the measurements moves the payload change's time and the drift's
        // clock with it (`Terms::output_delay`).
        let extra: Vec<f64> = ph
            .payload
            .map(|(t, _)| t + ph.output_delay)
            .into_iter()
            .collect();
        let (grid, index) = merged_grid(rec, ph.dead_time(), &extra)?;
        Ok(Self {
            v0,
            w0,
            grid,
            index,
            th_after: ph
                .payload
                .map(|(_, a)| [a[0], a[1], a[2], th0[3], a[3], th0[5]]),
            zoh: rec.command_hold() == CommandHold::Zoh,
            avg: rec.velocity_sampling() == VelocitySampling::WindowAverage,
            hold: holding_command(th0, initial),
            pipe: Setpoints {
                ph,
                track,
                t0: rec.t[0],
                origin: rec.drive_start() + ph.output_delay,
            },
        })
    }

    /// What is in force over the grid interval (`ta`, `tb`): `after` once a payload change has
    /// happened by its middle, else `before`.
    fn in_force<T: Copy>(&self, ta: f64, tb: f64, before: T, after: Option<T>) -> T {
        match (self.pipe.ph.payload, after) {
            (Some((ts, _)), Some(a)) if 0.5 * (ta + tb) >= ts + self.pipe.ph.output_delay => a,
            _ => before,
        }
    }

    /// The delayed recorded commands at the interval's start and end (`command`: the command
    /// at an instant [s]); one, at the middle, when commands are held.
    fn commands<C: Copy>(&self, ta: f64, tb: f64, command: &mut impl FnMut(f64) -> C) -> (C, C) {
        let delay = self.pipe.ph.dead_time();
        let ca = command(if self.zoh { 0.5 * (ta + tb) } else { ta } - delay);
        let cb = if self.zoh { ca } else { command(tb - delay) };
        (ca, cb)
    }
}

/// The setpoint pipeline after the delay: saturation → rate limit (a state) → asymmetry →
/// drive gain, each carrying the setpoint's sensitivities in `M` columns.
struct Setpoints<'a> {
    ph: &'a Terms,
    /// Wheel track \[m\].
    track: f64,
    /// The recording's first instant \[s\].
    t0: f64,
    /// The drift's origin: the drive's first instant \[s\] ([`Recording::drive_start`]).
    origin: f64,
}

impl Setpoints<'_> {
    /// Saturation: a clipped component holds the limit and loses its sensitivity.
    fn target<const M: usize>(&self, c: Cmd<M>) -> Cmd<M> {
        let Some(lim) = self.ph.sat else {
            return c;
        };
        let mut out = c;
        for (k, &l) in lim.iter().enumerate() {
            if c.u[k].abs() > l {
                out.u[k] = c.u[k].clamp(-l, l);
                out.du[k] = [0.0; M];
            }
        }
        out
    }

    /// The rate limit: from `s0` toward `tgt` by at most the limit × `h`; a slewing component
    /// keeps its own sensitivity.
    fn slew<const M: usize>(&self, s0: Cmd<M>, tgt: Cmd<M>, h: f64) -> Cmd<M> {
        let Some(a) = self.ph.accel else {
            return tgt;
        };
        let mut s1 = tgt;
        for (k, &rate) in a.iter().enumerate() {
            let step = rate * h;
            s1.u[k] = s0.u[k] + (tgt.u[k] - s0.u[k]).clamp(-step, step);
            if (tgt.u[k] - s0.u[k]).abs() > step {
                s1.du[k] = s0.du[k];
                s1.live |= s0.live;
            }
        }
        s1
    }

    /// Asymmetry and drive gain at `t` [s]: linear in the setpoint, so the same map takes its
    /// sensitivities.
    fn shape(&self, s: [f64; 2], t: f64) -> [f64; 2] {
        let (ph, d) = (self.ph, self.track);
        let [mut uv, mut uw] = s;
        if let Some(rho) = ph.ratio {
            let (gr, gl) = (2.0 * rho / (1.0 + rho), 2.0 / (1.0 + rho));
            let (vr, vl) = (gr * (uv + d * uw / 2.0), gl * (uv - d * uw / 2.0));
            uv = (vr + vl) / 2.0;
            uw = (vr - vl) / d;
        }
        let g = 1.0 + ph.drift * (t - self.origin);
        [uv * g, uw * g]
    }

    /// The commands at a sub-step's start and end, at fractions `f0`, `f1` of the way from the
    /// interval's delayed commands `ca` to `cb` and at the instants `t` [s], over `h` [s]:
    /// the target, the rate limit from the `setpoint` it holds (moved to the end's), then the
    /// shaping (without a rate limit the start is the target itself).
    fn substep<const M: usize>(
        &self,
        setpoint: &mut Cmd<M>,
        (ca, cb): (Cmd<M>, Cmd<M>),
        (f0, f1): (f64, f64),
        h: f64,
        t: (f64, f64),
    ) -> (Cmd<M>, Cmd<M>) {
        let s0 = *setpoint;
        let s1 = self.slew(s0, self.target(ca.lerp(&cb, f1)), h);
        let s_start = if self.ph.accel.is_some() {
            s0
        } else {
            self.target(ca.lerp(&cb, f0))
        };
        *setpoint = s1;
        (self.shaped(&s_start, t.0), self.shaped(&s1, t.1))
    }

    /// [`Setpoints::shape`] of a command and of its live sensitivities, with the drive gain.
    fn shaped<const M: usize>(&self, c: &Cmd<M>, t: f64) -> Cmd<M> {
        let mut out = *c;
        out.u = self.shape(c.u, t);
        out.g = 1.0 + self.ph.drift * (t - self.origin);
        if c.live {
            for j in 0..M {
                let col = self.shape([c.du[0][j], c.du[1][j]], t);
                out.du[0][j] = col[0];
                out.du[1][j] = col[1];
            }
        }
        out
    }
}

/// The fine grid's outputs back on the recording's samples (`index`: each sample's grid
/// point): instants, or length-weighted window averages.
fn to_samples<const N: usize>(
    y: &[Vec<f64>; N],
    grid: &[f64],
    index: &[usize],
    avg: bool,
) -> [Vec<f64>; N] {
    std::array::from_fn(|c| {
        let yc = &y[c];
        let mut o = Vec::with_capacity(index.len());
        for (k, &i) in index.iter().enumerate() {
            if !avg || k == 0 {
                o.push(yc[i]);
            } else {
                let i0 = index[k - 1];
                let total: f64 = (i0 + 1..=i).map(|j| (grid[j] - grid[j - 1]) * yc[j]).sum();
                o.push(total / (grid[i] - grid[i0]));
            }
        }
        o
    })
}

#[cfg(test)]
mod tests;
