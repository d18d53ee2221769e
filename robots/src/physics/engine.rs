//! The rigid-body world of one robot, on rapier3d-f64 (z up, x forward, y left).
//!
//! Bodies: a chassis (the total mass and yaw inertia less the wheels', its centre of mass
//! placed so that the whole robot's is b ahead of the axle), two wheels on revolute impulse
//! joints at (0, ±d/2) with spin inertia I_e, and one caster ball fixed to the chassis on G's
//! side of the axle (so the robot stands on three points, statically determinate, and the
//! wheels carry (1 − b/x_c) of the weight), with a tail skid clear of the floor on the other
//! side. The ground is a fixed box.
//!
//! Set-up details that bias θ at the % level, and what is done about them (figures from the
//! unit tests below and from steady turns against the map's steady state):
//! * **Contact softness** sinks the wheels into the ground and shortens the rolling radius:
//!   rapier's default floor contact (60 Hz, ζ = 10) sank a Khepera wheel by 1.9 mm (r = 20.5
//!   mm) and made the body run 4.8 % slower than the wheel rims.
//! * **Contact stiffness against the step**: too stiff a contact for the step makes the wheels
//!   chatter and creep. At 3 kHz, a Pioneer-like robot at h = 1 ms slipped 1.4 % under a 0.05 g
//!   push and yawed by itself (|ω| up to 3·10⁻³ rad/s driving straight); the steady state of a
//!   turn then missed the map's by 0.1–0.2 %, and identification traded θ5 (−35 %) for θ6
//!   (+1.0 %). The contact's natural frequency is therefore tied to the step,
//!   2π f_c h = [`CONTACT_OMEGA_H`] (f_c = 637 Hz at 1 ms, 2.5 kHz at 0.25 ms): static
//!   sinkage ≈ 0.005 % of r, slip under a 0.05 g push ≤ 0.05 %, no spurious yaw (< 10⁻⁶ rad/s),
//!   and steady turns within 10⁻⁵ of the map's on all three profiles.
//! * **Tyre scrub** in turns: the wheels are spheres of radius r, one contact point each, so a
//!   turning wheel does not scrub a contact patch (rapier's twist friction acts only on
//!   manifolds of two or more points).
//! * **Load on the wheels**: with a caster at each end the solver may carry the weight on the
//!   casters and the wheels slip (seen: 93 % slip); one caster on G's side fixes the split.
//! * **Tipping**: the motors' reaction pitches the chassis; past m g b of torque the caster
//!   lifts and, with nothing behind the axle, a hard start flips the robot backwards (seen: a
//!   Pioneer-like robot under saturated tracking commands stood on its tail at 55°). A tail skid
//!   on the other side of the axle, [`SKID_GAP`]·r above the floor (2.4–3.7° of pitch on the
//!   built-in profiles), stops it, as a real robot's rear caster or chassis does; it carries no
//!   load in normal driving, so the three-point load split above stands.
//! * **Caster drag**: the caster's friction is combined by `Min` with the floor's, i.e. zero.
//! * **Discretisation**: the step h is ≤ 1 ms and ≤ τ/100; the motor torque over a step is
//!   evaluated at its midpoint (`drive`), which removes the explicit-Euler bias −h/(2τ) of θ1,
//!   θ2 (−0.48 % for a Khepera at 0.25 ms).

use rapier3d_f64::prelude::*;

use super::effects::PhysicsEffects;
use super::payload::Payload;
use super::profile::PhysicalProfile;

/// The contacts' natural angular frequency × the physics step, 2π f_c h (module docs).
pub const CONTACT_OMEGA_H: f64 = 4.0;
/// The contacts' damping ratio.
pub const CONTACT_ZETA: f64 = 1.0;

/// Clearance of the tail skid over the floor, as a fraction of the wheel radius (module docs).
pub const SKID_GAP: f64 = 0.1;

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
    /// Axle centre x, y \[m\].
    pub x: f64,
    /// Axle centre y \[m\].
    pub y: f64,
    /// Heading \[rad\] (wrapped to (−π, π]).
    pub heading: f64,
}

impl Engine {
    /// Builds the robot at rest at the origin, heading +x, on a floor of friction
    /// `effects.floor_mu` (default [`FLOOR_MU`]), the right tyre's radius × `tyre_radius_right`
    /// (its axle mounted that much higher, so the chassis stays level).
    pub fn new(p: &PhysicalProfile, effects: &PhysicsEffects) -> Self {
        let floor_mu = effects.floor_mu.unwrap_or(FLOOR_MU);
        let radii = [p.r * effects.tyre_radius_right.unwrap_or(1.0), p.r];
        let mut world = PhysicsWorld::new();
        world.gravity = Vector::new(0.0, 0.0, -9.81);
        let ip = &mut world.integration_parameters;
        ip.dt = p.physics_step_s;
        ip.length_unit = p.r;
        let contact_hz = CONTACT_OMEGA_H / (2.0 * std::f64::consts::PI * p.physics_step_s);
        ip.contact_softness = SpringCoefficients::new(contact_hz, CONTACT_ZETA);
        ip.static_contact_softness = SpringCoefficients::new(contact_hz, CONTACT_ZETA);
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
        // The tail skid: on the other side of the axle, SKID_GAP · r above the floor.
        world.insert_collider(
            ColliderBuilder::ball(p.caster_radius)
                .translation(Vector::new(-p.caster_x, 0.0, caster_z + SKID_GAP * r))
                .density(0.0)
                .friction(0.0)
                .friction_combine_rule(CoefficientCombineRule::Min),
            Some(chassis),
        );
        let mut wheels = [chassis; 2];
        let mut wheel_colliders = Vec::with_capacity(2);
        for (i, side) in [-1.0, 1.0].into_iter().enumerate() {
            let ri = radii[i];
            let (wheel, collider) = world.insert(
                RigidBodyBuilder::dynamic()
                    .translation(Vector::new(0.0, side * p.d / 2.0, ri))
                    .can_sleep(false)
                    .additional_mass_properties(MassProperties::new(
                        Vector::ZERO,
                        mw,
                        Vector::new(i_perp, p.i_e, i_perp),
                    )),
                ColliderBuilder::ball(ri).density(0.0).friction(floor_mu),
            );
            let joint = RevoluteJointBuilder::new(Vector::Y)
                .local_anchor1(Vector::new(0.0, side * p.d / 2.0, ri - r))
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

    /// Sets `payload` down on the chassis now: a cube at `x_m` ahead of the axle, `size_m/2`
    /// above the axle's height, moving with the chassis, held by a fixed joint.
    pub fn place_payload(&mut self, payload: &Payload) {
        let c = &self.world.bodies[self.chassis];
        let local = Vector::new(payload.x_m, 0.0, 0.5 * payload.size_m);
        let at = c.translation() + c.rotation() * local;
        let (linvel, angvel) = (c.velocity_at_point(at), c.angvel());
        let i = payload.own_yaw_inertia();
        let body = self.world.insert_body(
            RigidBodyBuilder::dynamic()
                .pose(Pose::from_parts(at, *c.rotation()))
                .linvel(linvel)
                .angvel(angvel)
                .can_sleep(false)
                .additional_mass_properties(MassProperties::new(
                    Vector::ZERO,
                    payload.mass_kg,
                    Vector::new(i, i, i),
                )),
        );
        let joint = FixedJointBuilder::new().local_anchor1(local);
        self.world.insert_impulse_joint(self.chassis, body, joint);
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Rest sinkage, slip under a steady push, and yaw while driving straight, per profile.
    #[test]
    fn wheels_roll_without_sinking_slipping_or_yawing() {
        for name in PhysicalProfile::NAMES {
            let p = PhysicalProfile::by_name(name).expect("built in");
            let h = p.physics_step_s;
            let mut e = Engine::new(&p, &PhysicsEffects::default());
            for _ in 0..(0.2 / h) as usize {
                e.step([0.0; 2]);
            }
            let sink = p.r - e.world.bodies[e.wheels[0]].translation().z;
            // A push of about 0.05 g on the whole robot, then the second half of 0.6 s measured.
            let tau = 0.05 * 9.81 * p.m * p.r / 2.0;
            let n = (0.6 / h) as usize;
            let (mut rim, mut x0, mut w_max) = (0.0, 0.0, 0.0f64);
            for i in 0..n {
                if i == n / 2 {
                    (rim, x0) = (0.0, e.body().x);
                }
                e.step([tau; 2]);
                let r = e.wheel_rates();
                rim += p.r * h * 0.5 * (r[0] + r[1]);
                w_max = w_max.max(e.body().w.abs());
            }
            let ratio = (e.body().x - x0) / rim;
            eprintln!(
                "{name}: sinkage {:.4} % of r, body/rim {ratio:.6}, |ω| ≤ {w_max:.1e}",
                100.0 * sink / p.r
            );
            assert!(sink.abs() < 1e-4 * p.r, "{name}: sinkage {sink}");
            assert!((ratio - 1.0).abs() < 1e-3, "{name}: body/rim {ratio}");
            assert!(w_max < 1e-5, "{name}: yaw {w_max}");
        }
    }

    /// Normal force of the floor on both wheels together [N], from the last step's contact
    /// impulses.
    fn wheel_load(e: &Engine) -> f64 {
        let dt = e.world.integration_parameters.dt;
        e.wheel_colliders
            .iter()
            .flat_map(|c| e.world.contact_pairs_with(*c))
            .map(|pair| pair.total_impulse().z.abs() / dt)
            .sum()
    }

    /// The wheels' load on `e` (robot `p`, whole mass `m` [kg]) after `settle` s at rest, as a
    /// share of the weight, then the load moved onto them per unit of traction force while a
    /// steady torque of 0.1 × the weight × r/2 per wheel accelerates the robot (the mean
    /// over 0.2 s after 0.1 s), and that acceleration [m/s²].
    fn load_shift(e: &mut Engine, p: &PhysicalProfile, m: f64, settle: f64) -> (f64, f64, f64) {
        let h = p.physics_step_s;
        let mean_load = |e: &mut Engine, tau: f64, seconds: f64| {
            let n = (seconds / h) as usize;
            let v0 = e.body().v;
            let mut load = 0.0;
            for _ in 0..n {
                e.step([tau; 2]);
                load += wheel_load(e) / n as f64;
            }
            (load, (e.body().v - v0) / (n as f64 * h))
        };
        mean_load(e, 0.0, settle);
        let (rest, _) = mean_load(e, 0.0, 0.1);
        let weight = m * 9.81;
        let tau = 0.1 * weight * p.r / 2.0;
        mean_load(e, tau, 0.1);
        let (pushed, a) = mean_load(e, tau, 0.2);
        (rest / weight, (pushed - rest) / (m * a), a)
    }

    /// The load the wheels carry at rest and while a steady torque accelerates the robot, per
    /// profile, against the statics and the moment balance of `PhysicalProfile::
    /// wheel_load_share` and `load_transfer_per_force`. The Khepera-like robot's wheels spin
    /// 12.8 % of the moment: without that term (the centre of mass's height alone, r/x_c)
    /// the shifted load would be that much short.
    #[test]
    fn accelerating_moves_load_onto_the_wheels_by_the_moment_balance() {
        for name in PhysicalProfile::NAMES {
            let p = PhysicalProfile::by_name(name).expect("built in");
            let mut e = Engine::new(&p, &PhysicsEffects::default());
            let (rest, measured, a) = load_shift(&mut e, &p, p.m, 0.2);
            let expected = p.load_transfer_per_force();
            eprintln!(
                "{name}: rest {rest:.5} of the weight (1 − b/x_c = {:.5}); a = {a:.4} m/s², \
                 ΔN/F {measured:.5} vs (r + 2 I_e/(m r))/x_c {expected:.5}, r/x_c {:.5}",
                p.wheel_load_share(),
                p.r / p.caster_x
            );
            assert!((rest - p.wheel_load_share()).abs() < 1e-3, "{name}");
            assert!((measured / expected - 1.0).abs() < 1e-3, "{name}");
        }
    }

    /// The same with a payload set down on the chassis (a cube of side d/3, half the robot's
    /// mass, half-way to the caster): the wheels carry the loaded statics' share
    /// (`Payload::loaded`'s b') and the load moved per unit of traction force is
    /// `Payload::load_transfer_per_force`'s, the centre of mass lifted by the cube (the
    /// unloaded robot's (r + 2 I_e/(m r))/x_c is 15 % short of it on each profile).
    #[test]
    fn a_payload_moves_the_load_by_the_loaded_moment_balance() {
        for name in PhysicalProfile::NAMES {
            let p = PhysicalProfile::by_name(name).expect("built in");
            let payload = Payload {
                mass_kg: 0.5 * p.m,
                at_s: 0.0,
                x_m: 0.5 * p.caster_x,
                size_m: p.d / 3.0,
            };
            let loaded = payload.loaded(&p);
            let mut e = Engine::new(&p, &PhysicsEffects::default());
            e.place_payload(&payload);
            let (rest, measured, _) = load_shift(&mut e, &p, loaded.m, 0.3);
            let expected = payload.load_transfer_per_force(&p);
            eprintln!(
                "{name} + payload: rest {rest:.5} of the weight (1 − b'/x_c = {:.5}); ΔN/F \
                 {measured:.5} vs {expected:.5} (unloaded {:.5})",
                loaded.wheel_load_share(),
                p.load_transfer_per_force()
            );
            assert!((rest - loaded.wheel_load_share()).abs() < 1e-3, "{name}");
            assert!((measured / expected - 1.0).abs() < 2e-3, "{name}");
            assert!(measured / p.load_transfer_per_force() > 1.05, "{name}");
        }
    }
}
