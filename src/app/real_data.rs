//! The `real_data` job: every calibration method on the real UR10 laser-tracker campaigns of Landgraf et al.
//! (IEEE CASE 2021), read through a column mapping, by the protocol of [`crate::eval::protocol`]; the
//! README's tables as Markdown, and `real_data.json`.
//!
//! 1. **Across campaigns**: fitted on all of series C (training 2/3, validation 1/3, split seed 0) and tested
//!    on all of series D and of series B; fitted on B, tested on C. Each test campaign's tracker frame and
//!    probe mounting are re-registered on its own points (`eval::transfer`), the same for every method.
//! 2. **Within series C**: `calibrate`'s default split (50 / 25 / 25 %, seed 0), the model's own registration.
//! 3. **Temperature**: every method that regresses on inputs beyond the joint angles, again with the
//!    temperature column offered as a candidate input.
//! 4. **The learning curve**: sizes drawn from the training and validation part of (2), several draws each,
//!    each split 2/3 training, 1/3 validation, all tested on the same held-out 25 % of series C.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use serde::Serialize;

use crate::calib::method::FitContext;
use crate::calib::registry::{CLASSICAL, MethodKind, REFERENCE};
use crate::calib::regression::RegressionOptions;
use crate::dataset::mapping::ColumnMapping;
use crate::dataset::range::JointRange;
use crate::dataset::{Dataset, repeat_groups};
use crate::error::{Error, Result};
use crate::eval::curve::{CurveDraw, CurvePlan, learning_curve};
use crate::eval::protocol::{self, METHODS, Row, Table, TestSet, without_inputs};
use crate::eval::split::SplitRule;
use crate::eval::transfer::TestRegistration;
use crate::eval::{Stats, centre};
use crate::output;
use crate::robot::Chain;
use crate::robot::dh::DhChain;

use super::curve;

/// The files of the three series, under the data set's directory.
pub const SERIES: [(&str, &str); 3] = [
    ("B", "Series_B/measurements_joint_configurations.csv"),
    ("C", "Series_C/measurements_random_poses.csv"),
    ("D", "Series_D/measurements_iso_cubes.csv"),
];

/// Where the data is and what to run (the flags of `real_data`).
#[derive(Clone, Debug)]
pub struct RealDataOptions {
    /// The data set's directory (Series_B, Series_C, Series_D).
    pub data_dir: PathBuf,
    pub mapping: PathBuf,
    pub robot: PathBuf,
    /// Output directory.
    pub out: PathBuf,
    /// Draws per learning-curve size.
    pub draws: usize,
    /// Learning-curve sizes; none skips the curve.
    pub sizes: Option<Vec<usize>>,
}

/// `real_data.json`.
#[derive(Serialize)]
struct Report {
    protocol: serde_json::Value,
    across: Vec<(String, Vec<Row>)>,
    within_c: Vec<Row>,
    curve: Vec<CurvePoint>,
}

/// One fit of the learning curve as `real_data.json` has always recorded it: the held-out mean (mm) or why
/// the fit failed (`calibrate curve`'s curve.csv adds the 95th percentile and the max).
#[derive(Serialize)]
struct CurvePoint {
    method: MethodKind,
    size: usize,
    draw: usize,
    mean_mm: Option<f64>,
    error: Option<String>,
}

impl From<CurveDraw> for CurvePoint {
    fn from(d: CurveDraw) -> CurvePoint {
        CurvePoint {
            method: d.method,
            size: d.size,
            draw: d.draw,
            mean_mm: d.mean_mm,
            error: d.error,
        }
    }
}

impl RealDataOptions {
    /// The counts, before any file is read: a curve of no draws would print a table of nothing.
    pub fn validate(&self) -> Result<()> {
        match &self.sizes {
            None => Ok(()),
            Some(sizes) => plan(sizes, self.draws).check_counts(),
        }
    }
}

/// The learning curve's plan: `calibrate`'s default split (seed 0), as the other tables.
fn plan(sizes: &[usize], draws: usize) -> CurvePlan {
    CurvePlan {
        rule: SplitRule::default(),
        sizes: sizes.to_vec(),
        draws,
    }
}

/// Reads the three series of `options.data_dir` through the mapping, runs the protocol, hands each table to
/// `show` as Markdown as soon as it is ready, and writes `real_data.json` into `options.out`. Returns the
/// file's path.
pub fn run(options: &RealDataOptions, show: &mut dyn FnMut(&str)) -> Result<PathBuf> {
    options.validate()?;
    output::check_dir(&options.out, &["real_data.json"])?;
    if !options.data_dir.is_dir() {
        return Err(Error::Data {
            origin: options.data_dir.display().to_string(),
            message: format!(
                "no such directory (looked for from {}): pass the IPA UR10 data set's directory (holding \
                 Series_B, Series_C, Series_D) with --data-dir",
                std::env::current_dir()
                    .map(|d| d.display().to_string())
                    .unwrap_or_else(|_| "the current directory".into())
            ),
        });
    }
    let chain = crate::robot::load(&options.robot, None)?;
    let dh = DhChain::from_chain(&chain)?;
    let mapping = ColumnMapping::load(&options.mapping)?;
    let series = read_series(&options.data_dir, &mapping, &chain)?;
    let ctx = FitContext::new(&chain, &dh);
    let rule = SplitRule::default();
    show(&ranges_md(&series, &chain));
    show(&repeats_md(&series));
    let tables = tables(
        &METHODS,
        &ctx,
        &series,
        options.sizes.as_deref(),
        options.draws,
        show,
    )?;
    let protocol = serde_json::json!({
        "data": options.data_dir.display().to_string(),
        "mapping": options.mapping.display().to_string(),
        "robot": options.robot.display().to_string(),
        "train_fraction": rule.train_fraction(),
        "seed": rule.seed,
        "test_registration_across": "tracker frame (rigid, 6) and probe mounting (position 3, rotation 3) re-registered on each test series' own points against the model's predicted flange poses",
        "payload_kg": 0.0,
        "regression": RegressionOptions::default(),
    });
    let report = Report {
        protocol,
        across: tables
            .across
            .into_iter()
            .map(|t| (t.title, t.rows))
            .collect(),
        within_c: tables.within_c.rows,
        curve: tables.curve.into_iter().map(CurvePoint::from).collect(),
    };
    let json = serde_json::to_vec_pretty(&report)
        .map_err(|e| Error::Invalid(format!("cannot serialize: {e}")))?;
    output::write_files(&options.out, &[("real_data.json", json)])?;
    Ok(options.out.join("real_data.json"))
}

/// The protocol's tables on the three series B, C, D (in the order of [`SERIES`]).
pub struct Tables {
    /// Fitted on C and tested on D and B; fitted on B and tested on C.
    pub across: Vec<Table>,
    pub within_c: Table,
    /// Empty without sizes.
    pub curve: Vec<CurveDraw>,
    /// The held-out points of C the curve is tested on.
    pub n_test: usize,
}

/// Runs the protocol of the module notes on `series` (B, C, D) with `methods`; hands each table to `show` as
/// Markdown as soon as it is ready. The learning curve only with `sizes`.
pub fn tables(
    methods: &[MethodKind],
    ctx: &FitContext,
    series: &[Dataset],
    sizes: Option<&[usize]>,
    draws: usize,
    show: &mut dyn FnMut(&str),
) -> Result<Tables> {
    let [b, c, d] = [&series[0], &series[1], &series[2]];
    let rule = SplitRule::default();
    let refit = |name, data| TestSet {
        name,
        data,
        registration: TestRegistration::Refit,
    };
    let mut across = Vec::new();
    for (train, tests) in [
        (("C", c), vec![refit("D", d), refit("B", b)]),
        (("B", b), vec![refit("C", c)]),
    ] {
        let table = protocol::across(methods, ctx, &rule, train, &tests)?;
        show(&rows_md(&table));
        show(&best_md(&table.rows));
        across.push(table);
    }
    let (within_c, parts) = protocol::within(methods, ctx, &rule, ("C", c))?;
    show(&rows_md(&within_c));
    let curve = match sizes {
        None => Vec::new(),
        Some(sizes) => {
            let found = learning_curve(methods, ctx, &plan(sizes, draws), &without_inputs(c))?;
            show(&curve::markdown(methods, sizes, &found, "series C"));
            found.draws
        }
    };
    Ok(Tables {
        across,
        within_c,
        curve,
        n_test: parts.test.len(),
    })
}

/// The three series, in the order of [`SERIES`].
pub fn read_series(dir: &Path, mapping: &ColumnMapping, chain: &Chain) -> Result<Vec<Dataset>> {
    SERIES
        .iter()
        .map(|(_, file)| {
            let data = mapping.read(&dir.join(file), chain)?;
            JointRange::of_chain(chain, "the robot's URDF").check(
                &data.origin,
                &data.point_ids,
                &data.q,
            )?;
            Ok(data)
        })
        .collect()
}

pub(super) fn name(r: &Row) -> String {
    if r.inputs.is_empty() {
        format!("`{}`", r.method)
    } else {
        format!("`{}` + {}", r.method, r.inputs.join(", "))
    }
}

// `write!` into a `String` cannot fail: its results are ignored below.

fn rows_md(table: &Table) -> String {
    let (title, rows) = (&table.title, &table.rows);
    let mut out = String::new();
    let _ = writeln!(out, "\n#### {title}\n");
    let tests: Vec<&str> = rows[0].scores.iter().map(|s| s.test.as_str()).collect();
    out += "| method |";
    for t in &tests {
        let _ = write!(
            out,
            " {t}: mean / max / std / p95 (mm) | {t}: orientation mean / p95 (mrad) |"
        );
    }
    out += " fit (ms) |\n|---|";
    for _ in &tests {
        out += "---|---|";
    }
    out += "---|\n";
    // A calibration that makes the arm worse than no calibration (issue 13) is marked where it appears.
    let nominal = rows
        .iter()
        .find(|r| r.method == REFERENCE && r.inputs.is_empty());
    let mut marked = false;
    for r in rows {
        let _ = write!(out, "| {} |", name(r));
        for (k, s) in r.scores.iter().enumerate() {
            let p = &s.position_mm;
            let reference = nominal.map(|n| &n.scores[k]);
            let worse = reference.is_some_and(|n| p.mean > n.position_mm.mean);
            let _ = write!(
                out,
                " {:.4}{} / {:.3} / {:.3} / {:.3} |",
                p.mean,
                if worse { " †" } else { "" },
                p.max,
                p.std,
                p.p95
            );
            match &s.orientation_mrad {
                Some(o) => {
                    let worse = reference
                        .and_then(|n| n.orientation_mrad.as_ref())
                        .is_some_and(|n| o.mean > n.mean);
                    let _ = write!(
                        out,
                        " {:.3}{} / {:.3} |",
                        o.mean,
                        if worse { " †" } else { "" },
                        o.p95
                    );
                    marked |= worse;
                }
                None => out += " — |",
            }
            marked |= worse;
        }
        let _ = writeln!(out, " {:.0} |", r.fit_ms);
    }
    out += "\n";
    if marked {
        out += "† worse than `nominal` on that test: the calibration makes the arm less accurate there.\n\n";
    }
    for s in &rows[0].scores {
        let _ = writeln!(
            out,
            "{}: {} (the same for every method).",
            s.test, s.fitted_on_test
        );
    }
    out
}

/// The best mean on each test against classical calibration's (`kinematic`): the margin the README reports.
fn best_md(rows: &[Row]) -> String {
    let mut out = String::new();
    for (k, s) in rows[0].scores.iter().enumerate() {
        let mean = |r: &Row| r.scores[k].position_mm.mean;
        let best = rows
            .iter()
            .min_by(|a, b| mean(a).total_cmp(&mean(b)))
            .expect("rows");
        if let Some(kin) = rows
            .iter()
            .find(|r| r.method == CLASSICAL && r.inputs.is_empty())
        {
            let _ = writeln!(
                out,
                "{}: best {} at {:.4} mm mean, {:.1} % below `{}`'s {:.4} mm.",
                s.test,
                name(best),
                mean(best),
                100.0 * (1.0 - mean(best) / mean(kin)),
                kin.method,
                mean(kin)
            );
        }
    }
    out
}

/// Configurations measured more than once (joint angles equal to 1 mrad): how far each measurement lies from
/// its group's mean, in the tracker frame. What no model of the joint angles can remove.
fn repeats_md(series: &[Dataset]) -> String {
    let mut out = String::from(
        "\n#### Repeated configurations: distance of each measurement from its group's mean (mm)\n\n\
         | series | groups | measurements | mean | p95 | max |\n|---|---|---|---|---|---|\n",
    );
    for ((name, _), data) in SERIES.iter().zip(series) {
        let q: Vec<&[f64]> = data.q.iter().map(Vec::as_slice).collect();
        let groups = repeat_groups(&q);
        let mut distances = Vec::new();
        let n_groups = groups.len();
        for members in &groups {
            let points: Vec<_> = members.iter().map(|&i| data.measured[i][0]).collect();
            let mean = centre(&points);
            distances.extend(points.iter().map(|p| (p - mean).norm() * 1e3));
        }
        let _ = match Stats::of(&distances) {
            Some(s) => writeln!(
                out,
                "| {name} | {n_groups} | {} | {:.4} | {:.4} | {:.4} |",
                distances.len(),
                s.mean,
                s.p95,
                s.max
            ),
            None => writeln!(out, "| {name} | 0 | 0 | — | — | — |"),
        };
    }
    out + "\n"
}

/// Per series: the range of every joint (degrees) and of the temperature: where each model is fitted.
fn ranges_md(series: &[Dataset], chain: &Chain) -> String {
    let mut out = String::from(
        "#### Where the series lie: joint ranges (°) and temperature (°C), min … max\n\n| series | points |",
    );
    for j in chain.joint_names() {
        let _ = write!(out, " {j} |");
    }
    let _ = writeln!(
        out,
        " temperature |\n|---|---|{}---|",
        "---|".repeat(chain.dof())
    );
    for ((name, _), data) in SERIES.iter().zip(series) {
        let _ = write!(out, "| {name} | {} |", data.len());
        let range = |values: Vec<f64>| {
            let lo = values.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            (lo, hi)
        };
        for j in 0..chain.dof() {
            let (lo, hi) = range(data.q.iter().map(|q| q[j].to_degrees()).collect());
            let _ = write!(out, " {lo:.0} … {hi:.0} |");
        }
        let _ = match &data.extra_inputs {
            Some(x) => {
                let (lo, hi) = range(x.values.iter().map(|v| v[0]).collect());
                writeln!(out, " {lo:.2} … {hi:.2} |")
            }
            None => writeln!(out, " — |"),
        };
    }
    out
}
