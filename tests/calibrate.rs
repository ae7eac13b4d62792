//! The paper's pipeline on data whose errors are known exactly: a robot that follows the paper's own error
//! model (eq. 6) with constant error transforms, measured by a noisy tracker at an unknown pose.

use crate::common::synthetic::{Extra, mean, noise_mean, synthetic};

use calibench::calib::error_model::FrameErrors;
use calibench::calib::method::FitContext;
use calibench::calib::registry::MethodKind;
use calibench::calib::regression::RegressionOptions;
use calibench::robot::Payload;
use nalgebra::Point3;

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
    let s = synthetic(&errors, 1200, 1, &Extra::default());
    let idx = |a: usize, b: usize| (a..b).collect::<Vec<_>>();
    let (train, val, test) = (
        s.data.subset(&idx(0, 600)),
        s.data.subset(&idx(600, 900)),
        s.data.subset(&idx(900, 1200)),
    );
    let ctx = FitContext {
        share: None,
        chain: &s.chain,
        dh: &s.dh,
        payload: Payload::NONE,
        regression: RegressionOptions {
            cross_terms,
            ..RegressionOptions::default()
        },
    };
    let model = MethodKind::PaperRotxyzTransxyz
        .fit(&ctx, &train, &val)
        .unwrap();
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
