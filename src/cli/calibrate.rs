//! `calibrate`'s command line (its binary parses it with [`crate::app::parse_args`] and calls [`run`]).
//!
//! `calibrate --data FILE.csv [--robot URDF] [--method M] [--truth truth.csv] [--out DIR]`: fits a calibration
//! method on measured data, prints the paper's Table 1 (and Table 2 with measured orientation) for the test
//! split, and writes `report.json`, `model.json` and `predictions.csv`.
//!
//! `--mapping FILE.toml` reads a foreign export (delimiter, decimal comma, units, orientation convention; see
//! `calibench::dataset::mapping`); `--test-data FILE` fits on all of `--data` (train and validation) and tests
//! on another campaign, re-registering its tracker frame and probe mounting on its own points.
//!
//! `calibrate apply --model model.json --data FILE.csv [--out DIR]`: predicted poses and corrected joint
//! commands for new joint configurations, in `DIR/applied.csv`.

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand};

use crate::app::apply::{self, ApplyOptions};
use crate::app::arg_values;
use crate::app::calibrate::{self, FitOptions};
use crate::app::curve::{self, CurveOptions};
use crate::app::export::{self, ExportOptions};
use crate::calib::registry::{MethodKind, RECOMMENDED};
use crate::calib::regression::RegressionOptions;
use crate::error::{Error, Result};
use crate::eval::split::SplitRule;
use crate::eval::transfer::TestRegistration;

#[derive(Parser, Debug)]
#[command(
    version,
    about = "Calibrate a robot from laser-tracker measurements",
    args_conflicts_with_subcommands = true,
    allow_negative_numbers = true
)]
pub struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
    #[command(flatten)]
    fit: FitArgs,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Predict poses and corrected joint commands for new configurations with a saved model.
    Apply(ApplyArgs),
    /// The learning curve of a measured file: held-out errors of random training subsets of growing size.
    Curve(CurveOptions),
    /// A kinematic or elastic model as a robot description (URDF or DH table) that other tools load.
    Export(ExportOptions),
}

#[derive(Args, Debug)]
struct FitArgs {
    /// Measurements (the `measurements.csv` format; see results/README.md), or any export with `--mapping`.
    #[arg(long)]
    data: Option<PathBuf>,
    /// A column mapping (TOML) for reading a foreign export: columns, delimiter, decimal separator, units,
    /// orientation convention, extra inputs. See `mappings/ipa_ur10.toml`.
    #[arg(long)]
    mapping: Option<PathBuf>,
    /// Test on this campaign instead of a test split of `--data` (which then splits into training and
    /// validation only, in the ratio of the first two `--split` fractions).
    #[arg(long)]
    test_data: Option<PathBuf>,
    /// The mapping of `--test-data` [default: `--mapping`].
    #[arg(long)]
    test_mapping: Option<PathBuf>,
    /// How the test campaign is registered.
    #[arg(long, default_value = "refit", value_parser = arg_values::registration_values())]
    test_registration: TestRegistration,
    /// Drop the data's extra inputs (e.g. temperature) so no method regresses on them.
    #[arg(long)]
    ignore_inputs: bool,
    /// Give the methods that regress on extra inputs the motion as inputs: per joint, the torque the commanded
    /// motion needs beyond gravity (data measured on the fly with `qd_<joint>` and `qdd_<joint>` columns). A
    /// prediction without them is at rest.
    #[arg(long)]
    motion_inputs: bool,
    /// The robot: a URDF, or a DH description (.toml, see robots/README.md); its joint names name the joint
    /// columns. `robots/iiwa7.urdf`, `robots/ur10.urdf`, `robots/ur5.urdf` and `robots/ur5.toml` are built in:
    /// they work from any directory.
    #[arg(long, default_value = "robots/iiwa7.urdf")]
    robot: PathBuf,
    /// The link carrying the reflectors [default: the chain's last link].
    #[arg(long)]
    flange_link: Option<String>,
    /// The calibration method. The default, `elastic`, is the one the results recommend: on the real UR10
    /// campaigns it is the most accurate on a campaign other than the one it was fitted on (the regression
    /// methods fall back to their constant parts outside their training data), and in the simulated study it
    /// reaches the lowest floor with `hybrid`. Within one campaign's layout the methods end close together.
    #[arg(long, default_value_t = RECOMMENDED, value_parser = arg_values::method_values())]
    method: MethodKind,
    /// Mass on the flange (kg), for the gravity torques of the elastic methods.
    #[arg(long, default_value_t = 0.0)]
    payload_kg: f64,
    /// Its centre of mass in the flange frame (m), x,y,z.
    #[arg(long, value_delimiter = ',', default_value = "0,0,0")]
    payload_com_m: Vec<f64>,
    /// Ground truth (`truth.csv` of a simulated campaign) to evaluate against.
    #[arg(long)]
    truth: Option<PathBuf>,
    /// Output directory, relative to the current directory: model.json, report.json, predictions.csv and
    /// test_points.csv, replaced all at once.
    #[arg(long, default_value = "results/calibrate")]
    out: PathBuf,
    /// Train, validation and test fractions, used when the data has no `split` column.
    #[arg(long, value_delimiter = ',', default_value = "0.5,0.25,0.25")]
    split: Vec<f64>,
    /// Seed of the random split.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Highest polynomial degree the regression may choose.
    #[arg(long, default_value_t = 5)]
    max_degree: usize,
    /// Add pairwise products of the inputs to the polynomial features (eq. 18 has none).
    #[arg(long)]
    cross_terms: bool,
}

#[derive(Args, Debug)]
struct ApplyArgs {
    /// A `model.json` written by `calibrate`.
    #[arg(long)]
    model: PathBuf,
    /// Joint configurations: a CSV with one column per joint of the model, and one per extra input the model
    /// regressed on (e.g. `temperature`; a file without it is refused). Other columns are ignored.
    #[arg(long)]
    data: PathBuf,
    /// A column mapping (TOML) for reading `--data` (only its joint columns, `point_id` and the `[inputs]`
    /// the model regressed on are used).
    #[arg(long)]
    mapping: Option<PathBuf>,
    /// Output directory, relative to the current directory: applied.csv (predicted poses, corrected commands
    /// and each row's domain status), replaced all at once.
    #[arg(long, default_value = "results/apply")]
    out: PathBuf,
}

/// Runs the command line: fits, or applies a saved model; prints what was done and the warnings.
pub fn run(cli: Cli) -> Result<()> {
    let (text, warnings) = match cli.command {
        Some(Command::Curve(c)) => curve::run(&c)?.text_and_warnings(),
        Some(Command::Export(e)) => (export::export(&e)?.text(), Vec::new()),
        Some(Command::Apply(a)) => {
            let done = apply::apply(&ApplyOptions {
                model: a.model,
                data: a.data,
                mapping: a.mapping,
                out: a.out,
            })?;
            (done.text(), done.warnings)
        }
        None => {
            let done = calibrate::fit(&fit_options(cli.fit)?)?;
            (done.text(), done.report.warnings)
        }
    };
    print!("{text}");
    warnings.iter().for_each(|w| eprintln!("warning: {w}"));
    Ok(())
}

/// The flags as the job's options; the values are checked here, before any file is read.
fn fit_options(args: FitArgs) -> Result<FitOptions> {
    let data = args.data.ok_or_else(|| {
        Error::Invalid("--data FILE.csv is required (or use `calibrate apply`)".into())
    })?;
    let payload = calibrate::payload(args.payload_kg, &args.payload_com_m)?;
    let fractions: [f64; 3] = args.split.as_slice().try_into().map_err(|_| {
        let n = args.split.len();
        Error::Invalid(format!(
            "--split needs three fractions (train,val,test), got {n}"
        ))
    })?;
    Ok(FitOptions {
        data,
        mapping: args.mapping,
        test_data: args.test_data,
        test_mapping: args.test_mapping,
        test_registration: args.test_registration,
        ignore_inputs: args.ignore_inputs,
        motion_inputs: args.motion_inputs,
        robot: args.robot,
        flange_link: args.flange_link,
        method: args.method,
        payload,
        truth: args.truth,
        out: args.out,
        split: SplitRule::new(fractions, args.seed),
        regression: RegressionOptions {
            max_degree: args.max_degree,
            cross_terms: args.cross_terms,
            ..RegressionOptions::default()
        },
    })
}
