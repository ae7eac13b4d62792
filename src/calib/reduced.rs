//! A tall least-squares problem as the `levenberg-marquardt` crate's equivalent small one: at a point with
//! residuals `r` (m rows) and Jacobian `J` (m × n, m ≫ n), the n + 1 residuals `[a; ρ]` and the (n + 1) × n
//! Jacobian `[R; 0]`, where `RᵀR = JᵀJ`, `Rᵀa = Jᵀr` and `ρ² = ‖r‖² − ‖a‖²`.
//!
//! Why it is the same problem for the crate: Levenberg–Marquardt (MINPACK's `lmder`) uses the Jacobian and
//! the residuals only through `JᵀJ` (its trust-region subproblem), `Jᵀr` (the gradient and its `gtol` test),
//! the column norms of `J` (its scaling) and `‖r‖` (the actual and predicted reductions) — and the small
//! problem has all four equal. In exact arithmetic the crate takes the same steps and stops at the same
//! point; its pivoted QR then factors an (n + 1) × n matrix instead of m × n (on a 1168-point kinematic fit,
//! 3504 × 30: that QR was 40 % of the fit).
//!
//! `R` is the Cholesky factor of the Gram matrix with its columns scaled to unit norm, formed by one matrix
//! product. Forming `JᵀJ` squares the condition number, so it is used only where the scaled Gram is well
//! conditioned (its Cholesky pivots above [`MIN_PIVOT`]: a condition number below about 1e6, i.e. about
//! 1e-10 relative error in the step); otherwise `R` and `a` come from a Householder QR of `J` itself.
//! The callers make it well conditioned: the kinematic fit works in coordinates whitened by its starting
//! Jacobian (columns orthonormal at the start).

use std::cell::RefCell;

use levenberg_marquardt::LeastSquaresProblem;
use nalgebra::{DMatrix, DMatrixView, DVector, Dyn, Owned};

/// Smallest Cholesky pivot of the column-scaled Gram matrix (whose diagonal is 1) for which the normal
/// equations stand in for a QR: the scaled Jacobian's condition number is then at most about `1/MIN_PIVOT`.
pub const MIN_PIVOT: f64 = 1e-3;

/// The small problem at one point: residuals (n + 1) and Jacobian ((n + 1) × n).
#[derive(Clone, Debug)]
pub struct Reduced {
    pub residuals: DVector<f64>,
    pub jacobian: DMatrix<f64>,
}

/// The small problem equivalent to residuals `r` and Jacobian `j` (m × n; the problem itself where m ≤ n + 1);
/// `None` when either is not finite.
pub fn reduce(j: &DMatrix<f64>, r: &DVector<f64>) -> Option<Reduced> {
    reduce_with(j, r, gram)
}

/// [`reduce`] with `JᵀJ` from `gram` (called only on a finite, tall `j`).
fn reduce_with(
    j: &DMatrix<f64>,
    r: &DVector<f64>,
    gram: impl FnOnce(&DMatrix<f64>) -> DMatrix<f64>,
) -> Option<Reduced> {
    let (m, n) = j.shape();
    if !(all_finite(r.as_slice()) && all_finite(j.as_slice())) {
        return None;
    }
    if m <= n + 1 {
        return Some(Reduced {
            residuals: r.clone(),
            jacobian: j.clone(),
        });
    }
    let (upper, a) = from_gram(&gram(j), &j.tr_mul(r)).unwrap_or_else(|| householder(j, r));
    Some(assemble(upper, a, r.norm_squared()))
}

/// The small problem from `JᵀJ`, `Jᵀr` and `‖r‖²` alone (of a tall problem: more than n + 1 rows), through
/// the normal equations; `None` where any is not finite or the column-scaled Gram is not well conditioned
/// (a Cholesky pivot below [`MIN_PIVOT`]): the caller then reduces `J` itself ([`reduce`]).
pub fn reduce_gram(gram: &DMatrix<f64>, jtr: &DVector<f64>, rr: f64) -> Option<Reduced> {
    if !(rr.is_finite() && all_finite(gram.as_slice()) && all_finite(jtr.as_slice())) {
        return None;
    }
    let (upper, a) = from_gram(gram, jtr)?;
    Some(assemble(upper, a, rr))
}

/// `JᵀJ` of `j` (m × n) by one matrix product.
pub fn gram(j: &DMatrix<f64>) -> DMatrix<f64> {
    let (m, n) = j.shape();
    // Jᵀ as a view (strides swapped): the product goes through matrixmultiply's kernels.
    let jt = DMatrixView::from_slice_with_strides(j.as_slice(), n, m, m, 1);
    let mut gram = DMatrix::zeros(n, n);
    gram.gemm(1.0, &jt, j, 0.0);
    gram
}

/// Rows `..moving` of `JᵀJ` of `j` (m × n), and by symmetry its columns `..moving`, into `g`, which holds
/// `gram` of a Jacobian with the same columns after them (the rest of `g` stays); where `g` has the wrong
/// shape, all of [`gram`]. The entries are `gram`'s bit for bit: matrixmultiply sums each entry of a
/// product over the rows of `j` in the same blocks and order whatever the product's shape, and `a·b` is
/// `b·a`, so the mirrored entries are too (`moving_rows_of_the_gram_are_the_gram_s` holds them to it).
/// nalgebra multiplies through matrixmultiply only where every dimension exceeds 5: at least 6 rows are
/// formed.
pub fn gram_rows(j: &DMatrix<f64>, moving: usize, g: &mut DMatrix<f64>) {
    let (m, n) = j.shape();
    let k = moving.max(6);
    if g.shape() != (n, n) || k >= n || m <= 5 {
        *g = gram(j);
        return;
    }
    let jt = DMatrixView::from_slice_with_strides(&j.as_slice()[..k * m], k, m, m, 1);
    let mut rows = DMatrix::zeros(k, n);
    rows.gemm(1.0, &jt, j, 0.0);
    for c in 0..n {
        for r in 0..k {
            g[(r, c)] = rows[(r, c)];
            g[(c, r)] = rows[(r, c)];
        }
    }
}

/// `[R; 0]` and `[a; ρ]` with `ρ² = ‖r‖² − ‖a‖²` (`rr` = `‖r‖²`).
fn assemble(upper: DMatrix<f64>, a: DVector<f64>, rr: f64) -> Reduced {
    let n = a.len();
    let rest2 = (rr - a.norm_squared()).max(0.0);
    let mut residuals = DVector::zeros(n + 1);
    residuals.rows_mut(0, n).copy_from(&a);
    residuals[n] = rest2.sqrt();
    let mut jacobian = DMatrix::zeros(n + 1, n);
    jacobian.view_mut((0, 0), (n, n)).copy_from(&upper);
    Reduced {
        residuals,
        jacobian,
    }
}

/// A tall least-squares problem that writes its residuals and Jacobian into buffers kept by the caller, so
/// an evaluation allocates nothing. Both are functions of the parameters alone.
pub trait Tall {
    fn params(&self) -> DVector<f64>;
    fn set_params(&mut self, x: &DVector<f64>);
    /// The residuals at the parameters into `r` (resized by the problem when its length is wrong).
    fn residuals_into(&self, r: &mut DVector<f64>);
    /// The Jacobian at the parameters into `j` (resized when its shape is wrong). Entries that do not
    /// depend on the parameters may be left as the last call wrote them.
    fn jacobian_into(&self, j: &mut DMatrix<f64>);
    /// `JᵀJ` of the (finite, tall) Jacobian `jacobian_into` just wrote, into `g`: all of it ([`gram`]). A
    /// problem whose Jacobian has columns that do not move may form only the products of those that do
    /// ([`gram_rows`]): `g` holds the last call's.
    fn gram_into(&self, j: &DMatrix<f64>, g: &mut DMatrix<f64>) {
        *g = gram(j);
    }
}

/// A tall problem as the crate's small one: at every point the crate asks about, the inner problem's
/// residuals and Jacobian, reduced.
///
/// A point is evaluated when the crate first asks for its residuals, not when it is set: when a solve ends on
/// a failed try the crate's last call sets its last accepted point again (`reset_params_if`), whose
/// evaluation nothing then reads; that point's parameters are all the caller takes from the solve.
pub struct Small<P> {
    pub inner: P,
    evaluation: RefCell<Evaluation>,
}

/// The buffers of the inner problem and the small problem at its parameters (`None` until evaluated there;
/// `Some(None)` where the residuals or the Jacobian are not finite).
#[derive(Default)]
struct Evaluation {
    r: DVector<f64>,
    j: DMatrix<f64>,
    gram: DMatrix<f64>,
    small: Option<Option<Reduced>>,
}

impl<P: Tall> Small<P> {
    pub fn new(inner: P) -> Small<P> {
        Small {
            inner,
            evaluation: RefCell::new(Evaluation {
                r: DVector::zeros(0),
                j: DMatrix::zeros(0, 0),
                gram: DMatrix::zeros(0, 0),
                small: None,
            }),
        }
    }

    /// `read` of the small problem at the parameters, evaluated first if it is not yet.
    fn at_params<T>(&self, read: impl FnOnce(&Reduced) -> T) -> Option<T> {
        let mut evaluation = self.evaluation.borrow_mut();
        let e = &mut *evaluation;
        let small = e.small.get_or_insert_with(|| {
            self.inner.residuals_into(&mut e.r);
            self.inner.jacobian_into(&mut e.j);
            reduce_with(&e.j, &e.r, |j| {
                self.inner.gram_into(j, &mut e.gram);
                e.gram.clone()
            })
        });
        small.as_ref().map(read)
    }
}

impl<P: Tall> LeastSquaresProblem<f64, Dyn, Dyn> for Small<P> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, Dyn>;
    type ParameterStorage = Owned<f64, Dyn>;

    fn set_params(&mut self, x: &DVector<f64>) {
        self.inner.set_params(x);
        self.evaluation.get_mut().small = None;
    }

    fn params(&self) -> DVector<f64> {
        self.inner.params()
    }

    fn residuals(&self) -> Option<DVector<f64>> {
        self.at_params(|s| s.residuals.clone())
    }

    fn jacobian(&self) -> Option<DMatrix<f64>> {
        self.at_params(|s| s.jacobian.clone())
    }
}

/// Every value finite, without stopping at the first that is not (the check reads every entry of a tall
/// Jacobian at every point Levenberg–Marquardt tries): `0·v` is ±0 for a finite `v` and NaN otherwise, and a
/// NaN stays in a sum. Eight sums of independent lanes are a loop the compiler vectorizes (a fold of
/// `is_finite` into one flag was not: 4.3 instructions a value against 1.8).
fn all_finite(values: &[f64]) -> bool {
    let mut lanes = [0.0f64; 8];
    let chunks = values.chunks_exact(8);
    let rest = chunks.remainder();
    for chunk in chunks {
        for (s, v) in lanes.iter_mut().zip(chunk) {
            *s += v * 0.0;
        }
    }
    lanes.iter().chain(rest).all(|v| v.is_finite())
}

/// [`from_gram`] of `j` and `r` (the tests' reference).
#[cfg(test)]
fn normal_equations(j: &DMatrix<f64>, r: &DVector<f64>) -> Option<(DMatrix<f64>, DVector<f64>)> {
    from_gram(&gram(j), &j.tr_mul(r))
}

/// `R` and `a` from the Cholesky factor of the column-scaled `JᵀJ`, and `Jᵀr`; `None` where it is not well
/// conditioned.
fn from_gram(gram: &DMatrix<f64>, jtr: &DVector<f64>) -> Option<(DMatrix<f64>, DVector<f64>)> {
    let n = gram.ncols();
    let d: Vec<f64> = (0..n)
        .map(|c| gram[(c, c)].sqrt())
        .map(|v| if v > 0.0 { v } else { 1.0 })
        .collect();
    let scaled = DMatrix::from_fn(n, n, |a, c| gram[(a, c)] / (d[a] * d[c]));
    let l = scaled.cholesky()?.unpack();
    // A NaN pivot fails too.
    if !(0..n).all(|c| l[(c, c)] >= MIN_PIVOT) {
        return None;
    }
    let mut a = DVector::from_fn(n, |c, _| jtr[c] / d[c]);
    if !l.solve_lower_triangular_mut(&mut a) {
        return None;
    }
    let mut upper = l.transpose();
    for (c, mut col) in upper.column_iter_mut().enumerate() {
        col *= d[c];
    }
    Some((upper, a))
}

/// `R` and `a = (Qᵀr)[..n]` from a Householder QR of `J`.
fn householder(j: &DMatrix<f64>, r: &DVector<f64>) -> (DMatrix<f64>, DVector<f64>) {
    let n = j.ncols();
    let qr = j.clone().qr();
    let mut qtr = r.clone();
    qr.q_tr_mul(&mut qtr);
    (qr.r(), qtr.rows(0, n).into_owned())
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn random(m: usize, n: usize, seed: u64) -> (DMatrix<f64>, DVector<f64>) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let j = DMatrix::from_fn(m, n, |_, c| {
            rng.random_range(-1.0..1.0) * 10f64.powi(c as i32 - 2)
        });
        let r = DVector::from_fn(m, |_, _| rng.random_range(-1.0..1.0));
        (j, r)
    }

    /// The small problem from `JᵀJ`, `Jᵀr` and `‖r‖²` is the one from `J` and `r` bit for bit (the same
    /// normal equations); where the Gram matrix is not well conditioned or not finite it is left to the
    /// caller.
    #[test]
    fn small_problem_from_the_gram_matrix() {
        let (j, r) = random(300, 11, 4);
        let full = gram(&j);
        let tall = reduce(&j, &r).unwrap();
        let small = reduce_gram(&full, &j.tr_mul(&r), r.norm_squared()).unwrap();
        assert_eq!(tall.residuals, small.residuals);
        assert_eq!(tall.jacobian, small.jacobian);
        let mut bad = j.clone();
        let first = bad.column(0).into_owned();
        bad.set_column(10, &first);
        assert!(reduce_gram(&gram(&bad), &bad.tr_mul(&r), r.norm_squared()).is_none());
        assert!(reduce_gram(&full, &j.tr_mul(&r), f64::NAN).is_none());
    }

    /// The moving rows of the Gram matrix, formed alone with the rest kept, are `gram`'s bit for bit (entry
    /// by entry, signed zeros included), however many columns move; a non-finite value fails the check.
    #[test]
    fn moving_rows_of_the_gram_are_the_gram_s() {
        let bits = |g: &DMatrix<f64>| g.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        for (n, moving, seed) in [(9, 3, 5), (8, 3, 6), (12, 7, 7), (9, 0, 8)] {
            let (mut j, _) = random(1000, n, seed);
            let mut g = DMatrix::zeros(0, 0);
            gram_rows(&j, moving, &mut g);
            assert_eq!(bits(&g), bits(&gram(&j)));
            for step in 0..3 {
                let (other, _) = random(1000, moving.max(1), seed + 100 + step);
                j.columns_mut(0, moving)
                    .copy_from(&other.columns(0, moving));
                gram_rows(&j, moving, &mut g);
                assert_eq!(
                    bits(&g),
                    bits(&gram(&j)),
                    "n {n}, moving {moving}, step {step}"
                );
            }
        }
        let mut v = vec![1.0; 21];
        assert!(all_finite(&v));
        for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            for i in [0, 7, 16, 20] {
                v[i] = bad;
                assert!(!all_finite(&v));
                v[i] = -0.0;
                assert!(all_finite(&v));
            }
        }
    }

    /// The four quantities Levenberg–Marquardt reads agree with the tall problem's, through the normal
    /// equations (well conditioned) and through the QR (two equal columns).
    #[test]
    fn small_problem_has_the_tall_ones_gram_gradient_and_norm() {
        let (good, r) = random(300, 6, 1);
        let mut bad = good.clone();
        let first = bad.column(0).into_owned();
        bad.set_column(5, &first);
        for (j, well) in [(good, true), (bad, false)] {
            assert_eq!(normal_equations(&j, &r).is_some(), well);
            let s = reduce(&j, &r).unwrap();
            let gram = j.tr_mul(&j);
            let gram_small = s.jacobian.tr_mul(&s.jacobian);
            assert!((&gram_small - &gram).norm() <= 1e-12 * gram.norm());
            let g = j.tr_mul(&r);
            assert!((s.jacobian.tr_mul(&s.residuals) - &g).norm() <= 1e-12 * g.norm().max(1.0));
            assert!((s.residuals.norm() - r.norm()).abs() <= 1e-12 * r.norm());
            for c in 0..j.ncols() {
                let (big, small) = (j.column(c).norm(), s.jacobian.column(c).norm());
                assert!((big - small).abs() <= 1e-12 * big);
            }
        }
        let (j, mut r) = random(50, 3, 2);
        r[7] = f64::NAN;
        assert!(reduce(&j, &r).is_none());
        let (mut j, r) = random(50, 3, 3);
        j[(41, 2)] = f64::INFINITY;
        assert!(reduce(&j, &r).is_none());
    }
}
