//! `campaign [SCENARIO.toml] [--out DIR] [--threads N] [--replay FILE [--mapping MAP]] [--shard K/N]`, or
//! `campaign merge SHARD_DIR... [--out DIR]`: simulates a
//! laser-tracker campaign of a robot whose true errors are known, and writes `measurements.csv`, `truth.csv`
//! and `campaign.json`; with an `[evaluation]` section it then fits the listed methods, judges them against
//! the truth and writes `evaluation.json` beside them. `--replay` measures a real campaign's joint
//! configurations instead of the scenario's regions, in the file's order, with the tracker where the real one
//! stood. `--shard K/N` runs one shard of the study and `merge` puts the shards' results together
//! (`app::shard`).

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;

use calibench::app::MAX_THREADS;
use calibench::app::campaign::{self, CampaignRun, Options, ReplaySource};
use calibench::app::shard;
use calibench::eval::Stats;
use calibench::report::metrics::worse_than_nominal;
use calibench::scenario::Scenario;
use calibench::study::Shard;
use calibench::{Error, Result};

/// The scenario run when none is given: the study a user should run first.
const DEFAULT_SCENARIO: &str = include_str!("../../scenarios/default.toml");

#[derive(Parser, Debug)]
#[command(
    version,
    about = "Simulate a laser-tracker calibration campaign with known true robot errors",
    allow_negative_numbers = true,
    args_conflicts_with_subcommands = true
)]
struct Args {
    #[command(subcommand)]
    command: Option<Command>,
    /// Scenario file (TOML); the embedded default study (`scenarios/default.toml`) when omitted.
    scenario: Option<PathBuf>,
    /// Output directory [default: results/<scenario name>, relative to the current directory]: measurements.csv,
    /// truth.csv, campaign.json, and as the scenario asks evaluation.json or the study's metrics.csv,
    /// outside.csv, answer.csv, summary.md, plots/ and campaign.rrd, replaced all at once.
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
    /// Measure the joint configurations of this real campaign file, in its order, instead of the scenario's
    /// regions (no evaluation or study then). The tracker and the reflector are placed by registering the
    /// file's measurements on the nominal robot; every row is measured, even where the simulated acceptance
    /// cone or an obstacle would refuse it.
    #[arg(long, value_name = "FILE")]
    replay: Option<PathBuf>,
    /// Column mapping the replayed file is read through (as `calibrate --mapping`); without it the file is
    /// read as a `measurements.csv`.
    #[arg(long, value_name = "MAP", requires = "replay")]
    mapping: Option<PathBuf>,
    /// Run a study whose estimated time exceeds the budget of one hour.
    #[arg(long)]
    long: bool,
    /// Run only shard K of N of the study (its campaigns with index i mod N = K) and write a shard directory
    /// (shard.json, study.cbor, metrics.csv) [default --out: results/<scenario name>-shard-K-of-N]; put the
    /// shards together with `campaign merge`.
    #[arg(long, value_name = "K/N", conflicts_with = "replay")]
    shard: Option<String>,
}

#[derive(clap::Subcommand, Debug)]
enum Command {
    /// Merge the shard directories of one study (`--shard K/N` runs) into the files of an unsharded run:
    /// metrics.csv, summary.md, answer.csv, plots and campaign.rrd, plus the scenario's own campaign files.
    Merge {
        /// Every shard's directory, each once.
        #[arg(required = true)]
        dirs: Vec<PathBuf>,
        /// Output directory [default: results/<scenario name>, relative to the current directory].
        #[arg(long)]
        out: Option<PathBuf>,
        /// Worker threads [default: SLURM_CPUS_PER_TASK when set, else all cores].
        #[arg(long)]
        threads: Option<usize>,
    },
}

fn main() -> ExitCode {
    let args = calibench::app::parse_args::<Args>();
    match run(&args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", e.line());
            ExitCode::FAILURE
        }
    }
}

/// Sets the worker count: `--threads`, else `SLURM_CPUS_PER_TASK` (what a Slurm job was given), else every core.
fn threads(flag: Option<usize>) -> Result<()> {
    let n = match flag {
        Some(n) => Some((n, "--threads".to_string())),
        None => match std::env::var("SLURM_CPUS_PER_TASK") {
            Ok(v) => Some((
                v.trim().parse().map_err(|_| {
                    Error::Invalid(format!("SLURM_CPUS_PER_TASK='{v}' is not a thread count"))
                })?,
                "SLURM_CPUS_PER_TASK".to_string(),
            )),
            Err(_) => None,
        },
    };
    if let Some((n, from)) = n {
        if !(1..=MAX_THREADS).contains(&n) {
            return Err(Error::Invalid(format!(
                "{from} {n}: between 1 and {MAX_THREADS}"
            )));
        }
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build_global()
            .map_err(|e| Error::Invalid(format!("cannot start {n} threads: {e}")))?;
    }
    Ok(())
}

fn run(args: &Args) -> Result<()> {
    if let Some(Command::Merge {
        dirs,
        out,
        threads: t,
    }) = &args.command
    {
        threads(*t)?;
        let done = shard::merge(dirs, out.clone())?;
        println!("merged {} shard directories", dirs.len());
        print(&done);
        return Ok(());
    }
    threads(args.threads)?;
    let scenario = match &args.scenario {
        Some(path) => Scenario::load(path)?,
        None => Scenario::parse(DEFAULT_SCENARIO, "embedded default.toml")?,
    };
    if let Some(text) = &args.shard {
        let which = Shard::parse(text).map_err(Error::Invalid)?;
        let done = shard::run_shard(
            &scenario,
            which,
            args.out.as_deref(),
            args.timings,
            args.long,
        )?;
        println!(
            "scenario '{}', shard {}: {} of {} campaigns, {} runs ({} failed) in {}; merge every shard's \
             directory with `campaign merge`",
            done.scenario,
            done.shard,
            done.campaigns,
            done.total_campaigns,
            done.runs,
            done.failed,
            done.out.display()
        );
        return Ok(());
    }
    let options = Options {
        out: args.out.clone(),
        timings: args.timings,
        replay: args.replay.clone().map(|file| ReplaySource {
            file,
            mapping: args.mapping.clone(),
        }),
        long: args.long,
        parts: None,
    };
    let done = campaign::run(scenario, &options)?;
    print(&done);
    Ok(())
}

fn print(done: &CampaignRun) {
    let campaign = &done.sim.campaign;
    println!(
        "scenario '{}': {} points in {:.2} s",
        done.scenario.world.name,
        campaign.points.len(),
        done.generated.as_secs_f64()
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
    if let Some(m) = &done.motion {
        println!(
            "  measured on the fly: {} samples along one path through {} targets, {:.1} s of tracker time; motion \
             moved the flange by up to {:.3} mm; clock offset {:.1} µs (calibrate estimates and removes it); \
             beam lost at {} samples ({} acceptance cone, {} line of sight)",
            m.samples,
            m.targets,
            m.duration_s,
            m.dynamic_max_mm,
            m.clock_offset_s * 1e6,
            m.lost_acceptance_cone + m.lost_line_of_sight,
            m.lost_acceptance_cone,
            m.lost_line_of_sight
        );
    }
    let row = |name: &str, s: &Stats| {
        let s = s.scaled(1e3);
        println!(
            "  {name:<34} mean {:.4}  std {:.4}  max {:.4}  rms {:.4}  p95 {:.4}",
            s.mean, s.std, s.max, s.rms, s.p95
        );
    };
    if done.study.is_some() {
        println!(
            "the scenario's own campaign before calibration (not the study's answer, which follows), distance \
             errors after rigid registration (mm):"
        );
    } else {
        println!(
            "distance errors of the reflector (or nest centre) after rigid registration (mm):"
        );
    }
    row("measured (paper's Table 1 column)", &done.measured);
    row("true, all systematic errors", &done.budget.all_systematic);
    row("true, elastic deflection only", &done.budget.elastic_only);
    row("true, rigid errors only", &done.budget.rigid_only);
    if let Some(r) = &done.replay {
        let t = &done.scenario.world.tracker;
        let m = r.mounting_m.map(|v| v * 1e3);
        println!(
            "replayed {} rows of {}: real data registered with RMS {:.4} mm; tracker placed at [{:.4}, {:.4}, {:.4}] m, \
             yaw {:.4}°, tilts [{:.4}, {:.4}]° (decomposition residual {:.1e} rad); reflector at \
             [{:.3}, {:.3}, {:.3}] mm on the flange",
            r.rows,
            r.file.display(),
            r.registration_rms_m * 1e3,
            t.position_m[0],
            t.position_m[1],
            t.position_m[2],
            t.yaw_deg,
            t.tilt_deg[0],
            t.tilt_deg[1],
            r.placement_residual_rad,
            m[0],
            m[1],
            m[2]
        );
    }
    if let Some((evaluation, took)) = &done.evaluation {
        print!("{}", evaluation.table());
        println!(
            "evaluated {} methods in {:.2} s",
            evaluation.methods.len(),
            took.as_secs_f64()
        );
    }
    if let Some((study, took)) = &done.study {
        let failed = study.runs.iter().filter(|r| r.failure.is_some()).count();
        let worse = study
            .runs
            .iter()
            .filter(|r| worse_than_nominal(r, study) == Some(true))
            .count();
        println!(
            "study: {} runs ({} failed, reasons in metrics.csv; {} worse than nominal, flagged there) in {:.1} s; \
             see summary.md, answer.csv, plots/ and campaign.rrd (open with `rerun campaign.rrd`, rerun-sdk 0.36)",
            study.runs.len(),
            failed,
            worse,
            took.as_secs_f64()
        );
        print!("{}", calibench::report::answer::answer_text(study));
    }
    println!("wrote {}", done.out.display());
}
