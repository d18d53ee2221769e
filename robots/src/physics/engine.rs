//! The rigid-body world of one robot, on rapier3d-f64 (z up, x forward, y left).
//!
//! Bodies: a chassis (the total mass and yaw inertia less the wheels', its centre of mass
//! placed so that the whole robot's is b ahead of the axle), two wheels on revolute impulse
//! joints at (0, ±d/2) with spin inertia I_e, and one caster ball fixed to the chassis on G's
//! side of the axle (so the robot stands on three points, statically determinate, and the
//! wheels carry (1 − b/x_c) of the weight). The ground is a fixed box.
//!
//! Set-up details that bias θ at the % level, and what is done about them:
//! * **Contact softness** sinks the wheels into the ground and shortens the rolling radius:
//!   rapier's default floor contact (60 Hz, ζ = 10) sank a Khepera wheel by 1.9 mm (r = 20.5
//!   mm) and made the body run 4.8 % slower than the wheel rims. Contacts here are 3 kHz,
//!   ζ = 1: sinkage ~1 µm, rim-to-body slip 0.002 % in steady driving.
//! * **Tyre scrub** in turns: the wheels are spheres of radius r, one contact point each, so a
//!   turning wheel does not scrub a contact patch.
//! * **Load on the wheels**: with a caster at each end the solver may carry the weight on the
//!   casters and the wheels slip (seen: 93 % slip); one caster on G's side fixes the split.
//! * **Caster drag**: the caster's friction is combined by `Min` with the floor's, i.e. zero.
//! * **Discretisation**: the step h is ≤ 1 ms and about τ/100 (a 23 ms Khepera: 0.25 ms).

use rapier3d_f64::prelude::*;

use super::profile::PhysicalProfile;

/// Natural frequency [Hz] and damping ratio of the contacts.
const CONTACT_HZ: f64 = 3000.0;
const CONTACT_ZETA: f64 = 1.0;

/// Wheel-on-floor friction coefficient (dry rubber on a hard floor).
pub const FLOOR_MU: f64 = 1.0;

/// The world and the handles of the robot's bodies; wheel 0 is the right one (−y), 1 the left.
pub struct Engine {
    world: PhysicsWorld,
    chassis: RigidBodyHandle,
    wheels: [RigidBodyHandle; 2],
    wheel_colliders: [ColliderHandle; 2],
}

impl std::fmt::Debug for Engine {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Engine").finish_non_exhaustive()
    }
}

/// The planar state of the chassis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BodyState {
    /// Forward velocity of the axle centre [m/s].
    pub v: f64,
    /// Yaw rate [rad/s].
    pub w: f64,
    /// Axle centre x, y [m].
    pub x: f64,
    /// Axle centre y [m].
    pub y: f64,
    /// Heading [rad] (wrapped to (−π, π]).
    pub heading: f64,
}

impl Engine {
    /// Builds the robot at rest at the origin, heading +x, on a floor of friction `floor_mu`.
    pub fn new(p: &PhysicalProfile, floor_mu: f64) -> Self {
        let mut world = PhysicsWorld::new();
        world.gravity = Vector::new(0.0, 0.0, -9.81);
        let ip = &mut world.integration_parameters;
        ip.dt = p.physics_step_s;
        ip.length_unit = p.r;
        ip.contact_softness = SpringCoefficients::new(CONTACT_HZ, CONTACT_ZETA);
        ip.static_contact_softness = SpringCoefficients::new(CONTACT_HZ, CONTACT_ZETA);
        world.insert(
            RigidBodyBuilder::fixed(),
            ColliderBuilder::cuboid(1e4, 1e4, 1.0)
                .translation(Vector::new(0.0, 0.0, -1.0))
                .friction(floor_mu),
        );
        let r = p.r;
        // Wheel inertia about its own diameters (a thin disc: half the spin inertia).
        let i_perp = 0.5 * p.i_e;
        let mw = p.wheel_mass;
        let mc = p.m - 2.0 * mw;
        let bc = p.m * p.b / mc;
        // I_z of the whole robot about G = chassis about its own G + wheels (parallel axes).
        let izc = p.i_z + p.m * p.b * p.b - 2.0 * (mw * p.d * p.d / 4.0 + i_perp) - mc * bc * bc;
        let izc = izc.max(1e-3 * p.i_z);
        let caster_z = -(r - p.caster_radius);
        let (chassis, _) = world.insert(
            RigidBodyBuilder::dynamic()
                .translation(Vector::new(0.0, 0.0, r))
                .can_sleep(false)
                .additional_mass_properties(MassProperties::new(
                    Vector::new(bc, 0.0, 0.0),
                    mc,
                    Vector::new(izc, izc, izc),
                )),
            ColliderBuilder::ball(p.caster_radius)
                .translation(Vector::new(p.caster_x, 0.0, caster_z))
                .density(0.0)
                .friction(0.0)
                .friction_combine_rule(CoefficientCombineRule::Min),
        );
        let mut wheels = [chassis; 2];
        let mut wheel_colliders = Vec::with_capacity(2);
        for (i, side) in [-1.0, 1.0].into_iter().enumerate() {
            let (wheel, collider) = world.insert(
                RigidBodyBuilder::dynamic()
                    .translation(Vector::new(0.0, side * p.d / 2.0, r))
                    .can_sleep(false)
                    .additional_mass_properties(MassProperties::new(
                        Vector::ZERO,
                        mw,
                        Vector::new(i_perp, p.i_e, i_perp),
                    )),
                ColliderBuilder::ball(r).density(0.0).friction(floor_mu),
            );
            let joint = RevoluteJointBuilder::new(Vector::Y)
                .local_anchor1(Vector::new(0.0, side * p.d / 2.0, 0.0))
                .local_anchor2(Vector::ZERO);
            world.impulse_joints.insert(chassis, wheel, joint, true);
            wheels[i] = wheel;
            wheel_colliders.push(collider);
        }
        Self {
            world,
            chassis,
            wheels,
            wheel_colliders: [wheel_colliders[0], wheel_colliders[1]],
        }
    }

    /// The wheel axle's direction (the chassis's +y) in the world.
    fn axle(&self) -> Vector {
        self.world.bodies[self.chassis].rotation() * Vector::Y
    }

    /// Spin rates (right, left) of the wheels relative to the chassis [rad/s], positive
    /// forward: what the encoders see.
    pub fn wheel_rates(&self) -> [f64; 2] {
        let axle = self.axle();
        let c = self.world.bodies[self.chassis].angvel();
        self.wheels
            .map(|h| (self.world.bodies[h].angvel() - c).dot(axle))
    }

    /// Advances one physics step with the motor torques (right, left) [N·m] on the wheels
    /// about their axle, and their reaction on the chassis.
    pub fn step(&mut self, torque: [f64; 2]) {
        let axle = self.axle();
        for (h, tau) in self.wheels.iter().zip(torque) {
            let b = &mut self.world.bodies[*h];
            b.reset_torques(true);
            b.add_torque(axle * tau, true);
        }
        let c = &mut self.world.bodies[self.chassis];
        c.reset_torques(true);
        c.add_torque(-axle * (torque[0] + torque[1]), true);
        self.world.step();
    }

    /// The chassis's planar state (at the axle centre).
    pub fn body(&self) -> BodyState {
        let c = &self.world.bodies[self.chassis];
        let rot = c.rotation();
        let fwd = rot * Vector::X;
        let heading = fwd.y.atan2(fwd.x);
        let w = c.angvel().z;
        // The body origin is the axle centre; its velocity is the centre of mass's minus ω × G.
        let axle_centre = c.translation();
        let v_origin = c.velocity_at_point(axle_centre);
        BodyState {
            v: v_origin.dot(fwd),
            w,
            x: axle_centre.x,
            y: axle_centre.y,
            heading,
        }
    }

    /// Sets the friction of both wheels with the floor (the floor's own is [`FLOOR_MU`]; the
    /// pair uses the average of the two).
    pub fn set_wheel_friction(&mut self, mu: f64) {
        for h in self.wheel_colliders {
            if let Some(c) = self.world.colliders.get_mut(h) {
                c.set_friction(mu);
            }
        }
    }
}
