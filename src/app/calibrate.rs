//! The `calibrate` job: [`fit`] a method on measured data and judge it on a test split or another campaign
//! (`report.json`, `model.json`, `predictions.csv`, the paper's Tables 1 and 2), in steps that each return
//! what the next needs: read, fit, judge, report, write, tables. Applying a saved model is [`super::apply`].

use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::Serialize;
use serde_json::{Map, Value};

use crate::calib::clock::{self, ClockOffset};
use crate::calib::method::{FitContext, Fitted};
use crate::calib::motion_inputs::with_motion_inputs;
use crate::calib::registry::{MethodKind, REFERENCE, Save};
use crate::calib::regression::RegressionOptions;
use crate::calib::tracker_frame::Observation;
use crate::dataset::mapping::ColumnMapping;
use crate::dataset::range::JointRange;
use crate::dataset::{Dataset, TruthTable};
use crate::error::{Error, Result};
use crate::eval::iso_cubes::{self, CubesReport, Side};
use crate::eval::split::{Parts, SplitRule};
use crate::eval::tables::{BeforeAfter, BeforeAfterSummary, PointPrediction};
use crate::eval::transfer::{self, TestRegistration};
use crate::output;
use crate::robot::dh::DhChain;
use crate::robot::{Chain, Payload};

use super::calibration_report::{
    CalibrationReport, ClockReport, RegistrationReport, TestRegistrationReport, worse_than_nominal,
};
use super::predictions::{TestPredicted, predict_all, predictions_csv};
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

const BAD_PAYLOAD: &str =
    "--payload-kg must be finite and non-negative, --payload-com-m three numbers x,y,z";

/// The payload of `--payload-kg` and `--payload-com-m`, checked before any file is read.
pub fn payload(mass_kg: f64, com_m: &[f64]) -> Result<Payload> {
    match (com_m, mass_kg) {
        ([x, y, z], mass) if mass.is_finite() && mass >= 0.0 => Ok(Payload {
            mass,
            com: [*x, *y, *z],
        }),
        _ => Err(Error::Invalid(BAD_PAYLOAD.into())),
    }
}

/// The clock offset is searched within ±this (s): far beyond a synchronised controller's and tracker's.
pub const CLOCK_BOUND_S: f64 = 0.05;

/// What [`fit`] did, for the binary to print.
#[derive(Clone, Debug)]
pub struct FitOutcome {
    pub report: CalibrationReport,
    /// Tables 1 and 2 on the test data, then against the truth when given.
    pub tables: String,
    /// Where the files went.
    pub out: PathBuf,
}

impl FitOutcome {
    /// What `calibrate` prints: the tables, then what was fitted and where the files went (the report's
    /// warnings go to stderr apart).
    pub fn text(&self) -> String {
        let (r, out) = (&self.report, self.out.display());
        let (train, val, ms) = (r.n_train, r.n_val, r.fit_ms);
        let tables = &self.tables;
        format!(
            "{tables}fit on {train} training + {val} validation points in {ms:.1} ms; wrote {out}\n"
        )
    }
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
    let inputs = read(options)?;
    let pair = fit_pair(options, &inputs)?;
    let predicted = predict_all(pair.model(), &inputs.data);
    // `predictions.csv` (every point's prediction written out) needs only the model: made on another core
    // while the model is judged.
    std::thread::scope(|s| {
        let (data, labels) = (&inputs.data, &inputs.parts.labels);
        let predictions = s.spawn(|| predictions_csv(pair.model(), data, labels, &predicted));
        let judged = judge(options, &inputs, &pair, &predicted)?;
        let points = test_points(&inputs, &pair, &judged)?;
        let report = report(options, &inputs, &pair, &judged, points.outside);
        let files = Files {
            predictions: joined(predictions)?,
            test_points: points.csv,
        };
        write(options, &pair, &report, files)?;
        let tables = tables(&inputs, &pair, &report, &judged)?;
        Ok(FitOutcome {
            report,
            tables,
            out: options.out.clone(),
        })
    })
}

/// What a scoped thread returned; its panic goes on in the caller.
fn joined<T>(handle: std::thread::ScopedJoinHandle<'_, T>) -> T {
    handle
        .join()
        .unwrap_or_else(|panic| std::panic::resume_unwind(panic))
}

/// What [`fit`] reads: the robot, the data (synchronised), the test campaign or split, the truth.
struct Inputs {
    chain: Chain,
    dh: DhChain,
    data: Dataset,
    /// The clock offset removed from data measured on the fly.
    clock_offset: Option<ClockOffset>,
    /// With `--test-data`: the test campaign, read and synchronised as `data`.
    test_file: Option<Dataset>,
    /// The truth of `data`, aligned to its points.
    truth: Option<TruthTable>,
    parts: Parts,
}

impl Inputs {
    /// Where the model is judged: the test campaign, else the test split.
    fn test(&self) -> &Dataset {
        self.test_file.as_ref().unwrap_or(&self.parts.test)
    }

    fn ctx(&self, options: &FitOptions) -> FitContext<'_> {
        FitContext {
            share: None,
            chain: &self.chain,
            dh: &self.dh,
            payload: options.payload,
            regression: options.regression.clone(),
        }
    }
}

/// The robot (its chain and the DH form the fits work in) and the column mapping a measured file is read with.
pub(crate) fn robot_and_mapping(
    robot: &Path,
    flange_link: Option<&str>,
    mapping: Option<&Path>,
) -> Result<(Chain, DhChain, Option<ColumnMapping>)> {
    let chain = crate::robot::load(robot, flange_link)?;
    let dh = DhChain::from_chain(&chain)?;
    let mapping = mapping.map(ColumnMapping::load).transpose()?;
    Ok((chain, dh, mapping))
}

/// Reads the robot, the data and the test campaign (each checked against the joint ranges and synchronised),
/// the truth, and splits the data.
fn read(options: &FitOptions) -> Result<Inputs> {
    // The truth (another whole file) is read on another core meanwhile, when it will be needed.
    std::thread::scope(|s| {
        let truth = match (&options.truth, &options.test_data) {
            (Some(path), None) => Some(s.spawn(|| TruthTable::read(path))),
            _ => None,
        };
        read_with(options, truth)
    })
}

/// [`read`], the truth's file being read by `reading` when given.
fn read_with(
    options: &FitOptions,
    reading: Option<std::thread::ScopedJoinHandle<'_, Result<TruthTable>>>,
) -> Result<Inputs> {
    let (chain, dh, mapping) = robot_and_mapping(
        &options.robot,
        options.flange_link.as_deref(),
        options.mapping.as_deref(),
    )?;
    // Measured on the fly, a campaign is corrected for the clock offset first (in `read_measured`); with
    // `--motion-inputs` its motion then becomes the methods' inputs.
    let measured = |path: &Path, mapping: Option<&ColumnMapping>| {
        let (data, offset) = read_measured(
            path,
            mapping,
            (&chain, &dh),
            &options.robot,
            options.ignore_inputs,
        )?;
        if !options.motion_inputs {
            return Ok::<_, Error>((data, offset));
        }
        Ok((with_motion_inputs(&data, &chain, &options.payload)?, offset))
    };
    let (data, clock_offset) = measured(&options.data, mapping.as_ref())?;
    let test_file = match &options.test_data {
        Some(path) => {
            let test_mapping = match &options.test_mapping {
                Some(p) => Some(ColumnMapping::load(p)?),
                None => mapping.clone(),
            };
            Some(measured(path, test_mapping.as_ref())?.0)
        }
        None => None,
    };
    if test_file.is_some() && options.truth.is_some() {
        return Err(Error::Invalid(
            "--truth belongs to the test split of --data; it cannot be combined with --test-data"
                .into(),
        ));
    }
    let truth = match (&options.truth, reading) {
        (Some(_), Some(reading)) => Some(joined(reading)?.aligned_to(&data)?),
        (Some(path), None) => Some(TruthTable::read(path)?.aligned_to(&data)?),
        (None, _) => None,
    };
    let parts = options.split.apply(&data, test_file.is_some())?;
    if parts.test_indices.is_empty() && test_file.is_none() {
        return Err(Error::Invalid("the test split is empty".into()));
    }
    Ok(Inputs {
        chain,
        dh,
        data,
        clock_offset,
        test_file,
        truth,
        parts,
    })
}

/// A measured file as `calibrate` reads it: through `mapping` or in the `measurements.csv` format, without its
/// extra inputs when `ignore_inputs`, checked against the joint ranges of the robot (read from `robot`), and,
/// when measured on the fly (a `time` column), corrected for the clock offset between tracker and controller
/// (`calib::clock`), after which every method fits on the corrected samples as on points.
pub(super) fn read_measured(
    path: &Path,
    mapping: Option<&ColumnMapping>,
    (chain, dh): (&Chain, &DhChain),
    robot: &Path,
    ignore_inputs: bool,
) -> Result<(Dataset, Option<ClockOffset>)> {
    let mut data = match mapping {
        Some(m) => m.read(path, chain)?,
        None => Dataset::read(path, &chain.joint_names())?,
    };
    if ignore_inputs {
        data.extra_inputs = None;
    }
    JointRange::of_chain(chain, &robot.display().to_string()).check(
        &data.origin,
        &data.point_ids,
        &data.q,
    )?;
    if data.time.is_none() {
        return Ok((data, None));
    }
    let found = clock::estimate(dh, &data, CLOCK_BOUND_S)
        .map_err(|e| e.in_data(&data.origin, "estimating the clock offset"))?;
    Ok((clock::corrected(&data, found.offset_s)?, Some(found)))
}

/// The method's model, and the nominal model that measures "before" unless the method is the nominal one.
struct FittedPair {
    model: Box<dyn Fitted>,
    nominal: Option<Box<dyn Fitted>>,
    fit_ms: f64,
}

impl FittedPair {
    fn model(&self) -> &dyn Fitted {
        self.model.as_ref()
    }

    fn nominal(&self) -> &dyn Fitted {
        self.nominal.as_deref().unwrap_or(self.model())
    }
}

/// Fits the method on the training and validation parts, timed, then the nominal model.
fn fit_pair(options: &FitOptions, inputs: &Inputs) -> Result<FittedPair> {
    let (train, val) = (&inputs.parts.train, &inputs.parts.val);
    let ctx = inputs.ctx(options);
    std::thread::scope(|s| {
        // "Measured" (before) is one number per data set: the nominal kinematics under the nominal model's
        // own registration, whatever the method (a method's refined registration is reported apart). It
        // does not depend on the method's fit, so it is fitted beside it, on another core.
        let nominal =
            (options.method != REFERENCE).then(|| s.spawn(|| REFERENCE.fit(&ctx, train, val)));
        let started = Instant::now();
        let fitting = format!("fitting {}", options.method.info());
        let model = options
            .method
            .fit(&ctx, train, val)
            .map_err(|e| e.in_data(&inputs.data.origin, &fitting))?;
        let fit_ms = started.elapsed().as_secs_f64() * 1e3;
        Ok(FittedPair {
            model,
            nominal: nominal.map(joined).transpose()?,
            fit_ms,
        })
    })
}

/// The model judged on the test points, and against the truth when given.
struct Judged {
    /// The test points under the model's registration (the method reports its own facts on them).
    observed: Vec<Observation>,
    errors: BeforeAfter,
    summary: BeforeAfterSummary,
    /// With `--test-data`: how the test campaign was registered.
    registration: Option<TestRegistrationReport>,
    /// The parameters the test registration fitted on the test points.
    refitted: usize,
    /// With `--test-registration refit`: the test points through the model's own registration.
    kept: Option<BeforeAfterSummary>,
    truth: Option<(BeforeAfter, BeforeAfterSummary)>,
    /// ISO 9283's AP and RP on the test points' cubes, where they repeat cube points.
    iso: Option<CubesReport>,
}

/// `predicted`: the model's [`predict_all`] of the data.
fn judge(
    options: &FitOptions,
    inputs: &Inputs,
    pair: &FittedPair,
    predicted: &[PointPrediction],
) -> Result<Judged> {
    match &inputs.test_file {
        None => {
            let test_predicted = TestPredicted::of(
                inputs.test(),
                &inputs.parts.test_indices,
                (pair.model(), predicted),
                pair.nominal.as_deref(),
            );
            let mut judged = judge_split(inputs, pair, &test_predicted)?;
            judged.truth = judge_truth(inputs, pair, &test_predicted)?;
            Ok(judged)
        }
        // `--truth` is refused with `--test-data` (`read_with`).
        Some(t) => judge_campaign(options, t, pair),
    }
}

/// On the test split, each model under its own registration.
fn judge_split(inputs: &Inputs, pair: &FittedPair, predicted: &TestPredicted) -> Result<Judged> {
    let (model, test, origin) = (pair.model(), inputs.test(), &inputs.data.origin);
    let observed = model
        .registration()
        .observe(test)
        .map_err(|e| e.in_data(origin, "the test split"))?;
    let nominal_obs = pair
        .nominal
        .is_some()
        .then(|| pair.nominal().registration().observe(test))
        .transpose()
        .map_err(|e| e.in_data(origin, "the test split"))?;
    let errors = predicted.errors(&observed, nominal_obs.as_deref());
    let (nominal, registration) = (pair.nominal(), pair.nominal().registration());
    let iso = iso_cubes::cubes(
        test,
        &Side {
            model: nominal,
            registration,
        },
        &Side {
            model,
            registration: model.registration(),
        },
    )?;
    Ok(Judged {
        observed,
        summary: errors.summary()?,
        errors,
        registration: None,
        refitted: 0,
        kept: None,
        truth: None,
        iso,
    })
}

/// On another campaign, registered as `--test-registration` says.
fn judge_campaign(options: &FitOptions, t: &Dataset, pair: &FittedPair) -> Result<Judged> {
    let (model, nominal_model) = (pair.model(), pair.nominal());
    let mode = options.test_registration;
    let after = transfer::evaluate(model, t, mode)
        .map_err(|e| e.in_data(&t.origin, "registering the test campaign"))?;
    // "Before": the nominal kinematics, registered on the test campaign the same way.
    let before = transfer::evaluate(nominal_model, t, mode)?;
    let observed = after.registration.observe(t)?;
    let mut kept = None;
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
    let errors = BeforeAfter::transferred(&before, &after);
    let iso = iso_cubes::cubes(
        t,
        &Side {
            model: nominal_model,
            registration: &before.registration,
        },
        &Side {
            model,
            registration: &after.registration,
        },
    )?;
    Ok(Judged {
        observed,
        summary: errors.summary()?,
        errors,
        registration: Some(described),
        refitted: after.refitted_parameters(),
        kept,
        truth: None,
        iso,
    })
}

/// Against the true positions of the test split's points, with `--truth`.
fn judge_truth(
    inputs: &Inputs,
    pair: &FittedPair,
    predicted: &TestPredicted,
) -> Result<Option<(BeforeAfter, BeforeAfterSummary)>> {
    let Some(t) = &inputs.truth else {
        return Ok(None);
    };
    let (model, test) = (pair.model(), inputs.test());
    let t_test = t.subset(&inputs.parts.test_indices);
    let mut obs_truth = model
        .registration()
        .observe_points(&test.q, &t_test.in_tracker)?;
    // Each point with its own inputs (its temperature, its motion), as the measured test split has them.
    for (i, o) in obs_truth.iter_mut().enumerate() {
        o.inputs = test.extra_inputs_of(i).to_vec();
    }
    let nominal_truth = if pair.nominal.is_some() {
        let mut obs = pair
            .nominal()
            .registration()
            .observe_points(&test.q, &t_test.in_tracker)?;
        // The same inputs for the nominal model's (they do not move it: it has no regression), so its
        // predictions of the test points serve here too.
        for (o, m) in obs.iter_mut().zip(&obs_truth) {
            o.inputs.clone_from(&m.inputs);
        }
        Some(obs)
    } else {
        None
    };
    let e = predicted.errors(&obs_truth, nominal_truth.as_deref());
    let summary = e.summary()?;
    Ok(Some((e, summary)))
}

/// `test_points.csv`, and how many test points lie outside the model's training domain.
struct TestPoints {
    csv: Vec<u8>,
    outside: usize,
}

/// Per test point: inside the model's training domain or not (outside, its regression is left out).
fn test_points(inputs: &Inputs, pair: &FittedPair, judged: &Judged) -> Result<TestPoints> {
    let test = inputs.test();
    let placements = test_points::place_all(pair.model(), test);
    let (csv, outside) = test_points::test_points_csv(
        &test.point_ids,
        &placements,
        &judged.errors.before,
        &judged.errors.after,
    )?;
    Ok(TestPoints { csv, outside })
}

/// `report.json`'s content, with the warnings the user must read.
fn report(
    options: &FitOptions,
    inputs: &Inputs,
    pair: &FittedPair,
    judged: &Judged,
    outside: usize,
) -> CalibrationReport {
    let (model, test) = (pair.model(), inputs.test());
    let mut report = CalibrationReport {
        method: model.method().to_string(),
        data: options.data.display().to_string(),
        robot: options.robot.display().to_string(),
        n_train: inputs.parts.train.len(),
        n_val: inputs.parts.val.len(),
        n_test: test.len(),
        fit_ms: pair.fit_ms,
        registration: RegistrationReport::of(model.registration()),
        test: judged.summary.clone(),
        test_data: judged.registration.as_ref().map(|_| test.origin.clone()),
        test_registration: judged.registration.clone(),
        test_model_registration: judged.kept.clone(),
        extra_inputs: Some(model.input_names().to_vec()).filter(|n| !n.is_empty()),
        method_facts: match model.report(&judged.observed) {
            Value::Object(facts) => facts,
            _ => Map::new(),
        },
        truth: judged.truth.as_ref().map(|(_, s)| s.clone()),
        worse_than_nominal: false,
        warnings: Vec::new(),
        test_outside_domain: outside,
        iso9283: judged.iso.clone(),
        clock_offset: inputs.clock_offset.as_ref().map(|c| ClockReport {
            offset_s: c.offset_s,
            rms_mm: c.rms_m * 1e3,
            rms_at_zero_mm: c.rms_at_zero_m * 1e3,
        }),
    };
    report
        .warnings
        .extend(worse_than_nominal(&report.test, &what_test(&report)));
    report.worse_than_nominal = !report.warnings.is_empty();
    let refitted = judged.refitted;
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
    // Only a regression extrapolates: a model without one (a kinematic fit) has nothing to fade out there.
    if outside > 0 && model.has_regression() {
        report.warnings.push(format!(
            "{outside} of {} test points lie outside the model's training domain (joint or input ranges, or \
             far from every training configuration; `status` in test_points.csv); a regression is not \
             extrapolated there, the model falls back to its parametric part",
            test.len()
        ));
    }
    report
}

/// The fit's CSV files.
struct Files {
    predictions: Vec<u8>,
    test_points: Vec<u8>,
}

/// Writes the fit's files, all or none.
fn write(
    options: &FitOptions,
    pair: &FittedPair,
    report: &CalibrationReport,
    files: Files,
) -> Result<()> {
    let model = pair.model();
    output::write_dir(
        &options.out,
        &[
            ("report.json", to_json(&to_value(report)?)?),
            ("model.json", to_json(&model.save()?)?),
            ("predictions.csv", files.predictions),
            ("test_points.csv", files.test_points),
        ],
        &[],
    )
}

/// Tables 1 and 2 on the test points, what the clock and the model's own registration did, and the tables
/// against the truth.
fn tables(
    inputs: &Inputs,
    pair: &FittedPair,
    report: &CalibrationReport,
    judged: &Judged,
) -> Result<String> {
    let method = pair.model().method();
    let what = match &report.test_registration {
        Some(r) => format!(
            "on {}; fitted on it: {}",
            inputs.test().origin,
            r.fitted_on_test_data
        ),
        None => "on the test split".to_string(),
    };
    let mut tables = judged.errors.tables(
        method,
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
    if let Some(iso) = &judged.iso {
        tables += &iso.table();
    }
    if let Some((t, _)) = &judged.truth {
        tables += &t.tables(
            method,
            "Against the truth: positional errors on the test split",
            "Against the truth: orientational errors on the test split",
        )?;
    }
    Ok(tables)
}

/// What the test set is, for a warning.
fn what_test(report: &CalibrationReport) -> String {
    match &report.test_data {
        Some(t) => format!("on {t}"),
        None => "on the test split".into(),
    }
}

fn to_json(value: &impl Serialize) -> Result<Vec<u8>> {
    serde_json::to_vec_pretty(value).map_err(|e| Error::Invalid(format!("cannot serialize: {e}")))
}

/// As a [`Value`], whose maps sort their keys.
fn to_value(value: &impl Serialize) -> Result<Value> {
    serde_json::to_value(value).map_err(|e| Error::Invalid(format!("cannot serialize: {e}")))
}
