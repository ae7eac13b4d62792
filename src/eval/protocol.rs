//! The protocol of the real-data tables: every method fitted on one measured series and scored on others
//! ([`across`]), on a held-out part of the same series ([`within`]), and on that held-out part from growing
//! subsets of the rest ([`curve`]). The data is split by `calibrate`'s rule ([`super::split`]), so that
//! `calibrate --test-data` reproduces any row.
//!
//! Each method is fitted on the joint angles alone, and then, if it regresses on inputs beyond them, again
//! with the data's extra inputs (e.g. the temperature) offered.

use std::time::Instant;

use rand::seq::SliceRandom;
use rayon::prelude::*;
use serde::Serialize;

use super::split::{Parts, SplitRule};
use super::stats::Stats;
use super::transfer::{self, TestRegistration, Transfer};
use crate::calib::method::FitContext;
use crate::calib::registry::MethodKind;
use crate::dataset::{Dataset, Split, random_train_val};
use crate::error::{Error, Result};
use crate::rng::{Stream, derive};

/// The methods of the tables, in the README's order.
pub const METHODS: [MethodKind; 9] = MethodKind::ALL;

/// A data set a fitted model is scored on.
#[derive(Clone, Copy, Debug)]
pub struct TestSet<'a> {
    /// Its name in the tables.
    pub name: &'a str,
    pub data: &'a Dataset,
    /// How its measurements are brought into the model's frame.
    pub registration: TestRegistration,
}

/// Position (mm) and orientation (mrad) statistics of one test.
#[derive(Clone, Debug, Serialize)]
pub struct Scores {
    pub test: String,
    /// What was fitted on the test data itself (the re-registration).
    pub fitted_on_test: String,
    pub n: usize,
    pub position_mm: Stats,
    pub orientation_mrad: Option<Stats>,
}

/// One method fitted once and scored on every test set.
#[derive(Clone, Debug, Serialize)]
pub struct Row {
    pub method: MethodKind,
    /// Extra regression inputs offered (empty: the joint angles only).
    pub inputs: Vec<String>,
    pub fit_ms: f64,
    pub scores: Vec<Scores>,
}

/// One table: what was fitted on what and tested where, and its rows.
#[derive(Clone, Debug)]
pub struct Table {
    pub title: String,
    pub rows: Vec<Row>,
}

/// One fit of the learning curve: one method on one random training subset of one size.
#[derive(Clone, Debug, Serialize)]
pub struct CurveDraw {
    pub method: MethodKind,
    pub size: usize,
    pub draw: usize,
    /// Test mean position error (mm), or why the fit failed.
    pub mean_mm: Option<f64>,
    pub error: Option<String>,
}

/// The statistics of `transfer` under the name `test`.
pub fn scores(test: &str, transfer: &Transfer) -> Result<Scores> {
    let errors = &transfer.errors;
    let position = Stats::of(&errors.position)
        .ok_or_else(|| Error::Invalid(format!("{test}: no finite position errors")))?;
    Ok(Scores {
        test: test.to_string(),
        fitted_on_test: transfer.describe(),
        n: errors.position.len(),
        position_mm: position.scaled(1e3),
        orientation_mrad: Stats::of(&errors.orientation).map(|s| s.scaled(1e3)),
    })
}

/// `d` without its extra inputs.
pub fn without_inputs(d: &Dataset) -> Dataset {
    let mut d = d.clone();
    d.extra_inputs = None;
    d
}

/// Fits `kind` (timed) and scores it on each test set.
pub fn row(
    kind: MethodKind,
    ctx: &FitContext,
    train: &Dataset,
    val: &Dataset,
    tests: &[TestSet],
) -> Result<Row> {
    let started = Instant::now();
    let model = kind.fit(ctx, train, val)?;
    let fit_ms = started.elapsed().as_secs_f64() * 1e3;
    let scores = tests
        .iter()
        .map(|t| {
            scores(
                t.name,
                &transfer::evaluate(model.as_ref(), t.data, t.registration)?,
            )
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(Row {
        method: kind,
        inputs: model.input_names().to_vec(),
        fit_ms,
        scores,
    })
}

/// Every method of `methods` on the joint angles alone, then with the extra inputs those that take them.
pub fn rows(
    methods: &[MethodKind],
    ctx: &FitContext,
    train: &Dataset,
    val: &Dataset,
    tests: &[TestSet],
) -> Result<Vec<Row>> {
    let (train0, val0) = (without_inputs(train), without_inputs(val));
    let mut out = Vec::new();
    for &kind in methods {
        out.push(row(kind, ctx, &train0, &val0, tests)?);
    }
    for kind in methods.iter().copied().filter(|k| k.info().takes_inputs) {
        out.push(row(kind, ctx, train, val, tests)?);
    }
    Ok(out)
}

/// Every method fitted on all of series `name` (`data`, split into training and validation by `rule` as
/// `calibrate --test-data` splits it) and scored on each of `tests`.
pub fn across(
    methods: &[MethodKind],
    ctx: &FitContext,
    rule: &SplitRule,
    (name, data): (&str, &Dataset),
    tests: &[TestSet],
) -> Result<Table> {
    let Parts { train, val, .. } = rule.apply(data, true)?;
    let title = format!(
        "Trained on series {name} ({} training + {} validation points), tested on {}",
        train.len(),
        val.len(),
        tests
            .iter()
            .map(|t| format!("series {} ({} points)", t.name, t.data.len()))
            .collect::<Vec<_>>()
            .join(" and ")
    );
    let rows = rows(methods, ctx, &train, &val, tests)?;
    Ok(Table { title, rows })
}

/// Every method fitted on series `name` (`data`) split by `rule` as `calibrate` splits it, and scored on the
/// held-out part through the model's own registration. Returns the table and the split.
pub fn within(
    methods: &[MethodKind],
    ctx: &FitContext,
    rule: &SplitRule,
    (name, data): (&str, &Dataset),
) -> Result<(Table, Parts)> {
    let parts = rule.apply(data, false)?;
    let test_name = format!("{name} held out");
    let rows = rows(
        methods,
        ctx,
        &parts.train,
        &parts.val,
        &[TestSet {
            name: &test_name,
            data: &parts.test,
            registration: TestRegistration::Model,
        }],
    )?;
    let title = format!(
        "Within series {name}: {} training + {} validation points, {} held out (the model's registration)",
        parts.train.len(),
        parts.val.len(),
        parts.test.len()
    );
    Ok((Table { title, rows }, parts))
}

/// The learning curve: for each size `n` and draw, `n` points drawn from the training and validation part of
/// `parts` (a split of `data` by [`within`]), split in `rule`'s training fraction, every method fitted on
/// the joint angles alone and tested on the held-out part. A fit that fails is recorded with its reason.
pub fn curve(
    methods: &[MethodKind],
    ctx: &FitContext,
    rule: &SplitRule,
    data: &Dataset,
    parts: &Parts,
    sizes: &[usize],
    draws: usize,
) -> Result<Vec<CurveDraw>> {
    let labels = &parts.labels;
    let pool: Vec<usize> = (0..data.len())
        .filter(|&i| labels[i] != Split::Test)
        .collect();
    let test = without_inputs(&parts.test);
    let data0 = without_inputs(data);
    let jobs: Vec<(usize, usize, MethodKind)> = sizes
        .iter()
        .flat_map(|&n| (0..draws).flat_map(move |d| methods.iter().map(move |&m| (n, d, m))))
        .collect();
    if let Some(&n) = sizes.iter().find(|&&n| n > pool.len() || n < 3) {
        return Err(Error::Invalid(format!(
            "learning-curve size {n}: between 3 and the {} points of the pool",
            pool.len()
        )));
    }
    let fraction = rule.train_fraction();
    Ok(jobs
        .par_iter()
        .map(|&(n, d, kind)| {
            let mut order = pool.clone();
            order.shuffle(&mut derive(
                rule.seed,
                Stream::Split,
                &[n as u64, d as u64 + 1],
            ));
            let subset = data0.subset(&order[..n]);
            let result = random_train_val(n, fraction, d as u64).and_then(|labels| {
                let Parts { train, val, .. } = Parts::of(&subset, labels);
                let model = kind.fit(ctx, &train, &val)?;
                let e = transfer::evaluate(model.as_ref(), &test, TestRegistration::Model)?;
                Ok(Stats::of(&e.errors.position).map(|s| s.mean * 1e3))
            });
            let (mean_mm, error) = match result {
                Ok(m) => (m, None),
                Err(e) => (None, Some(e.to_string())),
            };
            CurveDraw {
                method: kind,
                size: n,
                draw: d,
                mean_mm,
                error,
            }
        })
        .collect())
}
