//! The tables of `summary.md`, and how it prints numbers: Table 1 (and 2) at the largest training set, the
//! learning curves, the points needed, accuracy by distance from the training region, and the points to each
//! method's best accuracy.

use std::fmt::Write as _;

use crate::study::{RunMetrics, StudyResult};

use super::aggregate::{
    Axes, Curve, CurvePoint, FLOOR_FACTOR, PLATEAU_TOLERANCE, Spread, best_target, cell_spread,
    floor_from, floor_spread, plateau_from, points_needed, points_to, runs_of, spread,
};
use super::metrics::{edge_text, mm};

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

pub(super) fn table_header(out: &mut String, first: &str, columns: &[String]) {
    let _ = writeln!(out, "| {first} | {} |", columns.join(" | "));
    let _ = writeln!(out, "|---|{}", "---:|".repeat(columns.len()));
}

/// Table 1 (positions) and, when the campaign measures orientation, Table 2 for every (region, layout) at the
/// largest training set, with the runs that failed there.
pub(super) fn accuracy_tables(study: &StudyResult, a: &Axes, largest: usize, out: &mut String) {
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
            table_header(out, "error", &methods);
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
                table_header(out, "error", &methods);
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
}

/// The learning-curve table of every (region, layout): a row per size, a column per method and the floor.
pub(super) fn learning_curve_tables(
    study: &StudyResult,
    a: &Axes,
    curves: &[Curve],
    out: &mut String,
) {
    let methods: Vec<String> = a.methods.iter().map(|m| format!("`{m}`")).collect();
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

/// The points-needed table of every region: a row per method, a column per layout.
pub(super) fn points_needed_tables(a: &Axes, curves: &[Curve], out: &mut String) {
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
        table_header(out, "method", &layouts);
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

/// Which layout gets each method to its best accuracy with the fewest points: the floor above is out of
/// every method's reach, so this asks for the method's own best plateau instead.
pub(super) fn best_accuracy_md(curves: &[Curve], a: &Axes, out: &mut String) {
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
