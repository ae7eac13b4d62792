//! What a fitted model was fitted on (issue 13): the range of every joint angle and extra input over its
//! training and validation points, and a sample of those configurations to measure how far a new one lies.
//! A regression evaluated outside that domain extrapolates a polynomial, so the models fade the regression
//! out to their parametric part just beyond it (the constant part of each regression, its intercept: constant
//! error parameters for the paper's models, a constant offset for the residual models, the base alone where
//! a hybrid's residual has none), or
//! farther than [`Domain::radius_rad`] from every training configuration ([`Domain::weight`]); `calibrate` says per
//! point whether it lies inside. Measured on UR10 C → D and C → B (README): holding the inputs at the edge
//! instead leaves `paper-rotxyz` 3.6× and `residual-ridge` 1.2× above `nominal` on D, since a polynomial at
//! its edge still carries its steepest value, and the same joint values on another branch are another pose.

use serde::{Deserialize, Serialize};

use crate::dataset::Dataset;
use crate::error::Result;
use crate::robot::plausible;

/// How far beyond a joint's training range (rad) a regression fades out entirely.
pub const FADE_RAD: f64 = 0.05;
/// The same for an extra input, as a fraction of its training range.
pub const FADE_INPUT: f64 = 0.1;

/// Training configurations kept to measure distances in joint space: evenly spaced in the data's order.
pub const SAMPLE: usize = 400;

#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct Domain {
    /// Per joint, the smallest and largest training angle (rad).
    pub joint_min: Vec<f64>,
    pub joint_max: Vec<f64>,
    /// Per extra input (the data's order), its training range.
    pub input_names: Vec<String>,
    pub input_min: Vec<f64>,
    pub input_max: Vec<f64>,
    /// Up to [`SAMPLE`] training configurations.
    pub sample: Vec<Vec<f64>>,
    /// How far (rad) from the nearest sampled configuration a point may lie and still count as inside:
    /// twice the largest distance of a sampled configuration to its nearest neighbour among the others (the
    /// sample's own spacing), so a point in a hole of the training data, or on another branch within the
    /// same joint ranges, is outside.
    #[serde(default)]
    pub radius_rad: f64,
}

/// Where a point lies against a [`Domain`].
#[derive(Clone, Debug, PartialEq)]
pub struct Placement {
    /// Every joint and extra input within its training range.
    pub inside: bool,
    /// The inputs outside, in words (`elbow_joint -0.52 rad outside [0.00, 2.32]`); empty inside.
    pub outside: Vec<String>,
    /// Joint-space distance (rad, Euclidean over the joints) to the nearest sampled training configuration.
    pub distance_rad: f64,
}

impl Domain {
    /// The domain of `train` and `val` together (what a method fits on).
    pub fn of(train: &Dataset, val: &Dataset) -> Domain {
        let n = train.joint_names.len();
        let q: Vec<&Vec<f64>> = train.q.iter().chain(&val.q).collect();
        let range = |values: &mut dyn Iterator<Item = f64>| {
            values.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
                (lo.min(v), hi.max(v))
            })
        };
        let (joint_min, joint_max) = (0..n).map(|j| range(&mut q.iter().map(|q| q[j]))).unzip();
        let input_names = train.extra_input_names().to_vec();
        let inputs = |d: &Dataset, k: usize| -> Vec<f64> {
            (0..d.len()).map(|i| d.extra_inputs_of(i)[k]).collect()
        };
        let (input_min, input_max) = (0..input_names.len())
            .map(|k| range(&mut inputs(train, k).into_iter().chain(inputs(val, k))))
            .unzip();
        let step = q.len().div_ceil(SAMPLE).max(1);
        let sample: Vec<Vec<f64>> = q.iter().step_by(step).map(|q| q.to_vec()).collect();
        let spacing = Columns::of(&sample).spacing(&sample);
        Domain {
            joint_min,
            joint_max,
            input_names,
            input_min,
            input_max,
            sample,
            radius_rad: 2.0 * spacing,
        }
    }

    /// The weight a regression's correction gets for a point at `q` with `inputs` (evaluated at the point
    /// itself): 1 inside the domain, fading linearly to 0 (the model's parametric part alone) over
    /// [`FADE_RAD`] beyond the joint ranges (the inputs' ranges over [`FADE_INPUT`] of their width), and from
    /// [`Domain::radius_rad`] to 1.25 times that away from the training configurations. Continuous, so a
    /// controller's inverse through the model still converges across the boundary.
    ///
    /// Evaluated at the point, not at the edge: a polynomial held at the edge has a kink there that keeps a
    /// controller's inverse from converging for points on the edge; within the short fade it extrapolates
    /// little.
    pub fn weight(&self, q: &[f64], inputs: &[f64]) -> f64 {
        if self.is_empty() {
            return 1.0;
        }
        // `distance(q, clamp_joints(q))`, without building the clamped vector.
        let clamped = |v: &[f64], lo: &[f64], hi: &[f64], k: usize| {
            if lo.len() == v.len() {
                v[k].clamp(lo[k], hi[k])
            } else {
                v[k]
            }
        };
        let beyond = (0..q.len())
            .map(|k| (q[k] - clamped(q, &self.joint_min, &self.joint_max, k)).powi(2))
            .sum::<f64>()
            .sqrt()
            / FADE_RAD;
        let beyond_inputs = (0..inputs.len().min(self.input_min.len()))
            .map(|k| {
                let c = clamped(inputs, &self.input_min, &self.input_max, k);
                (inputs[k] - c).abs()
                    / (FADE_INPUT * (self.input_max[k] - self.input_min[k])).max(f64::MIN_POSITIVE)
            })
            .fold(0.0, f64::max);
        // Within the radius of some sampled configuration (d − r ≤ 0), the distance adds nothing.
        let far = if self.sample.is_empty()
            || self.radius_rad <= 0.0
            || self.within(q, self.radius_rad)
        {
            0.0
        } else {
            (self.distance(q) - self.radius_rad).max(0.0) / (0.25 * self.radius_rad)
        };
        (1.0 - beyond.max(beyond_inputs).max(far)).clamp(0.0, 1.0)
    }

    /// Whether some sampled training configuration lies within `radius` (rad) of `q`.
    fn within(&self, q: &[f64], radius: f64) -> bool {
        self.sample.iter().any(|s| distance(s, q) <= radius)
    }

    /// Joint-space distance (rad) to the nearest sampled training configuration.
    pub fn distance(&self, q: &[f64]) -> f64 {
        nearest(&self.sample, q)
    }

    /// No domain recorded (a model saved before domains were).
    pub fn is_empty(&self) -> bool {
        self.joint_min.is_empty()
    }

    /// `q` held at the domain's edge, joint by joint.
    pub fn clamp_joints(&self, q: &[f64]) -> Vec<f64> {
        clamp(q, &self.joint_min, &self.joint_max)
    }

    /// Extra inputs held at the domain's edge (empty stays empty: the model's training means).
    pub fn clamp_inputs(&self, inputs: &[f64]) -> Vec<f64> {
        clamp(inputs, &self.input_min, &self.input_max)
    }

    pub fn place(&self, joint_names: &[String], q: &[f64], inputs: &[f64]) -> Placement {
        self.placement(joint_names, q, inputs, self.distance(q))
    }

    /// [`Domain::place`] for each `(q, inputs)` of `points`: the same placements, the distances to the sample
    /// computed a joint at a time over the whole sample (a test split of 584 points against 400 sampled
    /// configurations cost as much as reading the data).
    pub fn place_all<'a>(
        &self,
        joint_names: &[String],
        points: impl IntoIterator<Item = (&'a [f64], &'a [f64])>,
    ) -> Vec<Placement> {
        let columns = Columns::of(&self.sample);
        let mut squared = vec![0.0; self.sample.len()];
        points
            .into_iter()
            .map(|(q, inputs)| {
                columns.squared_distances(q, 0, &mut squared);
                // The nearest by its squared distance: `sqrt` is monotonic, so this is `distance`'s minimum.
                let nearest = squared.iter().copied().fold(f64::INFINITY, f64::min);
                self.placement(joint_names, q, inputs, nearest.sqrt())
            })
            .collect()
    }

    /// Where `q` with `inputs` lies, `distance_rad` from the nearest sampled configuration.
    fn placement(
        &self,
        joint_names: &[String],
        q: &[f64],
        inputs: &[f64],
        distance_rad: f64,
    ) -> Placement {
        let mut outside = Vec::new();
        let mut check = |name: &str, v: f64, lo: f64, hi: f64, unit: &str| {
            if !(lo..=hi).contains(&v) {
                outside.push(format!("{name} {v:.3}{unit} outside [{lo:.3}, {hi:.3}]"));
            }
        };
        for (j, (&lo, &hi)) in self.joint_min.iter().zip(&self.joint_max).enumerate() {
            if let Some(&v) = q.get(j) {
                let name = joint_names
                    .get(j)
                    .cloned()
                    .unwrap_or(format!("joint {}", j + 1));
                check(&name, v, lo, hi, " rad");
            }
        }
        if inputs.len() == self.input_names.len() {
            for (k, name) in self.input_names.iter().enumerate() {
                check(name, inputs[k], self.input_min[k], self.input_max[k], "");
            }
        }
        if distance_rad > self.radius_rad && !self.sample.is_empty() {
            outside.push(format!(
                "{distance_rad:.3} rad from the nearest training configuration (more than {:.3})",
                self.radius_rad
            ));
        }
        Placement {
            inside: outside.is_empty(),
            outside,
            distance_rad,
        }
    }

    /// A domain read from a file is usable: ranges of one length per joint (or none at all), ordered and
    /// finite; sampled configurations of one angle per joint.
    pub fn validate(&self, joints: usize) -> Result<()> {
        if self.is_empty() {
            return Ok(());
        }
        plausible::count("domain.joint_min", self.joint_min.len(), joints, "joints")?;
        plausible::count("domain.joint_max", self.joint_max.len(), joints, "joints")?;
        let k = self.input_names.len();
        plausible::count("domain.input_min", self.input_min.len(), k, "input_names")?;
        plausible::count("domain.input_max", self.input_max.len(), k, "input_names")?;
        for (field, lo, hi) in [
            ("domain.joint", &self.joint_min, &self.joint_max),
            ("domain.input", &self.input_min, &self.input_max),
        ] {
            for (i, (a, b)) in lo.iter().zip(hi).enumerate() {
                if !(a.is_finite() && b.is_finite() && a <= b) {
                    return Err(plausible::invalid(
                        &format!("{field}_min[{i}]"),
                        format!("[{a}, {b}] is not a finite range"),
                    ));
                }
            }
        }
        for (i, s) in self.sample.iter().enumerate() {
            plausible::count(&format!("domain.sample[{i}]"), s.len(), joints, "joints")?;
        }
        Ok(())
    }
}

/// The distance from `q` to the nearest of `sample`, ∞ without any.
fn nearest(sample: &[Vec<f64>], q: &[f64]) -> f64 {
    if q.is_empty() {
        return sample
            .iter()
            .map(|s| distance(s, q))
            .fold(f64::INFINITY, f64::min);
    }
    // The nearest by its sum of squares (the square root is monotone, so the minimum is the same); a partial
    // sum above the best so far can only grow (its terms are ≥ 0), so the rest of it is skipped.
    let mut best = f64::INFINITY;
    for s in sample {
        let mut terms = s.iter().zip(q).map(|(x, y)| (x - y).powi(2));
        let Some(mut sum) = terms.next() else {
            best = best.min(0.0);
            continue;
        };
        for t in terms {
            if sum > best {
                break;
            }
            sum += t;
        }
        best = best.min(sum);
    }
    best.sqrt()
}

fn distance(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).powi(2))
        .sum::<f64>()
        .sqrt()
}

/// Sampled configurations joint by joint, so that the squared distances from one configuration to many are
/// summed a joint at a time over all of them (a loop the compiler vectorises), in [`distance`]'s order.
struct Columns(Vec<Vec<f64>>);

impl Columns {
    fn of(sample: &[Vec<f64>]) -> Columns {
        let joints = sample.iter().map(Vec::len).min().unwrap_or(0);
        Columns(
            (0..joints)
                .map(|j| sample.iter().map(|s| s[j]).collect())
                .collect(),
        )
    }

    /// The squared distances from `q` to the sampled configurations `from..` into `out` (one each).
    /// In blocks of configurations whose sums stay in registers over the joints.
    fn squared_distances(&self, q: &[f64], from: usize, out: &mut [f64]) {
        const BLOCK: usize = 8;
        let whole = out.len();
        let mut blocks = out.chunks_exact_mut(BLOCK);
        for (b, block) in blocks.by_ref().enumerate() {
            let start = from + b * BLOCK;
            let mut sums = [0.0; BLOCK];
            for (column, &v) in self.0.iter().zip(q) {
                let column: &[f64; BLOCK] =
                    column[start..start + BLOCK].try_into().expect("a block");
                for l in 0..BLOCK {
                    sums[l] += (column[l] - v).powi(2);
                }
            }
            block.copy_from_slice(&sums);
        }
        let rest = blocks.into_remainder();
        let start = from + whole - rest.len();
        rest.fill(0.0);
        for (column, &v) in self.0.iter().zip(q) {
            for (o, s) in rest.iter_mut().zip(&column[start..]) {
                *o += (s - v).powi(2);
            }
        }
    }

    /// The largest distance of a configuration of `sample` (the sample these columns hold) to its nearest
    /// neighbour among the others; 0 with fewer than two. Each pair once, both ways: `(a - b)²` is `(b - a)²`.
    fn spacing(&self, sample: &[Vec<f64>]) -> f64 {
        let n = sample.len();
        let mut nearest = vec![f64::INFINITY; n];
        let mut squared = vec![0.0; n];
        for i in 0..n {
            let rest = &mut squared[i + 1..];
            self.squared_distances(&sample[i], i + 1, rest);
            for (k, &d) in rest.iter().enumerate() {
                nearest[i] = nearest[i].min(d);
                nearest[i + 1 + k] = nearest[i + 1 + k].min(d);
            }
        }
        nearest
            .into_iter()
            .filter(|d| d.is_finite())
            .fold(0.0, f64::max)
            .sqrt()
    }
}

fn clamp(v: &[f64], lo: &[f64], hi: &[f64]) -> Vec<f64> {
    if lo.len() != v.len() {
        return v.to_vec();
    }
    v.iter()
        .zip(lo.iter().zip(hi))
        .map(|(x, (a, b))| x.clamp(*a, *b))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// The weight as first written: every sampled configuration's distance, the clamped vectors built.
    fn weight_by_definition(d: &Domain, q: &[f64], inputs: &[f64]) -> f64 {
        let (qc, ic) = (d.clamp_joints(q), d.clamp_inputs(inputs));
        let beyond = distance(q, &qc) / FADE_RAD;
        let beyond_inputs = inputs
            .iter()
            .zip(&ic)
            .zip(d.input_min.iter().zip(&d.input_max))
            .map(|((v, c), (lo, hi))| {
                (v - c).abs() / (FADE_INPUT * (hi - lo)).max(f64::MIN_POSITIVE)
            })
            .fold(0.0, f64::max);
        let nearest = d
            .sample
            .iter()
            .map(|s| distance(s, q))
            .fold(f64::INFINITY, f64::min);
        let far = (nearest - d.radius_rad).max(0.0) / (0.25 * d.radius_rad);
        (1.0 - beyond.max(beyond_inputs).max(far)).clamp(0.0, 1.0)
    }

    /// The pruned searches give the brute force's numbers bit for bit, inside, in the fade and far outside.
    #[test]
    fn pruned_distance_and_weight_equal_the_brute_force() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let sample: Vec<Vec<f64>> = (0..300)
            .map(|_| (0..6).map(|_| rng.random_range(-1.0..1.0)).collect())
            .collect();
        let d = Domain {
            joint_min: vec![-1.0; 6],
            joint_max: vec![1.0; 6],
            input_names: vec!["temperature".into()],
            input_min: vec![20.0],
            input_max: vec![30.0],
            sample: sample.clone(),
            radius_rad: 0.6,
        };
        let mut faded = 0;
        for _ in 0..2000 {
            let q: Vec<f64> = (0..6).map(|_| rng.random_range(-1.6..1.6)).collect();
            let t = [rng.random_range(18.0..32.0)];
            let brute = sample
                .iter()
                .map(|s| distance(s, &q))
                .fold(f64::INFINITY, f64::min);
            assert_eq!(d.distance(&q).to_bits(), brute.to_bits());
            let w = d.weight(&q, &t);
            assert_eq!(w.to_bits(), weight_by_definition(&d, &q, &t).to_bits());
            faded += usize::from(w > 0.0 && w < 1.0);
        }
        assert!(faded > 50, "{faded} points in the fade");
        let spacing = (0..sample.len())
            .map(|i| {
                (0..sample.len())
                    .filter(|&k| k != i)
                    .map(|k| distance(&sample[i], &sample[k]))
                    .fold(f64::INFINITY, f64::min)
            })
            .fold(0.0, f64::max);
        let by_columns = Columns::of(&sample).spacing(&sample);
        assert_eq!(by_columns.to_bits(), spacing.to_bits());
    }
}
