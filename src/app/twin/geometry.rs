//! The identified arm's geometry in the truth's terms. The elastic fit says the geometry as errors of the DH
//! frames (`calib::kinematic`); the true robot perturbs the URDF chain's joint frames ([`KnownGeometry`]). The
//! offsets that make the true chain's rigid kinematics equal the model's are fitted here, by Gauss–Newton with
//! minimum-norm steps (the parametrization is redundant: a zero offset and a rotation of the joint frame about
//! its axis do the same), at configurations spread over the pilot's joint ranges. The last DH frame's error
//! acts after the last joint turns, where the URDF chain has only its fixed flange: it comes out as an offset
//! of the flange, which the twin carries in the probe's position on it (a probe is registered anyway).

use nalgebra::{DMatrix, DVector, Isometry3};
use rand::Rng;

use crate::calib::error_model::flange_pose_with_errors;
use crate::calib::kinematic::KinematicModel;
use crate::error::{Error, Result};
use crate::numeric;
use crate::rng::{Stream, derive};
use crate::robot::Chain;
use crate::robot::kinematics::{Frames, forward_kinematics};
use crate::truth::{KnownGeometry, Offset};

/// Configurations the two kinematics are matched at.
const MATCH_CONFIGURATIONS: usize = 60;
/// Gauss–Newton steps at most; three reach rounding for errors of an arm's size.
const MAX_STEPS: usize = 8;
/// Rotation residuals weigh as the displacement they cause at this distance (m).
const ROTATION_LENGTH_M: f64 = 1.0;
/// Central-difference step of the numeric Jacobian (m, rad).
const STEP: f64 = 1e-7;
/// The match must reach this (m): far below any tracker's noise.
const MATCH_TOLERANCE_M: f64 = 1e-9;

/// The known geometry whose rigid kinematics on `chain`, followed by a fixed offset of the flange, equal
/// `model`'s (its DH-frame errors, without the joints' deflection) at configurations within `ranges` (per
/// joint, min and max); the flange offset; the largest mismatch (m).
pub fn known_geometry(
    chain: &Chain,
    model: &KinematicModel,
    ranges: &[(f64, f64)],
    seed: u64,
) -> Result<(KnownGeometry, Isometry3<f64>, f64)> {
    let n = chain.dof();
    let mut rng = derive(seed, Stream::Layout, &[u64::MAX - 7]);
    let configs: Vec<Vec<f64>> = (0..MATCH_CONFIGURATIONS)
        .map(|_| {
            ranges
                .iter()
                .map(|&(lo, hi)| rng.random_range(lo..=hi.max(lo)))
                .collect()
        })
        .collect();
    let targets: Vec<Isometry3<f64>> = configs
        .iter()
        .map(|q| flange_pose_with_errors(&model.basis.dh, q, &model.errors))
        .collect();
    let mut p = DVector::zeros(7 * n + 12);
    let mut frames = Frames::new(chain);
    let mut worst = f64::INFINITY;
    for _ in 0..MAX_STEPS {
        let r = residuals(chain, &p, &configs, &targets, &mut frames);
        worst = r
            .as_slice()
            .chunks(3)
            .map(|c| (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt())
            .fold(0.0, f64::max);
        if std::env::var_os("CALIBENCH_DEBUG_TWIN").is_some() {
            eprintln!("twin geometry: worst {worst:.3e} m");
        }
        if worst < MATCH_TOLERANCE_M * 1e-2 {
            break;
        }
        let mut j = DMatrix::zeros(r.len(), p.len());
        for k in 0..p.len() {
            let (mut plus, mut minus) = (p.clone(), p.clone());
            plus[k] += STEP;
            minus[k] -= STEP;
            let d = (residuals(chain, &plus, &configs, &targets, &mut frames)
                - residuals(chain, &minus, &configs, &targets, &mut frames))
                / (2.0 * STEP);
            j.set_column(k, &d);
        }
        let svd = numeric::svd(j, true, true, "twin geometry")?;
        // Directions the flange does not feel (the redundancy) get no step: a minimum-norm solve.
        let largest = svd.singular_values.max();
        let step = svd
            .solve(&(-&r), 1e-6 * largest)
            .map_err(|e| Error::Invalid(format!("twin geometry: {e}")))?;
        p += step;
    }
    if worst.is_nan() || worst >= MATCH_TOLERANCE_M {
        return Err(Error::Invalid(format!(
            "the identified geometry could not be carried over to the robot's joint frames ({:.1e} m left): \
             the robot description and its DH form disagree",
            worst
        )));
    }
    Ok((geometry_of(&p, n), flange_of(&p, n).isometry(), worst))
}

/// The flange's offset: the last six parameters.
fn flange_of(p: &DVector<f64>, n: usize) -> Offset {
    let k = 7 * n + 6;
    Offset {
        translation: [p[k], p[k + 1], p[k + 2]],
        rotation: [p[k + 3], p[k + 4], p[k + 5]],
    }
}

/// Parameters: the base offset (6), each joint frame's (6 each), each joint's zero offset, the flange's (6).
fn geometry_of(p: &DVector<f64>, n: usize) -> KnownGeometry {
    let offset = |k: usize| Offset {
        translation: [p[k], p[k + 1], p[k + 2]],
        rotation: [p[k + 3], p[k + 4], p[k + 5]],
    };
    KnownGeometry {
        base: offset(0),
        joint_frames: (0..n).map(|j| offset(6 + 6 * j)).collect(),
        joint_zero_rad: (0..n).map(|j| p[6 + 6 * n + j]).collect(),
    }
}

/// The rigid true chain of a known geometry, as the true robot builds it.
pub fn true_chain(chain: &Chain, geometry: &KnownGeometry) -> Chain {
    let mut truth = chain.clone();
    truth.base = geometry.base.isometry() * chain.base;
    for (joint, offset) in truth.joints.iter_mut().zip(&geometry.joint_frames) {
        joint.origin *= offset.isometry();
    }
    truth
}

/// Per configuration: the flange position's difference (m) and its rotation's (rad, × [`ROTATION_LENGTH_M`]).
fn residuals(
    chain: &Chain,
    p: &DVector<f64>,
    configs: &[Vec<f64>],
    targets: &[Isometry3<f64>],
    frames: &mut Frames,
) -> DVector<f64> {
    let geometry = geometry_of(p, chain.dof());
    let mut truth = true_chain(chain, &geometry);
    truth.flange *= flange_of(p, chain.dof()).isometry();
    let mut r = DVector::zeros(6 * configs.len());
    for (k, (q, target)) in configs.iter().zip(targets).enumerate() {
        let angles: Vec<f64> = q
            .iter()
            .zip(&geometry.joint_zero_rad)
            .map(|(a, z)| a + z)
            .collect();
        forward_kinematics(&truth, &angles, frames);
        let f = frames.flange;
        let dp = f.translation.vector - target.translation.vector;
        let dr = (f.rotation * target.rotation.inverse()).scaled_axis() * ROTATION_LENGTH_M;
        r.fixed_rows_mut::<3>(6 * k).copy_from(&dp);
        r.fixed_rows_mut::<3>(6 * k + 3).copy_from(&dr);
    }
    r
}
