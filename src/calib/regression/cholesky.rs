//! The ridge search's Cholesky factorization, triangular solves and validation products over flat
//! column-major storage, each entry computed by nalgebra 0.34's operations in nalgebra's order (its left-looking
//! `Cholesky::new`, `solve_lower_triangular_unchecked_mut`, `ad_solve_lower_triangular_unchecked_mut`, `gemv`
//! with α = 1, β = 0, and `dot`), so every bit is nalgebra's (the tests hold them to it). nalgebra updates a
//! column with one `axpy` per earlier column, loading and storing each entry each time; the factorization and
//! `gemv` here keep a block of rows in registers across those updates (each entry's terms still in order), and
//! the solves and dot products skip the views and shape checks nalgebra sets up for each of them. nalgebra
//! writes an update `y ← a·x + y`; `y += a·x` adds the same two numbers, which IEEE addition does alike in
//! either order.

/// The lower Cholesky factor of `g + αI` (`g` column-major `n × n`) appended to `out`, the strict upper triangle
/// `g`'s; `false` where a pivot is zero, negative or not a number (the matrix does not factor; `out` still grows
/// by `n²`, the rest zeros). Column by column, each from the columns before it, as nalgebra's `Cholesky::new`:
/// every entry receives the same updates in the same order. nalgebra updates column `j` by one `axpy` per
/// earlier column `k` (`(−L[j,k])·L[j.., k] + y`); here a block of rows keeps its entries in registers across
/// all `k`, each entry's updates still in `k` order. Each column of `g` is copied in (α added to its diagonal
/// entry) just before its turn, instead of the whole matrix copied first: a column enters a left-looking
/// factorization only at its own turn, so the numbers are those of the shifted matrix factored in place.
/// `neg`: a buffer for `−L[j, ..j]`.
pub(super) fn factor_shifted(
    g: &[f64],
    alpha: f64,
    n: usize,
    out: &mut Vec<f64>,
    neg: &mut Vec<f64>,
) -> bool {
    debug_assert_eq!(g.len(), n * n);
    if n == 0 {
        return true;
    }
    let start = out.len();
    for (j, col) in g.chunks_exact(n).enumerate() {
        out.extend_from_slice(col);
        let a = &mut out[start..];
        a[j * n + j] += alpha;
        if !factor_column(a, n, j, neg) {
            out.resize(start + n * n, 0.0);
            return false;
        }
    }
    true
}

/// Column `j` of [`factor_shifted`], the columns before it already factored (`a` holds columns `..=j` at
/// least); `false` where its pivot fails.
fn factor_column(a: &mut [f64], n: usize, j: usize, neg: &mut Vec<f64>) -> bool {
    let (done, rest) = a.split_at_mut(j * n);
    let col_j = &mut rest[..n];
    neg.clear();
    neg.extend(done.chunks_exact(n).map(|col_k| -col_k[j]));
    let neg = &neg[..j];
    let mut i = j;
    while i + 16 <= n {
        update::<16>(col_j, done, neg, n, i);
        i += 16;
    }
    for b in [8, 4, 2, 1] {
        if i + b <= n {
            match b {
                8 => update::<8>(col_j, done, neg, n, i),
                4 => update::<4>(col_j, done, neg, n, i),
                2 => update::<2>(col_j, done, neg, n, i),
                _ => update::<1>(col_j, done, neg, n, i),
            }
            i += b;
        }
    }
    let diag = col_j[j];
    // nalgebra's test: not zero, and `try_sqrt` (`v ≥ 0`, so NaN fails).
    if diag.is_nan() || diag <= 0.0 {
        return false;
    }
    let denom = diag.sqrt();
    col_j[j] = denom;
    for v in &mut col_j[j + 1..] {
        *v /= denom;
    }
    true
}

/// Rows `i..i + B` of column `j` updated by every earlier column (`neg[k] = −L[j,k]`), `k` ascending.
#[inline(always)]
fn update<const B: usize>(col_j: &mut [f64], done: &[f64], neg: &[f64], n: usize, i: usize) {
    let mut acc: [f64; B] = col_j[i..i + B].try_into().expect("B rows");
    for (&f, col_k) in neg.iter().zip(done.chunks_exact(n)) {
        let x: &[f64; B] = col_k[i..i + B].try_into().expect("B rows");
        for r in 0..B {
            acc[r] += f * x[r];
        }
    }
    col_j[i..i + B].copy_from_slice(&acc);
}

/// Solves `L·x = b` in place, `L` the lower triangle of the column-major `n × n` factor `l`, `n = x.len()`:
/// nalgebra's forward substitution (each solved entry subtracted from the rest as an `axpy`).
pub(super) fn solve_lower(l: &[f64], x: &mut [f64]) {
    let n = x.len();
    for i in 0..n {
        let col = &l[i * n..(i + 1) * n];
        let c = x[i] / col[i];
        x[i] = c;
        let f = -c;
        for (y, a) in x[i + 1..].iter_mut().zip(&col[i + 1..]) {
            *y += f * a;
        }
    }
}

/// Solves `Lₘᵀ·x = b` in place, `Lₘ` the leading `m × m` block (`m = x.len()`) of the lower factor `l` stored
/// column-major with `ld` rows: nalgebra's back substitution, each entry from the dot product of its column
/// below the diagonal with the entries solved before it.
pub(super) fn solve_upper_transposed(l: &[f64], ld: usize, x: &mut [f64]) {
    let m = x.len();
    for i in (0..m).rev() {
        let col = &l[i * ld..i * ld + m];
        let (xi, below) = x[i..].split_first_mut().expect("i < m");
        let d = dot(&col[i + 1..], below);
        *xi = (*xi - d) / col[i];
    }
}

/// `y = G·w`, `G` the leading `m × m` block (`m = w.len() = y.len()`) of the column-major `g` with `ld` rows:
/// nalgebra's `gemv` with α = 1 and β = 0 (`y = G₀·w₀`, then `y += Gⱼ·wⱼ` column by column), a block of rows
/// at a time, each entry's terms in the same order.
pub(super) fn gemv(g: &[f64], ld: usize, w: &[f64], y: &mut [f64]) {
    let m = w.len();
    let mut i = 0;
    while i + 8 <= m {
        gemv_rows::<8>(g, ld, w, y, i);
        i += 8;
    }
    for b in [4, 2, 1] {
        if i + b <= m {
            match b {
                4 => gemv_rows::<4>(g, ld, w, y, i),
                2 => gemv_rows::<2>(g, ld, w, y, i),
                _ => gemv_rows::<1>(g, ld, w, y, i),
            }
            i += b;
        }
    }
}

/// Rows `i..i + B` of [`gemv`].
#[inline(always)]
fn gemv_rows<const B: usize>(g: &[f64], ld: usize, w: &[f64], y: &mut [f64], i: usize) {
    let mut cols = g.chunks(ld).zip(w);
    let Some((c0, &w0)) = cols.next() else {
        return;
    };
    // The first column's products start the sums (`β = 0`: nalgebra writes them, adding nothing).
    let x: &[f64; B] = c0[i..i + B].try_into().expect("B rows");
    let mut acc = [0.0; B];
    for r in 0..B {
        acc[r] = x[r] * w0;
    }
    for (col, &wj) in cols {
        let x: &[f64; B] = col[i..i + B].try_into().expect("B rows");
        for r in 0..B {
            acc[r] += x[r] * wj;
        }
    }
    y[i..i + B].copy_from_slice(&acc);
}

/// `a·b` as nalgebra's `dot`: eight partial sums over whole chunks of eight, added pairwise (0 + 4, 1 + 5, …)
/// into the result, then the remaining products one by one.
#[inline]
pub(super) fn dot(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    let whole = n / 8 * 8;
    let mut res = 0.0;
    if whole > 0 {
        let mut acc = [0.0_f64; 8];
        for (ca, cb) in a[..whole].chunks_exact(8).zip(b[..whole].chunks_exact(8)) {
            for l in 0..8 {
                acc[l] += ca[l] * cb[l];
            }
        }
        res += acc[0] + acc[4];
        res += acc[1] + acc[5];
        res += acc[2] + acc[6];
        res += acc[3] + acc[7];
    }
    // Below eight the partial sums are all +0 and nalgebra's four additions leave `res` at +0: skipped.
    for (x, y) in a[whole..n].iter().zip(&b[whole..n]) {
        res += x * y;
    }
    res
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{DMatrix, DVector};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn bits(v: &[f64]) -> Vec<u64> {
        v.iter().map(|x| x.to_bits()).collect()
    }

    /// A Gram matrix of `n` random features on `rows` rows plus `alpha` on the diagonal (rank-deficient where
    /// `rows < n` and `alpha` = 0: some such do not factor).
    fn gram(rng: &mut ChaCha8Rng, n: usize, rows: usize, alpha: f64) -> DMatrix<f64> {
        let f = DMatrix::from_fn(rows, n, |_, _| rng.random_range(-1.0..1.0));
        let mut g = f.tr_mul(&f);
        for i in 0..n {
            g[(i, i)] += alpha;
        }
        g
    }

    /// Every kernel against nalgebra's own call, bit for bit, on sizes 1 to 40 and every leading block (the
    /// factorization also of the matrix shifted as it is copied in).
    #[test]
    fn kernels_give_nalgebras_bits() {
        let mut rng = ChaCha8Rng::seed_from_u64(27);
        let (mut factored, mut refused) = (0, 0);
        for n in 1..=40 {
            for (rows, alpha) in [
                (n + 30, 1e-3),
                (n + 2, 0.0),
                (n / 2 + 1, 0.0),
                (3 * n, 10.0),
            ] {
                let g = gram(&mut rng, n, rows, alpha);
                let mut mine = Vec::new();
                let ok = factor_shifted(g.as_slice(), 0.0, n, &mut mine, &mut Vec::new());
                let theirs = g.clone().cholesky();
                assert_eq!(ok, theirs.is_some(), "n = {n}, rows = {rows}");
                // The same matrix plus a shift, factored as it is copied in after what a buffer holds.
                for shift in [0.0, 1e-3, 1.0] {
                    let mut plus = g.clone();
                    for i in 0..n {
                        plus[(i, i)] += shift;
                    }
                    let mut out = vec![7.0; 3];
                    let ok = factor_shifted(g.as_slice(), shift, n, &mut out, &mut Vec::new());
                    assert_eq!(out.len(), 3 + n * n);
                    match plus.cholesky() {
                        Some(ch) => {
                            assert!(ok, "n = {n}, shift {shift}");
                            assert_eq!(bits(&out[3..]), bits(ch.l_dirty().as_slice()));
                        }
                        None => assert!(!ok, "n = {n}, shift {shift}"),
                    }
                }
                let Some(ch) = theirs else {
                    refused += 1;
                    continue;
                };
                factored += 1;
                assert_eq!(bits(&mine), bits(ch.l_dirty().as_slice()), "n = {n}");
                let l = ch.l_dirty();
                let b = DVector::from_fn(n, |_, _| rng.random_range(-1.0..1.0));
                let mut fwd = b.clone();
                solve_lower(l.as_slice(), fwd.as_mut_slice());
                let mut want = b.clone();
                l.solve_lower_triangular_unchecked_mut(&mut want);
                assert_eq!(bits(fwd.as_slice()), bits(want.as_slice()));
                let gv = gram(&mut rng, n, rows, 0.0);
                for m in 1..=n {
                    let mut w = fwd.as_slice()[..m].to_vec();
                    solve_upper_transposed(l.as_slice(), n, &mut w);
                    let mut want = fwd.rows(0, m).clone_owned();
                    l.view((0, 0), (m, m))
                        .ad_solve_lower_triangular_unchecked_mut(&mut want);
                    assert_eq!(bits(&w), bits(want.as_slice()), "n = {n}, m = {m}");
                    let mut y = vec![f64::NAN; m];
                    gemv(gv.as_slice(), n, &w, &mut y);
                    let mut want_y = DVector::from_element(m, f64::NAN);
                    want_y.gemv(1.0, &gv.view((0, 0), (m, m)), &want, 0.0);
                    assert_eq!(bits(&y), bits(want_y.as_slice()));
                    assert_eq!(dot(&w, &y).to_bits(), want.dot(&want_y).to_bits());
                }
            }
        }
        // Both outcomes were exercised.
        assert!(factored > 100 && refused > 10, "{factored} {refused}");
    }

    /// `dot` on every length 0 to 40 with signed zeros, large and small magnitudes: nalgebra's bits.
    #[test]
    fn dot_gives_nalgebras_bits() {
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        for n in 0..=40 {
            for _ in 0..20 {
                let mut draw = || match rng.random_range(0..6) {
                    0 => -0.0,
                    1 => 0.0,
                    2 => rng.random_range(-1e12..1e12),
                    _ => rng.random_range(-1.0..1.0),
                };
                let a = DVector::from_fn(n, |_, _| draw());
                let b = DVector::from_fn(n, |_, _| draw());
                assert_eq!(
                    dot(a.as_slice(), b.as_slice()).to_bits(),
                    a.dot(&b).to_bits(),
                    "n = {n}"
                );
            }
        }
    }
}
