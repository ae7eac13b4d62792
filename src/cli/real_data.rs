//! `real_data`'s command line (its binary parses it with [`crate::app::parse_args`] and calls [`run`]).
//!
//! `real_data [--data-dir DIR] [--out DIR]`: every calibration method on the real UR10 laser-tracker campaigns
//! of Landgraf et al. (IEEE CASE 2021; `data/ipa-ur10`), read through `mappings/ipa_ur10.toml`.
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
//! `--simulate SCENARIO` replays the three series in the scenario's world (`campaign --replay`), runs the same
//! protocol on the simulated series, and prints every table's held-out mean and max beside the real one
//! (`DIR/sim_vs_real.json`, `DIR/sim_vs_real.csv`).
//!
//! `calibrate --robot robots/ur10.urdf --mapping mappings/ipa_ur10.toml --data …/Series_C/… --test-data
//! …/Series_D/… --method M` reproduces any row of table 1 (`--ignore-inputs` for the rows without
//! temperature).

use std::path::PathBuf;

use clap::Parser;

use crate::app::real_data::{self, RealDataOptions};
use crate::app::sim_vs_real;
use crate::error::Result;

#[derive(Parser, Debug)]
#[command(
    about = "Every calibration method on the real UR10 tracker data: the README's tables",
    allow_negative_numbers = true
)]
pub struct Cli {
    /// The data set's directory (Series_B, Series_C, Series_D), relative to the current directory: the copy
    /// in the repository by default.
    #[arg(long, default_value = "data/ipa-ur10")]
    data_dir: PathBuf,
    /// Column mapping of the series (built in: works from any directory).
    #[arg(long, default_value = "mappings/ipa_ur10.toml")]
    mapping: PathBuf,
    /// The robot, URDF or DH description (.toml); the default is built in.
    #[arg(long, default_value = "robots/ur10.urdf")]
    robot: PathBuf,
    /// Output directory, relative to the current directory: real_data.json (and sim_vs_real.json, .csv with
    /// --simulate).
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
    /// Replay the series in this scenario's world and print the simulated tables beside the real ones.
    #[arg(long, value_name = "SCENARIO")]
    simulate: Option<PathBuf>,
}

/// Runs the command line: the tables (printed as they are ready), or with `--simulate` the simulated ones
/// beside them; returns the file written.
pub fn run(cli: Cli) -> Result<PathBuf> {
    let options = RealDataOptions {
        data_dir: cli.data_dir,
        mapping: cli.mapping,
        robot: cli.robot,
        out: cli.out,
        draws: cli.draws,
        sizes: Some(cli.sizes).filter(|_| !cli.no_curve),
    };
    let show = &mut |text: &str| print!("{text}");
    match &cli.simulate {
        None => real_data::run(&options, show),
        Some(scenario) => sim_vs_real::run(&options, scenario, show),
    }
}
