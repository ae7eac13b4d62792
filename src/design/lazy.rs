//! Lazy greedy evaluation (Minoux 1978) for the D-optimal search of [`super::select`]: each candidate's gain
//! ln det(I + D_c) waits in a priority queue as an upper bound, and only the candidates that reach the top are
//! computed afresh.
//!
//! The gain of adding a candidate to a design is ln det(M + A_cᵀA_c) − ln det M = ln det(I + D_c),
//! D_c = A_c M⁻¹ A_cᵀ. ln det M is monotone submodular in the design: adding points makes M larger, M⁻¹ and every
//! D_c smaller, so a gain computed at an earlier, smaller design bounds the gain now from above. The first fresh
//! gain that no bound left in the queue exceeds is the one the plain greedy (every gain fresh) would choose.
//! A removal makes M smaller and the gains larger: the bounds fail there, and the exchange phase leaves the
//! queue as soon as it removes a point.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use nalgebra::{Cholesky, Const, DMatrix, Dyn, OMatrix, SMatrix};

/// How far below the best fresh gain a stale bound still gets its gain computed afresh (relative above 1,
/// absolute below): rounding can leave a bound a few ulps under the fresh gain it bounds, and a candidate that
/// close to the best must be compared by fresh gains, as the plain greedy compares it.
pub const LAZY_SLACK: f64 = 1e-9;

/// ln det of a small symmetric matrix; −∞ unless positive definite (a removal that would leave the design
/// singular is never the cheapest).
pub fn ln_det<const R: usize>(m: SMatrix<f64, R, R>) -> f64 {
    m.cholesky().map_or(f64::NEG_INFINITY, |ch| {
        2.0 * ch.l().diagonal().iter().map(|d| d.ln()).sum::<f64>()
    })
}

/// A candidate's gain ln det(I + D_c): exact at the design it was computed at, an upper bound on its gain at
/// any larger design. Ordered by the gain, then by the lower index (the greater of two equal gains).
#[derive(Clone, Copy, Debug)]
pub struct Gain {
    pub value: f64,
    pub c: usize,
}

impl Ord for Gain {
    fn cmp(&self, other: &Gain) -> Ordering {
        self.value
            .total_cmp(&other.value)
            .then(other.c.cmp(&self.c))
    }
}

impl PartialOrd for Gain {
    fn partial_cmp(&self, other: &Gain) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl PartialEq for Gain {
    fn eq(&self, other: &Gain) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}

impl Eq for Gain {}

/// The information matrix M = δI + Σ A_cᵀA_c of a design and its Cholesky factor L, from which any candidate's
/// D_c = YᵀY, Y = L⁻¹A_cᵀ (positive semi-definite by construction), costs a forward substitution: R k² / 2
/// multiply-adds, against R² k for one candidate's rank-R update in the exchange phase.
pub struct Factor {
    m: DMatrix<f64>,
    /// L's diagonal, and its rows left of the diagonal, packed: row i holds columns 0..i.
    diagonal: Vec<f64>,
    rows: Vec<f64>,
    /// Y by rows, R values each.
    y: Vec<f64>,
}

impl Factor {
    /// The factor of δI + Σ A_cᵀA_c over `design`.
    pub fn of<const R: usize>(
        a: &[OMatrix<f64, Const<R>, Dyn>],
        design: &[usize],
        delta: f64,
    ) -> Factor {
        let k = a[0].ncols();
        let mut m = DMatrix::identity(k, k) * delta;
        for &c in design {
            m += a[c].transpose() * &a[c];
        }
        let mut f = Factor {
            m,
            diagonal: Vec::with_capacity(k),
            rows: Vec::with_capacity(k * (k - 1) / 2),
            y: vec![0.0; R * k],
        };
        f.factor();
        f
    }

    /// Adds the candidate with rows `a` to the design.
    pub fn add<const R: usize>(&mut self, a: &OMatrix<f64, Const<R>, Dyn>) {
        self.m += a.transpose() * a;
        self.factor();
    }

    fn factor(&mut self) {
        let k = self.m.nrows();
        // δ > 0 keeps M positive definite; only non-finite input fails, which d_optimal refuses.
        let l = Cholesky::new(self.m.clone()).map_or_else(
            || DMatrix::identity(k, k) * self.m[(0, 0)].sqrt(),
            |ch| ch.l(),
        );
        self.diagonal.clear();
        self.rows.clear();
        for i in 0..k {
            self.diagonal.push(l[(i, i)]);
            self.rows.extend((0..i).map(|j| l[(i, j)]));
        }
    }

    /// D_c of the candidate whose R × k rows are `a` (column-major): Y row by row, its R right-hand sides
    /// together (one load of L's entry for R products), and D_c summed as the rows come.
    pub fn d<const R: usize>(&mut self, a: &[f64]) -> SMatrix<f64, R, R> {
        let mut d = [[0.0; R]; R];
        let mut rows = self.rows.as_slice();
        // As arrays of R, so that a row's R right-hand sides stay in registers through its substitution.
        let (columns, _) = a.as_chunks::<R>();
        let (ys, _) = self.y.as_chunks_mut::<R>();
        for (i, (l_ii, column)) in self.diagonal.iter().zip(columns).enumerate() {
            let (l_i, rest) = rows.split_at(i);
            rows = rest;
            let (done, next) = ys.split_at_mut(i);
            let mut y = *column;
            for (l, yj) in l_i.iter().zip(done.iter()) {
                for (v, u) in y.iter_mut().zip(yj) {
                    *v -= l * u;
                }
            }
            for v in &mut y {
                *v /= l_ii;
            }
            next[0] = y;
            for p in 0..R {
                for q in 0..=p {
                    d[p][q] += y[p] * y[q];
                }
            }
        }
        SMatrix::from_fn(|p, q| if q <= p { d[p][q] } else { d[q][p] })
    }

    /// The gain ln det(I + D_c) of adding candidate `c` with rows `a`.
    pub fn gain<const R: usize>(&mut self, a: &OMatrix<f64, Const<R>, Dyn>, c: usize) -> Gain {
        Gain {
            value: ln_det(SMatrix::<f64, R, R>::identity() + self.d::<R>(a.as_slice())),
            c,
        }
    }
}

/// The lazy greedy's state: the design's factor and every outside candidate's gain bound.
pub struct Lazy {
    pub factor: Factor,
    queue: BinaryHeap<Gain>,
    beaten: Vec<Gain>,
    /// Gains computed afresh so far (for the tests and the benchmark's account).
    pub evaluations: usize,
}

impl Lazy {
    /// Starts from `factor` (the design's) and `gains`, each outside candidate's gain at that design.
    pub fn new(factor: Factor, gains: impl IntoIterator<Item = Gain>) -> Lazy {
        Lazy {
            factor,
            queue: gains.into_iter().collect(),
            beaten: Vec::new(),
            evaluations: 0,
        }
    }

    /// Starts again from `gains`, every outside candidate's gain at the factor's design (after a removal,
    /// which raises gains above their bounds).
    pub fn reset(&mut self, gains: impl IntoIterator<Item = Gain>) {
        self.queue.clear();
        self.queue.extend(gains);
    }

    /// Takes out the outside candidate whose addition raises ln det M most, with its fresh gain (ties to the
    /// lower index): the top is computed afresh until no bound left in the queue reaches the best fresh gain
    /// (within [`LAZY_SLACK`]). `None` when no candidate is left outside.
    pub fn best<const R: usize>(&mut self, a: &[OMatrix<f64, Const<R>, Dyn>]) -> Option<Gain> {
        let mut best: Option<Gain> = None;
        while let Some(&top) = self.queue.peek() {
            if best.is_some_and(|b| top.value < b.value - LAZY_SLACK * b.value.abs().max(1.0)) {
                break;
            }
            self.queue.pop();
            let fresh = self.factor.gain(&a[top.c], top.c);
            self.evaluations += 1;
            match best {
                Some(b) if b > fresh => self.beaten.push(fresh),
                _ => {
                    self.beaten.extend(best);
                    best = Some(fresh);
                }
            }
        }
        self.queue.extend(self.beaten.drain(..));
        best
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn a_fresh_d_is_a_m_inverse_a_transpose() {
        let mut rng = ChaCha8Rng::seed_from_u64(8);
        let a: Vec<OMatrix<f64, Const<3>, Dyn>> = (0..40)
            .map(|_| {
                OMatrix::from_fn_generic(Const::<3>, Dyn(17), |_, _| rng.random_range(-1.0..1.0))
            })
            .collect();
        let design = [0, 3, 5, 8, 13, 21];
        let delta = 1e-3;
        let mut factor = Factor::of(&a, &design, delta);
        factor.add(&a[30]);
        let mut m = DMatrix::identity(17, 17) * delta;
        for &c in design.iter().chain(&[30]) {
            m += a[c].transpose() * &a[c];
        }
        let m_inv = m.try_inverse().expect("positive definite");
        for (c, a) in a.iter().enumerate() {
            let direct: SMatrix<f64, 3, 3> = a * &m_inv * a.transpose();
            let fresh = factor.d::<3>(a.as_slice());
            assert!(
                (fresh - direct).norm() <= 1e-9 * direct.norm(),
                "candidate {c}: {fresh} vs {direct}"
            );
            assert_eq!(fresh, fresh.transpose());
            let g = factor.gain(a, c);
            assert_eq!(g.value, ln_det(SMatrix::<f64, 3, 3>::identity() + fresh));
        }
    }

    #[test]
    fn gains_order_by_value_then_the_lower_index() {
        let g = |value, c| Gain { value, c };
        assert!(g(2.0, 9) > g(1.0, 0));
        assert!(g(1.0, 3) > g(1.0, 4));
        let mut queue: BinaryHeap<Gain> = [g(1.0, 4), g(0.5, 0), g(1.0, 3)].into_iter().collect();
        assert_eq!(queue.pop().map(|x| x.c), Some(3));
    }
}
