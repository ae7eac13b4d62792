//! Regions of the workspace and the target poses inside them.

use nalgebra::{Isometry3, Point3, Translation3, Unit, UnitQuaternion, Vector3};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::distribution::DistributionKind;
use super::trajectory::TrajectoryConfig;
use crate::robot::collision::Obstacle;

/// The most points a region may ask for. The paper measured 2 335 and the real UR10 series a few thousand;
/// a hundred thousand is forty times that, and with up to 50 candidate targets planned per point it is
/// already millions of inverse-kinematics solves. Without a cap, `points = 100000000` grew memory
/// without end.
pub const MAX_REGION_POINTS: usize = 100_000;

/// The largest candidate pool of a model-based layout, on the same grounds (every candidate is planned and
/// its identification Jacobian kept).
pub const MAX_POOL: usize = 100_000;

fn default_distribution() -> DistributionKind {
    DistributionKind::Uniform
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
    #[serde(default = "default_distribution")]
    pub distribution: DistributionKind,
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

fn default_limit_margin() -> f64 {
    2.0
}

/// How the arm is posed for a campaign, and what stands in its way.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct CampaignConfig {
    /// The posture inverse kinematics starts from and is drawn toward in the null space (deg, per joint).
    /// It fixes the arm's branch (elbow up or down, wrist flip) for the whole campaign.
    pub posture_deg: Vec<f64>,
    /// Per-point random change of the posture target (deg, uniform ±): varies the redundancy (the iiwa's
    /// elbow) within the branch. 0 keeps one redundancy resolution for the whole campaign.
    #[serde(default)]
    pub posture_spread_deg: f64,
    /// Solutions closer than this to a joint limit are rejected (deg).
    #[serde(default = "default_limit_margin")]
    pub limit_margin_deg: f64,
    /// Boxes in the scene the arm must not touch (a table, fixtures), base frame.
    #[serde(default)]
    pub obstacles: Vec<Obstacle>,
    /// How model-based layouts (`d-optimal`) build their candidate pool and choose from it.
    #[serde(default)]
    pub selection: SelectionConfig,
    /// `[campaign.trajectory]`: measure the planned targets on the fly, along one smooth path, instead of
    /// stopping at each ([`super::trajectory`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub trajectory: Option<TrajectoryConfig>,
}

/// The candidate pool and the model of a model-based layout. The pool is a uniform layout of
/// `clamp(pool_factor · N, pool_min, pool_max)` targets for N points, planned and measured like any campaign
/// point; the feasible ones are the candidates.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct SelectionConfig {
    /// The method whose parameters the points must determine (`kinematic`, `elastic`, or a paper model).
    pub model: String,
    pub pool_factor: f64,
    pub pool_min: usize,
    pub pool_max: usize,
    /// Per-candidate random change of the posture target (deg, uniform ±), so that the pool holds several
    /// redundancy resolutions (the iiwa's elbow) and the selection can use them. Replaces
    /// `posture_spread_deg` for the pool when larger.
    pub posture_spread_deg: f64,
    /// Exchange steps of the DETMAX phase at most; absent: twice the number of points.
    pub max_exchanges: Option<usize>,
}

impl Default for SelectionConfig {
    fn default() -> Self {
        SelectionConfig {
            model: "kinematic".into(),
            pool_factor: 20.0,
            pool_min: 2000,
            pool_max: 4000,
            posture_spread_deg: 20.0,
            max_exchanges: None,
        }
    }
}

impl SelectionConfig {
    /// Pool targets for a campaign of `n` points (never fewer than `n`).
    pub fn pool(&self, n: usize) -> usize {
        ((self.pool_factor * n as f64).ceil() as usize)
            .clamp(self.pool_min, self.pool_max.max(self.pool_min))
            .max(n)
    }

    /// Checks the pool; whether `model` names a method with robot parameters is for whoever knows the
    /// methods to say (the scenario, when it is read).
    pub fn validate(&self) -> std::result::Result<(), String> {
        if !(self.pool_factor.is_finite() && self.pool_factor >= 1.0) {
            return Err(format!(
                "selection.pool_factor = {} must be finite and at least 1",
                self.pool_factor
            ));
        }
        if self.pool_max > MAX_POOL {
            return Err(format!(
                "selection.pool_max = {} exceeds {MAX_POOL}",
                self.pool_max
            ));
        }
        if self.max_exchanges.is_some_and(|m| m > 100 * MAX_POOL) {
            return Err(format!(
                "selection.max_exchanges exceeds {}",
                100 * MAX_POOL
            ));
        }
        if self.pool_max < self.pool_min || self.pool_min == 0 {
            return Err(format!(
                "selection: pool_min = {} must be positive and at most pool_max = {}",
                self.pool_min, self.pool_max
            ));
        }
        if !(self.posture_spread_deg.is_finite() && self.posture_spread_deg >= 0.0) {
            return Err(format!(
                "selection.posture_spread_deg = {} must be finite and non-negative",
                self.posture_spread_deg
            ));
        }
        Ok(())
    }
}

impl CampaignConfig {
    /// The posture in radians: where a campaign starts and what its inverse kinematics is drawn toward.
    pub fn posture_rad(&self) -> Vec<f64> {
        self.posture_deg.iter().map(|d| d.to_radians()).collect()
    }

    pub fn validate(&self) -> std::result::Result<(), String> {
        if self.posture_deg.iter().any(|v| !v.is_finite()) {
            return Err("posture_deg must be finite".into());
        }
        for (name, v) in [
            ("posture_spread_deg", self.posture_spread_deg),
            ("limit_margin_deg", self.limit_margin_deg),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(format!("{name} = {v} must be finite and non-negative"));
            }
        }
        for o in &self.obstacles {
            if !o
                .center
                .iter()
                .chain(&o.half_extents)
                .all(|v| v.is_finite())
                || o.half_extents.iter().any(|h| *h <= 0.0)
            {
                return Err(format!(
                    "obstacle '{}' needs finite centre and positive half_extents",
                    o.name
                ));
            }
        }
        if let Some(t) = &self.trajectory {
            t.validate()?;
        }
        self.selection.validate()
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
            distribution: DistributionKind::Uniform,
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
