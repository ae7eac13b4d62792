//! Aggregation over seeds: median and interquartile range of `metrics.csv`'s written values per (region,
//! layout, method, size), the learning curves, and the points-needed rule read off them.

use crate::calib::registry::MethodKind;
use crate::campaign::LayoutKind;
use crate::study::{RunMetrics, StudyResult};

use super::metrics::cell;

/// A method is done learning at the smallest size whose median ground-truth mean is within this fraction of
/// its plateau …
pub const PLATEAU_TOLERANCE: f64 = 0.10;
/// … and within this factor of the floor (the oracle's ground-truth mean on the same campaigns).
pub const FLOOR_FACTOR: f64 = 1.5;

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
    pub layouts: Vec<LayoutKind>,
    pub methods: Vec<MethodKind>,
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
        layouts: Vec::new(),
        methods: Vec::new(),
        sizes: study.config.sizes.clone(),
    };
    for d in &study.config.layouts {
        push(&mut a.layouts, d);
    }
    for m in &study.config.methods {
        push(&mut a.methods, m);
    }
    // Only what has runs is shown.
    let runs = &study.runs;
    a.regions
        .retain(|r| runs.iter().any(|x| &x.key.region == r));
    a.layouts
        .retain(|d| runs.iter().any(|x| x.key.layout == *d));
    a.methods
        .retain(|m| runs.iter().any(|x| x.key.method == *m));
    a.sizes.retain(|n| runs.iter().any(|x| x.key.n_train == *n));
    for run in runs {
        push(&mut a.regions, &run.key.region);
        push(&mut a.layouts, &run.key.layout);
        push(&mut a.methods, &run.key.method);
        push(&mut a.sizes, &run.key.n_train);
    }
    a.sizes.sort_unstable();
    a.sizes.dedup();
    a
}

pub(super) fn runs_of<'a>(
    study: &'a StudyResult,
    region: &'a str,
    layout: LayoutKind,
    n_train: usize,
) -> impl Iterator<Item = &'a RunMetrics> + 'a {
    study.runs.iter().filter(move |r| {
        r.key.region == region && r.key.layout == layout && r.key.n_train == n_train
    })
}

/// Median and IQR of one column (a `metrics.csv` name) over the successful runs (the seeds) of one
/// (region, layout, method, size); `None` when no successful run has the value.
pub fn cell_spread(
    study: &StudyResult,
    region: &str,
    layout: LayoutKind,
    method: MethodKind,
    n_train: usize,
    column: &str,
) -> Option<Spread> {
    let values: Vec<f64> = runs_of(study, region, layout, n_train)
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
    layout: LayoutKind,
    n_train: usize,
) -> Option<Spread> {
    let mut seeds = Vec::new();
    let mut values = Vec::new();
    for r in runs_of(study, region, layout, n_train) {
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
    pub layout: LayoutKind,
    pub method: MethodKind,
    /// Sizes ascending.
    pub points: Vec<CurvePoint>,
}

/// Every learning curve, ordered by region, layout, method (as [`axes`]).
pub fn learning_curves(study: &StudyResult) -> Vec<Curve> {
    let a = axes(study);
    let mut curves = Vec::new();
    for region in &a.regions {
        for &layout in &a.layouts {
            for &method in &a.methods {
                let points: Vec<CurvePoint> = a
                    .sizes
                    .iter()
                    .filter_map(|&n| {
                        let runs: Vec<&RunMetrics> = runs_of(study, region, layout, n)
                            .filter(|r| r.key.method == method)
                            .collect();
                        (!runs.is_empty()).then(|| CurvePoint {
                            n_train: n,
                            runs: runs.len(),
                            failed: runs.iter().filter(|r| r.failure.is_some()).count(),
                            truth: cell_spread(study, region, layout, method, n, "truth_mean_mm"),
                            floor: cell_spread(study, region, layout, method, n, "floor_mean_mm"),
                        })
                    })
                    .collect();
                if !points.is_empty() {
                    curves.push(Curve {
                        region: region.clone(),
                        layout,
                        method,
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
