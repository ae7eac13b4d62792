//! The `calibrate` binary end to end on small simulated campaigns: the documented fields of `report.json`,
//! the tables on stdout, a `split` column in the data, the save / load / apply round trip, one-line errors
//! that leave nothing behind, and byte-identical output across runs.
//!
//! Campaigns come from the `campaign` binary on the shipped paper scenarios with a small point count,
//! written to a temporary directory; both binaries run from the crate root so `robots/iiwa7.urdf` resolves.

use crate::common::{
    IDEAL_ELASTIC, assert_clean_failure, edit, files_under, ideal_elastic_pose, read,
};

use std::collections::HashMap;
use std::ffi::OsStr;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use serde_json::Value;

use calibench::calib::registry::RECOMMENDED;
use tempfile::TempDir;

const PAPER: &str = include_str!("../scenarios/paper_iiwa.toml");
const PAPER_POSE: &str = include_str!("../scenarios/paper_iiwa_pose.toml");
const POINTS: usize = 300;
const POSE_POINTS: usize = 200;

fn small_paper(points: usize) -> String {
    edit(PAPER, "points = 2335", &format!("points = {points}"))
}

fn small_pose(points: usize) -> String {
    edit(PAPER_POSE, "points = 875", &format!("points = {points}"))
}

fn run_bin(bin: &str, args: &[&OsStr]) -> Output {
    Command::new(bin)
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap_or_else(|e| panic!("{bin} starts: {e}"))
}

/// Runs the campaign binary on scenario `text`; returns the directory with measurements.csv and truth.csv.
fn campaign(dir: &TempDir, name: &str, text: &str) -> PathBuf {
    let scenario = dir.path().join(format!("{name}.toml"));
    std::fs::write(&scenario, text).expect("write the scenario");
    let out = dir.path().join(format!("campaign_{name}"));
    let output = run_bin(
        env!("CARGO_BIN_EXE_campaign"),
        &[scenario.as_os_str(), "--out".as_ref(), out.as_os_str()],
    );
    assert!(
        output.status.success(),
        "campaign {name} failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    out
}

fn calibrate(args: &[&OsStr]) -> Output {
    run_bin(env!("CARGO_BIN_EXE_calibrate"), args)
}

/// `calibrate apply --model MODEL --data DATA --out DIR` (DIR/applied.csv).
fn apply_model(model: &Path, data: &Path, out: &Path) -> Output {
    calibrate(&[
        "apply".as_ref(),
        "--model".as_ref(),
        model.as_os_str(),
        "--data".as_ref(),
        data.as_os_str(),
        "--out".as_ref(),
        out.as_os_str(),
    ])
}

/// `calibrate --data DATA --out OUT` plus `extra`; must succeed. Returns stdout.
fn fit_ok(data: &Path, out: &Path, extra: &[&str]) -> String {
    let mut args: Vec<&OsStr> = vec![
        "--data".as_ref(),
        data.as_os_str(),
        "--out".as_ref(),
        out.as_os_str(),
    ];
    args.extend(extra.iter().map(OsStr::new));
    let output = calibrate(&args);
    assert!(
        output.status.success(),
        "calibrate {args:?} failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    String::from_utf8(output.stdout).expect("stdout is UTF-8")
}

fn json(path: &Path) -> Value {
    serde_json::from_slice(&read(path))
        .unwrap_or_else(|e| panic!("{} is not JSON: {e}", path.display()))
}

/// A CSV file as its header and rows of strings.
struct Csv {
    header: Vec<String>,
    rows: Vec<Vec<String>>,
}

impl Csv {
    fn read(path: &Path) -> Csv {
        let mut reader =
            csv::Reader::from_path(path).unwrap_or_else(|e| panic!("open {}: {e}", path.display()));
        let header = reader
            .headers()
            .expect("a header")
            .iter()
            .map(String::from)
            .collect();
        let rows = reader
            .records()
            .map(|r| r.expect("a CSV record").iter().map(String::from).collect())
            .collect();
        Csv { header, rows }
    }

    fn write(&self, path: &Path) {
        let mut w = csv::Writer::from_path(path).expect("create a CSV");
        w.write_record(&self.header).expect("write the header");
        for row in &self.rows {
            w.write_record(row).expect("write a row");
        }
        w.flush().expect("flush the CSV");
    }

    fn col(&self, name: &str) -> usize {
        self.header
            .iter()
            .position(|h| h == name)
            .unwrap_or_else(|| panic!("no column {name} in {:?}", self.header))
    }

    /// Rows by `point_id`.
    fn by_id(&self) -> HashMap<String, Vec<String>> {
        let id = self.col("point_id");
        let map: HashMap<_, _> = self
            .rows
            .iter()
            .map(|r| (r[id].clone(), r.clone()))
            .collect();
        assert_eq!(map.len(), self.rows.len(), "point_ids are not unique");
        map
    }
}

/// `calibrate --data DATA --out OUT` plus `extra`, which must fail cleanly (see [`assert_clean_failure`]).
fn fit_fails(data: &Path, out: &Path, extra: &[&str], needles: &[&str]) -> String {
    let mut args: Vec<&OsStr> = vec![
        "--data".as_ref(),
        data.as_os_str(),
        "--out".as_ref(),
        out.as_os_str(),
    ];
    args.extend(extra.iter().map(OsStr::new));
    assert_clean_failure(&calibrate(&args), out, needles)
}

fn num(v: &Value, what: &str) -> f64 {
    v.as_f64()
        .unwrap_or_else(|| panic!("{what} is not a number: {v}"))
}

fn count(report: &Value, key: &str) -> usize {
    report[key]
        .as_u64()
        .unwrap_or_else(|| panic!("{key} is not a count: {}", report[key])) as usize
}

/// Error statistics with `unit` ("mm" or "rad"): every field present, finite, non-negative and consistent.
fn check_stats(v: &Value, unit: &str, what: &str) {
    let field = |name: &str| {
        let x = num(
            &v[format!("{name}_{unit}")],
            &format!("{what}.{name}_{unit}"),
        );
        assert!(x.is_finite() && x >= 0.0, "{what}.{name}_{unit} = {x}");
        x
    };
    let (mean, max, std, rms, p95) = (
        field("mean"),
        field("max"),
        field("std"),
        field("rms"),
        field("p95"),
    );
    assert!(
        mean <= max && p95 <= max && rms <= max,
        "{what}: mean, p95 and rms must not exceed max: {v}"
    );
    assert!(rms >= mean - 1e-12, "{what}: rms below mean: {v}");
    assert!(
        (rms * rms - (mean * mean + std * std)).abs() <= 1e-6 * rms * rms + 1e-300,
        "{what}: rms² ≠ mean² + std²: {v}"
    );
}

fn check_before_after(v: &Value, unit: &str, what: &str) {
    check_stats(&v["before"], unit, &format!("{what}.before"));
    check_stats(&v["after"], unit, &format!("{what}.after"));
}

/// The counts of a 50/25/25 split of `n` points, each within one of its share.
fn check_random_split(report: &Value, n: usize) {
    let (train, val, test) = (
        count(report, "n_train"),
        count(report, "n_val"),
        count(report, "n_test"),
    );
    assert_eq!(
        train + val + test,
        n,
        "split counts {train}/{val}/{test} do not add up to {n}"
    );
    for (got, share) in [(train, 0.5), (val, 0.25), (test, 0.25)] {
        let want = n as f64 * share;
        assert!(
            (got as f64 - want).abs() <= 1.0,
            "split {train}/{val}/{test} is not 50/25/25 of {n} ±1"
        );
    }
}

fn names(v: &Value, what: &str) -> Vec<String> {
    v.as_array()
        .unwrap_or_else(|| panic!("{what} is not an array: {v}"))
        .iter()
        .map(|s| {
            s.as_str()
                .unwrap_or_else(|| panic!("{what}: {s} is not a name"))
                .to_string()
        })
        .collect()
}

/// The fields every fit's report has; returns the kept position parameters.
fn check_report(report: &Value, method: &str, n: usize) -> Vec<String> {
    assert_eq!(report["method"], method, "report.method");
    check_random_split(report, n);
    assert!(
        num(&report["fit_ms"], "fit_ms") >= 0.0,
        "fit_ms is negative"
    );
    check_before_after(&report["test"], "mm", "test");
    let position = names(
        &report["kept_parameters"]["position"],
        "kept_parameters.position",
    );
    let orientation = names(
        &report["kept_parameters"]["orientation"],
        "kept_parameters.orientation",
    );
    let r2 = report["r2"]
        .as_object()
        .unwrap_or_else(|| panic!("r2 is not an object: {}", report["r2"]));
    for name in position.iter().chain(&orientation) {
        let entry = r2
            .get(name)
            .unwrap_or_else(|| panic!("no r2 for kept parameter {name}: {r2:?}"));
        num(&entry["validation"], &format!("r2.{name}.validation"));
        num(&entry["test"], &format!("r2.{name}.test"));
    }
    assert_eq!(
        r2.len(),
        position.len() + orientation.len(),
        "r2 has entries for parameters not kept: {r2:?}"
    );
    position
}

#[test]
fn report_has_the_documented_fields_and_the_papers_parameter_counts() {
    let dir = TempDir::new().unwrap();
    let data = campaign(&dir, "paper", &small_paper(POINTS));
    for (method, kept) in [
        ("paper-rotxyz", 17),
        ("paper-rotz", 5),
        ("paper-rotxyz-transxyz", 38),
    ] {
        let out = dir.path().join(method);
        let stdout = fit_ok(&data.join("measurements.csv"), &out, &["--method", method]);
        assert!(
            stdout.contains("Table 1"),
            "{method}: no Table 1 on stdout:\n{stdout}"
        );
        assert!(
            !stdout.contains("Table 2"),
            "{method}: Table 2 without a nest:\n{stdout}"
        );
        let report = json(&out.join("report.json"));
        let position = check_report(&report, method, POINTS);
        assert_eq!(
            position.len(),
            kept,
            "{method}: kept position parameters {position:?}"
        );
        assert!(
            report["kept_parameters"]["orientation"]
                .as_array()
                .is_some_and(Vec::is_empty),
            "{method}: orientation parameters kept without a nest: {}",
            report["kept_parameters"]
        );
        assert!(
            report.get("truth").is_none(),
            "{method}: a truth section without --truth"
        );
        assert!(
            report["test"].get("orientation").is_none(),
            "{method}: orientation errors without a nest"
        );
        let (before, after) = (
            num(&report["test"]["before"]["rms_mm"], "before"),
            num(&report["test"]["after"]["rms_mm"], "after"),
        );
        assert!(
            after < before,
            "{method}: calibration did not reduce the test rms ({before} → {after} mm)"
        );
        for name in ["model.json", "predictions.csv"] {
            assert!(out.join(name).is_file(), "{method}: no {name}");
        }
        let predictions = Csv::read(&out.join("predictions.csv"));
        assert_eq!(
            predictions.rows.len(),
            POINTS,
            "{method}: predictions.csv rows"
        );
    }
}

#[test]
fn truth_adds_a_truth_section() {
    let dir = TempDir::new().unwrap();
    let data = campaign(&dir, "paper", &small_paper(POINTS));
    let out = dir.path().join("out");
    let truth = data.join("truth.csv");
    let stdout = fit_ok(
        &data.join("measurements.csv"),
        &out,
        &[
            "--method",
            "paper-rotxyz",
            "--truth",
            truth.to_str().unwrap(),
        ],
    );
    assert!(
        stdout.contains("Table 1"),
        "no Table 1 on stdout:\n{stdout}"
    );
    let report = json(&out.join("report.json"));
    check_report(&report, "paper-rotxyz", POINTS);
    check_before_after(&report["truth"], "mm", "truth");
    assert!(
        num(&report["truth"]["after"]["mean_mm"], "truth.after")
            < num(&report["truth"]["before"]["mean_mm"], "truth.before"),
        "calibration did not bring the test points closer to the truth: {}",
        report["truth"]
    );
}

#[test]
fn nest_reports_orientation_and_prints_table_2() {
    let dir = TempDir::new().unwrap();
    let data = campaign(&dir, "pose", &small_pose(POSE_POINTS));
    let out = dir.path().join("out");
    let truth = data.join("truth.csv");
    let stdout = fit_ok(
        &data.join("measurements.csv"),
        &out,
        &[
            "--method",
            "paper-rotxyz",
            "--truth",
            truth.to_str().unwrap(),
        ],
    );
    assert!(
        stdout.contains("Table 1"),
        "no Table 1 on stdout:\n{stdout}"
    );
    assert!(
        stdout.contains("Table 2"),
        "no Table 2 on stdout with a nest:\n{stdout}"
    );
    let report = json(&out.join("report.json"));
    let position = check_report(&report, "paper-rotxyz", POSE_POINTS);
    assert_eq!(position.len(), 17, "kept position parameters {position:?}");
    for section in ["test", "truth"] {
        check_before_after(&report[section], "mm", section);
        let orientation = &report[section]["orientation"];
        check_before_after(orientation, "rad", &format!("{section}.orientation"));
        let (before, after) = (
            num(&orientation["before"]["mean_rad"], "before"),
            num(&orientation["after"]["mean_rad"], "after"),
        );
        assert!(
            after < before,
            "{section}: orientation error not reduced ({before} → {after} rad)"
        );
    }
    let predictions = Csv::read(&out.join("predictions.csv"));
    for name in [
        "predicted_qw",
        "predicted_qx",
        "predicted_qy",
        "predicted_qz",
        "orientation_after_rad",
    ] {
        predictions.col(name);
    }
}

#[test]
fn a_split_column_is_honoured() {
    let dir = TempDir::new().unwrap();
    let data = campaign(&dir, "paper", &small_paper(POINTS));
    let mut table = Csv::read(&data.join("measurements.csv"));
    assert_eq!(table.rows.len(), POINTS);
    // Not the default 50/25/25, so a random split cannot pass by accident.
    let (n_train, n_val) = (POINTS / 2, 90);
    let n_test = POINTS - n_train - n_val;
    table.header.push("split".into());
    for (i, row) in table.rows.iter_mut().enumerate() {
        row.push(
            match i {
                i if i < n_train => "train",
                i if i < n_train + n_val => "val",
                _ => "test",
            }
            .into(),
        );
    }
    let with_split = dir.path().join("with_split.csv");
    table.write(&with_split);
    let out = dir.path().join("out");
    // --split applies only without a split column. No --method: the default is the recommended one.
    fit_ok(
        &with_split,
        &out,
        &["--split", "0.8,0.1,0.1", "--seed", "7"],
    );
    let report = json(&out.join("report.json"));
    assert_eq!(report["method"], RECOMMENDED.name(), "the default method");
    assert_eq!(
        (
            count(&report, "n_train"),
            count(&report, "n_val"),
            count(&report, "n_test")
        ),
        (n_train, n_val, n_test),
        "the split column was not honoured"
    );
    let given = table.by_id();
    let split = table.col("split");
    let predictions = Csv::read(&out.join("predictions.csv"));
    let (id, label) = (predictions.col("point_id"), predictions.col("split"));
    assert_eq!(predictions.rows.len(), POINTS);
    for row in &predictions.rows {
        assert_eq!(
            row[label], given[&row[id]][split],
            "point {}: split in predictions.csv",
            row[id]
        );
    }
}

/// Fits `data` into `out`, applies the model to the same file, and checks that the predicted positions (and
/// with `orientation` the quaternions) equal predictions.csv's bit for bit, and that the corrected commands
/// are close to the input with a negligible residual. `extra`: more flags of the fit (its method). Returns
/// the largest command change (rad).
fn round_trip(dir: &TempDir, data: &Path, orientation: bool, extra: &[&str]) -> f64 {
    let out = dir.path().join("fit");
    fit_ok(data, &out, extra);
    let model = out.join("model.json");
    let apply_dir = dir.path().join("apply");
    let applied = apply_dir.join("applied.csv");
    let output = apply_model(&model, data, &apply_dir);
    assert!(
        output.status.success(),
        "apply failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    assert_eq!(
        files_under(&apply_dir),
        vec![applied.clone()],
        "apply wrote other files"
    );

    let predictions_csv = Csv::read(&out.join("predictions.csv"));
    let predictions = predictions_csv.by_id();
    let input = Csv::read(data);
    let input_rows = input.by_id();
    let applied = Csv::read(&applied);
    assert_eq!(applied.rows.len(), input.rows.len(), "applied.csv rows");
    let mut compared = vec!["predicted_x", "predicted_y", "predicted_z"];
    if orientation {
        compared.extend([
            "predicted_qw",
            "predicted_qx",
            "predicted_qy",
            "predicted_qz",
        ]);
    }
    let id = applied.col("point_id");
    let joints: Vec<String> = (1..=7).map(|k| format!("iiwa_joint_{k}")).collect();
    let residual = applied.col("compensation_residual_m");
    let mut mismatches = Vec::new();
    let mut largest_change = 0.0_f64;
    for row in &applied.rows {
        let point = &row[id];
        let expected = predictions
            .get(point)
            .unwrap_or_else(|| panic!("point {point} not in predictions.csv"));
        for name in &compared {
            let (got, want) = (
                &row[applied.col(name)],
                &expected[predictions_csv.col(name)],
            );
            let (g, w): (f64, f64) = (got.parse().unwrap(), want.parse().unwrap());
            if g.to_bits() != w.to_bits() {
                mismatches.push(format!("point {point} {name}: apply {got} vs fit {want}"));
            }
        }
        for joint in &joints {
            let q: f64 = input_rows[point][input.col(joint)].parse().unwrap();
            let echoed: f64 = row[applied.col(joint)].parse().unwrap();
            assert_eq!(
                echoed.to_bits(),
                q.to_bits(),
                "point {point} {joint}: input not echoed"
            );
            let cmd: f64 = row[applied.col(&format!("cmd_{joint}"))]
                .parse()
                .unwrap_or_else(|_| panic!("point {point}: no command: {:?}", row));
            assert!(cmd.is_finite(), "point {point} cmd_{joint} = {cmd}");
            largest_change = largest_change.max((cmd - q).abs());
        }
        let r: f64 = row[residual].parse().unwrap();
        assert!(
            (0.0..=1e-9).contains(&r),
            "point {point}: compensation residual {r} m"
        );
    }
    assert!(
        mismatches.is_empty(),
        "{} of {} values differ between `apply` with the saved model and the fit's predictions.csv, e.g. {:?}",
        mismatches.len(),
        applied.rows.len() * compared.len(),
        &mismatches[..mismatches.len().min(3)]
    );
    assert!(
        largest_change > 0.0,
        "the corrected commands equal the input: nothing was compensated"
    );
    largest_change
}

#[test]
fn saved_model_applied_reproduces_the_predictions() {
    let dir = TempDir::new().unwrap();
    let data = campaign(&dir, "paper", &small_paper(POINTS));
    let change = round_trip(
        &dir,
        &data.join("measurements.csv"),
        false,
        &["--method", "paper-rotxyz"],
    );
    assert!(
        change <= 0.01,
        "corrected commands differ from the input by up to {change} rad"
    );
}

/// With a nest the model corrects the 0.22 rad mounting rotation too, so commands may move further; the
/// predicted orientation must survive the round trip as exactly as the position.
#[test]
fn saved_nest_model_applied_reproduces_positions_and_orientations() {
    let dir = TempDir::new().unwrap();
    // On the ideal truth: its campaign has no temperature column (a model that regressed on it is
    // `apply_passes_the_temperature_to_a_model_that_regressed_on_it`).
    let pose = edit(
        &ideal_elastic_pose(),
        "points = 875",
        &format!("points = {POSE_POINTS}"),
    );
    let data = campaign(&dir, "pose", &pose);
    round_trip(
        &dir,
        &data.join("measurements.csv"),
        true,
        &["--method", "paper-rotxyz"],
    );
}

/// A model that regressed on the temperature gets each configuration's own: `apply` reproduces the fit's
/// predictions.csv bit for bit (at the training mean it would not), the temperatures mirrored within their
/// training range move its predictions,
/// and a file without the column is refused on one line naming it and the file, with nothing written.
#[test]
fn apply_passes_the_temperature_to_a_model_that_regressed_on_it() {
    let dir = TempDir::new().unwrap();
    // A 10 K warm-up within the campaign (the shipped 3 K over 30 min leaves ~30 µm, which the regression
    // rightly ignores): about 0.2 mm over a metre of aluminium, which it takes up.
    let warm_up = edit(
        &small_paper(POINTS),
        "start_c = 20.0, end_c = 23.0, time_constant_s = 1800.0",
        "start_c = 20.0, end_c = 30.0, time_constant_s = 300.0",
    );
    let data = campaign(&dir, "paper", &warm_up).join("measurements.csv");
    round_trip(&dir, &data, false, &["--method", "residual-ridge"]);
    let model = dir.path().join("fit").join("model.json");
    let saved = std::fs::read_to_string(&model).unwrap();
    assert!(
        saved.contains("\"temperature\""),
        "the model took no temperature"
    );
    let table = Csv::read(&data);
    let t = table.col("temperature");
    // Each configuration at the temperature mirrored within the training range: still inside the domain.
    let temps: Vec<f64> = table.rows.iter().map(|r| r[t].parse().unwrap()).collect();
    let (lo, hi) = temps
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    let mut mirrored = Csv::read(&data);
    for (row, v) in mirrored.rows.iter_mut().zip(&temps) {
        row[t] = (lo + hi - v).to_string();
    }
    let mirrored_path = dir.path().join("mirrored.csv");
    mirrored.write(&mirrored_path);
    let applied = |path: &Path, name: &str| {
        let out = dir.path().join(name);
        let output = apply_model(&model, path, &out);
        assert!(
            output.status.success(),
            "{}",
            String::from_utf8_lossy(&output.stderr)
        );
        let csv = Csv::read(&out.join("applied.csv"));
        let x = csv.col("predicted_x");
        csv.rows
            .iter()
            .map(|r| r[x].parse::<f64>().unwrap())
            .collect::<Vec<f64>>()
    };
    let (at, other) = (
        applied(&data, "at.csv"),
        applied(&mirrored_path, "mirrored_applied.csv"),
    );
    let moved = at.iter().zip(&other).filter(|(a, b)| a != b).count();
    assert!(
        10 * moved >= 9 * at.len(),
        "the mirrored temperature moved {moved} of {} predictions",
        at.len()
    );
    let mut cold = Csv::read(&data);
    cold.header.remove(t);
    for row in &mut cold.rows {
        row.remove(t);
    }
    let cold_path = dir.path().join("no_temperature.csv");
    cold.write(&cold_path);
    let out_dir = dir.path().join("refused");
    let output = apply_model(&model, &cold_path, &out_dir.join("applied.csv"));
    assert_clean_failure(
        &output,
        &out_dir,
        &["no column 'temperature'", &cold_path.display().to_string()],
    );
}

/// Only a model with a regression part is warned about configurations outside its training domain: a
/// kinematic fit extrapolates nothing. The same file, with a configuration far from the training data, warns
/// for `residual-ridge` and not for `kinematic`, whose `domain` column still says where the point lies.
#[test]
fn only_a_regression_is_warned_about_the_training_domain() {
    let dir = TempDir::new().unwrap();
    let data = campaign(&dir, "paper", &small_paper(POINTS)).join("measurements.csv");
    let mut far = Csv::read(&data);
    for (k, v) in [(1, 2.9), (2, -1.9), (4, 0.3), (6, -1.9)] {
        let c = far.col(&format!("iiwa_joint_{k}"));
        far.rows[0][c] = v.to_string();
    }
    let far_path = dir.path().join("far.csv");
    far.write(&far_path);
    let warned = |method: &str| {
        let fit = dir.path().join(format!("fit_{method}"));
        fit_ok(&data, &fit, &["--method", method]);
        let out = dir.path().join(method);
        let output = apply_model(&fit.join("model.json"), &far_path, &out);
        assert!(
            output.status.success(),
            "{}",
            String::from_utf8_lossy(&output.stderr)
        );
        let applied = Csv::read(&out.join("applied.csv"));
        assert!(
            applied.rows[0][applied.col("domain")].starts_with("outside"),
            "{method}: the far configuration is inside"
        );
        String::from_utf8_lossy(&output.stderr).contains("training domain")
    };
    assert!(warned("residual-ridge"), "residual-ridge is not warned");
    assert!(
        !warned("kinematic"),
        "kinematic is warned about a regression it does not have"
    );
}

/// The campaign's measurements.csv rewritten by `change`.
fn altered(dir: &TempDir, name: &str, change: impl FnOnce(&mut Csv)) -> PathBuf {
    let data = campaign(dir, "paper", &small_paper(40));
    let mut table = Csv::read(&data.join("measurements.csv"));
    change(&mut table);
    let path = dir.path().join(name);
    table.write(&path);
    path
}

#[test]
fn a_missing_joint_column_is_one_line() {
    let dir = TempDir::new().unwrap();
    let data = altered(&dir, "no_joint_3.csv", |t| {
        let c = t.col("iiwa_joint_3");
        t.header.remove(c);
        for row in &mut t.rows {
            row.remove(c);
        }
    });
    fit_fails(&data, &dir.path().join("out"), &[], &["iiwa_joint_3"]);
}

#[test]
fn a_non_numeric_cell_is_one_line() {
    let dir = TempDir::new().unwrap();
    let data = altered(&dir, "text.csv", |t| {
        let c = t.col("iiwa_joint_2");
        t.rows[1][c] = "abc".into();
    });
    // Row 3 as a spreadsheet shows it: the header is row 1.
    fit_fails(
        &data,
        &dir.path().join("out"),
        &[],
        &["row 3", "iiwa_joint_2", "abc"],
    );
}

#[test]
fn a_nan_cell_is_one_line() {
    let dir = TempDir::new().unwrap();
    let data = altered(&dir, "nan.csv", |t| {
        let c = t.col("y1");
        t.rows[4][c] = "NaN".into();
    });
    fit_fails(&data, &dir.path().join("out"), &[], &["row 6", "y1"]);
}

/// 12 points give 6 training points for a model with 38 error parameters: the fit must refuse rather than
/// produce a model that is mostly noise.
#[test]
fn fewer_training_points_than_parameters_is_refused() {
    let dir = TempDir::new().unwrap();
    let data = campaign(&dir, "tiny", &small_paper(12));
    let out = dir.path().join("out");
    std::fs::create_dir(&out).unwrap();
    fit_fails(
        &data.join("measurements.csv"),
        &out,
        &["--method", "paper-rotxyz-transxyz"],
        &[],
    );
}

#[test]
fn an_unknown_method_is_one_line() {
    let dir = TempDir::new().unwrap();
    let data = campaign(&dir, "paper", &small_paper(40));
    fit_fails(
        &data.join("measurements.csv"),
        &dir.path().join("out"),
        &["--method", "paper-magic"],
        &["paper-magic"],
    );
}

#[test]
fn a_missing_data_file_is_one_line() {
    let dir = TempDir::new().unwrap();
    let out = dir.path().join("out");
    std::fs::create_dir(&out).unwrap();
    fit_fails(&dir.path().join("nowhere.csv"), &out, &[], &["nowhere.csv"]);
}

#[test]
fn apply_with_a_file_that_is_not_a_model_is_one_line() {
    let dir = TempDir::new().unwrap();
    let data = campaign(&dir, "paper", &small_paper(40));
    let fit = dir.path().join("fit");
    fit_ok(
        &data.join("measurements.csv"),
        &fit,
        &["--method", "paper-rotxyz"],
    );
    let apply_dir = dir.path().join("apply");
    for not_a_model in [
        fit.join("report.json"),
        data.join("campaign.json"),
        data.join("measurements.csv"),
    ] {
        let output = apply_model(&not_a_model, &data.join("measurements.csv"), &apply_dir);
        let name = not_a_model.file_name().unwrap().to_str().unwrap();
        assert_clean_failure(&output, &apply_dir, &[name]);
    }
}

#[test]
fn repeated_fits_are_byte_identical() {
    let dir = TempDir::new().unwrap();
    let paper = campaign(&dir, "paper", &small_paper(POINTS));
    let pose = campaign(&dir, "pose", &small_pose(POSE_POINTS));
    for (data, method) in [(&paper, "paper-rotxyz-transxyz"), (&pose, "paper-rotxyz")] {
        let runs: Vec<PathBuf> = (0..2)
            .map(|k| {
                let out = dir.path().join(format!("{method}_{k}"));
                fit_ok(&data.join("measurements.csv"), &out, &["--method", method]);
                out
            })
            .collect();
        for name in ["predictions.csv", "model.json"] {
            assert!(
                read(&runs[0].join(name)) == read(&runs[1].join(name)),
                "{method}: {name} differs between two identical runs"
            );
        }
    }
}

/// A configuration where the inverse is undefined (the iiwa standing straight up: joints 2, 4 and 6 at zero put
/// axes 1, 3, 5 and 7 on one line) gets its prediction and an empty command with the reason; the others are
/// commanded as usual, and the file is written. The straight arm lies far outside the campaign's domain, where
/// `paper-rotxyz`'s regressions fade out to their constant parts (issue 13); there the inverse either reaches
/// the target (the aligned axes 1, 3, 5, 7 share the correction) or is refused as singular.
#[test]
fn apply_reports_a_singular_configuration_per_row() {
    let dir = tempfile::tempdir().unwrap();
    let data = campaign(&dir, "small", &small_paper(POINTS)).join("measurements.csv");
    let fitted = dir.path().join("fit");
    fit_ok(&data, &fitted, &["--method", "paper-rotxyz"]);
    let joints = dir.path().join("joints.csv");
    let names: Vec<String> = (1..=7).map(|i| format!("iiwa_joint_{i}")).collect();
    std::fs::write(
        &joints,
        format!(
            // The temperature: the model (`paper-rotxyz`) regressed on it, so `apply` needs it.
            "point_id,{},temperature\nstraight,0,0,0,0,0,0,0,20.5\nbent,0.1,0.6,0.0,-1.6,0.0,-0.8,0.0,20.5\n",
            names.join(",")
        ),
    )
    .unwrap();
    let applied_dir = dir.path().join("applied");
    let applied = applied_dir.join("applied.csv");
    let output = apply_model(&fitted.join("model.json"), &joints, &applied_dir);
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let mut reader = csv::Reader::from_path(&applied).unwrap();
    let header = reader.headers().unwrap().clone();
    let col = |name: &str| header.iter().position(|h| h == name).unwrap();
    let rows: Vec<csv::StringRecord> = reader.records().map(|r| r.unwrap()).collect();
    assert_eq!(rows.len(), 2);
    let (straight, bent) = (&rows[0], &rows[1]);
    assert!(
        straight[col("domain")].starts_with("outside: "),
        "{straight:?}"
    );
    let status = &straight[col("status")];
    if status == "ok" {
        let r: f64 = straight[col("compensation_residual_m")].parse().unwrap();
        assert!(r <= 1e-9, "{straight:?}");
    } else {
        assert!(status.starts_with("no command"), "{straight:?}");
        assert!(straight[col("cmd_iiwa_joint_1")].is_empty());
    }
    assert!(
        straight[col("predicted_x")]
            .parse::<f64>()
            .unwrap()
            .is_finite()
    );
    assert_eq!(&bent[col("status")], "ok");
    assert!(bent[col("compensation_residual_m")].parse::<f64>().unwrap() <= 1e-9);
}

/// The first regression model in `model` (depth first) that has coefficients.
fn first_fitted_regression(model: &mut Value) -> Option<&mut Value> {
    if model
        .get("coef")
        .and_then(Value::as_array)
        .is_some_and(|c| !c.is_empty())
    {
        return Some(model);
    }
    match model {
        Value::Object(fields) => fields.values_mut().find_map(first_fitted_regression),
        Value::Array(items) => items.iter_mut().find_map(first_fitted_regression),
        _ => None,
    }
}

/// A saved model is input: a `model.json` that does not fit its own contents (a joint name, DH row,
/// coefficient or error row removed) or holds no plausible number (1e300, a NaN written as a string, a null)
/// is refused by `calibrate apply` with exit code 1 and one line naming the file and the field — never a
/// panic (exit 101), never predictions of 1e296 — and no output file. The untouched models still apply.
#[test]
fn apply_refuses_a_model_that_does_not_fit_itself() {
    let dir = TempDir::new().unwrap();
    // The hybrid's elastic part must converge on 20 training points: only where its model matches the truth.
    let ideal = edit(IDEAL_ELASTIC, "points = 2335", "points = 40");
    let data = campaign(&dir, "paper", &ideal).join("measurements.csv");
    let apply = |model: &Path, name: &str| {
        let out = dir.path().join(format!("apply_{name}"));
        let output = apply_model(model, &data, &out);
        (output, out)
    };
    type Change = fn(&mut Value);
    let cases: [(&str, &str, Change, &str); 11] = [
        (
            "paper-rotxyz",
            "no_joint_name",
            |m| {
                m["joint_names"].as_array_mut().unwrap().pop();
            },
            "joint_names",
        ),
        (
            "paper-rotxyz",
            "no_dh_row",
            |m| {
                m["dh"]["rows"].as_array_mut().unwrap().remove(2);
            },
            "dh.rows",
        ),
        (
            "paper-rotxyz",
            "no_coefficient",
            |m| {
                let r = first_fitted_regression(m).expect("a regression with coefficients");
                r["coef"].as_array_mut().unwrap().pop();
            },
            ".model.coef",
        ),
        (
            "paper-rotxyz",
            "huge_coefficient",
            |m| {
                let r = first_fitted_regression(m).expect("a regression with coefficients");
                r["coef"][0] = Value::from(1e300);
            },
            ".model.coef[0]",
        ),
        (
            "paper-rotxyz",
            "nan_string",
            |m| {
                m["dh"]["rows"][1]["d"] = Value::from("NaN");
            },
            "dh.rows[1].d",
        ),
        (
            "paper-rotxyz",
            "null_mounting",
            |m| {
                m["registration"]["frame"]["mounting"][0] = Value::Null;
            },
            "registration.frame.mounting[0]",
        ),
        (
            "kinematic",
            "no_error_row",
            |m| {
                m["errors"].as_array_mut().unwrap().pop();
            },
            "errors",
        ),
        (
            "kinematic",
            "huge_dh_length",
            |m| {
                m["dh"]["rows"][3]["a"] = Value::from(1e300);
            },
            "dh.rows[3].a",
        ),
        (
            "hybrid",
            "base_without_error_row",
            |m| {
                m["base"]["errors"].as_array_mut().unwrap().remove(0);
            },
            "base.errors",
        ),
        (
            "hybrid",
            "base_without_joint_name",
            |m| {
                m["base"]["joint_names"].as_array_mut().unwrap().remove(0);
            },
            "base.dh.rows",
        ),
        (
            "hybrid",
            "null_error",
            |m| {
                m["base"]["errors"][2][1] = Value::Null;
            },
            "base.errors[2][1]",
        ),
    ];
    let mut models = HashMap::new();
    for method in ["paper-rotxyz", "kinematic", "hybrid"] {
        let fit = dir.path().join(format!("fit_{method}"));
        fit_ok(&data, &fit, &["--method", method]);
        let model = fit.join("model.json");
        let (output, out) = apply(&model, method);
        assert!(
            output.status.success(),
            "the untouched {method} model: {}",
            String::from_utf8_lossy(&output.stderr)
        );
        assert_eq!(files_under(&out), vec![out.join("applied.csv")]);
        models.insert(method, json(&model));
    }
    for (method, name, change, field) in cases {
        let mut model = models[method].clone();
        change(&mut model);
        let path = dir.path().join(format!("{name}.json"));
        std::fs::write(&path, serde_json::to_vec_pretty(&model).unwrap()).unwrap();
        let (output, out) = apply(&path, name);
        assert_eq!(
            output.status.code(),
            Some(1),
            "{name}: {}",
            String::from_utf8_lossy(&output.stderr)
        );
        let line = assert_clean_failure(&output, &out, &[&format!("{name}.json"), field]);
        assert!(!out.exists(), "{name}: {line}");
    }
}

/// Issue 16: a campaign measured on the fly end to end. `[campaign.trajectory]` makes the `campaign` binary
/// sample one path through the planned targets, with a 3 ms clock offset; `measurements.csv` gains a `time`
/// column, and `calibrate` finds the offset (within 50 µs) and removes it before fitting. The same section
/// beside an `[evaluation]` (which judges campaigns measured at rest) is refused on one line.
#[test]
fn a_campaign_measured_on_the_fly_is_synchronised_by_calibrate() {
    let dir = TempDir::new().unwrap();
    let text = small_paper(40);
    let at_rest = &text[..text
        .find("[evaluation]")
        .expect("paper_iiwa has an [evaluation]")];
    let trajectory = "\n[campaign.trajectory]\nspeed = 0.5\nacceleration_rad_s2 = 5.0\n\
                      sample_rate_hz = 1000.0\nkeep_every = 10\nclock_offset_s = 0.003\njitter_s = 5e-6\n";
    let out = campaign(&dir, "on_the_fly", &format!("{at_rest}{trajectory}"));
    let measurements = out.join("measurements.csv");
    let csv = Csv::read(&measurements);
    assert!(csv.header.iter().any(|h| h == "time"), "{:?}", csv.header);
    let report = json(&out.join("campaign.json"));
    assert_eq!(report["trajectory"]["targets"], 40);
    assert_eq!(
        report["trajectory"]["samples"].as_u64(),
        Some(csv.rows.len() as u64)
    );
    assert!(csv.rows.len() > 100, "{} samples", csv.rows.len());

    let fitted = dir.path().join("fit");
    let stdout = fit_ok(&measurements, &fitted, &["--method", "kinematic"]);
    assert!(stdout.contains("clock offset"), "{stdout}");
    let offset = json(&fitted.join("report.json"))["clock_offset"]["offset_s"]
        .as_f64()
        .expect("report.json has clock_offset.offset_s");
    eprintln!(
        "{} samples: clock offset {:.1} µs (true 3000)",
        csv.rows.len(),
        offset * 1e6
    );
    assert!((offset - 0.003).abs() <= 50e-6, "{offset} s");

    // The commanded rates the controller logged make the motion inputs of a regression; a prediction without
    // them is at rest. Data without them is refused on one line.
    assert!(csv.header.iter().any(|h| h == "qdd_iiwa_joint_7"));
    let moving = dir.path().join("fit_motion");
    fit_ok(
        &measurements,
        &moving,
        &["--method", "paper-rotxyz", "--motion-inputs"],
    );
    let report = json(&moving.join("report.json"));
    let inputs: Vec<&str> = report["extra_inputs"]
        .as_array()
        .expect("report.json lists the extra inputs")
        .iter()
        .filter_map(Value::as_str)
        .collect();
    assert_eq!(inputs.len(), 7, "{inputs:?}");
    assert!(
        inputs
            .iter()
            .all(|n| n.starts_with("tau_motion_iiwa_joint_"))
    );
    let stop_and_go = campaign(&dir, "at_rest", at_rest);
    let no_rates = dir.path().join("fit_no_rates");
    let output = calibrate(&[
        "--data".as_ref(),
        stop_and_go.join("measurements.csv").as_os_str(),
        "--out".as_ref(),
        no_rates.as_os_str(),
        "--method".as_ref(),
        "paper-rotxyz".as_ref(),
        "--motion-inputs".as_ref(),
    ]);
    assert_clean_failure(&output, &no_rates, &["qd_<joint>", "measurements.csv"]);

    let refused = dir.path().join("refused.toml");
    std::fs::write(&refused, format!("{text}{trajectory}")).unwrap();
    let bad_out = dir.path().join("refused_out");
    let output = run_bin(
        env!("CARGO_BIN_EXE_campaign"),
        &[refused.as_os_str(), "--out".as_ref(), bad_out.as_os_str()],
    );
    assert_clean_failure(&output, &bad_out, &["campaign.trajectory", "[evaluation]"]);
}
