//! The study's tracker-time axis (issue 16): the same targets measured stop and go, or on the fly along a path
//! through them at several speeds, and what each costs in tracker time and gives in accuracy.
//!
//! For every (region, number of targets n, seed, speed) the path passes through the targets of the stop-and-go
//! campaign of the same region, size and seed on the uniform layout (its n training + validation points), so
//! that the two differ only in how they are measured. The tracker's samples are corrected for the clock offset
//! ([`crate::calib::clock`], estimated with each joint's lost motion), split at random into training and
//! validation samples in the study's ratio, and every method is fitted on them and judged on the region's
//! static ground-truth grid — the arm used point to point afterwards. A trajectory costs its duration; a
//! stop-and-go campaign `move_s + settle_s + measure_s` per point ([`super::StudyConfig`]).

use nalgebra::Point3;
use rand::seq::SliceRandom;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::StudyConfig;
use super::measure::{Measure, campaign_seed, layout_index};
use crate::calib::clock;
use crate::calib::method::{FitContext, FitShare, Fitted};
use crate::calib::motion_inputs::with_motion_inputs;
use crate::calib::registry::MethodKind;
use crate::campaign::config::TrajectoryConfig;
use crate::campaign::ground_truth::TruePoint;
use crate::campaign::trajectory::{self, TrajectoryCampaign};
use crate::campaign::{Campaign, LayoutKind};
use crate::dataset::Dataset;
use crate::error::{Error, Result};
use crate::eval::GroundTruth;
use crate::eval::Stats;
use crate::eval::judge::{truth_errors, truth_set_errors};
use crate::measurements::as_dataset;
use crate::rng::{Stream, derive};

/// `[study.trajectory]`: trajectory campaigns beside the stop-and-go ones. Magnitudes and their sources in
/// `scenarios/README.md`.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct TrajectoryStudy {
    /// Fractions of the joints' velocity and acceleration limits, one trajectory campaign each.
    pub speeds: Vec<f64>,
    /// Numbers of training targets the path passes through (each with its validation targets), among the
    /// study's sizes.
    pub sizes: Vec<usize>,
    /// Repetitions (seeds 0..seeds, the stop-and-go campaigns' seeds); at most the study's.
    pub seeds: u64,
    pub acceleration_rad_s2: f64,
    pub sample_rate_hz: f64,
    pub keep_every: usize,
    pub clock_offset_s: f64,
    pub jitter_s: f64,
    /// The clock offset is searched within ±this (s).
    pub clock_bound_s: f64,
    /// Also fit every method that regresses on extra inputs with the motion as inputs (`<method> + motion`):
    /// per joint, the torque the commanded motion needs beyond gravity on the nominal model (Nm), which the
    /// controller knows; judged on the static grid with those inputs at zero (the arm at rest).
    #[serde(default)]
    pub motion_inputs: bool,
}

impl TrajectoryStudy {
    pub fn config(&self, speed: f64) -> TrajectoryConfig {
        TrajectoryConfig {
            speed,
            acceleration_rad_s2: self.acceleration_rad_s2,
            sample_rate_hz: self.sample_rate_hz,
            keep_every: self.keep_every,
            clock_offset_s: self.clock_offset_s,
            jitter_s: self.jitter_s,
        }
    }

    pub fn validate(&self, study: &StudyConfig) -> std::result::Result<(), String> {
        if self.speeds.is_empty() {
            return Err("trajectory.speeds is empty".into());
        }
        for &s in &self.speeds {
            self.config(s).validate()?;
        }
        if self.sizes.is_empty() || self.sizes.iter().any(|n| !study.sizes.contains(n)) {
            return Err(format!(
                "trajectory.sizes {:?}: one or more of the study's sizes {:?}",
                self.sizes, study.sizes
            ));
        }
        if self.seeds == 0 || self.seeds > study.seeds {
            return Err(format!(
                "trajectory.seeds = {}: between 1 and the study's {}",
                self.seeds, study.seeds
            ));
        }
        if !(self.clock_bound_s > 0.0 && self.clock_bound_s <= 1.0) {
            return Err(format!(
                "trajectory.clock_bound_s = {}: in (0, 1]",
                self.clock_bound_s
            ));
        }
        Ok(())
    }
}

/// One method on one trajectory campaign.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct TrajectoryRun {
    pub region: String,
    pub method: MethodKind,
    /// Fitted with the motion as extra inputs ([`TrajectoryStudy::motion_inputs`]).
    #[serde(default)]
    pub motion_inputs: bool,
    pub speed: f64,
    /// Training targets the path passes through (the stop-and-go campaign's size).
    pub n_targets: usize,
    pub seed: u64,
    /// Samples kept (training + validation).
    pub samples: usize,
    /// The path's duration: the tracker time (s).
    pub tracker_s: f64,
    /// Estimated minus true clock offset (s).
    pub clock_error_s: f64,
    /// Largest flange displacement due to the motion over the kept samples (m).
    pub dynamic_max_m: f64,
    /// Ground-truth grid errors of the fitted method (m); `None` when the fit failed.
    pub truth: Option<Stats>,
    pub failure: Option<String>,
}

impl TrajectoryRun {
    /// The method as reports name the run: `paper-rotxyz`, or `paper-rotxyz + motion` with the motion as
    /// inputs.
    pub fn label(&self) -> String {
        label(self.method, self.motion_inputs)
    }
}

/// A method as the trajectory reports name it, with or without the motion as inputs.
pub fn label(method: MethodKind, motion_inputs: bool) -> String {
    if motion_inputs {
        format!("{method}{MOTION_SUFFIX}")
    } else {
        method.to_string()
    }
}

/// One sample of the trajectory shown in the recording.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct TrajectorySample {
    /// Tracker time (s).
    pub t: f64,
    /// Where the reflector really was (world frame, m).
    pub true_position: Point3<f64>,
    /// |prediction − truth| of the detail method at the sample's clock-corrected joint readings (m): what the
    /// static model leaves of the arm in motion.
    pub error_after: f64,
    /// The flange displacement due to the motion (m).
    pub dynamic: f64,
}

/// The trajectory shown sample by sample: the first region's, through the most targets, seed 0, at the highest
/// speed (where the motion matters most), with the study's detail method.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct TrajectoryDetail {
    pub region: String,
    pub method: MethodKind,
    pub speed: f64,
    pub n_targets: usize,
    pub samples: Vec<TrajectorySample>,
}

/// What the trajectory campaigns gave.
pub struct TrajectoryOutcome {
    pub runs: Vec<TrajectoryRun>,
    pub detail: Option<TrajectoryDetail>,
}

/// Every trajectory run of the study, in the order (region, size, seed, speed, method), and the detail. The
/// stop-and-go campaign a path passes through is generated once for all its speeds.
pub(super) fn run(
    measure: &Measure,
    config: &StudyConfig,
    study: &TrajectoryStudy,
    ctx: &FitContext,
    truth: &[&GroundTruth],
) -> Result<TrajectoryOutcome> {
    let shown_n = study.sizes.iter().copied().max().unwrap_or(0);
    let shown_speed = study.speeds.iter().copied().fold(0.0, f64::max);
    let mut targets = Vec::new();
    for r in 0..measure.regions.len() {
        for &n in &study.sizes {
            for seed in 0..study.seeds {
                targets.push((r, n, seed));
            }
        }
    }
    let context = PathContext {
        measure,
        config,
        study,
        ctx,
        truth,
    };
    let out: Vec<Vec<PathOutput>> = targets
        .par_iter()
        .map(|&(r, n, seed)| {
            let jobs: Vec<PathJob> = study
                .speeds
                .iter()
                .map(|&speed| PathJob {
                    r,
                    n,
                    seed,
                    speed,
                    shown: r == 0 && n == shown_n && seed == 0 && speed == shown_speed,
                })
                .collect();
            let key = context.key(jobs[0]);
            let planned = context.planned(jobs[0], key);
            jobs.par_iter()
                .map(|&job| match &planned {
                    Ok(planned) => context.run(job, key, planned),
                    Err(e) => (context.failed(job, e.detail()), None),
                })
                .collect()
        })
        .collect();
    let mut outcome = TrajectoryOutcome {
        runs: Vec::new(),
        detail: None,
    };
    for (runs, detail) in out.into_iter().flatten() {
        outcome.runs.extend(runs);
        outcome.detail = outcome.detail.or(detail);
    }
    Ok(outcome)
}

/// The runs of one trajectory campaign, and its detail when it is shown.
type PathOutput = (Vec<TrajectoryRun>, Option<TrajectoryDetail>);

/// One trajectory campaign: region `r`, `n` targets, repetition `seed`, `speed`; `shown` when the recording
/// shows it sample by sample.
#[derive(Clone, Copy)]
struct PathJob {
    r: usize,
    n: usize,
    seed: u64,
    speed: f64,
    shown: bool,
}

/// What every trajectory campaign shares.
struct PathContext<'a> {
    measure: &'a Measure<'a>,
    config: &'a StudyConfig,
    study: &'a TrajectoryStudy,
    ctx: &'a FitContext<'a>,
    truth: &'a [&'a GroundTruth],
}

/// A trajectory campaign's samples, clock-corrected, and which of them train and validate.
struct Samples {
    data: Dataset,
    train: Vec<usize>,
    val: Vec<usize>,
    offset_s: f64,
}

impl PathContext<'_> {
    /// The seed of `job`'s stop-and-go campaign (the same for every speed).
    fn key(&self, job: PathJob) -> u64 {
        campaign_seed(
            self.measure.world.seed(),
            job.r as u64,
            layout_index(LayoutKind::Uniform),
            job.n as u64,
            job.seed,
        )
    }

    /// The stop-and-go campaign of `job`'s region, size and seed on the uniform layout: the targets its path
    /// passes through.
    fn planned(&self, job: PathJob, key: u64) -> Result<Campaign> {
        self.measure.campaign(
            job.r,
            LayoutKind::Uniform,
            self.config.campaign_points(job.n),
            key,
        )
    }

    /// The runs of every method on `job`'s campaign through `planned` (failed runs when the campaign or its
    /// clock fails), and its detail when it is shown.
    fn run(&self, job: PathJob, key: u64, planned: &Campaign) -> PathOutput {
        let failed = |e: Error| (self.failed(job, e.detail()), None);
        let measured = match self.measure_path(job, key, planned) {
            Ok(m) => m,
            Err(e) => return failed(e),
        };
        let samples = match self.samples(&measured, key) {
            Ok(s) => s,
            Err(e) => return failed(e),
        };
        let template = TrajectoryRun {
            region: self.measure.regions[job.r].name.clone(),
            // Each run sets its own method.
            method: MethodKind::ALL[0],
            motion_inputs: false,
            speed: job.speed,
            n_targets: job.n,
            seed: job.seed,
            samples: samples.train.len() + samples.val.len(),
            tracker_s: measured.duration_s,
            clock_error_s: samples.offset_s - self.study.clock_offset_s,
            dynamic_max_m: measured.dynamic_m.iter().fold(0.0f64, |a, b| a.max(*b)),
            truth: None,
            failure: None,
        };
        let (train, val) = (
            samples.data.subset(&samples.train),
            samples.data.subset(&samples.val),
        );
        let mut share = FitShare::new(&train, &val);
        let (mut runs, detail) = self.fit_each(job, &template, &samples, &measured, &share);
        // Kept whole, the paper's factorizations raised the trajectory part's peak memory from 266 to 337 MB.
        share.drop_what_reads_inputs();
        if self.study.motion_inputs {
            match self.fit_with_motion(job, &template, &samples, &share) {
                Ok(moving) => runs.extend(moving),
                Err(e) => return failed(e),
            }
        }
        (runs, detail)
    }

    /// Every method's run on `job`, failed for `reason`.
    fn failed(&self, job: PathJob, reason: String) -> Vec<TrajectoryRun> {
        self.config
            .methods
            .iter()
            .map(|&method| TrajectoryRun {
                region: self.measure.regions[job.r].name.clone(),
                method,
                motion_inputs: false,
                speed: job.speed,
                n_targets: job.n,
                seed: job.seed,
                samples: 0,
                tracker_s: 0.0,
                clock_error_s: f64::NAN,
                dynamic_max_m: 0.0,
                truth: None,
                failure: Some(reason.clone()),
            })
            .collect()
    }

    /// The path through the stop-and-go campaign's targets `planned`, measured on the fly at `job`'s speed.
    fn measure_path(
        &self,
        job: PathJob,
        key: u64,
        planned: &Campaign,
    ) -> Result<TrajectoryCampaign> {
        let posture = self.measure.campaign.posture_rad();
        trajectory::measure(
            self.measure.world,
            planned,
            &posture,
            &self.study.config(job.speed),
            key,
        )
    }

    /// The campaign's samples with the clock offset removed, split at random into training and validation
    /// samples in the study's ratio.
    fn samples(&self, measured: &TrajectoryCampaign, key: u64) -> Result<Samples> {
        let data = as_dataset(&measured.campaign, "the trajectory campaign")?;
        let offset = clock::estimate(&self.measure.world.dh, &data, self.study.clock_bound_s)?;
        let data = clock::corrected(&data, offset.offset_s)?;
        let mut order: Vec<usize> = (0..data.len()).collect();
        order.shuffle(&mut derive(key, Stream::Split, &[1]));
        let n_train = ((data.len() as f64) / (1.0 + self.config.validation_ratio)).round() as usize;
        let (mut train, mut val) = (order[..n_train].to_vec(), order[n_train..].to_vec());
        train.sort_unstable();
        val.sort_unstable();
        if val.is_empty() {
            return Err(Error::Invalid("too few samples to validate".into()));
        }
        Ok(Samples {
            data,
            train,
            val,
            offset_s: offset.offset_s,
        })
    }

    /// Every method fitted on the samples and judged on the region's static grid; the detail method's error at
    /// every sample when the campaign is shown.
    fn fit_each(
        &self,
        job: PathJob,
        template: &TrajectoryRun,
        samples: &Samples,
        measured: &TrajectoryCampaign,
        share: &FitShare,
    ) -> (Vec<TrajectoryRun>, Option<TrajectoryDetail>) {
        let truth = self.truth[job.r];
        let (train, val) = (share.train(), share.val());
        let ctx = self.ctx.sharing(share);
        let fitted: Vec<(TrajectoryRun, Option<TrajectoryDetail>)> = self
            .config
            .methods
            .par_iter()
            .map(|&method| {
                let mut detail = None;
                let (truth, failure) = match method.fit(&ctx, train, val) {
                    Ok(model) => {
                        if job.shown && Some(method) == self.config.detail_method() {
                            detail = Some(sampled(
                                method,
                                model.as_ref(),
                                truth,
                                measured,
                                &samples.data,
                                (&template.region, job.speed, job.n),
                            ));
                        }
                        (grid_stats(model.as_ref(), truth), None)
                    }
                    Err(e) => (None, Some(e.detail())),
                };
                let run = TrajectoryRun {
                    method,
                    truth,
                    failure,
                    ..template.clone()
                };
                (run, detail)
            })
            .collect();
        let mut detail = None;
        let runs = fitted
            .into_iter()
            .map(|(run, d)| {
                detail = detail.take().or(d);
                run
            })
            .collect();
        (runs, detail)
    }

    /// Every method that regresses on extra inputs, fitted again with the motion as inputs, judged at rest.
    /// What the fits compute from the points alone (the registration, the kinematic fits under the hybrids,
    /// the paper's flange frames) is taken from the fits without them (`plain`).
    fn fit_with_motion(
        &self,
        job: PathJob,
        template: &TrajectoryRun,
        samples: &Samples,
        plain: &FitShare,
    ) -> Result<Vec<TrajectoryRun>> {
        let moving = with_motion_inputs(
            &samples.data,
            &self.measure.world.nominal,
            &self.ctx.payload,
        )?;
        let (train, val) = (moving.subset(&samples.train), moving.subset(&samples.val));
        let share =
            FitShare::beside(plain, &train, &val).unwrap_or_else(|| FitShare::new(&train, &val));
        let ctx = self.ctx.sharing(&share);
        let truth = self.truth[job.r];
        Ok(self
            .config
            .methods
            .par_iter()
            .filter(|k| k.info().takes_inputs)
            .map(|&method| {
                let (truth, failure) = match method.fit(&ctx, &train, &val) {
                    // At the inputs' defaults: the motion's are zero, the arm at rest.
                    Ok(model) => (grid_stats(model.as_ref(), truth), None),
                    Err(e) => (None, Some(e.detail())),
                };
                TrajectoryRun {
                    method,
                    motion_inputs: true,
                    truth,
                    failure,
                    ..template.clone()
                }
            })
            .collect())
    }
}

/// Statistics of `model`'s errors on the ground-truth grid.
fn grid_stats(model: &dyn Fitted, truth: &GroundTruth) -> Option<Stats> {
    Stats::of(&truth_set_errors(model, truth, &truth.grid).position)
}

/// The name suffix of a method fitted with the motion as inputs.
pub const MOTION_SUFFIX: &str = " + motion";

/// The detail method's error at every sample of `measured` (`data`: the same samples, clock-corrected).
fn sampled(
    method: MethodKind,
    model: &dyn Fitted,
    truth: &GroundTruth,
    measured: &TrajectoryCampaign,
    data: &Dataset,
    (region, speed, n_targets): (&str, f64, usize),
) -> TrajectoryDetail {
    let points: Vec<TruePoint> = measured
        .campaign
        .points
        .iter()
        .zip(&data.q)
        .map(|(p, q)| TruePoint {
            region: p.region.clone(),
            q_cmd: q.clone(),
            nominal_flange: p.nominal_flange,
            true_flange: p.true_flange,
            true_reflectors: p.true_reflectors.clone(),
        })
        .collect();
    let errors = truth_errors(model, truth, &points).position;
    TrajectoryDetail {
        region: region.to_string(),
        method,
        speed,
        n_targets,
        samples: measured
            .campaign
            .points
            .iter()
            .zip(errors)
            .zip(&measured.dynamic_m)
            .map(|((p, e), d)| TrajectorySample {
                t: p.time.unwrap_or(f64::NAN),
                true_position: p.true_reflectors[0],
                error_after: e,
                dynamic: *d,
            })
            .collect(),
    }
}
