//! URDF → [`Chain`]. Any serial URDF with revolute, continuous, prismatic and fixed joints.

use std::collections::HashMap;
use std::path::Path;

use nalgebra::{Isometry3, Matrix3, Point3, Translation3, Unit, UnitQuaternion, Vector3};

use super::chain::{Body, Chain, Collider, Inertial, Joint, JointKind, Shape};
use crate::error::{Error, Result};

/// Reads a URDF file. `flange_link` names the tool flange; `None` takes the chain's last link.
pub fn load_file(path: impl AsRef<Path>, flange_link: Option<&str>) -> Result<Chain> {
    let path = path.as_ref();
    let origin = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|e| Error::Urdf {
        origin: origin.clone(),
        message: format!("cannot read: {e}"),
    })?;
    load_str(&text, &origin, flange_link)
}

/// Parses URDF text; `origin` names it in error messages.
pub fn load_str(xml: &str, origin: &str, flange_link: Option<&str>) -> Result<Chain> {
    let err = |message: String| Error::Urdf {
        origin: origin.to_string(),
        message,
    };
    let robot = urdf_rs::read_from_string(xml)
        .map_err(|e| err(format!("not a valid URDF: {}", first_line(&e.to_string()))))?;
    if robot.links.is_empty() {
        return Err(err("no links".into()));
    }
    check_names(&robot).map_err(err)?;
    let tree = Tree::of(&robot).map_err(err)?;
    let (path_joints, leaf) = serial_path(&robot, &tree).map_err(err)?;
    let flange_name = match flange_link {
        Some(name) => {
            if !tree.link_index.contains_key(name) {
                return Err(err(format!("flange link '{name}' does not exist")));
            }
            name.to_string()
        }
        None => robot.links[leaf].name.clone(),
    };
    let Assembled {
        joints,
        bodies,
        flange,
    } = assemble(&robot, &tree, &path_joints, &flange_name).map_err(err)?;
    let Some(flange) = flange else {
        return Err(err(format!(
            "flange link '{flange_name}' is not on the chain"
        )));
    };
    if joints.is_empty() {
        return Err(err("no movable joint".into()));
    }
    Ok(Chain {
        name: robot.name.clone(),
        base: Isometry3::identity(),
        joints,
        bodies,
        flange,
        flange_link: flange_name,
    })
}

/// One name, one thing: a data column is matched to a joint by its name, so a repeated name would drive
/// two joints from one column (issue 14: 81 mm of error, and no complaint). Mimic joints are refused for the
/// same reason.
fn check_names(robot: &urdf_rs::Robot) -> std::result::Result<(), String> {
    for (what, names) in [
        (
            "link",
            robot
                .links
                .iter()
                .map(|l| l.name.as_str())
                .collect::<Vec<_>>(),
        ),
        (
            "joint",
            robot.joints.iter().map(|j| j.name.as_str()).collect(),
        ),
    ] {
        for (i, name) in names.iter().enumerate() {
            if names[..i].contains(name) {
                return Err(format!(
                    "two {what}s are named '{name}'; names must be unique"
                ));
            }
        }
    }
    if let Some(j) = robot.joints.iter().find(|j| j.mimic.is_some()) {
        let leader = j.mimic.as_ref().map_or("", |m| m.joint.as_str());
        return Err(format!(
            "joint '{}' mimics '{leader}': mimic joints are not supported (every joint is read from its own \
             column; model a coupled joint as fixed or give it its own column)",
            j.name
        ));
    }
    Ok(())
}

/// How the URDF's joints connect its links: each link's index by name, the joints leaving each link, and the
/// one root link.
struct Tree<'a> {
    link_index: HashMap<&'a str, usize>,
    child_joints: Vec<Vec<usize>>,
    root: usize,
}

impl<'a> Tree<'a> {
    /// The tree of `robot`, refused when a joint names a missing link, a link has two parents, or there is not
    /// exactly one root.
    fn of(robot: &'a urdf_rs::Robot) -> std::result::Result<Tree<'a>, String> {
        let link_index: HashMap<&str, usize> = robot
            .links
            .iter()
            .enumerate()
            .map(|(i, l)| (l.name.as_str(), i))
            .collect();
        let mut parent_joint: Vec<Option<usize>> = vec![None; robot.links.len()];
        let mut child_joints: Vec<Vec<usize>> = vec![Vec::new(); robot.links.len()];
        for (ji, j) in robot.joints.iter().enumerate() {
            let parent = *link_index.get(j.parent.link.as_str()).ok_or_else(|| {
                format!(
                    "joint '{}' names parent link '{}', which does not exist",
                    j.name, j.parent.link
                )
            })?;
            let child = *link_index.get(j.child.link.as_str()).ok_or_else(|| {
                format!(
                    "joint '{}' names child link '{}', which does not exist",
                    j.name, j.child.link
                )
            })?;
            if let Some(other) = parent_joint[child] {
                return Err(format!(
                    "link '{}' is the child of two joints ('{}' and '{}'): a closed loop, not a serial chain",
                    j.child.link, robot.joints[other].name, j.name
                ));
            }
            parent_joint[child] = Some(ji);
            child_joints[parent].push(ji);
        }
        let roots: Vec<usize> = (0..robot.links.len())
            .filter(|&i| parent_joint[i].is_none())
            .collect();
        let root = match roots.as_slice() {
            [r] => *r,
            [] => return Err("every link has a parent: the joints form a loop".into()),
            many => {
                let names: Vec<&str> = many.iter().map(|&i| robot.links[i].name.as_str()).collect();
                return Err(format!(
                    "several root links ({}): not one connected chain",
                    names.join(", ")
                ));
            }
        };
        Ok(Tree {
            link_index,
            child_joints,
            root,
        })
    }
}

/// The joints from the root to the leaf, in order, and the leaf link. Walks root → leaf, refusing branches: a
/// calibration chain has one tool.
fn serial_path(
    robot: &urdf_rs::Robot,
    tree: &Tree,
) -> std::result::Result<(Vec<usize>, usize), String> {
    let mut path_joints = Vec::new();
    let mut link = tree.root;
    let mut visited = vec![false; robot.links.len()];
    loop {
        if visited[link] {
            return Err("the joints form a loop".into());
        }
        visited[link] = true;
        match tree.child_joints[link].as_slice() {
            [] => break,
            [j] => {
                path_joints.push(*j);
                link = tree.link_index[robot.joints[*j].child.link.as_str()];
            }
            many => {
                let names: Vec<&str> = many
                    .iter()
                    .map(|&j| robot.joints[j].name.as_str())
                    .collect();
                return Err(format!(
                    "link '{}' branches into joints {}: only serial chains are supported",
                    robot.links[link].name,
                    names.join(", ")
                ));
            }
        }
    }
    if let Some(unvisited) = visited.iter().position(|v| !v) {
        return Err(format!(
            "link '{}' is not on the chain from the root: the joints form a loop",
            robot.links[unvisited].name
        ));
    }
    Ok((path_joints, link))
}

/// The chain's movable joints and rigid bodies along a path, up to the flange link.
struct Assembled {
    joints: Vec<Joint>,
    bodies: Vec<Body>,
    /// The flange's pose in its body; `None` when the flange link is not on the path.
    flange: Option<Isometry3<f64>>,
}

/// The chain along `path_joints` up to the flange link: fixed joints merge their child link into the body before
/// them.
fn assemble(
    robot: &urdf_rs::Robot,
    tree: &Tree,
    path_joints: &[usize],
    flange_name: &str,
) -> std::result::Result<Assembled, String> {
    let mut joints = Vec::new();
    let mut bodies = vec![empty_body()];
    // Pose of the current URDF link in the frame of the body it is merged into.
    let mut in_body = Isometry3::identity();
    let mut flange = None;
    let mut current = tree.root;
    attach(&mut bodies, &robot.links[current], &in_body)?;
    if robot.links[current].name == flange_name {
        flange = Some(in_body);
    }
    for &ji in path_joints {
        if flange.is_some() {
            break;
        }
        let j = &robot.joints[ji];
        let origin = pose_of(&j.origin).map_err(|m| format!("joint '{}': {m}", j.name))?;
        current = tree.link_index[j.child.link.as_str()];
        match joint_kind(j)? {
            None => in_body *= origin,
            Some(kind) => {
                joints.push(movable_joint(j, kind, in_body * origin)?);
                bodies.push(empty_body());
                in_body = Isometry3::identity();
            }
        }
        attach(&mut bodies, &robot.links[current], &in_body)?;
        if robot.links[current].name == flange_name {
            flange = Some(in_body);
        }
    }
    Ok(Assembled {
        joints,
        bodies,
        flange,
    })
}

fn empty_body() -> Body {
    Body {
        links: Vec::new(),
        inertial: Inertial::ZERO,
        colliders: Vec::new(),
    }
}

/// Merges `link`, at `pose` in the last body's frame, into the last body: its name, inertial and colliders.
fn attach(
    bodies: &mut [Body],
    link: &urdf_rs::Link,
    pose: &Isometry3<f64>,
) -> std::result::Result<(), String> {
    let body = bodies.last_mut().expect("bodies start non-empty");
    body.links.push(link.name.clone());
    let inertial = link_inertial(link).map_err(|m| format!("link '{}': {m}", link.name))?;
    body.inertial = body.inertial.combined(&inertial.transformed(pose));
    for c in &link.collision {
        let local = pose_of(&c.origin).map_err(|m| format!("link '{}': {m}", link.name))?;
        if let Some(shape) =
            shape_of(&c.geometry).map_err(|m| format!("link '{}': {m}", link.name))?
        {
            body.colliders.push(Collider {
                origin: pose * local,
                shape,
                link: link.name.clone(),
            });
        }
    }
    Ok(())
}

/// The kind of a URDF joint: `None` for a fixed one; refused for the types a serial chain does not hold.
fn joint_kind(j: &urdf_rs::Joint) -> std::result::Result<Option<JointKind>, String> {
    match j.joint_type {
        urdf_rs::JointType::Fixed => Ok(None),
        urdf_rs::JointType::Revolute | urdf_rs::JointType::Continuous => {
            Ok(Some(JointKind::Revolute))
        }
        urdf_rs::JointType::Prismatic => Ok(Some(JointKind::Prismatic)),
        ref other => Err(format!(
            "joint '{}' has type {other:?}; only revolute, continuous, prismatic and fixed are supported",
            j.name
        )),
    }
}

/// The chain joint of the movable URDF joint `j` of `kind`, at `origin` in its parent body's frame, with its axis
/// and limits checked.
fn movable_joint(
    j: &urdf_rs::Joint,
    kind: JointKind,
    origin: Isometry3<f64>,
) -> std::result::Result<Joint, String> {
    let axis = Vector3::from(j.axis.xyz.0);
    if !axis.iter().all(|v| v.is_finite()) || axis.norm() < 1e-9 {
        return Err(format!("joint '{}' has a zero or invalid axis", j.name));
    }
    let (lower, upper) = match j.joint_type {
        urdf_rs::JointType::Continuous => (f64::NEG_INFINITY, f64::INFINITY),
        _ => (j.limit.lower, j.limit.upper),
    };
    // urdf-rs reads a missing `<limit>` as [0, 0]: a joint that cannot move, never meant.
    if j.joint_type != urdf_rs::JointType::Continuous && lower == 0.0 && upper == 0.0 {
        return Err(format!(
            "joint '{}' has no <limit> (or limits [0, 0]): a {} joint needs lower and upper \
             limits (an unlimited revolute joint is type=\"continuous\")",
            j.name,
            if kind == JointKind::Prismatic {
                "prismatic"
            } else {
                "revolute"
            }
        ));
    }
    if lower.is_nan() || upper.is_nan() || lower > upper {
        return Err(format!("joint '{}' has limits [{lower}, {upper}]", j.name));
    }
    Ok(Joint {
        name: j.name.clone(),
        kind,
        origin,
        axis: Unit::new_normalize(axis),
        lower,
        upper,
        effort: j.limit.effort,
        velocity: if j.limit.velocity > 0.0 && j.limit.velocity.is_finite() {
            j.limit.velocity
        } else {
            f64::INFINITY
        },
    })
}

pub(super) fn first_line(s: &str) -> &str {
    s.lines().next().unwrap_or(s)
}

fn finite3(v: &[f64; 3], what: &str) -> std::result::Result<(), String> {
    if v.iter().all(|x| x.is_finite()) {
        Ok(())
    } else {
        Err(format!("{what} {v:?} is not finite"))
    }
}

pub(super) fn pose_of(p: &urdf_rs::Pose) -> std::result::Result<Isometry3<f64>, String> {
    finite3(&p.xyz.0, "origin xyz")?;
    finite3(&p.rpy.0, "origin rpy")?;
    let [x, y, z] = p.xyz.0;
    let [r, pi, ya] = p.rpy.0;
    // URDF rpy is fixed-axis X, then Y, then Z: R = Rz(yaw) Ry(pitch) Rx(roll), as nalgebra's euler angles.
    Ok(Isometry3::from_parts(
        Translation3::new(x, y, z),
        UnitQuaternion::from_euler_angles(r, pi, ya),
    ))
}

fn link_inertial(link: &urdf_rs::Link) -> std::result::Result<Inertial, String> {
    let i = &link.inertial;
    let m = i.mass.value;
    let t = &i.inertia;
    let vals = [m, t.ixx, t.ixy, t.ixz, t.iyy, t.iyz, t.izz];
    if vals.iter().any(|v| !v.is_finite()) || m < 0.0 {
        return Err(format!(
            "inertial has a negative or non-finite value: {vals:?}"
        ));
    }
    let frame = pose_of(&i.origin)?;
    let tensor = Matrix3::new(
        t.ixx, t.ixy, t.ixz, t.ixy, t.iyy, t.iyz, t.ixz, t.iyz, t.izz,
    );
    Ok(Inertial {
        mass: m,
        com: Point3::origin(),
        inertia: tensor,
    }
    .transformed(&frame))
}

/// `None` for meshes: the harness uses primitives only (see `robots/`); a mesh collision is skipped.
fn shape_of(g: &urdf_rs::Geometry) -> std::result::Result<Option<Shape>, String> {
    let positive = |v: f64, what: &str| {
        if v.is_finite() && v > 0.0 {
            Ok(v)
        } else {
            Err(format!("collision {what} {v} must be positive"))
        }
    };
    Ok(match g {
        urdf_rs::Geometry::Box { size } => {
            let s = size.0;
            Some(Shape::Cuboid {
                half_extents: [
                    positive(s[0], "box size")? / 2.0,
                    positive(s[1], "box size")? / 2.0,
                    positive(s[2], "box size")? / 2.0,
                ],
            })
        }
        urdf_rs::Geometry::Cylinder { radius, length } => Some(Shape::Cylinder {
            radius: positive(*radius, "radius")?,
            length: positive(*length, "length")?,
        }),
        urdf_rs::Geometry::Capsule { radius, length } => Some(Shape::Capsule {
            radius: positive(*radius, "radius")?,
            length: positive(*length, "length")?,
        }),
        urdf_rs::Geometry::Sphere { radius } => Some(Shape::Sphere {
            radius: positive(*radius, "radius")?,
        }),
        urdf_rs::Geometry::Mesh { .. } => None,
    })
}

/// Writes a chain back as URDF text, one link per body with its merged inertial and a payload folded into
/// the last body. The physics reference builds its multibody from this, so it sees exactly the geometry
/// and masses of the chain (perturbed or not). Colliders are left out: the physics needs mass, not contact.
///
/// The text describes the chain in its own base frame: `chain.base` is not written, because URDF loaders
/// (rapier's among them) drop a fixed joint from an empty root link. A caller that needs the base pose
/// expresses gravity in the base frame instead.
pub fn to_urdf_string(chain: &Chain, payload: &super::chain::Payload) -> Result<String> {
    let body_name = |i: usize| {
        chain.bodies[i]
            .links
            .first()
            .cloned()
            .unwrap_or_else(|| format!("body_{i}"))
    };
    let n = chain.dof();
    let mut links = Vec::new();
    let mut joints = Vec::new();
    for (i, body) in chain.bodies.iter().enumerate() {
        let mut inertial = body.inertial;
        if i == n && payload.mass > 0.0 {
            let load = Inertial {
                mass: payload.mass,
                com: chain.flange * Point3::from(payload.com),
                inertia: Matrix3::zeros(),
            };
            inertial = inertial.combined(&load);
        }
        links.push(urdf_link(body_name(i), &inertial));
        if i > 0 {
            joints.push(urdf_joint(
                &chain.joints[i - 1],
                &body_name(i - 1),
                &body_name(i),
            ));
        }
    }
    let robot = urdf_rs::Robot {
        name: chain.name.clone(),
        version: None,
        links,
        joints,
        materials: Vec::new(),
    };
    urdf_rs::write_to_string(&robot).map_err(|e| Error::Urdf {
        origin: chain.name.clone(),
        message: format!("cannot write: {e}"),
    })
}

fn urdf_pose(iso: &Isometry3<f64>) -> urdf_rs::Pose {
    let (r, p, y) = iso.rotation.euler_angles();
    let t = iso.translation.vector;
    urdf_rs::Pose {
        xyz: urdf_rs::Vec3([t.x, t.y, t.z]),
        rpy: urdf_rs::Vec3([r, p, y]),
    }
}

/// A URDF link of a body: its merged inertial, no geometry.
pub(super) fn urdf_link(name: String, inertial: &Inertial) -> urdf_rs::Link {
    let i = &inertial.inertia;
    urdf_rs::Link {
        name,
        inertial: urdf_rs::Inertial {
            origin: urdf_pose(&Isometry3::translation(
                inertial.com.x,
                inertial.com.y,
                inertial.com.z,
            )),
            mass: urdf_rs::Mass {
                value: inertial.mass,
            },
            inertia: urdf_rs::Inertia {
                ixx: i[(0, 0)],
                ixy: i[(0, 1)],
                ixz: i[(0, 2)],
                iyy: i[(1, 1)],
                iyz: i[(1, 2)],
                izz: i[(2, 2)],
            },
        },
        visual: Vec::new(),
        collision: Vec::new(),
    }
}

/// The URDF joint of chain joint `j` between the links `parent` and `child`: a revolute joint without finite
/// limits is written as continuous, an unlimited velocity as 1 rad/s.
fn urdf_joint(j: &Joint, parent: &str, child: &str) -> urdf_rs::Joint {
    let (joint_type, lower, upper) = match (j.kind, j.lower.is_finite() && j.upper.is_finite()) {
        (JointKind::Prismatic, _) => (urdf_rs::JointType::Prismatic, j.lower, j.upper),
        (JointKind::Revolute, true) => (urdf_rs::JointType::Revolute, j.lower, j.upper),
        (JointKind::Revolute, false) => (urdf_rs::JointType::Continuous, 0.0, 0.0),
    };
    let axis = j.axis.into_inner();
    urdf_rs::Joint {
        name: j.name.clone(),
        joint_type,
        origin: urdf_pose(&j.origin),
        parent: urdf_rs::LinkName {
            link: parent.to_string(),
        },
        child: urdf_rs::LinkName {
            link: child.to_string(),
        },
        axis: urdf_rs::Axis {
            xyz: urdf_rs::Vec3([axis.x, axis.y, axis.z]),
        },
        limit: urdf_rs::JointLimit {
            lower,
            upper,
            effort: j.effort,
            velocity: if j.velocity.is_finite() {
                j.velocity
            } else {
                1.0
            },
            ..Default::default()
        },
        calibration: None,
        dynamics: None,
        mimic: None,
        safety_controller: None,
    }
}
