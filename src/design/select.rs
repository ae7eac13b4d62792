//! D-optimal choice of N configurations from a candidate pool: greedy forward selection, then DETMAX
//! exchange (Mitchell 1974), with low-rank updates of the determinant and lazy evaluation of the gains.
//!
//! Each candidate c adds R rows A_c (R = 3 for a point, 6 with orientation) to the stacked Jacobian, so it
//! adds A_cᵀA_c to the information matrix M. The rank-one determinant update, for R rows at once (the matrix
//! determinant lemma and Woodbury's identity):
//!
//! - det(M ± A_cᵀA_c) = det M · det(I ± D_c), with D_c = A_c M⁻¹ A_cᵀ (R × R);
//! - (M ± A_sᵀA_s)⁻¹ = M⁻¹ ∓ U C⁻¹ Uᵀ, U = M⁻¹A_sᵀ, C = I ± D_s;
//! - every candidate's D_c then changes by ∓ W_c C⁻¹ W_cᵀ, W_c = A_c U.
//!
//! The greedy phase starts from M = δI (δ = [`SelectOptions::ridge`]), the usual way to rank points before N
//! reaches k / R. Its first steps keep every D_c and update them all by these identities, O(pool · R² k) per
//! step after an O(k²) update (M⁻¹ and every D_c recomputed from scratch every [`REFRESH`] updates, against
//! drift). Then it turns lazy ([`super::lazy`]): each gain a bound in a priority queue, only the top computed
//! afresh from a Cholesky factor of M; the same choices as the plain greedy.
//!
//! The exchange phase adds the best candidate outside the design, then removes the design point whose
//! removal costs least; it stops when that is the point just added (no exchange of one point raises the
//! determinant) or after [`SelectOptions::max_exchanges`]. It goes on the way the greedy ended: with every
//! D_c updated, or lazily, the queue filled afresh after each removal (which raises gains above their
//! bounds). The reported determinant is computed directly.
//!
//! Deterministic: ties go to the lower candidate index, and nothing depends on threads.

use nalgebra::{Cholesky, Const, DMatrix, Dyn, OMatrix, SMatrix};

use super::lazy::{Factor, Gain, Lazy, ln_det};
use super::observability::Indices;
use crate::error::{Error, Result};

/// Updates between two recomputations of M⁻¹ and the D_c from scratch.
pub const REFRESH: usize = 64;

/// Tunables of [`d_optimal`].
#[derive(Clone, Debug, PartialEq)]
pub struct SelectOptions {
    /// Exchange steps at most (0: greedy only). `None`: 2 N.
    pub max_exchanges: Option<usize>,
    /// δ of the greedy start M = δI, relative to the mean diagonal of one candidate's information.
    pub ridge: f64,
    /// An exchange that raises ln det by less than this ends the search.
    pub min_gain: f64,
}

impl Default for SelectOptions {
    fn default() -> Self {
        SelectOptions {
            max_exchanges: None,
            ridge: 1e-6,
            min_gain: 1e-9,
        }
    }
}

/// The chosen design.
#[derive(Clone, Debug, PartialEq)]
pub struct Selection {
    /// Indices into the pool, ascending.
    pub chosen: Vec<usize>,
    /// ln det(JᵀJ) of the chosen points after the greedy phase and at the end, computed directly.
    pub greedy_logdet: f64,
    pub logdet: f64,
    /// Exchanges that were made.
    pub exchanges: usize,
    /// The observability indices of the chosen points.
    pub indices: Indices,
}

/// Chooses `n` of the candidates `rows` (each R × k, the scaled Jacobian rows of one configuration) to
/// maximize det(JᵀJ). Fails when the pool is smaller than `n`, the rows disagree in shape or are not finite,
/// or the best design found leaves a parameter combination undetermined (O3 = 0): then no selection of
/// this pool determines the model, and a campaign measured from it could not be fitted.
pub fn d_optimal(rows: &[DMatrix<f64>], n: usize, options: &SelectOptions) -> Result<Selection> {
    let Some(first) = rows.first() else {
        return Err(Error::Invalid(
            "d-optimal: the candidate pool is empty".into(),
        ));
    };
    let (r, k) = first.shape();
    if n == 0 || n > rows.len() {
        return Err(Error::Invalid(format!(
            "d-optimal: cannot choose {n} of {} candidates",
            rows.len()
        )));
    }
    if k == 0 || rows.iter().any(|a| a.shape() != (r, k)) {
        return Err(Error::Invalid(
            "d-optimal: every candidate needs the same number of rows and parameters".into(),
        ));
    }
    if rows.iter().any(|a| a.iter().any(|v| !v.is_finite())) {
        return Err(Error::Invalid(
            "d-optimal: a candidate's Jacobian is not finite".into(),
        ));
    }
    let mut chosen = match r {
        3 => Search::<3>::new(rows, options).run(n, options),
        6 => Search::<6>::new(rows, options).run(n, options),
        _ => {
            return Err(Error::Invalid(format!(
                "d-optimal: {r} rows per candidate; 3 (a point) or 6 (with orientation) are supported"
            )));
        }
    };
    let greedy = chosen.greedy.clone();
    chosen.design.sort_unstable();
    let indices = Indices::of(&stack(rows, &chosen.design), n);
    if !indices.full_rank() {
        return Err(Error::Invalid(format!(
            "d-optimal: no {n} of the {} candidates determine the model's {k} parameters (rank {} of {k}, \
             O3 = 0); the pool lacks motion that some parameter needs",
            rows.len(),
            indices.rank
        )));
    }
    Ok(Selection {
        greedy_logdet: logdet(rows, &greedy),
        logdet: indices.logdet,
        exchanges: chosen.exchanges,
        chosen: chosen.design,
        indices,
    })
}

/// ln det(JᵀJ) of the candidates `chosen`, computed directly (−∞ when singular).
pub fn logdet(rows: &[DMatrix<f64>], chosen: &[usize]) -> f64 {
    let j = stack(rows, chosen);
    match Cholesky::new(j.transpose() * &j) {
        Some(c) => 2.0 * c.l().diagonal().iter().map(|d| d.ln()).sum::<f64>(),
        None => f64::NEG_INFINITY,
    }
}

fn stack(rows: &[DMatrix<f64>], chosen: &[usize]) -> DMatrix<f64> {
    let (r, k) = rows[0].shape();
    let mut j = DMatrix::zeros(r * chosen.len(), k);
    for (i, &c) in chosen.iter().enumerate() {
        j.view_mut((r * i, 0), (r, k)).copy_from(&rows[c]);
    }
    j
}

struct Found {
    design: Vec<usize>,
    greedy: Vec<usize>,
    exchanges: usize,
}

/// The search state for R rows per candidate.
struct Search<const R: usize> {
    a: Vec<OMatrix<f64, Const<R>, Dyn>>,
    delta: f64,
    in_design: Vec<bool>,
    design: Vec<usize>,
    m_inv: DMatrix<f64>,
    d: Vec<SMatrix<f64, R, R>>,
    /// Per candidate, the product [`Search::best_outside`] screens with.
    rank: Vec<f64>,
    since_refresh: usize,
}

impl<const R: usize> Search<R> {
    fn new(rows: &[DMatrix<f64>], options: &SelectOptions) -> Search<R> {
        let a: Vec<OMatrix<f64, Const<R>, Dyn>> = rows
            .iter()
            .map(|m| {
                OMatrix::<f64, Const<R>, Dyn>::from_column_slice_generic(
                    Const::<R>,
                    Dyn(m.ncols()),
                    m.as_slice(),
                )
            })
            .collect();
        let k = rows[0].ncols();
        let mean_diag = a.iter().map(|m| m.norm_squared()).sum::<f64>() / (a.len() * k) as f64;
        let delta = options.ridge * if mean_diag > 0.0 { mean_diag } else { 1.0 };
        Search {
            delta,
            in_design: vec![false; a.len()],
            design: Vec::new(),
            m_inv: DMatrix::zeros(k, k),
            d: vec![SMatrix::zeros(); a.len()],
            rank: vec![0.0; a.len()],
            since_refresh: 0,
            a,
        }
    }

    fn run(mut self, n: usize, options: &SelectOptions) -> Found {
        let mut lazy = self.greedy(n);
        let greedy = self.design.clone();
        let mut exchanges = 0;
        // With the whole pool in the design there is nothing to exchange.
        let limit = if n < self.a.len() {
            options.max_exchanges.unwrap_or(2 * n)
        } else {
            0
        };
        for _ in 0..limit {
            let (add, gain) = match lazy.as_mut() {
                Some(lazy) => self.add_lazily(lazy),
                None => {
                    let add = self.best_outside();
                    (add, self.update(add, 1.0))
                }
            };
            let remove = self.cheapest_inside(lazy.as_mut()).unwrap_or(add);
            if remove == add {
                match lazy {
                    Some(_) => self.leave(add),
                    None => {
                        self.update(add, -1.0);
                    }
                }
                break;
            }
            let loss = match lazy.as_mut() {
                Some(lazy) => self.remove_lazily(lazy, remove),
                None => self.update(remove, -1.0),
            };
            exchanges += 1;
            if gain + loss < options.min_gain {
                break;
            }
        }
        Found {
            design: self.design,
            greedy,
            exchanges,
        }
    }

    /// Adds `n` points to the design, each the candidate outside it whose addition raises ln det M most (ties
    /// to the lower index). The first steps keep every D_c and update them all (the search's rank-R
    /// identities): while the design has fewer rows than parameters, each addition closes directions of the
    /// δ ridge and lowers almost every gain below the best, so lazy bounds would save nothing; up to twice
    /// as many rows as parameters they still send about half the pool to a fresh computation per step
    /// (measured on the default study's pools). Once the design has that many rows and the last step's
    /// bounds would have sent fewer than a [`LAZY_COST`]-th of the outside candidates to a fresh
    /// computation, the rest is lazy ([`Lazy`]), which it returns for the exchange phase.
    fn greedy(&mut self, n: usize) -> Option<Lazy> {
        self.refresh();
        // Each outside candidate's Cholesky-diagonal product (√det(I + D_c)) at the last step.
        let mut last = vec![f64::INFINITY; self.a.len()];
        while self.design.len() < n {
            let best = self.best_outside();
            let outside = self.a.len() - self.design.len();
            let top = self.rank[best];
            let reached = (last.iter().zip(&self.rank))
                .filter(|&(l, r)| !r.is_nan() && *l >= top)
                .count();
            if reached * LAZY_COST < outside && self.design.len() * R >= 2 * self.m_inv.nrows() {
                return Some(self.go_lazy(best, n));
            }
            last.copy_from_slice(&self.rank);
            self.update(best, 1.0);
        }
        None
    }

    /// Adds `best` (this step's choice, with every D_c current) and the rest of the `n` points lazily.
    fn go_lazy(&mut self, best: usize, n: usize) -> Lazy {
        let gains: Vec<Gain> = (0..self.a.len())
            .filter(|&c| !self.in_design[c] && c != best)
            .map(|c| Gain {
                value: ln_det(SMatrix::<f64, R, R>::identity() + self.d[c]),
                c,
            })
            .collect();
        self.join(best);
        let mut lazy = Lazy::new(Factor::of(&self.a, &self.design, self.delta), gains);
        while self.design.len() < n {
            self.add_lazily(&mut lazy);
        }
        lazy
    }

    /// Adds the lazy search's best outside candidate; returns it with its gain, the change of ln det M.
    fn add_lazily(&mut self, lazy: &mut Lazy) -> (usize, f64) {
        // n < pool whenever a candidate is asked for, so the queue is not empty.
        let best = lazy.best(&self.a).expect("a candidate outside the design");
        self.join(best.c);
        lazy.factor.add(&self.a[best.c]);
        (best.c, best.value)
    }

    /// Removes `s` from the design; returns the change of ln det M. A removal raises every gain, so the
    /// queue's bounds fail: every outside candidate's gain is computed afresh at the new design.
    fn remove_lazily(&mut self, lazy: &mut Lazy, s: usize) -> f64 {
        let d = lazy.factor.d::<R>(self.a[s].as_slice());
        let loss = ln_det(SMatrix::<f64, R, R>::identity() - d);
        self.leave(s);
        lazy.factor = Factor::of(&self.a, &self.design, self.delta);
        let gains: Vec<Gain> = (0..self.a.len())
            .filter(|&c| !self.in_design[c])
            .map(|c| lazy.factor.gain(&self.a[c], c))
            .collect();
        lazy.evaluations += gains.len();
        lazy.reset(gains);
        loss
    }

    fn join(&mut self, c: usize) {
        self.in_design[c] = true;
        self.design.push(c);
    }

    fn leave(&mut self, c: usize) {
        self.in_design[c] = false;
        self.design.retain(|&x| x != c);
    }

    /// The candidate outside the design whose addition raises ln det most.
    ///
    /// The product of the Cholesky diagonal of I + D_c (the factor [`ln_det`] takes its logarithms of) ranks
    /// the candidates as ln det does up to a few roundings, without R logarithms per candidate; only the
    /// candidates within [`RANK_SLACK`] of the best product get ln det itself, so the choice (ties to the
    /// lower index) is the one ln det alone makes.
    fn best_outside(&mut self) -> usize {
        let mut top = 0.0_f64;
        for (c, d) in self.d.iter().enumerate() {
            let p = if self.in_design[c] {
                f64::NAN
            } else {
                (SMatrix::<f64, R, R>::identity() + d)
                    .cholesky()
                    .map_or(0.0, |ch| ch.l_dirty().diagonal().iter().product())
            };
            self.rank[c] = p;
            if p > top {
                top = p;
            }
        }
        let exact = |c: usize| self.rank[c] >= top * (1.0 - RANK_SLACK);
        let screened = top.is_finite() && top > 0.0;
        let mut best = (usize::MAX, f64::NEG_INFINITY);
        for (c, d) in self.d.iter().enumerate() {
            if self.in_design[c] || (screened && !exact(c)) {
                continue;
            }
            let g = ln_det(SMatrix::<f64, R, R>::identity() + d);
            if g > best.1 {
                best = (c, g);
            }
        }
        best.0
    }

    /// The design point whose removal lowers ln det least (its D_c from `lazy`'s factor, if given, else the
    /// kept one); `None` if every removal would leave M singular.
    fn cheapest_inside(&self, mut lazy: Option<&mut Lazy>) -> Option<usize> {
        let mut best = (None, f64::NEG_INFINITY);
        for &c in &self.design {
            let d = match lazy.as_mut() {
                Some(lazy) => lazy.factor.d::<R>(self.a[c].as_slice()),
                None => self.d[c],
            };
            let g = ln_det(SMatrix::<f64, R, R>::identity() - d);
            if g > best.1 {
                best = (Some(c), g);
            }
        }
        best.0
    }

    /// Adds (`sign` = 1) or removes (−1) candidate `s`; returns the change of ln det M.
    fn update(&mut self, s: usize, sign: f64) -> f64 {
        let c = SMatrix::<f64, R, R>::identity() + self.d[s] * sign;
        let c_chol = c.cholesky();
        let change = c_chol.as_ref().map_or(f64::NEG_INFINITY, |ch| {
            2.0 * ch.l().diagonal().iter().map(|d| d.ln()).sum::<f64>()
        });
        if sign > 0.0 {
            self.join(s);
        } else {
            self.leave(s);
        }
        self.since_refresh += 1;
        if self.since_refresh >= REFRESH {
            self.refresh();
            return change;
        }
        let Some(c_inv) = c_chol.map(|ch| ch.inverse()) else {
            self.refresh();
            return change;
        };
        let u: OMatrix<f64, Dyn, Const<R>> = &self.m_inv * self.a[s].transpose();
        let cu = c_inv * u.transpose();
        self.m_inv -= (&u * cu) * sign;
        let u_rows = rows_of(&u);
        for (a, d) in self.a.iter().zip(self.d.iter_mut()) {
            let w: SMatrix<f64, R, R> = if R <= GEMV_ROWS {
                product(a.as_slice(), &u_rows)
            } else {
                a * &u
            };
            *d -= w * c_inv * w.transpose() * sign;
        }
        change
    }

    /// M⁻¹ and every D_c from scratch.
    fn refresh(&mut self) {
        self.since_refresh = 0;
        let k = self.m_inv.nrows();
        let mut m = DMatrix::identity(k, k) * self.delta;
        for &c in &self.design {
            let a = &self.a[c];
            m += a.transpose() * a;
        }
        self.m_inv = match Cholesky::new(m) {
            Some(ch) => ch.inverse(),
            // δ > 0 keeps M positive definite; only non-finite input gets here, which d_optimal refuses.
            None => DMatrix::identity(k, k) / self.delta,
        };
        if R > GEMV_ROWS {
            for (a, d) in self.a.iter().zip(self.d.iter_mut()) {
                *d = a * &self.m_inv * a.transpose();
            }
            return;
        }
        // A · M⁻¹ first, then its product with Aᵀ, in nalgebra's order (see [`product`]).
        let (mut am, mut at) = (vec![0.0; R * k], vec![[0.0; R]; k]);
        for (a, d) in self.a.iter().zip(self.d.iter_mut()) {
            let a = a.as_slice();
            for (j, column) in self.m_inv.as_slice().chunks_exact(k).enumerate() {
                let mut acc: [f64; R] = std::array::from_fn(|i| a[i] * column[0]);
                for (l, m) in column.iter().enumerate().skip(1) {
                    for (v, ai) in acc.iter_mut().zip(&a[l * R..(l + 1) * R]) {
                        *v += ai * m;
                    }
                }
                am[j * R..(j + 1) * R].copy_from_slice(&acc);
            }
            for (row, column) in at.iter_mut().zip(a.chunks_exact(R)) {
                row.copy_from_slice(column);
            }
            *d = product(&am, &at);
        }
    }
}

/// Rows per candidate up to which nalgebra multiplies an R × k by a k × R matrix column by column, summing
/// over k in ascending order (from 6 rows on it hands the product to `matrixmultiply`, whose order differs).
const GEMV_ROWS: usize = 5;

/// How many eager updates of one candidate's D_c a fresh gain ([`Factor::gain`]) is counted as: callgrind, 29
/// parameters, about 1300 instructions an update against 5700 a gain, and the bounds a lazy step meets are
/// staler than the last step's, which the count of the rule sees.
const LAZY_COST: usize = 7;

/// How far below the best determinant a candidate is still ranked by its logarithm (relative): a million
/// times the roundings that separate the two rankings.
const RANK_SLACK: f64 = 1e-9;

/// The rows of a k × R matrix, each R values contiguous.
fn rows_of<const R: usize>(u: &OMatrix<f64, Dyn, Const<R>>) -> Vec<[f64; R]> {
    (0..u.nrows())
        .map(|l| std::array::from_fn(|j| u[(l, j)]))
        .collect()
}

/// `a · u` for `a` an R × k matrix (column-major: `a[l * R + i]`) and `u` given by its k rows: each entry summed
/// over l in ascending order from its first product, as nalgebra's product does for R ≤ [`GEMV_ROWS`] — the
/// same bits, without its per-column views on every candidate of the pool at every update.
#[inline]
fn product<const R: usize>(a: &[f64], u_rows: &[[f64; R]]) -> SMatrix<f64, R, R> {
    let mut w = [[0.0; R]; R];
    for (i, wi) in w.iter_mut().enumerate() {
        for (j, v) in wi.iter_mut().enumerate() {
            *v = a[i] * u_rows[0][j];
        }
    }
    for (l, ul) in u_rows.iter().enumerate().skip(1) {
        let column = &a[l * R..(l + 1) * R];
        for (wi, ai) in w.iter_mut().zip(column) {
            for (v, uj) in wi.iter_mut().zip(ul) {
                *v += ai * uj;
            }
        }
    }
    SMatrix::from_fn(|i, j| w[i][j])
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn pool(count: usize, r: usize, k: usize, seed: u64) -> Vec<DMatrix<f64>> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        (0..count)
            .map(|_| DMatrix::from_fn(r, k, |_, _| rng.random_range(-1.0..1.0)))
            .collect()
    }

    #[test]
    fn incremental_determinant_equals_direct() {
        for r in [3, 6] {
            let rows = pool(200, r, 12, 5);
            let options = SelectOptions {
                ridge: 0.0,
                ..SelectOptions::default()
            };
            // Start from a determined design, then add and remove points one by one: the sum of the
            // updates' ln det changes must equal the directly computed ln det at every step.
            let start: Vec<usize> = (0..10).collect();
            let check = |search_logdet: f64, design: &[usize]| {
                let direct = logdet(&rows, design);
                assert!(
                    (search_logdet - direct).abs() < 1e-8 * direct.abs().max(1.0),
                    "R = {r}: incremental {search_logdet} vs direct {direct}"
                );
            };
            macro_rules! walk {
                ($R:literal) => {{
                    let mut s = Search::<$R>::new(&rows, &options);
                    s.design = start.clone();
                    for &c in &start {
                        s.in_design[c] = true;
                    }
                    s.refresh();
                    let mut ld = logdet(&rows, &start);
                    for step in 0..150 {
                        if step % 3 == 2 {
                            let out = s.design[step % s.design.len()];
                            ld += s.update(out, -1.0);
                        } else {
                            let add = (10 + step * 7) % rows.len();
                            if s.in_design[add] {
                                continue;
                            }
                            ld += s.update(add, 1.0);
                        }
                        check(ld, &s.design);
                    }
                }};
            }
            if r == 3 {
                walk!(3);
            } else {
                walk!(6);
            }
        }
    }

    #[test]
    fn greedy_gain_is_the_determinant_ratio() {
        // The gain the search ranks candidates by, det(I + D_c), is det(M + A_cᵀA_c) / det M.
        let rows = pool(50, 3, 8, 9);
        let options = SelectOptions {
            ridge: 0.0,
            ..SelectOptions::default()
        };
        let mut s = Search::<3>::new(&rows, &options);
        s.design = (0..5).collect();
        for c in 0..5 {
            s.in_design[c] = true;
        }
        s.refresh();
        let base = logdet(&rows, &s.design);
        for c in 5..50 {
            let gain = ln_det(SMatrix::<f64, 3, 3>::identity() + s.d[c]);
            let mut with: Vec<usize> = s.design.clone();
            with.push(c);
            assert!((base + gain - logdet(&rows, &with)).abs() < 1e-9);
        }
    }

    #[test]
    fn the_hand_products_are_nalgebras_bit_for_bit() {
        // The search's choices are compared across commits byte for byte: its own loops must round as
        // nalgebra's products do.
        let rows = pool(40, 3, 29, 11);
        let a: Vec<OMatrix<f64, Const<3>, Dyn>> = rows
            .iter()
            .map(|m| OMatrix::from_column_slice_generic(Const::<3>, Dyn(29), m.as_slice()))
            .collect();
        let u: OMatrix<f64, Dyn, Const<3>> = a[7].transpose() * 0.37 + a[9].transpose();
        let u_rows = rows_of(&u);
        for a in &a {
            let direct: SMatrix<f64, 3, 3> = a * &u;
            assert_eq!(product(a.as_slice(), &u_rows), direct);
        }
        // refresh's D_c against nalgebra's A M⁻¹ Aᵀ.
        let mut s = Search::<3>::new(&rows, &SelectOptions::default());
        s.design = vec![1, 4, 6, 20, 33];
        s.refresh();
        for (a, d) in s.a.iter().zip(&s.d) {
            assert_eq!(*d, a * &s.m_inv * a.transpose());
        }
        // The screened choice is the one ln det makes over every candidate.
        for _ in 0..5 {
            let full = (0..rows.len())
                .filter(|&c| !s.in_design[c])
                .map(|c| (c, ln_det(SMatrix::<f64, 3, 3>::identity() + s.d[c])))
                .fold((usize::MAX, f64::NEG_INFINITY), |b, x| {
                    if x.1 > b.1 { x } else { b }
                });
            let best = s.best_outside();
            assert_eq!(best, full.0);
            s.update(best, 1.0);
        }
    }

    /// ln det(δI + JᵀJ) of `design`, directly.
    fn ridge_logdet(rows: &[DMatrix<f64>], design: &[usize], delta: f64) -> f64 {
        let j = stack(rows, design);
        let m = j.transpose() * &j + DMatrix::identity(j.ncols(), j.ncols()) * delta;
        let l = Cholesky::new(m).expect("δ > 0").l();
        2.0 * l.diagonal().iter().map(|d| d.ln()).sum::<f64>()
    }

    #[test]
    fn lazy_greedy_picks_the_plain_greedys_points() {
        // The plain greedy: every outside candidate's ln det(δI + JᵀJ) computed directly at every step, the
        // best taken, ties to the lower index. Pools with exact twins (later copies of earlier candidates)
        // check the ties.
        for (r, k, count, n, seed) in [
            (3, 12, 300, 40, 21),
            (3, 29, 400, 60, 22),
            (6, 20, 200, 30, 23),
        ] {
            let mut rows = pool(count, r, k, seed);
            for c in (0..count).step_by(7) {
                rows.push(rows[c].clone());
            }
            let mean = rows.iter().map(|m| m.norm_squared()).sum::<f64>() / (rows.len() * k) as f64;
            let delta = SelectOptions::default().ridge * mean;
            let mut plain: Vec<usize> = Vec::new();
            for _ in 0..n {
                let mut best = (usize::MAX, f64::NEG_INFINITY);
                for c in 0..rows.len() {
                    if plain.contains(&c) {
                        continue;
                    }
                    plain.push(c);
                    let g = ridge_logdet(&rows, &plain, delta);
                    plain.pop();
                    if g > best.1 {
                        best = (c, g);
                    }
                }
                plain.push(best.0);
            }
            macro_rules! lazy {
                ($R:literal) => {{
                    // As d_optimal runs it (eager first steps, then lazy where it pays)...
                    let mut s = Search::<$R>::new(&rows, &SelectOptions::default());
                    assert!((s.delta - delta).abs() <= 1e-12 * delta);
                    s.greedy(n);
                    // ...and lazy from the first point on.
                    let mut all = Search::<$R>::new(&rows, &SelectOptions::default());
                    all.refresh();
                    let first = all.best_outside();
                    let lazy = all.go_lazy(first, n);
                    // Lazy bounds did save fresh gains: fewer than the plain greedy's (on these small
                    // random pools, 26 to 52 %; the study's pools are in docs/speed.md).
                    assert!(lazy.evaluations < n * rows.len() * 3 / 5, "{}", lazy.evaluations);
                    (s.design, all.design)
                }};
            }
            let (chosen, all_lazy) = if r == 3 { lazy!(3) } else { lazy!(6) };
            assert_eq!(chosen, plain, "R = {r}, k = {k}");
            assert_eq!(all_lazy, plain, "R = {r}, k = {k}, lazy throughout");
        }
    }

    #[test]
    fn exchange_never_lowers_the_greedy_determinant_and_beats_random() {
        let rows = pool(400, 3, 15, 2);
        let sel = d_optimal(&rows, 12, &SelectOptions::default()).unwrap();
        assert_eq!(sel.chosen.len(), 12);
        assert!(sel.chosen.windows(2).all(|w| w[0] < w[1]));
        assert!(sel.logdet >= sel.greedy_logdet - 1e-9);
        assert!((sel.logdet - logdet(&rows, &sel.chosen)).abs() < 1e-9);
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        for _ in 0..50 {
            let random: Vec<usize> = rand::seq::index::sample(&mut rng, 400, 12).into_vec();
            assert!(logdet(&rows, &random) < sel.logdet);
        }
        // Deterministic.
        assert_eq!(
            d_optimal(&rows, 12, &SelectOptions::default()).unwrap(),
            sel
        );
    }

    #[test]
    fn exhaustive_optimum_on_a_small_pool() {
        // 12 candidates, choose 3 (R = 3, k = 6): 220 designs, checked one by one.
        let rows = pool(12, 3, 6, 4);
        let sel = d_optimal(&rows, 3, &SelectOptions::default()).unwrap();
        let mut best = f64::NEG_INFINITY;
        for a in 0..12 {
            for b in a + 1..12 {
                for c in b + 1..12 {
                    best = best.max(logdet(&rows, &[a, b, c]));
                }
            }
        }
        // DETMAX is a local search; on this pool it finds the optimum or comes within 1 %.
        assert!(
            sel.logdet >= best - 0.01 * best.abs(),
            "{} vs {best}",
            sel.logdet
        );
    }

    #[test]
    fn an_unobservable_parameter_is_refused() {
        let mut rows = pool(300, 3, 10, 3);
        for a in &mut rows {
            a.column_mut(7).fill(0.0);
        }
        let err = d_optimal(&rows, 20, &SelectOptions::default()).unwrap_err();
        assert!(err.to_string().contains("rank 9 of 10"), "{err}");
        assert!(err.to_string().contains("O3 = 0"), "{err}");
    }

    #[test]
    fn bad_requests_are_errors() {
        let rows = pool(5, 3, 4, 0);
        assert!(d_optimal(&rows, 6, &SelectOptions::default()).is_err());
        assert!(d_optimal(&rows, 0, &SelectOptions::default()).is_err());
        assert!(d_optimal(&[], 1, &SelectOptions::default()).is_err());
        let mut bad = rows.clone();
        bad[2][(0, 0)] = f64::NAN;
        assert!(d_optimal(&bad, 2, &SelectOptions::default()).is_err());
        let four = pool(5, 4, 4, 0);
        assert!(d_optimal(&four, 2, &SelectOptions::default()).is_err());
    }
}
