//! How a measured data set is divided for fitting and testing: `calibrate`'s rule, which the real-data
//! protocol ([`super::protocol`]) repeats, written once.
//!
//! A data set tested on its own points is cut into training, validation and test parts; one tested on another
//! campaign (`calibrate --test-data`, a series of the real-data protocol fitted whole) into training and
//! validation only, in the ratio of the first two fractions. A `split` column in the data overrides both.

use crate::dataset::{Dataset, Split, random_split, random_train_val};
use crate::error::Result;

/// `calibrate`'s default train, validation and test fractions.
pub const DEFAULT_FRACTIONS: [f64; 3] = [0.5, 0.25, 0.25];

/// The fractions and seed of a random split.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SplitRule {
    /// Train, validation and test fractions.
    pub fractions: [f64; 3],
    pub seed: u64,
}

impl Default for SplitRule {
    fn default() -> Self {
        SplitRule {
            fractions: DEFAULT_FRACTIONS,
            seed: 0,
        }
    }
}

impl SplitRule {
    pub fn new(fractions: [f64; 3], seed: u64) -> SplitRule {
        SplitRule { fractions, seed }
    }

    /// The training share of a data set fitted whole (tested elsewhere): train / (train + validation), 2/3
    /// with the default fractions.
    pub fn train_fraction(&self) -> f64 {
        let f = self.fractions;
        f[0] / (f[0] + f[1])
    }

    /// Each point's part: the data's own `split` column when it has one; otherwise drawn from the seed, into
    /// training, validation and test, or, when the data is `tested_elsewhere`, into training and validation
    /// in [`Self::train_fraction`].
    pub fn labels(&self, data: &Dataset, tested_elsewhere: bool) -> Result<Vec<Split>> {
        match &data.split {
            Some(labels) => Ok(labels.clone()),
            None if tested_elsewhere => {
                random_train_val(data.len(), self.train_fraction(), self.seed)
            }
            None => random_split(data.len(), self.fractions, self.seed),
        }
    }

    /// `data` cut by [`Self::labels`].
    pub fn apply(&self, data: &Dataset, tested_elsewhere: bool) -> Result<Parts> {
        Ok(Parts::of(data, self.labels(data, tested_elsewhere)?))
    }
}

/// A data set cut into its parts.
#[derive(Clone, Debug)]
pub struct Parts {
    /// Each point's part, in the data's order.
    pub labels: Vec<Split>,
    pub train: Dataset,
    pub val: Dataset,
    pub test: Dataset,
    /// The test points' indices in the data.
    pub test_indices: Vec<usize>,
}

impl Parts {
    pub fn of(data: &Dataset, labels: Vec<Split>) -> Parts {
        let indices =
            |s: Split| -> Vec<usize> { (0..data.len()).filter(|&i| labels[i] == s).collect() };
        let test_indices = indices(Split::Test);
        Parts {
            train: data.subset(&indices(Split::Train)),
            val: data.subset(&indices(Split::Val)),
            test: data.subset(&test_indices),
            test_indices,
            labels,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The real-data protocol's 2/3, written `2.0 / 3.0` before it was `calibrate`'s rule: the same number.
    #[test]
    fn the_default_train_fraction_is_two_thirds_exactly() {
        assert_eq!(SplitRule::default().train_fraction(), 2.0 / 3.0);
    }
}
