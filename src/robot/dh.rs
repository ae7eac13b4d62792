//! Standard Denavit–Hartenberg description of a [`Chain`] (paper §2.1, eq. 1).
//!
//! The paper's generalized error parameters (eq. 3–6) are attached to DH frames, so the calibration needs a
//! DH table for whatever robot a scenario loads. A hand-written table per robot would silently drift from
//! the URDF that the rest of the pipeline uses; instead the table is derived from the chain's joint axes at
//! q = 0 (their common normals), and [`DhChain::from_chain`] refuses a result whose kinematics disagree
//! with the chain.
//!
//! Where standard DH leaves a choice open, the choice keeps the table close to the published ones:
//! - the sign of each x axis is the one that keeps `theta_offset` within ±π/2 (so `a` may be negative,
//!   as in Universal Robots' own tables), which makes the iiwa's offsets all zero;
//! - for parallel axes the common normal passes through the previous origin (`d = 0`);
//! - frame 0 sits as close to the chain's base frame as joint 1's axis allows, frame n on the last axis
//!   as close to the flange as possible, so `base` and `tool` are identity for a URDF drawn in DH frames.
//!
//! Nearly parallel (but not parallel) consecutive axes — a UR arm's 2, 3 and 4 once a calibration has tilted
//! them — have a common normal metres to kilometres away, where standard DH needs a huge `d` (its known
//! ill-conditioning, which the paper's §1 mentions) and rounding loses the model. Those rows are Hayati's
//! (Hayati & Mirmirani 1985, "Improving the absolute positioning accuracy of robot manipulators", J. Robotic
//! Systems 2(4)): `A_i = Rz(θ_i) Tx(a_i) Rx(α_i) Ry(β_i)` with `d_i = 0`, frame i's origin where the next axis
//! crosses frame i−1's x-y plane. For exactly parallel axes that is the standard row with `d = 0` and β = 0,
//! so nominal tables do not change. The generalized error frames (`calib::error_model`) sit after A_i as
//! before: a β row only places frame i, and frame i's error about y is the calibration literature's β error
//! (which replaces the unidentifiable d error of a near-parallel row).

use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use super::chain::{Chain, JointKind};
use super::kinematics::{Frames, forward_kinematics};
use super::plausible;
use crate::error::{Error, Result};

/// One link of eq. 1. For a revolute joint θ = q + `theta_offset`; for a prismatic one d = `d` + q.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DhRow {
    pub theta_offset: f64,
    pub d: f64,
    pub a: f64,
    pub alpha: f64,
    /// Hayati's rotation about the new y axis, after `alpha` (0 for a standard row; see the module notes).
    /// Left out of files when 0, so tables without it read and write as before.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub beta: f64,
    pub prismatic: bool,
}

fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

/// A chain in DH form: `base · A_1(q_1) ⋯ A_n(q_n) · tool` is the flange pose.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DhChain {
    /// Pose of DH frame 0 in the world frame.
    pub base: Isometry3<f64>,
    pub rows: Vec<DhRow>,
    /// Pose of the flange in DH frame n.
    pub tool: Isometry3<f64>,
}

/// A configuration with a chain's link transforms and frames there ([`DhChain::pose`]): computed once where
/// many models of the same nominal chain are evaluated at the same configurations (a study judges every run
/// on the same ground truth), and in one pass where one model needs both.
#[derive(Clone, Debug)]
pub struct ChainPose {
    pub q: Vec<f64>,
    /// `A_i(q_i)`, one per joint ([`DhChain::link_transform`]).
    pub links: Vec<Isometry3<f64>>,
    /// DH frames 0..=n: [`DhChain::frames`]'s products, so the same bits.
    pub frames: Vec<Isometry3<f64>>,
}

impl ChainPose {
    /// [`DhChain::flange_pose`] at the pose's configuration (the same products), for the chain it was made on.
    pub fn flange(&self, dh: &DhChain) -> Isometry3<f64> {
        self.frames[self.links.len()] * dh.tool
    }
}

/// Per row of a [`DhChain`], its rotations that do not turn with the joint: `Rx(alpha)` and a Hayati row's
/// `Ry(beta)` ([`DhChain::fixed_rotations`]).
#[derive(Clone, Debug)]
pub struct FixedRotations(Vec<(UnitQuaternion<f64>, Option<UnitQuaternion<f64>>)>);

/// Below this sine of the angle between consecutive axes they are treated as parallel. Rounding in URDF
/// rotations is ~1e-16; anything above this threshold is a real (if tiny) skew that must be kept for
/// the DH model to be exact.
const PARALLEL_SIN: f64 = 1e-10;
/// From this sine of the angle between consecutive axes (0.57°) up, a standard row is used; below it (and
/// above [`PARALLEL_SIN`]) a Hayati row, whose frame stays near the arm where the common normal would not.
/// Nominal arms have exactly parallel or clearly skew axes; calibration tilts parallel ones by ~1e-4 rad.
const NEAR_PARALLEL_SIN: f64 = 1e-2;
/// Below this distance (m) two parallel axes are one line and the common normal's direction is free.
const COINCIDENT: f64 = 1e-12;
/// |cos θ| below which the two x-axis signs give θ = ±π/2 equally far from zero.
const TIE: f64 = 1e-9;

/// A DH frame under construction, in world coordinates.
struct FrameAxes {
    origin: Point3<f64>,
    x: Vector3<f64>,
    z: Vector3<f64>,
}

impl FrameAxes {
    fn pose(&self) -> Isometry3<f64> {
        let y = self.z.cross(&self.x);
        let rot = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[self.x, y, self.z]));
        Isometry3::from_parts(
            Translation3::from(self.origin.coords),
            UnitQuaternion::from_rotation_matrix(&rot),
        )
    }
}

impl DhChain {
    /// Derives the table from the chain's geometry at q = 0 (see the module notes for the conventions).
    pub fn from_chain(chain: &Chain) -> Result<DhChain> {
        let n = chain.dof();
        let invalid =
            |what: String| Error::Invalid(format!("DH of chain '{}': {what}", chain.name));
        if n == 0 {
            return Err(invalid("no movable joint".into()));
        }
        let mut fk = Frames::new(chain);
        forward_kinematics(chain, &vec![0.0; n], &mut fk);
        let mut lines = Vec::with_capacity(n);
        for i in 0..n {
            let (p, u) = (fk.anchor(i), fk.axis(chain, i));
            let finite = p.iter().chain(u.iter()).all(|v| v.is_finite());
            if !finite || (u.norm() - 1.0).abs() > 1e-6 {
                return Err(invalid(format!(
                    "joint '{}' has a non-finite or non-unit axis at q = 0",
                    chain.joints[i].name
                )));
            }
            lines.push((p, u.normalize()));
        }
        let finite_pose = |t: &Isometry3<f64>| {
            t.translation
                .vector
                .iter()
                .chain(t.rotation.coords.iter())
                .all(|v| v.is_finite())
        };
        if !finite_pose(&fk.flange) {
            return Err(invalid("non-finite base or flange pose".into()));
        }

        let mut axes: Vec<FrameAxes> = Vec::with_capacity(n + 1);
        let (p, u) = lines[0];
        let base_origin = Point3::from(chain.base.translation.vector);
        axes.push(FrameAxes {
            origin: p + u * (base_origin - p).dot(&u),
            x: perpendicular(&u, &chain.base.rotation),
            z: u,
        });
        // Per joint after the first: the Hayati row that reaches its frame, where one does.
        let mut hayati: Vec<Option<DhRow>> = Vec::with_capacity(n);
        for (&(p, v), joint) in lines[1..].iter().zip(&chain.joints) {
            let prev = axes.last().expect("frame 0 pushed above");
            let (frame, row) = next_frame(prev, p, v, joint.kind == JointKind::Prismatic);
            axes.push(frame);
            hayati.push(row);
        }
        let (p, u) = lines[n - 1];
        let flange_origin = Point3::from(fk.flange.translation.vector);
        axes.push(FrameAxes {
            origin: p + u * (flange_origin - p).dot(&u),
            x: perpendicular(&u, &fk.flange.rotation),
            z: u,
        });

        let rows = axes
            .windows(2)
            .zip(&chain.joints)
            .enumerate()
            .map(|(i, (w, joint))| {
                if let Some(row) = hayati.get(i).cloned().flatten() {
                    return row;
                }
                let (f, g) = (&w[0], &w[1]);
                let delta = g.origin - f.origin;
                DhRow {
                    theta_offset: angle(f.x.cross(&g.x).dot(&f.z), f.x.dot(&g.x)),
                    d: delta.dot(&f.z),
                    a: delta.dot(&g.x),
                    alpha: angle(f.z.cross(&g.z).dot(&g.x), f.z.dot(&g.z)),
                    beta: 0.0,
                    prismatic: joint.kind == JointKind::Prismatic,
                }
            })
            .collect();
        let base = axes[0].pose();
        let tool = axes[n].pose().inverse() * fk.flange;
        let dh = DhChain { base, rows, tool };
        dh.agrees_with(chain).map_err(invalid)?;
        Ok(dh)
    }

    pub fn dof(&self) -> usize {
        self.rows.len()
    }

    /// A table read from a file is usable: at least one row, every number finite, lengths and angles of a
    /// plausible size ([`plausible`]), base and tool proper poses. Fields are named as the file writes them.
    pub fn validate(&self) -> Result<()> {
        if self.rows.is_empty() {
            return Err(plausible::invalid("rows", "no joint"));
        }
        plausible::pose("base", &self.base)?;
        plausible::pose("tool", &self.tool)?;
        for (i, r) in self.rows.iter().enumerate() {
            let field = |name: &str| format!("rows[{i}].{name}");
            plausible::angle(&field("theta_offset"), r.theta_offset)?;
            plausible::length(&field("d"), r.d)?;
            plausible::length(&field("a"), r.a)?;
            plausible::angle(&field("alpha"), r.alpha)?;
            plausible::angle(&field("beta"), r.beta)?;
        }
        Ok(())
    }

    /// A_i(q_i) = Rz(q_i + theta_offset) Tz(d) Tx(a) Rx(alpha) (prismatic: d + q_i), paper eq. 1; a Hayati row
    /// turns on by Ry(beta).
    pub fn link_transform(&self, i: usize, qi: f64) -> Isometry3<f64> {
        let alpha = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), self.rows[i].alpha);
        let a = self.standard_transform(i, qi, &alpha);
        let beta = self.rows[i].beta;
        if beta == 0.0 {
            a
        } else {
            a * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), beta)
        }
    }

    /// The rotations of the rows that do not turn with their joints, for [`DhChain::link_transform_fixed`].
    pub fn fixed_rotations(&self) -> FixedRotations {
        FixedRotations(
            self.rows
                .iter()
                .map(|r| {
                    (
                        UnitQuaternion::from_axis_angle(&Vector3::x_axis(), r.alpha),
                        (r.beta != 0.0)
                            .then(|| UnitQuaternion::from_axis_angle(&Vector3::y_axis(), r.beta)),
                    )
                })
                .collect(),
        )
    }

    /// [`DhChain::link_transform`] with the rows' fixed rotations computed once (`fixed`, of this chain): the
    /// same products, the same bits, without their sines and cosines — for links evaluated at many angles.
    pub fn link_transform_fixed(
        &self,
        i: usize,
        qi: f64,
        fixed: &FixedRotations,
    ) -> Isometry3<f64> {
        let (alpha, beta) = &fixed.0[i];
        self.link_with(i, qi, alpha, beta.as_ref())
    }

    fn link_with(
        &self,
        i: usize,
        qi: f64,
        alpha: &UnitQuaternion<f64>,
        beta: Option<&UnitQuaternion<f64>>,
    ) -> Isometry3<f64> {
        let a = self.standard_transform(i, qi, alpha);
        match beta {
            None => a,
            Some(b) => a * *b,
        }
    }

    fn standard_transform(&self, i: usize, qi: f64, alpha: &UnitQuaternion<f64>) -> Isometry3<f64> {
        let r = &self.rows[i];
        let (theta, d) = if r.prismatic {
            (r.theta_offset, r.d + qi)
        } else {
            (qi + r.theta_offset, r.d)
        };
        let (st, ct) = theta.sin_cos();
        let rot = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), theta) * alpha;
        Isometry3::from_parts(Translation3::new(r.a * ct, r.a * st, d), rot)
    }

    /// World pose of DH frames 0..=n (n+1 entries) for q.
    pub fn frames(&self, q: &[f64]) -> Vec<Isometry3<f64>> {
        self.frames_through(q, |i, qi| self.link_transform(i, qi))
    }

    /// [`DhChain::frames`] with the rows' fixed rotations computed once ([`DhChain::fixed_rotations`]): the same
    /// frames, bit for bit, without two of each link's three sine–cosine pairs.
    pub fn frames_fixed(&self, q: &[f64], fixed: &FixedRotations) -> Vec<Isometry3<f64>> {
        self.frames_through(q, |i, qi| self.link_transform_fixed(i, qi, fixed))
    }

    /// The base, then the base times the links `link(i, q_i)` one by one.
    fn frames_through(
        &self,
        q: &[f64],
        link: impl Fn(usize, f64) -> Isometry3<f64>,
    ) -> Vec<Isometry3<f64>> {
        assert_eq!(
            q.len(),
            self.dof(),
            "configuration length must equal the chain's dof"
        );
        let mut out = Vec::with_capacity(q.len() + 1);
        let mut pose = self.base;
        out.push(pose);
        for (i, &qi) in q.iter().enumerate() {
            pose *= link(i, qi);
            out.push(pose);
        }
        out
    }

    /// The configuration `q` with its link transforms and frames ([`ChainPose`]).
    pub fn pose(&self, q: &[f64]) -> ChainPose {
        self.pose_through(q, |i, qi| self.link_transform(i, qi))
    }

    /// [`DhChain::pose`] with the rows' fixed rotations computed once ([`DhChain::fixed_rotations`]): the same
    /// links and frames, bit for bit, without two of each link's three sine–cosine pairs.
    pub fn pose_fixed(&self, q: &[f64], fixed: &FixedRotations) -> ChainPose {
        self.pose_through(q, |i, qi| self.link_transform_fixed(i, qi, fixed))
    }

    /// The links `link(i, q_i)` and the frames they make.
    fn pose_through(&self, q: &[f64], link: impl Fn(usize, f64) -> Isometry3<f64>) -> ChainPose {
        assert_eq!(
            q.len(),
            self.dof(),
            "configuration length must equal the chain's dof"
        );
        let links: Vec<Isometry3<f64>> = q.iter().enumerate().map(|(i, &qi)| link(i, qi)).collect();
        let mut frames = Vec::with_capacity(q.len() + 1);
        let mut pose = self.base;
        frames.push(pose);
        for link in &links {
            pose *= link;
            frames.push(pose);
        }
        ChainPose {
            q: q.to_vec(),
            links,
            frames,
        }
    }

    pub fn flange_pose(&self, q: &[f64]) -> Isometry3<f64> {
        self.flange_through(q, |i, qi| self.link_transform(i, qi))
    }

    /// [`DhChain::flange_pose`] with the rows' fixed rotations computed once ([`DhChain::fixed_rotations`]):
    /// the same pose, bit for bit, without two of each link's three sine–cosine pairs.
    pub fn flange_pose_fixed(&self, q: &[f64], fixed: &FixedRotations) -> Isometry3<f64> {
        self.flange_through(q, |i, qi| self.link_transform_fixed(i, qi, fixed))
    }

    /// The base, the links `link(i, q_i)` in order, the tool.
    fn flange_through(
        &self,
        q: &[f64],
        link: impl Fn(usize, f64) -> Isometry3<f64>,
    ) -> Isometry3<f64> {
        assert_eq!(
            q.len(),
            self.dof(),
            "configuration length must equal the chain's dof"
        );
        let mut pose = self.base;
        for (i, &qi) in q.iter().enumerate() {
            pose *= link(i, qi);
        }
        pose * self.tool
    }

    /// The construction is exact by design; this catches what it cannot handle (overflowing common normals
    /// of nearly parallel axes) before a calibration silently uses a wrong model.
    fn agrees_with(&self, chain: &Chain) -> std::result::Result<(), String> {
        let n = self.dof();
        let reach: f64 = chain
            .joints
            .iter()
            .map(|j| j.origin.translation.vector.norm())
            .sum::<f64>()
            + chain.flange.translation.vector.norm()
            + chain.base.translation.vector.norm();
        let tol = 1e-9 * (1.0 + reach);
        for k in 0..3 {
            let q: Vec<f64> = (0..n)
                .map(|i| 0.4 * k as f64 * (1.0 + 0.37 * i as f64))
                .collect();
            let want = super::kinematics::flange_pose(chain, &q);
            let got = self.flange_pose(&q);
            let dp = (got.translation.vector - want.translation.vector).norm();
            let dr = got.rotation.angle_to(&want.rotation);
            if !(dp <= tol && dr <= 1e-9) {
                return Err(format!(
                    "the derived DH table disagrees with the chain by {dp:e} m, {dr:e} rad \
                     (nearly parallel consecutive axes?)"
                ));
            }
        }
        Ok(())
    }
}

/// The DH frame on the line (`p`, `v`) of the next joint axis after `prev`, and the row that reaches it when
/// that is a Hayati row (the axes nearly parallel, see the module notes); `None` for a standard row, which the
/// caller reads off the two frames.
fn next_frame(
    prev: &FrameAxes,
    p: Point3<f64>,
    v: Vector3<f64>,
    prismatic: bool,
) -> (FrameAxes, Option<DhRow>) {
    let cross = prev.z.cross(&v);
    let sin = cross.norm();
    if (PARALLEL_SIN..NEAR_PARALLEL_SIN).contains(&sin) {
        let (frame, row) = hayati_frame(prev, p, v, prismatic);
        return (frame, Some(row));
    }
    let (origin, normal) = if sin < PARALLEL_SIN {
        let origin = p + v * (prev.origin - p).dot(&v);
        let w = origin - prev.origin;
        let normal = if w.norm() > COINCIDENT {
            w / w.norm()
        } else {
            // One line: any normal will do; the previous x keeps θ = 0.
            let r = prev.x - v * prev.x.dot(&v);
            r / r.norm()
        };
        (origin, normal)
    } else {
        // Foot on the new axis of the common normal of the two lines.
        let r = prev.origin - p;
        let (b, dz, ev) = (prev.z.dot(&v), prev.z.dot(&r), v.dot(&r));
        let t = (ev - b * dz) / (sin * sin);
        (p + v * t, cross / sin)
    };
    let x = orient(normal, &prev.x, &prev.z);
    (FrameAxes { origin, x, z: v }, None)
}

/// Hayati's frame on the line (`p`, `v`), nearly parallel to `prev`'s z: its origin where the line crosses
/// `prev`'s x-y plane (d = 0), reached by Rz(θ) Tx(a) along the common direction (θ within ±π/2 as for a
/// standard row), then turned by Rx(α) Ry(β) so that z lies along `v`.
fn hayati_frame(
    prev: &FrameAxes,
    p: Point3<f64>,
    v: Vector3<f64>,
    prismatic: bool,
) -> (FrameAxes, DhRow) {
    let origin = p + v * ((prev.origin - p).dot(&prev.z) / v.dot(&prev.z));
    let w = origin - prev.origin;
    let normal = if w.norm() > COINCIDENT {
        w / w.norm()
    } else {
        prev.x
    };
    let x1 = orient(normal, &prev.x, &prev.z);
    let y1 = prev.z.cross(&x1);
    // v = Rx(α) Ry(β) ẑ = (sin β, −sin α cos β, cos α cos β) in the turned frame (x1, y1, z).
    let (vx, vy, vz) = (v.dot(&x1), v.dot(&y1), v.dot(&prev.z));
    let beta = vx.atan2(vy.hypot(vz));
    let alpha = angle(-vy, vz);
    let (sa, ca) = alpha.sin_cos();
    let (sb, cb) = beta.sin_cos();
    let x = x1 * cb + y1 * (sa * sb) - prev.z * (ca * sb);
    let row = DhRow {
        theta_offset: angle(prev.x.cross(&x1).dot(&prev.z), prev.x.dot(&x1)),
        d: 0.0,
        a: w.dot(&x1),
        alpha,
        beta,
        prismatic,
    };
    (FrameAxes { origin, x, z: v }, row)
}

/// Unit vector perpendicular to `z` taken from the frame's x axis, or its y axis when x lies along `z`,
/// so that a frame already aligned with the DH one is reproduced exactly.
fn perpendicular(z: &Vector3<f64>, frame: &UnitQuaternion<f64>) -> Vector3<f64> {
    let project = |c: Vector3<f64>| c - z * c.dot(z);
    let x = project(frame * Vector3::x());
    // x and y are orthogonal, so at least one keeps a norm ≥ 1/√2.
    let v = if x.norm() > 1e-6 {
        x
    } else {
        project(frame * Vector3::y())
    };
    v / v.norm()
}

/// The sign of a common normal that keeps θ (from `prev_x` about `prev_z`) within ±π/2; +π/2 on a tie,
/// so the choice does not flip with rounding noise.
fn orient(normal: Vector3<f64>, prev_x: &Vector3<f64>, prev_z: &Vector3<f64>) -> Vector3<f64> {
    let cos = prev_x.dot(&normal);
    let flip = if cos.abs() > TIE {
        cos < 0.0
    } else {
        prev_x.cross(&normal).dot(prev_z) < 0.0
    };
    if flip { -normal } else { normal }
}

/// atan2 with −π folded onto +π, so an anti-parallel pair reads the same whatever the rounding.
fn angle(sin: f64, cos: f64) -> f64 {
    let a = sin.atan2(cos);
    if a <= -std::f64::consts::PI + 1e-12 {
        std::f64::consts::PI
    } else {
        a
    }
}

#[cfg(test)]
mod tests {
    use std::f64::consts::{FRAC_PI_2, PI};
    use std::fmt::Write;

    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::*;
    use crate::robot::{Body, kinematics, urdf};

    /// The links with the fixed rotations computed once are the links, bit for bit, standard and Hayati rows.
    #[test]
    fn fixed_rotations_give_the_same_links() {
        let chain = urdf::load_file("robots/iiwa7.urdf", None).unwrap();
        let mut dh = DhChain::from_chain(&chain).unwrap();
        dh.rows[2].beta = 0.013;
        let fixed = dh.fixed_rotations();
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        for _ in 0..20 {
            for i in 0..dh.dof() {
                let q = rng.random_range(-3.0..3.0);
                assert_eq!(
                    dh.link_transform_fixed(i, q, &fixed),
                    dh.link_transform(i, q)
                );
            }
            let q: Vec<f64> = (0..dh.dof()).map(|_| rng.random_range(-3.0..3.0)).collect();
            assert_eq!(dh.flange_pose_fixed(&q, &fixed), dh.flange_pose(&q));
            assert_eq!(dh.frames_fixed(&q, &fixed), dh.frames(&q));
            let (pose, fixed_pose) = (dh.pose(&q), dh.pose_fixed(&q, &fixed));
            assert_eq!(fixed_pose.links, pose.links);
            assert_eq!(fixed_pose.frames, dh.frames(&q));
            assert_eq!(fixed_pose.flange(&dh), dh.flange_pose(&q));
        }
        assert_ne!(
            dh.link_transform(2, 0.4),
            DhChain::from_chain(&chain).unwrap().link_transform(2, 0.4)
        );
    }

    fn pose_gap(a: &Isometry3<f64>, b: &Isometry3<f64>) -> (f64, f64) {
        (
            (a.translation.vector - b.translation.vector).norm(),
            a.rotation.angle_to(&b.rotation),
        )
    }

    fn random_q(chain: &Chain, rng: &mut ChaCha8Rng) -> Vec<f64> {
        chain
            .joints
            .iter()
            .map(|j| {
                let (lo, hi) = if j.lower.is_finite() && j.upper.is_finite() {
                    (j.lower, j.upper)
                } else {
                    (-PI, PI)
                };
                rng.random_range(lo..=hi)
            })
            .collect()
    }

    /// Flange agreement with the chain, and every DH frame k on chain joint k's axis (frame n on the last),
    /// its z along that axis: the two properties the error model relies on.
    fn assert_matches_chain(chain: &Chain, dh: &DhChain, seed: u64, count: usize) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut fk = Frames::new(chain);
        let n = chain.dof();
        for _ in 0..count {
            let q = random_q(chain, &mut rng);
            let (dp, dr) = pose_gap(&dh.flange_pose(&q), &kinematics::flange_pose(chain, &q));
            assert!(
                dp < 1e-9 && dr < 1e-9,
                "flange off by {dp:e} m, {dr:e} rad at {q:?}"
            );
            forward_kinematics(chain, &q, &mut fk);
            let frames = dh.frames(&q);
            assert_eq!(frames.len(), n + 1);
            let (dp, dr) = pose_gap(&(frames[n] * dh.tool), &fk.flange);
            assert!(
                dp < 1e-9 && dr < 1e-9,
                "frames[n]·tool off by {dp:e} m, {dr:e} rad"
            );
            for (k, f) in frames.iter().enumerate() {
                let j = k.min(n - 1);
                let axis = fk.axis(chain, j);
                let off = (Point3::from(f.translation.vector) - fk.anchor(j))
                    .cross(&axis)
                    .norm();
                assert!(
                    off < 1e-9,
                    "DH frame {k} origin {off:e} m off joint {j}'s axis"
                );
                let z = f.rotation * Vector3::z();
                assert!(
                    z.dot(&axis) > 1.0 - 1e-12,
                    "DH frame {k} z not along joint {j}'s axis"
                );
            }
        }
    }

    /// A URDF drawn in DH frames: body i's frame is DH frame i-1 turned by q_i, so joint i+1 sits at
    /// Tz(d_i) Tx(a_i) Rx(alpha_i) in it and the flange at the last row's transform.
    fn urdf_from_dh(name: &str, rows: &[(f64, f64, f64, bool)]) -> String {
        let mut s = format!("<?xml version=\"1.0\"?><robot name=\"{name}\"><link name=\"l0\"/>");
        let mut origin = "0 0 0".to_string();
        let mut rpy = "0 0 0".to_string();
        for (i, &(d, a, alpha, prismatic)) in rows.iter().enumerate() {
            let kind = if prismatic { "prismatic" } else { "revolute" };
            write!(
                s,
                "<link name=\"l{c}\"/><joint name=\"j{c}\" type=\"{kind}\"><parent link=\"l{i}\"/>\
                 <child link=\"l{c}\"/><origin xyz=\"{origin}\" rpy=\"{rpy}\"/><axis xyz=\"0 0 1\"/>\
                 <limit lower=\"-0.5\" upper=\"0.5\" effort=\"1\" velocity=\"1\"/></joint>",
                c = i + 1
            )
            .unwrap();
            origin = format!("{a} 0 {d}");
            rpy = format!("{alpha} 0 0");
        }
        write!(
            s,
            "<link name=\"flange\"/><joint name=\"jf\" type=\"fixed\"><parent link=\"l{}\"/>\
             <child link=\"flange\"/><origin xyz=\"{origin}\" rpy=\"{rpy}\"/></joint></robot>",
            rows.len()
        )
        .unwrap();
        s
    }

    fn assert_identity(t: &Isometry3<f64>, what: &str) {
        let (dp, dr) = pose_gap(t, &Isometry3::identity());
        assert!(dp < 1e-12 && dr < 1e-12, "{what} is not identity: {t:?}");
    }

    fn assert_table(dh: &DhChain, d: &[f64], a: &[f64], alpha: &[f64]) {
        assert_eq!(dh.rows.len(), d.len());
        for (i, r) in dh.rows.iter().enumerate() {
            assert!(
                r.theta_offset.abs() < 1e-12,
                "row {i}: theta_offset {}",
                r.theta_offset
            );
            assert!((r.d - d[i]).abs() < 1e-12, "row {i}: d {} != {}", r.d, d[i]);
            assert!((r.a - a[i]).abs() < 1e-12, "row {i}: a {} != {}", r.a, a[i]);
            assert!(
                (r.alpha - alpha[i]).abs() < 1e-12,
                "row {i}: alpha {} != {}",
                r.alpha,
                alpha[i]
            );
        }
    }

    const UR10_D: [f64; 6] = [0.1273, 0.0, 0.0, 0.163941, 0.1157, 0.0922];
    const UR10_A: [f64; 6] = [0.0, -0.612, -0.5723, 0.0, 0.0, 0.0];
    const UR10_ALPHA: [f64; 6] = [FRAC_PI_2, 0.0, 0.0, FRAC_PI_2, -FRAC_PI_2, 0.0];

    #[test]
    fn dh_of_iiwa_urdf_is_the_published_table() {
        let chain = urdf::load_file("robots/iiwa7.urdf", None).unwrap();
        let dh = DhChain::from_chain(&chain).unwrap();
        assert_table(
            &dh,
            &[0.34, 0.0, 0.40, 0.0, 0.40, 0.0, 0.126],
            &[0.0; 7],
            &[
                -FRAC_PI_2, FRAC_PI_2, FRAC_PI_2, -FRAC_PI_2, -FRAC_PI_2, FRAC_PI_2, 0.0,
            ],
        );
        assert!(dh.rows.iter().all(|r| !r.prismatic));
        assert_identity(&dh.base, "base");
        assert_identity(&dh.tool, "tool");
        let flange = dh.flange_pose(&[0.0; 7]);
        assert!((flange.translation.vector - Vector3::new(0.0, 0.0, 1.266)).norm() < 1e-12);
        assert_matches_chain(&chain, &dh, 7, 200);
    }

    #[test]
    fn dh_link_transform_is_eq_1() {
        let dh = DhChain {
            base: Isometry3::identity(),
            rows: vec![DhRow {
                theta_offset: 0.3,
                d: 0.2,
                a: -0.5,
                alpha: 0.7,
                beta: 0.0,
                prismatic: false,
            }],
            tool: Isometry3::identity(),
        };
        let (th, al) = (0.4_f64 + 0.3, 0.7_f64);
        let (st, ct, sa, ca) = (th.sin(), th.cos(), al.sin(), al.cos());
        let want = nalgebra::Matrix4::new(
            ct,
            -st * ca,
            st * sa,
            -0.5 * ct, //
            st,
            ct * ca,
            -ct * sa,
            -0.5 * st, //
            0.0,
            sa,
            ca,
            0.2, //
            0.0,
            0.0,
            0.0,
            1.0,
        );
        assert!(
            (dh.link_transform(0, 0.4).to_homogeneous() - want)
                .abs()
                .max()
                < 1e-15
        );
    }

    /// A Hayati row is the standard transform followed by Ry(β), as a matrix product.
    #[test]
    fn dh_link_transform_of_a_hayati_row_ends_with_ry_beta() {
        let row = |beta| DhRow {
            theta_offset: -0.2,
            d: 0.0,
            a: 0.4,
            alpha: 0.01,
            beta,
            prismatic: false,
        };
        let one = |r: DhRow| DhChain {
            base: Isometry3::identity(),
            rows: vec![r],
            tool: Isometry3::identity(),
        };
        let beta: f64 = 3e-4;
        let ry = nalgebra::Matrix4::new(
            beta.cos(),
            0.0,
            beta.sin(),
            0.0, //
            0.0,
            1.0,
            0.0,
            0.0, //
            -beta.sin(),
            0.0,
            beta.cos(),
            0.0, //
            0.0,
            0.0,
            0.0,
            1.0,
        );
        let want = one(row(0.0)).link_transform(0, 0.9).to_homogeneous() * ry;
        let got = one(row(beta)).link_transform(0, 0.9).to_homogeneous();
        assert!((got - want).abs().max() < 1e-15);
    }

    #[test]
    fn dh_of_ur10_drawn_in_dh_frames_is_the_published_table() {
        let rows: Vec<_> = (0..6)
            .map(|i| (UR10_D[i], UR10_A[i], UR10_ALPHA[i], false))
            .collect();
        let chain = urdf::load_str(&urdf_from_dh("ur10dh", &rows), "ur10dh", None).unwrap();
        let dh = DhChain::from_chain(&chain).unwrap();
        assert_table(&dh, &UR10_D, &UR10_A, &UR10_ALPHA);
        assert_identity(&dh.base, "base");
        assert_identity(&dh.tool, "tool");
        assert_matches_chain(&chain, &dh, 10, 100);
    }

    /// ur_description's UR10: frames not drawn as DH, shoulder offsets that cancel into d4, a base turned by
    /// π from the DH one and a flange whose x lies along the last axis.
    const UR10_URDF: &str = r#"<?xml version="1.0"?>
<robot name="ur10">
  <link name="base_link"/><link name="shoulder_link"/><link name="upper_arm_link"/><link name="forearm_link"/>
  <link name="wrist_1_link"/><link name="wrist_2_link"/><link name="wrist_3_link"/><link name="ee_link"/>
  <joint name="shoulder_pan_joint" type="revolute"><parent link="base_link"/><child link="shoulder_link"/>
    <origin xyz="0 0 0.1273" rpy="0 0 0"/><axis xyz="0 0 1"/><limit lower="-6.283" upper="6.283" effort="330" velocity="2.16"/></joint>
  <joint name="shoulder_lift_joint" type="revolute"><parent link="shoulder_link"/><child link="upper_arm_link"/>
    <origin xyz="0 0.220941 0" rpy="0 1.5707963267948966 0"/><axis xyz="0 1 0"/><limit lower="-6.283" upper="6.283" effort="330" velocity="2.16"/></joint>
  <joint name="elbow_joint" type="revolute"><parent link="upper_arm_link"/><child link="forearm_link"/>
    <origin xyz="0 -0.1719 0.612" rpy="0 0 0"/><axis xyz="0 1 0"/><limit lower="-3.1416" upper="3.1416" effort="150" velocity="3.15"/></joint>
  <joint name="wrist_1_joint" type="revolute"><parent link="forearm_link"/><child link="wrist_1_link"/>
    <origin xyz="0 0 0.5723" rpy="0 1.5707963267948966 0"/><axis xyz="0 1 0"/><limit lower="-6.283" upper="6.283" effort="54" velocity="3.2"/></joint>
  <joint name="wrist_2_joint" type="revolute"><parent link="wrist_1_link"/><child link="wrist_2_link"/>
    <origin xyz="0 0.1149 0" rpy="0 0 0"/><axis xyz="0 0 1"/><limit lower="-6.283" upper="6.283" effort="54" velocity="3.2"/></joint>
  <joint name="wrist_3_joint" type="revolute"><parent link="wrist_2_link"/><child link="wrist_3_link"/>
    <origin xyz="0 0 0.1157" rpy="0 0 0"/><axis xyz="0 1 0"/><limit lower="-6.283" upper="6.283" effort="54" velocity="3.2"/></joint>
  <joint name="ee_fixed_joint" type="fixed"><parent link="wrist_3_link"/><child link="ee_link"/>
    <origin xyz="0 0.0922 0" rpy="0 0 1.5707963267948966"/></joint>
</robot>"#;

    #[test]
    fn dh_of_ur10_description_matches_its_chain() {
        let chain = urdf::load_str(UR10_URDF, "ur10", None).unwrap();
        let dh = DhChain::from_chain(&chain).unwrap();
        // The geometry is the published one up to the frame conventions: same |a|, |d|, |alpha|.
        for (i, r) in dh.rows.iter().enumerate() {
            assert!((r.d.abs() - UR10_D[i]).abs() < 1e-12, "row {i}: d {}", r.d);
            assert!(
                (r.a.abs() - UR10_A[i].abs()).abs() < 1e-12,
                "row {i}: a {}",
                r.a
            );
            assert!(
                (r.alpha.abs() - UR10_ALPHA[i].abs()).abs() < 1e-12,
                "row {i}: alpha {}",
                r.alpha
            );
            assert!(
                r.theta_offset.abs() <= FRAC_PI_2 + 1e-12,
                "row {i}: theta {}",
                r.theta_offset
            );
        }
        // base_link's z is joint 1's axis through its origin: frame 0 is base_link.
        assert_identity(&dh.base, "base");
        // The flange sits on the last axis, so the tool only turns.
        assert!(dh.tool.translation.vector.norm() < 1e-12);
        assert_matches_chain(&chain, &dh, 11, 100);

        let mut moved = chain.clone();
        moved.base = Isometry3::from_parts(
            Translation3::new(1.0, -2.0, 0.5),
            UnitQuaternion::from_euler_angles(0.3, -0.2, 2.0),
        );
        let dh_moved = DhChain::from_chain(&moved).unwrap();
        let (dp, dr) = pose_gap(&dh_moved.base, &moved.base);
        assert!(
            dp < 1e-12 && dr < 1e-12,
            "base should follow the chain's base"
        );
        assert_matches_chain(&moved, &dh_moved, 12, 100);
    }

    /// ur_description's UR10 after a calibration: joint origins turned by 1e-4 rad, so that axes 2, 3 and 4
    /// are no longer parallel. Standard DH would put frames 2 and 3 on common normals kilometres away; the
    /// derived table has Hayati rows there (d = 0, β ≠ 0), keeps the frames on the arm and matches the chain.
    #[test]
    fn dh_of_a_skewed_ur10_has_hayati_rows_and_matches_its_chain() {
        let text = UR10_URDF
            .replace(
                "xyz=\"0 -0.1719 0.612\" rpy=\"0 0 0\"",
                "xyz=\"0 -0.1719 0.612\" rpy=\"1e-4 0 -2e-4\"",
            )
            .replace(
                "xyz=\"0 0 0.5723\" rpy=\"0 1.5707963267948966 0\"",
                "xyz=\"0 0 0.5723\" rpy=\"-1.5e-4 1.5707963267948966 0.5e-4\"",
            );
        assert_ne!(text, UR10_URDF);
        let chain = urdf::load_str(&text, "ur10 skewed", None).unwrap();
        let dh = DhChain::from_chain(&chain).unwrap();
        let hayati: Vec<usize> = (0..6).filter(|&i| dh.rows[i].beta != 0.0).collect();
        assert_eq!(hayati, [1, 2], "rows 2 and 3 join nearly parallel axes");
        for (i, r) in dh.rows.iter().enumerate() {
            assert!(r.d.abs() < 0.2 && r.a.abs() < 0.7, "row {i}: {r:?}");
            assert!(r.beta.abs() < 1e-3, "row {i}: beta {}", r.beta);
        }
        assert_eq!((dh.rows[1].d, dh.rows[2].d), (0.0, 0.0));
        // Unskewed, the same rows are standard ones: the nominal table does not change.
        let nominal =
            DhChain::from_chain(&urdf::load_str(UR10_URDF, "ur10", None).unwrap()).unwrap();
        assert!(nominal.rows.iter().all(|r| r.beta == 0.0));
        assert_matches_chain(&chain, &dh, 13, 300);
        // Serialized without `beta` where it is 0, with it where not.
        let json = serde_json::to_string(&dh).unwrap();
        assert_eq!(json.matches("\"beta\"").count(), 2, "{json}");
        let back: DhChain = serde_json::from_str(&json).unwrap();
        assert_eq!(back.rows[1].beta, dh.rows[1].beta);
    }

    /// Revolute, a prismatic joint on the same line (coincident axes), a skew revolute, a prismatic joint
    /// along an oblique axis, and a flange off the last axis.
    const PRISMATIC_URDF: &str = r#"<?xml version="1.0"?>
<robot name="mixed">
  <link name="b"/><link name="l1"/><link name="l2"/><link name="l3"/><link name="l4"/><link name="l5"/><link name="tool"/>
  <joint name="j1" type="revolute"><parent link="b"/><child link="l1"/>
    <origin xyz="0.1 -0.05 0.3" rpy="0.1 -0.2 0.3"/><axis xyz="0 0 1"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="j2" type="prismatic"><parent link="l1"/><child link="l2"/>
    <origin xyz="0 0 0.2" rpy="0 0 0.5"/><axis xyz="0 0 1"/><limit lower="-0.2" upper="0.3" effort="1" velocity="1"/></joint>
  <joint name="j3" type="revolute"><parent link="l2"/><child link="l3"/>
    <origin xyz="0.3 0.1 0" rpy="0 0 0.4"/><axis xyz="1 0 0"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="j4" type="prismatic"><parent link="l3"/><child link="l4"/>
    <origin xyz="0.2 0 0.1" rpy="0.5 0.2 -0.1"/><axis xyz="0.3 0.4 0.5"/><limit lower="-0.25" upper="0.25" effort="1" velocity="1"/></joint>
  <joint name="j5" type="revolute"><parent link="l4"/><child link="l5"/>
    <origin xyz="0 0 0.15" rpy="0 0 0"/><axis xyz="0 1 0"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="jt" type="fixed"><parent link="l5"/><child link="tool"/>
    <origin xyz="0.05 0.02 0.1" rpy="0.3 0.2 0.1"/></joint>
</robot>"#;

    #[test]
    fn dh_with_prismatic_joints_matches_its_chain() {
        let chain = urdf::load_str(PRISMATIC_URDF, "mixed", None).unwrap();
        let dh = DhChain::from_chain(&chain).unwrap();
        let kinds: Vec<bool> = dh.rows.iter().map(|r| r.prismatic).collect();
        assert_eq!(kinds, [false, true, false, true, false]);
        // j1 and j2 share a line: no common normal length, no twist.
        assert!(dh.rows[0].a.abs() < 1e-12 && dh.rows[0].alpha.abs() < 1e-12);
        assert_matches_chain(&chain, &dh, 4, 100);

        // A prismatic row slides frame i along z_{i-1} by exactly q.
        let q0 = [0.1, 0.0, -0.3, 0.05, 0.2];
        let mut q1 = q0;
        q1[3] += 0.123;
        let (f0, f1) = (dh.frames(&q0), dh.frames(&q1));
        let slide = f1[4].translation.vector - f0[4].translation.vector;
        assert!((slide - f0[3].rotation * Vector3::z() * 0.123).norm() < 1e-12);
        assert!(f1[4].rotation.angle_to(&f0[4].rotation) < 1e-12);

        // The DH-drawn prismatic table comes back as written (the last frame sits on the last axis, so
        // its a and alpha are 0 by construction).
        let rows = [
            (0.3, 0.0, FRAC_PI_2, false),
            (0.2, 0.1, -FRAC_PI_2, true),
            (0.05, 0.0, 0.0, false),
        ];
        let chain = urdf::load_str(&urdf_from_dh("rpr", &rows), "rpr", None).unwrap();
        let dh = DhChain::from_chain(&chain).unwrap();
        assert_table(
            &dh,
            &[0.3, 0.2, 0.05],
            &[0.0, 0.1, 0.0],
            &[FRAC_PI_2, -FRAC_PI_2, 0.0],
        );
        assert!(dh.rows[1].prismatic);
        assert_matches_chain(&chain, &dh, 5, 100);
    }

    /// Random geometry, with axes snapped to the frame axes half the time so that parallel, coincident
    /// and intersecting pairs occur alongside skew ones.
    #[test]
    fn dh_of_random_chains_matches_them() {
        let mut rng = ChaCha8Rng::seed_from_u64(2024);
        let snap = |rng: &mut ChaCha8Rng, v: f64| {
            if rng.random_bool(0.5) {
                (v * 2.0).round() * FRAC_PI_2 / 1.0
            } else {
                v
            }
        };
        for c in 0..60 {
            let n = rng.random_range(1..=7);
            let mut s =
                String::from("<?xml version=\"1.0\"?><robot name=\"r\"><link name=\"l0\"/>");
            let pick = |rng: &mut ChaCha8Rng, scale: f64| -> f64 {
                if rng.random_bool(0.4) {
                    0.0
                } else {
                    rng.random_range(-scale..scale)
                }
            };
            for i in 0..=n {
                let xyz: Vec<f64> = (0..3).map(|_| pick(&mut rng, 0.4)).collect();
                let rpy: Vec<f64> = (0..3)
                    .map(|_| {
                        let v = rng.random_range(-1.6..1.6);
                        snap(&mut rng, v)
                    })
                    .collect();
                let axis = match rng.random_range(0..4) {
                    0 => "1 0 0".to_string(),
                    1 => "0 1 0".to_string(),
                    2 => "0 0 -1".to_string(),
                    _ => format!(
                        "{} {} {}",
                        rng.random_range(-1.0..1.0),
                        rng.random_range(-1.0..1.0),
                        0.3
                    ),
                };
                let kind = if i == n {
                    "fixed"
                } else if rng.random_bool(0.25) {
                    "prismatic"
                } else {
                    "revolute"
                };
                write!(
                    s,
                    "<link name=\"l{c1}\"/><joint name=\"j{c1}\" type=\"{kind}\"><parent link=\"l{i}\"/>\
                     <child link=\"l{c1}\"/><origin xyz=\"{} {} {}\" rpy=\"{} {} {}\"/><axis xyz=\"{axis}\"/>\
                     <limit lower=\"-1\" upper=\"1\" effort=\"1\" velocity=\"1\"/></joint>",
                    xyz[0], xyz[1], xyz[2], rpy[0], rpy[1], rpy[2],
                    c1 = i + 1
                )
                .unwrap();
            }
            s.push_str("</robot>");
            let chain = urdf::load_str(&s, "random", None).unwrap();
            let dh = DhChain::from_chain(&chain).unwrap_or_else(|e| panic!("chain {c}: {e}\n{s}"));
            // The last row's theta follows the flange's x, not the sign rule.
            for r in &dh.rows[..n - 1] {
                assert!(
                    r.theta_offset.abs() <= FRAC_PI_2 + 1e-9,
                    "chain {c}: theta {}",
                    r.theta_offset
                );
            }
            assert_matches_chain(&chain, &dh, c, 20);
        }
    }

    #[test]
    fn dh_of_an_empty_chain_is_an_error() {
        let chain = Chain {
            name: "empty".into(),
            base: Isometry3::identity(),
            joints: Vec::new(),
            bodies: vec![Body {
                links: vec!["b".into()],
                inertial: crate::robot::Inertial::ZERO,
                colliders: Vec::new(),
            }],
            flange: Isometry3::identity(),
            flange_link: "b".into(),
        };
        assert!(matches!(
            DhChain::from_chain(&chain),
            Err(Error::Invalid(_))
        ));
    }
}
