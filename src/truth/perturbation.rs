//! What makes the true robot differ from its nominal model, as magnitudes (from the scenario) and as one
//! sampled draw (written to `campaign.json`, read by nothing but the evaluation).
//!
//! A new error source costs four edits, all here: its magnitude in [`ErrorModel`] (off by default, with its
//! default in the serde attribute only), its check (a line in a table of [`ErrorModel::validate`]), its value
//! in [`Perturbation`] and its draw in `Perturbation::draw` (after every earlier draw).

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};

use super::stiffness::SoftZone;
use super::thermal::ThermalProfile;
use crate::error::{Error, Result};

fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

fn unit_ratio() -> [f64; 2] {
    [1.0, 1.0]
}

fn is_unit_ratio(v: &[f64; 2]) -> bool {
    *v == unit_ratio()
}

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
    // The error sources no method models exactly. Each is off by default (and then left out of
    // `campaign.json`, so a scenario without them gives the files it always gave).
    /// Relative one-sigma scatter of each moving link's true mass about the URDF's.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub link_mass_spread: f64,
    /// One-sigma offset of each moving link's true centre of mass from the URDF's, per axis (m).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub link_com_m: f64,
    /// Cables and dress pack along the arm (kg per metre of link), lumped at the middle of each link.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub cable_kg_per_m: f64,
    /// Strain-wave gear ratio per joint: the wave generator turns `ratio` times per output revolution.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub gear_ratio: Vec<u32>,
    /// Amplitude of the transmission error at `ratio` and at `2·ratio` cycles per output revolution (rad).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub gear_wave_amplitude_rad: f64,
    /// Lost motion: full width of a joint's hysteresis band (rad); the joint lags by half of it behind the
    /// direction it last moved in.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub hysteresis_rad: f64,
    /// Soft zone per joint: the catalogue's torque limits `[T1, T2]` (Nm) of the low-torque stiffness ranges.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub soft_zone_torque_nm: Vec<[f64; 2]>,
    /// `[K1/K3, K2/K3]`: the stiffness below T1 and between T1 and T2 relative to the true stiffness (K3).
    #[serde(default = "unit_ratio", skip_serializing_if = "is_unit_ratio")]
    pub soft_zone_stiffness_ratio: [f64; 2],
    /// Stiffness about the two axes perpendicular to each joint (bearing tilt and link bending), Nm/rad.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub tilt_stiffness_nm_per_rad: Vec<f64>,
    /// Thermal growth of the links over the campaign (a warm-up); none by default.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub thermal: Option<ThermalProfile>,
    /// Damping of each joint's vibration about its transmission, as a fraction of critical damping for the
    /// inertia the joint carries at the campaign posture: only an arm in motion feels it.
    #[serde(
        default = "default_damping_ratio",
        skip_serializing_if = "is_default_damping_ratio"
    )]
    pub damping_ratio: f64,
    /// `[truth.geometry]`: the geometry of one particular arm (what `campaign twin` identified from a pilot
    /// campaign), to which the σ draws of `base_*`, `frame_*` and `joint_zero_rad` add; absent: none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub geometry: Option<KnownGeometry>,
}

/// Explicit geometric errors of the true robot, in the terms of [`Perturbation`]: the base's offset, an offset
/// appended to each joint's origin (in the joint frame), each joint's zero offset (rad).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct KnownGeometry {
    pub base: Offset,
    pub joint_frames: Vec<Offset>,
    pub joint_zero_rad: Vec<f64>,
}

/// The largest known offset a scenario may give (m, rad): a joint frame a few centimetres or degrees off is
/// not an arm's geometric error but a wrong robot description.
const MAX_KNOWN_TRANSLATION_M: f64 = 0.05;
const MAX_KNOWN_ROTATION_RAD: f64 = 0.1;

impl KnownGeometry {
    /// One offset per joint, every value finite and of an arm's size.
    fn validate(&self, dof: usize) -> Result<()> {
        let bad = |m: String| Err(Error::Invalid(m));
        for (name, len) in [
            ("joint_frames", self.joint_frames.len()),
            ("joint_zero_rad", self.joint_zero_rad.len()),
        ] {
            if len != dof {
                return bad(format!(
                    "truth.geometry.{name} has {len} values, the robot has {dof} joints"
                ));
            }
        }
        let offsets = std::iter::once(("base".to_string(), &self.base)).chain(
            self.joint_frames
                .iter()
                .enumerate()
                .map(|(i, o)| (format!("joint_frames[{i}]"), o)),
        );
        for (name, o) in offsets {
            let t = o.translation.iter().fold(0.0f64, |a, v| a.max(v.abs()));
            let r = o.rotation.iter().fold(0.0f64, |a, v| a.max(v.abs()));
            if !(t <= MAX_KNOWN_TRANSLATION_M && r <= MAX_KNOWN_ROTATION_RAD) {
                return bad(format!(
                    "truth.geometry.{name}: {:?} m, {:?} rad must be finite and within \
                     {MAX_KNOWN_TRANSLATION_M} m and {MAX_KNOWN_ROTATION_RAD} rad",
                    o.translation, o.rotation
                ));
            }
        }
        if let Some(z) = self
            .joint_zero_rad
            .iter()
            .find(|z| !z.is_finite() || z.abs() > MAX_KNOWN_ROTATION_RAD)
        {
            return bad(format!(
                "truth.geometry.joint_zero_rad has {z}; each must be finite and within \
                 {MAX_KNOWN_ROTATION_RAD} rad"
            ));
        }
        Ok(())
    }
}

/// The joints' damping ratio when a scenario gives none; its source is in `scenarios/README.md`
/// (`truth.damping_ratio`).
pub const DEFAULT_DAMPING_RATIO: f64 = 0.1;

fn default_damping_ratio() -> f64 {
    DEFAULT_DAMPING_RATIO
}

fn is_default_damping_ratio(v: &f64) -> bool {
    *v == DEFAULT_DAMPING_RATIO
}

/// How the static deflection is computed in a campaign.
#[derive(Clone, Copy, Debug, Default, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub enum DeflectionSolver {
    /// `q = q0 + K⁻¹ τ_g(q)` iterated to 1e-13 rad: microseconds per pose.
    #[default]
    FixedPoint,
    /// The rapier3d multibody stepped to rest: milliseconds per pose, the physics reference.
    Rapier,
}

/// The `[truth]` keys a scenario must give, each at zero. Every other key takes the default its serde attribute
/// above gives it, so [`ErrorModel::stiff_only`] repeats no default.
const REQUIRED_AT_ZERO: &str = "
frame_translation_m = 0.0
frame_rotation_rad = 0.0
joint_zero_rad = 0.0
base_translation_m = 0.0
base_rotation_rad = 0.0
stiffness_nm_per_rad = []
";

impl ErrorModel {
    /// A robot with joint stiffness `stiffness` and no other error: a base to set some errors on.
    pub fn stiff_only(stiffness: Vec<f64>) -> ErrorModel {
        let none: ErrorModel = toml::from_str(REQUIRED_AT_ZERO)
            .expect("REQUIRED_AT_ZERO is a complete [truth] section");
        ErrorModel {
            stiffness_nm_per_rad: stiffness,
            ..none
        }
    }

    /// Checks the magnitudes against a robot with `dof` joints. Most sources need only a line in one of the
    /// tables below (a magnitude, a relative scatter, a list with one value per joint); one with rules of its
    /// own gets a step of its own.
    pub fn validate(&self, dof: usize) -> Result<()> {
        let bad = |m: String| Err(Error::Invalid(m));
        let magnitudes = [
            ("frame_translation_m", self.frame_translation_m),
            ("frame_rotation_rad", self.frame_rotation_rad),
            ("joint_zero_rad", self.joint_zero_rad),
            ("base_translation_m", self.base_translation_m),
            ("base_rotation_rad", self.base_rotation_rad),
            ("stiffness_spread", self.stiffness_spread),
            ("gear_amplitude_rad", self.gear_amplitude_rad),
            ("repeatability_rad", self.repeatability_rad),
            ("link_mass_spread", self.link_mass_spread),
            ("link_com_m", self.link_com_m),
            ("cable_kg_per_m", self.cable_kg_per_m),
            ("gear_wave_amplitude_rad", self.gear_wave_amplitude_rad),
            ("hysteresis_rad", self.hysteresis_rad),
        ];
        if let Some((name, v)) = magnitudes
            .iter()
            .find(|(_, v)| !(v.is_finite() && *v >= 0.0))
        {
            return bad(format!(
                "truth.{name} = {v} must be finite and non-negative"
            ));
        }
        // Undamped joints would ring for ever after every move; above 2 the joints barely move back.
        if !(self.damping_ratio > 0.0 && self.damping_ratio <= 2.0) {
            return bad(format!(
                "truth.damping_ratio = {} must be in (0, 2] (a fraction of critical damping)",
                self.damping_ratio
            ));
        }
        if self.stiffness_nm_per_rad.len() != dof {
            return bad(format!(
                "truth.stiffness_nm_per_rad has {} values, the robot has {dof} joints",
                self.stiffness_nm_per_rad.len()
            ));
        }
        each_positive("stiffness_nm_per_rad", &self.stiffness_nm_per_rad)?;
        let scatters = [
            ("stiffness_spread", self.stiffness_spread),
            ("link_mass_spread", self.link_mass_spread),
        ];
        if let Some((name, _)) = scatters.iter().find(|(_, v)| *v >= 0.5) {
            return bad(format!(
                "truth.{name} must be below 0.5 (a relative scatter)"
            ));
        }
        let per_joint = [
            ("gear_ratio", self.gear_ratio.len()),
            ("soft_zone_torque_nm", self.soft_zone_torque_nm.len()),
            (
                "tilt_stiffness_nm_per_rad",
                self.tilt_stiffness_nm_per_rad.len(),
            ),
        ];
        if let Some((name, len)) = per_joint.iter().find(|(_, len)| *len != 0 && *len != dof) {
            return bad(format!(
                "truth.{name} has {len} values, the robot has {dof} joints (or leave it out)"
            ));
        }
        self.check_gear_wave()?;
        self.check_soft_zone()?;
        self.check_tilt()?;
        if let Some(t) = &self.thermal {
            t.validate()?;
        }
        if let Some(g) = &self.geometry {
            g.validate(dof)?;
        }
        Ok(())
    }

    /// The strain-wave harmonics need a ratio per joint, each at least 1.
    fn check_gear_wave(&self) -> Result<()> {
        let bad = |m: String| Err(Error::Invalid(m));
        if self.gear_wave_amplitude_rad > 0.0 && self.gear_ratio.is_empty() {
            return bad(
                "truth.gear_wave_amplitude_rad needs truth.gear_ratio (one per joint)".into(),
            );
        }
        if self.gear_ratio.contains(&0) {
            return bad("truth.gear_ratio has 0; every ratio must be at least 1".into());
        }
        Ok(())
    }

    /// The soft zone's torque limits and stiffness ratios must describe a stiffening torsion curve.
    fn check_soft_zone(&self) -> Result<()> {
        let bad = |m: String| Err(Error::Invalid(m));
        if let Some([t1, t2]) = self
            .soft_zone_torque_nm
            .iter()
            .find(|[t1, t2]| !(t1.is_finite() && t2.is_finite() && *t1 >= 0.0 && t1 <= t2))
        {
            return bad(format!(
                "truth.soft_zone_torque_nm has [{t1}, {t2}]; each pair must be 0 ≤ T1 ≤ T2, finite"
            ));
        }
        let [r1, r2] = self.soft_zone_stiffness_ratio;
        if !(r1 > 0.0 && r1 <= r2 && r2 <= 1.0) {
            return bad(format!(
                "truth.soft_zone_stiffness_ratio = [{r1}, {r2}] must satisfy 0 < K1/K3 ≤ K2/K3 ≤ 1"
            ));
        }
        Ok(())
    }

    /// Tilt needs positive stiffness and the fixed-point solver (rapier's joints do not tilt).
    fn check_tilt(&self) -> Result<()> {
        let bad = |m: String| Err(Error::Invalid(m));
        each_positive("tilt_stiffness_nm_per_rad", &self.tilt_stiffness_nm_per_rad)?;
        if !self.tilt_stiffness_nm_per_rad.is_empty() && self.deflection == DeflectionSolver::Rapier
        {
            return bad(
                "truth.tilt_stiffness_nm_per_rad needs deflection = \"fixed-point\": the rapier reference \
                 has no compliance about the axes perpendicular to the joints"
                    .into(),
            );
        }
        Ok(())
    }
}

/// Every stiffness in `truth.{name}` must be a positive number.
fn each_positive(name: &str, stiffness: &[f64]) -> Result<()> {
    match stiffness.iter().find(|k| !(k.is_finite() && **k > 0.0)) {
        Some(k) => Err(Error::Invalid(format!(
            "truth.{name} has {k}; every stiffness must be positive"
        ))),
        None => Ok(()),
    }
}

/// A small rigid offset: translation (m) and rotation vector (rad), `T(t) · exp(r)`.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
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

    /// The offset of both: their translations and rotation vectors added (exact to first order, which is what
    /// offsets of micrometres and microradians need).
    fn plus(&self, other: &Offset) -> Offset {
        let add = |a: [f64; 3], b: [f64; 3]| [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
        Offset {
            translation: add(self.translation, other.translation),
            rotation: add(self.rotation, other.rotation),
        }
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
    /// True mass of each moving link relative to the URDF's (one per joint, the link it moves); empty: as the
    /// URDF.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub link_mass_factor: Vec<f64>,
    /// Offset of each moving link's true centre of mass from the URDF's, in the link frame (m); empty: none.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub link_com_offset: Vec<[f64; 3]>,
    /// Cable load along the links (kg/m).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub cable_kg_per_m: f64,
    /// Full width of each joint's hysteresis band (rad).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub hysteresis_rad: f64,
    /// Load-dependent torsional stiffness per joint (its K3 is `stiffness`); empty: linear joints.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub soft_zone: Vec<SoftZone>,
    /// Stiffness about the axes perpendicular to each joint (Nm/rad); empty: none.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub tilt_stiffness: Vec<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub thermal: Option<ThermalProfile>,
    /// Damping of the joints' vibration, a fraction of critical ([`ErrorModel::damping_ratio`]).
    #[serde(
        default = "default_damping_ratio",
        skip_serializing_if = "is_default_damping_ratio"
    )]
    pub damping_ratio: f64,
}

impl Perturbation {
    /// Draws every error from `model`; the order of draws is fixed so a seed always gives the same robot.
    pub fn sample(model: &ErrorModel, dof: usize, rng: &mut ChaCha8Rng) -> Result<Perturbation> {
        model.validate(dof)?;
        Ok(Perturbation::draw(model, dof, rng))
    }

    /// A perturbation that changes nothing but the stiffness: the nominal geometry made compliant. It is the
    /// draw of a model without any error magnitude, which never calls the generator.
    pub fn rigid_geometry(stiffness: Vec<f64>) -> Perturbation {
        let dof = stiffness.len();
        let model = ErrorModel::stiff_only(stiffness);
        Perturbation::draw(&model, dof, &mut ChaCha8Rng::seed_from_u64(0))
    }

    /// The draw of a checked `model`: each source's value from its magnitude. A source that draws nothing may
    /// go anywhere; one that draws goes after every earlier draw, so a scenario without it draws the same robot.
    fn draw(model: &ErrorModel, dof: usize, rng: &mut ChaCha8Rng) -> Perturbation {
        let base = Offset::sample(rng, model.base_translation_m, model.base_rotation_rad);
        let joint_frames: Vec<Offset> = (0..dof)
            .map(|_| Offset::sample(rng, model.frame_translation_m, model.frame_rotation_rad))
            .collect();
        let joint_zero: Vec<f64> = (0..dof)
            .map(|_| normal(rng, model.joint_zero_rad))
            .collect();
        let stiffness: Vec<f64> = model
            .stiffness_nm_per_rad
            .iter()
            .map(|k| k * (1.0 + normal(rng, model.stiffness_spread)).max(0.5))
            .collect();
        let mut gear: Vec<Vec<GearHarmonic>> = (0..dof)
            .map(|_| harmonics(&model.gear_orders, model.gear_amplitude_rad, rng))
            .collect();
        // Drawn after everything above, so a scenario without these errors draws the same robot as before.
        let (link_mass_factor, link_com_offset) =
            if model.link_mass_spread > 0.0 || model.link_com_m > 0.0 {
                let c = model.link_com_m;
                (0..dof)
                    .map(|_| {
                        let mass = (1.0 + normal(rng, model.link_mass_spread)).max(0.5);
                        (mass, [normal(rng, c), normal(rng, c), normal(rng, c)])
                    })
                    .unzip()
            } else {
                (Vec::new(), Vec::new())
            };
        if model.gear_wave_amplitude_rad > 0.0 {
            for (gear, &ratio) in gear.iter_mut().zip(&model.gear_ratio) {
                gear.extend(harmonics(
                    &[ratio, 2 * ratio],
                    model.gear_wave_amplitude_rad,
                    rng,
                ));
            }
        }
        let [r1, r2] = model.soft_zone_stiffness_ratio;
        let soft_zone = model
            .soft_zone_torque_nm
            .iter()
            .zip(&stiffness)
            .map(|(&[t1, t2], &k3)| SoftZone {
                t1,
                t2,
                k1: r1 * k3,
                k2: r2 * k3,
                k3,
            })
            .collect();
        // A known geometry draws nothing: the draws above stay those of the same magnitudes without it.
        let (base, joint_frames, joint_zero) = match &model.geometry {
            None => (base, joint_frames, joint_zero),
            Some(known) => (
                known.base.plus(&base),
                known
                    .joint_frames
                    .iter()
                    .zip(&joint_frames)
                    .map(|(k, d)| k.plus(d))
                    .collect(),
                known
                    .joint_zero_rad
                    .iter()
                    .zip(&joint_zero)
                    .map(|(k, d)| k + d)
                    .collect(),
            ),
        };
        Perturbation {
            base,
            joint_frames,
            joint_zero,
            stiffness,
            gear,
            repeatability_rad: model.repeatability_rad,
            link_mass_factor,
            link_com_offset,
            cable_kg_per_m: model.cable_kg_per_m,
            hysteresis_rad: model.hysteresis_rad,
            soft_zone,
            tilt_stiffness: model.tilt_stiffness_nm_per_rad.clone(),
            thermal: model.thermal.clone(),
            damping_ratio: model.damping_ratio,
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

/// One harmonic of amplitude `amplitude` per order, each with a uniform phase (one draw per order, in order).
fn harmonics(orders: &[u32], amplitude: f64, rng: &mut ChaCha8Rng) -> Vec<GearHarmonic> {
    orders
        .iter()
        .map(|&order| GearHarmonic {
            order,
            amplitude,
            phase: rng.random_range(0.0..std::f64::consts::TAU),
        })
        .collect()
}

fn normal(rng: &mut ChaCha8Rng, sigma: f64) -> f64 {
    if sigma == 0.0 {
        return 0.0;
    }
    // sigma was validated finite and non-negative, so the distribution always exists.
    Normal::new(0.0, sigma).map_or(0.0, |d| d.sample(rng))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A known geometry is added to the σ draws, which stay what the same magnitudes draw without it; it is
    /// read from a `[truth.geometry]` table and refused when it does not fit the robot.
    #[test]
    fn a_known_geometry_adds_to_the_draws() {
        let mut model: ErrorModel = toml::from_str(&format!(
            "{REQUIRED_AT_ZERO}\n[geometry]\nbase = {{ translation = [0.001, 0.0, 0.0], rotation = [0.0, 0.0, 0.002] }}\n\
             joint_frames = [{{ translation = [0.0, 1e-4, 0.0], rotation = [3e-4, 0.0, 0.0] }}, \
             {{ translation = [0.0, 0.0, 2e-4], rotation = [0.0, 0.0, 0.0] }}]\njoint_zero_rad = [1e-3, -2e-3]\n"
        ))
        .unwrap();
        model.stiffness_nm_per_rad = vec![1e5; 2];
        model.validate(2).unwrap();
        let known = model.geometry.clone().unwrap();
        let exact = Perturbation::sample(&model, 2, &mut ChaCha8Rng::seed_from_u64(3)).unwrap();
        assert_eq!(exact.base, known.base);
        assert_eq!(exact.joint_frames, known.joint_frames);
        assert_eq!(exact.joint_zero, known.joint_zero_rad);

        model.frame_translation_m = 1e-4;
        model.joint_zero_rad = 1e-3;
        let with = Perturbation::sample(&model, 2, &mut ChaCha8Rng::seed_from_u64(3)).unwrap();
        let without = Perturbation::sample(
            &ErrorModel {
                geometry: None,
                ..model.clone()
            },
            2,
            &mut ChaCha8Rng::seed_from_u64(3),
        )
        .unwrap();
        for j in 0..2 {
            assert_eq!(
                with.joint_frames[j],
                known.joint_frames[j].plus(&without.joint_frames[j])
            );
            assert_eq!(
                with.joint_zero[j],
                known.joint_zero_rad[j] + without.joint_zero[j]
            );
        }
        assert_eq!(with.stiffness, without.stiffness);
        let three = ErrorModel {
            stiffness_nm_per_rad: vec![1e5; 3],
            ..model.clone()
        };
        let e = three.validate(3).unwrap_err().to_string();
        assert!(
            e.contains("truth.geometry.joint_frames has 2 values"),
            "{e}"
        );
        model.geometry.as_mut().unwrap().joint_zero_rad[1] = f64::NAN;
        assert!(
            model
                .validate(2)
                .unwrap_err()
                .to_string()
                .contains("joint_zero_rad")
        );
    }

    #[test]
    fn stiff_only_takes_every_default_from_the_serde_attributes() {
        let m = ErrorModel::stiff_only(vec![1e5; 2]);
        assert_eq!(m.stiffness_nm_per_rad, vec![1e5; 2]);
        assert_eq!(m.deflection, DeflectionSolver::FixedPoint);
        assert_eq!(m.soft_zone_stiffness_ratio, [1.0, 1.0]);
        assert_eq!(m.damping_ratio, DEFAULT_DAMPING_RATIO);
        assert_eq!(m.thermal, None);
        assert!(m.gear_orders.is_empty() && m.gear_ratio.is_empty());
        assert!(m.soft_zone_torque_nm.is_empty() && m.tilt_stiffness_nm_per_rad.is_empty());
        let magnitudes = [
            m.frame_translation_m,
            m.frame_rotation_rad,
            m.joint_zero_rad,
            m.base_translation_m,
            m.base_rotation_rad,
            m.stiffness_spread,
            m.gear_amplitude_rad,
            m.repeatability_rad,
            m.link_mass_spread,
            m.link_com_m,
            m.cable_kg_per_m,
            m.gear_wave_amplitude_rad,
            m.hysteresis_rad,
        ];
        assert!(magnitudes.iter().all(|&v| v == 0.0));
        m.validate(2).unwrap();
    }

    #[test]
    fn rigid_geometry_changes_nothing_but_the_stiffness() {
        let p = Perturbation::rigid_geometry(vec![2e4, 3e4]);
        let expected = Perturbation {
            base: Offset::ZERO,
            joint_frames: vec![Offset::ZERO; 2],
            joint_zero: vec![0.0; 2],
            stiffness: vec![2e4, 3e4],
            gear: vec![Vec::new(); 2],
            repeatability_rad: 0.0,
            link_mass_factor: Vec::new(),
            link_com_offset: Vec::new(),
            cable_kg_per_m: 0.0,
            hysteresis_rad: 0.0,
            soft_zone: Vec::new(),
            tilt_stiffness: Vec::new(),
            thermal: None,
            damping_ratio: DEFAULT_DAMPING_RATIO,
        };
        assert_eq!(p, expected);
    }
}
