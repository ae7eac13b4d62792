//! Classical calibration (`kinematic`) and its elasto-geometric extension (`elastic`): constant error
//! parameters fitted by Levenberg–Marquardt over all training points.
//!
//! Parameters, in priority order (earlier ones win where several describe the same motion):
//! 1. the tracker frame: a rotation vector on the left of the registration's rotation and a translation
//!    (`tracker_rx … tracker_z`), started from [`Registration::fit`]; for data already in the base frame,
//!    whose registration is the identity, the base error frame `E_0` in its place (`base_rx … base_z`, the
//!    same motion of the measured points; the model keeps its inverse, `E_0`, before the first joint, and
//!    the registration stays the identity);
//! 2. the mounting of the measured point in the flange frame (`mount_x … mount_z`);
//! 3. the generalized errors e_ik of every DH frame (eq. 6, `e11 … en6`), started from zero;
//! 4. for `elastic`, one compliance per joint (`c1 … cn`, rad/Nm): the commanded angles deflect by
//!    `δq_j = c_j τ_j(q)`, τ the gravity torques of the nominal inertials and the declared payload.
//!
//! Predicted point: `E_0 · FK_E(q + δq) · mount` (`E_0` the identity but for base-frame data); predicted
//! flange orientation: the rotation of `E_0 · FK_E(q + δq)`.
//!
//! **Identifiable set.** Structural, so it cannot change with the data: the Jacobian of every candidate is
//! stacked over a fixed set of configurations (a fixed internal seed, uniform within the joint limits), each
//! column scaled to unit norm, and the columns are taken in the priority order above by Gram–Schmidt,
//! keeping a column only if its part orthogonal to the ones kept before it is at least [`STRUCT_REL`](identify::STRUCT_REL).
//! This is QR in a fixed column order rather than with column pivoting: exactly redundant columns (e22 and
//! e13 of the iiwa, the tracker frame and the base-side errors) have equal norms, so a pivoting QR would
//! choose between them on rounding noise; a fixed order makes the choice a property of the robot. A column
//! whose norm stays below [`VANISH_REL`](identify::VANISH_REL) of the largest of its kind (geometric, or compliance) has no
//! measurable effect anywhere and is dropped first — the compliance of a joint whose gravity torque is
//! structurally zero (joint 1 of a level arm, joint 7 of the iiwa with its on-axis link and payload) goes
//! this way. The training data must then identify that whole set: the singular values of the training
//! Jacobian (columns scaled to unit norm) give the rank and condition number that `report()` shows, and a
//! rank below the set's size is refused with the least determined parameters named.
//!
//! **What the data determine.** Structural redundancy is not the whole story: a reflector a few micrometres
//! from the last joint's axis makes the rotations about it structurally independent but unmeasurable, and a
//! small training set cannot fix every parameter. So the structural set is reduced on the training Jacobian
//! itself ([`identify::determined`]): in the same priority order, a parameter is kept only if its standard
//! deviation given the kept ones before it, at the noise of the measurement, is below the size a real arm's
//! parameter reaches; the others stay nominal and are reported as [`Undetermined`], with the reason in words.
//! The noise ([`noise`]) is first the nominal model's residual — an upper bound, so nothing a near-axis
//! reflector barely moves comes in before anything is fitted — then the fitted model's own residual: the set
//! is judged again after each fit and refitted while that keeps another set, so the set a fit ends with is
//! the one its own residual determines. Neither goes below the scatter of repeated configurations (where the
//! data have enough) or else the tracker's specification. Judged at the nominal residual alone, a 7-joint
//! arm lost e54, e61 and e64 to 2.98 mm of "noise" that was mostly the error the fit removes. What is left
//! has full rank unless the tracker frame or the mounting themselves are not determined (always kept, so then
//! refused).
//!
//! **Reflector nests and 6-DoF probes.** With three reflectors the measured flange orientation is fitted too; a
//! rotation residual φ (rad) is weighted by the nest's RMS radius r (m), i.e. as the displacement `r·φ` it causes
//! at the reflectors, the quantity the tracker actually measured. A 6-DoF probe's orientation is fitted the same
//! way with r = [`PROBE_ORIENTATION_LENGTH_M`](super::tracker_frame::PROBE_ORIENTATION_LENGTH_M).
//!
//! **Solver.** The `levenberg-marquardt` crate (MINPACK's `lmder`) in coordinates whitened by the starting
//! Jacobian ([`solve::minimize`]), from the linearized (Gauss–Newton) solution: without whitening its diagonal
//! scaling zig-zags along the long valley that unmodelled elastic errors open in a weakly excited wrist. A fit
//! that does not converge within [`KinematicOptions::max_evaluations`] is an error, never a silent result.
//!
//! **Jacobian.** Analytic and exact at the current estimate: rotation parameters (tracker frame and every e_i4–6)
//! use SO(3)'s left Jacobian of their current value ([`so3_left_jacobian`](super::error_model::so3_left_jacobian)), so the derivative is not the
//! e = 0 one.
//!
//! **Files.** `params` (the candidates in priority order and the state they overwrite), `gravity` (gravity
//! torques on the DH chain for the compliances), `problem` (residuals and their analytic Jacobian), `solve`
//! (Levenberg–Marquardt in whitened coordinates), `identify` (the structural set, the rank check, the
//! identification Jacobian for design), `noise` (the noise the data are judged at), `fit` (the steps of the
//! fit), `geometry` (the fitted DH-frame errors as offsets of a robot description's joint frames: the twin's
//! truth, an exported URDF), and here the model: its fit, prediction and report.

mod fit;
pub mod geometry;
mod gravity;
mod identify;
mod noise;
mod params;
mod problem;
mod solve;

use nalgebra::{Isometry3, Point3, UnitQuaternion};
use serde::{Deserialize, Serialize};
use serde_json::json;

pub use gravity::GravityModel;
pub use identify::{Identification, Undetermined, plausible_size};
pub use noise::{MIN_NOISE_M, MIN_REPEAT_DOF, Noise, NoiseSource, SPEC_NOISE_M};
use params::State;
pub use params::{Param, candidates};
use problem::Problem;
pub use solve::Termination;

use super::error_model::{FrameErrors, flange_pose_with_errors, flange_pose_with_errors_on};
use super::method::{Basis, FitContext, Fitted, Method, MethodInfo, Prediction, RobotParameters};
use super::tracker_frame::Observation;
use crate::dataset::Dataset;
use crate::error::{Error, Result};
use crate::robot::dh::ChainPose;
use crate::robot::plausible;

/// The largest |compliance| (rad/Nm; m/N for a prismatic joint) a saved model may have. Real joints deflect
/// by 1e-5 to 1e-3 rad under a newton-metre; one that turned a radian would hold nothing.
pub const MAX_COMPLIANCE: f64 = 1.0;

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

pub const KINEMATIC: MethodInfo = MethodInfo {
    name: "kinematic",
    summary: "classical calibration: constant DH-frame errors, tracker frame and mounting by Levenberg–Marquardt",
    takes_inputs: false,
    base: None,
    parameters: RobotParameters::Identification { elastic: false },
};

pub const ELASTIC: MethodInfo = MethodInfo {
    name: "elastic",
    summary: "kinematic calibration plus one joint compliance per joint under the nominal gravity torques",
    takes_inputs: false,
    base: None,
    parameters: RobotParameters::Identification { elastic: true },
};

/// `kinematic`, and `elastic` with the joint compliances: one fitting.
pub struct Kinematic {
    pub elastic: bool,
}

impl Method for Kinematic {
    fn info(&self) -> &'static MethodInfo {
        if self.elastic { &ELASTIC } else { &KINEMATIC }
    }

    fn fit(&self, ctx: &FitContext, train: &Dataset, val: &Dataset) -> Result<Box<dyn Fitted>> {
        // Fitted once for a campaign's runs that share them: this method and the hybrid built on it (its base
        // fit is this fit, on the same sets), with the sets' extra inputs or others (the fit reads none of
        // them: only the training domain it records does, which is therefore the caller's own). An error is
        // not shared: the fit meets it again.
        let fit = || KinematicModel::fit(self.elastic, ctx, train, val);
        if !ctx.shares(train, val) {
            // Fitted here, on these very sets: the domain it records is theirs already.
            return Ok(Box::new(fit()?));
        }
        let mut model = match &*ctx.shared_without_inputs(self.info().name, train, val, fit) {
            Ok(model) => model.clone(),
            Err(_) => fit()?,
        };
        model.basis.domain = ctx.domain(train, val);
        Ok(Box::new(model))
    }
}

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
    /// The base error frame `E_0` before the first joint, fitted in place of the tracker frame for data
    /// already in the base frame (`None` otherwise).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub base_error: Option<Isometry3<f64>>,
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
    /// Standard deviation of each kept value from the training residuals (empty when there are no degrees
    /// of freedom left or the Jacobian is singular).
    #[serde(default)]
    pub std: Vec<f64>,
    /// Candidates left out as structurally redundant or without effect.
    pub dropped: Vec<Param>,
    /// Structurally identifiable parameters the training data do not determine, held at their nominal values.
    #[serde(default)]
    pub undetermined: Vec<Undetermined>,
    /// The noise of the measurement the kept set was judged at, and where it comes from.
    #[serde(default)]
    pub noise: Option<Noise>,
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
        let dh = ctx.dh;
        fit::check_points(method, dh.dof(), train, val)?;
        let mut poses = fit::poses(dh, train, val);
        let registration = fit::registration(ctx, train, val, &poses)?;
        let gravity = if elastic {
            Some(GravityModel::new(ctx.chain, dh, ctx.payload)?)
        } else {
            None
        };
        let length = registration.orientation_length();
        let base = State::initial(dh.dof(), registration.frame.mounting);
        let all = fit::candidates_to_fit(dh.dof(), elastic, registration.base_frame);
        let mut probe = Problem {
            dh,
            points: Vec::new(),
            length,
            base: base.clone(),
            params: all.clone(),
        };
        let (structural, dropped) = fit::structural(&probe, ctx, &all, gravity.as_ref());

        // What the training data determine of it, at the noise of the measurement (see `noise`); the rest
        // stays nominal and is reported.
        let val_poses = poses.split_off(train.len());
        probe.points = fit::points(dh, gravity.as_ref(), registration.observe(train)?, poses);
        let at_base = fit::jacobian_at_base(&mut probe, &base, &structural);
        let floor = noise::floor(train, val);
        let solution = fit::solve_judged(
            &mut probe,
            &base,
            &at_base,
            &structural,
            noise::nominal(dh, &registration, train, val, floor)?,
            floor,
            options.max_evaluations,
            method,
        )?;
        let mut undetermined = solution.undetermined;
        undetermined.extend(
            fit::structurally_dropped(&dropped)
                .into_iter()
                .filter(|u| u.parameter.starts_with('c')),
        );
        undetermined.extend(solution.at_bound);
        let state = State::with(&base, &solution.kept, &solution.values);
        let train_rms = problem::rms(dh, &state, &probe.points);
        if !train_rms.is_finite() || solution.values.iter().any(|v| !v.is_finite()) {
            return Err(Error::Invalid(format!(
                "{method}: the fit produced non-finite parameters"
            )));
        }
        let val_points = if val.is_empty() {
            Vec::new()
        } else {
            fit::points(dh, gravity.as_ref(), registration.observe(val)?, val_poses)
        };
        let validation_rms =
            (!val_points.is_empty()).then(|| problem::rms(dh, &state, &val_points));
        let evaluations = solution.minimum.evaluations;
        let base_error = fit::base_error(&registration, &state);
        Ok(KinematicModel {
            method,
            basis: Basis {
                joint_names: train.joint_names.clone(),
                dh: dh.clone(),
                registration: fit::refined(registration, &state, train_rms, evaluations),
                domain: ctx.domain(train, val),
            },
            base_error,
            errors: state.errors.clone(),
            compliance: elastic.then(|| state.compliance.clone()),
            gravity,
            orientation_length_m: length,
            kept: solution.kept,
            values: solution.values,
            std: solution.std,
            dropped,
            undetermined,
            noise: Some(solution.noise),
            rank: solution.id.rank,
            condition_number: solution.id.condition,
            evaluations,
            termination: solution.minimum.termination,
            train_rms_m: train_rms,
            validation_rms_m: validation_rms,
        })
    }

    /// A model read from a file can predict: its basis is valid ([`Basis::validate`]); one error row per DH
    /// row, translations plausible lengths and rotations plausible angles; `elastic` has one compliance per
    /// joint (at most [`MAX_COMPLIANCE`]) and a valid gravity model, `kinematic` neither; the kept
    /// parameters belong to the chain, one value each; every reported number finite.
    pub fn validate(&self) -> Result<()> {
        self.basis.validate()?;
        let n = self.basis.joint_names.len();
        let elastic = self.method.name == ELASTIC.name;
        plausible::count("errors", self.errors.len(), n, "DH rows (one per joint)")?;
        for (i, row) in self.errors.iter().enumerate() {
            for (k, &v) in row.iter().enumerate() {
                let field = format!("errors[{i}][{k}]");
                if k < 3 {
                    plausible::length(&field, v)?;
                } else {
                    plausible::angle(&field, v)?;
                }
            }
        }
        if let Some(e0) = &self.base_error {
            plausible::pose("base_error", e0)?;
        }
        match (elastic, &self.compliance, &self.gravity) {
            (true, Some(c), Some(g)) => {
                plausible::count("compliance", c.len(), n, "joints")?;
                for (j, &v) in c.iter().enumerate() {
                    plausible::non_negative(
                        &format!("compliance[{j}]"),
                        v,
                        MAX_COMPLIANCE,
                        "compliance in rad/Nm",
                    )?;
                }
                plausible::within("gravity", g.validate(n))?;
            }
            (false, None, None) => {}
            (true, ..) => {
                return Err(plausible::invalid(
                    "compliance",
                    "the elastic method needs both compliance and gravity",
                ));
            }
            (false, ..) => {
                return Err(plausible::invalid(
                    "compliance",
                    "the kinematic method has neither compliance nor gravity (null)",
                ));
            }
        }
        if let Some(l) = self.orientation_length_m {
            plausible::non_negative(
                "orientation_length_m",
                l,
                plausible::MAX_LENGTH_M,
                "length in metres",
            )?;
        }
        plausible::count(
            "values",
            self.values.len(),
            self.kept.len(),
            "kept parameters",
        )?;
        for (field, params) in [("kept", &self.kept), ("dropped", &self.dropped)] {
            if let Some(i) = params.iter().position(|p| !p.belongs_to(n, elastic)) {
                return Err(plausible::invalid(
                    &format!("{field}[{i}]"),
                    format!(
                        "{:?} is not a parameter of {} on {n} joints",
                        params[i], self.method.name
                    ),
                ));
            }
        }
        for (i, &v) in self.values.iter().enumerate() {
            plausible::length(&format!("values[{i}]"), v)?;
        }
        if !self.std.is_empty() {
            plausible::count("std", self.std.len(), self.kept.len(), "kept parameters")?;
            for (i, &v) in self.std.iter().enumerate() {
                plausible::non_negative(&format!("std[{i}]"), v, f64::MAX, "standard deviation")?;
            }
        }
        if self.rank > self.kept.len() {
            return Err(plausible::invalid(
                "rank",
                format!(
                    "{} is above the {} kept parameters",
                    self.rank,
                    self.kept.len()
                ),
            ));
        }
        plausible::finite("condition_number", self.condition_number)?;
        let rms = |field: &str, v: f64| {
            plausible::non_negative(field, v, plausible::MAX_LENGTH_M, "RMS in metres")
        };
        rms("train_rms_m", self.train_rms_m)?;
        if let Some(v) = self.validation_rms_m {
            rms("validation_rms_m", v)?;
        }
        Ok(())
    }

    /// Per joint of an `elastic` model: the compliance (rad/Nm), its standard deviation, and whether the data
    /// determined it (else why not); empty for `kinematic`.
    pub fn compliances(&self) -> Vec<serde_json::Value> {
        let Some(c) = &self.compliance else {
            return Vec::new();
        };
        c.iter()
            .enumerate()
            .map(|(j, &value)| {
                let name = Param::Compliance(j).name();
                let std = self
                    .kept
                    .iter()
                    .position(|&p| p == Param::Compliance(j))
                    .and_then(|i| self.std.get(i));
                let why = self.undetermined.iter().find(|u| u.parameter == name);
                json!({
                    "joint": self.basis.joint_names.get(j),
                    "parameter": name,
                    "value_rad_per_nm": value,
                    "std_rad_per_nm": std,
                    "determined": why.is_none() && std.is_some(),
                    "undetermined_because": why.map(|u| &u.reason),
                })
            })
            .collect()
    }

    /// Names of the kept parameters, in priority order.
    pub fn kept_names(&self) -> Vec<String> {
        self.kept.iter().map(|p| p.name()).collect()
    }

    /// The calibrated flange pose at commanded `q` (after the base error frame, where there is one).
    pub fn flange_pose(&self, q: &[f64]) -> Isometry3<f64> {
        let dh = &self.basis.dh;
        // `ErrorFrames::new(..).flange`'s products, without its frames.
        let flange = match (&self.gravity, &self.compliance) {
            (Some(g), Some(c)) => {
                flange_pose_with_errors(dh, &deflected(q, &g.torques(dh, q), c), &self.errors)
            }
            _ => flange_pose_with_errors(dh, q, &self.errors),
        };
        self.with_base_error(flange)
    }

    /// [`KinematicModel::flange_pose`] at a pose of the model's nominal chain, the same bits: its frames give
    /// the gravity torques and, where no compliance deflects the joints, its links the chain with errors.
    pub fn flange_pose_at(&self, pose: &ChainPose) -> Isometry3<f64> {
        let dh = &self.basis.dh;
        let flange = match (&self.gravity, &self.compliance) {
            (Some(g), Some(c)) => {
                let qd = deflected(&pose.q, &g.torques_on(dh, &pose.frames), c);
                flange_pose_with_errors(dh, &qd, &self.errors)
            }
            _ => flange_pose_with_errors_on(dh, pose.links.iter().copied(), &self.errors),
        };
        self.with_base_error(flange)
    }

    fn with_base_error(&self, flange: Isometry3<f64>) -> Isometry3<f64> {
        match &self.base_error {
            Some(e0) => e0 * flange,
            None => flange,
        }
    }
}

/// The joint angles the gravity torques `torques` deflect `q` to through the compliances `c`.
fn deflected(q: &[f64], torques: &[f64], c: &[f64]) -> Vec<f64> {
    torques
        .iter()
        .zip(c)
        .zip(q)
        .map(|((t, c), q)| q + c * t)
        .collect()
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

    fn point_at(&self, pose: &ChainPose, _inputs: &[f64]) -> (Point3<f64>, UnitQuaternion<f64>) {
        let f = self.flange_pose_at(pose);
        (f * self.basis.registration.frame.mounting, f.rotation)
    }

    /// One pass over the nominal chain: its flange is the nominal kinematics (`DhChain::flange_pose`'s
    /// products), its links and frames give the prediction ([`KinematicModel::flange_pose_at`]).
    fn nominal_and_prediction(
        &self,
        q: &[f64],
        _inputs: &[f64],
    ) -> ((Point3<f64>, UnitQuaternion<f64>), Prediction) {
        let pose = self.basis.dh.pose(q);
        let f = pose.flange(&self.basis.dh);
        let mounting = self.basis.registration.frame.mounting;
        let (position, orientation) = self.point_at(&pose, &[]);
        let prediction = Prediction {
            position,
            linearized_position: position,
            orientation,
        };
        ((f * mounting, f.rotation), prediction)
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
            "undetermined": self.undetermined,
            "noise_mm": self.noise.map(|n| n.sigma_m * 1e3),
            "noise_source": self.noise.map(|n| n.source),
            "base_error": self.base_error,
            "std": self.kept.iter().zip(&self.std).map(|(p, s)| (p.name(), json!(s))).collect::<serde_json::Map<_, _>>(),
            "rank": self.rank,
            "condition_number": self.condition_number,
            "evaluations": self.evaluations,
            "termination": self.termination,
            "train_rms_m": self.train_rms_m,
            "validation_rms_m": self.validation_rms_m,
            "test_rms_m": test_rms,
            "orientation_length_m": self.orientation_length_m,
            "compliance_rad_per_nm": self.compliance,
            "compliances": self.compliances(),
            "values": values,
        })
    }
}
