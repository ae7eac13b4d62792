//! The motion as inputs of a regression (issue 16): for a campaign measured on the fly, per joint, the torque the
//! commanded motion needs beyond gravity, `tau_motion_<joint>` (Nm), from the nominal model's inverse dynamics
//! at the commanded angles, velocities and accelerations the controller logged (`qd_*`, `qdd_*`), with the
//! declared payload. The motion deflects compliant joints by about their compliance times this torque, which no
//! static model describes; given it as an input, a regression can describe that part and leave it out at rest
//! (a motion input's default is zero: [`crate::dataset::Dataset::input_defaults`]).

use nalgebra::Vector3;

use crate::dataset::{Dataset, ExtraInputs, MOTION_INPUT_PREFIX};
use crate::error::{Error, Result};
use crate::robot::inverse_dynamics::{Workspace, inverse_dynamics};
use crate::robot::{Chain, Frames, Payload, forward_kinematics};

/// `data` with the motion inputs appended to its extra inputs. Errors: no `qd_*`/`qdd_*` columns, or rates of
/// another length than the chain's joints.
pub fn with_motion_inputs(data: &Dataset, chain: &Chain, payload: &Payload) -> Result<Dataset> {
    let rates = data.rates.as_ref().ok_or_else(|| Error::Data {
        origin: data.origin.clone(),
        message: "no qd_<joint> and qdd_<joint> columns: the motion inputs need the controller's commanded \
                  joint velocities and accelerations"
            .into(),
    })?;
    let n = chain.dof();
    if let Some(i) = rates
        .iter()
        .position(|r| r.qd.len() != n || r.qdd.len() != n)
    {
        return Err(Error::Data {
            origin: data.origin.clone(),
            message: format!(
                "point {}: joint rates for {} joints, the robot has {n}",
                data.point_ids[i],
                rates[i].qd.len()
            ),
        });
    }
    let mut frames = Frames::new(chain);
    let mut ws = Workspace::new(chain);
    let mut tau = vec![0.0; n];
    let values: Vec<Vec<f64>> = data
        .q
        .iter()
        .zip(rates)
        .map(|(q, r)| {
            forward_kinematics(chain, q, &mut frames);
            // Gravity off: only what the motion adds.
            inverse_dynamics(
                chain,
                &frames,
                payload,
                &Vector3::zeros(),
                &r.qd,
                &r.qdd,
                &mut ws,
                &mut tau,
            );
            tau.clone()
        })
        .collect();
    let mut out = data.clone();
    let (mut names, mut rows) = match data.extra_inputs.clone() {
        Some(x) => (x.names, x.values),
        None => (Vec::new(), vec![Vec::new(); data.len()]),
    };
    names.extend(
        chain
            .joints
            .iter()
            .map(|j| format!("{MOTION_INPUT_PREFIX}{}", j.name)),
    );
    for (row, v) in rows.iter_mut().zip(values) {
        row.extend(v);
    }
    out.extra_inputs = Some(ExtraInputs {
        names,
        values: rows,
    });
    Ok(out)
}
