//! The sweep engine: every run of a study, in parallel, with numbers independent of the thread count.
//!
//! The robot, the tracker and the reflector mounting are the scenario's (the same draws as `simulate`). Per
//! region, one measured **test set** (`test_points`, uniform layout) and one set of **ground truth** (grid,
//! shell, closed-loop targets) are built once and shared by every run, so runs are comparable. Then, for
//! every (region, layout, size `n`, seed), one campaign of `n + ceil(validation_ratio · n)` measured points
//! with that layout is generated, split into training and validation points by a seeded shuffle, and every
//! method is fitted on it — together with the oracle, registered on the same points, whose ground-truth mean
//! is the run's floor. A campaign the region cannot supply, or a method that cannot be fitted, makes failed
//! runs with the reason; the sweep goes on.
//!
//! Every random draw derives from (scenario seed, region index, layout, size, seed) — the layout's place in
//! [`DistributionKind::ALL`] and the size and seed values, not their places in the lists — so a run gives the
//! same numbers whatever else the study lists, and whatever the thread count.

use std::collections::BTreeMap;
use std::io::IsTerminal;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use indicatif::{ProgressBar, ProgressStyle};
use nalgebra::{Isometry3, Point3};
use rand::RngCore;
use rand::seq::SliceRandom;
use rayon::prelude::*;

use super::{
    BeforeAfter, Detail, DetailPoint, DistanceBand, GridPoint, RunKey, RunMetrics, StudyConfig,
    StudyResult,
};
use crate::calib::method::{FitContext, Fitted};
use crate::calib::registry::{self, MethodKind};
use crate::calib::regression::RegressionOptions;
use crate::campaign::{Campaign, DistributionKind, RegionConfig, Simulation};
use crate::dataset::Dataset;
use crate::design::{DesignModel, Indices};
use crate::error::{Error, Result};
use crate::eval::truth::{
    EvaluationConfig, GroundTruth, ORACLE, TruthSet, closed_loop_errors, setup, test_errors,
    truth_errors,
};
use crate::eval::{Oracle, Stats};
use crate::rng::{Stream, derive};
use crate::robot::dh::DhChain;
use crate::scenario::Scenario;

/// No ground-truth set, size or test set may ask for more points than this per region.
const MAX_POINTS: usize = 1_000_000;
/// A study of more campaigns than this is surely a typo.
const MAX_CAMPAIGNS: u128 = 1_000_000;
/// The region-level seed index of the test set, far from any layout index.
const TEST_SET: u64 = u64::MAX;

/// How the sweep reports progress on stderr.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Progress {
    /// A progress bar when stderr is a terminal, otherwise [`Progress::Lines`].
    Auto,
    /// A plain line every 10 % of the runs.
    Lines,
    /// Nothing.
    Hidden,
}

impl StudyConfig {
    /// Checks that need no robot; `regions` are the scenario's. Messages name the field (`sizes: …`).
    pub fn validate(&self, regions: &[RegionConfig]) -> std::result::Result<(), String> {
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
        if self.distributions.is_empty() {
            return Err("distributions is empty: list at least one layout".into());
        }
        for (i, d) in self.distributions.iter().enumerate() {
            if self.distributions[..i].contains(d) {
                return Err(format!("distributions: '{}' is listed twice", d.name()));
            }
        }
        if self.methods.is_empty() {
            return Err("methods is empty: list at least one method".into());
        }
        for (i, name) in self.methods.iter().enumerate() {
            if name == ORACLE {
                return Err(
                    "methods: 'oracle' is always run (its ground-truth mean is every run's floor_mean); \
                     do not list it"
                        .into(),
                );
            }
            MethodKind::parse(name).map_err(|e| {
                format!("methods: {}", e.to_string().replace("invalid input: ", ""))
            })?;
            if self.methods[..i].contains(name) {
                return Err(format!("methods: '{name}' is listed twice"));
            }
        }
        if let Some(detail) = &self.detail_method
            && !self.methods.contains(detail)
        {
            return Err(format!(
                "detail_method: '{detail}' is not among the methods ({})",
                self.methods.join(", ")
            ));
        }
        if self.seeds == 0 {
            return Err("seeds = 0: at least one repetition is needed".into());
        }
        let campaigns = (regions.len() as u128)
            * (self.distributions.len() as u128)
            * (self.sizes.len() as u128)
            * (self.seeds as u128);
        if campaigns > MAX_CAMPAIGNS {
            return Err(format!(
                "seeds = {}: {campaigns} campaigns exceed {MAX_CAMPAIGNS}",
                self.seeds
            ));
        }
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

    /// The method shown point by point: `detail_method`, or the first method.
    pub fn detail_method(&self) -> &str {
        self.detail_method
            .as_deref()
            .or(self.methods.first().map(String::as_str))
            .unwrap_or_default()
    }

    /// The ground-truth sets as the evaluation builds them.
    fn ground_truth_config(&self) -> EvaluationConfig {
        EvaluationConfig {
            methods: Vec::new(),
            grid_points: self.grid_points,
            shell_width_m: self.shell_width_m,
            shell_points: self.shell_points,
            closed_loop_points: self.closed_loop_points,
            ..EvaluationConfig::default()
        }
    }
}

/// The seed of one campaign of the study: region `r`, layout `d` (its place in [`DistributionKind::ALL`]),
/// training-set size `n` and repetition `s`; the test set uses `d = TEST_SET`.
fn campaign_seed(scenario_seed: u64, r: u64, d: u64, n: u64, s: u64) -> u64 {
    let region_layout = derive(scenario_seed, Stream::Study, &[r, d]).next_u64();
    derive(region_layout, Stream::Study, &[n, s]).next_u64()
}

fn layout_index(d: DistributionKind) -> u64 {
    DistributionKind::ALL
        .iter()
        .position(|&k| k == d)
        .expect("every layout is in ALL") as u64
}

/// A campaign of `points` measured points in `region` with `layout`, drawn from `seed`.
fn measure(
    scenario: &Scenario,
    sim: &Simulation,
    region: &RegionConfig,
    layout: DistributionKind,
    points: usize,
    seed: u64,
) -> Result<Campaign> {
    let region = RegionConfig {
        points,
        distribution: layout,
        ..region.clone()
    };
    let mut setup = setup(scenario, sim);
    setup.seed = seed;
    setup.run(std::slice::from_ref(&region))
}

/// The campaign as a method sees it (`measurements.csv` read back).
fn dataset(campaign: &Campaign, origin: &str) -> Result<Dataset> {
    let csv = crate::measurements::measurements_csv(campaign)?;
    Dataset::from_reader(csv.as_slice(), origin, &campaign.joint_names)
}

/// The ground truth restricted to one region.
fn region_truth(truth: &GroundTruth, region: &str) -> GroundTruth {
    let only = |set: &TruthSet| TruthSet {
        points: set
            .points
            .iter()
            .filter(|p| p.region == region)
            .cloned()
            .collect(),
        rejections: set
            .rejections
            .iter()
            .filter(|(name, _)| *name == region)
            .map(|(k, v)| (k.clone(), v.clone()))
            .collect(),
    };
    GroundTruth {
        tracker_pose: truth.tracker_pose,
        measured_point: truth.measured_point,
        nest_rotation: truth.nest_rotation,
        grid: only(&truth.grid),
        shell: only(&truth.shell),
        closed_loop: only(&truth.closed_loop),
    }
}

/// What every run of one region shares.
struct RegionSets {
    test: Dataset,
    truth: GroundTruth,
}

/// One campaign of the sweep: indices into the scenario's regions and the study's lists.
#[derive(Clone, Copy)]
struct Job {
    region: usize,
    distribution: usize,
    size: usize,
    seed: u64,
}

/// What the runs of one job give: (method index, metrics), and the detail when this job may be shown.
struct JobOutput {
    runs: Vec<(usize, RunMetrics)>,
    detail: Option<Detail>,
}

/// Per-point data of one method, kept only for the detail job.
struct PointData {
    test: Vec<f64>,
    /// World-frame predictions at the campaign's points and the grid residuals (the detail method only).
    campaign: Option<(Vec<Point3<f64>>, Vec<f64>)>,
}

/// Everything read-only the jobs share.
struct Shared<'a> {
    scenario: &'a Scenario,
    config: &'a StudyConfig,
    sim: &'a Simulation,
    ctx: FitContext<'a>,
    /// Per method, the model whose observability the run reports.
    designs: Vec<Option<DesignModel<'a>>>,
    kinds: Vec<MethodKind>,
    detail_method: usize,
    regions: Vec<RegionSets>,
    progress: &'a Counter,
}

/// Runs the scenario's `[study]` on the current rayon pool (install a pool to choose the thread count).
/// Errors: no `[study]` section, a robot that does not load, a region whose test set or ground truth cannot
/// be built. Runs that fail (a campaign the region cannot supply, a method that cannot be fitted) are
/// recorded as failed with their reason.
pub fn run_study(scenario: &Scenario, progress: Progress) -> Result<StudyResult> {
    let config = scenario.study.as_ref().ok_or_else(|| Error::Scenario {
        origin: scenario.origin.clone(),
        message: "no [study] section: nothing to sweep".into(),
    })?;
    config
        .validate(&scenario.regions)
        .map_err(|message| Error::Scenario {
            origin: scenario.origin.clone(),
            message: format!("study.{message}"),
        })?;
    let kinds: Vec<MethodKind> = config
        .methods
        .iter()
        .map(|m| MethodKind::parse(m))
        .collect::<Result<_>>()?;
    let detail_method = config
        .methods
        .iter()
        .position(|m| m == config.detail_method())
        .unwrap_or(0);

    let sim = crate::campaign::world(scenario)?;
    let dh = DhChain::from_chain(&sim.nominal)?;
    let truth = GroundTruth::build(scenario, &sim, &config.ground_truth_config())?;
    let regions = scenario
        .regions
        .iter()
        .enumerate()
        .map(|(r, region)| {
            let seed = campaign_seed(scenario.seed, r as u64, TEST_SET, 0, 0);
            let campaign = measure(
                scenario,
                &sim,
                region,
                DistributionKind::Uniform,
                config.test_points,
                seed,
            )
            .map_err(|e| {
                Error::Unreachable(format!(
                    "the study's test set of {} points: {}",
                    config.test_points,
                    e.to_string().replace("unreachable: ", "")
                ))
            })?;
            Ok(RegionSets {
                test: dataset(
                    &campaign,
                    &format!("the test set of region '{}'", region.name),
                )?,
                truth: region_truth(&truth, &region.name),
            })
        })
        .collect::<Result<Vec<_>>>()?;

    let mut jobs = Vec::new();
    for region in 0..scenario.regions.len() {
        for distribution in 0..config.distributions.len() {
            for size in 0..config.sizes.len() {
                for seed in 0..config.seeds {
                    jobs.push(Job {
                        region,
                        distribution,
                        size,
                        seed,
                    });
                }
            }
        }
    }
    let counter = Counter::new(progress, jobs.len() * kinds.len());
    let ctx = FitContext {
        chain: &sim.nominal,
        dh: &dh,
        payload: scenario.robot.payload(),
        regression: RegressionOptions::default(),
    };
    let designs = kinds
        .iter()
        .map(|&kind| DesignModel::for_method(kind, &ctx, &sim.mounting.nominal))
        .collect::<Result<Vec<_>>>()?;
    let shared = Shared {
        scenario,
        config,
        sim: &sim,
        ctx,
        designs,
        kinds,
        detail_method,
        regions,
        progress: &counter,
    };
    let outputs: Vec<(Job, JobOutput)> =
        jobs.par_iter().map(|&job| (job, shared.run(job))).collect();
    counter.finish();

    // Config order: region, layout, method, size, seed.
    let mut keyed = Vec::with_capacity(outputs.len() * shared.kinds.len());
    let mut details = Vec::new();
    for (job, output) in outputs {
        for (m, run) in output.runs {
            keyed.push(((job.region, job.distribution, m, job.size, job.seed), run));
        }
        if let Some(detail) = output.detail {
            details.push(detail);
        }
    }
    keyed.sort_by_key(|(k, _)| *k);
    let runs: Vec<RunMetrics> = keyed.into_iter().map(|(_, run)| run).collect();
    let detail = details
        .into_iter()
        .max_by_key(|d| d.n_train)
        .unwrap_or_else(|| Detail {
            region: scenario.regions[0].name.clone(),
            distribution: config.distributions[0],
            method: config.methods[detail_method].clone(),
            n_train: config.sizes.iter().copied().max().unwrap_or(0),
            points: Vec::new(),
            grid: Vec::new(),
            histograms: BTreeMap::new(),
            tracker: sim.tracker.pose,
        });
    Ok(StudyResult {
        scenario: scenario.clone(),
        config: config.clone(),
        regions: scenario.regions.clone(),
        runs,
        detail,
        orientation: sim.mounting.count() >= 3,
    })
}

/// The measured outcome of one method on one campaign.
struct Outcome {
    metrics: RunMetrics,
    points: Option<PointData>,
}

impl Shared<'_> {
    fn key(&self, job: Job, m: usize) -> RunKey {
        RunKey {
            region: self.scenario.regions[job.region].name.clone(),
            distribution: self.config.distributions[job.distribution],
            method: self.config.methods[m].clone(),
            n_train: self.config.sizes[job.size],
            seed: job.seed,
        }
    }

    fn failed(&self, job: Job, m: usize, reason: String, fit_ms: f64) -> RunMetrics {
        RunMetrics {
            key: self.key(job, m),
            failure: Some(reason),
            test: None,
            truth: None,
            outside: None,
            closed_loop: None,
            floor_mean: None,
            test_orientation: None,
            truth_orientation: None,
            by_distance: Vec::new(),
            observability: None,
            fit_ms,
        }
    }

    /// The observability indices of the training points for every method's design model; a model shared by
    /// several methods (a hybrid and its base) is computed once.
    fn observability(&self, train: &Dataset) -> Vec<Option<Indices>> {
        let qs: Vec<&[f64]> = train.q.iter().map(Vec::as_slice).collect();
        let mut done: Vec<(MethodKind, Indices)> = Vec::new();
        self.designs
            .iter()
            .map(|design| {
                let design = design.as_ref()?;
                if let Some((_, idx)) = done.iter().find(|(m, _)| *m == design.method) {
                    return Some(*idx);
                }
                let idx = Indices::of(&design.jacobian(&qs), qs.len());
                done.push((design.method, idx));
                Some(idx)
            })
            .collect()
    }

    /// Whether this job's campaign may be the one shown point by point.
    fn is_detail_candidate(&self, job: Job) -> bool {
        job.region == 0 && job.distribution == 0 && job.seed == 0
    }

    fn run(&self, job: Job) -> JobOutput {
        let n = self.config.sizes[job.size];
        let layout = self.config.distributions[job.distribution];
        let region = &self.scenario.regions[job.region];
        let seed = campaign_seed(
            self.scenario.seed,
            job.region as u64,
            layout_index(layout),
            n as u64,
            job.seed,
        );
        let (campaign, train, val) = match self.prepare(job, seed) {
            Ok(prepared) => prepared,
            Err(e) => {
                let reason = reason(&e);
                let runs = (0..self.kinds.len())
                    .map(|m| (m, self.failed(job, m, reason.clone(), 0.0)))
                    .collect();
                self.progress.add(self.kinds.len());
                return JobOutput { runs, detail: None };
            }
        };
        let sets = &self.regions[job.region];
        let floor_mean = Oracle::new(self.sim)
            .and_then(|o| o.registered_on(&[&train, &val]))
            .ok()
            .and_then(|oracle| {
                Stats::of(&truth_errors(&oracle, &sets.truth, &sets.truth.grid.points).position)
            })
            .map(|s| s.mean);
        let detail_job = self.is_detail_candidate(job);
        let observability = self.observability(&train);
        let outcomes: Vec<Outcome> = (0..self.kinds.len())
            .into_par_iter()
            .map(|m| {
                let mut outcome =
                    self.method(job, m, &campaign, &train, &val, floor_mean, detail_job);
                if outcome.metrics.failure.is_none() {
                    outcome.metrics.observability = observability[m];
                }
                self.progress.add(1);
                outcome
            })
            .collect();
        let detail = if detail_job {
            self.detail(job, region, &campaign, &train, &val, &outcomes)
        } else {
            None
        };
        JobOutput {
            runs: outcomes
                .into_iter()
                .enumerate()
                .map(|(m, o)| (m, o.metrics))
                .collect(),
            detail,
        }
    }

    /// The job's campaign and its training and validation sets.
    fn prepare(&self, job: Job, seed: u64) -> Result<(Campaign, Dataset, Dataset)> {
        let n = self.config.sizes[job.size];
        let region = &self.scenario.regions[job.region];
        let layout = self.config.distributions[job.distribution];
        let total = self.config.campaign_points(n);
        let campaign = measure(self.scenario, self.sim, region, layout, total, seed)?;
        let data = dataset(&campaign, "the study's campaign")?;
        let mut order: Vec<usize> = (0..data.len()).collect();
        order.shuffle(&mut derive(seed, Stream::Split, &[]));
        let (mut train, mut val) = (order[..n.min(order.len())].to_vec(), order[n..].to_vec());
        train.sort_unstable();
        val.sort_unstable();
        Ok((campaign, data.subset(&train), data.subset(&val)))
    }

    #[allow(clippy::too_many_arguments)]
    fn method(
        &self,
        job: Job,
        m: usize,
        campaign: &Campaign,
        train: &Dataset,
        val: &Dataset,
        floor_mean: Option<f64>,
        detail_job: bool,
    ) -> Outcome {
        let started = Instant::now();
        let fitted = registry::fit(self.kinds[m], &self.ctx, train, val);
        let fit_ms = started.elapsed().as_secs_f64() * 1e3;
        let model = match fitted {
            Ok(model) => model,
            Err(e) => {
                return Outcome {
                    metrics: self.failed(job, m, reason(&e), fit_ms),
                    points: None,
                };
            }
        };
        let sets = &self.regions[job.region];
        let truth = &sets.truth;
        let test = match test_errors(model.as_ref(), &sets.test) {
            Ok(e) => e,
            Err(e) => {
                return Outcome {
                    metrics: self.failed(job, m, reason(&e), fit_ms),
                    points: None,
                };
            }
        };
        let grid = truth_errors(model.as_ref(), truth, &truth.grid.points);
        let shell = truth_errors(model.as_ref(), truth, &truth.shell.points);
        let closed = closed_loop_errors(
            model.as_ref(),
            truth,
            &self.sim.robot,
            &truth.closed_loop.points,
        );
        let views = [
            ("test set", &test.position, sets.test.len()),
            ("ground-truth grid", &grid.position, truth.grid.points.len()),
            ("shell", &shell.position, truth.shell.points.len()),
        ];
        if let Some((view, _, _)) = views
            .iter()
            .find(|(_, errors, points)| *points > 0 && Stats::of(errors).is_none())
        {
            return Outcome {
                metrics: self.failed(
                    job,
                    m,
                    format!("the model's predictions on the {view} are not finite"),
                    fit_ms,
                ),
                points: None,
            };
        }
        let by_distance = self.by_distance(job, model.as_ref(), &grid.position, &shell.position);
        let points = detail_job.then(|| PointData {
            test: test.position.clone(),
            campaign: (m == self.detail_method).then(|| {
                (
                    world_predictions(model.as_ref(), truth, campaign),
                    grid.position.clone(),
                )
            }),
        });
        Outcome {
            metrics: RunMetrics {
                key: self.key(job, m),
                failure: None,
                test: Stats::of(&test.position),
                truth: Stats::of(&grid.position),
                outside: Stats::of(&shell.position),
                closed_loop: Stats::of(&closed.position),
                floor_mean,
                test_orientation: Stats::of(&test.orientation),
                truth_orientation: Stats::of(&grid.orientation),
                by_distance,
                observability: None,
                fit_ms,
            },
            points,
        }
    }

    /// Ground-truth errors by distance from the job's training region, over the grid and shell of every
    /// region: the training region's own (`grid`, `shell`, already computed) and the others', predicted here.
    fn by_distance(
        &self,
        job: Job,
        model: &dyn Fitted,
        grid: &[f64],
        shell: &[f64],
    ) -> Vec<DistanceBand> {
        let training = &self.scenario.regions[job.region];
        let edges = &self.config.distance_bands_m;
        let mut bands = Vec::new();
        for (r, region) in self.scenario.regions.iter().enumerate() {
            let truth = &self.regions[r].truth;
            let points = truth.grid.points.iter().chain(&truth.shell.points);
            let errors: Vec<f64> = if r == job.region {
                grid.iter().chain(shell).copied().collect()
            } else {
                let mut e = truth_errors(model, truth, &truth.grid.points).position;
                e.extend(truth_errors(model, truth, &truth.shell.points).position);
                e
            };
            // Band 0 is inside; band i ≥ 1 is (edge[i-2], edge[i-1]], the last one beyond every edge.
            let mut sums = vec![(0usize, 0.0f64); edges.len() + 2];
            for (p, e) in points.zip(&errors) {
                let d = training.distance(&Point3::from(p.nominal_flange.translation.vector));
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

    /// The detail of this job, when its campaign, the nominal model and the detail method all worked.
    fn detail(
        &self,
        job: Job,
        region: &RegionConfig,
        campaign: &Campaign,
        train: &Dataset,
        val: &Dataset,
        outcomes: &[Outcome],
    ) -> Option<Detail> {
        let nominal = registry::fit(MethodKind::Nominal, &self.ctx, train, val).ok()?;
        let sets = &self.regions[job.region];
        let truth = &sets.truth;
        let before_test = test_errors(nominal.as_ref(), &sets.test).ok()?.position;
        let before = world_predictions(nominal.as_ref(), truth, campaign);
        let (after, residuals) = outcomes[self.detail_method]
            .points
            .as_ref()?
            .campaign
            .as_ref()?;
        let points = campaign
            .points
            .iter()
            .zip(before.iter().zip(after))
            .map(|(p, (b, a))| {
                let true_position = truth.position(&p.true_flange);
                DetailPoint {
                    q_cmd: p.q_cmd.clone(),
                    true_flange: p.true_flange,
                    true_position,
                    error_before: b - true_position,
                    error_after: a - true_position,
                }
            })
            .collect();
        let grid = truth
            .grid
            .points
            .iter()
            .zip(residuals)
            .map(|(p, &residual)| GridPoint {
                true_position: truth.position(&p.true_flange),
                residual,
            })
            .collect();
        let histograms = outcomes
            .iter()
            .enumerate()
            .filter_map(|(m, o)| {
                let data = o.points.as_ref()?;
                Some((
                    self.config.methods[m].clone(),
                    BeforeAfter {
                        before: before_test.clone(),
                        after: data.test.clone(),
                    },
                ))
            })
            .collect();
        Some(Detail {
            region: region.name.clone(),
            distribution: self.config.distributions[job.distribution],
            method: self.config.methods[self.detail_method].clone(),
            n_train: self.config.sizes[job.size],
            points,
            grid,
            histograms,
            tracker: self.sim.tracker.pose,
        })
    }
}

/// The model's predictions of the measured point at the campaign's commands, mapped from its registered frame
/// into the world frame.
fn world_predictions(
    model: &dyn Fitted,
    truth: &GroundTruth,
    campaign: &Campaign,
) -> Vec<Point3<f64>> {
    let to_world: Isometry3<f64> = truth.to_method(model).inverse();
    campaign
        .points
        .iter()
        .map(|p| to_world * model.predict(&p.q_cmd).position)
        .collect()
}

/// A failure's reason without the error kind's prefix where it says nothing.
fn reason(e: &Error) -> String {
    match e {
        Error::Invalid(message) => message.clone(),
        other => other.to_string(),
    }
}

/// Counts finished runs and shows it: a bar on a terminal, else a line every 10 %.
struct Counter {
    bar: Option<ProgressBar>,
    lines: bool,
    done: AtomicUsize,
    total: usize,
}

impl Counter {
    fn new(progress: Progress, total: usize) -> Counter {
        let progress = match progress {
            Progress::Auto if std::io::stderr().is_terminal() => None,
            Progress::Auto => Some(Progress::Lines),
            other => Some(other),
        };
        let bar = progress.is_none().then(|| {
            let bar = ProgressBar::new(total as u64);
            if let Ok(style) = ProgressStyle::with_template(
                "study {elapsed_precise} [{bar:40}] {pos}/{len} runs, {eta} left",
            ) {
                bar.set_style(style.progress_chars("=> "));
            }
            bar
        });
        let lines = progress == Some(Progress::Lines);
        if lines {
            eprintln!("study: {total} runs");
        }
        Counter {
            bar,
            lines,
            done: AtomicUsize::new(0),
            total,
        }
    }

    fn add(&self, runs: usize) {
        let before = self.done.fetch_add(runs, Ordering::Relaxed);
        let after = before + runs;
        if let Some(bar) = &self.bar {
            bar.inc(runs as u64);
        }
        if self.lines && self.total > 0 {
            let tenth = |k: usize| k * 10 / self.total;
            if tenth(after) > tenth(before) {
                eprintln!(
                    "study: {} % ({after} of {} runs)",
                    tenth(after) * 10,
                    self.total
                );
            }
        }
    }

    fn finish(&self) {
        if let Some(bar) = &self.bar {
            bar.finish_and_clear();
        }
    }
}
