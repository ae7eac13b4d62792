//! calibench: a benchmark harness for robot absolute-accuracy calibration.
//!
//! Modules follow the pipeline of `DESIGN.md`, each depending only on those to its left:
//! `robot` → `truth` → `tracker` → `campaign` → `measurements` → `calib`; `scenario` reads the
//! configuration of all of them, `rng` and `error` serve every stage. One exception: `design` (experiment
//! design) works on `calib`'s identification Jacobians, and `campaign` calls it to choose the points of a
//! model-based (`d-optimal`) layout, because choosing them is part of planning the campaign.

pub mod calib;
pub mod campaign;
pub mod dataset;
pub mod design;
pub mod error;
pub mod eval;
pub mod measurements;
pub mod output;
pub mod report;
pub mod rng;
pub mod robot;
pub mod scenario;
pub mod study;
pub mod tracker;
pub mod truth;

pub use error::{Error, Result};
