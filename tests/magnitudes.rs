//! The shipped paper scenarios are realistic: after registration, the "Measured" errors fall in the bands of
//! the paper's Table 1 and the elastic deflection carries a large share; and the rapier deflection switch
//! reproduces the fast path's campaign.

use calibench::app::simulate;
use calibench::eval::{Budget, measured};
use calibench::scenario::Scenario;
use calibench::truth::DeflectionSolver;

#[test]
fn paper_scenario_has_the_papers_measured_error() {
    let scenario = Scenario::load("scenarios/paper_iiwa.toml").unwrap();
    let sim = simulate(&scenario).unwrap();
    assert_eq!(sim.campaign.points.len(), 2335);
    let m = measured(&sim.campaign).unwrap().scaled(1e3);
    // Paper, Table 1, "Measured": mean 0.4883, std 0.2536, max 1.5895 mm.
    assert!((m.mean - 0.49).abs() <= 0.10, "mean {} mm", m.mean);
    assert!((m.std - 0.25).abs() <= 0.08, "std {} mm", m.std);
    assert!((1.0..=2.2).contains(&m.max), "max {} mm", m.max);
    let commands: Vec<Vec<f64>> = sim
        .campaign
        .points
        .iter()
        .map(|p| p.q_cmd.clone())
        .collect();
    let budget = Budget::of(
        &sim.world.nominal,
        &sim.world.robot,
        &sim.world.mounting,
        &commands,
    )
    .unwrap();
    let elastic = budget.elastic_only.mean * 1e3;
    assert!(
        elastic >= m.mean / 3.0,
        "elastic-only mean {elastic} mm of {} mm",
        m.mean
    );
    // Without tracker and repeatability noise the systematic error is nearly all of it.
    assert!((budget.all_systematic.mean * 1e3 - m.mean).abs() < 0.01);
}

#[test]
fn rapier_deflection_gives_the_same_campaign() {
    // Every error source of the shipped scenario but the bearing tilt, which rapier cannot represent (README).
    let text = std::fs::read_to_string("scenarios/paper_iiwa_pose.toml")
        .unwrap()
        .replace("points = 875", "points = 40");
    let tilt = text
        .lines()
        .find(|l| l.starts_with("tilt_stiffness_nm_per_rad"))
        .expect("the shipped scenario has a bearing tilt");
    let text = text.replace(tilt, "");
    let fast = Scenario::parse(&text, "fast").unwrap();
    let mut physics = fast.clone();
    physics.world.truth.deflection = DeflectionSolver::Rapier;
    let (a, b) = (simulate(&fast).unwrap(), simulate(&physics).unwrap());
    assert_eq!(a.campaign.points.len(), 40);
    assert_eq!(b.campaign.points.len(), 40);
    let mut worst: f64 = 0.0;
    for (p, q) in a.campaign.points.iter().zip(&b.campaign.points) {
        assert_eq!(
            p.q_cmd, q.q_cmd,
            "the commands do not depend on the deflection solver"
        );
        for (x, y) in p.true_reflectors.iter().zip(&q.true_reflectors) {
            worst = worst.max((x - y).norm());
        }
    }
    assert!(
        worst <= 1e-6,
        "rapier and fixed point differ by {worst} m at a reflector"
    );
}
