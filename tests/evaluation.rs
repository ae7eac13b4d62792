//! The evaluation against the truth: the oracle's test error is the tracker's noise and its ground-truth and
//! closed-loop errors vanish; a method's ground-truth error is computed in its own registered frame (checked
//! against an independent computation); `campaign` writes `evaluation.json` with every method.

use crate::common::{IDEAL_ELASTIC, edit, read};

use std::path::Path;
use std::process::Command;
use std::sync::OnceLock;

use calibench::app::simulate;
use calibench::calib::method::{FitContext, Fitted};
use calibench::calib::registry::MethodKind;
use calibench::calib::regression::RegressionOptions;
use calibench::campaign::Simulation;
use calibench::eval::GroundTruth;
use calibench::eval::accuracy::{EvaluationConfig, split_campaign};
use calibench::eval::judge::{
    PointErrors, closed_loop_errors, test_errors, test_errors_at, truth_errors, truth_set_errors,
};
use calibench::eval::{Oracle, centre};
use calibench::robot::dh::{ChainPose, DhChain};
use calibench::scenario::Scenario;
use calibench::truth::TrueState;
use nalgebra::Point3;
use serde_json::Value;
use tempfile::TempDir;

const PAPER: &str = include_str!("../scenarios/paper_iiwa.toml");
const PAPER_POSE: &str = include_str!("../scenarios/paper_iiwa_pose.toml");

/// Small ground-truth sets: enough points for the assertions, fast to build.
fn small_config() -> EvaluationConfig {
    EvaluationConfig {
        split: [0.25, 0.25, 0.5],
        grid_points: 150,
        shell_points: 60,
        closed_loop_points: 40,
        ..EvaluationConfig::default()
    }
}

struct Fixture {
    scenario: Scenario,
    sim: Simulation,
    truth: GroundTruth,
}

/// paper_iiwa on the ideal truth (no lost motion, warm-up or tracker systematics, which the oracle, knowing
/// the robot but not the campaign's history, would not reproduce) with 600 points and no repeatability
/// noise: the only noise left is the tracker's.
fn paper() -> &'static Fixture {
    static F: OnceLock<Fixture> = OnceLock::new();
    F.get_or_init(|| {
        let text = edit(IDEAL_ELASTIC, "points = 2335", "points = 600");
        let text = edit(&text, "repeatability_rad = 8e-6", "repeatability_rad = 0.0");
        fixture(&text)
    })
}

/// paper_iiwa_pose (a nest of three reflectors, rotated on its mount) with 200 points.
fn pose() -> &'static Fixture {
    static F: OnceLock<Fixture> = OnceLock::new();
    F.get_or_init(|| fixture(&edit(PAPER_POSE, "points = 875", "points = 200")))
}

fn fixture(text: &str) -> Fixture {
    let scenario = Scenario::parse(text, "test scenario").unwrap();
    let sim = simulate(&scenario).unwrap();
    let truth = GroundTruth::build(
        &sim.world,
        &scenario.campaign,
        &scenario.regions,
        &small_config().ground_truth(),
    )
    .unwrap();
    assert!(truth.grid.points.len() > 100, "{}", truth.grid.points.len());
    assert!(!truth.shell.points.is_empty());
    assert!(truth.closed_loop.points.len() > 20);
    Fixture {
        scenario,
        sim,
        truth,
    }
}

#[test]
fn the_oracle_test_error_is_the_tracker_noise_and_its_truth_error_is_zero() {
    let f = paper();
    let (_, _, test) = split_campaign(&f.sim, small_config().split, f.scenario.world.seed).unwrap();
    assert!(test.len() >= 250, "{}", test.len());
    let oracle = Oracle::new(&f.sim.world).unwrap();
    let errors = test_errors(&oracle, &test).unwrap();
    let measured = errors.position.iter().sum::<f64>() / errors.position.len() as f64;
    // Per-axis σ from the noise model at each true point; an isotropic 3-D normal of per-axis σ has mean
    // distance σ·√(8/π) (the mean of a chi distribution with 3 degrees of freedom).
    let expected = test
        .q
        .iter()
        .map(|q| f.sim.world.tracker.noise_at(&oracle.predict(q).position))
        .sum::<f64>()
        / test.len() as f64
        * (8.0 / std::f64::consts::PI).sqrt();
    assert!(
        (measured / expected - 1.0).abs() < 0.10,
        "oracle test error {measured:.3e} m, the noise model predicts {expected:.3e} m"
    );

    for (name, set) in [("grid", &f.truth.grid), ("shell", &f.truth.shell)] {
        let e = truth_errors(&oracle, &f.truth, &set.points);
        assert_eq!(e.position.len(), set.points.len());
        let max = e.position.iter().copied().fold(0.0, f64::max);
        assert!(max <= 1e-9, "oracle {name} error {max:.3e} m");
    }
}

/// The study judges every run through the nominal chain's poses computed once ([`ChainPose`]): every method
/// must give there the bits it gives predicting at each configuration, or the study's figures would move.
#[test]
fn judging_through_the_truths_poses_gives_the_bits_of_predicting_at_each_configuration() {
    let f = paper();
    let (train, val, test) =
        split_campaign(&f.sim, small_config().split, f.scenario.world.seed).unwrap();
    let ctx = FitContext::of(&f.sim.world);
    let poses: Vec<ChainPose> = test.q.iter().map(|q| f.truth.nominal.pose(q)).collect();
    let bits = |e: &PointErrors| {
        let b = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        (b(&e.position), b(&e.orientation))
    };
    for kind in MethodKind::ALL {
        let model = kind.fit(&ctx, &train, &val).unwrap();
        let model = model.as_ref();
        // Else the poses would not be used and the comparison below would hold trivially.
        assert!(model.dh() == &f.truth.nominal, "{}", model.method());
        for set in [&f.truth.grid, &f.truth.shell] {
            let through_poses = truth_set_errors(model, &f.truth, set);
            let at_each = truth_errors(model, &f.truth, &set.points);
            assert_eq!(bits(&through_poses), bits(&at_each), "{}", model.method());
        }
        let through_poses = test_errors_at(model, &test, Some((&f.truth.nominal, &poses))).unwrap();
        let at_each = test_errors(model, &test).unwrap();
        assert_eq!(bits(&through_poses), bits(&at_each), "{}", model.method());
        for (q, pose) in test.q.iter().zip(&poses) {
            let p = model.predict_with(q, &[]);
            let (position, orientation) = model.point_at(pose, &[]);
            assert_eq!(
                position.coords.map(f64::to_bits),
                p.position.coords.map(f64::to_bits)
            );
            assert_eq!(
                orientation.coords.map(f64::to_bits),
                p.orientation.coords.map(f64::to_bits),
                "{}",
                model.method()
            );
            // `calibrate`'s predictions: the nominal kinematics and the prediction from one pass.
            let point = |p: &nalgebra::Point3<f64>| p.coords.map(f64::to_bits);
            let ((np, nr), both) = model.nominal_and_prediction(q, &[]);
            let (n, r) = model.nominal(q);
            let name = model.method();
            assert_eq!(point(&np), point(&n), "{name}");
            assert_eq!(nr.coords.map(f64::to_bits), r.coords.map(f64::to_bits));
            assert_eq!(point(&both.position), point(&p.position), "{name}");
            let linearized = point(&p.linearized_position);
            assert_eq!(point(&both.linearized_position), linearized, "{name}");
            let orientation = p.orientation.coords.map(f64::to_bits);
            assert_eq!(both.orientation.coords.map(f64::to_bits), orientation);
        }
    }
}

#[test]
fn a_methods_truth_error_is_measured_in_its_own_registered_frame() {
    let f = paper();
    let (train, val, _) =
        split_campaign(&f.sim, small_config().split, f.scenario.world.seed).unwrap();
    let dh = DhChain::from_chain(&f.sim.world.nominal).unwrap();
    let ctx = FitContext {
        share: None,
        chain: &f.sim.world.nominal,
        dh: &dh,
        payload: f.scenario.world.robot.payload(),
        regression: RegressionOptions::default(),
    };
    let model = MethodKind::Nominal.fit(&ctx, &train, &val).unwrap();
    let model = model.as_ref();
    let points = &f.truth.grid.points;
    let errors = truth_errors(model, &f.truth, points);

    // Independently: the true arm at each command, its true reflector seen by a perfect tracker, registered
    // into the base frame as the calibrate command does with truth.csv, against the nominal model.
    let mut state = TrueState::new(&f.sim.world.robot);
    let local = centre(&f.sim.world.mounting.actual);
    let mut worst: f64 = 0.0;
    let mut independent = Vec::new();
    for (p, e) in points.iter().zip(&errors.position) {
        let world = f.sim.world.robot.flange_pose(&p.q_cmd, &mut state).unwrap() * local;
        let in_tracker: Point3<f64> = f.sim.world.tracker.pose.inverse_transform_point(&world);
        let observed = model
            .registration()
            .observe_points(std::slice::from_ref(&p.q_cmd), &[vec![in_tracker]])
            .unwrap();
        let d = (observed[0].position - model.nominal(&p.q_cmd).0).norm();
        worst = worst.max((d - e).abs());
        independent.push(d);
    }
    assert!(
        worst < 1e-12,
        "the two computations differ by {worst:.3e} m"
    );
    let mean = independent.iter().sum::<f64>() / independent.len() as f64;
    // Not a degenerate agreement: the nominal model is off by a fraction of a millimetre.
    assert!(
        mean > 5e-5 && mean < 2e-3,
        "nominal truth error {mean:.3e} m"
    );
}

#[test]
fn the_oracle_closes_the_loop_and_the_nominal_model_does_not() {
    let f = paper();
    let oracle = Oracle::new(&f.sim.world).unwrap();
    let points = &f.truth.closed_loop.points;
    let e = closed_loop_errors(&oracle, &f.truth, &f.sim.world.robot, points);
    assert_eq!(e.failed, 0, "{:?}", e.first_failure);
    assert_eq!(e.position.len(), points.len());
    let max = e.position.iter().copied().fold(0.0, f64::max);
    assert!(max <= 1e-6, "oracle closed-loop error {max:.3e} m");

    let (train, val, _) =
        split_campaign(&f.sim, small_config().split, f.scenario.world.seed).unwrap();
    let dh = DhChain::from_chain(&f.sim.world.nominal).unwrap();
    let ctx = FitContext {
        share: None,
        chain: &f.sim.world.nominal,
        dh: &dh,
        payload: f.scenario.world.robot.payload(),
        regression: RegressionOptions::default(),
    };
    let nominal = MethodKind::Nominal.fit(&ctx, &train, &val).unwrap();
    let e = closed_loop_errors(nominal.as_ref(), &f.truth, &f.sim.world.robot, points);
    assert_eq!(e.failed, 0, "{:?}", e.first_failure);
    let mean = e.position.iter().sum::<f64>() / e.position.len() as f64;
    assert!(mean > 5e-5, "nominal closed-loop error {mean:.3e} m");
}

#[test]
fn with_a_nest_the_oracle_orientation_is_exact_on_the_truth_and_in_closed_loop() {
    let f = pose();
    let oracle = Oracle::new(&f.sim.world).unwrap();
    assert!(oracle.models_orientation());
    let (_, _, test) = split_campaign(&f.sim, small_config().split, f.scenario.world.seed).unwrap();
    let e = test_errors(&oracle, &test).unwrap();
    assert_eq!(e.orientation.len(), test.len());
    // The nest is rotated by 0.22 rad on its mount: an oracle that missed it would be off by that much.
    let worst = e.orientation.iter().copied().fold(0.0, f64::max);
    assert!(
        worst < 1e-3,
        "oracle test orientation error {worst:.3e} rad"
    );

    let e = truth_errors(&oracle, &f.truth, &f.truth.grid.points);
    assert_eq!(e.orientation.len(), f.truth.grid.points.len());
    assert!(e.orientation.iter().all(|a| *a <= 1e-9));
    assert!(e.position.iter().all(|d| *d <= 1e-9));

    let e = closed_loop_errors(
        &oracle,
        &f.truth,
        &f.sim.world.robot,
        &f.truth.closed_loop.points,
    );
    assert_eq!(e.failed, 0, "{:?}", e.first_failure);
    assert!(e.position.iter().all(|d| *d <= 1e-6));
    assert!(e.orientation.iter().all(|a| *a <= 1e-6));
}

#[test]
fn an_unknown_method_in_the_evaluation_is_refused() {
    let text = edit(PAPER, "\"hybrid\",", "\"hybird\",");
    let err = Scenario::parse(&text, "typo.toml").unwrap_err().to_string();
    assert!(
        err.contains("evaluation") && err.contains("hybird"),
        "{err}"
    );
}

#[test]
fn campaign_writes_evaluation_json_with_every_method() {
    let dir = TempDir::new().unwrap();
    // The ideal truth: the oracle's assertion below needs a robot without history (lost motion, warm-up),
    // which the oracle, approaching every pose from the posture, cannot know.
    let mut text = edit(IDEAL_ELASTIC, "points = 2335", "points = 200");
    for (from, to) in [
        ("grid_points = 2000", "grid_points = 120"),
        ("shell_points = 500", "shell_points = 40"),
        ("closed_loop_points = 200", "closed_loop_points = 20"),
    ] {
        text = edit(&text, from, to);
    }
    let scenario = dir.path().join("small.toml");
    std::fs::write(&scenario, &text).unwrap();
    let out = dir.path().join("out");
    let output = Command::new(env!("CARGO_BIN_EXE_campaign"))
        .args([scenario.as_os_str(), "--out".as_ref(), out.as_os_str()])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap();
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(stdout.contains("oracle"), "{stdout}");

    let report: Value = serde_json::from_slice(&read(&out.join("evaluation.json"))).unwrap();
    let methods = report["methods"].as_array().unwrap();
    let scenario = Scenario::parse(&text, "small").unwrap();
    let listed = &scenario.evaluation.as_ref().unwrap().methods;
    assert_eq!(methods.len(), listed.len() + 1, "one entry per method");
    for (entry, name) in methods
        .iter()
        .zip(listed.iter().map(|m| m.name()).chain(["oracle"]))
    {
        assert_eq!(entry["method"], name);
        match entry["status"].as_str() {
            Some("ok") => {
                for view in ["test", "truth", "shell", "closed_loop"] {
                    let s = &entry[view]["position_mm"];
                    for field in ["n", "mean", "max", "std", "rms", "p95"] {
                        assert!(
                            s[field].is_number(),
                            "{name}.{view}.position_mm.{field}: {s}"
                        );
                    }
                }
            }
            Some("failed") => assert!(entry["error"].is_string(), "{entry}"),
            other => panic!("{name}: status {other:?}"),
        }
    }
    let oracle = methods.last().unwrap();
    assert_eq!(oracle["status"], "ok");
    // The evaluation's oracle registers the tracker frame from the noisy training points like every method:
    // its ground-truth error is that registration's error, above zero and far below a single point's noise.
    let oracle_truth = oracle["truth"]["position_mm"]["mean"].as_f64().unwrap();
    let oracle_test = oracle["test"]["position_mm"]["mean"].as_f64().unwrap();
    assert!(
        oracle_truth > 0.0 && oracle_truth < 0.25 * oracle_test,
        "oracle truth {oracle_truth} mm, test {oracle_test} mm"
    );
    assert!(check_split(&report, 200));
    assert!(Path::new(&out.join("campaign.json")).exists());
}

fn check_split(report: &Value, points: u64) -> bool {
    let s = &report["split"];
    ["train", "val", "test"]
        .iter()
        .map(|k| s[k].as_u64().unwrap())
        .sum::<u64>()
        == points
}
