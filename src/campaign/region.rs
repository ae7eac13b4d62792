//! Regions of the workspace and the target poses inside them.

use nalgebra::{Isometry3, Point3, Translation3, Unit, UnitQuaternion, Vector3};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::layout::LayoutKind;

/// The most points a region may ask for. The paper measured 2 335 and the real UR10 series a few thousand;
/// a hundred thousand is forty times that, and with up to 50 candidate targets planned per point it is
/// already millions of inverse-kinematics solves. Without a cap, `points = 100000000` grew memory
/// without end.
pub const MAX_REGION_POINTS: usize = 100_000;

fn default_layout() -> LayoutKind {
    LayoutKind::Uniform
}

/// A box in the robot's base frame where the tool works, with the tool orientations allowed there.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct RegionConfig {
    pub name: String,
    /// Centre of the box (m, base frame).
    pub center_m: [f64; 3],
    /// Side lengths along base x, y, z (m).
    pub size_m: [f64; 3],
    /// Measured points wanted in this region.
    pub points: usize,
    /// How the region's points are placed (`uniform`, `grid`, `sobol`, …); `distribution` is its older name.
    #[serde(default = "default_layout", alias = "distribution")]
    pub layout: LayoutKind,
    /// Nominal flange orientation: roll, pitch, yaw (deg, URDF fixed-axis convention, base frame).
    pub tool_rpy_deg: [f64; 3],
    /// The flange z axis may tilt up to this angle from its nominal direction (deg), uniform over the cone.
    #[serde(default)]
    pub cone_half_angle_deg: f64,
    /// The flange may turn about its z axis by up to ± this angle (deg), uniform.
    #[serde(default)]
    pub spin_deg: f64,
}

impl RegionConfig {
    pub fn validate(&self) -> std::result::Result<(), String> {
        let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
        if !finite(&self.center_m) || !finite(&self.tool_rpy_deg) {
            return Err("center_m and tool_rpy_deg must be finite".into());
        }
        if !self.size_m.iter().all(|s| s.is_finite() && *s >= 0.0)
            || self.size_m.iter().all(|s| *s == 0.0)
        {
            return Err(format!(
                "size_m {:?} must be non-negative with one side at least non-zero",
                self.size_m
            ));
        }
        if !(1..=MAX_REGION_POINTS).contains(&self.points) {
            return Err(format!(
                "points = {}: between 1 and {MAX_REGION_POINTS} per region",
                self.points
            ));
        }
        if !(0.0..90.0).contains(&self.cone_half_angle_deg) {
            return Err(format!(
                "cone_half_angle_deg {} must lie in [0, 90)",
                self.cone_half_angle_deg
            ));
        }
        if !(0.0..=180.0).contains(&self.spin_deg) {
            return Err(format!("spin_deg {} must lie in [0, 180]", self.spin_deg));
        }
        Ok(())
    }

    pub fn min_corner(&self) -> Point3<f64> {
        Point3::from(Vector3::from(self.center_m) - Vector3::from(self.size_m) / 2.0)
    }

    /// A point of the unit cube mapped into the box.
    /// Distance (m) of `p` (base frame) from the region's box; 0 inside.
    pub fn distance(&self, p: &Point3<f64>) -> f64 {
        let c = Vector3::from(self.center_m);
        let half = Vector3::from(self.size_m) / 2.0;
        (p.coords - c)
            .abs()
            .zip_map(&half, |d, h| (d - h).max(0.0))
            .norm()
    }

    pub fn point_at(&self, unit: &[f64; 3]) -> Point3<f64> {
        self.min_corner() + Vector3::from(self.size_m).component_mul(&Vector3::from(*unit))
    }

    pub fn nominal_rotation(&self) -> UnitQuaternion<f64> {
        let [r, p, y] = self.tool_rpy_deg.map(f64::to_radians);
        UnitQuaternion::from_euler_angles(r, p, y)
    }

    /// A flange orientation drawn uniformly from the cone (area-uniform tilt) and the spin range.
    pub fn sample_rotation(&self, rng: &mut ChaCha8Rng) -> UnitQuaternion<f64> {
        let nominal = self.nominal_rotation();
        let cos_max = self.cone_half_angle_deg.to_radians().cos();
        let tilt = rng.random_range(cos_max..=1.0).acos();
        let azimuth = rng.random_range(0.0..std::f64::consts::TAU);
        let spin = rng.random_range(-1.0..=1.0) * self.spin_deg.to_radians();
        // The tilt axis is perpendicular to the nominal tool axis, at a random azimuth around it.
        let axis_local = Vector3::new(azimuth.cos(), azimuth.sin(), 0.0);
        let tilt_rot =
            UnitQuaternion::from_axis_angle(&Unit::new_normalize(nominal * axis_local), tilt);
        tilt_rot * nominal * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), spin)
    }

    pub fn target(&self, unit: &[f64; 3], rng: &mut ChaCha8Rng) -> Isometry3<f64> {
        let p = self.point_at(unit);
        Isometry3::from_parts(Translation3::from(p.coords), self.sample_rotation(rng))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distance_from_the_box() {
        let region = RegionConfig {
            name: "r".into(),
            center_m: [1.0, 0.0, 0.5],
            size_m: [0.2, 0.4, 0.6],
            points: 1,
            layout: LayoutKind::Uniform,
            tool_rpy_deg: [0.0; 3],
            cone_half_angle_deg: 0.0,
            spin_deg: 0.0,
        };
        // Inside, on a face, beyond a face, beyond an edge (3-4-5) and a corner.
        assert_eq!(region.distance(&Point3::new(1.05, 0.1, 0.7)), 0.0);
        assert!(region.distance(&Point3::new(1.1, 0.0, 0.5)) < 1e-15);
        assert!((region.distance(&Point3::new(1.0, 0.5, 0.5)) - 0.3).abs() < 1e-15);
        assert!((region.distance(&Point3::new(1.4, -0.6, 0.5)) - 0.5).abs() < 1e-15);
        let corner = region.distance(&Point3::new(0.8, 0.3, 0.1));
        assert!((corner - (0.1f64.powi(2) * 2.0 + 0.1f64.powi(2)).sqrt()).abs() < 1e-15);
    }
}
