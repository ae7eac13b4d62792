//! Observability indices of a campaign for a model (Borm & Menq 1991; Nahvi & Hollerbach 1996; Sun &
//! Hollerbach 2008), from the singular values σ₁ ≥ … ≥ σ_k of the campaign's identification Jacobian J
//! (rows of all its points, k parameter columns in the model's fixed scaling, see [`super::model`]):
//!
//! - **O1** = (σ₁ ⋯ σ_k)^{1/k} / √N, N the number of points: the geometric mean of the singular values per
//!   point. At a fixed N it is a monotone function of the D-criterion, so an O1-optimal and a D-optimal
//!   design are the same design.
//! - **O2** = σ_k / σ₁, the inverse condition number.
//! - **O3** = σ_k, the smallest singular value (the E-criterion's square root): the least-determined
//!   direction of the parameters.
//! - **logdet** = ln det(JᵀJ) = 2 Σ ln σ_i, the D-criterion: the (log) volume of the parameters' confidence
//!   ellipsoid, shrunk.
//!
//! A campaign that leaves a parameter combination undetermined (rank below k) has O1 = O2 = O3 = 0 and
//! logdet = −∞: the singular values below [`RANK_REL`] of the largest are zero, not rounding noise.

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

use crate::numeric;

/// Singular values below this fraction of the largest count as zero.
pub const RANK_REL: f64 = 1e-10;

/// The indices of one campaign for one model.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Indices {
    /// Points and parameters.
    pub points: usize,
    pub params: usize,
    /// Numerical rank of J.
    pub rank: usize,
    pub o1: f64,
    pub o2: f64,
    pub o3: f64,
    pub logdet: f64,
}

impl Indices {
    /// The indices of the Jacobian `j` of `points` points.
    pub fn of(j: &DMatrix<f64>, points: usize) -> Indices {
        let k = j.ncols();
        let deficient = Indices {
            points,
            params: k,
            rank: 0,
            o1: 0.0,
            o2: 0.0,
            o3: 0.0,
            logdet: f64::NEG_INFINITY,
        };
        if k == 0 || j.nrows() == 0 || j.iter().any(|v| !v.is_finite()) {
            return deficient;
        }
        // A tall J reduces to its triangle first: the same singular values from a k × k SVD.
        let square = if j.nrows() > k {
            j.clone().qr().r()
        } else {
            j.clone()
        };
        let Ok(svd) = numeric::svd(square, false, false, "observability") else {
            return deficient;
        };
        let s = svd.singular_values;
        let smax = s.max();
        let rank = s.iter().filter(|&&v| v > RANK_REL * smax).count();
        if rank < k || smax <= 0.0 {
            return Indices { rank, ..deficient };
        }
        let smin = s.min();
        let sum_ln: f64 = s.iter().map(|v| v.ln()).sum();
        Indices {
            points,
            params: k,
            rank,
            o1: (sum_ln / k as f64).exp() / (points.max(1) as f64).sqrt(),
            o2: smin / smax,
            o3: smin,
            logdet: 2.0 * sum_ln,
        }
    }

    /// Whether every parameter is determined.
    pub fn full_rank(&self) -> bool {
        self.rank == self.params && self.params > 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn known_singular_values() {
        // Two points of 3 rows each, 3 parameters: Jᵀ J = diag(4, 9, 16)·… built as [D; D] with D = diag(a).
        let d = DMatrix::from_diagonal(&nalgebra::DVector::from_vec(vec![2.0, 3.0, 4.0]));
        let mut j = DMatrix::zeros(6, 3);
        j.view_mut((0, 0), (3, 3)).copy_from(&d);
        j.view_mut((3, 0), (3, 3)).copy_from(&d);
        // σ_i = √2 · a_i.
        let s = [2.0, 3.0, 4.0].map(|a: f64| a * 2f64.sqrt());
        let idx = Indices::of(&j, 2);
        assert_eq!(idx.rank, 3);
        let gm = (s[0] * s[1] * s[2]).powf(1.0 / 3.0);
        assert!((idx.o1 - gm / 2f64.sqrt()).abs() < 1e-12);
        assert!((idx.o2 - s[0] / s[2]).abs() < 1e-12);
        assert!((idx.o3 - s[0]).abs() < 1e-12);
        let logdet = (j.transpose() * &j).determinant().ln();
        assert!((idx.logdet - logdet).abs() < 1e-12);
    }

    #[test]
    fn a_dependent_column_makes_every_index_zero() {
        let mut j = DMatrix::from_fn(12, 4, |r, c| ((r * 7 + c * 3) % 5) as f64 + 0.1 * c as f64);
        let dependent = j.column(0) * 2.0 - j.column(1);
        j.set_column(3, &dependent);
        let idx = Indices::of(&j, 4);
        assert_eq!(idx.rank, 3);
        assert!(!idx.full_rank());
        assert_eq!((idx.o1, idx.o2, idx.o3), (0.0, 0.0, 0.0));
        assert_eq!(idx.logdet, f64::NEG_INFINITY);
    }
}
