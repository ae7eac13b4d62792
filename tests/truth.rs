//! The true robot: sampled perturbations, the fast static deflection and its rapier reference.

use calibench::robot::{Chain, Payload, urdf};
use calibench::truth::physics::SettleOptions;
use calibench::truth::robot::Deflection;
use calibench::truth::{ErrorModel, Perturbation, TrueRobot, TrueState};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn iiwa() -> Chain {
    urdf::load_file("robots/iiwa7.urdf", None).expect("the shipped URDF loads")
}

fn model() -> ErrorModel {
    ErrorModel {
        frame_translation_m: 1e-4,
        frame_rotation_rad: 2e-4,
        joint_zero_rad: 2e-4,
        base_translation_m: 5e-4,
        base_rotation_rad: 5e-4,
        stiffness_nm_per_rad: vec![2.0e4, 1.5e4, 1.2e4, 1.0e4, 5e3, 4e3, 3e3],
        stiffness_spread: 0.1,
        gear_orders: vec![1, 2],
        gear_amplitude_rad: 2e-5,
        repeatability_rad: 1e-5,
        ..ErrorModel::stiff_only(vec![])
    }
}

fn payload() -> Payload {
    Payload {
        mass: 0.8,
        com: [0.0, 0.0, 0.06],
    }
}

fn random_q(chain: &Chain, rng: &mut ChaCha8Rng) -> Vec<f64> {
    chain
        .joints
        .iter()
        .map(|j| rng.random_range(0.8 * j.lower..0.8 * j.upper))
        .collect()
}

#[test]
fn a_seed_gives_one_robot() {
    let chain = iiwa();
    let a = Perturbation::sample(&model(), 7, &mut ChaCha8Rng::seed_from_u64(5)).unwrap();
    let b = Perturbation::sample(&model(), 7, &mut ChaCha8Rng::seed_from_u64(5)).unwrap();
    let c = Perturbation::sample(&model(), 7, &mut ChaCha8Rng::seed_from_u64(6)).unwrap();
    assert_eq!(a, b);
    assert_ne!(a, c);
    let wrong = ErrorModel {
        stiffness_nm_per_rad: vec![1e4; 6],
        ..model()
    };
    let e =
        Perturbation::sample(&wrong, chain.dof(), &mut ChaCha8Rng::seed_from_u64(5)).unwrap_err();
    assert!(e.to_string().contains("6 values"), "{e}");
}

#[test]
fn fixed_point_deflection_is_the_static_equilibrium() {
    let chain = iiwa();
    let p = Perturbation::sample(&model(), 7, &mut ChaCha8Rng::seed_from_u64(1)).unwrap();
    let robot = TrueRobot::new(&chain, p.clone(), payload()).unwrap();
    let mut state = TrueState::new(&robot);
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    let mut tau = vec![0.0; 7];
    let mut largest: f64 = 0.0;
    for _ in 0..50 {
        let q = random_q(&chain, &mut rng);
        robot.reach(&q, None, &mut state).unwrap();
        calibench::robot::dynamics::gravity_torques(
            &robot.chain,
            &state.frames,
            &robot.payload,
            &robot.gravity,
            &mut tau,
        );
        for (i, t) in tau.iter().enumerate() {
            let residual = p.stiffness[i] * (state.q[i] - state.q0[i]) - t;
            assert!(residual.abs() < 1e-8, "joint {i}: K·Δq − τ = {residual} Nm");
            largest = largest.max((state.q[i] - state.q0[i]).abs());
        }
    }
    // The deflection is real, not vanishing: the arm sags by around a milliradian somewhere.
    assert!(largest > 2e-4, "largest deflection {largest} rad");
}

#[test]
fn rapier_and_fixed_point_agree_at_the_flange() {
    let chain = iiwa();
    let p = Perturbation::sample(&model(), 7, &mut ChaCha8Rng::seed_from_u64(3)).unwrap();
    let robot = TrueRobot::new(&chain, p, payload()).unwrap();
    let mut physics = robot.physics_reference(SettleOptions::default()).unwrap();
    let mut fast = TrueState::new(&robot);
    let mut reference = TrueState::new(&robot);
    let mut rng = ChaCha8Rng::seed_from_u64(4);
    let mut worst: f64 = 0.0;
    let mut sag: f64 = 0.0;
    for _ in 0..24 {
        let q = random_q(&chain, &mut rng);
        robot.reach(&q, None, &mut fast).unwrap();
        let settled = physics.settle(&fast.q0).unwrap();
        let settled = Deflection {
            q: settled.q,
            tilt: Vec::new(),
        };
        robot.reach_with_angles(&settled, 1.0, None, &mut reference);
        let gap = (fast.frames.flange.translation.vector
            - reference.frames.flange.translation.vector)
            .norm();
        worst = worst.max(gap);
        let unloaded = calibench::robot::flange_pose(&robot.chain, &fast.q0);
        sag = sag.max((unloaded.translation.vector - fast.frames.flange.translation.vector).norm());
    }
    assert!(
        worst <= 1e-6,
        "rapier and fixed point differ by {worst} m at the flange"
    );
    // The agreement means something only if the deflection itself is far larger than the tolerance.
    assert!(sag > 3e-4, "largest flange sag {sag} m");
}

/// The linearisation's columns move one joint's angle or rate at a time: the frames from that joint on, computed
/// again on the others' (`kinematics_from`), their geometry (`geometry_from`) and the inverse dynamics from that
/// joint on (`inverse_dynamics_from`, on the base pass's motion before it), the workspace carried from column to
/// column as the motion's linearisation does, give a whole pass's frames and torques, bit for bit — tilted,
/// thermally scaled links.
#[test]
fn the_frames_and_torques_from_a_joint_on_are_a_whole_pass() {
    use calibench::robot::Frames;
    use calibench::robot::inverse_dynamics::{
        Workspace, geometry_from, inverse_dynamics, inverse_dynamics_from,
    };
    use nalgebra::Vector3;
    let chain = iiwa();
    let tilting = ErrorModel {
        tilt_stiffness_nm_per_rad: vec![1e6, 1e6, 6e5, 6e5, 4e5, 2e5, 2e5],
        ..model()
    };
    let p = Perturbation::sample(&tilting, 7, &mut ChaCha8Rng::seed_from_u64(7)).unwrap();
    let robot = TrueRobot::new(&chain, p, payload()).unwrap();
    assert!(robot.tilts());
    let mut rng = ChaCha8Rng::seed_from_u64(8);
    let mut small = || rng.random_range(-1e-4..1e-4);
    let tilt: Vec<Vector3<f64>> = (0..7)
        .map(|_| Vector3::new(small(), small(), small()))
        .collect();
    let q = random_q(&chain, &mut rng);
    let (qd, qdd) = (random_q(&chain, &mut rng), random_q(&chain, &mut rng));
    let scale = 1.0 + 4e-5;
    let mut base = Frames::new(&chain);
    robot.kinematics(&q, &tilt, scale, &mut base);
    let (chain, load, g) = (&robot.chain, &robot.payload, &robot.gravity);
    let mut scratch = Workspace::new(chain);
    let mut whole_pass = |frames: &Frames, qd: &[f64]| -> Vec<u64> {
        let mut tau = vec![0.0; 7];
        inverse_dynamics(chain, frames, load, g, qd, &qdd, &mut scratch, &mut tau);
        tau.iter().map(|t| t.to_bits()).collect()
    };
    // The workspace holds the state's geometry and motion first, as after the linearisation's base pass.
    let (mut ws, mut kept, mut tau) = (Workspace::new(chain), Workspace::new(chain), vec![0.0; 7]);
    inverse_dynamics(chain, &base, load, g, &qd, &qdd, &mut ws, &mut tau);
    kept.copy_motion_from(&ws, 7);
    let bits = |f: &Frames| -> Vec<u64> {
        f.body
            .iter()
            .chain(&f.joint)
            .chain([&f.flange])
            .flat_map(|i| {
                let (t, r) = (i.translation.vector, i.rotation.coords);
                [t.x, t.y, t.z, r.x, r.y, r.z, r.w]
            })
            .map(f64::to_bits)
            .collect()
    };
    let (mut whole, mut part) = (Frames::new(chain), Frames::new(chain));
    for j in 0..7 {
        let mut moved = q.clone();
        moved[j] += 1e-6;
        robot.kinematics(&moved, &tilt, scale, &mut whole);
        part.body[j] = base.body[j];
        robot.kinematics_from(&moved, &tilt, scale, &mut part, j);
        geometry_from(chain, &part, load, &mut ws, j);
        ws.copy_motion_from(&kept, j);
        inverse_dynamics_from(chain, &part, load, &qd, &qdd, &mut ws, &mut tau, j);
        // The joint frames before j are the last column's (not read); the rest must match.
        let (w, p) = (bits(&whole), bits(&part));
        let body = 8 * 7;
        assert_eq!(w[..body], p[..body], "angle {j}: bodies");
        assert_eq!(
            w[body + 7 * j..],
            p[body + 7 * j..],
            "angle {j}: joints from j on, flange"
        );
        let t: Vec<u64> = tau.iter().map(|t| t.to_bits()).collect();
        assert_eq!(whole_pass(&whole, &qd), t, "angle {j}: torques");
        assert_ne!(w, bits(&base), "angle {j}: the joint moved nothing");
    }
    // A joint's rate, on the state's frames.
    geometry_from(chain, &base, load, &mut ws, 0);
    for j in 0..7 {
        let mut faster = qd.clone();
        faster[j] += 1e-3;
        ws.copy_motion_from(&kept, j);
        inverse_dynamics_from(chain, &base, load, &faster, &qdd, &mut ws, &mut tau, j);
        let t: Vec<u64> = tau.iter().map(|t| t.to_bits()).collect();
        assert_eq!(whole_pass(&base, &faster), t, "rate {j}: torques");
        assert_ne!(
            whole_pass(&base, &qd),
            t,
            "rate {j}: the rate moved nothing"
        );
    }
}
