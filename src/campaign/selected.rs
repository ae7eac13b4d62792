//! Several campaigns from one pool: a model-based layout choosing, for each of several models, its points from
//! the same planned and measured candidates (the study gives each method the points chosen for it this way).

use std::collections::BTreeMap;

use super::generator::{Generator, Selector};
use super::points::{Campaign, Rejections};
use super::region::RegionConfig;
use super::sequence::Stop;
use crate::error::Result;
use crate::robot::collision::CollisionModel;

/// Candidate counts per region.
type Counts = BTreeMap<String, Rejections>;

impl Generator<'_> {
    /// Campaigns whose model-based regions choose their points with each of `selectors` in turn, from one pool
    /// planned once (the pool, its feasibility and every point's noise draws are the same for all): one result per
    /// selector, in order. A region with a geometric layout gives every campaign the same points. The pool
    /// failing fails the whole call; a selector that cannot choose fails only its own campaign.
    pub fn run_selected(
        &self,
        regions: &[RegionConfig],
        selectors: &[&dyn Selector],
    ) -> Result<Vec<Result<Campaign>>> {
        let collision = CollisionModel::new(&self.world.nominal);
        let mut per: Vec<Result<(Vec<Stop>, Counts)>> = (0..selectors.len())
            .map(|_| Ok(Default::default()))
            .collect();
        for (r, region) in regions.iter().enumerate() {
            let results = if region.layout.selects() {
                self.region_for(r as u64, region, &collision, selectors)?
            } else {
                let one = self
                    .region_for(r as u64, region, &collision, &[])?
                    .remove(0)?;
                selectors.iter().map(|_| Ok(one.clone())).collect()
            };
            for (slot, result) in per.iter_mut().zip(results) {
                if let Ok((visits, rejections)) = slot {
                    match result {
                        Ok((stops, counts)) => {
                            visits.extend(stops);
                            rejections.insert(region.name.clone(), counts);
                        }
                        Err(e) => *slot = Err(e),
                    }
                }
            }
        }
        Ok(per
            .into_iter()
            .map(|slot| {
                let (visits, rejections) = slot?;
                Ok(Campaign {
                    joint_names: self.world.nominal.joint_names(),
                    points: self.measure_sequence(&visits)?,
                    rejections,
                })
            })
            .collect())
    }
}
