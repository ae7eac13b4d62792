//! The fitted ridge model: what a calibration stores, how it predicts, and the check a model read from a file
//! must pass.

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

/// A fitted model, self-contained so it can be stored with a calibration and applied later to raw
/// candidate rows.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct RidgeModel {
    /// Candidate columns used, in rank order of |correlation| with the target on training data. Empty for
    /// an intercept-only model (constant target, or no candidate varies).
    pub inputs: Vec<usize>,
    /// Polynomial degree applied to every input (0 for an intercept-only model).
    pub degree: usize,
    pub alpha: f64,
    /// Whether the features include the pairwise products of the inputs; only ever set with degree ≥ 2.
    pub cross_terms: bool,
    /// Training mean and standard deviation of each used input.
    pub input_mean: Vec<f64>,
    pub input_scale: Vec<f64>,
    /// Training mean and standard deviation of each feature, in [`RidgeModel::predict`]'s feature order:
    /// for each input its powers 1..=degree, then the products of input pairs (i < j) in `inputs` order.
    pub feature_mean: Vec<f64>,
    pub feature_scale: Vec<f64>,
    pub coef: Vec<f64>,
    pub intercept: f64,
    /// R² (eq. 20) on the validation set; see [`r2`] for a constant validation target.
    pub validation_r2: f64,
}

impl RidgeModel {
    /// Evaluates the model on one row of candidate inputs (the same columns `fit_all` saw).
    ///
    /// Panics if `candidates` is shorter than the largest index in `inputs`.
    pub fn predict(&self, candidates: &[f64]) -> f64 {
        // Each feature's coefficient, mean and scale from one zipped iterator, in feature order: no index
        // checks in the loop, the same terms summed in the same order. (A fitted or validated model has one
        // of each per feature.)
        let mut features = self
            .coef
            .iter()
            .zip(&self.feature_mean)
            .zip(&self.feature_scale);
        let z = |i: usize| (candidates[self.inputs[i]] - self.input_mean[i]) / self.input_scale[i];
        let mut acc = self.intercept;
        for i in 0..self.inputs.len() {
            let zi = z(i);
            let mut p = zi;
            for ((c, m), s) in features.by_ref().take(self.degree) {
                acc += c * ((p - m) / s);
                p *= zi;
            }
        }
        if self.cross_terms {
            for a in 0..self.inputs.len() {
                for b in a + 1..self.inputs.len() {
                    if let Some(((c, m), s)) = features.next() {
                        acc += c * ((z(a) * z(b) - m) / s);
                    }
                }
            }
        }
        acc
    }

    pub fn n_features(&self) -> usize {
        n_features(self.inputs.len(), self.degree, self.cross_terms)
    }

    /// A model read from a file can predict from rows of `n_candidates` candidate inputs: its inputs are
    /// distinct candidates, every per-input and per-feature list has one entry per input or feature, scales
    /// are positive, and every number is finite and of a size a fit on metres and radians gives (see
    /// [`MAX_COEFFICIENT`], [`MAX_DEGREE`]). Fields are named as the file writes them.
    pub fn validate(&self, n_candidates: usize) -> Result<()> {
        self.validate_shape(n_candidates)?;
        self.validate_numbers()
    }

    /// The inputs, degree and list lengths: what decides which feature a number belongs to.
    fn validate_shape(&self, n_candidates: usize) -> Result<()> {
        for (k, &i) in self.inputs.iter().enumerate() {
            if i >= n_candidates {
                return invalid(
                    &format!("inputs[{k}]"),
                    format!("candidate {i} of {n_candidates} (they count from 0)"),
                );
            }
            if self.inputs[..k].contains(&i) {
                return invalid(
                    &format!("inputs[{k}]"),
                    format!("candidate {i} appears twice"),
                );
            }
        }
        if self.degree > MAX_DEGREE {
            return invalid(
                "degree",
                format!(
                    "{} is above the largest plausible {MAX_DEGREE}",
                    self.degree
                ),
            );
        }
        if self.cross_terms && self.degree < 2 {
            return invalid(
                "cross_terms",
                format!(
                    "set with degree {}; products need degree 2 or more",
                    self.degree
                ),
            );
        }
        let k = self.inputs.len();
        let p = self.n_features();
        for (field, len, want, of) in [
            ("input_mean", self.input_mean.len(), k, "inputs"),
            ("input_scale", self.input_scale.len(), k, "inputs"),
            ("feature_mean", self.feature_mean.len(), p, "features"),
            ("feature_scale", self.feature_scale.len(), p, "features"),
            ("coef", self.coef.len(), p, "features"),
        ] {
            if len != want {
                return invalid(
                    field,
                    format!(
                        "{len} entries for {want} {of} ({k} inputs of degree {}{})",
                        self.degree,
                        if self.cross_terms {
                            " with cross terms"
                        } else {
                            ""
                        }
                    ),
                );
            }
        }
        Ok(())
    }

    /// The numbers: finite, scales positive, coefficients of a size a fit gives.
    fn validate_numbers(&self) -> Result<()> {
        let finite = |field: &str, v: &[f64]| -> Result<()> {
            match v.iter().position(|x| !x.is_finite()) {
                Some(i) => invalid(&format!("{field}[{i}]"), format!("{} is not finite", v[i])),
                None => Ok(()),
            }
        };
        let positive = |field: &str, v: &[f64]| -> Result<()> {
            finite(field, v)?;
            match v.iter().position(|x| *x <= 0.0) {
                Some(i) => invalid(
                    &format!("{field}[{i}]"),
                    format!("{:e}: a scale must be positive", v[i]),
                ),
                None => Ok(()),
            }
        };
        finite("input_mean", &self.input_mean)?;
        positive("input_scale", &self.input_scale)?;
        finite("feature_mean", &self.feature_mean)?;
        positive("feature_scale", &self.feature_scale)?;
        finite("coef", &self.coef)?;
        if let Some(i) = self.coef.iter().position(|c| c.abs() > MAX_COEFFICIENT) {
            return invalid(
                &format!("coef[{i}]"),
                format!(
                    "{:e} is not a coefficient a fit on metres and radians gives (at most {MAX_COEFFICIENT} \
                     in magnitude)",
                    self.coef[i]
                ),
            );
        }
        if !(self.intercept.is_finite() && self.intercept.abs() <= MAX_COEFFICIENT) {
            return invalid(
                "intercept",
                format!(
                    "{:e} is not an intercept a fit on metres and radians gives (at most \
                     {MAX_COEFFICIENT} in magnitude)",
                    self.intercept
                ),
            );
        }
        if !(self.alpha.is_finite() && self.alpha >= 0.0) {
            return invalid("alpha", format!("{} is not finite and >= 0", self.alpha));
        }
        if !self.validation_r2.is_finite() {
            return invalid(
                "validation_r2",
                format!("{} is not finite", self.validation_r2),
            );
        }
        Ok(())
    }
}

/// A saved model's field `field` is wrong: `m` says how, in the file's terms.
fn invalid(field: &str, m: String) -> Result<()> {
    Err(Error::Invalid(format!("{field}: {m}")))
}

/// The largest |coefficient| (and |intercept|) a saved model may have. Each coefficient multiplies a feature
/// standardized on the training data (unit variance), so it is the error, in metres or radians, that one
/// standard deviation of the feature explains; the intercept is the mean error. Real fits give below 0.1
/// (millimetres and milliradians, a few times more where collinear powers cancel); 1e3 — a kilometre or 160
/// turns per standard deviation — is no calibration error, while 1e300 overflows the prediction.
pub const MAX_COEFFICIENT: f64 = 1e3;

/// The largest polynomial degree a saved model may have. The default search stops at 5; an input spread
/// evenly reaches √3 once standardized, whose powers overflow (which the fit refuses) from degree 1292 on.
/// The cap also keeps the feature count from overflowing and a prediction's loop over the powers short.
pub const MAX_DEGREE: usize = 1000;

fn n_features(k: usize, degree: usize, cross: bool) -> usize {
    k * degree
        + if cross {
            k * k.saturating_sub(1) / 2
        } else {
            0
        }
}
