//! The wheels' efforts in the field ([`wheelid_core::WheelTerms`]): each wheel's share of the
//! speed loop's effort, scaled by its amplifier, clamped at its supply, pushing the chassis
//! through its tyre — with the loop's derivative term, which a clamp takes away.
//!
//! With E = (E_v, E_ω) = u − g (v, ω) the loop's efforts of eq. 2.19 and O = (O_v, O_ω) every
//! other generalised force of the field (θ3 ω² − (θ4 − 1) v, friction, slip, the effects'
//! forces), the wheels' efforts are W_R = γ (E_v + κ E_ω), W_L = E_v − κ E_ω (γ = `right_gain`,
//! κ = `mix` · d/2), each pushes the chassis with a lever l_R = `right_lever`, l_L = 1, and with
//! t_R,L = (1, ±κ), q_R,L = (1/2, ±1/(2κ)) the wheels' rows and their recombination
//! (Σ_i q_i t_iᵀ = I). The derivative term δ = `derivative` \[s\] is K_D/K_P (K_DT/K_PT for the
//! v/ω loop, Appendix A.3; k_D/k_P for the wheel loop, §2.2): eq. 2.19's θ1, θ2 hold it (§2.2:
//! θ1 = (R_a R_t m + 2 k_a k_D + 2 I_e R_a)/(2 k_a k_P)), and a wheel's voltage, in effort units,
//! is its proportional effort less δ times its rim's acceleration. For the state's
//! accelerations x = (v̇, ω̇):
//!
//! ```text
//! diag(θ1 − δ, θ2 − δ) x = Σ_i q_i l_i ē_i + O
//! e_i = W_i − (δ/l_i) t_iᵀ x,     ē_i = clamp(dz(e_i), −c, c)  (c = `effort_max`)
//! dz(e) = 0 for |e| < β,  e − β sign(e) beyond                  (β = `effort_dead`)
//! ```
//!
//! Where no wheel is clamped this is eq. 2.19 with the wheels' gains, diag(θ1, θ2) x =
//! Σ_i q_i l_i W_i + O, whatever δ; where a wheel is clamped its derivative term is gone with
//! its feedback, so it accelerates the inertia θ − δ, not θ (with δ = 0, a clamp in effort
//! units comes out c/(1 − δ/θ1): about 10 % high on a Pioneer-like loop, and wrong after a
//! payload moves θ1). The clamped set C is the one where each clamped wheel's e_i is beyond
//! ±c and each other one within it (found from the unclamped solution, ≤ 4 passes); a wheel
//! within its dead band is held at 0 with it (its voltage, derivative term and all, is gone),
//! one beyond it follows with the offset ∓β added to its W_i in b below; and
//!
//! ```text
//! M x = b,   M = diag(θ1 − δ, θ2 − δ) + δ Σ_{i∉C} q_i t_iᵀ,
//!            b = O + Σ_{i∉C} q_i l_i W_i + Σ_{i∈C} q_i l_i c sign(e_i)
//! ```
//!
//! The field adds Δ = θ∘x − (E + O) to eq. 2.19's right-hand sides. With P = diag(θ) M⁻¹ and
//! B = Σ_{i∉C} q_i l_i γ_i t_iᵀ (γ_L = 1): ∂Δ/∂u = P B − I, ∂Δ/∂(v, ω) = P (−g B + ∂O/∂(v, ω))
//! − (−g I + ∂O/∂(v, ω)), ∂Δ/∂θ1 = (I − P)(v̇, 0), ∂Δ/∂θ2 = (I − P)(0, ω̇), ∂Δ/∂θk =
//! (P − I) ∂O/∂θk for k = 3…6. With δ = 0 (or no wheel clamped) P = I and Δ depends on E only.

use wheelid_core::WheelTerms;

/// A 2 × 2 matrix, rows first.
type M2 = [[f64; 2]; 2];

/// The derivative term's largest share of min(θ1, θ2) the solve takes (a larger one is held
/// there): the clamped inertia θ − δ stays ≥ half of θ.
const MAX_DERIVATIVE_SHARE: f64 = 0.5;

/// The wheels' correction Δ of eq. 2.19's right-hand sides and its derivatives (module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct WheelForce {
    /// Δ = (Δ_v, Δ_ω) [m/s, rad/s].
    pub d: [f64; 2],
    /// ∂Δ/∂(v, ω): rows Δ_v, Δ_ω.
    pub dx: M2,
    /// ∂Δ/∂u (u the commands after the pipeline).
    pub du: M2,
    /// ∂Δ/∂θ1…θ6 (rows Δ_v, Δ_ω); `None`: zero (no wheel clamped with a derivative term).
    pub dth: Option<[[f64; 6]; 2]>,
}

/// The other forces O at one state: O, ∂O/∂(v, ω) and ∂O/∂θ3…θ6 (columns, each (O_v, O_ω));
/// the derivatives are zeros where the caller needs none (a plain simulation), and so are the
/// derivatives of the [`WheelForce`] made from them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Others {
    pub o: [f64; 2],
    pub jac: M2,
    pub theta: [[f64; 2]; 4],
}

fn mul(a: &M2, b: &M2) -> M2 {
    std::array::from_fn(|r| std::array::from_fn(|c| a[r][0] * b[0][c] + a[r][1] * b[1][c]))
}

fn apply(a: &M2, x: [f64; 2]) -> [f64; 2] {
    [
        a[0][0] * x[0] + a[0][1] * x[1],
        a[1][0] * x[0] + a[1][1] * x[1],
    ]
}

fn inverse(m: &M2) -> M2 {
    let det = m[0][0] * m[1][1] - m[0][1] * m[1][0];
    [
        [m[1][1] / det, -m[0][1] / det],
        [-m[1][0] / det, m[0][0] / det],
    ]
}

/// The wheels' efforts of `wt` (its `mix` as κ \[m\]) for drive gain `g`, loop efforts `e`,
/// other forces `others` and θ1, θ2 = `th` (module docs).
pub(super) fn wheel_force(
    wt: &WheelTerms,
    g: f64,
    e: [f64; 2],
    others: &Others,
    th: [f64; 2],
) -> WheelForce {
    let delta = wt.derivative.min(MAX_DERIVATIVE_SHARE * th[0].min(th[1]));
    if delta > 0.0 && (wt.effort_max.is_finite() || wt.effort_dead > 0.0) {
        let free = WheelTerms {
            effort_max: f64::INFINITY,
            effort_dead: 0.0,
            ..*wt
        };
        let unclamped = proportional(&free, g, e);
        let x0 = [0, 1].map(|k| (e[k] + others.o[k] + unclamped.d[k]) / th[k]);
        if let Some(set) = clamped_set(wt, e, others, th, delta, x0) {
            return derivative_clamped(wt, g, e, others, th, delta, set);
        }
        return unclamped;
    }
    proportional(wt, g, e)
}

/// What a wheel's effort does at voltage (effort) `e`: follows it less the dead band
/// (`Follow(offset)`, the offset ∓β), or is held at a value (`Held`: 0 within the band, ±c
/// at the clamp), for dead band β = `wt.effort_dead` and clamp c = `wt.effort_max`.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Wheel {
    Follow(f64),
    Held(f64),
}

impl Wheel {
    fn of(wt: &WheelTerms, e: f64) -> Self {
        let (b, cl) = (wt.effort_dead, wt.effort_max);
        if e.abs() < b {
            Wheel::Held(0.0)
        } else if e.abs() - b >= cl {
            Wheel::Held(cl.copysign(e))
        } else {
            Wheel::Follow(-b.copysign(e))
        }
    }

    /// The effort it drives at voltage `e`.
    fn effort(self, e: f64) -> f64 {
        match self {
            Wheel::Follow(off) => e + off,
            Wheel::Held(c) => c,
        }
    }
}

/// The wheels' efforts without a derivative term (δ = 0): each wheel's effort less its dead
/// band and clamped as it is (module docs with δ = 0), Δ = Ē − E, depending on E only.
pub(super) fn proportional(wt: &WheelTerms, g: f64, e: [f64; 2]) -> WheelForce {
    let (gain, kappa, lever) = (wt.right_gain, wt.mix, wt.right_lever);
    let wheels = [gain * (e[0] + kappa * e[1]), e[0] - kappa * e[1]];
    let states = wheels.map(|w| Wheel::of(wt, w));
    let clamped = [
        lever * states[0].effort(wheels[0]),
        states[1].effort(wheels[1]),
    ];
    let ev = 0.5 * (clamped[0] + clamped[1]);
    let ew = (clamped[0] - clamped[1]) / (2.0 * kappa);
    // Each wheel's slope on its own error: its gain where it follows, 0 where it is held.
    let [fr, fl] = [0, 1].map(|i| match states[i] {
        Wheel::Follow(_) => [gain * lever, 1.0][i],
        Wheel::Held(_) => 0.0,
    });
    let (sum, diff) = (0.5 * (fr + fl), 0.5 * (fr - fl));
    let dx = [
        [g * (1.0 - sum), -g * kappa * diff],
        [-g * diff / kappa, g * (1.0 - sum)],
    ];
    WheelForce {
        d: [ev - e[0], ew - e[1]],
        dx,
        du: dx.map(|row| row.map(|d| -d / g)),
        dth: None,
    }
}

/// Wheel i's (amplifier gain, lever, row t_i, recombination q_i) for κ.
fn wheel(wt: &WheelTerms, i: usize) -> (f64, f64, [f64; 2], [f64; 2]) {
    let (s, k) = ([1.0, -1.0][i], wt.mix);
    let (gain, lever) = [(wt.right_gain, wt.right_lever), (1.0, 1.0)][i];
    (gain, lever, [1.0, s * k], [0.5, s * 0.5 / k])
}

/// The clamped set (each wheel's [`Wheel`] state) from the unclamped accelerations `x0`:
/// each wheel's state at its voltage e_i, then passes until every state is its voltage's
/// (≤ 4); `None` where every wheel follows its voltage whole.
fn clamped_set(
    wt: &WheelTerms,
    e: [f64; 2],
    others: &Others,
    th: [f64; 2],
    delta: f64,
    x0: [f64; 2],
) -> Option<[Wheel; 2]> {
    let voltage = |i: usize, x: [f64; 2]| {
        let (gain, lever, t, _) = wheel(wt, i);
        let w = gain * (e[0] + t[1] * e[1]);
        w - delta / lever * (t[0] * x[0] + t[1] * x[1])
    };
    let whole = [Wheel::Follow(0.0); 2];
    let mut set = whole;
    let mut x = x0;
    for _ in 0..4 {
        let next = [0, 1].map(|i| Wheel::of(wt, voltage(i, x)));
        if next == set {
            break;
        }
        set = next;
        if set == whole {
            break;
        }
        let (m, b, _) = system(wt, e, others, th, delta, &set);
        x = apply(&inverse(&m), b);
    }
    (set != whole).then_some(set)
}

/// M, b and B (module docs) for the clamped set `set`.
fn system(
    wt: &WheelTerms,
    e: [f64; 2],
    others: &Others,
    th: [f64; 2],
    delta: f64,
    set: &[Wheel; 2],
) -> (M2, [f64; 2], M2) {
    let mut m = [[th[0] - delta, 0.0], [0.0, th[1] - delta]];
    let mut b = others.o;
    let mut bu = [[0.0; 2]; 2];
    for (i, s) in set.iter().enumerate() {
        let (gain, lever, t, q) = wheel(wt, i);
        match *s {
            Wheel::Held(c) => {
                for r in 0..2 {
                    b[r] += q[r] * lever * c;
                }
            }
            Wheel::Follow(off) => {
                let w = gain * (e[0] + t[1] * e[1]) + off;
                for r in 0..2 {
                    b[r] += q[r] * lever * w;
                    for k in 0..2 {
                        m[r][k] += delta * q[r] * t[k];
                        bu[r][k] += q[r] * lever * gain * t[k];
                    }
                }
            }
        }
    }
    (m, b, bu)
}

/// Δ and its derivatives (module docs) with a derivative term `delta` and the clamped set
/// `set`.
fn derivative_clamped(
    wt: &WheelTerms,
    g: f64,
    e: [f64; 2],
    others: &Others,
    th: [f64; 2],
    delta: f64,
    set: [Wheel; 2],
) -> WheelForce {
    let (m, b, bu) = system(wt, e, others, th, delta, &set);
    let minv = inverse(&m);
    let x = apply(&minv, b);
    let p: M2 = std::array::from_fn(|r| minv[r].map(|a| th[r] * a));
    let eye = [[1.0, 0.0], [0.0, 1.0]];
    let pb = mul(&p, &bu);
    let du: M2 = std::array::from_fn(|r| std::array::from_fn(|k| pb[r][k] - eye[r][k]));
    let jo = others.jac;
    let db: M2 = std::array::from_fn(|r| std::array::from_fn(|k| -g * bu[r][k] + jo[r][k]));
    let pdb = mul(&p, &db);
    let dx: M2 =
        std::array::from_fn(|r| std::array::from_fn(|k| pdb[r][k] + g * eye[r][k] - jo[r][k]));
    let mut dth = [[0.0; 6]; 2];
    for (k, col) in [[x[0], 0.0], [0.0, x[1]]].into_iter().enumerate() {
        let pc = apply(&p, col);
        for r in 0..2 {
            dth[r][k] = col[r] - pc[r];
        }
    }
    for (k, col) in others.theta.iter().enumerate() {
        let pc = apply(&p, *col);
        for r in 0..2 {
            dth[r][2 + k] = pc[r] - col[r];
        }
    }
    WheelForce {
        d: [0, 1].map(|k| th[k] * x[k] - e[k] - others.o[k]),
        dx,
        du,
        dth: Some(dth),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One wheel clamped (the right, a weak amplifier and a larger tyre on it), the other
    /// following: the accelerations x = (E + O + Δ)/θ solve the module's equations — the
    /// right wheel's voltage beyond c and its effort c, the left one's voltage
    /// W_L − δ t_Lᵀ x within c and its effort that voltage — and where δ = 0 it is the
    /// proportional clamp. Both wheels following (a small effort), Δ is δ's-free.
    #[test]
    fn a_clamped_wheel_loses_its_derivative_term_and_the_other_keeps_it() {
        let (th, delta, cl) = ([0.26, 0.25], 0.0227, 0.12);
        let wt = WheelTerms {
            right_gain: 0.95,
            effort_max: cl,
            effort_dead: 0.0,
            mix: 0.14,
            right_lever: 1.0 / 1.03,
            derivative: delta,
        };
        let others = Others {
            o: [0.01, -0.02],
            jac: [[0.0; 2]; 2],
            theta: [[0.0; 2]; 4],
        };
        let e = [0.12, 0.5];
        let f = wheel_force(&wt, 1.0, e, &others, th);
        let x = [0, 1].map(|k| (e[k] + others.o[k] + f.d[k]) / th[k]);
        let (_, lever_r, t_r, q_r) = wheel(&wt, 0);
        let (_, _, t_l, q_l) = wheel(&wt, 1);
        let w_r = wt.right_gain * (e[0] + t_r[1] * e[1]);
        let w_l = e[0] + t_l[1] * e[1];
        let volt_r = w_r - delta / lever_r * (t_r[0] * x[0] + t_r[1] * x[1]);
        let volt_l = w_l - delta * (t_l[0] * x[0] + t_l[1] * x[1]);
        assert!(volt_r > cl && volt_l.abs() < cl, "{volt_r} {volt_l}");
        for r in 0..2 {
            let lhs = (th[r] - delta) * x[r];
            let rhs = q_r[r] * lever_r * cl + q_l[r] * volt_l + others.o[r];
            approx::assert_relative_eq!(lhs, rhs, epsilon = 1e-12);
        }
        let none = WheelTerms {
            derivative: 0.0,
            ..wt
        };
        assert_eq!(
            wheel_force(&none, 1.0, e, &others, th),
            proportional(&none, 1.0, e)
        );
        let small = [0.01, 0.02];
        let (with, without) = (
            wheel_force(&wt, 1.0, small, &others, th),
            proportional(&none, 1.0, small),
        );
        assert_eq!(
            (with.d, with.dx, with.du),
            (without.d, without.dx, without.du)
        );
    }
}
