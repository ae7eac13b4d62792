//! What makes the true robot differ from its nominal model, as magnitudes (from the scenario) and as one
//! sampled draw (written to `campaign.json`, read by nothing but the evaluation).

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};

use super::robot::DeflectionSolver;
use crate::error::{Error, Result};

/// Error magnitudes of the true robot, all one-sigma of zero-mean normal draws unless said otherwise.
/// SI units: metres, radians, newton-metres per radian.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ErrorModel {
    /// Translation offset of every joint frame, per axis (m).
    pub frame_translation_m: f64,
    /// Rotation offset of every joint frame, per axis (rad).
    pub frame_rotation_rad: f64,
    /// Joint zero (encoder) offsets (rad).
    pub joint_zero_rad: f64,
    /// Base mounting offset, per axis (m); registration absorbs it, but it keeps the base frame honest.
    pub base_translation_m: f64,
    /// Base mounting rotation, per axis (rad).
    pub base_rotation_rad: f64,
    /// Nominal joint stiffness, one per joint (Nm/rad), for joints 1..n.
    pub stiffness_nm_per_rad: Vec<f64>,
    /// Relative one-sigma scatter of each true stiffness about its nominal value.
    #[serde(default)]
    pub stiffness_spread: f64,
    /// Harmonic orders of the gear transmission error (cycles per joint revolution).
    #[serde(default)]
    pub gear_orders: Vec<u32>,
    /// Amplitude of each gear harmonic (rad); the phase is uniform.
    #[serde(default)]
    pub gear_amplitude_rad: f64,
    /// Repeatability: joint-angle noise of each reach of a pose (rad).
    #[serde(default)]
    pub repeatability_rad: f64,
    /// How the static deflection is solved: `fixed-point` (fast, default) or `rapier` (the physics reference).
    #[serde(default)]
    pub deflection: DeflectionSolver,
}

impl ErrorModel {
    pub fn validate(&self, dof: usize) -> Result<()> {
        let bad = |m: String| Err(Error::Invalid(m));
        let scalars = [
            ("frame_translation_m", self.frame_translation_m),
            ("frame_rotation_rad", self.frame_rotation_rad),
            ("joint_zero_rad", self.joint_zero_rad),
            ("base_translation_m", self.base_translation_m),
            ("base_rotation_rad", self.base_rotation_rad),
            ("stiffness_spread", self.stiffness_spread),
            ("gear_amplitude_rad", self.gear_amplitude_rad),
            ("repeatability_rad", self.repeatability_rad),
        ];
        for (name, v) in scalars {
            if !(v.is_finite() && v >= 0.0) {
                return bad(format!(
                    "truth.{name} = {v} must be finite and non-negative"
                ));
            }
        }
        if self.stiffness_nm_per_rad.len() != dof {
            return bad(format!(
                "truth.stiffness_nm_per_rad has {} values, the robot has {dof} joints",
                self.stiffness_nm_per_rad.len()
            ));
        }
        if let Some(k) = self
            .stiffness_nm_per_rad
            .iter()
            .find(|k| !(k.is_finite() && **k > 0.0))
        {
            return bad(format!(
                "truth.stiffness_nm_per_rad has {k}; every stiffness must be positive"
            ));
        }
        if self.stiffness_spread >= 0.5 {
            return bad("truth.stiffness_spread must be below 0.5 (a relative scatter)".into());
        }
        Ok(())
    }
}

/// A small rigid offset: translation (m) and rotation vector (rad), `T(t) · exp(r)`.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
pub struct Offset {
    pub translation: [f64; 3],
    pub rotation: [f64; 3],
}

impl Offset {
    pub const ZERO: Offset = Offset {
        translation: [0.0; 3],
        rotation: [0.0; 3],
    };

    pub fn isometry(&self) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::from(Vector3::from(self.translation)),
            UnitQuaternion::from_scaled_axis(Vector3::from(self.rotation)),
        )
    }

    fn sample(rng: &mut ChaCha8Rng, sigma_t: f64, sigma_r: f64) -> Offset {
        let mut draw = |s: f64| [normal(rng, s), normal(rng, s), normal(rng, s)];
        Offset {
            translation: draw(sigma_t),
            rotation: draw(sigma_r),
        }
    }
}

/// One harmonic of a joint's transmission error: `amplitude · sin(order · q + phase)`.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
pub struct GearHarmonic {
    pub order: u32,
    pub amplitude: f64,
    pub phase: f64,
}

/// One draw of the true robot's errors.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Perturbation {
    pub base: Offset,
    /// Offset appended to each joint's origin (in the joint frame).
    pub joint_frames: Vec<Offset>,
    pub joint_zero: Vec<f64>,
    /// True stiffness per joint (Nm/rad).
    pub stiffness: Vec<f64>,
    pub gear: Vec<Vec<GearHarmonic>>,
    pub repeatability_rad: f64,
}

impl Perturbation {
    /// Draws every error from `model`; the order of draws is fixed so a seed always gives the same robot.
    pub fn sample(model: &ErrorModel, dof: usize, rng: &mut ChaCha8Rng) -> Result<Perturbation> {
        model.validate(dof)?;
        let base = Offset::sample(rng, model.base_translation_m, model.base_rotation_rad);
        let joint_frames = (0..dof)
            .map(|_| Offset::sample(rng, model.frame_translation_m, model.frame_rotation_rad))
            .collect();
        let joint_zero = (0..dof)
            .map(|_| normal(rng, model.joint_zero_rad))
            .collect();
        let stiffness = model
            .stiffness_nm_per_rad
            .iter()
            .map(|k| k * (1.0 + normal(rng, model.stiffness_spread)).max(0.5))
            .collect();
        let gear = (0..dof)
            .map(|_| {
                model
                    .gear_orders
                    .iter()
                    .map(|&order| GearHarmonic {
                        order,
                        amplitude: model.gear_amplitude_rad,
                        phase: rng.random_range(0.0..std::f64::consts::TAU),
                    })
                    .collect()
            })
            .collect();
        Ok(Perturbation {
            base,
            joint_frames,
            joint_zero,
            stiffness,
            gear,
            repeatability_rad: model.repeatability_rad,
        })
    }

    /// A perturbation that changes nothing but the stiffness: the nominal geometry made compliant.
    pub fn rigid_geometry(stiffness: Vec<f64>) -> Perturbation {
        let dof = stiffness.len();
        Perturbation {
            base: Offset::ZERO,
            joint_frames: vec![Offset::ZERO; dof],
            joint_zero: vec![0.0; dof],
            stiffness,
            gear: vec![Vec::new(); dof],
            repeatability_rad: 0.0,
        }
    }

    /// Transmission error of joint `i` at commanded angle `q` (rad).
    #[inline]
    pub fn gear_error(&self, i: usize, q: f64) -> f64 {
        self.gear[i]
            .iter()
            .map(|h| h.amplitude * (f64::from(h.order) * q + h.phase).sin())
            .sum()
    }
}

fn normal(rng: &mut ChaCha8Rng, sigma: f64) -> f64 {
    if sigma == 0.0 {
        return 0.0;
    }
    // sigma was validated finite and non-negative, so the distribution always exists.
    Normal::new(0.0, sigma).map_or(0.0, |d| d.sample(rng))
}
