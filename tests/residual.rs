//! `residual-ridge` and `hybrid` on data whose errors are known exactly: a robot that follows the paper's error
//! model (eq. 6) with constant error transforms, plus a smooth position field of two joints, measured by a
//! noisy tracker at an unknown pose.

use crate::common::synthetic::{self as fixture, Extra, Field, Synthetic, mean, noise_mean};

use calibench::calib::error_model::FrameErrors;
use calibench::calib::method::{FitContext, Fitted};
use calibench::calib::registry::{MethodKind, Save, SavedModel};
use calibench::calib::regression::RegressionOptions;
use calibench::calib::residual::{Hybrid, ResidualModel};
use calibench::calib::tracker_frame::Observation;
use calibench::dataset::Dataset;
use calibench::robot::Payload;
use nalgebra::{Point3, UnitQuaternion, Vector3};

/// A smooth position error (base frame, m) of joints 2 and 4, up to about 0.2 mm.
fn field(q: &[f64]) -> Vector3<f64> {
    Vector3::new(
        2e-4 * (2.0 * q[1]).sin() + 0.6e-4 * (q[3] + 1.6).powi(2),
        -1.5e-4 * (2.5 * q[3]).cos() + 0.8e-4 * q[1].sin(),
        1.2e-4 * (3.0 * q[1] + 0.3).sin() - 0.8e-4 * (1.5 * q[3]).cos(),
    )
}

fn no_field(_: &[f64]) -> Vector3<f64> {
    Vector3::zeros()
}

/// `n` points of the common synthetic robot with `field` on top; one reflector, or a nest of three.
fn synthetic(errors: &FrameErrors, field: Field, nest: bool, n: usize, seed: u64) -> Synthetic {
    let extra = Extra {
        field: Some(field),
        nest,
        ..Extra::default()
    };
    fixture::synthetic(errors, n, seed, &extra)
}

/// Training, validation and test halves-quarter-quarter of the data.
fn splits(s: &Synthetic) -> (Dataset, Dataset, Dataset) {
    let n = s.data.len();
    let idx = |a: usize, b: usize| (a..b).collect::<Vec<_>>();
    (
        s.data.subset(&idx(0, n / 2)),
        s.data.subset(&idx(n / 2, 3 * n / 4)),
        s.data.subset(&idx(3 * n / 4, n)),
    )
}

fn ctx<'a>(s: &'a Synthetic, cross_terms: bool) -> FitContext<'a> {
    FitContext {
        share: None,
        chain: &s.chain,
        dh: &s.dh,
        payload: Payload::NONE,
        regression: RegressionOptions {
            cross_terms,
            ..RegressionOptions::default()
        },
    }
}

/// Mean distance from the observations to the model's predictions.
fn mean_error(model: &dyn Fitted, obs: &[Observation]) -> f64 {
    mean(
        obs.iter()
            .map(|o| (o.position - model.predict(&o.q).position).norm()),
    )
}

fn rms_error(model: &dyn Fitted, obs: &[Observation]) -> f64 {
    mean(
        obs.iter()
            .map(|o| (o.position - model.predict(&o.q).position).norm_squared()),
    )
    .sqrt()
}

/// The noise-free test points, registered as the model registers measurements.
fn truth_obs(model: &dyn Fitted, s: &Synthetic, test: &Dataset) -> Vec<Observation> {
    let n = s.data.len();
    let points: Vec<Vec<Point3<f64>>> = s.truth[3 * n / 4..].iter().map(|p| vec![*p]).collect();
    model
        .registration()
        .observe_points(&test.q, &points)
        .unwrap()
}

fn constant_errors() -> FrameErrors {
    let mut errors: FrameErrors = vec![[0.0; 6]; 7];
    errors[2] = [1.5e-4, -1e-4, 2e-4, 4e-4, -3e-4, 5e-4];
    errors[4] = [0.0, 0.0, 0.0, -2e-4, 3e-4, 2e-4];
    errors
}

#[test]
fn residual_ridge_models_a_smooth_field_of_two_joints_to_the_noise_level() {
    let s = synthetic(&vec![[0.0; 6]; 7], field, false, 2000, 1);
    let (train, val, test) = splits(&s);
    let ctx = ctx(&s, false);
    let model = MethodKind::ResidualRidge.fit(&ctx, &train, &val).unwrap();
    let nominal = MethodKind::Nominal.fit(&ctx, &train, &val).unwrap();
    assert_eq!(model.method(), "residual-ridge");
    assert!(!model.models_orientation());
    let obs = model.registration().observe(&test).unwrap();
    let (after, before) = (
        mean_error(model.as_ref(), &obs),
        mean_error(
            nominal.as_ref(),
            &nominal.registration().observe(&test).unwrap(),
        ),
    );
    let truth = truth_obs(model.as_ref(), &s, &test);
    println!(
        "residual-ridge: test {after:.3e} m, nominal {before:.3e} m, noise {:.3e} m, against the truth {:.3e} m",
        noise_mean(),
        mean_error(model.as_ref(), &truth)
    );
    assert!(
        before > 3.0 * noise_mean(),
        "nominal must not reach the noise: {before}"
    );
    assert!(
        after <= 1.2 * noise_mean(),
        "after {after} m vs noise {} m",
        noise_mean()
    );
    // The report names the inputs of every component: the field depends on joints 2 and 4 only.
    let report = model.report(&obs);
    let components = &report["residual"]["components"];
    let names = s.chain.joint_names();
    for c in ["dx", "dy", "dz"] {
        let inputs = components[c]["inputs"].as_array().unwrap();
        assert!(
            inputs.iter().any(|i| i == &names[1]) || inputs.iter().any(|i| i == &names[3]),
            "{c}: {report}"
        );
        assert!(components[c]["kept"].as_bool().unwrap(), "{report}");
        assert!(
            components[c]["r2"]["validation"].as_f64().unwrap() > 0.9,
            "{report}"
        );
        assert!(
            components[c]["r2"]["test"].as_f64().unwrap() > 0.9,
            "{report}"
        );
        assert!(components[c]["degree"].as_u64().unwrap() >= 1);
        assert!(components[c]["alpha"].as_f64().is_some());
    }
}

#[test]
fn hybrid_removes_most_of_the_smooth_residual_its_base_leaves() {
    // The nominal base leaves the whole field; the paper's base leaves what its features cannot express.
    for (errors, base, cross) in [
        (vec![[0.0; 6]; 7], MethodKind::Nominal, false),
        (constant_errors(), MethodKind::PaperRotxyzTransxyz, true),
    ] {
        let s = synthetic(&errors, field, false, 2000, 2);
        let (train, val, test) = splits(&s);
        let ctx = ctx(&s, cross);
        let hybrid = Hybrid {
            base: base.method(),
        }
        .fit_hybrid(&ctx, &train, &val)
        .unwrap();
        assert_eq!(hybrid.method(), format!("hybrid-{}", base.name()));
        assert_eq!(hybrid.base().method(), base.name());
        let obs = hybrid.registration().observe(&test).unwrap();
        let truth = truth_obs(&hybrid, &s, &test);
        let (base_truth, hybrid_truth) = (
            mean_error(hybrid.base(), &truth),
            mean_error(&hybrid, &truth),
        );
        let (base_test, hybrid_test) = (mean_error(hybrid.base(), &obs), mean_error(&hybrid, &obs));
        println!(
            "{}: against the truth base {base_truth:.3e} m, hybrid {hybrid_truth:.3e} m; measured base \
             {base_test:.3e} m, hybrid {hybrid_test:.3e} m, noise {:.3e} m",
            hybrid.method(),
            noise_mean()
        );
        assert!(hybrid_test <= base_test, "{}", hybrid.method());
        assert!(hybrid_truth <= base_truth, "{}", hybrid.method());
        if base == MethodKind::Nominal {
            assert!(
                base_truth > 3.0 * noise_mean(),
                "the base must leave a residual well above the noise: {base_truth}"
            );
            assert!(
                hybrid_truth < 0.2 * base_truth,
                "hybrid {hybrid_truth} m, base {base_truth} m against the truth"
            );
        }
        let report = hybrid.report(&obs);
        assert_eq!(report["base_method"], base.name());
        assert!(report["base"].is_object(), "{report}");
        assert!(
            report["residual"]["components"]["dx"]["r2"]["validation"].is_number(),
            "{report}"
        );
    }
}

#[test]
fn hybrid_is_never_worse_than_its_base_on_the_validation_data() {
    // Bases that leave a smooth residual, and ones that leave nothing but noise.
    let cases: [(Field, MethodKind, bool); 6] = [
        (no_field, MethodKind::PaperRotxyzTransxyz, true),
        (no_field, MethodKind::PaperRotz, false),
        (no_field, MethodKind::Nominal, false),
        (field, MethodKind::Nominal, false),
        (field, MethodKind::PaperRotxyz, false),
        (no_field, MethodKind::ResidualRidge, false),
    ];
    // Small sets too, where a residual model fitted to noise is most likely and the guard must act.
    let mut dropped = 0;
    for (seed, (f, base, cross)) in cases.into_iter().enumerate() {
        for n in [240, 60] {
            let s = synthetic(&constant_errors(), f, false, n, 10 + seed as u64);
            let (train, val, _) = splits(&s);
            let ctx = ctx(&s, cross);
            let hybrid = Hybrid {
                base: base.method(),
            }
            .fit_hybrid(&ctx, &train, &val)
            .unwrap();
            let obs = hybrid.registration().observe(&val).unwrap();
            let (b, h) = (mean_error(hybrid.base(), &obs), mean_error(&hybrid, &obs));
            let (b_rms, h_rms) = (rms_error(hybrid.base(), &obs), rms_error(&hybrid, &obs));
            let kept: Vec<bool> = hybrid
                .model()
                .residual
                .position
                .iter()
                .map(|m| m.kept)
                .collect();
            dropped += kept.iter().filter(|k| !**k).count();
            println!(
                "{} on {n} points: validation mean {b:.3e} -> {h:.3e} m, rms {b_rms:.3e} -> {h_rms:.3e} m, \
                 kept {kept:?}",
                hybrid.method()
            );
            assert!(h <= b * (1.0 + 1e-12), "{}: {h} > {b}", hybrid.method());
            assert!(
                h_rms <= b_rms * (1.0 + 1e-12),
                "{}: {h_rms} > {b_rms}",
                hybrid.method()
            );
        }
    }
    println!("{dropped} components dropped by the validation guard");
    assert!(dropped > 0, "the cases must exercise the guard");
}

/// Bit-identical predictions of `a` and `b` at the test configurations.
fn assert_same_predictions(a: &dyn Fitted, b: &dyn Fitted, test: &Dataset) {
    assert_eq!(a.method(), b.method());
    assert_eq!(a.models_orientation(), b.models_orientation());
    assert_eq!(a.registration(), b.registration());
    let bits = |p: &Point3<f64>| p.coords.map(f64::to_bits);
    for q in &test.q {
        let (pa, pb) = (a.predict(q), b.predict(q));
        assert_eq!(bits(&pa.position), bits(&pb.position));
        assert_eq!(bits(&pa.linearized_position), bits(&pb.linearized_position));
        assert_eq!(
            pa.orientation.coords.map(f64::to_bits),
            pb.orientation.coords.map(f64::to_bits)
        );
    }
}

fn round_trip(model: &dyn Fitted) -> Box<dyn Fitted> {
    let text = serde_json::to_string(&model.save().unwrap()).unwrap();
    serde_json::from_str::<SavedModel>(&text)
        .unwrap()
        .into_fitted()
        .unwrap()
}

#[test]
fn saved_models_predict_identically_after_a_json_round_trip() {
    // A reflector nest: the orientation residual is modelled too.
    let s = synthetic(&constant_errors(), field, true, 800, 3);
    let (train, val, test) = splits(&s);
    let ctx = ctx(&s, false);

    let residual = ResidualModel::fit(&ctx, &train, &val).unwrap();
    assert!(residual.models_orientation());
    assert_eq!(residual.residual.orientation.len(), 3);
    let json = serde_json::to_value(residual.save().unwrap()).unwrap();
    assert_eq!(json["model"], "residual");
    let back = round_trip(&residual);
    assert_same_predictions(&residual, back.as_ref(), &test);
    // The orientation model does something: closer to the true flange orientation than nominal (the
    // measured one has ~0.3 mrad of noise from 10 µm on reflectors 30 mm apart).
    let n = s.data.len();
    let to_base = residual.registration().frame.tracker_to_base.rotation;
    let angle = |f: &dyn Fn(&[f64]) -> UnitQuaternion<f64>| {
        mean(
            test.q
                .iter()
                .zip(&s.truth_orientation[3 * n / 4..])
                .map(|(q, r)| (to_base * r * f(q).inverse()).angle()),
        )
    };
    let (modelled, nominal) = (
        angle(&|q| residual.predict(q).orientation),
        angle(&|q| residual.nominal(q).1),
    );
    println!(
        "orientation against the truth: residual-ridge {modelled:.3e} rad, nominal {nominal:.3e} rad"
    );
    assert!(modelled < 0.5 * nominal, "{modelled} vs nominal {nominal}");

    let hybrid = Hybrid {
        base: MethodKind::PaperRotz.method(),
    }
    .fit_hybrid(&ctx, &train, &val)
    .unwrap();
    assert!(hybrid.models_orientation());
    let json = serde_json::to_value(hybrid.save().unwrap()).unwrap();
    assert_eq!(json["model"], "hybrid");
    assert_eq!(json["base"]["model"], "paper");
    let back = round_trip(&hybrid);
    assert_same_predictions(&hybrid, back.as_ref(), &test);
}

#[test]
fn hybrid_methods_name_their_base() {
    let s = synthetic(&constant_errors(), field, false, 120, 4);
    let (train, val, _) = splits(&s);
    let ctx = ctx(&s, false);
    for (kind, base) in [
        (MethodKind::Hybrid, MethodKind::Elastic),
        (MethodKind::HybridKinematic, MethodKind::Kinematic),
    ] {
        // Until the base method exists, the hybrid fails with the base's error.
        match (kind.fit(&ctx, &train, &val), base.fit(&ctx, &train, &val)) {
            (Ok(h), Ok(b)) => {
                assert_eq!(h.method(), kind.name());
                assert_eq!(b.method(), base.name());
            }
            (Err(h), Err(b)) => assert_eq!(h.to_string(), b.to_string()),
            (h, b) => panic!(
                "{}: hybrid {:?}, base {:?}",
                kind.name(),
                h.map(|m| m.method().to_string()),
                b.map(|m| m.method().to_string())
            ),
        }
    }
    let empty = train.subset(&[]);
    assert!(MethodKind::ResidualRidge.fit(&ctx, &train, &empty).is_err());
    assert!(
        Hybrid {
            base: MethodKind::Nominal.method()
        }
        .fit_hybrid(&ctx, &empty, &val)
        .is_err()
    );
}
