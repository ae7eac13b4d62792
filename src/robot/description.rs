//! A robot from its datasheet: a serial arm described by a standard or modified DH table in TOML
//! (`robots/ur5.toml`), and [`load`], which reads a robot file of either kind (`.toml` or URDF) or one of the
//! robots built into the binaries.
//!
//! Most calibration papers and datasheets give a DH table, a tool offset and perhaps masses, not a URDF. The
//! table becomes the same [`Chain`] a URDF gives, built directly (no URDF text in between, whose `rpy` would
//! round the joint frames): link i's frame is joint i's frame after its motion, as the URDF loader makes it.
//!
//! - **Standard DH** (`convention = "dh"`): `T = Π Rz(θᵢ + offsetᵢ) Tz(dᵢ) Tx(aᵢ) Rx(αᵢ) · tool`. Link i's frame is
//!   DH frame i−1 turned by θᵢ + offsetᵢ and moved dᵢ along the joint axis (as `robots/ur10.urdf` draws it); DH
//!   frame i is link i's frame moved by `Tx(aᵢ) Rx(αᵢ)`, and a row's `com` and `inertia` are given in DH frame i,
//!   as manufacturers publish them. A row may add Hayati's `beta`, a turn about the new y axis after α
//!   (`… Rx(αᵢ) Ry(βᵢ)`), which holds nearly parallel axes exactly ([`super::dh`]); `calibrate export` writes it
//!   for a calibrated UR arm.
//! - **Modified DH** (Craig, `convention = "modified-dh"`): `T = Π Rx(αᵢ₋₁) Tx(aᵢ₋₁) Rz(θᵢ + offsetᵢ) Tz(dᵢ) · tool`;
//!   row i holds `a` = aᵢ₋₁ and `alpha` = αᵢ₋₁ of the link before it. Link i's frame is DH frame i, in which the
//!   row's `com` and `inertia` are given.
//!
//! Every joint is revolute (a datasheet table with a prismatic joint is rare enough to write as URDF). The table
//! has no collision geometry: campaigns of such a robot check no self-collision (say so in a URDF if needed).

use std::path::Path;

use nalgebra::{Isometry3, Matrix3, Point3, Translation3, Unit, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use super::chain::{Body, Chain, Inertial, Joint, JointKind};
use super::dh::DhChain;
use super::kinematics::{Frames, forward_kinematics};
use super::plausible::{self, MAX_MASS_KG, bounded, length, non_negative};
use crate::error::{Error, Result};

/// The robots built into the binaries, by file name: the default robot and the examples of `robots/`, so that
/// `--robot robots/iiwa7.urdf` (the default) works from any directory.
const BUILT_IN: [(&str, &str); 4] = [
    ("iiwa7.urdf", include_str!("../../robots/iiwa7.urdf")),
    ("ur10.urdf", include_str!("../../robots/ur10.urdf")),
    ("ur5.urdf", include_str!("../../robots/ur5.urdf")),
    ("ur5.toml", include_str!("../../robots/ur5.toml")),
];

/// The built-in robot a path names when no such file exists: `robots/NAME` or `NAME` for a built-in NAME.
fn built_in(path: &Path) -> Option<&'static str> {
    let name = path.file_name()?.to_str()?;
    let parent = path.parent().map(|p| p.as_os_str().to_str().unwrap_or("?"));
    if !matches!(parent, Some("") | Some("robots") | None) {
        return None;
    }
    BUILT_IN
        .iter()
        .find(|(n, _)| *n == name)
        .map(|(_, text)| *text)
}

/// Reads a robot: a DH description when the file name ends in `.toml`, a URDF otherwise. A path of the form
/// `robots/NAME` that does not exist is read from the copy built into the binary when NAME is one of
/// `robots/`'s files. `flange_link` names the URDF's tool flange (`None`: the chain's last link); a DH
/// description has its flange after `tool` and accepts only `None` or `"flange"`.
pub fn load(path: impl AsRef<Path>, flange_link: Option<&str>) -> Result<Chain> {
    let path = path.as_ref();
    let origin = path.display().to_string();
    let text = read_text(path)?;
    if is_dh_table(path) {
        let chain = from_toml(&text, &origin)?;
        if let Some(name) = flange_link.filter(|n| *n != chain.flange_link) {
            return Err(Error::Urdf {
                origin,
                message: format!(
                    "flange link '{name}': a DH description's flange is '{}' (after `tool`)",
                    chain.flange_link
                ),
            });
        }
        Ok(chain)
    } else {
        super::urdf::load_str(&text, &origin, flange_link)
    }
}

/// The text of a robot file, or of the built-in robot its path names (see [`load`]).
pub fn read_text(path: &Path) -> Result<String> {
    match std::fs::read_to_string(path) {
        Ok(text) => Ok(text),
        Err(e) => match built_in(path) {
            Some(text) if !path.exists() => Ok(text.to_string()),
            _ => Err(Error::Urdf {
                origin: path.display().to_string(),
                message: format!("cannot read: {e}"),
            }),
        },
    }
}

/// Whether [`load`] reads `path` as a DH description (its name ends in `.toml`) rather than a URDF.
pub fn is_dh_table(path: &Path) -> bool {
    path.extension().is_some_and(|e| e == "toml")
}

/// The joint compliances (rad/Nm; joint name and value, base to tip) a robot file carries beside its
/// kinematics — `calibrate export`'s `compliance` fields of a DH table, `<calibench:compliance>` elements of a
/// URDF — or `None` when it carries none. No loader of the kinematics reads them: the chain is the unloaded
/// arm's.
pub fn compliances(path: &Path) -> Result<Option<Vec<(String, f64)>>> {
    let text = read_text(path)?;
    let origin = path.display().to_string();
    if !is_dh_table(path) {
        return super::export::urdf_compliances(&text, &origin);
    }
    let found: Vec<(String, f64)> = parse(&text, &origin)?
        .joints
        .into_iter()
        .filter_map(|r| Some((r.name, r.compliance?)))
        .collect();
    Ok((!found.is_empty()).then_some(found))
}

/// A chain as a standard DH table in TOML (what [`from_toml`] reads back as the same kinematics): its DH form
/// ([`DhChain::from_chain`]), each body's inertial in its DH frame, the limits (a continuous joint's as one turn
/// either way), a `compliance` per joint when given; `header` opens the file as comment lines.
pub fn to_toml(chain: &Chain, compliance: Option<&[f64]>, header: &str) -> Result<String> {
    let n = chain.dof();
    if let Some(j) = chain.joints.iter().find(|j| j.kind != JointKind::Revolute) {
        return Err(Error::Invalid(format!(
            "joint '{}' is prismatic: a DH table here holds revolute joints only; export as URDF",
            j.name
        )));
    }
    let dh = DhChain::from_chain(chain).map_err(|e| {
        Error::Invalid(format!(
            "no exact DH table: {}; export with --format urdf",
            e.detail()
        ))
    })?;
    let far = dh
        .rows
        .iter()
        .position(|r| r.d.abs().max(r.a.abs()) > plausible::MAX_LENGTH_M);
    if let Some(i) = far {
        return Err(Error::Invalid(format!(
            "no usable DH table: row {} needs a length of {:.0} m (nearly parallel joint axes made skew by the \
             calibration); export with --format urdf",
            i + 1,
            dh.rows[i].d.abs().max(dh.rows[i].a.abs())
        )));
    }
    let dh_frames = dh.frames(&vec![0.0; n]);
    let mut fk = Frames::new(chain);
    forward_kinematics(chain, &vec![0.0; n], &mut fk);
    let turn = 2.0 * std::f64::consts::PI;
    let joints = chain
        .joints
        .iter()
        .enumerate()
        .map(|(i, j)| {
            let r = &dh.rows[i];
            let body = chain.bodies[i + 1]
                .inertial
                .transformed(&(dh_frames[i + 1].inverse() * fk.body[i + 1]));
            let m = &body.inertia;
            let massive = body.mass > 0.0;
            JointRow {
                name: j.name.clone(),
                a: r.a,
                alpha: r.alpha,
                d: r.d,
                theta_offset: r.theta_offset,
                beta: (r.beta != 0.0).then_some(r.beta),
                lower: if j.lower.is_finite() { j.lower } else { -turn },
                upper: if j.upper.is_finite() { j.upper } else { turn },
                velocity: j.velocity.is_finite().then_some(j.velocity),
                effort: (j.effort > 0.0).then_some(j.effort),
                mass: massive.then_some(body.mass),
                com: massive.then_some([body.com.x, body.com.y, body.com.z]),
                inertia: massive.then_some([
                    m[(0, 0)],
                    m[(1, 1)],
                    m[(2, 2)],
                    m[(0, 1)],
                    m[(0, 2)],
                    m[(1, 2)],
                ]),
                compliance: compliance.and_then(|c| c.get(i).copied()),
            }
        })
        .collect();
    let frame = |iso: &Isometry3<f64>| {
        let (xyz, rpy) = super::export::xyz_rpy(iso);
        Frame { xyz, rpy }
    };
    let description = Description {
        name: chain.name.clone(),
        convention: DhConvention::Dh,
        angle_unit: AngleUnit::Rad,
        base: frame(&dh.base),
        tool: frame(&dh.tool),
        joints,
    };
    let text = toml::to_string(&description)
        .map_err(|e| Error::Invalid(format!("cannot write the DH table: {e}")))?;
    let comment: String = header.lines().map(|l| format!("# {l}\n")).collect();
    Ok(format!("{comment}{text}"))
}

#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
enum DhConvention {
    Dh,
    ModifiedDh,
}

/// The unit of angles in a file: a DH table's, a tracker export's.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum AngleUnit {
    #[default]
    Rad,
    Deg,
}

impl AngleUnit {
    /// Radians per unit.
    pub fn radians(self) -> f64 {
        match self {
            AngleUnit::Rad => 1.0,
            AngleUnit::Deg => std::f64::consts::PI / 180.0,
        }
    }
}

/// A fixed frame: translation (m) and fixed-axis roll, pitch, yaw (the table's angle unit), as a URDF origin.
#[derive(Clone, Copy, Debug, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
struct Frame {
    #[serde(default)]
    xyz: [f64; 3],
    #[serde(default)]
    rpy: [f64; 3],
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
struct JointRow {
    name: String,
    /// m
    a: f64,
    alpha: f64,
    /// m
    d: f64,
    /// Added to the joint angle: the link turns by q + theta_offset.
    #[serde(default)]
    theta_offset: f64,
    /// Hayati's turn about the new y axis after `alpha` (standard DH only): absent for a standard row.
    #[serde(default)]
    beta: Option<f64>,
    /// Joint limits (the table's angle unit).
    lower: f64,
    upper: f64,
    /// rad/s or deg/s, informative.
    #[serde(default)]
    velocity: Option<f64>,
    /// Nm, informative.
    #[serde(default)]
    effort: Option<f64>,
    /// kg, with `com` (m) and `inertia` (kg m², about the centre of mass: [ixx, iyy, izz, ixy, ixz, iyz]) in DH
    /// frame i.
    #[serde(default)]
    mass: Option<f64>,
    #[serde(default)]
    com: Option<[f64; 3]>,
    #[serde(default)]
    inertia: Option<[f64; 6]>,
    /// rad/Nm: the joint's compliance from an elastic calibration (`calibrate export`). Not kinematics: the
    /// chain is the unloaded arm's; [`compliances`] reads it.
    #[serde(default)]
    compliance: Option<f64>,
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
struct Description {
    name: String,
    convention: DhConvention,
    #[serde(default)]
    angle_unit: AngleUnit,
    /// The arm's base in the robot's base frame (default identity).
    #[serde(default)]
    base: Frame,
    /// The flange in the last DH frame (default identity).
    #[serde(default)]
    tool: Frame,
    joints: Vec<JointRow>,
}

/// The chain a DH description in TOML text gives; `origin` names the text in messages.
pub fn from_toml(text: &str, origin: &str) -> Result<Chain> {
    parse(text, origin)?.chain().map_err(|e| Error::Urdf {
        origin: origin.to_string(),
        message: e.detail(),
    })
}

/// The description in TOML text, its values not yet checked.
fn parse(text: &str, origin: &str) -> Result<Description> {
    let err = |message: String| Error::Urdf {
        origin: origin.to_string(),
        message,
    };
    toml::from_str(text).map_err(|e| {
        let at = e
            .span()
            .map(|s| {
                format!(
                    "line {}: ",
                    text[..s.start.min(text.len())].lines().count().max(1)
                )
            })
            .unwrap_or_default();
        err(format!("{at}{}", e.message().trim().replace('\n', " ")))
    })
}

impl Frame {
    fn pose(&self, unit: f64) -> Isometry3<f64> {
        let [r, p, y] = self.rpy.map(|v| v * unit);
        Isometry3::from_parts(
            Translation3::from(Vector3::from(self.xyz)),
            UnitQuaternion::from_euler_angles(r, p, y),
        )
    }

    fn check(&self, field: &str) -> Result<()> {
        for (k, v) in self.xyz.iter().enumerate() {
            length(&format!("{field}.xyz[{k}]"), *v)?;
        }
        for (k, v) in self.rpy.iter().enumerate() {
            bounded(&format!("{field}.rpy[{k}]"), *v, 1e3, "angle")?;
        }
        Ok(())
    }
}

fn rx(alpha: f64) -> Isometry3<f64> {
    Isometry3::rotation(Vector3::x() * alpha)
}

/// `frame · Ry(beta)`; a standard row (β = 0) is left untouched to the bit.
fn hayati(frame: Isometry3<f64>, beta: f64) -> Isometry3<f64> {
    if beta == 0.0 {
        frame
    } else {
        frame * Isometry3::rotation(Vector3::y() * beta)
    }
}

fn tx(a: f64) -> Isometry3<f64> {
    Isometry3::translation(a, 0.0, 0.0)
}

fn tz(d: f64) -> Isometry3<f64> {
    Isometry3::translation(0.0, 0.0, d)
}

fn rz(theta: f64) -> Isometry3<f64> {
    Isometry3::rotation(Vector3::z() * theta)
}

impl Description {
    fn check(&self) -> Result<()> {
        let invalid = |field: String, m: &str| Error::Invalid(format!("{field}: {m}"));
        if self.name.trim().is_empty() {
            return Err(invalid("name".into(), "must not be empty"));
        }
        if self.joints.is_empty() {
            return Err(invalid(
                "joints".into(),
                "no [[joints]] rows: a robot needs at least one",
            ));
        }
        self.base.check("base")?;
        self.tool.check("tool")?;
        for (i, r) in self.joints.iter().enumerate() {
            let f = |k: &str| format!("joints[{i}].{k}");
            if r.name.trim().is_empty() || self.joints[..i].iter().any(|o| o.name == r.name) {
                return Err(invalid(
                    f("name"),
                    &format!("'{}' is empty or used twice", r.name),
                ));
            }
            length(&f("a"), r.a)?;
            length(&f("d"), r.d)?;
            for (k, v) in [("alpha", r.alpha), ("theta_offset", r.theta_offset)] {
                bounded(&f(k), v, 1e3, "angle")?;
            }
            if let Some(beta) = r.beta {
                bounded(&f("beta"), beta, 1e3, "angle")?;
                if self.convention != DhConvention::Dh {
                    return Err(invalid(
                        f("beta"),
                        "Hayati's beta is a standard-DH field (convention = \"dh\")",
                    ));
                }
            }
            for (k, v) in [("lower", r.lower), ("upper", r.upper)] {
                bounded(&f(k), v, 1e4, "joint limit")?;
            }
            if r.lower >= r.upper {
                return Err(invalid(
                    f("lower"),
                    &format!("{} is not below upper {}", r.lower, r.upper),
                ));
            }
            for (k, v) in [("velocity", r.velocity), ("effort", r.effort)] {
                if let Some(v) = v {
                    non_negative(&f(k), v, 1e6, k)?;
                }
            }
            if let Some(c) = r.compliance {
                non_negative(&f("compliance"), c, 1.0, "compliance in rad/Nm")?;
            }
            match (r.mass, r.com, r.inertia) {
                (None, None, None) => {}
                (Some(m), com, inertia) => {
                    non_negative(&f("mass"), m, MAX_MASS_KG, "mass in kg")?;
                    for (k, v) in com.unwrap_or_default().iter().enumerate() {
                        length(&f(&format!("com[{k}]")), *v)?;
                    }
                    for (k, v) in inertia.unwrap_or_default().iter().enumerate() {
                        bounded(&f(&format!("inertia[{k}]")), *v, 1e6, "inertia in kg m²")?;
                    }
                }
                (None, _, _) => {
                    return Err(invalid(
                        f("mass"),
                        "missing: `com` and `inertia` need a `mass`",
                    ));
                }
            }
        }
        Ok(())
    }

    fn chain(&self) -> Result<Chain> {
        self.check()?;
        let unit = self.angle_unit.radians();
        let n = self.joints.len();
        let mut joints = Vec::with_capacity(n);
        let mut bodies = vec![Body {
            links: vec!["base".into()],
            inertial: Inertial::ZERO,
            colliders: Vec::new(),
        }];
        // The fixed part between the previous link's frame and this joint's frame.
        let mut before = self.base.pose(unit);
        for r in &self.joints {
            let (alpha, offset) = (r.alpha * unit, r.theta_offset * unit);
            let beta = r.beta.unwrap_or(0.0) * unit;
            // Joint frame (= link frame at q = 0) in the previous link's frame, and DH frame i in the link frame.
            let (origin, dh_frame) = match self.convention {
                DhConvention::Dh => (
                    before * tz(r.d) * rz(offset),
                    hayati(tx(r.a) * rx(alpha), beta),
                ),
                DhConvention::ModifiedDh => (
                    before * rx(alpha) * tx(r.a) * tz(r.d) * rz(offset),
                    Isometry3::identity(),
                ),
            };
            joints.push(Joint {
                name: r.name.clone(),
                kind: JointKind::Revolute,
                origin,
                axis: Unit::new_unchecked(Vector3::z()),
                lower: r.lower * unit,
                upper: r.upper * unit,
                effort: r.effort.unwrap_or(0.0),
                velocity: r
                    .velocity
                    .filter(|v| *v > 0.0)
                    .map_or(f64::INFINITY, |v| v * unit),
            });
            let inertial = match r.mass {
                Some(mass) => {
                    let [xx, yy, zz, xy, xz, yz] = r.inertia.unwrap_or_default();
                    Inertial {
                        mass,
                        com: Point3::from(r.com.unwrap_or_default()),
                        inertia: Matrix3::new(xx, xy, xz, xy, yy, yz, xz, yz, zz),
                    }
                    .transformed(&dh_frame)
                }
                None => Inertial::ZERO,
            };
            bodies.push(Body {
                links: vec![format!("{}_link", r.name)],
                inertial,
                colliders: Vec::new(),
            });
            before = match self.convention {
                DhConvention::Dh => dh_frame,
                DhConvention::ModifiedDh => Isometry3::identity(),
            };
        }
        Ok(Chain {
            name: self.name.clone(),
            base: Isometry3::identity(),
            joints,
            bodies,
            flange: before * self.tool.pose(unit),
            flange_link: "flange".into(),
        })
    }
}
