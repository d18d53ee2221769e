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

use wheelid_models::dynamics::{accel, rk4_step, substep};

use super::Split;

/// Most RK4 sub-steps a period (the cost of an update stays bounded whatever θ̂ asks).
const MAX_SUBSTEPS: usize = 12;

/// The simulated robot between samples.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Flow {
    /// (v, ω) at the last sample instant \[m/s, rad/s\].
    x: [f64; 2],
}

impl Flow {
    /// A simulation started at the state `x` (the measured velocities: the transient of the
    /// difference dies out at the robot's own time constants).
    pub(super) fn start(x: [f64; 2]) -> Self {
        Self { x }
    }

    /// Advances over `period` \[s\] under the held command `u` = (v_ref, ω_ref) at `theta`
    /// (θ1…θ6) and returns the outputs the stamping `split` reports (window averages for
    /// [`Split::WindowAverage`], else the instants).
    pub(super) fn advance(&mut self, theta: &[f64; 6], u: [f64; 2], period: f64, split: Split) -> [f64; 2] {
        let steps = ((period / substep(theta)).ceil() as usize).clamp(1, MAX_SUBSTEPS);
        let h = period / steps as f64;
        let f = |x: &[f64; 2], u: (f64, f64)| {
            let (dv, dw) = accel(theta, x[0], x[1], u.0, u.1);
            [dv, dw]
        };
        let mut integral = [0.0; 2];
        let held = (u[0], u[1]);
        for _ in 0..steps {
            rk4_step(f, &mut self.x, &mut integral, held, held, h);
        }
        match split {
            Split::WindowAverage => integral.map(|q| q / period),
            Split::Instant | Split::Free => self.x,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A linear channel (θ3 = θ5 = 0) under a held command: the instant and the window average
    /// against their closed forms, x(T) = K u + (x0 − K u) e^{−T/τ} and its mean
    /// K u + (x0 − K u) (τ/T)(1 − e^{−T/τ}).
    #[test]
    fn a_held_command_gives_the_closed_form() {
        let theta = [0.3, 0.2, 0.0, 1.2, 0.0, 0.8];
        let (u, x0, period) = ([0.6, -0.4], [0.1, 0.2], 0.1);
        for split in [Split::Instant, Split::WindowAverage] {
            let got = Flow::start(x0).advance(&theta, u, period, split);
            for i in 0..2 {
                let (tau, gain) = (theta[i] / theta[[3, 5][i]], 1.0 / theta[[3, 5][i]]);
                let e = (-period / tau).exp();
                let dev = x0[i] - gain * u[i];
                let want = match split {
                    Split::WindowAverage => gain * u[i] + dev * tau / period * (1.0 - e),
                    _ => gain * u[i] + dev * e,
                };
                assert!((got[i] - want).abs() < 1e-7, "{split:?} {i}: {} vs {want}", got[i]);
            }
        }
    }
}
