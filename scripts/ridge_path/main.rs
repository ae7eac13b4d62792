//! The regression search's α path for one target, two ways, on a problem of the paper methods' size (1168
//! training and 583 validation rows, 10 candidate inputs, degrees 1–5, the 10 nested input sets of each
//! degree, the default 21 α):
//!
//! - `chol`: what `calib::regression` does — per degree and α one Cholesky of `G + αI` of the largest set,
//!   then per set the back substitution of its leading block and the validation SSE by `gemv`;
//! - `eig`: per set one symmetric eigendecomposition `G = VΛVᵀ` and `M = VᵀGᵥV`, then per α
//!   `u = (Λ + α)⁻¹Vᵀb` and `SSE = rᵀr − 2uᵀVᵀcᵥ + uᵀMu` (the same estimator in exact arithmetic);
//! - `both`: both, and how far apart their coefficients and SSEs are and how often the best α differs;
//! - `none`: the set-up alone (subtract its instruction count).
//!
//! Count instructions with `valgrind --tool=callgrind /tmp/ridge_path/release/ridge_path MODE`.

use nalgebra::{DMatrix, DVector};

/// xorshift64: reproducible data without a dependency.
struct Rng(u64);

impl Rng {
    fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    }
}

/// Powers 1..=d of each input, input by input, each column standardized (as `regression::design` orders them).
fn features(x: &DMatrix<f64>, d: usize) -> DMatrix<f64> {
    let (n, c) = x.shape();
    let mut f = DMatrix::from_fn(n, c * d, |r, j| x[(r, j / d)].powi(1 + (j % d) as i32));
    for mut col in f.column_iter_mut() {
        let m = col.mean();
        let s = (col.iter().map(|v| (v - m).powi(2)).sum::<f64>() / n as f64).sqrt();
        col.apply(|v| *v = (*v - m) / s);
    }
    f
}

fn main() {
    let mode = std::env::args().nth(1).unwrap_or_else(|| "both".into());
    let mut rng = Rng(88172645463325252);
    let c = 10;
    let x = DMatrix::from_fn(1168, c, |_, _| rng.uniform());
    let xv = DMatrix::from_fn(583, c, |_, _| rng.uniform());
    let target = |x: &DMatrix<f64>, r: usize, e: f64| {
        1e-4 * (0.8 * x[(r, 0)]).sin() + 2e-4 * x[(r, 3)].powi(3) + 1e-6 * e
    };
    let y = DVector::from_fn(1168, |r, _| target(&x, r, rng.uniform()));
    let yv = DVector::from_fn(583, |r, _| target(&xv, r, rng.uniform()));
    let alphas: Vec<f64> = (0..=20)
        .rev()
        .map(|i| 10f64.powf(-8.0 + 0.5 * i as f64))
        .collect();
    let (mut dw, mut dsse, mut flips, mut sets, mut sink) = (0.0f64, 0.0f64, 0, 0, 0.0);
    for d in 1..=5 {
        let (f, fv) = (features(&x, d), features(&xv, d));
        let mean = y.mean();
        let (yc, r) = (y.add_scalar(-mean), yv.add_scalar(-mean));
        let (g, gv) = (f.tr_mul(&f), fv.tr_mul(&fv));
        let (b, cv, rr) = (f.tr_mul(&yc), fv.tr_mul(&r), r.norm_squared());
        let p = c * d;
        let sizes: Vec<usize> = (1..=c).map(|k| k * d).collect();
        let mut chol = vec![vec![(0.0, DVector::zeros(0)); alphas.len()]; sizes.len()];
        if mode == "chol" || mode == "both" {
            for (ai, &a) in alphas.iter().enumerate() {
                let mut s = g.clone();
                for i in 0..p {
                    s[(i, i)] += a;
                }
                let ch = s.cholesky().expect("positive definite");
                let mut fw = b.clone();
                ch.l_dirty().solve_lower_triangular_unchecked_mut(&mut fw);
                for (k, &m) in sizes.iter().enumerate() {
                    let mut w = fw.rows(0, m).clone_owned();
                    ch.l_dirty()
                        .view((0, 0), (m, m))
                        .ad_solve_lower_triangular_unchecked_mut(&mut w);
                    let mut gw = DVector::zeros(m);
                    gw.gemv(1.0, &gv.view((0, 0), (m, m)), &w, 0.0);
                    let sse = rr - 2.0 * w.dot(&cv.rows(0, m)) + w.dot(&gw);
                    sink += sse;
                    chol[k][ai] = (sse, w);
                }
            }
        }
        if mode == "eig" || mode == "both" {
            for (k, &m) in sizes.iter().enumerate() {
                let e = g.view((0, 0), (m, m)).clone_owned().symmetric_eigen();
                let v = &e.eigenvectors;
                let vb = v.tr_mul(&b.rows(0, m));
                let vc = v.tr_mul(&cv.rows(0, m));
                let mm = v.tr_mul(&(gv.view((0, 0), (m, m)) * v));
                let (mut u, mut mu) = (DVector::zeros(m), DVector::zeros(m));
                let (mut best, mut best_chol) = ((f64::INFINITY, 0), (f64::INFINITY, 0));
                for (ai, &a) in alphas.iter().enumerate() {
                    for i in 0..m {
                        u[i] = vb[i] / (e.eigenvalues[i] + a);
                    }
                    mu.gemv(1.0, &mm, &u, 0.0);
                    let sse = rr - 2.0 * u.dot(&vc) + u.dot(&mu);
                    sink += sse;
                    // Strict improvement with α descending: ties keep the larger α, as the search does.
                    if sse < best.0 {
                        best = (sse, ai);
                    }
                    if mode == "both" {
                        let (s0, w0) = &chol[k][ai];
                        dw = dw.max((v * &u - w0).norm() / w0.norm());
                        dsse = dsse.max((sse - s0).abs() / s0);
                        if *s0 < best_chol.0 {
                            best_chol = (*s0, ai);
                        }
                    }
                }
                if mode == "both" {
                    sets += 1;
                    flips += usize::from(best.1 != best_chol.1);
                }
            }
        }
    }
    println!(
        "{mode}: Σ SSE {sink:e}; largest relative difference: coefficients {dw:.1e}, validation SSE \
         {dsse:.1e}; best α differs in {flips} of {sets} sets"
    );
}
