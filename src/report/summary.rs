//! `metrics.csv` and `summary.md`.
//!
//! `metrics.csv` holds one row per run, in the study's fixed run order, millimetres and radians rounded to a
//! fixed number of decimals. Every number of `summary.md` is an aggregate of those *written* values (the
//! helpers below round exactly as the CSV does), so parsing `metrics.csv` and aggregating again gives the
//! summary's numbers to the last digit. The aggregation helpers are public for that check.

use std::fmt::Write as _;

use crate::campaign::DistributionKind;
use crate::error::{Error, Result};
use crate::eval::Stats;
use crate::study::{RunMetrics, StudyResult};

/// The columns of every `metrics.csv`, in order.
pub const COLUMNS: [&str; 23] = [
    "scenario",
    "region",
    "distribution",
    "method",
    "n_train",
    "seed",
    "status",
    "test_mean_mm",
    "test_max_mm",
    "test_std_mm",
    "test_rms_mm",
    "test_p95_mm",
    "truth_mean_mm",
    "truth_max_mm",
    "truth_p95_mm",
    "outside_mean_mm",
    "closed_loop_mean_mm",
    "floor_mean_mm",
    "o1",
    "o2",
    "o3",
    "logdet",
    "fit_ms",
];

/// The observability columns (see [`crate::design::observability`]): dimensionless, written with
/// [`INDEX_DIGITS`] significant digits. `logdet` is empty when the points leave a parameter undetermined
/// (−∞); O1 to O3 are then 0.
pub const INDEX_COLUMNS: [&str; 4] = ["o1", "o2", "o3", "logdet"];
pub const INDEX_DIGITS: usize = 7;

/// Appended when the campaign measures orientation.
pub const ORIENTATION_COLUMNS: [&str; 4] = [
    "test_ori_mean_rad",
    "test_ori_max_rad",
    "test_ori_std_rad",
    "truth_ori_mean_rad",
];

/// Decimals of the millimetre columns (1 nm) and of the radian columns (1 nrad).
pub const MM_DECIMALS: usize = 6;
pub const RAD_DECIMALS: usize = 9;

/// A method is done learning at the smallest size whose median ground-truth mean is within this fraction of
/// its plateau …
pub const PLATEAU_TOLERANCE: f64 = 0.10;
/// … and within this factor of the floor (the oracle's ground-truth mean on the same campaigns).
pub const FLOOR_FACTOR: f64 = 1.5;

/// The header of `metrics.csv`.
pub fn header(orientation: bool) -> Vec<&'static str> {
    let mut h = COLUMNS.to_vec();
    if orientation {
        h.extend(ORIENTATION_COLUMNS);
    }
    h
}

/// `x` as written with `decimals` decimals and read back.
fn rounded(x: f64, decimals: usize) -> f64 {
    format!("{x:.decimals$}")
        .parse()
        .expect("a formatted finite number parses")
}

/// A length in metres as `metrics.csv` holds it: millimetres, rounded to [`MM_DECIMALS`].
pub fn mm(x_m: f64) -> f64 {
    rounded(x_m * 1e3, MM_DECIMALS)
}

/// An angle as `metrics.csv` holds it: radians, rounded to [`RAD_DECIMALS`].
pub fn rad(x: f64) -> f64 {
    rounded(x, RAD_DECIMALS)
}

/// An observability index as written: [`INDEX_DIGITS`] significant digits.
fn index_text(x: f64) -> String {
    format!("{x:.prec$e}", prec = INDEX_DIGITS - 1)
}

/// An observability index as `metrics.csv` holds it.
pub fn index(x: f64) -> f64 {
    index_text(x)
        .parse()
        .expect("a formatted finite number parses")
}

/// The numeric cells of a run (every column after `status` but `fit_ms`), in header order, as written to
/// `metrics.csv`: `None` for an empty cell (a failed run, a view the study did not compute, a non-finite value).
pub fn cells(run: &RunMetrics, orientation: bool) -> Vec<(&'static str, Option<f64>)> {
    let ok = run.failure.is_none();
    let length = |x: Option<f64>| x.filter(|v| ok && v.is_finite()).map(mm);
    let angle = |x: Option<f64>| x.filter(|v| ok && v.is_finite()).map(rad);
    let get = |s: &Option<Stats>, f: fn(&Stats) -> f64| s.as_ref().map(f);
    let mut out = vec![
        ("test_mean_mm", length(get(&run.test, |s| s.mean))),
        ("test_max_mm", length(get(&run.test, |s| s.max))),
        ("test_std_mm", length(get(&run.test, |s| s.std))),
        ("test_rms_mm", length(get(&run.test, |s| s.rms))),
        ("test_p95_mm", length(get(&run.test, |s| s.p95))),
        ("truth_mean_mm", length(get(&run.truth, |s| s.mean))),
        ("truth_max_mm", length(get(&run.truth, |s| s.max))),
        ("truth_p95_mm", length(get(&run.truth, |s| s.p95))),
        ("outside_mean_mm", length(get(&run.outside, |s| s.mean))),
        (
            "closed_loop_mean_mm",
            length(get(&run.closed_loop, |s| s.mean)),
        ),
        ("floor_mean_mm", length(run.floor_mean)),
    ];
    let obs = run.observability.filter(|_| ok);
    let dimensionless = |x: Option<f64>| x.filter(|v| v.is_finite()).map(index);
    out.extend([
        ("o1", dimensionless(obs.map(|o| o.o1))),
        ("o2", dimensionless(obs.map(|o| o.o2))),
        ("o3", dimensionless(obs.map(|o| o.o3))),
        ("logdet", dimensionless(obs.map(|o| o.logdet))),
    ]);
    if orientation {
        out.extend([
            (
                "test_ori_mean_rad",
                angle(get(&run.test_orientation, |s| s.mean)),
            ),
            (
                "test_ori_max_rad",
                angle(get(&run.test_orientation, |s| s.max)),
            ),
            (
                "test_ori_std_rad",
                angle(get(&run.test_orientation, |s| s.std)),
            ),
            (
                "truth_ori_mean_rad",
                angle(get(&run.truth_orientation, |s| s.mean)),
            ),
        ]);
    }
    out
}

/// The value of one numeric column of a run, as written (see [`cells`]); `fit_ms` rounded to 0.1 ms.
pub fn cell(run: &RunMetrics, orientation: bool, column: &str) -> Option<f64> {
    if column == "fit_ms" {
        return run.fit_ms.is_finite().then(|| rounded(run.fit_ms, 1));
    }
    cells(run, orientation)
        .into_iter()
        .find(|(name, _)| *name == column)
        .and_then(|(_, v)| v)
}

/// `ok`, or `failed: <reason>` on one line.
pub fn status(run: &RunMetrics) -> String {
    match &run.failure {
        None => "ok".into(),
        Some(reason) => {
            let reason = reason.split_whitespace().collect::<Vec<_>>().join(" ");
            format!("failed: {reason}")
        }
    }
}

/// `metrics.csv`: one row per run, in the study's run order.
pub fn metrics_csv(study: &StudyResult) -> Result<Vec<u8>> {
    let data_error = |e: csv::Error| Error::Data {
        origin: "metrics.csv".into(),
        message: e.to_string(),
    };
    let mut w = csv::Writer::from_writer(Vec::new());
    w.write_record(header(study.orientation))
        .map_err(data_error)?;
    for run in &study.runs {
        let k = &run.key;
        let mut record = vec![
            study.scenario.name.clone(),
            k.region.clone(),
            k.distribution.name().to_string(),
            k.method.clone(),
            k.n_train.to_string(),
            k.seed.to_string(),
            status(run),
        ];
        for (name, value) in cells(run, study.orientation) {
            let text = |v: f64| {
                if INDEX_COLUMNS.contains(&name) {
                    index_text(v)
                } else if name.ends_with("_rad") {
                    format!("{v:.RAD_DECIMALS$}")
                } else {
                    format!("{v:.MM_DECIMALS$}")
                }
            };
            record.push(value.map_or(String::new(), text));
        }
        let fit = if run.fit_ms.is_finite() {
            format!("{:.1}", run.fit_ms)
        } else {
            String::new()
        };
        // fit_ms sits before the orientation columns.
        record.insert(COLUMNS.len() - 1, fit);
        w.write_record(&record).map_err(data_error)?;
    }
    w.into_inner().map_err(|e| Error::Data {
        origin: "metrics.csv".into(),
        message: e.to_string(),
    })
}

/// The columns of `outside.csv`: one row per (run, region of use, band of distance from the training region).
pub const OUTSIDE_COLUMNS: [&str; 11] = [
    "scenario",
    "region",
    "use_region",
    "distribution",
    "method",
    "n_train",
    "seed",
    "from_mm",
    "to_mm",
    "points",
    "outside_mean_mm",
];

/// A band edge as `outside.csv` writes it: millimetres, `inf` for the open end.
fn edge_text(m: f64) -> String {
    if m.is_finite() {
        format!("{}", rounded(m * 1e3, 3))
    } else {
        "inf".into()
    }
}

/// `outside.csv`: the ground-truth mean of every successful run by distance from its training region (`region`)
/// over the ground-truth points (grid and shell) of each region of use; band `from_mm = to_mm = 0` is inside
/// the training region, the others hold `from_mm < distance ≤ to_mm`.
pub fn outside_csv(study: &StudyResult) -> Result<Vec<u8>> {
    let data_error = |e: csv::Error| Error::Data {
        origin: "outside.csv".into(),
        message: e.to_string(),
    };
    let mut w = csv::Writer::from_writer(Vec::new());
    w.write_record(OUTSIDE_COLUMNS).map_err(data_error)?;
    for run in study.runs.iter().filter(|r| r.failure.is_none()) {
        let k = &run.key;
        for b in &run.by_distance {
            w.write_record([
                study.scenario.name.clone(),
                k.region.clone(),
                b.use_region.clone(),
                k.distribution.name().to_string(),
                k.method.clone(),
                k.n_train.to_string(),
                k.seed.to_string(),
                edge_text(b.from_m),
                edge_text(b.to_m),
                b.points.to_string(),
                format!("{:.MM_DECIMALS$}", mm(b.mean)),
            ])
            .map_err(data_error)?;
        }
    }
    w.into_inner().map_err(|e| Error::Data {
        origin: "outside.csv".into(),
        message: e.to_string(),
    })
}

/// A band as the summary names it.
fn band_label(from_m: f64, to_m: f64) -> String {
    if to_m == 0.0 {
        "inside".into()
    } else if to_m.is_finite() {
        format!("{}–{} mm", edge_text(from_m), edge_text(to_m))
    } else {
        format!("beyond {} mm", edge_text(from_m))
    }
}

fn outside_md(study: &StudyResult, a: &Axes, out: &mut String) {
    let Some(&largest) = a.sizes.last() else {
        return;
    };
    let Some(&layout) = a.distributions.first() else {
        return;
    };
    let ok = |r: &&RunMetrics| {
        r.failure.is_none() && r.key.n_train == largest && r.key.distribution == layout
    };
    if !study
        .runs
        .iter()
        .filter(ok)
        .any(|r| !r.by_distance.is_empty())
    {
        return;
    }
    let _ = writeln!(out, "## Accuracy by distance from the training region\n");
    let _ = writeln!(
        out,
        "Ground-truth mean (mm) of the calibration fitted in one region (trained on {largest} points, {} \
         layout) over the ground-truth points (grid and shell) of each region where it is used, grouped by \
         the distance of the target from the training region's box; median over the successful seeds. Every \
         run's rows are in `outside.csv`.\n",
        layout.name()
    );
    let methods: Vec<String> = a.methods.iter().map(|m| format!("`{m}`")).collect();
    for training in &a.regions {
        for used in &a.regions {
            let bands: Vec<(f64, f64)> = {
                let mut v: Vec<(f64, f64)> = Vec::new();
                for r in study
                    .runs
                    .iter()
                    .filter(ok)
                    .filter(|r| &r.key.region == training)
                {
                    for b in r.by_distance.iter().filter(|b| &b.use_region == used) {
                        if !v.contains(&(b.from_m, b.to_m)) {
                            v.push((b.from_m, b.to_m));
                        }
                    }
                }
                v.sort_by(|x, y| x.1.total_cmp(&y.1));
                v
            };
            if bands.is_empty() {
                continue;
            }
            let _ = writeln!(out, "### Trained in `{training}`, used in `{used}`\n");
            table_header(out, "distance", &methods);
            for (from, to) in bands {
                let row: Vec<String> = a
                    .methods
                    .iter()
                    .map(|m| {
                        let values: Vec<f64> = study
                            .runs
                            .iter()
                            .filter(ok)
                            .filter(|r| &r.key.region == training && &r.key.method == m)
                            .flat_map(|r| &r.by_distance)
                            .filter(|b| &b.use_region == used && b.from_m == from && b.to_m == to)
                            .map(|b| mm(b.mean))
                            .collect();
                        spread(&values).map_or("—".into(), |s| fmt_mm(s.median))
                    })
                    .collect();
                let _ = writeln!(out, "| {} | {} |", band_label(from, to), row.join(" | "));
            }
            out.push('\n');
        }
    }
}

// ------------------------------------------------------------------------------------------------------------
// Aggregation

/// Median and interquartile range of a set of values (quantiles by linear interpolation between order
/// statistics, numpy's default).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Spread {
    pub n: usize,
    pub median: f64,
    pub q1: f64,
    pub q3: f64,
}

/// The `q` quantile of sorted values, linear interpolation between order statistics.
pub fn quantile(sorted: &[f64], q: f64) -> f64 {
    let pos = q * (sorted.len() - 1) as f64;
    let lo = pos.floor() as usize;
    let hi = pos.ceil() as usize;
    sorted[lo] + (sorted[hi] - sorted[lo]) * (pos - lo as f64)
}

/// `None` when no value is finite.
pub fn spread(values: &[f64]) -> Option<Spread> {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    Some(Spread {
        n: v.len(),
        median: quantile(&v, 0.5),
        q1: quantile(&v, 0.25),
        q3: quantile(&v, 0.75),
    })
}

/// The values of the study, in the order tables and plots show them: configuration order first, then
/// anything else the runs hold in order of appearance; sizes ascending.
#[derive(Clone, Debug, PartialEq)]
pub struct Axes {
    pub regions: Vec<String>,
    pub distributions: Vec<DistributionKind>,
    pub methods: Vec<String>,
    pub sizes: Vec<usize>,
}

pub fn axes(study: &StudyResult) -> Axes {
    fn push<T: PartialEq + Clone>(v: &mut Vec<T>, x: &T) {
        if !v.contains(x) {
            v.push(x.clone());
        }
    }
    let mut a = Axes {
        regions: study.regions.iter().map(|r| r.name.clone()).collect(),
        distributions: Vec::new(),
        methods: Vec::new(),
        sizes: study.config.sizes.clone(),
    };
    for d in &study.config.distributions {
        push(&mut a.distributions, d);
    }
    for m in &study.config.methods {
        push(&mut a.methods, m);
    }
    // Only what has runs is shown.
    let runs = &study.runs;
    a.regions
        .retain(|r| runs.iter().any(|x| &x.key.region == r));
    a.distributions
        .retain(|d| runs.iter().any(|x| x.key.distribution == *d));
    a.methods
        .retain(|m| runs.iter().any(|x| &x.key.method == m));
    a.sizes.retain(|n| runs.iter().any(|x| x.key.n_train == *n));
    for run in runs {
        push(&mut a.regions, &run.key.region);
        push(&mut a.distributions, &run.key.distribution);
        push(&mut a.methods, &run.key.method);
        push(&mut a.sizes, &run.key.n_train);
    }
    a.sizes.sort_unstable();
    a.sizes.dedup();
    a
}

fn runs_of<'a>(
    study: &'a StudyResult,
    region: &'a str,
    distribution: DistributionKind,
    n_train: usize,
) -> impl Iterator<Item = &'a RunMetrics> + 'a {
    study.runs.iter().filter(move |r| {
        r.key.region == region && r.key.distribution == distribution && r.key.n_train == n_train
    })
}

/// Median and IQR of one column (a `metrics.csv` name) over the successful runs (the seeds) of one
/// (region, layout, method, size); `None` when no successful run has the value.
pub fn cell_spread(
    study: &StudyResult,
    region: &str,
    distribution: DistributionKind,
    method: &str,
    n_train: usize,
    column: &str,
) -> Option<Spread> {
    let values: Vec<f64> = runs_of(study, region, distribution, n_train)
        .filter(|r| r.key.method == method && r.failure.is_none())
        .filter_map(|r| cell(r, study.orientation, column))
        .collect();
    spread(&values)
}

/// The floor of a (region, layout, size) whatever the method: per seed, the `floor_mean_mm` of the first
/// successful run (in run order) that has one; median and IQR over the seeds.
pub fn floor_spread(
    study: &StudyResult,
    region: &str,
    distribution: DistributionKind,
    n_train: usize,
) -> Option<Spread> {
    let mut seeds = Vec::new();
    let mut values = Vec::new();
    for r in runs_of(study, region, distribution, n_train) {
        if r.failure.is_some() || seeds.contains(&r.key.seed) {
            continue;
        }
        if let Some(v) = cell(r, study.orientation, "floor_mean_mm") {
            seeds.push(r.key.seed);
            values.push(v);
        }
    }
    spread(&values)
}

/// One size of a learning curve.
#[derive(Clone, Debug, PartialEq)]
pub struct CurvePoint {
    pub n_train: usize,
    /// Runs (seeds) at this size, and how many of them failed.
    pub runs: usize,
    pub failed: usize,
    /// Ground-truth mean (mm) over the successful seeds.
    pub truth: Option<Spread>,
    /// The floor (mm) over the same runs.
    pub floor: Option<Spread>,
}

/// Ground-truth mean against training-set size for one (region, layout, method).
#[derive(Clone, Debug, PartialEq)]
pub struct Curve {
    pub region: String,
    pub distribution: DistributionKind,
    pub method: String,
    /// Sizes ascending.
    pub points: Vec<CurvePoint>,
}

/// Every learning curve, ordered by region, layout, method (as [`axes`]).
pub fn learning_curves(study: &StudyResult) -> Vec<Curve> {
    let a = axes(study);
    let mut curves = Vec::new();
    for region in &a.regions {
        for &distribution in &a.distributions {
            for method in &a.methods {
                let points: Vec<CurvePoint> = a
                    .sizes
                    .iter()
                    .filter_map(|&n| {
                        let runs: Vec<&RunMetrics> = runs_of(study, region, distribution, n)
                            .filter(|r| &r.key.method == method)
                            .collect();
                        (!runs.is_empty()).then(|| CurvePoint {
                            n_train: n,
                            runs: runs.len(),
                            failed: runs.iter().filter(|r| r.failure.is_some()).count(),
                            truth: cell_spread(
                                study,
                                region,
                                distribution,
                                method,
                                n,
                                "truth_mean_mm",
                            ),
                            floor: cell_spread(
                                study,
                                region,
                                distribution,
                                method,
                                n,
                                "floor_mean_mm",
                            ),
                        })
                    })
                    .collect();
                if !points.is_empty() {
                    curves.push(Curve {
                        region: region.clone(),
                        distribution,
                        method: method.clone(),
                        points,
                    });
                }
            }
        }
    }
    curves
}

/// The plateau of a curve: its median ground-truth mean at the largest size that has one (mm).
pub fn plateau(points: &[CurvePoint]) -> Option<f64> {
    points.iter().rev().find_map(|p| p.truth.map(|s| s.median))
}

/// Points needed: the smallest size whose median ground-truth mean is within [`PLATEAU_TOLERANCE`] of the
/// [`plateau`] and within [`FLOOR_FACTOR`] × the median floor at that size; `None`: not reached.
pub fn points_needed(points: &[CurvePoint]) -> Option<usize> {
    let plateau = plateau(points)?;
    points
        .iter()
        .filter(|p| {
            let (Some(t), Some(f)) = (p.truth, p.floor) else {
                return false;
            };
            t.median <= (1.0 + PLATEAU_TOLERANCE) * plateau && t.median <= FLOOR_FACTOR * f.median
        })
        .map(|p| p.n_train)
        .min()
}

// ------------------------------------------------------------------------------------------------------------
// summary.md

/// A millimetre value as the summary prints it.
pub fn fmt_mm(x: f64) -> String {
    format!("{x:.4}")
}

/// A radian value as the summary prints it.
pub fn fmt_rad(x: f64) -> String {
    format!("{x:.6}")
}

/// A cell of the learning-curve table: `median [q1–q3]`, `—` without a value.
pub fn fmt_spread(s: Option<Spread>) -> String {
    match s {
        Some(s) => format!("{} [{}–{}]", fmt_mm(s.median), fmt_mm(s.q1), fmt_mm(s.q3)),
        None => "—".into(),
    }
}

/// The smallest size whose median ground-truth mean is within [`PLATEAU_TOLERANCE`] of the plateau.
pub fn plateau_from(points: &[CurvePoint]) -> Option<usize> {
    let plateau = plateau(points)?;
    points
        .iter()
        .filter(|p| {
            p.truth
                .is_some_and(|t| t.median <= (1.0 + PLATEAU_TOLERANCE) * plateau)
        })
        .map(|p| p.n_train)
        .min()
}

/// The smallest size whose median ground-truth mean is within [`FLOOR_FACTOR`] × the floor at that size.
pub fn floor_from(points: &[CurvePoint]) -> Option<usize> {
    points
        .iter()
        .filter(|p| matches!((p.truth, p.floor), (Some(t), Some(f)) if t.median <= FLOOR_FACTOR * f.median))
        .map(|p| p.n_train)
        .min()
}

/// A cell of the points-needed table: the size meeting both conditions, else which one each size meets.
/// The floor is strict (the oracle estimates only the tracker frame), so the two parts tell a user more than
/// "not reached" alone: where the curve stops improving, and whether it ever nears the floor.
pub fn fmt_points_needed(points: &[CurvePoint]) -> String {
    match points_needed(points) {
        Some(n) => n.to_string(),
        None => {
            let part = |n: Option<usize>| n.map_or("never".to_string(), |n| n.to_string());
            format!(
                "not reached (plateau from {}; {FLOOR_FACTOR}× floor {})",
                part(plateau_from(points)),
                part(floor_from(points))
            )
        }
    }
}

/// The rows of Table 1 (positions, mm) and Table 2 (orientations, rad): label and `metrics.csv` column.
pub const TABLE1_ROWS: [(&str, &str); 12] = [
    ("test mean (mm)", "test_mean_mm"),
    ("test max (mm)", "test_max_mm"),
    ("test std (mm)", "test_std_mm"),
    ("test RMS (mm)", "test_rms_mm"),
    ("test p95 (mm)", "test_p95_mm"),
    ("ground-truth mean (mm)", "truth_mean_mm"),
    ("ground-truth max (mm)", "truth_max_mm"),
    ("ground-truth p95 (mm)", "truth_p95_mm"),
    ("outside the region, mean (mm)", "outside_mean_mm"),
    ("closed loop, mean (mm)", "closed_loop_mean_mm"),
    ("floor: oracle's ground-truth mean (mm)", "floor_mean_mm"),
    ("fit time (ms)", "fit_ms"),
];
pub const TABLE2_ROWS: [(&str, &str); 4] = [
    ("test mean (rad)", "test_ori_mean_rad"),
    ("test max (rad)", "test_ori_max_rad"),
    ("test std (rad)", "test_ori_std_rad"),
    ("ground-truth mean (rad)", "truth_ori_mean_rad"),
];

fn fmt_column(column: &str, s: Option<Spread>) -> String {
    match s {
        None => "—".into(),
        Some(s) if column.ends_with("_rad") => fmt_rad(s.median),
        Some(s) if column == "fit_ms" => format!("{:.1}", s.median),
        Some(s) => fmt_mm(s.median),
    }
}

fn list<T: std::fmt::Display>(items: &[T]) -> String {
    items
        .iter()
        .map(|x| x.to_string())
        .collect::<Vec<_>>()
        .join(", ")
}

fn micro(x_m: f64) -> String {
    format!("{}", rounded(x_m * 1e6, 2))
}

fn scenario_in_words(study: &StudyResult, a: &Axes, out: &mut String) {
    let s = &study.scenario;
    let c = &study.config;
    let robot = s.robot.urdf.file_stem().map_or_else(
        || s.robot.urdf.display().to_string(),
        |x| x.to_string_lossy().into_owned(),
    );
    let t = &s.truth;
    let k = &s.tracker;
    let _ = writeln!(out, "## The scenario\n");
    let _ = writeln!(
        out,
        "- **Robot:** `{robot}` (`{}`), carrying {} kg on the flange. The true robot differs from its nominal \
         model by joint-frame offsets of σ {} µm and {} µrad per axis, joint zero offsets of σ {} µrad, \
         joint compliance ({} Nm/rad, {} % scatter), gear errors of {} µrad and a repeatability of σ {} µrad per \
         joint.",
        s.robot.urdf.display(),
        s.robot.payload_kg,
        micro(t.frame_translation_m),
        micro(t.frame_rotation_rad),
        micro(t.joint_zero_rad),
        list(&t.stiffness_nm_per_rad),
        rounded(t.stiffness_spread * 100.0, 2),
        micro(t.gear_amplitude_rad),
        micro(t.repeatability_rad),
    );
    let reflectors = s.reflectors.nominal_m.len();
    let _ = writeln!(
        out,
        "- **Tracker:** at ({}, {}, {}) mm in the robot's base frame; noise σ {} µm + {} µm/m in range and {} µrad \
         per angle. {}",
        rounded(k.position_m[0] * 1e3, 1),
        rounded(k.position_m[1] * 1e3, 1),
        rounded(k.position_m[2] * 1e3, 1),
        micro(k.range_sigma_m),
        micro(k.range_sigma_per_m),
        micro(k.angle_sigma_rad),
        if study.orientation {
            format!("A nest of {reflectors} reflectors: position and orientation are measured.")
        } else if reflectors == 1 {
            "One reflector: positions only.".to_string()
        } else {
            format!("{reflectors} reflectors; positions only.")
        },
    );
    for r in &study.regions {
        let _ = writeln!(
            out,
            "- **Region `{}`:** a {} × {} × {} mm box centred at ({}, {}, {}) mm in the base frame; the tool \
             tilts up to {}° and turns ±{}°.",
            r.name,
            rounded(r.size_m[0] * 1e3, 1),
            rounded(r.size_m[1] * 1e3, 1),
            rounded(r.size_m[2] * 1e3, 1),
            rounded(r.center_m[0] * 1e3, 1),
            rounded(r.center_m[1] * 1e3, 1),
            rounded(r.center_m[2] * 1e3, 1),
            r.cone_half_angle_deg,
            r.spin_deg,
        );
    }
    let layouts: Vec<&str> = a.distributions.iter().map(|d| d.name()).collect();
    let _ = writeln!(
        out,
        "- **Training sets:** {} points (plus {} % as many validation points), placed by {} layout(s): {}; each \
         size and layout repeated with {} seed(s) (new layout, orientations and noise; the same robot).",
        list(&a.sizes),
        rounded(c.validation_ratio * 100.0, 1),
        layouts.len(),
        layouts.join(", "),
        c.seeds,
    );
    let _ = writeln!(
        out,
        "- **Judged on:** {} measured test points per region (one uniform campaign shared by every run); {} \
         noise-free ground-truth grid points per region; {} points in a {} mm shell just outside it; {} \
         closed-loop targets.",
        c.test_points,
        c.grid_points,
        c.shell_points,
        rounded(c.shell_width_m * 1e3, 1),
        c.closed_loop_points,
    );
    let failed = study.runs.iter().filter(|r| r.failure.is_some()).count();
    let _ = writeln!(
        out,
        "- **Methods:** {}. The *floor* is the oracle — the true robot, registered on the same training data — so \
         its ground-truth error is what perfect knowledge of the robot still leaves.",
        a.methods
            .iter()
            .map(|m| format!("`{m}`"))
            .collect::<Vec<_>>()
            .join(", "),
    );
    let _ = writeln!(
        out,
        "- **Runs:** {} in all, {} failed.\n",
        study.runs.len(),
        failed
    );
    let _ = writeln!(
        out,
        "*Ground-truth mean*: the mean distance (mm) between where a method predicts the reflector and where it \
         truly is, over the noise-free grid — what a user of the calibrated robot gets. *Test*: the same against \
         tracker measurements of the test points (noise included). Medians over the successful seeds; \
         [q1–q3] is the interquartile range.\n"
    );
}

fn table_header(out: &mut String, first: &str, columns: &[String]) {
    let _ = writeln!(out, "| {first} | {} |", columns.join(" | "));
    let _ = writeln!(out, "|---|{}", "---:|".repeat(columns.len()));
}

/// Sentence fragments of the verdict for one method in one region.
fn verdict(
    method: &str,
    curves: &[&Curve],
    study: &StudyResult,
    region: &str,
    largest: usize,
) -> String {
    let runs: Vec<&RunMetrics> = study
        .runs
        .iter()
        .filter(|r| r.key.region == region && r.key.method == method)
        .collect();
    let failed: Vec<&RunMetrics> = runs
        .iter()
        .copied()
        .filter(|r| r.failure.is_some())
        .collect();
    let failures = if failed.is_empty() {
        String::new()
    } else {
        format!(
            " {} of {} runs failed (first: {}).",
            failed.len(),
            runs.len(),
            failed[0].failure.as_deref().map_or(String::new(), |r| {
                r.split_whitespace().collect::<Vec<_>>().join(" ")
            })
        )
    };
    if failed.len() == runs.len() {
        return format!("**{method}**: every run failed — no result.{failures}");
    }
    if method == "nominal" {
        // No calibration: the starting point every method is measured against.
        let last = curves
            .iter()
            .filter_map(|c| c.points.iter().rev().find(|p| p.truth.is_some()))
            .next();
        if let Some(p) = last {
            let t = p.truth.expect("found with a value").median;
            let ratio = p
                .floor
                .filter(|f| f.median > 0.0)
                .map(|f| format!(", {:.1}× the floor", t / f.median))
                .unwrap_or_default();
            return format!(
                "**{method}**: no calibration — ground-truth mean {} mm{ratio}; what every method starts \
                 from.{failures}",
                fmt_mm(t)
            );
        }
    }
    // Reached: the layout needing the fewest points (ties: the lower plateau).
    let mut reached: Vec<(usize, f64, &Curve)> = curves
        .iter()
        .filter_map(|c| Some((points_needed(&c.points)?, plateau(&c.points)?, *c)))
        .collect();
    reached.sort_by(|a, b| a.0.cmp(&b.0).then(a.1.total_cmp(&b.1)));
    let others = |best: DistributionKind| -> String {
        let rest: Vec<String> = curves
            .iter()
            .filter(|c| c.distribution != best)
            .map(|c| {
                format!(
                    "{}: {}",
                    c.distribution.name(),
                    fmt_points_needed(&c.points)
                )
            })
            .collect();
        if rest.is_empty() {
            String::new()
        } else {
            format!(" ({})", rest.join("; "))
        }
    };
    if let Some(&(n, _, c)) = reached.first() {
        let p = c
            .points
            .iter()
            .find(|p| p.n_train == n)
            .expect("the size exists");
        let t = p.truth.expect("reached implies a value").median;
        let f = p.floor.expect("reached implies a floor").median;
        return format!(
            "**{method}**: reaches the floor from **{n} points** with {} — ground-truth mean {} mm against a \
             floor of {} mm ({:.2}×){}. Fewer points cost accuracy; more buy little.{failures}",
            c.distribution.name(),
            fmt_mm(t),
            fmt_mm(f),
            t / f,
            others(c.distribution),
        );
    }
    // Not reached: describe the best layout at its largest size.
    let best = curves
        .iter()
        .filter_map(|c| {
            let last = c.points.iter().rev().find(|p| p.truth.is_some())?;
            Some((last.truth?.median, *c, last))
        })
        .min_by(|a, b| a.0.total_cmp(&b.0));
    let Some((t, c, last)) = best else {
        return format!("**{method}**: no ground-truth result.{failures}");
    };
    let floor = last.floor.map(|f| f.median);
    let ratio = floor
        .filter(|f| *f > 0.0)
        .map(|f| format!(", {:.1}× the floor ({} mm)", t / f, fmt_mm(f)))
        .unwrap_or_default();
    let previous = c
        .points
        .iter()
        .rev()
        .filter(|p| p.n_train < last.n_train)
        .find_map(|p| p.truth.map(|s| (p.n_train, s.median)));
    let at = if last.n_train == largest {
        String::new()
    } else {
        " (the largest size with a result)".to_string()
    };
    match previous {
        Some((n0, t0)) if t0 > (1.0 + PLATEAU_TOLERANCE) * t => format!(
            "**{method}**: still improving at {} points{at} with {} — {} mm, down from {} mm at {n0}{ratio}; more \
             points may help, but it does not reach {FLOOR_FACTOR}× the floor in this study.{failures}",
            last.n_train,
            c.distribution.name(),
            fmt_mm(t),
            fmt_mm(t0),
        ),
        _ => format!(
            "**{method}**: plateaus at {} mm (best layout {}, {} points{at}){ratio} — more points do not help; \
             the model itself is the limit.{failures}",
            fmt_mm(t),
            c.distribution.name(),
            last.n_train,
        ),
    }
}

/// A method's best accuracy in the study: the lowest plateau (median ground-truth mean at the largest size,
/// mm) over the layouts, and the target within [`PLATEAU_TOLERANCE`] of it.
pub fn best_target(curves: &[&Curve]) -> Option<f64> {
    curves
        .iter()
        .filter_map(|c| plateau(&c.points))
        .min_by(f64::total_cmp)
        .map(|p| (1.0 + PLATEAU_TOLERANCE) * p)
}

/// The smallest size of a curve whose median ground-truth mean is at most `target` (mm).
pub fn points_to(points: &[CurvePoint], target: f64) -> Option<usize> {
    points
        .iter()
        .filter(|p| p.truth.is_some_and(|t| t.median <= target))
        .map(|p| p.n_train)
        .min()
}

/// Which layout gets each method to its best accuracy with the fewest points: the floor above is out of
/// every method's reach, so this asks for the method's own best plateau instead.
fn best_accuracy_md(curves: &[Curve], a: &Axes, out: &mut String) {
    let _ = writeln!(out, "## Points to the best accuracy\n");
    let _ = writeln!(
        out,
        "Per method, the smallest training-set size at which each layout's median ground-truth mean is within \
         {} % of the method's best plateau over all layouts (the target, mm); **bold**: the layout that needs \
         the fewest points (ties: all of them); \"never\": not within the sizes studied.\n",
        PLATEAU_TOLERANCE * 100.0
    );
    for region in &a.regions {
        let _ = writeln!(out, "### Region `{region}`\n");
        let mut columns = vec!["target (mm)".to_string()];
        columns.extend(a.distributions.iter().map(|d| d.name().to_string()));
        table_header(out, "method", &columns);
        for m in &a.methods {
            let these: Vec<&Curve> = curves
                .iter()
                .filter(|c| &c.region == region && &c.method == m)
                .collect();
            let Some(target) = best_target(&these) else {
                continue;
            };
            let needed: Vec<Option<usize>> = a
                .distributions
                .iter()
                .map(|&d| {
                    these
                        .iter()
                        .find(|c| c.distribution == d)
                        .and_then(|c| points_to(&c.points, target))
                })
                .collect();
            let fewest = needed.iter().flatten().min().copied();
            let mut row = vec![fmt_mm(target)];
            row.extend(needed.iter().map(|n| match n {
                Some(n) if Some(*n) == fewest => format!("**{n}**"),
                Some(n) => n.to_string(),
                None => "never".into(),
            }));
            let _ = writeln!(out, "| `{m}` | {} |", row.join(" | "));
        }
        out.push('\n');
    }
}

/// The method whose parameters a method's observability describes, when another listed method has the same
/// ones (a hybrid and its base): its rows would repeat that method's.
fn same_model_as(method: &str) -> Option<&'static str> {
    crate::calib::registry::MethodKind::parse(method)
        .ok()?
        .info()
        .base
        .map(|b| b.name)
}

/// One cell of the observability table: medians of O1, O3 and logdet over the successful seeds.
pub fn fmt_observability(
    study: &StudyResult,
    region: &str,
    distribution: DistributionKind,
    method: &str,
    n_train: usize,
) -> String {
    let median = |column: &str| {
        cell_spread(study, region, distribution, method, n_train, column).map(|s| s.median)
    };
    match (median("o1"), median("o3"), median("logdet")) {
        (None, None, None) => "—".into(),
        (o1, o3, logdet) => {
            let f = |x: Option<f64>, p: fn(f64) -> String| x.map_or("—".to_string(), p);
            format!(
                "{} · {} · {}",
                f(o1, |x| format!("{x:.4}")),
                f(o3, |x| format!("{x:.3e}")),
                f(logdet, |x| format!("{x:.1}"))
            )
        }
    }
}

fn observability_md(study: &StudyResult, a: &Axes, out: &mut String) {
    let shown: Vec<&String> = a
        .methods
        .iter()
        .filter(|m| {
            !same_model_as(m).is_some_and(|base| a.methods.iter().any(|x| x == base))
                && study
                    .runs
                    .iter()
                    .any(|r| &r.key.method == *m && r.observability.is_some())
        })
        .collect();
    if shown.is_empty() {
        return;
    }
    let _ = writeln!(out, "## Observability\n");
    let _ = writeln!(
        out,
        "How well each layout's training points determine each model's parameters: O1 (geometric mean of the \
         singular values of the identification Jacobian, per point) · O3 (its smallest singular value) · \
         ln det(JᵀJ) (the D-criterion), medians over the successful seeds; columns scaled to unit RMS over \
         the joint space, so values compare across layouts and sizes. Higher is better; O3 = 0 means a \
         parameter combination is not determined. `hybrid` and `hybrid-kinematic` share `elastic`'s and \
         `kinematic`'s parameters; `nominal` and `residual-ridge` have none. The paper's models are \
         assessed through their error parameters held constant, the degree-0 part of their regressions.\n"
    );
    for region in &a.regions {
        for m in &shown {
            let _ = writeln!(out, "### Region `{region}`, `{m}`\n");
            let layouts: Vec<String> = a
                .distributions
                .iter()
                .map(|d| d.name().to_string())
                .collect();
            table_header(out, "n_train", &layouts);
            for &n in &a.sizes {
                let row: Vec<String> = a
                    .distributions
                    .iter()
                    .map(|&d| fmt_observability(study, region, d, m, n))
                    .collect();
                let _ = writeln!(out, "| {n} | {} |", row.join(" | "));
            }
            out.push('\n');
        }
    }
}

/// `summary.md`: the scenario in words, Table 1 (and 2) at the largest training set, learning curves, points
/// needed and a verdict per method. Every number is an aggregate of `metrics.csv`'s written values.
pub fn summary_md(study: &StudyResult) -> Result<String> {
    if study.runs.is_empty() {
        return Err(Error::Invalid("the study has no runs to report".into()));
    }
    let a = axes(study);
    let curves = learning_curves(study);
    let largest = *a.sizes.last().expect("runs imply a size");
    let mut out = String::new();
    let _ = writeln!(out, "# Study `{}`\n", study.scenario.name);
    let _ = writeln!(
        out,
        "How many tracker points, placed how, with which method? Every number below is computed from \
         `metrics.csv` next to this file.\n"
    );
    scenario_in_words(study, &a, &mut out);

    let methods: Vec<String> = a.methods.iter().map(|m| format!("`{m}`")).collect();
    for region in &a.regions {
        for &d in &a.distributions {
            if !study.runs.iter().any(|r| {
                &r.key.region == region && r.key.distribution == d && r.key.n_train == largest
            }) {
                continue;
            }
            let _ = writeln!(
                out,
                "## Table 1 — region `{region}`, {} layout, {largest} training points\n",
                d.name()
            );
            let _ = writeln!(
                out,
                "Positional errors, median over the successful seeds (`nominal`, if present, is the paper's \
                 \"Measured\").\n"
            );
            table_header(&mut out, "error", &methods);
            for (label, column) in TABLE1_ROWS {
                let row: Vec<String> = a
                    .methods
                    .iter()
                    .map(|m| fmt_column(column, cell_spread(study, region, d, m, largest, column)))
                    .collect();
                let _ = writeln!(out, "| {label} | {} |", row.join(" | "));
            }
            let failed: Vec<String> = a
                .methods
                .iter()
                .filter_map(|m| {
                    let runs: Vec<_> = runs_of(study, region, d, largest)
                        .filter(|r| &r.key.method == m)
                        .collect();
                    let bad = runs.iter().filter(|r| r.failure.is_some()).count();
                    (bad > 0).then(|| format!("`{m}` {bad} of {}", runs.len()))
                })
                .collect();
            if !failed.is_empty() {
                let _ = writeln!(out, "\nFailed runs (left out): {}.", failed.join(", "));
            }
            out.push('\n');
            if study.orientation {
                let _ = writeln!(
                    out,
                    "## Table 2 — region `{region}`, {} layout, {largest} training points\n",
                    d.name()
                );
                let _ = writeln!(
                    out,
                    "Orientational errors, median over the successful seeds.\n"
                );
                table_header(&mut out, "error", &methods);
                for (label, column) in TABLE2_ROWS {
                    let row: Vec<String> = a
                        .methods
                        .iter()
                        .map(|m| {
                            fmt_column(column, cell_spread(study, region, d, m, largest, column))
                        })
                        .collect();
                    let _ = writeln!(out, "| {label} | {} |", row.join(" | "));
                }
                out.push('\n');
            }
        }
    }

    let _ = writeln!(out, "## Learning curves\n");
    let _ = writeln!(
        out,
        "Ground-truth mean (mm) against training-set size: median [q1–q3] over the successful seeds. The floor \
         column is the oracle's, per seed, over the same campaigns. Plots: `plots/`.\n"
    );
    for region in &a.regions {
        for &d in &a.distributions {
            let these: Vec<&Curve> = curves
                .iter()
                .filter(|c| &c.region == region && c.distribution == d)
                .collect();
            if these.is_empty() {
                continue;
            }
            let _ = writeln!(out, "### Region `{region}`, {} layout\n", d.name());
            let mut columns = methods.clone();
            columns.push("floor".into());
            table_header(&mut out, "n_train", &columns);
            for &n in &a.sizes {
                let mut row: Vec<String> = a
                    .methods
                    .iter()
                    .map(|m| {
                        let p = these
                            .iter()
                            .find(|c| &c.method == m)
                            .and_then(|c| c.points.iter().find(|p| p.n_train == n));
                        match p {
                            None => "—".into(),
                            Some(p) if p.failed > 0 => {
                                format!("{} ({} failed)", fmt_spread(p.truth), p.failed)
                            }
                            Some(p) => fmt_spread(p.truth),
                        }
                    })
                    .collect();
                row.push(fmt_spread(floor_spread(study, region, d, n)));
                let _ = writeln!(out, "| {n} | {} |", row.join(" | "));
            }
            out.push('\n');
        }
    }

    let _ = writeln!(out, "## Points needed\n");
    let _ = writeln!(
        out,
        "The smallest training-set size whose median ground-truth mean is within {} % of the method's plateau \
         (its median at the largest size) and within {FLOOR_FACTOR} × the floor at that size. When no size is, \
         the cell says from which size the curve is on its plateau, and from which it is within \
         {FLOOR_FACTOR} × the floor (\"never\" in this study). The floor is the oracle registered on the same \
         points: it estimates 6 parameters where the methods estimate dozens, so no method comes close at \
         large sizes; a method whose plateau is many times the floor is limited by its model, one still \
         falling at the largest size by the number of points.\n",
        PLATEAU_TOLERANCE * 100.0
    );
    for region in &a.regions {
        let _ = writeln!(out, "### Region `{region}`\n");
        let layouts: Vec<String> = a
            .distributions
            .iter()
            .map(|d| d.name().to_string())
            .collect();
        table_header(&mut out, "method", &layouts);
        for m in &a.methods {
            let row: Vec<String> = a
                .distributions
                .iter()
                .map(|&d| {
                    curves
                        .iter()
                        .find(|c| &c.region == region && c.distribution == d && &c.method == m)
                        .map_or("—".into(), |c| fmt_points_needed(&c.points))
                })
                .collect();
            let _ = writeln!(out, "| `{m}` | {} |", row.join(" | "));
        }
        out.push('\n');
    }

    outside_md(study, &a, &mut out);
    observability_md(study, &a, &mut out);

    best_accuracy_md(&curves, &a, &mut out);

    let _ = writeln!(out, "## Verdict\n");
    for region in &a.regions {
        if a.regions.len() > 1 {
            let _ = writeln!(out, "Region `{region}`:\n");
        }
        for m in &a.methods {
            let these: Vec<&Curve> = curves
                .iter()
                .filter(|c| &c.region == region && &c.method == m)
                .collect();
            if these.is_empty() {
                continue;
            }
            let _ = writeln!(out, "- {}", verdict(m, &these, study, region, largest));
        }
        out.push('\n');
    }
    while out.ends_with("\n\n") {
        out.pop();
    }
    Ok(out)
}
