//! Where a study's campaigns come from: their seeds, the measured campaigns of a layout (one per design for a
//! model-based layout), the ground truth of one region, and the split into training and validation points.

use rand::RngCore;
use rand::seq::SliceRandom;

use crate::campaign::{Campaign, CampaignConfig, Generator, LayoutKind, RegionConfig, Selector};
use crate::dataset::Dataset;
use crate::error::Result;
use crate::eval::ground_truth::{GroundTruth, TruthSet};
use crate::measurements::as_dataset;
use crate::rng::{Stream, derive};
use crate::world::World;

/// The region-level seed index of the test set, far from any layout index.
pub(super) const TEST_SET: u64 = u64::MAX;

/// The seed of one campaign of the study: region `r`, layout `d` (its place in [`LayoutKind::ALL`]),
/// training-set size `n` and repetition `s`; the test set uses `d = TEST_SET`.
pub(super) fn campaign_seed(scenario_seed: u64, r: u64, d: u64, n: u64, s: u64) -> u64 {
    let region_layout = derive(scenario_seed, Stream::Study, &[r, d]).next_u64();
    derive(region_layout, Stream::Study, &[n, s]).next_u64()
}

pub(super) fn layout_index(d: LayoutKind) -> u64 {
    LayoutKind::ALL
        .iter()
        .position(|&k| k == d)
        .expect("every layout is in ALL") as u64
}

/// Where a study's campaigns are measured, and how: the world, the campaign configuration and the regions.
#[derive(Clone, Copy)]
pub(super) struct Measure<'a> {
    pub(super) world: &'a World,
    pub(super) campaign: &'a CampaignConfig,
    pub(super) regions: &'a [RegionConfig],
}

impl Measure<'_> {
    /// A campaign of `points` measured points in region `r` with `layout`, drawn from `seed`.
    pub(super) fn campaign(
        &self,
        r: usize,
        layout: LayoutKind,
        points: usize,
        seed: u64,
    ) -> Result<Campaign> {
        self.campaigns(r, layout, points, seed, &[])?
            .pop()
            .expect("one campaign")
    }

    /// The campaigns of a model-based `layout`, one per selector, chosen from one shared pool; of a geometric
    /// layout (no selectors), the one campaign.
    pub(super) fn campaigns(
        &self,
        r: usize,
        layout: LayoutKind,
        points: usize,
        seed: u64,
        selectors: &[&dyn Selector],
    ) -> Result<Vec<Result<Campaign>>> {
        let region = RegionConfig {
            points,
            layout,
            ..self.regions[r].clone()
        };
        let generator = Generator {
            world: self.world,
            config: self.campaign,
            seed,
            selector: None,
        };
        if selectors.is_empty() {
            return Ok(vec![generator.run(std::slice::from_ref(&region))]);
        }
        generator.run_selected(std::slice::from_ref(&region), selectors)
    }
}

/// The ground truth restricted to one region.
pub(super) fn region_truth(truth: &GroundTruth, region: &str) -> GroundTruth {
    let only = |set: &TruthSet| TruthSet {
        points: set
            .points
            .iter()
            .filter(|p| p.region == region)
            .cloned()
            .collect(),
        poses: set
            .poses
            .iter()
            .zip(&set.points)
            .filter(|(_, p)| p.region == region)
            .map(|(pose, _)| pose.clone())
            .collect(),
        rejections: set
            .rejections
            .iter()
            .filter(|(name, _)| *name == region)
            .map(|(k, v)| (k.clone(), v.clone()))
            .collect(),
    };
    GroundTruth {
        nominal: truth.nominal.clone(),
        tracker_pose: truth.tracker_pose,
        measured_point: truth.measured_point,
        nest_rotation: truth.nest_rotation,
        grid: only(&truth.grid),
        shell: only(&truth.shell),
        closed_loop: only(&truth.closed_loop),
    }
}

/// A campaign with its training and validation sets.
pub(super) type Prepared = (Campaign, Dataset, Dataset);

/// `campaign` split into `n` training points and the rest for validation, by a shuffle seeded from `seed`.
pub(super) fn split(campaign: Campaign, n: usize, seed: u64) -> Result<Prepared> {
    let data = as_dataset(&campaign, "the study's campaign")?;
    let mut order: Vec<usize> = (0..data.len()).collect();
    order.shuffle(&mut derive(seed, Stream::Split, &[]));
    let (mut train, mut val) = (order[..n.min(order.len())].to_vec(), order[n..].to_vec());
    train.sort_unstable();
    val.sort_unstable();
    let (train, val) = (data.subset(&train), data.subset(&val));
    Ok((campaign, train, val))
}
