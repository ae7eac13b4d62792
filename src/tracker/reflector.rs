//! Reflectors on the flange: one for position campaigns, a nest of three for full-pose campaigns.
//!
//! The calibration knows the nominal mounting; the true one differs by an unknown offset (a nest is never
//! bolted on exactly as drawn). A fixed rotation of the nest is what gives the paper's Table 2 its large,
//! nearly constant "measured" orientation error.

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ReflectorConfig {
    /// Nominal reflector centres in the flange frame (m): one, or three for a nest.
    pub nominal_m: Vec<[f64; 3]>,
    /// Direction the reflectors face, in the flange frame (normalised on use).
    pub facing: [f64; 3],
    /// One-sigma translation of the unknown mounting error, per axis (m).
    #[serde(default)]
    pub mount_translation_m: f64,
    /// One-sigma rotation of the unknown mounting error about the reflectors' centroid, per axis (rad).
    #[serde(default)]
    pub mount_rotation_rad: f64,
    /// A fixed rotation of the mounting (rotation vector, rad), added to the random one.
    #[serde(default)]
    pub mount_fixed_rotation_rad: [f64; 3],
}

impl ReflectorConfig {
    pub fn validate(&self) -> std::result::Result<(), String> {
        if !matches!(self.nominal_m.len(), 1 | 3) {
            return Err(format!(
                "nominal_m has {} reflectors; use 1 (position) or 3 (a nest, full pose)",
                self.nominal_m.len()
            ));
        }
        let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
        if !self.nominal_m.iter().all(|p| finite(p)) || !finite(&self.mount_fixed_rotation_rad) {
            return Err("nominal_m and mount_fixed_rotation_rad must be finite".into());
        }
        if !finite(&self.facing) || Vector3::from(self.facing).norm() < 1e-9 {
            return Err("facing must be a non-zero direction".into());
        }
        for (name, v) in [
            ("mount_translation_m", self.mount_translation_m),
            ("mount_rotation_rad", self.mount_rotation_rad),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(format!("{name} = {v} must be finite and non-negative"));
            }
        }
        if self.nominal_m.len() == 3 {
            let [a, b, c] = [0, 1, 2].map(|i| Vector3::from(self.nominal_m[i]));
            if (b - a).cross(&(c - a)).norm() < 1e-6 {
                return Err(
                    "the three nest reflectors are collinear: they cannot give an orientation"
                        .into(),
                );
            }
        }
        Ok(())
    }

    pub fn nominal(&self) -> Vec<Point3<f64>> {
        self.nominal_m.iter().map(|p| Point3::from(*p)).collect()
    }
}

/// The reflectors as mounted: nominal positions (known) and true positions (unknown), in the flange frame.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Mounting {
    pub nominal: Vec<Point3<f64>>,
    #[serde(rename = "true")]
    pub actual: Vec<Point3<f64>>,
    /// Unit direction the reflectors face, flange frame.
    pub facing: Vector3<f64>,
}

impl Mounting {
    /// Draws the true mounting: a rigid offset about the nominal centroid.
    pub fn sample(config: &ReflectorConfig, rng: &mut ChaCha8Rng) -> Result<Mounting> {
        config
            .validate()
            .map_err(|m| Error::Invalid(format!("reflectors: {m}")))?;
        let mut draw = |sigma: f64| -> Vector3<f64> {
            if sigma == 0.0 {
                return Vector3::zeros();
            }
            let n = Normal::new(0.0, sigma).expect("sigma validated finite and non-negative");
            Vector3::new(n.sample(rng), n.sample(rng), n.sample(rng))
        };
        let translation = draw(config.mount_translation_m);
        let rotation = UnitQuaternion::from_scaled_axis(draw(config.mount_rotation_rad))
            * UnitQuaternion::from_scaled_axis(Vector3::from(config.mount_fixed_rotation_rad));
        let nominal = config.nominal();
        let centroid = Point3::from(
            nominal.iter().map(|p| p.coords).sum::<Vector3<f64>>() / nominal.len() as f64,
        );
        let offset =
            Isometry3::from_parts(Translation3::from(centroid.coords + translation), rotation)
                * Isometry3::translation(-centroid.x, -centroid.y, -centroid.z);
        let facing = Vector3::from(config.facing).normalize();
        Ok(Mounting {
            actual: nominal.iter().map(|p| offset * p).collect(),
            nominal,
            facing: rotation * facing,
        })
    }

    pub fn count(&self) -> usize {
        self.nominal.len()
    }
}
