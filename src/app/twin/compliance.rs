//! How far the pilot's configurations let the elastic fit's compliances stray, measured on the twin itself.
//!
//! The fit's own standard deviation assumes residuals that are independent from point to point. They are not:
//! what no method models (the gears' transmission error, the true link masses, the cable) is a function of the
//! configuration, and over a narrow band of torque it leans on a compliance as a change of it would. The twin
//! carries those sources at their fitted or cited magnitudes and knows its own compliances, so the pilot's
//! configurations replayed through it and refitted show how far the fit's compliance lands from the one that
//! made the data: the root mean square of that error over [`DRAWS`] draws (new gear phases, link masses,
//! noise), reported beside the fit's standard deviation. Using the larger of the two as the weight against the
//! prior (and moving the joint's zero by what the changed compliance deflects at the pilot's mean torque) was
//! tried on the IPA UR10 and not kept: the rest of series C came out 1–2 points worse from a 100-row pilot
//! (docs/twin.md).

use serde::Serialize;

use super::scenario::TwinValues;
use super::{Identified, magnitudes};
use crate::calib::kinematic::KinematicModel;
use crate::calib::method::FitContext;
use crate::dataset::{Dataset, random_train_val};
use crate::error::Result;
use crate::eval::split::Parts;

/// Draws of the twin the compliances' error is measured over.
pub const DRAWS: u64 = 8;

/// One joint's compliance: the pilot's fit and the fit's error on the twin's replays.
#[derive(Clone, Debug, Serialize)]
pub struct ComplianceCheck {
    pub joint: usize,
    /// The elastic fit's value and standard deviation on the real pilot (rad/Nm).
    pub fitted: f64,
    pub fitted_std: f64,
    /// The compliance the twin's replays were made with, and the fit's values on them.
    pub twin: f64,
    pub refits: Vec<f64>,
    /// Root mean square of `refits − twin`: how far the pilot's configurations let the fit stray.
    pub error_rms: f64,
}

/// Each identified compliance's error on the twin's replays of the pilot.
pub fn check(
    values: &TwinValues,
    identified: &Identified,
    pilot: &Dataset,
    ctx: &FitContext,
    seed: u64,
) -> Result<Vec<ComplianceCheck>> {
    let scenario = values.scenario()?;
    let joints: Vec<(usize, usize)> = identified
        .compliance
        .iter()
        .enumerate()
        .filter(|(_, c)| c.is_some())
        .filter_map(|(j, _)| {
            let name = format!("c{}", j + 1);
            Some((
                j,
                identified
                    .model
                    .kept
                    .iter()
                    .position(|p| p.name() == name)?,
            ))
        })
        .collect();
    let mut refits = vec![Vec::new(); joints.len()];
    for s in 0..DRAWS {
        let replayed = magnitudes::replay(&scenario, pilot, s)?;
        let labels = random_train_val(replayed.len(), 2.0 / 3.0, seed)?;
        let Parts { train, val, .. } = Parts::of(&replayed, labels);
        // A draw the fit fails on tells nothing of the compliance's error; the others do.
        let Ok(model) = KinematicModel::fit(true, ctx, &train, &val) else {
            continue;
        };
        for (r, &(j, _)) in refits.iter_mut().zip(&joints) {
            let name = format!("c{}", j + 1);
            if let Some(k) = model.kept.iter().position(|p| p.name() == name) {
                r.push(model.values[k]);
            }
        }
    }
    let mut checks = Vec::new();
    for (refits, &(j, k)) in refits.into_iter().zip(&joints) {
        let (fitted, fitted_std) = identified.raw[k];
        let twin = 1.0 / values.stiffness[j];
        if refits.is_empty() || !(fitted_std.is_finite() && fitted_std > 0.0) {
            continue;
        }
        let error_rms =
            (refits.iter().map(|c| (c - twin).powi(2)).sum::<f64>() / refits.len() as f64).sqrt();
        checks.push(ComplianceCheck {
            joint: j + 1,
            fitted,
            fitted_std,
            twin,
            refits,
            error_rms,
        });
    }
    Ok(checks)
}
