//! The output-error form's simulated outputs: eq. 2.19 integrated at θ̂ over each period the
//! stamps actually span, as the batch output-error fit simulates it
//! (`wheelid_models::dynamics`: classical RK4, window integrals by the same stages; here at
//! half the faster time constant, two sub-steps a period at least: [`SUBSTEPS_PER_TAU`]), so
//! that the recursion and the batch fit compare the robot with the same model:
//!
//! ```text
//! θ1 v̇ = v_ref − θ4 v + θ3 ω²,   θ2 ω̇ = ω_ref − θ6 ω − θ5 v ω,   (v_ref, ω_ref) held over [s_k, s_{k+1})
//! ŷ_{k+1} = x(s_{k+1})                          instants (a)
//! ŷ_{k+1} = (1/T_k) ∫_{s_k}^{s_{k+1}} x dt      window averages (b)
//! ```
//!
//! The sampled difference equation with the coupling's trapezoidal mean (module docs of
//! [`super`]) errs by 3·10⁻⁴ of θ2 on the rigid-body Pioneer-like robot (2–3 standard errors of
//! the batch answer), where the coupling θ5 v ω is a fifth of the ω channel's damping; so does
//! an exponential integrator with the coupling ramped over the period, and one with the ω
//! pole frozen at v's mean over it errs by 1.5·10⁻⁴ of θ6 (measured, tuning seeds 1–5).

use wheelid_models::dynamics::rk4_step;

use super::Split;
use super::split::Rates;

/// RK4 sub-steps per time constant of the faster channel, and at least [`MIN_SUBSTEPS`] a
/// period. The batch simulation takes 5 (at most 20 ms apart). Measured against the batch
/// answer on the rigid-body robots (tuning seeds 1–5, ± 10 % jitter): 3 a time constant moves
/// the online θ by at most 0.05 of its standard errors from 5's; 2 (with two a period at
/// least) by at most 0.1 more on the Khepera-like robot and nothing on the Pioneer-like one;
/// 2 with one a period allowed (the Pioneer-like robot's 0.1 s against its 0.25 s) by up to
/// 1.4 standard errors. Each sub-step costs about 30 ns.
const SUBSTEPS_PER_TAU: f64 = 2.0;

/// Fewest RK4 sub-steps a period.
const MIN_SUBSTEPS: usize = 2;

/// Most RK4 sub-steps a period.
const MAX_SUBSTEPS: usize = 12;

/// The simulated robot between samples.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Flow {
    /// (v, ω) at the last sample instant \[m/s, rad/s\].
    x: [f64; 2],
    /// Periods advanced since the start.
    age: u64,
    /// Periods after which the start's transient has died out.
    settle: u64,
}

impl Flow {
    /// A simulation started at the state `x` (the measured velocities: the transient of the
    /// difference, and of the gradient started at zero, dies out at the robot's own time
    /// constants: five of the slower of θ's, over periods of `dt` \[s\], at least five).
    pub(super) fn start(x: [f64; 2], rates: [Rates; 2], dt: f64) -> Self {
        let tau = 1.0 / rates[0].pole.min(rates[1].pole);
        let settle = (5.0 * tau / dt).ceil();
        Self {
            x,
            age: 0,
            settle: if settle.is_finite() {
                (settle as u64).max(5)
            } else {
                5
            },
        }
    }

    /// Whether the start's transient has died out: from then on the simulated outputs are the
    /// model's response to the commands alone.
    pub(super) fn settled(&self) -> bool {
        self.age >= self.settle
    }

    /// Advances over `period` \[s\] under the held command `u` = (v_ref, ω_ref) at the channels'
    /// `rates` (ẏ = r (K u + C n − y), n = ω², v ω: eq. 2.19 divided through by θ4, θ6) and
    /// returns the outputs the stamping `split` reports (window averages for
    /// [`Split::WindowAverage`], else the instants).
    pub(super) fn advance(
        &mut self,
        rates: [Rates; 2],
        u: [f64; 2],
        period: f64,
        split: Split,
    ) -> [f64; 2] {
        let [v, w] = rates;
        let steps = ceil_count(period * SUBSTEPS_PER_TAU * v.pole.max(w.pole))
            .clamp(MIN_SUBSTEPS, MAX_SUBSTEPS);
        let h = period / steps as f64;
        // r (K u + C n − y) with the products of constants taken once (each RK4 stage is then
        // two multiply-adds deep).
        let forced = [v.pole * v.gain * u[0], w.pole * w.gain * u[1]];
        let coupled = [v.pole * v.coupling, w.pole * w.coupling];
        let f = |x: &[f64; 2], _: (f64, f64)| {
            [
                (forced[0] - v.pole * x[0]) + coupled[0] * (x[1] * x[1]),
                (forced[1] - w.pole * x[1]) + coupled[1] * (x[0] * x[1]),
            ]
        };
        let mut integral = [0.0; 2];
        let mut x1 = self.x;
        for _ in 0..steps {
            rk4_step(f, &mut x1, &mut integral, (u[0], u[1]), (u[0], u[1]), h);
        }
        self.x = x1;
        self.age += 1;
        match split {
            Split::WindowAverage => {
                let inv = 1.0 / period;
                integral.map(|q| q * inv)
            }
            Split::Instant | Split::Free => x1,
        }
    }
}

/// `x.ceil() as usize` (saturating; 0 for NaN and x ≤ 0) without a call to `ceil`, which
/// baseline x86-64 (no SSE4.1 rounding instruction) makes a library call once a sample.
fn ceil_count(x: f64) -> usize {
    let n = x as usize;
    if (n as f64) < x {
        n.saturating_add(1)
    } else {
        n
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The rates of θ (module docs).
    fn rates(t: &[f64; 6]) -> [Rates; 2] {
        [
            Rates {
                pole: t[3] / t[0],
                gain: 1.0 / t[3],
                coupling: t[2] / t[3],
            },
            Rates {
                pole: t[5] / t[1],
                gain: 1.0 / t[5],
                coupling: -t[4] / t[5],
            },
        ]
    }

    /// [`ceil_count`] is `ceil() as usize` wherever the latter is defined, and saturates alike.
    #[test]
    fn the_sub_step_count_rounds_up_as_ceil_does() {
        let mut xs = vec![
            f64::NAN,
            f64::NEG_INFINITY,
            -1.5,
            -0.0,
            0.0,
            f64::MIN_POSITIVE,
            1.0,
            1.0 + f64::EPSILON,
            2.0 - f64::EPSILON,
            9.007_199_254_740_993e15,
            1.8e19,
            1e300,
            f64::INFINITY,
        ];
        xs.extend((0..2000).map(|k| k as f64 * 0.0137));
        for x in xs {
            assert_eq!(ceil_count(x), x.ceil() as usize, "{x}");
        }
    }

    /// A linear channel (θ3 = θ5 = 0) under a held command: the instant and the window average
    /// against their closed forms, x(T) = K u + (x0 − K u) e^{−T/τ} and its mean
    /// K u + (x0 − K u) (τ/T)(1 − e^{−T/τ}), within RK4's error at a third of the time
    /// constant, (1/3)⁵/120 ≈ 3·10⁻⁵ of the deviation x0 − K u a step (measured 4·10⁻⁶).
    #[test]
    fn a_held_command_gives_the_closed_form() {
        let theta = [0.3, 0.2, 0.0, 1.2, 0.0, 0.8];
        let (u, x0, period) = ([0.6, -0.4], [0.1, 0.2], 0.1);
        for split in [Split::Instant, Split::WindowAverage] {
            let got = Flow::start(x0, rates(&theta), 0.1).advance(rates(&theta), u, period, split);
            for i in 0..2 {
                let (tau, gain) = (theta[i] / theta[[3, 5][i]], 1.0 / theta[[3, 5][i]]);
                let e = (-period / tau).exp();
                let dev = x0[i] - gain * u[i];
                let want = match split {
                    Split::WindowAverage => gain * u[i] + dev * tau / period * (1.0 - e),
                    _ => gain * u[i] + dev * e,
                };
                let err = (got[i] - want).abs() / dev.abs();
                assert!(
                    err < 3e-5,
                    "{split:?} {i}: {} vs {want} ({err:.1e})",
                    got[i]
                );
            }
        }
    }

    /// The coupled eq. 2.19 (the rigid-body Pioneer's θ5 is a fifth of θ6) over 100 periods of
    /// a changing command, against `wheelid_models::dynamics`' RK4 at 1000 sub-steps a period:
    /// the instants and window averages within 2·10⁻⁵ m/s, rad/s (measured 1.3·10⁻⁵, about
    /// 10⁻⁵ of the 1.2 rad/s command: RK4 at a third of the time constant).
    #[test]
    fn the_coupled_model_follows_a_fine_integration() {
        use wheelid_models::dynamics::accel;
        let theta = [0.26, 0.25, 0.005, 1.0, 0.2, 1.0];
        let period = 0.1;
        let mut flow = Flow::start([0.0; 2], rates(&theta), period);
        let mut fine = [0.0f64; 2];
        let mut worst = 0.0f64;
        let f = |x: &[f64; 2], u: (f64, f64)| {
            let (dv, dw) = accel(&theta, x[0], x[1], u.0, u.1);
            [dv, dw]
        };
        for k in 0..100 {
            let t = k as f64 * period;
            let u = [0.4 + 0.3 * (1.7 * t).sin(), 1.2 * (2.3 * t).cos()];
            let (mut q, held) = ([0.0; 2], (u[0], u[1]));
            for _ in 0..1000 {
                rk4_step(f, &mut fine, &mut q, held, held, period / 1000.0);
            }
            let mean = flow.advance(rates(&theta), u, period, Split::WindowAverage);
            for i in 0..2 {
                worst = worst.max((mean[i] - q[i] / period).abs());
                worst = worst.max((flow.x[i] - fine[i]).abs());
            }
        }
        assert!(worst < 2e-5, "{worst:.2e}");
    }
}
