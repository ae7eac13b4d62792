//! The motion's step solve in place: `A x = b` by LU with partial pivoting on a column-major n × n slice,
//! nalgebra's `LU::new` and `LU::solve_mut` operation for operation (the same pivots, the same products in the
//! same order, the reciprocal of the pivot as nalgebra takes it), without their allocations: the matrix is
//! factored where it lies and the pivots go into the caller's buffer. The unit test holds the two bit-equal.

/// Factors the column-major `n × n` matrix `a` in place and solves for `b` (overwritten with `x`); `pivots`
/// is scratch. False, as nalgebra's, when a pivot is zero (the matrix is singular).
pub(super) fn lu_solve_in_place(
    a: &mut [f64],
    b: &mut [f64],
    pivots: &mut Vec<(usize, usize)>,
) -> bool {
    // The arms' joint counts as constants: their loops unrolled, their bounds known.
    match b.len() {
        6 => solve(a, b, pivots, 6),
        7 => solve(a, b, pivots, 7),
        n => solve(a, b, pivots, n),
    }
}

#[inline(always)]
fn solve(a: &mut [f64], b: &mut [f64], pivots: &mut Vec<(usize, usize)>, n: usize) -> bool {
    assert!(
        a.len() == n * n && b.len() == n,
        "an n × n matrix for n right-hand sides"
    );
    pivots.clear();
    for i in 0..n {
        let (left, right) = a.split_at_mut((i + 1) * n);
        // The first largest magnitude at or below the diagonal (nalgebra's `icamax`).
        let column = &left[i * n..];
        let (mut piv, mut max) = (i, column[i].abs());
        for (r, x) in column.iter().enumerate().skip(i + 1) {
            if x.abs() > max {
                (piv, max) = (r, x.abs());
            }
        }
        let diag = column[piv];
        if diag == 0.0 {
            continue;
        }
        if piv != i {
            pivots.push((i, piv));
            for c in left.chunks_exact_mut(n) {
                c.swap(i, piv);
            }
        }
        let inv_diag = 1.0 / diag;
        let coeffs = &mut left[i * n + i + 1..];
        for x in coeffs.iter_mut() {
            *x *= inv_diag;
        }
        let coeffs = &*coeffs;
        for col in right.chunks_exact_mut(n) {
            col.swap(i, piv);
            let p = -col[i];
            for (y, c) in col[i + 1..].iter_mut().zip(coeffs) {
                *y += p * c;
            }
        }
    }
    for &(i, piv) in pivots.iter() {
        b.swap(i, piv);
    }
    // L has a unit diagonal: nalgebra divides by that one, which changes no bit.
    for (i, col) in a.chunks_exact(n).enumerate() {
        let coeff = -b[i];
        let (_, below) = b.split_at_mut(i + 1);
        for (y, l) in below.iter_mut().zip(&col[i + 1..]) {
            *y += coeff * l;
        }
    }
    for (i, col) in a.chunks_exact(n).enumerate().rev() {
        if col[i] == 0.0 {
            return false;
        }
        let coeff = b[i] / col[i];
        b[i] = coeff;
        let coeff = -coeff;
        for (y, u) in b[..i].iter_mut().zip(&col[..i]) {
            *y += coeff * u;
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{DMatrix, DVector};

    /// Against nalgebra's LU on matrices that pivot at every column, none, or hit an exactly singular one: the
    /// same bits or the same refusal.
    #[test]
    fn it_gives_nalgebra_lu_bits() {
        let mut seed = 0x9e37_79b9_7f4a_7c15_u64;
        let mut next = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let mut pivots = Vec::new();
        let mut pivoted = 0;
        for case in 0..300 {
            let n = 1 + case % 8;
            let mut m = DMatrix::from_fn(n, n, |_, _| next() * 10f64.powi((case % 7) as i32 - 3));
            if case % 3 == 0 {
                // Diagonally dominant: no row swaps.
                for i in 0..n {
                    m[(i, i)] += 100.0 * 10f64.powi((case % 7) as i32 - 3);
                }
            }
            if case % 29 == 0 && n > 1 {
                let row = m.row(0).into_owned();
                m.set_row(n - 1, &row);
            }
            let b = DVector::from_fn(n, |_, _| next());
            let mut expected = b.clone();
            let solved = m.clone().lu().solve_mut(&mut expected);
            let (mut a, mut x) = (m.clone(), b.clone());
            let ok = lu_solve_in_place(a.as_mut_slice(), x.as_mut_slice(), &mut pivots);
            pivoted += usize::from(!pivots.is_empty());
            assert_eq!(ok, solved, "case {case}: {m}");
            if ok {
                for (x, e) in x.iter().zip(expected.iter()) {
                    assert_eq!(x.to_bits(), e.to_bits(), "case {case}: {m}");
                }
            }
        }
        assert!(pivoted > 100, "only {pivoted} cases swapped rows");
    }
}
