//! The TurtleBot3 Burger's physical constants, and its θ by the thesis's wheel-PD relations.
//!
//! # What is published, and where
//! | constant | value | source |
//! |---|---|---|
//! | mass m | 1.0 kg | ROBOTIS e-Manual, TurtleBot3 › Specifications: "Weight (+ SBC + Battery + Sensors) 1 kg" |
//! | wheel radius r (= tyre radius R_t) | 0.033 m | e-Manual; `turtlebot3_bringup/param/burger.yaml` `wheels.radius` |
//! | track d | 0.160 m | `burger.yaml` `wheels.separation` (wheel joints at y = ±0.080 m in the URDF) |
//! | max speeds | 0.22 m/s, 2.84 rad/s | e-Manual, Specifications (maximum translational / rotational velocity) |
//! | yaw inertia I_z | 2.394 × 10⁻³ kg·m² | `turtlebot3_description/urdf/turtlebot3_burger.urdf.xacro`, its CAD-derived inertials (early versions carry placeholders, 1 kg and izz 0.01): base izz 2.0064 × 10⁻³ (base mass 0.826 kg), plus per wheel its diametral 1.118 × 10⁻⁵ and 0.0285 kg × 0.080² |
//! | motor | 2 × Dynamixel XL430-W250-T, 258.5 : 1 | e-Manual, XL430-W250 › Specifications |
//! | k_a | 1.077 N·m/A | XL430 stall torque 1.4 N·m at 1.3 A, 11.1 V (ROBOTIS prints the ratio) |
//! | R_a | 8.54 Ω | 11.1 V / 1.3 A at stall (winding and driver together) |
//! | k_b | 1.860 V·s/rad | 11.1 V / no-load speed 57 rev/min (5.969 rad/s), friction neglected |
//!
//! # What is chosen (ROBOTIS does not publish it), and why
//! * **b = −0.032 m**, the centre of mass 32 mm *behind* the axle: the URDF puts the base's
//!   body box (and its visual mesh) at x = −0.032 m, and the battery and boards are stacked over
//!   it; the URDF's own inertial origin sits on the axle, which would make θ3 = θ5 = 0.
//! * **I_e = 6.89 × 10⁻⁴ kg·m²**: the wheel's spin inertia 2.07 × 10⁻⁵ (URDF) plus an assumed
//!   rotor inertia of 1 × 10⁻⁸ kg·m² (a small cored DC motor) reflected through 258.5².
//! * **B_e = 0**: no viscous figure is published; the dry friction is the Coulomb term below.
//! * **k_P = 40 V·s/rad, k_D = 6 V·s²/rad**, *equivalent* wheel-PD gains. Each XL430 closes
//!   its own velocity loop (a PI in control-table units, whose SI equivalent ROBOTIS does not
//!   give), so the Burger is a wheel-PD robot (thesis §2.2) whose gains are unknown. The
//!   passive plant is fast — with the constants above, the motor-and-body time constant is
//!   (R_a r² m + 2 I_e R_a)/(2 k_a k_b) ≈ 5 ms — so the response one sees is the servo's.
//!   A velocity servo with integral action tracks its reference (steady-state gain ≈ 1) with
//!   a time constant of the order of 0.1 s; these gains stand for that in eq. 2.19's
//!   structure: k_P sets θ4 = θ6 = 1 + k_b/k_P = 1.046, and k_D carries the time constant
//!   (θ1 ≈ θ2 ≈ k_D/k_P = 0.15 s, so θ1/θ4 = θ2/θ6 = 0.144 s; the body adds 0.2 ms).
//! * **T_c = 0.3 N·m** of dry friction per wheel, at the wheel (≈ 20 % of the stall torque; a
//!   258.5 : 1 gear train is far from back-drivable). Through the external-force terms of
//!   eq. 2.17–2.18 it enters the velocity equations as a dead band in command units:
//!   v_coulomb = R_a r T_c/(k_a k_P) (both wheels rolling the same way) and
//!   w_coulomb = 2 R_a r T_c/(k_a k_P d) = 2 v_coulomb/d (turning on the spot). The robot and
//!   the model keep one term per channel, `v_coulomb·sgn_ε(v)` and `w_coulomb·sgn_ε(ω)`, as
//!   wheelid's own simulator does; per wheel the two differ only while the wheels turn in
//!   opposite directions with v ≠ 0.
//!
//! # θ (wheel-PD, Laut 2011 §2.2 as corrected in `wheelid_models::physical`)
//! ```text
//! θ1 = (R_a R_t r m + 2 k_a k_D + 2 I_e R_a) / (2 k_a k_P)                       = 0.150240 s
//! θ2 = (k_a k_D d² + I_e R_a d² + 2 R_a R_t r (m b² + I_z)) / (k_a k_P d²)        = 0.150194 s
//! θ3 = R_a R_t r m b / (2 k_a k_P)                                               = −3.45e-6 s·m/rad²
//! θ4 = (k_a (k_P + k_b) + R_a B_e) / (k_a k_P)                                   = 1.046490
//! θ5 = 2 R_a R_t r m b / (k_a k_P d²)                                            = −5.40e-4 s/m
//! θ6 = θ4                                                                        = 1.046490
//! v_coulomb = R_a r T_c / (k_a k_P)                                              = 1.962e-3 m/s
//! w_coulomb = 2 R_a r T_c / (k_a k_P d)                                          = 2.453e-2 rad/s
//! ```
//! θ3 and θ5 are tiny: the couplings through the offset centre of mass are forces of the body,
//! and the stiff wheel loops dwarf them (the thesis's Pioneer has θ3 = −0.0005 as well).

/// The physical constants of a differential-drive robot with PD control on each wheel's
/// angular velocity (Laut 2011 §2.2), plus a dry friction torque per wheel. SI units; the tyre
/// radius R_t is taken equal to the wheel radius r.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WheelPdPhysics {
    /// Mass m \[kg\].
    pub m: f64,
    /// Moment of inertia about the vertical axis through the centre of mass, I_z [kg·m²].
    pub i_z: f64,
    /// Distance from the axle to the centre of mass, b \[m\] (forward positive).
    pub b: f64,
    /// Wheel (and tyre) radius r \[m\].
    pub r: f64,
    /// Track, the distance between the wheels, d \[m\].
    pub d: f64,
    /// Armature resistance R_a \[Ω\].
    pub r_a: f64,
    /// Torque constant at the wheel (gear included), k_a [N·m/A].
    pub k_a: f64,
    /// Back-EMF constant at the wheel, k_b [V·s/rad].
    pub k_b: f64,
    /// Inertia of motor, gears and wheel at the wheel, I_e [kg·m²].
    pub i_e: f64,
    /// Viscous friction at the wheel, B_e [N·m·s/rad].
    pub b_e: f64,
    /// Wheel-velocity PD proportional gain k_P [V·s/rad].
    pub k_p: f64,
    /// Wheel-velocity PD derivative gain k_D [V·s²/rad].
    pub k_d: f64,
    /// Dry (Coulomb) friction torque per wheel, at the wheel, T_c [N·m].
    pub t_c: f64,
}

impl WheelPdPhysics {
    /// θ1…θ6 of eq. 2.19 by the wheel-PD relations (module docs). Units: s, s, s·m/rad², -,
    /// s/m, -.
    pub fn theta(&self) -> [f64; 6] {
        let Self {
            m,
            i_z,
            b,
            r,
            d,
            r_a,
            k_a,
            k_b,
            i_e,
            b_e,
            k_p,
            k_d,
            ..
        } = *self;
        let r_t = r;
        let damping = (k_a * (k_p + k_b) + r_a * b_e) / (k_a * k_p);
        [
            (r_a * r_t * r * m + 2.0 * k_a * k_d + 2.0 * i_e * r_a) / (2.0 * k_a * k_p),
            (k_a * k_d * d * d + i_e * r_a * d * d + 2.0 * r_a * r_t * r * (m * b * b + i_z))
                / (k_a * k_p * d * d),
            r_a * r_t * r * m * b / (2.0 * k_a * k_p),
            damping,
            2.0 * r_a * r_t * r * m * b / (k_a * k_p * d * d),
            damping,
        ]
    }

    /// The dry friction in command units, [v_coulomb [m/s], w_coulomb [rad/s]] (module docs).
    pub fn coulomb(&self) -> [f64; 2] {
        let v = self.r_a * self.r * self.t_c / (self.k_a * self.k_p);
        [v, 2.0 * v / self.d]
    }

    /// The time constant of the passive plant \[s\]: the body and the motors under a constant
    /// voltage, (R_a r² m + 2 I_e R_a)/(2 k_a k_b) — what the servo's gains make slower.
    pub fn passive_time_constant(&self) -> f64 {
        (self.r_a * self.r * self.r * self.m + 2.0 * self.i_e * self.r_a)
            / (2.0 * self.k_a * self.k_b)
    }
}

/// Gear ratio of the Dynamixel XL430-W250 (e-Manual).
pub const XL430_GEAR_RATIO: f64 = 258.5;
/// Supply voltage of the XL430's rated figures and of the Burger's 3-cell Li-Po \[V\].
pub const XL430_VOLTAGE: f64 = 11.1;
/// XL430 stall current at 11.1 V \[A\] (e-Manual).
pub const XL430_STALL_CURRENT: f64 = 1.3;
/// XL430 stall torque at 11.1 V [N·m] (e-Manual).
pub const XL430_STALL_TORQUE: f64 = 1.4;
/// XL430 no-load speed at 11.1 V [rad/s] (e-Manual: 57 rev/min).
pub const XL430_NO_LOAD_SPEED: f64 = 57.0 * std::f64::consts::TAU / 60.0;
/// Unit of the XL430's `Present Velocity` register [rad/s] (control table: 0.229 rev/min).
pub const XL430_VELOCITY_UNIT: f64 = 0.229 * std::f64::consts::TAU / 60.0;
/// Encoder resolution of the XL430 [ticks per revolution] (12-bit absolute, e-Manual).
pub const XL430_TICKS_PER_REV: f64 = 4096.0;

/// Wheel radius of the Burger \[m\].
pub const WHEEL_RADIUS: f64 = 0.033;
/// Track of the Burger \[m\].
pub const TRACK: f64 = 0.160;
/// Maximum translational velocity of the Burger [m/s] (e-Manual).
pub const V_MAX: f64 = 0.22;
/// Maximum rotational velocity of the Burger [rad/s] (e-Manual).
pub const W_MAX: f64 = 2.84;
/// Control and report period of the Burger \[s\]: the OpenCR firmware (`turtlebot3_core`)
/// updates the motor goal velocities and publishes the drive information at 30 Hz
/// (`CONTROL_MOTOR_SPEED_FREQUENCY`, `DRIVE_INFORMATION_PUBLISH_FREQUENCY`).
pub const PERIOD_S: f64 = 1.0 / 30.0;

/// The TurtleBot3 Burger: published data and documented choices (module docs).
pub const BURGER: WheelPdPhysics = WheelPdPhysics {
    m: 1.0,
    i_z: 2.0064271e-3 + 2.0 * (1.1175580e-5 + 2.8498940e-2 * 0.080 * 0.080),
    b: -0.032,
    r: WHEEL_RADIUS,
    d: TRACK,
    r_a: XL430_VOLTAGE / XL430_STALL_CURRENT,
    k_a: 1.077,
    k_b: XL430_VOLTAGE / XL430_NO_LOAD_SPEED,
    i_e: 2.0712558e-5 + 1e-8 * XL430_GEAR_RATIO * XL430_GEAR_RATIO,
    b_e: 0.0,
    k_p: 40.0,
    k_d: 6.0,
    t_c: 0.3,
};

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn burger_theta_against_the_hand_computation_in_the_module_docs() {
        let th = BURGER.theta();
        let want = [0.150240, 0.150194, -3.453e-6, 1.046490, -5.396e-4, 1.046490];
        for (i, (g, w)) in th.iter().zip(want).enumerate() {
            assert_relative_eq!(*g, w, max_relative = 2e-4);
            assert!(g.is_finite(), "θ{}", i + 1);
        }
        let [vc, wc] = BURGER.coulomb();
        assert_relative_eq!(vc, 1.962e-3, max_relative = 2e-4);
        assert_relative_eq!(wc, 2.453e-2, max_relative = 2e-4);
        // The servo, not the body, sets the pace: the passive plant is ~5 ms, the loop 0.14 s.
        let tau = BURGER.passive_time_constant();
        assert!((0.004..0.006).contains(&tau), "{tau}");
        assert_relative_eq!(th[0] / th[3], 0.1436, max_relative = 1e-3);
        // The published maxima are one wheel-speed limit: 0.22 m/s ≈ 2.84 rad/s × d/2.
        assert_relative_eq!(W_MAX * TRACK / 2.0, V_MAX, max_relative = 0.04);
    }

    #[test]
    fn wheel_pd_relations_against_a_hand_computation() {
        // The same numbers as wheelid_models::physical's wheel-PD test (R_t = r = 0.1):
        // θ1 = 0.044, θ2 = 0.03525, θ3 = 0.001, θ4 = θ6 = 1.12, θ5 = 0.025.
        let c = WheelPdPhysics {
            m: 10.0,
            i_z: 0.2,
            b: 0.05,
            r: 0.1,
            d: 0.4,
            r_a: 2.0,
            k_a: 1.0,
            k_b: 0.5,
            i_e: 0.01,
            b_e: 0.05,
            k_p: 5.0,
            k_d: 0.1,
            t_c: 0.5,
        };
        for (g, w) in c
            .theta()
            .iter()
            .zip([0.044, 0.03525, 0.001, 1.12, 0.025, 1.12])
        {
            assert_relative_eq!(*g, w, max_relative = 1e-12);
        }
        // v_c = 2·0.1·0.5/(1·5) = 0.02 m/s; w_c = 2·0.02/0.4 = 0.1 rad/s.
        let [vc, wc] = c.coulomb();
        assert_relative_eq!(vc, 0.02, max_relative = 1e-12);
        assert_relative_eq!(wc, 0.1, max_relative = 1e-12);
    }
}
