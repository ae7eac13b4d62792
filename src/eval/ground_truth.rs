//! The ground truth a fitted method is judged on: noise-free true points of every region — a dense grid, a
//! shell just outside, closed-loop targets — and the tracker's true pose that maps them into a method's frame.
//! Only the evaluation builds it.
//!
//! A method predicts in its own registered frame `R = tracker_to_base · tracker`. The truth lives in the world
//! frame `W`, and the tracker's true pose is `T_trk` (world ← tracker); a true world point goes into `R` as
//! `tracker_to_base · T_trk⁻¹ · p_W`, which is what a perfect tracker would have measured seen through the
//! method's own registration.

use std::collections::BTreeMap;

use nalgebra::{Isometry3, Point3, UnitQuaternion, Vector3};
use rand::Rng;
use rayon::prelude::*;

use super::oracle::nest_rotation;
use crate::calib::method::Fitted;
use crate::campaign::ground_truth::{GROUND_TRUTH_ATTEMPT, TruePoint};
use crate::campaign::{CampaignConfig, Generator, LayoutKind, RegionConfig, Rejections};
use crate::error::Result;
use crate::rng::Stream;
use crate::robot::dh::{ChainPose, DhChain};
use crate::world::World;

/// No ground-truth set may ask for more points than this per region.
const MAX_SET_POINTS: usize = 1_000_000;

/// The sizes of the ground-truth sets, per region: the evaluation's and the study's alike.
#[derive(Clone, Debug, PartialEq)]
pub struct GroundTruthConfig {
    /// Points of the noise-free grid (a lattice: at least this many candidates).
    pub grid_points: usize,
    /// Thickness of the extrapolation shell around each region (m).
    pub shell_width_m: f64,
    /// Candidate points of the shell; 0 skips it.
    pub shell_points: usize,
    /// Closed-loop targets; 0 skips the closed loop.
    pub closed_loop_points: usize,
}

impl GroundTruthConfig {
    pub fn validate(&self) -> std::result::Result<(), String> {
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
}

/// Noise-free true points of one kind, over all regions.
#[derive(Clone, Debug, Default)]
pub struct TruthSet {
    pub points: Vec<TruePoint>,
    /// Per region: candidates, feasible, and why the others were dropped.
    pub rejections: BTreeMap<String, Rejections>,
    /// The nominal chain ([`GroundTruth::nominal`]) at each point's command, for the sets every fitted model
    /// is judged on (the grid and the shell; empty for the others): computed once, not once per model.
    pub poses: Vec<ChainPose>,
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
    /// The nominal DH chain of the sets' `poses`.
    pub nominal: DhChain,
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
        config: &GroundTruthConfig,
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
            let unit = LayoutKind::Grid.build().sample(
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
                let unit = LayoutKind::Uniform.build().sample(
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
        for set in [&mut grid, &mut shell] {
            set.poses = set
                .points
                .par_iter()
                .map(|p| world.dh.pose(&p.q_cmd))
                .collect();
        }
        Ok(GroundTruth {
            nominal: world.dh.clone(),
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
        world_to_method(&self.tracker_pose, model)
    }
}

/// World → the registered frame of `model` measured by a tracker at `tracker_pose` (world ← tracker).
pub fn world_to_method(tracker_pose: &Isometry3<f64>, model: &dyn Fitted) -> Isometry3<f64> {
    model.registration().frame.tracker_to_base * tracker_pose.inverse()
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
