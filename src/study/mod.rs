//! The study: every (region, layout, method, training-set size, seed) run of a scenario's `[study]` section,
//! judged against the truth — *how many tracker points, placed how, with which method*.
//!
//! This file holds the data the stages exchange: the configuration, one [`RunMetrics`] per run (a row of
//! `metrics.csv`), and the [`Detail`] of one representative run that the report's histograms and the rerun
//! recording show point by point. SI units throughout; the report converts to millimetres.

use std::collections::BTreeMap;

use nalgebra::{Isometry3, Point3, Vector3};
use serde::{Deserialize, Serialize};

use crate::calib::registry::MethodKind;
use crate::campaign::{LayoutKind, RegionConfig};
use crate::design::Indices;
use crate::eval::Stats;
pub use crate::eval::judge::DistanceBand;
use crate::world::WorldConfig;

pub mod config;
mod jobs;
pub mod limits;
mod measure;
mod progress;
pub mod shard;
pub mod sweep;
pub mod trajectory;

pub use config::StudyConfig;
pub use limits::Limits;
pub use shard::{Shard, StudyPart};

/// Which run: the key of a `metrics.csv` row.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct RunKey {
    pub region: String,
    pub layout: LayoutKind,
    pub method: MethodKind,
    pub n_train: usize,
    pub seed: u64,
}

/// One run's outcome: a `metrics.csv` row. Statistics in metres and radians.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct RunMetrics {
    pub key: RunKey,
    /// `None` when the run succeeded; the reason when it failed (the sweep goes on).
    pub failure: Option<String>,
    /// Held-out test split: measured vs predicted.
    pub test: Option<Stats>,
    /// Noise-free ground-truth grid: true vs predicted.
    pub truth: Option<Stats>,
    /// The shell just outside the region.
    pub outside: Option<Stats>,
    /// Closed loop: distance to ground-truth targets reached through the method's inverse.
    pub closed_loop: Option<Stats>,
    /// The oracle's ground-truth mean for the same campaign (the floor), m.
    pub floor_mean: Option<f64>,
    /// Orientation errors (rad) when the campaign measures orientation.
    pub test_orientation: Option<Stats>,
    pub truth_orientation: Option<Stats>,
    /// Ground-truth errors by distance from the training region, per region of use (non-empty bands only).
    pub by_distance: Vec<DistanceBand>,
    /// Observability indices of the training points for the method's model (`None` for methods without
    /// robot parameters, and for failed runs).
    pub observability: Option<Indices>,
    /// Wall time of the fit (ms); the only field that varies between two runs of the same scenario.
    pub fit_ms: f64,
}

/// The data of one method's before/after histogram: its per-point test-split errors (m) and the nominal
/// model's on the same points.
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct Histogram {
    pub before: Vec<f64>,
    pub after: Vec<f64>,
}

/// One measured point of the detail campaign, in the world frame.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct DetailPoint {
    pub q_cmd: Vec<f64>,
    /// True flange pose (the robot drawn at this point).
    pub true_flange: Isometry3<f64>,
    /// Where the point really was (world frame).
    pub true_position: Point3<f64>,
    /// Error before calibration: nominal prediction − true position (m, world frame).
    pub error_before: Vector3<f64>,
    /// Error after calibration with the detail method: its prediction − true position (m, world frame).
    pub error_after: Vector3<f64>,
}

/// A ground-truth grid point with the detail method's residual error.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct GridPoint {
    pub true_position: Point3<f64>,
    /// |prediction − truth| of the detail method (m).
    pub residual: f64,
}

/// The run shown point by point: the largest size, the first layout and seed, of the first region.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Detail {
    pub region: String,
    pub layout: LayoutKind,
    pub method: MethodKind,
    pub n_train: usize,
    /// Training and validation points of the campaign.
    pub points: Vec<DetailPoint>,
    /// The region's ground-truth grid with the detail method's residuals.
    pub grid: Vec<GridPoint>,
    /// Test-split errors before (nominal) and after, per method, at the largest size (first layout and seed).
    pub histograms: BTreeMap<MethodKind, Histogram>,
    /// The tracker's true pose (world ← tracker), for drawing it and its beams.
    pub tracker: Isometry3<f64>,
}

/// Everything the report and the recording need.
#[derive(Clone, Debug, Serialize)]
pub struct StudyResult {
    /// The world the study ran in: the scenario's name, seed, robot, true errors, tracker and reflectors.
    pub world: WorldConfig,
    pub config: StudyConfig,
    pub regions: Vec<RegionConfig>,
    /// Every run, in a fixed order (region, layout, method, size, seed): independent of threads.
    pub runs: Vec<RunMetrics>,
    pub detail: Detail,
    /// Whether the campaign measures orientation (three reflectors).
    pub orientation: bool,
    /// Per region, what the tracker's noise and the arm's repeatability leave (empty when not computed).
    pub limits: Vec<Limits>,
    /// The trajectory campaigns' runs (`[study.trajectory]`; empty without it).
    pub trajectory: Vec<trajectory::TrajectoryRun>,
    /// The trajectory the recording shows sample by sample.
    pub trajectory_detail: Option<trajectory::TrajectoryDetail>,
}
