//! Reading a foreign tracker export through a column mapping, so a user maps the file instead of editing it.
//!
//! A mapping (a TOML file, `calibrate --mapping FILE.toml`) names the columns and says how to read them:
//!
//! ```toml
//! delimiter = ";"          # one character; "\t" for tabs. Default ","
//! decimal = ","            # "." (default) or ","
//!
//! [joints]                 # optional: default the robot's joint names, in radians
//! unit = "rad"             # rad | deg (revolute joints; prismatic joints use [position].unit)
//! columns = ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint",
//!            "wrist_1_joint", "wrist_2_joint", "wrist_3_joint"]   # in the robot's joint order
//!
//! [position]               # the measured point (reflector, probe origin), tracker frame
//! unit = "mm"              # m | cm | mm | um
//! columns = ["measurement_x", "measurement_y", "measurement_z"]
//! # difference = ["dev_x", "dev_y", "dev_z"]   # optional: measured = columns + difference_sign · difference
//! # difference_sign = -1   # 1 (default: the difference is measured − columns) or -1 (columns − measured)
//! # frame = "base"         # the coordinates are already in the robot's base frame: only the mounting is fitted
//!
//! [orientation]            # optional: a 6-DoF probe's orientation, tracker frame
//! convention = "intrinsic-xyz"   # intrinsic-ABC | extrinsic-ABC (A, B, C each x, y or z) | quaternion-wxyz | quaternion-xyzw
//! unit = "deg"             # rad | deg (Euler angles only)
//! columns = ["measurement_rx", "measurement_ry", "measurement_rz"]
//!
//! [inputs]                 # optional: regression inputs beyond the joint angles, name = column
//! temperature = "measurement_temperature"
//!
//! # point_id = "id"        # optional columns: a unique point id; a train/val/test label
//! # split = "split"
//! ```
//!
//! `intrinsic-xyz` with angles (a, b, c) is `R = Rx(a)·Ry(b)·Rz(c)` (rotate about x, then about the new y, then
//! about the newest z); `extrinsic-xyz` is `R = Rz(c)·Ry(b)·Rx(a)` (about the fixed x, y, z in turn). Every
//! value is converted to metres and radians; unknown keys are refused, and every fault in the mapping or in
//! the file is one line naming the row (as a spreadsheet numbers it: the header is row 1) and the column.

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use nalgebra::{Point3, Quaternion, UnitQuaternion};
use serde::{Deserialize, Serialize};

use super::orientation::Convention;
use super::table::{self, CsvTable, Dialect};
use super::{Dataset, ExtraInputs, Split};
use crate::error::{Error, Result};
use crate::robot::Chain;
use crate::robot::chain::JointKind;

pub use crate::robot::AngleUnit;

/// A length unit of the file.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum LengthUnit {
    #[default]
    M,
    Cm,
    Mm,
    Um,
}

impl LengthUnit {
    /// Metres per unit.
    pub fn metres(self) -> f64 {
        match self {
            LengthUnit::M => 1.0,
            LengthUnit::Cm => 1e-2,
            LengthUnit::Mm => 1e-3,
            LengthUnit::Um => 1e-6,
        }
    }
}

#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointColumns {
    /// Unit of the revolute joints' angles.
    #[serde(default)]
    pub unit: AngleUnit,
    /// One column per joint of the robot, in its order; absent: the joints' own names.
    #[serde(default)]
    pub columns: Option<Vec<String>>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PositionColumns {
    #[serde(default)]
    pub unit: LengthUnit,
    /// x, y, z of the measured point in the tracker frame (with `difference`: of the point it is measured
    /// against, such as the target).
    pub columns: Vec<String>,
    /// x, y, z of a difference column group, in `unit`: the measured point is `columns + difference_sign ·
    /// difference` (exports that give a target and the deviation from it).
    #[serde(default)]
    pub difference: Option<Vec<String>>,
    /// +1 (the difference is measured − target) or −1 (target − measured).
    #[serde(default = "plus_one")]
    pub difference_sign: i32,
    /// The frame the coordinates are in: the tracker's (a tracker frame is fitted) or the robot's base frame
    /// (an export already transformed by the tracker software; only the mounting is fitted).
    #[serde(default)]
    pub frame: PositionFrame,
}

/// The frame of the measured positions.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum PositionFrame {
    #[default]
    Tracker,
    Base,
}

fn plus_one() -> i32 {
    1
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OrientationColumns {
    /// `intrinsic-ABC`, `extrinsic-ABC` (A, B, C each `x`, `y` or `z`), `quaternion-wxyz` or `quaternion-xyzw`.
    pub convention: String,
    /// Unit of Euler angles (ignored for quaternions).
    #[serde(default)]
    pub unit: AngleUnit,
    /// Three Euler angles in the convention's order, or four quaternion components in its order.
    pub columns: Vec<String>,
}

/// How to read a foreign measurement export (module notes).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ColumnMapping {
    #[serde(default = "default_delimiter")]
    pub delimiter: String,
    #[serde(default = "default_decimal")]
    pub decimal: String,
    #[serde(default)]
    pub joints: JointColumns,
    pub position: PositionColumns,
    #[serde(default)]
    pub orientation: Option<OrientationColumns>,
    /// Extra regression inputs: name → column (taken in name order).
    #[serde(default)]
    pub inputs: BTreeMap<String, String>,
    #[serde(default)]
    pub point_id: Option<String>,
    #[serde(default)]
    pub split: Option<String>,
}

fn default_delimiter() -> String {
    ",".into()
}

fn default_decimal() -> String {
    ".".into()
}

/// The mappings of `mappings/`, built in.
const BUILT_IN: [(&str, &str); 1] = [(
    "mappings/ipa_ur10.toml",
    include_str!("../../mappings/ipa_ur10.toml"),
)];

impl ColumnMapping {
    /// Reads a mapping file.
    /// `mappings/NAME` for a mapping shipped in `mappings/` is read from the copy built into the binary when no
    /// such file exists (so `real_data`'s default works from any directory).
    pub fn load(path: &Path) -> Result<ColumnMapping> {
        let origin = path.display().to_string();
        let text = match std::fs::read_to_string(path) {
            Ok(text) => text,
            Err(_) if !path.exists() && BUILT_IN.iter().any(|(n, _)| path == Path::new(n)) => {
                let (_, text) = BUILT_IN
                    .iter()
                    .find(|(n, _)| path == Path::new(n))
                    .expect("found");
                text.to_string()
            }
            Err(e) => {
                return Err(Error::Data {
                    origin,
                    message: format!("cannot read: {e}"),
                });
            }
        };
        ColumnMapping::from_toml(&text, &origin)
    }

    /// Parses and checks mapping TOML; `origin` names it in messages.
    pub fn from_toml(text: &str, origin: &str) -> Result<ColumnMapping> {
        let err = |message: String| Error::Data {
            origin: origin.to_string(),
            message,
        };
        let mapping: ColumnMapping = toml::from_str(text).map_err(|e| {
            let line = e
                .span()
                .map(|s| {
                    format!(
                        "line {}: ",
                        text[..s.start.min(text.len())].matches('\n').count() + 1
                    )
                })
                .unwrap_or_default();
            err(format!("{line}{}", e.message().trim().replace('\n', "; ")))
        })?;
        mapping.check().map_err(err)?;
        Ok(mapping)
    }

    fn check(&self) -> std::result::Result<(), String> {
        self.delimiter_byte()?;
        self.decimal_char()?;
        if self.position.columns.len() != 3 {
            return Err(format!(
                "[position] columns: x, y, z are 3 columns, the mapping names {}",
                self.position.columns.len()
            ));
        }
        if let Some(d) = &self.position.difference
            && d.len() != 3
        {
            return Err(format!(
                "[position] difference: x, y, z are 3 columns, the mapping names {}",
                d.len()
            ));
        }
        if self.position.difference_sign.abs() != 1 {
            return Err(format!(
                "[position] difference_sign = {}: 1 (measured = columns + difference) or -1 (columns − difference)",
                self.position.difference_sign
            ));
        }
        if let Some(o) = &self.orientation {
            let convention = Convention::parse(&o.convention)?;
            if o.columns.len() != convention.columns() {
                return Err(format!(
                    "[orientation] columns: {} takes {} columns, the mapping names {}",
                    o.convention,
                    convention.columns(),
                    o.columns.len()
                ));
            }
        }
        if self.delimiter_byte()? == b'.' && self.decimal_char()? == ',' {
            return Err("delimiter '.' with decimal ','".into());
        }
        if self.delimiter_byte()? as char == self.decimal_char()? {
            return Err(format!(
                "delimiter and decimal separator are both '{}'",
                self.delimiter
            ));
        }
        Ok(())
    }

    fn delimiter_byte(&self) -> std::result::Result<u8, String> {
        let d = match self.delimiter.as_str() {
            "\\t" | "tab" => "\t",
            other => other,
        };
        match d.as_bytes() {
            [b] if b.is_ascii() && *b != b'"' && *b != b'\n' && *b != b'\r' => Ok(*b),
            _ => Err(format!(
                "delimiter '{}': one ASCII character such as \",\", \";\" or \"\\t\"",
                self.delimiter.escape_default()
            )),
        }
    }

    fn decimal_char(&self) -> std::result::Result<char, String> {
        match self.decimal.as_str() {
            "." => Ok('.'),
            "," => Ok(','),
            other => Err(format!("decimal '{other}': \".\" or \",\"")),
        }
    }

    /// Reads a file through this mapping; `chain` gives the joints (their order and kinds).
    pub fn read(&self, path: &Path, chain: &Chain) -> Result<Dataset> {
        let origin = path.display().to_string();
        let file = std::fs::File::open(path).map_err(|e| Error::Data {
            origin: origin.clone(),
            message: format!("cannot read: {e}"),
        })?;
        self.from_reader(file, &origin, chain)
    }

    /// Joint configurations only (for `calibrate apply`): the point ids (the mapped `point_id` column or the
    /// row numbers) and the angles in `joint_names` order; `prismatic` marks prismatic joints (read in the
    /// `[position]` unit). The position and orientation columns need not exist.
    pub fn read_joints(
        &self,
        path: &Path,
        joint_names: &[String],
        prismatic: &[bool],
    ) -> Result<(Vec<String>, Vec<Vec<f64>>)> {
        let origin = path.display().to_string();
        let table = self.table(path, &origin)?;
        let (cols, scale) = self.joint_columns(&table, joint_names, prismatic)?;
        let id_col = match &self.point_id {
            Some(c) => Some(table.find(c, "point_id")?),
            None => None,
        };
        let mut ids = Vec::with_capacity(table.len());
        let mut q = Vec::with_capacity(table.len());
        for r in 0..table.len() {
            ids.push(match id_col {
                Some(c) => table.cell(r, c).to_string(),
                None => (r + 2).to_string(),
            });
            q.push(
                cols.iter()
                    .zip(&scale)
                    .map(|(&c, s)| Ok(table.number(r, c)? * s))
                    .collect::<Result<Vec<f64>>>()?,
            );
        }
        Ok((ids, q))
    }

    /// The extra inputs `names` of every row (for `calibrate apply` of a model that regressed on them), each
    /// from the column the mapping's `[inputs]` gives it, in `names` order. A name the mapping does not map,
    /// or a column the file lacks, is one error naming it.
    pub fn read_inputs(&self, path: &Path, names: &[String]) -> Result<Vec<Vec<f64>>> {
        let origin = path.display().to_string();
        let table = self.table(path, &origin)?;
        let cols = names
            .iter()
            .map(|name| match self.inputs.get(name) {
                Some(c) => table.find(c, &format!("[inputs] {name}")),
                None => Err(Error::Data {
                    origin: origin.clone(),
                    message: format!(
                        "the mapping's [inputs] names no column for '{name}', which the model regressed on \
                         (its extra inputs: {})",
                        names.join(", ")
                    ),
                }),
            })
            .collect::<Result<Vec<_>>>()?;
        (0..table.len())
            .map(|r| cols.iter().map(|&c| table.number(r, c)).collect())
            .collect()
    }

    fn table(&self, path: &Path, origin: &str) -> Result<CsvTable> {
        let err = |message: String| Error::Data {
            origin: origin.to_string(),
            message,
        };
        self.check().map_err(err)?;
        let file = std::fs::File::open(path).map_err(|e| err(format!("cannot read: {e}")))?;
        CsvTable::load(
            file,
            origin,
            Dialect::mapped(
                self.delimiter_byte().map_err(err)?,
                self.decimal_char().map_err(err)?,
            ),
        )
    }

    /// The column of every joint and its scale to radians (metres for a prismatic joint).
    fn joint_columns(
        &self,
        table: &CsvTable,
        joint_names: &[String],
        prismatic: &[bool],
    ) -> Result<(Vec<usize>, Vec<f64>)> {
        let joint_columns: Vec<String> = match &self.joints.columns {
            Some(c) if c.len() != joint_names.len() => {
                return Err(table.error(format!(
                    "the mapping's [joints] columns name {} columns, the robot has {} joints ({})",
                    c.len(),
                    joint_names.len(),
                    joint_names.join(", ")
                )));
            }
            Some(c) => c.clone(),
            None => joint_names.to_vec(),
        };
        let cols = joint_columns
            .iter()
            .zip(joint_names)
            .map(|(c, j)| table.find(c, &format!("[joints] column of joint {j}")))
            .collect::<Result<Vec<_>>>()?;
        let scale = (0..joint_names.len())
            .map(|i| {
                if prismatic.get(i).copied().unwrap_or(false) {
                    self.position.unit.metres()
                } else {
                    self.joints.unit.radians()
                }
            })
            .collect();
        Ok((cols, scale))
    }

    /// Reads export text from `reader` through this mapping; `origin` names it in messages.
    pub fn from_reader(
        &self,
        reader: impl std::io::Read,
        origin: &str,
        chain: &Chain,
    ) -> Result<Dataset> {
        let err = |message: String| Error::Data {
            origin: origin.to_string(),
            message,
        };
        self.check().map_err(err)?;
        let decimal = self.decimal_char().map_err(err)?;
        let table = CsvTable::load(
            reader,
            origin,
            Dialect::mapped(self.delimiter_byte().map_err(err)?, decimal),
        )?;
        let joint_names = chain.joint_names();
        let columns = self.columns(&table, chain, &joint_names)?;
        let rows = self.rows(&table, &columns)?;
        Ok(Dataset {
            origin: origin.to_string(),
            joint_names,
            point_ids: rows.ids,
            q: rows.q,
            measured: rows.measured,
            nominal_reflectors: None,
            nominal_flange: None,
            split: rows.split,
            regions: None,
            measured_orientation: rows.rotations,
            extra_inputs: (!self.inputs.is_empty()).then(|| ExtraInputs {
                names: self.inputs.keys().cloned().collect(),
                values: rows.inputs,
            }),
            time: None,
            rates: None,
            base_frame: self.position.frame == PositionFrame::Base,
        })
    }

    /// The file's columns this mapping names, each found in `table`'s header (an error names the first one
    /// missing); the joints are `chain`'s, named `joint_names`.
    fn columns(&self, table: &CsvTable, chain: &Chain, joint_names: &[String]) -> Result<Columns> {
        let prismatic: Vec<bool> = chain
            .joints
            .iter()
            .map(|j| j.kind == JointKind::Prismatic)
            .collect();
        let (joints, joint_scale) = self.joint_columns(table, joint_names, &prismatic)?;
        let axes = ["x", "y", "z"];
        let position = self
            .position
            .columns
            .iter()
            .zip(axes)
            .map(|(c, a)| table.find(c, &format!("[position] {a}")))
            .collect::<Result<Vec<_>>>()?;
        let difference = match &self.position.difference {
            Some(d) => Some(
                d.iter()
                    .zip(axes)
                    .map(|(c, a)| table.find(c, &format!("[position] difference {a}")))
                    .collect::<Result<Vec<_>>>()?,
            ),
            None => None,
        };
        let orientation = match &self.orientation {
            Some(o) => {
                let convention = Convention::parse(&o.convention).map_err(|m| table.error(m))?;
                let cols = o
                    .columns
                    .iter()
                    .enumerate()
                    .map(|(k, c)| {
                        table.find(
                            c,
                            &format!("[orientation] component {} of {}", k + 1, o.convention),
                        )
                    })
                    .collect::<Result<Vec<_>>>()?;
                Some((convention, o.unit.radians(), cols))
            }
            None => None,
        };
        let inputs = self
            .inputs
            .iter()
            .map(|(name, c)| table.find(c, &format!("[inputs] {name}")))
            .collect::<Result<Vec<_>>>()?;
        let id = match &self.point_id {
            Some(c) => Some(table.find(c, "point_id")?),
            None => None,
        };
        let split = match &self.split {
            Some(c) => Some(table.find(c, "split")?),
            None => None,
        };
        Ok(Columns {
            joints,
            joint_scale,
            position,
            difference,
            orientation,
            inputs,
            id,
            split,
        })
    }

    /// Every row of `table` read through `columns`, in metres and radians; an error names the first faulty
    /// cell.
    fn rows(&self, table: &CsvTable, columns: &Columns) -> Result<Rows> {
        let n = table.len();
        let mut rows = Rows {
            q: Vec::with_capacity(n),
            measured: Vec::with_capacity(n),
            rotations: columns.orientation.as_ref().map(|_| Vec::with_capacity(n)),
            inputs: Vec::with_capacity(n),
            split: columns.split.map(|_| Vec::with_capacity(n)),
            ids: Vec::with_capacity(n),
        };
        let mut seen: HashMap<String, usize> = HashMap::new();
        for r in 0..n {
            rows.q.push(
                columns
                    .joints
                    .iter()
                    .zip(&columns.joint_scale)
                    .map(|(&c, s)| Ok(table.number(r, c)? * s))
                    .collect::<Result<Vec<f64>>>()?,
            );
            rows.measured
                .push(vec![self.position_at(table, columns, r)?]);
            if let (Some(out), Some(orientation)) = (&mut rows.rotations, &columns.orientation) {
                out.push(rotation_at(table, orientation, r)?);
            }
            rows.inputs.push(
                columns
                    .inputs
                    .iter()
                    .map(|&c| table.number(r, c))
                    .collect::<Result<Vec<f64>>>()?,
            );
            if let (Some(out), Some(c)) = (&mut rows.split, columns.split) {
                out.push(table.split(r, c)?);
            }
            rows.ids.push(match columns.id {
                Some(c) => point_id(table, r, c, &mut seen)?,
                None => (r + 2).to_string(),
            });
        }
        Ok(rows)
    }

    /// The measured point of row `r`: the position columns plus the signed difference, if mapped (metres).
    fn position_at(&self, table: &CsvTable, columns: &Columns, r: usize) -> Result<Point3<f64>> {
        let length = self.position.unit.metres();
        let mut p = columns
            .position
            .iter()
            .map(|&c| Ok(table.number(r, c)? * length))
            .collect::<Result<Vec<f64>>>()?;
        if let Some(cols) = &columns.difference {
            let sign = f64::from(self.position.difference_sign);
            for (p, &c) in p.iter_mut().zip(cols) {
                *p += sign * table.number(r, c)? * length;
            }
        }
        Ok(Point3::new(p[0], p[1], p[2]))
    }
}

/// The columns a mapping reads, by index in the file.
struct Columns {
    joints: Vec<usize>,
    /// Per joint, the scale to radians (metres for a prismatic joint).
    joint_scale: Vec<f64>,
    position: Vec<usize>,
    difference: Option<Vec<usize>>,
    /// The convention, the angle unit's scale to radians and the columns of a 6-DoF probe's orientation.
    orientation: Option<(Convention, f64, Vec<usize>)>,
    inputs: Vec<usize>,
    id: Option<usize>,
    split: Option<usize>,
}

/// What the rows of a mapped file hold, row by row.
struct Rows {
    q: Vec<Vec<f64>>,
    measured: Vec<Vec<Point3<f64>>>,
    rotations: Option<Vec<UnitQuaternion<f64>>>,
    inputs: Vec<Vec<f64>>,
    split: Option<Vec<Split>>,
    ids: Vec<String>,
}

/// The orientation of row `r` read through `(convention, scale, cols)`; an error for a quaternion that is not
/// of unit norm.
fn rotation_at(
    table: &CsvTable,
    (convention, scale, cols): &(Convention, f64, Vec<usize>),
    r: usize,
) -> Result<UnitQuaternion<f64>> {
    let is_quaternion = cols.len() == 4;
    let v = cols
        .iter()
        .map(|&c| Ok(table.number(r, c)? * if is_quaternion { 1.0 } else { *scale }))
        .collect::<Result<Vec<f64>>>()?;
    convention.rotation(&v).ok_or_else(|| {
        table.error(format!(
            "row {}, columns {}…{}: the quaternion's norm is {}, not 1",
            r + 2,
            table.headers[cols[0]],
            table.headers[cols[3]],
            Quaternion::new(v[0], v[1], v[2], v[3]).norm()
        ))
    })
}

/// The point id of row `r` in column `c`: not empty, and not a repeat of an earlier row's (`seen` maps the ids
/// read so far to their rows).
fn point_id(
    table: &CsvTable,
    r: usize,
    c: usize,
    seen: &mut HashMap<String, usize>,
) -> Result<String> {
    let id = table.cell(r, c);
    if id.is_empty() {
        return Err(table.error(format!("{}: empty", table.at(r, c))));
    }
    if let Some(first) = seen.insert(id.to_string(), r) {
        return Err(table.error(format!(
            "{}: '{}' repeats row {}",
            table.at(r, c),
            table::shown(id),
            first + 2
        )));
    }
    Ok(id.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A target plus a signed deviation reads as the measured point itself.
    #[test]
    fn target_plus_signed_difference_is_the_measured_point() {
        let chain = crate::robot::description::from_toml(
            "name = \"two\"\nconvention = \"dh\"\n[[joints]]\nname = \"a\"\na = 0.5\nalpha = 0.0\nd = 0.0\n\
             lower = -3.0\nupper = 3.0\n[[joints]]\nname = \"b\"\na = 0.4\nalpha = 0.0\nd = 0.0\n\
             lower = -3.0\nupper = 3.0\n",
            "two",
        )
        .unwrap();
        let plain = "a,b,mx,my,mz\n0.1,0.2,1000.5,-20.25,3.0\n-0.3,0.4,5.0,6.0,7.0\n";
        let (tx, ty, tz) = ([1000.0, 5.5], [-20.0, 6.0], [2.0, 7.25]);
        let mut with_diff = String::from("a,b,tx,ty,tz,dx,dy,dz\n");
        let measured = [[1000.5, -20.25, 3.0], [5.0, 6.0, 7.0]];
        let q = [[0.1, 0.2], [-0.3, 0.4]];
        for r in 0..2 {
            let t = [tx[r], ty[r], tz[r]];
            // target − measured, so measured = target − difference
            let d: Vec<f64> = (0..3).map(|k| t[k] - measured[r][k]).collect();
            with_diff += &format!(
                "{},{},{},{},{},{},{},{}\n",
                q[r][0], q[r][1], t[0], t[1], t[2], d[0], d[1], d[2]
            );
        }
        let read = |mapping: &str, text: &str| {
            ColumnMapping::from_toml(mapping, "m")
                .unwrap()
                .from_reader(text.as_bytes(), "f", &chain)
                .unwrap()
        };
        let a = read(
            "[position]\nunit = \"mm\"\ncolumns = [\"mx\", \"my\", \"mz\"]\n",
            plain,
        );
        let b = read(
            "[position]\nunit = \"mm\"\ncolumns = [\"tx\", \"ty\", \"tz\"]\n\
             difference = [\"dx\", \"dy\", \"dz\"]\ndifference_sign = -1\n",
            &with_diff,
        );
        for (p, r) in a.measured.iter().zip(&b.measured) {
            assert!((p[0] - r[0]).norm() < 1e-12, "{} against {}", p[0], r[0]);
        }
        assert_eq!(a.q, b.q);
        let wrong_sign = read(
            "[position]\nunit = \"mm\"\ncolumns = [\"tx\", \"ty\", \"tz\"]\n\
             difference = [\"dx\", \"dy\", \"dz\"]\n",
            &with_diff,
        );
        assert!((wrong_sign.measured[0][0] - a.measured[0][0]).norm() > 1e-4);
        for (bad, needle) in [
            ("difference_sign = 2", "difference_sign = 2"),
            ("difference = [\"dx\", \"dy\"]", "difference: x, y, z"),
        ] {
            let e = ColumnMapping::from_toml(
                &format!("[position]\ncolumns = [\"tx\", \"ty\", \"tz\"]\n{bad}\n"),
                "m.toml",
            )
            .unwrap_err()
            .line();
            assert!(e.contains("m.toml") && e.contains(needle), "{e}");
        }
    }
}
