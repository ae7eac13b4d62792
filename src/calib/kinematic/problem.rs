//! The least-squares problem shared by the structural analysis, the rank check and Levenberg–Marquardt: the
//! residuals of the measured points and their analytic Jacobian at the current estimate.

use nalgebra::{
    DMatrix, DVector, Isometry3, Matrix3, Point3, Quaternion, Translation3, UnitQuaternion, Vector3,
};

use super::params::{Param, State};
use crate::calib::error_model::{ErrorFrames, error_transforms, so3_left_jacobian};
use crate::robot::dh::DhChain;

/// What the model knows about each fitted point.
pub(super) struct Point {
    /// The measured point, base frame of the initial registration.
    pub(super) y: Point3<f64>,
    /// The measured flange orientation, same frame (nests).
    pub(super) orientation: Option<UnitQuaternion<f64>>,
    /// Gravity torques at the commanded angles (elastic only; empty otherwise).
    pub(super) tau: Vec<f64>,
    /// The link transforms `A_i(q_i)` at the commanded angles, computed once for every evaluation (a
    /// compliance's deflection turns them by [`deflected`]).
    links: Vec<Isometry3<f64>>,
}

impl Point {
    #[cfg(test)]
    pub(super) fn new(
        dh: &DhChain,
        q: &[f64],
        y: Point3<f64>,
        orientation: Option<UnitQuaternion<f64>>,
        tau: Vec<f64>,
    ) -> Point {
        let links = q
            .iter()
            .enumerate()
            .map(|(i, &qi)| dh.link_transform(i, qi))
            .collect();
        Point::with_links(links, y, orientation, tau)
    }

    /// [`Point::new`] with its link transforms `A_i(q_i)` already computed (a [`ChainPose`]'s, whose frames
    /// also served the registration and the gravity torques): the same point, one pass over the chain fewer.
    ///
    /// [`ChainPose`]: crate::robot::dh::ChainPose
    pub(super) fn with_links(
        links: Vec<Isometry3<f64>>,
        y: Point3<f64>,
        orientation: Option<UnitQuaternion<f64>>,
        tau: Vec<f64>,
    ) -> Point {
        Point {
            y,
            orientation,
            tau,
            links,
        }
    }

    /// The chain's frames with errors at this point into `frames`: its link transforms, each deflected by
    /// its compliance times its gravity torque where those are fitted, with the error transforms
    /// `transforms` ([`error_transforms`]).
    pub(super) fn frames_into(
        &self,
        dh: &DhChain,
        compliance: &[f64],
        transforms: &[Option<Isometry3<f64>>],
        frames: &mut ErrorFrames,
    ) {
        if self.tau.is_empty() {
            frames.rebuild(dh, self.links.iter().copied(), transforms);
        } else {
            let links = self
                .links
                .iter()
                .zip(&self.tau)
                .zip(compliance)
                .zip(&dh.rows)
                .map(|(((a, t), c), row)| deflected(a, c * t, row.prismatic));
            frames.rebuild(dh, links, transforms);
        }
    }
}

/// `A_i(q_i + δ)` from `A_i(q_i)`: a DH row is `Rz(θ)·Tz(d)·Tx(a)·Rx(α)` (then a Hayati row's `Ry(β)`), and
/// a joint moves its first factors — a revolute one `Rz(θ)`, with `Rz(θ + δ) = Rz(δ)·Rz(θ)`, a prismatic
/// one `Tz(d)`, which commutes with `Rz(θ)` — so the deflection multiplies the link on the left. The
/// elastic fit's angles then take no sine or cosine per point and evaluation: the same transform as
/// [`DhChain::link_transform`] at `q_i + δ`, to rounding.
fn deflected(link: &Isometry3<f64>, delta: f64, prismatic: bool) -> Isometry3<f64> {
    if prismatic {
        return Translation3::new(0.0, 0.0, delta) * link;
    }
    let (s, c) = half_sin_cos(delta);
    Isometry3::from_parts(
        Translation3::identity(),
        UnitQuaternion::new_unchecked(Quaternion::new(c, 0.0, 0.0, s)),
    ) * link
}

/// `sin(δ/2)` and `cos(δ/2)`; by their Taylor series where `|δ/2| < 0.01` (a deflection is a few
/// milliradians), whose next terms (`x⁹/9!`, `x¹⁰/10!`) are below 1e-21 of the sum: the library's values
/// to rounding, without its argument reduction.
fn half_sin_cos(delta: f64) -> (f64, f64) {
    let x = 0.5 * delta;
    if x.abs() >= 0.01 {
        return x.sin_cos();
    }
    let x2 = x * x;
    let sin = x * (1.0 - x2 / 6.0 * (1.0 - x2 / 20.0 * (1.0 - x2 / 42.0)));
    let cos = 1.0 - x2 / 2.0 * (1.0 - x2 / 12.0 * (1.0 - x2 / 30.0 * (1.0 - x2 / 56.0)));
    (sin, cos)
}

/// RMS of the 3-D position residual of `state` over `points` (m).
pub(super) fn rms(dh: &DhChain, state: &State, points: &[Point]) -> f64 {
    let transforms = error_transforms(&state.errors);
    let rot = UnitQuaternion::from_scaled_axis(state.rho);
    let mut frames = empty_frames(dh);
    let sum: f64 = points
        .iter()
        .map(|pt| {
            pt.frames_into(dh, &state.compliance, &transforms, &mut frames);
            let p = frames.flange * state.mount;
            let v = rot * pt.y.coords + state.t;
            (p.coords - v).norm_squared()
        })
        .sum();
    (sum / points.len() as f64).sqrt()
}

/// The problem shared by the structural analysis, the rank check and Levenberg–Marquardt.
pub(super) struct Problem<'a> {
    pub(super) dh: &'a DhChain,
    pub(super) points: Vec<Point>,
    /// Rotation residual weight (m/rad), `Some` when orientations are fitted.
    pub(super) length: Option<f64>,
    pub(super) base: State,
    pub(super) params: Vec<Param>,
}

impl Problem<'_> {
    pub(super) fn rows(&self) -> usize {
        self.points
            .iter()
            .map(|p| if self.fits_rotation(p) { 6 } else { 3 })
            .sum()
    }

    fn fits_rotation(&self, p: &Point) -> bool {
        self.length.is_some() && p.orientation.is_some()
    }

    /// Residuals (predicted − measured) and, when asked, the Jacobian, at `values` of the kept parameters.
    pub(super) fn evaluate(
        &self,
        values: &[f64],
        jacobian: bool,
    ) -> (DVector<f64>, Option<DMatrix<f64>>) {
        let mut r = DVector::zeros(0);
        let mut j = jacobian.then(|| DMatrix::zeros(0, 0));
        self.evaluate_into(values, &mut r, j.as_mut());
        (r, j)
    }

    /// [`Problem::evaluate`] into `r` and `j` (resized where their shapes differ; every entry written), so
    /// that Levenberg–Marquardt's iterations reuse them. Each point's rows are written parameter by
    /// parameter straight into the buffer, the parameters decoded once per evaluation.
    pub(super) fn evaluate_into(
        &self,
        values: &[f64],
        r: &mut DVector<f64>,
        mut j: Option<&mut DMatrix<f64>>,
    ) {
        let s = State::with(&self.base, &self.params, values);
        self.shape(r, j.as_deref_mut());
        let rot = UnitQuaternion::from_scaled_axis(s.rho);
        let jl_rho = so3_left_jacobian(&s.rho);
        // Per frame, the left Jacobian of its rotation error (it does not depend on the configuration), and
        // per point the world axes of each frame's translation and rotation errors and the rotation centre.
        let jl_errors: Vec<Matrix3<f64>> = s
            .errors
            .iter()
            .map(|e| so3_left_jacobian(&Vector3::new(e[3], e[4], e[5])))
            .collect();
        let transforms = error_transforms(&s.errors);
        let mut axes: Vec<Axes> = vec![Axes::default(); s.errors.len()];
        let mut frames = empty_frames(self.dh);
        let fitted = self.fitted_frames(s.errors.len());
        let columns: Vec<Column> = self.params.iter().map(|&p| Column::of(p)).collect();
        let mut row = 0;
        for pt in &self.points {
            pt.frames_into(self.dh, &s.compliance, &transforms, &mut frames);
            let p = frames.flange * s.mount;
            let v = rot * pt.y.coords;
            r.fixed_rows_mut::<3>(row).copy_from(&(p.coords - v - s.t));
            // Rotation residual and the map of a world rotation of the flange (or of the measurement) into it.
            let rotation = match (self.length, pt.orientation) {
                (Some(l), Some(meas)) => {
                    let measured = rot * meas;
                    let phi = (frames.flange.rotation * measured.inverse()).scaled_axis();
                    r.fixed_rows_mut::<3>(row + 3).copy_from(&(phi * l));
                    let inv = |m: Matrix3<f64>| m.try_inverse().unwrap_or_else(Matrix3::identity);
                    Some((
                        l,
                        inv(so3_left_jacobian(&phi)),
                        inv(so3_left_jacobian(&-phi)),
                    ))
                }
                _ => None,
            };
            let rows = if rotation.is_some() { 6 } else { 3 };
            if let Some(jm) = j.as_mut() {
                for (i, ((g, e), jl)) in frames
                    .before
                    .iter()
                    .zip(&s.errors)
                    .zip(&jl_errors)
                    .enumerate()
                    .filter(|(i, _)| fitted[*i])
                {
                    let r = g.rotation.to_rotation_matrix().into_inner();
                    let centre = g * Point3::new(e[0], e[1], e[2]);
                    axes[i] = Axes {
                        translation: r,
                        rotation: r * jl,
                        lever: p - centre,
                    };
                }
                let at = AtPoint {
                    v_cross: v.cross_matrix(),
                    p,
                    frames: &frames,
                    axes: &axes,
                    rotation: &rotation,
                    tau: &pt.tau,
                };
                let m = jm.nrows();
                let data = jm.as_mut_slice();
                for (c, col) in columns.iter().enumerate() {
                    let start = c * m + row;
                    self.write_column(*col, &jl_rho, &at, &mut data[start..start + rows]);
                }
            }
            row += rows;
        }
    }

    /// Per error frame (of `n`), whether any of its errors is fitted: only those frames' axes are needed.
    fn fitted_frames(&self, n: usize) -> Vec<bool> {
        let mut fitted = vec![false; n];
        for prm in &self.params {
            if let Param::Error(e) = prm {
                fitted[e.frame - 1] = true;
            }
        }
        fitted
    }

    /// `r` and `j` resized to the problem's rows and parameters where they differ.
    fn shape(&self, r: &mut DVector<f64>, j: Option<&mut DMatrix<f64>>) {
        let (m, k) = (self.rows(), self.params.len());
        if r.len() != m {
            *r = DVector::zeros(m);
        }
        if let Some(j) = j
            && j.shape() != (m, k)
        {
            *j = DMatrix::zeros(m, k);
        }
    }

    /// The column of one parameter at one point, written into its residual rows `dst`: [linear; angular]
    /// (the angular part only where the point's orientation is fitted).
    fn write_column(&self, col: Column, jl_rho: &Matrix3<f64>, at: &AtPoint, dst: &mut [f64]) {
        let (lin, ang) = match col {
            Column::TrackerRotation(k) => {
                let lin = at.v_cross * jl_rho.column(k);
                let ang = match at.rotation {
                    Some((l, _, jr_inv)) => -(jr_inv * jl_rho.column(k)) * *l,
                    None => Vector3::zeros(),
                };
                (lin, ang)
            }
            Column::TrackerTranslation(k) => (-Vector3::ith(k, 1.0), Vector3::zeros()),
            Column::Mounting(k) => (
                at.frames.flange.rotation * Vector3::ith(k, 1.0),
                Vector3::zeros(),
            ),
            Column::ErrorTranslation(f, k) => {
                let lin = at.axes[f].translation.column(k).into_owned();
                flange_column(lin, Vector3::zeros(), at.rotation)
            }
            Column::ErrorRotation(f, k) => {
                let a = &at.axes[f];
                let u = a.rotation.column(k).into_owned();
                flange_column(u.cross(&a.lever), u, at.rotation)
            }
            Column::Compliance(jt) => {
                let col = at.frames.joint_column(self.dh, jt, &at.p) * at.tau[jt];
                flange_column(
                    col.fixed_rows::<3>(0).into_owned(),
                    col.fixed_rows::<3>(3).into_owned(),
                    at.rotation,
                )
            }
        };
        dst[..3].copy_from_slice(lin.as_slice());
        if dst.len() == 6 {
            dst[3..].copy_from_slice(ang.as_slice());
        }
    }
}

/// How a parameter's column is made, decoded once per evaluation: its kind, and the frame (from 0) and
/// axis, or the joint, it acts on.
#[derive(Clone, Copy)]
enum Column {
    TrackerRotation(usize),
    TrackerTranslation(usize),
    Mounting(usize),
    ErrorTranslation(usize, usize),
    ErrorRotation(usize, usize),
    Compliance(usize),
}

impl Column {
    fn of(prm: Param) -> Column {
        match prm {
            Param::TrackerRotation(k) | Param::BaseRotation(k) => Column::TrackerRotation(k),
            Param::TrackerTranslation(k) | Param::BaseTranslation(k) => {
                Column::TrackerTranslation(k)
            }
            Param::Mounting(k) => Column::Mounting(k),
            Param::Error(e) if e.component <= 3 => {
                Column::ErrorTranslation(e.frame - 1, e.component - 1)
            }
            Param::Error(e) => Column::ErrorRotation(e.frame - 1, e.component - 4),
            Param::Compliance(jt) => Column::Compliance(jt),
        }
    }
}

/// Per fitted frame at one point: the world axes of its translation errors, those of its rotation errors
/// (through the rotation error's left Jacobian), and the predicted point's lever about its rotation centre.
#[derive(Clone, Default)]
struct Axes {
    translation: Matrix3<f64>,
    rotation: Matrix3<f64>,
    lever: Vector3<f64>,
}

/// The frames before any point is placed in them.
fn empty_frames(dh: &DhChain) -> ErrorFrames {
    ErrorFrames {
        before: Vec::with_capacity(dh.dof()),
        after: Vec::with_capacity(dh.dof() + 1),
        flange: dh.base,
    }
}

/// What a point's Jacobian columns are made of: the measured point turned by the tracker-frame rotation,
/// the predicted point, the frames with errors, per frame its error axes and rotation centre, the rotation
/// residual's weight and maps, the gravity torques.
struct AtPoint<'a> {
    /// The cross-product matrix of the measured point turned by the tracker-frame rotation.
    v_cross: Matrix3<f64>,
    p: Point3<f64>,
    frames: &'a ErrorFrames,
    axes: &'a [Axes],
    rotation: &'a Option<(f64, Matrix3<f64>, Matrix3<f64>)>,
    tau: &'a [f64],
}

/// A column of the flange's linear and world angular motion as residual rows: the angular part mapped
/// through the rotation residual's inverse left Jacobian and weighted (read only where it is fitted).
fn flange_column(
    lin: Vector3<f64>,
    ang: Vector3<f64>,
    rotation: &Option<(f64, Matrix3<f64>, Matrix3<f64>)>,
) -> (Vector3<f64>, Vector3<f64>) {
    match rotation {
        Some((l, jl_inv, _)) => (lin, jl_inv * ang * *l),
        None => (lin, ang),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calib::kinematic::gravity::GravityModel;
    use crate::calib::kinematic::params::candidates;
    use crate::robot::Payload;
    use crate::robot::urdf;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// A link deflected on the left is the link at the deflected angle, revolute and prismatic, through the
    /// series (small deflections) and through the library's sine (large ones).
    #[test]
    fn deflected_link_is_the_link_at_the_deflected_angle() {
        let chain = urdf::load_file("robots/iiwa7.urdf", None).unwrap();
        let mut dh = DhChain::from_chain(&chain).unwrap();
        dh.rows[2].a = 0.05;
        dh.rows[4].beta = 0.01;
        dh.rows[5].prismatic = true;
        for i in [0, 2, 4, 5] {
            for (q, delta) in [(0.3, 1e-9), (-1.2, 3e-4), (2.0, -0.0199), (0.7, 0.5)] {
                let want = dh.link_transform(i, q + delta);
                let got = deflected(&dh.link_transform(i, q), delta, dh.rows[i].prismatic);
                let off = (got.to_homogeneous() - want.to_homogeneous()).abs().max();
                assert!(off < 1e-15, "row {i}, q {q}, δ {delta}: off by {off:e}");
            }
        }
    }

    /// The analytic Jacobian of every candidate, at a state far from zero (so the e = 0 formulas would be
    /// wrong), against central differences of the residuals; position and nest orientation rows, compliances.
    #[test]
    fn jacobian_matches_finite_differences() {
        let chain = urdf::load_file("robots/iiwa7.urdf", None).unwrap();
        let dh = DhChain::from_chain(&chain).unwrap();
        let gravity = GravityModel::new(&chain, &dh, Payload::NONE).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let points: Vec<Point> = (0..6)
            .map(|i| {
                let q: Vec<f64> = chain
                    .joints
                    .iter()
                    .map(|j| rng.random_range(j.lower..j.upper))
                    .collect();
                let f = dh.flange_pose(&q);
                let tau = gravity.torques(&dh, &q);
                Point::new(
                    &dh,
                    &q,
                    f * Point3::new(0.01, 0.02, 0.05),
                    (i % 2 == 0)
                        .then(|| UnitQuaternion::from_euler_angles(0.01, 0.02, 0.03) * f.rotation),
                    tau,
                )
            })
            .collect();
        let params = candidates(7, true);
        let setup = Problem {
            dh: &dh,
            points,
            length: Some(0.05),
            base: State::initial(7, Point3::new(0.0, 0.0, 0.03)),
            params: params.clone(),
        };
        let x: Vec<f64> = params
            .iter()
            .map(|p| match p {
                Param::Compliance(_) => rng.random_range(1e-4..1e-3),
                Param::Mounting(k) => [0.01, 0.02, 0.05][*k],
                _ => rng.random_range(-0.05..0.05),
            })
            .collect();
        let (_, j) = setup.evaluate(&x, true);
        let j = j.unwrap();
        for (c, p) in params.iter().enumerate() {
            let h = if p.is_compliance() { 1e-8 } else { 1e-6 };
            let at = |d: f64| {
                let mut xs = x.clone();
                xs[c] += d;
                setup.evaluate(&xs, false).0
            };
            let fd = (at(h) - at(-h)) / (2.0 * h);
            let err = (j.column(c) - &fd).norm() / (1.0 + fd.norm());
            assert!(err < 1e-6, "{}: off by {err:e}", p.name());
        }
    }
}
