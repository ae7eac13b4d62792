//! A simulated measurement campaign: targets in each region, inverse kinematics on the nominal model (what
//! the controller does), feasibility, then the true robot reaching each command and the tracker measuring it.
//!
//! Every candidate point draws from its own generator, derived from (seed, region, attempt, index), so the
//! work runs in parallel and the result is the same whatever the thread count.

use std::collections::BTreeMap;
use std::ops::Range;

use nalgebra::{Isometry3, Point3};
use rayon::prelude::*;

use super::generator::{Generator, PreviousSettle, Selector, Unloaded, Work};
use super::points::{BEAM_END_CLEARANCE_M, Campaign, Reason, Rejections};
use super::region::RegionConfig;
use super::sequence::Stop;
use crate::error::{Error, Result};
use crate::rng::{Stream, derive};
use crate::robot::collision::CollisionModel;
use crate::robot::ik::{IkError, IkOptions, IkSolver};
use crate::robot::kinematics::forward_kinematics;
use crate::truth::robot::Deflection;
use crate::truth::{TrueState, Visit};

/// Retries with more candidates when too few are feasible; the candidate count never exceeds this multiple.
const MAX_ATTEMPTS: u64 = 5;
const MAX_CANDIDATE_FACTOR: usize = 50;

/// A command the controller would send: the first half of a candidate's life.
pub(super) struct Planned {
    pub(super) q_cmd: Vec<f64>,
    pub(super) nominal_flange: Isometry3<f64>,
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
        let selects = region.layout.selects();
        let mut candidates = if selects {
            self.config.selection.pool(want)
        } else {
            want
        };
        let mut last = Rejections::default();
        for attempt in 0..MAX_ATTEMPTS {
            let layout = region.layout.build();
            let unit = layout.sample(
                candidates,
                region.size_m,
                &mut derive(self.seed, Stream::Layout, &[r, attempt]),
            );
            let goal = if selects { candidates } else { want };
            let last_try = attempt + 1 == MAX_ATTEMPTS || unit.len() >= MAX_CANDIDATE_FACTOR * want;
            let tried = Tried {
                r,
                attempt,
                region,
                anchor: &anchor,
                unit: &unit,
                collision,
            };
            let (accepted, counts) = match self.attempt(&tried, want, goal, last_try)? {
                Attempt::Done(accepted, counts) => (accepted, counts),
                Attempt::Failed(next, counts) => {
                    last = counts;
                    candidates = next;
                    continue;
                }
            };
            last = counts;
            if accepted.len() >= want && selects {
                if selectors.is_empty() {
                    return Err(Error::Invalid(format!(
                        "region '{}': layout '{}' chooses its points for a model, and no model was given",
                        region.name,
                        region.layout.name()
                    )));
                }
                // Each selector's choice is independent of the others': in parallel, in order.
                return Ok(selectors
                    .par_iter()
                    .map(|selector| {
                        let kept = self.select(region, *selector, &accepted, want)?;
                        let mut counts = last.clone();
                        counts.used = kept.len();
                        Ok((kept, counts))
                    })
                    .collect());
            }
            if accepted.len() >= want {
                let kept = thin_evenly(accepted, want);
                last.used = kept.len();
                return Ok(vec![Ok((kept, last))]);
            }
            if accepted.is_empty() && unit.len() >= 4 * want {
                break;
            }
            candidates = next_count(goal, accepted.len(), unit.len(), want);
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

    /// One attempt's candidates. When the attempt cannot succeed — it has no more candidates than points wanted —
    /// its first three quarters are judged first; if some were turned down (so it fails) and enough were
    /// feasible that the next attempt's size is fixed whatever the rest would give ([`next_count`] falls with
    /// the feasible share), the rest is never planned: `Failed` with that size and the partial counts, which
    /// nothing reads, since a later attempt follows (`last_try` false). Otherwise the whole attempt, as one pass.
    fn attempt(&self, t: &Tried, want: usize, goal: usize, last_try: bool) -> Result<Attempt> {
        let n = t.unit.len();
        let split = if !last_try && n <= want {
            (3 * n).div_ceil(4)
        } else {
            n
        };
        let (mut accepted, mut counts) = self.candidates(t, 0..split)?;
        if split < n {
            if let Some(next) = decided(goal, want, n, accepted.len(), split - accepted.len()) {
                return Ok(Attempt::Failed(next, counts));
            }
            let (rest, rest_counts) = self.candidates(t, split..n)?;
            accepted.extend(rest);
            counts.add(&rest_counts);
        }
        Ok(Attempt::Done(accepted, counts))
    }

    /// The feasible candidates among layout points `range` of one attempt, as the visits that would measure them,
    /// in layout order; the counts are of those points.
    fn candidates(&self, t: &Tried, range: Range<usize>) -> Result<(Vec<Stop>, Rejections)> {
        let (r, attempt, region, collision) = (t.r, t.attempt, t.region, t.collision);
        let first = range.start;
        let unit = &t.unit[range];
        let planned = self.plan_all(r, attempt, region, t.anchor, unit, first, collision);

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
                    let stream = [r, attempt, (first + i) as u64];
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

    /// [`Generator::plan`] for every layout point, in parallel, in layout order; `unit[0]` is the attempt's
    /// point `first`.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn plan_all(
        &self,
        r: u64,
        attempt: u64,
        region: &RegionConfig,
        anchor: &[f64],
        unit: &[[f64; 3]],
        first: usize,
        collision: &CollisionModel,
    ) -> Vec<std::result::Result<Planned, Reason>> {
        unit.par_iter()
            .enumerate()
            .map_init(
                || self.work(),
                |work, (i, u)| {
                    let i = (first + i) as u64;
                    self.plan(r, attempt, i, region, anchor, u, collision, work)
                },
            )
            .collect()
    }

    /// The region's anchor: its centre at the nominal tool orientation, solved from the configured posture.
    /// Every target of the region starts from it and is drawn toward it in the null space, so the whole
    /// region stays on the branch the posture chose.
    pub(super) fn anchor(&self, region: &RegionConfig) -> Result<Vec<f64>> {
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
        let spread = if region.layout.selects() {
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
    pub(super) fn deflect_planned(
        &self,
        planned: &[std::result::Result<Planned, Reason>],
        visit: impl Fn(&[f64]) -> Visit + Sync,
    ) -> Result<Vec<PreviousSettle>> {
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

/// One attempt of a region: its index, layout points and what planning them needs.
struct Tried<'a> {
    r: u64,
    attempt: u64,
    region: &'a RegionConfig,
    anchor: &'a [f64],
    unit: &'a [[f64; 3]],
    collision: &'a CollisionModel,
}

/// What an attempt gave: its feasible candidates and counts, or only that it fails, with the next attempt's
/// size.
enum Attempt {
    Done(Vec<Stop>, Rejections),
    Failed(usize, Rejections),
}

/// The next attempt's candidate count after one of `tried` candidates gave `feasible`, aiming at `goal` feasible
/// ones: more candidates the fewer were feasible (never fewer than twice as many as tried, at most
/// `MAX_CANDIDATE_FACTOR` times `want`). Never increasing in `feasible`: every rounding on the way is monotone.
fn next_count(goal: usize, feasible: usize, tried: usize, want: usize) -> usize {
    let rate = feasible as f64 / tried.max(1) as f64;
    let next = (goal as f64 / rate.max(0.02) * 1.25).ceil() as usize;
    next.max(2 * tried).min(MAX_CANDIDATE_FACTOR * want)
}

/// The next attempt's size when an attempt of `tried` candidates has already `feasible` feasible ones and
/// `turned_down` rejected ones, if the rest cannot change it: the attempt fails whatever the rest gives (fewer
/// than `want` feasible at most), keeps at least one, and [`next_count`] is the same at both ends of what the
/// feasible count can still be (so, it never increasing, in between).
fn decided(
    goal: usize,
    want: usize,
    tried: usize,
    feasible: usize,
    turned_down: usize,
) -> Option<usize> {
    let most = tried - turned_down;
    let next = next_count(goal, feasible, tried, want);
    (most < want && feasible > 0 && next == next_count(goal, most, tried, want)).then_some(next)
}

/// `want` of the feasible points `accepted` (at least that many), thinned evenly in layout order, so a grid stays
/// a grid and a low-discrepancy set stays spread.
fn thin_evenly(accepted: Vec<Stop>, want: usize) -> Vec<Stop> {
    let k = accepted.len();
    let keep: Vec<usize> = (0..want).map(|i| i * k / want).collect();
    let mut kept = Vec::with_capacity(want);
    for (i, p) in accepted.into_iter().enumerate() {
        if keep.binary_search(&i).is_ok() {
            kept.push(p);
        }
    }
    kept
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Wherever a partial attempt is taken as decided, every feasible count the whole attempt could have had
    /// fails it and sizes the next attempt alike; and the usual case (a tenth turned down, three quarters
    /// judged) is decided.
    #[test]
    fn a_decided_attempt_is_the_whole_attempt() {
        let (mut decided_cases, mut usual) = (0, 0);
        for want in [1_usize, 2, 5, 23, 45, 90, 188] {
            for goal in [want, 3 * want] {
                for tried in (want / 2).max(1)..=want {
                    let judged = (3 * tried).div_ceil(4);
                    for feasible in 0..=judged {
                        let Some(next) = decided(goal, want, tried, feasible, judged - feasible)
                        else {
                            continue;
                        };
                        decided_cases += 1;
                        for whole in feasible..=tried - (judged - feasible) {
                            assert!(whole < want && whole > 0);
                            assert_eq!(next_count(goal, whole, tried, want), next);
                        }
                    }
                }
            }
            let judged = (3 * want).div_ceil(4);
            let feasible = judged - judged.div_ceil(10);
            if want >= 23 && decided(want, want, want, feasible, judged - feasible).is_some() {
                usual += 1;
            }
        }
        // The decided branch is taken often enough for the checks above to mean something (557 cases).
        assert!(decided_cases > 500, "{decided_cases}");
        assert_eq!(usual, 4);
    }
}
