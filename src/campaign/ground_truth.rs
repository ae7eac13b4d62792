//! Noise-free ground-truth sets: where the true arm really is for the commands of a layout, planned as a campaign
//! plans its points, with no tracker and no scatter. The evaluation judges a calibration against them.

use nalgebra::{Isometry3, Point3};

use super::generator::Generator;
use super::layout::LayoutKind;
use super::points::Rejections;
use super::region::RegionConfig;
use crate::error::{Error, Result};
use crate::robot::collision::CollisionModel;
use crate::truth::TrueState;

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

impl Generator<'_> {
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
            layout: LayoutKind::Uniform,
            ..region.clone()
        };
        let planned = self.plan_all(r, attempt, region, &anchor, unit, 0, &collision);
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
}
