//! `summary.md`: the text a person reads, top-down: the answer ([`super::answer`]), the learning curves and a
//! verdict per method, then the details — the scenario in words, the tables ([`super::tables`]) and the
//! observability of each model. Every number is an aggregate
//! ([`super::aggregate`]) of `metrics.csv`'s written values ([`super::metrics`]), so parsing `metrics.csv`
//! and aggregating again gives the summary's numbers to the last digit; the aggregation helpers are public
//! for that check.

use std::fmt::Write as _;

use crate::calib::registry::{MethodKind, REFERENCE};
use crate::campaign::LayoutKind;
use crate::error::{Error, Result};
use crate::eval::iso9283::Iso9283;
use crate::study::{RunMetrics, StudyResult};

use super::aggregate::{
    Axes, Curve, CurvePoint, PLATEAU_TOLERANCE, axes, cell_spread, learning_curves, plateau_from,
};
use super::answer::{Answer, STATISTICS, answer_md, answers, fmt_target};
use super::metrics::{rounded, worse_than_nominal};
use super::plots::file_safe;
use super::tables::{
    accuracy_tables, compact_curves_md, fmt_mm, learning_curve_tables, outside_md, table_header,
    worse_md,
};

/// `metrics.csv` and `outside.csv`, for the callers that write a study's three files from here.
pub use super::metrics::{metrics_csv, outside_csv};

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

/// "The scenario": the simulated world (robot, tracker, regions), then what the study varies and how it judges.
fn scenario_in_words(study: &StudyResult, a: &Axes, out: &mut String) {
    let _ = writeln!(out, "### The scenario\n");
    out.push_str(&robot_in_words(study));
    out.push_str(&tracker_in_words(study));
    out.push_str(&regions_in_words(study));
    out.push_str(&study_in_words(study, a));
    let _ = writeln!(
        out,
        "*Ground-truth mean*: the mean distance (mm) between where a method predicts the reflector and where it \
         truly is, over the noise-free grid — what a user of the calibrated robot gets. *Test*: the same against \
         tracker measurements of the test points (noise included). Medians over the successful seeds; \
         [q1–q3] is the interquartile range.\n"
    );
}

/// The robot's line: its URDF, payload and how the true robot departs from the nominal model.
fn robot_in_words(study: &StudyResult) -> String {
    let s = &study.world;
    let robot = s.robot.urdf.file_stem().map_or_else(
        || s.robot.urdf.display().to_string(),
        |x| x.to_string_lossy().into_owned(),
    );
    let t = &s.truth;
    format!(
        "- **Robot:** `{robot}` (`{}`), carrying {} kg on the flange. The true robot differs from its nominal \
         model by joint-frame offsets of σ {} µm and {} µrad per axis, joint zero offsets of σ {} µrad, \
         joint compliance ({} Nm/rad, {} % scatter), gear errors of {} µrad and a repeatability of σ {} µrad per \
         joint.\n",
        s.robot.urdf.display(),
        s.robot.payload_kg,
        micro(t.frame_translation_m),
        micro(t.frame_rotation_rad),
        micro(t.joint_zero_rad),
        list(&t.stiffness_nm_per_rad),
        rounded(t.stiffness_spread * 100.0, 2),
        micro(t.gear_amplitude_rad),
        micro(t.repeatability_rad),
    )
}

/// The tracker's line: where it stands, its noise, and what its reflectors let it measure.
fn tracker_in_words(study: &StudyResult) -> String {
    let s = &study.world;
    let k = &s.tracker;
    let reflectors = s.reflectors.nominal_m.len();
    format!(
        "- **Tracker:** at ({}, {}, {}) mm in the robot's base frame; noise σ {} µm + {} µm/m in range and {} µrad \
         per angle. {}\n",
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
    )
}

/// One line per region: its box and the tool's tilt and turn.
fn regions_in_words(study: &StudyResult) -> String {
    let mut out = String::new();
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
    out
}

/// What the study varies (training sets, methods) and judges them on, and how its runs went.
fn study_in_words(study: &StudyResult, a: &Axes) -> String {
    let c = &study.config;
    let mut out = String::new();
    let layouts: Vec<&str> = a.layouts.iter().map(|d| d.name()).collect();
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
        "- **Runs:** {} in all, {} failed.",
        study.runs.len(),
        failed
    );
    let _ = writeln!(out, "- **Worse than nominal:** {}\n", worse_in_words(study));
    out
}

/// The runs whose calibration leaves the arm worse than the nominal model on the same campaign (ground-truth
/// mean; `metrics.csv`'s `worse_than_nominal`), counted by method and training-set size.
pub fn worse_in_words(study: &StudyResult) -> String {
    let mut by: Vec<(MethodKind, usize, usize)> = Vec::new();
    for run in &study.runs {
        if worse_than_nominal(run, study) == Some(true) {
            match by
                .iter_mut()
                .find(|(m, n, _)| *m == run.key.method && *n == run.key.n_train)
            {
                Some(e) => e.2 += 1,
                None => by.push((run.key.method, run.key.n_train, 1)),
            }
        }
    }
    let total: usize = by.iter().map(|e| e.2).sum();
    if total == 0 {
        return "no run ends worse than `nominal` on the same campaign.".into();
    }
    let parts: Vec<String> = by
        .iter()
        .map(|(m, n, c)| format!("`{m}` at {n} points: {c}"))
        .collect();
    format!(
        "**{total} runs end worse than `nominal`** on the same campaign (ground-truth mean; flagged in \
         `metrics.csv`): {}.",
        parts.join(", ")
    )
}

/// The verdict for one method in one region: where its curve ends, whether more points would help, and the
/// smallest target it reaches.
fn verdict(
    method: MethodKind,
    curves: &[&Curve],
    study: &StudyResult,
    answers: &[Answer],
) -> String {
    let region = curves.first().map_or("", |c| c.region.as_str());
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
    // The best layout: the lowest median at the largest size with a result.
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
    if method == REFERENCE {
        // No calibration: the starting point every method is measured against.
        return format!(
            "**{method}**: no calibration — ground-truth mean {} mm; what every method starts from.{failures}",
            fmt_mm(t)
        );
    }
    let curve = curve_in_words(c, last, t);
    let target = smallest_target_in_words(answers, region, method);
    format!(
        "**{method}**: {curve}{target}.{}{failures}",
        layout_sentence(method, curves)
    )
}

/// Where the best layout's curve `c` ends (`t` mm at `last`) and whether it still falls there: more points would
/// help, or the model is the limit.
fn curve_in_words(c: &Curve, last: &CurvePoint, t: f64) -> String {
    let previous = c
        .points
        .iter()
        .rev()
        .filter(|p| p.n_train < last.n_train)
        .find_map(|p| p.truth.map(|s| (p.n_train, s.median)));
    match previous {
        Some((n0, t0)) if t0 > (1.0 + PLATEAU_TOLERANCE) * t => format!(
            "still improving at {} points with {} — {} mm, down from {} mm at {n0}; more points would help",
            last.n_train,
            c.layout.name(),
            fmt_mm(t),
            fmt_mm(t0),
        ),
        _ => format!(
            "levels off at {} mm (best layout {}, within {} % from {} points) — more points do not help; its \
             model is the limit",
            fmt_mm(t),
            c.layout.name(),
            PLATEAU_TOLERANCE * 100.0,
            plateau_from(&c.points).map_or("—".to_string(), |n| n.to_string()),
        ),
    }
}

/// The smallest target on the ground-truth mean that `method` reaches in `region`, from how many points with
/// which layout; or that it reaches none.
fn smallest_target_in_words(answers: &[Answer], region: &str, method: MethodKind) -> String {
    let reached = answers
        .iter()
        .filter(|x| x.region == region && x.statistic == STATISTICS[0].0)
        .filter_map(|x| Some((x.target_mm, x.best_of(method)?)))
        .min_by(|a, b| a.0.total_cmp(&b.0));
    match reached {
        Some((target, cell)) => format!(
            "; its smallest target reached is {} mm (mean), from {} points with {}",
            fmt_target(target),
            cell.n_train.expect("best has points"),
            cell.layout.name()
        ),
        None => "; it reaches none of the targets".to_string(),
    }
}

/// Why the model-based layout helps or hurts `method`: its error against the best geometric layout's at the
/// largest size both have, and the reason its design implies.
fn layout_sentence(kind: MethodKind, curves: &[&Curve]) -> String {
    use crate::design::layout::PointDesign;
    let Some(designed) = curves.iter().find(|c| c.layout.selects()) else {
        return String::new();
    };
    let at = |c: &Curve, n: usize| {
        c.points
            .iter()
            .find(|p| p.n_train == n)
            .and_then(|p| p.truth)
            .map(|s| s.median)
    };
    let best = designed.points.iter().rev().find_map(|p| {
        let mine = p.truth?.median;
        curves
            .iter()
            .filter(|c| !c.layout.selects())
            .filter_map(|c| Some((at(c, p.n_train)?, *c)))
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .map(|(other, c)| (p.n_train, mine, other, c))
    });
    let Some((n, mine, other, geometric)) = best else {
        return String::new();
    };
    let design = PointDesign::of(kind);
    let ratio = mine / other;
    let (verb, why) = match (design, ratio) {
        (_, r) if (0.95..=1.05).contains(&r) => (
            "makes little difference to it",
            "the layout matters little for this model at this size",
        ),
        (PointDesign::Parameters(_), r) if r < 1.0 => (
            "helps it",
            "points chosen to determine its own parameters pay when its model describes the robot",
        ),
        (PointDesign::Parameters(_), _) => (
            "hurts it",
            "D-optimal points sit at the extremes of the joint space, where the errors its model lacks are \
             largest, so the fit is biased for the rest of the region (D-optimality assumes the model is right)",
        ),
        (PointDesign::SpaceFilling, r) if r < 1.0 => (
            "helps it",
            "it fits a function of the joint angles, and space-filling points cover those inputs evenly",
        ),
        (PointDesign::SpaceFilling, _) => (
            "hurts it",
            "it fits a function of the joint angles, and maximin points favour the edges of the pool's joint \
             space, so the configurations the region's targets mostly need are sampled more thinly than by \
             random points",
        ),
    };
    format!(
        " The {} layout ({}) {verb}: {} against {} mm with {} at {n} points — {why}.",
        designed.layout.name(),
        design.describe(),
        fmt_mm(mine),
        fmt_mm(other),
        geometric.layout.name(),
    )
}

/// The method whose parameters a method's observability describes, when another listed method has the same
/// ones (a hybrid and its base): its rows would repeat that method's.
fn same_model_as(method: MethodKind) -> Option<MethodKind> {
    MethodKind::of(method.info().base?)
}

/// One cell of the observability table: medians of O1, O3 and logdet over the successful seeds.
pub fn fmt_observability(
    study: &StudyResult,
    region: &str,
    layout: LayoutKind,
    method: MethodKind,
    n_train: usize,
) -> String {
    let median = |column: &str| {
        cell_spread(study, region, layout, method, n_train, column).map(|s| s.median)
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
    let shown: Vec<MethodKind> = a
        .methods
        .iter()
        .copied()
        .filter(|&m| {
            !same_model_as(m).is_some_and(|base| a.methods.contains(&base))
                && study
                    .runs
                    .iter()
                    .any(|r| r.key.method == m && r.observability.is_some())
        })
        .collect();
    if shown.is_empty() {
        return;
    }
    let _ = writeln!(out, "### Observability\n");
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
            let _ = writeln!(out, "#### Region `{region}`, `{m}`\n");
            let layouts: Vec<String> = a.layouts.iter().map(|d| d.name().to_string()).collect();
            table_header(out, "n_train", &layouts);
            for &n in &a.sizes {
                let row: Vec<String> = a
                    .layouts
                    .iter()
                    .map(|&d| fmt_observability(study, region, d, *m, n))
                    .collect();
                let _ = writeln!(out, "| {n} | {} |", row.join(" | "));
            }
            out.push('\n');
        }
    }
}

/// A study's `summary.md`, rendered. The recording shows it as a document, so [`super::recording::record`] takes
/// a `Summary` rather than any text: only [`Summary::of`] makes one, and a recording cannot be made before its
/// study's summary exists.
pub struct Summary(String);

impl Summary {
    /// Renders the study's `summary.md` ([`summary_md`]).
    pub fn of(study: &StudyResult) -> Result<Summary> {
        summary_md(study).map(Summary)
    }

    /// The markdown text.
    pub fn markdown(&self) -> &str {
        &self.0
    }

    /// The bytes of `summary.md`.
    pub fn into_bytes(self) -> Vec<u8> {
        self.0.into_bytes()
    }
}

/// `summary.md`, top-down: the answer, the learning curves and a verdict per method, then the details (the
/// scenario, the curves per layout, Table 1 at the largest size, runs made worse, accuracy outside the region,
/// observability). Every number is an aggregate of `metrics.csv`'s written values.
pub fn summary_md(study: &StudyResult) -> Result<String> {
    if study.runs.is_empty() {
        return Err(Error::Invalid("the study has no runs to report".into()));
    }
    let a = axes(study);
    let curves = learning_curves(study);
    let all = answers(study);
    let largest = *a.sizes.last().expect("runs imply a size");
    let mut out = String::new();
    let _ = writeln!(out, "# Study `{}`\n", study.world.name);
    let _ = writeln!(
        out,
        "How many tracker points, placed how, with which method, for the accuracy you need? Every number below \
         is computed from `metrics.csv` next to this file; the answer's every cell is in `answer.csv`.\n"
    );
    answer_md(study, &mut out);

    let _ = writeln!(out, "## Learning curves\n");
    let _ = writeln!(
        out,
        "Median ground-truth mean (mm) over the seeds against the number of training points; the figure has \
         every layout with its interquartile band and the floor (the true robot registered on the same points).\n"
    );
    for region in &a.regions {
        let _ = writeln!(
            out,
            "![learning curves, region {region}](plots/learning_curves_{}.png)\n",
            file_safe(region)
        );
    }
    compact_curves_md(&a, &curves, &mut out);
    super::trajectory::trajectory_md(study, &mut out);

    let _ = writeln!(out, "## Verdict\n");
    for region in &a.regions {
        if a.regions.len() > 1 {
            let _ = writeln!(out, "Region `{region}`:\n");
        }
        for &m in &a.methods {
            let these: Vec<&Curve> = curves
                .iter()
                .filter(|c| &c.region == region && c.method == m)
                .collect();
            if these.is_empty() {
                continue;
            }
            let _ = writeln!(out, "- {}", verdict(m, &these, study, &all));
        }
        out.push('\n');
    }

    let _ = writeln!(out, "## Details\n");
    scenario_in_words(study, &a, &mut out);
    learning_curve_tables(study, &a, &curves, &mut out);
    accuracy_tables(study, &a, largest, &mut out);
    worse_md(study, &mut out);
    outside_md(study, &a, &mut out);
    observability_md(study, &a, &mut out);
    while out.ends_with("\n\n") {
        out.pop();
    }
    Ok(out)
}

/// The ISO 9283 section of a campaign's `summary.md` (scenarios with `[iso9283]`): AP per point, its mean and the
/// largest RP, in mm, per method; `iso9283.csv` has every component and docs/iso9283.md what is followed.
pub fn iso9283_md(iso: &Iso9283) -> String {
    let c = &iso.cube;
    let mut out = format!(
        "## ISO 9283 pose accuracy and repeatability\n\nCube of edge {:.1} mm centred at [{:.1}, {:.1}, {:.1}] mm in \
         region `{}`, {} cycles P1 → P5 → P4 → P3 → P2 on the true arm, each method commanding through its \
         inverse; position of the reflector, mm (every component in `iso9283.csv`).\n\n\
         | method | AP P1 | AP P2 | AP P3 | AP P4 | AP P5 | mean AP | largest RP |\n\
         |---|---|---|---|---|---|---|---|\n",
        c.edge_mm, c.centre_mm[0], c.centre_mm[1], c.centre_mm[2], c.region, iso.cycles
    );
    for m in &iso.methods {
        let _ = write!(out, "| {} |", m.method);
        match &m.points {
            Ok(points) => {
                for a in points {
                    let _ = write!(out, " {:.4} |", a.ap * 1e3);
                }
                let mean = points.iter().map(|a| a.ap).sum::<f64>() / points.len().max(1) as f64;
                let rp = points.iter().filter_map(|a| a.rp).fold(f64::NAN, f64::max);
                let rp = if rp.is_nan() {
                    "—".into()
                } else {
                    format!("{:.4}", rp * 1e3)
                };
                let _ = writeln!(out, " {:.4} | {rp} |", mean * 1e3);
            }
            Err(e) => {
                let _ = writeln!(out, " failed: {e} | — | — | — | — | — | — |");
            }
        }
    }
    out
}
