//! `calibrate`'s `report.json`: what the fit, the test and the truth say about a model, and what the user
//! must know before trusting it.

use nalgebra::{Isometry3, Point3, UnitQuaternion};
use serde::Serialize;
use serde_json::{Map, Value};

use crate::calib::tracker_frame::Registration;
use crate::eval::iso_cubes::CubesReport;
use crate::eval::tables::BeforeAfterSummary;
use crate::eval::transfer::TestRegistration;

/// `report.json`.
///
/// Written through [`serde_json::Value`], whose maps keep their keys sorted (serde_json without
/// `preserve_order`): the file's keys are in alphabetical order at every level, as they always were, and
/// the method's own facts sit among the common fields.
#[derive(Clone, Debug, Serialize)]
pub struct CalibrationReport {
    pub method: String,
    pub data: String,
    pub robot: String,
    pub n_train: usize,
    pub n_val: usize,
    pub n_test: usize,
    pub fit_ms: f64,
    /// The model's registration of the training data.
    pub registration: RegistrationReport,
    pub test: BeforeAfterSummary,
    /// The test campaign, with `--test-data`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub test_data: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub test_registration: Option<TestRegistrationReport>,
    /// With `--test-registration refit`: the same test campaign through the model's own registration (nothing
    /// fitted on the test points), beside `test`, which a refit on few points flatters.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub test_model_registration: Option<BeforeAfterSummary>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub extra_inputs: Option<Vec<String>>,
    /// The method's own facts (kept parameters, R², rank, …) at the top level beside the common ones; a fact
    /// named like a field above replaces it.
    #[serde(flatten)]
    pub method_facts: Map<String, Value>,
    /// Against the ground truth, with `--truth`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub truth: Option<BeforeAfterSummary>,
    /// Whether the calibrated model's test mean (position, or orientation where measured) is above the
    /// nominal model's: a calibration that makes the arm worse.
    pub worse_than_nominal: bool,
    /// What the user must know before trusting the result, one sentence each (also printed as `warning:`).
    pub warnings: Vec<String>,
    /// Test points outside the model's training domain (`test_points.csv`).
    pub test_outside_domain: usize,
    /// ISO 9283's AP and RP on the test data's cubes, where it repeats their points.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub iso9283: Option<CubesReport>,
    /// For data measured on the fly (a `time` column): the clock offset removed before fitting (controller minus
    /// tracker, s) and the nominal registration's RMS at it and at zero (mm).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub clock_offset: Option<ClockReport>,
}

/// The clock offset `calibrate` removed.
#[derive(Clone, Debug, Serialize)]
pub struct ClockReport {
    pub offset_s: f64,
    pub rms_mm: f64,
    pub rms_at_zero_mm: f64,
}

/// A registration as `report.json` shows it.
#[derive(Clone, Debug, Serialize)]
pub struct RegistrationReport {
    pub tracker_to_base: Isometry3<f64>,
    pub mounting_m: Point3<f64>,
    pub probe_rotation: Option<UnitQuaternion<f64>>,
    pub rms_mm: f64,
}

impl RegistrationReport {
    pub fn of(r: &Registration) -> RegistrationReport {
        RegistrationReport {
            tracker_to_base: r.frame.tracker_to_base,
            mounting_m: r.frame.mounting,
            probe_rotation: r.probe_rotation,
            rms_mm: r.frame.rms * 1e3,
        }
    }
}

/// How the test campaign was registered, with `--test-data`.
#[derive(Clone, Debug, Serialize)]
pub struct TestRegistrationReport {
    pub mode: TestRegistration,
    pub fitted_on_test_data: String,
    #[serde(flatten)]
    pub registration: RegistrationReport,
}

/// A warning per quantity (position, orientation) on which the calibrated model errs more than the nominal
/// one: the calibration makes the arm worse there.
pub fn worse_than_nominal(test: &BeforeAfterSummary, on: &str) -> Vec<String> {
    let mut out = Vec::new();
    if test.after.mean_mm > test.before.mean_mm {
        out.push(format!(
            "the calibrated model is WORSE than the nominal one {on}: mean position error {:.4} mm against {:.4} mm \
             (Measured); do not use it",
            test.after.mean_mm, test.before.mean_mm
        ));
    }
    if let Some(o) = &test.orientation
        && o.after.mean_rad > o.before.mean_rad
    {
        out.push(format!(
            "the calibrated model is WORSE than the nominal one {on} in orientation: mean {:.3} mrad against {:.3} \
             mrad (Measured)",
            o.after.mean_rad * 1e3,
            o.before.mean_rad * 1e3
        ));
    }
    out
}
