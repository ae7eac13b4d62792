//! A simulated measurement campaign: targets in each region, inverse kinematics on the nominal model (what
//! the controller does), feasibility, then the true robot reaching each command and the tracker measuring it.
//!
//! Every candidate point draws from its own generator, derived from (seed, region, attempt, index), so the
//! work runs in parallel and the result is the same whatever the thread count.

use std::collections::BTreeMap;

use nalgebra::{Isometry3, Point3};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::Serialize;

use super::region::{CampaignConfig, RegionConfig};
use super::sequence::Stop;
use crate::error::{Error, Result};
use crate::rng::{Stream, derive};
use crate::robot::JointRates;
use crate::robot::collision::CollisionModel;
use crate::robot::ik::{IkError, IkOptions, IkSolver};
use crate::robot::kinematics::{Frames, forward_kinematics};
use crate::truth::physics::SettleOptions;
use crate::truth::robot::Deflection;
use crate::truth::{DeflectionSolver, TrueState, Visit};
use crate::world::World;

/// The last millimetres of a beam lie inside the reflector's own mount, which must not count as blocking.
pub(super) const BEAM_END_CLEARANCE_M: f64 = 0.005;
/// Retries with more candidates when too few are feasible; the candidate count never exceeds this multiple.
const MAX_ATTEMPTS: u64 = 5;
const MAX_CANDIDATE_FACTOR: usize = 50;

/// Generates campaigns in a world: its robots, tracker and mounting, the campaign's own configuration, the seed
/// its draws derive from (the world's, or one per campaign of a study), and the selector that chooses the points
/// of a model-based layout.
pub struct Generator<'a> {
    pub world: &'a World,
    pub config: &'a CampaignConfig,
    pub seed: u64,
    /// Chooses the points of a model-based layout (`d-optimal`) from its feasible pool; a campaign with such a
    /// layout and no selector is refused.
    pub selector: Option<&'a dyn Selector>,
}

/// Chooses the points of a model-based layout from a pool of feasible candidates. Experiment design
/// ([`crate::design`]) implements it for the model being fitted; the campaign only plans and measures the pool.
pub trait Selector: Sync {
    /// Indices of `want` of the candidates' commanded joint angles `pool`, in any order.
    fn choose(&self, pool: &[&[f64]], want: usize) -> Result<Vec<usize>>;
}

/// One measured point, with what the simulation knows about it.
#[derive(Clone, Debug)]
pub struct CampaignPoint {
    pub id: usize,
    pub region: String,
    /// Commanded joint angles (rad).
    pub q_cmd: Vec<f64>,
    /// The controller's flange pose for the command (nominal kinematics), base frame.
    pub nominal_flange: Isometry3<f64>,
    /// Reflectors from nominal kinematics and nominal mounting, base frame.
    pub nominal_reflectors: Vec<Point3<f64>>,
    /// Tracker measurements of each reflector, in the tracker's frame.
    pub measured: Vec<Point3<f64>>,
    /// The pose the true arm reached for this measurement (repeatability noise included), base frame.
    pub true_flange: Isometry3<f64>,
    pub true_reflectors: Vec<Point3<f64>>,
    /// The true reflector positions in the tracker's frame, without tracker noise: what a perfect tracker would
    /// have measured. The evaluation maps them through the calibration's own registration.
    pub true_in_tracker: Vec<Point3<f64>>,
    /// Link-side joint angles of the true arm (deflected, with noise).
    pub q_true: Vec<f64>,
    /// Temperature of the links when the point was measured (°C), when the true robot has a thermal profile.
    pub temperature: Option<f64>,
    /// The tracker's time stamp of a sample measured on the fly (s; [`super::trajectory`]); `None` stop and go.
    pub time: Option<f64>,
    /// The controller's commanded joint velocities and accelerations logged with a sample measured on the fly.
    pub rates: Option<JointRates>,
}

/// Where a point was commanded and where the true arm really was: what [`CampaignPoint::measured`] needs.
pub struct Visited {
    pub id: usize,
    pub region: String,
    /// The logged joint angles and the flange pose the nominal model gives them.
    pub q_cmd: Vec<f64>,
    pub nominal_flange: Isometry3<f64>,
    /// The true arm's flange pose and link-side joint angles.
    pub true_flange: Isometry3<f64>,
    pub q_true: Vec<f64>,
}

impl CampaignPoint {
    /// The point `visited` as the tracker measures it in `world`, its noise drawn from `rng` (one draw per
    /// reflector, in order). Temperature, time and rates are `None`, for the caller to set.
    pub fn measured(world: &World, visited: Visited, rng: &mut ChaCha8Rng) -> CampaignPoint {
        let true_reflectors: Vec<Point3<f64>> = world
            .mounting
            .actual
            .iter()
            .map(|p| visited.true_flange * p)
            .collect();
        let measured = true_reflectors
            .iter()
            .map(|p| world.tracker.measure(p, rng))
            .collect();
        CampaignPoint {
            id: visited.id,
            region: visited.region,
            q_cmd: visited.q_cmd,
            nominal_flange: visited.nominal_flange,
            nominal_reflectors: world
                .mounting
                .nominal
                .iter()
                .map(|p| visited.nominal_flange * p)
                .collect(),
            measured,
            true_flange: visited.true_flange,
            true_in_tracker: true_reflectors
                .iter()
                .map(|p| world.tracker.pose.inverse_transform_point(p))
                .collect(),
            true_reflectors,
            q_true: visited.q_true,
            temperature: None,
            time: None,
            rates: None,
        }
    }
}

/// A point of a noise-free ground-truth set ([`Generator::ground_truth`]): where the true arm really is for a
/// command, in the world frame, with neither repeatability nor tracker noise.
#[derive(Clone, Debug)]
pub struct TruePoint {
    pub region: String,
    /// Commanded joint angles (rad): the nominal inverse kinematics of the target.
    pub q_cmd: Vec<f64>,
    /// The target flange pose, which the nominal model reaches at `q_cmd` (world frame).
    pub nominal_flange: Isometry3<f64>,
    /// The flange pose the true arm reaches at `q_cmd`, noise-free (world frame).
    pub true_flange: Isometry3<f64>,
    /// The true reflector positions there (world frame).
    pub true_reflectors: Vec<Point3<f64>>,
}

/// Ground-truth sets draw their layouts and targets with this added to the attempt index, far above the
/// campaign's attempts (< `MAX_ATTEMPTS`), so they never share a random stream with the measured points.
pub const GROUND_TRUTH_ATTEMPT: u64 = 1 << 32;

/// Why a candidate target did not become a measured point.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Reason {
    OutOfReach,
    JointLimits,
    SelfCollision,
    EnvironmentCollision,
    LineOfSight,
    AcceptanceCone,
}

/// Candidate counts of one region, by outcome.
#[derive(Clone, Debug, Default, Serialize, PartialEq, Eq)]
pub struct Rejections {
    pub candidates: usize,
    pub feasible: usize,
    pub used: usize,
    pub out_of_reach: usize,
    pub joint_limits: usize,
    pub self_collision: usize,
    pub environment_collision: usize,
    pub line_of_sight: usize,
    pub acceptance_cone: usize,
}

impl Rejections {
    fn count(&mut self, reason: Reason) {
        let slot = match reason {
            Reason::OutOfReach => &mut self.out_of_reach,
            Reason::JointLimits => &mut self.joint_limits,
            Reason::SelfCollision => &mut self.self_collision,
            Reason::EnvironmentCollision => &mut self.environment_collision,
            Reason::LineOfSight => &mut self.line_of_sight,
            Reason::AcceptanceCone => &mut self.acceptance_cone,
        };
        *slot += 1;
    }

    fn describe(&self) -> String {
        format!(
            "{} out of reach, {} at joint limits, {} in self-collision, {} hitting an obstacle, \
             {} with the beam blocked, {} outside the reflector's acceptance cone",
            self.out_of_reach,
            self.joint_limits,
            self.self_collision,
            self.environment_collision,
            self.line_of_sight,
            self.acceptance_cone
        )
    }
}

#[derive(Clone, Debug)]
pub struct Campaign {
    pub joint_names: Vec<String>,
    pub points: Vec<CampaignPoint>,
    /// Per region, in scenario order.
    pub rejections: BTreeMap<String, Rejections>,
}

/// Unloaded angles and link-length factor of a command, for the deflection solvers.
pub(super) type Unloaded = Option<(Vec<f64>, f64)>;
/// The settled arm and its link-length factor.
pub(super) type Settled = Option<(Deflection, f64)>;

/// A command the controller would send: the first half of a candidate's life.
pub(super) struct Planned {
    pub(super) q_cmd: Vec<f64>,
    pub(super) nominal_flange: Isometry3<f64>,
}

/// Per-thread workspaces.
pub(super) struct Work {
    ik: IkSolver,
    pub(super) frames: Frames,
    pub(super) state: TrueState,
}

/// The points of one region and its candidate counts.
pub(super) type RegionPoints = (Vec<Stop>, Rejections);
impl Generator<'_> {
    /// Generates the campaign over all regions; points are numbered from 0 in region order, which is the order
    /// the arm visits them in. Each region's layout, inverse kinematics and feasibility choose its points; the
    /// chosen commands are then measured as one sequence ([`Generator::measure_sequence`]), the path a replayed
    /// real campaign takes too.
    pub fn run(&self, regions: &[RegionConfig]) -> Result<Campaign> {
        let collision = CollisionModel::new(&self.world.nominal);
        let mut visits = Vec::new();
        let mut rejections = BTreeMap::new();
        for (r, region) in regions.iter().enumerate() {
            let (region_visits, counts) = self.region(r as u64, region, &collision)?;
            visits.extend(region_visits);
            rejections.insert(region.name.clone(), counts);
        }
        Ok(Campaign {
            joint_names: self.world.nominal.joint_names(),
            points: self.measure_sequence(&visits)?,
            rejections,
        })
    }

    fn region(
        &self,
        r: u64,
        region: &RegionConfig,
        collision: &CollisionModel,
    ) -> Result<(Vec<Stop>, Rejections)> {
        let selectors: Vec<&dyn Selector> = self.selector.into_iter().collect();
        self.region_for(r, region, collision, &selectors)?.remove(0)
    }

    /// The points of one region: for a model-based layout, one choice per selector from the shared pool (an
    /// error when there is none); otherwise one set.
    pub(super) fn region_for(
        &self,
        r: u64,
        region: &RegionConfig,
        collision: &CollisionModel,
        selectors: &[&dyn Selector],
    ) -> Result<Vec<Result<RegionPoints>>> {
        let anchor = self.anchor(region)?;
        let want = region.points;
        let selects = region.distribution.selects();
        let mut candidates = if selects {
            self.config.selection.pool(want)
        } else {
            want
        };
        let mut last = Rejections::default();
        for attempt in 0..MAX_ATTEMPTS {
            let layout = region.distribution.build();
            let unit = layout.sample(
                candidates,
                region.size_m,
                &mut derive(self.seed, Stream::Layout, &[r, attempt]),
            );
            let (mut accepted, counts) =
                self.candidates(r, attempt, region, &anchor, &unit, collision)?;
            last = counts;
            if accepted.len() >= want && selects {
                if selectors.is_empty() {
                    return Err(Error::Invalid(format!(
                        "region '{}': layout '{}' chooses its points for a model, and no model was given",
                        region.name,
                        region.distribution.name()
                    )));
                }
                return Ok(selectors
                    .iter()
                    .map(|selector| {
                        let kept = self.select(region, *selector, &accepted, want)?;
                        let mut counts = last.clone();
                        counts.used = kept.len();
                        Ok((kept, counts))
                    })
                    .collect());
            }
            if accepted.len() >= want {
                let k = accepted.len();
                // Thin evenly in layout order, so a grid stays a grid and a low-discrepancy set stays spread.
                let keep: Vec<usize> = (0..want).map(|i| i * k / want).collect();
                let mut kept = Vec::with_capacity(want);
                for (i, p) in accepted.drain(..).enumerate() {
                    if keep.binary_search(&i).is_ok() {
                        kept.push(p);
                    }
                }
                last.used = kept.len();
                return Ok(vec![Ok((kept, last))]);
            }
            let rate = accepted.len() as f64 / unit.len().max(1) as f64;
            if accepted.is_empty() && unit.len() >= 4 * want {
                break;
            }
            let goal = if selects { candidates } else { want };
            let next = (goal as f64 / rate.max(0.02) * 1.25).ceil() as usize;
            candidates = next.max(2 * unit.len()).min(MAX_CANDIDATE_FACTOR * want);
            if unit.len() >= MAX_CANDIDATE_FACTOR * want {
                break;
            }
        }
        let what = if last.feasible == 0 {
            "no point is feasible"
        } else {
            "too few points are feasible"
        };
        Err(Error::Unreachable(format!(
            "region '{}': {what} ({} of {} wanted, from {} candidates: {})",
            region.name,
            last.feasible,
            want,
            last.candidates,
            last.describe()
        )))
    }

    /// The `want` feasible points of `pool` that `selector` chooses, in pool order.
    fn select(
        &self,
        region: &RegionConfig,
        selector: &dyn Selector,
        pool: &[Stop],
        want: usize,
    ) -> Result<Vec<Stop>> {
        let commands: Vec<&[f64]> = pool.iter().map(|p| p.q_cmd.as_slice()).collect();
        let mut chosen = selector
            .choose(&commands, want)
            .map_err(|e| Error::Unreachable(format!("region '{}': {}", region.name, e.detail())))?;
        chosen.sort_unstable();
        chosen.dedup();
        Ok(chosen
            .into_iter()
            .filter_map(|i| pool.get(i).cloned())
            .collect())
    }

    /// The feasible candidates of one attempt, as the visits that would measure them, in layout order.
    fn candidates(
        &self,
        r: u64,
        attempt: u64,
        region: &RegionConfig,
        anchor: &[f64],
        unit: &[[f64; 3]],
        collision: &CollisionModel,
    ) -> Result<(Vec<Stop>, Rejections)> {
        let planned = self.plan_all(r, attempt, region, anchor, unit, collision);

        let deflected = self.deflect_planned(&planned, |_| Visit::default())?;

        let outcomes: Vec<std::result::Result<Stop, Reason>> = planned
            .into_par_iter()
            .zip(deflected.into_par_iter())
            .enumerate()
            .map_init(
                || self.work(),
                |work, (i, (plan, settled))| {
                    let plan = plan?;
                    let (settled, scale) =
                        settled.expect("a planned command always has a deflection");
                    let stream = [r, attempt, i as u64];
                    self.visible(stream, &settled, scale, collision, work)?;
                    Ok(Stop {
                        region: region.name.clone(),
                        q_cmd: plan.q_cmd,
                        stream,
                    })
                },
            )
            .collect();

        let mut counts = Rejections {
            candidates: unit.len(),
            ..Rejections::default()
        };
        let mut accepted = Vec::new();
        for outcome in outcomes {
            match outcome {
                Ok(p) => accepted.push(p),
                Err(reason) => counts.count(reason),
            }
        }
        counts.feasible = accepted.len();
        Ok((accepted, counts))
    }

    /// A noise-free ground-truth set in `region` (index `r` in the scenario) at the layout points `unit` (unit-cube
    /// coordinates of the region's box; values outside [0, 1] lie outside the box). Targets, nominal inverse
    /// kinematics and the arm's feasibility (joint limits, self-collision, obstacles) are as in a campaign; the
    /// tracker is not involved (no line of sight, no acceptance cone, no measurement noise) and the arm does not
    /// scatter (no repeatability). The deflection is the scenario's solver. Infeasible targets are dropped and
    /// counted. `set` numbers the set, so different sets (and the campaign) draw independent orientations.
    pub fn ground_truth(
        &self,
        r: u64,
        set: u64,
        region: &RegionConfig,
        unit: &[[f64; 3]],
    ) -> Result<(Vec<TruePoint>, Rejections)> {
        let collision = CollisionModel::new(&self.world.nominal);
        let anchor = self.anchor(region)?;
        let attempt = GROUND_TRUTH_ATTEMPT + set;
        // Ground truth is where the arm is used, with the campaign's own redundancy resolution, not a
        // model-based pool's.
        let region = &RegionConfig {
            distribution: super::DistributionKind::Uniform,
            ..region.clone()
        };
        let planned = self.plan_all(r, attempt, region, &anchor, unit, &collision);
        // Each evaluation pose is approached from the campaign's posture, at the end of the warm-up.
        let robot = &self.world.robot;
        let deflected = self.deflect_planned(&planned, |q| robot.evaluation_visit(q))?;
        let mut counts = Rejections {
            candidates: unit.len(),
            ..Rejections::default()
        };
        let mut points = Vec::new();
        let mut state = TrueState::new(&self.world.robot);
        for (plan, q_link) in planned.into_iter().zip(deflected) {
            match (plan, q_link) {
                (Ok(plan), Some((settled, scale))) => {
                    self.world
                        .robot
                        .reach_with_angles(&settled, scale, None, &mut state);
                    let true_flange = state.frames.flange;
                    points.push(TruePoint {
                        region: region.name.clone(),
                        q_cmd: plan.q_cmd,
                        nominal_flange: plan.nominal_flange,
                        true_flange,
                        true_reflectors: self
                            .world
                            .mounting
                            .actual
                            .iter()
                            .map(|p| true_flange * p)
                            .collect(),
                    });
                }
                (Err(reason), _) => counts.count(reason),
                (Ok(_), None) => {
                    return Err(Error::Physics(
                        "ground truth: a planned command has no deflection".into(),
                    ));
                }
            }
        }
        counts.feasible = points.len();
        counts.used = points.len();
        Ok((points, counts))
    }

    /// A per-thread workspace of the planning and measuring steps.
    pub(super) fn work(&self) -> Work {
        Work {
            ik: IkSolver::new(&self.world.nominal, self.ik_options()),
            frames: Frames::new(&self.world.nominal),
            state: TrueState::new(&self.world.robot),
        }
    }

    /// [`Generator::plan`] for every layout point, in parallel, in layout order.
    fn plan_all(
        &self,
        r: u64,
        attempt: u64,
        region: &RegionConfig,
        anchor: &[f64],
        unit: &[[f64; 3]],
        collision: &CollisionModel,
    ) -> Vec<std::result::Result<Planned, Reason>> {
        unit.par_iter()
            .enumerate()
            .map_init(
                || self.work(),
                |work, (i, u)| self.plan(r, attempt, i as u64, region, anchor, u, collision, work),
            )
            .collect()
    }

    /// No random restarts: a restart may land on another branch (elbow, wrist flip), and a campaign that
    /// mixes branches is not what the scenario asked for. A target the solver cannot reach from the
    /// region's anchor counts as out of reach.
    fn ik_options(&self) -> IkOptions {
        IkOptions {
            limit_margin: self.config.limit_margin_deg.to_radians(),
            restarts: 0,
            ..IkOptions::default()
        }
    }

    /// The region's anchor: its centre at the nominal tool orientation, solved from the configured posture.
    /// Every target of the region starts from it and is drawn toward it in the null space, so the whole
    /// region stays on the branch the posture chose.
    fn anchor(&self, region: &RegionConfig) -> Result<Vec<f64>> {
        let posture = self.config.posture_rad();
        let centre = Isometry3::from_parts(
            Point3::from(region.center_m).coords.into(),
            region.nominal_rotation(),
        );
        let mut solver = IkSolver::new(
            &self.world.nominal,
            IkOptions {
                restarts: 0,
                ..self.ik_options()
            },
        );
        let mut rng = derive(self.seed, Stream::Target, &[u64::MAX]);
        solver
            .solve(&self.world.nominal, &centre, &Isometry3::identity(), &posture, Some(&posture), &mut rng)
            .map(|s| s.q)
            .map_err(|e| {
                Error::Unreachable(format!(
                    "region '{}': its centre at the nominal tool orientation cannot be reached from \
                     campaign.posture_deg ({e})",
                    region.name
                ))
            })
    }

    #[allow(clippy::too_many_arguments)]
    fn plan(
        &self,
        r: u64,
        attempt: u64,
        i: u64,
        region: &RegionConfig,
        anchor: &[f64],
        unit: &[f64; 3],
        collision: &CollisionModel,
        work: &mut Work,
    ) -> std::result::Result<Planned, Reason> {
        use rand::Rng;
        let mut rng = derive(self.seed, Stream::Target, &[r, attempt, i]);
        let target = region.target(unit, &mut rng);
        let spread = if region.distribution.selects() {
            self.config
                .posture_spread_deg
                .max(self.config.selection.posture_spread_deg)
        } else {
            self.config.posture_spread_deg
        }
        .to_radians();
        let pull: Vec<f64> = anchor
            .iter()
            .map(|p| {
                p + if spread > 0.0 {
                    rng.random_range(-spread..=spread)
                } else {
                    0.0
                }
            })
            .collect();
        let solution = work
            .ik
            .solve(
                &self.world.nominal,
                &target,
                &Isometry3::identity(),
                anchor,
                Some(&pull),
                &mut rng,
            )
            .map_err(|e| match e {
                IkError::NotConverged { .. } => Reason::OutOfReach,
                IkError::JointLimits => Reason::JointLimits,
            })?;
        forward_kinematics(&self.world.nominal, &solution.q, &mut work.frames);
        if collision.self_collision(&work.frames).is_some() {
            return Err(Reason::SelfCollision);
        }
        if self
            .config
            .obstacles
            .iter()
            .any(|o| collision.hits_obstacle(&work.frames, o).is_some())
        {
            return Err(Reason::EnvironmentCollision);
        }
        Ok(Planned {
            nominal_flange: work.frames.flange,
            q_cmd: solution.q,
        })
    }

    /// The static deflection of every planned command, each reached after the history `visit` gives it: fixed
    /// point in parallel, or the rapier reference.
    fn deflect_planned(
        &self,
        planned: &[std::result::Result<Planned, Reason>],
        visit: impl Fn(&[f64]) -> Visit + Sync,
    ) -> Result<Vec<Settled>> {
        let unloaded: Vec<Unloaded> = planned
            .par_iter()
            .map_init(
                || TrueState::new(&self.world.robot),
                |state, p| {
                    p.as_ref()
                        .ok()
                        .map(|p| self.unloaded(&p.q_cmd, &visit(&p.q_cmd), state))
                },
            )
            .collect();
        self.deflect_all(&unloaded)
    }

    pub(super) fn unloaded(
        &self,
        q_cmd: &[f64],
        visit: &Visit,
        state: &mut TrueState,
    ) -> (Vec<f64>, f64) {
        let robot = &self.world.robot;
        robot.unloaded_angles_after(q_cmd, visit, &mut state.q0);
        (state.q0.clone(), robot.length_scale(visit))
    }

    pub(super) fn deflect_all(&self, unloaded: &[Unloaded]) -> Result<Vec<Settled>> {
        match self.world.deflection() {
            DeflectionSolver::FixedPoint => unloaded
                .par_iter()
                .map_init(
                    || TrueState::new(&self.world.robot),
                    |state, u| {
                        u.as_ref()
                            .map(|(q0, scale)| {
                                state.q0.copy_from_slice(q0);
                                state.scale = *scale;
                                self.world
                                    .robot
                                    .deflect(state)
                                    .map(|_| (state.deflection(), *scale))
                            })
                            .transpose()
                    },
                )
                .collect(),
            DeflectionSolver::Rapier => {
                let mut physics = self
                    .world
                    .robot
                    .physics_reference(SettleOptions::default())?;
                unloaded
                    .iter()
                    .map(|u| {
                        u.as_ref()
                            .map(|(q0, scale)| {
                                physics.settle(q0).map(|s| {
                                    let settled = Deflection {
                                        q: s.q,
                                        tilt: Vec::new(),
                                    };
                                    (settled, *scale)
                                })
                            })
                            .transpose()
                    })
                    .collect()
            }
        }
    }

    /// Whether the tracker sees every reflector of the true arm `settled` (deflected link angles and tilts, links
    /// scaled by `scale`), with the
    /// repeatability draw of the visit keyed `stream` (the one its measurement will make): each reflector's
    /// acceptance cone faces the tracker, and no link blocks the beam.
    fn visible(
        &self,
        stream: [u64; 3],
        settled: &Deflection,
        scale: f64,
        collision: &CollisionModel,
        work: &mut Work,
    ) -> std::result::Result<(), Reason> {
        let mut rng = derive(self.seed, Stream::Measurement, &stream);
        self.world
            .robot
            .reach_with_angles(settled, scale, Some(&mut rng), &mut work.state);
        let true_flange = work.state.frames.flange;
        let origin = self.world.tracker.origin();
        let facing = true_flange.rotation * self.world.mounting.facing;
        for local in &self.world.mounting.actual {
            let p = true_flange * local;
            if !self.world.tracker.in_acceptance_cone(&p, &facing) {
                return Err(Reason::AcceptanceCone);
            }
            if collision.segment_blocked(&work.state.frames, &origin, &p, BEAM_END_CLEARANCE_M) {
                return Err(Reason::LineOfSight);
            }
        }
        Ok(())
    }
}
