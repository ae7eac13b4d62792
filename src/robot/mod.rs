//! The nominal robot: a serial chain loaded from URDF, its kinematics, statics and inverse kinematics.
//!
//! The [`Chain`] is the immutable model; [`Frames`] is the per-call workspace.

pub mod chain;
pub mod collision;
pub mod description;
pub mod dh;
pub mod dynamics;
pub mod export;
pub mod ik;
pub mod inverse_dynamics;
pub mod kinematics;
pub mod plausible;
pub mod urdf;

pub use chain::{Body, Chain, Collider, Inertial, Joint, JointKind, Payload, Shape};
pub use description::{AngleUnit, load};
pub use inverse_dynamics::JointRates;
pub use kinematics::{Frames, flange_pose, forward_kinematics, point_jacobian};
