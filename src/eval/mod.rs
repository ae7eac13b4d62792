//! Evaluation: error statistics as the paper reports them, and what the errors of a campaign are made of.
//! The only stage allowed to read the truth.
//!
//! - [`ground_truth`]: the noise-free true points of every region (grid, shell, closed-loop targets);
//! - [`judge`]: a fitted method's errors on the test split, the ground-truth grid, the shell and in closed loop —
//!   the one place a fit is judged, for the evaluation, the study and `calibrate --truth`;
//! - [`accuracy`]: the simulated campaign's `[evaluation]` (`evaluation.json`);
//! - [`pose_accuracy`]: ISO 9283's AP and RP of one commanded pose; [`iso9283`]: the standard's test cube run
//!   on the simulated arm for every fitted method (`[iso9283]`, `iso9283.csv`); [`iso_cubes`]: AP and RP on the
//!   cubes of a real file that repeats their points (`calibrate`);
//! - [`oracle`]: the true robot as a method (the floor); [`budget`]: what the errors of a campaign are made of;
//! - [`split`], [`tables`], [`transfer`], [`protocol`]: measured data split, the paper's Tables 1 and 2, a test
//!   campaign re-registered on its own points, and fitting on one real series and testing on another;
//! - [`curve`]: the learning curve of a measured file (`calibrate curve`, and `real_data`'s);
//! - [`stats`]: mean, max, std, RMS, p95.

pub mod accuracy;
pub mod budget;
pub mod curve;
pub mod ground_truth;
pub mod iso9283;
pub mod iso_cubes;
pub mod judge;
pub mod oracle;
pub mod pose_accuracy;
pub mod protocol;
pub mod split;
pub mod stats;
pub mod tables;
pub mod transfer;

pub use crate::calib::rigid::centre;
pub use accuracy::{Evaluation, EvaluationConfig, Fits, evaluate, fit_all, judge_all};
pub use budget::{Budget, measured, registered_distances};
pub use ground_truth::{GroundTruth, GroundTruthConfig};
pub use iso9283::Iso9283Config;
pub use judge::{Judgement, judge};
pub use oracle::Oracle;
pub use stats::Stats;
