//! The pilot campaign a twin is built from: read and checked (enough points, every joint moved), and its own
//! statistics — each method's error on points it was not fitted on, the spread of repeated configurations, the
//! drift of the residual along the campaign's order — computed the same way on the real pilot and on its replay
//! through a candidate twin, so the two compare.

use std::path::Path;

use nalgebra::{Point3, Vector3};
use rand::seq::SliceRandom;

use crate::calib::method::FitContext;
use crate::calib::registry::MethodKind;
use crate::calib::rigid::{centre, register_points};
use crate::dataset::mapping::ColumnMapping;
use crate::dataset::range::JointRange;
use crate::dataset::{Dataset, random_train_val};
use crate::error::{Error, Result};
use crate::eval::split::Parts;
use crate::eval::transfer::{self, TestRegistration};
use crate::rng::{Stream, derive};
use crate::robot::Chain;
use crate::robot::kinematics::flange_pose;

/// A pilot with fewer points is refused: four folds of cross-validation must each leave a training set of at
/// least 40 points and a validation set for the elastic fit's ~40 parameters (three equations a point).
pub const MIN_PILOT_POINTS: usize = 80;

/// Every joint must move at least this much over the pilot (rad, 20°): a joint that barely moves leaves its
/// geometry and compliance undetermined, and the twin would extrapolate it.
pub const MIN_JOINT_RANGE_RAD: f64 = 0.35;

/// Folds of the pilot's cross-validation: each point is held out once, every method fitted on the other
/// three quarters (two thirds training, one third validation, as `calibrate` splits).
pub const FOLDS: usize = 4;

/// Configurations within this of each other (rad, every joint) are the same pose measured again.
const REPEAT_TOLERANCE_RAD: f64 = 1e-3;

/// Reads the pilot (through `mapping` for a foreign export), checks it against the robot's joint ranges, and
/// drops its extra inputs when asked — after taking its temperature column, which the twin's warm-up follows
/// whether or not the methods may regress on it.
pub fn read(
    chain: &Chain,
    robot: &Path,
    file: &Path,
    mapping: Option<&Path>,
    ignore_inputs: bool,
) -> Result<(Dataset, Option<Vec<f64>>)> {
    let mut data = match mapping {
        Some(m) => ColumnMapping::load(m)?.read(file, chain)?,
        None => Dataset::read(file, &chain.joint_names())?,
    };
    JointRange::of_chain(chain, &robot.display().to_string()).check(
        &data.origin,
        &data.point_ids,
        &data.q,
    )?;
    let temperature = varying_input(&data, crate::dataset::TEMPERATURE_COLUMN);
    if ignore_inputs {
        data.extra_inputs = None;
    }
    Ok((data, temperature))
}

/// Refuses a pilot too small or too narrow to identify the arm, saying how many more points or which joints'
/// ranges it needs.
pub fn check(data: &Dataset, chain: &Chain) -> Result<()> {
    let refuse = |message: String| Error::Data {
        origin: data.origin.clone(),
        message,
    };
    if data.len() < MIN_PILOT_POINTS {
        return Err(refuse(format!(
            "a pilot of {} points is too small to build a twin: measure at least {} more (a twin needs \
             {MIN_PILOT_POINTS})",
            data.len(),
            MIN_PILOT_POINTS - data.len()
        )));
    }
    let narrow: Vec<String> = chain
        .joint_names()
        .iter()
        .enumerate()
        .filter_map(|(j, name)| {
            let (lo, hi) = data
                .q
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), q| {
                    (lo.min(q[j]), hi.max(q[j]))
                });
            (hi - lo < MIN_JOINT_RANGE_RAD)
                .then(|| format!("{name} ({:.1}°)", (hi - lo).to_degrees()))
        })
        .collect();
    if !narrow.is_empty() {
        return Err(refuse(format!(
            "the pilot moves {} less than {:.0}°: measure poses that turn {} further, or the twin cannot \
             identify {}",
            narrow.join(", "),
            MIN_JOINT_RANGE_RAD.to_degrees(),
            if narrow.len() == 1 { "it" } else { "them" },
            if narrow.len() == 1 {
                "that joint"
            } else {
                "those joints"
            }
        )));
    }
    Ok(())
}

/// The pilot's fold of each point: a seeded shuffle of the row numbers, dealt in turn, so it depends on the
/// number of points and the seed only — the real pilot and its replay are folded alike.
pub fn folds(n: usize, seed: u64) -> Vec<usize> {
    let mut order: Vec<usize> = (0..n).collect();
    order.shuffle(&mut derive(seed, Stream::Split, &[FOLDS as u64]));
    let mut fold = vec![0; n];
    for (k, &i) in order.iter().enumerate() {
        fold[i] = k % FOLDS;
    }
    fold
}

/// One method's error on the pilot's held-out points (every point once), mm: the mean, or why it failed.
#[derive(Clone, Debug, serde::Serialize)]
pub struct HeldOut {
    pub method: MethodKind,
    pub mean_mm: Option<f64>,
    pub failure: Option<String>,
}

/// Each method of `methods` cross-validated on `data` over [`FOLDS`] folds: fitted on three quarters (split
/// two to one into training and validation, seeded), tested on the quarter held out through its own
/// registration, the distances pooled over the folds.
pub fn held_out(
    data: &Dataset,
    ctx: &FitContext,
    methods: &[MethodKind],
    seed: u64,
) -> Vec<HeldOut> {
    let fold = folds(data.len(), seed);
    methods
        .iter()
        .map(|&method| {
            let mut distances = Vec::with_capacity(data.len());
            for f in 0..FOLDS {
                let outcome = fold_errors(data, ctx, method, &fold, f, seed);
                match outcome {
                    Ok(d) => distances.extend(d),
                    Err(e) => {
                        return HeldOut {
                            method,
                            mean_mm: None,
                            failure: Some(e.detail()),
                        };
                    }
                }
            }
            HeldOut {
                method,
                mean_mm: Some(1e3 * distances.iter().sum::<f64>() / distances.len() as f64),
                failure: None,
            }
        })
        .collect()
}

/// The distances (m) of fold `f`'s points from `method`'s predictions, fitted on the other folds.
fn fold_errors(
    data: &Dataset,
    ctx: &FitContext,
    method: MethodKind,
    fold: &[usize],
    f: usize,
    seed: u64,
) -> Result<Vec<f64>> {
    let pool: Vec<usize> = (0..data.len()).filter(|&i| fold[i] != f).collect();
    let held: Vec<usize> = (0..data.len()).filter(|&i| fold[i] == f).collect();
    let subset = data.subset(&pool);
    let labels = random_train_val(pool.len(), 2.0 / 3.0, seed ^ (f as u64 + 1))?;
    let Parts { train, val, .. } = Parts::of(&subset, labels);
    let model = method.fit(ctx, &train, &val)?;
    let test = transfer::evaluate(model.as_ref(), &data.subset(&held), TestRegistration::Model)?;
    Ok(test.errors.position)
}

/// Configurations measured more than once: how many groups, and the mean distance (m) of a measurement's
/// residual from its group's mean residual — the arm's repeatability with the tracker's noise, as the methods
/// see them. The residual is what the nominal kinematics at the recorded angles, registered onto the
/// measurements, leaves: a real arm records a repeated configuration a few 1e-5 rad apart, which its position
/// need not follow (the IPA UR10's series B: 3–10e-5 rad between repeats, while the raw points lie closer
/// together than those angles put them), and a twin replays the recorded angles as motion; on residuals both
/// count as what the angles do not explain.
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct Repeats {
    pub groups: usize,
    pub measurements: usize,
    pub mean_distance_m: f64,
}

impl Repeats {
    /// `None` without a configuration measured twice, or where the nominal points cannot be registered.
    /// `probe`: the measured point (the reflector, or a nest's centre) in the flange frame.
    pub fn of(data: &Dataset, chain: &Chain, probe: &Point3<f64>) -> Option<Repeats> {
        let mut groups: std::collections::BTreeMap<Vec<i64>, Vec<usize>> = Default::default();
        for (i, q) in data.q.iter().enumerate() {
            let key = q
                .iter()
                .map(|v| (v / REPEAT_TOLERANCE_RAD).round() as i64)
                .collect();
            groups.entry(key).or_default().push(i);
        }
        groups.retain(|_, members| members.len() > 1);
        if groups.is_empty() {
            return None;
        }
        let nominal: Vec<Point3<f64>> = data
            .q
            .iter()
            .map(|q| flange_pose(chain, q) * probe)
            .collect();
        let measured: Vec<Point3<f64>> = data.measured.iter().map(|m| centre(m)).collect();
        let registered = register_points(&nominal, &measured).ok()?.transform;
        let residual = |i: usize| measured[i] - registered * nominal[i];
        let mut distances = Vec::new();
        for members in groups.values() {
            let mean =
                members.iter().map(|&i| residual(i)).sum::<Vector3<f64>>() / members.len() as f64;
            distances.extend(members.iter().map(|&i| (residual(i) - mean).norm()));
        }
        Some(Repeats {
            groups: groups.len(),
            measurements: distances.len(),
            mean_distance_m: distances.iter().sum::<f64>() / distances.len() as f64,
        })
    }
}

/// A column of the data's extra inputs by name, when it has one that varies.
pub fn varying_input(data: &Dataset, name: &str) -> Option<Vec<f64>> {
    let x = data.extra_inputs.as_ref()?;
    let k = x.names.iter().position(|n| n == name)?;
    let column: Vec<f64> = x.values.iter().map(|row| row[k]).collect();
    let (lo, hi) = column
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(*v), hi.max(*v))
        });
    (hi > lo).then_some(column)
}
