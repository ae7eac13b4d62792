//! Evaluation: error statistics as the paper reports them, and what the errors of a campaign are made of.
//! The only stage allowed to read the truth.

pub mod budget;
pub mod oracle;
pub mod protocol;
pub mod split;
pub mod stats;
pub mod tables;
pub mod transfer;
pub mod truth;

pub use crate::calib::rigid::centre;
pub use budget::{Budget, measured, registered_distances};
pub use oracle::Oracle;
pub use stats::Stats;
pub use truth::{Evaluation, EvaluationConfig, GroundTruth, evaluate};
