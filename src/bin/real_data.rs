//! `real_data [--data-dir DIR] [--out DIR]`: every calibration method on the real UR10 laser-tracker campaigns
//! of Landgraf et al. (IEEE CASE 2021; `../shared/data/ipa-ur10`), read through `mappings/ipa_ur10.toml`.
//! Prints the README's tables as Markdown and writes them to `DIR/real_data.json`:
//!
//! 1. **Across campaigns**: fitted on all of series C (training 2/3, validation 1/3, split seed 0) and tested
//!    on all of series D and of series B; fitted on B, tested on C. Each test campaign's tracker frame and
//!    probe mounting are re-registered on its own points (`eval::transfer`), the same for every method.
//! 2. **Within series C**: `calibrate`'s default split (50 / 25 / 25 %, seed 0), the model's own registration.
//! 3. **Temperature**: every method that regresses on inputs beyond the joint angles, again with the
//!    temperature column offered as a candidate input.
//! 4. **The learning curve**: 25 … 1600 points drawn from the training and validation part of (2), five draws
//!    each, each split 2/3 training, 1/3 validation, all tested on the same held-out 25 % of series C.
//!
//! `calibrate --robot robots/ur10.urdf --mapping mappings/ipa_ur10.toml --data …/Series_C/… --test-data
//! …/Series_D/… --method M` reproduces any row of table 1 (`--ignore-inputs` for the rows without
//! temperature).

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use clap::Parser;
use rand::seq::SliceRandom;
use rayon::prelude::*;
use serde::Serialize;

use calibench::calib::method::FitContext;
use calibench::calib::registry::{self, MethodKind};
use calibench::calib::regression::RegressionOptions;
use calibench::dataset::mapping::ColumnMapping;
use calibench::dataset::{Dataset, Split, random_split, random_train_val};
use calibench::eval::Stats;
use calibench::eval::transfer::{self, TestRegistration};
use calibench::rng::{Stream, derive};
use calibench::robot::dh::DhChain;
use calibench::robot::{Chain, urdf};
use calibench::{Error, Result, output};

#[derive(Parser, Debug)]
#[command(about = "Every calibration method on the real UR10 tracker data: the README's tables")]
struct Cli {
    /// The data set's directory (Series_B, Series_C, Series_D).
    #[arg(long, default_value = "../shared/data/ipa-ur10")]
    data_dir: PathBuf,
    #[arg(long, default_value = "mappings/ipa_ur10.toml")]
    mapping: PathBuf,
    #[arg(long, default_value = "robots/ur10.urdf")]
    robot: PathBuf,
    #[arg(long, default_value = "results/real_data")]
    out: PathBuf,
    /// Draws per learning-curve size.
    #[arg(long, default_value_t = 5)]
    draws: usize,
    /// Learning-curve sizes.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "25,50,100,200,400,800,1600"
    )]
    sizes: Vec<usize>,
    /// Skip the learning curve.
    #[arg(long)]
    no_curve: bool,
}

/// The files of the three series.
const SERIES: [(&str, &str); 3] = [
    ("B", "Series_B/measurements_joint_configurations.csv"),
    ("C", "Series_C/measurements_random_poses.csv"),
    ("D", "Series_D/measurements_iso_cubes.csv"),
];

/// The methods of the tables, in the README's order.
const METHODS: [MethodKind; 9] = MethodKind::ALL;

/// Training share of a series fitted whole (`calibrate --test-data`'s default: 0.5 / (0.5 + 0.25)).
const TRAIN_FRACTION: f64 = 2.0 / 3.0;
const SEED: u64 = 0;

fn main() -> ExitCode {
    match run(&Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

/// Position (mm) and orientation (mrad) statistics of one test.
#[derive(Clone, Debug, Serialize)]
struct Scores {
    test: String,
    /// What was fitted on the test data itself (the re-registration).
    fitted_on_test: String,
    n: usize,
    position_mm: Stats,
    orientation_mrad: Option<Stats>,
}

#[derive(Clone, Debug, Serialize)]
struct Row {
    method: String,
    /// Extra regression inputs offered (empty: the joint angles only).
    inputs: Vec<String>,
    fit_ms: f64,
    scores: Vec<Scores>,
}

#[derive(Clone, Debug, Serialize)]
struct CurvePoint {
    method: String,
    size: usize,
    draw: usize,
    /// Test mean position error (mm), or why the fit failed.
    mean_mm: Option<f64>,
    error: Option<String>,
}

#[derive(Serialize)]
struct Report {
    protocol: serde_json::Value,
    across: Vec<(String, Vec<Row>)>,
    within_c: Vec<Row>,
    curve: Vec<CurvePoint>,
}

fn scores(test: &str, transfer: &transfer::Transfer) -> Result<Scores> {
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

fn accepts_inputs(kind: MethodKind) -> bool {
    kind.info().takes_inputs
}

fn without_inputs(d: &Dataset) -> Dataset {
    let mut d = d.clone();
    d.extra_inputs = None;
    d
}

fn split_by(data: &Dataset, labels: &[Split], s: Split) -> Dataset {
    let idx: Vec<usize> = (0..data.len()).filter(|&i| labels[i] == s).collect();
    data.subset(&idx)
}

/// Fits `kind` (timed) and scores it on each test set.
fn row(
    kind: MethodKind,
    ctx: &FitContext,
    train: &Dataset,
    val: &Dataset,
    tests: &[(&str, &Dataset, TestRegistration)],
) -> Result<Row> {
    let started = Instant::now();
    let model = registry::fit(kind, ctx, train, val)?;
    let fit_ms = started.elapsed().as_secs_f64() * 1e3;
    let scores = tests
        .iter()
        .map(|(name, test, mode)| scores(name, &transfer::evaluate(model.as_ref(), test, *mode)?))
        .collect::<Result<Vec<_>>>()?;
    Ok(Row {
        method: model.method().to_string(),
        inputs: model.input_names().to_vec(),
        fit_ms,
        scores,
    })
}

/// Every method, then with temperature those that take extra inputs.
fn rows(
    ctx: &FitContext,
    train: &Dataset,
    val: &Dataset,
    tests: &[(&str, &Dataset, TestRegistration)],
) -> Result<Vec<Row>> {
    let (train0, val0) = (without_inputs(train), without_inputs(val));
    let mut out = Vec::new();
    for kind in METHODS {
        out.push(row(kind, ctx, &train0, &val0, tests)?);
    }
    for kind in METHODS.into_iter().filter(|k| accepts_inputs(*k)) {
        out.push(row(kind, ctx, train, val, tests)?);
    }
    Ok(out)
}

fn name(r: &Row) -> String {
    if r.inputs.is_empty() {
        format!("`{}`", r.method)
    } else {
        format!("`{}` + {}", r.method, r.inputs.join(", "))
    }
}

fn print_rows(title: &str, rows: &[Row]) {
    println!("\n#### {title}\n");
    let tests: Vec<&str> = rows[0].scores.iter().map(|s| s.test.as_str()).collect();
    print!("| method |");
    for t in &tests {
        print!(" {t}: mean / max / std / p95 (mm) | {t}: orientation mean / p95 (mrad) |");
    }
    println!(" fit (ms) |");
    print!("|---|");
    for _ in &tests {
        print!("---|---|");
    }
    println!("---|");
    for r in rows {
        print!("| {} |", name(r));
        for s in &r.scores {
            let p = &s.position_mm;
            print!(
                " {:.4} / {:.3} / {:.3} / {:.3} |",
                p.mean, p.max, p.std, p.p95
            );
            match &s.orientation_mrad {
                Some(o) => print!(" {:.3} / {:.3} |", o.mean, o.p95),
                None => print!(" — |"),
            }
        }
        println!(" {:.0} |", r.fit_ms);
    }
    println!();
    for s in &rows[0].scores {
        println!(
            "{}: {} (the same for every method).",
            s.test, s.fitted_on_test
        );
    }
}

fn read_series(dir: &Path, mapping: &ColumnMapping, chain: &Chain) -> Result<Vec<Dataset>> {
    SERIES
        .iter()
        .map(|(_, file)| mapping.read(&dir.join(file), chain))
        .collect()
}

fn run(cli: &Cli) -> Result<()> {
    let chain = urdf::load_file(&cli.robot, None)?;
    let dh = DhChain::from_chain(&chain)?;
    let mapping = ColumnMapping::load(&cli.mapping)?;
    let series = read_series(&cli.data_dir, &mapping, &chain)?;
    let [b, c, d] = [&series[0], &series[1], &series[2]];
    let ctx = FitContext::new(&chain, &dh);
    let refit = TestRegistration::Refit;
    print_ranges(&series, &chain);
    print_repeats(&series);

    // 1. Across campaigns.
    let mut across = Vec::new();
    for (train_name, data, tests) in [
        ("C", c, vec![("D", d, refit), ("B", b, refit)]),
        ("B", b, vec![("C", c, refit)]),
    ] {
        let labels = random_train_val(data.len(), TRAIN_FRACTION, SEED)?;
        let (train, val) = (
            split_by(data, &labels, Split::Train),
            split_by(data, &labels, Split::Val),
        );
        let title = format!(
            "Trained on series {train_name} ({} training + {} validation points), tested on {}",
            train.len(),
            val.len(),
            tests
                .iter()
                .map(|(n, t, _)| format!("series {n} ({} points)", t.len()))
                .collect::<Vec<_>>()
                .join(" and ")
        );
        let rows = rows(&ctx, &train, &val, &tests)?;
        print_rows(&title, &rows);
        print_best(&rows);
        across.push((title, rows));
    }

    // 2. Within series C.
    let labels = random_split(c.len(), [0.5, 0.25, 0.25], SEED)?;
    let (train, val, test) = (
        split_by(c, &labels, Split::Train),
        split_by(c, &labels, Split::Val),
        split_by(c, &labels, Split::Test),
    );
    let within_c = rows(
        &ctx,
        &train,
        &val,
        &[("C held out", &test, TestRegistration::Model)],
    )?;
    print_rows(
        &format!(
            "Within series C: {} training + {} validation points, {} held out (the model's registration)",
            train.len(),
            val.len(),
            test.len()
        ),
        &within_c,
    );

    // 3. The learning curve: subsets of C's training + validation pool, tested on the held-out 25 %.
    let curve = if cli.no_curve {
        Vec::new()
    } else {
        let pool: Vec<usize> = (0..c.len()).filter(|&i| labels[i] != Split::Test).collect();
        let test = without_inputs(&test);
        let c0 = without_inputs(c);
        let jobs: Vec<(usize, usize, MethodKind)> = cli
            .sizes
            .iter()
            .flat_map(|&n| (0..cli.draws).flat_map(move |d| METHODS.map(|m| (n, d, m))))
            .collect();
        if let Some(&n) = cli.sizes.iter().find(|&&n| n > pool.len() || n < 3) {
            return Err(Error::Invalid(format!(
                "learning-curve size {n}: between 3 and the {} points of the pool",
                pool.len()
            )));
        }
        let curve: Vec<CurvePoint> = jobs
            .par_iter()
            .map(|&(n, d, kind)| {
                let mut order = pool.clone();
                order.shuffle(&mut derive(SEED, Stream::Split, &[n as u64, d as u64 + 1]));
                let subset = c0.subset(&order[..n]);
                let result = random_train_val(n, TRAIN_FRACTION, d as u64).and_then(|labels| {
                    let (train, val) = (
                        split_by(&subset, &labels, Split::Train),
                        split_by(&subset, &labels, Split::Val),
                    );
                    let model = registry::fit(kind, &ctx, &train, &val)?;
                    let e = transfer::evaluate(model.as_ref(), &test, TestRegistration::Model)?;
                    Ok(Stats::of(&e.errors.position).map(|s| s.mean * 1e3))
                });
                let (mean_mm, error) = match result {
                    Ok(m) => (m, None),
                    Err(e) => (None, Some(e.to_string())),
                };
                CurvePoint {
                    method: kind.name().to_string(),
                    size: n,
                    draw: d,
                    mean_mm,
                    error,
                }
            })
            .collect();
        print_curve(&curve, &cli.sizes, test.len());
        curve
    };

    let protocol = serde_json::json!({
        "data": cli.data_dir.display().to_string(),
        "mapping": cli.mapping.display().to_string(),
        "robot": cli.robot.display().to_string(),
        "train_fraction": TRAIN_FRACTION,
        "seed": SEED,
        "test_registration_across": "tracker frame (rigid, 6) and probe mounting (position 3, rotation 3) re-registered on each test series' own points against the model's predicted flange poses",
        "payload_kg": 0.0,
        "regression": RegressionOptions::default(),
    });
    let report = Report {
        protocol,
        across,
        within_c,
        curve,
    };
    let json = serde_json::to_vec_pretty(&report)
        .map_err(|e| Error::Invalid(format!("cannot serialize: {e}")))?;
    output::write_files(&cli.out, &[("real_data.json", json)])?;
    println!("\nwrote {}", cli.out.join("real_data.json").display());
    Ok(())
}

/// The best mean on each test against `kinematic`'s: the margin the README reports.
fn print_best(rows: &[Row]) {
    for (k, s) in rows[0].scores.iter().enumerate() {
        let mean = |r: &Row| r.scores[k].position_mm.mean;
        let best = rows
            .iter()
            .min_by(|a, b| mean(a).total_cmp(&mean(b)))
            .expect("rows");
        if let Some(kin) = rows.iter().find(|r| r.method == "kinematic") {
            println!(
                "{}: best {} at {:.4} mm mean, {:.1} % below `kinematic`'s {:.4} mm.",
                s.test,
                name(best),
                mean(best),
                100.0 * (1.0 - mean(best) / mean(kin)),
                mean(kin)
            );
        }
    }
}

/// Configurations measured more than once (joint angles equal to 1 mrad): how far each measurement lies from
/// its group's mean, in the tracker frame. What no model of the joint angles can remove.
fn print_repeats(series: &[Dataset]) {
    println!(
        "\n#### Repeated configurations: distance of each measurement from its group's mean (mm)\n"
    );
    println!("| series | groups | measurements | mean | p95 | max |");
    println!("|---|---|---|---|---|---|");
    for ((name, _), data) in SERIES.iter().zip(series) {
        let mut groups: std::collections::BTreeMap<Vec<i64>, Vec<usize>> = Default::default();
        for (i, q) in data.q.iter().enumerate() {
            let key = q.iter().map(|v| (v * 1e3).round() as i64).collect();
            groups.entry(key).or_default().push(i);
        }
        let mut distances = Vec::new();
        let mut n_groups = 0;
        for members in groups.values().filter(|m| m.len() > 1) {
            n_groups += 1;
            let points: Vec<_> = members.iter().map(|&i| data.measured[i][0]).collect();
            let mean = calibench::eval::centre(&points);
            distances.extend(points.iter().map(|p| (p - mean).norm() * 1e3));
        }
        match Stats::of(&distances) {
            Some(s) => println!(
                "| {name} | {n_groups} | {} | {:.4} | {:.4} | {:.4} |",
                distances.len(),
                s.mean,
                s.p95,
                s.max
            ),
            None => println!("| {name} | 0 | 0 | — | — | — |"),
        }
    }
    println!();
}

/// Per series: the range of every joint (degrees) and of the temperature: where each model is fitted.
fn print_ranges(series: &[Dataset], chain: &Chain) {
    println!("#### Where the series lie: joint ranges (°) and temperature (°C), min … max\n");
    print!("| series | points |");
    for j in chain.joint_names() {
        print!(" {j} |");
    }
    println!(" temperature |");
    println!("|---|---|{}---|", "---|".repeat(chain.dof()));
    for ((name, _), data) in SERIES.iter().zip(series) {
        print!("| {name} | {} |", data.len());
        let range = |values: Vec<f64>| {
            let lo = values.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            (lo, hi)
        };
        for j in 0..chain.dof() {
            let (lo, hi) = range(data.q.iter().map(|q| q[j].to_degrees()).collect());
            print!(" {lo:.0} … {hi:.0} |");
        }
        match &data.extra_inputs {
            Some(x) => {
                let (lo, hi) = range(x.values.iter().map(|v| v[0]).collect());
                println!(" {lo:.2} … {hi:.2} |");
            }
            None => println!(" — |"),
        }
    }
}

fn print_curve(curve: &[CurvePoint], sizes: &[usize], n_test: usize) {
    println!(
        "\n#### Learning curve: mean position error (mm) on the {n_test} held-out points of series C, \
         mean over draws (min–max)\n"
    );
    print!("| method |");
    for n in sizes {
        print!(" {n} |");
    }
    println!();
    print!("|---|");
    for _ in sizes {
        print!("---|");
    }
    println!();
    for kind in METHODS {
        print!("| `{}` |", kind.name());
        for &n in sizes {
            let values: Vec<f64> = curve
                .iter()
                .filter(|p| p.method == kind.name() && p.size == n)
                .filter_map(|p| p.mean_mm)
                .collect();
            let failed = curve
                .iter()
                .filter(|p| p.method == kind.name() && p.size == n && p.mean_mm.is_none())
                .count();
            if values.is_empty() {
                print!(" failed |");
                continue;
            }
            let mean = values.iter().sum::<f64>() / values.len() as f64;
            let lo = values.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = values.iter().copied().fold(0.0, f64::max);
            let note = if failed > 0 {
                format!(" ({failed} failed)")
            } else {
                String::new()
            };
            print!(" {mean:.3} ({lo:.3}–{hi:.3}){note} |");
        }
        println!();
    }
}
