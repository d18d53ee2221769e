//! The output-error form's simulated outputs: eq. 2.19 integrated at θ̂ over each period the
//! stamps actually span, as the batch output-error fit simulates it
//! (`wheelid_models::dynamics`: classical RK4 at a fifth of the faster time constant, window
//! integrals by the same stages), so that the recursion and the batch fit compare the robot
//! with the same model:
//!
//! ```text
//! θ1 v̇ = v_ref − θ4 v + θ3 ω²,   θ2 ω̇ = ω_ref − θ6 ω − θ5 v ω,   (v_ref, ω_ref) held over [s_k, s_{k+1})
//! ŷ_{k+1} = x(s_{k+1})                          instants (a)
//! ŷ_{k+1} = (1/T_k) ∫_{s_k}^{s_{k+1}} x dt      window averages (b)
//! ```
//!
//! The sampled difference equation with the coupling's trapezoidal mean (module docs of
//! [`super`]) errs by a few 10⁻⁴ of θ2 on the rigid-body Pioneer-like robot, where the coupling
//! θ5 v ω is a fifth of the ω channel's damping: as large as the batch interval.

use wheelid_models::dynamics::rk4_step;

use super::Split;

/// RK4 sub-steps per time constant of the faster channel: 3 (the batch simulation takes 5, at
/// most 20 ms; 3 moves the online answer by at most 0.05 of its standard errors on the
/// rigid-body robots, 2 by up to 1.4).
const SUBSTEPS_PER_TAU: f64 = 3.0;

/// Most RK4 sub-steps a period.
const MAX_SUBSTEPS: usize = 12;

/// Corrections of the coupling's value at the period's end after the first prediction (each
/// contracts the error by about the coupling's share of the damping times the period over
/// the time constant).
const CORRECTIONS: usize = 2;

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
    pub(super) fn start(x: [f64; 2], theta: &[f64; 6], dt: f64) -> Self {
        let tau = (theta[0] / theta[3]).max(theta[1] / theta[5]);
        let settle = (5.0 * tau / dt).ceil();
        Self {
            x,
            age: 0,
            settle: if settle.is_finite() { (settle as u64).max(5) } else { 5 },
        }
    }

    /// Whether the start's transient has died out: from then on the simulated outputs are the
    /// model's response to the commands alone.
    pub(super) fn settled(&self) -> bool {
        self.age >= self.settle
    }

    /// Advances over `period` \[s\] under the held command `u` = (v_ref, ω_ref) at `theta`
    /// (θ1…θ6) and returns the outputs the stamping `split` reports (window averages for
    /// [`Split::WindowAverage`], else the instants) — by the exponential integrator of the
    /// module docs.
    pub(super) fn advance(
        &mut self,
        theta: &[f64; 6],
        u: [f64; 2],
        period: f64,
        split: Split,
    ) -> [f64; 2] {
        let [t1, t2, t3, t4, t5, t6] = *theta;
        let tau = (t1 / t4).min(t2 / t6);
        let steps = ((period * SUBSTEPS_PER_TAU / tau).ceil() as usize).clamp(1, MAX_SUBSTEPS);
        let h = period / steps as f64;
        let (i1, i2) = (1.0 / t1, 1.0 / t2);
        let f = |x: &[f64; 2], u: (f64, f64)| {
            [
                (t3 * x[1] * x[1] - t4 * x[0] + u.0) * i1,
                (-t5 * x[0] * x[1] - t6 * x[1] + u.1) * i2,
            ]
        };
        let mut integral = [0.0; 2];
        let held = (u[0], u[1]);
        let mut x1 = self.x;
        for _ in 0..steps {
            rk4_step(f, &mut x1, &mut integral, held, held, h);
        }
        let mean = integral.map(|q| q / period);
        self.x = x1;
        self.age += 1;
        match split {
            Split::WindowAverage => mean,
            Split::Instant | Split::Free => x1,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A linear channel (θ3 = θ5 = 0) under a held command: the instant and the window average
    /// against their closed forms, x(T) = K u + (x0 − K u) e^{−T/τ} and its mean
    /// K u + (x0 − K u) (τ/T)(1 − e^{−T/τ}), within RK4's error at a third of the time
    /// constant, (1/3)⁵/120 ≈ 3·10⁻⁵ of the deviation x0 − K u a step (measured 4·10⁻⁶).
    #[test]
    fn a_held_command_gives_the_closed_form() {
        let theta = [0.3, 0.2, 0.0, 1.2, 0.0, 0.8];
        let (u, x0, period) = ([0.6, -0.4], [0.1, 0.2], 0.1);
        for split in [Split::Instant, Split::WindowAverage] {
            let got = Flow::start(x0, &theta, 0.1).advance(&theta, u, period, split);
            for i in 0..2 {
                let (tau, gain) = (theta[i] / theta[[3, 5][i]], 1.0 / theta[[3, 5][i]]);
                let e = (-period / tau).exp();
                let dev = x0[i] - gain * u[i];
                let want = match split {
                    Split::WindowAverage => gain * u[i] + dev * tau / period * (1.0 - e),
                    _ => gain * u[i] + dev * e,
                };
                let err = (got[i] - want).abs() / dev.abs();
                assert!(err < 3e-5, "{split:?} {i}: {} vs {want} ({err:.1e})", got[i]);
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
        let mut flow = Flow::start([0.0; 2], &theta, period);
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
            let mean = flow.advance(&theta, u, period, Split::WindowAverage);
            for i in 0..2 {
                worst = worst.max((mean[i] - q[i] / period).abs());
                worst = worst.max((flow.x[i] - fine[i]).abs());
            }
        }
        assert!(worst < 2e-5, "{worst:.2e}");
    }
}
