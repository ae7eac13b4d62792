//! Ridge regression of each error parameter on polynomial features of candidate inputs (paper §3,
//! eqs. 17–20), with the inputs chosen by correlation and the degree and α by validation R².
//!
//! The selection search fits hundreds of models per error parameter, and a campaign sweep runs thousands of
//! calibrations, so fitting must not touch the data rows once per model. The candidate features do not
//! depend on the target: the standardized features of every candidate at the largest degree, and their
//! training and validation Gram matrices, are built once per call. A model is then a Cholesky solve on a
//! sub-block of the training Gram, and its validation error follows from the validation Gram,
//! `SSE = rᵀr − 2wᵀFᵥᵀr + wᵀ(FᵥᵀFᵥ)w`, without another pass over the rows.
//!
//! Standardization (inputs, then features, both on training statistics) exists because α penalizes all
//! coefficients alike: without it the penalty would depend on whether an input is in radians or metres and
//! on the size of `x⁵`. The intercept is left unpenalized by centring features and target, so a constant
//! offset in an error parameter is never shrunk.

mod cholesky;
mod design;
mod model;
mod shared;
mod stats;

use std::ops::Range;
use std::sync::{Arc, Mutex, PoisonError};

use nalgebra::{DMatrix, DVectorView};
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use design::{Block, Design, FactorSource, Factors, Scratch, SharedFactors, Target, build};
pub use model::{MAX_COEFFICIENT, MAX_DEGREE, RidgeModel};
pub use shared::SharedFeatures;
pub use stats::r2;

/// Search space of [`fit_all`].
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(default)]
pub struct RegressionOptions {
    /// Highest polynomial degree tried; every degree from 1 up is tried.
    pub max_degree: usize,
    /// Penalties tried, in the sum form of eq. 19 (`‖Fw − y‖² + α‖w‖²` on standardized features, so α is
    /// comparable with the number of training points). Finite and ≥ 0.
    pub alphas: Vec<f64>,
    /// Candidates whose |Pearson r| with the target (training data) is below this are left out, as the
    /// paper keeps only inputs "that displayed significant correlation"; the best one is always kept.
    pub min_correlation: f64,
    /// At most this many inputs per model; 0 means no limit (0 rather than `usize::MAX` so the options
    /// survive TOML, whose integers are i64).
    pub max_inputs: usize,
    /// Adds the pairwise products of the inputs for degrees ≥ 2. Off by default: eq. 18 has no cross terms.
    pub cross_terms: bool,
    /// A model with more features replaces the current choice only if its validation SSE is lower by more
    /// than this many standard errors of the paired per-point difference of squared residuals (1: the
    /// one-standard-error rule). It automates the paper's reading of "the progression of R²": an
    /// irrelevant input or degree raises validation R² by chance so often that the plain maximum (0)
    /// picks one up in about half the fits of a known polynomial, and a fixed relative margin would be too
    /// lax at small N and too strict at large N. On simulated polynomials and smooth targets, 1 predicted
    /// fresh points 5–10 % better than 0 except at N = 40 with heavy noise (5 % worse); 2 and more underfit
    /// at small N.
    pub parsimony_z: f64,
}

impl Default for RegressionOptions {
    fn default() -> Self {
        RegressionOptions {
            max_degree: 5,
            alphas: (0..=20)
                .map(|i| 10f64.powf(-8.0 + 0.5 * i as f64))
                .collect(),
            min_correlation: 0.05,
            max_inputs: 0,
            cross_terms: false,
            parsimony_z: 1.0,
        }
    }
}

/// One model per column of `y_train`. Rows are points, columns of x are candidate inputs.
///
/// Per target: candidates ranked by |Pearson r| on training data, those with |r| ≥ `min_correlation` kept
/// (at least the best, at most `max_inputs`); the input sets are the top k for k = 1, 2, … (the paper's
/// progression of R² as another input is added), each at every degree and α. For each (inputs, degree) the
/// α with the best validation R² is taken (ties → the larger α); among those, models are visited from
/// fewest features up and a larger one is taken only if it beats the current choice significantly
/// (`parsimony_z`). Models with more features than training points − 1 are skipped. A constant target, or
/// one with no varying candidate, gets an intercept-only model.
///
/// Screening by plain correlation is the paper's, with its blind spot: an input that acts only through an
/// even function (cos of a joint angle over a symmetric range) or only in a product has |r| ≈ 0 and is
/// dropped; `min_correlation: 0.0` admits every candidate in rank order.
///
/// Errors (`Error::Invalid`): shapes that disagree, a NaN or infinite value, no validation rows, fewer than
/// 2 training rows (the smallest model has 1 feature plus the intercept), `max_degree` 0, or an empty,
/// negative or non-finite α grid.
pub fn fit_all(
    x_train: &DMatrix<f64>,
    y_train: &DMatrix<f64>,
    x_val: &DMatrix<f64>,
    y_val: &DMatrix<f64>,
    opts: &RegressionOptions,
) -> Result<Vec<RidgeModel>> {
    Candidates::new(x_train.clone(), x_val.clone()).fit(y_train, y_val, opts)
}

/// The candidate rows of [`fit_all`] kept for several calls on the same rows: their standardized features and
/// Gram matrices are built once, on the first fit (`residual-ridge` refits its residual on the same joint
/// angles every registration round, the paper's method its position and orientation parameters on the same
/// candidates). Each [`Candidates::fit`] gives what `fit_all` gives on the same arguments.
pub struct Candidates {
    x_train: DMatrix<f64>,
    x_val: DMatrix<f64>,
    /// The design and the (`max_degree`, `cross_terms`) it was built for.
    design: Option<((usize, bool), Design)>,
    /// Factorizations kept for the next fit ([`Candidates::keeping_factors`]).
    factors: Option<Factors>,
}

impl Candidates {
    pub fn new(x_train: DMatrix<f64>, x_val: DMatrix<f64>) -> Candidates {
        Candidates {
            x_train,
            x_val,
            design: None,
            factors: None,
        }
    }

    /// Keeps the factorizations of `G + αI` on each structure searched (they depend on the features and α,
    /// not on the target) for the targets and fits after, where several targets rank the candidates alike or
    /// a later fit searches the same structures: the same numbers, each factorization done once. It holds
    /// one fit's worth (those a fit did not use are dropped at its end): up to the α grid's length ×
    /// `max_degree` × the targets' distinct rankings, each at most `max_degree` × candidates features square.
    pub fn keeping_factors(mut self) -> Candidates {
        self.factors = Some(Factors::default());
        self
    }

    /// [`fit_all`] on these candidate rows.
    pub fn fit(
        &mut self,
        y_train: &DMatrix<f64>,
        y_val: &DMatrix<f64>,
        opts: &RegressionOptions,
    ) -> Result<Vec<RidgeModel>> {
        check_inputs(&self.x_train, y_train, &self.x_val, y_val, opts)?;
        let n = self.x_train.nrows();
        let key = (opts.max_degree, opts.cross_terms);
        let design = match &mut self.design {
            Some((k, design)) if *k == key => design,
            slot => {
                let design = Design::new(&self.x_train, &self.x_val, key.0, key.1)?;
                if let Some(f) = &mut self.factors {
                    *f = Factors::default();
                }
                &mut slot.insert((key, design)).1
            }
        };
        let mut alphas = opts.alphas.clone();
        alphas.sort_by(|a, b| b.total_cmp(a));
        alphas.dedup();
        let factors = &mut self.factors;
        let models = y_train
            .column_iter()
            .zip(y_val.column_iter())
            .map(|(y, yv)| {
                let y: Vec<f64> = y.iter().copied().collect();
                let yv: Vec<f64> = yv.iter().copied().collect();
                let target = Target::new(design, &y, &yv);
                let source = match factors.as_mut() {
                    Some(f) => FactorSource::Own(f),
                    None => FactorSource::None,
                };
                fit_one(design, &target, n, &alphas, opts, source)
            })
            .collect();
        if let Some(f) = factors {
            f.finish_fit();
        }
        models
    }
}

impl Candidates {
    /// [`RidgeModel::predict`] of `model`, fitted by the latest [`Candidates::fit`], at every training row and
    /// every validation row, bit for bit, from the search's own feature columns; `None` where it cannot say
    /// (no fit yet, a model of another design, a feature constant on the training rows).
    pub fn fitted(&self, model: &RidgeModel) -> Option<(Vec<f64>, Vec<f64>)> {
        let (_, design) = self.design.as_ref()?;
        design.fitted(model)
    }
}

/// [`Candidates`] for several fits at once, from any thread: the paper's three error models, fitted on the same
/// campaign, regress on the same candidate rows, and their parameters often rank the candidates alike. The
/// design is built by the first fit and every factorization is kept for all of them (until this is dropped),
/// so each [`SharedCandidates::fit`] gives what [`fit_all`] gives on the same arguments, bit for bit, whatever
/// the order in which the fits run.
pub struct SharedCandidates {
    x_train: DMatrix<f64>,
    x_val: DMatrix<f64>,
    /// The design, for the (`max_degree`, `cross_terms`) of the first fit.
    design: Mutex<Option<DesignFor>>,
    factors: SharedFactors,
}

/// A design and the (`max_degree`, `cross_terms`) it was built for.
type DesignFor = ((usize, bool), Arc<Design>);

impl SharedCandidates {
    pub fn new(x_train: DMatrix<f64>, x_val: DMatrix<f64>) -> SharedCandidates {
        SharedCandidates {
            x_train,
            x_val,
            design: Mutex::new(None),
            factors: SharedFactors::default(),
        }
    }

    /// [`fit_all`] on these candidate rows.
    pub fn fit(
        &self,
        y_train: &DMatrix<f64>,
        y_val: &DMatrix<f64>,
        opts: &RegressionOptions,
    ) -> Result<Vec<RidgeModel>> {
        check_inputs(&self.x_train, y_train, &self.x_val, y_val, opts)?;
        let key = (opts.max_degree, opts.cross_terms);
        let lock = || self.design.lock().unwrap_or_else(PoisonError::into_inner);
        let kept = lock().clone();
        let design = match kept {
            Some((k, design)) if k == key => design,
            // Options of another search than the design's: a design of its own, nothing shared.
            Some(_) => {
                return Candidates::new(self.x_train.clone(), self.x_val.clone())
                    .fit(y_train, y_val, opts);
            }
            None => {
                // Built outside the lock; a fit that built it too keeps the first.
                let made = Arc::new(Design::new(&self.x_train, &self.x_val, key.0, key.1)?);
                lock().get_or_insert((key, made)).1.clone()
            }
        };
        let n = self.x_train.nrows();
        let mut alphas = opts.alphas.clone();
        alphas.sort_by(|a, b| b.total_cmp(a));
        alphas.dedup();
        y_train
            .column_iter()
            .zip(y_val.column_iter())
            .map(|(y, yv)| {
                let y: Vec<f64> = y.iter().copied().collect();
                let yv: Vec<f64> = yv.iter().copied().collect();
                let target = Target::new(&design, &y, &yv);
                let source = FactorSource::Shared(&self.factors);
                fit_one(&design, &target, n, &alphas, opts, source)
            })
            .collect()
    }
}

fn check_inputs(
    x_train: &DMatrix<f64>,
    y_train: &DMatrix<f64>,
    x_val: &DMatrix<f64>,
    y_val: &DMatrix<f64>,
    opts: &RegressionOptions,
) -> Result<()> {
    let invalid = |m: String| Err(Error::Invalid(format!("regression: {m}")));
    if x_train.nrows() != y_train.nrows() || x_val.nrows() != y_val.nrows() {
        return invalid(format!(
            "row counts differ: x_train {}, y_train {}, x_val {}, y_val {}",
            x_train.nrows(),
            y_train.nrows(),
            x_val.nrows(),
            y_val.nrows()
        ));
    }
    if x_train.ncols() != x_val.ncols() || y_train.ncols() != y_val.ncols() {
        return invalid(format!(
            "column counts differ: x_train {} vs x_val {}, y_train {} vs y_val {}",
            x_train.ncols(),
            x_val.ncols(),
            y_train.ncols(),
            y_val.ncols()
        ));
    }
    for (name, m) in [
        ("x_train", x_train),
        ("y_train", y_train),
        ("x_val", x_val),
        ("y_val", y_val),
    ] {
        if let Some(i) = m.iter().position(|v| !v.is_finite()) {
            let (r, c) = (i % m.nrows(), i / m.nrows());
            return invalid(format!("{name} row {r} column {c} is {}", m[(r, c)]));
        }
    }
    if x_train.nrows() < 2 {
        return invalid(format!(
            "{} training points are fewer than the 2 needed by the smallest model (1 feature plus intercept)",
            x_train.nrows()
        ));
    }
    if x_val.nrows() == 0 {
        return invalid("no validation points to choose the model on".into());
    }
    if opts.max_degree == 0 {
        return invalid("max_degree must be at least 1".into());
    }
    if opts.alphas.is_empty() || opts.alphas.iter().any(|a| !a.is_finite() || *a < 0.0) {
        return invalid(format!(
            "alphas must be non-empty, finite and >= 0, got {:?}",
            opts.alphas
        ));
    }
    if !opts.min_correlation.is_finite() || !opts.parsimony_z.is_finite() || opts.parsimony_z < 0.0
    {
        return invalid(format!(
            "min_correlation {} and parsimony_z {} must be finite, parsimony_z >= 0",
            opts.min_correlation, opts.parsimony_z
        ));
    }
    Ok(())
}

/// The winner among the α of one structure: the top `k + 1` inputs of the ranking at `degree`, its coefficients
/// at `w` of the search's buffer.
struct RidgeFit {
    k: usize,
    degree: usize,
    n_features: usize,
    alpha: f64,
    w: Range<usize>,
    sse: f64,
}

fn fit_one(
    design: &Design,
    target: &Target,
    n: usize,
    alphas: &[f64],
    opts: &RegressionOptions,
    factors: FactorSource,
) -> Result<RidgeModel> {
    let intercept_only = || build(design, target, &[], 0, 0.0, &[], target.rr);
    if target.constant {
        return Ok(intercept_only());
    }
    let order = design.ranked_inputs(target, opts.min_correlation, opts.max_inputs);
    if order.is_empty() {
        return Ok(intercept_only());
    }
    let (fitted, ws) = fit_structures(design, target, &order, n, alphas, factors);
    let choice = choose(design, target, (&order, &ws), fitted, n, opts.parsimony_z)?;
    Ok(build(
        design,
        target,
        &order[..=choice.k],
        choice.degree,
        choice.alpha,
        &ws[choice.w],
        choice.sse,
    ))
}

/// Every structure (the top k of `order` at each degree) that `n` training points can fit, each with the α
/// that gives the lowest validation SSE, and one buffer holding all their coefficients.
///
/// Without cross terms the features of the top k inputs at a degree are the leading ones of the top k + 1's
/// ([`Design::feature_indices`] lists them input by input), so one factorization per degree and α serves every
/// k ([`Block::solve_leading`]); with cross terms the products of a new input fall among the old ones', and
/// each structure is solved on its own.
fn fit_structures(
    design: &Design,
    target: &Target,
    order: &[usize],
    n: usize,
    alphas: &[f64],
    mut factors: FactorSource,
) -> (Vec<RidgeFit>, Vec<f64>) {
    let mut fitted = Vec::new();
    let mut ws = Vec::new();
    let scratch = &mut Scratch::default();
    let (mut sizes, mut largest) = (Vec::new(), Vec::new());
    let mut found = Vec::new();
    for degree in 1..=design.max_degree {
        // The feature count grows with k: the structures `n` points can fit are the first few.
        let (nested, blocks) = if design.crossed(degree) {
            let idx: Vec<Vec<usize>> = (1..=order.len())
                .map(|k| design.feature_indices(&order[..k], degree))
                .take_while(|idx| idx.len() < n)
                .collect();
            let Some(last) = idx.last() else {
                continue;
            };
            sizes.clear();
            sizes.extend(idx.iter().map(Vec::len));
            largest.clone_from(last);
            let nested = idx.iter().all(|i| largest.starts_with(i));
            let blocks: Vec<Block> = if nested {
                vec![Block::new(design, target, &largest)]
            } else {
                idx.iter().map(|i| Block::new(design, target, i)).collect()
            };
            (nested, blocks)
        } else {
            // The top k inputs' features are k · degree, the leading ones of the largest set's.
            let count = order.len().min((n - 1) / degree);
            if count == 0 {
                continue;
            }
            sizes.clear();
            sizes.extend((1..=count).map(|k| k * degree));
            design.feature_indices_into(&order[..count], degree, &mut largest);
            (true, vec![Block::new(design, target, &largest)])
        };
        // Every α's factor of a nested structure at once: one look-up per structure, not per α.
        let grid = nested.then(|| match &mut factors {
            FactorSource::Own(f) => f.get(&blocks[0], &largest, alphas),
            FactorSource::Shared(f) => f.get_all(&blocks[0], &largest, alphas),
            FactorSource::None => Arc::new(blocks[0].factors(alphas)),
        });
        // α descending, strict improvement: equal scores keep the stronger penalty. Each size's best so far
        // (α, coefficients, SSE) in the buffer's part for it, overwritten where a later α beats it.
        let first = fitted.len();
        let mut at = ws.len();
        for (k, &m) in sizes.iter().enumerate() {
            fitted.push(RidgeFit {
                k,
                degree,
                n_features: m,
                alpha: f64::NAN,
                w: at..at + m,
                sse: f64::NAN,
            });
            at += m;
        }
        ws.resize(at, 0.0);
        let best = &mut fitted[first..];
        found.clear();
        found.resize(sizes.len(), false);
        for (a, &alpha) in alphas.iter().enumerate() {
            let mut keep = |k: usize, w: DVectorView<f64>, sse: f64| {
                let b = &mut best[k];
                if !found[k] || sse < b.sse {
                    b.alpha = alpha;
                    ws[b.w.clone()].copy_from_slice(w.as_slice());
                    b.sse = sse;
                    found[k] = true;
                }
            };
            match &grid {
                Some(grid) => {
                    blocks[0].solve_leading(target, alpha, &sizes, grid.at(a), scratch, keep)
                }
                None => {
                    for (k, b) in blocks.iter().enumerate() {
                        let (w, sse) = b.solve(target, alpha);
                        keep(k, w.as_view(), sse);
                    }
                }
            }
        }
        assert!(found.iter().all(|&f| f), "alphas is non-empty");
    }
    (fitted, ws)
}

/// The structure chosen: from the fewest features up, a larger one replaces the choice only if its validation
/// SSE is lower by more than `parsimony_z` standard errors of the paired difference (see
/// [`RegressionOptions::parsimony_z`]). `order` and `ws`: the ranking and the coefficients' buffer of `fitted`.
fn choose(
    design: &Design,
    target: &Target,
    (order, ws): (&[usize], &[f64]),
    mut fitted: Vec<RidgeFit>,
    n: usize,
    parsimony_z: f64,
) -> Result<RidgeFit> {
    fitted.sort_by_key(|f| (f.n_features, f.k));
    let mut fitted = fitted.into_iter();
    let Some(mut choice) = fitted.next() else {
        return Err(Error::Invalid(format!(
            "regression: {n} training points are fewer than the 2 needed by the smallest model (1 feature \
             plus intercept)"
        )));
    };
    let idx = &mut Vec::new();
    let mut residuals = |f: &RidgeFit, res: &mut Vec<f64>| {
        let structure = (&order[..=f.k], f.degree);
        design.val_residuals(target, structure, &ws[f.w.clone()], idx, res);
    };
    let (mut choice_res, mut res) = (Vec::new(), Vec::new());
    residuals(&choice, &mut choice_res);
    for f in fitted {
        if f.sse >= choice.sse {
            continue;
        }
        residuals(&f, &mut res);
        let d = || choice_res.iter().zip(&res).map(|(a, b)| a * a - b * b);
        let m = choice_res.len().min(res.len()) as f64;
        let gain = d().sum::<f64>();
        let var = d().map(|v| (v - gain / m).powi(2)).sum::<f64>() / (m - 1.0).max(1.0);
        if gain > parsimony_z * (m * var).sqrt() {
            choice = f;
            std::mem::swap(&mut choice_res, &mut res);
        }
    }
    Ok(choice)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DVector;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, Normal};

    fn uniform(rng: &mut ChaCha8Rng, rows: usize, cols: usize, half: f64) -> DMatrix<f64> {
        DMatrix::from_fn(rows, cols, |_, _| rng.random_range(-half..half))
    }

    fn truth(x: &[f64]) -> f64 {
        0.3 + 2.0 * x[1] - 0.5 * x[1] * x[1] + 0.1 * x[3].powi(3)
    }

    const NOISE: f64 = 0.01;

    /// y = truth(x) + N(0, NOISE²) on five candidates uniform in [−3, 3], where the cubic term is large
    /// enough (|r| ≈ 0.24) to pass correlation screening clearly above the noise inputs (|r| ≈ 0.04).
    fn poly_data(seed: u64, rows: usize) -> (DMatrix<f64>, DMatrix<f64>) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let x = uniform(&mut rng, rows, 5, 3.0);
        let noise = Normal::new(0.0, NOISE).unwrap();
        let y = DMatrix::from_fn(rows, 1, |r, _| {
            let row: Vec<f64> = x.row(r).iter().copied().collect();
            truth(&row) + noise.sample(&mut rng)
        });
        (x, y)
    }

    fn row(x: &DMatrix<f64>, r: usize) -> Vec<f64> {
        x.row(r).iter().copied().collect()
    }

    #[test]
    fn recovers_known_polynomial() {
        let (xt, yt) = poly_data(1, 600);
        let (xv, yv) = poly_data(2, 300);
        let m = &fit_all(&xt, &yt, &xv, &yv, &RegressionOptions::default()).unwrap()[0];
        assert!(m.validation_r2 > 0.99, "{m:?}");
        let mut inputs = m.inputs.clone();
        inputs.sort();
        assert_eq!(inputs, vec![1, 3], "{m:?}");
        assert_eq!(m.degree, 3);
        let (xf, _) = poly_data(3, 500);
        let errs: Vec<f64> = (0..500)
            .map(|r| m.predict(&row(&xf, r)) - truth(&row(&xf, r)))
            .collect();
        let rms = (errs.iter().map(|e| e * e).sum::<f64>() / errs.len() as f64).sqrt();
        let max = errs.iter().fold(0.0f64, |a, e| a.max(e.abs()));
        assert!(rms < 0.3 * NOISE && max < NOISE, "rms {rms}, max {max}");
    }

    #[test]
    fn recovery_is_robust_across_seeds() {
        // Counted rather than required per seed: the one-standard-error rule still admits a chance input
        // now and then, which the plain maximum (parsimony_z = 0) does in about half the fits.
        let count = |z: f64| {
            (0..40)
                .filter(|&seed| {
                    let (xt, yt) = poly_data(100 + seed, 600);
                    let (xv, yv) = poly_data(200 + seed, 300);
                    let opts = RegressionOptions {
                        parsimony_z: z,
                        ..Default::default()
                    };
                    let m = &fit_all(&xt, &yt, &xv, &yv, &opts).unwrap()[0];
                    let mut inputs = m.inputs.clone();
                    inputs.sort();
                    (inputs, m.degree) == (vec![1, 3], 3)
                })
                .count()
        };
        let (plain, default) = (count(0.0), count(1.0));
        assert!(
            default >= 32 && default > plain,
            "exact structure in {default}/40 (plain maximum {plain}/40)"
        );
    }

    #[test]
    fn pure_noise_gives_r2_near_zero() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let noise = Normal::new(0.0, 1.0).unwrap();
        let (xt, xv, xf) = (
            uniform(&mut rng, 600, 5, 2.0),
            uniform(&mut rng, 300, 5, 2.0),
            uniform(&mut rng, 500, 5, 2.0),
        );
        let yt = DMatrix::from_fn(600, 1, |_, _| noise.sample(&mut rng));
        let yv = DMatrix::from_fn(300, 1, |_, _| noise.sample(&mut rng));
        let m = &fit_all(&xt, &yt, &xv, &yv, &RegressionOptions::default()).unwrap()[0];
        assert!(m.validation_r2.abs() < 0.05, "{m:?}");
        assert!(
            m.coef.iter().all(|c| c.is_finite() && c.abs() < 1.0),
            "{m:?}"
        );
        for r in 0..500 {
            let p = m.predict(&row(&xf, r));
            assert!((p - m.intercept).abs() < 0.5, "prediction {p} at row {r}");
        }
    }

    /// Independent ridge: explicit features, augmented least squares `[X; √α I] w = [y − ȳ; 0]` by SVD.
    fn direct_fit(
        x: &DMatrix<f64>,
        y: &[f64],
        inputs: &[usize],
        degree: usize,
        cross: bool,
        alpha: f64,
    ) -> Vec<f64> {
        let n = x.nrows();
        let stats = |v: &[f64]| {
            let m = v.iter().sum::<f64>() / v.len() as f64;
            (
                m,
                (v.iter().map(|a| (a - m).powi(2)).sum::<f64>() / v.len() as f64).sqrt(),
            )
        };
        let z: Vec<Vec<f64>> = inputs
            .iter()
            .map(|&c| {
                let col: Vec<f64> = x.column(c).iter().copied().collect();
                let (m, s) = stats(&col);
                col.iter().map(|v| (v - m) / s).collect()
            })
            .collect();
        let mut feats: Vec<Vec<f64>> = Vec::new();
        for zi in &z {
            for p in 1..=degree {
                feats.push(zi.iter().map(|v| v.powi(p as i32)).collect());
            }
        }
        if cross && degree >= 2 {
            for a in 0..z.len() {
                for b in a + 1..z.len() {
                    feats.push((0..n).map(|r| z[a][r] * z[b][r]).collect());
                }
            }
        }
        let p = feats.len();
        let mut aug = DMatrix::zeros(n + p, p);
        for (j, f) in feats.iter().enumerate() {
            let (m, s) = stats(f);
            for r in 0..n {
                aug[(r, j)] = (f[r] - m) / s;
            }
            aug[(n + j, j)] = alpha.sqrt();
        }
        let ym = y.iter().sum::<f64>() / n as f64;
        let rhs = DVector::from_fn(n + p, |r, _| if r < n { y[r] - ym } else { 0.0 });
        aug.svd(true, true)
            .solve(&rhs, 1e-300)
            .unwrap()
            .iter()
            .copied()
            .collect()
    }

    fn assert_close(a: &[f64], b: &[f64], tol: f64) {
        assert_eq!(a.len(), b.len());
        for (x, y) in a.iter().zip(b) {
            assert!((x - y).abs() <= tol * y.abs().max(1.0), "{a:?} vs {b:?}");
        }
    }

    #[test]
    fn gram_shortcut_matches_direct_fit() {
        let (xt, yt) = poly_data(11, 400);
        let (xv, yv) = poly_data(12, 200);
        let y: Vec<f64> = yt.iter().copied().collect();
        let y_val: Vec<f64> = yv.iter().copied().collect();
        for (cross, inputs, degree, alpha) in [
            (false, vec![1, 3], 3, 1e-3),
            (false, vec![3, 0, 1], 4, 0.5),
            (true, vec![1, 3, 4], 2, 1e-2),
            (true, vec![4, 1], 3, 10.0),
        ] {
            let design = Design::new(&xt, &xv, 5, cross).unwrap();
            let target = Target::new(&design, &y, &y_val);
            let block = Block::new(&design, &target, &design.feature_indices(&inputs, degree));
            let (w, sse) = block.solve(&target, alpha);
            let m = build(&design, &target, &inputs, degree, alpha, w.as_slice(), sse);
            assert_eq!(m.n_features(), w.len());
            assert_close(
                &m.coef,
                &direct_fit(&xt, &y, &inputs, degree, cross, alpha),
                1e-9,
            );
            let pred: Vec<f64> = (0..xv.nrows()).map(|r| m.predict(&row(&xv, r))).collect();
            assert!(
                (m.validation_r2 - r2(&y_val, &pred)).abs() < 1e-9,
                "{} vs {}",
                m.validation_r2,
                r2(&y_val, &pred)
            );
        }
        // The model fit_all picks obeys the same identities.
        let opts = RegressionOptions {
            cross_terms: true,
            ..Default::default()
        };
        let m = &fit_all(&xt, &yt, &xv, &yv, &opts).unwrap()[0];
        assert_close(
            &m.coef,
            &direct_fit(&xt, &y, &m.inputs, m.degree, m.cross_terms, m.alpha),
            1e-9,
        );
        let pred: Vec<f64> = (0..xv.nrows()).map(|r| m.predict(&row(&xv, r))).collect();
        assert!((m.validation_r2 - r2(&y_val, &pred)).abs() < 1e-9);
    }

    /// One factorization per degree and α serves every nested input set: each leading solve equals the solve
    /// of its block alone bit for bit, and fits that keep their factorizations give `fit_all`'s models.
    #[test]
    fn leading_solves_equal_each_block_alone() {
        let (xt, yt) = poly_data(13, 300);
        let (xv, yv) = poly_data(14, 150);
        let (y, y_val): (Vec<f64>, Vec<f64>) =
            (yt.iter().copied().collect(), yv.iter().copied().collect());
        let design = Design::new(&xt, &xv, 5, false).unwrap();
        let target = Target::new(&design, &y, &y_val);
        let order = [3, 1, 0, 4];
        for degree in [1, 3, 5] {
            let idx = design.feature_indices(&order, degree);
            let block = Block::new(&design, &target, &idx);
            let sizes: Vec<usize> = (1..=order.len()).map(|k| k * degree).collect();
            for alpha in [0.0, 1e-8, 1e-2, 30.0] {
                let mut leading = Vec::new();
                block.solve_leading(
                    &target,
                    alpha,
                    &sizes,
                    block.factors(&[alpha]).at(0),
                    &mut Scratch::default(),
                    |_, w, sse| leading.push((w.into_owned(), sse)),
                );
                for (k, (w, sse)) in leading.iter().enumerate() {
                    let alone = Block::new(&design, &target, &idx[..sizes[k]]);
                    let (w1, sse1) = alone.solve(&target, alpha);
                    assert_eq!(
                        sse.to_bits(),
                        sse1.to_bits(),
                        "degree {degree}, α {alpha}, k {k}"
                    );
                    assert_eq!(w.len(), w1.len());
                    assert!(w.iter().zip(&w1).all(|(a, b)| a.to_bits() == b.to_bits()));
                }
            }
        }
        let opts = RegressionOptions::default();
        let mut kept = Candidates::new(xt.clone(), xv.clone()).keeping_factors();
        let want = fit_all(&xt, &yt, &xv, &yv, &opts).unwrap();
        for _ in 0..2 {
            assert_eq!(kept.fit(&yt, &yv, &opts).unwrap(), want);
        }
        // Shared by two fits at once whose targets rank the inputs alike (the same target negated): they take
        // each other's factorizations, and each gives `fit_all`'s models.
        let shared = SharedCandidates::new(xt.clone(), xv.clone());
        let (nt, nv) = (-yt.clone(), -yv.clone());
        let want_neg = fit_all(&xt, &nt, &xv, &nv, &opts).unwrap();
        std::thread::scope(|s| {
            let a = s.spawn(|| shared.fit(&yt, &yv, &opts).unwrap());
            let b = s.spawn(|| shared.fit(&nt, &nv, &opts).unwrap());
            assert_eq!(a.join().unwrap(), want);
            assert_eq!(b.join().unwrap(), want_neg);
        });
        assert_eq!(shared.fit(&yt, &yv, &opts).unwrap(), want);
    }

    #[test]
    fn serde_round_trip_predicts_identically() {
        let (xt, yt) = poly_data(21, 300);
        let (xv, yv) = poly_data(22, 150);
        let opts = RegressionOptions {
            cross_terms: true,
            ..Default::default()
        };
        let m = fit_all(&xt, &yt, &xv, &yv, &opts).unwrap().remove(0);
        // TOML, not JSON: serde_json parses floats exactly only with its `float_roundtrip` feature.
        let back: RidgeModel = toml::from_str(&toml::to_string(&m).unwrap()).unwrap();
        assert_eq!(back, m);
        let (xf, _) = poly_data(23, 200);
        for r in 0..200 {
            let x = row(&xf, r);
            assert_eq!(m.predict(&x).to_bits(), back.predict(&x).to_bits());
        }
        let opts_back: RegressionOptions =
            toml::from_str(&toml::to_string(&opts).unwrap()).unwrap();
        assert_eq!(opts_back, opts);
    }

    #[test]
    fn rejects_bad_input() {
        let (xt, yt) = poly_data(31, 50);
        let (xv, yv) = poly_data(32, 20);
        let opts = RegressionOptions::default();
        let one = fit_all(
            &xt.rows(0, 1).into(),
            &yt.rows(0, 1).into(),
            &xv,
            &yv,
            &opts,
        );
        let msg = one.unwrap_err().to_string();
        assert!(msg.contains("1 training points are fewer than"), "{msg}");
        let mut bad = xt.clone();
        bad[(4, 2)] = f64::NAN;
        let msg = fit_all(&bad, &yt, &xv, &yv, &opts).unwrap_err().to_string();
        assert!(msg.contains("x_train row 4 column 2 is NaN"), "{msg}");
        let mut bad = yv.clone();
        bad[(3, 0)] = f64::INFINITY;
        assert!(fit_all(&xt, &yt, &xv, &bad, &opts).is_err());
        assert!(fit_all(&xt, &yt, &xv.rows(0, 5).into(), &yv, &opts).is_err());
        for bad in [
            RegressionOptions {
                max_degree: 0,
                ..opts.clone()
            },
            RegressionOptions {
                alphas: vec![],
                ..opts.clone()
            },
            RegressionOptions {
                alphas: vec![-1.0],
                ..opts.clone()
            },
        ] {
            assert!(fit_all(&xt, &yt, &xv, &yv, &bad).is_err());
        }
    }

    #[test]
    fn large_models_are_skipped_when_rows_are_few() {
        // 8 rows: at most 7 features, so degree 5 on two inputs (10 features) is never fitted.
        let (xt, yt) = poly_data(41, 8);
        let (xv, yv) = poly_data(42, 20);
        let m = &fit_all(&xt, &yt, &xv, &yv, &RegressionOptions::default()).unwrap()[0];
        assert!(m.n_features() < 8, "{m:?}");
    }

    #[test]
    fn constant_columns() {
        let (mut xt, yt) = poly_data(51, 200);
        let (mut xv, yv) = poly_data(52, 100);
        // The true input made constant can never be selected, however the ranking would go.
        xt.column_mut(1).fill(0.7);
        xv.column_mut(1).fill(0.7);
        let m = &fit_all(&xt, &yt, &xv, &yv, &RegressionOptions::default()).unwrap()[0];
        assert!(!m.inputs.contains(&1), "{m:?}");

        let zeros = DMatrix::zeros(200, 1);
        let m = &fit_all(
            &xt,
            &zeros,
            &xv,
            &DMatrix::zeros(100, 1),
            &RegressionOptions::default(),
        )
        .unwrap()[0];
        assert!(m.inputs.is_empty() && m.coef.is_empty() && m.n_features() == 0);
        assert_eq!((m.intercept, m.validation_r2), (0.0, 1.0));
        let m = &fit_all(
            &xt,
            &zeros.add_scalar(0.1),
            &xv,
            &yv,
            &RegressionOptions::default(),
        )
        .unwrap()[0];
        assert!(m.inputs.is_empty() && m.validation_r2 < 0.0, "{m:?}");
        assert!((m.predict(&row(&xv, 0)) - 0.1).abs() < 1e-15);
        assert_eq!(r2(&[0.1; 4], &[0.1 + 1e-17; 4]), 1.0);
        assert_eq!(r2(&[0.1; 4], &[0.2; 4]), 0.0);
    }

    #[test]
    fn cross_terms_recover_a_product() {
        let mut rng = ChaCha8Rng::seed_from_u64(61);
        let (xt, xv) = (
            uniform(&mut rng, 400, 4, 1.0),
            uniform(&mut rng, 200, 4, 1.0),
        );
        // Both factors must correlate with the target on their own to pass the correlation screening.
        let f = |x: &DMatrix<f64>| {
            DMatrix::from_fn(x.nrows(), 1, |r, _| {
                x[(r, 0)] + 0.5 * x[(r, 2)] + x[(r, 0)] * x[(r, 2)]
            })
        };
        let with = RegressionOptions {
            cross_terms: true,
            ..Default::default()
        };
        let m = &fit_all(&xt, &f(&xt), &xv, &f(&xv), &with).unwrap()[0];
        assert!(m.cross_terms && m.validation_r2 > 0.999_999, "{m:?}");
        let m = &fit_all(&xt, &f(&xt), &xv, &f(&xv), &RegressionOptions::default()).unwrap()[0];
        assert!(!m.cross_terms && m.validation_r2 < 0.9, "{m:?}");
    }

    /// A calibration's worth of regression: 17 error parameters, 1167 training and 580 validation points,
    /// 10 candidates (7 joint angles, 3 TCP coordinates that depend on them), smooth targets of three
    /// candidates each. Timed with the default screening and with every candidate admitted (the largest
    /// search: 10 input sets × 5 degrees × 21 α, up to 50 features).
    #[test]
    fn timing_of_a_full_calibration() {
        let mut rng = ChaCha8Rng::seed_from_u64(71);
        let noise = Normal::new(0.0, 1e-6).unwrap();
        let make = |rows: usize, rng: &mut ChaCha8Rng| {
            let q = uniform(rng, rows, 7, 2.5);
            let x = DMatrix::from_fn(rows, 10, |r, c| match c {
                0..7 => q[(r, c)],
                7 => 0.4 * q[(r, 0)].cos() * q[(r, 1)].sin() + 0.3 * q[(r, 3)].sin(),
                8 => 0.4 * q[(r, 0)].sin() * q[(r, 1)].sin() + 0.3 * q[(r, 2)].cos(),
                _ => 0.4 * q[(r, 1)].cos() + 0.3 * q[(r, 3)].cos(),
            });
            let y = DMatrix::from_fn(rows, 17, |r, t| {
                let (a, b, c) = (t % 7, (t + 2) % 7, 7 + t % 3);
                1e-4 * (0.8 * x[(r, a)] + 0.3 * t as f64).sin()
                    + 5e-5 * (0.5 * x[(r, b)]).cos()
                    + 2e-4 * x[(r, c)]
                    + noise.sample(rng)
            });
            (x, y)
        };
        let (xt, yt) = make(1167, &mut rng);
        let (xv, yv) = make(580, &mut rng);
        for (label, opts) in [
            ("default screening", RegressionOptions::default()),
            (
                "all candidates",
                RegressionOptions {
                    min_correlation: 0.0,
                    ..Default::default()
                },
            ),
        ] {
            let mut best = f64::INFINITY;
            let mut models = Vec::new();
            for _ in 0..5 {
                let t0 = std::time::Instant::now();
                models = fit_all(&xt, &yt, &xv, &yv, &opts).unwrap();
                best = best.min(t0.elapsed().as_secs_f64());
            }
            let r2s: Vec<f64> = models.iter().map(|m| m.validation_r2).collect();
            let inputs: Vec<usize> = models.iter().map(|m| m.inputs.len()).collect();
            println!(
                "fit_all, 17 targets x 1167 rows x 10 candidates, {label}: {:.1} ms (best of 5); \
                 validation R² {:.4}..{:.4}; inputs {inputs:?}",
                best * 1e3,
                r2s.iter().fold(1.0f64, |a, b| a.min(*b)),
                r2s.iter().fold(0.0f64, |a, b| a.max(*b)),
            );
            assert_eq!(models.len(), 17);
            assert!(best < 1.0, "{best} s");
        }
    }
}
