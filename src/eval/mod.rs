//! Evaluation: error statistics as the paper reports them, and what the errors of a campaign are made of.
//! The only stage allowed to read the truth.
//!
//! - [`accuracy`]: how accurate a fitted method is on the test split, the ground-truth grid, the shell and in
//!   closed loop (the simulated campaign's `[evaluation]`);
//! - [`oracle`]: the true robot as a method (the floor); [`budget`]: what the errors of a campaign are made of;
//! - [`split`], [`tables`], [`transfer`], [`protocol`]: measured data split, the paper's Tables 1 and 2, a test
//!   campaign re-registered on its own points, and fitting on one real series and testing on another;
//! - [`stats`]: mean, max, std, RMS, p95.

pub mod accuracy;
pub mod budget;
pub mod oracle;
pub mod protocol;
pub mod split;
pub mod stats;
pub mod tables;
pub mod transfer;

pub use crate::calib::rigid::centre;
pub use accuracy::{Evaluation, EvaluationConfig, GroundTruth, evaluate};
pub use budget::{Budget, measured, registered_distances};
pub use oracle::Oracle;
pub use stats::Stats;
