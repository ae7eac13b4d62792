//! Eq. 13 of the paper per point: the minimum-norm error parameters `e` with `J_e e = Δ` for a 3-row `J_e`
//! (a position or an orientation deviation), in closed form where the rows are clearly independent, else by
//! the SVD's pseudo-inverse.

use nalgebra::{Matrix3, Matrix3xX, Vector3};

use crate::numeric;

/// Singular values below this fraction of the largest are treated as zero in the minimum-norm solves: the
/// paper's indistinguishable parameters (eq. 14–16, 22) make `J_e` rank-deficient by construction.
pub(super) const PINV_REL_EPS: f64 = 1e-10;

/// A non-finite Jacobian or deviation (a configuration far outside the robot's range) gives NaN parameters,
/// which the regression after it refuses, rather than an SVD that never returns.
pub(super) fn min_norm(j: Matrix3xX<f64>, rhs: Vector3<f64>) -> Vec<f64> {
    let cols = j.ncols();
    if !numeric::all_finite(rhs.iter()) {
        return vec![f64::NAN; cols];
    }
    if let Some(x) = min_norm_full_rank(&j, &rhs) {
        return x;
    }
    let Ok(svd) = numeric::svd(j, true, true, "eq. 13") else {
        return vec![f64::NAN; cols];
    };
    let tol = svd.singular_values.max() * PINV_REL_EPS;
    svd.solve(&rhs, tol)
        .map(|x| x.iter().copied().collect())
        .unwrap_or_else(|_| vec![0.0; j_cols(&svd)])
}

/// Below this, a row of `J_e` is too nearly in the span of the rows before it (the squared sine of the angle
/// between them) for [`min_norm_full_rank`]: the minimum-norm solve goes to the SVD.
const MIN_ROW_PIVOT: f64 = 1e-6;

/// The minimum-norm solution `Jᵀ(JJᵀ)⁻¹Δ` where `J`'s three rows are clearly independent (each row's part
/// outside the span of the rows before it at least `√MIN_ROW_PIVOT` of its length, the Cholesky factor of
/// `JJᵀ` says): then the SVD's pseudo-inverse drops no singular value (`PINV_REL_EPS` is far below), and the
/// two are the same solution in exact arithmetic, at a 3 × 3 Cholesky instead of an SVD of `J`. `None`
/// otherwise (a wrist singularity, a non-finite `J`).
pub(super) fn min_norm_full_rank(j: &Matrix3xX<f64>, rhs: &Vector3<f64>) -> Option<Vec<f64>> {
    let gram: Matrix3<f64> = j * j.transpose();
    if !numeric::all_finite(gram.iter()) {
        return None;
    }
    let ch = gram.cholesky()?;
    let l = ch.l_dirty();
    // A NaN pivot fails too.
    if !(0..3).all(|i| l[(i, i)] * l[(i, i)] >= MIN_ROW_PIVOT * gram[(i, i)]) {
        return None;
    }
    Some((j.transpose() * ch.solve(rhs)).iter().copied().collect())
}

fn j_cols(svd: &nalgebra::SVD<f64, nalgebra::U3, nalgebra::Dyn>) -> usize {
    svd.v_t.as_ref().map_or(0, |v| v.ncols())
}
