//! ISO 9283's pose accuracy and repeatability (issue 26): known answers of the simulated test (an arm with only
//! a constant offset, with repeatability only, with lost motion only, cold and warm), the shipped scenario
//! before and after calibration, the scenario's checks, and the real UR10's test cubes.

use std::path::{Path, PathBuf};

use nalgebra::Vector3;
use tempfile::TempDir;

use calibench::app;
use calibench::app::campaign::CampaignOptions;
use calibench::calib::method::FitContext;
use calibench::calib::registry::MethodKind;
use calibench::campaign::iso_cube::CYCLE;
use calibench::dataset::mapping::ColumnMapping;
use calibench::eval::iso_cubes::{self, Side};
use calibench::eval::iso9283::IsoTest;
use calibench::robot::dh::DhChain;
use calibench::robot::urdf;
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

fn ur10_data(series: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data/ipa-ur10")
        .join(series)
}

/// Series D of the IPA UR10 measures 70 blocks of a cube's centre and eight corners; its first cube (400 mm)
/// three times in a row, so its corners are visited three times and its centre five (once more for each of
/// the 250 and 100 mm cubes around it).
#[test]
fn the_real_ur10_cubes_and_their_repeats_are_found() {
    let chain = urdf::load_file(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("robots/ur10.urdf"),
        None,
    )
    .unwrap();
    let dh = DhChain::from_chain(&chain).unwrap();
    let mapping =
        ColumnMapping::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("mappings/ipa_ur10.toml"))
            .unwrap();
    let mut d = mapping
        .read(&ur10_data("Series_D/measurements_iso_cubes.csv"), &chain)
        .unwrap();
    d.extra_inputs = None;
    let ctx = FitContext::new(&chain, &dh);
    let nominal = MethodKind::Nominal.fit(&ctx, &d, &d).unwrap();
    let side = Side {
        model: nominal.as_ref(),
        registration: nominal.registration(),
    };
    let report = iso_cubes::cubes(&d, &side, &side)
        .unwrap()
        .expect("cubes with repeats");
    assert_eq!(report.poses, 574);
    assert_eq!(report.repeated_poses, 31);
    let blocks: usize = report.cubes.iter().map(|c| c.blocks.len()).sum();
    assert_eq!((report.cubes.len(), blocks), (68, 70));
    let first = &report.cubes[0];
    assert_eq!(
        first.blocks,
        ["2", "11", "20"],
        "rows 2, 11 and 20 of the file start it"
    );
    assert!((first.edge_mm - 400.0).abs() < 1.0, "{}", first.edge_mm);
    let centre = &first.points[0];
    assert_eq!(centre.role, "centre");
    assert_eq!(centre.point_ids, ["2", "11", "20", "29", "38"]);
    // AP at the centre by hand: the barycentre of the measured points (through the registration) against the
    // nominal model's prediction, over the five rows.
    let observed = nominal.registration().observe(&d).unwrap();
    let rows = [0usize, 9, 18, 27, 36];
    let deviation: Vector3<f64> = rows
        .iter()
        .map(|&i| observed[i].position - nominal.predict(&d.q[i]).position)
        .sum::<Vector3<f64>>()
        / 5.0;
    assert!((centre.before.ap_mm - deviation.norm() * 1e3).abs() < 1e-9);
    let attempts: Vec<Vector3<f64>> = rows
        .iter()
        .map(|&i| observed[i].position - nominal.predict(&d.q[i]).position)
        .collect();
    assert!((centre.before.rp_mm.unwrap() - rp_by_hand(&attempts) * 1e3).abs() < 1e-9);
    // The UR10's repeatability is ±0.1 mm (its data sheet); the tracker adds hundredths.
    assert!(centre.before.rp_mm.unwrap() < 0.2, "{:?}", centre.before);
    // Series C has no cube: nothing to report.
    let mut c = mapping
        .read(&ur10_data("Series_C/measurements_random_poses.csv"), &chain)
        .unwrap();
    c.extra_inputs = None;
    let nominal_c = MethodKind::Nominal.fit(&ctx, &c, &c).unwrap();
    let side_c = Side {
        model: nominal_c.as_ref(),
        registration: nominal_c.registration(),
    };
    assert!(iso_cubes::cubes(&c, &side_c, &side_c).unwrap().is_none());
}

/// `calibrate` reports the cubes of its test file in `report.json` and in the printed tables.
#[test]
fn calibrate_reports_the_cubes_of_its_test_file() {
    let out = TempDir::new().unwrap();
    let dir = out.path().join("cal");
    let output = std::process::Command::new(env!("CARGO_BIN_EXE_calibrate"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args([
            "--robot",
            "robots/ur10.urdf",
            "--mapping",
            "mappings/ipa_ur10.toml",
            "--method",
            "nominal",
        ])
        .arg("--data")
        .arg(ur10_data("Series_C/measurements_random_poses.csv"))
        .arg("--test-data")
        .arg(ur10_data("Series_D/measurements_iso_cubes.csv"))
        .arg("--out")
        .arg(&dir)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    assert!(
        stdout.contains("ISO 9283 pose accuracy on the test cubes of"),
        "{stdout}"
    );
    assert!(
        stdout.contains("68 cubes, 31 of 574 commanded poses visited more than once"),
        "{stdout}"
    );
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("report.json")).unwrap()).unwrap();
    let cubes = report["iso9283"]["cubes"].as_array().unwrap();
    assert_eq!(cubes.len(), 68);
    assert_eq!(cubes[0]["points"].as_array().unwrap().len(), 9);
}
