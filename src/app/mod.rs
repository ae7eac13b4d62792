//! The jobs the binaries run: each binary parses its flags into a job's options, calls the job, and prints
//! what it returns. [`campaign`] runs a scenario: build its world once, hand each stage the world and its own
//! section, and gather what they return (the only module that reads a [`Scenario`] besides `scenario`
//! itself); [`calibrate`] fits a method on measured data (its `report.json` is [`calibration_report`]) and
//! [`apply`] applies a saved model to new configurations, [`export`] writes one as a robot description;
//! [`curve`] draws the learning curve of a measured file (`calibrate curve`); [`real_data`] runs the
//! real-data protocol of
//! `eval::protocol` on the UR10 series.

pub mod apply;
pub mod arg_values;
pub mod calibrate;
pub mod calibration_report;
pub mod predictions;
pub mod campaign;
pub mod curve;
pub mod export;
pub mod real_data;
pub mod replay;
pub mod shard;
pub mod sim_vs_real;
pub mod test_points;
pub mod twin;

use crate::calib::method::FitContext;
use crate::campaign::{Generator, Simulation};
use crate::design::DOptimal;
use crate::error::{Error, Result};
use crate::scenario::Scenario;
use crate::study::sweep::{self, RunOptions};
use crate::study::{StudyConfig, StudyResult};
use crate::world::World;

/// The most worker threads `--threads` may ask for: more than the cores of any machine this runs on, and
/// few enough that starting them cannot exhaust the system (100 000 threads hung it).
pub const MAX_THREADS: usize = 256;

/// Sets the worker count: `flag` (`--threads`), else `SLURM_CPUS_PER_TASK` (what a Slurm job was given), else
/// every core.
pub fn set_threads(flag: Option<usize>) -> Result<()> {
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

/// The command line as `T`, or the process ends: with help or version printed (exit 0), or with one
/// `error:` line (exit 1, as every other refusal of the tools; clap alone would print its usage and exit 2).
pub fn parse_args<T: clap::Parser>() -> T {
    use clap::error::ErrorKind;
    match T::try_parse() {
        Ok(args) => args,
        Err(e) => match e.kind() {
            ErrorKind::DisplayHelp
            | ErrorKind::DisplayVersion
            | ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand => e.exit(),
            _ => {
                let text = e.to_string();
                let first = text
                    .lines()
                    .map(str::trim)
                    .find(|l| !l.is_empty())
                    .unwrap_or("error: bad arguments");
                let line = Error::Invalid(first.trim_start_matches("error:").trim().into()).line();
                eprintln!(
                    "error: {} (see --help)",
                    line.trim_start_matches("invalid input: ")
                );
                std::process::exit(1)
            }
        },
    }
}

/// The longest study `campaign` runs without `--long`: one hour by the up-front estimate
/// ([`StudyConfig::estimated_core_seconds`] over the cores). A study of two million runs was accepted and
/// would have run for weeks.
pub const STUDY_BUDGET_S: f64 = 3600.0;

/// Refuses a study estimated above [`STUDY_BUDGET_S`] on `threads` workers, unless `long`.
pub fn check_study_budget(scenario: &Scenario, threads: usize, long: bool) -> Result<()> {
    let Some(study) = &scenario.study else {
        return Ok(());
    };
    let seconds = study.estimated_core_seconds(scenario.regions.len()) / threads.max(1) as f64;
    if long || seconds <= STUDY_BUDGET_S {
        return Ok(());
    }
    Err(Error::Scenario {
        origin: scenario.origin.clone(),
        message: format!(
            "[study]: {} runs, an estimated {:.1} hours on {threads} threads, above the budget of {:.0} hour \
             (fewer sizes, seeds, layouts or methods shorten it); pass --long to run it anyway",
            study.runs(scenario.regions.len()),
            seconds / 3600.0,
            STUDY_BUDGET_S / 3600.0
        ),
    })
}

/// The scenario's world: its robot loaded and checked, the true robot, tracker and mounting drawn from its seed.
/// Evaluation poses are approached from the campaign's posture.
pub fn world(scenario: &Scenario) -> Result<World> {
    let mut world = World::new(scenario.load_robot()?, scenario.world.clone())
        .map_err(|e| e.in_scenario(&scenario.origin))?;
    world.robot.set_approach(&scenario.campaign.posture_rad());
    Ok(world)
}

/// The scenario's world and its campaign over every region.
pub fn simulate(scenario: &Scenario) -> Result<Simulation> {
    let world = world(scenario)?;
    let campaign = {
        let ctx = FitContext::of(&world);
        let selector = DOptimal::when_needed(
            scenario.regions.iter().map(|r| r.layout),
            &scenario.campaign.selection,
            &ctx,
            &world.mounting.nominal,
        )?;
        Generator {
            world: &world,
            config: &scenario.campaign,
            seed: world.seed(),
            selector: selector.as_ref().map(|s| s as _),
        }
        .run(&scenario.regions)
        .map_err(|e| e.in_scenario(&scenario.origin))?
    };
    Ok(Simulation { world, campaign })
}

/// Runs the scenario's `[study]` on the current rayon pool (install a pool to choose the thread count).
/// Errors: no `[study]` section, a robot that does not load, a region whose test set or ground truth cannot
/// be built. Runs that fail (a campaign the region cannot supply, a method that cannot be fitted) are
/// recorded as failed with their reason.
pub fn run_study(scenario: &Scenario, options: RunOptions) -> Result<StudyResult> {
    let config = study_config(scenario)?;
    sweep::run_study(
        &world(scenario)?,
        &scenario.campaign,
        &scenario.regions,
        config,
        options,
    )
}

/// The scenario's `[study]` (checked against its regions when the scenario was read).
fn study_config(scenario: &Scenario) -> Result<&StudyConfig> {
    scenario.study.as_ref().ok_or_else(|| Error::Scenario {
        origin: scenario.origin.clone(),
        message: "no [study] section: nothing to sweep".into(),
    })
}
