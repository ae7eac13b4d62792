//! The paper's "Measured" column and the error budget of a campaign.
//!
//! "Measured" is what a user sees before any calibration: tracker points registered rigidly (least squares)
//! onto the nominal reflector positions, and the distances that remain. The budget repeats that on the true
//! reflector positions (no tracker noise) for the robot as it is, for the robot with only its elasticity, and
//! for the robot with only its rigid errors, so a scenario author sees what carries the error.

use nalgebra::Point3;
use serde::Serialize;

use super::stats::Stats;
use crate::calib::rigid::{centre, register_points};
use crate::campaign::Campaign;
use crate::error::{Error, Result};
use crate::robot::Chain;
use crate::robot::kinematics::flange_pose;
use crate::tracker::reflector::Mounting;
use crate::truth::{Perturbation, TrueRobot, TrueState};

/// Distances (m) between `reference` points and `measured` points after the least-squares rigid
/// registration of `measured` onto `reference`.
pub fn registered_distances(
    reference: &[Point3<f64>],
    measured: &[Point3<f64>],
) -> Result<Vec<f64>> {
    let fit = register_points(measured, reference)?;
    Ok(fit.residuals)
}

/// The paper's "Measured" column: tracker points registered onto the nominal reflector positions, one centre
/// per point (the reflector, or the nest centre), the distances that remain (m).
pub fn measured(campaign: &Campaign) -> Result<Stats> {
    let nominal: Vec<Point3<f64>> = campaign
        .points
        .iter()
        .map(|p| centre(&p.nominal_reflectors))
        .collect();
    let measured: Vec<Point3<f64>> = campaign
        .points
        .iter()
        .map(|p| centre(&p.measured))
        .collect();
    Stats::of(&registered_distances(&nominal, &measured)?)
        .ok_or_else(|| Error::Invalid("the campaign has no points".into()))
}

/// Registered distance statistics (m) of the true reflector centres, by error source.
#[derive(Clone, Debug, Serialize)]
pub struct Budget {
    /// The true robot without repeatability or tracker noise.
    pub all_systematic: Stats,
    /// Nominal geometry and mounting, with the true joint stiffness: gravity and payload deflection only.
    pub elastic_only: Stats,
    /// The true geometry, zero offsets, gear errors and mounting, with infinitely stiff joints.
    pub rigid_only: Stats,
}

impl Budget {
    pub fn of(
        nominal: &Chain,
        robot: &TrueRobot,
        mounting: &Mounting,
        commands: &[Vec<f64>],
    ) -> Result<Budget> {
        let nominal_centre = centre(&mounting.nominal);
        let reference: Vec<Point3<f64>> = commands
            .iter()
            .map(|q| flange_pose(nominal, q) * nominal_centre)
            .collect();
        let distances = |robot: &TrueRobot, reflectors: &[Point3<f64>]| -> Result<Stats> {
            let mut state = TrueState::new(robot);
            let local = centre(reflectors);
            let mut points = Vec::with_capacity(reference.len());
            for q in commands {
                points.push(robot.flange_pose(q, &mut state)? * local);
            }
            Stats::of(&registered_distances(&reference, &points)?)
                .ok_or_else(|| Error::Invalid("no points for the error budget".into()))
        };
        let elastic = TrueRobot::new(
            nominal,
            Perturbation::rigid_geometry(robot.perturbation.stiffness.clone()),
            robot.payload,
        )?;
        let mut stiff = robot.perturbation.clone();
        stiff.stiffness.iter_mut().for_each(|k| *k *= 1e12);
        let rigid = TrueRobot::new(nominal, stiff, robot.payload)?;
        Ok(Budget {
            all_systematic: distances(robot, &mounting.actual)?,
            elastic_only: distances(&elastic, &mounting.nominal)?,
            rigid_only: distances(&rigid, &mounting.actual)?,
        })
    }
}
