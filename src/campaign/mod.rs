//! Measurement campaigns: regions of the workspace, point layouts inside them, inverse kinematics of the
//! nominal model, feasibility (limits, collisions, the tracker's line of sight) and the simulated measurement.

pub mod distribution;
pub mod generate;
pub mod region;

pub use distribution::{DistributionKind, PointDistribution};
pub use generate::{Campaign, CampaignPoint, Rejections, Setup};
pub use region::{CampaignConfig, RegionConfig};
