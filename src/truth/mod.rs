//! The true robot: what the real arm has and the controller does not know.
pub mod command;
pub mod history;
pub mod motion;
pub mod perturbation;
pub mod physics;
pub mod physics_motion;
pub mod resolution;
pub mod robot;
pub mod stiffness;
pub mod thermal;

pub use command::{Command, PathPoint};
pub use history::Visit;
pub use motion::MotionSample;
pub use perturbation::{DeflectionSolver, ErrorModel, KnownGeometry, Offset, Perturbation};
pub use robot::{TrueRobot, TrueState};
pub use thermal::ThermalProfile;
