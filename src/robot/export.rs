//! A robot description moved by a calibration, written back as a robot file (`calibrate export`): the URDF the
//! robot was given as, with its joint origins corrected, or its DH table ([`super::description::to_toml`]).
//!
//! **URDF.** Everything the description holds that urdf-rs reads (links with their visuals, collisions and
//! inertials, joints with limits and dynamics, materials) is kept; only the movable joints' origins change,
//! each by the offset appended to it (the joint frame's offset, then its zero offset as a turn about its own
//! axis). The base's offset is put into the first movable joint's origin, so the root link stays where the
//! robot is mounted. The probe becomes a fixed link [`PROBE_LINK`] after the chain's last link: the chain's
//! default flange then is the measured point, with the flange's orientation. Elements urdf-rs does not model
//! (`<transmission>`, `<gazebo>`) are not carried over.
//!
//! **Compliances** (an elastic model's) travel as `<calibench:compliance joint="…" rad_per_nm="…"/>` elements of
//! the namespace [`NAMESPACE`] at the end of `<robot>`. A URDF loader does not read them (urdf-rs drops every
//! element of `<robot>` but links, joints and materials; ROS' urdfdom looks elements up by name): loaded as a
//! robot, the file is the unloaded arm. [`urdf_compliances`] reads them.
//!
//! **Angles.** Rotations are written as roll, pitch, yaw by [`rpy`], which stays exact near pitch = ±π/2, where
//! UR arms have joint origins and the textbook extraction loses half the digits.

use nalgebra::{Isometry3, Rotation3, Translation3, UnitQuaternion, Vector3};

use super::chain::{Chain, Inertial};
use super::urdf;
use crate::error::{Error, Result};

/// The fixed link of the probe (the measured point) that an exported URDF ends with.
pub const PROBE_LINK: &str = "calibench_probe";
/// The XML namespace of calibench's elements in an exported URDF.
pub const NAMESPACE: &str = "urn:calibench";

/// A calibration as a robot description's corrections.
#[derive(Clone, Debug)]
pub struct Correction {
    /// The arm's base moved in the robot's base frame (on the left of the chain).
    pub base: Isometry3<f64>,
    /// Per movable joint, appended to its origin (in the joint frame): the frame's offset and its zero offset.
    pub joints: Vec<Isometry3<f64>>,
    /// The probe frame (the measured point, with the flange's orientation) in the flange frame.
    pub probe: Isometry3<f64>,
}

impl Correction {
    /// `chain` corrected: what an exported file loads back as, its flange at the probe.
    pub fn chain(&self, chain: &Chain) -> Chain {
        let mut out = chain.clone();
        out.base = self.base * chain.base;
        for (joint, offset) in out.joints.iter_mut().zip(&self.joints) {
            joint.origin *= offset;
        }
        out.flange *= self.probe;
        out.flange_link = PROBE_LINK.into();
        out
    }
}

/// URDF text `original` (named `origin` in messages), whose chain up to `flange_link` (`None`: its last link) is
/// the one `correction` was found for, with the correction applied and `compliance` (per joint, rad/Nm) added;
/// `header` is put in a comment at the top.
pub fn corrected_urdf(
    original: &str,
    origin: &str,
    flange_link: Option<&str>,
    correction: &Correction,
    compliance: Option<&[f64]>,
    header: &str,
) -> Result<String> {
    let err = |message: String| Error::Urdf {
        origin: origin.to_string(),
        message,
    };
    let chain = urdf::load_str(original, origin, flange_link)?;
    let leaf = urdf::load_str(original, origin, None)?;
    if leaf.dof() != chain.dof() {
        return Err(err(format!(
            "joints move after the flange link '{}': an exported robot ends at its flange",
            chain.flange_link
        )));
    }
    let mut robot = urdf_rs::read_from_string(original).map_err(|e| {
        err(format!(
            "not a valid URDF: {}",
            urdf::first_line(&e.to_string())
        ))
    })?;
    if robot.links.iter().any(|l| l.name == PROBE_LINK) {
        return Err(err(format!(
            "already has a '{PROBE_LINK}' link: it is an exported robot; export from the description \
             `calibrate` was run with"
        )));
    }
    for (i, joint) in chain.joints.iter().enumerate() {
        let written = robot
            .joints
            .iter_mut()
            .find(|j| j.name == joint.name)
            .ok_or_else(|| err(format!("joint '{}' not found", joint.name)))?;
        let before = urdf::pose_of(&written.origin).map_err(|m| err(m.to_string()))?;
        let mut after = before * correction.joints[i];
        if i == 0 {
            // The fixed frames between the robot's base and the first joint's parent link.
            let mount = chain.base * joint.origin * before.inverse();
            after = mount.inverse() * correction.base * mount * after;
        }
        written.origin = pose(&after);
    }
    // Both flanges are poses in the last body; the probe hangs from the leaf link.
    let probe = (chain.flange.inverse() * leaf.flange).inverse() * correction.probe;
    finish(robot, &leaf.flange_link, &probe, &chain, compliance, header).map_err(err)
}

/// A chain (a DH table's, which has no URDF) corrected, as URDF text: one link per body as
/// [`urdf::to_urdf_string`] writes it (kinematics and inertials, no geometry), the base folded into the first
/// joint's origin, the probe link after the last body.
pub fn chain_urdf(
    chain: &Chain,
    correction: &Correction,
    compliance: Option<&[f64]>,
    header: &str,
) -> Result<String> {
    let mut folded = correction.chain(chain);
    folded.joints[0].origin = folded.base * folded.joints[0].origin;
    folded.base = Isometry3::identity();
    let probe = folded.flange;
    let text = urdf::to_urdf_string(&folded, &super::chain::Payload::NONE)?;
    let err = |message: String| Error::Urdf {
        origin: chain.name.clone(),
        message,
    };
    let robot = urdf_rs::read_from_string(&text).map_err(|e| err(e.to_string()))?;
    let last = robot
        .links
        .last()
        .map(|l| l.name.clone())
        .ok_or_else(|| err("no links".into()))?;
    finish(robot, &last, &probe, chain, compliance, header).map_err(err)
}

/// `robot` with the probe link at `probe` after `leaf`, the namespace, the compliances of `chain`'s joints and
/// the header comment, as text.
fn finish(
    mut robot: urdf_rs::Robot,
    leaf: &str,
    probe: &Isometry3<f64>,
    chain: &Chain,
    compliance: Option<&[f64]>,
    header: &str,
) -> std::result::Result<String, String> {
    robot
        .links
        .push(urdf::urdf_link(PROBE_LINK.into(), &Inertial::ZERO));
    robot.joints.push(urdf_rs::Joint {
        name: format!("{PROBE_LINK}_joint"),
        joint_type: urdf_rs::JointType::Fixed,
        origin: pose(probe),
        parent: urdf_rs::LinkName {
            link: leaf.to_string(),
        },
        child: urdf_rs::LinkName {
            link: PROBE_LINK.into(),
        },
        axis: urdf_rs::Axis::default(),
        limit: urdf_rs::JointLimit::default(),
        calibration: None,
        dynamics: None,
        mimic: None,
        safety_controller: None,
    });
    let text = urdf_rs::write_to_string(&robot).map_err(|e| format!("cannot write: {e}"))?;
    let text = text.replacen(
        "<robot ",
        &format!("<robot xmlns:calibench=\"{NAMESPACE}\" "),
        1,
    );
    let Some(end) = text.rfind("</robot>") else {
        return Err("urdf-rs wrote no </robot>".into());
    };
    let mut extra = String::new();
    for (joint, c) in chain.joints.iter().zip(compliance.unwrap_or(&[])) {
        extra.push_str(&format!(
            "  <calibench:compliance joint=\"{}\" rad_per_nm=\"{c:e}\"/>\n",
            joint.name
        ));
    }
    let comment = header.replace("--", "- -");
    Ok(format!(
        "<?xml version=\"1.0\"?>\n<!--\n{comment}-->\n{}{extra}{}\n",
        &text[..end],
        &text[end..]
    ))
}

/// The `<calibench:compliance>` elements of URDF text, (joint, rad/Nm) in the file's order; `None` without any.
pub fn urdf_compliances(text: &str, origin: &str) -> Result<Option<Vec<(String, f64)>>> {
    use xml::reader::{EventReader, XmlEvent};
    let err = |message: String| Error::Urdf {
        origin: origin.to_string(),
        message,
    };
    let mut found = Vec::new();
    for event in EventReader::from_str(text) {
        let event = event.map_err(|e| err(format!("not valid XML: {e}")))?;
        let XmlEvent::StartElement {
            name, attributes, ..
        } = event
        else {
            continue;
        };
        if name.namespace.as_deref() != Some(NAMESPACE) || name.local_name != "compliance" {
            continue;
        }
        let k = found.len();
        let attribute = |key: &str| {
            attributes
                .iter()
                .find(|a| a.name.local_name == key)
                .map(|a| a.value.clone())
                .ok_or_else(|| err(format!("calibench:compliance[{k}]: no `{key}` attribute")))
        };
        let joint = attribute("joint")?;
        let text = attribute("rad_per_nm")?;
        let value: f64 = text.trim().parse().map_err(|_| {
            err(format!(
                "calibench:compliance[{k}] (joint '{joint}'): rad_per_nm {text:?} is not a number"
            ))
        })?;
        if !(0.0..=1.0).contains(&value) {
            return Err(err(format!(
                "calibench:compliance[{k}] (joint '{joint}'): {value} rad/Nm is not a compliance (0 to 1)"
            )));
        }
        found.push((joint, value));
    }
    Ok((!found.is_empty()).then_some(found))
}

/// A pose as a URDF origin.
fn pose(iso: &Isometry3<f64>) -> urdf_rs::Pose {
    let t = iso.translation.vector;
    urdf_rs::Pose {
        xyz: urdf_rs::Vec3([t.x, t.y, t.z]),
        rpy: urdf_rs::Vec3(rpy(&iso.rotation)),
    }
}

/// Fixed-axis roll, pitch, yaw of `r` (`R = Rz(yaw) Ry(pitch) Rx(roll)`), exact to rounding everywhere: the
/// pitch from an `atan2` (not the `asin` that loses half the digits near ±π/2), the roll from what yaw and pitch
/// leave, so that an ill-determined yaw near the singularity is made up for rather than passed on.
pub fn rpy(r: &UnitQuaternion<f64>) -> [f64; 3] {
    let m = r.to_rotation_matrix();
    let m = m.matrix();
    let cos_pitch = m[(0, 0)].hypot(m[(1, 0)]);
    let yaw = if cos_pitch > 1e-12 {
        m[(1, 0)].atan2(m[(0, 0)])
    } else {
        0.0
    };
    let pitch = (-m[(2, 0)]).atan2(cos_pitch);
    let left = Rotation3::from_euler_angles(0.0, pitch, yaw);
    let rest = left.inverse() * r.to_rotation_matrix();
    let roll = rest[(2, 1)].atan2(rest[(1, 1)]);
    [roll, pitch, yaw]
}

/// The pose written as a DH table's `xyz` and `rpy`.
pub fn xyz_rpy(iso: &Isometry3<f64>) -> ([f64; 3], [f64; 3]) {
    let t: Vector3<f64> = iso.translation.vector;
    ([t.x, t.y, t.z], rpy(&iso.rotation))
}

/// A translation as an isometry (the probe's point on the flange).
pub fn at(point: &Vector3<f64>) -> Isometry3<f64> {
    Isometry3::from_parts(Translation3::from(*point), UnitQuaternion::identity())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rotations at and near pitch = ±π/2 come back from their roll, pitch and yaw to rounding.
    #[test]
    fn rpy_is_exact_near_gimbal_lock() {
        for pitch in [
            0.3,
            1.0,
            std::f64::consts::FRAC_PI_2 - 1e-9,
            std::f64::consts::FRAC_PI_2,
        ] {
            for sign in [1.0, -1.0] {
                let r = UnitQuaternion::from_euler_angles(0.2, sign * pitch, -0.7)
                    * UnitQuaternion::from_scaled_axis(Vector3::new(1e-7, -3e-8, 2e-9));
                let [a, b, c] = rpy(&r);
                let back = UnitQuaternion::from_euler_angles(a, b, c);
                assert!(
                    back.angle_to(&r) < 1e-15,
                    "pitch {pitch}: {}",
                    back.angle_to(&r)
                );
            }
        }
    }
}
