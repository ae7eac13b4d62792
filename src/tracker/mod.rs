//! The laser tracker: an instrument standing somewhere in the cell, in a frame the calibration does not know
//! (it is recovered by registration), measuring reflector positions in its own spherical coordinates.
//!
//! Noise is added where the instrument makes it — on the interferometer/ADM range and on the two encoder
//! angles — so its Cartesian shape (a thin disc across the beam far away, elongated along it close by) is
//! what a real campaign sees, not an isotropic blob.

pub mod reflector;

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

fn default_cone() -> f64 {
    30.0
}

fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

fn is_zero2(v: &[f64; 2]) -> bool {
    *v == [0.0; 2]
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct TrackerConfig {
    /// Tracker head in the robot base (world) frame, m.
    pub position_m: [f64; 3],
    /// Rotation of the tracker frame about world z, deg; unknown to the calibration.
    pub yaw_deg: f64,
    /// Small tilts about x and y, deg (a tripod is never quite level).
    #[serde(default)]
    pub tilt_deg: [f64; 2],
    /// Constant part of the range noise, m (1σ).
    pub range_sigma_m: f64,
    /// Distance-proportional part of the range noise, m per m.
    pub range_sigma_per_m: f64,
    /// Noise of each of the two angles, rad (1σ).
    pub angle_sigma_rad: f64,
    /// Half angle of the reflector's acceptance cone, deg.
    #[serde(default = "default_cone")]
    pub acceptance_half_angle_deg: f64,
    /// Noise of a 6-DoF probe's measured orientation, rad (1σ per axis); only a replay of a campaign that
    /// measured a probe's orientation uses it.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub orientation_sigma_rad: f64,
    // Systematic errors the tracker's own compensation leaves (none by default): the same on every
    // measurement, so registration cannot average them away.
    /// Constant error of the range (ADM / bird-bath offset), m.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub range_offset_m: f64,
    /// Range scale error (m per m): a residual of the air's refractive index compensation.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub range_scale: f64,
    /// Eccentricity of the azimuth encoder: error `e0 cos(az) + e1 sin(az)` of the azimuth, rad.
    #[serde(default, skip_serializing_if = "is_zero2")]
    pub azimuth_eccentricity_rad: [f64; 2],
    /// Eccentricity of the elevation encoder: error `e0 cos(el) + e1 sin(el)` of the elevation, rad.
    #[serde(default, skip_serializing_if = "is_zero2")]
    pub elevation_eccentricity_rad: [f64; 2],
    /// Vertical index offset: a constant error of the elevation, rad.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub vertical_index_offset_rad: f64,
}

impl TrackerConfig {
    /// This configuration with the tracker frame at `pose` (tracker frame in the world frame), written as
    /// position, yaw and tilts: `Rz(yaw)·Ry(tilt_y)·Rx(tilt_x)` is a complete Euler decomposition, so any
    /// rotation is represented. Returns the angle (rad) between `pose`'s rotation and the one the fields give
    /// back, the round-off of the decomposition.
    pub fn placed_at(&self, pose: &Isometry3<f64>) -> (TrackerConfig, f64) {
        let (roll, pitch, yaw) = pose.rotation.euler_angles();
        let config = TrackerConfig {
            position_m: pose.translation.vector.into(),
            yaw_deg: yaw.to_degrees(),
            tilt_deg: [roll.to_degrees(), pitch.to_degrees()],
            ..self.clone()
        };
        let residual = (config.rotation().inverse() * pose.rotation).angle();
        (config, residual)
    }

    /// The rotation of the tracker frame in the world frame.
    fn rotation(&self) -> UnitQuaternion<f64> {
        UnitQuaternion::from_euler_angles(
            self.tilt_deg[0].to_radians(),
            self.tilt_deg[1].to_radians(),
            self.yaw_deg.to_radians(),
        )
    }

    /// Whether the tracker has any systematic error.
    pub fn has_systematic(&self) -> bool {
        self.range_offset_m != 0.0
            || self.range_scale != 0.0
            || !is_zero2(&self.azimuth_eccentricity_rad)
            || !is_zero2(&self.elevation_eccentricity_rad)
            || self.vertical_index_offset_rad != 0.0
    }
}

#[derive(Clone, Debug)]
pub struct Tracker {
    /// Tracker frame in the world frame.
    pub pose: Isometry3<f64>,
    pub config: TrackerConfig,
}

impl Tracker {
    /// The frame is `Rz(yaw)·Ry(tilt_y)·Rx(tilt_x)` at `position_m`: yaw is the free setup angle, the tilts
    /// the residual of levelling.
    pub fn new(config: TrackerConfig) -> Result<Tracker> {
        let bad = |what: &str| Err(Error::Invalid(format!("tracker: {what}")));
        let c = &config;
        if !c.position_m.iter().all(|v| v.is_finite()) {
            return bad("position_m must be finite");
        }
        if !c.yaw_deg.is_finite() || !c.tilt_deg.iter().all(|v| v.is_finite()) {
            return bad("yaw_deg and tilt_deg must be finite");
        }
        for (name, v) in [
            ("range_sigma_m", c.range_sigma_m),
            ("range_sigma_per_m", c.range_sigma_per_m),
            ("angle_sigma_rad", c.angle_sigma_rad),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return bad(&format!("{name} must be finite and non-negative, got {v}"));
            }
        }
        let systematic = [
            ("range_offset_m", c.range_offset_m),
            ("range_scale", c.range_scale),
            ("azimuth_eccentricity_rad", c.azimuth_eccentricity_rad[0]),
            ("azimuth_eccentricity_rad", c.azimuth_eccentricity_rad[1]),
            (
                "elevation_eccentricity_rad",
                c.elevation_eccentricity_rad[0],
            ),
            (
                "elevation_eccentricity_rad",
                c.elevation_eccentricity_rad[1],
            ),
            ("vertical_index_offset_rad", c.vertical_index_offset_rad),
        ];
        for (name, v) in systematic {
            if !v.is_finite() {
                return bad(&format!("{name} must be finite, got {v}"));
            }
        }
        if c.range_scale.abs() >= 0.01 {
            return bad(&format!(
                "range_scale must be a small relative error (|s| < 0.01), got {}",
                c.range_scale
            ));
        }
        let cone = c.acceptance_half_angle_deg;
        if !(cone > 0.0 && cone < 90.0) {
            return bad(&format!(
                "acceptance_half_angle_deg must lie in (0, 90), got {cone}"
            ));
        }
        if !(c.orientation_sigma_rad.is_finite() && c.orientation_sigma_rad >= 0.0) {
            return bad(&format!(
                "orientation_sigma_rad must be finite and non-negative, got {}",
                c.orientation_sigma_rad
            ));
        }
        let rotation = c.rotation();
        let [x, y, z] = c.position_m;
        Ok(Tracker {
            pose: Isometry3::from_parts(Translation3::new(x, y, z), rotation),
            config,
        })
    }

    pub fn origin(&self) -> Point3<f64> {
        Point3::from(self.pose.translation.vector)
    }

    fn range_sigma(&self, range: f64) -> f64 {
        self.config.range_sigma_m + self.config.range_sigma_per_m * range
    }

    /// A noisy measurement of a world point, in the TRACKER frame (m). Three standard normals are drawn in the
    /// fixed order range, azimuth, elevation — always three, even with zero sigmas — so a campaign's random
    /// stream does not depend on the noise settings.
    pub fn measure(&self, world_point: &Point3<f64>, rng: &mut ChaCha8Rng) -> Point3<f64> {
        let p = self.pose.inverse_transform_point(world_point);
        let n_range: f64 = rng.sample(StandardNormal);
        let n_az: f64 = rng.sample(StandardNormal);
        let n_el: f64 = rng.sample(StandardNormal);
        let c = &self.config;
        let systematic = c.has_systematic();
        if c.range_sigma_m == 0.0
            && c.range_sigma_per_m == 0.0
            && c.angle_sigma_rad == 0.0
            && !systematic
        {
            // Exact, rather than through a spherical round trip that would cost a few ulps.
            return p;
        }
        let horizontal = p.x.hypot(p.y);
        let range = p.coords.norm();
        let azimuth = p.y.atan2(p.x);
        let elevation = p.z.atan2(horizontal);
        let mut r = range + self.range_sigma(range) * n_range;
        let mut az = azimuth + c.angle_sigma_rad * n_az;
        let mut el = elevation + c.angle_sigma_rad * n_el;
        if systematic {
            let (sa, ca) = azimuth.sin_cos();
            let (se, ce) = elevation.sin_cos();
            let [a0, a1] = c.azimuth_eccentricity_rad;
            let [e0, e1] = c.elevation_eccentricity_rad;
            r += c.range_offset_m + c.range_scale * range;
            az += a0 * ca + a1 * sa;
            el += e0 * ce + e1 * se + c.vertical_index_offset_rad;
        }
        let (sa, ca) = az.sin_cos();
        let (se, ce) = el.sin_cos();
        Point3::new(r * ce * ca, r * ce * sa, r * se)
    }

    /// A 6-DoF probe's measured orientation, in the TRACKER frame, of a probe whose frame has rotation `world`
    /// in the world frame: the frame change and a rotation vector of `orientation_sigma_rad` per axis. Three
    /// standard normals are drawn whatever the sigma, as in [`Tracker::measure`].
    pub fn measure_orientation(
        &self,
        world: &UnitQuaternion<f64>,
        rng: &mut ChaCha8Rng,
    ) -> UnitQuaternion<f64> {
        let noise = Vector3::from_fn(|_, _| rng.sample::<f64, _>(StandardNormal))
            * self.config.orientation_sigma_rad;
        self.pose.rotation.inverse() * world * UnitQuaternion::from_scaled_axis(noise)
    }

    /// Whether the reflector, facing along `facing` (world), returns the beam: the direction from the reflector
    /// to the tracker must lie within the acceptance half angle of `facing`. A degenerate input (zero facing,
    /// reflector at the head) is not seen.
    pub fn in_acceptance_cone(&self, reflector: &Point3<f64>, facing: &Vector3<f64>) -> bool {
        let beam = self.origin() - reflector;
        let denom = beam.norm() * facing.norm();
        if !(denom > 0.0 && denom.is_finite()) {
            return false;
        }
        let cos = beam.dot(facing) / denom;
        cos >= self.config.acceptance_half_angle_deg.to_radians().cos()
    }

    /// Expected 1σ position noise per axis at a point (m): the root mean square of the three principal
    /// standard deviations (range; r·cos(el)·σ across in azimuth; r·σ in elevation), i.e. √(trace Σ / 3),
    /// so a report can compare it with per-axis residuals.
    pub fn noise_at(&self, world_point: &Point3<f64>) -> f64 {
        let p = self.pose.inverse_transform_point(world_point);
        let range = p.coords.norm();
        let cos_el = if range > 0.0 {
            p.x.hypot(p.y) / range
        } else {
            1.0
        };
        let s_r = self.range_sigma(range);
        let s_az = range * cos_el * self.config.angle_sigma_rad;
        let s_el = range * self.config.angle_sigma_rad;
        ((s_r * s_r + s_az * s_az + s_el * s_el) / 3.0).sqrt()
    }
}
