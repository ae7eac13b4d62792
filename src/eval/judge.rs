//! How a fitted method is judged: its errors in every view, computed here once for the evaluation, the study
//! and the trajectory campaigns alike. Four views, all of the measured point (the reflector, or the nest
//! centre) and, where the data has it, of the nest orientation:
//!
//! - **test**: the held-out test split, measured vs predicted — what a user can see (tracker noise included);
//! - **truth**: a dense noise-free grid of every region, true vs predicted — what the user will get;
//! - **shell**: the same on a shell just outside the regions — extrapolation;
//! - **closed loop**: for target poses, the joint command from the method's inverse, run on the true arm,
//!   and the distance to the target — what a controller sent that command would do.
//!
//! Closed-loop targets go into the method's frame as the ground truth's points do
//! ([`GroundTruth::to_method`]), and the distance is taken in the world frame.

use nalgebra::{Point3, UnitQuaternion};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::ground_truth::{GroundTruth, TruthSet};
use crate::calib::method::Fitted;
use crate::campaign::RegionConfig;
use crate::campaign::ground_truth::TruePoint;
use crate::dataset::Dataset;
use crate::error::Result;
use crate::robot::dh::{ChainPose, DhChain};
use crate::truth::{TrueRobot, TrueState};

/// Per-point errors of one view: distances (m) and, where the data has it, orientation angles (rad).
#[derive(Clone, Debug, Default)]
pub struct PointErrors {
    pub position: Vec<f64>,
    pub orientation: Vec<f64>,
    /// Points the method could not handle (closed loop: its inverse did not converge).
    pub failed: usize,
    pub first_failure: Option<String>,
}

/// Measured (the tracker, through the method's registration) vs predicted, on held-out data.
pub fn test_errors(model: &dyn Fitted, test: &Dataset) -> Result<PointErrors> {
    test_errors_at(model, test, None)
}

/// [`test_errors`], the model predicting through `poses` (a [`ChainPose`] of `test`'s every configuration on a
/// nominal chain) where that chain is the model's own.
pub fn test_errors_at(
    model: &dyn Fitted,
    test: &Dataset,
    poses: Option<(&DhChain, &[ChainPose])>,
) -> Result<PointErrors> {
    let observations = model.registration().observe(test)?;
    let poses = usable(model, poses, observations.len());
    let mut e = PointErrors::default();
    for (i, o) in observations.iter().enumerate() {
        let (position, orientation) = predicted(model, &o.q, poses.map(|p| &p[i]), &o.inputs);
        e.position.push((o.position - position).norm());
        if let Some(measured) = o.orientation {
            e.orientation.push(measured.angle_to(&orientation));
        }
    }
    Ok(e)
}

/// `poses` where they are of the model's own nominal chain, one per each of `n` points (else the model
/// evaluates at the configurations themselves).
fn usable<'a>(
    model: &dyn Fitted,
    poses: Option<(&DhChain, &'a [ChainPose])>,
    n: usize,
) -> Option<&'a [ChainPose]> {
    poses
        .filter(|(chain, poses)| poses.len() == n && *chain == model.dh())
        .map(|(_, poses)| poses)
}

/// The model's position and orientation at `q`, through its nominal chain's `pose` there where given.
fn predicted(
    model: &dyn Fitted,
    q: &[f64],
    pose: Option<&ChainPose>,
    inputs: &[f64],
) -> (Point3<f64>, UnitQuaternion<f64>) {
    match pose {
        Some(pose) => model.point_at(pose, inputs),
        None => {
            let p = model.predict_with(q, inputs);
            (p.position, p.orientation)
        }
    }
}

/// True (mapped into the method's frame) vs predicted at the commands of `points`.
pub fn truth_errors(model: &dyn Fitted, truth: &GroundTruth, points: &[TruePoint]) -> PointErrors {
    truth_errors_with(model, truth, points, &[])
}

/// [`truth_errors`] on one of the truth's sets, through the nominal chain's poses it holds.
pub fn truth_set_errors(model: &dyn Fitted, truth: &GroundTruth, set: &TruthSet) -> PointErrors {
    let poses = usable(model, Some((&truth.nominal, &set.poses)), set.points.len());
    errors_at(model, truth, &set.points, poses, &[])
}

/// [`truth_errors`] with the model's extra inputs set to `inputs` at every point (empty: their training means).
pub fn truth_errors_with(
    model: &dyn Fitted,
    truth: &GroundTruth,
    points: &[TruePoint],
    inputs: &[f64],
) -> PointErrors {
    errors_at(model, truth, points, None, inputs)
}

/// [`truth_errors_with`], through `poses` (one per point, of the model's nominal chain) where given.
fn errors_at(
    model: &dyn Fitted,
    truth: &GroundTruth,
    points: &[TruePoint],
    poses: Option<&[ChainPose]>,
    inputs: &[f64],
) -> PointErrors {
    let to_method = truth.to_method(model);
    let with_orientation = model.registration().measures_orientation();
    let per_point: Vec<(f64, Option<f64>)> = points
        .par_iter()
        .enumerate()
        .map(|(i, p)| {
            let (predicted, rotation) = predicted(model, &p.q_cmd, poses.map(|s| &s[i]), inputs);
            let position = to_method * truth.position(&p.true_flange);
            let angle = truth
                .orientation(&p.true_flange)
                .filter(|_| with_orientation)
                .map(|r| (to_method.rotation * r).angle_to(&rotation));
            ((position - predicted).norm(), angle)
        })
        .collect();
    let mut e = PointErrors::default();
    for (d, a) in per_point {
        e.position.push(d);
        e.orientation.extend(a);
    }
    e
}

/// The position errors at `points` of a model whose predictions there are `predicted` already: those of
/// [`truth_errors`], for a model whose predictions are the same every time but for its registration, which
/// only moves the truth into its frame (the oracle registered on each campaign: the true robot).
pub fn truth_position_errors(
    model: &dyn Fitted,
    truth: &GroundTruth,
    points: &[TruePoint],
    predicted: &[Point3<f64>],
) -> Vec<f64> {
    let to_method = truth.to_method(model);
    points
        .iter()
        .zip(predicted)
        .map(|(p, predicted)| (to_method * truth.position(&p.true_flange) - predicted).norm())
        .collect()
}

/// Closed loop: each point's target pose (the flange pose its command reaches on the nominal model, carrying
/// the true measured point and nest), into the method's frame, the method's inverse from the target's nominal
/// command, that command on the true arm (noise-free, fixed-point deflection), and the distance (and angle) to
/// the target in the world frame.
pub fn closed_loop_errors(
    model: &dyn Fitted,
    truth: &GroundTruth,
    robot: &TrueRobot,
    points: &[TruePoint],
) -> PointErrors {
    let to_method = truth.to_method(model);
    let with_orientation = model.registration().measures_orientation();
    let per_point: Vec<std::result::Result<(f64, Option<f64>), String>> = points
        .par_iter()
        .map_init(
            || TrueState::new(robot),
            |state, p| {
                let target = truth.position(&p.nominal_flange);
                let target_rotation = truth
                    .orientation(&p.nominal_flange)
                    .filter(|_| with_orientation);
                let in_method = target_rotation.map(|r| to_method.rotation * r);
                let (command, _) = model
                    .command_for(&(to_method * target), in_method.as_ref(), &p.q_cmd, &[])
                    .map_err(|e| e.to_string())?;
                let reached = robot
                    .flange_pose(&command, state)
                    .map_err(|e| e.to_string())?;
                let angle = target_rotation
                    .zip(truth.orientation(&reached))
                    .map(|(t, r)| r.angle_to(&t));
                Ok(((truth.position(&reached) - target).norm(), angle))
            },
        )
        .collect();
    let mut e = PointErrors::default();
    for outcome in per_point {
        match outcome {
            Ok((d, a)) => {
                e.position.push(d);
                e.orientation.extend(a);
            }
            Err(message) => {
                e.failed += 1;
                e.first_failure.get_or_insert(message);
            }
        }
    }
    e
}

/// A fitted model's errors in every view ([`judge`]).
#[derive(Clone, Debug, Default)]
pub struct Judgement {
    /// Measured vs predicted on the held-out test data.
    pub test: PointErrors,
    /// True vs predicted on the ground-truth grid, and on the shell just outside the regions.
    pub grid: PointErrors,
    pub shell: PointErrors,
    /// Distance to the closed-loop targets reached through the method's inverse on the true arm.
    pub closed_loop: PointErrors,
}

/// Judges `model` in every view: on the held-out `test` data, and on `truth` — its grid, its shell and its
/// closed-loop targets, reached on the true arm `robot`.
/// `test_poses`: the truth's nominal chain ([`GroundTruth::nominal`]) at every test configuration, computed
/// once for every model judged on them (empty: each model evaluates at the configurations).
pub fn judge(
    model: &dyn Fitted,
    (test, test_poses): (&Dataset, &[ChainPose]),
    truth: &GroundTruth,
    robot: &TrueRobot,
) -> Result<Judgement> {
    Ok(Judgement {
        test: test_errors_at(model, test, Some((&truth.nominal, test_poses)))?,
        grid: truth_set_errors(model, truth, &truth.grid),
        shell: truth_set_errors(model, truth, &truth.shell),
        closed_loop: closed_loop_errors(model, truth, robot, &truth.closed_loop.points),
    })
}

impl Judgement {
    /// The first view (test set, grid, shell) with a prediction that is not a finite number: a model that
    /// extrapolated to nonsense there has no statistics to report.
    pub fn non_finite_view(&self) -> Option<&'static str> {
        [
            ("test set", &self.test),
            ("ground-truth grid", &self.grid),
            ("shell", &self.shell),
        ]
        .into_iter()
        .find(|(_, e)| e.position.iter().any(|d| !d.is_finite()))
        .map(|(view, _)| view)
    }
}

/// Ground-truth errors of one run in one band of distance from its training region, over the ground-truth
/// points (grid and shell) of one region where the calibration is used.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct DistanceBand {
    pub use_region: String,
    /// Band of distance from the training region's box (m): `from < d ≤ to`; `from = to = 0` is inside,
    /// `to = ∞` the last band.
    pub from_m: f64,
    pub to_m: f64,
    pub points: usize,
    /// Mean ground-truth position error (m).
    pub mean: f64,
}

/// Ground-truth errors of `model`, fitted in region `training` of `regions`, by distance from that region's box
/// over the grid and shell of every region: bands `edges` (m, ascending) apart. The training region's own
/// errors are `judged`'s; the other regions' are predicted here.
pub fn by_distance(
    model: &dyn Fitted,
    training: usize,
    regions: &[(&RegionConfig, &GroundTruth)],
    judged: &Judgement,
    edges: &[f64],
) -> Vec<DistanceBand> {
    let box_of_training = regions[training].0;
    let mut bands = Vec::new();
    for (r, &(region, truth)) in regions.iter().enumerate() {
        let points = truth.grid.points.iter().chain(&truth.shell.points);
        let errors: Vec<f64> = if r == training {
            judged
                .grid
                .position
                .iter()
                .chain(&judged.shell.position)
                .copied()
                .collect()
        } else {
            let mut e = truth_set_errors(model, truth, &truth.grid).position;
            e.extend(truth_set_errors(model, truth, &truth.shell).position);
            e
        };
        // Band 0 is inside; band i ≥ 1 is (edge[i-2], edge[i-1]], the last one beyond every edge.
        let mut sums = vec![(0usize, 0.0f64); edges.len() + 2];
        for (p, e) in points.zip(&errors) {
            let d = box_of_training.distance(&Point3::from(p.nominal_flange.translation.vector));
            let band = if d == 0.0 {
                0
            } else {
                1 + edges.iter().take_while(|&&b| d > b).count()
            };
            sums[band].0 += 1;
            sums[band].1 += e;
        }
        for (band, (count, sum)) in sums.into_iter().enumerate() {
            if count == 0 {
                continue;
            }
            let (from_m, to_m) = match band {
                0 => (0.0, 0.0),
                b => (
                    if b == 1 { 0.0 } else { edges[b - 2] },
                    edges.get(b - 1).copied().unwrap_or(f64::INFINITY),
                ),
            };
            bands.push(DistanceBand {
                use_region: region.name.clone(),
                from_m,
                to_m,
                points: count,
                mean: sum / count as f64,
            });
        }
    }
    bands
}
