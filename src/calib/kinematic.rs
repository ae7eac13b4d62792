//! Classical calibration (`kinematic`) and its elasto-geometric extension (`elastic`): constant error
//! parameters fitted by Levenberg–Marquardt over all training points.
//!
//! Parameters, in priority order (earlier ones win where several describe the same motion):
//! 1. the tracker frame: a rotation vector on the left of the registration's rotation and a translation
//!    (`tracker_rx … tracker_z`), started from [`Registration::fit`];
//! 2. the mounting of the measured point in the flange frame (`mount_x … mount_z`);
//! 3. the generalized errors e_ik of every DH frame (eq. 6, `e11 … en6`), started from zero;
//! 4. for `elastic`, one compliance per joint (`c1 … cn`, rad/Nm): the commanded angles deflect by
//!    `δq_j = c_j τ_j(q)`, τ the gravity torques of the nominal inertials and the declared payload.
//!
//! Predicted point: `FK_E(q + δq) · mount`; predicted flange orientation: the rotation of `FK_E(q + δq)`.
//!
//! **Identifiable set.** Structural, so it cannot change with the data: the Jacobian of every candidate is
//! stacked over a fixed set of configurations (a fixed internal seed, uniform within the joint limits), each
//! column scaled to unit norm, and the columns are taken in the priority order above by Gram–Schmidt,
//! keeping a column only if its part orthogonal to the ones kept before it is at least [`STRUCT_REL`].
//! This is QR in a fixed column order rather than with column pivoting: exactly redundant columns (e22 and
//! e13 of the iiwa, the tracker frame and the base-side errors) have equal norms, so a pivoting QR would
//! choose between them on rounding noise; a fixed order makes the choice a property of the robot. A column
//! whose norm stays below [`VANISH_REL`] of the largest of its kind (geometric, or compliance) has no
//! measurable effect anywhere and is dropped first — the compliance of a joint whose gravity torque is
//! structurally zero (joint 1 of a level arm, joint 7 of the iiwa with its on-axis link and payload) goes
//! this way. The training data must then identify that whole set: the singular values of the training
//! Jacobian (columns scaled to unit norm) give the rank and condition number that `report()` shows, and a
//! rank below the set's size is refused with the least determined parameters named.
//!
//! **Reflector nests and 6-DoF probes.** With three reflectors the measured flange orientation is fitted too; a
//! rotation residual φ (rad) is weighted by the nest's RMS radius r (m), i.e. as the displacement `r·φ` it causes
//! at the reflectors, the quantity the tracker actually measured. A 6-DoF probe's orientation is fitted the same
//! way with r = [`PROBE_ORIENTATION_LENGTH_M`](super::tracker_frame::PROBE_ORIENTATION_LENGTH_M).
//!
//! **Solver.** The `levenberg-marquardt` crate (MINPACK's `lmder`) in coordinates whitened by the starting
//! Jacobian ([`minimize`]), from the linearized (Gauss–Newton) solution: without whitening its diagonal
//! scaling zig-zags along the long valley that unmodelled elastic errors open in a weakly excited wrist. A fit
//! that does not converge within [`KinematicOptions::max_evaluations`] is an error, never a silent result.
//!
//! **Jacobian.** Analytic and exact at the current estimate: rotation parameters (tracker frame and every e_i4–6)
//! use SO(3)'s left Jacobian of their current value ([`so3_left_jacobian`]), so the derivative is not the
//! e = 0 one.

use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt, TerminationReason};
use nalgebra::{
    DMatrix, DVector, Dyn, Isometry3, Matrix3, Owned, Point3, Translation3, UnitQuaternion,
    Vector3, Vector6,
};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use serde_json::json;

use super::error_model::{ErrorFrames, ErrorModelKind, ErrorParam, FrameErrors, so3_left_jacobian};
use super::method::{Basis, Design, FitContext, Fitted, MethodInfo, Prediction};
use super::tracker_frame::{Observation, Registration, TrackerFrame};
use crate::dataset::Dataset;
use crate::error::{Error, Result};
use crate::robot::chain::sample_within;
use crate::robot::dh::DhChain;
use crate::robot::dynamics::GRAVITY;
use crate::robot::kinematics::{Frames, forward_kinematics};
use crate::robot::{Chain, Payload};

/// Configurations of the structural analysis: enough that every parameter acting anywhere acts in many.
const STRUCT_SAMPLES: usize = 200;
/// Fixed, so the identifiable set is the same in every run.
const STRUCT_SEED: u64 = 0x6b1e_7a71;
/// Part of a unit column orthogonal to the kept ones below which it is redundant. Exact redundancies leave
/// ≤ 1e-13; the weakest independent parameter of the iiwa over its joint range leaves 2e-3 (a test says so).
const STRUCT_REL: f64 = 1e-7;
/// A column below this fraction of the largest of its kind acts nowhere: the iiwa's joint-7 compliance column
/// is 2e-10 (1e-8 with a nest) of joint 2's, as link 7 and the payload sit on its axis.
const VANISH_REL: f64 = 1e-6;
/// Singular values of the (column-scaled) training Jacobian below this fraction of the largest are zero.
const RANK_REL: f64 = 1e-10;

/// Tunables of the fit; the defaults are what `fit` uses.
#[derive(Clone, Debug)]
pub struct KinematicOptions {
    /// Levenberg–Marquardt stops with an error after this many residual evaluations (a well-posed fit
    /// needs about ten: the model is nearly linear in its small parameters).
    pub max_evaluations: usize,
}

impl Default for KinematicOptions {
    fn default() -> Self {
        KinematicOptions {
            max_evaluations: 400,
        }
    }
}

/// One candidate parameter. Indices count from 0 for axes (x, y, z) and from 0 for joints.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Param {
    TrackerRotation(usize),
    TrackerTranslation(usize),
    Mounting(usize),
    Error(ErrorParam),
    Compliance(usize),
}

impl Param {
    pub fn name(&self) -> String {
        const AXES: [&str; 3] = ["x", "y", "z"];
        match self {
            Param::TrackerRotation(k) => format!("tracker_r{}", AXES[*k]),
            Param::TrackerTranslation(k) => format!("tracker_{}", AXES[*k]),
            Param::Mounting(k) => format!("mount_{}", AXES[*k]),
            Param::Error(e) => e.name(),
            Param::Compliance(j) => format!("c{}", j + 1),
        }
    }

    fn is_compliance(&self) -> bool {
        matches!(self, Param::Compliance(_))
    }
}

/// Every candidate of an `n`-joint chain, in priority order.
pub fn candidates(n: usize, elastic: bool) -> Vec<Param> {
    let mut out: Vec<Param> = (0..3).map(Param::TrackerRotation).collect();
    out.extend((0..3).map(Param::TrackerTranslation));
    out.extend((0..3).map(Param::Mounting));
    out.extend(
        ErrorModelKind::RotXyzTransXyz
            .params(n)
            .into_iter()
            .map(Param::Error),
    );
    if elastic {
        out.extend((0..n).map(Param::Compliance));
    }
    out
}

/// The nominal inertials re-expressed in the DH frames, so gravity torques need only the DH chain (and the
/// saved model needs no URDF): body j + 1 (moved by joint j) in DH frame j + 1, the payload in the flange frame.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct GravityModel {
    /// Per moving body: mass (kg) and centre of mass in its DH frame (m).
    pub masses: Vec<f64>,
    pub coms: Vec<[f64; 3]>,
    pub payload: Payload,
    pub gravity: [f64; 3],
}

impl GravityModel {
    pub fn new(chain: &Chain, dh: &DhChain, payload: Payload) -> Result<GravityModel> {
        let n = chain.dof();
        if dh.dof() != n {
            return Err(Error::Invalid(format!(
                "the DH chain has {} joints, the URDF chain {n}",
                dh.dof()
            )));
        }
        if !(payload.mass.is_finite() && payload.mass >= 0.0)
            || payload.com.iter().any(|c| !c.is_finite())
        {
            return Err(Error::Invalid(format!(
                "payload {payload:?} must be finite, mass ≥ 0"
            )));
        }
        let q0 = vec![0.0; n];
        let mut fk = Frames::new(chain);
        forward_kinematics(chain, &q0, &mut fk);
        let dh_frames = dh.frames(&q0);
        let mut masses = Vec::with_capacity(n);
        let mut coms = Vec::with_capacity(n);
        for i in 0..n {
            let body = &chain.bodies[i + 1];
            let com = dh_frames[i + 1].inverse() * (fk.body[i + 1] * body.inertial.com);
            masses.push(body.inertial.mass);
            coms.push([com.x, com.y, com.z]);
        }
        // The payload's centre is given in the chain's flange frame, which is the DH chain's (tool) flange.
        Ok(GravityModel {
            masses,
            coms,
            payload,
            gravity: [GRAVITY.x, GRAVITY.y, GRAVITY.z],
        })
    }

    /// Gravity torques (Nm; N for a prismatic joint) at `q` of the nominal DH chain, as
    /// [`crate::robot::dynamics::gravity_torques`] gives them on the URDF chain.
    pub fn torques(&self, dh: &DhChain, q: &[f64]) -> Vec<f64> {
        let frames = dh.frames(q);
        let n = dh.dof();
        let g = Vector3::from(self.gravity);
        let flange = frames[n] * dh.tool;
        let mut mass = self.payload.mass;
        let mut moment = (flange * Point3::from(self.payload.com)).coords * self.payload.mass;
        let mut out = vec![0.0; n];
        for i in (0..n).rev() {
            mass += self.masses[i];
            moment += (frames[i + 1] * Point3::from(self.coms[i])).coords * self.masses[i];
            let z = frames[i].rotation * Vector3::z();
            out[i] = if dh.rows[i].prismatic {
                z.dot(&(g * mass))
            } else {
                let lever = moment - frames[i].translation.vector * mass;
                z.dot(&lever.cross(&g))
            };
        }
        out
    }
}

/// What the model knows about each fitted point.
struct Point {
    q: Vec<f64>,
    /// The measured point, base frame of the initial registration.
    y: Point3<f64>,
    /// The measured flange orientation, same frame (nests).
    orientation: Option<UnitQuaternion<f64>>,
    /// Gravity torques at the commanded angles (elastic only; empty otherwise).
    tau: Vec<f64>,
}

/// Full parameter state: the defaults overwritten by the kept parameters.
#[derive(Clone, Debug)]
struct State {
    rho: Vector3<f64>,
    t: Vector3<f64>,
    mount: Point3<f64>,
    errors: FrameErrors,
    compliance: Vec<f64>,
}

impl State {
    fn initial(n: usize, mount: Point3<f64>) -> State {
        State {
            rho: Vector3::zeros(),
            t: Vector3::zeros(),
            mount,
            errors: vec![[0.0; 6]; n],
            compliance: vec![0.0; n],
        }
    }

    fn get(&self, p: Param) -> f64 {
        match p {
            Param::TrackerRotation(k) => self.rho[k],
            Param::TrackerTranslation(k) => self.t[k],
            Param::Mounting(k) => self.mount[k],
            Param::Error(e) => self.errors[e.frame - 1][e.component - 1],
            Param::Compliance(j) => self.compliance[j],
        }
    }

    fn set(&mut self, p: Param, v: f64) {
        match p {
            Param::TrackerRotation(k) => self.rho[k] = v,
            Param::TrackerTranslation(k) => self.t[k] = v,
            Param::Mounting(k) => self.mount[k] = v,
            Param::Error(e) => self.errors[e.frame - 1][e.component - 1] = v,
            Param::Compliance(j) => self.compliance[j] = v,
        }
    }

    fn with(base: &State, params: &[Param], values: &[f64]) -> State {
        let mut s = base.clone();
        for (&p, &v) in params.iter().zip(values) {
            s.set(p, v);
        }
        s
    }

    /// Deflected angles for commanded `q` with torques `tau` (no deflection without torques).
    fn deflected(&self, q: &[f64], tau: &[f64]) -> Vec<f64> {
        if tau.is_empty() {
            return q.to_vec();
        }
        q.iter()
            .zip(tau)
            .zip(&self.compliance)
            .map(|((q, t), c)| q + c * t)
            .collect()
    }
}

/// The problem shared by the structural analysis, the rank check and Levenberg–Marquardt.
struct Setup<'a> {
    dh: &'a DhChain,
    points: Vec<Point>,
    /// Rotation residual weight (m/rad), `Some` when orientations are fitted.
    length: Option<f64>,
    base: State,
    params: Vec<Param>,
}

impl Setup<'_> {
    fn rows(&self) -> usize {
        self.points
            .iter()
            .map(|p| if self.fits_rotation(p) { 6 } else { 3 })
            .sum()
    }

    fn fits_rotation(&self, p: &Point) -> bool {
        self.length.is_some() && p.orientation.is_some()
    }

    /// Residuals (predicted − measured) and, when asked, the Jacobian, at `values` of the kept parameters.
    fn evaluate(&self, values: &[f64], jacobian: bool) -> (DVector<f64>, Option<DMatrix<f64>>) {
        let s = State::with(&self.base, &self.params, values);
        let m = self.rows();
        let mut r = DVector::zeros(m);
        let mut j = jacobian.then(|| DMatrix::zeros(m, self.params.len()));
        let rot = UnitQuaternion::from_scaled_axis(s.rho);
        let jl_rho = so3_left_jacobian(&s.rho);
        // Per frame, the left Jacobian of its rotation error (it does not depend on the configuration), and
        // per point the world axes of each frame's translation and rotation errors and the rotation centre.
        let jl_errors: Vec<Matrix3<f64>> = s
            .errors
            .iter()
            .map(|e| so3_left_jacobian(&Vector3::new(e[3], e[4], e[5])))
            .collect();
        let mut axes: Vec<(Matrix3<f64>, Matrix3<f64>, Point3<f64>)> =
            vec![(Matrix3::zeros(), Matrix3::zeros(), Point3::origin()); s.errors.len()];
        let mut row = 0;
        for pt in &self.points {
            let qd = s.deflected(&pt.q, &pt.tau);
            let frames = ErrorFrames::new(self.dh, &qd, &s.errors);
            if j.is_some() {
                for (i, ((g, e), jl)) in frames
                    .before
                    .iter()
                    .zip(&s.errors)
                    .zip(&jl_errors)
                    .enumerate()
                {
                    let r = g.rotation.to_rotation_matrix().into_inner();
                    axes[i] = (r, r * jl, g * Point3::new(e[0], e[1], e[2]));
                }
            }
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
            if let Some(jm) = j.as_mut() {
                for (c, prm) in self.params.iter().enumerate() {
                    let col: Vector6<f64> = match *prm {
                        Param::TrackerRotation(k) => {
                            let lin = v.cross_matrix() * jl_rho.column(k);
                            let ang = match &rotation {
                                Some((l, _, jr_inv)) => -(jr_inv * jl_rho.column(k)) * *l,
                                None => Vector3::zeros(),
                            };
                            stack(&lin, &ang)
                        }
                        Param::TrackerTranslation(k) => {
                            stack(&-Vector3::ith(k, 1.0), &Vector3::zeros())
                        }
                        Param::Mounting(k) => stack(
                            &(frames.flange.rotation * Vector3::ith(k, 1.0)),
                            &Vector3::zeros(),
                        ),
                        Param::Error(e) => {
                            let (r, u, centre) = &axes[e.frame - 1];
                            let k = (e.component - 1) % 3;
                            let col = if e.component <= 3 {
                                stack(&r.column(k).into_owned(), &Vector3::zeros())
                            } else {
                                let u = u.column(k).into_owned();
                                stack(&u.cross(&(p - centre)), &u)
                            };
                            flange_column(col, &rotation)
                        }
                        Param::Compliance(jt) => flange_column(
                            frames.joint_column(self.dh, jt, &p) * pt.tau[jt],
                            &rotation,
                        ),
                    };
                    let rows = if rotation.is_some() { 6 } else { 3 };
                    for k in 0..rows {
                        jm[(row + k, c)] = col[k];
                    }
                }
            }
            row += if rotation.is_some() { 6 } else { 3 };
        }
        (r, j)
    }
}

fn stack(lin: &Vector3<f64>, ang: &Vector3<f64>) -> Vector6<f64> {
    Vector6::new(lin.x, lin.y, lin.z, ang.x, ang.y, ang.z)
}

/// A column of the flange's [linear; world angular] motion as residual rows: the angular part mapped through
/// the rotation residual's inverse left Jacobian and weighted.
fn flange_column(
    col: Vector6<f64>,
    rotation: &Option<(f64, Matrix3<f64>, Matrix3<f64>)>,
) -> Vector6<f64> {
    match rotation {
        Some((l, jl_inv, _)) => {
            let ang = jl_inv * col.fixed_rows::<3>(3) * *l;
            stack(&col.fixed_rows::<3>(0).into_owned(), &ang)
        }
        None => col,
    }
}

/// How the minimization ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Termination {
    /// The residuals are orthogonal to every Jacobian column to [`LM_GTOL`].
    Gradient,
    /// The trust region shrank below [`LM_XTOL`] of the (scaled) correction.
    Step,
    /// Actual and predicted relative reductions of the sum of squares are below [`LM_FTOL`].
    Objective,
}

/// Convergence tolerances of [`minimize`] (the crate's `gtol`, `xtol`, `ftol`), relative.
const LM_GTOL: f64 = 1e-10;
const LM_XTOL: f64 = 1e-10;
const LM_FTOL: f64 = 1e-12;

struct Minimum {
    x: DVector<f64>,
    evaluations: usize,
    termination: Termination,
}

/// The least-squares problem in whitened coordinates `x = x0 + S·z`, for the `levenberg-marquardt` crate.
/// `S` makes `J(x0)·S` orthonormal: the trust region is then a ball in the data's metric, and steps follow
/// the long, gently curved valleys of a weakly excited campaign instead of zig-zagging across them, which
/// keeps the iterations (each a QR of the full Jacobian) to a handful.
struct Whitened<'a> {
    setup: &'a Setup<'a>,
    x0: &'a DVector<f64>,
    s: &'a DMatrix<f64>,
    z: DVector<f64>,
    r: DVector<f64>,
    /// The Jacobian at `z`, computed when the crate asks for it: it does so only at accepted steps, so
    /// rejected trial points cost a residual evaluation alone.
    jz: std::cell::OnceCell<Option<DMatrix<f64>>>,
}

impl Whitened<'_> {
    fn x(&self) -> DVector<f64> {
        self.x0 + self.s * &self.z
    }
}

impl LeastSquaresProblem<f64, Dyn, Dyn> for Whitened<'_> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, Dyn>;
    type ParameterStorage = Owned<f64, Dyn>;

    fn set_params(&mut self, z: &DVector<f64>) {
        self.z.copy_from(z);
        self.r = self.setup.evaluate(self.x().as_slice(), false).0;
        self.jz = std::cell::OnceCell::new();
    }

    fn params(&self) -> DVector<f64> {
        self.z.clone()
    }

    fn residuals(&self) -> Option<DVector<f64>> {
        self.r.iter().all(|v| v.is_finite()).then(|| self.r.clone())
    }

    fn jacobian(&self) -> Option<DMatrix<f64>> {
        self.jz
            .get_or_init(|| {
                let (_, j) = self.setup.evaluate(self.x().as_slice(), true);
                j.map(|j| j * self.s)
            })
            .clone()
            .filter(|j| j.iter().all(|v| v.is_finite()))
    }
}

/// Levenberg–Marquardt (the `levenberg-marquardt` crate, MINPACK's algorithm) on the whitened problem, from
/// `x0`. A run that stops for any reason but convergence is an error, never a silent result.
fn minimize(
    setup: &Setup,
    x0: &DVector<f64>,
    s: &DMatrix<f64>,
    max_evaluations: usize,
) -> std::result::Result<Minimum, String> {
    let k = x0.len();
    let mut problem = Whitened {
        setup,
        x0,
        s,
        z: DVector::zeros(k),
        r: DVector::zeros(0),
        jz: std::cell::OnceCell::new(),
    };
    // The linearized solution first (classical calibration's first estimate): in whitened coordinates the
    // Jacobian has orthonormal columns, so the Gauss–Newton step is a product. The problem is nearly linear
    // in its small parameters, so Levenberg–Marquardt then only polishes; if the step does not help, it
    // starts from the nominal model instead.
    problem.set_params(&DVector::zeros(k));
    let start_norm = problem.r.norm();
    let gauss_newton = problem.jacobian().map(|jz| -(jz.tr_mul(&problem.r)));
    let mut evaluations_before = 1;
    if let Some(z0) = gauss_newton {
        problem.set_params(&z0);
        evaluations_before += 1;
        // A NaN norm counts as no improvement.
        if problem.r.norm().partial_cmp(&start_norm) != Some(std::cmp::Ordering::Less) {
            problem.set_params(&DVector::zeros(k));
        }
    }
    // The crate's patience counts evaluations in units of (parameters + 1).
    let patience = (max_evaluations / (k + 1)).max(1);
    let (problem, report) = LevenbergMarquardt::new()
        .with_ftol(LM_FTOL)
        .with_xtol(LM_XTOL)
        .with_gtol(LM_GTOL)
        .with_patience(patience)
        .minimize(problem);
    let termination = match report.termination {
        TerminationReason::Orthogonal => Termination::Gradient,
        TerminationReason::Converged { xtol: true, .. } => Termination::Step,
        TerminationReason::Converged { .. } | TerminationReason::ResidualsZero => {
            Termination::Objective
        }
        TerminationReason::LostPatience => {
            return Err(format!(
                "no convergence within {max_evaluations} evaluations"
            ));
        }
        other => return Err(format!("{other:?}")),
    };
    // The crate counts patience in units of (parameters + 1) evaluations; the cap is the caller's, exactly.
    let evaluations = report.number_of_evaluations + evaluations_before;
    if evaluations > max_evaluations {
        return Err(format!(
            "no convergence within {max_evaluations} evaluations"
        ));
    }
    Ok(Minimum {
        x: problem.x(),
        evaluations,
        termination,
    })
}

/// Gram–Schmidt in priority order over the columns of `setup`'s Jacobian at its base state.
fn structural_columns(setup: &Setup, candidates: &[Param]) -> Vec<Param> {
    structural_analysis(setup, candidates)
        .into_iter()
        .filter(|a| a.kept)
        .map(|a| a.param)
        .collect()
}

/// One candidate in the structural analysis: its column's norm relative to the largest of its kind, and
/// the part of its unit column orthogonal to the columns kept before it.
#[derive(Debug)]
struct Analysed {
    param: Param,
    /// Read by the test that checks the margins of the decisions.
    #[cfg_attr(not(test), allow(dead_code))]
    relative_norm: f64,
    #[cfg_attr(not(test), allow(dead_code))]
    rest: f64,
    kept: bool,
}

fn structural_analysis(setup: &Setup, candidates: &[Param]) -> Vec<Analysed> {
    let values: Vec<f64> = candidates.iter().map(|&p| setup.base.get(p)).collect();
    let (_, j) = setup.evaluate(&values, true);
    let j = j.expect("jacobian requested");
    let norms: Vec<f64> = (0..j.ncols()).map(|c| j.column(c).norm()).collect();
    let largest = |compliance: bool| {
        candidates
            .iter()
            .zip(&norms)
            .filter(|(p, _)| p.is_compliance() == compliance)
            .map(|(_, &n)| n)
            .fold(0.0, f64::max)
    };
    let (geo_max, comp_max) = (largest(false), largest(true));
    let mut basis: Vec<DVector<f64>> = Vec::new();
    let mut out = Vec::with_capacity(candidates.len());
    for (c, &prm) in candidates.iter().enumerate() {
        let scale = if prm.is_compliance() {
            comp_max
        } else {
            geo_max
        };
        let relative_norm = norms[c] / scale;
        if relative_norm.is_nan() || relative_norm <= VANISH_REL {
            out.push(Analysed {
                param: prm,
                relative_norm,
                rest: 0.0,
                kept: false,
            });
            continue;
        }
        let mut v = j.column(c) / norms[c];
        // Twice is enough (Kahan–Parlett) for the orthogonality the threshold needs.
        for _ in 0..2 {
            for b in &basis {
                let d = b.dot(&v);
                v.axpy(-d, b, 1.0);
            }
        }
        let rest = v.norm();
        let kept = rest >= STRUCT_REL;
        if kept {
            basis.push(v / rest);
        }
        out.push(Analysed {
            param: prm,
            relative_norm,
            rest,
            kept,
        });
    }
    out
}

/// Rank and condition number of the training Jacobian (columns scaled to unit norm), and the names of the
/// parameters that weigh most in its null space when it is rank-deficient.
struct Identifiability {
    rank: usize,
    condition: f64,
    weakest: Vec<String>,
    /// `S` with `J·S` orthonormal (full rank only): the coordinates Levenberg–Marquardt works in.
    whitening: Option<DMatrix<f64>>,
}

fn identifiability(j: &DMatrix<f64>, params: &[Param]) -> Identifiability {
    let mut scaled = j.clone();
    let mut norms = Vec::with_capacity(j.ncols());
    for mut col in scaled.column_iter_mut() {
        let n = col.norm();
        if n > 0.0 {
            col /= n;
        }
        norms.push(if n > 0.0 { n } else { 1.0 });
    }
    let k = params.len();
    // Reduce a tall matrix to its triangle first: same singular values, a much smaller SVD.
    let square = if scaled.nrows() > k {
        scaled.qr().r()
    } else {
        scaled
    };
    let whitening = (square.nrows() == k)
        .then(|| square.clone().try_inverse())
        .flatten()
        .map(|r_inv| {
            let mut s = r_inv;
            for (mut row, n) in s.row_iter_mut().zip(&norms) {
                row /= *n;
            }
            s
        });
    let svd = square.svd(false, true);
    let s = &svd.singular_values;
    let smax = s.max();
    let rank = s.iter().filter(|&&v| v > RANK_REL * smax).count();
    let smin = if s.len() < k { 0.0 } else { s.min() };
    let condition = if smin > 0.0 {
        smax / smin
    } else {
        f64::INFINITY
    };
    let mut weakest = Vec::new();
    if rank < k
        && let Some(vt) = &svd.v_t
    {
        // Rows of Vᵀ for the vanishing singular values span (part of) the null space; weigh each parameter
        // by its share in them.
        let mut weight = vec![0.0; k];
        for (i, sv) in s.iter().enumerate() {
            if *sv <= RANK_REL * smax {
                for (c, w) in weight.iter_mut().enumerate() {
                    *w += vt[(i, c)].powi(2);
                }
            }
        }
        let mut order: Vec<usize> = (0..k).collect();
        order.sort_by(|&a, &b| weight[b].total_cmp(&weight[a]));
        weakest = order
            .into_iter()
            .take(4)
            .filter(|&c| weight[c] > 1e-3)
            .map(|c| params[c].name())
            .collect();
    }
    Identifiability {
        rank,
        condition,
        weakest,
        whitening,
    }
}

pub const KINEMATIC: MethodInfo = MethodInfo {
    name: "kinematic",
    summary: "classical calibration: constant DH-frame errors, tracker frame and mounting by Levenberg–Marquardt",
    takes_inputs: false,
    has_robot_parameters: true,
    base: None,
    design: Design::Identification { elastic: false },
};

pub const ELASTIC: MethodInfo = MethodInfo {
    name: "elastic",
    summary: "kinematic calibration plus one joint compliance per joint under the nominal gravity torques",
    takes_inputs: false,
    has_robot_parameters: true,
    base: None,
    design: Design::Identification { elastic: true },
};

fn method_from_name<'de, D: serde::Deserializer<'de>>(
    d: D,
) -> std::result::Result<&'static MethodInfo, D::Error> {
    MethodInfo::deserialize_among(d, &[&KINEMATIC, &ELASTIC])
}

/// Everything a later run needs to predict: `model.json`.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct KinematicModel {
    /// `kinematic` or `elastic`.
    #[serde(deserialize_with = "method_from_name")]
    pub method: &'static MethodInfo,
    /// The registration is the refined tracker frame and mounting: the one test data are observed through.
    #[serde(flatten)]
    pub basis: Basis,
    /// Per DH frame, the fitted [tx, ty, tz, rx, ry, rz] (zero where not kept).
    pub errors: FrameErrors,
    /// Per joint (rad/Nm; zero where not kept), `elastic` only.
    pub compliance: Option<Vec<f64>>,
    pub gravity: Option<GravityModel>,
    /// Weight of rotation residuals (m/rad): the nest's RMS radius; `None` without a nest.
    pub orientation_length_m: Option<f64>,
    /// The structurally identifiable parameters, in priority order, and their fitted values.
    pub kept: Vec<Param>,
    pub values: Vec<f64>,
    /// Candidates left out as structurally redundant or without effect.
    pub dropped: Vec<Param>,
    /// Rank and condition number of the training Jacobian (columns scaled to unit norm).
    pub rank: usize,
    pub condition_number: f64,
    /// Levenberg–Marquardt evaluations (residuals and Jacobian), and how it stopped.
    pub evaluations: usize,
    pub termination: Termination,
    /// RMS of the 3-D position residual over the training and validation points (m).
    pub train_rms_m: f64,
    pub validation_rms_m: Option<f64>,
}

impl KinematicModel {
    pub fn fit(
        elastic: bool,
        ctx: &FitContext,
        train: &Dataset,
        val: &Dataset,
    ) -> Result<KinematicModel> {
        KinematicModel::fit_with(elastic, ctx, train, val, &KinematicOptions::default())
    }

    pub fn fit_with(
        elastic: bool,
        ctx: &FitContext,
        train: &Dataset,
        val: &Dataset,
        options: &KinematicOptions,
    ) -> Result<KinematicModel> {
        let method = if elastic { &ELASTIC } else { &KINEMATIC };
        if train.is_empty() {
            return Err(Error::Invalid(format!("{method}: no training points")));
        }
        let dh = ctx.dh;
        let n = dh.dof();
        for data in [train, val] {
            let bad = data.q.iter().zip(&data.measured).position(|(q, m)| {
                !(q.len() == n
                    && q.iter().all(|v| v.is_finite())
                    && m.iter().all(|p| p.iter().all(|v| v.is_finite())))
            });
            if let Some(i) = bad {
                return Err(Error::Data {
                    origin: data.origin.clone(),
                    message: format!(
                        "{method}: point {} has a non-finite measurement or not {n} finite joint angles",
                        data.point_ids.get(i).map_or("?", |s| s.as_str())
                    ),
                });
            }
        }
        let registration = Registration::fit(dh, train, val)?;
        let gravity = if elastic {
            Some(GravityModel::new(ctx.chain, dh, ctx.payload)?)
        } else {
            None
        };
        let length = registration.orientation_length();
        let to_points = |obs: Vec<Observation>| -> Vec<Point> {
            obs.into_iter()
                .map(|o| Point {
                    tau: gravity
                        .as_ref()
                        .map_or_else(Vec::new, |g| g.torques(dh, &o.q)),
                    q: o.q,
                    y: o.position,
                    orientation: o.orientation,
                })
                .collect()
        };
        let base = State::initial(n, registration.frame.mounting);
        let all = candidates(n, elastic);

        // The structurally identifiable set, from configurations that do not depend on the data.
        let (lower, upper) = ctx.limits();
        let mut probe = Setup {
            dh,
            points: Vec::new(),
            length,
            base: base.clone(),
            params: all.clone(),
        };
        let kept = structural_set(&probe, &lower, &upper, &all, gravity.as_ref());
        let dropped: Vec<Param> = all.iter().copied().filter(|p| !kept.contains(p)).collect();

        // Does the training data identify it?
        probe.points = to_points(registration.observe(train)?);
        probe.params = kept.clone();
        let x0: Vec<f64> = kept.iter().map(|&p| base.get(p)).collect();
        let (_, j0) = probe.evaluate(&x0, true);
        let id = identifiability(&j0.expect("jacobian requested"), &kept);
        if id.rank < kept.len() {
            let weakest = if id.weakest.is_empty() {
                String::new()
            } else {
                format!("; least determined: {}", id.weakest.join(", "))
            };
            return Err(Error::Invalid(format!(
                "{method}: the training points do not identify the model: rank {} of {} \
                 (condition number {:.1e}){weakest}; measure more points and vary every joint",
                id.rank,
                kept.len(),
                id.condition
            )));
        }

        let k = kept.len();
        let whitening = id
            .whitening
            .clone()
            .unwrap_or_else(|| DMatrix::identity(k, k));
        let minimum = minimize(
            &probe,
            &DVector::from_vec(x0),
            &whitening,
            options.max_evaluations.max(2),
        )
        .map_err(|why| {
            Error::Invalid(format!(
                "{method}: Levenberg–Marquardt did not converge ({why}); the data may be \
                 inconsistent with a constant-error model"
            ))
        })?;
        let values: Vec<f64> = minimum.x.iter().copied().collect();
        let state = State::with(&base, &kept, &values);
        let rms = |points: &[Point]| -> f64 {
            let sum: f64 = points
                .iter()
                .map(|pt| {
                    let qd = state.deflected(&pt.q, &pt.tau);
                    let p = ErrorFrames::new(dh, &qd, &state.errors).flange * state.mount;
                    let v = UnitQuaternion::from_scaled_axis(state.rho) * pt.y.coords + state.t;
                    (p.coords - v).norm_squared()
                })
                .sum();
            (sum / points.len() as f64).sqrt()
        };
        let train_rms = rms(&probe.points);
        if !train_rms.is_finite() || values.iter().any(|v| !v.is_finite()) {
            return Err(Error::Invalid(format!(
                "{method}: the fit produced non-finite parameters"
            )));
        }
        let val_points = if val.is_empty() {
            Vec::new()
        } else {
            to_points(registration.observe(val)?)
        };
        let validation_rms = (!val_points.is_empty()).then(|| rms(&val_points));
        let initial = registration.frame.tracker_to_base;
        let refined = Isometry3::from_parts(
            Translation3::from(state.t),
            UnitQuaternion::from_scaled_axis(state.rho),
        ) * initial;
        Ok(KinematicModel {
            method,
            basis: Basis {
                joint_names: train.joint_names.clone(),
                dh: dh.clone(),
                registration: Registration {
                    frame: TrackerFrame {
                        tracker_to_base: refined,
                        mounting: state.mount,
                        rms: train_rms,
                        evaluations: minimum.evaluations,
                    },
                    nest: registration.nest,
                    probe_rotation: registration.probe_rotation,
                },
            },
            errors: state.errors.clone(),
            compliance: elastic.then(|| state.compliance.clone()),
            gravity,
            orientation_length_m: length,
            kept,
            values,
            dropped,
            rank: id.rank,
            condition_number: id.condition,
            evaluations: minimum.evaluations,
            termination: minimum.termination,
            train_rms_m: train_rms,
            validation_rms_m: validation_rms,
        })
    }

    /// Names of the kept parameters, in priority order.
    pub fn kept_names(&self) -> Vec<String> {
        self.kept.iter().map(|p| p.name()).collect()
    }

    /// The calibrated flange pose at commanded `q`.
    pub fn flange_pose(&self, q: &[f64]) -> Isometry3<f64> {
        let qd: Vec<f64> = match (&self.gravity, &self.compliance) {
            (Some(g), Some(c)) => g
                .torques(&self.basis.dh, q)
                .iter()
                .zip(c)
                .zip(q)
                .map(|((t, c), q)| q + c * t)
                .collect(),
            _ => q.to_vec(),
        };
        ErrorFrames::new(&self.basis.dh, &qd, &self.errors).flange
    }
}

/// The structurally identifiable parameters among `candidates`, in their order (see the module notes):
/// the Jacobian at the start of `setup` over configurations drawn with a fixed seed, each carrying its
/// gravity torques when compliances are candidates.
fn structural_set(
    setup: &Setup,
    lower: &[f64],
    upper: &[f64],
    candidates: &[Param],
    gravity: Option<&GravityModel>,
) -> Vec<Param> {
    let mut rng = ChaCha8Rng::seed_from_u64(STRUCT_SEED);
    let n = setup.dh.dof();
    let points = (0..STRUCT_SAMPLES)
        .map(|_| {
            let q: Vec<f64> = (0..n)
                .map(|i| sample_within(lower[i], upper[i], &mut rng))
                .collect();
            synthetic_point(setup, gravity, q)
        })
        .collect();
    let structural = Setup {
        dh: setup.dh,
        points,
        length: setup.length,
        base: setup.base.clone(),
        params: candidates.to_vec(),
    };
    structural_columns(&structural, candidates)
}

/// A point that the initial state of `setup` fits exactly, so the Jacobian there is the one at the start.
fn synthetic_point(setup: &Setup, gravity: Option<&GravityModel>, q: Vec<f64>) -> Point {
    let flange = setup.dh.flange_pose(&q);
    Point {
        y: flange * setup.base.mount,
        orientation: setup.length.map(|_| flange.rotation),
        tau: gravity.map_or_else(Vec::new, |g| g.torques(setup.dh, &q)),
        q,
    }
}

/// The identification Jacobian of `kinematic` (or `elastic`) at the nominal model, before anything is
/// measured: what experiment design ([`crate::design`]) needs. The parameters are the structurally
/// identifiable set a fit would keep; the rows of a configuration are those its measured point would add
/// (3, or 6 when orientation is fitted). The tracker frame is taken as the base frame: the columns of a
/// tracker rotation about another point differ from these by tracker-translation columns, which changes no
/// observability index that is invariant to such reparametrization (the determinant up to a constant, and
/// the rank).
pub struct Identification<'a> {
    setup: Setup<'a>,
    gravity: Option<GravityModel>,
}

impl<'a> Identification<'a> {
    /// `mount`: the measured point in the flange frame (a nest's centroid); `length`: the weight of rotation
    /// rows (m/rad, a nest's RMS radius), `None` for a position-only measurement.
    pub fn new(
        elastic: bool,
        ctx: &FitContext<'a>,
        mount: Point3<f64>,
        length: Option<f64>,
    ) -> Result<Identification<'a>> {
        let n = ctx.dh.dof();
        let gravity = if elastic {
            Some(GravityModel::new(ctx.chain, ctx.dh, ctx.payload)?)
        } else {
            None
        };
        let all = candidates(n, elastic);
        let (lower, upper) = ctx.limits();
        let mut setup = Setup {
            dh: ctx.dh,
            points: Vec::new(),
            length,
            base: State::initial(n, mount),
            params: all.clone(),
        };
        setup.params = structural_set(&setup, &lower, &upper, &all, gravity.as_ref());
        Ok(Identification { setup, gravity })
    }

    /// The structurally identifiable parameters: the columns of [`Identification::jacobian`].
    pub fn params(&self) -> &[Param] {
        &self.setup.params
    }

    /// Rows per configuration: 3 for a point, 6 with orientation.
    pub fn rows_per_point(&self) -> usize {
        if self.setup.length.is_some() { 6 } else { 3 }
    }

    /// The Jacobian of the predicted measurement over the configurations `qs`, stacked in their order.
    pub fn jacobian(&self, qs: &[&[f64]]) -> DMatrix<f64> {
        let s = &self.setup;
        let probe = Setup {
            dh: s.dh,
            points: qs
                .iter()
                .map(|q| synthetic_point(s, self.gravity.as_ref(), q.to_vec()))
                .collect(),
            length: s.length,
            base: s.base.clone(),
            params: s.params.clone(),
        };
        let x0: Vec<f64> = s.params.iter().map(|&p| s.base.get(p)).collect();
        probe.evaluate(&x0, true).1.expect("jacobian requested")
    }
}

impl Fitted for KinematicModel {
    fn info(&self) -> &'static MethodInfo {
        self.method
    }

    fn basis(&self) -> &Basis {
        &self.basis
    }

    fn predict(&self, q: &[f64]) -> Prediction {
        let f = self.flange_pose(q);
        let position = f * self.basis.registration.frame.mounting;
        Prediction {
            position,
            linearized_position: position,
            orientation: f.rotation,
        }
    }

    fn models_orientation(&self) -> bool {
        self.basis.registration.measures_orientation()
    }

    fn report(&self, test: &[Observation]) -> serde_json::Value {
        let test_rms = (!test.is_empty()).then(|| {
            let sum: f64 = test
                .iter()
                .map(|o| (o.position - self.predict(&o.q).position).norm_squared())
                .sum();
            (sum / test.len() as f64).sqrt()
        });
        let values: serde_json::Map<String, serde_json::Value> = self
            .kept
            .iter()
            .zip(&self.values)
            .map(|(p, v)| (p.name(), json!(v)))
            .collect();
        json!({
            "kept_parameters": self.kept_names(),
            "dropped_parameters": self.dropped.iter().map(|p| p.name()).collect::<Vec<_>>(),
            "rank": self.rank,
            "condition_number": self.condition_number,
            "evaluations": self.evaluations,
            "termination": self.termination,
            "train_rms_m": self.train_rms_m,
            "validation_rms_m": self.validation_rms_m,
            "test_rms_m": test_rms,
            "orientation_length_m": self.orientation_length_m,
            "compliance_rad_per_nm": self.compliance,
            "values": values,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robot::urdf;
    use rand::Rng;

    /// The structural decisions are far from their thresholds: what is kept is independent by orders of
    /// magnitude, what is dropped is redundant to rounding (or acts nowhere), for position-only and nest
    /// campaigns, kinematic and elastic.
    #[test]
    fn structural_decisions_are_clear_cut() {
        let chain = urdf::load_file("robots/iiwa7.urdf", None).unwrap();
        let dh = DhChain::from_chain(&chain).unwrap();
        let payload = Payload {
            mass: 0.4,
            com: [0.0, 0.0, 0.03],
        };
        let gravity = GravityModel::new(&chain, &dh, payload).unwrap();
        let (lower, upper) = (chain.lower_limits(), chain.upper_limits());
        for length in [None, Some(0.05)] {
            let setup = Setup {
                dh: &dh,
                points: Vec::new(),
                length,
                base: State::initial(7, Point3::new(0.0006, -0.0004, 0.0302)),
                params: Vec::new(),
            };
            let all = candidates(7, true);
            let mut rng = ChaCha8Rng::seed_from_u64(STRUCT_SEED);
            let points = (0..STRUCT_SAMPLES)
                .map(|_| {
                    let q: Vec<f64> = (0..7)
                        .map(|i| sample_within(lower[i], upper[i], &mut rng))
                        .collect();
                    let f = dh.flange_pose(&q);
                    Point {
                        y: f * setup.base.mount,
                        orientation: length.map(|_| f.rotation),
                        tau: gravity.torques(&dh, &q),
                        q,
                    }
                })
                .collect();
            let structural = Setup {
                points,
                params: all.clone(),
                ..setup
            };
            let analysis = structural_analysis(&structural, &all);
            let min_kept = analysis
                .iter()
                .filter(|a| a.kept)
                .map(|a| a.rest.min(a.relative_norm))
                .fold(f64::INFINITY, f64::min);
            // Dropped as acting nowhere (relative norm) or as redundant (rest).
            let vanishing = analysis
                .iter()
                .filter(|a| !a.kept && a.rest == 0.0)
                .map(|a| a.relative_norm)
                .fold(0.0, f64::max);
            let redundant = analysis
                .iter()
                .filter(|a| !a.kept && a.rest > 0.0)
                .map(|a| a.rest)
                .fold(0.0, f64::max);
            let names = |kept: bool| -> Vec<String> {
                analysis
                    .iter()
                    .filter(|a| a.kept == kept)
                    .map(|a| a.param.name())
                    .collect()
            };
            eprintln!(
                "nest {length:?}: kept {} (weakest {min_kept:.1e}); dropped {:?} (largest norm {vanishing:.1e}, \
                 largest rest {redundant:.1e})",
                names(true).len(),
                names(false),
            );
            assert!(min_kept > 1e-4, "{min_kept}");
            assert!(vanishing < 1e-7, "{vanishing}");
            assert!(redundant < 1e-10, "{redundant}");
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
                Point {
                    y: f * Point3::new(0.01, 0.02, 0.05),
                    orientation: (i % 2 == 0)
                        .then(|| UnitQuaternion::from_euler_angles(0.01, 0.02, 0.03) * f.rotation),
                    tau: gravity.torques(&dh, &q),
                    q,
                }
            })
            .collect();
        let params = candidates(7, true);
        let setup = Setup {
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
