//! The sweep engine: every run of a study, in parallel, with numbers independent of the thread count.
//!
//! The robot, the tracker and the reflector mounting are the scenario's (the same draws as `simulate`). Per
//! region, one measured **test set** (`test_points`, uniform layout) and one set of **ground truth** (grid,
//! shell, closed-loop targets) are built once and shared by every run, so runs are comparable. Then, for
//! every (region, layout, size `n`, seed), one campaign of `n + ceil(validation_ratio · n)` measured points
//! with that layout is generated, split into training and validation points by a seeded shuffle, and every
//! method is fitted on it — together with the oracle, registered on the same points, whose ground-truth mean
//! is the run's floor. A model-based layout (`d-optimal`) gives each method the points chosen for it
//! ([`Design`]): one pool per (region, layout, size, seed), one campaign per distinct design chosen from it. A campaign the region cannot supply, or a method that cannot be fitted, makes failed
//! runs with the reason; the sweep goes on.
//!
//! Every random draw derives from (scenario seed, region index, layout, size, seed) — the layout's place in
//! [`LayoutKind::ALL`] and the size and seed values, not their places in the lists — so a run gives the
//! same numbers whatever else the study lists, and whatever the thread count.

use std::time::Instant;

use nalgebra::{Isometry3, Point3};
use rayon::prelude::*;

use super::jobs::{Job, jobs, longest_first};
use super::measure::{
    Measure, Prepared, TEST_SET, campaign_seed, layout_index, region_truth, split,
};
pub use super::progress::Progress;
use super::progress::{Counter, run_weight};
use super::shard::{Shard, StudyPart, assemble};
use super::{
    Detail, DetailPoint, GridPoint, Histogram, RunKey, RunMetrics, StudyConfig, StudyResult,
};
use crate::calib::method::{FitContext, FitShare, Fitted};
use crate::calib::registry::{MethodKind, REFERENCE};
use crate::campaign::{Campaign, CampaignConfig, LayoutKind, RegionConfig, Selector};
use crate::dataset::Dataset;
use crate::design::layout::PointDesign;
use crate::design::{DesignModel, Indices};
use crate::error::{Error, Result};
use crate::eval::GroundTruth;
use crate::eval::judge::{by_distance, judge, test_errors, truth_position_errors};
use crate::eval::{Oracle, Stats};
use crate::measurements::as_dataset;
use crate::robot::dh::ChainPose;
use crate::world::World;

/// What every run of one region shares.
struct RegionSets {
    test: Dataset,
    /// The nominal chain at every test configuration, for every run's judging.
    test_poses: Vec<ChainPose>,
    truth: GroundTruth,
    /// The oracle's predictions on the grid: the true robot's, the same for every campaign's oracle.
    oracle_grid: Option<Vec<Point3<f64>>>,
    limits: super::Limits,
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
    measure: Measure<'a>,
    config: &'a StudyConfig,
    world: &'a World,
    /// The selectors of model-based layouts, one per distinct design, and each method's index into them.
    selectors: Vec<&'a dyn Selector>,
    design_of: Vec<usize>,
    ctx: FitContext<'a>,
    /// Per method, the model whose observability the run reports.
    designs: Vec<Option<DesignModel<'a>>>,
    kinds: Vec<MethodKind>,
    detail_method: usize,
    regions: Vec<RegionSets>,
    progress: &'a Counter,
    /// Whether `fit_ms` holds wall-clock times ([`RunOptions::timings`]).
    timings: bool,
}

/// How a sweep runs, beside what it runs.
#[derive(Clone, Copy, Debug)]
pub struct RunOptions {
    pub progress: Progress,
    /// Record each fit's wall-clock time in `fit_ms`; otherwise NaN, so that the same scenario gives
    /// byte-identical files whatever the machine and the thread count.
    pub timings: bool,
}

impl RunOptions {
    /// No progress shown and no timings: for callers that want only the numbers.
    pub const QUIET: RunOptions = RunOptions {
        progress: Progress::Hidden,
        timings: false,
    };
}

/// Runs the study `config` over `regions` of `world`, with the campaign configuration `campaign`, on the current
/// rayon pool (install a pool to choose the thread count). `config` must have passed
/// [`StudyConfig::validate`] for `regions` (reading a scenario checks it). Errors: a region whose test set or
/// ground truth cannot be built. Runs that fail (a campaign the region cannot supply, a method that cannot be
/// fitted) are recorded as failed with their reason.
pub fn run_study(
    world: &World,
    campaign: &CampaignConfig,
    regions: &[RegionConfig],
    config: &StudyConfig,
    options: RunOptions,
) -> Result<StudyResult> {
    let part = run_part(world, campaign, regions, config, options, Shard::WHOLE)?;
    Ok(assemble(world, regions, config, vec![part]))
}

/// [`run_study`] restricted to the campaigns of `shard` ([`super::shard`]): their runs, the detail run if the
/// shard holds it, and the limits; [`assemble`] puts the parts of every shard together.
pub fn run_part(
    world: &World,
    campaign: &CampaignConfig,
    regions: &[RegionConfig],
    config: &StudyConfig,
    options: RunOptions,
    shard: Shard,
) -> Result<StudyPart> {
    let ctx = FitContext::of(world);
    let kinds = config.methods.clone();
    let measure = Measure {
        world,
        campaign,
        regions,
    };
    let (selectors, design_of) = selectors(config, &ctx, world, campaign)?;
    let region_sets = region_sets(&measure, config)?;
    let (held, mut jobs, total_campaigns) = jobs(regions.len(), config, shard);
    longest_first(&mut jobs, config);
    let total_work = jobs
        .iter()
        .map(|j| kinds.len() as u64 * run_weight(config, config.sizes[j.size]))
        .sum();
    let counter = Counter::new(options.progress, jobs.len() * kinds.len(), total_work);
    let designs = kinds
        .iter()
        .map(|&kind| DesignModel::for_method(kind, &ctx, &world.mounting.nominal))
        .collect::<Result<Vec<_>>>()?;
    let shared = Shared {
        measure,
        config,
        world,
        selectors: selectors.iter().map(|s| s.as_ref()).collect(),
        design_of,
        ctx,
        designs,
        detail_method: config
            .detail_method()
            .and_then(|d| kinds.iter().position(|&m| m == d))
            .unwrap_or(0),
        kinds,
        regions: region_sets,
        progress: &counter,
        timings: options.timings,
    };
    // The trajectory campaigns run beside the stop-and-go ones rather than after them: neither waits on the
    // other, and the pool stays busy through the longest job of either.
    let (outputs, trajectory) = rayon::join(
        || -> Vec<(Job, JobOutput)> {
            jobs.par_iter().map(|&job| (job, shared.run(job))).collect()
        },
        || match (&config.trajectory, shard.index) {
            (Some(t), 0) => super::trajectory::run(
                &shared.measure,
                config,
                t,
                &shared.ctx,
                &shared.regions.iter().map(|r| &r.truth).collect::<Vec<_>>(),
            ),
            _ => Ok(super::trajectory::TrajectoryOutcome {
                runs: Vec::new(),
                detail: None,
            }),
        },
    );
    counter.finish();
    let trajectory = trajectory?;
    let (runs, detail) = in_config_order(outputs);
    Ok(StudyPart {
        shard,
        campaigns: held,
        total_campaigns,
        runs,
        detail,
        limits: shared.regions.iter().map(|r| r.limits.clone()).collect(),
        trajectory: trajectory.runs,
        trajectory_detail: trajectory.detail,
    })
}

/// One selector per distinct design of the study's methods.
type Selectors<'a> = Vec<Box<dyn Selector + 'a>>;

/// The selectors of the model-based layouts the study lists, one per distinct design (none when it lists
/// none), and each method's index into them: a model-based layout chooses each method's points for that
/// method.
fn selectors<'a>(
    config: &StudyConfig,
    ctx: &FitContext<'a>,
    world: &'a World,
    campaign: &'a CampaignConfig,
) -> Result<(Selectors<'a>, Vec<usize>)> {
    let mut layouts: Vec<PointDesign> = Vec::new();
    let mut design_of = Vec::with_capacity(config.methods.len());
    for &kind in &config.methods {
        let design = PointDesign::of(kind);
        design_of.push(
            layouts
                .iter()
                .position(|d| *d == design)
                .unwrap_or_else(|| {
                    layouts.push(design);
                    layouts.len() - 1
                }),
        );
    }
    let selectors = if config.layouts.iter().any(|d| d.selects()) {
        layouts
            .iter()
            .map(|d| d.selector(ctx, &world.mounting.nominal, &campaign.selection))
            .collect::<Result<_>>()?
    } else {
        Vec::new()
    };
    Ok((selectors, design_of))
}

/// Per region, what every run shares: the measured test set, the ground truth, and the measurement's limits.
fn region_sets(measure: &Measure, config: &StudyConfig) -> Result<Vec<RegionSets>> {
    let world = measure.world;
    let truth = GroundTruth::build(
        world,
        measure.campaign,
        measure.regions,
        &config.ground_truth_config(),
    )?;
    measure
        .regions
        .iter()
        .enumerate()
        .map(|(r, region)| {
            let seed = campaign_seed(world.seed(), r as u64, TEST_SET, 0, 0);
            let campaign = measure
                .campaign(r, LayoutKind::Uniform, config.test_points, seed)
                .map_err(|e| {
                    Error::Unreachable(format!(
                        "the study's test set of {} points: {}",
                        config.test_points,
                        e.detail()
                    ))
                })?;
            let test = as_dataset(
                &campaign,
                &format!("the test set of region '{}'", region.name),
            )?;
            let truth = region_truth(&truth, &region.name);
            let oracle_grid = Oracle::new(world).ok().map(|oracle| {
                let grid = truth.grid.points.par_iter();
                grid.map(|p| oracle.predict(&p.q_cmd).position).collect()
            });
            Ok(RegionSets {
                limits: super::Limits::of(world, &region.name, &campaign),
                test_poses: test.q.par_iter().map(|q| world.dh.pose(q)).collect(),
                test,
                truth,
                oracle_grid,
            })
        })
        .collect()
}

/// The runs of every job in config order (region, layout, method, size, seed), and the detail: the job's at the
/// largest size among those that may be shown.
fn in_config_order(mut outputs: Vec<(Job, JobOutput)>) -> (Vec<RunMetrics>, Option<Detail>) {
    // Jobs in config order first: the detail's tie-break (the last of equal sizes) must not follow the
    // execution order.
    outputs.sort_by_key(|(j, _)| (j.region, j.layout, j.size, j.seed));
    let mut keyed = Vec::new();
    let mut details = Vec::new();
    for (job, output) in outputs {
        for (m, run) in output.runs {
            keyed.push(((job.region, job.layout, m, job.size, job.seed), run));
        }
        if let Some(detail) = output.detail {
            details.push(detail);
        }
    }
    keyed.sort_by_key(|(k, _)| *k);
    (
        keyed.into_iter().map(|(_, run)| run).collect(),
        details.into_iter().max_by_key(|d| d.n_train),
    )
}

/// The measured outcome of one method on one campaign.
struct MethodRun {
    metrics: RunMetrics,
    points: Option<PointData>,
}

impl Shared<'_> {
    fn key(&self, job: Job, m: usize) -> RunKey {
        RunKey {
            region: self.measure.regions[job.region].name.clone(),
            layout: self.config.layouts[job.layout],
            method: self.kinds[m],
            n_train: self.config.sizes[job.size],
            seed: job.seed,
        }
    }

    /// The fit's wall-clock time since `started` (ms) when the study records timings, else NaN.
    fn fit_ms(&self, started: Instant) -> f64 {
        if self.timings {
            started.elapsed().as_secs_f64() * 1e3
        } else {
            f64::NAN
        }
    }

    /// `fit_ms` of a run whose campaign failed before any fit: 0, or NaN when the study records no timings.
    fn no_fit_ms(&self) -> f64 {
        if self.timings { 0.0 } else { f64::NAN }
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
        job.region == 0 && job.layout == 0 && job.seed == 0
    }

    fn run(&self, job: Job) -> JobOutput {
        let n = self.config.sizes[job.size];
        let layout = self.config.layouts[job.layout];
        let region = &self.measure.regions[job.region];
        let seed = campaign_seed(
            self.world.seed(),
            job.region as u64,
            layout_index(layout),
            n as u64,
            job.seed,
        );
        let k = self.kinds.len();
        // Which methods share a campaign: all of them, or, for a model-based layout, those of one design.
        let bundles: Vec<(Vec<usize>, Result<Prepared>)> = if layout.selects() {
            match self.prepare_designed(job, seed) {
                Ok(prepared) => prepared
                    .into_iter()
                    .enumerate()
                    .map(|(g, p)| ((0..k).filter(|&m| self.design_of[m] == g).collect(), p))
                    .collect(),
                Err(e) => vec![((0..k).collect(), Err(e))],
            }
        } else {
            vec![((0..k).collect(), self.prepare(job, seed))]
        };
        let detail_job = self.is_detail_candidate(job);
        let mut outcomes: Vec<Option<MethodRun>> = (0..k).map(|_| None).collect();
        let mut detail_campaign = None;
        for (methods, prepared) in bundles {
            let (campaign, train, val) = match prepared {
                Ok(prepared) => prepared,
                Err(e) => {
                    let reason = reason(&e);
                    for &m in &methods {
                        outcomes[m] = Some(MethodRun {
                            metrics: self.failed(job, m, reason.clone(), self.no_fit_ms()),
                            points: None,
                        });
                    }
                    self.progress.add(methods.len(), run_weight(self.config, n));
                    continue;
                }
            };
            let sets = &self.regions[job.region];
            let floor_mean = sets.oracle_grid.as_ref().and_then(|predicted| {
                let oracle = Oracle::new(self.world).and_then(|o| o.registered_on(&[&train, &val]));
                let grid = &sets.truth.grid.points;
                Stats::of(&truth_position_errors(
                    &oracle.ok()?,
                    &sets.truth,
                    grid,
                    predicted,
                ))
                .map(|s| s.mean)
            });
            let observability = self.observability(&train);
            // The methods fitted on these sets compute their registration (and more) once.
            let share = FitShare::new(&train, &val);
            let ctx = self.ctx.sharing(&share);
            let runs: Vec<(usize, MethodRun)> = methods
                .par_iter()
                .map(|&m| {
                    let sets = (&campaign, &train, &val);
                    let mut outcome = self.method(job, m, &ctx, sets, floor_mean, detail_job);
                    if outcome.metrics.failure.is_none() {
                        outcome.metrics.observability = observability[m];
                    }
                    self.progress.add(1, run_weight(self.config, n));
                    (m, outcome)
                })
                .collect();
            for (m, run) in runs {
                outcomes[m] = Some(run);
            }
            if detail_job && methods.contains(&self.detail_method) {
                detail_campaign = Some((campaign, train, val));
            }
        }
        let outcomes: Vec<MethodRun> = outcomes
            .into_iter()
            .map(|o| o.expect("every method belongs to one bundle"))
            .collect();
        let detail = detail_campaign.and_then(|(campaign, train, val)| {
            self.detail(job, region, &campaign, &train, &val, &outcomes)
        });
        JobOutput {
            runs: outcomes
                .into_iter()
                .enumerate()
                .map(|(m, o)| (m, o.metrics))
                .collect(),
            detail,
        }
    }

    /// The campaigns of a model-based layout, one per design (in the order of `self.selectors`), each split into
    /// training and validation sets; an error when the shared pool cannot be planned.
    fn prepare_designed(&self, job: Job, seed: u64) -> Result<Vec<Result<Prepared>>> {
        let n = self.config.sizes[job.size];
        let layout = self.config.layouts[job.layout];
        let total = self.config.campaign_points(n);
        Ok(self
            .measure
            .campaigns(job.region, layout, total, seed, &self.selectors)?
            .into_iter()
            .map(|c| split(c?, n, seed))
            .collect())
    }

    /// The job's campaign and its training and validation sets.
    fn prepare(&self, job: Job, seed: u64) -> Result<Prepared> {
        let n = self.config.sizes[job.size];
        let layout = self.config.layouts[job.layout];
        let total = self.config.campaign_points(n);
        split(
            self.measure.campaign(job.region, layout, total, seed)?,
            n,
            seed,
        )
    }

    /// Method `m` fitted (under `ctx`) on the job's campaign's training and validation sets, and judged.
    fn method(
        &self,
        job: Job,
        m: usize,
        ctx: &FitContext,
        (campaign, train, val): (&Campaign, &Dataset, &Dataset),
        floor_mean: Option<f64>,
        detail_job: bool,
    ) -> MethodRun {
        let started = Instant::now();
        let fitted = self.kinds[m].fit(ctx, train, val);
        let fit_ms = self.fit_ms(started);
        let sets = &self.regions[job.region];
        let judged = fitted.and_then(|model| {
            let test = (&sets.test, &sets.test_poses[..]);
            let judged = judge(model.as_ref(), test, &sets.truth, &self.world.robot)?;
            match judged.non_finite_view() {
                Some(view) => Err(Error::Invalid(format!(
                    "the model's predictions on the {view} are not finite"
                ))),
                None => Ok((model, judged)),
            }
        });
        let (model, judged) = match judged {
            Ok(ok) => ok,
            Err(e) => {
                return MethodRun {
                    metrics: self.failed(job, m, reason(&e), fit_ms),
                    points: None,
                };
            }
        };
        let regions: Vec<(&RegionConfig, &GroundTruth)> = self
            .measure
            .regions
            .iter()
            .zip(&self.regions)
            .map(|(region, sets)| (region, &sets.truth))
            .collect();
        let by_distance = by_distance(
            model.as_ref(),
            job.region,
            &regions,
            &judged,
            &self.config.distance_bands_m,
        );
        let points = detail_job.then(|| PointData {
            test: judged.test.position.clone(),
            campaign: (m == self.detail_method).then(|| {
                (
                    world_predictions(model.as_ref(), &sets.truth, campaign),
                    judged.grid.position.clone(),
                )
            }),
        });
        MethodRun {
            metrics: RunMetrics {
                key: self.key(job, m),
                failure: None,
                test: Stats::of(&judged.test.position),
                truth: Stats::of(&judged.grid.position),
                outside: Stats::of(&judged.shell.position),
                closed_loop: Stats::of(&judged.closed_loop.position),
                floor_mean,
                test_orientation: Stats::of(&judged.test.orientation),
                truth_orientation: Stats::of(&judged.grid.orientation),
                by_distance,
                observability: None,
                fit_ms,
            },
            points,
        }
    }

    /// The detail of this job, when its campaign, the nominal model and the detail method all worked.
    fn detail(
        &self,
        job: Job,
        region: &RegionConfig,
        campaign: &Campaign,
        train: &Dataset,
        val: &Dataset,
        outcomes: &[MethodRun],
    ) -> Option<Detail> {
        let nominal = REFERENCE.fit(&self.ctx, train, val).ok()?;
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
                    self.kinds[m],
                    Histogram {
                        before: before_test.clone(),
                        after: data.test.clone(),
                    },
                ))
            })
            .collect();
        Some(Detail {
            region: region.name.clone(),
            layout: self.config.layouts[job.layout],
            method: self.kinds[self.detail_method],
            n_train: self.config.sizes[job.size],
            points,
            grid,
            histograms,
            tracker: self.world.tracker.pose,
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
