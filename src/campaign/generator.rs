//! The generator of a world's campaigns, and the steps every way of measuring shares: the per-thread workspaces
//! and the true arm settling (unloaded angles after the arm's history, then the static deflection). A planned
//! campaign ([`super::generate`]), a replayed one ([`super::sequence`]) and a ground-truth set
//! ([`super::ground_truth`]) are all built on these.

use rayon::prelude::*;

use super::config::CampaignConfig;
use crate::error::Result;
use crate::robot::ik::{IkOptions, IkSolver};
use crate::robot::kinematics::Frames;
use crate::truth::physics::SettleOptions;
use crate::truth::robot::Deflection;
use crate::truth::{DeflectionSolver, TrueState, Visit};
use crate::world::World;

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

/// Unloaded angles and link-length factor of a command, for the deflection solvers.
pub(super) type Unloaded = Option<(Vec<f64>, f64)>;
/// The settled arm and its link-length factor.
pub(super) type PreviousSettle = Option<(Deflection, f64)>;

/// Per-thread workspaces.
pub(super) struct Work {
    pub(super) ik: IkSolver,
    pub(super) frames: Frames,
    pub(super) state: TrueState,
}

impl Generator<'_> {
    /// A per-thread workspace of the planning and measuring steps.
    pub(super) fn work(&self) -> Work {
        Work {
            ik: IkSolver::new(&self.world.nominal, self.ik_options()),
            frames: Frames::new(&self.world.nominal),
            state: TrueState::new(&self.world.robot),
        }
    }

    /// No random restarts: a restart may land on another branch (elbow, wrist flip), and a campaign that
    /// mixes branches is not what the scenario asked for. A target the solver cannot reach from the
    /// region's anchor counts as out of reach.
    pub(super) fn ik_options(&self) -> IkOptions {
        IkOptions {
            limit_margin: self.config.limit_margin_deg.to_radians(),
            restarts: 0,
            ..IkOptions::default()
        }
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

    pub(super) fn deflect_all(&self, unloaded: &[Unloaded]) -> Result<Vec<PreviousSettle>> {
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
                                    .deflect_angles(state)
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
}
