//! The `[study]` section of a scenario and its checks.

use serde::{Deserialize, Serialize};

use crate::calib::registry::MethodKind;
use crate::campaign::{LayoutKind, RegionConfig};
use crate::eval::GroundTruthConfig;

/// No ground-truth set, size or test set may ask for more points than this per region.
const MAX_POINTS: usize = 1_000_000;
/// A study of more campaigns than this is surely a typo.
const MAX_CAMPAIGNS: u128 = 1_000_000;

fn default_validation_ratio() -> f64 {
    0.5
}

fn default_distance_bands() -> Vec<f64> {
    vec![0.025, 0.05, 0.1, 0.2]
}

fn default_targets_mm() -> Vec<f64> {
    vec![0.5, 0.3, 0.2, 0.1, 0.05]
}

/// Seconds per measured point, by part; see scenarios/README.md for where the defaults come from.
fn default_move_s() -> f64 {
    3.0
}
fn default_settle_s() -> f64 {
    2.0
}
fn default_measure_s() -> f64 {
    1.0
}

/// The share of seeds in which a size must reach a target for the answer to name it.
pub const REACH_SHARE: f64 = 0.8;

/// The `[study]` section of a scenario.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct StudyConfig {
    /// Training-set sizes (points), each a separate campaign.
    pub sizes: Vec<usize>,
    /// Point layouts to compare; `distributions` is their older name.
    #[serde(alias = "distributions")]
    pub layouts: Vec<LayoutKind>,
    /// Methods (named as `calibrate --method` names them); the oracle is always run as the floor.
    pub methods: Vec<MethodKind>,
    /// Repetitions: seeds 0..seeds of the campaign draws (layout, orientations, noise); the robot stays the
    /// scenario's one.
    pub seeds: u64,
    /// Validation points measured in addition to each training set, as a fraction of it (the paper's
    /// 50 / 25 split gives 0.5); at least 1 point.
    #[serde(default = "default_validation_ratio")]
    pub validation_ratio: f64,
    /// Measured test points per region: one fixed uniform campaign shared by every run.
    pub test_points: usize,
    /// Noise-free ground-truth grid points per region, shared by every run.
    pub grid_points: usize,
    /// Thickness (m) and points of the shell just outside each region.
    pub shell_width_m: f64,
    pub shell_points: usize,
    /// Ground-truth targets per region for the closed-loop view.
    pub closed_loop_points: usize,
    /// The method shown point by point (error arrows, residual grid); the first method when absent.
    #[serde(default)]
    pub detail_method: Option<MethodKind>,
    /// Upper edges (m, ascending) of the bands of distance from the training region by which `outside.csv`
    /// groups the ground-truth points of every region (grid and shell): inside (0), then (0, b₁], (b₁, b₂],
    /// …, and beyond the last edge.
    #[serde(default = "default_distance_bands")]
    pub distance_bands_m: Vec<f64>,
    /// The accuracies a user may need (mm, on the ground-truth mean and on its 95th percentile): the answer
    /// gives, per target, the fewest training points reaching it in at least [`REACH_SHARE`] of the seeds.
    #[serde(default = "default_targets_mm")]
    pub targets_mm: Vec<f64>,
    /// Tracker time per measured point (s): moving to it, waiting for the arm to settle, measuring.
    #[serde(default = "default_move_s")]
    pub move_s: f64,
    #[serde(default = "default_settle_s")]
    pub settle_s: f64,
    #[serde(default = "default_measure_s")]
    pub measure_s: f64,
    /// Trajectory campaigns through the same targets, for the tracker-time comparison ([`super::trajectory`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub trajectory: Option<super::trajectory::TrajectoryStudy>,
}

impl StudyConfig {
    /// Checks that need no robot; `regions` are the scenario's. Messages name the field (`sizes: …`); the first
    /// failing check, in this order, is the one reported.
    pub fn validate(&self, regions: &[RegionConfig]) -> std::result::Result<(), String> {
        self.check_sizes()?;
        self.check_layouts()?;
        self.check_methods()?;
        if self.seeds == 0 {
            return Err("seeds = 0: at least one repetition is needed".into());
        }
        if let Some(t) = &self.trajectory {
            t.validate(self)?;
        }
        self.check_campaign_count(regions)?;
        self.check_judging()?;
        self.check_answer()?;
        self.check_campaigns_fit(regions)
    }

    /// The training-set sizes: at least one, each in 1..=[`MAX_POINTS`], none twice.
    fn check_sizes(&self) -> std::result::Result<(), String> {
        if self.sizes.is_empty() {
            return Err("sizes is empty: list at least one training-set size".into());
        }
        for (i, &n) in self.sizes.iter().enumerate() {
            if n == 0 {
                return Err("sizes: a training set needs at least 1 point, got 0".into());
            }
            if n > MAX_POINTS {
                return Err(format!("sizes: {n} exceeds {MAX_POINTS}"));
            }
            if self.sizes[..i].contains(&n) {
                return Err(format!("sizes: {n} is listed twice"));
            }
        }
        Ok(())
    }

    /// The layouts: at least one, none twice.
    fn check_layouts(&self) -> std::result::Result<(), String> {
        if self.layouts.is_empty() {
            return Err("layouts is empty: list at least one layout".into());
        }
        for (i, d) in self.layouts.iter().enumerate() {
            if self.layouts[..i].contains(d) {
                return Err(format!("layouts: '{}' is listed twice", d.name()));
            }
        }
        Ok(())
    }

    /// The methods: at least one, none twice, and the detail method among them.
    fn check_methods(&self) -> std::result::Result<(), String> {
        if self.methods.is_empty() {
            return Err("methods is empty: list at least one method".into());
        }
        for (i, method) in self.methods.iter().enumerate() {
            if self.methods[..i].contains(method) {
                return Err(format!("methods: '{method}' is listed twice"));
            }
        }
        if let Some(detail) = &self.detail_method
            && !self.methods.contains(detail)
        {
            let names: Vec<&str> = self.methods.iter().map(|m| m.name()).collect();
            return Err(format!(
                "detail_method: '{detail}' is not among the methods ({})",
                names.join(", ")
            ));
        }
        Ok(())
    }

    /// At most [`MAX_CAMPAIGNS`] campaigns (regions × layouts × sizes × seeds).
    fn check_campaign_count(&self, regions: &[RegionConfig]) -> std::result::Result<(), String> {
        let campaigns = self.campaigns(regions.len());
        if campaigns > MAX_CAMPAIGNS {
            return Err(format!(
                "seeds = {}: {campaigns} campaigns exceed {MAX_CAMPAIGNS}",
                self.seeds
            ));
        }
        Ok(())
    }

    /// How the runs are judged: the validation share, the test set, the ground-truth sets and the distance bands.
    fn check_judging(&self) -> std::result::Result<(), String> {
        if !(self.validation_ratio.is_finite() && self.validation_ratio > 0.0) {
            return Err(format!(
                "validation_ratio = {} must be finite and positive",
                self.validation_ratio
            ));
        }
        if self.test_points == 0 {
            return Err("test_points must be at least 1".into());
        }
        if self.test_points > MAX_POINTS {
            return Err(format!(
                "test_points = {} exceeds {MAX_POINTS}",
                self.test_points
            ));
        }
        self.ground_truth_config().validate()?;
        if self
            .distance_bands_m
            .iter()
            .any(|b| !(b.is_finite() && *b > 0.0))
            || self.distance_bands_m.windows(2).any(|w| w[0] >= w[1])
        {
            return Err(format!(
                "distance_bands_m = {:?} must be positive, finite and ascending",
                self.distance_bands_m
            ));
        }
        Ok(())
    }

    /// What the answer needs: the targets (positive, none twice) and the tracker time per point.
    fn check_answer(&self) -> std::result::Result<(), String> {
        if self.targets_mm.is_empty() {
            return Err("targets_mm is empty: list at least one accuracy (mm)".into());
        }
        for (i, t) in self.targets_mm.iter().enumerate() {
            if !(t.is_finite() && *t > 0.0) {
                return Err(format!(
                    "targets_mm: {t} must be a positive number of millimetres"
                ));
            }
            if self.targets_mm[..i].contains(t) {
                return Err(format!("targets_mm: {t} is listed twice"));
            }
        }
        for (name, v) in [
            ("move_s", self.move_s),
            ("settle_s", self.settle_s),
            ("measure_s", self.measure_s),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(format!(
                    "{name} = {v} must be a finite, non-negative time (s)"
                ));
            }
        }
        Ok(())
    }

    /// Every campaign (a training set and its validation points) fits in every region's `points`.
    fn check_campaigns_fit(&self, regions: &[RegionConfig]) -> std::result::Result<(), String> {
        for &n in &self.sizes {
            let total = self.campaign_points(n);
            if let Some(r) = regions.iter().find(|r| total > r.points) {
                return Err(format!(
                    "sizes: {n} training + {} validation points exceed the points = {} of region '{}' \
                     (the most one of its campaigns may measure)",
                    total - n,
                    r.points,
                    r.name
                ));
            }
        }
        Ok(())
    }

    /// Validation points measured with a training set of `n`: `ceil(validation_ratio · n)`, at least 1.
    pub fn validation_points(&self, n: usize) -> usize {
        ((self.validation_ratio * n as f64).ceil() as usize).max(1)
    }

    /// Points of the campaign of a training set of `n`: training plus validation.
    pub fn campaign_points(&self, n: usize) -> usize {
        n + self.validation_points(n)
    }

    /// Runs of the study: every (region, layout, size, seed) campaign fitted by every method and the oracle.
    pub fn runs(&self, regions: usize) -> u128 {
        self.campaigns(regions) * (self.methods.len() as u128 + 1)
    }

    fn campaigns(&self, regions: usize) -> u128 {
        (regions as u128)
            * (self.layouts.len() as u128)
            * (self.sizes.len() as u128)
            * (self.seeds as u128)
    }

    /// The study's cost in core-seconds, estimated before anything runs: every campaign point simulated and
    /// fitted by every method, every evaluation point predicted by every run. The rates are measured on the
    /// default study (`scenarios/default.toml`: 1 575 stop-and-go runs, 63 core-seconds on the 2-core reference
    /// machine, and 18 trajectory runs, 125;
    /// `benches/calibrate.rs` gives 16–65 µs per training point for the methods); a d-optimal pool adds a few
    /// per cent. An estimate to refuse absurd studies, not a prediction to the second.
    pub fn estimated_core_seconds(&self, regions: usize) -> f64 {
        const SIMULATE_S_PER_POINT: f64 = 20e-6;
        const FIT_S_PER_POINT: f64 = 30e-6;
        const EVALUATE_S_PER_POINT: f64 = 6e-6;
        let methods = self.methods.len() as f64 + 1.0;
        let per_layout_and_seed: f64 = self
            .sizes
            .iter()
            .map(|&n| self.campaign_points(n) as f64)
            .sum::<f64>()
            * (SIMULATE_S_PER_POINT + methods * FIT_S_PER_POINT);
        let combos = (regions * self.layouts.len()) as f64 * self.seeds as f64;
        let sets =
            (self.test_points + self.grid_points + self.shell_points + self.closed_loop_points)
                as f64;
        combos * per_layout_and_seed
            + self.campaigns(regions) as f64 * methods * sets * EVALUATE_S_PER_POINT
            + regions as f64 * sets * SIMULATE_S_PER_POINT
            + self.trajectory.as_ref().map_or(0.0, |t| {
                // A path takes about a second per target at full speed and 1/speed as long slower (an upper
                // bound: the default study's take 0.9, 1.4 and 2.4 s at speeds 1, 0.5 and 0.25). Per second of that
                // bound a run costs 21 ms of one core besides its fits (the arm in motion at nodes every 2 ms, the
                // tracker, the clock offset's search), and every kept sample is fitted as a point, twice with the
                // motion as inputs: measured all-in on the default study, 125 core-seconds for 18 runs.
                const PATH_S_PER_TARGET: f64 = 1.0;
                const RUN_S_PER_PATH_S: f64 = 21e-3;
                let targets: f64 = t
                    .sizes
                    .iter()
                    .map(|&n| self.campaign_points(n) as f64)
                    .sum();
                let path_s: f64 = t
                    .speeds
                    .iter()
                    .map(|s| targets * PATH_S_PER_TARGET / s)
                    .sum();
                let samples = path_s * t.sample_rate_hz / t.keep_every as f64;
                let fits = if t.motion_inputs { 2.0 } else { 1.0 };
                let runs = t.sizes.len() as f64 * t.speeds.len() as f64;
                regions as f64
                    * t.seeds as f64
                    * (path_s * RUN_S_PER_PATH_S
                        + samples * methods * fits * FIT_S_PER_POINT
                        + runs * methods * fits * sets * EVALUATE_S_PER_POINT)
            })
    }

    /// Tracker time (s) of one measured point: move, settle, measure.
    pub fn seconds_per_point(&self) -> f64 {
        self.move_s + self.settle_s + self.measure_s
    }

    /// Tracker hours of the campaign of a training set of `n`: its training and validation points.
    pub fn campaign_hours(&self, n: usize) -> f64 {
        self.campaign_points(n) as f64 * self.seconds_per_point() / 3600.0
    }

    /// The method shown point by point: `detail_method`, or the first method (a valid study lists one).
    pub fn detail_method(&self) -> Option<MethodKind> {
        self.detail_method.or(self.methods.first().copied())
    }

    /// The ground-truth sets every run is judged on.
    pub fn ground_truth_config(&self) -> GroundTruthConfig {
        GroundTruthConfig {
            grid_points: self.grid_points,
            shell_width_m: self.shell_width_m,
            shell_points: self.shell_points,
            closed_loop_points: self.closed_loop_points,
        }
    }
}
