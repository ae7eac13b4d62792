//! `calibrate --data FILE.csv [--robot URDF] [--method M] [--truth truth.csv] [--out DIR]`: fits a calibration
//! method on measured data, prints the paper's Table 1 (and Table 2 with measured orientation) for the test
//! split, and writes `report.json`, `model.json` and `predictions.csv`.
//!
//! `--mapping FILE.toml` reads a foreign export (delimiter, decimal comma, units, orientation convention; see
//! `calibench::dataset::mapping`); `--test-data FILE` fits on all of `--data` (train and validation) and tests
//! on another campaign, re-registering its tracker frame and probe mounting on its own points.
//!
//! `calibrate apply --model model.json --data FILE.csv [--out FILE]`: predicted poses and corrected joint
//! commands for new joint configurations.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use clap::{Args, Parser, Subcommand};
use nalgebra::{Point3, UnitQuaternion};
use serde::Serialize;
use serde_json::json;

use calibench::calib::method::{FitContext, Fitted};
use calibench::calib::registry::{self, MethodKind, Save, SavedModel};
use calibench::calib::regression::RegressionOptions;
use calibench::calib::tracker_frame::Observation;
use calibench::dataset::mapping::ColumnMapping;
use calibench::dataset::{Dataset, Split, TruthTable, random_split, random_train_val};
use calibench::eval::Stats;
use calibench::eval::transfer::{self, TestRegistration};
use calibench::robot::dh::DhChain;
use calibench::robot::{Payload, urdf};
use calibench::{Error, Result, output};

#[derive(Parser, Debug)]
#[command(
    version,
    about = "Calibrate a robot from laser-tracker measurements",
    args_conflicts_with_subcommands = true
)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
    #[command(flatten)]
    fit: FitArgs,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Predict poses and corrected joint commands for new configurations with a saved model.
    Apply(ApplyArgs),
}

#[derive(Args, Debug)]
struct FitArgs {
    /// Measurements (the `measurements.csv` format; see results/README.md), or any export with `--mapping`.
    #[arg(long)]
    data: Option<PathBuf>,
    /// A column mapping (TOML) for reading a foreign export: columns, delimiter, decimal separator, units,
    /// orientation convention, extra inputs. See `mappings/ipa_ur10.toml`.
    #[arg(long)]
    mapping: Option<PathBuf>,
    /// Test on this campaign instead of a test split of `--data` (which then splits into training and
    /// validation only, in the ratio of the first two `--split` fractions).
    #[arg(long)]
    test_data: Option<PathBuf>,
    /// The mapping of `--test-data` [default: `--mapping`].
    #[arg(long)]
    test_mapping: Option<PathBuf>,
    /// refit: register the test campaign's tracker frame and probe mounting on its own points (another
    /// station, another day); model: use the model's registration (same station and probe).
    #[arg(long, default_value = "refit")]
    test_registration: String,
    /// Drop the data's extra inputs (e.g. temperature) so no method regresses on them.
    #[arg(long)]
    ignore_inputs: bool,
    /// The robot's URDF; its joint names name the joint columns.
    #[arg(long, default_value = "robots/iiwa7.urdf")]
    robot: PathBuf,
    /// The link carrying the reflectors [default: the chain's last link].
    #[arg(long)]
    flange_link: Option<String>,
    /// nominal | paper-rotz | paper-rotxyz | paper-rotxyz-transxyz | kinematic | elastic | residual-ridge |
    /// hybrid | hybrid-kinematic
    #[arg(long, default_value = "paper-rotxyz")]
    method: String,
    /// Mass on the flange (kg), for the gravity torques of the elastic methods.
    #[arg(long, default_value_t = 0.0)]
    payload_kg: f64,
    /// Its centre of mass in the flange frame (m), x,y,z.
    #[arg(long, value_delimiter = ',', default_value = "0,0,0")]
    payload_com_m: Vec<f64>,
    /// Ground truth (`truth.csv` of a simulated campaign) to evaluate against.
    #[arg(long)]
    truth: Option<PathBuf>,
    /// Output directory.
    #[arg(long, default_value = "results/calibrate")]
    out: PathBuf,
    /// Train, validation and test fractions, used when the data has no `split` column.
    #[arg(long, value_delimiter = ',', default_value = "0.5,0.25,0.25")]
    split: Vec<f64>,
    /// Seed of the random split.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Highest polynomial degree the regression may choose.
    #[arg(long, default_value_t = 5)]
    max_degree: usize,
    /// Add pairwise products of the inputs to the polynomial features (eq. 18 has none).
    #[arg(long)]
    cross_terms: bool,
}

#[derive(Args, Debug)]
struct ApplyArgs {
    /// A `model.json` written by `calibrate`.
    #[arg(long)]
    model: PathBuf,
    /// Joint configurations: a CSV with one column per joint of the model (extra columns are ignored).
    #[arg(long)]
    data: PathBuf,
    /// A column mapping (TOML) for reading `--data` (only its joint columns and `point_id` are used; extra
    /// inputs such as the temperature take their training means).
    #[arg(long)]
    mapping: Option<PathBuf>,
    /// Output CSV.
    #[arg(long, default_value = "results/calibrate/applied.csv")]
    out: PathBuf,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match &cli.command {
        Some(Command::Apply(args)) => apply(args),
        None => fit(&cli.fit),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

/// Distance statistics in millimetres, as `report.json` names them.
#[derive(Serialize)]
struct MmStats {
    n: usize,
    mean_mm: f64,
    max_mm: f64,
    std_mm: f64,
    rms_mm: f64,
    p95_mm: f64,
}

/// Angle statistics in radians.
#[derive(Serialize)]
struct RadStats {
    n: usize,
    mean_rad: f64,
    max_rad: f64,
    std_rad: f64,
    rms_rad: f64,
    p95_rad: f64,
}

fn stats_of(values: &[f64]) -> Result<Stats> {
    Stats::of(values).ok_or_else(|| Error::Invalid("no finite errors to summarize".into()))
}

fn mm(values: &[f64]) -> Result<MmStats> {
    let s = stats_of(values)?.scaled(1e3);
    Ok(MmStats {
        n: s.n,
        mean_mm: s.mean,
        max_mm: s.max,
        std_mm: s.std,
        rms_mm: s.rms,
        p95_mm: s.p95,
    })
}

fn rad(values: &[f64]) -> Result<RadStats> {
    let s = stats_of(values)?;
    Ok(RadStats {
        n: s.n,
        mean_rad: s.mean,
        max_rad: s.max,
        std_rad: s.std,
        rms_rad: s.rms,
        p95_rad: s.p95,
    })
}

/// Errors of the nominal model ("before") and of the fitted one ("after") against observations.
struct Errors {
    before: Vec<f64>,
    after: Vec<f64>,
    linearized: Vec<f64>,
    orientation_before: Vec<f64>,
    orientation_after: Vec<f64>,
}

fn errors(model: &dyn Fitted, observations: &[Observation]) -> Errors {
    let mut e = Errors {
        before: Vec::new(),
        after: Vec::new(),
        linearized: Vec::new(),
        orientation_before: Vec::new(),
        orientation_after: Vec::new(),
    };
    for o in observations {
        let (nominal_p, nominal_r) = model.nominal(&o.q);
        let pred = model.predict_with(&o.q, &o.inputs);
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

fn errors_json(e: &Errors) -> Result<serde_json::Value> {
    let mut v = json!({ "before": mm(&e.before)?, "after": mm(&e.after)? });
    // The linearized prediction (eq. 10) is reported when it differs from the full one by more than a micrometre.
    let gap = e
        .after
        .iter()
        .zip(&e.linearized)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    if gap > 1e-6 {
        v["after_linearized"] = serde_json::to_value(mm(&e.linearized)?).expect("plain numbers");
    }
    if !e.orientation_before.is_empty() {
        v["orientation"] =
            json!({ "before": rad(&e.orientation_before)?, "after": rad(&e.orientation_after)? });
    }
    Ok(v)
}

fn fit(args: &FitArgs) -> Result<()> {
    let data_path = args.data.as_ref().ok_or_else(|| {
        Error::Invalid("--data FILE.csv is required (or use `calibrate apply`)".into())
    })?;
    let kind = MethodKind::parse(&args.method)?;
    let payload = match args.payload_com_m.as_slice() {
        [x, y, z] if args.payload_kg.is_finite() && args.payload_kg >= 0.0 => Payload {
            mass: args.payload_kg,
            com: [*x, *y, *z],
        },
        _ => {
            return Err(Error::Invalid(
                "--payload-kg must be finite and non-negative, --payload-com-m three numbers x,y,z"
                    .into(),
            ));
        }
    };
    let chain = urdf::load_file(&args.robot, args.flange_link.as_deref())?;
    let dh = DhChain::from_chain(&chain)?;
    let mapping = args
        .mapping
        .as_deref()
        .map(ColumnMapping::load)
        .transpose()?;
    let read = |path: &Path, mapping: Option<&ColumnMapping>| -> Result<Dataset> {
        let mut data = match mapping {
            Some(m) => m.read(path, &chain)?,
            None => Dataset::read(path, &chain.joint_names())?,
        };
        if args.ignore_inputs {
            data.extra_inputs = None;
        }
        Ok(data)
    };
    let data = read(data_path, mapping.as_ref())?;
    let test_file = match &args.test_data {
        Some(path) => {
            let test_mapping = match &args.test_mapping {
                Some(p) => Some(ColumnMapping::load(p)?),
                None => mapping.clone(),
            };
            Some(read(path, test_mapping.as_ref())?)
        }
        None => None,
    };
    let test_mode = TestRegistration::parse(&args.test_registration)?;
    if test_file.is_some() && args.truth.is_some() {
        return Err(Error::Invalid(
            "--truth belongs to the test split of --data; it cannot be combined with --test-data"
                .into(),
        ));
    }
    let truth = match &args.truth {
        Some(path) => Some(TruthTable::read(path)?.aligned_to(&data)?),
        None => None,
    };
    let f: [f64; 3] = args.split.as_slice().try_into().map_err(|_| {
        Error::Invalid(format!(
            "--split needs three fractions (train,val,test), got {}",
            args.split.len()
        ))
    })?;
    let labels = match (&data.split, &test_file) {
        (Some(labels), _) => labels.clone(),
        (None, None) => random_split(data.len(), f, args.seed)?,
        (None, Some(_)) => random_train_val(data.len(), f[0] / (f[0] + f[1]), args.seed)?,
    };
    let indices =
        |s: Split| -> Vec<usize> { (0..data.len()).filter(|&i| labels[i] == s).collect() };
    let (i_train, i_val, i_test) = (
        indices(Split::Train),
        indices(Split::Val),
        indices(Split::Test),
    );
    if i_test.is_empty() && test_file.is_none() {
        return Err(Error::Invalid("the test split is empty".into()));
    }
    let (train, val) = (data.subset(&i_train), data.subset(&i_val));
    let test = match &test_file {
        Some(t) => t.clone(),
        None => data.subset(&i_test),
    };
    let options = RegressionOptions {
        max_degree: args.max_degree,
        cross_terms: args.cross_terms,
        ..RegressionOptions::default()
    };

    let started = Instant::now();
    let ctx = FitContext {
        chain: &chain,
        dh: &dh,
        payload,
        regression: options,
    };
    let model = registry::fit(kind, &ctx, &train, &val)?;
    let model = model.as_ref();
    let fit_ms = started.elapsed().as_secs_f64() * 1e3;

    let (obs_test, test_errors, test_registration) = match &test_file {
        None => {
            let obs = model.registration().observe(&test)?;
            let e = errors(model, &obs);
            (obs, e, None)
        }
        Some(t) => {
            let after = transfer::evaluate(model, t, test_mode)?;
            // "Before": the nominal kinematics, registered on the test campaign the same way.
            let nominal = match kind {
                MethodKind::Nominal => None,
                _ => Some(registry::fit(MethodKind::Nominal, &ctx, &train, &val)?),
            };
            let before = transfer::evaluate(nominal.as_deref().unwrap_or(model), t, test_mode)?;
            let obs = after.registration.observe(t)?;
            let fitted_on_test = after.describe();
            let e = Errors {
                before: before.errors.position,
                after: after.errors.position.clone(),
                linearized: after.errors.position,
                orientation_before: before.errors.orientation,
                orientation_after: after.errors.orientation,
            };
            let r = &after.registration;
            let described = json!({
                "mode": test_mode,
                "fitted_on_test_data": fitted_on_test,
                "tracker_to_base": r.frame.tracker_to_base,
                "mounting_m": r.frame.mounting,
                "probe_rotation": r.probe_rotation,
                "rms_mm": r.frame.rms * 1e3,
            });
            (obs, e, Some(described))
        }
    };
    let registration = model.registration();
    let mut report = json!({
        "method": model.method(),
        "data": data_path.display().to_string(),
        "robot": args.robot.display().to_string(),
        "n_train": train.len(),
        "n_val": val.len(),
        "n_test": test.len(),
        "fit_ms": fit_ms,
        "registration": {
            "tracker_to_base": registration.frame.tracker_to_base,
            "mounting_m": registration.frame.mounting,
            "probe_rotation": registration.probe_rotation,
            "rms_mm": registration.frame.rms * 1e3,
        },
        "test": errors_json(&test_errors)?,
    });
    let fitted_on_test = test_registration
        .as_ref()
        .and_then(|d| d["fitted_on_test_data"].as_str())
        .map(String::from);
    if let Some(described) = test_registration {
        report["test_data"] = json!(test.origin);
        report["test_registration"] = described;
    }
    if !model.input_names().is_empty() {
        report["extra_inputs"] = json!(model.input_names());
    }
    // The method's own facts (kept parameters, R², rank, …) sit at the top level beside the common ones.
    if let (Some(target), serde_json::Value::Object(extra)) =
        (report.as_object_mut(), model.report(&obs_test))
    {
        target.extend(extra);
    }
    let truth_errors = match &truth {
        Some(t) => {
            let t_test = t.subset(&i_test);
            let obs_truth = registration.observe_points(&test.q, &t_test.in_tracker)?;
            let e = errors(model, &obs_truth);
            report["truth"] = errors_json(&e)?;
            Some(e)
        }
        None => None,
    };

    let predictions = predictions_csv(model, &data, &labels)?;
    output::write_files(
        &args.out,
        &[
            ("report.json", to_json(&report)?),
            ("model.json", to_json(&model.save())?),
            ("predictions.csv", predictions),
        ],
    )?;

    let what = match (&test_file, fitted_on_test) {
        (Some(t), Some(fitted)) => format!("on {}; fitted on it: {fitted}", t.origin),
        _ => "on the test split".to_string(),
    };
    print_tables(model.method(), &what, &test_errors, truth_errors.as_ref())?;
    println!(
        "fit on {} training + {} validation points in {fit_ms:.1} ms; wrote {}",
        train.len(),
        val.len(),
        args.out.display()
    );
    Ok(())
}

fn to_json(value: &impl Serialize) -> Result<Vec<u8>> {
    serde_json::to_vec_pretty(value).map_err(|e| Error::Invalid(format!("cannot serialize: {e}")))
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

fn print_tables(method: &str, what: &str, test: &Errors, truth: Option<&Errors>) -> Result<()> {
    let table =
        |title: &str, unit: &str, before: &[f64], after: &[f64], scale: f64| -> Result<()> {
            let (b, a) = (
                stats_of(before)?.scaled(scale),
                stats_of(after)?.scaled(scale),
            );
            println!("{title} ({unit}), n = {}", b.n);
            println!("  {:<6} {:>10} {:>22}", "Error", "Measured", method);
            for (name, x, y) in [
                ("mean", b.mean, a.mean),
                ("max", b.max, a.max),
                ("std", b.std, a.std),
                ("rms", b.rms, a.rms),
                ("p95", b.p95, a.p95),
            ] {
                println!("  {name:<6} {x:>10.4} {y:>22.4}");
            }
            Ok(())
        };
    table(
        &format!("Table 1. Positional errors {what}"),
        "mm",
        &test.before,
        &test.after,
        1e3,
    )?;
    if !test.orientation_before.is_empty() {
        table(
            &format!("Table 2. Orientational errors {what}"),
            "rad",
            &test.orientation_before,
            &test.orientation_after,
            1.0,
        )?;
    }
    if let Some(t) = truth {
        table(
            "Against the truth: positional errors on the test split",
            "mm",
            &t.before,
            &t.after,
            1e3,
        )?;
        if !t.orientation_before.is_empty() {
            table(
                "Against the truth: orientational errors on the test split",
                "rad",
                &t.orientation_before,
                &t.orientation_after,
                1.0,
            )?;
        }
    }
    Ok(())
}

fn apply(args: &ApplyArgs) -> Result<()> {
    let text = std::fs::read_to_string(&args.model).map_err(|e| Error::Data {
        origin: args.model.display().to_string(),
        message: format!("cannot read: {e}"),
    })?;
    let saved: SavedModel = serde_json::from_str(&text).map_err(|e| Error::Data {
        origin: args.model.display().to_string(),
        message: format!("not a calibrate model: {e}"),
    })?;
    let model = saved.into_fitted();
    let joint_names = model.joint_names().to_vec();
    let (ids, configurations) = match &args.mapping {
        Some(path) => {
            let prismatic: Vec<bool> = model.dh().rows.iter().map(|r| r.prismatic).collect();
            ColumnMapping::load(path)?.read_joints(&args.data, &joint_names, &prismatic)?
        }
        None => calibench::dataset::read_joints(&args.data, &joint_names)?,
    };
    let mut w = csv::Writer::from_writer(Vec::new());
    let csv_err = |e: csv::Error| Error::Invalid(format!("{}: {e}", args.out.display()));
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
    w.write_record(&header).map_err(csv_err)?;
    // A configuration where the inverse is undefined (a singular pose, such as a straight arm) still gets its
    // prediction; its command cells stay empty and `status` says why, so one such row does not cost the file.
    let mut singular = 0;
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
                row.push(format!("no command: {e}"));
            }
        }
        w.write_record(&row).map_err(csv_err)?;
    }
    let bytes = w
        .into_inner()
        .map_err(|e| Error::Invalid(format!("{}: {e}", args.out.display())))?;
    let (dir, name) = split_path(&args.out)?;
    output::write_files(dir, &[(name, bytes)])?;
    println!(
        "{} configurations: predicted poses and corrected commands in {}{}",
        ids.len(),
        args.out.display(),
        if singular > 0 {
            format!(" ({singular} without a command: the inverse is undefined there, see `status`)")
        } else {
            String::new()
        }
    );
    Ok(())
}

fn split_path(path: &Path) -> Result<(&Path, &str)> {
    let name = path
        .file_name()
        .and_then(|n| n.to_str())
        .ok_or_else(|| Error::Invalid(format!("--out {} is not a file name", path.display())))?;
    Ok((
        path.parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new(".")),
        name,
    ))
}
