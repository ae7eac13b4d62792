//! ISO 9283's pose accuracy and repeatability (issue 26): known answers of the simulated test (an arm with only
//! a constant offset, with repeatability only, with lost motion only, cold and warm), the shipped scenario
//! before and after calibration, the scenario's checks, and the test cubes of a measured file (a synthetic one
//! with known repeats; the real UR10's figures are in docs/iso9283.md).

use std::path::Path;

use nalgebra::{Isometry3, Point3, Translation3, Vector3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use tempfile::TempDir;

use calibench::app;
use calibench::app::campaign::CampaignOptions;
use calibench::calib::method::FitContext;
use calibench::calib::registry::REFERENCE;
use calibench::calib::tracker_frame::{Registration, TrackerFrame};
use calibench::campaign::iso_cube::CYCLE;
use calibench::dataset::Dataset;
use calibench::eval::iso_cubes::{self, Side};
use calibench::eval::iso9283::IsoTest;
use calibench::robot::dh::DhChain;
use calibench::robot::ik::{IkOptions, IkSolver};
use calibench::robot::{Chain, flange_pose, urdf};
use calibench::scenario::Scenario;
use calibench::truth::TrueRobot;
use calibench::truth::perturbation::Offset;
use calibench::world::World;

const PAPER: &str = include_str!("../scenarios/paper_iiwa.toml");
const PAPER_ISO: &str = include_str!("../scenarios/paper_iiwa_iso.toml");

/// The paper's robot, region and tracker place with no error at all: rigid joints, no noise, one reflector
/// mounted where the drawing says. `truth` adds to the `[truth]` section.
fn exact(truth: &str) -> Scenario {
    let text = format!(
        r#"
name = "iso_exact"
seed = 7

[robot]
urdf = "robots/iiwa7.urdf"
payload_kg = 0.4

[truth]
frame_translation_m = 0.0
frame_rotation_rad = 0.0
joint_zero_rad = 0.0
base_translation_m = 0.0
base_rotation_rad = 0.0
stiffness_nm_per_rad = [1e9, 1e9, 1e9, 1e9, 1e9, 1e9, 1e9]
{truth}

[tracker]
position_m = [3.0, 0.3, 1.75]
yaw_deg = 187.0
range_sigma_m = 0.0
range_sigma_per_m = 0.0
angle_sigma_rad = 0.0

[reflectors]
nominal_m = [[0.0, 0.0, 0.03]]
facing = [0.0, 0.0, 1.0]

[campaign]
posture_deg = [0.0, 30.0, 0.0, -90.0, 0.0, -30.0, 0.0]

[[regions]]
name = "paper"
center_m = [0.66, 0.0, 0.40]
size_m = [0.24, 0.68, 0.64]
points = 10
tool_rpy_deg = [0.0, 60.0, 0.0]
"#
    );
    let mut scenario = Scenario::parse(&text, "iso_exact").expect("the test scenario parses");
    scenario.world.robot.urdf = Path::new(env!("CARGO_MANIFEST_DIR")).join("robots/iiwa7.urdf");
    scenario
}

/// The world of `scenario` without gravity, so that the rigid joints do not sag even by nanometres.
fn weightless(scenario: &Scenario) -> World {
    let mut world = app::world(scenario).expect("the world builds");
    world.robot.gravity = Vector3::zeros();
    world
}

#[test]
fn a_constant_offset_is_the_pose_accuracy() {
    let scenario = exact("");
    let mut world = weightless(&scenario);
    let offset = Vector3::new(1.0e-3, -2.0e-3, 0.5e-3);
    let mut perturbation = world.robot.perturbation.clone();
    perturbation.base = Offset {
        translation: offset.into(),
        rotation: [0.0; 3],
    };
    let posture = world.robot.approach().to_vec();
    world.robot = TrueRobot::new(&world.nominal, perturbation, world.robot.payload).unwrap();
    world.robot.gravity = Vector3::zeros();
    world.robot.set_approach(&posture);
    let test = IsoTest::new(&world, &scenario.campaign, &scenario.regions, 0).unwrap();
    // The paper's region is 240 mm deep: the largest cube, reached whole.
    assert!((test.cube.edge_m - 0.24).abs() < 1e-12);
    let attempts = test.measure(&test.cube.q_nominal, 30, None).unwrap();
    for (k, a) in attempts.accuracy().unwrap().iter().enumerate() {
        assert_eq!(a.attempts, 30);
        assert!(
            (a.offset - offset).norm() < 1e-12,
            "P{}: barycentre off the command by {:?}, the arm by {offset:?}",
            k + 1,
            a.offset
        );
        assert!((a.ap - offset.norm()).abs() < 1e-12);
        assert!(a.rp.unwrap() < 1e-12, "no noise, no spread: RP {:?}", a.rp);
    }
}

/// The standard's RP computed here from the attempts, apart from the library's.
fn rp_by_hand(attempts: &[Vector3<f64>]) -> f64 {
    let n = attempts.len() as f64;
    let bary = attempts.iter().sum::<Vector3<f64>>() / n;
    let l: Vec<f64> = attempts.iter().map(|a| (a - bary).norm()).collect();
    let l_bar = l.iter().sum::<f64>() / n;
    let s_l = (l.iter().map(|x| (x - l_bar).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    l_bar + 3.0 * s_l
}

#[test]
fn repeatability_alone_gives_the_standards_rp_and_no_ap() {
    let scenario = exact("repeatability_rad = 2e-5");
    let world = weightless(&scenario);
    let test = IsoTest::new(&world, &scenario.campaign, &scenario.regions, 0).unwrap();
    let attempts = test.measure(&test.cube.q_nominal, 30, None).unwrap();
    for (k, a) in attempts.accuracy().unwrap().iter().enumerate() {
        let p = &attempts.positions[k];
        let rp = rp_by_hand(p);
        // 2e-5 rad on seven joints about 0.5 m from the point: tens of micrometres.
        assert!(rp > 1e-5 && rp < 2e-4, "P{}: RP {rp}", k + 1);
        assert!((a.rp.unwrap() - rp).abs() < 1e-15, "P{}", k + 1);
        let l_bar = p.iter().map(|v| (v - a.offset).norm()).sum::<f64>() / 30.0;
        assert!(
            a.ap < 0.5 * l_bar,
            "P{}: AP {} is noise averaged over 30 attempts, of order {l_bar}/√30",
            k + 1,
            a.ap
        );
    }
}

#[test]
fn lost_motion_moves_ap_but_every_attempt_comes_the_same_way() {
    let scenario = exact("hysteresis_rad = 2e-4");
    let world = weightless(&scenario);
    let test = IsoTest::new(&world, &scenario.campaign, &scenario.regions, 0).unwrap();
    let accuracy = test
        .measure(&test.cube.q_nominal, 30, None)
        .unwrap()
        .accuracy()
        .unwrap();
    // Each joint lags half the band behind its last motion: tenths of a millimetre off the command ...
    assert!(accuracy.iter().all(|a| a.ap > 1e-5), "{accuracy:?}");
    // ... the same at every attempt, the first P1 included (the unmeasured lead-in to P2 before it).
    assert!(
        accuracy.iter().all(|a| a.rp.unwrap() < 1e-12),
        "{accuracy:?}"
    );
    // The visiting order is the standard's: P1 → P5 → P4 → P3 → P2.
    assert_eq!(CYCLE, [0, 4, 3, 2, 1]);
}

#[test]
fn a_cold_arm_drifts_and_a_warm_one_does_not() {
    // The paper's warm-up, 20 → 23 °C with a 30 min time constant, 5 s from point to point.
    let thermal = "thermal = { start_c = 20.0, end_c = 23.0, time_constant_s = 1800.0, seconds_per_point = 5.0, \
                   expansion_per_k = 23e-6, reference_c = 20.0 }";
    let scenario = exact(thermal);
    let world = weightless(&scenario);
    let test = IsoTest::new(&world, &scenario.campaign, &scenario.regions, 0).unwrap();
    let rp = |warm_up_s: Option<f64>| -> Vec<f64> {
        let a = test.measure(&test.cube.q_nominal, 30, warm_up_s).unwrap();
        a.accuracy()
            .unwrap()
            .iter()
            .map(|a| a.rp.unwrap())
            .collect()
    };
    let (cold, warm) = (rp(Some(0.0)), rp(None));
    // Cold, the links grow by 23e-6 /K × ~1 K over the 151 visits (12.6 min): micrometres at ~1 m.
    assert!(cold.iter().all(|r| *r > 2e-6), "cold {cold:?}");
    assert!(warm.iter().all(|r| *r < 1e-12), "warm {warm:?}");
}

#[test]
fn the_shipped_scenario_is_paper_iiwa_with_the_test() {
    let paper = Scenario::parse(PAPER, "paper_iiwa").unwrap();
    let mut iso = Scenario::parse(PAPER_ISO, "paper_iiwa_iso").unwrap();
    let config = iso.iso9283.take().expect("an [iso9283] section");
    assert_eq!(config.cycles, 30);
    assert_eq!(config.region.as_deref(), Some("paper"));
    assert_eq!(iso.world.name, "paper_iiwa_iso");
    iso.world.name = paper.world.name.clone();
    iso.origin = paper.origin.clone();
    assert_eq!(
        iso, paper,
        "the same world, campaign and evaluation as paper_iiwa.toml"
    );
}

fn csv_rows(path: &Path) -> Vec<csv::StringRecord> {
    let mut reader = csv::Reader::from_path(path).unwrap();
    reader.records().map(|r| r.unwrap()).collect()
}

#[test]
fn calibration_improves_the_pose_accuracy_of_the_paper_iiwa() {
    let out = TempDir::new().unwrap();
    let mut scenario = Scenario::parse(PAPER_ISO, "paper_iiwa_iso").unwrap();
    scenario.world.robot.urdf = Path::new(env!("CARGO_MANIFEST_DIR")).join("robots/iiwa7.urdf");
    let options = CampaignOptions {
        out: Some(out.path().join("iso")),
        ..CampaignOptions::default()
    };
    let run = app::campaign::run(scenario, &options).unwrap();
    let rows = csv_rows(&out.path().join("iso/iso9283.csv"));
    // Nine methods and the oracle, five points each, none failed.
    assert_eq!(rows.len(), 50);
    assert!(
        rows.iter().all(|r| r[11].is_empty() && &r[5] == "30"),
        "{rows:?}"
    );
    let mean_ap = |method: &str| {
        let ap: Vec<f64> = rows
            .iter()
            .filter(|r| &r[0] == method)
            .map(|r| r[6].parse::<f64>().unwrap())
            .collect();
        assert_eq!(ap.len(), 5, "{method}");
        ap.iter().sum::<f64>() / 5.0
    };
    let nominal = mean_ap("nominal");
    for method in ["kinematic", "elastic", "hybrid"] {
        assert!(
            mean_ap(method) < 0.6 * nominal,
            "{method}: mean AP {} mm against the nominal {nominal} mm",
            mean_ap(method)
        );
    }
    // RP is the arm's: the same noise at the same visits, whichever model commands.
    let rp: Vec<f64> = rows.iter().map(|r| r[10].parse().unwrap()).collect();
    let (lo, hi) = rp
        .iter()
        .fold((f64::MAX, 0.0f64), |(a, b), r| (a.min(*r), b.max(*r)));
    assert!(hi < 1.5 * lo && hi < 0.1, "RP from {lo} to {hi} mm");
    let text = run.text();
    assert!(
        text.contains("ISO 9283 pose accuracy AP and repeatability RP (mm): cube of edge 240.0 mm")
    );
    // summary.md has the table, its mean AP the csv's (a scenario without a study gets a summary of it alone).
    let summary = std::fs::read_to_string(out.path().join("iso/summary.md")).unwrap();
    let row = summary
        .lines()
        .find(|l| l.starts_with("| nominal |"))
        .unwrap_or_else(|| panic!("no nominal row:\n{summary}"));
    let cells: Vec<&str> = row.split('|').map(str::trim).collect();
    assert_eq!(cells[7], format!("{nominal:.4}"), "{row}");
    assert_eq!(cells[8], format!("{hi:.4}"), "{row}");
}

#[test]
fn a_bad_iso9283_section_is_refused_with_its_key() {
    let refused = |from: &str, to: &str, needle: &str| {
        let text = crate::common::edit(PAPER_ISO, from, to);
        let e = Scenario::parse(&text, "bad.toml").unwrap_err().to_string();
        assert!(e.contains(needle) && e.contains("bad.toml"), "{e}");
        assert_eq!(e.lines().count(), 1, "{e}");
    };
    refused("cycles = 30 ", "cycles = 2 ", "iso9283.cycles = 2");
    refused(
        "region = \"paper\" ",
        "region = \"elsewhere\" ",
        "iso9283.region = 'elsewhere' is not a region",
    );
    refused(
        "cycles = 30 ",
        "warm_up_s = -1.0\n",
        "iso9283.warm_up_s = -1",
    );
    refused("cycles = 30 ", "payload_kg = nan\n", "iso9283.payload_kg");
    refused("cycles = 30 ", "cycle = 30\n", "unknown field `cycle`");
    let without_evaluation = {
        let start = PAPER_ISO.find("\n[evaluation]").unwrap();
        let end = PAPER_ISO.find("\n[iso9283]").unwrap();
        format!("{}{}", &PAPER_ISO[..start], &PAPER_ISO[end..])
    };
    let e = Scenario::parse(&without_evaluation, "bad.toml")
        .unwrap_err()
        .to_string();
    assert!(e.contains("add an [evaluation] section"), "{e}");
}

/// The iiwa's joints at the paper's posture and at the eight corners of a cube of edge `edge` centred on its
/// flange, at the posture's flange orientation (the nominal inverse kinematics): the centre first, then the
/// corners, as series D of the IPA UR10 measures its cubes.
fn cube_joints(chain: &Chain, edge: f64) -> Vec<Vec<f64>> {
    let q0: Vec<f64> = [0.0, 30.0, 0.0, -90.0, 0.0, -30.0, 0.0]
        .map(f64::to_radians)
        .to_vec();
    let home = flange_pose(chain, &q0);
    let mut solver = IkSolver::new(chain, IkOptions::default());
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let mut joints = vec![q0.clone()];
    for corner in 0..8 {
        let side = |bit: usize| {
            if corner & bit != 0 {
                edge / 2.0
            } else {
                -edge / 2.0
            }
        };
        let target = Isometry3::from_parts(
            Translation3::from(home.translation.vector + Vector3::new(side(1), side(2), side(4))),
            home.rotation,
        );
        let q = solver
            .solve(chain, &target, &Isometry3::identity(), &q0, None, &mut rng)
            .expect("the corner is reachable")
            .q;
        joints.push(q);
    }
    joints
}

/// Twelve postures around the paper's, the flange turned every way, so that a registration on them is
/// determined.
fn spread_joints() -> Vec<Vec<f64>> {
    let q0 = [0.0, 30.0, 0.0, -90.0, 0.0, -30.0, 0.0].map(f64::to_radians);
    (0..12)
        .map(|i| {
            (0..7)
                .map(|j| q0[j] + 0.35 * (1.7 * i as f64 + 2.3 * j as f64).sin())
                .collect()
        })
        .collect()
}

/// The reflector on the flange (m) and the tracker's place (base ← tracker) of the synthetic files.
const REFLECTOR: [f64; 3] = [0.0, 0.0, 0.03];
fn tracker() -> Isometry3<f64> {
    Isometry3::new(
        Vector3::new(3.0, 0.3, 1.75),
        Vector3::z() * 187f64.to_radians(),
    )
}

/// Four visits of a cube's centre off its command by these (m, base frame): mean zero, at 1 and 3 mm from it, so
/// AP is 0 and RP = l̄ + 3·S_l = 2 + 3·√(4/3) mm (two distances of 1 mm, two of 3 mm).
const SCATTER: [[f64; 3]; 4] = [
    [1e-3, 0.0, 0.0],
    [-1e-3, 0.0, 0.0],
    [0.0, 3e-3, 0.0],
    [0.0, -3e-3, 0.0],
];
fn scatter_rp_mm() -> f64 {
    2.0 + 3.0 * (4.0f64 / 3.0).sqrt()
}

/// A cube of 200 mm measured four times (centre, then its eight corners), every visit exact but the centre's
/// ([`SCATTER`] plus `centre_offset`) and the corner `+++`'s (`corner_offset` at each visit); then the twelve
/// spread postures, exact. Positions in the base frame (m) and the joints.
fn cube_file(
    chain: &Chain,
    centre_offset: Vector3<f64>,
    corner_offset: Vector3<f64>,
) -> (Vec<Vec<f64>>, Vec<Point3<f64>>) {
    let dh = DhChain::from_chain(chain).unwrap();
    let cube = cube_joints(chain, 0.2);
    let mut q = Vec::new();
    let mut p = Vec::new();
    for scatter in SCATTER {
        for (k, joints) in cube.iter().enumerate() {
            let deviation = match k {
                0 => Vector3::from(scatter) + centre_offset,
                8 => corner_offset,
                _ => Vector3::zeros(),
            };
            q.push(joints.clone());
            p.push(dh.flange_pose(joints) * Point3::from(REFLECTOR) + deviation);
        }
    }
    for joints in spread_joints() {
        p.push(dh.flange_pose(&joints) * Point3::from(REFLECTOR));
        q.push(joints);
    }
    (q, p)
}

fn iiwa() -> Chain {
    urdf::load_file(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("robots/iiwa7.urdf"),
        None,
    )
    .unwrap()
}

/// A file that measures one cube four times: the cube is found, its points grouped with their repeats, and AP
/// and RP at each are the known deviations' (seen through an exact registration, so nothing else moves them).
#[test]
fn the_cubes_of_a_file_and_their_known_ap_and_rp() {
    let chain = iiwa();
    let dh = DhChain::from_chain(&chain).unwrap();
    let centre_offset = Vector3::new(0.2e-3, -0.1e-3, 0.3e-3);
    let corner_offset = Vector3::new(0.0, 0.5e-3, 0.0);
    let (q, p) = cube_file(&chain, centre_offset, corner_offset);
    let d = Dataset::in_memory(
        "cubes.csv",
        chain.joint_names(),
        q,
        p.into_iter().map(|p| vec![p]).collect(),
    );
    let nominal = REFERENCE
        .fit(&FitContext::new(&chain, &dh), &d, &d)
        .unwrap();
    let exact = Registration {
        frame: TrackerFrame {
            tracker_to_base: Isometry3::identity(),
            mounting: Point3::from(REFLECTOR),
            rms: 0.0,
            evaluations: 0,
        },
        nest: None,
        probe_rotation: None,
        base_frame: true,
    };
    let side = Side {
        model: nominal.as_ref(),
        registration: &exact,
    };
    let report = iso_cubes::cubes(&d, &side, &side)
        .unwrap()
        .expect("a cube with repeats");
    // Nine commanded poses visited four times each, twelve once.
    assert_eq!((report.poses, report.repeated_poses), (21, 9));
    assert_eq!(report.cubes.len(), 1, "the four blocks are one cube");
    let cube = &report.cubes[0];
    assert_eq!(cube.blocks, ["0", "9", "18", "27"]);
    assert!((cube.edge_mm - 200.0).abs() < 1e-6, "{}", cube.edge_mm);
    let centre = &cube.points[0];
    assert_eq!(centre.role, "centre");
    assert_eq!(centre.point_ids, ["0", "9", "18", "27"]);
    let close = |a: f64, b: f64| (a - b).abs() < 1e-9;
    assert!(
        close(centre.before.ap_mm, centre_offset.norm() * 1e3),
        "{:?}",
        centre.before
    );
    assert!(
        close(centre.before.rp_mm.unwrap(), scatter_rp_mm()),
        "{:?}",
        centre.before
    );
    let corner = cube.points.iter().find(|p| p.role == "+++").unwrap();
    assert_eq!(corner.point_ids, ["8", "17", "26", "35"]);
    assert!(close(corner.before.ap_mm, 0.5) && close(corner.before.rp_mm.unwrap(), 0.0));
    for point in cube
        .points
        .iter()
        .filter(|p| p.role != "centre" && p.role != "+++")
    {
        assert!(
            point.before.ap_mm < 1e-9 && point.before.rp_mm.unwrap() < 1e-9,
            "{point:?}"
        );
    }
    assert!(
        cube.points.iter().all(|p| p.after == p.before),
        "one model on both sides"
    );
    // Without its repeats (the first block alone) the file is no test of repeatability: nothing to report.
    let once = d.subset(&(0..9).chain(36..48).collect::<Vec<_>>());
    assert!(iso_cubes::cubes(&once, &side, &side).unwrap().is_none());
}

/// `calibrate` reports the cubes of its test file in `report.json` and the printed tables: a file in the
/// tracker's frame, registered on its own points, whose cube centre scatters by a known amount about its command.
#[test]
fn calibrate_reports_the_cubes_of_its_test_file() {
    let chain = iiwa();
    let dir = TempDir::new().unwrap();
    let write = |name: &str, q: &[Vec<f64>], p: &[Point3<f64>]| {
        let to_tracker = tracker().inverse();
        let mut text = format!("point_id,{},x1,y1,z1\n", chain.joint_names().join(","));
        for (i, (q, p)) in q.iter().zip(p).enumerate() {
            let y = to_tracker * p;
            let joints: Vec<String> = q.iter().map(|v| v.to_string()).collect();
            text += &format!("{i},{},{},{},{}\n", joints.join(","), y.x, y.y, y.z);
        }
        let path = dir.path().join(name);
        std::fs::write(&path, text).unwrap();
        path
    };
    let dh = DhChain::from_chain(&chain).unwrap();
    let spread = spread_joints();
    let exact: Vec<Point3<f64>> = spread
        .iter()
        .map(|q| dh.flange_pose(q) * Point3::from(REFLECTOR))
        .collect();
    let train = write("train.csv", &spread, &exact);
    let (q, p) = cube_file(&chain, Vector3::zeros(), Vector3::zeros());
    let test = write("cubes.csv", &q, &p);
    let out = dir.path().join("cal");
    let output = std::process::Command::new(env!("CARGO_BIN_EXE_calibrate"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args(["--method", REFERENCE.info().name])
        .arg("--data")
        .arg(&train)
        .arg("--test-data")
        .arg(&test)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    assert!(
        stdout.contains("ISO 9283 pose accuracy on the test cubes of")
            && stdout.contains("1 cubes, 9 of 21 commanded poses visited more than once"),
        "{stdout}"
    );
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("report.json")).unwrap()).unwrap();
    let cubes = report["iso9283"]["cubes"].as_array().unwrap();
    assert_eq!(cubes.len(), 1);
    let points = cubes[0]["points"].as_array().unwrap();
    assert_eq!(points.len(), 9);
    // The scatter sums to zero at one configuration, so the registration on the test file's own points is the
    // exact one: AP 0 and the known RP at the centre, nothing at the corners.
    let centre = &points[0]["before"];
    assert!(centre["ap_mm"].as_f64().unwrap() < 1e-6, "{centre}");
    assert!(
        (centre["rp_mm"].as_f64().unwrap() - scatter_rp_mm()).abs() < 1e-6,
        "{centre}"
    );
    for p in &points[1..] {
        assert!(p["before"]["ap_mm"].as_f64().unwrap() < 1e-6, "{p}");
        assert!(p["after"]["rp_mm"].as_f64().unwrap() < 1e-6, "{p}");
    }
}
