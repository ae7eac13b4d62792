//! `campaign`'s command line (its binary parses it with [`crate::app::parse_args`] and calls [`run`]).
//!
//! `campaign [SCENARIO.toml] [--out DIR] [--threads N] [--replay FILE [--mapping MAP]] [--shard K/N]`, or
//! `campaign merge SHARD_DIR... [--out DIR]`: simulates a
//! laser-tracker campaign of a robot whose true errors are known, and writes `measurements.csv`, `truth.csv`
//! and `campaign.json`; with an `[evaluation]` section it then fits the listed methods, judges them against
//! the truth and writes `evaluation.json` beside them. `--replay` measures a real campaign's joint
//! configurations instead of the scenario's regions, in the file's order, with the tracker where the real one
//! stood. `--shard K/N` runs one shard of the study and `merge` puts the shards' results together
//! (`app::shard`).

use std::path::PathBuf;

use clap::Parser;

use crate::app::campaign::{self, CampaignOptions, ReplaySource};
use crate::app::{calibrate, set_threads, shard, twin};
use crate::error::{Error, Result};
use crate::scenario::Scenario;
use crate::study::Shard;

/// The scenario run when none is given: the study a user should run first.
const DEFAULT_SCENARIO: &str = include_str!("../../scenarios/default.toml");

#[derive(Parser, Debug)]
#[command(
    version,
    about = "Simulate a laser-tracker calibration campaign with known true robot errors",
    allow_negative_numbers = true,
    args_conflicts_with_subcommands = true
)]
pub struct Args {
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
    /// Build the twin of one measured arm from a pilot campaign (100–300 points): its identified geometry and
    /// joint compliances, the magnitudes of what no method models fitted to the pilot; writes twin.toml (a
    /// scenario: `campaign DIR/twin.toml`, `--replay`), twin.json and twin.md.
    Twin(TwinArgs),
}

#[derive(clap::Args, Debug)]
struct TwinArgs {
    /// The robot: a URDF or a DH description (.toml); built-in robots work from any directory.
    #[arg(long)]
    robot: PathBuf,
    /// The link carrying the probe [default: the chain's last link].
    #[arg(long)]
    flange_link: Option<String>,
    /// The pilot campaign (the `measurements.csv` format, or any export with `--mapping`).
    #[arg(long)]
    data: PathBuf,
    #[arg(long)]
    mapping: Option<PathBuf>,
    /// Drop the pilot's extra inputs (its temperature).
    #[arg(long)]
    ignore_inputs: bool,
    /// Mass on the flange (kg) and its centre of mass in the flange frame (m, x,y,z).
    #[arg(long, default_value_t = 0.0)]
    payload_kg: f64,
    #[arg(long, value_delimiter = ',', default_value = "0,0,0")]
    payload_com_m: Vec<f64>,
    /// Seed of the pilot's splits and of the twin's draws.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Draws of the twin its study is run for, to give the answer with a range (0: none).
    #[arg(long, default_value_t = 5)]
    answer_draws: usize,
    /// Output directory: twin.toml, twin.json, twin.md, replaced all at once.
    #[arg(long)]
    out: PathBuf,
}

/// Runs the command line: a campaign or study, a shard, a merge or a twin; prints what was done.
pub fn run(args: &Args) -> Result<()> {
    if let Some(Command::Merge {
        dirs,
        out,
        threads: t,
    }) = &args.command
    {
        set_threads(*t)?;
        let done = shard::merge(dirs, out.clone())?;
        println!("merged {} shard directories", dirs.len());
        print!("{}", done.text());
        return Ok(());
    }
    if let Some(Command::Twin(a)) = &args.command {
        set_threads(args.threads)?;
        let done = twin::run(&twin::TwinOptions {
            robot: a.robot.clone(),
            flange_link: a.flange_link.clone(),
            data: a.data.clone(),
            mapping: a.mapping.clone(),
            ignore_inputs: a.ignore_inputs,
            payload: calibrate::payload(a.payload_kg, &a.payload_com_m)?,
            seed: a.seed,
            answer_draws: a.answer_draws,
            out: a.out.clone(),
        })?;
        if let Some(w) = done.warning() {
            eprintln!("warning: {w}");
        }
        print!("{}", done.text());
        return Ok(());
    }
    set_threads(args.threads)?;
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
        print!("{}", done.text());
        return Ok(());
    }
    let options = CampaignOptions {
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
    print!("{}", done.text());
    Ok(())
}
