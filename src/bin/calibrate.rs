//! `calibrate --data FILE.csv [--robot URDF] [--method M] [--truth truth.csv] [--out DIR]`: fits a calibration
//! method on measured data, prints the paper's Table 1 (and Table 2 with measured orientation) for the test
//! split, and writes `report.json`, `model.json` and `predictions.csv`.
//!
//! `--mapping FILE.toml` reads a foreign export (delimiter, decimal comma, units, orientation convention; see
//! `calibench::dataset::mapping`); `--test-data FILE` fits on all of `--data` (train and validation) and tests
//! on another campaign, re-registering its tracker frame and probe mounting on its own points.
//!
//! `calibrate apply --model model.json --data FILE.csv [--out DIR]`: predicted poses and corrected joint
//! commands for new joint configurations, in `DIR/applied.csv`. `calibrate curve` and `calibrate export`
//! (flags: `--help`): the learning curve of a file; a kinematic or elastic model as a robot description.

use std::process::ExitCode;

use calibench::cli::calibrate::{Cli, run};

fn main() -> ExitCode {
    match run(calibench::app::parse_args::<Cli>()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", e.line());
            ExitCode::FAILURE
        }
    }
}
