//! The `calibrate curve` job: the learning curve of any measured file ([`crate::eval::curve`], where the
//! held-out quarter and the subsets are drawn from the row count and the seed alone): for each size and draw a
//! random subset, split into training and validation as `calibrate` splits, every method fitted on it and
//! tested on one fixed held-out quarter of the file. Writes `curve.csv` and `curve.png`, all or none.

use std::fmt::Write as _;
use std::path::PathBuf;

use clap::Args;

use crate::calib::method::FitContext;
use crate::calib::registry::MethodKind;
use crate::calib::regression::RegressionOptions;
use crate::error::{Error, Result};
use crate::eval::curve::{self, CurvePlan, LearningCurve, learning_curve};
use crate::eval::split::{DEFAULT_FRACTIONS, SplitRule};
use crate::output;
use crate::report::plots::{self, Band};

use super::arg_values;
use super::calibrate::{self, read_measured};

/// The flags of `calibrate curve` (parsed here, so that the binary stays a parser of subcommands).
#[derive(Args, Clone, Debug)]
pub struct CurveOptions {
    /// The robot: a URDF, or a DH description (.toml); the built-in robots of `calibrate --robot` work from any
    /// directory.
    #[arg(long)]
    pub robot: PathBuf,
    /// The link carrying the reflectors [default: the chain's last link].
    #[arg(long)]
    pub flange_link: Option<String>,
    /// Measurements (the `measurements.csv` format), or any export with `--mapping`. A `split` column is
    /// ignored: the held-out quarter and the subsets depend only on the row count and `--seed`.
    #[arg(long)]
    pub data: PathBuf,
    /// A column mapping (TOML) for reading a foreign export, as `calibrate --mapping`.
    #[arg(long)]
    pub mapping: Option<PathBuf>,
    /// Drop the data's extra inputs (e.g. temperature) so no method regresses on them.
    #[arg(long)]
    pub ignore_inputs: bool,
    /// The methods, comma-separated.
    #[arg(long, value_delimiter = ',', required = true, value_parser = arg_values::method_values())]
    pub methods: Vec<MethodKind>,
    /// Subset sizes, comma-separated: the points each fit draws (2/3 training, 1/3 validation, as `calibrate`
    /// splits 50 % : 25 %), from the three quarters of the file not held out.
    #[arg(long, value_delimiter = ',', required = true)]
    pub sizes: Vec<usize>,
    /// Random subsets per size.
    #[arg(long)]
    pub draws: usize,
    /// Seed of the held-out quarter and of the subsets.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Mass on the flange (kg), for the gravity torques of the elastic methods.
    #[arg(long, default_value_t = 0.0)]
    pub payload_kg: f64,
    /// Its centre of mass in the flange frame (m), x,y,z.
    #[arg(long, value_delimiter = ',', default_value = "0,0,0")]
    pub payload_com_m: Vec<f64>,
    /// Worker threads (the results do not depend on it) [default: SLURM_CPUS_PER_TASK when set, else all
    /// cores].
    #[arg(long)]
    pub threads: Option<usize>,
    /// Output directory, relative to the current directory: curve.csv and curve.png, replaced all at once.
    #[arg(long)]
    pub out: PathBuf,
}

impl CurveOptions {
    /// The sizes, draws and seed as a plan over `calibrate`'s default fractions.
    pub fn plan(&self) -> CurvePlan {
        CurvePlan {
            rule: SplitRule::new(DEFAULT_FRACTIONS, self.seed),
            sizes: self.sizes.clone(),
            draws: self.draws,
        }
    }
}

/// The files `calibrate curve` writes.
const OUTPUTS: [&str; 2] = ["curve.csv", "curve.png"];

/// What [`run`] did, for the binary to print.
#[derive(Clone, Debug)]
pub struct CurveOutcome {
    pub curve: LearningCurve,
    /// The table of means over draws (Markdown).
    pub table: String,
    pub out: PathBuf,
    pub warnings: Vec<String>,
}

impl CurveOutcome {
    /// What `calibrate curve` prints (stdout) and warns (stderr).
    pub fn text_and_warnings(self) -> (String, Vec<String>) {
        let text = format!(
            "{}\nwrote {} ({})\n",
            self.table,
            self.out.display(),
            OUTPUTS.join(", ")
        );
        (text, self.warnings)
    }
}

/// Sets the worker count (`--threads`), then [`curve`].
pub fn run(options: &CurveOptions) -> Result<CurveOutcome> {
    super::set_threads(options.threads)?;
    curve(options)
}

/// Computes the learning curve of `options.data` on the current rayon pool and writes `curve.csv` and
/// `curve.png` into `options.out`, all or none. Every count is checked before the file is read, the sizes
/// against the pool before anything is fitted.
pub fn curve(options: &CurveOptions) -> Result<CurveOutcome> {
    let plan = options.plan();
    plan.check_counts()?;
    if let Some(m) = options
        .methods
        .iter()
        .enumerate()
        .find_map(|(k, m)| options.methods[..k].contains(m).then_some(m))
    {
        return Err(Error::Invalid(format!("--methods: {m} is given twice")));
    }
    let payload = calibrate::payload(options.payload_kg, &options.payload_com_m)?;
    output::check_dir(&options.out, &OUTPUTS)?;
    let (chain, dh, mapping) = calibrate::robot_and_mapping(
        &options.robot,
        options.flange_link.as_deref(),
        options.mapping.as_deref(),
    )?;
    let (data, _) = read_measured(
        &options.data,
        mapping.as_ref(),
        (&chain, &dh),
        &options.robot,
        options.ignore_inputs,
    )?;
    let ctx = FitContext {
        share: None,
        chain: &chain,
        dh: &dh,
        payload,
        regression: RegressionOptions::default(),
    };
    let found = learning_curve(&options.methods, &ctx, &plan, &data)?;
    let name = options
        .data
        .file_name()
        .map_or_else(|| data.origin.clone(), |n| n.to_string_lossy().into_owned());
    let title = format!(
        "{name}: {} held-out points, {} draws",
        found.n_test, plan.draws
    );
    let png = plots::measured_curve_png(&title, &bands(&options.methods, &plan.sizes, &found))?;
    output::write_dir(
        &options.out,
        &[("curve.csv", curve_csv(&found)?), ("curve.png", png)],
        &[],
    )?;
    let mut warnings = Vec::new();
    if data.split.is_some() {
        warnings.push(format!(
            "{}: its split column is ignored; the held-out quarter and the subsets are drawn from the row \
             count and --seed alone",
            data.origin
        ));
    }
    warnings.extend(outside_warning(&plan.sizes, &found));
    let failed = found.draws.iter().filter(|d| d.error.is_some()).count();
    if failed > 0 {
        warnings.push(format!(
            "{failed} of {} fits failed; curve.csv's status column says why",
            found.draws.len()
        ));
    }
    Ok(CurveOutcome {
        table: markdown(&options.methods, &plan.sizes, &found, &name),
        curve: found,
        out: options.out.clone(),
        warnings,
    })
}

/// How many held-out points lie outside the fits' training domains, per size (mean over the successful
/// fits), when any does: there the models' regressions fade out to their parametric part, so the curve's
/// small sizes say how a method does mostly beyond its data.
fn outside_warning(sizes: &[usize], found: &LearningCurve) -> Option<String> {
    let per_size: Vec<String> = sizes
        .iter()
        .filter_map(|&n| {
            let counts: Vec<usize> = found
                .draws
                .iter()
                .filter(|d| d.size == n)
                .filter_map(|d| d.outside_domain)
                .collect();
            let mean = counts.iter().sum::<usize>() as f64 / counts.len().max(1) as f64;
            (mean > 0.0).then(|| format!("{mean:.0} at {n} points"))
        })
        .collect();
    (!per_size.is_empty()).then(|| {
        format!(
            "of the {} held-out points, these lie outside the fits' training domain (mean over fits; the \
             regressions fade out there, `calibrate`'s test_points.csv names them): {}",
            found.n_test,
            per_size.join(", ")
        )
    })
}

/// `curve.csv`: one row per fit, by size, draw and method; the held-out errors in mm, empty when the fit
/// failed, and the status `ok` or `failed: <why>`.
fn curve_csv(found: &LearningCurve) -> Result<Vec<u8>> {
    let csv_err = |e: csv::Error| Error::Invalid(format!("curve.csv: {e}"));
    let mut w = csv::Writer::from_writer(Vec::new());
    w.write_record([
        "method",
        "size",
        "draw",
        "test_mean_mm",
        "test_p95_mm",
        "test_max_mm",
        "status",
    ])
    .map_err(csv_err)?;
    let cell = |v: Option<f64>| v.map_or(String::new(), |v| v.to_string());
    for d in &found.draws {
        let status = match &d.error {
            None => "ok".to_string(),
            Some(e) => format!("failed: {e}"),
        };
        w.write_record([
            d.method.name().to_string(),
            d.size.to_string(),
            d.draw.to_string(),
            cell(d.mean_mm),
            cell(d.p95_mm),
            cell(d.max_mm),
            status,
        ])
        .map_err(csv_err)?;
    }
    w.into_inner()
        .map_err(|e| Error::Invalid(format!("curve.csv: {e}")))
}

/// Per method, the plot's line (the mean over draws of the held-out mean) and band (their min and max).
fn bands(methods: &[MethodKind], sizes: &[usize], found: &LearningCurve) -> Vec<Band> {
    let mut sorted = sizes.to_vec();
    sorted.sort_unstable();
    methods
        .iter()
        .map(|&method| Band {
            method,
            points: sorted
                .iter()
                .filter_map(|&n| {
                    let (Some([mean, lo, hi]), _) = curve::cell(&found.draws, method, n) else {
                        return None;
                    };
                    Some([n as f64, lo, mean, hi])
                })
                .collect(),
        })
        .collect()
}

/// The curve as a Markdown table: per method and size the mean over draws of the held-out mean (mm), with
/// its min–max, on the held-out points of `what`.
pub fn markdown(
    methods: &[MethodKind],
    sizes: &[usize],
    found: &LearningCurve,
    what: &str,
) -> String {
    // `write!` into a `String` cannot fail: its results are ignored.
    let mut out = format!(
        "\n#### Learning curve: mean position error (mm) on the {} held-out points of {what}, \
         mean over draws (min–max)\n\n| method |",
        found.n_test
    );
    for n in sizes {
        let _ = write!(out, " {n} |");
    }
    out += "\n|---|";
    for _ in sizes {
        out += "---|";
    }
    out += "\n";
    for &kind in methods {
        let _ = write!(out, "| `{}` |", kind.name());
        for &n in sizes {
            match curve::cell(&found.draws, kind, n) {
                (None, _) => out += " failed |",
                (Some([mean, lo, hi]), failed) => {
                    let note = if failed > 0 {
                        format!(" ({failed} failed)")
                    } else {
                        String::new()
                    };
                    let _ = write!(out, " {mean:.3} ({lo:.3}–{hi:.3}){note} |");
                }
            }
        }
        out += "\n";
    }
    out
}
