//! The paper's generalized error parameters (§2.2, eqs. 3–8): an error transform E_i after every DH
//! transform A_i, so that the flange pose with errors is `base · Π A_i E_i · tool` (eq. 6).
//!
//! E_i is taken here as `Trans(e_i1, e_i2, e_i3) · Exp(e_i4, e_i5, e_i6)` with a rotation vector instead of
//! eq. 3's X-Y-Z Euler angles. Both agree to first order — so the Jacobian J_e at e = 0 (eq. 11), which is
//! all the per-point solve of eq. 13 uses, is the paper's — but with the rotation vector a constant rotation
//! of the last frame (a reflector nest mounted askew, DESIGN "Table 2") is exactly one value of (e_n4, e_n5,
//! e_n6), and the orientation solve of §4.3, which works in rotation vectors (eqs. 23–25), needs no Euler
//! conversion.

use nalgebra::{Isometry3, Matrix6xX, Point3, Translation3, UnitQuaternion, Vector3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::robot::chain::sample_within;
use crate::robot::dh::DhChain;

/// The three error models of §2.2.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ErrorModelKind {
    /// Eq. 7: only the rotation about each frame's z (n parameters).
    RotZ,
    /// Eq. 8: rotations about x, y, z (3n parameters).
    RotXyz,
    /// Eq. 5: translations and rotations (6n parameters).
    RotXyzTransXyz,
}

impl ErrorModelKind {
    /// The paper's component indices k of e_ik that the model lets vary.
    pub fn components(self) -> &'static [usize] {
        match self {
            ErrorModelKind::RotZ => &[6],
            ErrorModelKind::RotXyz => &[4, 5, 6],
            ErrorModelKind::RotXyzTransXyz => &[1, 2, 3, 4, 5, 6],
        }
    }

    /// The paper's spelling, for reports.
    pub fn name(self) -> &'static str {
        match self {
            ErrorModelKind::RotZ => "RotZ",
            ErrorModelKind::RotXyz => "RotXYZ",
            ErrorModelKind::RotXyzTransXyz => "RotXYZTransXYZ",
        }
    }

    /// Every parameter of the model for an n-joint chain, in the paper's order (e11, e12, …, en6).
    pub fn params(self, n: usize) -> Vec<ErrorParam> {
        (1..=n)
            .flat_map(|frame| {
                self.components()
                    .iter()
                    .map(move |&component| ErrorParam { frame, component })
            })
            .collect()
    }
}

/// One generalized error parameter e_ik. Ordered by frame, then component — the paper's order.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub struct ErrorParam {
    /// The paper's i: the error sits after A_i, in DH frame i (1..=n).
    pub frame: usize,
    /// The paper's k (1..=6): 1–3 translations along x, y, z, 4–6 rotations about them.
    pub component: usize,
}

impl ErrorParam {
    /// "e16" as in the paper; from frame 10 on a dot keeps "e10.6" apart from frame 1's "e106"-like names.
    pub fn name(&self) -> String {
        if self.frame >= 10 {
            format!("e{}.{}", self.frame, self.component)
        } else {
            format!("e{}{}", self.frame, self.component)
        }
    }
}

/// Per-frame error values, [tx, ty, tz, rx, ry, rz] for frames 1..=n (index 0 = frame 1).
pub type FrameErrors = Vec<[f64; 6]>;

/// Scatters a solved parameter vector into full per-frame errors; parameters not listed stay zero, which is
/// how a model with fewer components (or dropped parameters) is applied.
pub fn frame_errors(n: usize, params: &[ErrorParam], values: &[f64]) -> FrameErrors {
    assert_eq!(params.len(), values.len(), "one value per error parameter");
    let mut out = vec![[0.0; 6]; n];
    for (p, &v) in params.iter().zip(values) {
        assert!(
            (1..=n).contains(&p.frame) && (1..=6).contains(&p.component),
            "error parameter {p:?} outside a {n}-joint chain"
        );
        out[p.frame - 1][p.component - 1] = v;
    }
    out
}

/// E_i of every frame, `None` where its row is zero: skipping zero rows keeps e = 0 bit-identical to the
/// nominal model.
pub fn error_transforms(errors: &FrameErrors) -> Vec<Option<Isometry3<f64>>> {
    errors
        .iter()
        .map(|e| e.iter().any(|&v| v != 0.0).then(|| error_transform(e)))
        .collect()
}

/// E_i of one frame; see the module notes for why a rotation vector.
fn error_transform(e: &[f64; 6]) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(e[0], e[1], e[2]),
        UnitQuaternion::from_scaled_axis(Vector3::new(e[3], e[4], e[5])),
    )
}

/// Eq. 6, exact (not linearized), so that corrected poses and simulated "true" robots are consistent with
/// the parametrization rather than with its first-order approximation.
pub fn flange_pose_with_errors(dh: &DhChain, q: &[f64], errors: &FrameErrors) -> Isometry3<f64> {
    let n = dh.dof();
    assert_eq!(
        q.len(),
        n,
        "configuration length must equal the chain's dof"
    );
    let links = q
        .iter()
        .enumerate()
        .map(|(i, &qi)| dh.link_transform(i, qi));
    flange_pose_with_errors_on(dh, links, errors)
}

/// [`flange_pose_with_errors`] from the link transforms `A_i(q_i)` (a [`ChainPose`](crate::robot::dh::ChainPose)'s): the same products in
/// the same order, so the same bits.
pub fn flange_pose_with_errors_on(
    dh: &DhChain,
    links: impl Iterator<Item = Isometry3<f64>>,
    errors: &FrameErrors,
) -> Isometry3<f64> {
    assert_eq!(errors.len(), dh.dof(), "one error row per DH frame");
    let mut pose = dh.base;
    for (link, e) in links.zip(errors) {
        pose *= link;
        // Skipping zero rows keeps e = 0 bit-identical to the nominal model.
        if e.iter().any(|&v| v != 0.0) {
            pose *= error_transform(e);
        }
    }
    pose * dh.tool
}

/// J_e at e = 0 (eq. 11) for a point fixed in the flange frame: 6 × P, rows 0..3 the point's displacement,
/// rows 3..6 the flange's small rotation (world frame), one column per param in `params` order.
///
/// Since E_i sits after A_i, a perturbation acts in DH frame i's coordinates: with F_i = (R_i, o_i) that
/// frame's world pose, the flange moves by F_i · E_i · F_i⁻¹. A translation along axis k of frame i thus
/// shifts the point by R_i e_k; a rotation about axis k of frame i (through o_i) turns everything by
/// u = R_i e_k, moving the point by u × (p − o_i). Analytic and from one pass over the frames, since it is
/// evaluated for every measured point.
pub fn error_jacobian(
    dh: &DhChain,
    q: &[f64],
    point: &Point3<f64>,
    params: &[ErrorParam],
) -> Matrix6xX<f64> {
    error_jacobian_on(dh, &dh.frames(q), point, params)
}

/// [`error_jacobian`] on the DH frames of the configuration (`dh.frames(q)`), which a caller may need too.
pub fn error_jacobian_on(
    dh: &DhChain,
    frames: &[Isometry3<f64>],
    point: &Point3<f64>,
    params: &[ErrorParam],
) -> Matrix6xX<f64> {
    let n = dh.dof();
    let p = frames[n] * dh.tool * point;
    let mut j = Matrix6xX::zeros(params.len());
    for (c, prm) in params.iter().enumerate() {
        assert!(
            (1..=n).contains(&prm.frame) && (1..=6).contains(&prm.component),
            "error parameter {prm:?} outside a {n}-joint chain"
        );
        let f = &frames[prm.frame];
        let k = (prm.component - 1) % 3;
        let u = f.rotation * Vector3::ith(k, 1.0);
        let mut col = j.column_mut(c);
        if prm.component <= 3 {
            col.fixed_rows_mut::<3>(0).copy_from(&u);
        } else {
            let lever = p - Point3::from(f.translation.vector);
            col.fixed_rows_mut::<3>(0).copy_from(&u.cross(&lever));
            col.fixed_rows_mut::<3>(3).copy_from(&u);
        }
    }
    j
}

/// Which parameters act on what (§4.2–4.3).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct ParamSelection {
    pub kind: ErrorModelKind,
    /// Parameters that move the flange origin in some configuration: the unknowns of the position solve.
    pub position: Vec<ErrorParam>,
    /// Parameters that never move the flange origin but do turn the flange: the unknowns of the orientation
    /// solve.
    pub orientation_only: Vec<ErrorParam>,
}

/// Configurations sampled by [`select_params`]: a parameter that acts at all acts in almost every
/// configuration, so a few dozen already decide; more only cost a little once per calibration.
const SELECT_SAMPLES: usize = 64;
/// Fixed so the selection — and with it the shape of every regression — is the same in every run.
const SELECT_SEED: u64 = 0x5e1ec7;
/// A column whose norm stays below this fraction of the largest one is rounding noise, not an effect.
const VANISH_REL: f64 = 1e-9;

/// Finds the parameters numerically (DESIGN: columns of J_e that vanish over many configurations) rather
/// than from the paper's lists, so that any URDF robot gets its own. Decided at the flange origin, as the
/// paper does: an off-axis reflector would be moved by every parameter.
pub fn select_params(
    dh: &DhChain,
    lower: &[f64],
    upper: &[f64],
    kind: ErrorModelKind,
) -> ParamSelection {
    let n = dh.dof();
    assert!(
        lower.len() == n && upper.len() == n,
        "one limit pair per joint"
    );
    let params = kind.params(n);
    let mut rng = ChaCha8Rng::seed_from_u64(SELECT_SEED);
    let mut pos_max = vec![0.0_f64; params.len()];
    let mut rot_max = vec![0.0_f64; params.len()];
    let origin = Point3::origin();
    let mut q = vec![0.0; n];
    for _ in 0..SELECT_SAMPLES {
        for (qi, (&lo, &hi)) in q.iter_mut().zip(lower.iter().zip(upper)) {
            *qi = sample_within(lo, hi, &mut rng);
        }
        let j = error_jacobian(dh, &q, &origin, &params);
        for c in 0..params.len() {
            let col = j.column(c);
            pos_max[c] = pos_max[c].max(col.fixed_rows::<3>(0).norm());
            rot_max[c] = rot_max[c].max(col.fixed_rows::<3>(3).norm());
        }
    }
    let pos_tol = VANISH_REL * pos_max.iter().copied().fold(0.0, f64::max);
    let rot_tol = VANISH_REL * rot_max.iter().copied().fold(0.0, f64::max);
    let mut position = Vec::new();
    let mut orientation_only = Vec::new();
    for (c, &prm) in params.iter().enumerate() {
        if pos_max[c] > pos_tol {
            position.push(prm);
        } else if rot_max[c] > rot_tol {
            orientation_only.push(prm);
        }
    }
    ParamSelection {
        kind,
        position,
        orientation_only,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robot::{Chain, urdf};
    use rand::Rng;

    fn iiwa() -> (Chain, DhChain) {
        let chain = urdf::load_file("robots/iiwa7.urdf", None).unwrap();
        let dh = DhChain::from_chain(&chain).unwrap();
        (chain, dh)
    }

    fn limits(chain: &Chain) -> (Vec<f64>, Vec<f64>) {
        (
            chain.joints.iter().map(|j| j.lower).collect(),
            chain.joints.iter().map(|j| j.upper).collect(),
        )
    }

    fn random_q(lower: &[f64], upper: &[f64], rng: &mut ChaCha8Rng) -> Vec<f64> {
        lower
            .iter()
            .zip(upper)
            .map(|(&lo, &hi)| rng.random_range(lo..hi))
            .collect()
    }

    fn p(frame: usize, component: usize) -> ErrorParam {
        ErrorParam { frame, component }
    }

    #[test]
    fn names_and_kinds() {
        assert_eq!(p(1, 6).name(), "e16");
        assert_eq!(p(10, 6).name(), "e10.6");
        assert_eq!(ErrorModelKind::RotXyz.name(), "RotXYZ");
        assert_eq!(ErrorModelKind::RotXyzTransXyz.params(7).len(), 42);
        assert_eq!(
            serde_json::to_string(&ErrorModelKind::RotXyzTransXyz).unwrap(),
            "\"rot-xyz-trans-xyz\""
        );
        let fe = frame_errors(3, &[p(2, 5), p(3, 1)], &[0.1, -0.2]);
        assert_eq!(
            fe,
            vec![
                [0.0; 6],
                [0.0, 0.0, 0.0, 0.0, 0.1, 0.0],
                [-0.2, 0.0, 0.0, 0.0, 0.0, 0.0]
            ]
        );
    }

    /// §4.2–4.3's counts and lists for the LBR iiwa, found from the URDF alone.
    #[test]
    fn iiwa_selection_is_the_papers() {
        let (chain, dh) = iiwa();
        let (lo, hi) = limits(&chain);
        let wrist = vec![p(6, 6), p(7, 4), p(7, 5), p(7, 6)];
        for (kind, count, dropped) in [
            (ErrorModelKind::RotZ, 5, vec![p(6, 6), p(7, 6)]),
            (ErrorModelKind::RotXyz, 17, wrist.clone()),
            (ErrorModelKind::RotXyzTransXyz, 38, wrist.clone()),
        ] {
            let sel = select_params(&dh, &lo, &hi, kind);
            assert_eq!(sel.kind, kind);
            assert_eq!(sel.position.len(), count, "{}", kind.name());
            let missing: Vec<_> = kind
                .params(7)
                .into_iter()
                .filter(|x| !sel.position.contains(x))
                .collect();
            assert_eq!(missing, dropped, "{}", kind.name());
            assert_eq!(sel.orientation_only, dropped, "{}", kind.name());
            assert_eq!(sel, select_params(&dh, &lo, &hi, kind), "deterministic");
        }
    }

    /// Central differences of the exact model, position of an off-axis point and orientation as the
    /// rotation vector of R(e+h)·R(e−h)ᵀ.
    #[test]
    fn jacobian_matches_finite_differences() {
        let (chain, dh) = iiwa();
        let (lo, hi) = limits(&chain);
        let params = ErrorModelKind::RotXyzTransXyz.params(7);
        let point = Point3::new(0.03, -0.02, 0.05);
        let h = 1e-6;
        let mut rng = ChaCha8Rng::seed_from_u64(17);
        let mut worst = 0.0_f64;
        for _ in 0..25 {
            let q = random_q(&lo, &hi, &mut rng);
            let j = error_jacobian(&dh, &q, &point, &params);
            for (c, &prm) in params.iter().enumerate() {
                let at = |v: f64| flange_pose_with_errors(&dh, &q, &frame_errors(7, &[prm], &[v]));
                let (plus, minus) = (at(h), at(-h));
                let dp = ((plus * point) - (minus * point)) / (2.0 * h);
                let dr = (plus.rotation * minus.rotation.inverse()).scaled_axis() / (2.0 * h);
                let col = j.column(c);
                let scale = 1.0 + col.norm();
                let err = (col.fixed_rows::<3>(0) - dp)
                    .norm()
                    .max((col.fixed_rows::<3>(3) - dr).norm())
                    / scale;
                worst = worst.max(err);
                assert!(err <= 1e-7, "{} at {q:?}: off by {err:e}", prm.name());
            }
        }
        assert!(worst > 0.0, "finite differences should show some noise");
    }

    #[test]
    fn zero_errors_are_the_nominal_pose() {
        let (chain, dh) = iiwa();
        let (lo, hi) = limits(&chain);
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for _ in 0..20 {
            let q = random_q(&lo, &hi, &mut rng);
            assert_eq!(
                flange_pose_with_errors(&dh, &q, &vec![[0.0; 6]; 7]),
                dh.flange_pose(&q)
            );
        }
    }

    /// A reflector nest turned against the flange is exactly E_7's rotation, not only to first order.
    #[test]
    fn constant_last_frame_rotation_is_exact() {
        let (chain, mut dh) = iiwa();
        dh.tool = Isometry3::identity();
        let (lo, hi) = limits(&chain);
        let r = Vector3::new(0.03, -0.02, 0.22);
        let errors = frame_errors(7, &[p(7, 4), p(7, 5), p(7, 6)], &[r.x, r.y, r.z]);
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        for _ in 0..20 {
            let q = random_q(&lo, &hi, &mut rng);
            let got = flange_pose_with_errors(&dh, &q, &errors);
            let want = dh.flange_pose(&q) * UnitQuaternion::from_scaled_axis(r);
            assert!((got.translation.vector - want.translation.vector).norm() < 1e-14);
            assert!(got.rotation.angle_to(&want.rotation) < 1e-14);
        }
    }

    /// Eq. 22's first equivalence, e22 = e13 (α_2 = +π/2 in the iiwa table): identical position columns, so
    /// the position solve cannot tell them apart.
    #[test]
    fn e22_and_e13_are_indistinguishable() {
        let (chain, dh) = iiwa();
        assert!((dh.rows[1].alpha - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        let (lo, hi) = limits(&chain);
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        for _ in 0..20 {
            let q = random_q(&lo, &hi, &mut rng);
            let j = error_jacobian(&dh, &q, &Point3::origin(), &[p(2, 2), p(1, 3)]);
            let (a, b) = (j.fixed_view::<3, 1>(0, 0), j.fixed_view::<3, 1>(0, 1));
            assert!((b.norm() - 1.0).abs() < 1e-12);
            assert!((a - b).norm() < 1e-12, "e22 {a:?} vs e13 {b:?}");
        }
    }
}

/// SO(3)'s left Jacobian of the rotation vector `r`: `Exp(r + dr) = Exp(J_l(r)·dr)·Exp(r)` to first order in
/// `dr`, so that derivatives at non-zero rotation errors stay exact.
pub fn so3_left_jacobian(r: &Vector3<f64>) -> nalgebra::Matrix3<f64> {
    let theta2 = r.norm_squared();
    let (a, b) = if theta2 < 1e-8 {
        // Series to the order that keeps ~1e-17 relative error at θ ≤ 1e-4.
        (0.5 - theta2 / 24.0, 1.0 / 6.0 - theta2 / 120.0)
    } else {
        let theta = theta2.sqrt();
        (
            (1.0 - theta.cos()) / theta2,
            (theta - theta.sin()) / (theta2 * theta),
        )
    };
    let k = r.cross_matrix();
    nalgebra::Matrix3::identity() + k * a + k * k * b
}

/// The frames of eq. 6 with errors, for derivatives at non-zero errors: `before[i]` is DH frame i + 1 before
/// its error transform (`F_i · A_{i+1}`), `after[i]` the frame F_i after it (`after[0]` is the base frame 0),
/// all in the world frame. Joint i + 1 turns about the z axis of `after[i]`.
#[derive(Clone, Debug)]
pub struct ErrorFrames {
    pub before: Vec<Isometry3<f64>>,
    pub after: Vec<Isometry3<f64>>,
    pub flange: Isometry3<f64>,
}

impl ErrorFrames {
    pub fn new(dh: &DhChain, q: &[f64], errors: &FrameErrors) -> ErrorFrames {
        let n = dh.dof();
        assert_eq!(
            q.len(),
            n,
            "configuration length must equal the chain's dof"
        );
        assert_eq!(errors.len(), n, "one error row per DH frame");
        let mut frames = ErrorFrames {
            before: Vec::with_capacity(n),
            after: Vec::with_capacity(n + 1),
            flange: Isometry3::identity(),
        };
        let links = q
            .iter()
            .enumerate()
            .map(|(i, &qi)| dh.link_transform(i, qi));
        frames.rebuild(dh, links, &error_transforms(errors));
        frames
    }

    /// The frames again, in place, from the link transforms `A_i(q_i)` and the error transforms of
    /// [`error_transforms`]: what a fit evaluating many points at one set of errors computes once (the error
    /// transforms) or once per point for all fits (the link transforms at fixed joint angles). The same
    /// products in the same order as [`ErrorFrames::new`], so the same bits.
    pub fn rebuild(
        &mut self,
        dh: &DhChain,
        links: impl Iterator<Item = Isometry3<f64>>,
        transforms: &[Option<Isometry3<f64>>],
    ) {
        self.before.clear();
        self.after.clear();
        let mut pose = dh.base;
        self.after.push(pose);
        for (link, e) in links.zip(transforms) {
            pose *= link;
            self.before.push(pose);
            if let Some(e) = e {
                pose *= e;
            }
            self.after.push(pose);
        }
        self.flange = pose * dh.tool;
    }

    /// d(point, flange rotation)/d e_ik at the errors the frames were built with, for a world point `p` fixed
    /// to the flange: [linear; angular]. The rotation part uses [`so3_left_jacobian`] of frame i's rotation
    /// error, so the column is exact, not only at e = 0.
    pub fn error_column(
        &self,
        errors: &FrameErrors,
        prm: ErrorParam,
        p: &Point3<f64>,
    ) -> nalgebra::Vector6<f64> {
        let g = &self.before[prm.frame - 1];
        let e = &errors[prm.frame - 1];
        let k = (prm.component - 1) % 3;
        let mut col = nalgebra::Vector6::zeros();
        if prm.component <= 3 {
            col.fixed_rows_mut::<3>(0)
                .copy_from(&(g.rotation * Vector3::ith(k, 1.0)));
        } else {
            let r = Vector3::new(e[3], e[4], e[5]);
            let u = g.rotation * so3_left_jacobian(&r).column(k).into_owned();
            let centre = g * Point3::new(e[0], e[1], e[2]);
            col.fixed_rows_mut::<3>(0)
                .copy_from(&u.cross(&(p - centre)));
            col.fixed_rows_mut::<3>(3).copy_from(&u);
        }
        col
    }

    /// d(point, flange rotation)/d q_j (j from 0) of the chain with errors, for a world point `p` fixed to the
    /// flange.
    pub fn joint_column(&self, dh: &DhChain, j: usize, p: &Point3<f64>) -> nalgebra::Vector6<f64> {
        let f = &self.after[j];
        let (lin, ang) = crate::robot::kinematics::joint_column(
            &(f.rotation * Vector3::z()),
            &Point3::from(f.translation.vector),
            p,
            dh.rows[j].prismatic,
        );
        nalgebra::Vector6::new(lin.x, lin.y, lin.z, ang.x, ang.y, ang.z)
    }
}

/// [`error_jacobian`] at non-zero errors `errors`: the same layout, exact for the parametrization of
/// [`flange_pose_with_errors`] (a rotation error's column accounts for the rotation already there).
pub fn error_jacobian_at(
    dh: &DhChain,
    q: &[f64],
    point: &Point3<f64>,
    errors: &FrameErrors,
    params: &[ErrorParam],
) -> Matrix6xX<f64> {
    let n = dh.dof();
    let frames = ErrorFrames::new(dh, q, errors);
    let p = frames.flange * point;
    let mut j = Matrix6xX::zeros(params.len());
    for (c, prm) in params.iter().enumerate() {
        assert!(
            (1..=n).contains(&prm.frame) && (1..=6).contains(&prm.component),
            "error parameter {prm:?} outside a {n}-joint chain"
        );
        j.set_column(c, &frames.error_column(errors, *prm, &p));
    }
    j
}
