//! `twin.json` (every identified value and magnitude, its standard deviation and what it was fitted to) and
//! `twin.md` (the pilot's statistics, real beside twin), and the lines `campaign twin` prints.

use std::fmt::Write as _;

use serde_json::json;

use super::{Identified, TwinOptions, TwinOutcome};
use crate::calib::method::Fitted;
use crate::error::{Error, Result};

/// The three files of a twin.
pub fn files(
    outcome: &TwinOutcome,
    identified: &Identified,
    options: &TwinOptions,
) -> Result<Vec<(String, Vec<u8>)>> {
    Ok(vec![
        ("twin.toml".into(), outcome.values.text().into_bytes()),
        ("twin.json".into(), json_file(outcome, identified, options)?),
        ("twin.md".into(), markdown(outcome, options).into_bytes()),
    ])
}

fn json_file(
    outcome: &TwinOutcome,
    identified: &Identified,
    options: &TwinOptions,
) -> Result<Vec<u8>> {
    let model = &identified.model;
    let parameters: Vec<_> = model
        .kept
        .iter()
        .zip(&model.values)
        .enumerate()
        .map(|(k, (p, v))| {
            json!({
                "name": p.name(), "value": v, "std": model.std.get(k),
                "fitted": identified.raw.get(k).map(|r| r.0), "fitted_std": identified.raw.get(k).map(|r| r.1),
            })
        })
        .collect();
    let compliance: Vec<_> = identified
        .compliance
        .iter()
        .zip(&outcome.values.stiffness)
        .enumerate()
        .map(|(j, (c, k))| match c {
            Some((c, s)) => json!({
                "joint": j + 1, "compliance_rad_per_nm": c, "std": s, "stiffness_nm_per_rad": k,
                "stiffness_std": s / (c * c),
                "source": "identified (elastic fit on the pilot); its error on the twin's replays in compliance_check",
            }),
            None => json!({
                "joint": j + 1, "stiffness_nm_per_rad": k,
                "source": identified.unkept_stiffness[j].1,
            }),
        })
        .collect();
    let s = &outcome.statistics;
    let statistics: Vec<_> = s
        .real
        .iter()
        .zip(&s.twin)
        .map(|(r, (_, twin))| {
            json!({ "method": r.method, "real_mm": r.mean_mm, "real_failure": r.failure, "twin_mm": twin })
        })
        .collect();
    let registration = model.registration();
    let value = json!({
        "pilot": {
            "file": options.data.display().to_string(),
            "mapping": options.mapping.as_ref().map(|m| m.display().to_string()),
            "points": outcome.points,
            "joint_ranges_rad": identified.ranges,
        },
        "identified": {
            "method": model.info(),
            "parameters": parameters,
            "undetermined": model.undetermined,
            "dropped": model.dropped.iter().map(|p| p.name()).collect::<Vec<_>>(),
            "compliance": compliance,
            "tracker_to_base": registration.frame.tracker_to_base,
            "mounting_m": registration.frame.mounting,
            "geometry": identified.geometry,
            "geometry_match_m": identified.geometry_match_m,
        },
        "torque_coverage": {
            "joints": outcome.coverage,
            "narrow_below": super::coverage::NARROW_FRACTION,
            "warning": outcome.warning(),
        },
        "compliance_check": {
            "draws": super::compliance::DRAWS,
            "joints": outcome.compliance,
        },
        "magnitudes": outcome.values.magnitudes,
        "answer": outcome.answer,
        "statistics": {
            "held_out_mm": statistics,
            "repeats_real_m": s.real_repeats.map(|r| r.mean_distance_m),
            "repeats_twin_m": s.twin_repeats,
            "draws": super::magnitudes::SEEDS,
            "folds": super::pilot::FOLDS,
        },
    });
    serde_json::to_vec_pretty(&value).map_err(|e| Error::Invalid(format!("twin.json: {e}")))
}

fn mm(v: Option<f64>) -> String {
    v.map_or("—".into(), |v| format!("{v:.4}"))
}

/// The twin's held-out mean over its draws, with their range.
fn twin_cell(draws: &[f64]) -> String {
    if draws.is_empty() {
        return "failed".into();
    }
    let mean = draws.iter().sum::<f64>() / draws.len() as f64;
    let lo = draws.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = draws.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    format!("{mean:.4} [{lo:.4}–{hi:.4}]")
}

fn markdown(outcome: &TwinOutcome, options: &TwinOptions) -> String {
    let s = &outcome.statistics;
    let mut out = format!(
        "# Twin of the arm that measured `{}`\n\n\
         Each method cross-validated within the pilot ({} folds: fitted on three quarters, two thirds of them \
         training and one third validation, tested on the quarter held out through its own registration), on the \
         real pilot and on the pilot's configurations replayed through the twin ({} draws: mean [min–max]); \
         mean distance, mm.\n\n| method | real | twin | twin / real |\n|---|---|---|---|\n",
        options.data.display(),
        super::pilot::FOLDS,
        super::magnitudes::SEEDS
    );
    for (r, (_, twin)) in s.real.iter().zip(&s.twin) {
        let ratio = match (r.mean_mm, twin.is_empty()) {
            (Some(real), false) => {
                format!("{:.2}", twin.iter().sum::<f64>() / twin.len() as f64 / real)
            }
            _ => "—".into(),
        };
        let _ = writeln!(
            out,
            "| `{}` | {} | {} | {ratio} |",
            r.method,
            mm(r.mean_mm),
            twin_cell(twin)
        );
    }
    if let Some(r) = s.real_repeats {
        let _ = writeln!(
            out,
            "\nRepeated configurations: {} groups, {} measurements, mean distance from the group's mean {:.4} mm \
             real, {} twin.",
            r.groups,
            r.measurements,
            r.mean_distance_m * 1e3,
            twin_cell(&s.twin_repeats.iter().map(|d| d * 1e3).collect::<Vec<_>>())
        );
    }
    coverage_md(outcome, &mut out);
    answer_md(outcome, &mut out);
    out += "\n## Magnitudes\n\n| key | value | std | source |\n|---|---|---|---|\n";
    for m in &outcome.values.magnitudes {
        let _ = writeln!(
            out,
            "| `{}` | {:.3e} {} | {} | {} |",
            m.key,
            m.value,
            m.unit,
            m.std.map_or("—".into(), |s| format!("{s:.2e}")),
            m.source
        );
    }
    out
}

/// The gravity torques the pilot covers, and the compliances as the twin takes them.
fn coverage_md(outcome: &TwinOutcome, out: &mut String) {
    out.push_str(
        "\n## Gravity torque the pilot covers\n\nPer joint, the gravity torque (Nm) over the pilot and over \
         configurations drawn within the joint limits; a compliance is told from the change of the deflection \
         with the torque, so outside the pilot's band it is extrapolated.\n\n\
         | joint | pilot | joint's range | covered |\n|---|---|---|---|\n",
    );
    for s in &outcome.coverage {
        let covered = s.covered.map_or("not loaded".into(), |c| {
            format!(
                "{:.0} %{}",
                100.0 * c,
                if s.narrow() { " (narrow)" } else { "" }
            )
        });
        let _ = writeln!(
            out,
            "| {} | {:.1} … {:.1} | {:.1} … {:.1} | {covered} |",
            s.joint, s.pilot[0], s.pilot[1], s.reachable[0], s.reachable[1]
        );
    }
    if let Some(w) = outcome.warning() {
        let _ = writeln!(out, "\n**Warning:** {w}.");
    }
    let _ = writeln!(
        out,
        "\nCompliances (rad/Nm): the elastic fit's on the pilot with its standard deviation, and how far the same \
         fit lands from the twin's own compliance on the pilot replayed through the twin ({} draws, RMS): where \
         that error exceeds the standard deviation, what no method models leans on the compliance within the \
         pilot's band.\n\n| joint | fitted ± std | twin | error on the twin's replays |\n|---|---|---|---|",
        super::compliance::DRAWS
    );
    for c in &outcome.compliance {
        let _ = writeln!(
            out,
            "| {} | {:.2e} ± {:.1e} | {:.2e} | {:.1e} |",
            c.joint, c.fitted, c.fitted_std, c.twin, c.error_rms
        );
    }
}

/// The twin's answer over its draws.
fn answer_md(outcome: &TwinOutcome, out: &mut String) {
    let Some(first) = outcome.answer.first() else {
        return;
    };
    let _ = writeln!(
        out,
        "\n## The answer for this arm\n\nThe twin's study (`campaign twin.toml`: the pilot's workspace) run for {} \
         draws of the twin — new phases of the gears' waves, new noise, each fitted magnitude drawn from its \
         standard deviation: per target on the ground-truth mean, the method and layout recommended in most draws \
         and the training points it needs, median [min–max] over the draws.\n\n\
         | target (mm) | method, layout | chosen in | points |\n|---|---|---|---|",
        first.points.len()
    );
    for r in &outcome.answer {
        let pick = match (r.method, r.layout) {
            (Some(m), Some(l)) => format!("`{m}`, {}", l.name()),
            _ => "none reaches it".into(),
        };
        let _ = writeln!(
            out,
            "| {} | {pick} | {} of {} | {} |",
            r.target_mm,
            r.chosen_in,
            r.points.len(),
            r.points_text()
        );
    }
}

/// What `campaign twin` prints: where the files went and the pilot's statistics, real beside twin.
pub fn console(outcome: &TwinOutcome) -> String {
    let mut out = format!(
        "twin: {} parameters identified; files in {} (twin.toml, twin.json, twin.md)\n\
         held-out mean on the pilot (mm), real / twin:\n",
        outcome.identified_parameters,
        outcome.out.display()
    );
    let s = &outcome.statistics;
    for (r, (_, twin)) in s.real.iter().zip(&s.twin) {
        let _ = writeln!(
            out,
            "  {:<22} {} / {}",
            r.method,
            mm(r.mean_mm),
            twin_cell(twin)
        );
    }
    if !outcome.answer.is_empty() {
        out += "the answer for this arm (ground-truth mean; points: median [min–max] over the twin's draws):\n";
        for r in &outcome.answer {
            let pick = match (r.method, r.layout) {
                (Some(m), Some(l)) => format!("{m}, {}", l.name()),
                _ => "none reaches it".into(),
            };
            let _ = writeln!(out, "  {:<8} {pick:<28} {}", r.target_mm, r.points_text());
        }
    }
    out
}
