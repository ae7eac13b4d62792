//! `real_data --simulate SCENARIO`: the real-data protocol ([`super::real_data::tables`]) run twice, on the real
//! UR10 series B, C, D and on their replays in the scenario's world ([`super::replay`]), and the two tables
//! side by side, per protocol and method (held-out mean and max, mm).
//!
//! Each series is replayed in the same world (one true robot), with its own tracker placement and probe
//! position from registering that series, and its own noise streams. The replayed series enter the protocol as
//! [`Dataset`]s of the same form as the real ones: the same rows, ids, joint angles, a simulated probe
//! orientation, and the temperature simulated when the truth has a warm-up profile, else the real one passed through.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use serde::Serialize;

use super::real_data::{self, RealDataOptions, SERIES, Tables, name, read_series};
use super::replay;
use crate::calib::method::FitContext;
use crate::calib::registry::MethodKind;
use crate::dataset::Dataset;
use crate::dataset::mapping::ColumnMapping;
use crate::error::{Error, Result};
use crate::eval::protocol::METHODS;
use crate::output;
use crate::robot::dh::DhChain;
use crate::scenario::Scenario;

/// Where a series' replay put the tracker and the probe.
#[derive(Clone, Debug, Serialize)]
pub struct TrackerPlacement {
    pub series: String,
    pub registration_rms_mm: f64,
    pub tracker_position_m: [f64; 3],
    pub tracker_yaw_deg: f64,
    pub tracker_tilt_deg: [f64; 2],
    pub probe_mm: [f64; 3],
}

/// One method under one protocol, real beside simulated.
#[derive(Clone, Debug, Serialize)]
pub struct Line {
    /// `C → D`, `within C`, `curve C, 25 points`, …
    pub protocol: String,
    pub method: String,
    pub real_mean_mm: Option<f64>,
    pub sim_mean_mm: Option<f64>,
    /// Not for the learning curve (its cells are means over draws).
    pub real_max_mm: Option<f64>,
    pub sim_max_mm: Option<f64>,
}

/// The replays of `real` (B, C, D) in `scenario`'s world, as data sets of the real ones' form.
pub fn simulate_series(
    scenario: &Scenario,
    real: &[Dataset],
) -> Result<(Vec<Dataset>, Vec<TrackerPlacement>)> {
    let mut sims = Vec::new();
    let mut placements = Vec::new();
    for (k, (data, (series, _))) in real.iter().zip(SERIES).enumerate() {
        let mut scenario = scenario.clone();
        let r = replay::replay(&mut scenario, data, k as u64)?;
        sims.push(replay::as_dataset(&r, data)?);
        let t = &scenario.world.tracker;
        placements.push(TrackerPlacement {
            series: series.to_string(),
            registration_rms_mm: r.registration.frame.rms * 1e3,
            tracker_position_m: t.position_m,
            tracker_yaw_deg: t.yaw_deg,
            tracker_tilt_deg: t.tilt_deg,
            probe_mm: (r.registration.frame.mounting.coords * 1e3).into(),
        });
    }
    Ok((sims, placements))
}

/// Real and simulated tables, line by line.
pub fn compare(methods: &[MethodKind], real: &Tables, sim: &Tables, sizes: &[usize]) -> Vec<Line> {
    let mut lines = Vec::new();
    let pairs = real
        .across
        .iter()
        .zip(&sim.across)
        .chain([(&real.within_c, &sim.within_c)]);
    for (train, (r, s)) in ["C", "B", "C"].into_iter().zip(pairs) {
        for (k, score) in r.rows[0].scores.iter().enumerate() {
            let protocol = match score.test.strip_suffix(" held out") {
                Some(series) => format!("within {series}"),
                None => format!("{train} → {}", score.test),
            };
            for (rr, sr) in r.rows.iter().zip(&s.rows) {
                let (a, b) = (&rr.scores[k].position_mm, &sr.scores[k].position_mm);
                lines.push(Line {
                    protocol: protocol.clone(),
                    method: name(rr).replace('`', ""),
                    real_mean_mm: Some(a.mean),
                    sim_mean_mm: Some(b.mean),
                    real_max_mm: Some(a.max),
                    sim_max_mm: Some(b.max),
                });
            }
        }
    }
    let cell = |t: &Tables, m: &MethodKind, n: usize| {
        let v: Vec<f64> = t
            .curve
            .iter()
            .filter(|p| p.method == *m && p.size == n)
            .filter_map(|p| p.mean_mm)
            .collect();
        (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
    };
    for &n in sizes {
        for m in methods {
            lines.push(Line {
                protocol: format!("curve C, {n} points"),
                method: m.name().to_string(),
                real_mean_mm: cell(real, m, n),
                sim_mean_mm: cell(sim, m, n),
                real_max_mm: None,
                sim_max_mm: None,
            });
        }
    }
    lines
}

fn mm(v: Option<f64>) -> String {
    v.map_or("—".into(), |v| format!("{v:.4}"))
}

/// The lines as one Markdown table per protocol, and the learning curve as one table of real / simulated
/// means per size.
pub fn lines_md(lines: &[Line]) -> String {
    let mut out = String::new();
    let mut last = "";
    for l in lines.iter().filter(|l| !l.protocol.starts_with("curve")) {
        if l.protocol != last {
            last = &l.protocol;
            let _ = write!(
                out,
                "\n#### {last}: real vs simulated (mm)\n\n| method | real mean | sim mean | sim / real | \
                 real max | sim max |\n|---|---|---|---|---|---|\n"
            );
        }
        let ratio = match (l.real_mean_mm, l.sim_mean_mm) {
            (Some(r), Some(s)) if r > 0.0 => format!("{:.2}", s / r),
            _ => "—".into(),
        };
        let _ = writeln!(
            out,
            "| `{}` | {} | {} | {ratio} | {} | {} |",
            l.method,
            mm(l.real_mean_mm),
            mm(l.sim_mean_mm),
            mm(l.real_max_mm),
            mm(l.sim_max_mm)
        );
    }
    let curve: Vec<&Line> = lines
        .iter()
        .filter(|l| l.protocol.starts_with("curve"))
        .collect();
    let mut sizes: Vec<&str> = curve.iter().map(|l| l.protocol.as_str()).collect();
    sizes.dedup();
    if sizes.is_empty() {
        return out;
    }
    out += "\n#### Learning curve within C: held-out mean (mm), real / simulated, mean over draws\n\n| method |";
    for p in &sizes {
        let n = p
            .trim_start_matches("curve C, ")
            .trim_end_matches(" points");
        let _ = write!(out, " {n} |");
    }
    let _ = writeln!(out, "\n|---|{}", "---|".repeat(sizes.len()));
    let mut methods: Vec<&str> = Vec::new();
    for l in &curve {
        if !methods.contains(&l.method.as_str()) {
            methods.push(&l.method);
        }
    }
    for m in methods {
        let _ = write!(out, "| `{m}` |");
        for p in &sizes {
            let l = curve.iter().find(|l| l.method == m && l.protocol == *p);
            let cell = l.map_or("—".into(), |l| {
                format!("{} / {}", mm(l.real_mean_mm), mm(l.sim_mean_mm))
            });
            let _ = write!(out, " {cell} |");
        }
        out += "\n";
    }
    out
}

fn csv(lines: &[Line]) -> Result<Vec<u8>> {
    let err = |e: csv::Error| Error::Invalid(format!("sim_vs_real.csv: {e}"));
    let mut w = csv::Writer::from_writer(Vec::new());
    for l in lines {
        w.serialize(l).map_err(err)?;
    }
    w.into_inner()
        .map_err(|e| Error::Invalid(format!("sim_vs_real.csv: {e}")))
}

/// Reads the real series as `real_data` does, replays them in `scenario`, runs the protocol on both, shows
/// the placements and the side-by-side tables, and writes `sim_vs_real.json` and `sim_vs_real.csv` into
/// `options.out`. Returns the JSON file's path.
pub fn run(
    options: &RealDataOptions,
    scenario: &Path,
    show: &mut dyn FnMut(&str),
) -> Result<PathBuf> {
    let scenario = Scenario::load(scenario)?;
    let chain = crate::robot::load(&options.robot, None)?;
    let simulated = scenario.load_robot()?;
    if simulated.joint_names() != chain.joint_names() {
        return Err(Error::Scenario {
            origin: scenario.origin.clone(),
            message: format!(
                "its robot's joints ({}) are not those of {} ({})",
                simulated.joint_names().join(", "),
                options.robot.display(),
                chain.joint_names().join(", ")
            ),
        });
    }
    let dh = DhChain::from_chain(&chain)?;
    let ctx = FitContext::new(&chain, &dh);
    let real = read_series(
        &options.data_dir,
        &ColumnMapping::load(&options.mapping)?,
        &chain,
    )?;
    let (sim, placements) = simulate_series(&scenario, &real)?;
    show(&placements_md(&placements, &scenario.world.name));
    let sizes = options.sizes.as_deref();
    let quiet = &mut |_: &str| {};
    let real_tables = real_data::tables(&METHODS, &ctx, &real, sizes, options.draws, quiet)?;
    let sim_tables = real_data::tables(&METHODS, &ctx, &sim, sizes, options.draws, quiet)?;
    let lines = compare(&METHODS, &real_tables, &sim_tables, sizes.unwrap_or(&[]));
    show(&lines_md(&lines));
    let json = serde_json::to_vec_pretty(&serde_json::json!({
        "scenario": scenario,
        "placements": placements,
        "temperature": "simulated by the truth's warm-up profile when it has one, else the real series' column passed through",
        "lines": lines,
    }))
    .map_err(|e| Error::Invalid(format!("cannot serialize: {e}")))?;
    output::write_files(
        &options.out,
        &[
            ("sim_vs_real.json", json),
            ("sim_vs_real.csv", csv(&lines)?),
        ],
    )?;
    Ok(options.out.join("sim_vs_real.json"))
}

fn placements_md(placements: &[TrackerPlacement], scenario: &str) -> String {
    let mut out = format!(
        "#### The replays in '{scenario}': where the registration of each real series put the tracker and the probe\n\n\
         | series | registration RMS (mm) | tracker position (m) | yaw (°) | tilts (°) | probe on the flange (mm) |\n\
         |---|---|---|---|---|---|\n"
    );
    for p in placements {
        let [x, y, z] = p.tracker_position_m;
        let [a, b, c] = p.probe_mm;
        let _ = writeln!(
            out,
            "| {} | {:.4} | {x:.4}, {y:.4}, {z:.4} | {:.3} | {:.3}, {:.3} | {a:.3}, {b:.3}, {c:.3} |",
            p.series,
            p.registration_rms_mm,
            p.tracker_yaw_deg,
            p.tracker_tilt_deg[0],
            p.tracker_tilt_deg[1]
        );
    }
    out
}
