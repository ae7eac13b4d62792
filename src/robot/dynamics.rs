//! Static dynamics: gravity torques and potential energy of a chain carrying a payload.

use nalgebra::{Isometry3, Point3, Vector3};

use super::chain::{Chain, JointKind, Payload};
use super::kinematics::Frames;

/// Standard gravity in the world frame (URDF convention: z up), m/s².
pub const GRAVITY: Vector3<f64> = Vector3::new(0.0, 0.0, -9.81);

/// Generalized gravity force `τ = -∂V/∂q` at the configuration in `frames`: the torque (Nm) or force (N)
/// that gravity applies to each joint, which a compliant joint balances by deflecting.
///
/// One backward pass: the mass and first moment of everything beyond joint `i` is all that joint feels.
pub fn gravity_torques(
    chain: &Chain,
    frames: &Frames,
    payload: &Payload,
    gravity: &Vector3<f64>,
    out: &mut [f64],
) {
    assert_eq!(
        out.len(),
        chain.dof(),
        "output length must equal the chain's dof"
    );
    gravity_pass(payload, &frames.flange, gravity, out, |i| {
        GravityJoint::of(chain, frames, i)
    });
}

/// Joint `i`'s part in [`gravity_pass`]: the body it moves (mass, world centre of mass) and its world axis
/// through `anchor`.
pub struct GravityJoint {
    pub mass: f64,
    pub com: Point3<f64>,
    pub axis: Vector3<f64>,
    pub anchor: Point3<f64>,
    pub prismatic: bool,
}

impl GravityJoint {
    /// Joint `i` of the URDF chain at `frames`, with the chain's own inertials.
    fn of(chain: &Chain, frames: &Frames, i: usize) -> GravityJoint {
        let body = &chain.bodies[i + 1];
        GravityJoint {
            mass: body.inertial.mass,
            com: frames.body[i + 1] * body.inertial.com,
            axis: frames.axis(chain, i),
            anchor: frames.anchor(i),
            prismatic: matches!(chain.joints[i].kind, JointKind::Prismatic),
        }
    }
}

/// The backward pass behind every gravity torque here, of the URDF chain ([`gravity_torques`]) and of the DH
/// chain (the elastic model's [`crate::calib::kinematic::GravityModel`]): the payload at the `flange`, then
/// joint by joint from the last (`joint(i)`), the mass and first moment of everything beyond joint `i` is all
/// that joint feels. Fills `out` (one value per joint).
pub fn gravity_pass(
    payload: &Payload,
    flange: &Isometry3<f64>,
    gravity: &Vector3<f64>,
    out: &mut [f64],
    joint: impl Fn(usize) -> GravityJoint,
) {
    gravity_pass_full(payload, flange, gravity, out, None, joint);
}

/// [`gravity_pass`] that also gives, when `moments` is given, the full gravity moment (Nm, world frame) about
/// each revolute joint's anchor of everything beyond it — the axial torque is its component along the axis;
/// the rest loads the joint's bearings and links (a prismatic joint's entry is zero).
pub fn gravity_pass_full(
    payload: &Payload,
    flange: &Isometry3<f64>,
    gravity: &Vector3<f64>,
    out: &mut [f64],
    mut moments: Option<&mut [Vector3<f64>]>,
    joint: impl Fn(usize) -> GravityJoint,
) {
    let mut mass = payload.mass;
    let mut moment = (flange * Point3::from(payload.com)).coords * payload.mass;
    for i in (0..out.len()).rev() {
        let j = joint(i);
        mass += j.mass;
        moment += j.com.coords * j.mass;
        let full = if j.prismatic {
            Vector3::zeros()
        } else {
            let lever = moment - j.anchor.coords * mass;
            lever.cross(gravity)
        };
        out[i] = if j.prismatic {
            j.axis.dot(&(gravity * mass))
        } else {
            j.axis.dot(&full)
        };
        if let Some(m) = moments.as_deref_mut() {
            m[i] = full;
        }
    }
}

/// [`gravity_torques`] and the full gravity moment about every joint's anchor (world frame, Nm): what a
/// compliance about the axes perpendicular to a joint (bearing tilt, link bending) responds to.
pub fn gravity_moments(
    chain: &Chain,
    frames: &Frames,
    payload: &Payload,
    gravity: &Vector3<f64>,
    torques: &mut [f64],
    moments: &mut [Vector3<f64>],
) {
    gravity_moments_of(chain, frames, payload, gravity, torques, moments, |i| {
        GravityJoint::of(chain, frames, i)
    });
}

/// [`gravity_moments`] with each joint's mass, centre of mass, axis and anchor from `joint`.
pub fn gravity_moments_of(
    chain: &Chain,
    frames: &Frames,
    payload: &Payload,
    gravity: &Vector3<f64>,
    torques: &mut [f64],
    moments: &mut [Vector3<f64>],
    joint: impl Fn(usize) -> GravityJoint,
) {
    assert!(
        torques.len() == chain.dof() && moments.len() == chain.dof(),
        "output lengths must equal the chain's dof"
    );
    gravity_pass_full(
        payload,
        &frames.flange,
        gravity,
        torques,
        Some(moments),
        joint,
    );
}

/// Gravitational potential energy (J) relative to the world origin.
pub fn potential_energy(
    chain: &Chain,
    frames: &Frames,
    payload: &Payload,
    gravity: &Vector3<f64>,
) -> f64 {
    let bodies: f64 = chain
        .bodies
        .iter()
        .zip(&frames.body)
        .map(|(b, f)| -b.inertial.mass * gravity.dot(&(f * b.inertial.com).coords))
        .sum();
    let load = -payload.mass * gravity.dot(&(frames.flange * Point3::from(payload.com)).coords);
    bodies + load
}
