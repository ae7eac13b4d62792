//! Inverse dynamics of a serial chain: the joint torques `τ = M(q) q̈ + C(q, q̇) q̇ − τ_g(q)` that move it along
//! `q(t)`, by the recursive Newton–Euler algorithm (Luh, Walker and Paul 1980; Featherstone, *Rigid Body Dynamics
//! Algorithms*, 2008, ch. 5) written with world-frame vectors on the frames of a forward-kinematics pass, so
//! that it runs on any geometry that pass produced (the true robot's tilted, thermally scaled links included).
//!
//! At rest (`q̇ = q̈ = 0`) it is `−τ_g` of [`super::dynamics::gravity_torques`]: the torque a joint must supply to
//! hold the arm, of the opposite sign to what gravity applies. Gravity enters as an upward acceleration of the
//! base (the usual trick), so one pass gives the inertial and the gravity terms together.

use nalgebra::{Matrix3, Point3, Vector3};

use super::chain::{Chain, JointKind, Payload};
use super::dynamics::{GravityJoint, gravity_moments_of};
use super::kinematics::Frames;

/// Per-call workspace of [`inverse_dynamics`].
#[derive(Clone, Debug)]
pub struct Workspace {
    omega: Vec<Vector3<f64>>,
    alpha: Vec<Vector3<f64>>,
    /// Linear acceleration of each body's frame origin (world, gravity included as −g at the base).
    accel: Vec<Vector3<f64>>,
    force: Vec<Vector3<f64>>,
    /// Moment about the body's centre of mass.
    moment: Vec<Vector3<f64>>,
    /// The geometry of the frames of the last [`inverse_dynamics`] call, which [`inverse_dynamics_again`]
    /// reuses: each joint's axis and anchor, each body's centre of mass, its offset from the body's origin and
    /// its inertia (world), the payload's centre of mass.
    axis: Vec<Vector3<f64>>,
    anchor: Vec<Vector3<f64>>,
    com: Vec<Vector3<f64>>,
    com_offset: Vec<Vector3<f64>>,
    inertia: Vec<Matrix3<f64>>,
    payload_com: Vector3<f64>,
}

impl Workspace {
    pub fn new(chain: &Chain) -> Workspace {
        let n = chain.dof() + 1;
        Workspace {
            omega: vec![Vector3::zeros(); n],
            alpha: vec![Vector3::zeros(); n],
            accel: vec![Vector3::zeros(); n],
            force: vec![Vector3::zeros(); n],
            moment: vec![Vector3::zeros(); n],
            axis: vec![Vector3::zeros(); n],
            anchor: vec![Vector3::zeros(); n],
            com: vec![Vector3::zeros(); n],
            com_offset: vec![Vector3::zeros(); n],
            inertia: vec![Matrix3::zeros(); n],
            payload_com: Vector3::zeros(),
        }
    }
}

impl Workspace {
    /// The velocities, accelerations, forces and moments of `other`'s last pass up to body `upto`, for
    /// [`inverse_dynamics_from`].
    pub fn copy_motion_from(&mut self, other: &Workspace, upto: usize) {
        for (to, from) in [
            (&mut self.omega, &other.omega),
            (&mut self.alpha, &other.alpha),
            (&mut self.accel, &other.accel),
            (&mut self.force, &other.force),
            (&mut self.moment, &other.moment),
        ] {
            to[..=upto].copy_from_slice(&from[..=upto]);
        }
    }
}

/// Acceleration of the point `p` of a body whose frame origin `o` has acceleration `a`, turning at `omega`
/// with angular acceleration `alpha`.
#[inline]
fn point_accel(
    a: &Vector3<f64>,
    omega: &Vector3<f64>,
    alpha: &Vector3<f64>,
    r: &Vector3<f64>,
) -> Vector3<f64> {
    a + alpha.cross(r) + omega.cross(&omega.cross(r))
}

/// Joint velocities (rad/s) and accelerations (rad/s²), in the chain's joint order: what the controller commands
/// with the angles at a sample of a path.
#[derive(Clone, Debug, PartialEq)]
pub struct JointRates {
    pub qd: Vec<f64>,
    pub qdd: Vec<f64>,
}

/// Joint torques (Nm; N for a prismatic joint) that move the chain, in the configuration of `frames` (a
/// forward-kinematics pass at `q`), with joint velocities `qd` and accelerations `qdd`, carrying `payload` at
/// the flange, under `gravity` (world frame). Fills `out`.
#[allow(clippy::too_many_arguments)]
pub fn inverse_dynamics(
    chain: &Chain,
    frames: &Frames,
    payload: &Payload,
    gravity: &Vector3<f64>,
    qd: &[f64],
    qdd: &[f64],
    ws: &mut Workspace,
    out: &mut [f64],
) {
    geometry(chain, frames, payload, ws);
    inverse_dynamics_again(chain, frames, payload, gravity, qd, qdd, ws, out);
}

/// What the passes read of `frames` alone, into `ws`: [`inverse_dynamics`]'s first half, which
/// [`inverse_dynamics_again`], [`mass_matrix_column`] and [`gravity_moments_again`] then reuse.
pub fn geometry(chain: &Chain, frames: &Frames, payload: &Payload, ws: &mut Workspace) {
    geometry_from(chain, frames, payload, ws, 0);
}

/// [`geometry`] of joint `from` and body `from` on, the rest of `ws` kept: after a change of the frames from
/// body `from` on alone (one joint's angle moved), the geometry of the whole `frames`.
pub fn geometry_from(
    chain: &Chain,
    frames: &Frames,
    payload: &Payload,
    ws: &mut Workspace,
    from: usize,
) {
    let n = chain.dof();
    for i in from..n {
        ws.axis[i] = frames.axis(chain, i);
        ws.anchor[i] = frames.anchor(i).coords;
    }
    for b in from.max(1)..=n {
        let body = &chain.bodies[b];
        let frame = &frames.body[b];
        let com = frame * body.inertial.com;
        ws.com[b] = com.coords;
        ws.com_offset[b] = com.coords - frame.translation.vector;
        let rot = frame.rotation.to_rotation_matrix();
        ws.inertia[b] = rot.matrix() * body.inertial.inertia * rot.matrix().transpose();
    }
    if payload.mass > 0.0 {
        ws.payload_com = (frames.flange * Point3::from(payload.com)).coords;
    }
}

/// [`inverse_dynamics`] on the same `frames` (and chain and payload) as the last call with `ws`, at other rates
/// or gravity: the world axes, centres of mass and inertias are that call's, the arithmetic the same (a
/// linearisation's columns, a dozen passes on one posture): the Newton–Euler recursion on the geometry in `ws`,
/// which [`inverse_dynamics`] computes first.
#[allow(clippy::too_many_arguments)]
pub fn inverse_dynamics_again(
    chain: &Chain,
    frames: &Frames,
    payload: &Payload,
    gravity: &Vector3<f64>,
    qd: &[f64],
    qdd: &[f64],
    ws: &mut Workspace,
    out: &mut [f64],
) {
    // The base's motion: gravity as an upward acceleration.
    ws.omega[0] = Vector3::zeros();
    ws.alpha[0] = Vector3::zeros();
    ws.accel[0] = -gravity;
    inverse_dynamics_from(chain, frames, payload, qd, qdd, ws, out, 0);
}

/// [`inverse_dynamics_again`] whose bodies up to body `from` move as in an earlier pass, whose velocities,
/// accelerations, forces and moments up to there `ws` holds ([`Workspace::copy_motion_from`]): a pass that
/// differs from it only in joint `from`'s rate or in the frames beyond body `from` (a linearisation's column),
/// computed from joint `from` on — the bodies before it the same bits.
#[allow(clippy::too_many_arguments)]
pub fn inverse_dynamics_from(
    chain: &Chain,
    frames: &Frames,
    payload: &Payload,
    qd: &[f64],
    qdd: &[f64],
    ws: &mut Workspace,
    out: &mut [f64],
    from: usize,
) {
    let n = chain.dof();
    assert!(
        qd.len() == n && qdd.len() == n && out.len() == n && from < n,
        "velocity, acceleration and output lengths must equal the chain's dof"
    );
    // Forward: velocities and accelerations, base to tip.
    for i in from..n {
        let (axis, anchor) = (ws.axis[i], ws.anchor[i]);
        let parent_origin = frames.body[i].translation.vector;
        let origin = frames.body[i + 1].translation.vector;
        let (w, al, a) = (ws.omega[i], ws.alpha[i], ws.accel[i]);
        // The joint's anchor is a point of the parent body.
        let a_anchor = point_accel(&a, &w, &al, &(anchor - parent_origin));
        match chain.joints[i].kind {
            JointKind::Revolute => {
                let spin = axis * qd[i];
                ws.omega[i + 1] = w + spin;
                ws.alpha[i + 1] = al + axis * qdd[i] + w.cross(&spin);
                let omega = ws.omega[i + 1];
                // The body's origin turns about the anchor with the child's motion.
                ws.accel[i + 1] =
                    point_accel(&a_anchor, &omega, &ws.alpha[i + 1], &(origin - anchor));
            }
            JointKind::Prismatic => {
                ws.omega[i + 1] = w;
                ws.alpha[i + 1] = al;
                ws.accel[i + 1] = point_accel(&a_anchor, &w, &al, &(origin - anchor))
                    + w.cross(&(axis * qd[i])) * 2.0
                    + axis * qdd[i];
            }
        }
    }
    // Per body: the force and the moment about its centre of mass that move it.
    for b in from + 1..=n {
        let m = chain.bodies[b].inertial.mass;
        let a_com = point_accel(&ws.accel[b], &ws.omega[b], &ws.alpha[b], &ws.com_offset[b]);
        let inertia = &ws.inertia[b];
        let w = ws.omega[b];
        ws.force[b] = a_com * m;
        ws.moment[b] = inertia * ws.alpha[b] + w.cross(&(inertia * w));
    }
    // Backward: everything beyond joint i, reduced to its anchor.
    let mut f = Vector3::zeros();
    let mut n_about_origin = Vector3::zeros();
    let mut reduced_at = frames.flange.translation.vector;
    if payload.mass > 0.0 {
        let p = ws.payload_com;
        let last = n;
        let origin = frames.body[last].translation.vector;
        let a = point_accel(
            &ws.accel[last],
            &ws.omega[last],
            &ws.alpha[last],
            &(p - origin),
        );
        f = a * payload.mass;
        reduced_at = p;
    }
    for i in (0..n).rev() {
        let b = i + 1;
        let (com, anchor) = (ws.com[b], ws.anchor[i]);
        // Moment about the anchor of what lies beyond (already reduced to `reduced_at`) plus this body.
        n_about_origin = n_about_origin
            + (reduced_at - anchor).cross(&f)
            + ws.moment[b]
            + (com - anchor).cross(&ws.force[b]);
        f += ws.force[b];
        reduced_at = anchor;
        out[i] = along_joint(chain.joints[i].kind, &ws.axis[i], &n_about_origin, &f);
    }
}

/// [`super::dynamics::gravity_moments`] on the geometry in `ws` (the last [`geometry`] call's, on the same
/// `frames`): the centres of mass, axes and anchors that pass computes are those [`geometry`] computed, by the
/// same expressions, so the torques and moments are the same bits without computing them twice (a moving arm's
/// fixed point needs both the gravity moments and the inverse dynamics of each iterate).
pub fn gravity_moments_again(
    chain: &Chain,
    frames: &Frames,
    payload: &Payload,
    gravity: &Vector3<f64>,
    ws: &Workspace,
    torques: &mut [f64],
    moments: &mut [Vector3<f64>],
) {
    gravity_moments_of(chain, frames, payload, gravity, torques, moments, |i| {
        GravityJoint {
            mass: chain.bodies[i + 1].inertial.mass,
            com: Point3::from(ws.com[i + 1]),
            axis: ws.axis[i],
            anchor: Point3::from(ws.anchor[i]),
            prismatic: matches!(chain.joints[i].kind, JointKind::Prismatic),
        }
    });
}

/// Column `j` of the mass matrix on the geometry in `ws` (the last [`geometry`] call's, on the same `frames`):
/// [`inverse_dynamics_again`] from rest (`q̇ = 0`), without gravity, at a unit acceleration of joint `j`, with
/// the terms that are then exact zeros left out — the angular velocities, the Coriolis and centripetal terms, and
/// the bodies before joint `j`, which stay at rest. Leaving out an addition of ±0 changes no nonzero result, so
/// every entry equals the general pass's, bit for bit but for the sign of an entry that is exactly zero.
pub fn mass_matrix_column(
    chain: &Chain,
    frames: &Frames,
    payload: &Payload,
    j: usize,
    ws: &mut Workspace,
    out: &mut [f64],
) {
    let n = chain.dof();
    assert!(
        j < n && out.len() == n,
        "the column must be a joint and the output's length the chain's dof"
    );
    // Forward from joint j: the bodies before it at rest, those beyond turning at joint j's unit acceleration.
    let (mut alpha, mut accel) = (Vector3::zeros(), Vector3::zeros());
    for i in j..n {
        let (axis, anchor) = (ws.axis[i], ws.anchor[i]);
        let parent_origin = frames.body[i].translation.vector;
        let origin = frames.body[i + 1].translation.vector;
        let a_anchor = accel + alpha.cross(&(anchor - parent_origin));
        match chain.joints[i].kind {
            JointKind::Revolute => {
                if i == j {
                    alpha += axis;
                }
                accel = a_anchor + alpha.cross(&(origin - anchor));
            }
            JointKind::Prismatic => {
                accel = a_anchor + alpha.cross(&(origin - anchor));
                if i == j {
                    accel += axis;
                }
            }
        }
        ws.alpha[i + 1] = alpha;
        ws.accel[i + 1] = accel;
    }
    for b in j + 1..=n {
        let m = chain.bodies[b].inertial.mass;
        let a_com = ws.accel[b] + ws.alpha[b].cross(&ws.com_offset[b]);
        ws.force[b] = a_com * m;
        ws.moment[b] = ws.inertia[b] * ws.alpha[b];
    }
    // Backward, as in the general pass; the bodies at rest add nothing.
    let mut f = Vector3::zeros();
    let mut n_about_origin = Vector3::zeros();
    let mut reduced_at = frames.flange.translation.vector;
    if payload.mass > 0.0 {
        let p = ws.payload_com;
        let origin = frames.body[n].translation.vector;
        let a = ws.accel[n] + ws.alpha[n].cross(&(p - origin));
        f = a * payload.mass;
        reduced_at = p;
    }
    for i in (0..n).rev() {
        let b = i + 1;
        let anchor = ws.anchor[i];
        n_about_origin += (reduced_at - anchor).cross(&f);
        if b > j {
            n_about_origin =
                n_about_origin + ws.moment[b] + (ws.com[b] - anchor).cross(&ws.force[b]);
            f += ws.force[b];
        }
        reduced_at = anchor;
        out[i] = along_joint(chain.joints[i].kind, &ws.axis[i], &n_about_origin, &f);
    }
}

/// What a joint carries of the moment about its anchor and the force beyond it: the moment along a revolute
/// joint's axis, the force along a prismatic one's.
fn along_joint(
    kind: JointKind,
    axis: &Vector3<f64>,
    moment: &Vector3<f64>,
    force: &Vector3<f64>,
) -> f64 {
    match kind {
        JointKind::Revolute => axis.dot(moment),
        JointKind::Prismatic => axis.dot(force),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robot::dynamics::{GRAVITY, gravity_moments, gravity_torques};
    use crate::robot::forward_kinematics;
    use nalgebra::DMatrix;

    fn iiwa() -> Chain {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("robots/iiwa7.urdf");
        crate::robot::urdf::load_file(&path, None).unwrap()
    }

    fn torques(
        chain: &Chain,
        p: &Payload,
        q: &[f64],
        qd: &[f64],
        qdd: &[f64],
        g: &Vector3<f64>,
    ) -> Vec<f64> {
        let mut frames = Frames::new(chain);
        forward_kinematics(chain, q, &mut frames);
        let mut ws = Workspace::new(chain);
        let mut out = vec![0.0; chain.dof()];
        inverse_dynamics(chain, &frames, p, g, qd, qdd, &mut ws, &mut out);
        out
    }

    const Q: [f64; 7] = [0.3, -0.7, 0.5, 1.2, -0.4, 0.9, 0.2];
    const PAYLOAD: Payload = Payload {
        mass: 1.5,
        com: [0.01, -0.02, 0.06],
    };

    #[test]
    fn at_rest_it_holds_the_arm_against_gravity() {
        let chain = iiwa();
        let zero = [0.0; 7];
        let tau = torques(&chain, &PAYLOAD, &Q, &zero, &zero, &GRAVITY);
        let mut frames = Frames::new(&chain);
        forward_kinematics(&chain, &Q, &mut frames);
        let mut g = vec![0.0; 7];
        gravity_torques(&chain, &frames, &PAYLOAD, &GRAVITY, &mut g);
        for (t, g) in tau.iter().zip(&g) {
            assert!((t + g).abs() < 1e-10, "{t} against {}", -g);
        }
    }

    /// The pass from rest gives the general pass's mass-matrix columns: bit for bit at postures without exact
    /// zeros, in value at the zero posture (whose world axes have exact zero components).
    #[test]
    fn a_mass_matrix_column_is_the_general_pass_from_rest() {
        let chain = iiwa();
        let (zero, none) = ([0.0; 7], Vector3::zeros());
        let other = [-1.1, 0.4, -2.0, -0.3, 1.7, -1.2, 2.5];
        for (q, payload, bits) in [
            (Q, PAYLOAD, true),
            (other, Payload::NONE, true),
            (zero, PAYLOAD, false),
        ] {
            let mut frames = Frames::new(&chain);
            forward_kinematics(&chain, &q, &mut frames);
            let mut ws = Workspace::new(&chain);
            let (mut general, mut column) = (vec![0.0; 7], vec![0.0; 7]);
            for j in 0..7 {
                let mut unit = [0.0; 7];
                unit[j] = 1.0;
                inverse_dynamics(
                    &chain,
                    &frames,
                    &payload,
                    &none,
                    &zero,
                    &unit,
                    &mut ws,
                    &mut general,
                );
                mass_matrix_column(&chain, &frames, &payload, j, &mut ws, &mut column);
                for (g, c) in general.iter().zip(&column) {
                    assert!(
                        *g == *c && (!bits || g.to_bits() == c.to_bits()),
                        "column {j}: {g} against {c}"
                    );
                }
            }
        }
    }

    /// The gravity pass on the inverse dynamics' geometry is `gravity_moments`, bit for bit.
    #[test]
    fn gravity_moments_on_the_geometry_are_the_same_bits() {
        let chain = iiwa();
        let mut frames = Frames::new(&chain);
        forward_kinematics(&chain, &Q, &mut frames);
        let mut ws = Workspace::new(&chain);
        geometry(&chain, &frames, &PAYLOAD, &mut ws);
        let (mut t0, mut t1) = (vec![0.0; 7], vec![0.0; 7]);
        let (mut m0, mut m1) = (vec![Vector3::zeros(); 7], vec![Vector3::zeros(); 7]);
        gravity_moments(&chain, &frames, &PAYLOAD, &GRAVITY, &mut t0, &mut m0);
        gravity_moments_again(&chain, &frames, &PAYLOAD, &GRAVITY, &ws, &mut t1, &mut m1);
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&t0), bits(&t1));
        assert!(t0.iter().filter(|t| t.abs() > 1e-3).count() >= 4, "{t0:?}");
        for (a, b) in m0.iter().zip(&m1) {
            assert_eq!(bits(a.as_slice()), bits(b.as_slice()));
        }
    }

    /// The mass matrix from unit accelerations (no gravity, no velocity) is symmetric positive definite.
    #[test]
    fn the_mass_matrix_is_symmetric_positive_definite() {
        let chain = iiwa();
        let zero = [0.0; 7];
        let none = Vector3::zeros();
        let m = DMatrix::from_fn(7, 7, |r, c| {
            let mut e = [0.0; 7];
            e[c] = 1.0;
            torques(&chain, &PAYLOAD, &Q, &zero, &e, &none)[r]
        });
        assert!((&m - m.transpose()).amax() < 1e-12, "{m}");
        assert!(m.clone().cholesky().is_some(), "{m}");
    }

    /// Power balance along a path: without gravity, q̇ᵀτ = dT/dt, the kinetic energy's rate, with T from
    /// finite-difference velocities of every body (an independent computation).
    #[test]
    fn the_torques_supply_the_rate_of_kinetic_energy() {
        let chain = iiwa();
        let none = Vector3::zeros();
        let q_at = |t: f64| -> Vec<f64> {
            (0..7)
                .map(|j| Q[j] + 0.4 * (1.3 * t + j as f64).sin())
                .collect()
        };
        let kinetic = |t: f64| -> f64 {
            let h = 1e-6;
            let (mut a, mut b) = (Frames::new(&chain), Frames::new(&chain));
            forward_kinematics(&chain, &q_at(t - h), &mut a);
            forward_kinematics(&chain, &q_at(t + h), &mut b);
            let mut energy = 0.0;
            for k in 1..=7 {
                let body = &chain.bodies[k];
                let (ca, cb) = (a.body[k] * body.inertial.com, b.body[k] * body.inertial.com);
                let v = (cb - ca) / (2.0 * h);
                let w =
                    (b.body[k].rotation * a.body[k].rotation.inverse()).scaled_axis() / (2.0 * h);
                let mut mid = Frames::new(&chain);
                forward_kinematics(&chain, &q_at(t), &mut mid);
                let rot = mid.body[k].rotation.to_rotation_matrix();
                let inertia = rot.matrix() * body.inertial.inertia * rot.matrix().transpose();
                energy += 0.5 * body.inertial.mass * v.norm_squared() + 0.5 * w.dot(&(inertia * w));
            }
            energy
        };
        for t in [0.0, 0.7, 1.9] {
            let h = 1e-4;
            let qd: Vec<f64> = (0..7)
                .map(|j| (q_at(t + h)[j] - q_at(t - h)[j]) / (2.0 * h))
                .collect();
            let qdd: Vec<f64> = (0..7)
                .map(|j| (q_at(t + h)[j] - 2.0 * q_at(t)[j] + q_at(t - h)[j]) / (h * h))
                .collect();
            let tau = torques(&chain, &Payload::NONE, &q_at(t), &qd, &qdd, &none);
            let power: f64 = tau.iter().zip(&qd).map(|(a, b)| a * b).sum();
            let dt = 1e-3;
            let rate = (kinetic(t + dt) - kinetic(t - dt)) / (2.0 * dt);
            assert!(
                (power - rate).abs() < 1e-4 * (1.0 + rate.abs()),
                "t {t}: power {power} W, dT/dt {rate} W"
            );
        }
    }
}
