//! The protocol of the real-data tables: every method fitted on one measured series and scored on others
//! ([`across`]) and on a held-out part of the same series ([`within`]); the learning curve on that held-out
//! part is [`super::curve`]'s, as `calibrate curve` computes it. The data is split by `calibrate`'s rule
//! ([`super::split`]), so that `calibrate --test-data` reproduces any row.
//!
//! Each method is fitted on the joint angles alone, and then, if it regresses on inputs beyond them, again
//! with the data's extra inputs (e.g. the temperature) offered.

use std::time::Instant;

use serde::Serialize;

use super::split::{Parts, SplitRule};
use super::stats::Stats;
use super::transfer::{self, TestRegistration, Transfer};
use crate::calib::method::FitContext;
use crate::calib::registry::MethodKind;
use crate::dataset::Dataset;
use crate::error::{Error, Result};

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
