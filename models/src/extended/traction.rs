//! The traction stage ([`wheelid_core::Traction`]): the wheels and the body as two inertias
//! coupled at each wheel's contact by a force that saturates at the floor's grip. The encoders
//! see the wheels, so on a slippery floor they run ahead of the body at high demand, and the
//! body's speed (not the wheels') decides when they grip again.
//!
//! State z = (v_b, ω_b, s_R, s_L): the body's speeds and each wheel's slip speed at its contact
//! (wheel rim less body), so that the wheels' speeds are v_w = v_b + (s_R + s_L)/2 and
//! ω_w = ω_b + (s_R − s_L)/d. With f eq. 2.19's right-hand side at the wheels' speeds (every
//! other stage applied as in the module docs of [`super`]), t_R,L = c' tanh(s_R,L/s0) with
//! each wheel's limit c' = c/(1 − p ḡ) grown by the load transfer p (ḡ the two tanh's mean:
//! c' = c + p T_v) and T = ((t_R + t_L)/2, (t_R − t_L)/(2κ)):
//!
//! ```text
//! v̇_b = T_v / ((1 − ε) θ1)                     ω̇_b = T_ω / ((1 − ε) θ2)
//! ṡ_R,L = (v̇_w − v̇_b) ± (d/2)(ω̇_w − ω̇_b),     v̇_w = (f_v − T_v)/(ε θ1), ω̇_w = (f_ω − T_ω)/(ε θ2)
//! ```
//!
//! The grip is stiff (rate ≈ c/s0 × the contact's inverse inertia, ≈ 1/(0.02 ε τ)): an
//! L-stable Rosenbrock method on equal sub-steps of τ/80 ([`ros2_step`]), its Jacobian exact at
//! every step (the contact's by hand, the field's from [`Field::local`]: a Jacobian held over
//! a sample interval misses the grip's knee and moves the re-grip by ~0.3 s). Outputs are the
//! wheels' speeds, instants or window averages as the recording says.
//!
//! A larger right tyre (`tyre_asymmetry`, radius ratio ρ) acts at its contact: with the rims'
//! speeds m_R,L = v_w ± (d/2) ω_w (the encoders'), the right contact moves at ρ m_R, so
//! s_R = ρ m_R − (v_b + (d/2) ω_b), s_L = m_L − (v_b − (d/2) ω_b); the contact force t_R turns
//! its wheel back by ρ t_R (in the rims' units), and the motor's effort turns the wheel whole
//! (the field is taken without the tyre's own scalings, the effort over ρ and the chassis row).
//! In grip, as ε → 0, this is `tyre_asymmetry`'s ṁ = S B S (e − …), S = diag(1/ρ, 1) (the
//! losses scaled with the effort, a second-order difference). Composed as the tyre alone
//! inside this stage, a slipping wheel answered its motor as if the amplifier were weak: the
//! physics backend's Pioneer-like robot with a 1.0495 tyre on a floor of μ = 0.053 (hold-out
//! seed 1043) was named a false 0.972 amplifier beside both.

use wheelid_core::{Recording, Result, TRACTION_SLIP_SHARE, Terms, Traction};

use super::{Cmd, CommandCursor, Extended, Field, Forces, Local, Run, to_samples};
use crate::dynamics;

/// Sub-steps per shortest time constant min(θ1/θ4, θ2/θ6) ([`ros2_step`] is L-stable: the
/// grip's stiffness does not limit its stability, but a slip's start and end fall inside a
/// sub-step, and how they fall moves the outputs). At τ/40 the training cost of the physics
/// backend's Pioneer-like robot on a slippery floor (tuning seed 1023) jumped by 5–20 %
/// between neighbouring values of a parameter (load transfer steps of 0.002, θ1 steps of 0.1 %),
/// so that a fit stopped in whichever dent it started near (validation fits 96.9–98.8 % in v
/// by where the load transfer started); at τ/80 the same scans are smooth, the fit ends at
/// v 99.5 %, ω 98.9 % whether the load transfer starts at 0 or 0.1, at twice the cost of a
/// simulation.
const STEPS_PER_TAU: f64 = 80.0;

/// One step of Verwer's two-stage Rosenbrock method ROS2 (γ = 1 + 1/√2; 2nd order,
/// L-stable; Verwer, Spee, Blom & Hundsdorfer, SIAM J. Sci. Comput. 20 (1999) 1456) on
/// ż = f(z, u) over `h`, ending under `u1`, given f and its Jacobian ∂f/∂z at the step's start
/// (`start`); adds the trapezoidal ∫z over the step to `q`. The Jacobian's body rows must not
/// depend on the body speeds (∂ż₀,₁/∂z₀,₁ = 0, as [`Contact::rhs`] gives it): W = I − γhJ is
/// then solved by its 2×2 Schur complement ([`Ros2Matrix`]).
fn ros2_step<U>(
    f: impl Fn(&[f64; 4], &U) -> [f64; 4],
    start: ([f64; 4], nalgebra::Matrix4<f64>),
    z: &mut [f64; 4],
    q: &mut [f64; 4],
    u1: &U,
    h: f64,
) {
    const GAMMA: f64 = 1.0 + std::f64::consts::FRAC_1_SQRT_2;
    let (f0, jac) = start;
    debug_assert!(jac.fixed_view::<2, 2>(0, 0).iter().all(|&x| x == 0.0));
    let Some(w) = Ros2Matrix::new(&jac, GAMMA * h) else {
        z.iter_mut().for_each(|x| *x = f64::NAN);
        return;
    };
    let k1 = w.solve(f0);
    let z1: [f64; 4] = std::array::from_fn(|i| z[i] + h * k1[i]);
    let f1 = f(&z1, u1);
    let k2 = w.solve(std::array::from_fn(|i| f1[i] - 2.0 * k1[i]));
    let start = *z;
    for i in 0..4 {
        z[i] += h * (1.5 * k1[i] + 0.5 * k2[i]);
        q[i] += 0.5 * h * (start[i] + z[i]);
    }
}

/// W = I − g J for a Jacobian J whose body block ∂ż₀,₁/∂z₀,₁ is zero:
/// W = [[I, B], [C, D]] with B = −g J₀₁,₂₃, C = −g J₂₃,₀₁, D = I − g J₂₃,₂₃, solved through
/// the inverse of its Schur complement S = D − C B (2×2; det W = det S). Exact block
/// elimination, no pivoting needed: the leading block is the identity.
struct Ros2Matrix {
    b: [[f64; 2]; 2],
    c: [[f64; 2]; 2],
    /// S⁻¹.
    s_inv: [[f64; 2]; 2],
}

impl Ros2Matrix {
    /// `None` where S is singular or not finite.
    #[inline(always)]
    fn new(jac: &nalgebra::Matrix4<f64>, g: f64) -> Option<Self> {
        let b = [
            [-g * jac[(0, 2)], -g * jac[(0, 3)]],
            [-g * jac[(1, 2)], -g * jac[(1, 3)]],
        ];
        let c = [
            [-g * jac[(2, 0)], -g * jac[(2, 1)]],
            [-g * jac[(3, 0)], -g * jac[(3, 1)]],
        ];
        let d = [
            [1.0 - g * jac[(2, 2)], -g * jac[(2, 3)]],
            [-g * jac[(3, 2)], 1.0 - g * jac[(3, 3)]],
        ];
        let s: [[f64; 2]; 2] = std::array::from_fn(|i| {
            std::array::from_fn(|j| d[i][j] - c[i][0] * b[0][j] - c[i][1] * b[1][j])
        });
        let det = s[0][0] * s[1][1] - s[0][1] * s[1][0];
        let scale = s.iter().flatten().fold(0.0_f64, |m, x| m.max(x.abs()));
        if !(det.is_finite() && det.abs() > f64::EPSILON * scale * scale) {
            return None;
        }
        let s_inv = [
            [s[1][1] / det, -s[0][1] / det],
            [-s[1][0] / det, s[0][0] / det],
        ];
        Some(Self { b, c, s_inv })
    }

    /// x with W x = r.
    #[inline(always)]
    fn solve(&self, r: [f64; 4]) -> [f64; 4] {
        let (b, c, s) = (&self.b, &self.c, &self.s_inv);
        // [x₀₁; x₂₃]: S x₂₃ = r₂₃ − C r₀₁, x₀₁ = r₀₁ − B x₂₃.
        let y = [
            r[2] - c[0][0] * r[0] - c[0][1] * r[1],
            r[3] - c[1][0] * r[0] - c[1][1] * r[1],
        ];
        let x2 = s[0][0] * y[0] + s[0][1] * y[1];
        let x3 = s[1][0] * y[0] + s[1][1] * y[1];
        [
            r[0] - b[0][0] * x2 - b[0][1] * x3,
            r[1] - b[1][0] * x2 - b[1][1] * x3,
            x2,
            x3,
        ]
    }
}

/// The contact's constants for θ = `th`: the limit c, the slip scale s0, ε, κ, the load
/// transfer p and d/2.
#[derive(Debug, Clone, Copy)]
struct Contact {
    /// Largest wheel force c = (1 − ε) θ1 a_max [m/s].
    c: f64,
    /// Slip scale s0 = a_max × [`TRACTION_SLIP_SHARE`] × min(θ1/θ4, θ2/θ6) [m/s].
    s0: f64,
    /// Share ε of the inertia on the wheels' side.
    eps: f64,
    /// Force mixing κ = mix × d/2 \[m\].
    kappa: f64,
    /// Load transfer p: each wheel's limit is c/(1 − p ḡ), ḡ the wheels' mean grip share.
    load: f64,
    /// Half track d/2 \[m\].
    half: f64,
    /// Right/left tyre radius ratio ρ (`tyre_asymmetry`; 1 without one): the right contact
    /// moves at ρ times the right rim's speed and turns the wheel back by ρ times its force.
    rho: f64,
}

impl Contact {
    fn new(tr: &Traction, th: &[f64; 6], track: f64, rho: f64) -> Self {
        let eps = tr.wheel_share;
        Self {
            c: (1.0 - eps) * th[0] * tr.accel_max,
            s0: tr.accel_max
                * TRACTION_SLIP_SHARE
                * (th[0] / th[3]).abs().min((th[1] / th[5]).abs()),
            eps,
            kappa: tr.mix * 0.5 * track,
            load: tr.load_transfer,
            half: 0.5 * track,
            rho,
        }
    }

    /// ż for z = (v_b, ω_b, s_R, s_L), given the field at the wheels' speeds (eq. 2.19's
    /// right-hand side divided by θ1, θ2, as [`Field::local`] gives it) and, with `jac`, the
    /// Jacobian ∂ż/∂z (the contact's exactly, the field's from its own; zeros without `jac`).
    #[inline(always)]
    fn rhs(
        &self,
        th: &[f64; 6],
        z: &[f64; 4],
        field: impl Fn((f64, f64), bool) -> Local,
        jac: bool,
    ) -> ([f64; 4], nalgebra::Matrix4<f64>) {
        let [_, _, sr, sl] = *z;
        let (h, rho) = (self.half, self.rho);
        let [vw, ww] = self.wheels(z);
        let local = field((vw, ww), jac);
        let (dv, dw) = (local.f[0] * th[0], local.f[1] * th[1]);
        let (gr, gl) = (dynamics::tanh(sr / self.s0), dynamics::tanh(sl / self.s0));
        // Each wheel's limit grows with the body's traction force T_v by the load transfer p:
        // t = (c + p T_v) g with T_v = (t_R + t_L)/2, i.e. a limit c/(1 − p ḡ).
        let ce = self.c / (1.0 - self.load * 0.5 * (gr + gl));
        let (tr, tl) = (ce * gr, ce * gl);
        let (tv, tw) = (0.5 * (tr + tl), (tr - tl) / (2.0 * self.kappa));
        // The wheels feel the contact forces at their radii: the right one ρ t_R.
        let (rv_, rw_) = (0.5 * (rho * tr + tl), (rho * tr - tl) / (2.0 * self.kappa));
        let e = self.eps;
        let (mb_v, mb_w) = (1.0 / ((1.0 - e) * th[0]), 1.0 / ((1.0 - e) * th[1]));
        let (mw_v, mw_w) = (1.0 / (e * th[0]), 1.0 / (e * th[1]));
        let (vb_dot, wb_dot) = (tv * mb_v, tw * mb_w);
        let (vw_dot, ww_dot) = ((dv - rv_) * mw_v, (dw - rw_) * mw_w);
        // s_R = ρ m_R − (v_b + h ω_b), s_L = m_L − (v_b − h ω_b).
        let zdot = [
            vb_dot,
            wb_dot,
            rho * (vw_dot + h * ww_dot) - (vb_dot + h * wb_dot),
            (vw_dot - h * ww_dot) - (vb_dot - h * wb_dot),
        ];
        let mut j = nalgebra::Matrix4::zeros();
        if jac {
            type Row = nalgebra::RowVector4<f64>;
            let [d_vw, d_ww] = self.wheel_rows();
            let a = local.a;
            let d_dv = th[0] * (a[0][0] * d_vw + a[0][1] * d_ww);
            let d_dw = th[1] * (a[1][0] * d_vw + a[1][1] * d_ww);
            // g' = ∂g/∂s; ∂ce/∂s_j = ce² p g_j' / (2c).
            let slope = |g: f64| (1.0 - g * g) / self.s0;
            let (dgr, dgl) = (slope(gr), slope(gl));
            let d_ce = Row::new(0.0, 0.0, dgr, dgl) * (ce * ce * self.load / (2.0 * self.c));
            let d_tr = Row::new(0.0, 0.0, ce * dgr, 0.0) + d_ce * gr;
            let d_tl = Row::new(0.0, 0.0, 0.0, ce * dgl) + d_ce * gl;
            let d_tv = 0.5 * (d_tr + d_tl);
            let d_tw = (d_tr - d_tl) / (2.0 * self.kappa);
            let d_rv = 0.5 * (rho * d_tr + d_tl);
            let d_rw = (rho * d_tr - d_tl) / (2.0 * self.kappa);
            let d_vb = d_tv * mb_v;
            let d_wb = d_tw * mb_w;
            let d_vwd = (d_dv - d_rv) * mw_v;
            let d_wwd = (d_dw - d_rw) * mw_w;
            j.set_row(0, &d_vb);
            j.set_row(1, &d_wb);
            j.set_row(2, &(rho * (d_vwd + h * d_wwd) - (d_vb + h * d_wb)));
            j.set_row(3, &((d_vwd - h * d_wwd) - (d_vb - h * d_wb)));
        }
        (zdot, j)
    }

    /// ∂(v_w, ω_w)/∂z: the rims' speeds m_R = (v_b + h ω_b + s_R)/ρ, m_L = v_b − h ω_b + s_L
    /// as v_w = (m_R + m_L)/2, ω_w = (m_R − m_L)/(2h) (h = d/2).
    fn wheel_rows(&self) -> [nalgebra::RowVector4<f64>; 2] {
        let (h, r) = (self.half, 1.0 / self.rho);
        [
            nalgebra::RowVector4::new(0.5 * (r + 1.0), 0.5 * h * (r - 1.0), 0.5 * r, 0.5),
            nalgebra::RowVector4::new(0.5 * (r - 1.0) / h, 0.5 * (r + 1.0), 0.5 * r / h, -0.5 / h),
        ]
    }

    /// The wheels' speeds (v_w, ω_w) of state (or state integral) `z` ([`Self::wheel_rows`]).
    fn wheels(&self, z: &[f64; 4]) -> [f64; 2] {
        let z = nalgebra::Vector4::from(*z);
        self.wheel_rows().map(|r| (r * z)[0])
    }

    /// The state in grip whose wheels run at (v, ω): the body at the contacts' speeds
    /// ρ m_R, m_L.
    fn gripping(&self, (v, w): (f64, f64)) -> [f64; 4] {
        let h = self.half;
        let (cr, cl) = (self.rho * (v + h * w), v - h * w);
        [0.5 * (cr + cl), 0.5 * (cr - cl) / h, 0.0, 0.0]
    }
}

impl Extended {
    /// The simulation of the module doc under the traction stage `tr` on the recording's
    /// samples: the wheels' speeds (v̂, ω̂), starting in grip at `initial`.
    ///
    /// # Errors
    /// As [`super::Extended::simulate`]: a bad initial state or grid.
    pub(super) fn integrate_traction(
        &self,
        th0: &[f64; 6],
        ph: &Terms,
        forces: &Forces,
        rec: &Recording,
        initial: &[f64],
        tr: &Traction,
    ) -> Result<[Vec<f64>; 2]> {
        let run = Run::new(self.track, th0, ph, rec, initial)?;
        let (v0, w0, hold, pipe) = (run.v0, run.w0, run.hold, &run.pipe);
        let mut cursor = CommandCursor::new(rec, hold);
        let mut command = |tau: f64| {
            let c = cursor.at(tau);
            Cmd::<0>::at([c.0, c.1], [[]; 2], false)
        };
        // A larger tyre acts at its contact (`Contact::rho`): the motor's effort turns its
        // wheel whole, and the wheel's own inertia is not seen through the tyre.
        let rho = ph.right_row.map_or(1.0, |r| 1.0 / r);
        let mut at_rims = *ph;
        at_rims.right_row = None;
        if let Some(w) = at_rims.wheels.as_mut() {
            w.right_lever *= rho;
        }
        let field = Field::new(forces, self.track, &at_rims);
        let prepare = |th: [f64; 6]| {
            let contact = Contact::new(tr, &th, self.track, rho);
            let tau = (th[0] / th[3]).abs().min((th[1] / th[5]).abs());
            let h = (tau / STEPS_PER_TAU).min(dynamics::substep(&th));
            (th, [1.0 / th[0], 1.0 / th[1]], contact, h)
        };
        let (before, after) = (prepare(*th0), run.th_after.map(prepare));
        let mut setpoint = if ph.accel.is_some() {
            Cmd::at([hold.0, hold.1], [[]; 2], false)
        } else {
            pipe.target(command(pipe.t0 - ph.dead_time()))
        };
        let mut z = before.2.gripping((v0, w0));
        let mut y: [Vec<f64>; 2] = [vec![v0], vec![w0]];
        for i in 1..run.grid.len() {
            let (ta, tb) = (run.grid[i - 1], run.grid[i]);
            let span = tb - ta;
            let (th, inv, contact, h_max) = run.in_force(ta, tb, before, after);
            let (ca, cb) = run.commands(ta, tb, &mut command);
            let n = (span / h_max).ceil().max(1.0) as usize;
            let h = span / n as f64;
            let mut q = [0.0; 4];
            for k in 0..n {
                let (f0, f1) = (k as f64 / n as f64, (k + 1) as f64 / n as f64);
                let times = (ta + f0 * span, ta + f1 * span);
                let (u0, u1) = pipe.substep(&mut setpoint, (ca, cb), (f0, f1), h, times);
                let rhs = |x: &[f64; 4], c: &Cmd<0>, jac: bool| {
                    contact.rhs(&th, x, |vw, jac| field.local(&th, &inv, vw, c, jac), jac)
                };
                let start = rhs(&z, &u0, true);
                ros2_step(|x, c| rhs(x, c, false).0, start, &mut z, &mut q, &u1, h);
            }
            if z.iter().any(|x| !x.is_finite()) {
                return Err(wheelid_core::Error::InvalidSetting(
                    "the traction model does not simulate (finitely)".into(),
                ));
            }
            let out = if run.avg {
                contact.wheels(&q).map(|x| x / span)
            } else {
                contact.wheels(&z)
            };
            y[0].push(out[0]);
            y[1].push(out[1]);
        }
        Ok(to_samples(&y, &run.grid, &run.index, run.avg))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::effects::Candidate;
    use wheelid_core::DynamicModel;

    /// The Schur-complement solve of W = I − gJ against nalgebra's pivoted LU, on a stiff J
    /// with a zero body block (as the contact's): agreement to rounding.
    #[test]
    fn ros2_matrix_solves_as_lu_does() {
        let jac = nalgebra::Matrix4::new(
            0.0, 0.0, 812.0, 790.0, //
            0.0, 0.0, 3100.0, -2950.0, //
            -35.0, 2.0, -9.4e4, 1.2e3, //
            -33.0, -1.5, 1.1e3, -9.1e4,
        );
        let g = 1.7e-3;
        let w = nalgebra::Matrix4::identity() - g * jac;
        let r = [0.3, -1.2, 45.0, -7.5];
        let x = Ros2Matrix::new(&jac, g).expect("invertible").solve(r);
        let lu = w
            .lu()
            .solve(&nalgebra::Vector4::from(r))
            .expect("invertible");
        for i in 0..4 {
            assert!(
                (x[i] - lu[i]).abs() <= 1e-12 * lu[i].abs().max(1.0),
                "{i}: {x:?} {lu}"
            );
        }
        // W x = r closes to rounding.
        let back = w * nalgebra::Vector4::from(x);
        for i in 0..4 {
            assert!((back[i] - r[i]).abs() < 1e-10, "{back} {r:?}");
        }
        // A singular complement is refused: D = C B (here g = 0 gives W = I, never singular;
        // J chosen so that S = 0).
        let sing = nalgebra::Matrix4::new(
            0.0, 0.0, 0.0, 0.0, //
            0.0, 0.0, 0.0, 0.0, //
            0.0, 0.0, 1.0, 0.0, //
            0.0, 0.0, 0.0, 1.0,
        );
        assert!(Ros2Matrix::new(&sing, 1.0).is_none());
    }

    /// A straight drive: θ3 = θ5 = 0, θ4 = θ6 = 1.
    const THETA: [f64; 6] = [0.26, 0.25, 0.0, 1.0, 0.0, 1.0];

    fn recording(n: usize, dt: f64, f: impl Fn(f64) -> (f64, f64)) -> Recording {
        let t: Vec<f64> = (0..n).map(|k| k as f64 * dt).collect();
        let (vr, wr): (Vec<f64>, Vec<f64>) = t.iter().map(|&x| f(x)).unzip();
        let mut rec = Recording::new("x", t, vr, wr, vec![0.0; n], vec![0.0; n]).expect("valid");
        rec.set_meta("command_hold", "zoh");
        rec
    }

    fn traction(theta: &[f64; 6], a: f64, eps: f64, p: f64, rec: &Recording) -> Vec<Vec<f64>> {
        let e = Extended::new(&[Candidate::TRACTION_LIMIT], 0.33).expect("model");
        let mut th = theta.to_vec();
        th.extend([a, eps, 1.0, p]);
        e.simulate(&th, rec, &[0.0, 0.0]).expect("sim")
    }

    /// In grip the wheels and the body move as one: eq. 2.19 up to the grip's compliance,
    /// the wheels leading by ≈ 2 % of τ (|Δv| ≤ 0.03 τ max|v̇|).
    #[test]
    fn in_grip_it_is_eq_2_19() {
        let rec = recording(200, 0.1, |x| {
            (0.3 + 0.2 * (0.9 * x).sin(), 0.5 * (0.5 * x).cos())
        });
        let plain = Extended::new(&[], 0.33)
            .expect("model")
            .simulate(&THETA, &rec, &[0.0, 0.0])
            .expect("sim");
        let got = traction(&THETA, 50.0, 0.1, 0.2, &rec);
        for ch in 0..2 {
            let accel = plain[ch]
                .windows(2)
                .fold(0.0f64, |m, w| m.max((w[1] - w[0]).abs() / 0.1));
            let tau = THETA[ch] / THETA[3 + 2 * ch];
            for k in 0..rec.len() {
                let d = (got[ch][k] - plain[ch][k]).abs();
                assert!(d <= 0.03 * tau * accel + 1e-6, "ch {ch} k {k}: {d}");
            }
        }
    }

    /// A step to 1 m/s beyond the grip (a_max = 0.2 m/s²): the wheels spin up alone (inertia
    /// ε θ1) to the plateau (u − c)/θ4, c = (1 − ε) θ1 a_max, while the body accelerates at
    /// a_max; they grip again when the body reaches the wheels, at t* = plateau / a_max, and then
    /// rise with the whole inertia to u/θ4. A load transfer p scales the limit while both
    /// wheels slip forward by 1/(1 − p): c and a_max become c/(1 − p), a_max/(1 − p).
    /// (Closed forms of the two-inertia model with a saturated contact.)
    #[test]
    fn beyond_the_grip_the_wheels_run_ahead_until_the_body_catches_up() {
        for p in [0.0, 0.2, -0.2] {
            beyond_the_grip(p);
        }
    }

    /// The closed forms above under load transfer `p`: a fitted a_max of 0.2 m/s² is
    /// 0.2/(1 − p) while both wheels slip forward.
    fn beyond_the_grip(p: f64) {
        let (a, eps, u) = (0.2 / (1.0 - p), 0.1, 1.0);
        let rec = recording(1000, 0.02, |_| (u, 0.0));
        let v = &traction(&THETA, 0.2, eps, p, &rec)[0];
        let c = (1.0 - eps) * THETA[0] * a;
        let plateau = (u - c) / THETA[3];
        let t_grip = plateau / a;
        for (k, &vk) in v.iter().enumerate() {
            let t = rec.t[k];
            if t > 10.0 * eps * THETA[0] && t < t_grip - 0.3 {
                approx::assert_abs_diff_eq!(vk, plateau, epsilon = 2e-3);
            }
            if t > t_grip + 8.0 * THETA[0] {
                approx::assert_abs_diff_eq!(vk, u / THETA[3], epsilon = 2e-3);
            }
        }
        // The plateau ends near t*: a little before it, as the contact's compliance lets the
        // traction fall off over the last few s0 of slip (≈ 0.1 s here).
        let end = v
            .iter()
            .position(|&x| x > plateau + 1e-3)
            .map(|k| rec.t[k])
            .expect("the plateau ends");
        assert!(
            end > t_grip - 0.15 && end <= t_grip,
            "p {p}: {end} vs {t_grip}"
        );
    }

    /// A larger right tyre ρ on the same step beyond the grip: the right contact turns its
    /// wheel back by ρ c, the left by c, while the motor's effort turns each wheel whole. With
    /// both wheels slipping the body goes straight at a_max, and the rims hold at
    /// v_w = (u − (1 + ρ) c/2)/θ4 and ω_w = −(ρ − 1) c/(2κ θ6), κ = d/2: the larger tyre's rim
    /// runs slower. (Closed forms of the two-inertia model with a saturated contact; the tyre
    /// composed as the tyre alone, effort over ρ and its chassis row scaled, gives other
    /// plateaus.)
    #[test]
    fn beyond_the_grip_a_larger_tyre_turns_its_rim_back_by_its_radius() {
        let (a, eps, u, rho, d) = (0.2, 0.1, 1.0, 1.05, 0.33);
        let rec = recording(1000, 0.02, |_| (u, 0.0));
        let model = Extended::new(&[Candidate::TRACTION_LIMIT, Candidate::TYRE_ASYMMETRY], d)
            .expect("model");
        let mut th = THETA.to_vec();
        th.extend([a, eps, 1.0, 0.0, rho]);
        let y = model.simulate(&th, &rec, &[0.0, 0.0]).expect("sim");
        let c = (1.0 - eps) * THETA[0] * a;
        let v_plateau = (u - 0.5 * (1.0 + rho) * c) / THETA[3];
        let w_plateau = -(rho - 1.0) * c / (d * THETA[5]);
        let t_grip = v_plateau / a;
        let mut checked = 0;
        for (k, &t) in rec.t.iter().enumerate() {
            if t > 10.0 * eps * THETA[0] && t < 0.8 * t_grip {
                approx::assert_abs_diff_eq!(y[0][k], v_plateau, epsilon = 2e-3);
                approx::assert_abs_diff_eq!(y[1][k], w_plateau, epsilon = 3e-4);
                checked += 1;
            }
        }
        assert!(checked > 100 && w_plateau < -5e-3, "{checked} {w_plateau}");
    }

    /// ROS2's Jacobian ∂ż/∂z (the contact's by hand, the field's from [`Field::local`]) is the
    /// right-hand side's central differences, in grip, on the grip's knee and in slip, with
    /// dry friction and slip terms in the field, with equal tyres and with a larger right one
    /// (ρ = 1.05: its contact's speed and lever).
    #[test]
    fn the_contacts_jacobian_is_its_differences() {
        let ph = Terms {
            coulomb: [0.02, 0.1],
            slip: [0.1, 0.2],
            ..Terms::default()
        };
        let field = Field::new(&Vec::new(), 0.33, &ph);
        let th = [0.26, 0.25, 0.02, 1.0, 0.05, 1.0];
        let tr = Traction {
            accel_max: 0.5,
            wheel_share: 0.15,
            mix: 1.2,
            load_transfer: 0.2,
        };
        let inv = [1.0 / th[0], 1.0 / th[1]];
        let c = Cmd::<0>::at([0.4, 0.3], [[]; 2], false);
        for rho in [1.0, 1.05] {
            let contact = Contact::new(&tr, &th, 0.33, rho);
            jacobian_matches_differences(&contact, &|z: &[f64; 4], jac| {
                contact.rhs(&th, z, |vw, jac| field.local(&th, &inv, vw, &c, jac), jac)
            });
        }
    }

    /// The contact's ż and ∂ż/∂z at a state, with or without the Jacobian.
    type ContactRhs<'a> = dyn Fn(&[f64; 4], bool) -> ([f64; 4], nalgebra::Matrix4<f64>) + 'a;

    /// `rhs`'s Jacobian against its central differences at three states of `contact` (in
    /// grip, on the knee, in slip), to 1e-6 of its largest entry.
    fn jacobian_matches_differences(contact: &Contact, rhs: &ContactRhs<'_>) {
        let s0 = contact.s0;
        for z in [
            [0.3, 0.2, 0.1 * s0, -0.05 * s0],
            [0.3, -0.2, 0.7 * s0, -1.3 * s0],
            [-0.1, 0.4, 5.0 * s0, 0.2 * s0],
        ] {
            let (_, j) = rhs(&z, true);
            let scale = j.amax();
            for col in 0..4 {
                let d = 1e-6 * s0;
                let (mut up, mut down) = (z, z);
                up[col] += d;
                down[col] -= d;
                let (fu, fd) = (rhs(&up, false).0, rhs(&down, false).0);
                for row in 0..4 {
                    let central = (fu[row] - fd[row]) / (2.0 * d);
                    let err = (j[(row, col)] - central).abs();
                    assert!(
                        err <= 1e-6 * scale,
                        "ρ {} z {z:?} ({row}, {col}): {err} of {scale}",
                        contact.rho
                    );
                }
            }
        }
    }

    /// The cost a fit descends is smooth in the parameters (the reason for
    /// [`STEPS_PER_TAU`]): 60 s at 10 Hz of a Pioneer-like θ whose commands ask more than
    /// the floor's 0.35 m/s², compared with its own simulation at a load transfer of 0.03; as
    /// the load transfer steps by 0.002 from 0 to 0.06 the squared error must fall, then rise,
    /// no step's slope falling by more than a fifth of the largest change between steps (at
    /// τ/40 sub-steps it does).
    #[test]
    fn the_fits_cost_is_smooth_in_the_load_transfer() {
        let rec = recording(600, 0.1, |x| {
            let v = 0.4 * (0.7 * x).sin() + 0.3 * (2.3 * x + 1.0).sin() + 0.2 * (5.1 * x).sin();
            let w = 0.8 * (1.1 * x).cos() + 0.6 * (3.7 * x + 0.5).sin();
            (v, w)
        });
        let th = [0.26, 0.25, 0.005, 1.003, 0.1, 1.01];
        let data = traction(&th, 0.35, 0.1, 0.03, &rec);
        let cost: Vec<f64> = (0..=30)
            .map(|i| {
                let y = traction(&th, 0.35, 0.1, 0.002 * i as f64, &rec);
                (0..2)
                    .map(|c| {
                        (0..rec.len())
                            .map(|k| (y[c][k] - data[c][k]).powi(2))
                            .sum::<f64>()
                    })
                    .sum()
            })
            .collect();
        let steps: Vec<f64> = cost.windows(2).map(|w| w[1] - w[0]).collect();
        let scale = steps.iter().fold(0.0f64, |m, d| m.max(d.abs()));
        let kinks = steps
            .windows(2)
            .filter(|w| w[1] - w[0] < -0.2 * scale)
            .count();
        assert!(
            cost[15] < 1e-20 && cost[0] > 0.0 && cost[30] > 0.0,
            "{cost:?}"
        );
        assert_eq!(kinks, 0, "{cost:?}");
    }

    /// The traction stage has no sensitivity equations: every column comes by differences,
    /// and they agree with central differences of the simulation.
    #[test]
    fn its_sensitivities_are_the_simulations_differences() {
        let rec = recording(300, 0.02, |x| {
            (0.8 * (x * 2.0).sin(), 2.0 * (x * 1.3).cos())
        });
        let e = Extended::new(&[Candidate::TRACTION_LIMIT], 0.33).expect("model");
        let mut th = THETA.to_vec();
        th.extend([0.5, 0.15, 1.2, 0.2]);
        let (y, s) = e
            .sensitivities_of(&th, &rec, &[0.0, 0.0], &[0, 6, 7, 9])
            .expect("sens");
        for (a, &j) in [0usize, 6, 7, 9].iter().enumerate() {
            let h = 1e-4 * th[j].abs();
            let (mut up, mut down) = (th.clone(), th.clone());
            up[j] += h;
            down[j] -= h;
            let yu = e.simulate(&up, &rec, &[0.0, 0.0]).expect("sim");
            let yd = e.simulate(&down, &rec, &[0.0, 0.0]).expect("sim");
            for c in 0..2 {
                let scale = (0..rec.len()).fold(1e-9f64, |m, k| m.max(s.theta[c][(k, a)].abs()));
                for k in 0..rec.len() {
                    let central = (yu[c][k] - yd[c][k]) / (2.0 * h);
                    let d = (s.theta[c][(k, a)] - central).abs();
                    assert!(d <= 0.02 * scale, "column {j} ch {c} k {k}: {d} of {scale}");
                }
            }
        }
        assert_eq!(y.len(), 2);
    }
}
