//! The statistics of the regression: R² (eq. 20) with its rule for a target that does not vary, and the
//! standardization of a column (none for one that does not vary).

/// Coefficient of determination (eq. 20).
///
/// When `y` has no variance (to 1e-12 of its magnitude), eq. 20 divides by zero; as in scikit-learn the
/// result is then 1 if the predictions match `y` to the same precision and 0 otherwise, so an error
/// parameter that is identically zero and predicted as zero counts as perfectly explained. Empty input
/// gives 0.
///
/// Panics if the lengths differ.
pub fn r2(y: &[f64], y_hat: &[f64]) -> f64 {
    assert_eq!(y.len(), y_hat.len(), "r2: y and y_hat lengths differ");
    if y.is_empty() {
        return 0.0;
    }
    let mean = y.iter().sum::<f64>() / y.len() as f64;
    let sst = y.iter().map(|v| (v - mean).powi(2)).sum::<f64>();
    let sse = y
        .iter()
        .zip(y_hat)
        .map(|(v, h)| (v - h).powi(2))
        .sum::<f64>();
    r2_from_sums(sse, sst, zero_sum_tol(y))
}

/// A sum of squares at or below this is rounding noise of values of `y`'s magnitude.
pub(super) fn zero_sum_tol(y: &[f64]) -> f64 {
    let scale = y.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    y.len() as f64 * (ZERO_REL * scale).powi(2)
}

/// Relative spread below which a column counts as constant: means of identical values differ from them
/// by rounding only (~1e-16), while any real variation is far above 1e-12.
const ZERO_REL: f64 = 1e-12;

pub(super) fn r2_from_sums(sse: f64, sst: f64, tol: f64) -> f64 {
    if sst <= tol {
        if sse <= tol { 1.0 } else { 0.0 }
    } else {
        1.0 - sse / sst
    }
}

/// Mean and population standard deviation, with `None` for a column that does not vary.
pub(super) fn standardization(
    values: impl Iterator<Item = f64> + Clone,
    n: usize,
) -> (f64, Option<f64>) {
    let mean = values.clone().sum::<f64>() / n as f64;
    let sd = (values.map(|v| (v - mean).powi(2)).sum::<f64>() / n as f64).sqrt();
    if sd == 0.0 || sd <= ZERO_REL * mean.abs() {
        (mean, None)
    } else {
        (mean, Some(sd))
    }
}
