//! The paper's Tables 1 and 2 for a fitted model on a test set: the errors of the nominal kinematics
//! ("Measured", before calibration) beside the fitted model's (after), as statistics in `report.json` and as
//! the text `calibrate` prints.

use std::fmt::Write as _;

use nalgebra::{Point3, UnitQuaternion};
use serde::Serialize;

use super::stats::Stats;
use super::transfer::Transfer;

use crate::calib::method::{Fitted, Prediction};
use crate::calib::tracker_frame::Observation;
use crate::error::{Error, Result};

/// Per-point errors of the nominal model (before) and of the fitted one (after): distances (m) and, where the
/// data measures it, orientation angles (rad).
#[derive(Clone, Debug, Default)]
pub struct BeforeAfter {
    pub before: Vec<f64>,
    pub after: Vec<f64>,
    /// After, with the linearized prediction (eq. 10).
    pub linearized: Vec<f64>,
    pub orientation_before: Vec<f64>,
    pub orientation_after: Vec<f64>,
    /// The nominal kinematics seen through the fitted method's own registration (its refined tracker frame
    /// and mounting), when "before" is the registered nominal model's: reported apart, as it differs by method.
    pub own_registration_before: Vec<f64>,
}

/// What a model says of one configuration: its nominal kinematics ([`Fitted::nominal`]: the measured point
/// and the flange orientation) and its prediction ([`Fitted::predict_with`]).
#[derive(Clone, Debug)]
pub struct PointPrediction {
    pub nominal: (Point3<f64>, UnitQuaternion<f64>),
    pub predicted: Prediction,
}

impl PointPrediction {
    /// `model` at `q` with the extra inputs `inputs`.
    pub fn of(model: &dyn Fitted, q: &[f64], inputs: &[f64]) -> PointPrediction {
        let (nominal, predicted) = model.nominal_and_prediction(q, inputs);
        PointPrediction { nominal, predicted }
    }
}

impl BeforeAfter {
    /// `model` and its nominal kinematics against `observations` (measured, or true points seen through the
    /// model's registration).
    pub fn of(model: &dyn Fitted, observations: &[Observation]) -> BeforeAfter {
        let predicted: Vec<PointPrediction> = observations
            .iter()
            .map(|o| PointPrediction::of(model, &o.q, &o.inputs))
            .collect();
        BeforeAfter::of_predicted(observations, &predicted)
    }

    /// [`BeforeAfter::of`] with the model's [`PointPrediction`] of each observation already made (one per
    /// observation, in order): a caller that needs them elsewhere too computes them once.
    pub fn of_predicted<'a>(
        observations: &[Observation],
        predicted: impl IntoIterator<Item = &'a PointPrediction>,
    ) -> BeforeAfter {
        let mut e = BeforeAfter::default();
        for (o, p) in observations.iter().zip(predicted) {
            let ((nominal_p, nominal_r), pred) = (p.nominal, &p.predicted);
            e.before.push((o.position - nominal_p).norm());
            e.after.push((o.position - pred.position).norm());
            e.linearized
                .push((o.position - pred.linearized_position).norm());
            if let Some(measured) = o.orientation {
                e.orientation_before.push(measured.angle_to(&nominal_r));
                e.orientation_after
                    .push(measured.angle_to(&pred.orientation));
            }
        }
        e
    }

    /// On another campaign: the nominal model's errors (`before`) and the fitted model's (`after`), each
    /// through its own registration of the campaign ([`super::transfer::evaluate`]).
    pub fn transferred(before: &Transfer, after: &Transfer) -> BeforeAfter {
        BeforeAfter {
            before: before.errors.position.clone(),
            after: after.errors.position.clone(),
            linearized: after.errors.position.clone(),
            orientation_before: before.errors.orientation.clone(),
            orientation_after: after.errors.orientation.clone(),
            own_registration_before: Vec::new(),
        }
    }

    /// "Measured" as one number per data set: `self`'s "before" (the nominal kinematics through the method's
    /// own registration) replaced by the registered nominal model's errors `nominal` on the same points
    /// (its `after`), and kept apart as `own_registration_before`.
    pub fn measured_by(mut self, nominal: &BeforeAfter) -> BeforeAfter {
        let own = std::mem::replace(&mut self.before, nominal.after.clone());
        if own != self.before {
            self.own_registration_before = own;
        }
        self.orientation_before = nominal.orientation_after.clone();
        self
    }

    /// The statistics `report.json` holds.
    pub fn summary(&self) -> Result<BeforeAfterSummary> {
        // The linearized prediction (eq. 10) is reported when it differs from the full one by more than a
        // micrometre.
        let gap = self
            .after
            .iter()
            .zip(&self.linearized)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        Ok(BeforeAfterSummary {
            own_registration_before: match self.own_registration_before.is_empty() {
                true => None,
                false => Some(MmStats::of(&self.own_registration_before)?),
            },
            before: MmStats::of(&self.before)?,
            after: MmStats::of(&self.after)?,
            after_linearized: match gap > 1e-6 {
                true => Some(MmStats::of(&self.linearized)?),
                false => None,
            },
            orientation: match self.orientation_before.is_empty() {
                true => None,
                false => Some(OrientationSummary {
                    before: RadStats::of(&self.orientation_before)?,
                    after: RadStats::of(&self.orientation_after)?,
                }),
            },
        })
    }

    /// Table 1 (positions, mm) titled `position_title`, and Table 2 (orientations, rad) titled
    /// `orientation_title` when the data measures orientation; `method` heads the "after" column.
    pub fn tables(
        &self,
        method: &str,
        position_title: &str,
        orientation_title: &str,
    ) -> Result<String> {
        let mut out = table(position_title, "mm", method, &self.before, &self.after, 1e3)?;
        if !self.orientation_before.is_empty() {
            out += &table(
                orientation_title,
                "rad",
                method,
                &self.orientation_before,
                &self.orientation_after,
                1.0,
            )?;
        }
        Ok(out)
    }
}

fn stats_of(values: &[f64]) -> Result<Stats> {
    Stats::of(values).ok_or_else(|| Error::Invalid("no finite errors to summarize".into()))
}

/// One table: mean, max, std, rms and p95 before and after, scaled by `scale` into `unit`.
fn table(
    title: &str,
    unit: &str,
    method: &str,
    before: &[f64],
    after: &[f64],
    scale: f64,
) -> Result<String> {
    let (b, a) = (
        stats_of(before)?.scaled(scale),
        stats_of(after)?.scaled(scale),
    );
    let mut out = String::new();
    let _ = writeln!(out, "{title} ({unit}), n = {}", b.n);
    let _ = writeln!(out, "  {:<6} {:>10} {:>22}", "Error", "Measured", method);
    for (name, x, y) in [
        ("mean", b.mean, a.mean),
        ("max", b.max, a.max),
        ("std", b.std, a.std),
        ("rms", b.rms, a.rms),
        ("p95", b.p95, a.p95),
    ] {
        let _ = writeln!(out, "  {name:<6} {x:>10.4} {y:>22.4}");
    }
    Ok(out)
}

/// Before and after, as `report.json` names them. `before` is the paper's "Measured": the registered nominal
/// model, the same for every method on the same data.
#[derive(Clone, Debug, Serialize)]
pub struct BeforeAfterSummary {
    pub before: MmStats,
    /// The nominal kinematics through the method's own registration, where that differs from `before`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub own_registration_before: Option<MmStats>,
    pub after: MmStats,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub after_linearized: Option<MmStats>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub orientation: Option<OrientationSummary>,
}

#[derive(Clone, Debug, Serialize)]
pub struct OrientationSummary {
    pub before: RadStats,
    pub after: RadStats,
}

/// Distance statistics in millimetres.
#[derive(Clone, Debug, Serialize)]
pub struct MmStats {
    pub n: usize,
    pub mean_mm: f64,
    pub max_mm: f64,
    pub std_mm: f64,
    pub rms_mm: f64,
    pub p95_mm: f64,
}

impl MmStats {
    /// Of distances in metres; an error when there are none or one is not finite.
    pub fn of(metres: &[f64]) -> Result<MmStats> {
        let s = stats_of(metres)?.scaled(1e3);
        Ok(MmStats {
            n: s.n,
            mean_mm: s.mean,
            max_mm: s.max,
            std_mm: s.std,
            rms_mm: s.rms,
            p95_mm: s.p95,
        })
    }
}

/// Angle statistics in radians.
#[derive(Clone, Debug, Serialize)]
pub struct RadStats {
    pub n: usize,
    pub mean_rad: f64,
    pub max_rad: f64,
    pub std_rad: f64,
    pub rms_rad: f64,
    pub p95_rad: f64,
}

impl RadStats {
    /// Of angles in radians; an error when there are none or one is not finite.
    pub fn of(radians: &[f64]) -> Result<RadStats> {
        let s = stats_of(radians)?;
        Ok(RadStats {
            n: s.n,
            mean_rad: s.mean,
            max_rad: s.max,
            std_rad: s.std,
            rms_rad: s.rms,
            p95_rad: s.p95,
        })
    }
}
