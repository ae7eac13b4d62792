//! A robot from its datasheet's DH table (`robots/*.toml`, `calibench::robot::description`): the UR5's table
//! against a URDF of the same arm drawn in other frames, the modified-DH form of the same table, the centres of
//! mass placed in the DH frames, bad descriptions refused on one line, and the built-in robots used from a
//! directory that has none.

use std::f64::consts::PI;
use std::path::Path;
use std::process::Command;

use nalgebra::{Isometry3, Point3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use calibench::robot::{self, Chain, Frames, flange_pose, forward_kinematics};

use crate::common::read;

fn repo(path: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(path)
}

const UR5_TOML: &str = include_str!("../robots/ur5.toml");

/// The UR5's published standard DH table: (a, alpha, d) per joint.
const UR5_DH: [(f64, f64, f64); 6] = [
    (0.0, PI / 2.0, 0.089159),
    (-0.425, 0.0, 0.0),
    (-0.39225, 0.0, 0.0),
    (0.0, PI / 2.0, 0.10915),
    (0.0, -PI / 2.0, 0.09465),
    (0.0, 0.0, 0.0823),
];

fn random_configurations(chain: &Chain, n: usize, seed: u64) -> Vec<Vec<f64>> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..n)
        .map(|_| {
            chain
                .joints
                .iter()
                .map(|j| rng.random_range(j.lower..=j.upper))
                .collect()
        })
        .collect()
}

/// Position (m) and rotation (rad) differences of two poses.
fn difference(a: &Isometry3<f64>, b: &Isometry3<f64>) -> (f64, f64) {
    (
        (a.translation.vector - b.translation.vector).norm(),
        a.rotation.angle_to(&b.rotation),
    )
}

#[test]
fn the_ur5_dh_table_and_its_urdf_agree_at_100_configurations() {
    let dh = robot::load(repo("robots/ur5.toml"), None).expect("robots/ur5.toml loads");
    let urdf = robot::load(repo("robots/ur5.urdf"), Some("tool0")).expect("robots/ur5.urdf loads");
    assert_eq!(dh.dof(), 6);
    assert_eq!(dh.joint_names(), urdf.joint_names());
    // ROS' base_link is the controller's Base turned by π about z; tool0 is the flange frame in both.
    let base = Isometry3::rotation(Vector3::z() * PI);
    let (mut worst_m, mut worst_rad) = (0.0f64, 0.0f64);
    for q in random_configurations(&dh, 100, 5) {
        let (m, rad) = difference(&(base * flange_pose(&dh, &q)), &flange_pose(&urdf, &q));
        worst_m = worst_m.max(m);
        worst_rad = worst_rad.max(rad);
    }
    assert!(
        worst_m <= 1e-9 && worst_rad <= 1e-9,
        "DH table and URDF differ by up to {worst_m:e} m and {worst_rad:e} rad"
    );
    // And the table is the published product Π Rz(q) Tz(d) Tx(a) Rx(α), computed here independently.
    for q in random_configurations(&dh, 20, 6) {
        let mut t = Isometry3::identity();
        for ((a, alpha, d), qi) in UR5_DH.iter().zip(&q) {
            t = t
                * Isometry3::rotation(Vector3::z() * *qi)
                * Isometry3::translation(0.0, 0.0, *d)
                * Isometry3::translation(*a, 0.0, 0.0)
                * Isometry3::rotation(Vector3::x() * *alpha);
        }
        let (m, rad) = difference(&t, &flange_pose(&dh, &q));
        assert!(m <= 1e-12 && rad <= 1e-12, "{m:e} m, {rad:e} rad");
    }
}

/// `robots/ur5.toml` rewritten as a modified-DH (Craig) table: row i takes a and alpha of the row before it.
fn modified_ur5() -> String {
    let mut text = String::from("name = \"ur5-modified\"\nconvention = \"modified-dh\"\n");
    for (i, (_, _, d)) in UR5_DH.iter().enumerate() {
        let (a, alpha) = if i == 0 {
            (0.0, 0.0)
        } else {
            (UR5_DH[i - 1].0, UR5_DH[i - 1].1)
        };
        text += &format!(
            "[[joints]]\nname = \"j{i}\"\na = {a:?}\nalpha = {alpha:?}\nd = {d:?}\nlower = -6.3\nupper = 6.3\n"
        );
    }
    // The last row's a and alpha (0 for the UR5) would go into `tool`.
    text
}

#[test]
fn a_modified_dh_table_of_the_same_arm_gives_the_same_flange() {
    let standard = robot::description::from_toml(UR5_TOML, "ur5.toml").unwrap();
    let modified = robot::description::from_toml(&modified_ur5(), "modified").unwrap();
    for q in random_configurations(&standard, 100, 7) {
        let (m, rad) = difference(&flange_pose(&standard, &q), &flange_pose(&modified, &q));
        assert!(m <= 1e-12 && rad <= 1e-12, "{m:e} m, {rad:e} rad at {q:?}");
    }
    // Degrees are degrees: the same table with alpha in degrees.
    let deg = UR5_TOML
        .replace("angle_unit = \"rad\"", "angle_unit = \"deg\"")
        .replace("alpha = 1.5707963267948966", "alpha = 90.0")
        .replace("alpha = -1.5707963267948966", "alpha = -90.0")
        .replace("-6.283185307179586", "-360.0")
        .replace("6.283185307179586", "360.0")
        .replace("3.141592653589793", "180.0");
    let in_degrees = robot::description::from_toml(&deg, "deg").unwrap();
    for q in random_configurations(&standard, 20, 8) {
        let (m, rad) = difference(&flange_pose(&standard, &q), &flange_pose(&in_degrees, &q));
        assert!(m <= 1e-12 && rad <= 1e-12, "{m:e} m, {rad:e} rad");
    }
    assert!((in_degrees.joints[0].upper - 2.0 * PI).abs() < 1e-12);
}

/// A table with Hayati rows (`beta` on rows 2 and 3, as `calibrate export` writes a calibrated UR arm) is the
/// product Π Rz(q) Tz(d) Tx(a) Rx(α) Ry(β), and calibench's own DH form of the loaded chain is that table again.
/// `beta` in a modified-DH table is refused on one line.
#[test]
fn a_table_with_hayati_rows_is_the_product_with_ry_beta_and_reads_back() {
    let beta = [0.0, 2e-4, -1.5e-4, 0.0, 0.0, 0.0];
    let text = UR5_TOML
        .replacen("d = 0.0\n", "d = 0.0\nbeta = 2e-4\n", 1)
        .replacen(
            "a = -0.39225\nalpha = 0.0\nd = 0.0\n",
            "a = -0.39225\nalpha = 0.0\nd = 0.0\nbeta = -1.5e-4\n",
            1,
        );
    assert_eq!(text.matches("beta = ").count(), 2, "{text}");
    let chain = robot::description::from_toml(&text, "hayati.toml").unwrap();
    for q in random_configurations(&chain, 20, 9) {
        let mut t = Isometry3::identity();
        for (((a, alpha, d), b), qi) in UR5_DH.iter().zip(beta).zip(&q) {
            t = t
                * Isometry3::rotation(Vector3::z() * *qi)
                * Isometry3::translation(0.0, 0.0, *d)
                * Isometry3::translation(*a, 0.0, 0.0)
                * Isometry3::rotation(Vector3::x() * *alpha)
                * Isometry3::rotation(Vector3::y() * b);
        }
        let (m, rad) = difference(&t, &flange_pose(&chain, &q));
        assert!(m <= 1e-12 && rad <= 1e-12, "{m:e} m, {rad:e} rad");
    }
    let dh = calibench::robot::dh::DhChain::from_chain(&chain).unwrap();
    for (i, (r, (a, alpha, d))) in dh.rows.iter().zip(UR5_DH).enumerate() {
        let diff = [
            r.a - a,
            r.alpha - alpha,
            r.d - d,
            r.beta - beta[i],
            r.theta_offset,
        ];
        assert!(diff.iter().all(|v| v.abs() < 1e-12), "row {i}: {r:?}");
    }
    let modified = modified_ur5().replacen("d = 0.0\n", "d = 0.0\nbeta = 1e-4\n", 1);
    let e = robot::description::from_toml(&modified, "modified.toml")
        .expect_err("beta in modified DH")
        .line();
    assert!(e.contains("modified.toml") && e.contains("beta"), "{e}");
}

#[test]
fn centres_of_mass_sit_where_the_datasheet_puts_them_in_dh_frame_i() {
    let chain = robot::load(repo("robots/ur5.toml"), None).unwrap();
    let coms = [
        [0.0, -0.02561, 0.00193],
        [0.2125, 0.0, 0.11336],
        [0.15, 0.0, 0.0265],
        [0.0, -0.0018, 0.01634],
        [0.0, 0.0018, 0.01634],
        [0.0, 0.0, -0.001159],
    ];
    let masses = [3.7, 8.393, 2.275, 1.219, 1.219, 0.1879];
    let mut frames = Frames::new(&chain);
    for q in random_configurations(&chain, 10, 9) {
        forward_kinematics(&chain, &q, &mut frames);
        let mut dh_frame = Isometry3::identity();
        for (i, ((a, alpha, d), qi)) in UR5_DH.iter().zip(&q).enumerate() {
            dh_frame = dh_frame
                * Isometry3::rotation(Vector3::z() * *qi)
                * Isometry3::translation(*a, 0.0, *d)
                * Isometry3::rotation(Vector3::x() * *alpha);
            let want = dh_frame * Point3::from(coms[i]);
            let inertial = &chain.bodies[i + 1].inertial;
            let got = frames.body[i + 1] * inertial.com;
            assert!(
                (got - want).norm() < 1e-12,
                "link {i}: {got} against {want}"
            );
            assert_eq!(inertial.mass, masses[i]);
        }
    }
}

#[test]
fn bad_descriptions_are_refused_on_one_line_naming_file_and_key() {
    let dir = tempfile::tempdir().unwrap();
    let cases = [
        (
            "unknown key",
            UR5_TOML.replacen("d = 0.089159", "d = 0.089159\nlenght = 1.0", 1),
            "lenght",
        ),
        (
            "missing field",
            UR5_TOML.replacen("a = -0.425\n", "", 1),
            "`a`",
        ),
        (
            "not a number",
            UR5_TOML.replacen("d = 0.10915", "d = nan", 1),
            "joints[3].d",
        ),
        (
            "absurd",
            UR5_TOML.replacen("a = -0.39225", "a = -3.9e5", 1),
            "joints[2].a",
        ),
        (
            "limits",
            UR5_TOML.replacen("lower = -6.283185307179586", "lower = 7.0", 1),
            "joints[0].lower",
        ),
        (
            "twice",
            UR5_TOML.replacen(
                "name = \"elbow_joint\"",
                "name = \"shoulder_lift_joint\"",
                1,
            ),
            "joints[2].name",
        ),
        (
            "convention",
            UR5_TOML.replacen("convention = \"dh\"", "convention = \"dh-ish\"", 1),
            "dh-ish",
        ),
    ];
    for (what, text, needle) in cases {
        let path = dir.path().join("arm.toml");
        std::fs::write(&path, &text).unwrap();
        let e = robot::load(&path, None).expect_err(what).line();
        assert!(e.contains("arm.toml") && e.contains(needle), "{what}: {e}");
        assert_eq!(e.lines().count(), 1, "{what}: {e}");
    }
    // Through a binary: exit 1, one line.
    let path = dir.path().join("arm.toml");
    std::fs::write(&path, UR5_TOML.replacen("d = 0.10915", "d = nan", 1)).unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_calibrate"))
        .args(["--data", "nowhere.csv", "--robot"])
        .arg(&path)
        .current_dir(dir.path())
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(
        err.contains("arm.toml") && err.contains("joints[3].d"),
        "{err}"
    );
}

/// The default robot and mapping are built in: a campaign and a calibration run from a directory that holds
/// neither `robots/` nor `mappings/`, and a missing data directory is named.
#[test]
fn the_tools_run_from_any_directory() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("small.toml"),
        crate::study_cli::small_study(),
    )
    .unwrap();
    let run = |bin: &str, args: &[&str]| {
        Command::new(bin)
            .args(args)
            .current_dir(dir.path())
            .output()
            .unwrap()
    };
    let o = run(
        env!("CARGO_BIN_EXE_campaign"),
        &["small.toml", "--out", "sim", "--threads", "1"],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let o = run(
        env!("CARGO_BIN_EXE_calibrate"),
        &["--data", "sim/measurements.csv", "--method", "kinematic"],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(!read(&dir.path().join("results/calibrate/model.json")).is_empty());
    let o = run(env!("CARGO_BIN_EXE_real_data"), &[]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("ipa-ur10") && err.contains("--data-dir"),
        "{err}"
    );
}
