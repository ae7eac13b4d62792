//! The `calibrate` jobs: [`fit`] a method on measured data and judge it on a test split or another campaign
//! (`report.json`, `model.json`, `predictions.csv`, the paper's Tables 1 and 2), and [`apply`] a saved model
//! to new joint configurations (predicted poses and corrected commands).

use std::path::{Path, PathBuf};
use std::time::Instant;

use nalgebra::{Isometry3, Point3, UnitQuaternion};
use serde::Serialize;
use serde_json::{Map, Value};

use crate::calib::clock::{self, ClockOffset};
use crate::calib::method::{FitContext, Fitted};
use crate::calib::motion_inputs::with_motion_inputs;
use crate::calib::registry::{MethodKind, REFERENCE, Save, SavedModel};
use crate::calib::regression::RegressionOptions;
use crate::calib::tracker_frame::Registration;
use crate::dataset::mapping::ColumnMapping;
use crate::dataset::range::JointRange;
use crate::dataset::{self, Dataset, Split, TruthTable};
use crate::error::{Error, Result};
use crate::eval::split::SplitRule;
use crate::eval::tables::{BeforeAfter, BeforeAfterSummary};
use crate::eval::transfer::{self, TestRegistration};
use crate::output;
use crate::robot::Payload;
use crate::robot::dh::DhChain;

use super::test_points;

/// What to fit and where to test it (the flags of `calibrate`).
#[derive(Clone, Debug)]
pub struct FitOptions {
    /// Measurements (`measurements.csv`), or any export with `mapping`.
    pub data: PathBuf,
    pub mapping: Option<PathBuf>,
    /// Test on this campaign instead of a test split of `data`.
    pub test_data: Option<PathBuf>,
    /// The mapping of `test_data`; `mapping` when absent.
    pub test_mapping: Option<PathBuf>,
    pub test_registration: TestRegistration,
    /// Drop the data's extra inputs so no method regresses on them.
    pub ignore_inputs: bool,
    /// Give the methods that regress on extra inputs the motion as inputs (`calib::motion_inputs`; the data
    /// needs the commanded joint rates, `qd_*` and `qdd_*`).
    pub motion_inputs: bool,
    pub robot: PathBuf,
    /// The link carrying the reflectors; the chain's last link when absent.
    pub flange_link: Option<String>,
    pub method: MethodKind,
    pub payload: Payload,
    /// Ground truth (`truth.csv` of a simulated campaign) of `data`.
    pub truth: Option<PathBuf>,
    /// Output directory.
    pub out: PathBuf,
    /// Used when the data has no `split` column.
    pub split: SplitRule,
    pub regression: RegressionOptions,
}

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

/// The clock offset is searched within ±this (s): far beyond a synchronised controller's and tracker's.
pub const CLOCK_BOUND_S: f64 = 0.05;

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

/// What [`fit`] did, for the binary to print.
#[derive(Clone, Debug)]
pub struct FitOutcome {
    pub report: CalibrationReport,
    /// Tables 1 and 2 on the test data, then against the truth when given.
    pub tables: String,
    /// Where the files went.
    pub out: PathBuf,
}

/// A refitted test registration is trusted with at least this many test points per refitted parameter:
/// below it the refit absorbs a visible part of the error (on 20 UR10 points, 9 parameters flattered the mean
/// by 9–15 %, issue 13).
pub const MIN_POINTS_PER_REFITTED_PARAMETER: usize = 10;

/// The files a fit writes.
const FIT_OUTPUTS: [&str; 4] = [
    "report.json",
    "model.json",
    "predictions.csv",
    "test_points.csv",
];

/// Fits `options.method` and writes `report.json`, `model.json`, `predictions.csv` and `test_points.csv` into `options.out`,
/// all or none.
pub fn fit(options: &FitOptions) -> Result<FitOutcome> {
    output::check_dir(&options.out, &FIT_OUTPUTS)?;
    let chain = crate::robot::load(&options.robot, options.flange_link.as_deref())?;
    let dh = DhChain::from_chain(&chain)?;
    let mapping = options
        .mapping
        .as_deref()
        .map(ColumnMapping::load)
        .transpose()?;
    let range = JointRange::of_chain(&chain, &options.robot.display().to_string());
    let read = |path: &Path, mapping: Option<&ColumnMapping>| -> Result<Dataset> {
        let mut data = match mapping {
            Some(m) => m.read(path, &chain)?,
            None => Dataset::read(path, &chain.joint_names())?,
        };
        if options.ignore_inputs {
            data.extra_inputs = None;
        }
        range.check(&data.origin, &data.point_ids, &data.q)?;
        Ok(data)
    };
    // A campaign measured on the fly (a `time` column) is corrected for the clock offset between tracker and
    // controller first; every method then fits on the corrected samples as on points (calib::clock).
    let synchronised = |data: Dataset| -> Result<(Dataset, Option<ClockOffset>)> {
        if data.time.is_none() {
            return Ok((data, None));
        }
        let found = clock::estimate(&dh, &data, CLOCK_BOUND_S)
            .map_err(|e| e.in_data(&data.origin, "estimating the clock offset"))?;
        Ok((clock::corrected(&data, found.offset_s)?, Some(found)))
    };
    let synchronised = |data: Dataset| -> Result<(Dataset, Option<ClockOffset>)> {
        let (data, offset) = synchronised(data)?;
        if !options.motion_inputs {
            return Ok((data, offset));
        }
        Ok((with_motion_inputs(&data, &chain, &options.payload)?, offset))
    };
    let (data, clock_offset) = synchronised(read(&options.data, mapping.as_ref())?)?;
    let test_file = match &options.test_data {
        Some(path) => {
            let test_mapping = match &options.test_mapping {
                Some(p) => Some(ColumnMapping::load(p)?),
                None => mapping.clone(),
            };
            Some(synchronised(read(path, test_mapping.as_ref())?)?.0)
        }
        None => None,
    };
    if test_file.is_some() && options.truth.is_some() {
        return Err(Error::Invalid(
            "--truth belongs to the test split of --data; it cannot be combined with --test-data"
                .into(),
        ));
    }
    let truth = match &options.truth {
        Some(path) => Some(TruthTable::read(path)?.aligned_to(&data)?),
        None => None,
    };
    let parts = options.split.apply(&data, test_file.is_some())?;
    if parts.test_indices.is_empty() && test_file.is_none() {
        return Err(Error::Invalid("the test split is empty".into()));
    }
    let (train, val) = (&parts.train, &parts.val);
    let test = test_file.as_ref().unwrap_or(&parts.test);

    let started = Instant::now();
    let ctx = FitContext {
        chain: &chain,
        dh: &dh,
        payload: options.payload,
        regression: options.regression.clone(),
    };
    let fitting = format!("fitting {}", options.method.info());
    let model = options
        .method
        .fit(&ctx, train, val)
        .map_err(|e| e.in_data(&data.origin, &fitting))?;
    let model = model.as_ref();
    let fit_ms = started.elapsed().as_secs_f64() * 1e3;

    // "Measured" (before) is one number per data set: the nominal kinematics under the nominal model's own
    // registration, whatever the method (a method's refined registration is reported apart).
    let nominal = if options.method == REFERENCE {
        None
    } else {
        Some(REFERENCE.fit(&ctx, train, val)?)
    };
    let nominal_model = nominal.as_deref().unwrap_or(model);
    let (mut refitted, mut kept) = (0usize, None);
    let (obs_test, test_errors, test_registration) = match &test_file {
        None => {
            let obs = model
                .registration()
                .observe(test)
                .map_err(|e| e.in_data(&data.origin, "the test split"))?;
            let mut e = BeforeAfter::of(model, &obs);
            if nominal.is_some() {
                let nominal_obs = nominal_model
                    .registration()
                    .observe(test)
                    .map_err(|e| e.in_data(&data.origin, "the test split"))?;
                e = e.measured_by(&BeforeAfter::of(nominal_model, &nominal_obs));
            }
            (obs, e, None)
        }
        Some(t) => {
            let mode = options.test_registration;
            let after = transfer::evaluate(model, t, mode)
                .map_err(|e| e.in_data(&t.origin, "registering the test campaign"))?;
            // "Before": the nominal kinematics, registered on the test campaign the same way.
            let before = transfer::evaluate(nominal_model, t, mode)?;
            let obs = after.registration.observe(t)?;
            refitted = after.refitted_parameters();
            if mode == TestRegistration::Refit {
                // The model's registration on the same points: nothing fitted on them. It may not apply (a
                // campaign measured from another station); then only the refit is reported.
                kept = transfer::evaluate(model, t, TestRegistration::Model)
                    .and_then(|a| {
                        let b = transfer::evaluate(nominal_model, t, TestRegistration::Model)?;
                        BeforeAfter::transferred(&b, &a).summary()
                    })
                    .ok();
            }
            let described = TestRegistrationReport {
                mode,
                fitted_on_test_data: after.describe(),
                registration: RegistrationReport::of(&after.registration),
            };
            (
                obs,
                BeforeAfter::transferred(&before, &after),
                Some(described),
            )
        }
    };
    let registration = model.registration();
    let mut report = CalibrationReport {
        method: model.method().to_string(),
        data: options.data.display().to_string(),
        robot: options.robot.display().to_string(),
        n_train: train.len(),
        n_val: val.len(),
        n_test: test.len(),
        fit_ms,
        registration: RegistrationReport::of(registration),
        test: test_errors.summary()?,
        test_data: test_registration.as_ref().map(|_| test.origin.clone()),
        test_registration,
        test_model_registration: kept,
        extra_inputs: Some(model.input_names().to_vec()).filter(|n| !n.is_empty()),
        method_facts: match model.report(&obs_test) {
            Value::Object(facts) => facts,
            _ => Map::new(),
        },
        truth: None,
        worse_than_nominal: false,
        warnings: Vec::new(),
        test_outside_domain: 0,
        clock_offset: clock_offset.map(|c| ClockReport {
            offset_s: c.offset_s,
            rms_mm: c.rms_m * 1e3,
            rms_at_zero_mm: c.rms_at_zero_m * 1e3,
        }),
    };
    report
        .warnings
        .extend(worse_than_nominal(&report.test, &what_test(&report)));
    report.worse_than_nominal = !report.warnings.is_empty();
    if refitted > 0 && test.len() < MIN_POINTS_PER_REFITTED_PARAMETER * refitted {
        let kept = match &report.test_model_registration {
            Some(k) => format!(
                " (with the model's own registration, nothing fitted on them: {:.4} mm mean, against {:.4} \
                 mm refitted)",
                k.after.mean_mm, report.test.after.mean_mm
            ),
            None => String::new(),
        };
        report.warnings.push(format!(
            "the test registration fits {refitted} parameters on {} test points (fewer than \
             {MIN_POINTS_PER_REFITTED_PARAMETER} per parameter): the refit absorbs part of the error and flatters \
             the result{kept}",
            test.len()
        ));
    }
    let truth_errors = match &truth {
        Some(t) => {
            let t_test = t.subset(&parts.test_indices);
            let mut obs_truth = registration.observe_points(&test.q, &t_test.in_tracker)?;
            // Each point with its own inputs (its temperature, its motion), as the measured test split has them.
            for (i, o) in obs_truth.iter_mut().enumerate() {
                o.inputs = test.extra_inputs_of(i).to_vec();
            }
            let mut e = BeforeAfter::of(model, &obs_truth);
            if nominal.is_some() {
                let nominal_truth = nominal_model
                    .registration()
                    .observe_points(&test.q, &t_test.in_tracker)?;
                e = e.measured_by(&BeforeAfter::of(nominal_model, &nominal_truth));
            }
            report.truth = Some(e.summary()?);
            Some(e)
        }
        None => None,
    };

    // Per test point: inside the model's training domain or not (outside, its regression is left out).
    let placements: Vec<_> = (0..test.len())
        .map(|i| test_points::place(model, &test.q[i], test.extra_inputs_of(i)))
        .collect();
    let (test_points_file, outside) = test_points::test_points_csv(
        &test.point_ids,
        &placements,
        &test_errors.before,
        &test_errors.after,
    )?;
    report.test_outside_domain = outside;
    if outside > 0 {
        report.warnings.push(format!(
            "{outside} of {} test points lie outside the model's training domain (joint or input ranges, or \
             far from every training configuration; `status` in test_points.csv); a regression is not \
             extrapolated there, the model falls back to its parametric part",
            test.len()
        ));
    }
    let predictions = predictions_csv(model, &data, &parts.labels)?;
    output::write_dir(
        &options.out,
        &[
            ("report.json", to_json(&to_value(&report)?)?),
            ("model.json", to_json(&model.save()?)?),
            ("predictions.csv", predictions),
            ("test_points.csv", test_points_file),
        ],
        &[],
    )?;

    let what = match &report.test_registration {
        Some(r) => format!(
            "on {}; fitted on it: {}",
            test.origin, r.fitted_on_test_data
        ),
        None => "on the test split".to_string(),
    };
    let mut tables = test_errors.tables(
        model.method(),
        &format!("Table 1. Positional errors {what}"),
        &format!("Table 2. Orientational errors {what}"),
    )?;
    if let Some(c) = &report.clock_offset {
        tables += &format!(
            "Measured on the fly: a clock offset of {:.1} µs between controller and tracker was removed before \
             fitting (nominal registration RMS {:.4} mm at it, {:.4} mm at zero)\n",
            c.offset_s * 1e6,
            c.rms_mm,
            c.rms_at_zero_mm
        );
    }
    if let Some(k) = &report.test_model_registration {
        tables += &format!(
            "The same test points through the model's own registration (nothing fitted on them): measured \
             {:.4} mm, after calibration {:.4} mm mean ({:.4} mm with the refit above)\n",
            k.before.mean_mm, k.after.mean_mm, report.test.after.mean_mm
        );
    }
    if let Some(t) = truth_errors {
        tables += &t.tables(
            model.method(),
            "Against the truth: positional errors on the test split",
            "Against the truth: orientational errors on the test split",
        )?;
    }
    Ok(FitOutcome {
        report,
        tables,
        out: options.out.clone(),
    })
}

/// What the test set is, for a warning.
fn what_test(report: &CalibrationReport) -> String {
    match &report.test_data {
        Some(t) => format!("on {t}"),
        None => "on the test split".into(),
    }
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

fn to_json(value: &impl Serialize) -> Result<Vec<u8>> {
    serde_json::to_vec_pretty(value).map_err(|e| Error::Invalid(format!("cannot serialize: {e}")))
}

/// As a [`Value`], whose maps sort their keys.
fn to_value(value: &impl Serialize) -> Result<Value> {
    serde_json::to_value(value).map_err(|e| Error::Invalid(format!("cannot serialize: {e}")))
}

fn predictions_csv(model: &dyn Fitted, data: &Dataset, labels: &[Split]) -> Result<Vec<u8>> {
    let observations = model.registration().observe(data)?;
    let mut w = csv::Writer::from_writer(Vec::new());
    let csv_err = |e: csv::Error| Error::Invalid(format!("predictions.csv: {e}"));
    let mut header = vec![
        "point_id",
        "split",
        "measured_x",
        "measured_y",
        "measured_z",
        "nominal_x",
        "nominal_y",
        "nominal_z",
        "predicted_x",
        "predicted_y",
        "predicted_z",
        "error_before_mm",
        "error_after_mm",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect::<Vec<_>>();
    let with_orientation = model.registration().measures_orientation();
    if with_orientation {
        header.extend(
            [
                "predicted_qw",
                "predicted_qx",
                "predicted_qy",
                "predicted_qz",
                "orientation_before_rad",
                "orientation_after_rad",
            ]
            .map(String::from),
        );
    }
    w.write_record(&header).map_err(csv_err)?;
    for ((id, o), label) in data.point_ids.iter().zip(&observations).zip(labels) {
        let (np, nr) = model.nominal(&o.q);
        let p = model.predict_with(&o.q, &o.inputs);
        let mut row = vec![id.clone(), format!("{label:?}").to_lowercase()];
        for v in [o.position.coords, np.coords, p.position.coords] {
            row.extend(v.iter().map(|x| x.to_string()));
        }
        row.push(((o.position - np).norm() * 1e3).to_string());
        row.push(((o.position - p.position).norm() * 1e3).to_string());
        if with_orientation {
            let q = p.orientation.quaternion();
            row.extend([q.w, q.i, q.j, q.k].map(|v| v.to_string()));
            let m = o.orientation.unwrap_or(nr);
            row.push(m.angle_to(&nr).to_string());
            row.push(m.angle_to(&p.orientation).to_string());
        }
        w.write_record(&row).map_err(csv_err)?;
    }
    w.into_inner()
        .map_err(|e| Error::Invalid(format!("predictions.csv: {e}")))
}

/// What to apply a saved model to (the flags of `calibrate apply`).
#[derive(Clone, Debug)]
pub struct ApplyOptions {
    /// A `model.json` written by [`fit`].
    pub model: PathBuf,
    /// Joint configurations: one column per joint of the model.
    pub data: PathBuf,
    /// A column mapping for reading `data`.
    pub mapping: Option<PathBuf>,
    /// Output CSV.
    pub out: PathBuf,
}

/// What [`apply`] did.
#[derive(Clone, Debug)]
pub struct ApplyOutcome {
    pub configurations: usize,
    /// Configurations outside the model's training domain (the `domain` column).
    pub outside_domain: usize,
    /// What the user must know, one sentence each (printed as `warning:`).
    pub warnings: Vec<String>,
    /// Configurations without a corrected command: the inverse is undefined there.
    pub without_command: usize,
    pub out: PathBuf,
}

/// Writes the saved model's predicted pose and corrected joint command for every configuration of
/// `options.data` to `options.out`.
pub fn apply(options: &ApplyOptions) -> Result<ApplyOutcome> {
    let model = SavedModel::read(&options.model)?;
    let joint_names = model.joint_names().to_vec();
    let (ids, configurations) = match &options.mapping {
        Some(path) => {
            let prismatic: Vec<bool> = model.dh().rows.iter().map(|r| r.prismatic).collect();
            ColumnMapping::load(path)?.read_joints(&options.data, &joint_names, &prismatic)?
        }
        None => dataset::read_joints(&options.data, &joint_names)?,
    };
    let prismatic: Vec<bool> = model.dh().rows.iter().map(|r| r.prismatic).collect();
    JointRange::plausible(&joint_names, &prismatic).check(
        &options.data.display().to_string(),
        &ids,
        &configurations,
    )?;
    let out = &options.out;
    let mut w = csv::Writer::from_writer(Vec::new());
    let csv_err = |e: csv::Error| Error::Invalid(format!("{}: {e}", out.display()));
    let mut header: Vec<String> = vec!["point_id".into()];
    header.extend(joint_names.iter().cloned());
    header.extend(
        [
            "predicted_x",
            "predicted_y",
            "predicted_z",
            "predicted_qw",
            "predicted_qx",
            "predicted_qy",
            "predicted_qz",
        ]
        .map(String::from),
    );
    header.extend(joint_names.iter().map(|n| format!("cmd_{n}")));
    header.push("compensation_residual_m".into());
    header.push("status".into());
    header.push("domain_distance_rad".into());
    header.push("domain".into());
    w.write_record(&header).map_err(csv_err)?;
    // A configuration where the inverse is undefined (a singular pose, such as a straight arm) still gets its
    // prediction; its command cells stay empty and `status` says why, so one such row does not cost the file.
    let (mut singular, mut outside) = (0, 0);
    for (id, q) in ids.iter().zip(&configurations) {
        let p = model.predict(q);
        let r: UnitQuaternion<f64> = p.orientation;
        let pos: Point3<f64> = p.position;
        let mut row = vec![id.clone()];
        row.extend(q.iter().map(|v| v.to_string()));
        row.extend([pos.x, pos.y, pos.z, r.w, r.i, r.j, r.k].map(|v| v.to_string()));
        match model.compensate(q) {
            Ok((command, residual)) => {
                row.extend(command.iter().map(|v| v.to_string()));
                row.push(residual.to_string());
                row.push("ok".into());
            }
            Err(e) => {
                singular += 1;
                row.extend(std::iter::repeat_n(String::new(), joint_names.len() + 1));
                row.push(format!("no command: {}", e.detail()));
            }
        }
        // Extra inputs are not read here: the model takes their training means, always inside.
        let placement = test_points::place(model.as_ref(), q, &[]);
        outside += usize::from(!placement.inside);
        row.push(placement.distance_rad.to_string());
        row.push(test_points::domain_cell(&placement));
        w.write_record(&row).map_err(csv_err)?;
    }
    let bytes = w
        .into_inner()
        .map_err(|e| Error::Invalid(format!("{}: {e}", out.display())))?;
    output::write_file(out, &bytes)?;
    Ok(ApplyOutcome {
        configurations: ids.len(),
        without_command: singular,
        outside_domain: outside,
        warnings: (outside > 0)
            .then(|| {
                format!(
                    "{outside} of {} configurations lie outside the model's training domain (column `domain`); \
                     a regression is not extrapolated there, the model falls back to its parametric part",
                    ids.len()
                )
            })
            .into_iter()
            .collect(),
        out: out.clone(),
    })
}

/// `calibrate --method`'s values, each with what the method is, as `--help` lists them.
pub fn method_values() -> clap::builder::PossibleValuesParser {
    use clap::builder::PossibleValue;
    clap::builder::PossibleValuesParser::new(
        MethodKind::ALL.map(|m| PossibleValue::new(m.name()).help(m.info().summary)),
    )
}

/// `calibrate --test-registration`'s values.
pub fn registration_values() -> clap::builder::PossibleValuesParser {
    use clap::builder::PossibleValue;
    clap::builder::PossibleValuesParser::new([
        PossibleValue::new("refit").help(
            "the test campaign's tracker frame and probe mounting, registered on its own points (another \
             station, another day)",
        ),
        PossibleValue::new("model").help("the model's registration (same station and probe)"),
    ])
}
