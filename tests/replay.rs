//! Replaying a campaign (`campaign SCENARIO --replay FILE [--mapping MAP]`): the real UR10 series C is measured
//! in the simulation with exactly its configurations in its order; a tracker pose and reflector offset known
//! from a simulated campaign are recovered by the replay's placement; every row is measured, even where the
//! simulated acceptance cone would refuse it; a row outside the joint limits is one error naming it.

use std::path::{Path, PathBuf};

use tempfile::TempDir;

use calibench::app::campaign::{self, CampaignOptions, ReplaySource};
use calibench::dataset::Dataset;
use calibench::dataset::mapping::ColumnMapping;
use calibench::robot::urdf;
use calibench::scenario::Scenario;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn series_c() -> PathBuf {
    root().join("data/ipa-ur10/Series_C/measurements_random_poses.csv")
}

fn ur10_ipa() -> Scenario {
    let mut s =
        Scenario::load(root().join("scenarios/ur10_ipa.toml")).expect("the shipped scenario");
    s.world.robot.urdf = root().join("robots/ur10.urdf");
    s
}

/// The UR10, its DH form, and the real series B, C, D read as `real_data` reads them.
fn ur10_series() -> (
    calibench::robot::Chain,
    calibench::robot::dh::DhChain,
    Vec<Dataset>,
) {
    let chain = urdf::load_file(root().join("robots/ur10.urdf"), None).unwrap();
    let dh = calibench::robot::dh::DhChain::from_chain(&chain).unwrap();
    let mapping = ColumnMapping::load(&root().join("mappings/ipa_ur10.toml")).unwrap();
    let real =
        calibench::app::real_data::read_series(&root().join("data/ipa-ur10"), &mapping, &chain)
            .unwrap();
    (chain, dh, real)
}

fn replay(
    scenario: Scenario,
    file: &Path,
    mapping: Option<PathBuf>,
    out: &Path,
) -> campaign::CampaignRun {
    campaign::run(
        scenario,
        &CampaignOptions {
            out: Some(out.to_path_buf()),
            replay: Some(ReplaySource {
                file: file.to_path_buf(),
                mapping,
            }),
            ..CampaignOptions::default()
        },
    )
    .expect("the replay runs")
}

#[test]
fn a_replay_measures_the_real_configurations_in_the_files_order() {
    let dir = TempDir::new().unwrap();
    let chain = urdf::load_file(root().join("robots/ur10.urdf"), None).unwrap();
    let real = ColumnMapping::load(&root().join("mappings/ipa_ur10.toml"))
        .unwrap()
        .read(&series_c(), &chain)
        .unwrap();
    let done = replay(
        ur10_ipa(),
        &series_c(),
        Some(root().join("mappings/ipa_ur10.toml")),
        dir.path(),
    );
    let sim = Dataset::read(&dir.path().join("measurements.csv"), &chain.joint_names()).unwrap();
    assert_eq!(sim.len(), 2773);
    // Bit for bit, row by row: the file's configurations in the file's order.
    assert_eq!(sim.q, real.q);
    assert_eq!(
        sim.point_ids,
        (0..2773).map(|i| i.to_string()).collect::<Vec<_>>()
    );
    // The simulated tracker stands where the real one did: the real and simulated measurements of the same
    // configuration lie as far apart as the nominal robot is from the real one (the registration's ~1 mm),
    // not metres.
    let far = real
        .measured
        .iter()
        .zip(&sim.measured)
        .map(|(a, b)| (a[0] - b[0]).norm())
        .fold(0.0, f64::max);
    assert!(far < 0.01, "real and replayed points {far} m apart");
    let r = done.replay.expect("a replay report");
    assert!(
        r.placement_residual_rad < 1e-12,
        "{}",
        r.placement_residual_rad
    );
    assert!(
        (r.mounting_m[2] - 0.0928).abs() < 1e-3,
        "{:?}",
        r.mounting_m
    );
}

/// A world whose true robot is its nominal one and whose tracker is exact: a registration recovers the tracker
/// pose and the reflector offset exactly, whatever they are.
fn exact_world(yaw: f64, tilt: [f64; 2], position: [f64; 3], reflector: [f64; 3]) -> Scenario {
    let mut s = ur10_ipa();
    s.world.truth = calibench::truth::ErrorModel::stiff_only(vec![1e12; 6]);
    let k = &mut s.world.tracker;
    (k.range_sigma_m, k.range_sigma_per_m, k.angle_sigma_rad) = (0.0, 0.0, 0.0);
    (k.range_offset_m, k.range_scale, k.vertical_index_offset_rad) = (0.0, 0.0, 0.0);
    (k.azimuth_eccentricity_rad, k.elevation_eccentricity_rad) = ([0.0; 2], [0.0; 2]);
    (k.position_m, k.yaw_deg, k.tilt_deg) = (position, yaw, tilt);
    s.world.reflectors.nominal_m = vec![reflector];
    s
}

#[test]
fn the_replay_places_the_tracker_and_the_reflector_where_they_were() {
    let dir = TempDir::new().unwrap();
    let (position, yaw, tilt, reflector) =
        ([0.9, 3.1, 1.4], -23.0, [1.5, -2.5], [0.004, -0.003, 0.085]);
    let planned = campaign::run(
        exact_world(yaw, tilt, position, reflector),
        &CampaignOptions {
            out: Some(dir.path().join("planned")),
            ..CampaignOptions::default()
        },
    )
    .unwrap();
    let known = planned.sim.world.tracker.pose;
    // Replayed in a world whose tracker and reflector stand elsewhere.
    let file = dir.path().join("planned/measurements.csv");
    let done = replay(
        exact_world(40.0, [0.0, 0.0], [-2.0, 0.0, 0.5], [0.0, 0.0, 0.2]),
        &file,
        None,
        &dir.path().join("replayed"),
    );
    let placed = done.sim.world.tracker.pose;
    let moved = (placed.translation.vector - known.translation.vector).norm();
    let turned = (placed.rotation * known.rotation.inverse()).angle();
    // Exact up to where Levenberg–Marquardt stops (nanometres), far below any tracker noise.
    assert!(
        moved < 1e-8 && turned < 1e-9,
        "tracker off by {moved} m, {turned} rad"
    );
    let t = &done.scenario.world.tracker;
    assert!((t.yaw_deg - yaw).abs() < 1e-8, "yaw {}", t.yaw_deg);
    assert!((t.tilt_deg[0] - tilt[0]).abs() < 1e-8 && (t.tilt_deg[1] - tilt[1]).abs() < 1e-8);
    let m = done.replay.unwrap().mounting_m;
    let off = (0..3)
        .map(|i| (m[i] - reflector[i]).abs())
        .fold(0.0, f64::max);
    assert!(off < 1e-8, "reflector {m:?}, was {reflector:?}");
    // And so the replay measures what the original campaign measured.
    let chain = &done.sim.world.nominal;
    let a = Dataset::read(&file, &chain.joint_names()).unwrap();
    let b = Dataset::read(
        &dir.path().join("replayed/measurements.csv"),
        &chain.joint_names(),
    )
    .unwrap();
    assert_eq!(a.q, b.q);
    let worst = a
        .measured
        .iter()
        .zip(&b.measured)
        .map(|(p, q)| (p[0] - q[0]).norm())
        .fold(0.0, f64::max);
    assert!(
        worst < 1e-9,
        "replayed measurements {worst} m from the originals"
    );
}

#[test]
fn every_row_is_measured_even_where_the_simulated_tracker_would_not_see_it() {
    let dir = TempDir::new().unwrap();
    let mut scenario = ur10_ipa();
    // A 1° acceptance cone would refuse nearly every configuration of a planned campaign.
    scenario.world.tracker.acceptance_half_angle_deg = 1.0;
    let done = replay(
        scenario,
        &series_c(),
        Some(root().join("mappings/ipa_ur10.toml")),
        dir.path(),
    );
    assert_eq!(done.sim.campaign.points.len(), 2773);
    let seen = done
        .sim
        .campaign
        .points
        .iter()
        .filter(|p| {
            let facing = p.true_flange.rotation * done.sim.world.mounting.facing;
            done.sim
                .world
                .tracker
                .in_acceptance_cone(&p.true_reflectors[0], &facing)
        })
        .count();
    assert!(seen < 2773 / 10, "{seen} of 2773 inside the 1° cone");
}

#[test]
fn a_row_outside_the_joint_limits_is_an_error_naming_it() {
    let dir = TempDir::new().unwrap();
    let file = dir.path().join("real.csv");
    let joints = "shoulder_pan_joint,shoulder_lift_joint,elbow_joint,wrist_1_joint,wrist_2_joint,wrist_3_joint";
    let rows = [
        "0.1,-1.5,1.2,-1.0,-1.5,0.0,0.5,3.0,0.9",
        "0.2,-1.4,1.1,-1.1,-1.4,0.1,0.6,3.1,0.8",
        "0.3,-1.3,7.0,-1.2,-1.3,0.2,0.7,3.2,0.7",
        "0.4,-1.2,1.0,-1.3,-1.2,0.3,0.8,3.3,0.6",
        "0.5,-1.1,0.9,-1.4,-1.1,0.4,0.9,3.4,0.5",
    ];
    std::fs::write(&file, format!("{joints},x1,y1,z1\n{}\n", rows.join("\n"))).unwrap();
    let out = dir.path().join("out");
    let err = campaign::run(
        ur10_ipa(),
        &CampaignOptions {
            out: Some(out.clone()),
            replay: Some(ReplaySource {
                file: file.clone(),
                mapping: None,
            }),
            ..CampaignOptions::default()
        },
    )
    .err()
    .expect("a joint beyond its limit is refused")
    .to_string();
    assert!(
        err.contains("real.csv") && err.contains("row 4") && err.contains("elbow_joint"),
        "{err}"
    );
    assert!(!out.exists(), "nothing is written");
}

/// `real_data --simulate` on a slice of each series (every 8th row) in a world whose robot is its nominal model
/// and whose tracker is exact: the replayed series keep the real rows, angles and temperature, carry a probe
/// orientation like the real ones, and go through the same protocol — where the nominal model, half a
/// millimetre off on the real arm, is exact on the simulated one.
#[test]
fn the_simulated_tables_stand_beside_the_real_ones() {
    use calibench::app::real_data;
    use calibench::app::sim_vs_real::{compare, simulate_series};
    use calibench::calib::method::FitContext;
    use calibench::calib::registry::MethodKind;

    let (chain, dh, real) = ur10_series();
    let ctx = FitContext::new(&chain, &dh);
    let real: Vec<Dataset> = real
        .iter()
        .map(|d| d.subset(&(0..d.len()).step_by(8).collect::<Vec<_>>()))
        .collect();
    let mut exact = exact_world(0.0, [0.0, 0.0], [0.0, 3.0, 1.0], [0.0, 0.0, 0.1]);
    exact.world.tracker.orientation_sigma_rad = 0.0;
    let (sim, placements) = simulate_series(&exact, &real).unwrap();
    assert_eq!(placements.len(), 3);
    for (r, s) in real.iter().zip(&sim) {
        assert_eq!(r.q, s.q);
        assert_eq!(r.point_ids, s.point_ids);
        assert_eq!(
            r.extra_inputs, s.extra_inputs,
            "the real temperature, passed through (the exact world has no warm-up)"
        );
        assert_eq!(
            r.measured_orientation.as_ref().map(Vec::len),
            s.measured_orientation.as_ref().map(Vec::len)
        );
        assert_ne!(r.measured, s.measured);
    }
    let methods = [MethodKind::Nominal, MethodKind::Kinematic];
    let sizes = [40, 80];
    let quiet = &mut |_: &str| {};
    let real_t = real_data::tables(&methods, &ctx, &real, Some(&sizes), 1, quiet).unwrap();
    let sim_t = real_data::tables(&methods, &ctx, &sim, Some(&sizes), 1, quiet).unwrap();
    let lines = compare(&methods, &real_t, &sim_t, &sizes);
    let protocols: Vec<&str> = lines.iter().map(|l| l.protocol.as_str()).collect();
    for p in [
        "C → D",
        "C → B",
        "B → C",
        "within C",
        "curve C, 40 points",
        "curve C, 80 points",
    ] {
        assert_eq!(
            protocols.iter().filter(|&&q| q == p).count(),
            2,
            "{p}: {protocols:?}"
        );
    }
    let nominal = lines
        .iter()
        .find(|l| l.protocol == "within C" && l.method == "nominal")
        .unwrap();
    let (real_mean, sim_mean) = (nominal.real_mean_mm.unwrap(), nominal.sim_mean_mm.unwrap());
    assert!(real_mean > 0.5, "real nominal {real_mean} mm");
    assert!(sim_mean < 1e-3, "the exact robot's nominal {sim_mean} mm");
}

/// The shipped UR10 scenario, fitted to the real arm (README, "A simulated UR10 fitted to the real one"), on the
/// whole of series B, C and D: within C every method's held-out mean lies within ±25 % of the real one, and
/// across series the constant-parameter `kinematic` transfers worse than `elastic`, as on the real arm. These are
/// the figures; the scenario was fitted to them, so the test guards the fit against a change of the truth
/// or the protocol that would silently undo it.
#[test]
fn the_fitted_ur10_errs_like_the_real_one() {
    use calibench::app::real_data;
    use calibench::app::sim_vs_real::{compare, simulate_series};
    use calibench::calib::method::FitContext;
    use calibench::calib::registry::MethodKind as M;

    let (chain, dh, real) = ur10_series();
    let ctx = FitContext::new(&chain, &dh);
    let (sim, _) = simulate_series(&ur10_ipa(), &real).unwrap();
    for s in &sim {
        assert!(
            s.extra_inputs
                .as_ref()
                .is_some_and(|x| x.names.contains(&"temperature".to_string())),
            "the simulated warm-up's temperature"
        );
    }
    let methods = [
        M::Nominal,
        M::PaperRotxyz,
        M::Kinematic,
        M::Elastic,
        M::ResidualRidge,
        M::Hybrid,
    ];
    let quiet = &mut |_: &str| {};
    let real_t = real_data::tables(&methods, &ctx, &real, None, 1, quiet).unwrap();
    let sim_t = real_data::tables(&methods, &ctx, &sim, None, 1, quiet).unwrap();
    let lines = compare(&methods, &real_t, &sim_t, &[]);
    let mean = |protocol: &str, method: &str| {
        let l = lines
            .iter()
            .find(|l| l.protocol == protocol && l.method == method)
            .unwrap_or_else(|| panic!("no line {protocol} / {method}"));
        (l.real_mean_mm.unwrap(), l.sim_mean_mm.unwrap())
    };
    for m in [
        "nominal",
        "paper-rotxyz",
        "kinematic",
        "elastic",
        "residual-ridge",
        "hybrid",
    ] {
        let (real, sim) = mean("within C", m);
        assert!(
            (sim / real - 1.0).abs() <= 0.25,
            "within C, {m}: simulated {sim:.4} mm against real {real:.4} mm"
        );
    }
    for protocol in ["C → D", "C → B"] {
        let (real_k, sim_k) = mean(protocol, "kinematic");
        let (real_e, sim_e) = mean(protocol, "elastic");
        assert!(real_e < real_k, "{protocol}: the real order");
        assert!(
            sim_e < sim_k,
            "{protocol}: simulated elastic {sim_e:.4} mm, kinematic {sim_k:.4} mm; real {real_e:.4}, {real_k:.4}"
        );
    }
}
