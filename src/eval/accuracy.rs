//! The simulated campaign's `[evaluation]`: every listed method fitted on a split of the campaign, the oracle
//! beside them, each judged in every view ([`super::judge`]) and written to `evaluation.json`.

use std::collections::BTreeMap;
use std::fmt::Write as _;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::ground_truth::{GroundTruth, GroundTruthConfig, TruthSet};
use super::judge::{Judgement, PointErrors, judge};
use super::oracle::{ORACLE, Oracle};
use super::split::Parts;
use super::stats::Stats;
use crate::calib::method::{FitContext, Fitted, MethodInfo};
use crate::calib::registry::MethodKind;
use crate::campaign::ground_truth::TruePoint;
use crate::campaign::{CampaignConfig, RegionConfig, Rejections, Simulation};
use crate::dataset::{Dataset, random_split};
use crate::error::{Error, Result};
use crate::measurements::as_dataset;
use crate::robot::dh::ChainPose;
use crate::truth::TrueRobot;

fn default_methods() -> Vec<MethodKind> {
    MethodKind::ALL.to_vec()
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
    /// Methods to fit (`nominal`, `paper-rotz`, …); the oracle is always added.
    #[serde(default = "default_methods")]
    pub methods: Vec<MethodKind>,
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
        for (i, method) in self.methods.iter().enumerate() {
            if self.methods[..i].contains(method) {
                return Err(format!("methods: '{method}' is listed twice"));
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
        self.ground_truth().validate()
    }

    /// The ground-truth sets the methods are judged on.
    pub fn ground_truth(&self) -> GroundTruthConfig {
        GroundTruthConfig {
            grid_points: self.grid_points,
            shell_width_m: self.shell_width_m,
            shell_points: self.shell_points,
            closed_loop_points: self.closed_loop_points,
        }
    }
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
    pub method: &'static MethodInfo,
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
    /// The statistics of every view `judged` has points in.
    fn judged(
        method: &'static MethodInfo,
        judged: &Judgement,
        truth: &GroundTruth,
    ) -> MethodReport {
        let view = |points: &[TruePoint], errors: &PointErrors| {
            (!points.is_empty()).then(|| errors.summary())
        };
        MethodReport {
            method,
            status: "ok".into(),
            error: None,
            test: Some(judged.test.summary()),
            truth: view(&truth.grid.points, &judged.grid),
            shell: view(&truth.shell.points, &judged.shell),
            closed_loop: view(&truth.closed_loop.points, &judged.closed_loop),
        }
    }

    fn failed(method: &'static MethodInfo, error: &Error) -> MethodReport {
        MethodReport {
            method,
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

/// Every view of one fitted method, for `evaluation.json`.
pub fn evaluate_method(
    model: &dyn Fitted,
    test: (&Dataset, &[ChainPose]),
    truth: &GroundTruth,
    robot: &TrueRobot,
) -> Result<MethodReport> {
    let judged = judge(model, test, truth, robot)?;
    Ok(MethodReport::judged(model.info(), &judged, truth))
}

/// The methods of an `[evaluation]`, each fitted on the campaign's training split (validation for its
/// hyper-parameters), or why it could not be; the test split is kept for judging them.
pub struct Fits {
    /// The split's seed.
    pub seed: u64,
    pub train: Dataset,
    pub val: Dataset,
    pub test: Dataset,
    /// In the order of `config.methods`.
    pub models: Vec<(MethodKind, Result<Box<dyn Fitted>>)>,
}

/// Fits every method of `config` on the split of the simulated campaign.
pub fn fit_all(sim: &Simulation, config: &EvaluationConfig) -> Result<Fits> {
    let seed = config.split_seed.unwrap_or(sim.world.seed());
    let (train, val, test) = split_campaign(sim, config.split, seed)?;
    let ctx = FitContext::of(&sim.world);
    let models = config
        .methods
        .par_iter()
        .map(|&kind| (kind, kind.fit(&ctx, &train, &val)))
        .collect();
    Ok(Fits {
        seed,
        train,
        val,
        test,
        models,
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
    judge_all(sim, campaign, regions, config, &fit_all(sim, config)?)
}

/// [`evaluate`] of methods already fitted ([`fit_all`]).
pub fn judge_all(
    sim: &Simulation,
    campaign: &CampaignConfig,
    regions: &[RegionConfig],
    config: &EvaluationConfig,
    fits: &Fits,
) -> Result<Evaluation> {
    let world = &sim.world;
    let (train, val, test) = (&fits.train, &fits.val, &fits.test);
    let truth = GroundTruth::build(world, campaign, regions, &config.ground_truth())?;
    let poses: Vec<ChainPose> = test.q.par_iter().map(|q| truth.nominal.pose(q)).collect();
    let posed = (test, &poses[..]);
    let mut methods: Vec<MethodReport> = fits
        .models
        .par_iter()
        .map(|(kind, model)| match model {
            Ok(model) => evaluate_method(model.as_ref(), posed, &truth, &world.robot)
                .unwrap_or_else(|e| MethodReport::failed(kind.info(), &e)),
            Err(e) => MethodReport::failed(kind.info(), e),
        })
        .collect();
    let oracle = Oracle::new(world)?.registered_on(&[train, val])?;
    methods.push(
        evaluate_method(&oracle, posed, &truth, &world.robot)
            .unwrap_or_else(|e| MethodReport::failed(&ORACLE, &e)),
    );
    Ok(Evaluation {
        scenario: world.config.name.clone(),
        units: "positions in mm, orientations in rad".into(),
        split: SplitReport {
            fractions: config.split,
            seed: fits.seed,
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
