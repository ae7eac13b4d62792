//! The `calibrate apply` job: a saved model's predicted poses and corrected joint commands for new joint
//! configurations.

use std::path::{Path, PathBuf};

use nalgebra::{Point3, UnitQuaternion};

use crate::calib::registry::SavedModel;
use crate::dataset::mapping::ColumnMapping;
use crate::dataset::range::JointRange;
use crate::dataset::{self, MOTION_INPUT_PREFIX};
use crate::error::{Error, Result};
use crate::output;

use super::test_points;

/// What to apply a saved model to (the flags of `calibrate apply`).
#[derive(Clone, Debug)]
pub struct ApplyOptions {
    /// A `model.json` written by [`super::calibrate::fit`].
    pub model: PathBuf,
    /// Joint configurations: one column per joint of the model.
    pub data: PathBuf,
    /// A column mapping for reading `data`.
    pub mapping: Option<PathBuf>,
    /// Output directory: [`APPLIED`] inside it.
    pub out: PathBuf,
}

/// The file `calibrate apply` writes into its output directory.
pub const APPLIED: &str = "applied.csv";

/// What [`apply`] did.
#[derive(Clone, Debug)]
pub struct ApplyOutcome {
    pub configurations: usize,
    /// Configurations outside the model's training domain (the `domain` column).
    pub outside_domain: usize,
    /// What the user must know, one sentence each (printed as `warning:`).
    pub warnings: Vec<String>,
    /// Configurations without a corrected command: the inverse is undefined there.
    pub without_command: usize,
    /// The file written.
    pub out: PathBuf,
}

impl ApplyOutcome {
    /// The line `calibrate apply` prints (the warnings go to stderr apart).
    pub fn text(&self) -> String {
        let singular = match self.without_command {
            0 => String::new(),
            k => format!(" ({k} without a command: singular or extrapolated, see `status`)"),
        };
        let (n, out) = (self.configurations, self.out.display());
        format!("{n} configurations: predicted poses and corrected commands in {out}{singular}\n")
    }
}

/// Writes the saved model's predicted pose and corrected joint command for every configuration of
/// `options.data` to [`APPLIED`] in the directory `options.out` (all or nothing, as every command writes).
pub fn apply(options: &ApplyOptions) -> Result<ApplyOutcome> {
    output::check_dir(&options.out, &[APPLIED])?;
    let model = SavedModel::read(&options.model)?;
    let joint_names = model.joint_names().to_vec();
    let prismatic: Vec<bool> = model.dh().rows.iter().map(|r| r.prismatic).collect();
    let (ids, configurations) = match &options.mapping {
        Some(path) => {
            ColumnMapping::load(path)?.read_joints(&options.data, &joint_names, &prismatic)?
        }
        None => dataset::read_joints(&options.data, &joint_names)?,
    };
    let inputs = extra_inputs(
        &options.data,
        options.mapping.as_deref(),
        model.input_names(),
        ids.len(),
    )?;
    JointRange::plausible(&joint_names, &prismatic).check(
        &options.data.display().to_string(),
        &ids,
        &configurations,
    )?;
    let out = &options.out.join(APPLIED);
    let mut w = csv::Writer::from_writer(Vec::new());
    let csv_err = |e: csv::Error| Error::Invalid(format!("{}: {e}", out.display()));
    w.write_record(header(&joint_names)).map_err(csv_err)?;
    // A configuration where the inverse is undefined (a singular pose, such as a straight arm) still gets its
    // prediction; its command cells stay empty and `status` says why, so one such row does not cost the file.
    let placements = model.basis().domain.place_all(
        model.joint_names(),
        configurations
            .iter()
            .zip(&inputs)
            .map(|(q, x)| (q.as_slice(), x.as_slice())),
    );
    let (mut singular, mut outside) = (0, 0);
    for (((id, q), x), placement) in ids
        .iter()
        .zip(&configurations)
        .zip(&inputs)
        .zip(&placements)
    {
        let p = model.predict_with(q, x);
        let r: UnitQuaternion<f64> = p.orientation;
        let pos: Point3<f64> = p.position;
        let mut row = vec![id.clone()];
        row.extend(q.iter().map(|v| v.to_string()));
        row.extend([pos.x, pos.y, pos.z, r.w, r.i, r.j, r.k].map(|v| v.to_string()));
        match model.compensate(q, x) {
            Ok((command, residual)) => {
                row.extend(command.iter().map(|v| v.to_string()));
                row.push(residual.to_string());
                row.push("ok".into());
            }
            Err(e) => {
                singular += 1;
                row.extend(std::iter::repeat_n(String::new(), joint_names.len() + 1));
                row.push(format!("no command: {}", e.detail()));
            }
        }
        outside += usize::from(!placement.inside);
        row.push(placement.distance_rad.to_string());
        row.push(test_points::domain_cell(placement));
        w.write_record(&row).map_err(csv_err)?;
    }
    let bytes = w
        .into_inner()
        .map_err(|e| Error::Invalid(format!("{}: {e}", out.display())))?;
    output::write_files(&options.out, &[(APPLIED, bytes)])?;
    Ok(ApplyOutcome {
        configurations: ids.len(),
        without_command: singular,
        outside_domain: outside,
        // Only a regression extrapolates: a model without one has nothing to fade out there.
        warnings: (outside > 0 && model.has_regression())
            .then(|| {
                format!(
                    "{outside} of {} configurations lie outside the model's training domain (column `domain`); \
                     a regression is not extrapolated there, the model falls back to its parametric part",
                    ids.len()
                )
            })
            .into_iter()
            .collect(),
        out: out.clone(),
    })
}

/// Per configuration of `data`, the extra inputs the model regressed on, in `names` order: each from the
/// file's column of that name (or the column `mapping`'s `[inputs]` gives it), which must exist; a motion
/// input ([`MOTION_INPUT_PREFIX`]) is zero, the arm at rest, as corrected commands are used. Without
/// inputs, an empty list for each of the file's `rows` configurations.
fn extra_inputs(
    data: &Path,
    mapping: Option<&Path>,
    names: &[String],
    rows: usize,
) -> Result<Vec<Vec<f64>>> {
    let read: Vec<String> = names
        .iter()
        .filter(|n| !n.starts_with(MOTION_INPUT_PREFIX))
        .cloned()
        .collect();
    if names.is_empty() {
        return Ok(vec![Vec::new(); rows]);
    }
    let values = match mapping {
        Some(path) => ColumnMapping::load(path)?.read_inputs(data, &read)?,
        None => dataset::read_inputs(data, &read)?,
    };
    Ok(values
        .into_iter()
        .map(|row| {
            let mut row = row.into_iter();
            names
                .iter()
                .map(|n| {
                    if n.starts_with(MOTION_INPUT_PREFIX) {
                        0.0
                    } else {
                        row.next().unwrap_or(f64::NAN)
                    }
                })
                .collect()
        })
        .collect())
}

/// The columns of [`APPLIED`].
fn header(joint_names: &[String]) -> Vec<String> {
    let mut header: Vec<String> = vec!["point_id".into()];
    header.extend(joint_names.iter().cloned());
    header.extend(
        [
            "predicted_x",
            "predicted_y",
            "predicted_z",
            "predicted_qw",
            "predicted_qx",
            "predicted_qy",
            "predicted_qz",
        ]
        .map(String::from),
    );
    header.extend(joint_names.iter().map(|n| format!("cmd_{n}")));
    header.push("compensation_residual_m".into());
    header.push("status".into());
    header.push("domain_distance_rad".into());
    header.push("domain".into());
    header
}
