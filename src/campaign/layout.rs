//! Where the measurement points go inside a region.
//!
//! How well a learned error model generalizes depends on how its training points cover the region, and the
//! study compares layouts at equal point counts. Every layout works in the unit cube and the caller scales
//! to the region's box, so a layout knows nothing of robots and can be tested on its own. All randomness
//! comes from the caller's generator, so a run is reproducible from (scenario seed, run index).

use rand::Rng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;

/// One way of laying out points in the unit cube. Kept object-safe so a scenario can pick layouts by name
/// at run time and new ones (the model-based optimal selector) slot in beside these.
pub trait PointLayout: Send + Sync {
    fn name(&self) -> &'static str;
    /// About `n` points in the unit cube [0,1]^3 (the caller scales them to a box with side lengths `extent`, metres).
    fn sample(&self, n: usize, extent: [f64; 3], rng: &mut ChaCha8Rng) -> Vec<[f64; 3]>;
}

/// Independent uniform draws: the baseline every other layout must beat, and what an operator jogging
/// the arm at random approximates. Exactly `n` points in [0,1)^3.
#[derive(Clone, Copy, Debug, Default)]
pub struct Uniform;

/// A regular lattice of cell centres, as an operator would lay out a measurement grid by hand.
///
/// Returns **at least** `n` points: a lattice only has certain sizes. The per-axis counts follow the box's
/// side lengths (equal spacing in metres, roughly), so a flat region gets fewer layers along its thin side
/// but never zero; among such proportional lattices the smallest with `n` or more points is taken. See
/// [`grid_counts`]. Ignores the generator.
#[derive(Clone, Copy, Debug, Default)]
pub struct Grid;

/// Owen-scrambled Sobol points (sobol_burley): low discrepancy without the grid's aliasing with periodic
/// errors such as gear transmission. Exactly `n` points in [0,1)^3; the scramble seed comes from the
/// generator. The first 2^k points of each block are a (t, k, 3)-net, so powers of two stratify best.
#[derive(Clone, Copy, Debug, Default)]
pub struct Sobol;

/// Latin hypercube: exactly `n` points, one in each of the `n` equal slabs of every axis (random
/// permutations, random position inside the slab), so each joint-space-relevant coordinate is covered
/// evenly even for small `n`.
#[derive(Clone, Copy, Debug, Default)]
pub struct LatinHypercube;

/// The layouts a scenario can name.
#[derive(
    serde::Deserialize, serde::Serialize, Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash,
)]
#[serde(rename_all = "kebab-case")]
pub enum LayoutKind {
    Uniform,
    Grid,
    Sobol,
    LatinHypercube,
    /// Model-based: the configurations that maximize det(JᵀJ) of the campaign's identification Jacobian for
    /// the model of `campaign.selection`, chosen from a pool of feasible uniform candidates
    /// ([`crate::design::select`]). `o1-optimal` is accepted as another name for it: at a fixed number of
    /// points O1 is a monotone function of the determinant, so the two criteria choose the same design.
    #[serde(alias = "o1-optimal")]
    DOptimal,
}

impl LayoutKind {
    /// Every kind, for sweeps over all layouts.
    pub const ALL: [LayoutKind; 5] = [
        LayoutKind::Uniform,
        LayoutKind::Grid,
        LayoutKind::Sobol,
        LayoutKind::LatinHypercube,
        LayoutKind::DOptimal,
    ];

    /// The layouts that place points in the unit cube without knowing the robot.
    pub const GEOMETRIC: [LayoutKind; 4] = [
        LayoutKind::Uniform,
        LayoutKind::Grid,
        LayoutKind::Sobol,
        LayoutKind::LatinHypercube,
    ];

    /// The layout in the unit cube: for a model-based kind, that of its candidate pool (uniform).
    pub fn build(self) -> Box<dyn PointLayout> {
        match self {
            LayoutKind::Uniform | LayoutKind::DOptimal => Box::new(Uniform),
            LayoutKind::Grid => Box::new(Grid),
            LayoutKind::Sobol => Box::new(Sobol),
            LayoutKind::LatinHypercube => Box::new(LatinHypercube),
        }
    }

    /// Whether the campaign chooses its points from a candidate pool by a model (see
    /// [`crate::campaign::region::SelectionConfig`]).
    pub fn selects(self) -> bool {
        self == LayoutKind::DOptimal
    }

    /// The same spelling as in scenario files, so reports and inputs agree.
    pub fn name(self) -> &'static str {
        match self {
            LayoutKind::Uniform => "uniform",
            LayoutKind::Grid => "grid",
            LayoutKind::Sobol => "sobol",
            LayoutKind::LatinHypercube => "latin-hypercube",
            LayoutKind::DOptimal => "d-optimal",
        }
    }
}

impl PointLayout for Uniform {
    fn name(&self) -> &'static str {
        LayoutKind::Uniform.name()
    }

    fn sample(&self, n: usize, _extent: [f64; 3], rng: &mut ChaCha8Rng) -> Vec<[f64; 3]> {
        (0..n)
            .map(|_| [rng.random(), rng.random(), rng.random()])
            .collect()
    }
}

impl PointLayout for Grid {
    fn name(&self) -> &'static str {
        LayoutKind::Grid.name()
    }

    fn sample(&self, n: usize, extent: [f64; 3], _rng: &mut ChaCha8Rng) -> Vec<[f64; 3]> {
        if n == 0 {
            return Vec::new();
        }
        let c = grid_counts(n, extent);
        let centre = |i: usize, k: usize| (i as f64 + 0.5) / k as f64;
        let mut points = Vec::with_capacity(c[0] * c[1] * c[2]);
        for i in 0..c[0] {
            for j in 0..c[1] {
                for k in 0..c[2] {
                    points.push([centre(i, c[0]), centre(j, c[1]), centre(k, c[2])]);
                }
            }
        }
        points
    }
}

/// Per-axis counts of the [`Grid`] layout for `n` points in a box of side lengths `extent`.
///
/// The counts are `max(1, round(s·extent_i))` for the smallest scale `s` whose product reaches `n`: that
/// keeps the spacing close to equal in metres (a lattice proportional to the box) while wasting as few
/// points as a proportional lattice allows. Axes with zero, negative or non-finite extent get one layer;
/// when no axis has a usable extent the box is treated as a cube. `n = 0` gives `[1, 1, 1]`.
pub fn grid_counts(n: usize, extent: [f64; 3]) -> [usize; 3] {
    let mut e = extent.map(|x| if x.is_finite() && x > 0.0 { x } else { 0.0 });
    let max = e.iter().copied().fold(0.0, f64::max);
    if max == 0.0 {
        e = [1.0; 3];
    } else {
        e = e.map(|x| x / max);
    }
    let mut c = [1usize; 3];
    let product = |c: &[usize; 3]| c.iter().fold(1usize, |p, &k| p.saturating_mul(k));
    while product(&c) < n {
        // Scale at which round(s·e_i) first exceeds the current count of axis i.
        let next = |i: usize| {
            if e[i] > 0.0 {
                (c[i] as f64 + 0.5) / e[i]
            } else {
                f64::INFINITY
            }
        };
        let s = (0..3).map(next).fold(f64::INFINITY, f64::min);
        // Axes tied at the same scale (a cube's three sides) grow together, or the lattice would lose its
        // proportions to the order of the axes.
        let grow: Vec<usize> = (0..3).filter(|&i| next(i) <= s * (1.0 + 1e-12)).collect();
        for i in grow {
            c[i] += 1;
        }
    }
    c
}

/// Largest sample count for one sobol_burley sequence; longer requests continue with fresh seeds.
const SOBOL_BLOCK: usize = 1 << 16;

impl PointLayout for Sobol {
    fn name(&self) -> &'static str {
        LayoutKind::Sobol.name()
    }

    fn sample(&self, n: usize, _extent: [f64; 3], rng: &mut ChaCha8Rng) -> Vec<[f64; 3]> {
        let mut points = Vec::with_capacity(n);
        // sobol_burley supports 2^16 indices per seed; beyond that, independent scrambled blocks (Burley's
        // padding) keep every block a net rather than letting indices wrap.
        while points.len() < n {
            let seed: u32 = rng.random();
            let len = (n - points.len()).min(SOBOL_BLOCK);
            points.extend((0..len as u32).map(|i| {
                let s = sobol_burley::sample_4d(i, 0, seed);
                [f64::from(s[0]), f64::from(s[1]), f64::from(s[2])]
            }));
        }
        points
    }
}

impl PointLayout for LatinHypercube {
    fn name(&self) -> &'static str {
        LayoutKind::LatinHypercube.name()
    }

    fn sample(&self, n: usize, _extent: [f64; 3], rng: &mut ChaCha8Rng) -> Vec<[f64; 3]> {
        let perms: [Vec<usize>; 3] = std::array::from_fn(|_| {
            let mut p: Vec<usize> = (0..n).collect();
            p.shuffle(rng);
            p
        });
        let nf = n as f64;
        (0..n)
            .map(|i| {
                std::array::from_fn(|a| {
                    let k = perms[a][i];
                    let x = (k as f64 + rng.random::<f64>()) / nf;
                    // Rounding can push a draw near the top of its slab into the next one; the slab, not the
                    // exact position, is the point of the design.
                    if (x * nf).floor() as usize == k && x < 1.0 {
                        x
                    } else {
                        (k as f64 + 0.5) / nf
                    }
                })
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    fn rng(seed: u64) -> ChaCha8Rng {
        ChaCha8Rng::seed_from_u64(seed)
    }

    const EXTENTS: [[f64; 3]; 4] = [
        [0.4, 0.4, 0.4],
        [0.6, 0.3, 0.05],
        [1.0, 0.0, 0.2],
        [0.0, 0.0, 0.0],
    ];

    #[test]
    fn all_points_inside_unit_cube_with_expected_counts() {
        for kind in LayoutKind::GEOMETRIC {
            let d = kind.build();
            for n in [0, 1, 2, 7, 100, 1000] {
                for extent in EXTENTS {
                    let pts = d.sample(n, extent, &mut rng(11));
                    if kind == LayoutKind::Grid {
                        assert!(pts.len() >= n, "{} n={n}", kind.name());
                    } else {
                        assert_eq!(pts.len(), n, "{} n={n}", kind.name());
                    }
                    for p in &pts {
                        assert!(
                            p.iter().all(|x| (0.0..1.0).contains(x)),
                            "{} {p:?}",
                            kind.name()
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn latin_hypercube_one_point_per_stratum() {
        for n in [1, 5, 97, 1000] {
            let pts = LatinHypercube.sample(n, [1.0; 3], &mut rng(n as u64));
            assert_eq!(pts.len(), n);
            for a in 0..3 {
                let mut seen = vec![false; n];
                for p in &pts {
                    let k = (p[a] * n as f64).floor() as usize;
                    assert!(!seen[k], "axis {a}: stratum {k} twice (n={n})");
                    seen[k] = true;
                }
                assert!(seen.iter().all(|&s| s));
            }
        }
    }

    fn unique_sorted(pts: &[[f64; 3]], a: usize) -> Vec<f64> {
        let mut v: Vec<f64> = pts.iter().map(|p| p[a]).collect();
        v.sort_by(f64::total_cmp);
        v.dedup();
        v
    }

    #[test]
    fn grid_is_regular_and_follows_extent_ratios() {
        // 2 : 1 : 0.5 with n = 64 has the exact proportional lattice 8 × 4 × 2.
        let pts = Grid.sample(64, [2.0, 1.0, 0.5], &mut rng(0));
        assert_eq!(pts.len(), 64);
        for (a, count) in [8usize, 4, 2].into_iter().enumerate() {
            let xs = unique_sorted(&pts, a);
            assert_eq!(xs.len(), count, "axis {a}");
            let h = 1.0 / count as f64;
            assert!((xs[0] - h / 2.0).abs() < 1e-15);
            for w in xs.windows(2) {
                assert!((w[1] - w[0] - h).abs() < 1e-12, "axis {a} spacing");
            }
        }
        // A flat box: one layer along its thin side, never zero.
        assert_eq!(grid_counts(100, [1.0, 1.0, 0.05]), [10, 10, 1]);
        let flat = Grid.sample(100, [1.0, 1.0, 0.05], &mut rng(0));
        assert_eq!(unique_sorted(&flat, 2), vec![0.5]);
        // A cube stays a cube.
        assert_eq!(grid_counts(512, [0.3; 3]), [8, 8, 8]);
        assert_eq!(grid_counts(513, [0.3; 3]), [9, 9, 9]);
    }

    #[test]
    fn grid_counts_are_proportional_and_tight() {
        for extent in [[2.0, 1.0, 0.5], [1.0, 0.6, 0.25]] {
            for n in 1..3000 {
                let c = grid_counts(n, extent);
                let p = c[0] * c[1] * c[2];
                assert!(p >= n);
                // No exact ties for these extents, so the last step grew one axis by one: removing that
                // layer again falls below n, which bounds the waste.
                let bound = (0..3)
                    .filter(|&i| c[i] > 1)
                    .map(|i| c[i] as f64 / (c[i] - 1) as f64)
                    .fold(1.0, f64::max);
                assert!(p as f64 <= n as f64 * bound + 1e-9, "n={n} {c:?}");
                // Counts are one proportional lattice rounded: a single scale s puts every axis within
                // half a layer of s·extent.
                let lo = (0..3)
                    .filter(|&i| c[i] > 1)
                    .map(|i| (c[i] as f64 - 0.5) / extent[i])
                    .fold(f64::NEG_INFINITY, f64::max);
                let hi = (0..3)
                    .map(|i| (c[i] as f64 + 0.5) / extent[i])
                    .fold(f64::INFINITY, f64::min);
                assert!(lo <= hi * (1.0 + 1e-12), "n={n} {c:?}");
            }
        }
    }

    #[test]
    fn sobol_512_stratifies_octants_and_4_cubed_cells() {
        for seed in 0..5 {
            let pts = Sobol.sample(512, [1.0; 3], &mut rng(seed));
            let mut octants = [0usize; 8];
            let mut cells = [0usize; 64];
            for p in &pts {
                let b = p.map(|x| (x * 2.0) as usize);
                octants[b[0] * 4 + b[1] * 2 + b[2]] += 1;
                let q = p.map(|x| (x * 4.0) as usize);
                cells[q[0] * 16 + q[1] * 4 + q[2]] += 1;
            }
            assert_eq!(octants, [64; 8], "seed {seed}");
            assert_eq!(cells, [8; 64], "seed {seed}");
        }
        // Uniform draws, for contrast, essentially never do this.
        let pts = Uniform.sample(512, [1.0; 3], &mut rng(0));
        let mut octants = [0usize; 8];
        for p in &pts {
            let b = p.map(|x| (x * 2.0) as usize);
            octants[b[0] * 4 + b[1] * 2 + b[2]] += 1;
        }
        assert_ne!(octants, [64; 8]);
    }

    #[test]
    fn sobol_beyond_one_block() {
        let n = SOBOL_BLOCK + 1000;
        let pts = Sobol.sample(n, [1.0; 3], &mut rng(3));
        assert_eq!(pts.len(), n);
        assert_ne!(pts[0], pts[SOBOL_BLOCK]);
        assert!(pts.iter().all(|p| p.iter().all(|x| (0.0..1.0).contains(x))));
    }

    #[test]
    fn deterministic_per_seed() {
        for kind in LayoutKind::GEOMETRIC {
            let d = kind.build();
            let a = d.sample(200, [0.5, 0.4, 0.3], &mut rng(42));
            let b = d.sample(200, [0.5, 0.4, 0.3], &mut rng(42));
            let c = d.sample(200, [0.5, 0.4, 0.3], &mut rng(43));
            assert_eq!(a, b, "{}", kind.name());
            if kind == LayoutKind::Grid {
                assert_eq!(a, c);
            } else {
                assert_ne!(a, c, "{}", kind.name());
            }
        }
    }

    #[test]
    fn names_match_scenario_spelling() {
        for kind in LayoutKind::GEOMETRIC {
            assert_eq!(kind.build().name(), kind.name());
        }
        let alias: LayoutKind = serde_json::from_str("\"o1-optimal\"").unwrap();
        assert_eq!(alias, LayoutKind::DOptimal);
        for kind in LayoutKind::ALL {
            let json = serde_json::to_string(&kind).unwrap();
            assert_eq!(json, format!("\"{}\"", kind.name()));
            let back: LayoutKind = serde_json::from_str(&json).unwrap();
            assert_eq!(back, kind);
        }
    }
}
