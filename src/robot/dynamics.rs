//! Static dynamics: gravity torques and potential energy of a chain carrying a payload.

use nalgebra::{Point3, Vector3};

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
    let n = chain.dof();
    let mut mass = payload.mass;
    let mut moment = (frames.flange * Point3::from(payload.com)).coords * payload.mass;
    for i in (0..n).rev() {
        let body = &chain.bodies[i + 1];
        mass += body.inertial.mass;
        moment += (frames.body[i + 1] * body.inertial.com).coords * body.inertial.mass;
        let z = frames.axis(chain, i);
        out[i] = match chain.joints[i].kind {
            JointKind::Revolute => {
                let lever = moment - frames.anchor(i).coords * mass;
                z.dot(&lever.cross(gravity))
            }
            JointKind::Prismatic => z.dot(&(gravity * mass)),
        };
    }
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
