//! `calibrate curve` end to end on a small simulated campaign of `geometric_only.toml` (geometric errors and
//! tracker noise only, which `kinematic` models exactly): the held-out quarter is the one `calibrate` holds
//! out with the same seed, whatever the size, draw and method; `kinematic` reaches the tracker-noise floor of
//! that quarter; the same seed gives the same bytes whatever the thread count; bad input is one error line.

use crate::common::{assert_clean_failure, edit, read};

use std::collections::HashMap;
use std::ffi::OsStr;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;

use calibench::app::simulate;
use calibench::dataset::{Split, random_split};
use calibench::measurements::{measurements_csv, truth_csv};
use calibench::scenario::Scenario;
use tempfile::TempDir;

const GEOMETRIC: &str = include_str!("../scenarios/geometric_only.toml");
const SEED: &str = "5";

/// A 300-point `geometric_only` campaign, simulated once: measurements.csv and truth.csv in a directory
/// kept for the test run.
fn campaign() -> &'static Path {
    static DIR: OnceLock<TempDir> = OnceLock::new();
    DIR.get_or_init(|| {
        let text = edit(GEOMETRIC, "points = 2335", "points = 300");
        let scenario = Scenario::parse(&text, "small geometric_only").unwrap();
        let c = simulate(&scenario).unwrap().campaign;
        let dir = TempDir::new().unwrap();
        std::fs::write(
            dir.path().join("measurements.csv"),
            measurements_csv(&c).unwrap(),
        )
        .unwrap();
        std::fs::write(dir.path().join("truth.csv"), truth_csv(&c).unwrap()).unwrap();
        dir
    })
    .path()
}

fn measurements() -> PathBuf {
    campaign().join("measurements.csv")
}

fn run_bin(bin: &str, args: &[&OsStr], threads: Option<&str>) -> Output {
    let mut cmd = Command::new(bin);
    cmd.args(args).current_dir(env!("CARGO_MANIFEST_DIR"));
    if let Some(n) = threads {
        cmd.env("RAYON_NUM_THREADS", n);
    }
    cmd.env_remove("SLURM_CPUS_PER_TASK");
    cmd.output().unwrap_or_else(|e| panic!("{bin} starts: {e}"))
}

/// `calibrate curve` on `data` into `out` with the iiwa and the scenario's payload, plus `extra`.
fn curve(data: &Path, out: &Path, extra: &[&str], threads: Option<&str>) -> Output {
    let mut args: Vec<&OsStr> = vec![
        "curve".as_ref(),
        "--robot".as_ref(),
        "robots/iiwa7.urdf".as_ref(),
        "--data".as_ref(),
        data.as_os_str(),
        "--payload-kg".as_ref(),
        "0.4".as_ref(),
        "--payload-com-m".as_ref(),
        "0,0,0.03".as_ref(),
        "--out".as_ref(),
        out.as_os_str(),
    ];
    args.extend(extra.iter().map(OsStr::new));
    run_bin(env!("CARGO_BIN_EXE_calibrate"), &args, threads)
}

fn curve_ok(data: &Path, out: &Path, extra: &[&str], threads: Option<&str>) -> String {
    let output = curve(data, out, extra, threads);
    assert!(
        output.status.success(),
        "calibrate curve {extra:?} failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    String::from_utf8(output.stdout).unwrap()
}

/// A CSV file as rows of column name → value.
fn rows(path: &Path) -> Vec<HashMap<String, String>> {
    let mut reader = csv::Reader::from_path(path).unwrap();
    let header: Vec<String> = reader.headers().unwrap().iter().map(String::from).collect();
    reader
        .records()
        .map(|r| {
            header
                .iter()
                .cloned()
                .zip(r.unwrap().iter().map(String::from))
                .collect()
        })
        .collect()
}

fn num(row: &HashMap<String, String>, col: &str) -> f64 {
    row[col]
        .parse()
        .unwrap_or_else(|e| panic!("{col} = {:?}: {e}", row[col]))
}

/// The rows `calibrate --seed SEED` holds out of `n` (its default 50 / 25 / 25 % split).
fn held_out(n: usize) -> Vec<usize> {
    let labels = random_split(n, [0.5, 0.25, 0.25], SEED.parse().unwrap()).unwrap();
    (0..n).filter(|&i| labels[i] == Split::Test).collect()
}

/// The mean tracker noise (mm) over the held-out rows: measured against true reflector positions, both in
/// the tracker frame. What a model that knew the arm exactly would still be off by.
fn noise_floor_mm(rows_m: &[HashMap<String, String>], test: &[usize]) -> f64 {
    let truth: HashMap<String, HashMap<String, String>> = rows(&campaign().join("truth.csv"))
        .into_iter()
        .map(|r| (r["point_id"].clone(), r))
        .collect();
    let sum: f64 = test
        .iter()
        .map(|&i| {
            let m = &rows_m[i];
            let t = &truth[&m["point_id"]];
            let d: f64 = ["x1", "y1", "z1"]
                .iter()
                .map(|c| (num(m, c) - num(t, &format!("trk_{c}"))).powi(2))
                .sum();
            d.sqrt()
        })
        .sum();
    sum / test.len() as f64 * 1e3
}

/// The held-out quarter is `calibrate`'s: at the largest size (the whole pool) `nominal`, which registers the
/// tracker on all the points it is given, scores on every draw exactly what `calibrate --method nominal` with
/// the same seed reports on its test part. `kinematic`, on geometric errors it models exactly, comes within 1.5×
/// the tracker noise on that quarter, far below `nominal`.
#[test]
fn the_held_out_quarter_is_calibrates_and_kinematic_reaches_the_noise() {
    let dir = TempDir::new().unwrap();
    let data = measurements();
    let m = rows(&data);
    let n_pool = m.len() - held_out(m.len()).len();
    let sizes = format!("60,{n_pool}");
    let out = dir.path().join("curve");
    let stdout = curve_ok(
        &data,
        &out,
        &[
            "--methods",
            "nominal,kinematic",
            "--sizes",
            &sizes,
            "--draws",
            "2",
            "--seed",
            SEED,
        ],
        None,
    );
    assert!(stdout.contains("Learning curve"), "{stdout}");
    assert!(out.join("curve.png").is_file());
    let found = rows(&out.join("curve.csv"));
    assert_eq!(found.len(), 2 * 2 * 2);
    assert!(found.iter().all(|r| r["status"] == "ok"), "{found:?}");
    let at = |method: &str, size: usize| -> Vec<f64> {
        found
            .iter()
            .filter(|r| r["method"] == method && r["size"] == size.to_string())
            .map(|r| num(r, "test_mean_mm"))
            .collect()
    };

    let fit = dir.path().join("nominal");
    let output = run_bin(
        env!("CARGO_BIN_EXE_calibrate"),
        &[
            "--robot".as_ref(),
            "robots/iiwa7.urdf".as_ref(),
            "--data".as_ref(),
            data.as_os_str(),
            "--method".as_ref(),
            "nominal".as_ref(),
            "--seed".as_ref(),
            SEED.as_ref(),
            "--out".as_ref(),
            fit.as_os_str(),
        ],
        None,
    );
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let report: serde_json::Value =
        serde_json::from_slice(&read(&fit.join("report.json"))).unwrap();
    let direct = report["test"]["after"]["mean_mm"].as_f64().unwrap();
    assert_eq!(report["n_test"].as_u64(), Some((m.len() - n_pool) as u64));
    for mean in at("nominal", n_pool) {
        assert!(
            (mean - direct).abs() < 1e-9,
            "nominal on the whole pool: {mean} mm, calibrate says {direct} mm on its test part"
        );
    }

    let floor = noise_floor_mm(&m, &held_out(m.len()));
    let nominal = at("nominal", n_pool)[0];
    for mean in at("kinematic", n_pool) {
        assert!(
            mean < 1.5 * floor && mean < nominal / 5.0,
            "kinematic on {n_pool} points: {mean:.4} mm held out; noise floor {floor:.4} mm, nominal \
             {nominal:.4} mm"
        );
    }
}

/// A gross error in one held-out row shows in every fit's held-out maximum, whatever the size, draw or
/// method: that row is never drawn for training. The same error in a row of the pool never shows.
#[test]
fn every_fit_is_tested_on_the_same_rows() {
    let dir = TempDir::new().unwrap();
    let n = rows(&measurements()).len();
    let text = String::from_utf8(read(&measurements())).unwrap();
    let test = held_out(n);
    let pool_row = (0..n).find(|i| !test.contains(i)).unwrap();
    let shifted = |row: usize| -> PathBuf {
        let mut lines: Vec<String> = text.lines().map(String::from).collect();
        let header: Vec<&str> = lines[0].split(',').collect();
        let x = header.iter().position(|h| *h == "x1").unwrap();
        let mut cells: Vec<String> = lines[row + 1].split(',').map(String::from).collect();
        cells[x] = (cells[x].parse::<f64>().unwrap() + 0.02).to_string();
        lines[row + 1] = cells.join(",");
        let path = dir.path().join(format!("shifted_{row}.csv"));
        std::fs::write(&path, lines.join("\n") + "\n").unwrap();
        path
    };
    for (row, held) in [(test[7], true), (pool_row, false)] {
        let out = dir.path().join(format!("curve_{row}"));
        curve_ok(
            &shifted(row),
            &out,
            &[
                "--methods",
                "nominal,paper-rotz,kinematic",
                "--sizes",
                "40,120",
                "--draws",
                "2",
                "--seed",
                SEED,
            ],
            None,
        );
        let found = rows(&out.join("curve.csv"));
        assert_eq!(found.len(), 3 * 2 * 2);
        for r in &found {
            let max = num(r, "test_max_mm");
            assert_eq!(
                max > 10.0,
                held,
                "row {row} shifted by 20 mm ({}): {} at {} points, draw {}: held-out max {max} mm",
                if held { "held out" } else { "in the pool" },
                r["method"],
                r["size"],
                r["draw"]
            );
        }
    }
}

/// The same seed gives the same curve.csv and curve.png, byte for byte, on one thread and on three.
#[test]
fn the_curve_does_not_depend_on_the_thread_count() {
    let dir = TempDir::new().unwrap();
    let args = [
        "--methods",
        "nominal,kinematic,elastic",
        "--sizes",
        "40,90",
        "--draws",
        "2",
        "--seed",
        SEED,
    ];
    let out: Vec<PathBuf> = ["1", "3"]
        .iter()
        .map(|t| {
            let out = dir.path().join(format!("threads_{t}"));
            curve_ok(&measurements(), &out, &args, Some(t));
            out
        })
        .collect();
    for file in ["curve.csv", "curve.png"] {
        assert!(
            read(&out[0].join(file)) == read(&out[1].join(file)),
            "{file} differs between 1 and 3 threads"
        );
    }
}

/// Bad input: one error line naming the flag or the file and row, exit 1, nothing written.
#[test]
fn bad_input_is_one_line_and_writes_nothing() {
    let dir = TempDir::new().unwrap();
    let data = measurements();
    let n = rows(&data).len();
    let n_pool = n - held_out(n).len();
    let too_many = format!("50,{}", n_pool + 1);
    let largest = format!("the largest possible size is {n_pool}");
    let text = String::from_utf8(read(&data)).unwrap();
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    let x = lines[0].split(',').position(|h| h == "x1").unwrap();
    let mut cells: Vec<String> = lines[4].split(',').map(String::from).collect();
    cells[x] = "NaN".into();
    lines[4] = cells.join(",");
    let nan = dir.path().join("nan.csv");
    std::fs::write(&nan, lines.join("\n") + "\n").unwrap();
    let cases: [(&Path, [&str; 6], Vec<&str>); 4] = [
        (
            &data,
            ["--methods", "nominal", "--sizes", &too_many, "--draws", "1"],
            vec!["--sizes", &largest],
        ),
        (
            &data,
            [
                "--methods",
                "nominal,kinematik",
                "--sizes",
                "50",
                "--draws",
                "1",
            ],
            vec!["kinematik"],
        ),
        (
            &data,
            ["--methods", "nominal", "--sizes", "50", "--draws", "0"],
            vec!["--draws 0"],
        ),
        (
            &nan,
            ["--methods", "nominal", "--sizes", "50", "--draws", "1"],
            vec!["nan.csv", "x1"],
        ),
    ];
    for (k, (file, args, needles)) in cases.iter().enumerate() {
        let out = dir.path().join(format!("bad_{k}"));
        let output = curve(file, &out, args, None);
        assert_eq!(output.status.code(), Some(1), "{args:?}");
        assert_clean_failure(&output, &out, needles);
        assert!(!out.exists(), "{args:?} created {}", out.display());
    }
}
