//! A delimited text file held in memory, its columns found by name: the reader under every file the dataset
//! module reads (the project's own CSV files and foreign exports read through a column mapping). It knows
//! nothing of robots or trackers; [`super`] gives the columns their meaning. Every fault is one
//! [`Error::Data`] naming the file, the row as a spreadsheet numbers it (the header is row 1) and the column.

use std::collections::HashMap;
use std::path::Path;

use nalgebra::Point3;

use super::split::Split;
use crate::error::{Error, Result};

pub(super) fn open(path: &Path) -> Result<std::fs::File> {
    std::fs::File::open(path).map_err(|e| Error::Data {
        origin: path.display().to_string(),
        message: format!("cannot read: {e}"),
    })
}

/// A cell or header as a message shows it: whole when short, its first [`SHOWN_CHARS`] characters and its
/// length otherwise (a 10 MB cell is not echoed into an error line).
pub(super) fn shown(cell: &str) -> String {
    if cell.chars().count() <= SHOWN_CHARS {
        cell.to_string()
    } else {
        let head: String = cell.chars().take(SHOWN_CHARS).collect();
        format!("{head}… ({} characters)", cell.chars().count())
    }
}

/// The ASCII whitespace `str::trim` removes.
fn space(b: &u8) -> bool {
    matches!(b, b'\t' | b'\n' | b'\x0B' | b'\x0C' | b'\r' | b' ')
}

/// `cell` without the whitespace `str::trim` removes, for an ASCII cell.
fn trim_ascii(cell: &[u8]) -> &[u8] {
    let start = cell.iter().position(|b| !space(b)).unwrap_or(cell.len());
    let end = cell
        .iter()
        .rposition(|b| !space(b))
        .map_or(start, |e| e + 1);
    &cell[start..end]
}

/// Appends `record`'s cells, trimmed, to `text`, and where each ends to `bounds`; a cell that is not UTF-8 is
/// an error carrying the record's index (the header's is 0).
fn push_cells(
    record: &csv::ByteRecord,
    text: &mut Vec<u8>,
    bounds: &mut Vec<usize>,
) -> std::result::Result<(), u64> {
    // An ASCII row (all of a campaign's) needs no UTF-8 check per cell.
    let ascii = record.as_slice().is_ascii();
    if ascii {
        // Nothing to trim (a campaign's rows): the record's cells are already one after the other.
        let (mut end, row_bounds) = (text.len(), bounds.len());
        bounds.reserve(record.len());
        for cell in record {
            if cell.first().is_some_and(space) || cell.last().is_some_and(space) {
                break;
            }
            end += cell.len();
            bounds.push(end);
        }
        if bounds.len() == row_bounds + record.len() {
            text.extend_from_slice(record.as_slice());
            return Ok(());
        }
        bounds.truncate(row_bounds);
    }
    for cell in record {
        let cell = if ascii {
            trim_ascii(cell)
        } else {
            std::str::from_utf8(cell)
                .map_err(|_| record.position().map_or(0, |p| p.record()))?
                .trim()
                .as_bytes()
        };
        text.extend_from_slice(cell);
        bounds.push(text.len());
    }
    Ok(())
}

/// How much of a cell a message shows.
pub(super) const SHOWN_CHARS: usize = 40;

/// How a delimited file is written: `,` and `.` for the project's own files, anything for a mapped export.
#[derive(Clone, Copy, Debug)]
pub(super) struct Dialect {
    pub(super) delimiter: u8,
    pub(super) decimal: char,
    /// Read through a column mapping: messages then name the mapping's settings, rows of empty cells are
    /// skipped, and a header of one column hints at a wrong delimiter.
    pub(super) mapped: bool,
}

impl Dialect {
    pub(super) const PLAIN: Dialect = Dialect {
        delimiter: b',',
        decimal: '.',
        mapped: false,
    };

    pub(super) fn mapped(delimiter: u8, decimal: char) -> Dialect {
        Dialect {
            delimiter,
            decimal,
            mapped: true,
        }
    }
}

/// A delimited file held in memory, every row of the header's length.
pub(super) struct CsvTable {
    pub(super) origin: String,
    pub(super) headers: Vec<String>,
    pub(super) index: HashMap<String, usize>,
    /// Every data row's cells, trimmed, one after the other: one buffer rather than a string per cell (a
    /// 2335-row campaign has 54 000 cells, and allocating each cost as much as reading the file).
    text: String,
    /// Cell `k = r · width + c` (row `r`, column `c`) is `text[bounds[k]..bounds[k + 1]]`.
    bounds: Vec<usize>,
    pub(super) dialect: Dialect,
}

impl CsvTable {
    pub(super) fn load(
        reader: impl std::io::Read,
        origin: &str,
        dialect: Dialect,
    ) -> Result<CsvTable> {
        let err = |message: String| Error::Data {
            origin: origin.to_string(),
            message,
        };
        let csv_err = |e: csv::Error| {
            let row = e.position().map(|p| format!("row {}: ", p.record() + 1));
            let message = match e.kind() {
                csv::ErrorKind::Io(io) => format!("cannot read: {io}"),
                _ => e.to_string(),
            };
            err(format!("{}{message}", row.unwrap_or_default()))
        };
        // `record` is the record's index counting the header as 0.
        let not_utf8 = |record: u64| err(format!("row {}: not valid UTF-8", record + 1));
        let delimiter = (dialect.delimiter as char).escape_default();
        // Read as bytes and trimmed here: the crate's own trimming rebuilds every record twice.
        let mut csv = csv::ReaderBuilder::new()
            .delimiter(dialect.delimiter)
            .flexible(true)
            .from_reader(reader);
        let headers: Vec<String> = csv
            .byte_headers()
            .map_err(csv_err)?
            .iter()
            .map(|h| {
                let h = std::str::from_utf8(h).map_err(|_| not_utf8(0))?;
                Ok(h.trim().trim_start_matches('\u{feff}').trim().to_string())
            })
            .collect::<Result<_>>()?;
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
                    "row 1: column '{}' appears twice (columns {} and {})",
                    shown(h),
                    first + 1,
                    i + 1
                )));
            }
        }
        let (mut text, mut bounds) = (Vec::new(), vec![0]);
        let mut rows = 0;
        let mut record = csv::ByteRecord::new();
        while csv.read_byte_record(&mut record).map_err(csv_err)? {
            let (row_text, row_bounds) = (text.len(), bounds.len());
            push_cells(&record, &mut text, &mut bounds).map_err(not_utf8)?;
            if dialect.mapped && text.len() == row_text {
                bounds.truncate(row_bounds);
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
                    rows + 2,
                    record.len(),
                    headers.len()
                )));
            }
            rows += 1;
        }
        if rows == 0 {
            return Err(err("no data rows after the header".into()));
        }
        // Every cell was checked (or is ASCII), so the whole is UTF-8 with a cell boundary at each bound.
        let text = String::from_utf8(text).map_err(|_| err("not valid UTF-8".into()))?;
        Ok(CsvTable {
            origin: origin.to_string(),
            headers,
            index,
            text,
            bounds,
            dialect,
        })
    }

    /// The number of data rows.
    pub(super) fn len(&self) -> usize {
        (self.bounds.len() - 1) / self.headers.len()
    }

    /// The column `name`, which a mapping gives as `role`; an error naming both and what the header has.
    pub(super) fn find(&self, name: &str, role: &str) -> Result<usize> {
        self.index.get(name.trim()).copied().ok_or_else(|| {
            const SHOWN: usize = 16;
            let mut names: Vec<String> =
                self.headers.iter().take(SHOWN).map(|h| shown(h)).collect();
            if self.headers.len() > SHOWN {
                names.push("…".into());
            }
            self.error(format!(
                "no column '{name}' (the mapping's {role}); the header has {} columns: {}",
                self.headers.len(),
                names.join(", ")
            ))
        })
    }

    pub(super) fn error(&self, message: String) -> Error {
        Error::Data {
            origin: self.origin.clone(),
            message,
        }
    }

    pub(super) fn column(&self, name: &str) -> Option<usize> {
        self.index.get(name).copied()
    }

    /// The header's names, the first few of them when there are many.
    pub(super) fn header_summary(&self) -> String {
        const SHOWN: usize = 12;
        let names: Vec<String> = self.headers.iter().take(SHOWN).map(|h| shown(h)).collect();
        if self.headers.len() > SHOWN {
            format!("{}, … ({} columns)", names.join(", "), self.headers.len())
        } else {
            names.join(", ")
        }
    }

    /// "row R, column NAME" for data row `r` (0-based).
    pub(super) fn at(&self, r: usize, c: usize) -> String {
        format!("row {}, column {}", r + 2, shown(&self.headers[c]))
    }

    #[inline]
    pub(super) fn cell(&self, r: usize, c: usize) -> &str {
        let k = r * self.headers.len() + c;
        &self.text[self.bounds[k]..self.bounds[k + 1]]
    }

    /// A number in the file's dialect (a mapped export may write a decimal comma).
    /// The cell at row `r`, column `c` as a split label.
    pub(super) fn split(&self, r: usize, c: usize) -> Result<Split> {
        let cell = self.cell(r, c);
        Split::parse(cell).ok_or_else(|| {
            self.error(format!(
                "{}: '{}' is not a split (train, val, validation or test)",
                self.at(r, c),
                shown(cell)
            ))
        })
    }

    pub(super) fn number(&self, r: usize, c: usize) -> Result<f64> {
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
            let cell = shown(cell);
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
            let cell = shown(cell);
            return Err(self.error(format!("{}: '{cell}' is not finite", self.at(r, c))));
        }
        Ok(value)
    }

    pub(super) fn numbers(&self, r: usize, cols: &[usize]) -> Result<Vec<f64>> {
        cols.iter().map(|&c| self.number(r, c)).collect()
    }

    pub(super) fn points(&self, r: usize, cols: &[[usize; 3]]) -> Result<Vec<Point3<f64>>> {
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

    /// All of `names` as columns, none of them (`None`), or an error naming the first one missing.
    pub(super) fn group(&self, names: &[&str]) -> Result<Option<Vec<usize>>> {
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
}
