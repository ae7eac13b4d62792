//! Physics reference for the static deflection of a compliant serial arm.
//!
//! The arm is loaded from URDF text with `rapier3d-urdf` as one rapier multibody (reduced
//! coordinates, fixed root, no self contacts, the URDF inertials as the only mass). Every
//! movable joint gets a passive implicit spring `τ = -k (q - rest)` and per-DoF damping, and the
//! world is stepped under gravity until the joint coordinates stop moving. The result is the
//! static equilibrium `k (q - rest) = τ_g(q)` that the fast fixed-point solver must reproduce.
//!
//! Rapier works in `f32`: against an f64 Newton solution the settled angles agree to 1e-8–5e-8
//! rad (one or two f32 ulps of the angle); the settle tolerance (1e-7 rad per step, floored at two
//! ulps) is tuned for that. With the default 0.1 s step a pose takes 5–35 steps, about 0.2 ms for
//! a 7-DoF arm (release build).
//!
//! Every movable joint of the URDF must be listed by the caller; it is found by its URDF name
//! even when `rapier3d-urdf` squeezed empty frame links (`world`, `tool0`) and moved the joint
//! onto a representative (`UrdfJoint::source_urdf_joint_index`).
//!
//! Joint limits of the URDF are removed: this is a reference for the elastic sag, and a limit
//! touching near a pose at the edge of the range would silently change the answer.

use std::collections::HashMap;
use std::path::Path;

use rapier3d::prelude::{
    JointAxesMask, MultibodyJointHandle, PhysicsWorld, Real, RigidBodyBuilder, Vector,
};
use rapier3d_urdf::{UrdfLoaderOptions, UrdfMultibodyOptions, UrdfRobot, urdf_rs};

use super::stiffness::SoftZone;
use crate::error::{Error, Result};

/// Index of the URDF joint axis in rapier's 6-DoF joint layout (`AngX`): the loader aligns the
/// joint frame's X axis with the URDF `<axis>` (and [`super::physics_motion`] builds its frames the same way).
pub(super) const ANG_X: usize = 3;

/// How the reference world is stepped to equilibrium.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SettleOptions {
    /// Time step [s]. The springs and the damping are implicit (backward Euler), so the settled
    /// state is the exact static equilibrium whatever the step, and a large step (k·dt² ≫ link
    /// inertia) makes each step nearly one fixed-point iteration `q ← rest + K⁻¹ τ_g(q)`:
    /// 0.1 s settles a 7-DoF arm in about 10–25 steps, 0.02 s needs 50–350. Use a small step only
    /// to look at the transient. Convergence needs k_i well above the gravity stiffness
    /// |∂τ_g/∂q| (true for real arms).
    pub dt: f64,
    /// Give up (with an error) after this many steps.
    pub max_steps: usize,
    /// Settled when no joint moves more than this between steps [rad] (or two f32 ulps of the
    /// angle, if larger: about 2.4e-7 rad for |q| ≥ 1), for `quiet_steps` consecutive steps.
    pub tol_rad: f64,
    /// Viscous damping on every joint [Nm·s/rad].
    pub damping: f64,
    /// Consecutive quiet steps required (guards against a momentary turning point).
    pub quiet_steps: usize,
}

impl Default for SettleOptions {
    fn default() -> Self {
        Self {
            dt: 0.1,
            max_steps: 5000,
            tol_rad: 1e-7,
            damping: 1.0,
            quiet_steps: 3,
        }
    }
}

/// The settled state of one pose.
#[derive(Debug, Clone, PartialEq)]
pub struct Settled {
    /// Joint angles [rad], in the caller's `joint_names` order.
    pub q: Vec<f64>,
    /// Physics steps used.
    pub steps: usize,
}

/// One caller joint: its name and the multibody joint that moves it.
#[derive(Debug, Clone)]
struct JointSlot {
    name: String,
    handle: MultibodyJointHandle,
    stiffness: f64,
}

/// A rapier world holding the compliant arm.
pub struct PhysicsReference {
    world: PhysicsWorld,
    joints: Vec<JointSlot>,
    opts: SettleOptions,
    /// Load-dependent stiffness per joint (empty: the linear springs of `joints`).
    soft_zones: Vec<SoftZone>,
}

impl std::fmt::Debug for PhysicsReference {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PhysicsReference")
            .field("joints", &self.joints)
            .field("opts", &self.opts)
            .finish_non_exhaustive()
    }
}

fn urdf_err(message: impl Into<String>) -> Error {
    Error::Urdf {
        origin: "physics reference".into(),
        message: message.into(),
    }
}

impl PhysicsReference {
    /// Builds the world from URDF text. `joint_names`: the movable joints in chain order (the
    /// caller's order). `stiffness`: one per joint, Nm/rad. Root fixed, no self contacts,
    /// imported mass properties.
    ///
    /// Every movable joint of the arm must be listed (an unlisted one would flop freely and never
    /// settle); only revolute and continuous joints are supported.
    pub fn new(
        urdf_xml: &str,
        joint_names: &[String],
        stiffness: &[f64],
        gravity: [f64; 3],
        opts: SettleOptions,
    ) -> Result<Self> {
        let slot_of_name = check_inputs(joint_names, stiffness, gravity, &opts)?;
        let (mut robot, urdf) = load_urdf(urdf_xml)?;
        let slot_of_robot_joint = match_joints(&mut robot, &urdf, &slot_of_name, joint_names)?;
        let (world, robot_joint_handles) = insert_robot(robot, gravity, opts.dt);
        let joints = joint_slots(
            &robot_joint_handles,
            &slot_of_robot_joint,
            joint_names,
            stiffness,
        )?;
        let mut reference = Self {
            world,
            joints,
            opts,
            soft_zones: Vec::new(),
        };
        reference.fix_root()?;
        reference.check_one_tree()?;
        Ok(reference)
    }

    /// All joints must sit in one multibody; make its root fixed in its coordinates now
    /// (until the first forward kinematics the fixed root counts as 6 free DoFs).
    fn fix_root(&mut self) -> Result<()> {
        let first = self.joints[0].handle;
        let (mb, _) = self
            .world
            .multibody_joints
            .get_mut(first)
            .ok_or_else(|| Error::Physics("multibody of the first joint is gone".into()))?;
        mb.forward_kinematics(&self.world.bodies, true);
        mb.update_rigid_bodies(&mut self.world.bodies, true);
        let ndofs = mb.ndofs();
        if ndofs != self.joints.len() {
            return Err(Error::Physics(format!(
                "the arm's multibody has {ndofs} DoFs, expected {} (one per listed joint; is the \
                 root fixed?)",
                self.joints.len()
            )));
        }
        Ok(())
    }

    /// Every listed joint must be in the first joint's multibody.
    fn check_one_tree(&self) -> Result<()> {
        let first_mb = self.multibody_of(0)?;
        for i in 1..self.joints.len() {
            if self.multibody_of(i)? != first_mb {
                return Err(urdf_err(format!(
                    "joint `{}` is not in the same kinematic tree as `{}`",
                    self.joints[i].name, self.joints[0].name
                )));
            }
        }
        Ok(())
    }

    /// The movable joints, in the caller's order.
    pub fn joint_names(&self) -> Vec<&str> {
        self.joints.iter().map(|j| j.name.as_str()).collect()
    }

    /// Gives every joint the soft zone's torsion curve instead of its linear spring (one per joint). Rapier's
    /// springs are linear, so before every step each joint's spring is set to the line of the curve's range
    /// its current deflection lies in ([`SoftZone::segment`]); at rest the joint sits on the curve.
    pub fn set_soft_zones(&mut self, zones: &[SoftZone]) -> Result<()> {
        if !zones.is_empty() && zones.len() != self.joints.len() {
            return Err(Error::Invalid(format!(
                "physics reference: {} soft zones for {} joints",
                zones.len(),
                self.joints.len()
            )));
        }
        self.soft_zones = zones.to_vec();
        Ok(())
    }

    /// Sets each soft-zone joint's spring to its curve's line at the current angles `q`.
    fn follow_soft_zones(
        &mut self,
        links: &[(usize, usize)],
        rest: &[f64],
        q: &[f64],
    ) -> Result<()> {
        if self.soft_zones.is_empty() {
            return Ok(());
        }
        let (mb, _) = self
            .world
            .multibody_joints
            .get_mut(self.joints[0].handle)
            .ok_or_else(|| Error::Physics("multibody lost".into()))?;
        for (((zone, &(link_id, _)), &r), &qi) in self.soft_zones.iter().zip(links).zip(rest).zip(q)
        {
            let (k, offset) = zone.segment(qi - r);
            let link = mb
                .link_mut(link_id)
                .ok_or_else(|| Error::Physics("multibody link lost".into()))?;
            link.joint
                .set_spring(ANG_X, k as Real, (r + offset) as Real);
        }
        Ok(())
    }

    /// The settle options in use.
    pub fn options(&self) -> &SettleOptions {
        &self.opts
    }

    fn multibody_of(&self, slot: usize) -> Result<rapier3d::prelude::MultibodyIndex> {
        let (mb, link) = self
            .world
            .multibody_joints
            .get(self.joints[slot].handle)
            .ok_or_else(|| Error::Physics(format!("joint `{}` lost", self.joints[slot].name)))?;
        let body = mb
            .link(link)
            .ok_or_else(|| Error::Physics(format!("joint `{}` lost", self.joints[slot].name)))?
            .rigid_body_handle();
        self.world
            .multibody_joints
            .rigid_body_link(body)
            .map(|l| l.multibody)
            .ok_or_else(|| Error::Physics(format!("joint `{}` lost", self.joints[slot].name)))
    }

    /// Offsets of the caller's joints in the multibody's generalized coordinates.
    fn dof_indices(&self) -> Result<Vec<(usize, usize)>> {
        self.joints
            .iter()
            .map(|j| {
                let (mb, link_id) = self
                    .world
                    .multibody_joints
                    .get(j.handle)
                    .ok_or_else(|| Error::Physics(format!("joint `{}` lost", j.name)))?;
                let link = mb
                    .link(link_id)
                    .ok_or_else(|| Error::Physics(format!("joint `{}` lost", j.name)))?;
                Ok((link_id, link.assembly_id()))
            })
            .collect()
    }

    fn read_q(&self, links: &[(usize, usize)], out: &mut [f64]) -> Result<()> {
        let (mb, _) = self
            .world
            .multibody_joints
            .get(self.joints[0].handle)
            .ok_or_else(|| Error::Physics("multibody lost".into()))?;
        for (o, &(link_id, _)) in out.iter_mut().zip(links) {
            let link = mb
                .link(link_id)
                .ok_or_else(|| Error::Physics("multibody link lost".into()))?;
            *o = f64::from(link.joint().coords()[ANG_X]);
        }
        Ok(())
    }

    /// Sets every joint spring's rest angle, starts the joints AT rest with zero velocity, steps
    /// to equilibrium. Returns the settled joint angles (rad) in `joint_names` order, and the
    /// number of steps used.
    pub fn settle(&mut self, rest: &[f64]) -> Result<Settled> {
        let n = self.joints.len();
        if rest.len() != n {
            return Err(Error::Invalid(format!(
                "physics reference: {} rest angles for {n} joints",
                rest.len()
            )));
        }
        if let Some(i) = rest.iter().position(|r| !r.is_finite()) {
            return Err(Error::Invalid(format!(
                "physics reference: rest angle of `{}` is {}",
                self.joints[i].name, rest[i]
            )));
        }
        let links = self.dof_indices()?;
        {
            let world = &mut self.world;
            let (mb, _) = world
                .multibody_joints
                .get_mut(self.joints[0].handle)
                .ok_or_else(|| Error::Physics("multibody lost".into()))?;
            let mut disp = vec![Real::default(); mb.ndofs()];
            for ((slot, &(link_id, dof)), &r) in self.joints.iter().zip(&links).zip(rest) {
                let link = mb
                    .link_mut(link_id)
                    .ok_or_else(|| Error::Physics("multibody link lost".into()))?;
                link.joint
                    .set_spring(ANG_X, slot.stiffness as Real, r as Real);
                disp[dof] = r as Real - link.joint.coords()[ANG_X];
            }
            mb.apply_displacements(&disp);
            mb.generalized_velocity_mut().fill(0.0);
            mb.damping_mut().fill(self.opts.damping as Real);
            mb.forward_kinematics(&world.bodies, false);
            mb.update_rigid_bodies(&mut world.bodies, true);
            let bodies: Vec<_> = mb.links().map(|l| l.rigid_body_handle()).collect();
            for h in bodies {
                if let Some(rb) = world.bodies.get_mut(h) {
                    rb.set_linvel(Vector::ZERO, false);
                    rb.set_angvel(Vector::ZERO, false);
                }
            }
        }

        let mut q = vec![0.0; n];
        let mut prev = vec![0.0; n];
        self.read_q(&links, &mut prev)?;
        let mut quiet = 0usize;
        let mut last_change = f64::INFINITY;
        for step in 1..=self.opts.max_steps {
            self.follow_soft_zones(&links, rest, &prev)?;
            self.world.step();
            self.read_q(&links, &mut q)?;
            if q.iter().any(|v| !v.is_finite()) {
                return Err(Error::Physics(format!(
                    "joint angles became non-finite after {step} steps (dt {} too large?)",
                    self.opts.dt
                )));
            }
            // change relative to the tolerance, floored at 2 f32 ulps of the angle (a
            // one-ulp jitter at |q| ≥ 1 already exceeds 1e-7)
            let (mut worst, mut quiet_now) = (0.0f64, true);
            for (a, b) in q.iter().zip(&prev) {
                let change = (a - b).abs();
                let x = a.abs() as f32;
                let tol = self.opts.tol_rad.max(2.0 * f64::from(x.next_up() - x));
                worst = worst.max(change);
                quiet_now &= change <= tol;
            }
            last_change = worst;
            if quiet_now {
                quiet += 1;
                if quiet >= self.opts.quiet_steps.max(1) {
                    return Ok(Settled { q, steps: step });
                }
            } else {
                quiet = 0;
            }
            std::mem::swap(&mut q, &mut prev);
        }
        Err(Error::Physics(format!(
            "not settled after {} steps of {} s: last per-step joint change {last_change:.3e} rad \
             (tolerance {:.1e})",
            self.opts.max_steps, self.opts.dt, self.opts.tol_rad
        )))
    }
}

/// Checks the caller's joints, stiffness, gravity and options; returns each joint name's slot (its index in
/// `joint_names`).
fn check_inputs<'a>(
    joint_names: &'a [String],
    stiffness: &[f64],
    gravity: [f64; 3],
    opts: &SettleOptions,
) -> Result<HashMap<&'a str, usize>> {
    if joint_names.is_empty() {
        return Err(Error::Invalid("physics reference: no joints given".into()));
    }
    if stiffness.len() != joint_names.len() {
        return Err(Error::Invalid(format!(
            "physics reference: {} stiffness values for {} joints",
            stiffness.len(),
            joint_names.len()
        )));
    }
    for (name, &k) in joint_names.iter().zip(stiffness) {
        if !(k.is_finite() && k > 0.0) {
            return Err(Error::Invalid(format!(
                "physics reference: stiffness of joint `{name}` is {k}, must be finite and > 0"
            )));
        }
    }
    if gravity.iter().any(|g| !g.is_finite()) {
        return Err(Error::Invalid(format!(
            "physics reference: gravity {gravity:?} is not finite"
        )));
    }
    let positive = |x: f64| x.is_finite() && x > 0.0;
    let options_ok = positive(opts.dt)
        && positive(opts.tol_rad)
        && opts.damping.is_finite()
        && opts.damping >= 0.0
        && opts.max_steps > 0;
    if !options_ok {
        return Err(Error::Invalid(format!(
            "physics reference: bad settle options {opts:?}"
        )));
    }
    let mut seen = HashMap::new();
    for (i, name) in joint_names.iter().enumerate() {
        if seen.insert(name.as_str(), i).is_some() {
            return Err(Error::Invalid(format!(
                "physics reference: joint `{name}` listed twice"
            )));
        }
    }
    Ok(seen)
}

/// The rapier robot of the URDF text (dynamic bodies that never sleep, the URDF's inertials, no colliders, the
/// root fixed) and the parsed URDF.
fn load_urdf(urdf_xml: &str) -> Result<(UrdfRobot, urdf_rs::Robot)> {
    let loader = UrdfLoaderOptions {
        create_colliders_from_collision_shapes: false,
        create_colliders_from_visual_shapes: false,
        apply_imported_mass_props: true,
        make_roots_fixed: true,
        rigid_body_blueprint: RigidBodyBuilder::dynamic().can_sleep(false),
        ..UrdfLoaderOptions::default()
    };
    // `from_str` can panic inside urdf-rs/the loader on odd input; keep the promise of
    // never panicking.
    let parsed = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        UrdfRobot::from_str(urdf_xml, loader, Path::new("."))
    }))
    .map_err(|_| urdf_err("the URDF loader panicked on this input"))?;
    parsed.map_err(|e| urdf_err(format!("{e:#}")))
}

/// Which UrdfRobot joint carries each caller joint (its slot; `None`: a fixed joint). After squeezing empty
/// fixed links a moving joint may live on a representative joint: its source index names the URDF joint it
/// took its type and axis from. Removes the limits of the caller's joints.
fn match_joints(
    robot: &mut UrdfRobot,
    urdf: &urdf_rs::Robot,
    slot_of_name: &HashMap<&str, usize>,
    joint_names: &[String],
) -> Result<Vec<Option<usize>>> {
    let mut slot_of_robot_joint: Vec<Option<usize>> = vec![None; robot.joints.len()];
    let mut found = vec![false; joint_names.len()];
    for (rj, joint) in robot.joints.iter_mut().enumerate() {
        let src = &urdf.joints[joint.source_urdf_joint_index()];
        let movable = !matches!(src.joint_type, urdf_rs::JointType::Fixed);
        match slot_of_name.get(src.name.as_str()) {
            Some(&slot) => {
                if !matches!(
                    src.joint_type,
                    urdf_rs::JointType::Revolute | urdf_rs::JointType::Continuous
                ) {
                    return Err(urdf_err(format!(
                        "joint `{}` is {:?}; only revolute/continuous joints can be springs",
                        src.name, src.joint_type
                    )));
                }
                slot_of_robot_joint[rj] = Some(slot);
                found[slot] = true;
                // The sag reference ignores joint limits.
                joint.joint.limit_axes = JointAxesMask::empty();
            }
            None if movable => {
                return Err(urdf_err(format!(
                    "movable joint `{}` is not in the joint list {joint_names:?}",
                    src.name
                )));
            }
            None => {}
        }
    }
    if let Some(missing) = found.iter().position(|f| !f) {
        let movable: Vec<&str> = urdf
            .joints
            .iter()
            .filter(|j| !matches!(j.joint_type, urdf_rs::JointType::Fixed))
            .map(|j| j.name.as_str())
            .collect();
        return Err(urdf_err(format!(
            "joint `{}` is not a movable joint of the URDF (movable joints: {movable:?})",
            joint_names[missing]
        )));
    }
    Ok(slot_of_robot_joint)
}

/// A world under `gravity`, stepped by `dt`, holding the robot as multibody joints without self contacts;
/// with the multibody joint of each robot joint (`None`: not inserted as one).
fn insert_robot(
    robot: UrdfRobot,
    gravity: [f64; 3],
    dt: f64,
) -> (PhysicsWorld, Vec<Option<MultibodyJointHandle>>) {
    let mut world = PhysicsWorld {
        gravity: Vector::new(gravity[0] as Real, gravity[1] as Real, gravity[2] as Real),
        ..PhysicsWorld::default()
    };
    world.integration_parameters.dt = dt as Real;
    let handles = robot.insert_using_multibody_joints(
        &mut world.bodies,
        &mut world.colliders,
        &mut world.multibody_joints,
        UrdfMultibodyOptions::DISABLE_SELF_CONTACTS,
    );
    let joints = handles.joints.iter().map(|jh| jh.joint).collect();
    (world, joints)
}

/// The caller's joints in their order, each with its multibody joint and stiffness.
fn joint_slots(
    robot_joint_handles: &[Option<MultibodyJointHandle>],
    slot_of_robot_joint: &[Option<usize>],
    joint_names: &[String],
    stiffness: &[f64],
) -> Result<Vec<JointSlot>> {
    let mut slot_handle: Vec<Option<MultibodyJointHandle>> = vec![None; joint_names.len()];
    for (rj, handle) in robot_joint_handles.iter().enumerate() {
        if let Some(slot) = slot_of_robot_joint[rj] {
            let h = handle.ok_or_else(|| {
                Error::Physics(format!(
                    "joint `{}` could not be inserted as a multibody joint (kinematic loop?)",
                    joint_names[slot]
                ))
            })?;
            slot_handle[slot] = Some(h);
        }
    }
    joint_names
        .iter()
        .zip(stiffness)
        .zip(slot_handle)
        .map(|((name, &k), h)| {
            h.map(|handle| JointSlot {
                name: name.clone(),
                handle,
                stiffness: k,
            })
            .ok_or_else(|| Error::Physics(format!("joint `{name}` has no multibody joint")))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    const G: f64 = 9.81;

    fn names(v: &[&str]) -> Vec<String> {
        v.iter().map(|s| s.to_string()).collect()
    }

    /// One revolute joint about +y at height 1 m; the link is a mass `m` at `l` along x.
    fn pendulum_urdf(m: f64, l: f64) -> String {
        format!(
            r#"<?xml version="1.0"?>
<robot name="pendulum">
  <link name="base">
    <inertial><origin xyz="0 0 0"/><mass value="5"/>
      <inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial>
  </link>
  <link name="arm">
    <inertial><origin xyz="{l} 0 0"/><mass value="{m}"/>
      <inertia ixx="1e-4" ixy="0" ixz="0" iyy="1e-4" iyz="0" izz="1e-4"/></inertial>
  </link>
  <joint name="j1" type="revolute">
    <parent link="base"/><child link="arm"/>
    <origin xyz="0 0 1" rpy="0 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-0.5" upper="0.5" effort="100" velocity="1"/>
  </joint>
</robot>"#
        )
    }

    /// Two revolute joints about +y; an empty `world` root (fixed joint) and an empty `tool0`
    /// flange frame, both squeezed away by the loader.
    fn planar_urdf(m1: f64, c1: f64, l1: f64, m2: f64, c2: f64) -> String {
        format!(
            r#"<?xml version="1.0"?>
<robot name="planar2">
  <link name="world"/>
  <joint name="world_fix" type="fixed">
    <parent link="world"/><child link="base"/><origin xyz="0 0 0.3"/>
  </joint>
  <link name="base">
    <inertial><origin xyz="0 0 0"/><mass value="5"/>
      <inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial>
  </link>
  <link name="link1">
    <inertial><origin xyz="{c1} 0 0"/><mass value="{m1}"/>
      <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.05" iyz="0" izz="0.05"/></inertial>
  </link>
  <link name="link2">
    <inertial><origin xyz="{c2} 0 0"/><mass value="{m2}"/>
      <inertia ixx="0.005" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.02"/></inertial>
  </link>
  <link name="tool0"/>
  <joint name="shoulder" type="revolute">
    <parent link="base"/><child link="link1"/>
    <origin xyz="0 0 0.5"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="100" velocity="1"/>
  </joint>
  <joint name="elbow" type="continuous">
    <parent link="link1"/><child link="link2"/>
    <origin xyz="{l1} 0 0"/><axis xyz="0 1 0"/>
  </joint>
  <joint name="flange" type="fixed">
    <parent link="link2"/><child link="tool0"/><origin xyz="0.4 0 0"/>
  </joint>
</robot>"#
        )
    }

    /// Pendulum: the mass sits at `L (cos q, 0, -sin q)` (a positive rotation about +y takes +x
    /// towards -z), so V = -m g L sin q and τ_g = -dV/dq = m g L cos q. Equilibrium:
    /// f(q) = k (q - r) - m g L cos q = 0, solved by Newton.
    #[test]
    fn pendulum_matches_scalar_equilibrium() {
        let (m, l, k, r): (f64, f64, f64, f64) = (2.0, 0.5, 150.0, 0.3);
        let mut q = r;
        for _ in 0..50 {
            let f = k * (q - r) - m * G * l * q.cos();
            let df = k + m * G * l * q.sin();
            q -= f / df;
        }
        assert!((k * (q - r) - m * G * l * q.cos()).abs() < 1e-12);
        // the joint limit (±0.5) must not clamp the answer (q ≈ 0.36, rest beyond it below)
        let mut phys = PhysicsReference::new(
            &pendulum_urdf(m, l),
            &names(&["j1"]),
            &[k],
            [0.0, 0.0, -G],
            SettleOptions::default(),
        )
        .unwrap();
        let s = phys.settle(&[r]).unwrap();
        eprintln!(
            "pendulum: q {:.9} expected {q:.9}, {} steps",
            s.q[0], s.steps
        );
        assert!((s.q[0] - q).abs() <= 1e-6, "{} vs {q}", s.q[0]);
        assert!(s.q[0] - r > 0.05, "gravity must pull q up (sign)");

        // a second pose from the same world, past the URDF limit
        let r2: f64 = 0.6;
        let mut q2 = r2;
        for _ in 0..50 {
            q2 -= (k * (q2 - r2) - m * G * l * q2.cos()) / (k + m * G * l * q2.sin());
        }
        let s2 = phys.settle(&[r2]).unwrap();
        assert!((s2.q[0] - q2).abs() <= 1e-6, "{} vs {q2}", s2.q[0]);
    }

    /// Two-link planar arm in the x-z plane, both axes +y.
    /// com1 = c1 u(q1), com2 = l1 u(q1) + c2 u(q1+q2), u(a) = (cos a, 0, -sin a).
    /// τ1 = g [(m1 c1 + m2 l1) cos q1 + m2 c2 cos(q1+q2)], τ2 = g m2 c2 cos(q1+q2).
    #[test]
    fn planar_arm_matches_newton_equilibrium() {
        let (m1, c1, l1, m2, c2) = (4.0, 0.3, 0.6, 2.5, 0.25);
        let k = [900.0, 300.0];
        let tau = |q: [f64; 2]| {
            let a = G * m2 * c2 * (q[0] + q[1]).cos();
            [G * (m1 * c1 + m2 * l1) * q[0].cos() + a, a]
        };
        let solve = |r: [f64; 2]| {
            let mut q = r;
            for _ in 0..50 {
                let t = tau(q);
                let f = [k[0] * (q[0] - r[0]) - t[0], k[1] * (q[1] - r[1]) - t[1]];
                let s12 = (q[0] + q[1]).sin();
                let b = G * m2 * c2 * s12;
                // d(-τ)/dq
                let j00 = k[0] + G * (m1 * c1 + m2 * l1) * q[0].sin() + b;
                let j01 = b;
                let j10 = b;
                let j11 = k[1] + b;
                let det = j00 * j11 - j01 * j10;
                q[0] -= (j11 * f[0] - j01 * f[1]) / det;
                q[1] -= (-j10 * f[0] + j00 * f[1]) / det;
            }
            let t = tau(q);
            assert!((k[0] * (q[0] - r[0]) - t[0]).abs() < 1e-10);
            assert!((k[1] * (q[1] - r[1]) - t[1]).abs() < 1e-10);
            q
        };
        // caller order deliberately reversed
        let mut phys = PhysicsReference::new(
            &planar_urdf(m1, c1, l1, m2, c2),
            &names(&["elbow", "shoulder"]),
            &[k[1], k[0]],
            [0.0, 0.0, -G],
            SettleOptions::default(),
        )
        .unwrap();
        for r in [[0.2, -0.4], [-1.0, 0.7], [1.2, 0.9]] {
            let expect = solve(r);
            let t0 = std::time::Instant::now();
            let s = phys.settle(&[r[1], r[0]]).unwrap();
            eprintln!(
                "planar rest {r:?}: q [{:.9}, {:.9}] expected {expect:.9?}, {} steps, {:?}",
                s.q[1],
                s.q[0],
                s.steps,
                t0.elapsed()
            );
            assert!(
                (s.q[1] - expect[0]).abs() <= 1e-6,
                "{:?} vs {expect:?}",
                s.q
            );
            assert!(
                (s.q[0] - expect[1]).abs() <= 1e-6,
                "{:?} vs {expect:?}",
                s.q
            );
        }
    }

    #[test]
    fn bad_inputs_are_errors() {
        let urdf = pendulum_urdf(1.0, 0.5);
        let g = [0.0, 0.0, -G];
        let opts = SettleOptions::default();
        let e = PhysicsReference::new(&urdf, &names(&["nope"]), &[100.0], g, opts).unwrap_err();
        assert!(matches!(e, Error::Urdf { .. }), "{e}");
        assert!(e.to_string().contains("nope"), "{e}");
        assert!(PhysicsReference::new(&urdf, &names(&["j1"]), &[f64::NAN], g, opts).is_err());
        assert!(PhysicsReference::new(&urdf, &names(&["j1"]), &[0.0], g, opts).is_err());
        assert!(PhysicsReference::new(&urdf, &names(&["j1"]), &[1.0, 2.0], g, opts).is_err());
        assert!(PhysicsReference::new("<robot", &names(&["j1"]), &[1.0], g, opts).is_err());
        // an unlisted movable joint
        let planar = planar_urdf(1.0, 0.2, 0.5, 1.0, 0.2);
        let e =
            PhysicsReference::new(&planar, &names(&["shoulder"]), &[100.0], g, opts).unwrap_err();
        assert!(e.to_string().contains("elbow"), "{e}");
        // a fixed joint is not a spring
        assert!(
            PhysicsReference::new(
                &planar,
                &names(&["shoulder", "flange"]),
                &[1.0, 1.0],
                g,
                opts
            )
            .is_err()
        );
        let mut phys = PhysicsReference::new(&urdf, &names(&["j1"]), &[100.0], g, opts).unwrap();
        assert!(phys.settle(&[0.1, 0.2]).is_err());
        assert!(phys.settle(&[f64::NAN]).is_err());
        // too few steps: an error naming the residual
        let mut short = PhysicsReference::new(
            &urdf,
            &names(&["j1"]),
            &[100.0],
            g,
            SettleOptions {
                max_steps: 2,
                ..opts
            },
        )
        .unwrap();
        let e = short.settle(&[0.0]).unwrap_err();
        assert!(e.to_string().contains("not settled"), "{e}");
    }

    /// An iiwa-like 7-DoF arm (alternating z/y axes, datasheet-like masses, offset CoMs), with an
    /// empty `world` root and an empty `tool0` frame.
    fn arm7() -> String {
        let axes = [
            "0 0 1", "0 1 0", "0 0 1", "0 -1 0", "0 0 1", "0 1 0", "0 0 1",
        ];
        let z = [0.1575, 0.2025, 0.2045, 0.2155, 0.1845, 0.2155, 0.081];
        let m = [3.4, 3.43, 4.0, 3.43, 2.13, 2.31, 0.34];
        let com = [
            "0 -0.03 0.12",
            "0.0003 0.059 0.042",
            "0 0.03 0.13",
            "0 0.067 0.034",
            "0.0001 0.021 0.076",
            "0 0.0006 0.0004",
            "0 0 0.02",
        ];
        let mut s = String::from(
            "<?xml version=\"1.0\"?><robot name=\"a7\"><link name=\"world\"/><joint name=\"wf\" type=\"fixed\"><parent link=\"world\"/><child link=\"l0\"/></joint><link name=\"l0\"><inertial><origin xyz=\"0 0 0.07\"/><mass value=\"4.9\"/><inertia ixx=\"0.05\" ixy=\"0\" ixz=\"0\" iyy=\"0.06\" iyz=\"0\" izz=\"0.03\"/></inertial></link>",
        );
        for i in 0..7 {
            s += &format!(
                "<link name=\"l{}\"><inertial><origin xyz=\"{}\"/><mass value=\"{}\"/><inertia ixx=\"0.03\" ixy=\"0\" ixz=\"0\" iyy=\"0.03\" iyz=\"0\" izz=\"0.01\"/></inertial></link>",
                i + 1,
                com[i],
                m[i]
            );
            s += &format!(
                "<joint name=\"A{}\" type=\"revolute\"><parent link=\"l{}\"/><child link=\"l{}\"/><origin xyz=\"0 0 {}\"/><axis xyz=\"{}\"/><limit lower=\"-2.9\" upper=\"2.9\" effort=\"100\" velocity=\"1\"/></joint>",
                i + 1,
                i,
                i + 1,
                z[i],
                axes[i]
            );
        }
        s += "<link name=\"tool0\"/><joint name=\"ff\" type=\"fixed\"><parent link=\"l7\"/><child link=\"tool0\"/><origin xyz=\"0 0 0.045\"/></joint></robot>";
        s
    }

    /// The same equilibrium from a large and a small step, from a reused and a fresh world
    /// (settle must reset the state), with each joint moved by the sag.
    #[test]
    fn arm7_settles_consistently() {
        let urdf = arm7();
        let names: Vec<String> = (1..=7).map(|i| format!("A{i}")).collect();
        let k = [1.5e4, 1.5e4, 1e4, 1e4, 3e3, 3e3, 2e3];
        let g = [0.0, 0.0, -G];
        let poses = [
            [0.3, 0.8, -0.4, -1.2, 0.5, 1.0, 0.2],
            [0.0, 1.5, 0.0, 0.3, 0.0, -1.4, 0.0],
        ];
        let mut reused =
            PhysicsReference::new(&urdf, &names, &k, g, SettleOptions::default()).unwrap();
        for rest in poses.iter().chain(poses.iter().rev()) {
            let t0 = std::time::Instant::now();
            let a = reused.settle(rest).unwrap();
            let elapsed = t0.elapsed();
            let mut fresh =
                PhysicsReference::new(&urdf, &names, &k, g, SettleOptions::default()).unwrap();
            let b = fresh.settle(rest).unwrap();
            let small = SettleOptions {
                dt: 0.02,
                ..SettleOptions::default()
            };
            let c = PhysicsReference::new(&urdf, &names, &k, g, small)
                .unwrap()
                .settle(rest)
                .unwrap();
            eprintln!(
                "arm7: {} steps ({} at dt 0.02), {elapsed:?}, sag {:?}",
                a.steps,
                c.steps,
                a.q.iter()
                    .zip(rest)
                    .map(|(q, r)| format!("{:.2e}", q - r))
                    .collect::<Vec<_>>()
            );
            for i in 0..7 {
                assert!(
                    (a.q[i] - b.q[i]).abs() <= 1e-7,
                    "reuse {i}: {:?} {:?}",
                    a.q,
                    b.q
                );
                assert!(
                    (a.q[i] - c.q[i]).abs() <= 3e-7,
                    "dt {i}: {:?} {:?}",
                    a.q,
                    c.q
                );
            }
            // shoulder and elbow sag by more than a milliradian/ten µrad
            assert!((a.q[1] - rest[1]).abs() > 1e-3 || (a.q[3] - rest[3]).abs() > 1e-3);
            assert!(a.steps < 100, "{} steps", a.steps);
        }
    }
}
