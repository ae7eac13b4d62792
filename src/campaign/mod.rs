//! Measurement campaigns: regions of the workspace, point layouts inside them, inverse kinematics of the
//! nominal model, feasibility (limits, collisions, the tracker's line of sight) and the simulated measurement.
//! A campaign takes the [`World`] it is measured in and its own configuration ([`CampaignConfig`], regions).

pub mod distribution;
pub mod generate;
pub mod region;
mod selected;
pub mod sequence;
pub mod trajectory;

pub use distribution::{DistributionKind, PointDistribution};
pub use generate::{Campaign, CampaignPoint, Generator, Rejections, Selector};
pub use region::{CampaignConfig, RegionConfig};
pub use sequence::Stop;

use crate::world::World;

/// A world and the campaign measured in it.
pub struct Simulation {
    pub world: World,
    pub campaign: Campaign,
}
