//! The role of each point (train, validation, test) and the seeded splits that assign it.

use rand::seq::SliceRandom;

use crate::error::{Error, Result};
use crate::rng::{Stream, derive};

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
