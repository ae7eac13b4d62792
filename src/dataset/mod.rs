//! Reading a campaign back: `measurements.csv` (from the simulation or from a real tracker) as a
//! [`Dataset`], `truth.csv` as a [`TruthTable`], and the seeded train/val/test split of the points.
//!
//! Columns are found by name, so their order does not matter and unknown columns are ignored. Only the
//! robot's joint columns and the tracker measurements `x1, y1, z1` (with `x2…z3` for a three-reflector
//! nest) are required; the other groups (`point_id`, `region`, `split`, `nom_*`, `flange_*`, `temperature`,
//! the last an extra input a method may regress on) are read when present and must then be complete. Every fault is reported on one line naming the row as a
//! spreadsheet shows it (the header is row 1, the first data row is row 2) and the column.
//!
//! A foreign export (another delimiter, decimal commas, millimetres and degrees, a 6-DoF probe's orientation, a
//! temperature column) is read through a [`mapping::ColumnMapping`] instead.

use std::collections::HashMap;
use std::path::Path;

use nalgebra::{Isometry3, Point3, Quaternion, Translation3, Unit, UnitQuaternion};

use crate::error::Result;

pub mod mapping;
pub mod orientation;
pub mod range;
mod split;
mod table;
mod truth_table;

pub use split::{Split, random_split, random_train_val};
pub use truth_table::TruthTable;

use table::{CsvTable, Dialect, open};

/// The controller's nominal flange pose: position (m) and unit quaternion, base frame.
pub const FLANGE_COLUMNS: [&str; 7] = [
    "flange_x",
    "flange_y",
    "flange_z",
    "flange_qw",
    "flange_qx",
    "flange_qy",
    "flange_qz",
];

/// The temperature column (°C) of a measurements file: read as the extra input `temperature`.
pub const TEMPERATURE_COLUMN: &str = "temperature";

/// The time column (s, the tracker's clock) of a campaign measured on the fly.
pub const TIME_COLUMN: &str = "time";

/// Column prefixes of the controller's commanded joint velocities (`qd_<joint>`, rad/s) and accelerations
/// (`qdd_<joint>`, rad/s²) logged with each sample of a campaign measured on the fly.
pub const VELOCITY_PREFIX: &str = "qd_";
pub const ACCELERATION_PREFIX: &str = "qdd_";

/// Name prefix of the motion inputs (`tau_motion_<joint>`, Nm; [`crate::calib::motion_inputs`]): an input whose
/// value at rest is zero, which a model takes when not told otherwise.
pub const MOTION_INPUT_PREFIX: &str = "tau_motion_";

pub use crate::robot::JointRates;

/// The points of a measurement campaign, as a calibration method may see them.
#[derive(Clone, Debug)]
pub struct Dataset {
    /// The file (or other source) the data came from, for messages.
    pub origin: String,
    pub joint_names: Vec<String>,
    /// The `point_id` column, or when absent the row numbers as a spreadsheet shows them ("2" for the
    /// first data row), so that an id and the row of an error message agree.
    pub point_ids: Vec<String>,
    /// Commanded joint angles (rad) in `joint_names` order.
    pub q: Vec<Vec<f64>>,
    /// Tracker measurements `x1, y1, z1 [, x2…z3]`: 1 or 3 reflectors, tracker frame, m.
    pub measured: Vec<Vec<Point3<f64>>>,
    /// Nominal reflector positions `nom_x1…` (base frame, m) when the file has them.
    pub nominal_reflectors: Option<Vec<Vec<Point3<f64>>>>,
    /// The controller's nominal flange pose `flange_x…z, flange_qw…qz` when the file has it.
    pub nominal_flange: Option<Vec<Isometry3<f64>>>,
    pub split: Option<Vec<Split>>,
    pub regions: Option<Vec<String>>,
    /// Measured orientation of a 6-DoF probe (its frame in the tracker frame) when the source has it (a
    /// [`mapping::ColumnMapping`] with an `[orientation]` group); the probe's mounting on the flange is unknown.
    pub measured_orientation: Option<Vec<UnitQuaternion<f64>>>,
    /// Inputs beyond the joint angles (e.g. the temperature) that a method may regress on.
    pub extra_inputs: Option<ExtraInputs>,
    /// The tracker's time stamp of each sample (s), for a campaign measured on the fly (`time` column).
    pub time: Option<Vec<f64>>,
    /// The commanded joint velocities and accelerations of each sample (`qd_*`, `qdd_*` columns).
    pub rates: Option<Vec<JointRates>>,
    /// The measurements are already in the robot's base frame (a mapping's `[position] frame = "base"`): no
    /// tracker frame is fitted, only the mounting.
    pub base_frame: bool,
}

/// Per-point values of named inputs beyond the joint angles.
#[derive(Clone, Debug, PartialEq)]
pub struct ExtraInputs {
    pub names: Vec<String>,
    /// One row per point, in `names` order.
    pub values: Vec<Vec<f64>>,
}

impl Dataset {
    /// Reads a measurements file. `joint_names`: the robot's joints (from its URDF); each must be a column.
    pub fn read(path: &Path, joint_names: &[String]) -> Result<Dataset> {
        let origin = path.display().to_string();
        let file = open(path)?;
        Dataset::from_reader(file, &origin, joint_names)
    }

    /// Reads measurements CSV text from `reader`; `origin` names it in messages.
    pub fn from_reader(
        reader: impl std::io::Read,
        origin: &str,
        joint_names: &[String],
    ) -> Result<Dataset> {
        let table = CsvTable::load(reader, origin, Dialect::PLAIN)?;
        let joints = table.joint_columns(joint_names)?;
        let measured_cols = table.reflectors("")?.ok_or_else(|| {
            let missing = ["x1", "y1", "z1"]
                .into_iter()
                .find(|n| table.column(n).is_none())
                .unwrap_or("x1");
            table.error(format!(
                "no column '{missing}': the tracker measurements x1, y1, z1 are required; the header has: {}",
                table.header_summary()
            ))
        })?;
        let nominal_cols = table.reflectors("nom_")?;
        if let Some(nominal) = &nominal_cols
            && nominal.len() != measured_cols.len()
        {
            return Err(table.error(format!(
                "the nom_* columns have {} reflector(s), the measurements x* {}",
                nominal.len(),
                measured_cols.len()
            )));
        }
        let flange_cols = table.group(&FLANGE_COLUMNS)?;
        let split_col = table.column("split");
        let region_col = table.column("region");
        let temperature_col = table.column(TEMPERATURE_COLUMN);
        let time_col = table.column(TIME_COLUMN);
        let rate_cols = table.rate_columns(joint_names)?;

        let n = table.len();
        let point_ids = table.point_ids()?;
        let mut q = Vec::with_capacity(n);
        let mut measured = Vec::with_capacity(n);
        let mut nominal = nominal_cols.as_ref().map(|_| Vec::with_capacity(n));
        let mut flange = flange_cols.as_ref().map(|_| Vec::with_capacity(n));
        let mut split = split_col.map(|_| Vec::with_capacity(n));
        let mut regions = region_col.map(|_| Vec::with_capacity(n));
        let mut temperature = temperature_col.map(|_| Vec::with_capacity(n));
        let mut time = time_col.map(|_| Vec::with_capacity(n));
        let mut rates = rate_cols.as_ref().map(|_| Vec::with_capacity(n));
        for r in 0..n {
            if let (Some(out), Some((qd, qdd))) = (&mut rates, &rate_cols) {
                out.push(JointRates {
                    qd: table.numbers(r, qd)?,
                    qdd: table.numbers(r, qdd)?,
                });
            }
            if let (Some(out), Some(c)) = (&mut time, time_col) {
                out.push(table.number(r, c)?);
            }
            if let (Some(out), Some(c)) = (&mut temperature, temperature_col) {
                out.push(vec![table.number(r, c)?]);
            }
            q.push(table.numbers(r, &joints)?);
            measured.push(table.points(r, &measured_cols)?);
            if let (Some(out), Some(cols)) = (&mut nominal, &nominal_cols) {
                out.push(table.points(r, cols)?);
            }
            if let (Some(out), Some(cols)) = (&mut flange, &flange_cols) {
                out.push(table.pose(r, cols)?);
            }
            if let (Some(out), Some(c)) = (&mut split, split_col) {
                out.push(table.split(r, c)?);
            }
            if let (Some(out), Some(c)) = (&mut regions, region_col) {
                out.push(table.cell(r, c).to_string());
            }
        }
        Ok(Dataset {
            origin: origin.to_string(),
            joint_names: joint_names.to_vec(),
            point_ids,
            q,
            measured,
            nominal_reflectors: nominal,
            nominal_flange: flange,
            split,
            regions,
            measured_orientation: None,
            extra_inputs: temperature.map(|values| ExtraInputs {
                names: vec![TEMPERATURE_COLUMN.to_string()],
                values,
            }),
            time,
            rates,
            base_frame: false,
        })
    }

    /// A dataset built in memory (a synthetic robot, a test): point ids are row numbers, and the optional
    /// columns are absent until the caller sets them.
    pub fn in_memory(
        origin: &str,
        joint_names: Vec<String>,
        q: Vec<Vec<f64>>,
        measured: Vec<Vec<Point3<f64>>>,
    ) -> Dataset {
        Dataset {
            origin: origin.to_string(),
            joint_names,
            point_ids: (0..q.len()).map(|i| i.to_string()).collect(),
            q,
            measured,
            nominal_reflectors: None,
            nominal_flange: None,
            split: None,
            regions: None,
            measured_orientation: None,
            extra_inputs: None,
            time: None,
            rates: None,
            base_frame: false,
        }
    }

    pub fn len(&self) -> usize {
        self.point_ids.len()
    }

    pub fn is_empty(&self) -> bool {
        self.point_ids.is_empty()
    }

    /// Reflectors measured per point (1 or 3); 0 for a dataset without points.
    pub fn reflectors(&self) -> usize {
        self.measured.first().map_or(0, Vec::len)
    }

    /// Whether `other` holds the same points as this, in the same order — everything equal but the extra
    /// inputs (a value computed from the points alone is then the same for both).
    pub fn with_other_inputs_is(&self, other: &Dataset) -> bool {
        let Dataset {
            origin,
            joint_names,
            point_ids,
            q,
            measured,
            nominal_reflectors,
            nominal_flange,
            split,
            regions,
            measured_orientation,
            extra_inputs: _,
            time,
            rates,
            base_frame,
        } = self;
        *origin == other.origin
            && *joint_names == other.joint_names
            && *point_ids == other.point_ids
            && *q == other.q
            && *measured == other.measured
            && *nominal_reflectors == other.nominal_reflectors
            && *nominal_flange == other.nominal_flange
            && *split == other.split
            && *regions == other.regions
            && *measured_orientation == other.measured_orientation
            && *time == other.time
            && *rates == other.rates
            && *base_frame == other.base_frame
    }

    /// A new dataset with the rows at `indices`, in that order. Panics on an index out of range.
    pub fn subset(&self, indices: &[usize]) -> Dataset {
        fn pick<T: Clone>(v: &[T], indices: &[usize]) -> Vec<T> {
            indices.iter().map(|&i| v[i].clone()).collect()
        }
        Dataset {
            origin: self.origin.clone(),
            joint_names: self.joint_names.clone(),
            point_ids: pick(&self.point_ids, indices),
            q: pick(&self.q, indices),
            measured: pick(&self.measured, indices),
            nominal_reflectors: self.nominal_reflectors.as_deref().map(|v| pick(v, indices)),
            nominal_flange: self.nominal_flange.as_deref().map(|v| pick(v, indices)),
            split: self.split.as_deref().map(|v| pick(v, indices)),
            regions: self.regions.as_deref().map(|v| pick(v, indices)),
            measured_orientation: self
                .measured_orientation
                .as_deref()
                .map(|v| pick(v, indices)),
            extra_inputs: self.extra_inputs.as_ref().map(|x| ExtraInputs {
                names: x.names.clone(),
                values: pick(&x.values, indices),
            }),
            time: self.time.as_deref().map(|v| pick(v, indices)),
            rates: self.rates.as_deref().map(|v| pick(v, indices)),
            base_frame: self.base_frame,
        }
    }

    /// Names of the extra inputs (empty without any).
    pub fn extra_input_names(&self) -> &[String] {
        self.extra_inputs
            .as_ref()
            .map_or(&[], |x| x.names.as_slice())
    }

    /// The value each extra input takes when a model is not given it: its mean over the rows, except a motion
    /// input ([`MOTION_INPUT_PREFIX`]), which is zero — the arm at rest, as it is used after calibration.
    pub fn input_defaults(&self) -> Vec<f64> {
        let Some(x) = &self.extra_inputs else {
            return Vec::new();
        };
        x.names
            .iter()
            .enumerate()
            .map(|(k, name)| {
                if name.starts_with(MOTION_INPUT_PREFIX) || x.values.is_empty() {
                    0.0
                } else {
                    x.values.iter().map(|v| v[k]).sum::<f64>() / x.values.len() as f64
                }
            })
            .collect()
    }

    /// The extra inputs of point `i` (empty without any).
    pub fn extra_inputs_of(&self, i: usize) -> &[f64] {
        self.extra_inputs
            .as_ref()
            .map_or(&[], |x| x.values[i].as_slice())
    }
}

/// The extra inputs `names` of every row of a file of joint configurations (for applying a model that
/// regressed on them), one column each, in `names` order. A missing column is one error naming it.
pub fn read_inputs(path: &Path, names: &[String]) -> Result<Vec<Vec<f64>>> {
    inputs_from_reader(open(path)?, &path.display().to_string(), names)
}

/// [`read_inputs`] from any reader; `origin` names it in messages.
pub fn inputs_from_reader(
    reader: impl std::io::Read,
    origin: &str,
    names: &[String],
) -> Result<Vec<Vec<f64>>> {
    let table = CsvTable::load(reader, origin, Dialect::PLAIN)?;
    let cols = names
        .iter()
        .map(|name| {
            table.column(name).ok_or_else(|| {
                table.error(format!(
                    "no column '{name}': the model regressed on it (its extra inputs: {}), so each \
                     configuration needs its value; the header has: {}",
                    names.join(", "),
                    table.header_summary()
                ))
            })
        })
        .collect::<Result<Vec<_>>>()?;
    (0..table.len()).map(|r| table.numbers(r, &cols)).collect()
}

/// Configurations measured more than once: the indices of each group of `q` whose joint angles agree to
/// 1 mrad (rounded to it), groups of two or more only, in the order of their angles.
pub fn repeat_groups(q: &[&[f64]]) -> Vec<Vec<usize>> {
    // Every key in one buffer (row `i` at `starts[i]..starts[i + 1]`), and a stable sort of the indices by
    // them: the groups of a map keyed by them, in its (lexicographic) order, each in the order of its
    // indices — without a tree node, a key's allocation and a search per point.
    let mut flat: Vec<i64> = Vec::with_capacity(q.iter().map(|q| q.len()).sum());
    let mut starts = Vec::with_capacity(q.len() + 1);
    starts.push(0);
    for q in q {
        flat.extend(q.iter().map(|v| (v * 1e3).round() as i64));
        starts.push(flat.len());
    }
    let key = |i: usize| &flat[starts[i]..starts[i + 1]];
    let mut order: Vec<usize> = (0..q.len()).collect();
    order.sort_by(|&a, &b| key(a).cmp(key(b)));
    order
        .chunk_by(|&a, &b| key(a) == key(b))
        .filter(|m| m.len() > 1)
        .map(<[usize]>::to_vec)
        .collect()
}

/// Joint configurations only (for applying a model to commands): the `point_id` column (or row
/// numbers, as in [`Dataset`]) and the angles (rad) in `joint_names` order. Other columns are ignored.
pub fn read_joints(path: &Path, joint_names: &[String]) -> Result<(Vec<String>, Vec<Vec<f64>>)> {
    joints_from_reader(open(path)?, &path.display().to_string(), joint_names)
}

/// [`read_joints`] from any reader; `origin` names it in messages.
pub fn joints_from_reader(
    reader: impl std::io::Read,
    origin: &str,
    joint_names: &[String],
) -> Result<(Vec<String>, Vec<Vec<f64>>)> {
    let table = CsvTable::load(reader, origin, Dialect::PLAIN)?;
    let joints = table.joint_columns(joint_names)?;
    let q = (0..table.len())
        .map(|r| table.numbers(r, &joints))
        .collect::<Result<Vec<_>>>()?;
    Ok((table.point_ids()?, q))
}

/// How the campaign files lay out their columns: the robot's joints by name, reflector groups
/// `{prefix}x1…z3`, a pose as `x, y, z, qw, qx, qy, qz`, and the `point_id` column.
impl CsvTable {
    /// The column of each joint, or an error naming the first one missing and what the header has.
    fn joint_columns(&self, joint_names: &[String]) -> Result<Vec<usize>> {
        joint_names
            .iter()
            .enumerate()
            .map(|(i, name)| {
                self.column(name).ok_or_else(|| {
                    self.error(format!(
                        "no column '{name}' for joint {} of the robot; the header has: {}",
                        i + 1,
                        self.header_summary()
                    ))
                })
            })
            .collect()
    }

    /// The `qd_<joint>` and `qdd_<joint>` columns of every joint, `None` when the file has none of them; a
    /// file with some but not all is refused, naming the first one missing.
    fn rate_columns(&self, joint_names: &[String]) -> Result<Option<(Vec<usize>, Vec<usize>)>> {
        let names: Vec<String> = [VELOCITY_PREFIX, ACCELERATION_PREFIX]
            .iter()
            .flat_map(|p| joint_names.iter().map(move |j| format!("{p}{j}")))
            .collect();
        let found: Vec<Option<usize>> = names.iter().map(|n| self.column(n)).collect();
        if found.iter().all(Option::is_none) {
            return Ok(None);
        }
        if let Some(k) = found.iter().position(Option::is_none) {
            return Err(self.error(format!(
                "no column '{}': commanded joint rates need qd_<joint> and qdd_<joint> for every joint",
                names[k]
            )));
        }
        let cols: Vec<usize> = found.into_iter().flatten().collect();
        let n = joint_names.len();
        Ok(Some((cols[..n].to_vec(), cols[n..].to_vec())))
    }

    /// `x, y, z, qw, qx, qy, qz`. A quaternion within 1e-9 of unit norm is kept as written (so a file
    /// read back gives the same numbers bit for bit), one within 1e-2 is normalised, others are refused.
    fn pose(&self, r: usize, cols: &[usize]) -> Result<Isometry3<f64>> {
        let mut v = [0.0; 7];
        for (v, &c) in v.iter_mut().zip(cols) {
            *v = self.number(r, c)?;
        }
        let q = Quaternion::new(v[3], v[4], v[5], v[6]);
        let norm = q.norm();
        let rotation = if (norm - 1.0).abs() <= 1e-9 {
            Unit::new_unchecked(q)
        } else if (norm - 1.0).abs() <= 1e-2 {
            UnitQuaternion::from_quaternion(q)
        } else {
            return Err(self.error(format!(
                "row {}, columns {}…{}: the quaternion's norm is {norm}, not 1",
                r + 2,
                self.headers[cols[3]],
                self.headers[cols[6]]
            )));
        };
        Ok(Isometry3::from_parts(
            Translation3::new(v[0], v[1], v[2]),
            rotation,
        ))
    }

    /// groups and for reflector counts other than 1 or 3.
    fn reflectors(&self, prefix: &str) -> Result<Option<Vec<[usize; 3]>>> {
        let group = |k: usize| -> Result<Option<[usize; 3]>> {
            let names = ["x", "y", "z"].map(|a| format!("{prefix}{a}{k}"));
            Ok(self
                .group(&names.each_ref().map(String::as_str))?
                .map(|c| [c[0], c[1], c[2]]))
        };
        let groups = [group(1)?, group(2)?, group(3)?];
        if let Some(c) = ["x", "y", "z"]
            .iter()
            .find_map(|a| self.column(&format!("{prefix}{a}4")))
        {
            return Err(self.error(format!(
                "column '{}': only 1 or 3 reflectors are supported",
                self.headers[c]
            )));
        }
        let cols = |k: usize| format!("{prefix}x{k}, {prefix}y{k}, {prefix}z{k}");
        match groups {
            [None, None, None] => Ok(None),
            [Some(a), None, None] => Ok(Some(vec![a])),
            [Some(a), Some(b), Some(c)] => Ok(Some(vec![a, b, c])),
            [None, ..] => {
                Err(self.error(format!("columns for reflector 2 or 3 but no {}", cols(1))))
            }
            [Some(_), Some(_), None] => Err(self.error(format!(
                "columns {} but no {}: only 1 or 3 reflectors are supported",
                cols(2),
                cols(3)
            ))),
            [Some(_), None, Some(_)] => Err(self.error(format!(
                "columns {} but no {}: only 1 or 3 reflectors are supported",
                cols(3),
                cols(2)
            ))),
        }
    }

    /// The `point_id` column (non-empty, unique), or the rows' numbers when it is absent.
    fn point_ids(&self) -> Result<Vec<String>> {
        let Some(c) = self.column("point_id") else {
            return Ok((0..self.len()).map(|r| (r + 2).to_string()).collect());
        };
        let mut seen: HashMap<&str, usize> = HashMap::with_capacity(self.len());
        let mut ids = Vec::with_capacity(self.len());
        for r in 0..self.len() {
            let id = self.cell(r, c);
            if id.is_empty() {
                return Err(self.error(format!("{}: empty", self.at(r, c))));
            }
            if let Some(first) = seen.insert(id, r) {
                return Err(self.error(format!(
                    "{}: '{}' repeats row {}",
                    self.at(r, c),
                    table::shown(id),
                    first + 2
                )));
            }
            ids.push(id.to_string());
        }
        Ok(ids)
    }
}

#[cfg(test)]
mod tests {
    use super::repeat_groups;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// The groups a map keyed by the rounded angles gives, in its order: what `repeat_groups` computed before
    /// it sorted instead.
    fn by_map(q: &[&[f64]]) -> Vec<Vec<usize>> {
        let mut groups: std::collections::BTreeMap<Vec<i64>, Vec<usize>> = Default::default();
        for (i, q) in q.iter().enumerate() {
            let key = q.iter().map(|v| (v * 1e3).round() as i64).collect();
            groups.entry(key).or_default().push(i);
        }
        groups.into_values().filter(|m| m.len() > 1).collect()
    }

    #[test]
    fn repeat_groups_are_those_of_a_map_of_the_rounded_angles() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        // Few distinct angles (so configurations repeat, some within 1 mrad of each other, some not), a few
        // shorter rows, negative angles.
        let q: Vec<Vec<f64>> = (0..400)
            .map(|i| {
                let n = if i % 37 == 0 { 2 } else { 3 };
                (0..n)
                    .map(|_| {
                        rng.random_range(-2..=2) as f64 * 0.7
                            + rng.random_range(-2..=2) as f64 * 4e-4
                    })
                    .collect()
            })
            .collect();
        let rows: Vec<&[f64]> = q.iter().map(Vec::as_slice).collect();
        let groups = repeat_groups(&rows);
        assert!(groups.len() > 10 && groups.iter().any(|g| g.len() > 3));
        assert_eq!(groups, by_map(&rows));
    }
}
