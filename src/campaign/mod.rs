//! Measurement campaigns: regions of the workspace, point layouts inside them, inverse kinematics of the
//! nominal model, feasibility (limits, collisions, the tracker's line of sight) and the simulated measurement.

pub mod distribution;
pub mod generate;
pub mod region;

pub use distribution::{DistributionKind, PointDistribution};
pub use generate::{Campaign, CampaignPoint, Rejections, Setup};
pub use region::{CampaignConfig, RegionConfig};

use crate::error::Result;
use crate::rng::{Stream, derive};
use crate::robot::Chain;
use crate::scenario::Scenario;
use crate::tracker::Tracker;
use crate::tracker::reflector::Mounting;
use crate::truth::{Perturbation, TrueRobot};

/// A scenario made real: the robots, the instrument and the campaign they produce.
pub struct Simulation {
    pub nominal: Chain,
    pub robot: TrueRobot,
    pub tracker: Tracker,
    pub mounting: Mounting,
    pub campaign: Campaign,
}

/// The scenario's nominal and true robots, tracker and reflector mounting, with no campaign yet. Every draw
/// derives from the scenario seed, so every stage that needs the scenario's world gets the same one.
pub fn world(scenario: &Scenario) -> Result<Simulation> {
    let nominal = scenario.load_robot()?;
    let perturbation = Perturbation::sample(
        &scenario.truth,
        nominal.dof(),
        &mut derive(scenario.seed, Stream::Perturbation, &[]),
    )?;
    let robot = TrueRobot::new(&nominal, perturbation, scenario.robot.payload())?;
    let tracker = Tracker::new(scenario.tracker.clone())?;
    let mounting = Mounting::sample(
        &scenario.reflectors,
        &mut derive(scenario.seed, Stream::Mounting, &[]),
    )?;
    Ok(Simulation {
        campaign: Campaign {
            joint_names: nominal.joint_names(),
            points: Vec::new(),
            rejections: Default::default(),
        },
        nominal,
        robot,
        tracker,
        mounting,
    })
}

/// The scenario's world ([`world`]) and its campaign over every region.
pub fn simulate(scenario: &Scenario) -> Result<Simulation> {
    let mut sim = world(scenario)?;
    sim.campaign = Setup {
        nominal: &sim.nominal,
        robot: &sim.robot,
        tracker: &sim.tracker,
        mounting: &sim.mounting,
        config: &scenario.campaign,
        deflection: scenario.truth.deflection,
        seed: scenario.seed,
    }
    .run(&scenario.regions)?;
    Ok(sim)
}
