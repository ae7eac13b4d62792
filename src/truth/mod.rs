//! The true robot: what the real arm has and the controller does not know.
pub mod perturbation;
pub mod physics;
pub mod robot;

pub use perturbation::{ErrorModel, Perturbation};
pub use robot::{DeflectionSolver, TrueRobot, TrueState};
