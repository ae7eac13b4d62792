//! How accurate each fitted method really is. Four views, all of the measured point (the reflector, or the
//! nest centre) and, where the data has it, of the nest orientation:
//!
//! - **test**: the held-out test split, measured vs predicted — what a user can see (tracker noise included);
//! - **truth**: a dense noise-free grid of every region, true vs predicted — what the user will get;
//! - **shell**: the same on a shell just outside the regions — extrapolation;
//! - **closed loop**: for target poses, the joint command from the method's inverse, run on the true arm,
//!   and the distance to the target — what a controller sent that command would do.
//!
//! A method predicts in its own registered frame `R = tracker_to_base · tracker`. The truth lives in the world
//! frame `W`, and the tracker's true pose is `T_trk` (world ← tracker); a true world point goes into `R` as
//! `tracker_to_base · T_trk⁻¹ · p_W`, which is what a perfect tracker would have measured seen through the
//! method's own registration. Closed-loop targets go into `R` the same way and the distance is taken in `W`.

use std::collections::BTreeMap;
use std::fmt::Write as _;

use nalgebra::{Isometry3, Point3, UnitQuaternion, Vector3};
use rand::Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::oracle::{Oracle, nest_rotation};
use super::split::Parts;
use super::stats::Stats;
use crate::calib::method::{FitContext, Fitted};
use crate::calib::registry::{self, MethodKind};
use crate::calib::regression::RegressionOptions;
use crate::campaign::ground_truth::{GROUND_TRUTH_ATTEMPT, TruePoint};
use crate::campaign::{
    CampaignConfig, DistributionKind, Generator, RegionConfig, Rejections, Simulation,
};
use crate::dataset::{Dataset, random_split};
use crate::error::{Error, Result};
use crate::measurements::as_dataset;
use crate::rng::Stream;
use crate::truth::{TrueRobot, TrueState};
use crate::world::World;

/// The name the oracle goes by in a scenario's method list and in reports.
pub const ORACLE: &str = "oracle";
/// No ground-truth set may ask for more points than this per region.
const MAX_SET_POINTS: usize = 1_000_000;

fn default_methods() -> Vec<String> {
    MethodKind::ALL
        .iter()
        .map(|m| m.name().to_string())
        .collect()
}
fn default_split() -> [f64; 3] {
    [0.5, 0.25, 0.25]
}
fn default_grid_points() -> usize {
    2000
}
fn default_shell_width() -> f64 {
    0.05
}
fn default_shell_points() -> usize {
    500
}
fn default_closed_loop_points() -> usize {
    200
}

/// The `[evaluation]` section of a scenario: which methods to fit on the campaign, and how to judge them.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct EvaluationConfig {
    /// Methods to fit, by name (`nominal`, `paper-rotz`, …); the oracle is always added.
    #[serde(default = "default_methods")]
    pub methods: Vec<String>,
    /// Train, validation and test fractions of the campaign's points.
    #[serde(default = "default_split")]
    pub split: [f64; 3],
    /// Seed of the split; the scenario's seed when absent.
    #[serde(default)]
    pub split_seed: Option<u64>,
    /// Points of the noise-free ground-truth grid, per region (a lattice: at least this many candidates).
    #[serde(default = "default_grid_points")]
    pub grid_points: usize,
    /// Thickness of the extrapolation shell around each region (m).
    #[serde(default = "default_shell_width")]
    pub shell_width_m: f64,
    /// Candidate points of the shell, per region; 0 skips it.
    #[serde(default = "default_shell_points")]
    pub shell_points: usize,
    /// Closed-loop targets per region; 0 skips the closed loop.
    #[serde(default = "default_closed_loop_points")]
    pub closed_loop_points: usize,
}

impl Default for EvaluationConfig {
    fn default() -> Self {
        EvaluationConfig {
            methods: default_methods(),
            split: default_split(),
            split_seed: None,
            grid_points: default_grid_points(),
            shell_width_m: default_shell_width(),
            shell_points: default_shell_points(),
            closed_loop_points: default_closed_loop_points(),
        }
    }
}

impl EvaluationConfig {
    pub fn validate(&self) -> std::result::Result<(), String> {
        for (i, name) in self.methods.iter().enumerate() {
            if name != ORACLE {
                MethodKind::parse(name).map_err(|e| format!("methods: {}", e.detail()))?;
            }
            if self.methods[..i].contains(name) {
                return Err(format!("methods: '{name}' is listed twice"));
            }
        }
        if self.split.iter().any(|f| !(f.is_finite() && *f > 0.0))
            || (self.split.iter().sum::<f64>() - 1.0).abs() > 1e-9
        {
            return Err(format!(
                "split {:?} must be three positive fractions (train, val, test) summing to 1",
                self.split
            ));
        }
        if self.grid_points == 0 {
            return Err("grid_points must be at least 1".into());
        }
        for (name, n) in [
            ("grid_points", self.grid_points),
            ("shell_points", self.shell_points),
            ("closed_loop_points", self.closed_loop_points),
        ] {
            if n > MAX_SET_POINTS {
                return Err(format!("{name} = {n} exceeds {MAX_SET_POINTS}"));
            }
        }
        if !(self.shell_width_m.is_finite() && self.shell_width_m > 0.0) {
            return Err(format!(
                "shell_width_m = {} must be finite and positive",
                self.shell_width_m
            ));
        }
        Ok(())
    }

    /// The listed methods a user can fit (everything but the oracle), in order.
    pub fn kinds(&self) -> Result<Vec<MethodKind>> {
        self.methods
            .iter()
            .filter(|m| *m != ORACLE)
            .map(|m| MethodKind::parse(m))
            .collect()
    }
}

/// Noise-free true points of one kind, over all regions.
#[derive(Clone, Debug, Default)]
pub struct TruthSet {
    pub points: Vec<TruePoint>,
    /// Per region: candidates, feasible, and why the others were dropped.
    pub rejections: BTreeMap<String, Rejections>,
}

/// What the evaluation knows that no method does.
#[derive(Clone, Debug)]
pub struct GroundTruth {
    /// The tracker's true pose, world ← tracker.
    pub tracker_pose: Isometry3<f64>,
    /// The true measured point (reflector, or nest centre) in the flange frame.
    pub measured_point: Point3<f64>,
    /// The nest's true rotation from its drawing; `None` for a single reflector.
    pub nest_rotation: Option<UnitQuaternion<f64>>,
    /// A lattice over each region.
    pub grid: TruthSet,
    /// Points within `shell_width_m` outside each region's box.
    pub shell: TruthSet,
    /// Closed-loop targets: uniform in each region.
    pub closed_loop: TruthSet,
}

/// What every method fitted in `world` may know: its nominal robot and the payload the user declares.
pub fn fit_context(world: &World) -> FitContext<'_> {
    FitContext {
        chain: &world.nominal,
        dh: &world.dh,
        payload: world.payload(),
        regression: RegressionOptions::default(),
    }
}

/// Set numbers: each draws its own layouts and orientations.
const GRID: u64 = 0;
const SHELL: u64 = 1;
const CLOSED_LOOP: u64 = 2;

impl GroundTruth {
    /// The ground truth of `regions` in `world`, with the campaign's posture and obstacles (`campaign`).
    pub fn build(
        world: &World,
        campaign: &CampaignConfig,
        regions: &[RegionConfig],
        config: &EvaluationConfig,
    ) -> Result<GroundTruth> {
        let generator = Generator {
            world,
            config: campaign,
            seed: world.seed(),
            selector: None,
        };
        let layout_rng =
            |r: u64, set: u64| world.rng(Stream::Layout, &[r, GROUND_TRUTH_ATTEMPT + set]);
        let mut grid = TruthSet::default();
        let mut shell = TruthSet::default();
        let mut closed_loop = TruthSet::default();
        for (r, region) in regions.iter().enumerate() {
            let r = r as u64;
            let unit = DistributionKind::Grid.build().sample(
                config.grid_points,
                region.size_m,
                &mut layout_rng(r, GRID),
            );
            grid.add(region, generator.ground_truth(r, GRID, region, &unit)?);

            if config.shell_points > 0 {
                let (grown, unit) = shell_layout(
                    region,
                    config.shell_width_m,
                    config.shell_points,
                    &mut layout_rng(r, SHELL),
                );
                shell.add(region, generator.ground_truth(r, SHELL, &grown, &unit)?);
            }

            if config.closed_loop_points > 0 {
                let unit = DistributionKind::Uniform.build().sample(
                    config.closed_loop_points,
                    region.size_m,
                    &mut layout_rng(r, CLOSED_LOOP),
                );
                closed_loop.add(
                    region,
                    generator.ground_truth(r, CLOSED_LOOP, region, &unit)?,
                );
            }
        }
        Ok(GroundTruth {
            tracker_pose: world.tracker.pose,
            measured_point: super::centre(&world.mounting.actual),
            nest_rotation: nest_rotation(&world.mounting)?,
            grid,
            shell,
            closed_loop,
        })
    }

    /// The true measured point of a flange pose (world).
    pub fn position(&self, flange: &Isometry3<f64>) -> Point3<f64> {
        flange * self.measured_point
    }

    /// The true nest orientation of a flange pose (world), for nests.
    pub fn orientation(&self, flange: &Isometry3<f64>) -> Option<UnitQuaternion<f64>> {
        self.nest_rotation.map(|r| flange.rotation * r)
    }

    /// World → the registered frame of `model`: `tracker_to_base · T_trk⁻¹`.
    pub fn to_method(&self, model: &dyn Fitted) -> Isometry3<f64> {
        model.registration().frame.tracker_to_base * self.tracker_pose.inverse()
    }
}

impl TruthSet {
    fn add(&mut self, region: &RegionConfig, (points, counts): (Vec<TruePoint>, Rejections)) {
        self.points.extend(points);
        self.rejections.insert(region.name.clone(), counts);
    }
}

/// The region's box grown by `width` on every side, and `n` uniform points of it (unit coordinates of the grown
/// box) that lie outside the original box.
fn shell_layout(
    region: &RegionConfig,
    width: f64,
    n: usize,
    rng: &mut rand_chacha::ChaCha8Rng,
) -> (RegionConfig, Vec<[f64; 3]>) {
    let grown = RegionConfig {
        size_m: region.size_m.map(|s| s + 2.0 * width),
        ..region.clone()
    };
    let centre = Vector3::from(region.center_m);
    let half = Vector3::from(region.size_m) / 2.0;
    let outside = |u: &[f64; 3]| {
        let d = grown.point_at(u).coords - centre;
        (0..3).any(|k| d[k].abs() > half[k])
    };
    let mut unit = Vec::with_capacity(n);
    // At least a fraction 1 − s/(s + 2w) ≥ 2w/(s + 2w) of the grown box lies outside; the bound on draws only
    // guards against a pathological width.
    for _ in 0..n.saturating_mul(10_000) {
        if unit.len() == n {
            break;
        }
        let u = [rng.random(), rng.random(), rng.random()];
        if outside(&u) {
            unit.push(u);
        }
    }
    (grown, unit)
}

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
    let observations = model.registration().observe(test)?;
    let mut e = PointErrors::default();
    for o in &observations {
        let pred = model.predict_with(&o.q, &o.inputs);
        e.position.push((o.position - pred.position).norm());
        if let Some(measured) = o.orientation {
            e.orientation.push(measured.angle_to(&pred.orientation));
        }
    }
    Ok(e)
}

/// True (mapped into the method's frame) vs predicted at the commands of `points`.
pub fn truth_errors(model: &dyn Fitted, truth: &GroundTruth, points: &[TruePoint]) -> PointErrors {
    truth_errors_with(model, truth, points, &[])
}

/// [`truth_errors`] with the model's extra inputs set to `inputs` at every point (empty: their training means).
pub fn truth_errors_with(
    model: &dyn Fitted,
    truth: &GroundTruth,
    points: &[TruePoint],
    inputs: &[f64],
) -> PointErrors {
    let to_method = truth.to_method(model);
    let with_orientation = model.registration().measures_orientation();
    let per_point: Vec<(f64, Option<f64>)> = points
        .par_iter()
        .map(|p| {
            let pred = model.predict_with(&p.q_cmd, inputs);
            let position = to_method * truth.position(&p.true_flange);
            let angle = truth
                .orientation(&p.true_flange)
                .filter(|_| with_orientation)
                .map(|r| (to_method.rotation * r).angle_to(&pred.orientation));
            ((position - pred.position).norm(), angle)
        })
        .collect();
    let mut e = PointErrors::default();
    for (d, a) in per_point {
        e.position.push(d);
        e.orientation.extend(a);
    }
    e
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
                    .command_for(&(to_method * target), in_method.as_ref(), &p.q_cmd)
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

/// Statistics of one view: position in millimetres, orientation in radians.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct Summary {
    /// `None` when the view has no point (or a prediction was not finite).
    pub position_mm: Option<Stats>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub orientation_rad: Option<Stats>,
    pub failed: usize,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub first_failure: Option<String>,
}

impl PointErrors {
    pub fn summary(&self) -> Summary {
        Summary {
            position_mm: Stats::of(&self.position).map(|s| s.scaled(1e3)),
            orientation_rad: Stats::of(&self.orientation),
            failed: self.failed,
            first_failure: self.first_failure.clone(),
        }
    }
}

/// One method's evaluation, or why it has none.
#[derive(Clone, Debug, Serialize)]
pub struct MethodReport {
    pub method: String,
    /// `ok` or `failed`.
    pub status: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub test: Option<Summary>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub truth: Option<Summary>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub shell: Option<Summary>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub closed_loop: Option<Summary>,
}

impl MethodReport {
    fn failed(method: &str, error: &Error) -> MethodReport {
        MethodReport {
            method: method.to_string(),
            status: "failed".into(),
            error: Some(error.to_string()),
            test: None,
            truth: None,
            shell: None,
            closed_loop: None,
        }
    }
}

#[derive(Clone, Debug, Serialize)]
pub struct SplitReport {
    pub fractions: [f64; 3],
    pub seed: u64,
    pub train: usize,
    pub val: usize,
    pub test: usize,
}

#[derive(Clone, Debug, Serialize)]
pub struct SetReport {
    pub points: usize,
    pub rejections: BTreeMap<String, Rejections>,
}

impl SetReport {
    fn of(set: &TruthSet) -> SetReport {
        SetReport {
            points: set.points.len(),
            rejections: set.rejections.clone(),
        }
    }
}

#[derive(Clone, Debug, Serialize)]
pub struct SetsReport {
    pub grid: SetReport,
    pub shell: SetReport,
    pub shell_width_m: f64,
    pub closed_loop: SetReport,
}

/// `evaluation.json`: every listed method and the oracle, on every view.
#[derive(Clone, Debug, Serialize)]
pub struct Evaluation {
    pub scenario: String,
    pub units: String,
    pub split: SplitReport,
    pub ground_truth: SetsReport,
    pub methods: Vec<MethodReport>,
}

/// The campaign's points as a method sees them (`measurements.csv` read back), split into train, val and test.
pub fn split_campaign(
    sim: &Simulation,
    fractions: [f64; 3],
    seed: u64,
) -> Result<(Dataset, Dataset, Dataset)> {
    let data = as_dataset(&sim.campaign, "the campaign's measurements")?;
    let parts = Parts::of(&data, random_split(data.len(), fractions, seed)?);
    Ok((parts.train, parts.val, parts.test))
}

/// Every view of one fitted method.
pub fn evaluate_method(
    model: &dyn Fitted,
    test: &Dataset,
    truth: &GroundTruth,
    robot: &TrueRobot,
) -> Result<MethodReport> {
    let views = |points: &[TruePoint], closed: bool| -> Option<Summary> {
        if points.is_empty() {
            return None;
        }
        Some(
            if closed {
                closed_loop_errors(model, truth, robot, points)
            } else {
                truth_errors(model, truth, points)
            }
            .summary(),
        )
    };
    Ok(MethodReport {
        method: model.method().to_string(),
        status: "ok".into(),
        error: None,
        test: Some(test_errors(model, test)?.summary()),
        truth: views(&truth.grid.points, false),
        shell: views(&truth.shell.points, false),
        closed_loop: views(&truth.closed_loop.points, true),
    })
}

/// Fits every method of `config` on the simulated campaign, adds the oracle, and evaluates them all. A method
/// that cannot be fitted (or evaluated) is reported as failed, with the reason, and the others go on. The
/// ground truth covers `regions` with the campaign's posture and obstacles (`campaign`).
pub fn evaluate(
    sim: &Simulation,
    campaign: &CampaignConfig,
    regions: &[RegionConfig],
    config: &EvaluationConfig,
) -> Result<Evaluation> {
    let world = &sim.world;
    let seed = config.split_seed.unwrap_or(world.seed());
    let (train, val, test) = split_campaign(sim, config.split, seed)?;
    let truth = GroundTruth::build(world, campaign, regions, config)?;
    let ctx = fit_context(world);
    let kinds = config.kinds()?;
    let mut methods: Vec<MethodReport> = kinds
        .par_iter()
        .map(|&kind| {
            registry::fit(kind, &ctx, &train, &val)
                .and_then(|model| evaluate_method(model.as_ref(), &test, &truth, &world.robot))
                .unwrap_or_else(|e| MethodReport::failed(kind.name(), &e))
        })
        .collect();
    let oracle = Oracle::new(world)?.registered_on(&[&train, &val])?;
    methods.push(
        evaluate_method(&oracle, &test, &truth, &world.robot)
            .unwrap_or_else(|e| MethodReport::failed(ORACLE, &e)),
    );
    Ok(Evaluation {
        scenario: world.config.name.clone(),
        units: "positions in mm, orientations in rad".into(),
        split: SplitReport {
            fractions: config.split,
            seed,
            train: train.len(),
            val: val.len(),
            test: test.len(),
        },
        ground_truth: SetsReport {
            grid: SetReport::of(&truth.grid),
            shell: SetReport::of(&truth.shell),
            shell_width_m: config.shell_width_m,
            closed_loop: SetReport::of(&truth.closed_loop),
        },
        methods,
    })
}

impl Evaluation {
    /// The table a person reads: per method, mean / p95 / max of every view; failed methods with their reason.
    pub fn table(&self) -> String {
        let g = &self.ground_truth;
        let mut out = format!(
            "accuracy of the measured point (mm)\n  test: measured vs predicted on {} held-out points; \
             truth: true vs predicted on a {}-point noise-free grid;\n  shell: the same on {} points within {} mm \
             outside; closed loop: distance to {} targets reached through the method's inverse on the true arm\n",
            self.split.test,
            g.grid.points,
            g.shell.points,
            g.shell_width_m * 1e3,
            g.closed_loop.points
        );
        fn views(m: &MethodReport) -> [&Option<Summary>; 4] {
            [&m.test, &m.truth, &m.shell, &m.closed_loop]
        }
        let header = |out: &mut String| {
            let _ = write!(out, "  {:<22}", "method");
            for view in ["test", "truth", "shell"] {
                let _ = write!(out, " | {view:<26}");
            }
            out.push_str(" | closed loop\n");
            let _ = write!(out, "  {:<22}", "");
            for _ in 0..4 {
                let _ = write!(out, " | {:>8} {:>8} {:>8}", "mean", "p95", "max");
            }
            out.push('\n');
        };
        let row =
            |out: &mut String, m: &MethodReport, pick: fn(&Summary) -> Option<Stats>, digits| {
                let _ = write!(out, "  {:<22}", m.method);
                for view in views(m) {
                    match view.as_ref().and_then(pick) {
                        Some(s) => {
                            let _ = write!(
                                out,
                                " | {:>8.*} {:>8.*} {:>8.*}",
                                digits, s.mean, digits, s.p95, digits, s.max
                            );
                        }
                        None => {
                            let _ = write!(out, " | {:>8} {:>8} {:>8}", "-", "-", "-");
                        }
                    }
                }
                if let Some(failed) = m.closed_loop.as_ref().filter(|c| c.failed > 0) {
                    let _ = write!(out, "  ({} closed-loop targets failed)", failed.failed);
                }
                out.push('\n');
            };
        header(&mut out);
        let ok: Vec<&MethodReport> = self.methods.iter().filter(|m| m.error.is_none()).collect();
        for m in &ok {
            row(&mut out, m, |s| s.position_mm, 4);
        }
        if ok.iter().any(|m| {
            views(m)
                .iter()
                .any(|v| v.as_ref().is_some_and(|s| s.orientation_rad.is_some()))
        }) {
            out.push_str("orientation of the nest (rad), same views:\n");
            header(&mut out);
            for m in &ok {
                row(&mut out, m, |s| s.orientation_rad, 6);
            }
        }
        for m in self.methods.iter().filter(|m| m.error.is_some()) {
            let _ = writeln!(
                out,
                "  {:<22} failed: {}",
                m.method,
                m.error.as_deref().unwrap_or_default()
            );
        }
        out
    }
}
