//! The answer to the planning question: for each accuracy a user may need (`study.targets_mm`, on the
//! ground-truth mean and on its 95th percentile), the fewest training points with which each method and layout
//! reaches it in at least [`REACH_SHARE`] of the seeds, the hours of tracker time that campaign costs, and one
//! recommended (method, layout, points) per target. `summary.md` opens with it, `answer.csv` holds every cell,
//! and the binary prints the recommendations.
//!
//! Every number comes from `metrics.csv`'s written values ([`cell`]), so the answer can be recomputed from the
//! file alone: a size *reaches* a target when at least [`REACH_SHARE`] of its runs (failed runs count as not
//! reaching) have the statistic at or below the target.

use std::fmt::Write as _;

use crate::calib::registry::MethodKind;
use crate::campaign::LayoutKind;
use crate::error::{Error, Result};
use crate::study::StudyResult;
use crate::study::config::REACH_SHARE;

use super::aggregate::{Axes, Spread, axes, cell_spread, runs_of};
use super::metrics::cell;
use super::tables::{fmt_mm, table_header};

/// The statistics a target applies to: `metrics.csv` column and how the report names it.
pub const STATISTICS: [(&str, &str); 2] = [
    ("truth_mean_mm", "ground-truth mean"),
    ("truth_p95_mm", "ground-truth p95"),
];

/// One (method, layout) against one target.
#[derive(Clone, Debug, PartialEq)]
pub struct Cell {
    pub method: MethodKind,
    pub layout: LayoutKind,
    /// The fewest training points reaching the target; `None`: not within the sizes studied.
    pub n_train: Option<usize>,
    /// At `n_train` (else at the largest size): runs at or below the target, and runs (seeds).
    pub reaching: usize,
    pub seeds: usize,
    /// The statistic at `n_train` over the successful seeds (mm).
    pub expected: Option<Spread>,
    /// The median of the statistic at the largest size with a successful run (mm): where the curve ends.
    pub plateau: Option<f64>,
    /// The largest size studied for this method and layout.
    pub largest: usize,
}

/// Every (method, layout) against one target, in one region, on one statistic.
#[derive(Clone, Debug, PartialEq)]
pub struct Answer {
    pub region: String,
    /// `metrics.csv` column and name of the statistic.
    pub statistic: &'static str,
    pub statistic_name: &'static str,
    pub target_mm: f64,
    /// Methods in study order, each with its layouts in study order.
    pub cells: Vec<Cell>,
    /// Index into `cells` of the recommendation: the fewest points, then the lower expected median, then
    /// study order.
    pub recommended: Option<usize>,
}

impl Answer {
    pub fn recommendation(&self) -> Option<&Cell> {
        self.recommended.map(|i| &self.cells[i])
    }

    /// The best layout of `method` for this target: the fewest points, then the lower expected median.
    pub fn best_of(&self, method: MethodKind) -> Option<&Cell> {
        best(self.cells.iter().filter(|c| c.method == method))
    }
}

fn best<'a>(cells: impl Iterator<Item = &'a Cell>) -> Option<&'a Cell> {
    cells.filter(|c| c.n_train.is_some()).min_by(|a, b| {
        a.n_train.cmp(&b.n_train).then(
            median(a.expected)
                .total_cmp(&median(b.expected))
                .then(std::cmp::Ordering::Equal),
        )
    })
}

fn median(s: Option<Spread>) -> f64 {
    s.map_or(f64::INFINITY, |s| s.median)
}

/// Whether `reaching` of `seeds` runs is enough: at least [`REACH_SHARE`] of them.
pub fn enough(reaching: usize, seeds: usize) -> bool {
    seeds > 0 && reaching as f64 >= REACH_SHARE * seeds as f64 - 1e-9
}

/// The answers of a study: per region, statistic and target (study order).
pub fn answers(study: &StudyResult) -> Vec<Answer> {
    let a = axes(study);
    let mut out = Vec::new();
    for region in &a.regions {
        for (statistic, statistic_name) in STATISTICS {
            for &target_mm in &study.config.targets_mm {
                let mut cells = Vec::new();
                for &method in &a.methods {
                    for &d in &a.layouts {
                        if let Some(c) = cell_of(study, &a, region, d, method, statistic, target_mm)
                        {
                            cells.push(c);
                        }
                    }
                }
                let recommended =
                    best(cells.iter()).and_then(|b| cells.iter().position(|c| std::ptr::eq(c, b)));
                out.push(Answer {
                    region: region.clone(),
                    statistic,
                    statistic_name,
                    target_mm,
                    cells,
                    recommended,
                });
            }
        }
    }
    out
}

fn cell_of(
    study: &StudyResult,
    a: &Axes,
    region: &str,
    d: LayoutKind,
    method: MethodKind,
    statistic: &str,
    target_mm: f64,
) -> Option<Cell> {
    let mut first: Option<(usize, usize, usize)> = None;
    let mut last_counts = (0, 0);
    let mut largest = None;
    let mut plateau = None;
    for &n in &a.sizes {
        let runs: Vec<_> = runs_of(study, region, d, n)
            .filter(|r| r.key.method == method)
            .collect();
        if runs.is_empty() {
            continue;
        }
        largest = Some(n);
        let reaching = runs
            .iter()
            .filter(|r| r.failure.is_none())
            .filter(|r| cell(r, study.orientation, statistic).is_some_and(|v| v <= target_mm))
            .count();
        last_counts = (reaching, runs.len());
        if let Some(s) = cell_spread(study, region, d, method, n, statistic) {
            plateau = Some(s.median);
        }
        if first.is_none() && enough(reaching, runs.len()) {
            first = Some((n, reaching, runs.len()));
        }
    }
    let largest = largest?;
    let (n_train, (reaching, seeds)) = match first {
        Some((n, r, s)) => (Some(n), (r, s)),
        None => (None, last_counts),
    };
    Some(Cell {
        method,
        layout: d,
        n_train,
        reaching,
        seeds,
        expected: n_train.and_then(|n| cell_spread(study, region, d, method, n, statistic)),
        plateau,
        largest,
    })
}

/// Hours with two decimals.
pub fn fmt_hours(h: f64) -> String {
    format!("{h:.2}")
}

/// A target as the report writes it.
pub fn fmt_target(t: f64) -> String {
    format!("{t}")
}

fn spread_text(s: Option<Spread>) -> String {
    s.map_or("—".into(), |s| {
        format!("{} [{}–{}]", fmt_mm(s.median), fmt_mm(s.q1), fmt_mm(s.q3))
    })
}

/// What the target is below, if anything: the repeatability or the tracker's noise of the region.
fn limit_note(study: &StudyResult, region: &str, target_mm: f64) -> Option<String> {
    let l = study.limits.iter().find(|l| l.region == region)?;
    let (rep, noise) = (l.repeatability_mean * 1e3, l.tracker_noise_mean * 1e3);
    if target_mm < rep {
        Some(format!("below the repeatability ({} mm)", fmt_mm(rep)))
    } else if target_mm < noise {
        Some(format!("below the tracker noise ({} mm)", fmt_mm(noise)))
    } else {
        None
    }
}

/// The answer's method cell: the best layout's points, or "not up to N" with the method's plateau.
fn method_cell(answer: &Answer, method: MethodKind) -> String {
    match answer.best_of(method) {
        Some(c) => format!(
            "{} ({})",
            c.n_train.expect("best has points"),
            c.layout.name()
        ),
        None => {
            let mine: Vec<&Cell> = answer.cells.iter().filter(|c| c.method == method).collect();
            let largest = mine.iter().map(|c| c.largest).max().unwrap_or(0);
            match mine.iter().filter_map(|c| c.plateau).min_by(f64::total_cmp) {
                Some(p) => format!("not up to {largest} (plateau {})", fmt_mm(p)),
                None => format!("not up to {largest} (every run failed)"),
            }
        }
    }
}

/// The answer section of `summary.md`.
pub fn answer_md(study: &StudyResult, out: &mut String) {
    let a = axes(study);
    let all = answers(study);
    let c = &study.config;
    let _ = writeln!(out, "## The answer\n");
    let _ = writeln!(
        out,
        "For each accuracy a user may need, the fewest training points with which a method reaches it in at least \
         {} % of the seeds (runs that failed count as not reaching), judged on the noise-free ground-truth grid \
         of the region: its **mean** error, and its **95th percentile** (what 19 of 20 targets stay within). \
         Each method's cell gives its best layout; \"not up to N\" means no studied size reached it, with the \
         median error at its largest size (its plateau). The recommendation is the method and layout needing \
         the fewest points (then the lower error). *Expected*: median [q1–q3] over the seeds at that size. \
         *Tracker hours*: the campaign's training and validation points at {} s each (move {} s, settle {} s, \
         measure {} s). A count equal to the smallest size studied ({}) means *at most* that many.\n",
        REACH_SHARE * 100.0,
        c.seconds_per_point(),
        c.move_s,
        c.settle_s,
        c.measure_s,
        a.sizes.first().copied().unwrap_or(0),
    );
    let methods: Vec<String> = a.methods.iter().map(|m| format!("`{m}`")).collect();
    for region in &a.regions {
        for (statistic, name) in STATISTICS {
            let these: Vec<&Answer> = all
                .iter()
                .filter(|x| &x.region == region && x.statistic == statistic)
                .collect();
            let _ = writeln!(
                out,
                "### {} ≤ target, region `{region}`\n",
                capitalised(name)
            );
            let mut columns: Vec<String> =
                ["recommended", "points", "tracker hours", "expected (mm)"]
                    .iter()
                    .map(|s| s.to_string())
                    .collect();
            columns.extend(methods.iter().cloned());
            table_header(out, "target (mm)", &columns);
            for x in &these {
                let target = match limit_note(study, region, x.target_mm) {
                    Some(note) => format!("{} ({note})", fmt_target(x.target_mm)),
                    None => fmt_target(x.target_mm),
                };
                let mut row = match x.recommendation() {
                    Some(r) => {
                        let n = r.n_train.expect("recommended has points");
                        vec![
                            format!("`{}`, {}", r.method, r.layout.name()),
                            n.to_string(),
                            fmt_hours(c.campaign_hours(n)),
                            spread_text(r.expected),
                        ]
                    }
                    None => vec![
                        "no method in this study".into(),
                        "—".into(),
                        "—".into(),
                        "—".into(),
                    ],
                };
                row.extend(a.methods.iter().map(|&m| method_cell(x, m)));
                let _ = writeln!(out, "| {target} | {} |", row.join(" | "));
            }
            out.push('\n');
        }
        per_layout_md(study, &a, &all, region, out);
        limits_md(study, region, out);
    }
}

fn capitalised(s: &str) -> String {
    let mut c = s.chars();
    c.next()
        .map_or(String::new(), |f| f.to_uppercase().chain(c).collect())
}

/// Points per method and layout for every target of the ground-truth mean, in one compact table.
fn per_layout_md(study: &StudyResult, a: &Axes, all: &[Answer], region: &str, out: &mut String) {
    let (statistic, name) = STATISTICS[0];
    let targets: Vec<String> = study
        .config
        .targets_mm
        .iter()
        .map(|t| fmt_target(*t))
        .collect();
    let _ = writeln!(
        out,
        "### Points per method and layout, {name} ≤ {} mm, region `{region}`\n",
        targets.join(" · ")
    );
    let _ = writeln!(
        out,
        "Each cell lists, for the targets in that order, the fewest training points reaching it in at least \
         {} % of the seeds (— : not within the sizes studied). Every cell of both statistics is in `answer.csv`.\n",
        REACH_SHARE * 100.0
    );
    let layouts: Vec<String> = a.layouts.iter().map(|d| d.name().to_string()).collect();
    table_header(out, "method", &layouts);
    let these: Vec<&Answer> = all
        .iter()
        .filter(|x| x.region == region && x.statistic == statistic)
        .collect();
    for m in &a.methods {
        let row: Vec<String> = a
            .layouts
            .iter()
            .map(|&d| {
                these
                    .iter()
                    .map(|x| {
                        x.cells
                            .iter()
                            .find(|c| c.method == *m && c.layout == d)
                            .and_then(|c| c.n_train)
                            .map_or("—".to_string(), |n| n.to_string())
                    })
                    .collect::<Vec<_>>()
                    .join(" · ")
            })
            .collect();
        let _ = writeln!(out, "| `{m}` | {} |", row.join(" | "));
    }
    out.push('\n');
}

fn limits_md(study: &StudyResult, region: &str, out: &mut String) {
    let Some(l) = study.limits.iter().find(|l| l.region == region) else {
        return;
    };
    let _ = writeln!(
        out,
        "**Limits of the measurement, region `{region}`.** The tracker's random error on one point is {} mm \
         (mean 3-D length at this region's range): a calibration may get below it, since a fit averages many \
         points, but a single tracker point cannot verify that. The arm's repeatability moves the flange by \
         {} mm (mean 3-D length): the ground truth above is noise-free, so an arm in use scatters by this much \
         about whatever a calibration predicts — a target below it is not held, whatever the method.\n",
        fmt_mm(l.tracker_noise_mean * 1e3),
        fmt_mm(l.repeatability_mean * 1e3),
    );
}

/// The recommendations for the console: one block per region and statistic, under 80 columns.
pub fn answer_text(study: &StudyResult) -> String {
    let mut out = String::new();
    let c = &study.config;
    let all = answers(study);
    let a = axes(study);
    for region in &a.regions {
        for (statistic, name) in STATISTICS {
            let _ = writeln!(
                out,
                "answer, region '{region}', {name} (reached in ≥ {} % of seeds):",
                REACH_SHARE * 100.0
            );
            let _ = writeln!(
                out,
                "  {:<10} {:<30} {:>6} {:>6}  expected mm",
                "target mm", "method, layout", "points", "hours"
            );
            for x in all
                .iter()
                .filter(|x| &x.region == region && x.statistic == statistic)
            {
                let target = fmt_target(x.target_mm);
                match x.recommendation() {
                    Some(r) => {
                        let n = r.n_train.expect("recommended has points");
                        let _ = writeln!(
                            out,
                            "  {target:<10} {:<30} {n:>6} {:>6}  {}",
                            format!("{}, {}", r.method, r.layout.name()),
                            fmt_hours(c.campaign_hours(n)),
                            r.expected.map_or("—".into(), |s| fmt_mm(s.median)),
                        );
                    }
                    None => {
                        let _ = writeln!(out, "  {target:<10} no method reaches it in this study");
                    }
                }
            }
        }
    }
    out
}

/// The columns of `answer.csv`.
pub const ANSWER_COLUMNS: [&str; 15] = [
    "scenario",
    "region",
    "statistic",
    "target_mm",
    "method",
    "distribution",
    "n_train",
    "seeds_reaching",
    "seeds",
    "median_mm",
    "q1_mm",
    "q3_mm",
    "plateau_mm",
    "tracker_hours",
    "recommended",
];

/// `answer.csv`: one row per (region, statistic, target, method, layout); `n_train` empty when not reached.
pub fn answer_csv(study: &StudyResult) -> Result<Vec<u8>> {
    let data_error = |e: csv::Error| Error::Data {
        origin: "answer.csv".into(),
        message: e.to_string(),
    };
    let mut w = csv::Writer::from_writer(Vec::new());
    w.write_record(ANSWER_COLUMNS).map_err(data_error)?;
    let opt = |x: Option<f64>| x.map_or(String::new(), fmt_mm);
    for x in answers(study) {
        for (i, c) in x.cells.iter().enumerate() {
            w.write_record([
                study.world.name.clone(),
                x.region.clone(),
                x.statistic.to_string(),
                fmt_target(x.target_mm),
                c.method.to_string(),
                c.layout.name().to_string(),
                c.n_train.map_or(String::new(), |n| n.to_string()),
                c.reaching.to_string(),
                c.seeds.to_string(),
                opt(c.expected.map(|s| s.median)),
                opt(c.expected.map(|s| s.q1)),
                opt(c.expected.map(|s| s.q3)),
                opt(c.plateau),
                c.n_train
                    .map_or(String::new(), |n| fmt_hours(study.config.campaign_hours(n))),
                (x.recommended == Some(i)).to_string(),
            ])
            .map_err(data_error)?;
        }
    }
    w.into_inner().map_err(|e| Error::Data {
        origin: "answer.csv".into(),
        message: e.to_string(),
    })
}
