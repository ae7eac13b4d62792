//! `campaign [SCENARIO.toml] [--out DIR] [--threads N] [--replay FILE [--mapping MAP]] [--shard K/N]`, or
//! `campaign merge SHARD_DIR... [--out DIR]`: simulates a
//! laser-tracker campaign of a robot whose true errors are known, and writes `measurements.csv`, `truth.csv`
//! and `campaign.json`; with an `[evaluation]` section it then fits the listed methods, judges them against
//! the truth and writes `evaluation.json` beside them. `--replay` measures a real campaign's joint
//! configurations instead of the scenario's regions, in the file's order, with the tracker where the real one
//! stood. `--shard K/N` runs one shard of the study and `merge` puts the shards' results together
//! (`app::shard`).

use std::process::ExitCode;

use calibench::cli::campaign::{Args, run};

fn main() -> ExitCode {
    match run(&calibench::app::parse_args::<Args>()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", e.line());
            ExitCode::FAILURE
        }
    }
}
