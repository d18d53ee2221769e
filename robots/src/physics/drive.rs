//! The drive: onboard controller, amplifier and DC motors, run at the physics step.
//!
//! Per wheel i (0 right, 1 left), with ω_i its spin rate relative to the chassis:
//!
//! ```text
//! wheel-PD (§2.2):  u_i = k_P (ω_i,ref − ω_i) − k_D ω̇_i,   ω_r,l,ref = (v_ref ± d ω_ref/2)/r
//! v/ω-PD (A.3):     u_r,l = [K_PT (v_ref − v) − K_DT v̇] ± [K_PR (ω_ref − ω) − K_DR ω̇],
//!                   v = r (ω_r + ω_l)/2,  ω = r (ω_r − ω_l)/d
//! motor (2.9–2.10): τ_i = (k_a/R_a)(u_i − k_b ω_i) − B_e ω_i       (torque on the wheel)
//! ```
//!
//! The derivatives are backward differences at the physics step through a first-order filter
//! of time constant T_f = n_f h, as an embedded controller computes them: unfiltered, the
//! derivative term is an explicit negative inertia that makes a wheel with no load (slipping,
//! lifted) unstable whenever its gain on the wheel's own acceleration, as a torque,
//! k_eff = (k_a/R_a)·k_D (wheel-PD) or (k_a/R_a)(K_DT r/2 + K_DR r/d) (v/ω-PD), times the
//! gain of the rates it differentiates at the Nyquist frequency, exceeds 2 I_e T_f/h. Those
//! rates are extrapolated to the step's midpoint, ω + (ω − ω_prev)/2, whose gain at the
//! Nyquist frequency is 2 (an alternating sequence doubles). So n_f = max(1, 2 k_eff/I_e): a
//! free wheel's loop keeps a margin of 2 (Khepera-like: 2 k_eff/I_e = 0.42, n_f = 1;
//! Pioneer-like: n_f ≈ 7.6). Without the factor 2 (n_f ≈ 3.8) the Pioneer-like robot's loop
//! had no margin left: on a slippery floor (μ = 0.05) its unloaded wheels went unstable, the
//! controller asked 64 kV and the wheels spun at 78 m/s, both at once, so the encoders read
//! ω = 0 (`tests/physics.rs`, `a_slipping_pioneer_keeps_its_wheels_on_their_setpoints`). The
//! filter lags the derivative term by about T_f ≪ the robot's time constants (measured on the
//! noise-free Pioneer-like run of `tests/physics_identify.rs` with n_f ≈ 7.6: θ1, θ2 within
//! 0.002 %, θ4 +0.03 %, θ6 +0.07 % of the map).
//!
//! Controller and motor are continuous-time elements integrated by the engine's step: the
//! torque held over a step is evaluated at the step's midpoint, with the wheel rates
//! extrapolated by half a step, ω + (ω − ω_prev)/2. Evaluated at the step's start (explicit
//! Euler), the feedback would act h/2 early on average and shorten the closed loop's time
//! constants by h/2: θ1, θ2 biased by −h/(2τ) (−0.48 % for a Khepera-like robot at 0.25 ms,
//! measured −0.45 %).
//!
//! A profile may give the controller its own period T_c (`controller_period_s`, a whole number
//! of steps): it then samples the wheel rates at its instants, differentiates over T_c (the
//! same filter, n_f controller periods) and holds its voltages for T_c, as a digital
//! controller does — the motor (back-EMF, friction) still acts continuously. The sample-and-hold
//! lags the feedback by T_c/2 on average, so θ1, θ2 come out shorter than the continuous map's
//! by about θ4·T_c/2 and θ6·T_c/2 (a physical effect of a slow controller, not of the engine).

use super::profile::{Controller, PhysicalProfile};

/// Gain of the midpoint extrapolation ω + (ω − ω_prev)/2 at the Nyquist frequency, |1.5 + 0.5|
/// (module docs).
const MIDPOINT_NYQUIST_GAIN: f64 = 2.0;

/// Controller and motor state of both wheels.
#[derive(Debug, Clone)]
pub struct Drive {
    p: PhysicalProfile,
    /// The differentiated quantities at the last step (wheel rates, or v and ω).
    last: Option<[f64; 2]>,
    /// Their filtered derivatives.
    rate: [f64; 2],
    /// Wheel rates at the previous step (for the midpoint extrapolation).
    prev_rates: Option<[f64; 2]>,
    /// The derivative filter's time constant in steps, n_f (module docs).
    filter_steps: f64,
    /// Physics steps per controller period (1: the controller runs at every step, continuous).
    every: usize,
    /// Physics steps taken, and the voltages held since the controller's last update.
    count: usize,
    held: [f64; 2],
}

impl Drive {
    /// A drive at rest for profile `p`.
    pub fn new(p: &PhysicalProfile) -> Self {
        Self {
            p: p.clone(),
            last: None,
            rate: [0.0; 2],
            prev_rates: None,
            filter_steps: Self::filter_steps(p),
            every: p.controller_steps(),
            count: 0,
            held: [0.0; 2],
        }
    }

    /// One physics step of `h` seconds: the controller's voltages (right, left) \[V\] for the
    /// setpoints and the wheel rates now [rad/s] — at every step from the rates extrapolated
    /// to the step's midpoint, or, with a controller period, updated from the rates at its
    /// instants and held — and those midpoint rates, at which the motors are evaluated.
    pub fn control(
        &mut self,
        setpoint: (f64, f64),
        rates: [f64; 2],
        h: f64,
    ) -> ([f64; 2], [f64; 2]) {
        let mid = self.midpoint(rates);
        let u = if self.every <= 1 {
            self.voltages(setpoint, mid, h)
        } else {
            if self.count.is_multiple_of(self.every) {
                self.held = self.voltages(setpoint, rates, self.every as f64 * h);
            }
            self.held
        };
        self.count += 1;
        (u, mid)
    }

    /// n_f = max(1, 2 k_eff/I_e): the derivative filter's time constant in steps, the 2 the
    /// midpoint extrapolation's gain at the Nyquist frequency (module docs).
    pub fn filter_steps(p: &PhysicalProfile) -> f64 {
        let gain = match p.controller {
            Controller::WheelPd { k_d, .. } => k_d,
            Controller::VwPd { k_dt, k_dr, .. } => k_dt * p.r / 2.0 + k_dr * p.r / p.d,
        };
        (MIDPOINT_NYQUIST_GAIN * p.k_a / p.r_a * gain / p.i_e).max(1.0)
    }

    /// The wheel rates [rad/s] at the middle of the coming step, extrapolated from `rates`
    /// (now) and the previous step's: ω + (ω − ω_prev)/2.
    pub fn midpoint(&mut self, rates: [f64; 2]) -> [f64; 2] {
        let prev = self.prev_rates.unwrap_or(rates);
        self.prev_rates = Some(rates);
        [0, 1].map(|i| rates[i] + 0.5 * (rates[i] - prev[i]))
    }

    /// Filtered derivatives of `x` over one step of `h` seconds.
    fn derivative(&mut self, x: [f64; 2], h: f64) -> [f64; 2] {
        if let Some(prev) = self.last {
            let a = 1.0 / (self.filter_steps + 1.0);
            for i in 0..2 {
                let raw = (x[i] - prev[i]) / h;
                self.rate[i] += a * (raw - self.rate[i]);
            }
        }
        self.last = Some(x);
        self.rate
    }

    /// Controller voltages (right, left) \[V\] for the setpoints (v_ref [m/s], ω_ref [rad/s]) and
    /// the wheel rates (right, left) [rad/s], one step of `h` seconds after the last call.
    pub fn voltages(&mut self, setpoint: (f64, f64), rates: [f64; 2], h: f64) -> [f64; 2] {
        let (r, d) = (self.p.r, self.p.d);
        let (v_ref, w_ref) = setpoint;
        match self.p.controller {
            Controller::WheelPd { k_p, k_d } => {
                let refs = [(v_ref + d * w_ref / 2.0) / r, (v_ref - d * w_ref / 2.0) / r];
                let acc = self.derivative(rates, h);
                [0, 1].map(|i| k_p * (refs[i] - rates[i]) - k_d * acc[i])
            }
            Controller::VwPd {
                k_pt,
                k_dt,
                k_pr,
                k_dr,
            } => {
                let v = r * (rates[0] + rates[1]) / 2.0;
                let w = r * (rates[0] - rates[1]) / d;
                let [dv, dw] = self.derivative([v, w], h);
                let common = k_pt * (v_ref - v) - k_dt * dv;
                let diff = k_pr * (w_ref - w) - k_dr * dw;
                [common + diff, common - diff]
            }
        }
    }

    /// Motor torques (right, left) [N·m] on the wheels from the amplifier's output voltages
    /// `u` \[V\] and the wheel rates [rad/s] (eq. 2.9–2.10).
    pub fn torques(&self, u: [f64; 2], rates: [f64; 2]) -> [f64; 2] {
        let p = &self.p;
        [0, 1].map(|i| p.k_a / p.r_a * (u[i] - p.k_b * rates[i]) - p.b_e * rates[i])
    }
}
