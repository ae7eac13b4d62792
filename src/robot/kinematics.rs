//! Forward kinematics and geometric Jacobians over a [`Chain`] and a per-call [`Frames`] workspace.

use nalgebra::{Isometry3, Matrix6xX, Point3, Vector3};

use super::chain::{Chain, JointKind};

/// Per-call workspace (pinocchio's `Data`): every frame of one configuration, in the world frame.
#[derive(Clone, Debug)]
pub struct Frames {
    /// Frame of joint `i` before its own motion; its axis and anchor are the joint's screw.
    pub joint: Vec<Isometry3<f64>>,
    /// Frame of body `i` (body 0 is the base).
    pub body: Vec<Isometry3<f64>>,
    pub flange: Isometry3<f64>,
}

impl Frames {
    pub fn new(chain: &Chain) -> Self {
        Frames {
            joint: vec![Isometry3::identity(); chain.dof()],
            body: vec![Isometry3::identity(); chain.dof() + 1],
            flange: Isometry3::identity(),
        }
    }

    /// World direction of joint `i`'s axis.
    #[inline]
    pub fn axis(&self, chain: &Chain, i: usize) -> Vector3<f64> {
        self.joint[i].rotation * chain.joints[i].axis.into_inner()
    }

    /// A point on joint `i`'s axis.
    #[inline]
    pub fn anchor(&self, i: usize) -> Point3<f64> {
        Point3::from(self.joint[i].translation.vector)
    }
}

/// Fills `frames` for configuration `q` (length = dof; a shorter or longer slice is a caller bug).
pub fn forward_kinematics(chain: &Chain, q: &[f64], frames: &mut Frames) {
    assert_eq!(
        q.len(),
        chain.dof(),
        "configuration length must equal the chain's dof"
    );
    let mut pose = chain.base;
    frames.body[0] = pose;
    for (i, (joint, &qi)) in chain.joints.iter().zip(q).enumerate() {
        let joint_frame = pose * joint.origin;
        frames.joint[i] = joint_frame;
        pose = joint_frame * joint.motion(qi);
        frames.body[i + 1] = pose;
    }
    frames.flange = pose * chain.flange;
}

/// Flange pose in the world frame, without a workspace.
pub fn flange_pose(chain: &Chain, q: &[f64]) -> Isometry3<f64> {
    assert_eq!(
        q.len(),
        chain.dof(),
        "configuration length must equal the chain's dof"
    );
    let mut pose = chain.base;
    for (joint, &qi) in chain.joints.iter().zip(q) {
        pose = pose * joint.origin * joint.motion(qi);
    }
    pose * chain.flange
}

/// Geometric Jacobian of a point fixed to the last body, given in world coordinates: rows 0–2 the
/// point's linear velocity, rows 3–5 the angular velocity, one column per joint.
pub fn point_jacobian(chain: &Chain, frames: &Frames, point: &Point3<f64>) -> Matrix6xX<f64> {
    let mut jac = Matrix6xX::zeros(chain.dof());
    point_jacobian_into(chain, frames, point, &mut jac);
    jac
}

pub fn point_jacobian_into(
    chain: &Chain,
    frames: &Frames,
    point: &Point3<f64>,
    jac: &mut Matrix6xX<f64>,
) {
    for i in 0..chain.dof() {
        let prismatic = matches!(chain.joints[i].kind, JointKind::Prismatic);
        let (lin, ang) = joint_column(&frames.axis(chain, i), &frames.anchor(i), point, prismatic);
        jac.fixed_view_mut::<3, 1>(0, i).copy_from(&lin);
        jac.fixed_view_mut::<3, 1>(3, i).copy_from(&ang);
    }
}

/// One column of a geometric Jacobian: the velocity of the world point `point` moved by a joint at unit rate,
/// and the angular velocity, for the joint of world axis `axis` through `anchor`. The one formula behind every
/// Jacobian here, of the URDF chain ([`point_jacobian`]) and of the DH chain
/// ([`crate::calib::method::nominal_jacobian`], the error model's chain).
#[inline]
pub fn joint_column(
    axis: &Vector3<f64>,
    anchor: &Point3<f64>,
    point: &Point3<f64>,
    prismatic: bool,
) -> (Vector3<f64>, Vector3<f64>) {
    if prismatic {
        (*axis, Vector3::zeros())
    } else {
        (axis.cross(&(point - anchor)), *axis)
    }
}

/// Jacobian of the flange frame origin (angular rows: the flange's angular velocity).
pub fn flange_jacobian(chain: &Chain, frames: &Frames) -> Matrix6xX<f64> {
    point_jacobian(
        chain,
        frames,
        &Point3::from(frames.flange.translation.vector),
    )
}
