//! Experiment design on the iiwa: observability indices on cases with a known answer, the D-optimal
//! selector's refusal of a pool that cannot determine the model, d-optimal campaigns (deterministic, better
//! conditioned than uniform ones) and whether d-optimal pays at small N on `geometric_only`.

use crate::common::edit;
use crate::common::synthetic::iiwa;

use calibench::app::run_study;
use calibench::app::simulate;
use calibench::calib::method::FitContext;
use calibench::calib::registry::MethodKind;
use calibench::design::{DesignModel, Indices, SelectOptions, d_optimal};
use calibench::robot::Chain;
use calibench::robot::dh::DhChain;
use calibench::scenario::Scenario;
use calibench::study::sweep::RunOptions;
use nalgebra::{DMatrix, Point3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const GEOMETRIC: &str = include_str!("../scenarios/geometric_only.toml");

/// `count` configurations uniform within 90 % of the joint ranges; joint `fixed` (if any) held at 0.3 rad.
fn configurations(chain: &Chain, count: usize, fixed: Option<usize>, seed: u64) -> Vec<Vec<f64>> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (lo, hi) = (chain.lower_limits(), chain.upper_limits());
    (0..count)
        .map(|_| {
            (0..lo.len())
                .map(|j| {
                    if Some(j) == fixed {
                        0.3
                    } else {
                        0.9 * rng.random_range(lo[j]..hi[j])
                    }
                })
                .collect()
        })
        .collect()
}

fn rows(model: &DesignModel, qs: &[Vec<f64>]) -> Vec<DMatrix<f64>> {
    qs.iter().map(|q| model.jacobian(&[q.as_slice()])).collect()
}

#[test]
fn a_joint_that_never_moves_leaves_parameters_unobservable_and_the_selector_refuses() {
    let (chain, dh) = iiwa();
    let ctx = FitContext::new(&chain, &dh);
    let reflector = [Point3::new(0.0, 0.0, 0.03)];
    let model = DesignModel::for_method(MethodKind::Kinematic, &ctx, &reflector)
        .unwrap()
        .unwrap();
    let k = model.params().len();
    assert!(k > 20, "{:?}", model.params());

    let free = configurations(&chain, 400, None, 1);
    let refs: Vec<&[f64]> = free.iter().map(Vec::as_slice).collect();
    let idx = Indices::of(&model.jacobian(&refs), refs.len());
    assert!(
        idx.full_rank() && idx.o3 > 0.0 && idx.logdet.is_finite(),
        "{idx:?}"
    );
    // The reference scaling gives columns unit RMS per row over the joint space, so the mean σ² of a large
    // campaign spread over the joint space is about 3 N (3 rows per point) and O1, a geometric mean, stays
    // below √3.
    assert!(idx.o1 > 0.05 && idx.o1 < 3f64.sqrt(), "{idx:?}");

    // Joint 4 held still: its encoder offset and the frame errors it would separate cannot be told apart.
    let stuck = configurations(&chain, 400, Some(3), 1);
    let refs: Vec<&[f64]> = stuck.iter().map(Vec::as_slice).collect();
    let idx = Indices::of(&model.jacobian(&refs), refs.len());
    assert!(idx.rank < k, "{idx:?}");
    assert_eq!((idx.o1, idx.o2, idx.o3), (0.0, 0.0, 0.0));
    assert_eq!(idx.logdet, f64::NEG_INFINITY);
    let err = d_optimal(&rows(&model, &stuck), 60, &SelectOptions::default()).unwrap_err();
    let message = err.to_string();
    assert!(message.contains("O3 = 0"), "{message}");
    assert!(message.contains(&format!("of {k}")), "{message}");

    // The same selector on the free pool chooses a design far better than random draws of the same size.
    let pool = rows(&model, &free);
    let sel = d_optimal(&pool, 40, &SelectOptions::default()).unwrap();
    assert!(sel.indices.full_rank());
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    for _ in 0..20 {
        let random = rand::seq::index::sample(&mut rng, pool.len(), 40).into_vec();
        let j = DMatrix::from_fn(3 * 40, k, |r, c| pool[random[r / 3]][(r % 3, c)]);
        let other = Indices::of(&j, 40);
        assert!(other.logdet < sel.logdet && other.o1 < sel.indices.o1);
    }
}

#[test]
fn every_design_model_is_full_rank_on_a_varied_campaign() {
    let (chain, dh) = iiwa();
    let ctx = FitContext::new(&chain, &dh);
    let free = configurations(&chain, 300, None, 2);
    let refs: Vec<&[f64]> = free.iter().map(Vec::as_slice).collect();
    let nest = [
        Point3::new(0.05, 0.0, 0.03),
        Point3::new(-0.025, 0.043, 0.03),
        Point3::new(-0.025, -0.043, 0.03),
    ];
    for reflectors in [&[Point3::new(0.0, 0.0, 0.03)][..], &nest[..]] {
        for kind in MethodKind::ALL {
            let model = DesignModel::for_method(kind, &ctx, reflectors).unwrap();
            match kind {
                MethodKind::Nominal | MethodKind::ResidualRidge => assert!(model.is_none()),
                _ => {
                    let model = model.unwrap();
                    let j = model.jacobian(&refs);
                    assert_eq!(j.nrows(), model.rows_per_point() * refs.len());
                    let idx = Indices::of(&j, refs.len());
                    assert!(idx.full_rank(), "{} {idx:?}", kind.name());
                }
            }
        }
    }
}

/// geometric_only with one region of `points` points laid out by `layout`, campaign seed `seed`.
fn geometric(layout: &str, points: usize, seed: u64) -> Scenario {
    let text = edit(GEOMETRIC, "points = 2335", &format!("points = {points}"));
    let text = edit(
        &text,
        "layout = \"uniform\"",
        &format!("layout = \"{layout}\""),
    );
    let text = edit(&text, "seed = 2019", &format!("seed = {seed}"));
    Scenario::parse(&text, "geometric_only").unwrap()
}

#[test]
fn d_optimal_campaigns_are_deterministic_and_better_conditioned_than_uniform() {
    let a = simulate(&geometric("d-optimal", 40, 7)).unwrap();
    let b = simulate(&geometric("d-optimal", 40, 7)).unwrap();
    let q = |s: &calibench::campaign::Simulation| -> Vec<Vec<f64>> {
        s.campaign.points.iter().map(|p| p.q_cmd.clone()).collect()
    };
    assert_eq!(a.campaign.points.len(), 40);
    assert_eq!(q(&a), q(&b));
    let c = simulate(&geometric("d-optimal", 40, 8)).unwrap();
    assert_ne!(q(&a), q(&c));
    let used = &a.campaign.rejections["paper"];
    assert_eq!(used.used, 40);
    assert!(used.feasible >= 1000, "the pool: {used:?}");

    let dh = DhChain::from_chain(&a.world.nominal).unwrap();
    let ctx = FitContext::new(&a.world.nominal, &dh);
    let model = DesignModel::for_method(MethodKind::Kinematic, &ctx, &a.world.mounting.nominal)
        .unwrap()
        .unwrap();
    let indices = |s: &calibench::campaign::Simulation| {
        let qs = q(s);
        let refs: Vec<&[f64]> = qs.iter().map(Vec::as_slice).collect();
        Indices::of(&model.jacobian(&refs), refs.len())
    };
    let optimal = indices(&a);
    for seed in 0..5 {
        let uniform = indices(&simulate(&geometric("uniform", 40, seed)).unwrap());
        assert!(
            optimal.logdet > uniform.logdet + 10.0 && optimal.o1 > uniform.o1,
            "d-optimal {optimal:?} vs uniform {uniform:?}"
        );
    }
}

#[test]
fn d_optimal_beats_uniform_at_small_n_for_kinematic_on_geometric_only() {
    // 15 training points (45 coordinates for 31 parameters) and 8 validation points, 10 campaign seeds per
    // layout, judged on the ground-truth grid.
    let study = r#"
[study]
sizes = [15]
layouts = ["uniform", "d-optimal"]
methods = ["kinematic"]
seeds = 10
test_points = 60
grid_points = 400
shell_width_m = 0.05
shell_points = 20
closed_loop_points = 5
"#;
    let text = GEOMETRIC.split("[evaluation]").next().unwrap().to_string() + study;
    let scenario = Scenario::parse(&text, "geometric_only study").unwrap();
    let result = run_study(&scenario, RunOptions::QUIET).unwrap();
    let median = |layout: &str| {
        let mut v: Vec<f64> = result
            .runs
            .iter()
            .filter(|r| r.key.layout.name() == layout)
            .map(|r| r.truth.as_ref().map_or(f64::INFINITY, |s| s.mean))
            .collect();
        assert_eq!(v.len(), 10);
        v.sort_by(f64::total_cmp);
        (v[4] + v[5]) / 2.0
    };
    let (uniform, optimal) = (median("uniform"), median("d-optimal"));
    eprintln!(
        "kinematic, 15 points, median ground-truth mean over 10 seeds: uniform {:.4} mm, d-optimal {:.4} mm",
        uniform * 1e3,
        optimal * 1e3
    );
    assert!(
        optimal < uniform,
        "d-optimal {optimal} vs uniform {uniform}"
    );
}

#[test]
fn space_filling_spreads_the_points_over_the_pool_and_each_method_has_its_design() {
    use calibench::calib::registry::MethodKind;
    use calibench::campaign::Selector;
    use calibench::design::layout::{PointDesign, SpaceFilling};
    // A 1-D pool 0..=10: the centre first, then the two ends.
    let line: Vec<Vec<f64>> = (0..=10).map(|i| vec![i as f64]).collect();
    let pool: Vec<&[f64]> = line.iter().map(Vec::as_slice).collect();
    assert_eq!(SpaceFilling.choose(&pool, 3).unwrap(), [0, 5, 10]);
    // A 5 × 5 grid in two joints with different ranges (scaled away): the centre, then the four corners.
    let grid: Vec<Vec<f64>> = (0..25)
        .map(|i| vec![(i % 5) as f64 * 0.1, (i / 5) as f64 * 2.0])
        .collect();
    let pool: Vec<&[f64]> = grid.iter().map(Vec::as_slice).collect();
    assert_eq!(SpaceFilling.choose(&pool, 5).unwrap(), [0, 4, 12, 20, 24]);
    assert!(SpaceFilling.choose(&pool, 26).is_err());

    let design = |m: &str| PointDesign::of(MethodKind::parse(m).unwrap());
    let kinematic = MethodKind::parse("kinematic").unwrap();
    let elastic = MethodKind::parse("elastic").unwrap();
    assert_eq!(design("kinematic"), PointDesign::Parameters(kinematic));
    assert_eq!(
        design("hybrid-kinematic"),
        PointDesign::Parameters(kinematic)
    );
    assert_eq!(design("elastic"), PointDesign::Parameters(elastic));
    assert_eq!(design("hybrid"), PointDesign::Parameters(elastic));
    for m in ["nominal", "paper-rotz", "paper-rotxyz", "residual-ridge"] {
        assert_eq!(design(m), PointDesign::SpaceFilling, "{m}");
    }
}

#[test]
fn in_a_study_d_optimal_points_are_chosen_for_the_method_that_uses_them() {
    let study = r#"
[study]
sizes = [40]
layouts = ["uniform", "d-optimal"]
methods = ["kinematic", "hybrid-kinematic", "elastic", "residual-ridge"]
seeds = 1
test_points = 40
grid_points = 60
shell_width_m = 0.05
shell_points = 0
closed_loop_points = 0
"#;
    let text = GEOMETRIC.split("[evaluation]").next().unwrap().to_string() + study;
    let scenario = Scenario::parse(&text, "per-method design").unwrap();
    let result = run_study(&scenario, RunOptions::QUIET).unwrap();
    let run = |layout: &str, method: &str| {
        result
            .runs
            .iter()
            .find(|r| r.key.layout.name() == layout && r.key.method.name() == method)
            .unwrap_or_else(|| panic!("{layout} {method}"))
    };
    let floor = |layout: &str, method: &str| run(layout, method).floor_mean.unwrap();
    // A geometric layout: one campaign for all, so one floor (the oracle registered on its points).
    let uniform = floor("uniform", "kinematic");
    for m in ["hybrid-kinematic", "elastic", "residual-ridge"] {
        assert_eq!(floor("uniform", m), uniform, "{m}");
    }
    // d-optimal: a campaign per design. A hybrid shares its base's; the others differ.
    assert_eq!(
        floor("d-optimal", "kinematic"),
        floor("d-optimal", "hybrid-kinematic")
    );
    assert_ne!(
        floor("d-optimal", "kinematic"),
        floor("d-optimal", "elastic")
    );
    assert_ne!(
        floor("d-optimal", "kinematic"),
        floor("d-optimal", "residual-ridge")
    );
    // Chosen with its own identification Jacobian: each parametric method's points determine its parameters
    // better than uniform points do (ln det of its own information matrix).
    for m in ["kinematic", "elastic"] {
        let logdet = |layout: &str| run(layout, m).observability.unwrap().logdet;
        assert!(
            logdet("d-optimal") > logdet("uniform") + 1.0,
            "{m}: d-optimal {} vs uniform {}",
            logdet("d-optimal"),
            logdet("uniform")
        );
    }
}
