//! A campaign measured as the sequence the arm visits: each point's history (the direction each joint came
//! from, the temperature at its place in the sequence) is a function of the sequence, so a simulated campaign
//! and a replayed real one get it the same way.

use nalgebra::Point3;
use rayon::prelude::*;

use super::generate::{CampaignPoint, Generator, Planned, Unloaded, Work};
use crate::error::{Error, Result};
use crate::rng::{Stream, derive};
use crate::robot::kinematics::forward_kinematics;
use crate::truth::{TrueState, history};

impl Generator<'_> {
    /// Measures `points` (region name, commanded joint angles) in the order given, as the sequence the arm
    /// visits from the campaign's posture: each point's history (the direction each joint came from, the
    /// temperature at its place in the sequence; [`history::sequence`]), the deflection by the scenario's
    /// solver, repeatability and tracker noise from the point's place `k` in the sequence. No feasibility
    /// test: every point is measured (a replayed real campaign was measured). Point ids are the places.
    pub fn measure_sequence(&self, points: &[(String, Vec<f64>)]) -> Result<Vec<CampaignPoint>> {
        let robot = &self.world.robot;
        let dof = self.world.nominal.dof();
        if let Some(k) = points
            .iter()
            .position(|(_, q)| q.len() != dof || q.iter().any(|v| !v.is_finite()))
        {
            return Err(Error::Invalid(format!(
                "point {k} of the sequence: the command must hold {dof} finite joint angles"
            )));
        }
        let posture: Vec<f64> = self
            .config
            .posture_deg
            .iter()
            .map(|d| d.to_radians())
            .collect();
        let visits = history::sequence(
            &robot.perturbation,
            &posture,
            points.iter().map(|(_, q)| q.as_slice()),
        );
        let unloaded: Vec<Unloaded> = points
            .par_iter()
            .zip(&visits)
            .map_init(
                || TrueState::new(robot),
                |state, ((_, q), visit)| Some(self.unloaded(q, visit, state)),
            )
            .collect();
        let settled = self.deflect_all(&unloaded)?;
        Ok(points
            .par_iter()
            .zip(settled.into_par_iter())
            .zip(&visits)
            .enumerate()
            .map_init(
                || self.work(),
                |work, (k, (((region, q), settled), visit))| {
                    let (settled, scale) = settled.expect("every command has a deflection");
                    let mut rng = derive(self.seed, Stream::Sequence, &[k as u64]);
                    robot.reach_with_angles(&settled, scale, Some(&mut rng), &mut work.state);
                    forward_kinematics(&self.world.nominal, q, &mut work.frames);
                    let plan = Planned {
                        q_cmd: q.clone(),
                        nominal_flange: work.frames.flange,
                    };
                    let true_reflectors = self.true_reflectors(work);
                    let mut point = self.record(region, plan, true_reflectors, &mut rng, work);
                    point.id = k;
                    point.temperature = visit.temperature;
                    point
                },
            )
            .collect())
    }

    pub(super) fn true_reflectors(&self, work: &Work) -> Vec<Point3<f64>> {
        let flange = work.state.frames.flange;
        self.world
            .mounting
            .actual
            .iter()
            .map(|p| flange * p)
            .collect()
    }

    /// The tracker's measurement of the reached arm in `work.state`, and what the simulation knows about it.
    pub(super) fn record(
        &self,
        region: &str,
        plan: Planned,
        true_reflectors: Vec<Point3<f64>>,
        rng: &mut rand_chacha::ChaCha8Rng,
        work: &Work,
    ) -> CampaignPoint {
        let measured = true_reflectors
            .iter()
            .map(|p| self.world.tracker.measure(p, rng))
            .collect();
        CampaignPoint {
            id: 0,
            region: region.to_string(),
            nominal_reflectors: self
                .world
                .mounting
                .nominal
                .iter()
                .map(|p| plan.nominal_flange * p)
                .collect(),
            q_cmd: plan.q_cmd,
            nominal_flange: plan.nominal_flange,
            measured,
            true_flange: work.state.frames.flange,
            true_in_tracker: true_reflectors
                .iter()
                .map(|p| self.world.tracker.pose.inverse_transform_point(p))
                .collect(),
            true_reflectors,
            q_true: work.state.q.clone(),
            temperature: None,
        }
    }
}
