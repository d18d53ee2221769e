//! The velocity dynamics of Laut 2011 eq. 2.19 (rows 4–5) and their free-run simulation.
//!
//! ```text
//! v̇ = (θ3/θ1) ω² − (θ4/θ1) v + (1/θ1) v_ref
//! ω̇ = −(θ5/θ2) v ω − (θ6/θ2) ω + (1/θ2) ω_ref
//! ```
//!
//! The simulation integrates with classical fourth-order Runge–Kutta at a sub-step of a fifth
//! of the model's faster time constant ([`substep`]), with the commands held (zero-order hold)
//! or linearly interpolated between samples as the recording says, and reports instantaneous
//! values or window averages (the integral of the velocity over the sample period, divided by
//! it) likewise.
//!
//! # Stiff θ
//! A time constant far below the sample period (a lag shorter than a sample, or a fitter's trial
//! θ1 → 0) would make RK4 take hundreds of sub-steps per sample. When RK4 would need more than
//! [`STIFF_SUBSTEPS`] per interval of sub-steps under a quarter of [`ETD_MAX_SUBSTEP`] (a time
//! constant below half a sample and below 6.25 ms), the simulation switches to the exponential Runge–Kutta
//! method ETDRK4 of Cox & Matthews (J. Comput. Phys. 176, 2002, eq. 26) with the diagonal of the
//! Jacobian as its linear part, ẋ = L x + N(x, u), L = diag(∂f_v/∂v, ∂f_ω/∂ω) at the step's
//! start:
//!
//! ```text
//! a = e^{hL/2} x + (h/2) φ1(hL/2) N(x, u0)
//! b = e^{hL/2} x + (h/2) φ1(hL/2) N(a, u½)
//! c = e^{hL/2} a + (h/2) φ1(hL/2) (2 N(b, u½) − N(x, u0))
//! x⁺ = e^{hL} x + h [(φ1 − 3φ2 + 4φ3) N(x) + 2 (φ2 − 2φ3) (N(a) + N(b)) + (4φ3 − φ2) N(c, u1)]
//! φ1(z) = (e^z − 1)/z,  φ2(z) = (e^z − 1 − z)/z²,  φ3(z) = (e^z − 1 − z − z²/2)/z³
//! ```
//!
//! exact for a linear model under a held command whatever the time constant, with a step set
//! by [`plan`]. With N over the step the quadratic c0 + c1 s/h + c2 (s/h)²/2 these stages imply
//! (c0 = N(x), c1 = −3N(x) + 2N(a) + 2N(b) − N(c), c2 = 4(N(x) − N(a) − N(b) + N(c))), the
//! step is x⁺ = e^{hL} x + h Σ φ_{k+1}(hL) c_k and its window integral, exactly for that
//! quadratic, ∫x = h φ1(hL) x + h² Σ φ_{k+2}(hL) c_k. Every other θ integrates by RK4 exactly as
//! before (the Khepera III's 23 ms at 10 Hz among them).
//!
//! # Sensitivities
//! With x = (v, ω) and p = (θ1…θ6, v0, ω0), the output sensitivities S = ∂x/∂p (2 × 8) obey the
//! forward sensitivity equations, integrated alongside x by the same RK4 steps
//! ([`simulate_with_sensitivities`]):
//!
//! ```text
//! Ṡ = A S + [B | 0],   S(0) = [0 | I₂],
//! A = ∂f/∂x = [ −θ4/θ1        2θ3ω/θ1       ]
//!             [ −θ5ω/θ2      −(θ5v + θ6)/θ2 ]
//! B = ∂f/∂θ = [ −v̇/θ1  0       ω²/θ1  −v/θ1  0        0     ]
//!             [ 0      −ω̇/θ2   0      0      −vω/θ2  −ω/θ2 ]
//! ```
//!
//! and window-averaged outputs have the window average of S as their sensitivity.

use wheelid_core::{CommandHold, Error, Recording, Result, VelocitySampling};

mod sensitivities;
mod speculative;

pub use sensitivities::simulate_with_sensitivities;

/// Longest integration sub-step \[s\].
pub const MAX_SUBSTEP: f64 = 0.02;
/// Shortest integration sub-step \[s\]: time constants below a millisecond are not a robot's;
/// a θ that asks for them (a fitter's trial step) integrates unstably and is rejected as a
/// non-finite simulation instead of taking millions of sub-steps.
pub const MIN_SUBSTEP: f64 = 1e-4;

/// tanh(x), answering ±1 without the call where |x| ≥ 19.5: libm's tanh rounds to exactly ±1
/// from |x| ≈ 19.06 on, so the result is the same bit for bit. Dry friction's sign is smoothed
/// by a tanh over a few mm/s, and most samples of a drive are far beyond it.
#[inline(always)]
pub fn tanh(x: f64) -> f64 {
    if x >= 19.5 {
        1.0
    } else if x <= -19.5 {
        -1.0
    } else {
        x.tanh()
    }
}

/// (v̇, ω̇) of eq. 2.19 for θ (length 6), state (v, ω) and commands (v_ref, ω_ref).
#[inline]
pub fn accel(theta: &[f64; 6], v: f64, w: f64, v_ref: f64, w_ref: f64) -> (f64, f64) {
    let [t1, t2, t3, t4, t5, t6] = *theta;
    (
        (t3 * w * w - t4 * v + v_ref) / t1,
        (-t5 * v * w - t6 * w + w_ref) / t2,
    )
}

/// A command that varies linearly over an integration step: what [`rk4_step`] needs of it.
pub trait StepCommand: Copy {
    /// The command halfway between `self` and `other`.
    fn midpoint(&self, other: &Self) -> Self;
}

impl StepCommand for (f64, f64) {
    #[inline(always)]
    fn midpoint(&self, other: &Self) -> Self {
        ((self.0 + other.0) * 0.5, (self.1 + other.1) * 0.5)
    }
}

/// One classical RK4 step of ẋ = f(x, u) of length `h`, with the command varying linearly from
/// `u0` to `u1` over the step (its midpoint for the middle stages); adds ∫x over the step, by the
/// same stages, to `q` — window averages to the same order as the state. `x`, `q`: N state
/// components in their own units; `h` in seconds. Components that fall below 1e-200 are set
/// to zero (they would stall as slow subnormal numbers). Model plugins integrate with it too.
#[inline(always)]
pub fn rk4_step<const N: usize, U: StepCommand>(
    f: impl Fn(&[f64; N], U) -> [f64; N],
    x: &mut [f64; N],
    q: &mut [f64; N],
    u0: U,
    u1: U,
    h: f64,
) {
    let um = u0.midpoint(&u1);
    let k1 = f(x, u0);
    let x2: [f64; N] = std::array::from_fn(|i| x[i] + 0.5 * h * k1[i]);
    let k2 = f(&x2, um);
    let x3: [f64; N] = std::array::from_fn(|i| x[i] + 0.5 * h * k2[i]);
    let k3 = f(&x3, um);
    let x4: [f64; N] = std::array::from_fn(|i| x[i] + h * k3[i]);
    let k4 = f(&x4, u1);
    for i in 0..N {
        q[i] += h / 6.0 * (x[i] + 2.0 * x2[i] + 2.0 * x3[i] + x4[i]);
        x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
        // A decaying component (the sensitivity to the initial state, a velocity at rest)
        // would otherwise stall in the subnormal range, where RK4's increment rounds to
        // nothing, and make every later step ~10× slower: below 1e-200 it is zero.
        if x[i].abs() < FLUSH {
            x[i] = 0.0;
        }
    }
}

/// Magnitude under which [`rk4_step`] sets a state component to zero (any unit: far below
/// every physical value, far above the subnormal range that starts at 2.2e-308).
const FLUSH: f64 = 1e-200;

/// Calls `step(u0, u1, h, exponential)` for the equal sub-steps of the interval [t_{k−1}, t_k]
/// that [`plan`] sets for θ (`planner`: θ's part of it, made once a run), with the command held or linearly interpolated as `hold` says;
/// returns the interval's length.
fn for_each_substep(
    rec: &Recording,
    k: usize,
    hold: CommandHold,
    planner: &Planner,
    mut step: impl FnMut((f64, f64), (f64, f64), f64, bool),
) -> f64 {
    let span = rec.t[k] - rec.t[k - 1];
    let plan = planner.plan(span);
    let exponential = plan.exponential();
    let ua = (rec.v_ref[k - 1], rec.w_ref[k - 1]);
    let ub = match hold {
        CommandHold::Zoh => ua,
        CommandHold::Sampled => (rec.v_ref[k], rec.w_ref[k]),
    };
    let at = |f: f64| (ua.0 + f * (ub.0 - ua.0), ua.1 + f * (ub.1 - ua.1));
    for sub in plan.substeps() {
        step(at(sub.f0), at(sub.f1), sub.h, exponential);
    }
    span
}

/// Integration sub-step for θ: a fifth of the faster time constant (θ1/θ4, θ2/θ6), at most
/// [`MAX_SUBSTEP`] and at least [`MIN_SUBSTEP`]. RK4's error per step of e^{−h/τ} at h = τ/5 is
/// 2.5e-6 of the state, so a step response stays within 1e-5 of its final value (test), far
/// below any measurement's noise.
pub fn substep(theta: &[f64; 6]) -> f64 {
    let tau = (theta[0] / theta[3]).abs().min((theta[1] / theta[5]).abs());
    if tau.is_finite() && tau > 0.0 {
        (tau / 5.0).clamp(MIN_SUBSTEP, MAX_SUBSTEP)
    } else {
        MAX_SUBSTEP
    }
}

/// RK4 sub-steps per sample interval beyond which a simulation integrates by ETDRK4 (module
/// doc) — when RK4's sub-step is also below a quarter of [`ETD_MAX_SUBSTEP`], where ETDRK4
/// saves steps: the faster time constant is then shorter than half a sample and than 6.25 ms.
pub const STIFF_SUBSTEPS: usize = 10;

/// ETDRK4's longest sub-step \[s\]: its linear part is the Jacobian's diagonal, so the coupling
/// of v and ω (θ3 ω², θ5 v ω over θ1, θ2: tens per second for a stiff θ) is explicit; at 5 ms
/// a stiff turning drive stays within 2e-6 of a fine RK4 and the sensitivities within 6e-4 of
/// the simulation's derivative (tests; 1.5e-5 and 1.2e-3 at 20 ms).
pub const ETD_MAX_SUBSTEP: f64 = 0.005;

/// How an interval of length `span` \[s\] is integrated for θ: equal sub-steps by RK4, or by
/// ETDRK4 when RK4 would take more than [`STIFF_SUBSTEPS`] (module doc). ETDRK4's sub-steps grow
/// geometrically from half the fastest time constant — the fast transient after a command's
/// change is resolved, its stages see the forcing that transient puts on the other channel — up
/// to a fifth of the time constants that are not stiff (at most [`ETD_MAX_SUBSTEP`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plan {
    span: f64,
    /// RK4: the number of equal sub-steps; ETDRK4: 0.
    equal: usize,
    /// ETDRK4's first sub-step and its longest \[s\].
    first: f64,
    cap: f64,
}

/// One sub-step of a [`Plan`]: the fractions `f0`, `f1` of the interval it spans, its length
/// `h` \[s\] and its start `t0` and end `t1` \[s\] from the interval's start.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Substep {
    /// Fraction of the interval where the sub-step starts.
    pub f0: f64,
    /// Fraction of the interval where it ends.
    pub f1: f64,
    /// Its length \[s\].
    pub h: f64,
    /// Its start \[s\] after the interval's start.
    pub t0: f64,
    /// Its end \[s\] after the interval's start.
    pub t1: f64,
}

impl Plan {
    /// ETDRK4 ([`etdrk4_step`]) rather than RK4 ([`rk4_step`]).
    pub fn exponential(&self) -> bool {
        self.equal == 0
    }

    /// The sub-steps in order; they tile the interval.
    pub fn substeps(&self) -> impl Iterator<Item = Substep> + use<> {
        let Plan {
            span,
            equal,
            first,
            cap,
        } = *self;
        let h_eq = span / equal.max(1) as f64;
        let mut j = 0usize;
        let mut t = 0.0f64;
        let mut next = first;
        // j/equal of the sub-step's start: the previous one's end (the same quotient).
        let mut f_start = 0.0;
        std::iter::from_fn(move || {
            if equal > 0 {
                (j < equal).then(|| {
                    let f1 = (j + 1) as f64 / equal as f64;
                    let s = Substep {
                        f0: f_start,
                        f1,
                        h: h_eq,
                        t0: j as f64 * h_eq,
                        t1: (j + 1) as f64 * h_eq,
                    };
                    f_start = f1;
                    j += 1;
                    s
                })
            } else {
                let left = span - t;
                (left > 0.0).then(|| {
                    // The rest in one step when what would remain is under half this one.
                    let h = if left < 1.5 * next { left } else { next };
                    let end = if h == left { span } else { t + h };
                    let s = Substep {
                        f0: t / span,
                        f1: end / span,
                        h: end - t,
                        t0: t,
                        t1: end,
                    };
                    t = end;
                    next = (2.0 * next).min(cap);
                    s
                })
            }
        })
    }

    /// How many sub-steps [`Plan::substeps`] yields (at least one).
    pub fn count(&self) -> usize {
        if self.equal > 0 {
            self.equal
        } else {
            self.substeps().count()
        }
    }
}

/// The [`Plan`] for θ over an interval of `span` seconds.
pub fn plan(theta: &[f64; 6], span: f64) -> Plan {
    Planner::new(theta).plan(span)
}

/// θ's part of [`plan`] (the RK4 sub-step and the time constants), computed once for the
/// many intervals of a run: [`Planner::plan`] is [`plan`], the same operations on the same
/// values, with only the interval's own left per sample.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Planner {
    h_rk4: f64,
    taus: [f64; 2],
}

impl Planner {
    pub(crate) fn new(theta: &[f64; 6]) -> Self {
        Self {
            h_rk4: substep(theta),
            taus: [theta[0] / theta[3], theta[1] / theta[5]].map(f64::abs),
        }
    }

    /// [`plan`] over an interval of `span` seconds.
    pub(crate) fn plan(&self, span: f64) -> Plan {
        let Planner { h_rk4, taus } = *self;
        let count = |h: f64| (span / h).ceil().max(1.0) as usize;
        let equal = count(h_rk4);
        let stiff = equal > STIFF_SUBSTEPS && h_rk4 < 0.25 * ETD_MAX_SUBSTEP;
        if !stiff || span.is_nan() || span <= 0.0 || taus.iter().any(|t| !t.is_finite()) {
            return Plan {
                span,
                equal,
                first: span,
                cap: span,
            };
        }
        let floor = span / STIFF_SUBSTEPS as f64;
        let cap = taus
            .iter()
            .map(|t| t / 5.0)
            .filter(|h| *h >= floor)
            .fold(ETD_MAX_SUBSTEP, f64::min);
        // Both on fixed fractions of the interval (span/2^m, span/n), so that the grid does not
        // move with θ between changes of m, n, as RK4's does not between changes of its count.
        let cap = span / (span / cap).ceil();
        let fastest = taus[0].min(taus[1]).max(MIN_SUBSTEP);
        let halvings = (span / (0.25 * fastest)).log2().ceil().clamp(0.0, 30.0);
        Plan {
            span,
            equal: 0,
            first: (span / halvings.exp2()).min(cap),
            cap,
        }
    }
}

/// φ1…φ4 at z (module doc; φ4(z) = (φ3(z) − 1/6)/z): by their Taylor series Σ z^j/(j+k)! for
/// |z| < ½, where the closed forms cancel, else in closed form.
#[cfg(test)]
fn phi(z: f64) -> [f64; 4] {
    phi_with(z, z.exp())
}

/// [`phi`] given `e` = e^z.
fn phi_with(z: f64, e: f64) -> [f64; 4] {
    if z.abs() < 0.5 {
        let mut p = [0.0; 4];
        for (k, out) in p.iter_mut().enumerate() {
            let mut term = 1.0 / (1..=k as u32 + 1).map(f64::from).product::<f64>();
            let mut sum = 0.0;
            for j in 0..16u32 {
                sum += term;
                term *= z / f64::from(j + k as u32 + 2);
            }
            *out = sum;
        }
        return p;
    }
    let p1 = (e - 1.0) / z;
    let p2 = (p1 - 1.0) / z;
    let p3 = (p2 - 0.5) / z;
    let p4 = (p3 - 1.0 / 6.0) / z;
    [p1, p2, p3, p4]
}

/// The diagonal linear part's row for component `i` of an `N`-component state laid out as
/// (v, ω, ∂v/∂p…, ∂ω/∂p…): v and its sensitivities follow ∂f_v/∂v, ω and its follow ∂f_ω/∂ω.
#[inline(always)]
fn row<const N: usize>(i: usize) -> usize {
    if i < 2 {
        i
    } else {
        usize::from(i >= 2 + (N - 2) / 2)
    }
}

/// One ETDRK4 step (Cox & Matthews 2002; module doc) of ẋ = f(x, u) of length `h` \[s\] with the
/// command varying linearly from `u0` to `u1`, linear part `lin` = (∂f_v/∂v, ∂f_ω/∂ω) [1/s]
/// applied by `row` to a state laid out as (v, ω, ∂v/∂p…, ∂ω/∂p…); adds ∫x over the step to
/// `q`. Flushes components below 1e-200 to zero as [`rk4_step`] does.
#[inline]
pub fn etdrk4_step<const N: usize, U: StepCommand>(
    f: impl Fn(&[f64; N], U) -> [f64; N],
    lin: [f64; 2],
    x: &mut [f64; N],
    q: &mut [f64; N],
    u0: U,
    u1: U,
    h: f64,
) {
    struct Coef {
        l: f64,
        e: f64,
        e2: f64,
        p2h: f64,
        /// h φ1…φ4 at hL.
        p: [f64; 4],
    }
    let coef = |l: f64| {
        let z = h * l;
        // φ's closed forms need e^z anyway: one exponential per argument.
        let (e2, e) = ((0.5 * z).exp(), z.exp());
        let [half, ..] = phi_with(0.5 * z, e2);
        Coef {
            l,
            e,
            e2,
            p2h: 0.5 * h * half,
            p: phi_with(z, e).map(|p| h * p),
        }
    };
    let k = [coef(lin[0]), coef(lin[1])];
    let co = |i: usize| &k[row::<N>(i)];
    let nl = |y: &[f64; N], u: U| {
        let fy = f(y, u);
        std::array::from_fn::<f64, N, _>(|i| fy[i] - co(i).l * y[i])
    };
    let um = u0.midpoint(&u1);
    let n0 = nl(x, u0);
    let a: [f64; N] = std::array::from_fn(|i| co(i).e2 * x[i] + co(i).p2h * n0[i]);
    let na = nl(&a, um);
    let b: [f64; N] = std::array::from_fn(|i| co(i).e2 * x[i] + co(i).p2h * na[i]);
    let nb = nl(&b, um);
    let c: [f64; N] = std::array::from_fn(|i| co(i).e2 * a[i] + co(i).p2h * (2.0 * nb[i] - n0[i]));
    let nc = nl(&c, u1);
    for i in 0..N {
        let Coef { e, p, .. } = *co(i);
        // N over the step as the quadratic c0 + c1 (s/h) + c2 (s/h)²/2 that ETDRK4 integrates;
        // x(s) is then e^{sL} x + Σ s^{k+1} φ_{k+1}(sL) c_k and ∫x adds one to each φ's index.
        let c0 = n0[i];
        let c1 = -3.0 * n0[i] + 2.0 * (na[i] + nb[i]) - nc[i];
        let c2 = 4.0 * (n0[i] - na[i] - nb[i] + nc[i]);
        q[i] += p[0] * x[i] + h * (p[1] * c0 + p[2] * c1 + p[3] * c2);
        let next = e * x[i] + p[0] * c0 + p[1] * c1 + p[2] * c2;
        x[i] = if next.abs() < FLUSH { 0.0 } else { next };
    }
}

/// (∂f_v/∂v, ∂f_ω/∂ω) of ẋ = f(x, u) at (x, u) by forward differences (steps of 1e-7 in the
/// component's magnitude, at least 1e-9): the linear part [`etdrk4_step`] takes for a model
/// whose Jacobian is not written out (clamps, friction, plugins).
pub fn diagonal_jacobian<const N: usize, U: StepCommand>(
    f: impl Fn(&[f64; N], U) -> [f64; N],
    x: &[f64; N],
    u: U,
) -> [f64; 2] {
    let f0 = f(x, u);
    std::array::from_fn(|c| {
        let d = 1e-7 * x[c].abs().max(1e-2);
        let mut y = *x;
        y[c] += d;
        (f(&y, u)[c] - f0[c]) / d
    })
}

/// Checks θ: six finite values with θ1, θ2 ≠ 0.
///
/// # Errors
/// [`Error::InvalidSetting`] otherwise.
pub fn check_theta(theta: &[f64]) -> Result<[f64; 6]> {
    let th: [f64; 6] = theta
        .try_into()
        .map_err(|_| Error::InvalidSetting(format!("θ must have 6 values, got {}", theta.len())))?;
    if th.iter().any(|x| !x.is_finite()) || th[0] == 0.0 || th[1] == 0.0 {
        return Err(Error::InvalidSetting(format!(
            "θ must be finite with θ1, θ2 ≠ 0, got {th:?}"
        )));
    }
    Ok(th)
}

/// What both simulations check and read first.
#[derive(Clone, Copy)]
struct Setup {
    th: [f64; 6],
    v0: f64,
    w0: f64,
    n: usize,
    hold: CommandHold,
    avg: bool,
}

/// Checks θ, the initial state and the recording, and reads how it holds and samples.
fn setup(theta: &[f64], rec: &Recording, initial: &[f64]) -> Result<Setup> {
    let th = check_theta(theta)?;
    let &[v0, w0] = initial else {
        return Err(Error::InvalidSetting(format!(
            "initial state must be [v, ω], got {} values",
            initial.len()
        )));
    };
    let n = rec.len();
    if n == 0 {
        return Err(Error::InvalidSetting("the recording is empty".into()));
    }
    Ok(Setup {
        th,
        v0,
        w0,
        n,
        hold: rec.command_hold(),
        avg: rec.velocity_sampling() == VelocitySampling::WindowAverage,
    })
}

/// Free-run simulation of (v, ω) on the recording's time base from its commands, starting at
/// `initial = [v0, ω0]`.
///
/// Output samples follow the recording's velocity sampling: instantaneous values at t_k, or,
/// for window averages, the mean over [t_{k−1}, t_k] (the first sample is the initial state).
///
/// # Errors
/// [`Error::InvalidSetting`] for a bad θ or initial state, or an empty recording.
pub fn simulate(theta: &[f64], rec: &Recording, initial: &[f64]) -> Result<[Vec<f64>; 2]> {
    let setup = setup(theta, rec, initial)?;
    let parts = if setup.n < speculative::MIN_SAMPLES {
        1
    } else {
        (speculative::LANES * rayon::current_num_threads()).clamp(1, speculative::MAX_PARTS)
    };
    Ok(speculative::free_run(&FreeRun::new(&setup, rec), parts))
}

/// The free run's step from one sample to the next: a pure function of the state at the
/// previous sample and the recording, which is what lets [`speculative::free_run`] integrate
/// parts of a long recording at once.
pub(crate) struct FreeRun<'a> {
    rec: &'a Recording,
    th: [f64; 6],
    inv: [f64; 2],
    hold: CommandHold,
    avg: bool,
    initial: [f64; 2],
    planner: Planner,
}

impl<'a> FreeRun<'a> {
    fn new(setup: &Setup, rec: &'a Recording) -> Self {
        let th = setup.th;
        Self {
            rec,
            th,
            inv: [1.0 / th[0], 1.0 / th[1]],
            hold: setup.hold,
            avg: setup.avg,
            initial: [setup.v0, setup.w0],
            planner: Planner::new(&th),
        }
    }

    /// Samples in the recording.
    pub(crate) fn len(&self) -> usize {
        self.rec.len()
    }

    /// The initial state (v0, ω0): output sample 0.
    pub(crate) fn initial(&self) -> [f64; 2] {
        self.initial
    }

    /// A guess of the state at sample `k` (the measured velocities, zero where not finite),
    /// for a part that starts there without the exact state.
    pub(crate) fn guess(&self, k: usize) -> [f64; 2] {
        [self.rec.v[k], self.rec.w[k]].map(|x| if x.is_finite() { x } else { 0.0 })
    }

    /// Eq. 2.19 as `accel` at this run's θ, multiplying by 1/θ1, 1/θ2 (the step's critical
    /// path): (v, ω) and the command (v_ref, ω_ref) → (v̇, ω̇).
    #[inline]
    fn field(&self) -> impl Fn(&[f64; 2], (f64, f64)) -> [f64; 2] + Copy {
        let [_, _, t3, t4, t5, t6] = self.th;
        let [i1, i2] = self.inv;
        move |x: &[f64; 2], u: (f64, f64)| {
            let [v, w] = *x;
            [
                (t3 * w * w - t4 * v + u.0) * i1,
                (-t5 * v * w - t6 * w + u.1) * i2,
            ]
        }
    }

    /// Advances the state `x` from t_{k−1} to t_k (k ≥ 1) and returns output sample k: the
    /// state, or its window average when the recording samples so.
    #[inline]
    pub(crate) fn step(&self, k: usize, x: &mut [f64; 2]) -> [f64; 2] {
        let [_, _, _, t4, t5, t6] = self.th;
        let [i1, i2] = self.inv;
        let f = self.field();
        let mut q = [0.0; 2];
        let span = for_each_substep(
            self.rec,
            k,
            self.hold,
            &self.planner,
            |u0, u1, h, exponential| {
                if exponential {
                    let lin = [-t4 * i1, -(t5 * x[0] + t6) * i2];
                    etdrk4_step(f, lin, x, &mut q, u0, u1, h);
                } else {
                    rk4_step(f, x, &mut q, u0, u1, h);
                }
            },
        );
        if self.avg { q.map(|i| i / span) } else { *x }
    }

    /// [`FreeRun::step`] of L independent runs at once — run l from t_{ks[l]−1} to t_{ks[l]}
    /// from state `xs[l]` — their RK4 sub-steps interleaved: each run is a chain of dependent
    /// operations whose latency, not the core's throughput, sets its speed, so L chains side by
    /// side cost about what one does. Each run gets the same operations on the same values as
    /// [`FreeRun::step`] (the same [`rk4_step`] per sub-step), so the same bits; intervals whose
    /// plans differ in their sub-step count, or that ETDRK4 integrates, are stepped one by one.
    #[inline]
    pub(crate) fn step_lanes<const L: usize>(
        &self,
        ks: [usize; L],
        xs: &mut [[f64; 2]; L],
    ) -> [[f64; 2]; L] {
        let spans: [f64; L] = ks.map(|k| self.rec.t[k] - self.rec.t[k - 1]);
        let plans = spans.map(|s| self.planner.plan(s));
        let equal = plans[0].equal;
        if equal == 0 || plans.iter().any(|p| p.equal != equal) {
            return std::array::from_fn(|l| self.step(ks[l], &mut xs[l]));
        }
        let f = self.field();
        let commands = ks.map(|k| {
            let ua = (self.rec.v_ref[k - 1], self.rec.w_ref[k - 1]);
            let ub = match self.hold {
                CommandHold::Zoh => ua,
                CommandHold::Sampled => (self.rec.v_ref[k], self.rec.w_ref[k]),
            };
            (ua, ub)
        });
        let at = |(ua, ub): ((f64, f64), (f64, f64)), f: f64| {
            (ua.0 + f * (ub.0 - ua.0), ua.1 + f * (ub.1 - ua.1))
        };
        let mut q = [[0.0; 2]; L];
        for j in 0..equal {
            // The fractions and lengths of `Plan::substeps`' RK4 sub-steps.
            let f0 = j as f64 / equal as f64;
            let f1 = (j + 1) as f64 / equal as f64;
            for l in 0..L {
                let h = spans[l] / equal as f64;
                let (u0, u1) = (at(commands[l], f0), at(commands[l], f1));
                rk4_step(f, &mut xs[l], &mut q[l], u0, u1, h);
            }
        }
        std::array::from_fn(|l| {
            if self.avg {
                q[l].map(|i| i / spans[l])
            } else {
                xs[l]
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::sensitivities::{sensitivities_on_one_thread, sensitivities_on_two_threads};
    use super::*;

    /// A recording of `t`, held commands `vr`, `wr` (zero-order hold) and zero outputs, its
    /// velocities window averages when `avg`, else instants.
    fn zoh_recording(t: &[f64], vr: &[f64], wr: &[f64], avg: bool) -> Recording {
        let n = t.len();
        let mut rec = Recording::new(
            "zoh",
            t.to_vec(),
            vr.to_vec(),
            wr.to_vec(),
            vec![0.0; n],
            vec![0.0; n],
        )
        .expect("valid");
        rec.set_meta("command_hold", "zoh");
        if avg {
            rec.set_meta("velocity_sampling", "window_average");
        }
        rec
    }

    /// Straight-drive step response (ω = 0): θ1 v̇ = u − θ4 v → v(t) = (u/θ4)(1 − e^{−θ4 t/θ1}).
    /// Returns the largest error relative to the final value u/θ4, checking ω stays 0.
    fn step_error(theta: [f64; 6], dt: f64, u: f64) -> f64 {
        let t: Vec<f64> = (0..=20).map(|k| k as f64 * dt).collect();
        let n = t.len();
        let rec = Recording::new(
            "step",
            t.clone(),
            vec![u; n],
            vec![0.0; n],
            vec![0.0; n],
            vec![0.0; n],
        )
        .expect("valid");
        let [v, w] = simulate(&theta, &rec, &[0.0, 0.0]).expect("sim");
        assert!(w.iter().all(|x| *x == 0.0));
        let final_value = u / theta[3];
        t.iter()
            .zip(&v)
            .map(|(tk, vk)| {
                (vk - final_value * (1.0 - (-theta[3] * tk / theta[0]).exp())).abs() / final_value
            })
            .fold(0.0f64, f64::max)
    }

    #[test]
    fn sensitivities_split_over_two_threads_are_the_same_bit_for_bit_with_the_free_run() {
        // A turning drive of 2,000 samples with held and window-averaged samples, at the
        // Khepera's θ (RK4 sub-steps) and at a stiff θ (ETDRK4): the two-thread split gives
        // exactly the one-thread numbers.
        let t: Vec<f64> = (0..2000).map(|k| k as f64 * 0.02).collect();
        let vr: Vec<f64> = t.iter().map(|t| 0.1 + 0.08 * (1.3 * t).sin()).collect();
        let wr: Vec<f64> = t.iter().map(|t| 0.9 * (0.7 * t).cos()).collect();
        for avg in [false, true] {
            let rec = zoh_recording(&t, &vr, &wr, avg);
            for theta in [
                [0.0228, 0.0568, -0.0001, 1.003, 0.0732, 0.9981],
                [0.0004, 0.0009, -0.0001, 1.01, 0.07, 0.99],
            ] {
                let setup = setup(&theta, &rec, &[0.05, -0.2]).expect("valid");
                let (y1, s1) = sensitivities_on_one_thread(&setup, &rec);
                let (y2, s2) = sensitivities_on_two_threads(&setup, &rec);
                assert!(y1 == y2 && s1.theta == s2.theta && s1.initial == s2.initial);
                // The outputs are the free run's (output error takes them for its residuals).
                let free = simulate(&theta, &rec, &[0.05, -0.2]).expect("simulates");
                assert!(y1 == free, "avg {avg}, θ {theta:?}");
                assert!(s1.initial[0][(0, 0)] == 1.0 && s1.theta[1].iter().any(|x| *x != 0.0));
                // The initial state is forgotten: its columns end exactly zero (the two-thread
                // run drops them from there).
                let last = rec.len() - 1;
                assert!(
                    s2.initial
                        .iter()
                        .all(|m| m.row(last).iter().all(|x| *x == 0.0))
                );
            }
        }
    }

    #[test]
    fn a_decaying_state_reaches_zero_instead_of_stalling_subnormal() {
        // ẋ = −x/τ from 1 with h = τ/5: RK4 follows e^{−t/τ} (its per-step factor, to 1e-12),
        // and once below the flush level the state is exactly 0 — never a subnormal number,
        // where it would otherwise stay (the increment rounds to nothing there).
        let (tau, h): (f64, f64) = (0.02, 0.004);
        let mut x = [1.0];
        let mut q = [0.0];
        let z = h / tau;
        let factor = 1.0 - z + z * z / 2.0 - z.powi(3) / 6.0 + z.powi(4) / 24.0;
        for k in 1..=5000 {
            rk4_step(
                |x: &[f64; 1], _u: (f64, f64)| [-x[0] / tau],
                &mut x,
                &mut q,
                (0.0, 0.0),
                (0.0, 0.0),
                h,
            );
            assert!(x[0] == 0.0 || x[0].is_normal(), "step {k}: {:e}", x[0]);
            if k == 100 {
                let expect = factor.powi(100);
                assert!((x[0] / expect - 1.0).abs() < 1e-12, "{} vs {expect}", x[0]);
            }
        }
        assert_eq!(x[0], 0.0);
    }

    #[test]
    fn step_response_of_a_straight_drive_is_first_order() {
        // Pioneer θ (τ = 0.26 s) at 10 Hz: sub-step capped at 20 ms, error below 1e-6.
        let worst = step_error([0.26, 0.25, -0.0005, 0.9965, 0.0026, 1.0768], 0.1, 0.5);
        assert!(worst < 1e-6, "{worst:e}");
    }

    #[test]
    fn a_fast_robot_at_a_fifth_of_its_time_constant_stays_within_1e_5() {
        // Khepera III θ: τ = θ1/θ4 = 23 ms, sampled at 20 ms → 5 RK4 sub-steps of 4.5 ms.
        let worst = step_error([0.0228, 0.0568, -0.0001, 1.0030, 0.0732, 0.9981], 0.02, 0.3);
        assert!(worst < 1e-5, "{worst:e}");
        // And it is not a trivially tiny error: h = τ/5 leaves a measurable one.
        assert!(worst > 1e-8, "{worst:e}");
    }

    #[test]
    fn phi_series_and_closed_forms_agree_at_their_seam() {
        // φk is continuous: the series just below |z| = ½ and the closed form just above.
        for z in [0.5f64, -0.5] {
            let below = phi(z * (1.0 - 1e-12));
            let above = phi(z * (1.0 + 1e-12));
            for k in 0..4 {
                assert!((below[k] - above[k]).abs() < 1e-10, "z {z} φ{}", k + 1);
            }
        }
        // Closed forms at z = −1: φ1 = 1 − e^{−1}, φ2 = e^{−1}, φ3 = ½ − e^{−1}, φ4 = e^{−1} − ⅓.
        let e = (-1.0f64).exp();
        let [p1, p2, p3, p4] = phi(-1.0);
        assert!((p1 - (1.0 - e)).abs() < 1e-15 && (p2 - e).abs() < 1e-15);
        assert!((p3 - (0.5 - e)).abs() < 1e-15, "{p3}");
        assert!((p4 - (e - 1.0 / 3.0)).abs() < 1e-15, "{p4}");
        assert_eq!(phi(0.0), [1.0, 0.5, 1.0 / 6.0, 1.0 / 24.0]);
    }

    #[test]
    fn plans_switch_to_etdrk4_only_below_half_a_sample() {
        let khepera = [0.0228, 0.0568, -0.0001, 1.0030, 0.0732, 0.9981];
        let p = plan(&khepera, 0.02);
        assert!(!p.exponential());
        let h: Vec<f64> = p.substeps().map(|s| s.h).collect();
        assert_eq!(h, vec![0.004; 5]);
        // At 10 Hz RK4 takes 22 sub-steps of 4.5 ms, where ETDRK4 would save nothing.
        let p = plan(&khepera, 0.1);
        assert!(!p.exponential() && p.count() == 22);
        // θ1 = 1 ms: RK4 would take 100 sub-steps of 0.2 ms; ETDRK4 starts at 20/2^7 ms (the
        // first halving of 20 ms below τ/4 = 0.25 ms) and doubles up to 5 ms
        // (ETD_MAX_SUBSTEP, below ω's τ/5 = 11.4 ms); the rest, 5.16 ms, is one step.
        let stiff = [0.001, 0.0568, -0.0001, 1.0, 0.0732, 0.9981];
        let p = plan(&stiff, 0.02);
        assert!(p.exponential());
        let h: Vec<f64> = p.substeps().map(|s| s.h).collect();
        let u = 0.02 / 128.0;
        let expect = [
            u,
            2.0 * u,
            4.0 * u,
            8.0 * u,
            16.0 * u,
            0.005,
            0.005,
            0.01 - 31.0 * u,
        ];
        assert_eq!(h.len(), expect.len(), "{h:?}");
        for (a, b) in h.iter().zip(expect) {
            assert!((a - b).abs() < 1e-15, "{h:?}");
        }
        let last = p.substeps().last().expect("steps");
        assert_eq!(last.f1, 1.0);
        assert_eq!(p.count(), 8);
    }

    /// A stiff straight drive (θ1 = 1 ms, sampled at 20 ms) from rest under v_ref = u:
    /// v(t) = (u/θ4)(1 − e^{−t/τ}), and its window average over [t_{k−1}, t_k] is
    /// (u/θ4)(1 − τ (e^{−t_{k−1}/τ} − e^{−t_k/τ})/Δt).
    #[test]
    fn a_stiff_step_response_is_exact_in_instants_and_window_averages() {
        let theta = [0.001, 0.05, 0.0, 1.2, 0.0, 1.0];
        let (dt, u) = (0.02, 0.6);
        let n = 30;
        let t: Vec<f64> = (0..n).map(|k| k as f64 * dt).collect();
        let tau = theta[0] / theta[3];
        let gain = u / theta[3];
        let (vr, wr) = (vec![u; n], vec![0.0; n]);
        for avg in [false, true] {
            let rec = zoh_recording(&t, &vr, &wr, avg);
            let [v, w] = simulate(&theta, &rec, &[0.0, 0.0]).expect("sim");
            assert!(w.iter().all(|x| *x == 0.0));
            for k in 1..n {
                let exact = if avg {
                    let decay = (-t[k - 1] / tau).exp() - (-t[k] / tau).exp();
                    gain * (1.0 - tau * decay / dt)
                } else {
                    gain * (1.0 - (-t[k] / tau).exp())
                };
                assert!(
                    (v[k] - exact).abs() < 1e-12,
                    "avg {avg} k {k}: {} vs {exact}",
                    v[k]
                );
            }
        }
    }

    /// A turning drive with a stiff ω channel (θ2 = 1 ms) and θ3, θ5 acting: ETDRK4 at its plan
    /// against RK4 at 1 µs sub-steps, in instants and window averages.
    #[test]
    fn a_stiff_turning_drive_matches_fine_rk4() {
        let theta = [0.05, 0.001, -0.02, 1.0, 0.05, 1.1];
        assert!(plan(&theta, 0.02).exponential());
        let n = 60;
        let t: Vec<f64> = (0..n).map(|k| k as f64 * 0.02).collect();
        let vr: Vec<f64> = t.iter().map(|&x| 0.4 + 0.3 * (3.0 * x).sin()).collect();
        let wr: Vec<f64> = t.iter().map(|&x| 1.5 * (5.0 * x).cos()).collect();
        let f = |x: &[f64; 2], u: (f64, f64)| {
            let (a, b) = accel(&theta, x[0], x[1], u.0, u.1);
            [a, b]
        };
        for avg in [false, true] {
            let rec = zoh_recording(&t, &vr, &wr, avg);
            let y = simulate(&theta, &rec, &[0.1, 0.0]).expect("sim");
            let mut x = [0.1, 0.0];
            for k in 1..n {
                let u = (vr[k - 1], wr[k - 1]);
                let mut q = [0.0; 2];
                for _ in 0..20_000 {
                    rk4_step(f, &mut x, &mut q, u, u, 1e-6);
                }
                for c in 0..2 {
                    let fine = if avg { q[c] / 0.02 } else { x[c] };
                    assert!(
                        (y[c][k] - fine).abs() < 2e-6 * (1.0 + fine.abs()),
                        "avg {avg} k {k} ch {c}: {} vs {fine}",
                        y[c][k]
                    );
                }
            }
        }
    }

    #[test]
    fn sensitivities_match_central_differences() {
        sensitivities_match_central_differences_at([0.26, 0.25, -0.05, 0.9965, 0.08, 1.0768], 1e-6);
    }

    #[test]
    fn stiff_sensitivities_match_central_differences() {
        // θ1, θ2 of a few ms at 10 Hz: ETDRK4 (checked by the plan), the same sensitivity law,
        // integrated by ETDRK4 to 6e-4 of the simulation's derivative: the θ1, θ2 sources
        // (−v̇/θ1, −ω̇/θ2) carry the state's error over θ1, θ2.
        let theta = [0.004, 0.003, -0.05, 0.9965, 0.08, 1.0768];
        assert!(plan(&theta, 0.1).exponential());
        sensitivities_match_central_differences_at(theta, 1e-3);
    }

    /// Central differences of [`simulate`] against [`simulate_with_sensitivities`], relative
    /// tolerance `tol`.
    fn sensitivities_match_central_differences_at(theta: [f64; 6], tol: f64) {
        // A turning, accelerating recording so that every θ (also θ3, θ5) acts.
        let n = 80;
        let t: Vec<f64> = (0..n).map(|k| k as f64 * 0.1).collect();
        let vr: Vec<f64> = t.iter().map(|&x| 0.4 + 0.3 * (1.3 * x).sin()).collect();
        let wr: Vec<f64> = t.iter().map(|&x| 1.2 * (0.7 * x).cos()).collect();
        for avg in [false, true] {
            let rec = zoh_recording(&t, &vr, &wr, avg);
            let x0 = [0.1, -0.2];
            let (y, s) = simulate_with_sensitivities(&theta, &rec, &x0).expect("sim");
            let plain = simulate(&theta, &rec, &x0).expect("sim");
            for ch in 0..2 {
                for k in 0..n {
                    approx::assert_abs_diff_eq!(y[ch][k], plain[ch][k], epsilon = 1e-12);
                }
            }
            // Central differences with the integration grid held fixed (h scaled with θ).
            for j in 0..8 {
                let mut p: Vec<f64> = theta.iter().chain(&x0).copied().collect();
                let h = 1e-6 * p[j].abs().max(1e-2);
                p[j] += h;
                let up = simulate(&p[..6], &rec, &p[6..]).expect("sim");
                p[j] -= 2.0 * h;
                let dn = simulate(&p[..6], &rec, &p[6..]).expect("sim");
                for ch in 0..2 {
                    for k in 0..n {
                        let fd = (up[ch][k] - dn[ch][k]) / (2.0 * h);
                        let an = if j < 6 {
                            s.theta[ch][(k, j)]
                        } else {
                            s.initial[ch][(k, j - 6)]
                        };
                        assert!(
                            (fd - an).abs() <= tol * (1.0 + fd.abs()),
                            "avg {avg} ch {ch} k {k} p {j}: fd {fd} analytic {an}"
                        );
                    }
                }
            }
        }
    }
}
