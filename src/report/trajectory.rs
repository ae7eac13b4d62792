//! The tracker-time comparison (issue 16): `trajectory.csv`, one row per trajectory run, and the summary's
//! section that answers "how much tracker time does a trajectory save, and what accuracy does it cost".
//!
//! A trajectory run is compared with the stop-and-go runs of the same region, method, targets and seeds on the
//! uniform layout (the targets the path passes through): both judged on the same static ground-truth grid,
//! medians over the seeds of the ground-truth mean as `metrics.csv` writes it.

use std::fmt::Write;

use super::aggregate::spread;
use super::metrics::mm;
use crate::calib::registry::MethodKind;
use crate::campaign::LayoutKind;
use crate::error::{Error, Result};
use crate::study::StudyResult;
use crate::study::trajectory::{TrajectoryRun, label};

const COLUMNS: [&str; 13] = [
    "region",
    "method",
    "speed",
    "n_targets",
    "seed",
    "samples",
    "tracker_s",
    "clock_error_us",
    "dynamic_max_mm",
    "status",
    "truth_mean_mm",
    "truth_p95_mm",
    "truth_max_mm",
];

/// `trajectory.csv`; `None` without trajectory runs.
pub fn trajectory_csv(study: &StudyResult) -> Result<Option<Vec<u8>>> {
    if study.trajectory.is_empty() {
        return Ok(None);
    }
    let err = |e: csv::Error| Error::Invalid(format!("trajectory.csv: {e}"));
    let mut w = csv::Writer::from_writer(Vec::new());
    w.write_record(COLUMNS).map_err(err)?;
    for r in &study.trajectory {
        let stat = |f: fn(&crate::eval::Stats) -> f64| {
            r.truth
                .as_ref()
                .map_or(String::new(), |s| format!("{:.6}", f(s) * 1e3))
        };
        w.write_record([
            r.region.clone(),
            r.label(),
            r.speed.to_string(),
            r.n_targets.to_string(),
            r.seed.to_string(),
            r.samples.to_string(),
            format!("{:.3}", r.tracker_s),
            if r.clock_error_s.is_finite() {
                format!("{:.3}", r.clock_error_s * 1e6)
            } else {
                String::new()
            },
            format!("{:.6}", r.dynamic_max_m * 1e3),
            r.failure
                .as_ref()
                .map_or("ok".to_string(), |f| format!("failed: {f}")),
            stat(|s| s.mean),
            stat(|s| s.p95),
            stat(|s| s.max),
        ])
        .map_err(err)?;
    }
    w.into_inner()
        .map(Some)
        .map_err(|e| Error::Invalid(format!("trajectory.csv: {e}")))
}

/// The median of `v` (the study's quantiles, [`spread`]); `None` when empty.
fn median(v: Vec<f64>) -> Option<f64> {
    spread(&v).map(|s| s.median)
}

fn cell(v: Option<f64>) -> String {
    v.map_or("—".into(), |x| format!("{x:.4}"))
}

/// One way of measuring the targets: its tracker time (s) and the ground-truth mean it gives (mm), medians over
/// the seeds; `None` where no run of it succeeded.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Measuring {
    pub tracker_s: Option<f64>,
    pub mean_mm: Option<f64>,
}

/// One method through one set of targets, measured stop and go and on the fly at each speed.
#[derive(Clone, Debug, PartialEq)]
pub struct Comparison {
    pub region: String,
    pub method: MethodKind,
    /// Fitted with the motion as inputs on the fly (stop and go: the method itself, no motion there).
    pub motion_inputs: bool,
    pub n_targets: usize,
    pub stop: Measuring,
    /// In the order of `[study.trajectory] speeds`, with the speed.
    pub speeds: Vec<(f64, Measuring)>,
}

/// The tracker-time comparison, in the order (region, method, targets): what the summary's table, the plot and
/// the recording show.
pub fn comparison(study: &StudyResult) -> Vec<Comparison> {
    let t = &study.trajectory;
    let Some(cfg) = study.config.trajectory.as_ref() else {
        return Vec::new();
    };
    let per_point = study.config.move_s + study.config.settle_s + study.config.measure_s;
    let mut regions: Vec<&str> = t.iter().map(|r| r.region.as_str()).collect();
    regions.dedup();
    let mut methods: Vec<(MethodKind, bool)> = Vec::new();
    for r in t {
        if !methods.contains(&(r.method, r.motion_inputs)) {
            methods.push((r.method, r.motion_inputs));
        }
    }
    let mut out = Vec::new();
    for region in regions {
        for &(method, motion_inputs) in &methods {
            for &n in &cfg.sizes {
                let stop: Vec<f64> = study
                    .runs
                    .iter()
                    .filter(|r| {
                        r.key.region == region
                            && r.key.method == method
                            && r.key.n_train == n
                            && r.key.layout == LayoutKind::Uniform
                            && r.key.seed < cfg.seeds
                    })
                    .filter_map(|r| r.truth.as_ref().map(|s| mm(s.mean)))
                    .collect();
                let speeds = cfg
                    .speeds
                    .iter()
                    .map(|&speed| {
                        let these: Vec<&TrajectoryRun> = t
                            .iter()
                            .filter(|r| {
                                r.region == region
                                    && r.method == method
                                    && r.motion_inputs == motion_inputs
                                    && r.n_targets == n
                                    && r.speed == speed
                            })
                            .collect();
                        let measuring = Measuring {
                            tracker_s: median(these.iter().map(|r| r.tracker_s).collect()),
                            mean_mm: median(
                                these
                                    .iter()
                                    .filter_map(|r| r.truth.as_ref().map(|s| mm(s.mean)))
                                    .collect(),
                            ),
                        };
                        (speed, measuring)
                    })
                    .collect();
                out.push(Comparison {
                    region: region.to_string(),
                    method,
                    motion_inputs,
                    n_targets: n,
                    stop: Measuring {
                        tracker_s: Some(study.config.campaign_points(n) as f64 * per_point),
                        mean_mm: median(stop),
                    },
                    speeds,
                });
            }
        }
    }
    out
}

impl Comparison {
    /// The method as the table, the plot and the recording name it (`… + motion` with the motion as inputs).
    pub fn label(&self) -> String {
        label(self.method, self.motion_inputs)
    }
}

/// The position of `method` in the study's methods: its colour in the plots and the recording, with the motion
/// as inputs or without.
pub fn method_index(study: &StudyResult, method: MethodKind) -> usize {
    study
        .config
        .methods
        .iter()
        .position(|&m| m == method)
        .unwrap_or(0)
}

/// The summary's section; empty without trajectory runs.
pub fn trajectory_md(study: &StudyResult, out: &mut String) {
    let t = &study.trajectory;
    let Some(cfg) = study.config.trajectory.as_ref() else {
        return;
    };
    if t.is_empty() {
        return;
    }
    let per_point = study.config.move_s + study.config.settle_s + study.config.measure_s;
    let _ = writeln!(
        out,
        "## Measuring on the fly: tracker time against accuracy\n"
    );
    let _ = writeln!(
        out,
        "Each trajectory passes through the targets of the uniform stop-and-go campaign of the same size and \
         seed (its training and validation points), at a fraction `speed` of the joints' velocity and \
         acceleration limits ({:.1} rad/s²), sampled at {:.0} Hz (every {}th sample kept); a {:.1} ms clock \
         offset between tracker and controller is estimated and removed first. Stop and go costs {per_point:.0} s \
         per point. Ground-truth mean (mm), median over {} seeds, on the same static grid; `trajectory.csv` has \
         every run. The truth moves with its joints' dynamics: the motion's inertial loads deflect the compliant \
         joints, which lag and ring about that deflection (`truth.damping_ratio`).\n",
        cfg.acceleration_rad_s2,
        cfg.sample_rate_hz,
        cfg.keep_every,
        cfg.clock_offset_s * 1e3,
        cfg.seeds
    );
    let mut regions: Vec<&str> = t.iter().map(|r| r.region.as_str()).collect();
    regions.dedup();
    if cfg.motion_inputs {
        let _ = writeln!(
            out,
            "A `+ motion` row is the method fitted on the same samples with the motion as extra inputs (per joint, \
             the torque the commanded motion needs beyond gravity on the nominal model, Nm, which the controller \
             can compute) and judged at rest (those inputs zero); its stop-and-go column is the method's own.\n"
        );
    }
    let rows = comparison(study);
    for region in regions {
        if study.regions.len() > 1 {
            let _ = writeln!(out, "Region `{region}`:\n");
        }
        out.push_str(&comparison_table(&rows, region, &cfg.speeds));
        out.push('\n');
        out.push_str(&runs_in_words(t, region));
    }
}

/// The table of one region: a row per method and targets, stop and go then each speed (tracker minutes / mm).
fn comparison_table(rows: &[Comparison], region: &str, speeds: &[f64]) -> String {
    let mut out = String::new();
    let mut head = String::from("| method | targets | stop and go: min / mm |");
    let mut rule = String::from("|---|---:|---:|");
    for s in speeds {
        let _ = write!(head, " speed {s}: min / mm |");
        rule += "---:|";
    }
    let _ = writeln!(out, "{head}\n{rule}");
    for row in rows.iter().filter(|r| r.region == region) {
        let _ = write!(
            out,
            "| `{}` | {} | {:.1} / {} |",
            row.label(),
            row.n_targets,
            row.stop.tracker_s.unwrap_or(f64::NAN) / 60.0,
            cell(row.stop.mean_mm)
        );
        for (_, p) in &row.speeds {
            let _ = write!(
                out,
                " {} / {} |",
                p.tracker_s
                    .map_or("—".into(), |x| format!("{:.1}", x / 60.0)),
                cell(p.mean_mm)
            );
        }
        out.push('\n');
    }
    out
}

/// How a region's trajectory runs went: the largest clock error left, the largest motion displacement, the
/// failures.
fn runs_in_words(t: &[TrajectoryRun], region: &str) -> String {
    let clock: Vec<f64> = t
        .iter()
        .filter(|r| r.region == region && r.clock_error_s.is_finite())
        .map(|r| r.clock_error_s.abs() * 1e6)
        .collect();
    let dynamic = t
        .iter()
        .filter(|r| r.region == region)
        .map(|r| r.dynamic_max_m * 1e3)
        .fold(0.0f64, f64::max);
    let failed = t
        .iter()
        .filter(|r| r.region == region && r.failure.is_some())
        .count();
    format!(
        "Clock offset recovered to {} µs (largest error over the runs); the motion displaced the flange by up \
         to {dynamic:.3} mm from where it would stand still; {failed} trajectory runs failed.\n\n",
        clock
            .iter()
            .copied()
            .fold(None, |a: Option<f64>, b| Some(a.map_or(b, |a| a.max(b))))
            .map_or("—".into(), |x| format!("{x:.1}"))
    )
}
