//! What a campaign is made of: its measured points, and per region the candidates it turned down and why. Every
//! other file of the campaign builds or reads these, so this one imports none of them.

use std::collections::BTreeMap;

use nalgebra::{Isometry3, Point3};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

use crate::robot::JointRates;
use crate::world::World;

/// The last millimetres of a beam lie inside the reflector's own mount, which must not count as blocking.
pub(super) const BEAM_END_CLEARANCE_M: f64 = 0.005;

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

/// Why a candidate target did not become a measured point.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Reason {
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
    pub(super) fn count(&mut self, reason: Reason) {
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

    /// Adds the counts of `other`, more candidates of the same attempt.
    pub(super) fn add(&mut self, other: &Rejections) {
        self.candidates += other.candidates;
        self.feasible += other.feasible;
        self.used += other.used;
        self.out_of_reach += other.out_of_reach;
        self.joint_limits += other.joint_limits;
        self.self_collision += other.self_collision;
        self.environment_collision += other.environment_collision;
        self.line_of_sight += other.line_of_sight;
        self.acceptance_cone += other.acceptance_cone;
    }

    pub(super) fn describe(&self) -> String {
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
