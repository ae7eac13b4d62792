//! `calibrate export` end to end: a kinematic and an elastic fit on a small simulated campaign, exported as the
//! robot's URDF (UR10, iiwa) or DH table (UR5), loaded back as the robot. The exported robot must predict the
//! model's geometry to 1e-9 m at 1000 configurations, carry an elastic model's compliances (so that its flange at
//! the deflected angles is the model's prediction), and, given to `calibrate --method nominal`, have the model's
//! own held-out error. A model that is not a robot description is refused on one line.

use std::ffi::OsStr;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use calibench::app::export::max_difference;
use calibench::calib::error_model::FrameErrors;
use calibench::calib::kinematic::{GravityModel, KinematicModel};
use calibench::calib::registry::SavedModel;
use calibench::robot::description::compliances;
use calibench::robot::dh::DhChain;
use calibench::robot::{Chain, Payload, flange_pose};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use serde_json::Value;
use tempfile::TempDir;

use crate::common::assert_clean_failure;

/// Tracker noise per axis (m): a laser tracker's, as `tests/common/synthetic.rs` has it.
const NOISE: f64 = 10e-6;
/// Points of the campaign: half train, a quarter validation, a quarter test (the `split` column).
const POINTS: usize = 240;
/// Size of each DH-frame error component (m, rad): a real arm's tenth of a millimetre.
const ERROR: f64 = 1e-4;
/// Joint compliances of the elastic campaign (rad/Nm), of the iiwa's order (DESIGN: 1e-5 to 1e-4).
const COMPLIANCE: f64 = 2e-5;
/// The campaigns' centre configurations (rad), as `tests/common/synthetic.rs` has them.
const UR_CENTRE: &[f64] = &[0.3, -1.4, 1.6, -1.8, -1.5, 0.2];
const IIWA_CENTRE: &[f64] = &[0.0, 0.6, 0.0, -1.5, 0.0, -0.8, 0.0];

fn calibrate(args: &[&OsStr]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_calibrate"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("calibrate starts")
}

fn ok(args: &[&OsStr]) -> String {
    let out = calibrate(args);
    assert!(
        out.status.success(),
        "calibrate {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

/// A campaign of `robot` around `centre` with random DH-frame errors (and compliances when `elastic`), seen by a
/// tracker at an unknown pose, written as `measurements.csv` with a `split` column.
fn campaign(dir: &Path, robot: &str, centre: &[f64], elastic: bool, seed: u64) -> PathBuf {
    let chain = calibench::robot::load(robot, None).unwrap();
    let dh = DhChain::from_chain(&chain).unwrap();
    let n = chain.dof();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let errors: FrameErrors = (0..n)
        .map(|_| std::array::from_fn(|_| rng.random_range(-ERROR..ERROR)))
        .collect();
    let gravity = GravityModel::new(&chain, &dh, Payload::NONE).unwrap();
    let tracker = Isometry3::from_parts(
        Translation3::new(3.0, 0.3, 1.7),
        UnitQuaternion::from_euler_angles(0.01, 0.02, 3.1),
    );
    let (mount_nominal, mount_true) = (
        Point3::new(0.0, 0.0, 0.03),
        Point3::new(6e-4, -4e-4, 0.0302),
    );
    let noise = Normal::new(0.0, NOISE).unwrap();
    let names = chain.joint_names();
    let mut text = format!(
        "point_id,split,{},nom_x1,nom_y1,nom_z1,x1,y1,z1\n",
        names.join(",")
    );
    for i in 0..POINTS {
        let q: Vec<f64> = centre
            .iter()
            .map(|c| c + rng.random_range(-0.5..0.5))
            .collect();
        let reached: Vec<f64> = if elastic {
            let tau = gravity.torques(&dh, &q);
            q.iter()
                .zip(&tau)
                .map(|(q, t)| q + COMPLIANCE * t)
                .collect()
        } else {
            q.clone()
        };
        let truth = calibench::calib::error_model::flange_pose_with_errors(&dh, &reached, &errors);
        let seen = tracker.inverse_transform_point(&(truth * mount_true));
        let nominal = dh.flange_pose(&q) * mount_nominal;
        let split = match i % 4 {
            0 | 1 => "train",
            2 => "val",
            _ => "test",
        };
        let cells: Vec<String> = q
            .iter()
            .map(|v| v.to_string())
            .chain(nominal.iter().map(|v| v.to_string()))
            .chain(
                seen.iter()
                    .map(|v| (v + noise.sample(&mut rng)).to_string()),
            )
            .collect();
        text.push_str(&format!("{i},{split},{}\n", cells.join(",")));
    }
    let path = dir.join(format!("measurements_{seed}.csv"));
    std::fs::write(&path, text).unwrap();
    path
}

fn os(s: &str) -> &OsStr {
    OsStr::new(s)
}

fn json(path: &Path) -> Value {
    serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap()
}

fn test_rms_mm(report: &Path) -> f64 {
    json(report)["test"]["after"]["rms_mm"].as_f64().unwrap()
}

fn kinematic_model(path: &Path) -> KinematicModel {
    let text = std::fs::read_to_string(path).unwrap();
    match serde_json::from_str::<SavedModel>(&text).unwrap() {
        SavedModel::Kinematic(m) => *m,
        _ => panic!("{} is not a kinematic model", path.display()),
    }
}

/// The exported robot's flange at the angles the model deflects `q` to, against the model's prediction (m).
fn deflected_difference(robot: &Chain, model: &KinematicModel, c: &[f64], seed: u64) -> f64 {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let gravity = model.gravity.as_ref().unwrap();
    (0..1000)
        .map(|_| {
            let q: Vec<f64> = robot
                .joints
                .iter()
                .map(|j| rng.random_range(j.lower.max(-3.0)..j.upper.min(3.0)))
                .collect();
            let tau = gravity.torques(&model.basis.dh, &q);
            let bent: Vec<f64> = q
                .iter()
                .zip(&tau)
                .zip(c)
                .map(|((q, t), c)| q + c * t)
                .collect();
            let got = flange_pose(robot, &bent).translation.vector;
            use calibench::calib::method::Fitted;
            (got - model.predict(&q).position.coords).norm()
        })
        .fold(0.0, f64::max)
}

/// `calibrate --method METHOD` on a fresh campaign of `robot`: the data and the fit's directory.
fn fit(dir: &Path, robot: &str, centre: &[f64], method: &str, seed: u64) -> (PathBuf, PathBuf) {
    std::fs::create_dir_all(dir).unwrap();
    let data = campaign(dir, robot, centre, method == "elastic", seed);
    let fit = dir.join(format!("fit_{method}"));
    ok(&[
        os("--data"),
        data.as_os_str(),
        os("--robot"),
        os(robot),
        os("--method"),
        os(method),
        os("--out"),
        fit.as_os_str(),
    ]);
    (data, fit)
}

/// `calibrate export` of the model in `fit`.
fn export(fit: &Path, robot: &str, format: &str, out: &Path) -> Output {
    let model = fit.join("model.json");
    calibrate(&[
        os("export"),
        os("--model"),
        model.as_os_str(),
        os("--robot"),
        os(robot),
        os("--format"),
        os(format),
        os("--out"),
        out.as_os_str(),
    ])
}

/// `calibrate --robot EXPORTED --method nominal` on the campaign: its held-out RMS is the model's, up to the
/// registration, which the nominal method makes on the training and validation points and the fitted model
/// refined on the training points alone (so the two differ at the tracker's noise: within 2 %). A UR fit makes
/// the parallel axes 2, 3 and 4 slightly skew: calibrate's DH form of the exported robot has Hayati rows there.
fn held_out(dir: &Path, data: &Path, fit: &Path, file: &Path, robot: &str, method: &str) {
    let out = dir.join("nominal");
    let args = [
        os("--data"),
        data.as_os_str(),
        os("--robot"),
        file.as_os_str(),
        os("--method"),
        os("nominal"),
        os("--out"),
        out.as_os_str(),
    ];
    let run = calibrate(&args);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let (own, via) = (
        test_rms_mm(&fit.join("report.json")),
        test_rms_mm(&out.join("report.json")),
    );
    eprintln!(
        "{robot} {method}: held-out RMS {own:.6} mm (model), {via:.6} mm (nominal on the exported robot)"
    );
    assert!(
        (own - via).abs() <= 0.02 * own,
        "{robot} {method}: held-out {own} mm vs {via} mm"
    );
}

/// Fit, export, load back, compare: kinematic and elastic.
fn round_trip(robot: &str, format: &str, centre: &[f64]) {
    let dir = TempDir::new().unwrap();
    for (method, seed) in [("kinematic", 1), ("elastic", 2)] {
        let dir = dir.path().join(method);
        let (data, fit) = fit(&dir, robot, centre, method, seed);
        let exported = dir.join("export");
        let done = export(&fit, robot, format, &exported);
        assert!(
            done.status.success(),
            "export: {}",
            String::from_utf8_lossy(&done.stderr)
        );
        let said = String::from_utf8_lossy(&done.stdout);
        let file = exported.join(if format == "urdf" {
            "robot.urdf"
        } else {
            "robot.toml"
        });
        let back = calibench::robot::load(&file, None).unwrap();
        let model = kinematic_model(&fit.join("model.json"));
        let worst = max_difference(&back, &model, 1000, 7);
        let c = compliances(&file).unwrap();
        eprintln!(
            "{robot} {method} → {format}: max difference {worst:.2e} m at 1000 configurations\n{said}"
        );
        assert!(
            worst < 1e-9,
            "{robot} {method}: exported robot differs by {worst} m"
        );
        // Loaded as the robot, the elastic export is the unloaded arm: its held-out error is not the model's
        // (the compliances are checked below, read back and applied).
        if method == "kinematic" {
            held_out(&dir, &data, &fit, &file, robot, method);
        }
        if method == "elastic" {
            let c = c.expect("the elastic export carries compliances");
            let values: Vec<f64> = c.iter().map(|(_, v)| *v).collect();
            let names: Vec<String> = c.into_iter().map(|(n, _)| n).collect();
            assert_eq!(names, model.basis.joint_names);
            assert_eq!(
                Some(&values),
                model.compliance.as_ref(),
                "compliances read back"
            );
            assert!(values.iter().any(|&v| v > COMPLIANCE / 2.0), "{values:?}");
            let bent = deflected_difference(&back, &model, &values, 8);
            eprintln!(
                "{robot} elastic: with the compliances read back, {bent:.2e} m from the model's prediction"
            );
            assert!(
                bent < 1e-9,
                "{robot}: deflected exported robot differs by {bent} m"
            );
        } else {
            assert!(c.is_none(), "a kinematic export carries no compliances");
        }
    }
}

#[test]
fn ur10_exports_as_urdf_and_loads_back_as_the_model() {
    round_trip("robots/ur10.urdf", "urdf", UR_CENTRE);
}

#[test]
fn iiwa_exports_as_urdf_and_loads_back_as_the_model() {
    round_trip("robots/iiwa7.urdf", "urdf", IIWA_CENTRE);
}

#[test]
fn iiwa_exports_as_dh_and_loads_back_as_the_model() {
    round_trip("robots/iiwa7.urdf", "dh", IIWA_CENTRE);
}

#[test]
fn ur5_exports_as_urdf_and_loads_back_as_the_model() {
    round_trip("robots/ur5.toml", "urdf", UR_CENTRE);
}

/// The UR5's parallel axes 2, 3 and 4 come out of the fit slightly skew: the DH table holds them in Hayati
/// rows (`beta`), and reads back as the model.
#[test]
fn ur5_exports_as_dh_and_loads_back_as_the_model() {
    round_trip("robots/ur5.toml", "dh", UR_CENTRE);
}

/// The exported UR5 as the nominal robot of a new calibration: its DH form has Hayati rows, whose frames carry
/// the error model as standard ones do. A known perturbation of it is recovered to the tracker's noise, as
/// the same perturbation (same seed: same errors, configurations and noise) of the nominal UR5 is.
#[test]
fn a_kinematic_fit_on_an_exported_ur5_recovers_a_known_perturbation() {
    let dir = TempDir::new().unwrap();
    let (_, first) = fit(
        &dir.path().join("first"),
        "robots/ur5.toml",
        UR_CENTRE,
        "kinematic",
        5,
    );
    let exported = dir.path().join("export");
    let done = export(&first, "robots/ur5.toml", "dh", &exported);
    assert!(
        done.status.success(),
        "{}",
        String::from_utf8_lossy(&done.stderr)
    );
    let file = exported.join("robot.toml");
    let text = std::fs::read_to_string(&file).unwrap();
    assert!(text.contains("beta = "), "no Hayati row:\n{text}");
    let dh = DhChain::from_chain(&calibench::robot::load(&file, None).unwrap()).unwrap();
    let hayati = dh.rows.iter().filter(|r| r.beta != 0.0).count();
    assert_eq!(hayati, 2, "rows 2 and 3: {:?}", dh.rows);
    let fit_of =
        |name: &str, robot: &str| fit(&dir.path().join(name), robot, UR_CENTRE, "kinematic", 6).1;
    let (on_export, on_nominal) = (
        fit_of("on_export", file.to_str().unwrap()),
        fit_of("on_nominal", "robots/ur5.toml"),
    );
    let rms = |fit: &Path, when: &str| {
        json(&fit.join("report.json"))["test"][when]["rms_mm"]
            .as_f64()
            .unwrap()
    };
    let kept = |fit: &Path| kinematic_model(&fit.join("model.json")).kept.len();
    let (before, after) = (rms(&on_export, "before"), rms(&on_export, "after"));
    let reference = rms(&on_nominal, "after");
    eprintln!(
        "exported UR5 ({hayati} Hayati rows) perturbed: held-out {before:.4} mm nominal, {after:.4} mm fitted \
         ({} parameters kept); the nominal UR5 perturbed alike: {:.4} mm nominal, {reference:.4} mm fitted ({} kept)",
        kept(&on_export),
        rms(&on_nominal, "before"),
        kept(&on_nominal)
    );
    // The tracker's noise as a 3-D RMS is √3 · 10 µm = 0.017 mm.
    assert!(after < 1.5 * 3f64.sqrt() * NOISE * 1e3, "{after} mm");
    assert!(before > 2.5 * after, "{before} mm before the fit");
    assert!(
        (after - reference).abs() < 0.05 * reference,
        "{after} against {reference} mm"
    );
}

#[test]
fn a_model_that_is_not_a_robot_description_is_refused_on_one_line() {
    let dir = TempDir::new().unwrap();
    let (_, fit) = fit(
        dir.path(),
        "robots/iiwa7.urdf",
        IIWA_CENTRE,
        "paper-rotxyz",
        3,
    );
    let out = dir.path().join("export");
    let refused = export(&fit, "robots/iiwa7.urdf", "urdf", &out);
    let line = assert_clean_failure(
        &refused,
        &out,
        &["not a robot description", "calibrate apply"],
    );
    eprintln!("{line}");
}
