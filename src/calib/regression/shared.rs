//! Several ridge models evaluated together at one row of candidates, each feature computed once.
//!
//! A paper method regresses each of its error parameters (up to 42) on the same candidate columns, standardized
//! with the same training means and scales, and standardizes each power of an input with the same training
//! statistics: the parameters' models differ in which inputs they keep, their degree and coefficients, not in the
//! features themselves. [`RidgeModel::predict`] computes every model's features anew — about 1100 standardized
//! powers at a point of `paper-rotxyz-transxyz` where some 50 differ. Here an input and a feature are shared
//! only where their column, power and statistics are the same to the bit, so every model's value is
//! [`RidgeModel::predict`]'s: the same features summed in the same order.

use super::model::RidgeModel;

/// The distinct standardized inputs and features of a set of models, and each model's terms over them.
#[derive(Clone, Debug, Default)]
pub struct SharedFeatures {
    inputs: Vec<Input>,
    features: Vec<Feature>,
    models: Vec<Terms>,
    /// The inputs' powers, input after input (each input's degree of them).
    powers: usize,
}

/// A candidate column standardized with one training mean and scale, and the highest power any model takes.
#[derive(Clone, Debug)]
struct Input {
    column: usize,
    mean: f64,
    scale: f64,
    degree: usize,
}

/// A power (from 1) of an input, standardized with one training mean and scale; `at`: where that power is
/// among every input's.
#[derive(Clone, Debug)]
struct Feature {
    input: usize,
    power: usize,
    mean: f64,
    scale: f64,
    at: usize,
}

/// One model: its intercept, its powers' coefficients and features in its feature order, then its cross terms
/// (coefficient, the two inputs, the product's mean and scale).
#[derive(Clone, Debug)]
struct Terms {
    intercept: f64,
    powers: Vec<(f64, usize)>,
    cross: Vec<(f64, usize, usize, f64, f64)>,
}

impl SharedFeatures {
    /// The shared features of `models`; `None` where a model's lists do not have one entry per input and
    /// feature (a model that did not come from a fit or a validated file), which [`RidgeModel::predict`]
    /// reads differently.
    pub fn of<'a>(models: impl IntoIterator<Item = &'a RidgeModel>) -> Option<SharedFeatures> {
        let mut shared = SharedFeatures::default();
        for m in models {
            let k = m.inputs.len();
            let p = m.n_features();
            if m.input_mean.len() != k
                || m.input_scale.len() != k
                || m.coef.len() != p
                || m.feature_mean.len() != p
                || m.feature_scale.len() != p
            {
                return None;
            }
            let inputs: Vec<usize> = (0..k)
                .map(|i| shared.input(m.inputs[i], m.input_mean[i], m.input_scale[i], m.degree))
                .collect();
            let mut f = 0;
            let mut powers = Vec::with_capacity(k * m.degree);
            for &input in &inputs {
                for power in 1..=m.degree {
                    let feature =
                        shared.feature(input, power, m.feature_mean[f], m.feature_scale[f]);
                    powers.push((m.coef[f], feature));
                    f += 1;
                }
            }
            let mut cross = Vec::new();
            if m.cross_terms {
                for a in 0..k {
                    for b in a + 1..k {
                        let (c, mean, scale) = (m.coef[f], m.feature_mean[f], m.feature_scale[f]);
                        cross.push((c, inputs[a], inputs[b], mean, scale));
                        f += 1;
                    }
                }
            }
            shared.models.push(Terms {
                intercept: m.intercept,
                powers,
                cross,
            });
        }
        let mut first = Vec::with_capacity(shared.inputs.len());
        for input in &shared.inputs {
            first.push(shared.powers);
            shared.powers += input.degree;
        }
        for f in &mut shared.features {
            f.at = first[f.input] + f.power - 1;
        }
        Some(shared)
    }

    /// The models this was built of.
    pub fn len(&self) -> usize {
        self.models.len()
    }

    pub fn is_empty(&self) -> bool {
        self.models.is_empty()
    }

    /// The index of the input standardizing `column` by `mean` and `scale`, raised to at least `degree`.
    fn input(&mut self, column: usize, mean: f64, scale: f64, degree: usize) -> usize {
        let same = |i: &Input| {
            i.column == column
                && i.mean.to_bits() == mean.to_bits()
                && i.scale.to_bits() == scale.to_bits()
        };
        match self.inputs.iter().position(same) {
            Some(i) => {
                self.inputs[i].degree = self.inputs[i].degree.max(degree);
                i
            }
            None => {
                self.inputs.push(Input {
                    column,
                    mean,
                    scale,
                    degree,
                });
                self.inputs.len() - 1
            }
        }
    }

    /// The index of `input`'s `power` standardized by `mean` and `scale`.
    fn feature(&mut self, input: usize, power: usize, mean: f64, scale: f64) -> usize {
        let same = |f: &Feature| {
            f.input == input
                && f.power == power
                && f.mean.to_bits() == mean.to_bits()
                && f.scale.to_bits() == scale.to_bits()
        };
        self.features.iter().position(same).unwrap_or_else(|| {
            self.features.push(Feature {
                input,
                power,
                mean,
                scale,
                at: 0,
            });
            self.features.len() - 1
        })
    }

    /// Every model's [`RidgeModel::predict`] at `candidates`, in the order the models were given.
    ///
    /// Panics if `candidates` is shorter than the largest column a model reads.
    pub fn predict(&self, candidates: &[f64]) -> Vec<f64> {
        // The standardized inputs, their powers as `predict` raises them (one product a power, from the input
        // itself) and the standardized powers, in one buffer (filled, not zeroed first).
        let (n_inputs, n_powers) = (self.inputs.len(), self.powers);
        let mut buffer = Vec::with_capacity(n_inputs + n_powers + self.features.len());
        buffer.extend(
            self.inputs
                .iter()
                .map(|i| (candidates[i.column] - i.mean) / i.scale),
        );
        for (i, input) in self.inputs.iter().enumerate() {
            let zi = buffer[i];
            let mut p = zi;
            for _ in 0..input.degree {
                buffer.push(p);
                p *= zi;
            }
        }
        for f in &self.features {
            let value = (buffer[n_inputs + f.at] - f.mean) / f.scale;
            buffer.push(value);
        }
        let (z, rest) = buffer.split_at(n_inputs);
        let features = &rest[n_powers..];
        self.models
            .iter()
            .map(|m| {
                let mut acc = m.intercept;
                for &(c, f) in &m.powers {
                    acc += c * features[f];
                }
                for &(c, a, b, mean, scale) in &m.cross {
                    acc += c * ((z[a] * z[b] - mean) / scale);
                }
                acc
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// A model on the candidate columns `inputs`, each column's and power's statistics a function of them alone
    /// (as one design's models share theirs), its coefficients drawn.
    fn model(rng: &mut ChaCha8Rng, inputs: &[usize], degree: usize, cross: bool) -> RidgeModel {
        let stats = |c: usize| (0.1 * c as f64 - 0.3, 0.2 + 0.05 * c as f64);
        let feature = |c: usize, p: usize| {
            (
                0.01 * (c * p) as f64,
                1.0 + 0.1 * p as f64 + 0.01 * c as f64,
            )
        };
        let k = inputs.len();
        let mut feature_mean = Vec::new();
        let mut feature_scale = Vec::new();
        for &c in inputs {
            for p in 1..=degree {
                feature_mean.push(feature(c, p).0);
                feature_scale.push(feature(c, p).1);
            }
        }
        let pairs = if cross { k * (k - 1) / 2 } else { 0 };
        for _ in 0..pairs {
            feature_mean.push(rng.random_range(-0.5..0.5));
            feature_scale.push(rng.random_range(0.5..2.0));
        }
        RidgeModel {
            inputs: inputs.to_vec(),
            degree,
            alpha: 1e-3,
            cross_terms: cross,
            input_mean: inputs.iter().map(|&c| stats(c).0).collect(),
            input_scale: inputs.iter().map(|&c| stats(c).1).collect(),
            coef: (0..feature_mean.len())
                .map(|_| rng.random_range(-1e-3..1e-3))
                .collect(),
            feature_mean,
            feature_scale,
            intercept: rng.random_range(-1e-3..1e-3),
            validation_r2: 0.5,
        }
    }

    #[test]
    fn every_model_predicts_its_own_bits() {
        let mut rng = ChaCha8Rng::seed_from_u64(27);
        let mut models = vec![
            model(&mut rng, &[3, 0, 7, 9], 3, false),
            model(&mut rng, &[7, 3, 1], 5, false),
            model(&mut rng, &[9, 3, 0, 2], 2, true),
            model(&mut rng, &[], 0, false),
            model(&mut rng, &[4], 1, false),
        ];
        // A column standardized with other statistics is a feature of its own.
        let mut other = model(&mut rng, &[3, 7], 3, false);
        other.input_mean[0] += 1e-9;
        other.feature_scale[4] *= 1.0 + 1e-12;
        models.push(other);
        let shared = SharedFeatures::of(&models).unwrap();
        assert_eq!(shared.len(), models.len());
        // Column 3's and 7's standardizations appear twice; column 3's powers are shared across models.
        assert_eq!(shared.inputs.len(), 8);
        assert!(
            shared.features.len()
                < models
                    .iter()
                    .map(|m| m.inputs.len() * m.degree)
                    .sum::<usize>()
        );
        for _ in 0..200 {
            let row: Vec<f64> = (0..10).map(|_| rng.random_range(-2.0..2.0)).collect();
            let together = shared.predict(&row);
            for (m, v) in models.iter().zip(&together) {
                assert_eq!(m.predict(&row).to_bits(), v.to_bits());
            }
        }
    }

    #[test]
    fn a_model_with_short_lists_is_not_shared() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let mut m = model(&mut rng, &[0, 1], 2, false);
        m.coef.pop();
        assert!(SharedFeatures::of([&m]).is_none());
    }
}
