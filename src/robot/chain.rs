//! The robot *model*: an immutable description of a serial chain, in the manner of pinocchio's `Model`.
//!
//! Fixed joints of the URDF are folded away: every link rigidly attached to a moving body becomes part of
//! that body (its inertial merged, its collision shapes re-expressed in the body frame). What remains is
//! `n` movable joints and `n + 1` bodies, body 0 being the base.

use nalgebra::{Isometry3, Matrix3, Point3, Unit, Vector3};
use serde::{Deserialize, Serialize};

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum JointKind {
    Revolute,
    Prismatic,
}

#[derive(Clone, Debug)]
pub struct Joint {
    pub name: String,
    pub kind: JointKind,
    /// Pose of the joint frame in the frame of the preceding body at q = 0 (fixed joints folded in).
    pub origin: Isometry3<f64>,
    /// Motion axis in the joint frame.
    pub axis: Unit<Vector3<f64>>,
    /// Position limits (rad or m); infinite for a continuous joint.
    pub lower: f64,
    pub upper: f64,
    /// Effort limit (Nm or N) as written in the URDF; informative only.
    pub effort: f64,
    /// Velocity limit (rad/s or m/s) as written in the URDF; infinite when not given. Trajectories are timed
    /// against it.
    pub velocity: f64,
}

impl Joint {
    /// The joint's motion as a rigid transform of its own frame.
    #[inline]
    pub fn motion(&self, q: f64) -> Isometry3<f64> {
        match self.kind {
            JointKind::Revolute => Isometry3::rotation(self.axis.into_inner() * q),
            JointKind::Prismatic => {
                Isometry3::translation(self.axis.x * q, self.axis.y * q, self.axis.z * q)
            }
        }
    }

    pub fn within_limits(&self, q: f64) -> bool {
        q >= self.lower && q <= self.upper
    }
}

/// Mass properties of a body, in that body's frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Inertial {
    pub mass: f64,
    pub com: Point3<f64>,
    /// Inertia tensor about the centre of mass, axes of the body frame.
    pub inertia: Matrix3<f64>,
}

impl Inertial {
    pub const ZERO: Inertial = Inertial {
        mass: 0.0,
        com: Point3::new(0.0, 0.0, 0.0),
        inertia: Matrix3::new(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
    };

    /// Re-expresses the inertial in a parent frame where this one's frame sits at `pose`.
    pub fn transformed(&self, pose: &Isometry3<f64>) -> Inertial {
        let r = pose.rotation.to_rotation_matrix();
        Inertial {
            mass: self.mass,
            com: pose * self.com,
            inertia: r.matrix() * self.inertia * r.matrix().transpose(),
        }
    }

    /// Sum of two rigidly joined bodies (parallel-axis theorem about the combined centre of mass).
    pub fn combined(&self, other: &Inertial) -> Inertial {
        let mass = self.mass + other.mass;
        if mass <= 0.0 {
            return Inertial::ZERO;
        }
        let com =
            Point3::from((self.com.coords * self.mass + other.com.coords * other.mass) / mass);
        let shift = |i: &Inertial| {
            let d = i.com - com;
            i.inertia + i.mass * (Matrix3::identity() * d.dot(&d) - d * d.transpose())
        };
        Inertial {
            mass,
            com,
            inertia: shift(self) + shift(other),
        }
    }
}

/// Collision primitives, as URDF has them (meshes are not supported: the harness needs closed-form shapes).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum Shape {
    /// Axis along z of its frame, centred on the frame origin.
    Cylinder {
        radius: f64,
        length: f64,
    },
    /// Axis along z of its frame, centred on the frame origin; `length` excludes the caps.
    Capsule {
        radius: f64,
        length: f64,
    },
    Sphere {
        radius: f64,
    },
    Cuboid {
        half_extents: [f64; 3],
    },
}

#[derive(Clone, Debug)]
pub struct Collider {
    /// Pose of the shape in its body's frame.
    pub origin: Isometry3<f64>,
    pub shape: Shape,
    /// The URDF link it came from, for messages and visualisation.
    pub link: String,
}

#[derive(Clone, Debug)]
pub struct Body {
    /// URDF links merged into this body; the first one defines the body frame.
    pub links: Vec<String>,
    pub inertial: Inertial,
    pub colliders: Vec<Collider>,
}

/// A serial chain: `joints[i]` moves `bodies[i + 1]` relative to `bodies[i]`.
#[derive(Clone, Debug)]
pub struct Chain {
    pub name: String,
    /// Pose of body 0 (the URDF root link) in the world frame. Identity for a nominal robot.
    pub base: Isometry3<f64>,
    pub joints: Vec<Joint>,
    pub bodies: Vec<Body>,
    /// The tool flange: a frame fixed to the last body.
    pub flange: Isometry3<f64>,
    pub flange_link: String,
}

impl Chain {
    /// Number of movable joints (degrees of freedom).
    pub fn dof(&self) -> usize {
        self.joints.len()
    }

    pub fn joint_names(&self) -> Vec<String> {
        self.joints.iter().map(|j| j.name.clone()).collect()
    }

    pub fn lower_limits(&self) -> Vec<f64> {
        self.joints.iter().map(|j| j.lower).collect()
    }

    pub fn upper_limits(&self) -> Vec<f64> {
        self.joints.iter().map(|j| j.upper).collect()
    }

    pub fn within_limits(&self, q: &[f64]) -> bool {
        q.len() == self.dof() && self.joints.iter().zip(q).all(|(j, &v)| j.within_limits(v))
    }

    pub fn total_mass(&self) -> f64 {
        self.bodies.iter().map(|b| b.inertial.mass).sum()
    }
}

/// A joint value drawn uniformly from `[lo, hi]`, for random configurations: an unbounded side (a continuous
/// joint) is cut at ±π, and an empty range gives its middle.
pub fn sample_within(lo: f64, hi: f64, rng: &mut impl rand::Rng) -> f64 {
    let lo = if lo.is_finite() {
        lo
    } else {
        -std::f64::consts::PI
    };
    let hi = if hi.is_finite() {
        hi
    } else {
        std::f64::consts::PI
    };
    if lo < hi {
        rng.random_range(lo..=hi)
    } else {
        0.5 * (lo + hi)
    }
}

/// A mass carried on the flange (tool, reflector nest), in the flange frame.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Payload {
    /// kg
    pub mass: f64,
    /// Centre of mass in the flange frame, m.
    pub com: [f64; 3],
}

impl Payload {
    pub const NONE: Payload = Payload {
        mass: 0.0,
        com: [0.0; 3],
    };
}
