//! The nominal robot: URDF loading and its errors, Jacobians and gravity against finite differences.

use calibench::robot::dynamics::{GRAVITY, gravity_moments, gravity_torques, potential_energy};
use calibench::robot::kinematics::{flange_pose, forward_kinematics, point_jacobian};
use calibench::robot::{Chain, Frames, Payload, urdf};
use nalgebra::{Point3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn iiwa() -> Chain {
    urdf::load_file("robots/iiwa7.urdf", None).expect("the shipped URDF loads")
}

fn random_q(chain: &Chain, rng: &mut ChaCha8Rng) -> Vec<f64> {
    chain
        .joints
        .iter()
        .map(|j| rng.random_range(j.lower..j.upper))
        .collect()
}

#[test]
fn iiwa_urdf_has_the_published_structure() {
    let chain = iiwa();
    assert_eq!(chain.dof(), 7);
    let names: Vec<String> = (1..=7).map(|i| format!("iiwa_joint_{i}")).collect();
    assert_eq!(chain.joint_names(), names);
    assert_eq!(chain.flange_link, "iiwa_link_ee");
    assert!(
        (chain.total_mass() - 23.9).abs() < 0.05,
        "mass {}",
        chain.total_mass()
    );
    let limits_deg = [170.0, 120.0, 170.0, 120.0, 170.0, 120.0, 175.0];
    for (j, lim) in chain.joints.iter().zip(limits_deg) {
        assert!((j.upper - f64::to_radians(lim)).abs() < 1e-9, "{}", j.name);
        assert!((j.lower + f64::to_radians(lim)).abs() < 1e-9, "{}", j.name);
    }
    let home = flange_pose(&chain, &[0.0; 7]);
    assert!((home.translation.vector - Vector3::new(0.0, 0.0, 1.266)).norm() < 1e-12);
    assert!(home.rotation.angle() < 1e-12);
    for body in &chain.bodies[1..] {
        assert!(
            !body.colliders.is_empty(),
            "{:?} has no collision shape",
            body.links
        );
    }
}

#[test]
fn jacobian_equals_finite_differences() {
    let chain = iiwa();
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let mut frames = Frames::new(&chain);
    let tool = Point3::new(0.03, -0.02, 0.08);
    for _ in 0..50 {
        let q = random_q(&chain, &mut rng);
        forward_kinematics(&chain, &q, &mut frames);
        let point = frames.flange * tool;
        let jac = point_jacobian(&chain, &frames, &point);
        let h = 1e-6;
        for i in 0..chain.dof() {
            let (mut qp, mut qm) = (q.clone(), q.clone());
            qp[i] += h;
            qm[i] -= h;
            let (fp, fm) = (flange_pose(&chain, &qp), flange_pose(&chain, &qm));
            let dp = ((fp * tool) - (fm * tool)) / (2.0 * h);
            let dr = (fp.rotation * fm.rotation.inverse()).scaled_axis() / (2.0 * h);
            let col = jac.column(i);
            assert!(
                (col.fixed_rows::<3>(0) - dp).norm() < 1e-8,
                "linear column {i}"
            );
            assert!(
                (col.fixed_rows::<3>(3) - dr).norm() < 1e-8,
                "angular column {i}"
            );
        }
    }
}

#[test]
fn gravity_torque_is_minus_the_gradient_of_potential_energy() {
    let chain = iiwa();
    let payload = Payload {
        mass: 1.5,
        com: [0.01, 0.02, 0.06],
    };
    let mut rng = ChaCha8Rng::seed_from_u64(12);
    let mut frames = Frames::new(&chain);
    let mut tau = vec![0.0; 7];
    let energy = |q: &[f64], frames: &mut Frames| {
        forward_kinematics(&chain, q, frames);
        potential_energy(&chain, frames, &payload, &GRAVITY)
    };
    for _ in 0..50 {
        let q = random_q(&chain, &mut rng);
        forward_kinematics(&chain, &q, &mut frames);
        gravity_torques(&chain, &frames, &payload, &GRAVITY, &mut tau);
        let h = 1e-6;
        for i in 0..7 {
            let (mut qp, mut qm) = (q.clone(), q.clone());
            qp[i] += h;
            qm[i] -= h;
            let grad = (energy(&qp, &mut frames) - energy(&qm, &mut frames)) / (2.0 * h);
            assert!(
                (tau[i] + grad).abs() < 1e-6,
                "joint {i}: τ {} vs -dV/dq {}",
                tau[i],
                -grad
            );
        }
    }
    // Joint 1's axis is vertical: gravity can never turn it.
    assert!(tau[0].abs() < 1e-12);
}

#[test]
fn gravity_of_a_horizontal_arm_is_the_static_moment() {
    // At q2 = 90° the arm lies along the base x axis; joint 2 carries the moment of everything above it.
    let chain = iiwa();
    let mut q = [0.0; 7];
    q[1] = std::f64::consts::FRAC_PI_2;
    let mut frames = Frames::new(&chain);
    forward_kinematics(&chain, &q, &mut frames);
    let mut tau = vec![0.0; 7];
    gravity_torques(&chain, &frames, &Payload::NONE, &GRAVITY, &mut tau);
    let anchor = frames.anchor(1);
    let moment: f64 = (1..chain.bodies.len())
        .skip(1)
        .map(|b| {
            let com = frames.body[b] * chain.bodies[b].inertial.com;
            chain.bodies[b].inertial.mass * 9.81 * (com.x - anchor.x)
        })
        .sum();
    assert!(
        moment.abs() > 50.0,
        "the horizontal arm has a large moment: {moment}"
    );
    assert!(
        (tau[1].abs() - moment.abs()).abs() < 1e-9,
        "τ2 {} vs moment {moment}",
        tau[1]
    );
}

const TWO_LINKS: &str = r#"<robot name="two">
  <link name="a"/><link name="b"/><link name="c"/>
  <joint name="j1" type="revolute"><parent link="a"/><child link="b"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><origin xyz="0 0 1"/><parent link="b"/><child link="c"/><axis xyz="0 1 0"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
</robot>"#;

#[test]
fn a_small_chain_has_the_expected_transform() {
    let chain = urdf::load_str(TWO_LINKS, "inline", None).unwrap();
    assert_eq!(chain.dof(), 2);
    let pose = flange_pose(&chain, &[std::f64::consts::FRAC_PI_2, 0.3]);
    // j1 turns about z by 90°, j2 (1 m up) about the turned y axis: the flange stays on the z axis.
    assert!((pose.translation.vector - Vector3::new(0.0, 0.0, 1.0)).norm() < 1e-12);
    let y_turned = pose.rotation * Vector3::y();
    assert!((y_turned - Vector3::new(-1.0, 0.0, 0.0)).norm() < 1e-12);
}

#[test]
fn bad_urdfs_are_refused_with_a_clear_message() {
    let missing = urdf::load_file("robots/no_such_robot.urdf", None)
        .unwrap_err()
        .to_string();
    assert!(missing.contains("cannot read"), "{missing}");

    let branching = TWO_LINKS.replace(
        "</robot>",
        r#"<link name="d"/><joint name="j3" type="fixed"><parent link="b"/><child link="d"/></joint></robot>"#,
    );
    let e = urdf::load_str(&branching, "branch", None)
        .unwrap_err()
        .to_string();
    assert!(e.contains("branches"), "{e}");

    let dangling = TWO_LINKS.replace(r#"<child link="c"/>"#, r#"<child link="z"/>"#);
    let e = urdf::load_str(&dangling, "dangling", None)
        .unwrap_err()
        .to_string();
    assert!(e.contains("'z'") && e.contains("does not exist"), "{e}");

    let looped = TWO_LINKS.replace(
        "</robot>",
        r#"<joint name="j3" type="fixed"><parent link="c"/><child link="a"/></joint></robot>"#,
    );
    let e = urdf::load_str(&looped, "loop", None)
        .unwrap_err()
        .to_string();
    assert!(e.contains("loop"), "{e}");

    let e = urdf::load_str(TWO_LINKS, "inline", Some("nope"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("'nope'"), "{e}");

    let e = urdf::load_str("<robot name=\"x\"><link", "garbled", None)
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with("robot garbled: not a valid URDF") && !e.contains('\n'),
        "{e}"
    );
}

#[test]
fn the_full_gravity_moment_is_minus_the_gradient_of_tilting_the_subtree() {
    // The moment about any axis w through joint i's anchor is −dV/dε for turning everything beyond joint i
    // by ε about w: an energy difference, independent of the cross product the pass uses.
    let chain = iiwa();
    let payload = Payload {
        mass: 1.5,
        com: [0.01, 0.02, 0.06],
    };
    let mut rng = ChaCha8Rng::seed_from_u64(13);
    let mut frames = Frames::new(&chain);
    let (mut tau, mut moments) = (vec![0.0; 7], vec![Vector3::zeros(); 7]);
    let mut largest_perpendicular: f64 = 0.0;
    for _ in 0..20 {
        let q = random_q(&chain, &mut rng);
        forward_kinematics(&chain, &q, &mut frames);
        gravity_moments(&chain, &frames, &payload, &GRAVITY, &mut tau, &mut moments);
        let mut axial = vec![0.0; 7];
        gravity_torques(&chain, &frames, &payload, &GRAVITY, &mut axial);
        for i in 0..7 {
            assert_eq!(tau[i], axial[i], "the axial torques are the same pass");
            let axis = frames.axis(&chain, i);
            assert!((moments[i].dot(&axis) - tau[i]).abs() < 1e-9);
            let anchor = frames.anchor(i);
            let masses: Vec<(f64, Point3<f64>)> = (i + 1..chain.bodies.len())
                .map(|b| {
                    (
                        chain.bodies[b].inertial.mass,
                        frames.body[b] * chain.bodies[b].inertial.com,
                    )
                })
                .chain([(payload.mass, frames.flange * Point3::from(payload.com))])
                .collect();
            for w in [Vector3::x(), Vector3::y(), Vector3::z()] {
                let energy = |e: f64| -> f64 {
                    let turn = nalgebra::Rotation3::from_scaled_axis(w * e);
                    masses
                        .iter()
                        .map(|(m, c)| -m * GRAVITY.dot(&(anchor.coords + turn * (c - anchor))))
                        .sum()
                };
                let h = 1e-6;
                let grad = (energy(h) - energy(-h)) / (2.0 * h);
                assert!(
                    (moments[i].dot(&w) + grad).abs() < 1e-6,
                    "joint {i}, axis {w:?}: M·w {} vs −dV/dε {}",
                    moments[i].dot(&w),
                    -grad
                );
            }
            largest_perpendicular = largest_perpendicular.max((moments[i] - axis * tau[i]).norm());
        }
    }
    // The perpendicular part is what the axial torque leaves out, and it is large.
    assert!(largest_perpendicular > 50.0, "{largest_perpendicular} Nm");
}
