//! `metrics.csv` and `outside.csv`: the study's results as tidy rows, one per run (and per region of use and
//! band of distance, for `outside.csv`).
//!
//! `metrics.csv` holds one row per run, in the study's fixed run order, millimetres and radians rounded to a
//! fixed number of decimals. The helpers below ([`mm`], [`rad`], [`index`], [`cells`], [`cell`]) give a
//! value exactly as the file holds it, so that every number of `summary.md` (an aggregate of these *written*
//! values, see [`super::aggregate`]) can be recomputed from the file to the last digit.

use crate::calib::registry::REFERENCE;
use crate::error::{Error, Result};
use crate::eval::Stats;
use crate::study::{RunMetrics, StudyResult};

/// The columns of every `metrics.csv`, in order.
pub const COLUMNS: [&str; 24] = [
    "scenario",
    "region",
    "distribution",
    "method",
    "n_train",
    "seed",
    "status",
    "worse_than_nominal",
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

/// The header of `metrics.csv`.
pub fn header(orientation: bool) -> Vec<&'static str> {
    let mut h = COLUMNS.to_vec();
    if orientation {
        h.extend(ORIENTATION_COLUMNS);
    }
    h
}

/// `x` as written with `decimals` decimals and read back.
pub(super) fn rounded(x: f64, decimals: usize) -> f64 {
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

/// Whether `run` ends worse than the reference (`nominal`) on the same campaign (same region, layout, size and
/// seed): its ground-truth mean, as written, above the reference's — a calibration that makes the arm worse.
/// `None` for the reference itself, a failed run, or a study without the reference.
pub fn worse_than_nominal(run: &RunMetrics, study: &StudyResult) -> Option<bool> {
    if run.key.method == REFERENCE || run.failure.is_some() {
        return None;
    }
    let k = &run.key;
    let nominal = study.runs.iter().find(|r| {
        r.key.method == REFERENCE
            && r.key.region == k.region
            && r.key.layout == k.layout
            && r.key.n_train == k.n_train
            && r.key.seed == k.seed
    })?;
    let (a, b) = (run.truth.as_ref()?, nominal.truth.as_ref()?);
    Some(mm(a.mean) > mm(b.mean))
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
            study.world.name.clone(),
            k.region.clone(),
            k.layout.name().to_string(),
            k.method.to_string(),
            k.n_train.to_string(),
            k.seed.to_string(),
            status(run),
            worse_than_nominal(run, study).map_or(String::new(), |w| w.to_string()),
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
pub(super) fn edge_text(m: f64) -> String {
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
                study.world.name.clone(),
                k.region.clone(),
                b.use_region.clone(),
                k.layout.name().to_string(),
                k.method.to_string(),
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
