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

use std::process::ExitCode;

use calibench::cli::real_data::{Cli, run};

fn main() -> ExitCode {
    match run(calibench::app::parse_args::<Cli>()) {
        Ok(written) => {
            println!("\nwrote {}", written.display());
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("error: {}", e.line());
            ExitCode::FAILURE
        }
    }
}
