//! Reading a campaign back: `measurements.csv` (from the simulation or from a real tracker) as a
//! [`Dataset`], `truth.csv` as a [`Truth`], and the seeded train/val/test split of the points.
//!
//! Columns are found by name, so their order does not matter and unknown columns are ignored. Only the
//! robot's joint columns and the tracker measurements `x1, y1, z1` (with `x2…z3` for a three-reflector
//! nest) are required; the other groups (`point_id`, `region`, `split`, `nom_*`, `flange_*`) are read
//! when present and must then be complete. Every fault is reported on one line naming the row as a
//! spreadsheet shows it (the header is row 1, the first data row is row 2) and the column.
//!
//! A foreign export (another delimiter, decimal commas, millimetres and degrees, a 6-DoF probe's orientation, a
//! temperature column) is read through a [`mapping::ColumnMapping`] instead.

use std::collections::HashMap;
use std::path::Path;

use nalgebra::{Isometry3, Point3, Quaternion, Translation3, Unit, UnitQuaternion};
use rand::seq::SliceRandom;

use crate::error::{Error, Result};
use crate::rng::{Stream, derive};

pub mod mapping;

/// The role of a point in a calibration benchmark.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Split {
    Train,
    Val,
    Test,
}

impl Split {
    /// A `split` cell: `train`, `val`, `validation` or `test`, in any case.
    pub fn parse(cell: &str) -> Option<Split> {
        match cell.trim().to_ascii_lowercase().as_str() {
            "train" => Some(Split::Train),
            "val" | "validation" => Some(Split::Val),
            "test" => Some(Split::Test),
            _ => None,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Split::Train => "train",
            Split::Val => "val",
            Split::Test => "test",
        }
    }
}

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
        let table = Table::load(reader, origin, Dialect::PLAIN)?;
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
        let flange_cols = table.group(&crate::measurements::FLANGE_COLUMNS)?;
        let split_col = table.column("split");
        let region_col = table.column("region");

        let n = table.rows.len();
        let point_ids = table.point_ids()?;
        let mut q = Vec::with_capacity(n);
        let mut measured = Vec::with_capacity(n);
        let mut nominal = nominal_cols.as_ref().map(|_| Vec::with_capacity(n));
        let mut flange = flange_cols.as_ref().map(|_| Vec::with_capacity(n));
        let mut split = split_col.map(|_| Vec::with_capacity(n));
        let mut regions = region_col.map(|_| Vec::with_capacity(n));
        for r in 0..n {
            q.push(table.numbers(r, &joints)?);
            measured.push(table.points(r, &measured_cols)?);
            if let (Some(out), Some(cols)) = (&mut nominal, &nominal_cols) {
                out.push(table.points(r, cols)?);
            }
            if let (Some(out), Some(cols)) = (&mut flange, &flange_cols) {
                out.push(table.pose(r, cols)?);
            }
            if let (Some(out), Some(c)) = (&mut split, split_col) {
                let cell = table.cell(r, c);
                out.push(Split::parse(cell).ok_or_else(|| {
                    table.error(format!(
                        "{}: '{cell}' is not a split (train, val, validation or test)",
                        table.at(r, c)
                    ))
                })?);
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
            extra_inputs: None,
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
        }
    }

    /// Names of the extra inputs (empty without any).
    pub fn extra_input_names(&self) -> &[String] {
        self.extra_inputs
            .as_ref()
            .map_or(&[], |x| x.names.as_slice())
    }

    /// The extra inputs of point `i` (empty without any).
    pub fn extra_inputs_of(&self, i: usize) -> &[f64] {
        self.extra_inputs
            .as_ref()
            .map_or(&[], |x| x.values[i].as_slice())
    }
}

/// What only the simulation knows about each point, for the evaluation.
#[derive(Clone, Debug)]
pub struct Truth {
    /// The file the truth came from, for messages.
    pub origin: String,
    pub point_ids: Vec<String>,
    /// True reflector positions in the tracker frame without tracker noise (`trk_x1…`), m.
    pub in_tracker: Vec<Vec<Point3<f64>>>,
    /// True reflector positions in the base frame (`true_x1…`), m.
    pub in_base: Vec<Vec<Point3<f64>>>,
}

impl Truth {
    /// Reads a `truth.csv`: `point_id` (or row numbers when absent), `true_x1…` and `trk_x1…`.
    pub fn read(path: &Path) -> Result<Truth> {
        let origin = path.display().to_string();
        Truth::from_reader(open(path)?, &origin)
    }

    /// Reads truth CSV text from `reader`; `origin` names it in messages.
    pub fn from_reader(reader: impl std::io::Read, origin: &str) -> Result<Truth> {
        let table = Table::load(reader, origin, Dialect::PLAIN)?;
        let required = |prefix: &str| -> Result<Vec<[usize; 3]>> {
            table.reflectors(prefix)?.ok_or_else(|| {
                table.error(format!(
                    "no column '{prefix}x1': a truth file needs true_x1, true_y1, true_z1 and trk_x1, trk_y1, trk_z1; the header has: {}",
                    table.header_summary()
                ))
            })
        };
        let base_cols = required("true_")?;
        let tracker_cols = required("trk_")?;
        if base_cols.len() != tracker_cols.len() {
            return Err(table.error(format!(
                "the true_* columns have {} reflector(s), the trk_* columns {}",
                base_cols.len(),
                tracker_cols.len()
            )));
        }
        let point_ids = table.point_ids()?;
        let rows = 0..table.rows.len();
        let in_base = rows
            .clone()
            .map(|r| table.points(r, &base_cols))
            .collect::<Result<Vec<_>>>()?;
        let in_tracker = rows
            .map(|r| table.points(r, &tracker_cols))
            .collect::<Result<Vec<_>>>()?;
        Ok(Truth {
            origin: origin.to_string(),
            point_ids,
            in_tracker,
            in_base,
        })
    }

    pub fn len(&self) -> usize {
        self.point_ids.len()
    }

    pub fn is_empty(&self) -> bool {
        self.point_ids.is_empty()
    }

    /// A new truth with the rows at `indices`, in that order. Panics on an index out of range.
    pub fn subset(&self, indices: &[usize]) -> Truth {
        Truth {
            origin: self.origin.clone(),
            point_ids: indices.iter().map(|&i| self.point_ids[i].clone()).collect(),
            in_tracker: indices
                .iter()
                .map(|&i| self.in_tracker[i].clone())
                .collect(),
            in_base: indices.iter().map(|&i| self.in_base[i].clone()).collect(),
        }
    }

    /// Truth rows reordered to match `dataset.point_ids`; error naming the first point_id missing from
    /// the truth file, or a reflector count that differs from the dataset's.
    pub fn aligned_to(&self, dataset: &Dataset) -> Result<Truth> {
        let err = |message: String| Error::Data {
            origin: self.origin.clone(),
            message,
        };
        let truth_reflectors = self.in_base.first().map_or(0, Vec::len);
        if !dataset.is_empty() && !self.is_empty() && truth_reflectors != dataset.reflectors() {
            return Err(err(format!(
                "{} reflector(s) per point, {} has {}",
                truth_reflectors,
                dataset.origin,
                dataset.reflectors()
            )));
        }
        let index: HashMap<&str, usize> = self
            .point_ids
            .iter()
            .enumerate()
            .map(|(i, id)| (id.as_str(), i))
            .collect();
        let rows = dataset
            .point_ids
            .iter()
            .map(|id| {
                index.get(id.as_str()).copied().ok_or_else(|| {
                    err(format!(
                        "no point_id '{id}' (a point of {}) in the truth file",
                        dataset.origin
                    ))
                })
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(self.subset(&rows))
    }
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
    let table = Table::load(reader, origin, Dialect::PLAIN)?;
    let joints = table.joint_columns(joint_names)?;
    let q = (0..table.rows.len())
        .map(|r| table.numbers(r, &joints))
        .collect::<Result<Vec<_>>>()?;
    Ok((table.point_ids()?, q))
}

/// Deterministic split by seed: `fractions` (train, val, test) summing to 1 (the paper: 0.5, 0.25,
/// 0.25). The points are shuffled with the seed's `Split` stream and the shuffled order is cut at
/// `round(n · cumulative fraction)`, so every point gets exactly one label and each count is within one
/// of `n · fraction` (2335 at 0.5/0.25/0.25: 1168 / 583 / 584). Errors: a fraction negative or not
/// finite, fractions not summing to 1 (±1e-9), or a split left empty.
pub fn random_split(n: usize, fractions: [f64; 3], seed: u64) -> Result<Vec<Split>> {
    const SPLITS: [Split; 3] = [Split::Train, Split::Val, Split::Test];
    if let Some(k) = fractions.iter().position(|f| !(f.is_finite() && *f >= 0.0)) {
        return Err(Error::Invalid(format!(
            "split fraction for {} is {}: fractions must be finite and non-negative",
            SPLITS[k].name(),
            fractions[k]
        )));
    }
    let total: f64 = fractions.iter().sum();
    if (total - 1.0).abs() > 1e-9 {
        return Err(Error::Invalid(format!(
            "split fractions {} / {} / {} sum to {total}, not 1",
            fractions[0], fractions[1], fractions[2]
        )));
    }
    let cut1 = ((n as f64) * fractions[0]).round() as usize;
    let cut2 = ((n as f64) * (fractions[0] + fractions[1])).round() as usize;
    let cuts = [0, cut1.min(n), cut2.clamp(cut1.min(n), n), n];
    if let Some(k) = (0..3).find(|&k| cuts[k + 1] == cuts[k]) {
        return Err(Error::Invalid(format!(
            "the {} split would be empty: {n} points at fractions {} / {} / {}",
            SPLITS[k].name(),
            fractions[0],
            fractions[1],
            fractions[2]
        )));
    }
    let mut order: Vec<usize> = (0..n).collect();
    order.shuffle(&mut derive(seed, Stream::Split, &[]));
    let mut labels = vec![Split::Train; n];
    for k in 0..3 {
        for &i in &order[cuts[k]..cuts[k + 1]] {
            labels[i] = SPLITS[k];
        }
    }
    Ok(labels)
}

/// A seeded split into training and validation only, for data whose test points are elsewhere (another
/// campaign): the points shuffled as [`random_split`] shuffles them, the first `round(n · train_fraction)`
/// training, the rest validation. Errors: a fraction outside (0, 1), or either set left empty.
pub fn random_train_val(n: usize, train_fraction: f64, seed: u64) -> Result<Vec<Split>> {
    if !(train_fraction.is_finite() && train_fraction > 0.0 && train_fraction < 1.0) {
        return Err(Error::Invalid(format!(
            "training fraction {train_fraction}: it must lie strictly between 0 and 1"
        )));
    }
    let cut = ((n as f64) * train_fraction).round() as usize;
    if cut == 0 || cut >= n {
        return Err(Error::Invalid(format!(
            "{n} points at a training fraction of {train_fraction} leave the training or the validation set empty"
        )));
    }
    let mut order: Vec<usize> = (0..n).collect();
    order.shuffle(&mut derive(seed, Stream::Split, &[]));
    let mut labels = vec![Split::Val; n];
    for &i in &order[..cut] {
        labels[i] = Split::Train;
    }
    Ok(labels)
}

fn open(path: &Path) -> Result<std::fs::File> {
    std::fs::File::open(path).map_err(|e| Error::Data {
        origin: path.display().to_string(),
        message: format!("cannot read: {e}"),
    })
}

/// How a delimited file is written: `,` and `.` for the project's own files, anything for a mapped export.
#[derive(Clone, Copy, Debug)]
struct Dialect {
    delimiter: u8,
    decimal: char,
    /// Read through a column mapping: messages then name the mapping's settings, rows of empty cells are
    /// skipped, and a header of one column hints at a wrong delimiter.
    mapped: bool,
}

impl Dialect {
    const PLAIN: Dialect = Dialect {
        delimiter: b',',
        decimal: '.',
        mapped: false,
    };

    fn mapped(delimiter: u8, decimal: char) -> Dialect {
        Dialect {
            delimiter,
            decimal,
            mapped: true,
        }
    }
}

/// A delimited file held in memory, every row of the header's length.
struct Table {
    origin: String,
    headers: Vec<String>,
    index: HashMap<String, usize>,
    rows: Vec<csv::StringRecord>,
    dialect: Dialect,
}

impl Table {
    fn load(reader: impl std::io::Read, origin: &str, dialect: Dialect) -> Result<Table> {
        let err = |message: String| Error::Data {
            origin: origin.to_string(),
            message,
        };
        let csv_err = |e: csv::Error| {
            let row = e.position().map(|p| format!("row {}: ", p.record() + 1));
            let message = match e.kind() {
                csv::ErrorKind::Utf8 { .. } => "not valid UTF-8".to_string(),
                csv::ErrorKind::Io(io) => format!("cannot read: {io}"),
                _ => e.to_string(),
            };
            err(format!("{}{message}", row.unwrap_or_default()))
        };
        let delimiter = (dialect.delimiter as char).escape_default();
        let mut csv = csv::ReaderBuilder::new()
            .delimiter(dialect.delimiter)
            .flexible(true)
            .trim(csv::Trim::All)
            .from_reader(reader);
        let headers: Vec<String> = csv
            .headers()
            .map_err(csv_err)?
            .iter()
            .map(|h| h.trim_start_matches('\u{feff}').trim().to_string())
            .collect();
        if headers.iter().all(String::is_empty) {
            return Err(err("empty file: no header row".into()));
        }
        if dialect.mapped && headers.len() == 1 {
            let shown: String = headers[0].chars().take(40).collect();
            return Err(err(format!(
                "row 1: one column only with delimiter '{delimiter}' (the header reads '{shown}…'); is the delimiter right?"
            )));
        }
        let mut index = HashMap::new();
        for (i, h) in headers.iter().enumerate() {
            if h.is_empty() {
                continue;
            }
            if let Some(first) = index.insert(h.clone(), i) {
                return Err(err(format!(
                    "row 1: column '{h}' appears twice (columns {} and {})",
                    first + 1,
                    i + 1
                )));
            }
        }
        let mut rows = Vec::new();
        for record in csv.records() {
            let record = record.map_err(csv_err)?;
            if dialect.mapped && record.iter().all(str::is_empty) {
                continue;
            }
            if record.len() != headers.len() {
                let hint = if dialect.mapped {
                    format!(" (delimiter '{delimiter}')")
                } else {
                    String::new()
                };
                return Err(err(format!(
                    "row {}: {} fields, the header has {}{hint}",
                    rows.len() + 2,
                    record.len(),
                    headers.len()
                )));
            }
            rows.push(record);
        }
        if rows.is_empty() {
            return Err(err("no data rows after the header".into()));
        }
        Ok(Table {
            origin: origin.to_string(),
            headers,
            index,
            rows,
            dialect,
        })
    }

    /// The column `name`, which a mapping gives as `role`; an error naming both and what the header has.
    fn find(&self, name: &str, role: &str) -> Result<usize> {
        self.index.get(name.trim()).copied().ok_or_else(|| {
            const SHOWN: usize = 16;
            let mut names: Vec<&str> = self
                .headers
                .iter()
                .take(SHOWN)
                .map(String::as_str)
                .collect();
            if self.headers.len() > SHOWN {
                names.push("…");
            }
            self.error(format!(
                "no column '{name}' (the mapping's {role}); the header has {} columns: {}",
                self.headers.len(),
                names.join(", ")
            ))
        })
    }

    fn error(&self, message: String) -> Error {
        Error::Data {
            origin: self.origin.clone(),
            message,
        }
    }

    fn column(&self, name: &str) -> Option<usize> {
        self.index.get(name).copied()
    }

    /// The header's names, the first few of them when there are many.
    fn header_summary(&self) -> String {
        const SHOWN: usize = 12;
        let names: Vec<&str> = self
            .headers
            .iter()
            .take(SHOWN)
            .map(String::as_str)
            .collect();
        if self.headers.len() > SHOWN {
            format!("{}, … ({} columns)", names.join(", "), self.headers.len())
        } else {
            names.join(", ")
        }
    }

    /// "row R, column NAME" for data row `r` (0-based).
    fn at(&self, r: usize, c: usize) -> String {
        format!("row {}, column {}", r + 2, self.headers[c])
    }

    fn cell(&self, r: usize, c: usize) -> &str {
        &self.rows[r][c]
    }

    /// A number in the file's dialect (a mapped export may write a decimal comma).
    fn number(&self, r: usize, c: usize) -> Result<f64> {
        let cell = self.cell(r, c);
        if cell.is_empty() {
            return Err(self.error(format!("{}: empty, a number is needed", self.at(r, c))));
        }
        let decimal = self.dialect.decimal;
        let not_a_number = || {
            let hint = if self.dialect.mapped {
                format!(" (the mapping's decimal separator is '{decimal}')")
            } else {
                String::new()
            };
            self.error(format!("{}: '{cell}' is not a number{hint}", self.at(r, c)))
        };
        let value: f64 = if decimal == '.' {
            if self.dialect.mapped && cell.contains(',') {
                return Err(not_a_number());
            }
            cell.parse().map_err(|_| not_a_number())?
        } else {
            if cell.contains('.') {
                return Err(not_a_number());
            }
            cell.replace(decimal, ".")
                .parse()
                .map_err(|_| not_a_number())?
        };
        if !value.is_finite() {
            return Err(self.error(format!("{}: '{cell}' is not finite", self.at(r, c))));
        }
        Ok(value)
    }

    fn numbers(&self, r: usize, cols: &[usize]) -> Result<Vec<f64>> {
        cols.iter().map(|&c| self.number(r, c)).collect()
    }

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

    fn points(&self, r: usize, cols: &[[usize; 3]]) -> Result<Vec<Point3<f64>>> {
        cols.iter()
            .map(|&[x, y, z]| {
                Ok(Point3::new(
                    self.number(r, x)?,
                    self.number(r, y)?,
                    self.number(r, z)?,
                ))
            })
            .collect()
    }

    /// `x, y, z, qw, qx, qy, qz`. A quaternion within 1e-9 of unit norm is kept as written (so a file
    /// read back gives the same numbers bit for bit), one within 1e-2 is normalised, others are refused.
    fn pose(&self, r: usize, cols: &[usize]) -> Result<Isometry3<f64>> {
        let v = cols
            .iter()
            .map(|&c| self.number(r, c))
            .collect::<Result<Vec<_>>>()?;
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

    /// All of `names` as columns, none of them (`None`), or an error naming the first one missing.
    fn group(&self, names: &[&str]) -> Result<Option<Vec<usize>>> {
        let found: Vec<Option<usize>> = names.iter().map(|n| self.column(n)).collect();
        if found.iter().all(Option::is_none) {
            return Ok(None);
        }
        if let Some(k) = found.iter().position(Option::is_none) {
            let present = found.iter().position(Option::is_some).unwrap_or(0);
            return Err(self.error(format!(
                "no column '{}' though '{}' is present: the columns {} go together",
                names[k],
                names[present],
                names.join(", ")
            )));
        }
        Ok(Some(found.into_iter().flatten().collect()))
    }

    /// The `{prefix}x1…z1` or `{prefix}x1…z3` columns: `None` if there are none, an error for partial
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
            return Ok((0..self.rows.len()).map(|r| (r + 2).to_string()).collect());
        };
        let mut seen: HashMap<&str, usize> = HashMap::new();
        let mut ids = Vec::with_capacity(self.rows.len());
        for r in 0..self.rows.len() {
            let id = self.cell(r, c);
            if id.is_empty() {
                return Err(self.error(format!("{}: empty", self.at(r, c))));
            }
            if let Some(first) = seen.insert(id, r) {
                return Err(self.error(format!(
                    "{}: '{id}' repeats row {}",
                    self.at(r, c),
                    first + 2
                )));
            }
            ids.push(id.to_string());
        }
        Ok(ids)
    }
}
