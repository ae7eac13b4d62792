//! The simulated world, built once per scenario and handed to every stage that simulates: the nominal robot
//! (as the controller knows it, with its DH form), the true robot, the tracker, the reflector mounting, and
//! the seed every random stream derives from. A stage takes the world and its own configuration; nothing
//! downstream rebuilds the chain, its DH form or the true robot.

use std::path::PathBuf;

use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::error::Result;
use crate::rng::{Stream, derive};
use crate::robot::dh::DhChain;
use crate::robot::{Chain, Payload};
use crate::tracker::Tracker;
use crate::tracker::TrackerConfig;
use crate::tracker::reflector::{Mounting, ReflectorConfig};
use crate::truth::{DeflectionSolver, ErrorModel, Perturbation, TrueRobot};

/// The `[robot]` section of a scenario.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct RobotConfig {
    /// URDF path, relative to the working directory (or, failing that, to the scenario file's directory).
    pub urdf: PathBuf,
    /// Link that carries the reflectors; defaults to the chain's last link.
    #[serde(default)]
    pub flange_link: Option<String>,
    /// Mass carried on the flange (kg): the reflector nest, a tool.
    #[serde(default)]
    pub payload_kg: f64,
    /// Its centre of mass in the flange frame (m).
    #[serde(default)]
    pub payload_com_m: [f64; 3],
}

impl RobotConfig {
    pub fn payload(&self) -> Payload {
        Payload {
            mass: self.payload_kg,
            com: self.payload_com_m,
        }
    }
}

/// What a world is made of: the scenario's name, seed, robot, true errors, tracker and reflectors. Reports
/// describe the world from it.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct WorldConfig {
    /// Names the results directory and every report row.
    pub name: String,
    /// Every random draw derives from this seed.
    pub seed: u64,
    pub robot: RobotConfig,
    pub truth: ErrorModel,
    pub tracker: TrackerConfig,
    pub reflectors: ReflectorConfig,
}

/// The nominal and true robots, tracker and reflector mounting of a scenario. Every draw derives from the
/// seed, so every stage that is handed the world sees the same one.
pub struct World {
    pub config: WorldConfig,
    /// The nominal robot as its URDF describes it: what the controller believes.
    pub nominal: Chain,
    /// The same chain in DH form, for the error models of the paper's method.
    pub dh: DhChain,
    pub robot: TrueRobot,
    pub tracker: Tracker,
    pub mounting: Mounting,
}

impl World {
    /// The world of `config` on the nominal robot `nominal` (loaded and checked against the configuration by
    /// the caller, which knows where it came from).
    pub fn new(nominal: Chain, config: WorldConfig) -> Result<World> {
        let perturbation = Perturbation::sample(
            &config.truth,
            nominal.dof(),
            &mut derive(config.seed, Stream::Perturbation, &[]),
        )?;
        let robot = TrueRobot::new(&nominal, perturbation, config.robot.payload())?;
        let tracker = Tracker::new(config.tracker.clone())?;
        let mounting = Mounting::sample(
            &config.reflectors,
            &mut derive(config.seed, Stream::Mounting, &[]),
        )?;
        let dh = DhChain::from_chain(&nominal)?;
        Ok(World {
            config,
            nominal,
            dh,
            robot,
            tracker,
            mounting,
        })
    }

    /// The seed every random stream of the world's campaigns derives from.
    pub fn seed(&self) -> u64 {
        self.config.seed
    }

    /// A generator for `purpose` and `indices`, from the world's seed ([`derive`]).
    pub fn rng(&self, purpose: Stream, indices: &[u64]) -> ChaCha8Rng {
        derive(self.config.seed, purpose, indices)
    }

    /// The payload the user declares on the flange (for the gravity torques of the elastic methods).
    pub fn payload(&self) -> Payload {
        self.config.robot.payload()
    }

    /// How the true robot's static deflection is solved.
    pub fn deflection(&self) -> DeflectionSolver {
        self.config.truth.deflection
    }
}
