//! Measurement campaigns: regions of the workspace, point layouts inside them, inverse kinematics of the
//! nominal model, feasibility (limits, collisions, the tracker's line of sight) and the simulated measurement.
//! A campaign takes the [`World`] it is measured in and its own configuration ([`CampaignConfig`], regions).
//!
//! The files import one way, from the bottom up: `points` (what a campaign is made of), `config`, `region` and
//! `layout` (how a region's points are placed), `generator` (the generator and the true arm's settling),
//! `sequence` (measuring commands in their order, a replayed campaign), `generate` (planning a campaign:
//! targets, inverse kinematics, feasibility), and on it `ground_truth`, `iso_cube` (ISO 9283's test cube and
//! its cycles) and `selected`. `trajectory` (measuring on the fly) needs only `points` and `config`.

pub mod config;
pub mod layout;
pub mod generate;
pub mod generator;
pub mod ground_truth;
pub mod iso_cube;
pub mod points;
pub mod region;
mod selected;
pub mod sequence;
pub mod trajectory;

pub use config::{CampaignConfig, SelectionConfig, TrajectoryConfig};
pub use generator::{Generator, Selector};
pub use layout::{LayoutKind, PointLayout};
pub use points::{Campaign, CampaignPoint, Rejections};
pub use region::RegionConfig;
pub use sequence::Stop;

use crate::world::World;

/// A world and the campaign measured in it.
pub struct Simulation {
    pub world: World,
    pub campaign: Campaign,
}
