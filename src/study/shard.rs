//! A study split over processes: shard K of N computes the campaigns whose global index i has i mod N = K,
//! and the shards' parts, put together, are the unsharded study.
//!
//! The unit of a shard is the **campaign** (region, layout, size, seed), with every method fitted on it: the
//! methods of one campaign share its measured points, so splitting them would measure it twice. Every draw of a
//! campaign derives from its own key ([`super::measure::campaign_seed`]), and the region sets every run shares
//! (test set, ground truth) are rebuilt identically by each shard, so a run's numbers do not depend on the
//! shard that computes it. [`assemble`] orders the runs as the unsharded sweep does and picks the same detail
//! run, so the merged `metrics.csv`, `summary.md` and `answer.csv` are byte-identical to an unsharded run's.

use std::collections::BTreeMap;
use std::fmt;

use serde::{Deserialize, Serialize};

use super::{Detail, Limits, RunMetrics, StudyConfig, StudyResult};
use crate::campaign::RegionConfig;
use crate::world::World;

/// Shard `index` of `count` (`index < count`); `Shard::WHOLE` is the unsharded study.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Shard {
    pub index: usize,
    pub count: usize,
}

/// The most shards a study may be split into: far more than the campaigns of any study a cluster would run
/// as an array, and a guard against a typo such as `--shard 0/1000000000`.
pub const MAX_SHARDS: usize = 100_000;

impl Shard {
    pub const WHOLE: Shard = Shard { index: 0, count: 1 };

    /// Parses `K/N`.
    pub fn parse(text: &str) -> Result<Shard, String> {
        let bad = || format!("--shard '{text}': K/N with 0 ≤ K < N ≤ {MAX_SHARDS}, e.g. 0/4");
        let (k, n) = text.split_once('/').ok_or_else(bad)?;
        let index: usize = k.trim().parse().map_err(|_| bad())?;
        let count: usize = n.trim().parse().map_err(|_| bad())?;
        if count == 0 || index >= count || count > MAX_SHARDS {
            return Err(bad());
        }
        Ok(Shard { index, count })
    }

    /// Whether the campaign with global index `i` belongs to this shard.
    pub fn holds(&self, i: usize) -> bool {
        i % self.count == self.index
    }
}

impl fmt::Display for Shard {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

/// What one shard computed: its runs (in the sweep's order), the detail run if it held that campaign, and
/// the per-region limits (the same in every shard).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct StudyPart {
    pub shard: Shard,
    /// Global indices of the campaigns this shard ran.
    pub campaigns: Vec<usize>,
    /// How many campaigns the whole study has.
    pub total_campaigns: usize,
    pub runs: Vec<RunMetrics>,
    pub detail: Option<Detail>,
    pub limits: Vec<Limits>,
    /// The trajectory runs, computed by shard 0 alone.
    pub trajectory: Vec<super::trajectory::TrajectoryRun>,
    /// The trajectory shown sample by sample (shard 0).
    #[serde(default)]
    pub trajectory_detail: Option<super::trajectory::TrajectoryDetail>,
}

/// The study of `parts` (one unsharded part, or every shard's): runs in the configuration's order (region,
/// layout, method, size, seed), the detail run of the largest size, limits from the first part.
pub fn assemble(
    world: &World,
    regions: &[RegionConfig],
    config: &StudyConfig,
    parts: Vec<StudyPart>,
) -> StudyResult {
    let region_at: BTreeMap<&str, usize> = regions
        .iter()
        .enumerate()
        .map(|(i, r)| (r.name.as_str(), i))
        .collect();
    let order = |run: &RunMetrics| {
        let k = &run.key;
        (
            region_at
                .get(k.region.as_str())
                .copied()
                .unwrap_or(usize::MAX),
            config
                .layouts
                .iter()
                .position(|d| *d == k.layout)
                .unwrap_or(usize::MAX),
            config
                .methods
                .iter()
                .position(|&m| m == k.method)
                .unwrap_or(usize::MAX),
            config
                .sizes
                .iter()
                .position(|&n| n == k.n_train)
                .unwrap_or(usize::MAX),
            k.seed,
        )
    };
    let limits = parts.first().map(|p| p.limits.clone()).unwrap_or_default();
    let mut runs = Vec::new();
    let mut details = Vec::new();
    let mut trajectory = Vec::new();
    let mut trajectory_detail = None;
    for part in parts {
        trajectory_detail = trajectory_detail.or(part.trajectory_detail);
        runs.extend(part.runs);
        details.extend(part.detail);
        trajectory.extend(part.trajectory);
    }
    runs.sort_by_key(|r| order(r));
    // The detail candidates are the campaigns of the first region, layout and seed: one per size, so the
    // largest is unique whichever shard holds it.
    let detail = details
        .into_iter()
        .max_by_key(|d| d.n_train)
        .unwrap_or_else(|| Detail {
            region: regions[0].name.clone(),
            layout: config.layouts[0],
            method: config.detail_method().unwrap_or(config.methods[0]),
            n_train: config.sizes.iter().copied().max().unwrap_or(0),
            points: Vec::new(),
            grid: Vec::new(),
            histograms: BTreeMap::new(),
            tracker: world.tracker.pose,
        });
    StudyResult {
        world: world.config.clone(),
        config: config.clone(),
        regions: regions.to_vec(),
        runs,
        detail,
        orientation: world.mounting.count() >= 3,
        limits,
        trajectory,
        trajectory_detail,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_k_of_n_and_refuses_the_rest() {
        assert_eq!(Shard::parse("2/5"), Ok(Shard { index: 2, count: 5 }));
        for bad in ["5/5", "1/0", "-1/3", "a/3", "3", "0/1000000000", ""] {
            assert!(Shard::parse(bad).is_err(), "{bad}");
        }
        let s = Shard::parse("1/3").unwrap();
        let held: Vec<usize> = (0..9).filter(|&i| s.holds(i)).collect();
        assert_eq!(held, [1, 4, 7]);
    }
}
