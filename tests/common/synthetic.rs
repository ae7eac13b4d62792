//! The synthetic robot of tests/calibrate.rs, tests/kinematic.rs and tests/residual.rs: the iiwa following the
//! paper's error model (eq. 6) with constant error transforms, measured with [`NOISE`] by a tracker at an
//! unknown pose, one reflector mounted 0.7 mm off its nominal place (or a nest of three around it); optionally
//! compliant under gravity, with a joint held fixed, or with a smooth position field on top.

use calibench::calib::error_model::{FrameErrors, flange_pose_with_errors};
use calibench::dataset::Dataset;
use calibench::robot::dh::DhChain;
use calibench::robot::dynamics::{GRAVITY, gravity_torques};
use calibench::robot::kinematics::forward_kinematics;
use calibench::robot::{Chain, Frames, Payload, urdf};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

/// The tracker noise (m, per axis).
pub const NOISE: f64 = 10e-6;

/// The default load of compliant joints.
pub const PAYLOAD: Payload = Payload {
    mass: 0.4,
    com: [0.0, 0.0, 0.03],
};

/// A position error (base frame, m) as a function of the joint angles.
pub type Field = fn(&[f64]) -> Vector3<f64>;

pub fn iiwa() -> (Chain, DhChain) {
    robot("robots/iiwa7.urdf")
}

pub fn robot(urdf_path: &str) -> (Chain, DhChain) {
    let chain = urdf::load_file(urdf_path, None).unwrap();
    let dh = DhChain::from_chain(&chain).unwrap();
    (chain, dh)
}

/// What the synthetic robot does besides its constant error transforms.
#[derive(Default)]
pub struct Extra {
    /// Joint compliances (rad/Nm): the arm deflects by `C τ(q)`, τ of the nominal URDF inertials + payload.
    pub compliance: Option<Vec<f64>>,
    /// Joint (0-based) held at the centre value in every configuration (its random draw is still made).
    pub fixed_joint: Option<usize>,
    /// Half-width of the joint ranges around the centre configuration (rad, default 0.5).
    pub spread: Option<f64>,
    /// The load the compliant joints carry (default [`PAYLOAD`]).
    pub payload: Option<Payload>,
    /// A position error (base frame) of the commanded joint angles added to every true point.
    pub field: Option<Field>,
    /// A nest of three reflectors around the mounting point instead of one reflector on it.
    pub nest: bool,
    /// The UR10 (6 joints, `robots/ur10.urdf`) instead of the iiwa.
    pub ur10: bool,
    /// The reflector exactly on the last joint's axis (the flange z axis, 30 mm out), nominally and truly.
    pub on_axis: bool,
}

pub struct Synthetic {
    pub chain: Chain,
    pub dh: DhChain,
    pub data: Dataset,
    /// Noise-free true positions of the mounting point (the nest centre) in the tracker frame.
    pub truth: Vec<Point3<f64>>,
    /// True flange orientations in the tracker frame.
    pub truth_orientation: Vec<UnitQuaternion<f64>>,
}

/// `n` points of a forward-reaching family of configurations (one IK branch, as a campaign has). The random
/// draws, per point: the joint offsets (one per joint), then 3 normal noise samples per reflector.
pub fn synthetic(errors: &FrameErrors, n: usize, seed: u64, extra: &Extra) -> Synthetic {
    synthetic_with_noise(errors, n, seed, extra, NOISE)
}

/// [`synthetic`] with the tracker noise `noise` (m per axis; 0 for noise-free data).
pub fn synthetic_with_noise(
    errors: &FrameErrors,
    n: usize,
    seed: u64,
    extra: &Extra,
    noise: f64,
) -> Synthetic {
    let (chain, dh) = if extra.ur10 {
        robot("robots/ur10.urdf")
    } else {
        iiwa()
    };
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let tracker = Isometry3::from_parts(
        Translation3::new(3.0, 0.3, 1.7),
        UnitQuaternion::from_euler_angles(0.01, 0.02, 3.1),
    );
    let (mount_nominal, mount_true) = if extra.on_axis {
        (Point3::new(0.0, 0.0, 0.03), Point3::new(0.0, 0.0, 0.03))
    } else {
        (
            Point3::new(0.0, 0.0, 0.03),
            Point3::new(0.0006, -0.0004, 0.0302),
        )
    };
    let offsets: Vec<Vector3<f64>> = if extra.nest {
        vec![
            Vector3::new(0.03, 0.0, 0.0),
            Vector3::new(-0.015, 0.026, 0.0),
            Vector3::new(-0.015, -0.026, 0.0),
        ]
    } else {
        vec![Vector3::zeros()]
    };
    let noise = Normal::new(0.0, noise).unwrap();
    let (mut q, mut measured, mut nominal, mut truth) = (vec![], vec![], vec![], vec![]);
    let mut truth_orientation = vec![];
    let centre: &[f64] = if extra.ur10 {
        &[0.3, -1.4, 1.6, -1.8, -1.5, 0.2]
    } else {
        &[0.0, 0.6, 0.0, -1.6, 0.0, -0.8, 0.0]
    };
    let dof = centre.len();
    let spread = extra.spread.unwrap_or(0.5);
    let mut frames = Frames::new(&chain);
    let mut tau = vec![0.0; dof];
    for _ in 0..n {
        let qi: Vec<f64> = centre
            .iter()
            .enumerate()
            .map(|(j, c)| {
                let d = rng.random_range(-spread..spread);
                if extra.fixed_joint == Some(j) {
                    *c
                } else {
                    c + d
                }
            })
            .collect();
        let reached: Vec<f64> = match &extra.compliance {
            Some(c) => {
                forward_kinematics(&chain, &qi, &mut frames);
                let payload = extra.payload.unwrap_or(PAYLOAD);
                gravity_torques(&chain, &frames, &payload, &GRAVITY, &mut tau);
                qi.iter()
                    .zip(c)
                    .zip(&tau)
                    .map(|((q, c), t)| q + c * t)
                    .collect()
            }
            None => qi.clone(),
        };
        let flange = flange_pose_with_errors(&dh, &reached, errors);
        let shift = extra.field.map(|f| f(&qi));
        // A point on the flange in the tracker frame (without a field, nothing is added, not even zero).
        let observed = |p: Point3<f64>| {
            let base = flange * p;
            tracker.inverse_transform_point(&match shift {
                Some(s) => base + s,
                None => base,
            })
        };
        truth.push(observed(mount_true));
        truth_orientation.push(tracker.rotation.inverse() * flange.rotation);
        measured.push(
            offsets
                .iter()
                .map(|d| observed(mount_true + d) + Vector3::from_fn(|_, _| noise.sample(&mut rng)))
                .collect::<Vec<_>>(),
        );
        let nominal_flange = dh.flange_pose(&qi);
        nominal.push(
            offsets
                .iter()
                .map(|d| nominal_flange * (mount_nominal + d))
                .collect::<Vec<_>>(),
        );
        q.push(qi);
    }
    let mut data = Dataset::in_memory("synthetic", chain.joint_names(), q, measured);
    data.nominal_reflectors = Some(nominal);
    Synthetic {
        chain,
        dh,
        data,
        truth,
        truth_orientation,
    }
}

pub fn mean(v: impl Iterator<Item = f64>) -> f64 {
    let v: Vec<f64> = v.collect();
    v.iter().sum::<f64>() / v.len() as f64
}

/// Mean distance of a 3-D isotropic normal error of σ per axis: σ·√(8/π).
pub fn noise_mean() -> f64 {
    NOISE * (8.0 / std::f64::consts::PI).sqrt()
}
