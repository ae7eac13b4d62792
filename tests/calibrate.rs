//! The paper's pipeline on data whose errors are known exactly: a robot that follows the paper's own error
//! model (eq. 6) with constant error transforms, measured by a noisy tracker at an unknown pose.

use calibench::calib::error_model::{FrameErrors, flange_pose_with_errors};
use calibench::calib::method::FitContext;
use calibench::calib::registry::{MethodKind, fit};
use calibench::calib::regression::RegressionOptions;
use calibench::dataset::Dataset;
use calibench::robot::dh::DhChain;
use calibench::robot::{Chain, Payload, urdf};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

const NOISE: f64 = 10e-6;

struct Synthetic {
    chain: Chain,
    dh: DhChain,
    data: Dataset,
    /// Noise-free true positions in the tracker frame.
    truth: Vec<Point3<f64>>,
}

fn synthetic(errors: &FrameErrors, n: usize, seed: u64) -> Synthetic {
    let chain = urdf::load_file("robots/iiwa7.urdf", None).unwrap();
    let dh = DhChain::from_chain(&chain).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let tracker = Isometry3::from_parts(
        Translation3::new(3.0, 0.3, 1.7),
        UnitQuaternion::from_euler_angles(0.01, 0.02, 3.1),
    );
    let (mount_nominal, mount_true) = (
        Point3::new(0.0, 0.0, 0.03),
        Point3::new(0.0006, -0.0004, 0.0302),
    );
    let noise = Normal::new(0.0, NOISE).unwrap();
    let (mut q, mut measured, mut nominal, mut truth) = (vec![], vec![], vec![], vec![]);
    // A forward-reaching family of configurations (one IK branch, as a campaign has).
    let centre = [0.0, 0.6, 0.0, -1.6, 0.0, -0.8, 0.0];
    for _ in 0..n {
        let qi: Vec<f64> = centre
            .iter()
            .map(|c| c + rng.random_range(-0.5..0.5))
            .collect();
        let true_point = tracker
            .inverse_transform_point(&(flange_pose_with_errors(&dh, &qi, errors) * mount_true));
        truth.push(true_point);
        measured.push(vec![
            true_point + Vector3::from_fn(|_, _| noise.sample(&mut rng)),
        ]);
        nominal.push(vec![dh.flange_pose(&qi) * mount_nominal]);
        q.push(qi);
    }
    let mut data = Dataset::in_memory("synthetic", chain.joint_names(), q, measured);
    data.nominal_reflectors = Some(nominal);
    Synthetic {
        chain,
        dh,
        data,
        truth,
    }
}

fn mean(v: impl Iterator<Item = f64>) -> f64 {
    let v: Vec<f64> = v.collect();
    v.iter().sum::<f64>() / v.len() as f64
}

struct Outcome {
    before: f64,
    after: f64,
    after_truth: f64,
}

/// Fits RotXYZTransXYZ on 600 + 300 points and evaluates on 300 held-out ones.
fn fit_constant_errors(cross_terms: bool) -> Outcome {
    let mut errors: FrameErrors = vec![[0.0; 6]; 7];
    errors[2] = [1.5e-4, -1e-4, 2e-4, 4e-4, -3e-4, 5e-4];
    errors[4] = [0.0, 0.0, 0.0, -2e-4, 3e-4, 2e-4];
    let s = synthetic(&errors, 1200, 1);
    let idx = |a: usize, b: usize| (a..b).collect::<Vec<_>>();
    let (train, val, test) = (
        s.data.subset(&idx(0, 600)),
        s.data.subset(&idx(600, 900)),
        s.data.subset(&idx(900, 1200)),
    );
    let ctx = FitContext {
        chain: &s.chain,
        dh: &s.dh,
        payload: Payload::NONE,
        regression: RegressionOptions {
            cross_terms,
            ..RegressionOptions::default()
        },
    };
    let model = fit(MethodKind::PaperRotxyzTransxyz, &ctx, &train, &val).unwrap();
    let registration = model.registration();
    let obs = registration.observe(&test).unwrap();
    let true_points: Vec<Vec<Point3<f64>>> = s.truth[900..].iter().map(|p| vec![*p]).collect();
    let truth = registration.observe_points(&test.q, &true_points).unwrap();
    Outcome {
        before: mean(
            obs.iter()
                .map(|o| (o.position - model.nominal(&o.q).0).norm()),
        ),
        after: mean(
            obs.iter()
                .map(|o| (o.position - model.predict(&o.q).position).norm()),
        ),
        after_truth: mean(
            truth
                .iter()
                .map(|o| (o.position - model.predict(&o.q).position).norm()),
        ),
    }
}

/// Mean distance of a 3-D isotropic normal error of σ per axis: σ·√(8/π).
fn noise_mean() -> f64 {
    NOISE * (8.0 / std::f64::consts::PI).sqrt()
}

#[test]
fn a_constant_error_transform_is_recovered_to_the_noise_level_with_cross_terms() {
    let o = fit_constant_errors(true);
    assert!(
        o.before > 5.0 * noise_mean(),
        "the errors must be well above the noise: {}",
        o.before
    );
    assert!(
        o.after <= 1.15 * noise_mean(),
        "after {} m vs noise {} m",
        o.after,
        noise_mean()
    );
    assert!(
        o.after_truth <= 10e-6,
        "against the truth {} m",
        o.after_truth
    );
}

/// The paper's features (eq. 18, no cross terms) cannot represent the per-point minimum-norm parameters of a
/// constant error exactly: they are its projection onto the row space of J_e(q), which mixes joints. What is
/// left is measured here (about 21 µm against the truth, with 16 µm of tracker noise on top) and reported in
/// the README; the bound guards against regressions, it is not the noise-level target.
#[test]
fn a_constant_error_transform_with_the_papers_features() {
    let o = fit_constant_errors(false);
    assert!(
        o.after < o.before / 3.0,
        "after {} m, before {} m",
        o.after,
        o.before
    );
    assert!(
        o.after_truth <= 25e-6,
        "against the truth {} m",
        o.after_truth
    );
}
