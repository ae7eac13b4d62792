//! The true robot: the nominal chain with a [`Perturbation`] applied, and how it actually reaches a command.
//!
//! A command `q_cmd` becomes the unloaded joint angle `q0 = q_cmd + zero offset + gear error (+ half the
//! hysteresis band, by the direction the joint last moved in)`; the compliant joints then settle where
//! `θ_i(τ_i(q)) = q_i − q0_i` (θ the joint's torsion curve: `τ/K`, or the soft zone's piecewise curve) and each
//! joint tilts about its perpendicular axes by the perpendicular gravity moment over the tilt stiffness,
//! gravity and payload acting on the *true* link inertials; link lengths follow the temperature; repeatability
//! noise is added last. The fast path solves that equilibrium by fixed point (a contraction: the largest
//! compliance times ‖∂τ/∂q‖ stays ≪ 1 for any real arm); [`super::physics`] is the rapier reference it is
//! checked against.

use nalgebra::{Isometry3, Matrix3, Point3, Translation3, UnitQuaternion, Vector3};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

use super::history::{Visit, approach};
use super::perturbation::Perturbation;
use super::stiffness::tilt;
use crate::error::{Error, Result};
use crate::robot::dynamics::{GRAVITY, gravity_moments, gravity_torques};
use crate::robot::inverse_dynamics::{
    Workspace, geometry, gravity_moments_again, inverse_dynamics, inverse_dynamics_again,
};
use crate::robot::kinematics::forward_kinematics;
use crate::robot::{Chain, Frames, Inertial, JointKind, Payload};

#[derive(Clone, Debug)]
pub struct TrueRobot {
    /// The perturbed geometry (base offset and joint-frame offsets applied to the nominal chain) with the true
    /// link inertials (URDF's, perturbed, plus cables): what gravity acts on.
    pub chain: Chain,
    pub perturbation: Perturbation,
    pub payload: Payload,
    pub gravity: Vector3<f64>,
    compliance: Vec<f64>,
    /// Compliance about the axes perpendicular to each joint (rad/Nm); empty: none.
    tilt_compliance: Vec<f64>,
    /// The posture evaluation poses are approached from ([`TrueRobot::flange_pose`]).
    approach: Vec<f64>,
}

/// The settled arm: link-side joint angles (rad) and each joint's tilt about its perpendicular axes (rotation
/// vector in the joint frame, rad; empty without tilt compliance).
#[derive(Clone, Debug, PartialEq)]
pub struct Deflection {
    pub q: Vec<f64>,
    pub tilt: Vec<Vector3<f64>>,
}

/// Per-call workspace of the true robot.
#[derive(Clone, Debug)]
pub struct TrueState {
    /// Link-side joint angles at equilibrium (rad).
    pub q: Vec<f64>,
    /// Frames of the true chain at `q`.
    pub frames: Frames,
    /// Unloaded angles of the last reach (rad).
    pub q0: Vec<f64>,
    /// Tilt of each joint about its perpendicular axes (rotation vector in the joint frame, rad).
    pub tilt: Vec<Vector3<f64>>,
    /// Factor on every link length (thermal growth) of the last reach.
    pub scale: f64,
    tau: Vec<f64>,
    moments: Vec<Vector3<f64>>,
    dynamics: Workspace,
}

impl TrueState {
    pub fn new(robot: &TrueRobot) -> Self {
        let n = robot.chain.dof();
        TrueState {
            q: vec![0.0; n],
            frames: Frames::new(&robot.chain),
            q0: vec![0.0; n],
            tilt: vec![Vector3::zeros(); n],
            scale: 1.0,
            tau: vec![0.0; n],
            moments: vec![Vector3::zeros(); n],
            dynamics: Workspace::new(&robot.chain),
        }
    }

    /// The torque each joint's load applies at the last solve (Nm).
    pub(super) fn tau(&self) -> &[f64] {
        &self.tau
    }

    /// The settled arm of the last reach.
    pub fn deflection(&self) -> Deflection {
        Deflection {
            q: self.q.clone(),
            tilt: self.tilt.clone(),
        }
    }
}

/// The fixed point stops when no joint moves by more than this (rad).
const FIXED_POINT_TOL: f64 = 1e-13;
const FIXED_POINT_MAX_ITERS: usize = 60;

impl TrueRobot {
    pub fn new(nominal: &Chain, perturbation: Perturbation, payload: Payload) -> Result<TrueRobot> {
        let n = nominal.dof();
        let lengths = [
            perturbation.joint_frames.len(),
            perturbation.joint_zero.len(),
            perturbation.stiffness.len(),
            perturbation.gear.len(),
        ];
        let optional = [
            perturbation.link_mass_factor.len(),
            perturbation.link_com_offset.len(),
            perturbation.soft_zone.len(),
            perturbation.tilt_stiffness.len(),
        ];
        if lengths.iter().any(|&l| l != n) || optional.iter().any(|&l| l != 0 && l != n) {
            return Err(Error::Invalid(format!(
                "perturbation sized for {lengths:?} / {optional:?} joints, the robot has {n}"
            )));
        }
        if let Some(k) = perturbation
            .stiffness
            .iter()
            .chain(&perturbation.tilt_stiffness)
            .find(|k| !(k.is_finite() && **k > 0.0))
        {
            return Err(Error::Invalid(format!(
                "joint stiffness {k} must be positive"
            )));
        }
        if !(payload.mass.is_finite() && payload.mass >= 0.0)
            || payload.com.iter().any(|c| !c.is_finite())
        {
            return Err(Error::Invalid(format!(
                "payload {payload:?} must be finite, mass ≥ 0"
            )));
        }
        let mut chain = nominal.clone();
        chain.base = perturbation.base.isometry() * nominal.base;
        for (joint, offset) in chain.joints.iter_mut().zip(&perturbation.joint_frames) {
            joint.origin *= offset.isometry();
        }
        true_inertials(&mut chain, &perturbation);
        let compliance = perturbation.stiffness.iter().map(|k| 1.0 / k).collect();
        let tilt_compliance = perturbation
            .tilt_stiffness
            .iter()
            .map(|k| 1.0 / k)
            .collect();
        Ok(TrueRobot {
            chain,
            perturbation,
            payload,
            gravity: GRAVITY,
            compliance,
            tilt_compliance,
            approach: vec![0.0; n],
        })
    }

    /// Sets the posture evaluation poses are approached from (the campaign's posture); the zero
    /// configuration until set.
    pub fn set_approach(&mut self, posture: &[f64]) {
        if posture.len() == self.approach.len() {
            self.approach.copy_from_slice(posture);
        }
    }

    /// The posture evaluation poses are approached from.
    pub fn approach(&self) -> &[f64] {
        &self.approach
    }

    /// Whether a reach depends on its history (lost motion, a temperature profile): then the order of a
    /// campaign matters.
    pub fn has_history(&self) -> bool {
        self.perturbation.hysteresis_rad > 0.0 || self.perturbation.thermal.is_some()
    }

    /// Whether joints tilt about their perpendicular axes.
    pub fn tilts(&self) -> bool {
        !self.tilt_compliance.is_empty()
    }

    /// Joint angles the arm would hold without any load: command, zero offset and transmission error.
    pub fn unloaded_angles(&self, q_cmd: &[f64], out: &mut [f64]) {
        for (i, (o, &q)) in out.iter_mut().zip(q_cmd).enumerate() {
            *o = q + self.perturbation.joint_zero[i] + self.perturbation.gear_error(i, q);
        }
    }

    /// [`TrueRobot::unloaded_angles`] after the history `visit`: each joint lags half the hysteresis band behind
    /// the direction it last moved in.
    pub fn unloaded_angles_after(&self, q_cmd: &[f64], visit: &Visit, out: &mut [f64]) {
        self.unloaded_angles(q_cmd, out);
        let half = 0.5 * self.perturbation.hysteresis_rad;
        if half > 0.0 {
            for (o, d) in out.iter_mut().zip(&visit.direction) {
                *o -= d * half;
            }
        }
    }

    /// The factor on every link length at the visit's temperature (1 without a thermal profile).
    pub fn length_scale(&self, visit: &Visit) -> f64 {
        match (&self.perturbation.thermal, visit.temperature) {
            (Some(t), Some(temperature)) => t.scale(temperature),
            _ => 1.0,
        }
    }

    /// The true chain's frames at link angles `q`, tilts `tilt` and link lengths × `scale`. Growing every link
    /// translation by one factor scales every frame's position about the base, as a uniformly warm arm does.
    pub fn kinematics(&self, q: &[f64], tilt: &[Vector3<f64>], scale: f64, frames: &mut Frames) {
        frames.body[0] = self.chain.base;
        self.kinematics_from(q, tilt, scale, frames, 0);
    }

    /// [`TrueRobot::kinematics`] from joint `from` on, the frames before it kept: `frames.body[from]` (and the
    /// frames before) must be those of the same angles before joint `from`, tilts and scale — a joint's angle
    /// moves no frame before its own body, so a change of `q[from]` alone gives the same frames as a whole pass.
    pub fn kinematics_from(
        &self,
        q: &[f64],
        tilt: &[Vector3<f64>],
        scale: f64,
        frames: &mut Frames,
        from: usize,
    ) {
        let tilting = self.tilts() && tilt.len() == q.len();
        if !tilting && scale == 1.0 {
            forward_kinematics(&self.chain, q, frames);
            return;
        }
        let chain = &self.chain;
        let mut pose = frames.body[from];
        for (i, (joint, &qi)) in chain.joints.iter().zip(q).enumerate().skip(from) {
            let mut origin = joint.origin;
            origin.translation.vector *= scale;
            let mut joint_frame = pose * origin;
            if tilting {
                joint_frame *= UnitQuaternion::from_scaled_axis(tilt[i]);
            }
            frames.joint[i] = joint_frame;
            pose = match joint.kind {
                JointKind::Revolute => turned(&joint_frame, &joint.motion(qi).rotation),
                JointKind::Prismatic => joint_frame * joint.motion(qi),
            };
            frames.body[i + 1] = pose;
        }
        let mut flange = chain.flange;
        flange.translation.vector *= scale;
        frames.flange = pose * flange;
    }

    /// Joint `i`'s torsion under torque `tau` (rad).
    #[inline]
    fn torsion(&self, i: usize, tau: f64) -> f64 {
        match self.perturbation.soft_zone.get(i) {
            Some(zone) => zone.deflection(tau),
            None => self.compliance[i] * tau,
        }
    }

    /// Joint `i`'s stiffness at torque `tau` (Nm/rad): the slope of its torsion curve there.
    pub(super) fn tangent_stiffness(&self, i: usize, tau: f64) -> f64 {
        match self.perturbation.soft_zone.get(i) {
            Some(zone) => zone.segment(zone.deflection(tau)).0,
            None => self.perturbation.stiffness[i],
        }
    }

    /// Each joint's viscous damping across its transmission (Nm·s/rad): `damping_ratio` of critical for the
    /// joint's stiffness and the inertia it carries alone (the mass matrix's diagonal) at the approach posture
    /// — a constant of the joint, as a transmission's damping is, sized where the arm works.
    pub fn transmission_damping(&self) -> Vec<f64> {
        let n = self.chain.dof();
        let mut frames = Frames::new(&self.chain);
        forward_kinematics(&self.chain, &self.approach, &mut frames);
        let mut ws = Workspace::new(&self.chain);
        let (zero, mut unit, mut column) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
        (0..n)
            .map(|i| {
                unit.fill(0.0);
                unit[i] = 1.0;
                inverse_dynamics(
                    &self.chain,
                    &frames,
                    &self.payload,
                    &Vector3::zeros(),
                    &zero,
                    &unit,
                    &mut ws,
                    &mut column,
                );
                2.0 * self.perturbation.damping_ratio
                    * (self.perturbation.stiffness[i] * column[i]).sqrt()
            })
            .collect()
    }

    /// Solves the static equilibrium from the unloaded angles `state.q0` at link lengths × `state.scale` by
    /// fixed point; on return `state.q` holds the deflected angles, `state.tilt` the tilts and `state.frames`
    /// their frames. Returns the iterations used.
    pub fn deflect(&self, state: &mut TrueState) -> Result<usize> {
        self.deflect_moving(state, None)
    }

    /// [`TrueRobot::deflect`] of the arm in motion: with `motion = (q̇, q̈)` (rad/s, rad/s²) each joint carries
    /// the full inverse-dynamics torque of the true links (inertial, Coriolis and centrifugal terms beside
    /// gravity) instead of the gravity torque alone — quasi-static: the transmission's own vibration is added
    /// about it by [`super::motion`]. Tilt still follows the gravity moment. With `None` it is the static solve,
    /// bit for bit.
    pub fn deflect_moving(
        &self,
        state: &mut TrueState,
        motion: Option<(&[f64], &[f64])>,
    ) -> Result<usize> {
        state.q.copy_from_slice(&state.q0);
        state.tilt.fill(Vector3::zeros());
        self.deflect_from_guess(state, motion)
    }

    /// [`TrueRobot::deflect_moving`] started from the angles and tilts already in `state` (an arm in motion
    /// starts from where it was a step ago: a fraction of the iterations).
    pub(super) fn deflect_from_guess(
        &self,
        state: &mut TrueState,
        motion: Option<(&[f64], &[f64])>,
    ) -> Result<usize> {
        let iters = self.fixed_point(state, motion)?;
        self.kinematics(&state.q, &state.tilt, state.scale, &mut state.frames);
        Ok(iters)
    }

    /// [`TrueRobot::deflect`] without the frames of the settled arm (`state.frames` are left at the last
    /// iterate): for a caller that keeps only the angles and tilts, or computes the frames again after
    /// repeatability noise.
    pub fn deflect_angles(&self, state: &mut TrueState) -> Result<usize> {
        state.q.copy_from_slice(&state.q0);
        state.tilt.fill(Vector3::zeros());
        self.fixed_point(state, None)
    }

    /// The fixed-point iteration of [`TrueRobot::deflect_from_guess`], up to the settled angles and tilts.
    fn fixed_point(
        &self,
        state: &mut TrueState,
        motion: Option<(&[f64], &[f64])>,
    ) -> Result<usize> {
        let tilting = self.tilts();
        for iter in 1..=FIXED_POINT_MAX_ITERS {
            self.kinematics(&state.q, &state.tilt, state.scale, &mut state.frames);
            let (chain, frames, payload) = (&self.chain, &state.frames, &self.payload);
            match motion {
                Some((qd, qdd)) => {
                    // The frames' centres of mass, axes and anchors once for the gravity moments (tilt) and
                    // the inverse dynamics; the torque is the latter's.
                    geometry(chain, frames, payload, &mut state.dynamics);
                    if tilting {
                        gravity_moments_again(
                            chain,
                            frames,
                            payload,
                            &self.gravity,
                            &state.dynamics,
                            &mut state.tau,
                            &mut state.moments,
                        );
                    }
                    // What the load applies to the joint is minus what the joint must supply to move it.
                    inverse_dynamics_again(
                        chain,
                        frames,
                        payload,
                        &self.gravity,
                        qd,
                        qdd,
                        &mut state.dynamics,
                        &mut state.tau,
                    );
                    state.tau.iter_mut().for_each(|t| *t = -*t);
                }
                None if tilting => gravity_moments(
                    chain,
                    frames,
                    payload,
                    &self.gravity,
                    &mut state.tau,
                    &mut state.moments,
                ),
                None => gravity_torques(chain, frames, payload, &self.gravity, &mut state.tau),
            }
            let mut step: f64 = 0.0;
            for (i, ((q, q0), tau)) in state
                .q
                .iter_mut()
                .zip(&state.q0)
                .zip(&state.tau)
                .enumerate()
            {
                let next = q0 + self.torsion(i, *tau);
                step = step.max((next - *q).abs());
                *q = next;
            }
            if tilting {
                for (i, (t, c)) in state.tilt.iter_mut().zip(&self.tilt_compliance).enumerate() {
                    let local = state.frames.joint[i]
                        .rotation
                        .inverse_transform_vector(&state.moments[i]);
                    let next = tilt(&self.chain.joints[i].axis, &local, *c);
                    step = step.max((next - *t).amax());
                    *t = next;
                }
            }
            if !step.is_finite() {
                return Err(Error::Physics(format!(
                    "static deflection: the gravity torques are not finite numbers at iteration {iter} (a \
                     frame offset, mass or joint angle far too large for a robot)"
                )));
            }
            if step < FIXED_POINT_TOL {
                return Ok(iter);
            }
        }
        let worst = state
            .tau
            .iter()
            .zip(&self.compliance)
            .map(|(t, c)| (t * c).abs())
            .fold(0.0, f64::max);
        Err(Error::Physics(format!(
            "static deflection did not converge in {FIXED_POINT_MAX_ITERS} fixed-point iterations (a \
             deflection of {worst:.2e} rad): the joints are too soft for the load, or a mass or frame offset \
             is far larger than a robot's"
        )))
    }

    /// The true arm reaching command `q_cmd` with no history (no lost motion, links at their reference
    /// length): unloaded angles, deflection, then repeatability noise when `noise` is given.
    /// `state.frames` holds the reached frames on return.
    pub fn reach(
        &self,
        q_cmd: &[f64],
        noise: Option<&mut ChaCha8Rng>,
        state: &mut TrueState,
    ) -> Result<()> {
        self.reach_after(q_cmd, &Visit::default(), noise, state)
    }

    /// [`TrueRobot::reach`] after the history `visit` (the direction each joint came from, the temperature).
    pub fn reach_after(
        &self,
        q_cmd: &[f64],
        visit: &Visit,
        noise: Option<&mut ChaCha8Rng>,
        state: &mut TrueState,
    ) -> Result<()> {
        if q_cmd.len() != self.chain.dof() || q_cmd.iter().any(|q| !q.is_finite()) {
            return Err(Error::Invalid(format!(
                "joint command {q_cmd:?} must hold {} finite angles",
                self.chain.dof()
            )));
        }
        self.unloaded_angles_after(q_cmd, visit, &mut state.q0);
        state.scale = self.length_scale(visit);
        self.deflect_angles(state)?;
        if !self.add_noise(noise, state) {
            self.kinematics(&state.q, &state.tilt, state.scale, &mut state.frames);
        }
        Ok(())
    }

    /// Reach with the settled arm given by another solver (the rapier reference) or an earlier solve, at link
    /// lengths × `scale`.
    pub fn reach_with_angles(
        &self,
        settled: &Deflection,
        scale: f64,
        noise: Option<&mut ChaCha8Rng>,
        state: &mut TrueState,
    ) {
        state.q.copy_from_slice(&settled.q);
        if settled.tilt.len() == state.tilt.len() {
            state.tilt.copy_from_slice(&settled.tilt);
        } else {
            state.tilt.fill(Vector3::zeros());
        }
        state.scale = scale;
        if !self.add_noise(noise, state) {
            self.kinematics(&state.q, &state.tilt, state.scale, &mut state.frames);
        }
    }

    /// Adds the repeatability noise to `state.q` and computes the frames there; false (and nothing done) without
    /// noise, when the caller's frames are its own to compute.
    pub(crate) fn add_noise(&self, noise: Option<&mut ChaCha8Rng>, state: &mut TrueState) -> bool {
        let sigma = self.perturbation.repeatability_rad;
        if let (Some(rng), true) = (noise, sigma > 0.0) {
            let normal = Normal::new(0.0, sigma).expect("sigma validated positive and finite");
            for q in state.q.iter_mut() {
                *q += normal.sample(rng);
            }
            self.kinematics(&state.q, &state.tilt, state.scale, &mut state.frames);
            return true;
        }
        false
    }

    /// How an evaluation pose `q_cmd` is reached: from the approach posture, at the end of the warm-up.
    pub fn evaluation_visit(&self, q_cmd: &[f64]) -> Visit {
        approach(&self.perturbation, &self.approach, q_cmd)
    }

    /// True flange pose for a command (no repeatability noise), reached as an evaluation pose
    /// ([`TrueRobot::evaluation_visit`]): the ground truth of the evaluation.
    pub fn flange_pose(&self, q_cmd: &[f64], state: &mut TrueState) -> Result<Isometry3<f64>> {
        let visit = self.evaluation_visit(q_cmd);
        self.reach_after(q_cmd, &visit, None, state)?;
        Ok(state.frames.flange)
    }

    /// World position of a point given in the flange frame, after the last reach.
    pub fn point_on_flange(state: &TrueState, local: &Point3<f64>) -> Point3<f64> {
        state.frames.flange * local
    }

    /// The rapier multibody of this robot (its true geometry, stiffness and payload), ready to settle poses.
    /// It is built in the base frame, so gravity goes in rotated by the base tilt.
    pub fn physics_reference(
        &self,
        opts: super::physics::SettleOptions,
    ) -> Result<super::physics::PhysicsReference> {
        if self.tilts() {
            return Err(Error::Invalid(
                "the rapier reference has no compliance about the axes perpendicular to the joints \
                 (truth.tilt_stiffness_nm_per_rad): solve with deflection = \"fixed-point\""
                    .into(),
            ));
        }
        let gravity_in_base = self.chain.base.rotation.inverse() * self.gravity;
        let mut reference = super::physics::PhysicsReference::new(
            &self.urdf()?,
            &self.chain.joint_names(),
            &self.perturbation.stiffness,
            gravity_in_base.into(),
            opts,
        )?;
        reference.set_soft_zones(&self.perturbation.soft_zone)?;
        Ok(reference)
    }

    /// URDF text of the true robot in its base frame (perturbed geometry, payload folded in).
    pub fn urdf(&self) -> Result<String> {
        crate::robot::urdf::to_urdf_string(&self.chain, &self.payload)
    }
}

/// `frame` times a pure rotation: nalgebra's isometry product bit for bit without its one wasted step. That
/// product adds the rotated translation of the turn, here zero, and a finite quaternion rotates zero into an
/// exact +0; the addition is kept (a −0 becomes +0 as there), the rotation dropped.
#[inline]
fn turned(frame: &Isometry3<f64>, rotation: &UnitQuaternion<f64>) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::from(frame.translation.vector + Vector3::zeros()),
        frame.rotation * rotation,
    )
}

/// The true inertial of every moving link: the URDF's with its mass scaled and centre of mass moved by the
/// perturbation, plus the cable along the link (from the link's frame to the next joint, or to the flange)
/// as a point mass at its middle.
fn true_inertials(chain: &mut Chain, p: &Perturbation) {
    let n = chain.dof();
    for i in 0..n {
        let next = if i + 1 < n {
            chain.joints[i + 1].origin.translation.vector
        } else {
            chain.flange.translation.vector
        };
        let inertial = &mut chain.bodies[i + 1].inertial;
        if let Some(&f) = p.link_mass_factor.get(i) {
            inertial.mass *= f;
            inertial.inertia *= f;
        }
        if let Some(o) = p.link_com_offset.get(i) {
            inertial.com += Vector3::from(*o);
        }
        if p.cable_kg_per_m > 0.0 {
            let cable = Inertial {
                mass: p.cable_kg_per_m * next.norm(),
                com: Point3::from(next * 0.5),
                inertia: Matrix3::zeros(),
            };
            *inertial = inertial.combined(&cable);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Against nalgebra's product with `Isometry3::rotation`, signed zeros in the translation included.
    #[test]
    fn a_turn_keeps_the_isometry_products_bits() {
        let mut seed = 0x2545_f491_4f6c_dd1d_u64;
        let mut r = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64 * 4.0 - 2.0
        };
        for case in 0..2000 {
            let mut t = Vector3::new(r(), r(), r());
            if case % 5 == 0 {
                t[case % 3] = if case % 2 == 0 { -0.0 } else { 0.0 };
            }
            let frame = Isometry3::new(t, Vector3::new(r(), r(), r()));
            let axis = Vector3::new(r(), r(), r()).normalize();
            let turn = Isometry3::rotation(axis * r() * 2.0);
            let (ours, theirs) = (turned(&frame, &turn.rotation), frame * turn);
            let bits = |i: &Isometry3<f64>| {
                let (t, q) = (i.translation.vector, i.rotation.coords);
                [t.x, t.y, t.z, q.x, q.y, q.z, q.w].map(f64::to_bits)
            };
            assert_eq!(bits(&ours), bits(&theirs), "case {case}: {frame} {turn}");
        }
    }
}
