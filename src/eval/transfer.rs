//! Evaluating a fitted model on another campaign: another series, another day, another layout.
//!
//! A model predicts in the frame of its own registration: the tracker where it stood during training and the
//! probe as it was mounted then. A campaign measured another day need have neither — each series of the UR10
//! data was measured from its own tracker set-up (D from a station 6.7 m away from C's), and in D the T-Mac
//! sits 0.8 mm sideways and 0.14° turned from its place in C. The robot is the same, and the robot is what the
//! model is about; so on such a campaign
//! ([`TestRegistration::Refit`]) its own tracker frame (rigid, 6 parameters) and probe mounting (position, 3;
//! rotation, 3 more when the orientation is measured) are registered on its own points against the *model's*
//! predicted flange poses, as a user re-registers a tracker after moving it, and nothing else is refitted.
//! Every method, `nominal` included, gets the same 9 (12) parameters. [`TestRegistration::Model`] keeps the
//! model's registration, for a campaign measured from the same station with the same probe.
//!
//! A mounting offset along a direction about which the flange never turns moves every point alike: it is a
//! shift of the tracker frame, and fitting it anyway hands it to whatever the model gets wrong about the
//! orientation (on series D, whose 632 points all keep the tool axis along −y, the probe's axial position came
//! out anywhere between −88 and +132 mm depending on the model). So the mounting is refitted only along the
//! directions about which the commanded flange turns by at least [`MIN_TURN_RAD`] RMS over the test points
//! ([`turning_directions`] of the nominal kinematics: the campaign's layout decides, not the model) and kept
//! at the model's value across the others.

use nalgebra::Isometry3;
use serde::Serialize;

use super::judge::PointErrors;
use crate::calib::method::Fitted;
use crate::calib::rigid::centre;
use crate::calib::tracker_frame::{
    Registration, fit_mounting, fit_tracker_frame, fit_tracker_frame_along, probe_rotation,
    turning_directions,
};
use crate::dataset::Dataset;
use crate::error::{Error, Result};

/// How a test campaign's measurements are brought into the model's base frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum TestRegistration {
    /// The test campaign's tracker frame and probe mounting, registered on its own points against the
    /// model's predicted flange poses.
    Refit,
    /// The model's own registration.
    Model,
}

impl TestRegistration {
    pub fn parse(text: &str) -> Result<TestRegistration> {
        match text {
            "refit" => Ok(TestRegistration::Refit),
            "model" => Ok(TestRegistration::Model),
            other => Err(Error::Invalid(format!(
                "test registration '{other}': refit (the test data's own tracker frame and probe mounting) or \
                 model (the model's)"
            ))),
        }
    }
}

/// The mounting is refitted along a direction only if the flange turns about it by at least this much (RMS
/// over the test points, rad; 0.05 rad ≈ 3°).
pub const MIN_TURN_RAD: f64 = 0.05;

/// A model's errors on a test campaign, with the registration they were measured through.
#[derive(Clone, Debug)]
pub struct Transfer {
    pub registration: Registration,
    pub mode: TestRegistration,
    /// With [`TestRegistration::Refit`], the mounting directions refitted (3 unless the flange did not turn
    /// about some direction).
    pub mounting_directions: usize,
    /// Distances (m) and, where the campaign measures it, orientation angles (rad) per point.
    pub errors: PointErrors,
}

/// The extra inputs of `data` the model takes: its own names must be the data's (a model without extra
/// inputs takes none).
fn check_inputs(model: &dyn Fitted, data: &Dataset) -> Result<bool> {
    let wanted = model.input_names();
    if wanted.is_empty() {
        return Ok(false);
    }
    if wanted != data.extra_input_names() {
        return Err(Error::Data {
            origin: data.origin.clone(),
            message: format!(
                "the model regresses on [{}], the data has extra inputs [{}]",
                wanted.join(", "),
                data.extra_input_names().join(", ")
            ),
        });
    }
    Ok(true)
}

/// The model's predicted flange pose at every point of `data`.
pub fn predicted_flanges(model: &dyn Fitted, data: &Dataset) -> Result<Vec<Isometry3<f64>>> {
    if data.joint_names != model.joint_names() {
        return Err(Error::Data {
            origin: data.origin.clone(),
            message: format!(
                "joints [{}], the model's [{}]",
                data.joint_names.join(", "),
                model.joint_names().join(", ")
            ),
        });
    }
    let with_inputs = check_inputs(model, data)?;
    Ok((0..data.len())
        .map(|i| {
            let inputs = if with_inputs {
                data.extra_inputs_of(i)
            } else {
                &[]
            };
            model.predicted_flange(&data.q[i], inputs)
        })
        .collect())
}

impl Transfer {
    /// What was fitted on the test data, for reports.
    /// Parameters fitted on the test data's own points (0 with the model's registration).
    pub fn refitted_parameters(&self) -> usize {
        match self.mode {
            TestRegistration::Model => 0,
            TestRegistration::Refit => {
                6 + self.mounting_directions
                    + if self.registration.probe_rotation.is_some() {
                        3
                    } else {
                        0
                    }
            }
        }
    }

    pub fn describe(&self) -> String {
        match self.mode {
            TestRegistration::Model => "none: the model's registration".into(),
            TestRegistration::Refit => {
                let mounting = match self.mounting_directions {
                    3 => "position 3".to_string(),
                    k => format!(
                        "position along the {k} of 3 directions the flange turns about, the rest kept"
                    ),
                };
                let (rotation, extra) = match self.registration.probe_rotation {
                    Some(_) => (", rotation 3", 3),
                    None => ("", 0),
                };
                let _ = extra;
                format!(
                    "tracker frame (rigid, 6) and probe mounting ({mounting}{rotation}) re-registered on \
                     the test data's own points: {} parameters",
                    self.refitted_parameters()
                )
            }
        }
    }
}

/// The test campaign's tracker frame and probe mounting (and probe rotation when it measures orientation),
/// registered on all its points against the model's predicted flange poses; and the number of mounting
/// directions refitted.
pub fn reregister(model: &dyn Fitted, data: &Dataset) -> Result<(Registration, usize)> {
    let flanges = predicted_flanges(model, data)?;
    reregister_on(model, data, &flanges)
}

fn reregister_on(
    model: &dyn Fitted,
    data: &Dataset,
    flanges: &[Isometry3<f64>],
) -> Result<(Registration, usize)> {
    let centres: Vec<_> = data.measured.iter().map(|m| centre(m)).collect();
    let mounting = model.registration().frame.mounting;
    // From the commanded (nominal) flanges: a property of the campaign's layout, the same for every method,
    // whatever a model predicts about the orientation.
    let commanded: Vec<Isometry3<f64>> = data.q.iter().map(|q| model.dh().flange_pose(q)).collect();
    let directions = turning_directions(&commanded, MIN_TURN_RAD);
    let frame = if data.base_frame {
        fit_mounting(&centres, flanges)?
    } else if directions.len() == 3 {
        fit_tracker_frame(&centres, flanges, &mounting)?
    } else {
        fit_tracker_frame_along(&centres, flanges, &mounting, &directions)?
    };
    let probe_rotation = match &data.measured_orientation {
        Some(measured) => Some(probe_rotation(&frame, flanges, measured)?),
        None => None,
    };
    let nest = model
        .registration()
        .nest
        .clone()
        .filter(|n| n.len() == data.reflectors());
    Ok((
        Registration {
            frame,
            nest,
            probe_rotation,
            base_frame: data.base_frame,
        },
        directions.len(),
    ))
}

/// The model's errors on `data`, measured through the registration `mode` says.
pub fn evaluate(model: &dyn Fitted, data: &Dataset, mode: TestRegistration) -> Result<Transfer> {
    if data.is_empty() {
        return Err(Error::Data {
            origin: data.origin.clone(),
            message: "no points to evaluate on".into(),
        });
    }
    let flanges = predicted_flanges(model, data)?;
    let (registration, mounting_directions) = match mode {
        TestRegistration::Refit => reregister_on(model, data, &flanges)?,
        TestRegistration::Model => {
            let r = model.registration().clone();
            if data.measured_orientation.is_some() != r.probe_rotation.is_some() {
                return Err(Error::Data {
                    origin: data.origin.clone(),
                    message: "the data and the model's registration disagree on a measured probe \
                              orientation; re-register (refit) instead"
                        .into(),
                });
            }
            (r, 0)
        }
    };
    let observations = registration.observe(data)?;
    let mut errors = PointErrors::default();
    for (o, f) in observations.iter().zip(&flanges) {
        errors
            .position
            .push((o.position - f * registration.frame.mounting).norm());
        if let Some(measured) = o.orientation {
            errors.orientation.push(measured.angle_to(&f.rotation));
        }
    }
    Ok(Transfer {
        registration,
        mode,
        mounting_directions,
        errors,
    })
}
