//! The oracle: a "calibration" that is the true robot itself. It predicts what a perfect tracker would
//! measure, so its error on measured data is the measurement noise alone. It needs the truth, so only the
//! evaluation can build it; it is not a [`MethodKind`](crate::calib::registry::MethodKind).
//!
//! The evaluation's oracle registers the tracker frame from the same noisy training measurements as every
//! method ([`Oracle::registered_on`]): its ground-truth error is then what perfect knowledge of the robot
//! still leaves, the floor a method's ground-truth error is compared with. Built with the tracker's true
//! pose ([`Oracle::new`]) its ground-truth error is zero.

use nalgebra::{Point3, UnitQuaternion};
use serde_json::json;

use crate::calib::method::{Basis, Fitted, MethodInfo, Prediction, RobotParameters};
use crate::calib::rigid::{centre, register_points};
use crate::calib::tracker_frame::{Observation, Registration, TrackerFrame};
use crate::dataset::Dataset;
use crate::error::Result;
use crate::tracker::reflector::Mounting;
use crate::truth::{TrueRobot, TrueState};
use crate::world::World;

/// The true robot as a fitted method. Its registered frame is the world frame: `tracker_to_base` is the
/// tracker's true pose, the mounting is the true measured point (reflector, or nest centre) on the flange.
pub struct Oracle {
    robot: TrueRobot,
    basis: Basis,
    /// The true rotation of the nest from its drawing (identity for a single reflector): the measured
    /// orientation of a nest is the flange's turned by it.
    nest_rotation: UnitQuaternion<f64>,
}

impl Oracle {
    pub fn new(world: &World) -> Result<Oracle> {
        let mounting = &world.mounting;
        let nest = (mounting.count() >= 3).then(|| {
            let c = centre(&mounting.nominal);
            mounting
                .nominal
                .iter()
                .map(|p| Point3::from(p - c))
                .collect::<Vec<_>>()
        });
        let nest_rotation = nest_rotation(mounting)?.unwrap_or_else(UnitQuaternion::identity);
        Ok(Oracle {
            robot: world.robot.clone(),
            basis: Basis {
                joint_names: world.nominal.joint_names(),
                dh: world.dh.clone(),
                registration: Registration {
                    frame: TrackerFrame {
                        tracker_to_base: world.tracker.pose,
                        mounting: centre(&mounting.actual),
                        rms: 0.0,
                        evaluations: 0,
                    },
                    nest,
                    probe_rotation: None,
                    base_frame: false,
                },
                domain: Default::default(),
            },
            nest_rotation,
        })
    }

    /// The same oracle with its tracker frame registered, by least squares, from the measurements of `sets`
    /// (the training and validation points) onto its own true predictions.
    pub fn registered_on(mut self, sets: &[&Dataset]) -> Result<Oracle> {
        let (mut measured, mut predicted) = (Vec::new(), Vec::new());
        for data in sets {
            for (q, points) in data.q.iter().zip(&data.measured) {
                measured.push(centre(points));
                predicted.push(self.predict(q).position);
            }
        }
        let fit = register_points(&measured, &predicted)?;
        self.basis.registration.frame.tracker_to_base = fit.transform;
        self.basis.registration.frame.rms = fit.rms;
        Ok(self)
    }

    /// The true robot the oracle predicts with.
    pub fn robot(&self) -> &TrueRobot {
        &self.robot
    }
}

/// The rotation of a nest's true reflectors from its drawing, about their centres (`None` for a single
/// reflector, which has no orientation): a nest's measured orientation is the flange's turned by it.
pub fn nest_rotation(mounting: &Mounting) -> Result<Option<UnitQuaternion<f64>>> {
    if mounting.count() < 3 {
        return Ok(None);
    }
    let centred = |points: &[Point3<f64>]| -> Vec<Point3<f64>> {
        let c = centre(points);
        points.iter().map(|p| Point3::from(p - c)).collect()
    };
    let fit = register_points(&centred(&mounting.nominal), &centred(&mounting.actual))?;
    Ok(Some(fit.transform.rotation))
}

/// The oracle as a method: not one a user can choose, as it is the truth.
pub const ORACLE: MethodInfo = MethodInfo {
    name: "oracle",
    summary: "the true robot, noise-free: the measurement-noise floor",
    takes_inputs: false,
    base: None,
    parameters: RobotParameters::None,
};

impl Fitted for Oracle {
    fn info(&self) -> &'static MethodInfo {
        &ORACLE
    }

    fn basis(&self) -> &Basis {
        &self.basis
    }

    /// The true arm at `q`, noise-free, with the fixed-point deflection (a scenario solving its deflection
    /// with rapier differs from it by what the truth tests allow). A command the true robot cannot settle
    /// at gives NaN, which the statistics refuse.
    fn predict(&self, q: &[f64]) -> Prediction {
        let mut state = TrueState::new(&self.robot);
        match self.robot.flange_pose(q, &mut state) {
            Ok(flange) => {
                let position = flange * self.basis.registration.frame.mounting;
                Prediction {
                    position,
                    linearized_position: position,
                    orientation: flange.rotation * self.nest_rotation,
                }
            }
            Err(_) => {
                let nan = Point3::new(f64::NAN, f64::NAN, f64::NAN);
                Prediction {
                    position: nan,
                    linearized_position: nan,
                    orientation: UnitQuaternion::identity(),
                }
            }
        }
    }

    fn models_orientation(&self) -> bool {
        self.basis.registration.measures_orientation()
    }

    fn report(&self, _test: &[Observation]) -> serde_json::Value {
        json!({ "oracle": "the true robot, noise-free: the measurement-noise floor" })
    }
}
