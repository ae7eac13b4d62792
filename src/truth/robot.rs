//! The true robot: the nominal chain with a [`Perturbation`] applied, and how it actually reaches a command.
//!
//! A command `q_cmd` becomes the unloaded joint angle `q0 = q_cmd + zero offset + gear error`; the compliant
//! joints then settle where `K (q − q0) = τ_g(q)`, gravity and payload included; repeatability noise is
//! added last. The fast path solves that equilibrium by fixed point (a contraction: ‖K⁻¹ ∂τ/∂q‖ ≪ 1 for any
//! real arm); [`super::physics`] is the rapier reference it is checked against.

use nalgebra::{Isometry3, Point3, Vector3};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};

use super::perturbation::Perturbation;
use crate::error::{Error, Result};
use crate::robot::dynamics::{GRAVITY, gravity_torques};
use crate::robot::kinematics::forward_kinematics;
use crate::robot::{Chain, Frames, Payload};

/// How the static deflection is computed in a campaign.
#[derive(Clone, Copy, Debug, Default, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub enum DeflectionSolver {
    /// `q = q0 + K⁻¹ τ_g(q)` iterated to 1e-13 rad: microseconds per pose.
    #[default]
    FixedPoint,
    /// The rapier3d multibody stepped to rest: milliseconds per pose, the physics reference.
    Rapier,
}

#[derive(Clone, Debug)]
pub struct TrueRobot {
    /// The perturbed geometry: base offset and joint-frame offsets applied to the nominal chain.
    pub chain: Chain,
    pub perturbation: Perturbation,
    pub payload: Payload,
    pub gravity: Vector3<f64>,
    compliance: Vec<f64>,
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
    tau: Vec<f64>,
}

impl TrueState {
    pub fn new(robot: &TrueRobot) -> Self {
        let n = robot.chain.dof();
        TrueState {
            q: vec![0.0; n],
            frames: Frames::new(&robot.chain),
            q0: vec![0.0; n],
            tau: vec![0.0; n],
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
        if lengths.iter().any(|&l| l != n) {
            return Err(Error::Invalid(format!(
                "perturbation sized for {lengths:?} joints, the robot has {n}"
            )));
        }
        if let Some(k) = perturbation
            .stiffness
            .iter()
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
        let compliance = perturbation.stiffness.iter().map(|k| 1.0 / k).collect();
        Ok(TrueRobot {
            chain,
            perturbation,
            payload,
            gravity: GRAVITY,
            compliance,
        })
    }

    /// Joint angles the arm would hold without any load: command, zero offset and transmission error.
    pub fn unloaded_angles(&self, q_cmd: &[f64], out: &mut [f64]) {
        for (i, (o, &q)) in out.iter_mut().zip(q_cmd).enumerate() {
            *o = q + self.perturbation.joint_zero[i] + self.perturbation.gear_error(i, q);
        }
    }

    /// Solves the static equilibrium from the unloaded angles `state.q0` by fixed point; on return `state.q` holds the
    /// deflected angles and `state.frames` their frames. Returns the iterations used.
    pub fn deflect(&self, state: &mut TrueState) -> Result<usize> {
        state.q.copy_from_slice(&state.q0);
        for iter in 1..=FIXED_POINT_MAX_ITERS {
            forward_kinematics(&self.chain, &state.q, &mut state.frames);
            gravity_torques(
                &self.chain,
                &state.frames,
                &self.payload,
                &self.gravity,
                &mut state.tau,
            );
            let mut step: f64 = 0.0;
            for (((q, q0), c), tau) in state
                .q
                .iter_mut()
                .zip(&state.q0)
                .zip(&self.compliance)
                .zip(&state.tau)
            {
                let next = q0 + c * tau;
                step = step.max((next - *q).abs());
                *q = next;
            }
            if !step.is_finite() {
                return Err(Error::Physics(format!(
                    "static deflection: the gravity torques are not finite numbers at iteration {iter} (a \
                     frame offset, mass or joint angle far too large for a robot)"
                )));
            }
            if step < FIXED_POINT_TOL {
                forward_kinematics(&self.chain, &state.q, &mut state.frames);
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

    /// The true arm reaching command `q_cmd`: unloaded angles, deflection, then repeatability noise when
    /// `noise` is given. `state.frames` holds the reached frames on return.
    pub fn reach(
        &self,
        q_cmd: &[f64],
        noise: Option<&mut ChaCha8Rng>,
        state: &mut TrueState,
    ) -> Result<()> {
        if q_cmd.len() != self.chain.dof() || q_cmd.iter().any(|q| !q.is_finite()) {
            return Err(Error::Invalid(format!(
                "joint command {q_cmd:?} must hold {} finite angles",
                self.chain.dof()
            )));
        }
        self.unloaded_angles(q_cmd, &mut state.q0);
        self.deflect(state)?;
        self.add_noise(noise, state);
        Ok(())
    }

    /// Reach with the deflected angles given by another solver (the rapier reference).
    pub fn reach_with_angles(
        &self,
        q_link: &[f64],
        noise: Option<&mut ChaCha8Rng>,
        state: &mut TrueState,
    ) {
        state.q.copy_from_slice(q_link);
        self.add_noise(noise, state);
        forward_kinematics(&self.chain, &state.q, &mut state.frames);
    }

    fn add_noise(&self, noise: Option<&mut ChaCha8Rng>, state: &mut TrueState) {
        let sigma = self.perturbation.repeatability_rad;
        if let (Some(rng), true) = (noise, sigma > 0.0) {
            let normal = Normal::new(0.0, sigma).expect("sigma validated positive and finite");
            for q in state.q.iter_mut() {
                *q += normal.sample(rng);
            }
            forward_kinematics(&self.chain, &state.q, &mut state.frames);
        }
    }

    /// True flange pose for a command (no repeatability noise): the ground truth of the evaluation.
    pub fn flange_pose(&self, q_cmd: &[f64], state: &mut TrueState) -> Result<Isometry3<f64>> {
        self.reach(q_cmd, None, state)?;
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
        let gravity_in_base = self.chain.base.rotation.inverse() * self.gravity;
        super::physics::PhysicsReference::new(
            &self.urdf()?,
            &self.chain.joint_names(),
            &self.perturbation.stiffness,
            gravity_in_base.into(),
            opts,
        )
    }

    /// URDF text of the true robot in its base frame (perturbed geometry, payload folded in).
    pub fn urdf(&self) -> Result<String> {
        crate::robot::urdf::to_urdf_string(&self.chain, &self.payload)
    }
}
