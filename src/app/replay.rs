//! Replaying a real campaign in a scenario's world: the file's joint configurations, in its order, measured by
//! the simulated robot and tracker ([`crate::campaign::Generator::replay`]), with the tracker standing where the
//! real one stood and the reflector (or probe) where the real one sat on the flange.
//!
//! Where they stood comes from registering the real data on the nominal robot (`calib::tracker_frame`, the
//! registration every method starts from): the tracker frame becomes the simulated tracker's pose (as position,
//! yaw and tilts, an exact Euler decomposition), and the registered point on the flange becomes the reflector's
//! nominal position; the scenario's mounting error still draws the true one about it. The scenario's tracker
//! noise, and everything of the true robot, stay the scenario's.

use std::path::Path;

use nalgebra::UnitQuaternion;

use crate::calib::tracker_frame::Registration;
use crate::campaign::Campaign;
use crate::campaign::sequence::{REPLAY_ATTEMPT, check_replayable};
use crate::campaign::{Generator, Simulation};
use crate::dataset::Dataset;
use crate::dataset::mapping::ColumnMapping;
use crate::error::{Error, Result};
use crate::rng::Stream;
use crate::robot::Chain;
use crate::robot::dh::DhChain;
use crate::scenario::Scenario;
use crate::world::World;

/// The region name of a replayed campaign's points in `measurements.csv`.
pub const REGION: &str = "replay";

/// A real campaign replayed in a scenario's world.
pub struct Replay {
    /// Which replay of the world this is.
    pub index: u64,
    pub sim: Simulation,
    /// The registration of the real data on the nominal robot, which placed the tracker and the reflector.
    pub registration: Registration,
    /// The angle (rad) between the registered tracker rotation and the one the scenario's yaw and tilt fields
    /// give back: the round-off of the decomposition.
    pub placement_residual_rad: f64,
}

/// Reads a campaign file: through `mapping` (a foreign export, as `calibrate --mapping` reads it), or as a
/// `measurements.csv`.
pub fn read(chain: &Chain, file: &Path, mapping: Option<&Path>) -> Result<Dataset> {
    match mapping {
        Some(m) => ColumnMapping::load(m)?.read(file, chain),
        None => Dataset::read(file, &chain.joint_names()),
    }
}

/// Registers `data` on the scenario's nominal robot, moves the scenario's tracker and reflector there (so the
/// scenario written to `campaign.json` says where they stood), and measures `data`'s configurations in order.
/// `index` numbers the replay among several in the same world (independent noise).
pub fn replay(scenario: &mut Scenario, data: &Dataset, index: u64) -> Result<Replay> {
    let chain = scenario.load_robot()?;
    check_replayable(&chain, &data.origin, &data.point_ids, &data.q)?;
    let dh = DhChain::from_chain(&chain)?;
    let registration =
        Registration::fit(&dh, data, &data.subset(&[])).map_err(|e| Error::Data {
            origin: data.origin.clone(),
            message: format!(
                "cannot register the data to place the tracker: {}",
                e.detail()
            ),
        })?;
    let (tracker, placement_residual_rad) = scenario
        .world
        .tracker
        .placed_at(&registration.frame.tracker_to_base);
    scenario.world.tracker = tracker;
    let mounting = registration.frame.mounting;
    scenario.world.reflectors.nominal_m = match &registration.nest {
        Some(nest) => nest
            .iter()
            .map(|p| (p.coords + mounting.coords).into())
            .collect(),
        None => vec![mounting.coords.into()],
    };
    scenario
        .world
        .reflectors
        .validate()
        .map_err(|m| Error::Data {
            origin: data.origin.clone(),
            message: format!("the registered reflectors: {m}"),
        })?;
    let world = World::new(chain, scenario.world.clone())?;
    let campaign = Generator {
        world: &world,
        config: &scenario.campaign,
        seed: world.seed(),
        selector: None,
    }
    .replay(index, &data.origin, REGION, &data.point_ids, &data.q)?;
    Ok(Replay {
        index,
        sim: Simulation { world, campaign },
        registration,
        placement_residual_rad,
    })
}

/// The replayed campaign as the same kind of [`Dataset`] as the real `data` it replays: the same rows, ids,
/// columns and extra inputs (the temperature is the simulated one when the true robot has a warm-up profile,
/// put in place of the real file's `temperature` input; otherwise
/// the real one is passed through), the
/// tracker measurements from the simulation, and, when `data` measured a 6-DoF probe's orientation, the
/// simulated probe's (the registered probe rotation on the true flange, with the tracker's orientation noise).
pub fn as_dataset(replay: &Replay, data: &Dataset) -> Result<Dataset> {
    let Simulation { world, campaign } = &replay.sim;
    if campaign.points.len() != data.len() {
        return Err(Error::Invalid(format!(
            "{} replayed points for the {} rows of {}",
            campaign.points.len(),
            data.len(),
            data.origin
        )));
    }
    let mut sim = data.clone();
    sim.origin = format!("{} (replayed in '{}')", data.origin, world.config.name);
    sim.measured = campaign.points.iter().map(|p| p.measured.clone()).collect();
    let simulated: Option<Vec<f64>> = campaign.points.iter().map(|p| p.temperature).collect();
    if let Some(temperature) = simulated {
        let name = crate::dataset::TEMPERATURE_COLUMN;
        let x = sim
            .extra_inputs
            .get_or_insert_with(|| crate::dataset::ExtraInputs {
                names: Vec::new(),
                values: vec![Vec::new(); temperature.len()],
            });
        let column = x.names.iter().position(|n| n == name).unwrap_or_else(|| {
            x.names.push(name.to_string());
            x.values.iter_mut().for_each(|row| row.push(0.0));
            x.names.len() - 1
        });
        for (row, t) in x.values.iter_mut().zip(temperature) {
            row[column] = t;
        }
    }
    if data.measured_orientation.is_some() {
        sim.measured_orientation = Some(probe_orientations(replay, campaign)?);
    }
    Ok(sim)
}

fn probe_orientations(replay: &Replay, campaign: &Campaign) -> Result<Vec<UnitQuaternion<f64>>> {
    let probe = replay.registration.probe_rotation.ok_or_else(|| {
        Error::Invalid("the registration has no probe rotation to simulate".into())
    })?;
    let world = &replay.sim.world;
    Ok(campaign
        .points
        .iter()
        .enumerate()
        .map(|(k, p)| {
            // Its own stream: the positions' stays as a campaign without a probe draws it.
            let mut rng = world.rng(
                Stream::Measurement,
                &[replay.index, REPLAY_ATTEMPT + 1, k as u64],
            );
            world
                .tracker
                .measure_orientation(&(p.true_flange.rotation * probe), &mut rng)
        })
        .collect())
}
