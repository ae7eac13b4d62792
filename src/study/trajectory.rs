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
use crate::calib::method::{FitContext, Fitted};
use crate::calib::motion_inputs::with_motion_inputs;
use crate::calib::registry::{self, MethodKind};
use crate::campaign::DistributionKind;
use crate::campaign::config::TrajectoryConfig;
use crate::campaign::ground_truth::TruePoint;
use crate::campaign::trajectory::{self, TrajectoryCampaign};
use crate::dataset::Dataset;
use crate::error::{Error, Result};
use crate::eval::Stats;
use crate::eval::accuracy::{GroundTruth, truth_errors};
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
    pub method: String,
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
    pub method: String,
    pub speed: f64,
    pub n_targets: usize,
    pub samples: Vec<TrajectorySample>,
}

/// What the trajectory campaigns gave.
pub struct TrajectoryOutcome {
    pub runs: Vec<TrajectoryRun>,
    pub detail: Option<TrajectoryDetail>,
}

/// Every trajectory run of the study, in the order (region, size, seed, speed, method), and the detail.
pub(super) fn run(
    measure: &Measure,
    config: &StudyConfig,
    study: &TrajectoryStudy,
    ctx: &FitContext,
    kinds: &[MethodKind],
    truth: &[&GroundTruth],
) -> Result<TrajectoryOutcome> {
    let world = measure.world;
    let posture = measure.campaign.posture_rad();
    let detail_n = study.sizes.iter().copied().max().unwrap_or(0);
    let detail_speed = study.speeds.iter().copied().fold(0.0, f64::max);
    let mut jobs = Vec::new();
    for r in 0..measure.regions.len() {
        for &n in &study.sizes {
            for seed in 0..study.seeds {
                for &speed in &study.speeds {
                    jobs.push((r, n, seed, speed));
                }
            }
        }
    }
    let out: Vec<(Vec<TrajectoryRun>, Option<TrajectoryDetail>)> = jobs
        .par_iter()
        .map(|&(r, n, seed, speed)| {
            let region = &measure.regions[r].name;
            let key = campaign_seed(
                world.seed(),
                r as u64,
                layout_index(DistributionKind::Uniform),
                n as u64,
                seed,
            );
            let failed = |reason: String| {
                kinds
                    .iter()
                    .map(|k| TrajectoryRun {
                        region: region.clone(),
                        method: k.name().to_string(),
                        speed,
                        n_targets: n,
                        seed,
                        samples: 0,
                        tracker_s: 0.0,
                        clock_error_s: f64::NAN,
                        dynamic_max_m: 0.0,
                        truth: None,
                        failure: Some(reason.clone()),
                    })
                    .collect::<Vec<_>>()
            };
            let failed = |reason: String| (failed(reason), None);
            let measured = measure
                .campaign(r, DistributionKind::Uniform, config.campaign_points(n), key)
                .and_then(|planned| {
                    trajectory::measure(world, &planned, &posture, &study.config(speed), key)
                });
            let measured = match measured {
                Ok(m) => m,
                Err(e) => return failed(e.detail()),
            };
            let prepared = (|| -> Result<_> {
                let data = as_dataset(&measured.campaign, "the trajectory campaign")?;
                let offset = clock::estimate(&world.dh, &data, study.clock_bound_s)?;
                let data = clock::corrected(&data, offset.offset_s)?;
                let mut order: Vec<usize> = (0..data.len()).collect();
                order.shuffle(&mut derive(key, Stream::Split, &[1]));
                let n_train =
                    ((data.len() as f64) / (1.0 + config.validation_ratio)).round() as usize;
                let (mut train, mut val) = (order[..n_train].to_vec(), order[n_train..].to_vec());
                train.sort_unstable();
                val.sort_unstable();
                if val.is_empty() {
                    return Err(Error::Invalid("too few samples to validate".into()));
                }
                Ok((train, val, offset.offset_s, data))
            })();
            let (train_rows, val_rows, offset, data) = match prepared {
                Ok(p) => p,
                Err(e) => return failed(e.detail()),
            };
            let (train, val) = (data.subset(&train_rows), data.subset(&val_rows));
            let dynamic_max_m = measured.dynamic_m.iter().fold(0.0f64, |a, b| a.max(*b));
            let shown = r == 0 && n == detail_n && seed == 0 && speed == detail_speed;
            let mut detail = None;
            let run_of =
                |method: String, truth: Option<Stats>, failure: Option<String>| TrajectoryRun {
                    region: region.clone(),
                    method,
                    speed,
                    n_targets: n,
                    seed,
                    samples: train.len() + val.len(),
                    tracker_s: measured.duration_s,
                    clock_error_s: offset - study.clock_offset_s,
                    dynamic_max_m,
                    truth,
                    failure,
                };
            let mut runs: Vec<TrajectoryRun> = kinds
                .iter()
                .map(|&kind| {
                    let fitted = registry::fit(kind, ctx, &train, &val);
                    let (truth, failure) = match fitted {
                        Ok(model) => {
                            if shown && kind.name() == config.detail_method() {
                                detail = Some(sampled(
                                    model.as_ref(),
                                    truth[r],
                                    &measured,
                                    &data,
                                    (region, speed, n),
                                ));
                            }
                            (
                                Stats::of(
                                    &truth_errors(model.as_ref(), truth[r], &truth[r].grid.points)
                                        .position,
                                ),
                                None,
                            )
                        }
                        Err(e) => (None, Some(e.detail())),
                    };
                    run_of(kind.name().to_string(), truth, failure)
                })
                .collect();
            if study.motion_inputs {
                let moving = match with_motion_inputs(&data, &world.nominal, &ctx.payload) {
                    Ok(m) => m,
                    Err(e) => return failed(e.detail()),
                };
                let (train, val) = (moving.subset(&train_rows), moving.subset(&val_rows));
                for &kind in kinds.iter().filter(|k| k.info().takes_inputs) {
                    let (truth, failure) = match registry::fit(kind, ctx, &train, &val) {
                        Ok(model) => (
                            Stats::of(
                                // At the inputs' defaults: the motion's are zero, the arm at rest.
                                &truth_errors(model.as_ref(), truth[r], &truth[r].grid.points)
                                    .position,
                            ),
                            None,
                        ),
                        Err(e) => (None, Some(e.detail())),
                    };
                    runs.push(run_of(
                        format!("{}{MOTION_SUFFIX}", kind.name()),
                        truth,
                        failure,
                    ));
                }
            }
            (runs, detail)
        })
        .collect();
    let mut outcome = TrajectoryOutcome {
        runs: Vec::new(),
        detail: None,
    };
    for (runs, detail) in out {
        outcome.runs.extend(runs);
        outcome.detail = outcome.detail.or(detail);
    }
    Ok(outcome)
}

/// The name suffix of a method fitted with the motion as inputs.
pub const MOTION_SUFFIX: &str = " + motion";

/// The detail method's error at every sample of `measured` (`data`: the same samples, clock-corrected).
fn sampled(
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
        method: model.info().name.to_string(),
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
