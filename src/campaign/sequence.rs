//! The measured sequence: the arm visits its commands one after the other and the tracker measures each
//! stop. A planned campaign ([`Generator::run`]) and a replayed real one ([`Generator::replay`]) both end
//! here, so whatever makes the true arm depend on its place in the sequence applies to both alike.

use std::collections::BTreeMap;

use rayon::prelude::*;

use super::generator::{Generator, Unloaded};
use super::points::{Campaign, CampaignPoint, Rejections, Visited};
use crate::error::{Error, Result};
use crate::rng::{Stream, derive};
use crate::robot::Chain;
use crate::robot::kinematics::forward_kinematics;
use crate::truth::{TrueState, history};

/// A replayed campaign draws its noise with this as the attempt index: above the planned campaigns' attempts
/// and the ground-truth sets' (`GROUND_TRUTH_ATTEMPT + set`), so it never shares their streams. A simulated
/// 6-DoF probe's orientation noise draws with the next one.
pub const REPLAY_ATTEMPT: u64 = 1 << 33;

/// One stop of the arm's visit sequence.
#[derive(Clone, Debug, PartialEq)]
pub struct Stop {
    /// The region (or replayed file) the point belongs to, for `measurements.csv`.
    pub region: String,
    /// Commanded joint angles (rad).
    pub q_cmd: Vec<f64>,
    /// The indices the visit's repeatability and tracker noise derive from, with the generator's seed:
    /// (region, attempt, candidate) for a planned point, so that a point draws the same whatever else the
    /// campaign measures; (replay, [`REPLAY_ATTEMPT`], row) for a replayed one.
    pub stream: [u64; 3],
}

impl Generator<'_> {
    /// Measures `stops` in their order, as the sequence the arm visits from the campaign's posture: each stop's
    /// history (the direction each joint came from, the links' temperature at its place in the sequence;
    /// [`history::sequence`]), the true arm reaching the command (zero offsets, transmission error, lost motion,
    /// thermal growth, static deflection, repeatability), and the tracker measuring its reflectors. No
    /// feasibility is checked here: a planned campaign chose its stops by their feasibility, and a replayed one
    /// was measured. Points are numbered from 0 in visit order.
    pub fn measure_sequence(&self, stops: &[Stop]) -> Result<Vec<CampaignPoint>> {
        self.measure_sequence_at(stops, Some(0.0))
    }

    /// [`Generator::measure_sequence`] begun `start_s` seconds into the true robot's warm-up (`None`: the arm
    /// warm, [`history::sequence_at`]).
    pub fn measure_sequence_at(
        &self,
        stops: &[Stop],
        start_s: Option<f64>,
    ) -> Result<Vec<CampaignPoint>> {
        let robot = &self.world.robot;
        let dof = self.world.nominal.dof();
        if let Some((k, v)) = stops
            .iter()
            .enumerate()
            .find(|(_, v)| v.q_cmd.len() != dof || v.q_cmd.iter().any(|q| !q.is_finite()))
        {
            return Err(Error::Invalid(format!(
                "visit {k}: the command {:?} must hold {dof} finite joint angles",
                v.q_cmd
            )));
        }
        let posture = self.config.posture_rad();
        let histories = history::sequence_at(
            &robot.perturbation,
            &posture,
            stops.iter().map(|s| s.q_cmd.as_slice()),
            start_s,
        );
        let unloaded: Vec<Unloaded> = stops
            .par_iter()
            .zip(&histories)
            .map_init(
                || TrueState::new(robot),
                |state, (stop, history)| Some(self.unloaded(&stop.q_cmd, history, state)),
            )
            .collect();
        let settled = self.deflect_all(&unloaded)?;
        Ok(stops
            .par_iter()
            .zip(settled)
            .zip(&histories)
            .enumerate()
            .map_init(
                || self.work(),
                |work, (k, ((stop, settled), history))| {
                    let (settled, scale) = settled.expect("every stop has unloaded angles");
                    let mut rng = derive(self.seed, Stream::Measurement, &stop.stream);
                    // Repeatability first, then the tracker, from one stream: the order the feasibility
                    // check of a planned point draws in, so the check saw the pose measured here.
                    robot.reach_with_angles(&settled, scale, Some(&mut rng), &mut work.state);
                    let true_flange = work.state.frames.flange;
                    forward_kinematics(&self.world.nominal, &stop.q_cmd, &mut work.frames);
                    let visited = Visited {
                        id: k,
                        region: stop.region.clone(),
                        q_cmd: stop.q_cmd.clone(),
                        nominal_flange: work.frames.flange,
                        true_flange,
                        q_true: work.state.q.clone(),
                    };
                    CampaignPoint {
                        temperature: history.temperature,
                        ..CampaignPoint::measured(self.world, visited, &mut rng)
                    }
                },
            )
            .collect())
    }

    /// A real campaign's commands measured in this world, in their order, as region `region`: no layout, no
    /// inverse kinematics and no feasibility check — the real tracker measured these points, so they are
    /// measured even where the simulated acceptance cone, line of sight or an obstacle would refuse them. A
    /// command outside the robot's joint limits (or with the wrong number of angles) is an error naming its
    /// row of `origin` as a spreadsheet numbers it (the header is row 1) and its point id `ids[k]`. `replay`
    /// numbers the replay, so that several replays in one world (the series of a data set) draw independent
    /// noise.
    pub fn replay(
        &self,
        replay: u64,
        origin: &str,
        region: &str,
        ids: &[String],
        commands: &[Vec<f64>],
    ) -> Result<Campaign> {
        let chain = &self.world.nominal;
        check_replayable(chain, origin, ids, commands)?;
        let stops: Vec<Stop> = commands
            .iter()
            .enumerate()
            .map(|(k, q)| Stop {
                region: region.to_string(),
                q_cmd: q.clone(),
                stream: [replay, REPLAY_ATTEMPT, k as u64],
            })
            .collect();
        let n = stops.len();
        Ok(Campaign {
            joint_names: chain.joint_names(),
            points: self.measure_sequence(&stops)?,
            rejections: BTreeMap::from([(
                region.to_string(),
                Rejections {
                    candidates: n,
                    feasible: n,
                    used: n,
                    ..Rejections::default()
                },
            )]),
        })
    }
}

/// Whether `commands` (rows `ids` of `origin`) can be replayed on `chain`: at least one, each with one angle per
/// joint, finite and within the joint's limits. The error names the first row that is not.
pub fn check_replayable(
    chain: &Chain,
    origin: &str,
    ids: &[String],
    commands: &[Vec<f64>],
) -> Result<()> {
    let err = |message: String| Error::Data {
        origin: origin.to_string(),
        message,
    };
    if ids.len() != commands.len() {
        return Err(err(format!(
            "{} row ids for {} commands",
            ids.len(),
            commands.len()
        )));
    }
    if commands.is_empty() {
        return Err(err("no rows to replay".into()));
    }
    for (k, (id, q)) in ids.iter().zip(commands).enumerate() {
        let row = if *id == (k + 2).to_string() {
            format!("row {id}")
        } else {
            format!("row {} (point_id {id})", k + 2)
        };
        if q.len() != chain.dof() {
            return Err(err(format!(
                "{row}: {} joint angles, the robot has {} joints",
                q.len(),
                chain.dof()
            )));
        }
        for (joint, &v) in chain.joints.iter().zip(q) {
            if !(v.is_finite() && joint.within_limits(v)) {
                return Err(err(format!(
                    "{row}: joint {} = {v} is outside its limits [{}, {}] (URDF); a replay \
                         measures every row, so a file the robot cannot have measured is refused",
                    joint.name, joint.lower, joint.upper
                )));
            }
        }
    }
    Ok(())
}
