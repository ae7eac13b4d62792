//! The tables of `summary.md`, and how it prints numbers: the learning curves (compact, and per layout), Table 1
//! (and 2) at the largest training set in one table per region, the runs that calibration made worse, and
//! accuracy by distance from the training region.

use std::fmt::Write as _;

use crate::calib::registry::{MethodKind, REFERENCE};
use crate::campaign::LayoutKind;
use crate::study::{RunMetrics, StudyResult};

use super::aggregate::{Axes, Curve, Spread, cell_spread, floor_spread, runs_of, spread};
use super::metrics::{cell, edge_text, mm};

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

/// The rows of Table 1 (positions, mm) and Table 2 (orientations, rad): label and `metrics.csv` column.
pub const TABLE1_ROWS: [(&str, &str); 12] = [
    ("test mean", "test_mean_mm"),
    ("test max", "test_max_mm"),
    ("test std", "test_std_mm"),
    ("test RMS", "test_rms_mm"),
    ("test p95", "test_p95_mm"),
    ("truth mean", "truth_mean_mm"),
    ("truth max", "truth_max_mm"),
    ("truth p95", "truth_p95_mm"),
    ("outside mean", "outside_mean_mm"),
    ("closed loop mean", "closed_loop_mean_mm"),
    ("floor mean", "floor_mean_mm"),
    ("fit (ms)", "fit_ms"),
];
pub const TABLE2_ROWS: [(&str, &str); 4] = [
    ("test mean", "test_ori_mean_rad"),
    ("test max", "test_ori_max_rad"),
    ("test std", "test_ori_std_rad"),
    ("truth mean", "truth_ori_mean_rad"),
];

fn fmt_column(column: &str, s: Option<Spread>) -> String {
    match s {
        None => "—".into(),
        Some(s) if column.ends_with("_rad") => fmt_rad(s.median),
        Some(s) if column == "fit_ms" => format!("{:.1}", s.median),
        Some(s) => fmt_mm(s.median),
    }
}

pub(super) fn table_header(out: &mut String, first: &str, columns: &[String]) {
    let _ = writeln!(out, "| {first} | {} |", columns.join(" | "));
    let _ = writeln!(out, "|---|{}", "---:|".repeat(columns.len()));
}

/// Table 1 (positions) and, when the campaign measures orientation, Table 2 at the largest training set: one
/// table per region, a row per method and layout, a column per statistic; columns without a value anywhere and
/// rows without a successful run are left out (those runs are counted below the table).
pub(super) fn accuracy_tables(study: &StudyResult, a: &Axes, largest: usize, out: &mut String) {
    for region in &a.regions {
        for (table, rows, what, unit) in [
            ("Table 1", &TABLE1_ROWS[..], "Positional errors", "mm"),
            ("Table 2", &TABLE2_ROWS[..], "Orientational errors", "rad"),
        ] {
            if table == "Table 2" && !study.orientation {
                continue;
            }
            let keys: Vec<(MethodKind, LayoutKind)> = a
                .methods
                .iter()
                .flat_map(|&m| a.layouts.iter().map(move |&d| (m, d)))
                .collect();
            let value = |m: MethodKind, d: LayoutKind, column: &str| {
                cell_spread(study, region, d, m, largest, column)
            };
            let columns: Vec<(&str, &str)> = rows
                .iter()
                .copied()
                .filter(|(_, c)| keys.iter().any(|&(m, d)| value(m, d, c).is_some()))
                .collect();
            let shown: Vec<&(MethodKind, LayoutKind)> = keys
                .iter()
                .filter(|&&(m, d)| columns.iter().any(|(_, c)| value(m, d, c).is_some()))
                .collect();
            if shown.is_empty() {
                continue;
            }
            let _ = writeln!(
                out,
                "### {table} — region `{region}`, {largest} training points\n"
            );
            let _ = writeln!(
                out,
                "{what} ({unit}; *truth*: the noise-free ground-truth grid) at the largest size, median over the successful seeds (`nominal`, if present, is the \
                 paper's \"Measured\"); the floor is the oracle — the true robot registered on the same points.\n"
            );
            let mut header = vec!["layout".to_string()];
            header.extend(columns.iter().map(|(label, _)| label.to_string()));
            table_header(out, "method", &header);
            for &(m, d) in shown {
                let mut row = vec![d.name().to_string()];
                row.extend(columns.iter().map(|(_, c)| fmt_column(c, value(m, d, c))));
                let _ = writeln!(out, "| `{m}` | {} |", row.join(" | "));
            }
            if table == "Table 1" {
                let failed: Vec<String> = keys
                    .iter()
                    .filter_map(|&(m, d)| {
                        let runs: Vec<_> = runs_of(study, region, d, largest)
                            .filter(|r| r.key.method == m)
                            .collect();
                        let bad = runs.iter().filter(|r| r.failure.is_some()).count();
                        (bad > 0).then(|| format!("`{m}` {} {bad} of {}", d.name(), runs.len()))
                    })
                    .collect();
                if !failed.is_empty() {
                    let _ = writeln!(out, "\nFailed runs (left out): {}.", failed.join(", "));
                }
            }
            out.push('\n');
        }
    }
}

/// The learning curves in one compact table per region: a row per method on its best layout (the lowest
/// median at the largest size), a column per size, the median ground-truth mean (mm).
pub(super) fn compact_curves_md(a: &Axes, curves: &[Curve], out: &mut String) {
    for region in &a.regions {
        let _ = writeln!(
            out,
            "### Region `{region}`: each method on its best layout\n"
        );
        let mut columns = vec!["layout".to_string()];
        columns.extend(a.sizes.iter().map(|n| n.to_string()));
        table_header(out, "method", &columns);
        for m in &a.methods {
            let best = curves
                .iter()
                .filter(|c| &c.region == region && &c.method == m)
                .filter_map(|c| Some((super::aggregate::plateau(&c.points)?, c)))
                .min_by(|x, y| x.0.total_cmp(&y.0));
            let Some((_, c)) = best else {
                continue;
            };
            let mut row = vec![c.layout.name().to_string()];
            row.extend(a.sizes.iter().map(|&n| {
                c.points
                    .iter()
                    .find(|p| p.n_train == n)
                    .and_then(|p| p.truth)
                    .map_or("—".into(), |s| fmt_mm(s.median))
            }));
            let _ = writeln!(out, "| `{m}` | {} |", row.join(" | "));
        }
        out.push('\n');
    }
}

/// Runs whose ground-truth mean is above `nominal`'s on the same campaign (region, layout, size, seed): the
/// calibration made the arm worse. Counted per method and listed.
pub(super) fn worse_md(study: &StudyResult, out: &mut String) {
    let worse = worse_runs(study);
    let _ = writeln!(out, "### Runs where calibration made the arm worse\n");
    if !study.runs.iter().any(|r| r.key.method == REFERENCE) {
        let _ = writeln!(
            out,
            "`nominal` is not in the study, so there is nothing to compare with.\n"
        );
        return;
    }
    let compared = study
        .runs
        .iter()
        .filter(|r| r.failure.is_none() && r.key.method != REFERENCE)
        .count();
    let _ = writeln!(
        out,
        "{} of {compared} successful runs have a ground-truth mean above `nominal`'s (no calibration) on the \
         same campaign.{}\n",
        worse.len(),
        if worse.is_empty() { "" } else { " They are:" }
    );
    if worse.is_empty() {
        return;
    }
    table_header(
        out,
        "method",
        &[
            "layout".into(),
            "n_train".into(),
            "seed".into(),
            "after (mm)".into(),
            "nominal (mm)".into(),
        ],
    );
    let listed = worse.len().min(WORSE_LISTED);
    for &(r, after, before) in &worse[..listed] {
        let k = &r.key;
        let _ = writeln!(
            out,
            "| `{}` | {} | {} | {} | {} | {} |",
            k.method,
            k.layout.name(),
            k.n_train,
            k.seed,
            fmt_mm(after),
            fmt_mm(before)
        );
    }
    if worse.len() > listed {
        let _ = writeln!(
            out,
            "\n… and {} more (every run's errors are in `metrics.csv`).",
            worse.len() - listed
        );
    }
    out.push('\n');
}

/// The successful runs whose ground-truth mean is above `nominal`'s on the same campaign, with both values (mm),
/// in the study's order.
fn worse_runs(study: &StudyResult) -> Vec<(&RunMetrics, f64, f64)> {
    let column = "truth_mean_mm";
    let mut worse: Vec<(&RunMetrics, f64, f64)> = Vec::new();
    for r in study
        .runs
        .iter()
        .filter(|r| r.failure.is_none() && r.key.method != REFERENCE)
    {
        let nominal = study.runs.iter().find(|n| {
            n.key.method == REFERENCE
                && n.failure.is_none()
                && n.key.region == r.key.region
                && n.key.layout == r.key.layout
                && n.key.n_train == r.key.n_train
                && n.key.seed == r.key.seed
        });
        let (Some(n), Some(v)) = (nominal, cell(r, study.orientation, column)) else {
            continue;
        };
        if let Some(before) = cell(n, study.orientation, column)
            && v > before
        {
            worse.push((r, v, before));
        }
    }
    worse
}

/// At most this many runs made worse are listed in the summary.
const WORSE_LISTED: usize = 40;

/// The learning-curve table of every (region, layout): a row per size, a column per method and the floor.
pub(super) fn learning_curve_tables(
    study: &StudyResult,
    a: &Axes,
    curves: &[Curve],
    out: &mut String,
) {
    let methods: Vec<String> = a.methods.iter().map(|m| format!("`{m}`")).collect();
    let _ = writeln!(out, "### Learning curves per layout\n");
    let _ = writeln!(
        out,
        "Ground-truth mean (mm) against training-set size: median [q1–q3] over the successful seeds. The floor \
         column is the oracle's, per seed, over the same campaigns.\n"
    );
    for region in &a.regions {
        for &d in &a.layouts {
            let these: Vec<&Curve> = curves
                .iter()
                .filter(|c| &c.region == region && c.layout == d)
                .collect();
            if these.is_empty() {
                continue;
            }
            let _ = writeln!(out, "#### Region `{region}`, {} layout\n", d.name());
            let mut columns = methods.clone();
            columns.push("floor".into());
            table_header(out, "n_train", &columns);
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

pub(super) fn outside_md(study: &StudyResult, a: &Axes, out: &mut String) {
    let Some(&largest) = a.sizes.last() else {
        return;
    };
    let Some(&layout) = a.layouts.first() else {
        return;
    };
    let ok =
        |r: &&RunMetrics| r.failure.is_none() && r.key.n_train == largest && r.key.layout == layout;
    if !study
        .runs
        .iter()
        .filter(ok)
        .any(|r| !r.by_distance.is_empty())
    {
        return;
    }
    let _ = writeln!(out, "### Accuracy by distance from the training region\n");
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
            let _ = writeln!(out, "#### Trained in `{training}`, used in `{used}`\n");
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
