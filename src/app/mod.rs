//! The jobs the binaries run: each binary parses its flags into a job's options, calls the job, and prints
//! what it returns. [`campaign`] runs a scenario: build its world once, hand each stage the world and its own
//! section, and gather what they return (the only module that reads a [`Scenario`] besides `scenario`
//! itself); [`calibrate`] fits a method on measured data and applies a saved model; [`real_data`] runs the
//! real-data protocol of `eval::protocol` on the UR10 series.

pub mod calibrate;
pub mod campaign;
pub mod real_data;
pub mod replay;
pub mod sim_vs_real;
pub mod test_points;

use crate::campaign::{Generator, Simulation};
use crate::design::DOptimal;
use crate::error::{Error, Result};
use crate::eval::accuracy::fit_context;
use crate::scenario::Scenario;
use crate::study::sweep::{self, Progress};
use crate::study::{StudyConfig, StudyResult};
use crate::world::World;

/// The scenario's world: its robot loaded and checked, the true robot, tracker and mounting drawn from its seed.
/// Evaluation poses are approached from the campaign's posture.
pub fn world(scenario: &Scenario) -> Result<World> {
    let mut world = World::new(scenario.load_robot()?, scenario.world_config())?;
    let posture: Vec<f64> = scenario
        .campaign
        .posture_deg
        .iter()
        .map(|d| d.to_radians())
        .collect();
    world.robot.set_approach(&posture);
    Ok(world)
}

/// The scenario's world and its campaign over every region.
pub fn simulate(scenario: &Scenario) -> Result<Simulation> {
    let world = world(scenario)?;
    let campaign = {
        let ctx = fit_context(&world);
        let selector = DOptimal::when_needed(
            scenario.regions.iter().map(|r| r.distribution),
            &scenario.campaign.selection,
            &ctx,
            &world.mounting.nominal,
        )?;
        Generator {
            world: &world,
            config: &scenario.campaign,
            seed: world.seed(),
            selector: selector.as_ref().map(|s| s as _),
        }
        .run(&scenario.regions)?
    };
    Ok(Simulation { world, campaign })
}

/// Runs the scenario's `[study]` on the current rayon pool (install a pool to choose the thread count).
/// Errors: no `[study]` section, a robot that does not load, a region whose test set or ground truth cannot
/// be built. Runs that fail (a campaign the region cannot supply, a method that cannot be fitted) are
/// recorded as failed with their reason.
pub fn run_study(scenario: &Scenario, progress: Progress) -> Result<StudyResult> {
    let config = study_config(scenario)?;
    sweep::run_study(
        &world(scenario)?,
        &scenario.campaign,
        &scenario.regions,
        config,
        progress,
    )
}

/// The scenario's `[study]`, checked against its regions.
fn study_config(scenario: &Scenario) -> Result<&StudyConfig> {
    let scenario_err = |message: String| Error::Scenario {
        origin: scenario.origin.clone(),
        message,
    };
    let config = scenario
        .study
        .as_ref()
        .ok_or_else(|| scenario_err("no [study] section: nothing to sweep".into()))?;
    config
        .validate(&scenario.regions)
        .map_err(|message| scenario_err(format!("study.{message}")))?;
    Ok(config)
}
