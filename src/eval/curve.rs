//! The learning curve of a measured data set: every method fitted on random subsets of growing size and tested
//! on one held-out part of the same data. `calibrate curve` and the real-data tables (`real_data`) both compute
//! theirs here.
//!
//! **Nothing here looks at the data's values.** The held-out part is the test part of `calibrate`'s default
//! split ([`super::split`]: 25 %, a permutation drawn from the seed), of the row count alone: a `split` column
//! in the data is ignored. Each subset of size `n`, draw `d`, is the first `n` of the remaining rows (the pool)
//! shuffled by a generator derived from (seed, `n`, `d`), and is cut into training and validation in the
//! ratio of `calibrate`'s first two fractions (2/3 and 1/3) by a permutation drawn from `d`. A real file and
//! the same configurations replayed through a simulation (`campaign --replay`, which keeps the file's order)
//! are therefore cut identically, row for row, and their curves compare point by point.
//!
//! Every fit draws from its own generators, so the curve is the same whatever the thread count.

use rand::seq::SliceRandom;
use rayon::prelude::*;
use serde::Serialize;

use super::split::{Parts, SplitRule};
use super::stats::Stats;
use super::transfer::{self, TestRegistration};
use crate::calib::method::{FitContext, Fitted};
use crate::calib::registry::MethodKind;
use crate::dataset::{Dataset, Split, random_split, random_train_val};
use crate::error::{Error, Result};
use crate::rng::{Stream, derive};

/// Draws per size: each draw fits every method once (about a second at a few hundred points), so a hundred
/// draws of seven sizes already take the better part of an hour.
pub const MAX_DRAWS: usize = 100;
/// At most this many sizes, each at most [`MAX_CURVE_POINTS`] (checked again against the pool of the data).
pub const MAX_SIZES: usize = 50;
pub const MAX_CURVE_POINTS: usize = 100_000;
/// The smallest subset: two training points and one validation point. Most methods need more; their fits
/// then fail and say so in their row.
pub const MIN_SIZE: usize = 3;

/// What a learning curve draws: the sizes, the draws per size, and the split rule whose fractions and seed
/// choose the held-out part and the subsets.
#[derive(Clone, Debug, PartialEq)]
pub struct CurvePlan {
    pub rule: SplitRule,
    /// Subset sizes (training + validation points).
    pub sizes: Vec<usize>,
    pub draws: usize,
}

/// One fit of the learning curve: one method on one random subset of one size, tested on the held-out part.
#[derive(Clone, Debug, Serialize)]
pub struct CurveDraw {
    pub method: MethodKind,
    pub size: usize,
    pub draw: usize,
    /// Held-out position errors (mm): mean, 95th percentile, max; none when the fit failed.
    pub mean_mm: Option<f64>,
    pub p95_mm: Option<f64>,
    pub max_mm: Option<f64>,
    /// Held-out points outside the model's training domain (`calib::domain`: where its regressions fade out to
    /// their parametric part); none when the fit failed.
    pub outside_domain: Option<usize>,
    /// Why the fit or its test failed.
    pub error: Option<String>,
}

/// A learning curve: its fits (by size, then draw, then method), and the parts it drew from.
#[derive(Clone, Debug)]
pub struct LearningCurve {
    pub draws: Vec<CurveDraw>,
    /// Rows the subsets were drawn from.
    pub n_pool: usize,
    /// Held-out rows every fit is tested on.
    pub n_test: usize,
}

impl CurvePlan {
    /// The counts, before any file is read.
    pub fn check_counts(&self) -> Result<()> {
        if !(1..=MAX_DRAWS).contains(&self.draws) {
            return Err(Error::Invalid(format!(
                "--draws {}: between 1 and {MAX_DRAWS} draws per learning-curve size",
                self.draws
            )));
        }
        if self.sizes.is_empty() || self.sizes.len() > MAX_SIZES {
            return Err(Error::Invalid(format!(
                "--sizes: between 1 and {MAX_SIZES} learning-curve sizes, got {}",
                self.sizes.len()
            )));
        }
        if let Some(n) = self
            .sizes
            .iter()
            .find(|&&n| !(MIN_SIZE..=MAX_CURVE_POINTS).contains(&n))
        {
            return Err(Error::Invalid(format!(
                "--sizes: {n} points: a learning-curve size is between {MIN_SIZE} and {MAX_CURVE_POINTS}"
            )));
        }
        if let Some((k, n)) = self
            .sizes
            .iter()
            .enumerate()
            .find(|(k, n)| self.sizes[..*k].contains(n))
        {
            return Err(Error::Invalid(format!(
                "--sizes: {n} is given twice (the {} size repeats an earlier one)",
                ordinal(k + 1)
            )));
        }
        Ok(())
    }

    /// Each row's part for `n_rows` rows: [`Split::Test`] the held-out part, the rest the pool. From the row
    /// count and the seed alone.
    pub fn held_out(&self, n_rows: usize) -> Result<Vec<Split>> {
        random_split(n_rows, self.rule.fractions, self.rule.seed)
    }

    /// The rows of size `n`, draw `d`: the first `n` of `pool` shuffled by a generator of (seed, `n`, `d`).
    pub fn subset(&self, pool: &[usize], n: usize, d: usize) -> Vec<usize> {
        let mut order = pool.to_vec();
        order.shuffle(&mut derive(
            self.rule.seed,
            Stream::Split,
            &[n as u64, d as u64 + 1],
        ));
        order.truncate(n);
        order
    }

    /// A size larger than the pool, refused on one line naming the largest possible size.
    fn check_pool(&self, n_rows: usize, n_pool: usize) -> Result<()> {
        match self.sizes.iter().find(|&&n| n > n_pool) {
            Some(n) => Err(Error::Invalid(format!(
                "--sizes: {n} points, but the {n_rows} rows leave {n_pool} for training and validation once \
                 the held-out {} are set aside: the largest possible size is {n_pool}",
                n_rows - n_pool
            ))),
            None => Ok(()),
        }
    }
}

/// "1st", "2nd", "3rd", "4th", ….
fn ordinal(k: usize) -> String {
    let suffix = match (k % 10, k % 100) {
        (_, 11..=13) => "th",
        (1, _) => "st",
        (2, _) => "nd",
        (3, _) => "rd",
        _ => "th",
    };
    format!("{k}{suffix}")
}

/// The learning curve of `data` as the module notes say: for each size and draw of `plan`, every method of
/// `methods` fitted on the subset (with whatever extra inputs `data` carries) and tested on the held-out part
/// through the model's own registration. A fit that fails is recorded with its reason; a size beyond the pool
/// is refused before anything is fitted.
pub fn learning_curve(
    methods: &[MethodKind],
    ctx: &FitContext,
    plan: &CurvePlan,
    data: &Dataset,
) -> Result<LearningCurve> {
    plan.check_counts()?;
    let labels = plan.held_out(data.len())?;
    let pool: Vec<usize> = (0..data.len())
        .filter(|&i| labels[i] != Split::Test)
        .collect();
    plan.check_pool(data.len(), pool.len())?;
    let test_rows: Vec<usize> = (0..data.len())
        .filter(|&i| labels[i] == Split::Test)
        .collect();
    let test = data.subset(&test_rows);
    let jobs: Vec<(usize, usize, MethodKind)> = plan
        .sizes
        .iter()
        .flat_map(|&n| (0..plan.draws).flat_map(move |d| methods.iter().map(move |&m| (n, d, m))))
        .collect();
    let fraction = plan.rule.train_fraction();
    let draws = jobs
        .par_iter()
        .map(|&(n, d, kind)| {
            let subset = data.subset(&plan.subset(&pool, n, d));
            let result = random_train_val(n, fraction, d as u64).and_then(|labels| {
                let Parts { train, val, .. } = Parts::of(&subset, labels);
                let model = kind.fit(ctx, &train, &val)?;
                let e = transfer::evaluate(model.as_ref(), &test, TestRegistration::Model)?;
                let stats = Stats::of(&e.errors.position)
                    .ok_or_else(|| Error::Invalid("no finite held-out error".into()))?;
                Ok((stats.scaled(1e3), outside_domain(model.as_ref(), &test)))
            });
            let (stats, outside, error) = match result {
                Ok((s, outside)) => (Some(s), Some(outside), None),
                Err(e) => (None, None, Some(e.to_string())),
            };
            CurveDraw {
                method: kind,
                size: n,
                draw: d,
                mean_mm: stats.map(|s| s.mean),
                p95_mm: stats.map(|s| s.p95),
                max_mm: stats.map(|s| s.max),
                outside_domain: outside,
                error,
            }
        })
        .collect();
    Ok(LearningCurve {
        draws,
        n_pool: pool.len(),
        n_test: test.len(),
    })
}

/// How many points of `test` lie outside `model`'s training domain.
fn outside_domain(model: &dyn Fitted, test: &Dataset) -> usize {
    let points = (0..test.len()).map(|i| (test.q[i].as_slice(), test.extra_inputs_of(i)));
    let placements = model.basis().domain.place_all(model.joint_names(), points);
    placements.iter().filter(|p| !p.inside).count()
}

/// Per method and size: the mean over the successful draws of their held-out means (mm), their min and
/// max, and how many draws failed. `None` when every draw failed.
pub fn cell(draws: &[CurveDraw], method: MethodKind, size: usize) -> (Option<[f64; 3]>, usize) {
    let of_cell = || {
        draws
            .iter()
            .filter(move |p| p.method == method && p.size == size)
    };
    let values: Vec<f64> = of_cell().filter_map(|p| p.mean_mm).collect();
    let failed = of_cell().filter(|p| p.mean_mm.is_none()).count();
    if values.is_empty() {
        return (None, failed);
    }
    let mean = values.iter().sum::<f64>() / values.len() as f64;
    let lo = values.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = values.iter().copied().fold(0.0, f64::max);
    (Some([mean, lo, hi]), failed)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plan(sizes: &[usize], draws: usize, seed: u64) -> CurvePlan {
        CurvePlan {
            rule: SplitRule::new(super::super::split::DEFAULT_FRACTIONS, seed),
            sizes: sizes.to_vec(),
            draws,
        }
    }

    /// The held-out part and the subsets depend on the row count and the seed only, and a subset is drawn
    /// without repetition from the pool.
    #[test]
    fn the_parts_follow_the_count_and_the_seed() {
        let p = plan(&[50], 2, 7);
        let labels = p.held_out(200).unwrap();
        assert_eq!(labels, p.held_out(200).unwrap());
        assert_ne!(labels, plan(&[50], 2, 8).held_out(200).unwrap());
        assert_eq!(labels.iter().filter(|l| **l == Split::Test).count(), 50);
        let pool: Vec<usize> = (0..200).filter(|&i| labels[i] != Split::Test).collect();
        let s = p.subset(&pool, 50, 1);
        assert_eq!(s, p.subset(&pool, 50, 1));
        assert_ne!(s, p.subset(&pool, 50, 0));
        let mut unique = s.clone();
        unique.sort_unstable();
        unique.dedup();
        assert_eq!(unique.len(), 50);
        assert!(s.iter().all(|i| pool.contains(i)));
    }

    #[test]
    fn bad_counts_are_refused_with_the_flag() {
        let said = |p: CurvePlan| p.check_counts().unwrap_err().to_string();
        assert!(said(plan(&[50], 0, 0)).contains("--draws 0"));
        assert!(said(plan(&[0, 50], 1, 0)).contains("--sizes: 0 points"));
        assert!(said(plan(&[], 1, 0)).contains("got 0"));
        assert!(said(plan(&[50, 100, 50], 1, 0)).contains("50 is given twice (the 3rd size"));
        let p = plan(&[100, 160], 1, 0);
        let e = p.check_pool(200, 150).unwrap_err().to_string();
        assert!(e.contains("the largest possible size is 150"), "{e}");
    }
}
