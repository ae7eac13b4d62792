//! Eq. 13 of the paper, `Δp = J_e e` at one point: the minimum-norm error parameters `e` that explain the
//! deviation `Δp` (its §2.3–2.4: "a least mean square approach", which splits indistinguishable parameters
//! equally).

use nalgebra::{Matrix3, Matrix3xX, Vector3};

use crate::numeric;

/// Singular values below this fraction of the largest are treated as zero in the minimum-norm solves: the
/// paper's indistinguishable parameters (eq. 14–16, 22) make `J_e` rank-deficient by construction.
const PINV_REL_EPS: f64 = 1e-10;

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
fn min_norm_full_rank(j: &Matrix3xX<f64>, rhs: &Vector3<f64>) -> Option<Vec<f64>> {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calib::error_model::{ErrorModelKind, error_jacobian_on, select_params};
    use crate::robot::dh::DhChain;
    use crate::robot::urdf;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// The SVD's minimum-norm solution, as `min_norm` computed it before the closed form.
    fn by_svd(j: Matrix3xX<f64>, rhs: Vector3<f64>) -> Vec<f64> {
        let svd = numeric::svd(j, true, true, "test").unwrap();
        let tol = svd.singular_values.max() * PINV_REL_EPS;
        svd.solve(&rhs, tol).unwrap().iter().copied().collect()
    }

    /// The minimum-norm solution from a Householder QR of `Jᵀ = QR` (backward stable): `x = Q R⁻ᵀ Δ`.
    fn by_qr(j: &Matrix3xX<f64>, rhs: Vector3<f64>) -> Vec<f64> {
        let qr = j.transpose().qr();
        let r = qr.r();
        let y = Matrix3::from_fn(|a, b| r[(b, a)])
            .solve_lower_triangular(&rhs)
            .unwrap();
        (qr.q() * nalgebra::DVector::from_column_slice(y.as_slice()))
            .iter()
            .copied()
            .collect()
    }

    fn relative(a: &[f64], b: &[f64]) -> f64 {
        let d = a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum::<f64>();
        (d / b.iter().map(|v| v * v).sum::<f64>()).sqrt()
    }

    /// Eq. 13 on the iiwa's Jacobians at random configurations, for each error model: the closed form is the
    /// minimum-norm solution of a QR of `Jᵀ` to 1e-12 of its norm (nalgebra's SVD of the wide `J`, the
    /// previous way, is further off: up to 1e-6, its residual as large), and solves the equation; a
    /// Jacobian whose rows are dependent goes to the SVD.
    #[test]
    fn closed_form_min_norm_is_the_qrs() {
        let chain = urdf::load_file("robots/iiwa7.urdf", None).unwrap();
        let dh = DhChain::from_chain(&chain).unwrap();
        let lower: Vec<f64> = chain.joints.iter().map(|j| j.lower).collect();
        let upper: Vec<f64> = chain.joints.iter().map(|j| j.upper).collect();
        let mounting = nalgebra::Point3::new(0.01, -0.02, 0.05);
        let mut rng = ChaCha8Rng::seed_from_u64(13);
        let (mut closed, mut worst, mut worst_svd) = (0, 0.0f64, 0.0f64);
        for kind in [
            ErrorModelKind::RotZ,
            ErrorModelKind::RotXyz,
            ErrorModelKind::RotXyzTransXyz,
        ] {
            let params = select_params(&dh, &lower, &upper, kind).position;
            for _ in 0..300 {
                let q: Vec<f64> = lower
                    .iter()
                    .zip(&upper)
                    .map(|(&lo, &hi)| rng.random_range(lo..hi))
                    .collect();
                let frames = dh.frames(&q);
                let j = error_jacobian_on(&dh, &frames, &mounting, &params)
                    .fixed_rows::<3>(0)
                    .into_owned();
                let rhs = Vector3::from_fn(|_, _| rng.random_range(-1e-3..1e-3));
                let want = by_qr(&j, rhs);
                let got = min_norm(j.clone(), rhs);
                if min_norm_full_rank(&j, &rhs).is_some() {
                    closed += 1;
                }
                worst = worst.max(relative(&got, &want));
                worst_svd = worst_svd.max(relative(&by_svd(j.clone(), rhs), &want));
                let x = nalgebra::DVector::from_vec(got);
                assert!((&j * x - rhs).norm() <= 1e-12 * rhs.norm());
            }
        }
        assert!(
            worst <= 1e-12,
            "closed form off the QR's by {worst:e} of the norm"
        );
        assert!(worst_svd <= 1e-5, "the SVD off the QR's by {worst_svd:e}");
        assert!(closed >= 890, "closed form on {closed} of 900 Jacobians");
        // Two equal rows: rank 2, the SVD's pseudo-inverse.
        let j = Matrix3xX::from_row_slice(&[1.0, 2.0, 0.5, 1.0, 2.0, 0.5, 0.0, 1.0, 3.0]);
        let rhs = Vector3::new(1.0, 1.0, 2.0);
        assert!(min_norm_full_rank(&j, &rhs).is_none());
        assert_eq!(min_norm(j.clone(), rhs), by_svd(j, rhs));
    }
}
