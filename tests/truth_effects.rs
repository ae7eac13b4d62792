//! The error sources no method models exactly, one at a time: each moves the flange (or the measurement) by
//! what its magnitude implies.

use calibench::robot::dynamics::{gravity_moments, gravity_torques};
use calibench::robot::kinematics::{Frames, flange_pose, forward_kinematics};
use calibench::robot::{Chain, Payload, urdf};
use calibench::truth::history::{self, Visit};
use calibench::truth::stiffness::SoftZone;
use calibench::truth::{ErrorModel, Perturbation, ThermalProfile, TrueRobot, TrueState};
use nalgebra::{Point3, Vector3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

fn iiwa() -> Chain {
    urdf::load_file("robots/iiwa7.urdf", None).expect("the shipped URDF loads")
}

/// Joints so stiff that gravity turns them by under 1e-10 rad.
const RIGID: f64 = 1e12;

fn perturbation(model: &ErrorModel) -> Perturbation {
    Perturbation::sample(model, 7, &mut ChaCha8Rng::seed_from_u64(7)).unwrap()
}

fn weightless(chain: &Chain, p: Perturbation) -> TrueRobot {
    let mut robot = TrueRobot::new(chain, p, Payload::NONE).unwrap();
    robot.gravity = Vector3::zeros();
    robot
}

fn position(robot: &TrueRobot, q: &[f64], visit: &Visit) -> Vector3<f64> {
    let mut state = TrueState::new(robot);
    robot.reach_after(q, visit, None, &mut state).unwrap();
    state.frames.flange.translation.vector
}

/// Lever of joint `i`'s axis at configuration `q` for the flange origin (nominal chain).
fn lever(chain: &Chain, q: &[f64], i: usize) -> f64 {
    let mut frames = Frames::new(chain);
    forward_kinematics(chain, q, &mut frames);
    let p = Point3::from(frames.flange.translation.vector);
    frames.axis(chain, i).cross(&(p - frames.anchor(i))).norm()
}

const BENT: [f64; 7] = [0.3, 0.8, -0.2, -1.2, 0.4, 0.9, 0.1];

#[test]
fn a_wave_generator_harmonic_turns_its_joint_by_its_amplitude() {
    let chain = iiwa();
    let model = ErrorModel {
        gear_ratio: vec![100, 100, 120, 100, 100, 100, 100],
        gear_wave_amplitude_rad: 5e-5,
        ..ErrorModel::stiff_only(vec![RIGID; 7])
    };
    let mut p = perturbation(&model);
    let orders: Vec<u32> = p.gear[2].iter().map(|h| h.order).collect();
    assert_eq!(orders, [120, 240], "orders ratio and 2·ratio");
    assert!(p.gear[2].iter().all(|h| h.amplitude == 5e-5));
    // Joint 3 alone, its first harmonic alone.
    for (i, g) in p.gear.iter_mut().enumerate() {
        g.retain(|h| i == 2 && h.order == 120);
    }
    let robot = weightless(&chain, p);
    let arm = lever(&chain, &BENT, 2);
    let mut largest: f64 = 0.0;
    for k in 0..400 {
        let mut q = BENT;
        q[2] += k as f64 * std::f64::consts::TAU / 120.0 / 400.0;
        let moved = (position(&robot, &q, &Visit::default())
            - flange_pose(&chain, &q).translation.vector)
            .norm();
        let turn = robot.perturbation.gear_error(2, q[2]);
        assert!((moved - turn.abs() * arm).abs() < 1e-3 * 5e-5 * arm + 1e-10);
        largest = largest.max(moved);
    }
    // Over one period of the harmonic (1/120 of a turn) the flange swings by the amplitude times the lever.
    assert!(
        (largest - 5e-5 * arm).abs() < 2e-3 * 5e-5 * arm,
        "{largest} vs {}",
        5e-5 * arm
    );
}

#[test]
fn a_warm_arm_is_longer_by_alpha_delta_t() {
    let chain = iiwa();
    let thermal = ThermalProfile {
        start_c: 20.0,
        end_c: 26.0,
        time_constant_s: 1800.0,
        seconds_per_point: 6.0,
        expansion_per_k: 23e-6,
        reference_c: 20.0,
    };
    assert_eq!(thermal.temperature(0), 20.0);
    assert!((thermal.temperature(300) - (26.0 - 6.0 / std::f64::consts::E)).abs() < 1e-12);
    let model = ErrorModel {
        thermal: Some(thermal),
        ..ErrorModel::stiff_only(vec![RIGID; 7])
    };
    let robot = weightless(&chain, perturbation(&model));
    // Stretched straight up: the flange is L above the base and rises by α ΔT L.
    let q = [0.0; 7];
    let cold = position(&robot, &q, &Visit::default());
    let warm = position(
        &robot,
        &q,
        &Visit {
            direction: vec![],
            temperature: Some(26.0),
        },
    );
    let length = cold.norm();
    assert!(
        (length - 1.266).abs() < 1e-9,
        "the straight iiwa is 1.266 m long: {length}"
    );
    let grown = warm - cold;
    assert!(
        (grown.z - 23e-6 * 6.0 * length).abs() < 1e-12,
        "{} vs {}",
        grown.z,
        23e-6 * 6.0 * length
    );
    assert!(grown.x.abs() < 1e-15 && grown.y.abs() < 1e-15);
    // Bent, every position about the base scales by the same factor.
    let cold = position(&robot, &BENT, &Visit::default());
    let warm = position(
        &robot,
        &BENT,
        &Visit {
            direction: vec![],
            temperature: Some(23.0),
        },
    );
    assert!((warm - cold * (1.0 + 23e-6 * 3.0)).norm() < 1e-14);
}

#[test]
fn lost_motion_depends_on_the_direction_a_joint_came_from() {
    let chain = iiwa();
    let h = 2e-4;
    let model = ErrorModel {
        hysteresis_rad: h,
        ..ErrorModel::stiff_only(vec![RIGID; 7])
    };
    let robot = weightless(&chain, perturbation(&model));
    // Joint 2 goes below, to, above, to, below and to the same configuration; the others stay put.
    let target = BENT.to_vec();
    let off = |d: f64| {
        let mut q = BENT.to_vec();
        q[1] += d;
        q
    };
    let sequence = [
        off(-0.1),
        target.clone(),
        off(0.1),
        target.clone(),
        off(-0.2),
        target.clone(),
    ];
    let start = vec![0.0; 7];
    let visits = history::sequence(
        &robot.perturbation,
        &start,
        sequence.iter().map(Vec::as_slice),
    );
    let at = |k: usize| position(&robot, &sequence[k], &visits[k]);
    let (up, down, up_again) = (at(1), at(3), at(5));
    assert_eq!(
        up, up_again,
        "reached from the same direction: the same pose, bit for bit"
    );
    // Reached from opposite directions, joint 2 differs by the full band h.
    let arm = lever(&chain, &BENT, 1);
    let gap = (up - down).norm();
    assert!(
        (gap - h * arm).abs() < 1e-3 * h * arm,
        "{gap} vs {}",
        h * arm
    );
    let mut q0 = [vec![0.0; 7], vec![0.0; 7]];
    robot.unloaded_angles_after(&target, &visits[1], &mut q0[0]);
    robot.unloaded_angles_after(&target, &visits[3], &mut q0[1]);
    assert!(
        (q0[1][1] - q0[0][1] - h).abs() < 1e-15,
        "moving up, the joint lags below"
    );
    // The joints that did not move keep the direction they last moved in (from the start posture).
    assert_eq!(visits[3].direction[0], 1.0);
    assert_eq!(visits[3].direction[3], -1.0);
    assert!((0..7).filter(|&j| j != 1).all(|j| q0[0][j] == q0[1][j]));
}

#[test]
fn the_soft_zone_follows_the_catalogue_torsion_curve() {
    let zone = SoftZone {
        t1: 29.0,
        t2: 108.0,
        k1: 6.7e4,
        k2: 1.1e5,
        k3: 1.2e5,
    };
    // Harmonic Drive's worked example (CHA engineering data, §4.2): 60 Nm twist 7.15e-4 rad.
    assert!((zone.deflection(60.0) - 7.1462e-4).abs() < 1e-7);
    assert_eq!(zone.deflection(-60.0), -zone.deflection(60.0));
    for theta in [1e-4, 7e-4, 2e-3, -2e-3] {
        let (k, offset) = zone.segment(theta);
        let tau = k * (theta - offset);
        assert!(
            (zone.deflection(tau) - theta).abs() < 1e-15,
            "the segment's spring lies on the curve"
        );
    }
    // On the arm: joint 2 of the stretched-out iiwa under gravity settles on the curve.
    let chain = iiwa();
    let model = ErrorModel {
        soft_zone_torque_nm: vec![[29.0, 108.0]; 7],
        soft_zone_stiffness_ratio: [6.7 / 12.0, 11.0 / 12.0],
        ..ErrorModel::stiff_only(vec![1.2e5; 7])
    };
    let robot = TrueRobot::new(&chain, perturbation(&model), Payload::NONE).unwrap();
    let linear = TrueRobot::new(
        &chain,
        perturbation(&ErrorModel::stiff_only(vec![1.2e5; 7])),
        Payload::NONE,
    )
    .unwrap();
    let mut state = TrueState::new(&robot);
    let mut tau = vec![0.0; 7];
    for q2 in [0.1, 0.3, 1.5] {
        let q = [0.0, q2, 0.0, 0.0, 0.0, 0.0, 0.0];
        robot.reach(&q, None, &mut state).unwrap();
        gravity_torques(
            &robot.chain,
            &state.frames,
            &robot.payload,
            &robot.gravity,
            &mut tau,
        );
        let twist = state.q[1] - state.q0[1];
        assert!((twist - zone.deflection(tau[1])).abs() < 1e-13);
        let mut lin = TrueState::new(&linear);
        linear.reach(&q, None, &mut lin).unwrap();
        let stiff_twist = lin.q[1] - lin.q0[1];
        if tau[1].abs() < 29.0 {
            // Below T1 the joint is K3/K1 softer than its nominal stiffness says (to the torque's own change
            // with the larger sag, a few parts in 1e4).
            assert!(
                (twist / stiff_twist - 12.0 / 6.7).abs() < 2e-3,
                "{}",
                twist / stiff_twist
            );
        } else {
            assert!(twist.abs() > stiff_twist.abs());
        }
    }
}

#[test]
fn perpendicular_compliance_tilts_a_joint_by_c_times_the_moment() {
    let chain = iiwa();
    let k_tilt = 2e5;
    let model = ErrorModel {
        tilt_stiffness_nm_per_rad: vec![k_tilt, 1e18, 1e18, 1e18, 1e18, 1e18, 1e18],
        ..ErrorModel::stiff_only(vec![RIGID; 7])
    };
    let robot = TrueRobot::new(&chain, perturbation(&model), Payload::NONE).unwrap();
    // Arm stretched out along x: joint 1 (vertical) carries the whole arm's moment about a horizontal axis,
    // which its axial spring cannot feel.
    let q = [0.0, std::f64::consts::FRAC_PI_2, 0.0, 0.0, 0.0, 0.0, 0.0];
    let mut state = TrueState::new(&robot);
    robot.reach(&q, None, &mut state).unwrap();
    let (mut tau, mut moments) = (vec![0.0; 7], vec![Vector3::zeros(); 7]);
    gravity_moments(
        &robot.chain,
        &state.frames,
        &robot.payload,
        &robot.gravity,
        &mut tau,
        &mut moments,
    );
    let local = state.frames.joint[0]
        .rotation
        .inverse_transform_vector(&moments[0]);
    let perpendicular = Vector3::new(local.x, local.y, 0.0);
    assert!(
        (state.tilt[0] - perpendicular / k_tilt).norm() < 1e-15,
        "the fixed point: δ = c·M⊥"
    );
    // The static moment, summed by hand: the arm's mass times g times its centre's reach.
    let mut frames = Frames::new(&chain);
    forward_kinematics(&chain, &q, &mut frames);
    let reach: f64 = (1..chain.bodies.len())
        .map(|b| {
            chain.bodies[b].inertial.mass * 9.81 * (frames.body[b] * chain.bodies[b].inertial.com).x
        })
        .sum();
    assert!((state.tilt[0].norm() - reach.abs() / k_tilt).abs() < 1e-3 * reach.abs() / k_tilt);
    // The flange drops by the tilt times its distance from the joint's anchor.
    let rigid = flange_pose(&robot.chain, &state.q).translation.vector;
    let drop = rigid - state.frames.flange.translation.vector;
    let distance = (Point3::from(rigid) - frames.anchor(0)).norm();
    assert!(drop.z > 0.0, "gravity tilts the arm down");
    assert!(
        (drop.norm() - state.tilt[0].norm() * distance).abs() < 1e-3 * drop.norm(),
        "{drop:?}"
    );
    assert!(
        drop.norm() > 1e-4,
        "a tenth of a millimetre or more: {}",
        drop.norm()
    );
}

#[test]
fn true_inertials_and_cables_load_the_joints_more_than_the_urdf_says() {
    let chain = iiwa();
    let rho = 1.2;
    let model = ErrorModel {
        cable_kg_per_m: rho,
        ..ErrorModel::stiff_only(vec![1e4; 7])
    };
    let robot = TrueRobot::new(&chain, perturbation(&model), Payload::NONE).unwrap();
    let length: f64 = (0..7)
        .map(|i| {
            if i + 1 < 7 {
                chain.joints[i + 1].origin.translation.vector.norm()
            } else {
                chain.flange.translation.vector.norm()
            }
        })
        .sum();
    assert!((robot.chain.total_mass() - chain.total_mass() - rho * length).abs() < 1e-12);
    // Joint 2 of the outstretched arm carries the cable's moment as well: ρ g Σ L_i x_mid_i.
    let q = [0.0, std::f64::consts::FRAC_PI_2, 0.0, 0.0, 0.0, 0.0, 0.0];
    let mut frames = Frames::new(&chain);
    forward_kinematics(&chain, &q, &mut frames);
    let cable_moment: f64 = (1..7)
        .map(|i| {
            let next = if i + 1 < 7 {
                chain.joints[i + 1].origin.translation.vector
            } else {
                chain.flange.translation.vector
            };
            let mid = frames.body[i + 1] * Point3::from(next * 0.5);
            rho * next.norm() * 9.81 * (mid.x - frames.anchor(1).x)
        })
        .sum();
    let (mut urdf_tau, mut true_tau) = (vec![0.0; 7], vec![0.0; 7]);
    gravity_torques(
        &chain,
        &frames,
        &Payload::NONE,
        &robot.gravity,
        &mut urdf_tau,
    );
    gravity_torques(
        &robot.chain,
        &frames,
        &Payload::NONE,
        &robot.gravity,
        &mut true_tau,
    );
    assert!(((true_tau[1] - urdf_tau[1]).abs() - cable_moment.abs()).abs() < 1e-9);
    assert!(cable_moment.abs() > 1.0, "{cable_moment} Nm");
    // Scattered masses and centres: each link's mass is the URDF's times its factor.
    let model = ErrorModel {
        link_mass_spread: 0.1,
        link_com_m: 0.01,
        ..ErrorModel::stiff_only(vec![1e4; 7])
    };
    let p = perturbation(&model);
    let robot = TrueRobot::new(&chain, p.clone(), Payload::NONE).unwrap();
    for i in 0..7 {
        let (nominal, truth) = (
            &chain.bodies[i + 1].inertial,
            &robot.chain.bodies[i + 1].inertial,
        );
        assert!((truth.mass - nominal.mass * p.link_mass_factor[i]).abs() < 1e-12);
        assert!((truth.com - nominal.com - Vector3::from(p.link_com_offset[i])).norm() < 1e-15);
    }
    assert!(p.link_mass_factor.iter().any(|f| (f - 1.0).abs() > 0.03));
}

#[test]
fn rapier_follows_the_soft_zone_and_the_true_inertials_as_the_fixed_point_does() {
    use calibench::truth::physics::SettleOptions;
    use calibench::truth::robot::Deflection;
    use rand::Rng;
    let chain = iiwa();
    let model = ErrorModel {
        frame_translation_m: 1e-4,
        frame_rotation_rad: 2e-4,
        link_mass_spread: 0.1,
        link_com_m: 0.01,
        cable_kg_per_m: 0.5,
        soft_zone_torque_nm: vec![
            [29.0, 108.0],
            [29.0, 108.0],
            [14.0, 48.0],
            [14.0, 48.0],
            [4.0, 14.0],
            [4.0, 14.0],
            [4.0, 14.0],
        ],
        soft_zone_stiffness_ratio: [0.56, 0.92],
        ..ErrorModel::stiff_only(vec![
            22000.0, 14500.0, 11000.0, 11000.0, 4400.0, 3600.0, 2900.0,
        ])
    };
    let payload = Payload {
        mass: 0.4,
        com: [0.0, 0.0, 0.03],
    };
    let robot = TrueRobot::new(&chain, perturbation(&model), payload).unwrap();
    let mut physics = robot.physics_reference(SettleOptions::default()).unwrap();
    let (mut fast, mut reference) = (TrueState::new(&robot), TrueState::new(&robot));
    let mut rng = ChaCha8Rng::seed_from_u64(4);
    let (mut worst, mut soft): (f64, f64) = (0.0, 0.0);
    for _ in 0..16 {
        let q: Vec<f64> = chain
            .joints
            .iter()
            .map(|j| rng.random_range(0.8 * j.lower..0.8 * j.upper))
            .collect();
        robot.reach(&q, None, &mut fast).unwrap();
        let settled = physics.settle(&fast.q0).unwrap();
        robot.reach_with_angles(
            &Deflection {
                q: settled.q,
                tilt: vec![],
            },
            1.0,
            None,
            &mut reference,
        );
        worst = worst.max(
            (fast.frames.flange.translation.vector - reference.frames.flange.translation.vector)
                .norm(),
        );
        // How much the soft zone itself moves the flange: against the linear springs (K3).
        let mut linear = robot.clone();
        linear.perturbation.soft_zone.clear();
        let mut lin = TrueState::new(&linear);
        linear.reach(&q, None, &mut lin).unwrap();
        soft = soft.max(
            (lin.frames.flange.translation.vector - fast.frames.flange.translation.vector).norm(),
        );
    }
    assert!(
        worst <= 1e-6,
        "rapier and fixed point differ by {worst} m at the flange"
    );
    assert!(soft > 5e-5, "the soft zone moves the flange by {soft} m");
}
