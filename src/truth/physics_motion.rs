//! The rapier reference of the arm in motion: the true chain as a rapier multibody in f64 (reduced coordinates,
//! fixed base, the true link inertials and the payload as the only mass, no colliders), each joint a spring with a
//! damper across its transmission, driven along a path by moving the springs' rest angles (the motor side) and
//! stepped at a small time step, so that the link side follows with its full dynamics — inertia, Coriolis and
//! centrifugal loads, the joints' own ringing — in rapier's own integrator: the reference the fast path
//! ([`super::motion`]) is held against in `tests/motion.rs`.
//!
//! It is built from the chain rather than from URDF text (as [`super::physics`]'s static reference is) because
//! `rapier3d-urdf` builds f32 worlds only, and f32 cannot integrate a path to micrometres: below a 0.1 ms step a
//! step's position increment at the slow velocities of a joint ringing down falls under the angle's rounding
//! (1e-7 rad), and the answer drifts by tens of micrometres.
//!
//! Each transmission is `τ = k (θ − q) + d (θ̇ − q̇)`. Rapier's joint spring pulls toward a rest angle and its joint
//! damping acts on the absolute joint velocity, so the rest angle is set to `θ + (d/k) θ̇`:
//! `−k (q − θ − (d/k) θ̇) − d q̇` is the same torque, and both parts stay implicit. Rapier integrates them by
//! backward Euler: first order in the step, with a numerical damping of about ω·dt/2 on top of the joints' own.

use nalgebra::{Isometry3, Point3, Vector3};
use rapier3d_f64::parry::math::{Matrix, Pose, Rot3, Vector};
use rapier3d_f64::prelude::{
    GenericJoint, GenericJointBuilder, JointAxesMask, MassProperties, MultibodyJointHandle,
    PhysicsWorld, RigidBodyBuilder,
};

use super::physics::ANG_X;
use super::robot::{TrueRobot, TrueState};
use crate::error::{Error, Result};
use crate::robot::{Frames, Inertial, JointKind, forward_kinematics};

/// A rapier f64 world holding the true arm with compliant, damped joints.
pub struct MotionReference {
    world: PhysicsWorld,
    joints: Vec<MultibodyJointHandle>,
    stiffness: Vec<f64>,
    damping: Vec<f64>,
}

impl std::fmt::Debug for MotionReference {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MotionReference")
            .field("stiffness", &self.stiffness)
            .field("damping", &self.damping)
            .finish_non_exhaustive()
    }
}

fn pose(iso: &Isometry3<f64>) -> Pose {
    let (t, q) = (iso.translation.vector, iso.rotation);
    Pose::from_parts(
        Vector::new(t.x, t.y, t.z),
        Rot3::from_xyzw(q.i, q.j, q.k, q.w).normalize(),
    )
}

fn lost() -> Error {
    Error::Physics("motion reference: the multibody lost a joint".into())
}

impl TrueRobot {
    /// The rapier f64 multibody of this robot in motion: its true geometry and inertials, the payload at the
    /// flange, linear springs of its true stiffness and its [`TrueRobot::transmission_damping`] (the soft zones
    /// and the tilt of the fast path are not represented: a reference for the dynamics of the linear joints).
    pub fn motion_reference(&self) -> Result<MotionReference> {
        if self.tilts() || !self.perturbation.soft_zone.is_empty() {
            return Err(Error::Invalid(
                "the rapier motion reference has linear joints without tilt: a truth with soft zones or \
                 truth.tilt_stiffness_nm_per_rad is followed by the fast path only"
                    .into(),
            ));
        }
        let chain = &self.chain;
        let n = chain.dof();
        if let Some(j) = chain
            .joints
            .iter()
            .find(|j| !matches!(j.kind, JointKind::Revolute))
        {
            return Err(Error::Invalid(format!(
                "the rapier motion reference takes revolute joints only; `{}` is not one",
                j.name
            )));
        }
        let mut frames = Frames::new(chain);
        forward_kinematics(chain, &vec![0.0; n], &mut frames);
        let mut world = PhysicsWorld::new();
        let g = self.gravity;
        world.gravity = Vector::new(g.x, g.y, g.z);
        let mut parent = world
            .bodies
            .insert(RigidBodyBuilder::fixed().pose(pose(&frames.body[0])));
        let mut joints = Vec::with_capacity(n);
        for (i, joint) in chain.joints.iter().enumerate() {
            let mut inertial = chain.bodies[i + 1].inertial;
            if i + 1 == n && self.payload.mass > 0.0 {
                inertial = inertial.combined(&Inertial {
                    mass: self.payload.mass,
                    com: chain.flange * Point3::from(Vector3::from(self.payload.com)),
                    inertia: nalgebra::Matrix3::zeros(),
                });
            }
            let c = inertial.com;
            let body = RigidBodyBuilder::dynamic()
                .can_sleep(false)
                .pose(pose(&frames.body[i + 1]))
                .additional_mass_properties(MassProperties::with_inertia_matrix(
                    Vector::new(c.x, c.y, c.z),
                    inertial.mass,
                    Matrix::from_cols_slice(inertial.inertia.as_slice()),
                ));
            let child = world.bodies.insert(body);
            // One frame on the joint's axis, the same on both sides (the child's frame is the joint frame at 0).
            let a = joint.axis.into_inner();
            let basis =
                Pose::from_rotation(GenericJoint::complete_ang_frame(Vector::new(a.x, a.y, a.z)));
            let spring = GenericJointBuilder::new(JointAxesMask::LOCKED_REVOLUTE_AXES)
                .local_frame1(pose(&joint.origin) * basis)
                .local_frame2(basis)
                .build();
            let handle = world
                .multibody_joints
                .insert(parent, child, spring, true)
                .ok_or_else(|| {
                    Error::Physics(format!(
                        "motion reference: rapier refused joint `{}` into the multibody",
                        joint.name
                    ))
                })?;
            joints.push(handle);
            parent = child;
        }
        Ok(MotionReference {
            world,
            joints,
            stiffness: self.perturbation.stiffness.clone(),
            damping: self.transmission_damping(),
        })
    }
}

impl MotionReference {
    /// Each caller joint's (multibody link, generalised coordinate).
    fn links(&self) -> Result<Vec<(usize, usize)>> {
        self.joints
            .iter()
            .map(|&h| {
                let (mb, link) = self.world.multibody_joints.get(h).ok_or_else(lost)?;
                Ok((link, mb.link(link).ok_or_else(lost)?.assembly_id()))
            })
            .collect()
    }

    /// Sets every spring's rest angle to `rest + (d/k)·rate` (see the module's header).
    fn drive(&mut self, links: &[(usize, usize)], rest: &[f64], rate: &[f64]) -> Result<()> {
        let (mb, _) = self
            .world
            .multibody_joints
            .get_mut(self.joints[0])
            .ok_or_else(lost)?;
        for (j, &(link, _)) in links.iter().enumerate() {
            let (k, d) = (self.stiffness[j], self.damping[j]);
            let link = mb.link_mut(link).ok_or_else(lost)?;
            link.joint.set_spring(ANG_X, k, rest[j] + d / k * rate[j]);
        }
        Ok(())
    }

    fn read(&self, links: &[(usize, usize)]) -> Result<Vec<f64>> {
        let (mb, _) = self
            .world
            .multibody_joints
            .get(self.joints[0])
            .ok_or_else(lost)?;
        links
            .iter()
            .map(|&(link, _)| Ok(mb.link(link).ok_or_else(lost)?.joint().coords()[ANG_X]))
            .collect()
    }

    /// The joint angles (rad) at each of `times` (ascending, s) of the arm whose motor side follows `rest_at(t)`,
    /// starting at rest in the static equilibrium of `rest_at(times[0])` (placed where the fast path's static
    /// solve puts it: the same physics, so rapier starts still), stepped at `dt` (s).
    pub fn follow(
        &mut self,
        robot: &TrueRobot,
        rest_at: &dyn Fn(f64) -> Vec<f64>,
        times: &[f64],
        dt: f64,
    ) -> Result<Vec<Vec<f64>>> {
        let Some(&t0) = times.first() else {
            return Ok(Vec::new());
        };
        if !(dt.is_finite() && dt > 0.0)
            || times
                .windows(2)
                .any(|w| w[1].partial_cmp(&w[0]).is_none_or(|o| o.is_lt()))
        {
            return Err(Error::Invalid(format!(
                "motion reference: time step {dt} s must be positive and the times ascending"
            )));
        }
        let links = self.links()?;
        let n = links.len();
        // Start at the static equilibrium, at rest.
        let mut state = TrueState::new(robot);
        state.q0 = rest_at(t0);
        robot.deflect(&mut state)?;
        {
            let world = &mut self.world;
            let (mb, _) = world
                .multibody_joints
                .get_mut(self.joints[0])
                .ok_or_else(lost)?;
            let mut shift = vec![0.0; mb.ndofs()];
            for (j, &(link, dof)) in links.iter().enumerate() {
                shift[dof] = state.q[j] - mb.link(link).ok_or_else(lost)?.joint().coords()[ANG_X];
            }
            mb.apply_displacements(&shift);
            mb.generalized_velocity_mut().fill(0.0);
            let dampings = mb.damping_mut();
            for (j, &(_, dof)) in links.iter().enumerate() {
                dampings[dof] = self.damping[j];
            }
            mb.forward_kinematics(&world.bodies, false);
            mb.update_rigid_bodies(&mut world.bodies, true);
        }
        self.world.integration_parameters.dt = dt;
        let mut out = Vec::with_capacity(times.len());
        let mut t = t0;
        let zero = vec![0.0; n];
        self.drive(&links, &rest_at(t0), &zero)?;
        for &target in times {
            while t + 0.5 * dt < target {
                // The implicit spring acts with the rest angle at the end of the step; the motor side's rate
                // by a central difference (the path is smooth).
                const H: f64 = 1e-6;
                let (ahead, behind) = (rest_at(t + dt + H), rest_at(t + dt - H));
                let rate: Vec<f64> = ahead
                    .iter()
                    .zip(&behind)
                    .map(|(a, b)| (a - b) / (2.0 * H))
                    .collect();
                self.drive(&links, &rest_at(t + dt), &rate)?;
                self.world.step();
                t += dt;
            }
            let q = self.read(&links)?;
            if q.iter().any(|v| !v.is_finite()) {
                return Err(Error::Physics(format!(
                    "motion reference: joint angles became non-finite at t = {t} s (dt {dt} s too large?)"
                )));
            }
            out.push(q);
        }
        Ok(out)
    }
}
