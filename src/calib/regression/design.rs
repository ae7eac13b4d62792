//! The target-independent half of the regression ([`Design`]: standardized features of every candidate at the
//! largest degree and their Gram matrices), the sums one target adds ([`Target`]), and the solve of one
//! structure on sub-blocks of the Grams ([`Block`]); see the module notes of `regression`.

use std::collections::HashMap;
use std::sync::{Arc, Mutex, PoisonError};

use nalgebra::{DMatrix, DVector, DVectorView};

use super::cholesky;
use super::model::RidgeModel;
use super::stats::{r2_from_sums, standardization, zero_sum_tol};
use crate::error::{Error, Result};
use crate::numeric;

/// Everything that does not depend on the target: standardized features of all candidates at the largest
/// degree (column `c·D + p − 1` is candidate `c` to the power `p`; then the cross products of candidate
/// pairs) and their Gram matrices.
pub(super) struct Design {
    n_cand: usize,
    pub(super) max_degree: usize,
    cross: bool,
    input_mean: Vec<f64>,
    input_scale: Vec<f64>,
    /// Candidates that vary on the training set; the others can explain nothing and are never selected.
    usable: Vec<bool>,
    feature_mean: Vec<f64>,
    feature_scale: Vec<f64>,
    /// Features constant on the training set, whose training column is zeroed.
    constant: Vec<bool>,
    f_train: DMatrix<f64>,
    f_val: DMatrix<f64>,
    g_train: DMatrix<f64>,
    g_val: DMatrix<f64>,
}

impl Design {
    pub(super) fn new(
        x_train: &DMatrix<f64>,
        x_val: &DMatrix<f64>,
        max_degree: usize,
        cross: bool,
    ) -> Result<Design> {
        let (n, c) = x_train.shape();
        let mut input_mean = Vec::with_capacity(c);
        let mut input_scale = Vec::with_capacity(c);
        let mut usable = Vec::with_capacity(c);
        for col in x_train.column_iter() {
            let (m, s) = standardization(col.iter().copied(), n);
            input_mean.push(m);
            input_scale.push(s.unwrap_or(1.0));
            usable.push(s.is_some());
        }
        let cross = cross && max_degree >= 2;
        let n_pairs = if cross {
            c * c.saturating_sub(1) / 2
        } else {
            0
        };
        let p = c * max_degree + n_pairs;
        let raw = |x| raw_features(x, &input_mean, &input_scale, max_degree, cross, p);
        let mut f_train = raw(x_train);
        let mut f_val = raw(x_val);
        if f_train.iter().chain(f_val.iter()).any(|v| !v.is_finite()) {
            return Err(overflow(
                &[x_train, x_val],
                &input_mean,
                &input_scale,
                max_degree,
            ));
        }
        let mut feature_mean = Vec::with_capacity(p);
        let mut feature_scale = Vec::with_capacity(p);
        let mut constant = Vec::with_capacity(p);
        for j in 0..p {
            let (m, s) = standardization(f_train.column(j).iter().copied(), n);
            let scale = s.unwrap_or(1.0);
            feature_mean.push(m);
            feature_scale.push(scale);
            constant.push(s.is_none());
            match s {
                // A constant feature (z² of a two-valued input) carries nothing; exact zeros give it a
                // zero coefficient instead of one fitted to rounding noise.
                None => f_train.column_mut(j).fill(0.0),
                Some(_) => f_train.column_mut(j).apply(|v| *v = (*v - m) / scale),
            }
            f_val.column_mut(j).apply(|v| *v = (*v - m) / scale);
        }
        let (g_train, g_val) = (gram(&f_train), gram(&f_val));
        Ok(Design {
            n_cand: c,
            max_degree,
            cross,
            input_mean,
            input_scale,
            usable,
            feature_mean,
            feature_scale,
            constant,
            f_train,
            f_val,
            g_train,
            g_val,
        })
    }

    /// Validation residuals `y_val − ŷ` of a fitted structure, written into `res`; only the few structures that
    /// compete for the final choice need them. `idx`: a buffer for the structure's feature columns.
    pub(super) fn val_residuals(
        &self,
        target: &Target,
        (inputs, degree): (&[usize], usize),
        w: &[f64],
        idx: &mut Vec<usize>,
        res: &mut Vec<f64>,
    ) {
        self.feature_indices_into(inputs, degree, idx);
        // Column by column (contiguous), each row's sum in feature order as a row-wise sum would take it; the
        // first column's products start the sums, and the residuals overwrite them in place.
        let rows = self.f_val.nrows();
        let column = |j: usize| &self.f_val.as_slice()[j * rows..(j + 1) * rows];
        res.clear();
        match idx.first().zip(w.first()) {
            Some((&j, &wj)) => res.extend(column(j).iter().map(|f| f * wj)),
            None => res.resize(rows, 0.0),
        }
        // Four columns per pass over the rows: each row still adds its terms one by one in feature order.
        let (rest, w_rest) = (idx.get(1..).unwrap_or(&[]), w.get(1..).unwrap_or(&[]));
        let n_rest = rest.len().min(w_rest.len());
        let quads = n_rest / 4 * 4;
        for (q, wq) in rest[..quads].chunks_exact(4).zip(w_rest.chunks_exact(4)) {
            let [c0, c1, c2, c3] = [0, 1, 2, 3].map(|t| column(q[t]));
            let [w0, w1, w2, w3] = [wq[0], wq[1], wq[2], wq[3]];
            for (i, a) in res.iter_mut().enumerate() {
                let mut v = *a;
                v += c0[i] * w0;
                v += c1[i] * w1;
                v += c2[i] * w2;
                v += c3[i] * w3;
                *a = v;
            }
        }
        for (&j, &wj) in rest[quads..n_rest].iter().zip(&w_rest[quads..]) {
            res.iter_mut()
                .zip(column(j))
                .for_each(|(a, f)| *a += f * wj);
        }
        res.iter_mut()
            .zip(target.r.iter())
            .for_each(|(a, r)| *a = r - *a);
    }

    /// [`RidgeModel::predict`] of `model` (fitted on this design) at every training row, then every validation
    /// row, bit for bit: a feature column holds `(p − mean)/scale` of the same powers `predict` forms, so the
    /// sum `intercept + Σ c·f` taken column by column in feature order is `predict`'s, row by row. `None` where
    /// a feature of the model is constant on the training rows (its training column is zeroed).
    pub(super) fn fitted(&self, model: &RidgeModel) -> Option<(Vec<f64>, Vec<f64>)> {
        let idx = self.feature_indices(&model.inputs, model.degree);
        if idx.len() != model.coef.len() || idx.iter().any(|&j| self.constant[j]) {
            return None;
        }
        let sum = |f: &DMatrix<f64>| {
            let rows = f.nrows();
            let mut acc = vec![model.intercept; rows];
            for (&j, &c) in idx.iter().zip(&model.coef) {
                let column = &f.as_slice()[j * rows..(j + 1) * rows];
                acc.iter_mut().zip(column).for_each(|(a, v)| *a += c * v);
            }
            acc
        };
        Some((sum(&self.f_train), sum(&self.f_val)))
    }

    /// Columns of the model on `inputs` (rank order) at `degree`, in [`RidgeModel::predict`]'s order.
    pub(super) fn feature_indices(&self, inputs: &[usize], degree: usize) -> Vec<usize> {
        let mut idx = Vec::new();
        self.feature_indices_into(inputs, degree, &mut idx);
        idx
    }

    /// [`Design::feature_indices`] written into `idx`.
    pub(super) fn feature_indices_into(
        &self,
        inputs: &[usize],
        degree: usize,
        idx: &mut Vec<usize>,
    ) {
        idx.clear();
        idx.extend(
            inputs
                .iter()
                .flat_map(|&k| (0..degree).map(move |d| k * self.max_degree + d)),
        );
        if self.crossed(degree) {
            let c = self.n_cand;
            for (i, &a) in inputs.iter().enumerate() {
                for &b in &inputs[i + 1..] {
                    let (lo, hi) = (a.min(b), a.max(b));
                    idx.push(c * self.max_degree + lo * c - lo * (lo + 1) / 2 + (hi - lo - 1));
                }
            }
        }
    }

    /// Whether the features at `degree` hold cross products of the inputs, which fall among the powers: without
    /// them the features of the top k inputs are the leading ones of the top k + 1's.
    pub(super) fn crossed(&self, degree: usize) -> bool {
        self.cross && degree >= 2
    }

    /// The usable candidates in rank order of |Pearson r| with the target on training data (ties by index),
    /// those with |r| ≥ `min_correlation` (at least the best, at most `max_inputs`; 0: no limit).
    pub(super) fn ranked_inputs(
        &self,
        target: &Target,
        min_correlation: f64,
        max_inputs: usize,
    ) -> Vec<usize> {
        let mut ranked: Vec<(usize, f64)> = (0..self.n_cand)
            .filter(|&c| self.usable[c])
            .map(|c| {
                let j = c * self.max_degree;
                let denom = (self.g_train[(j, j)] * target.yy).sqrt();
                (
                    c,
                    if denom > 0.0 {
                        (target.b[j] / denom).abs()
                    } else {
                        0.0
                    },
                )
            })
            .collect();
        ranked.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
        let limit = if max_inputs == 0 {
            usize::MAX
        } else {
            max_inputs
        };
        ranked
            .iter()
            .enumerate()
            .take_while(|(i, (_, r))| *i == 0 || *r >= min_correlation)
            .take(limit)
            .map(|(_, (c, _))| *c)
            .collect()
    }
}

/// The target-dependent sums: `Fᵀ(y − ȳ)` on training data and, with `r = y_val − ȳ` (the residual of the
/// intercept alone), `Fᵥᵀr` and `rᵀr`.
pub(super) struct Target {
    mean: f64,
    pub(super) constant: bool,
    yy: f64,
    b: DVector<f64>,
    cv: DVector<f64>,
    r: DVector<f64>,
    pub(super) rr: f64,
    sst_val: f64,
    tol_val: f64,
}

impl Target {
    pub(super) fn new(design: &Design, y: &[f64], y_val: &[f64]) -> Target {
        let n = y.len();
        let (mean, sd) = standardization(y.iter().copied(), n);
        let yc = DVector::from_iterator(n, y.iter().map(|v| v - mean));
        let r = DVector::from_iterator(y_val.len(), y_val.iter().map(|v| v - mean));
        let val_mean = y_val.iter().sum::<f64>() / y_val.len() as f64;
        Target {
            mean,
            constant: sd.is_none(),
            yy: yc.norm_squared(),
            b: design.f_train.tr_mul(&yc),
            cv: design.f_val.tr_mul(&r),
            rr: r.norm_squared(),
            r,
            sst_val: y_val.iter().map(|v| (v - val_mean).powi(2)).sum(),
            tol_val: zero_sum_tol(y_val),
        }
    }

    fn r2(&self, sse: f64) -> f64 {
        r2_from_sums(sse, self.sst_val, self.tol_val)
    }
}

/// The Gram sub-blocks of one (inputs, degree) structure, reused across α.
pub(super) struct Block {
    g: DMatrix<f64>,
    gv: DMatrix<f64>,
    b: DVector<f64>,
    cv: DVector<f64>,
}

impl Block {
    pub(super) fn new(design: &Design, target: &Target, idx: &[usize]) -> Block {
        let n = idx.len();
        Block {
            g: DMatrix::from_fn(n, n, |a, b| design.g_train[(idx[a], idx[b])]),
            gv: DMatrix::from_fn(n, n, |a, b| design.g_val[(idx[a], idx[b])]),
            b: DVector::from_fn(n, |a, _| target.b[idx[a]]),
            cv: DVector::from_fn(n, |a, _| target.cv[idx[a]]),
        }
    }

    /// Ridge coefficients and the validation SSE they give.
    pub(super) fn solve(&self, target: &Target, alpha: f64) -> (DVector<f64>, f64) {
        let n = self.g.nrows();
        let w = match self.shifted(alpha).cholesky() {
            Some(ch) => ch.solve(&self.b),
            // Only with α = 0 (or α lost in rounding) on collinear features; the minimum-norm solution is
            // the limit of ridge as α → 0.
            None => {
                // A Gram matrix that is not finite gives NaN coefficients and a NaN score, which the
                // search never chooses, rather than an SVD that never returns.
                match numeric::svd(self.shifted(alpha), true, true, "ridge") {
                    Ok(svd) => {
                        let eps = svd.singular_values.max() * n as f64 * f64::EPSILON;
                        svd.solve(&self.b, eps)
                            .unwrap_or_else(|_| DVector::zeros(n))
                    }
                    Err(_) => DVector::from_element(n, f64::NAN),
                }
            }
        };
        let sse = target.rr - 2.0 * w.dot(&self.cv) + w.dot(&(&self.gv * &w));
        (w, sse.max(0.0))
    }

    /// [`Block::solve`] on each leading `m × m` sub-block, `m` in `sizes`, from one factorization of the whole;
    /// `each(k, w, sse)` receives the solution of `sizes[k]` (`w` lives until the next call).
    /// The leading block of a Cholesky factor is the factor of the leading block, and [`cholesky`] computes it
    /// by nalgebra's operations in nalgebra's order (the factorization goes column by column, each entry from
    /// the columns before it; the forward substitution and the matrix–vector product work entry by entry), so
    /// each solution is bit for bit the one of the sub-block alone. Where the whole does not factor (collinear
    /// features at α ≈ 0), each sub-block is solved on its own.
    /// `factor`: the block's factor at `alpha` ([`Block::factors`]); `scratch`: buffers reused from call to call.
    pub(super) fn solve_leading(
        &self,
        target: &Target,
        alpha: f64,
        sizes: &[usize],
        factor: Option<&[f64]>,
        scratch: &mut Scratch,
        mut each: impl FnMut(usize, DVectorView<f64>, f64),
    ) {
        let Some(l) = factor else {
            for (k, &m) in sizes.iter().enumerate() {
                let (w, sse) = self.leading(m).solve(target, alpha);
                each(k, w.as_view(), sse);
            }
            return;
        };
        let p = self.b.len();
        let Scratch { forward, w, gw } = scratch;
        forward.clear();
        forward.extend_from_slice(self.b.as_slice());
        // One buffer for every size's solution and one for its product with the validation Gram, with nothing
        // allocated per call; each size writes the entries it reads.
        for v in [&mut *w, &mut *gw] {
            if v.len() < p {
                v.resize(p, 0.0);
            }
        }
        // The forward substitution too goes entry by entry: its leading rows are each sub-block's.
        cholesky::solve_lower(l, forward);
        let (gv, cv) = (self.gv.as_slice(), self.cv.as_slice());
        for (k, &m) in sizes.iter().enumerate() {
            let (wm, gwm) = (&mut w[..m], &mut gw[..m]);
            wm.copy_from_slice(&forward[..m]);
            cholesky::solve_upper_transposed(l, p, wm);
            cholesky::gemv(gv, p, wm, gwm);
            let sse = target.rr - 2.0 * cholesky::dot(wm, &cv[..m]) + cholesky::dot(wm, gwm);
            each(k, DVectorView::from_slice(wm, m), sse.max(0.0));
        }
    }

    /// The Cholesky factors of the training Gram block plus each of `alphas` on its diagonal (nalgebra's bits,
    /// by [`cholesky::factor_shifted`]), one after another in one buffer.
    pub(super) fn factors(&self, alphas: &[f64]) -> Grid {
        let p = self.g.nrows();
        let g = self.g.as_slice();
        let mut data = Vec::with_capacity(alphas.len() * g.len());
        let neg = &mut Vec::with_capacity(p);
        let ok = alphas
            .iter()
            .map(|&alpha| cholesky::factor_shifted(g, alpha, p, &mut data, neg))
            .collect();
        Grid { p, data, ok }
    }

    /// The training Gram block plus `alpha` on its diagonal.
    fn shifted(&self, alpha: f64) -> DMatrix<f64> {
        let mut a = self.g.clone();
        for i in 0..a.nrows() {
            a[(i, i)] += alpha;
        }
        a
    }

    /// The block of the first `m` features.
    fn leading(&self, m: usize) -> Block {
        Block {
            g: self.g.view((0, 0), (m, m)).clone_owned(),
            gv: self.gv.view((0, 0), (m, m)).clone_owned(),
            b: self.b.rows(0, m).clone_owned(),
            cv: self.cv.rows(0, m).clone_owned(),
        }
    }
}

/// A structure's factors of `G + αI` at each α of a grid, one `p × p` column-major matrix after another in one
/// buffer: a factor's lower triangle is the Cholesky factor (nalgebra's bits), its strict upper triangle `G`'s.
pub(super) struct Grid {
    p: usize,
    data: Vec<f64>,
    /// Whether the matrix at each α factored.
    ok: Vec<bool>,
}

impl Grid {
    /// The factor at the `a`-th α of the grid; `None` where `G + αI` does not factor.
    pub(super) fn at(&self, a: usize) -> Option<&[f64]> {
        let len = self.p * self.p;
        self.ok[a].then(|| &self.data[a * len..(a + 1) * len])
    }
}

/// [`Block::solve_leading`]'s working vectors (the forward substitution, a solution, its product with the
/// validation Gram), kept across its calls instead of three allocations per structure and α.
#[derive(Default)]
pub(super) struct Scratch {
    forward: Vec<f64>,
    w: Vec<f64>,
    gw: Vec<f64>,
}

/// [`Block::factors`] kept from one fit to the next on the same design: a factor depends on the features and
/// α, not on the target, and `residual-ridge`'s rounds search the same structures on new residuals. Those the
/// latest fit did not use are dropped, so it holds at most one fit's worth.
#[derive(Default)]
pub(super) struct Factors {
    /// By feature columns.
    map: HashMap<Vec<usize>, Kept>,
    fit: u64,
}

/// One block's factors: the α grid's bits, the factor at each α, and the fit that last used them.
type Kept = (Vec<u64>, SharedGrid, u64);

impl Factors {
    /// The factors of `block` (on features `idx`) at each of `alphas`, computed on first use: one look-up per
    /// block, not per α, and no key built where the block is kept.
    pub(super) fn get(&mut self, block: &Block, idx: &[usize], alphas: &[f64]) -> SharedGrid {
        let fit = self.fit;
        if let Some(entry) = self.map.get_mut(idx) {
            if !same_bits(&entry.0, alphas) {
                entry.0 = alphas.iter().map(|a| a.to_bits()).collect();
                entry.1 = Arc::new(block.factors(alphas));
            }
            entry.2 = fit;
            return entry.1.clone();
        }
        let made = Arc::new(block.factors(alphas));
        let bits = alphas.iter().map(|a| a.to_bits()).collect();
        self.map.insert(idx.to_vec(), (bits, made.clone(), fit));
        made
    }

    /// Ends a fit: drops what it did not use.
    pub(super) fn finish_fit(&mut self) {
        let fit = self.fit;
        self.map.retain(|_, (_, _, used)| *used == fit);
        self.fit += 1;
    }
}

/// Whether `bits` are the bits of `alphas`, one by one.
fn same_bits(bits: &[u64], alphas: &[f64]) -> bool {
    bits.len() == alphas.len() && bits.iter().zip(alphas).all(|(b, a)| *b == a.to_bits())
}

/// [`Block::factors`] kept for every fit on one design, from any thread: the same factors whichever fit computed
/// them first (a function of the features and α alone). All are kept until the design is dropped.
#[derive(Default)]
pub(super) struct SharedFactors {
    /// By feature columns: for each α grid met (its bits), the factor at each of its α.
    map: Mutex<HashMap<Vec<usize>, Vec<GridOf>>>,
}

/// An α grid's bits and a structure's factors at each of its α.
type GridOf = (Vec<u64>, SharedGrid);

/// The factors of one structure at each α of a grid, shared.
type SharedGrid = Arc<Grid>;

impl SharedFactors {
    /// The factors of `block` (on features `idx`) at every α of `alphas`, in order, computed on first use
    /// (outside the lock: a fit that computed them too keeps the first): one look-up per structure, not per α,
    /// and no key built where the structure is kept.
    pub(super) fn get_all(&self, block: &Block, idx: &[usize], alphas: &[f64]) -> SharedGrid {
        let lock = || self.map.lock().unwrap_or_else(PoisonError::into_inner);
        let find = |grids: &[GridOf]| {
            grids
                .iter()
                .find(|(bits, _)| same_bits(bits, alphas))
                .map(|(_, f)| f.clone())
        };
        if let Some(f) = lock().get(idx).and_then(|grids| find(grids)) {
            return f;
        }
        let made = Arc::new(block.factors(alphas));
        let mut map = lock();
        let grids = map.entry(idx.to_vec()).or_default();
        find(grids).unwrap_or_else(|| {
            let bits = alphas.iter().map(|a| a.to_bits()).collect();
            grids.push((bits, made.clone()));
            made
        })
    }
}

/// Where a search takes its factorizations from.
pub(super) enum FactorSource<'a> {
    /// Each computed where it is used.
    None,
    /// Kept from one fit to the next by one owner.
    Own(&'a mut Factors),
    /// Kept for every fit on the design.
    Shared(&'a SharedFactors),
}

/// `fᵀf`, each entry below the diagonal the one above: `tr_mul`'s dot product of two columns takes the same
/// products in the same order whichever comes first.
fn gram(f: &DMatrix<f64>) -> DMatrix<f64> {
    let p = f.ncols();
    let mut g = DMatrix::zeros(p, p);
    for j in 0..p {
        for i in 0..=j {
            let v = f.column(i).dot(&f.column(j));
            g[(i, j)] = v;
            g[(j, i)] = v;
        }
    }
    g
}

/// The polynomial features of `x`'s rows, standardized inputs to the powers 1..=`max_degree` (column
/// `c·D + p − 1`), then with `cross` the products of input pairs; `p` columns in all.
fn raw_features(
    x: &DMatrix<f64>,
    input_mean: &[f64],
    input_scale: &[f64],
    max_degree: usize,
    cross: bool,
    p: usize,
) -> DMatrix<f64> {
    let c = input_mean.len();
    let rows = x.nrows();
    let mut f = DMatrix::<f64>::zeros(rows, p);
    for r in 0..rows {
        let z = |k: usize| (x[(r, k)] - input_mean[k]) / input_scale[k];
        for k in 0..c {
            let zk = z(k);
            let mut v = zk;
            for d in 0..max_degree {
                f[(r, k * max_degree + d)] = v;
                v *= zk;
            }
        }
        if cross {
            let mut col = c * max_degree;
            for a in 0..c {
                for b in a + 1..c {
                    f[(r, col)] = z(a) * z(b);
                    col += 1;
                }
            }
        }
    }
    f
}

/// The error for features that overflow: the input value furthest from its training mean, in standard
/// deviations, over the rows of `xs`.
fn overflow(
    xs: &[&DMatrix<f64>],
    input_mean: &[f64],
    input_scale: &[f64],
    max_degree: usize,
) -> Error {
    let c = input_mean.len();
    // The cause is an input far from the others (an outlier, a wrong unit), not the degree.
    let (mut worst, mut at) = (0.0_f64, 0);
    for x in xs {
        for r in 0..x.nrows() {
            for k in 0..c {
                let z = ((x[(r, k)] - input_mean[k]) / input_scale[k]).abs();
                if z.is_nan() || z > worst {
                    (worst, at) = (z, k);
                }
            }
        }
    }
    Error::Invalid(format!(
        "regression: polynomial features of degree {max_degree} overflow: a value of input {} lies \
         {worst:.1e} standard deviations from its training mean (an outlier or a wrong unit in the data)",
        at + 1
    ))
}

/// The model of one structure: its coefficients `w` (on the standardized features) with the design's
/// standardization and the target's mean.
pub(super) fn build(
    design: &Design,
    target: &Target,
    inputs: &[usize],
    degree: usize,
    alpha: f64,
    w: &[f64],
    sse: f64,
) -> RidgeModel {
    let idx = design.feature_indices(inputs, degree);
    RidgeModel {
        inputs: inputs.to_vec(),
        degree,
        alpha,
        cross_terms: design.crossed(degree) && inputs.len() >= 2,
        input_mean: inputs.iter().map(|&c| design.input_mean[c]).collect(),
        input_scale: inputs.iter().map(|&c| design.input_scale[c]).collect(),
        feature_mean: idx.iter().map(|&j| design.feature_mean[j]).collect(),
        feature_scale: idx.iter().map(|&j| design.feature_scale[j]).collect(),
        coef: w.to_vec(),
        intercept: target.mean,
        validation_r2: target.r2(sse),
    }
}
