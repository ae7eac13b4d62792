//! `campaign [SCENARIO.toml] [--out DIR] [--threads N]`: simulates a laser-tracker campaign of a robot
//! whose true errors are known, and writes `measurements.csv`, `truth.csv` and `campaign.json`; with an
//! `[evaluation]` section it then fits the listed methods, judges them against the truth and writes
//! `evaluation.json` beside them.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use clap::Parser;
use serde_json::json;

use calibench::eval::{Budget, Stats};
use calibench::scenario::Scenario;
use calibench::study::sweep::{Progress, run_study};
use calibench::tracker::Tracker;
use calibench::{Error, Result, campaign, eval, measurements, output, report};

/// The scenario run when none is given: the study a user should run first.
const DEFAULT_SCENARIO: &str = include_str!("../../scenarios/default.toml");

#[derive(Parser, Debug)]
#[command(
    version,
    about = "Simulate a laser-tracker calibration campaign with known true robot errors"
)]
struct Args {
    /// Scenario file (TOML); the embedded paper_iiwa scenario when omitted.
    scenario: Option<PathBuf>,
    /// Output directory [default: results/<scenario name>].
    #[arg(long)]
    out: Option<PathBuf>,
    /// Worker threads (the results do not depend on it) [default: all cores].
    #[arg(long)]
    threads: Option<usize>,
    /// Fill the study's `fit_ms` column with wall-clock fit times. Off by default so that `metrics.csv` and
    /// `summary.md` are byte-identical for the same scenario whatever the machine and thread count; the
    /// benchmarks (`cargo bench`) measure fit times properly.
    #[arg(long)]
    timings: bool,
}

fn main() -> ExitCode {
    let args = Args::parse();
    match run(&args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

fn run(args: &Args) -> Result<()> {
    if let Some(n) = args.threads {
        if n == 0 {
            return Err(Error::Invalid("--threads must be at least 1".into()));
        }
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build_global()
            .map_err(|e| Error::Invalid(format!("cannot start {n} threads: {e}")))?;
    }
    let scenario = match &args.scenario {
        Some(path) => Scenario::load(path)?,
        None => Scenario::parse(DEFAULT_SCENARIO, "embedded default.toml")?,
    };
    let started = Instant::now();
    let sim = campaign::simulate(&scenario)?;
    let generated = started.elapsed();
    let (robot, tracker, mounting, campaign) =
        (&sim.robot, &sim.tracker, &sim.mounting, &sim.campaign);

    let measured = eval::measured(campaign)?;
    let commands: Vec<Vec<f64>> = campaign.points.iter().map(|p| p.q_cmd.clone()).collect();
    let budget = Budget::of(&sim.nominal, robot, mounting, &commands)?;

    let out = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("results").join(&scenario.name));
    let report = json!({
        "scenario": scenario,
        "points": campaign.points.len(),
        "rejections": campaign.rejections,
        "truth": {
            "perturbation": robot.perturbation,
            "mounting": mounting,
            "tracker_pose": {
                "translation_m": tracker_translation(tracker),
                "rotation_quaternion_wxyz": tracker_quaternion(tracker),
            },
        },
        "measured_mm": measured.scaled(1e3),
        "error_budget_mm": {
            "all_systematic": budget.all_systematic.scaled(1e3),
            "elastic_only": budget.elastic_only.scaled(1e3),
            "rigid_only": budget.rigid_only.scaled(1e3),
        },
    });
    let json = serde_json::to_vec_pretty(&report)
        .map_err(|e| Error::Invalid(format!("campaign.json: {e}")))?;
    let mut files: Vec<(String, Vec<u8>)> = vec![
        (
            "measurements.csv".into(),
            measurements::measurements_csv(campaign)?,
        ),
        ("truth.csv".into(), measurements::truth_csv(campaign)?),
        ("campaign.json".into(), json),
    ];
    let evaluation = match &scenario.evaluation {
        Some(config) => {
            let started = Instant::now();
            let evaluation = eval::evaluate(&scenario, &sim, config)?;
            let json = serde_json::to_vec_pretty(&evaluation)
                .map_err(|e| Error::Invalid(format!("evaluation.json: {e}")))?;
            files.push(("evaluation.json".into(), json));
            Some((evaluation, started.elapsed()))
        }
        None => None,
    };
    let study = match &scenario.study {
        Some(_) => {
            let started = Instant::now();
            let mut study = run_study(&scenario, Progress::Auto)?;
            if !args.timings {
                study.runs.iter_mut().for_each(|r| r.fit_ms = f64::NAN);
            }
            let summary = report::summary::summary_md(&study)?;
            files.push(("metrics.csv".into(), report::summary::metrics_csv(&study)?));
            files.push(("outside.csv".into(), report::summary::outside_csv(&study)?));
            files.extend(report::plots::learning_curves_png(&study)?);
            files.extend(report::plots::histograms_png(&study)?);
            files.push((
                "campaign.rrd".into(),
                report::recording::record(&study, &sim.nominal, &summary)?,
            ));
            files.push(("summary.md".into(), summary.into_bytes()));
            Some((study, started.elapsed()))
        }
        None => None,
    };
    output::write_files(&out, &files)?;

    println!(
        "scenario '{}': {} points in {:.2} s",
        scenario.name,
        campaign.points.len(),
        generated.as_secs_f64()
    );
    for (region, r) in &campaign.rejections {
        println!(
            "  region '{region}': {} used of {} feasible from {} candidates (rejected: {} out of reach, {} joint limits, \
             {} self-collision, {} obstacle, {} line of sight, {} acceptance cone)",
            r.used,
            r.feasible,
            r.candidates,
            r.out_of_reach,
            r.joint_limits,
            r.self_collision,
            r.environment_collision,
            r.line_of_sight,
            r.acceptance_cone
        );
    }
    let row = |name: &str, s: &Stats| {
        let s = s.scaled(1e3);
        println!(
            "  {name:<34} mean {:.4}  std {:.4}  max {:.4}  rms {:.4}  p95 {:.4}",
            s.mean, s.std, s.max, s.rms, s.p95
        );
    };
    println!("distance errors of the reflector (or nest centre) after rigid registration (mm):");
    row("measured (paper's Table 1 column)", &measured);
    row("true, all systematic errors", &budget.all_systematic);
    row("true, elastic deflection only", &budget.elastic_only);
    row("true, rigid errors only", &budget.rigid_only);
    if let Some((evaluation, took)) = &evaluation {
        print!("{}", evaluation.table());
        println!(
            "evaluated {} methods in {:.2} s",
            evaluation.methods.len(),
            took.as_secs_f64()
        );
    }
    if let Some((study, took)) = &study {
        let failed = study.runs.iter().filter(|r| r.failure.is_some()).count();
        println!(
            "study: {} runs ({} failed, reasons in metrics.csv) in {:.1} s; see summary.md, plots/ and campaign.rrd \
             (open with `rerun campaign.rrd`, rerun-sdk 0.36)",
            study.runs.len(),
            failed,
            took.as_secs_f64()
        );
    }
    println!("wrote {}", out.display());
    Ok(())
}

fn tracker_translation(tracker: &Tracker) -> [f64; 3] {
    tracker.pose.translation.vector.into()
}

fn tracker_quaternion(tracker: &Tracker) -> [f64; 4] {
    let q = tracker.pose.rotation.quaternion();
    [q.w, q.i, q.j, q.k]
}
