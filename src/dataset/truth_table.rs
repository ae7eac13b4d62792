//! `truth.csv` read back: what only the simulation knows about each point.

use std::collections::HashMap;
use std::path::Path;

use nalgebra::Point3;

use super::Dataset;
use super::table::{CsvTable, Dialect, open};
use crate::error::{Error, Result};

/// What only the simulation knows about each point, for the evaluation.
#[derive(Clone, Debug)]
pub struct TruthTable {
    /// The file the truth came from, for messages.
    pub origin: String,
    pub point_ids: Vec<String>,
    /// True reflector positions in the tracker frame without tracker noise (`trk_x1…`), m.
    pub in_tracker: Vec<Vec<Point3<f64>>>,
    /// True reflector positions in the base frame (`true_x1…`), m.
    pub in_base: Vec<Vec<Point3<f64>>>,
}

impl TruthTable {
    /// Reads a `truth.csv`: `point_id` (or row numbers when absent), `true_x1…` and `trk_x1…`.
    pub fn read(path: &Path) -> Result<TruthTable> {
        let origin = path.display().to_string();
        TruthTable::from_reader(open(path)?, &origin)
    }

    /// Reads truth CSV text from `reader`; `origin` names it in messages.
    pub fn from_reader(reader: impl std::io::Read, origin: &str) -> Result<TruthTable> {
        let table = CsvTable::load(reader, origin, Dialect::PLAIN)?;
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
        let rows = 0..table.len();
        let in_base = rows
            .clone()
            .map(|r| table.points(r, &base_cols))
            .collect::<Result<Vec<_>>>()?;
        let in_tracker = rows
            .map(|r| table.points(r, &tracker_cols))
            .collect::<Result<Vec<_>>>()?;
        Ok(TruthTable {
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
    pub fn subset(&self, indices: &[usize]) -> TruthTable {
        TruthTable {
            origin: self.origin.clone(),
            point_ids: indices.iter().map(|&i| self.point_ids[i].clone()).collect(),
            in_tracker: indices
                .iter()
                .map(|&i| self.in_tracker[i].clone())
                .collect(),
            in_base: indices.iter().map(|&i| self.in_base[i].clone()).collect(),
        }
    }

    /// The rows reordered to match `dataset.point_ids`; error naming the first point_id missing from
    /// the truth file, or a reflector count that differs from the dataset's.
    pub fn aligned_to(self, dataset: &Dataset) -> Result<TruthTable> {
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
        // A campaign's truth lists its points in the measurements' order: nothing to reorder or copy.
        if self.point_ids == dataset.point_ids {
            return Ok(self);
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
