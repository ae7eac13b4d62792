//! Decompositions that cannot hang. nalgebra's SVD and symmetric eigen-decomposition iterate until they
//! converge, and on a matrix holding NaN or an infinity they never do (a joint value of 1e300 in a data file
//! was enough: its prediction overflowed and the corrected-command solve spun forever). Every iterative
//! decomposition in the crate goes through here: the matrix is checked finite first, and the iteration is
//! capped, so a bad number becomes an error naming what was being computed.

use nalgebra::allocator::Allocator;
use nalgebra::{
    DefaultAllocator, Dim, DimDiff, DimMin, DimMinimum, DimSub, Matrix3, OMatrix, SVD,
    SymmetricEigen, U1,
};

use levenberg_marquardt::TerminationReason;

use crate::error::{Error, Result};

/// Iterations allowed per singular value (or eigenvalue). The implicit-shift QR sweep needs two or three per
/// value on well-scaled input (LAPACK's `dbdsqr` allows six times n² inner steps in all); the cap only
/// turns a runaway into an error and is never reached by a finite, well-formed matrix.
pub const ITERATIONS_PER_VALUE: usize = 100;

/// Whether every element is finite.
pub fn all_finite<'a>(values: impl IntoIterator<Item = &'a f64>) -> bool {
    values.into_iter().all(|v| v.is_finite())
}

/// The error for a non-finite input to `what`.
pub fn not_finite(what: &str) -> Error {
    Error::Invalid(format!(
        "{what}: a value is not a finite number (an input too large or a prediction that overflowed)"
    ))
}

/// The SVD of `m` (singular values sorted, largest first), refused when `m` holds a non-finite value and
/// bounded in iterations. `what` names the computation in the error.
pub fn svd<R, C>(
    m: OMatrix<f64, R, C>,
    compute_u: bool,
    compute_v: bool,
    what: &str,
) -> Result<SVD<f64, R, C>>
where
    R: DimMin<C>,
    C: Dim,
    DimMinimum<R, C>: DimSub<U1>,
    DefaultAllocator: Allocator<R, C>
        + Allocator<C>
        + Allocator<R>
        + Allocator<DimDiff<DimMinimum<R, C>, U1>>
        + Allocator<DimMinimum<R, C>, C>
        + Allocator<R, DimMinimum<R, C>>
        + Allocator<DimMinimum<R, C>>,
{
    if !all_finite(m.iter()) {
        return Err(not_finite(what));
    }
    let k = m.nrows().min(m.ncols()).max(1);
    SVD::try_new(
        m,
        compute_u,
        compute_v,
        f64::EPSILON,
        ITERATIONS_PER_VALUE * k,
    )
    .ok_or_else(|| {
        Error::Invalid(format!(
            "{what}: the singular value decomposition did not converge"
        ))
    })
}

/// The eigen-decomposition of a symmetric 3 × 3 matrix, on the same terms as [`svd`].
pub fn symmetric_eigen3(m: Matrix3<f64>, what: &str) -> Result<SymmetricEigen<f64, nalgebra::U3>> {
    if !all_finite(m.iter()) {
        return Err(not_finite(what));
    }
    SymmetricEigen::try_new(m, f64::EPSILON, ITERATIONS_PER_VALUE * 3)
        .ok_or_else(|| Error::Invalid(format!("{what}: the eigen-decomposition did not converge")))
}

/// Why a Levenberg–Marquardt minimization stopped, in words (the crate's enum is not for users).
pub fn stopped(reason: &TerminationReason) -> String {
    match reason {
        TerminationReason::ResidualsZero => "the residuals are zero".into(),
        TerminationReason::Orthogonal | TerminationReason::Converged { .. } => {
            "it converged".into()
        }
        TerminationReason::LostPatience => {
            "it did not converge within its limit of evaluations".into()
        }
        TerminationReason::Numerical(what) | TerminationReason::User(what) => format!(
            "a value became NaN or infinite (in the {}): the data hold a number far out of scale, or \
             the starting guess is far off",
            what.replace("norm", "").trim()
        ),
        TerminationReason::NoImprovementPossible(what) => {
            format!("no further improvement is possible at machine precision ({what})")
        }
        TerminationReason::NoParameters => "there is no parameter to fit".into(),
        TerminationReason::NoResiduals => "there is no point to fit".into(),
        TerminationReason::WrongDimensions(what) => {
            format!("an internal error: the {what} has the wrong dimensions")
        }
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::DMatrix;

    use super::*;

    #[test]
    fn non_finite_is_refused_not_spun_on() {
        for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            let m = DMatrix::from_row_slice(2, 2, &[1.0, bad, 0.0, 1.0]);
            let e = svd(m, true, true, "test solve").unwrap_err().to_string();
            assert!(e.contains("test solve") && e.contains("finite"), "{e}");
            let e = symmetric_eigen3(Matrix3::from_diagonal_element(bad), "spread").unwrap_err();
            assert!(e.to_string().contains("spread"));
        }
    }

    #[test]
    fn finite_input_gives_the_known_singular_values() {
        let m = DMatrix::from_row_slice(3, 2, &[3.0, 0.0, 0.0, -2.0, 0.0, 0.0]);
        let s = svd(m, false, false, "t").unwrap().singular_values;
        assert_eq!(s.as_slice(), &[3.0, 2.0]);
    }
}
