//! One interface for every calibration method: fit on training data (validation data for hyper-parameters),
//! predict the measured point and the flange orientation for joint angles, and invert — the joint command
//! that makes the calibrated model reach a target, which is what a controller is sent.
//!
//! What a method *is* ([`MethodInfo`]) and how it fits ([`Method`]) are stated once, in the method's own file,
//! and asked of it everywhere else; the list of methods a user can choose is `calib::registry`, which sits
//! above every method. This file knows no method.

use std::any::Any;
use std::fmt;
use std::sync::{Arc, Mutex, PoisonError};

use nalgebra::{DMatrix, DVector, Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Deserializer, Serialize, Serializer};

use super::domain::Domain;
use super::error_model::ErrorModelKind;
use super::regression::RegressionOptions;
use super::tracker_frame::{Observation, Registration};
use crate::dataset::Dataset;
use crate::error::{Error, Result};
use crate::numeric;
use crate::robot::dh::{ChainPose, DhChain};
use crate::robot::kinematics::joint_column;
use crate::robot::plausible;
use crate::robot::{Chain, Payload};
use crate::world::World;

/// What a method is, said once next to the method (a `const` in its file) and asked of it everywhere else.
#[derive(Debug, PartialEq)]
pub struct MethodInfo {
    /// The name a user chooses it by, in files and on the command line.
    pub name: &'static str,
    /// One line on what it does.
    pub summary: &'static str,
    /// Whether it regresses on the data's inputs beyond the joint angles (e.g. `temperature`).
    pub takes_inputs: bool,
    /// A hybrid's base method: the one whose prediction it corrects.
    pub base: Option<&'static MethodInfo>,
    /// The parameters of the robot it identifies: what a campaign for it is designed to determine.
    pub parameters: RobotParameters,
}

/// The parameters of the robot a method identifies, the model its points are designed for ([`crate::design`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RobotParameters {
    /// No parameters of the robot to determine.
    None,
    /// The error parameters of one of the paper's error models.
    ErrorModel(ErrorModelKind),
    /// The structurally identifiable set of the kinematic fit, with compliances when `elastic`.
    Identification { elastic: bool },
}

impl fmt::Display for MethodInfo {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.pad(self.name)
    }
}

/// A method is written to files by its name.
impl Serialize for MethodInfo {
    fn serialize<S: Serializer>(&self, serializer: S) -> std::result::Result<S::Ok, S::Error> {
        serializer.serialize_str(self.name)
    }
}

impl MethodInfo {
    /// Whether it identifies parameters of the robot: those its points can be designed to determine.
    pub fn has_robot_parameters(&self) -> bool {
        self.parameters != RobotParameters::None
    }

    /// Reads a method's name from a file, as one of `methods` (those a model type can be).
    pub fn deserialize_among<'de, D: Deserializer<'de>>(
        deserializer: D,
        methods: &[&'static MethodInfo],
    ) -> std::result::Result<&'static MethodInfo, D::Error> {
        let name = String::deserialize(deserializer)?;
        methods
            .iter()
            .copied()
            .find(|m| m.name == name)
            .ok_or_else(|| {
                let names: Vec<&str> = methods.iter().map(|m| m.name).collect();
                serde::de::Error::custom(format!(
                    "method '{name}' is not one of {}",
                    names.join(", ")
                ))
            })
    }
}

/// A calibration method: what it is and how it fits. Each method's file implements it beside its
/// [`MethodInfo`]; the registry lists the implementations.
pub trait Method: Sync {
    /// What the method is.
    fn info(&self) -> &'static MethodInfo;
    /// Fits on `train`, choosing hyper-parameters on `val`.
    fn fit(&self, ctx: &FitContext, train: &Dataset, val: &Dataset) -> Result<Box<dyn Fitted>>;
}

/// What every fitted model holds besides its own parameters: the robot's joints, the nominal kinematics it
/// corrects and the registration its data are observed through. A model's file writes these fields in its
/// own object (`#[serde(flatten)]`).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Basis {
    /// The robot's joints, in the order of `q`.
    pub joint_names: Vec<String>,
    /// The nominal kinematics the method corrects (DH form of the robot's URDF).
    pub dh: DhChain,
    pub registration: Registration,
    /// What the model was fitted on; empty in a model saved before domains were recorded.
    #[serde(default, skip_serializing_if = "Domain::is_empty")]
    pub domain: Domain,
}

impl Basis {
    /// What a file holds for the basis is usable: one DH row per joint name, names non-empty and distinct
    /// (a data column drives one joint), and the DH table and registration valid on their own.
    pub fn validate(&self) -> Result<()> {
        if let Some(i) = self.joint_names.iter().position(|n| n.trim().is_empty()) {
            return Err(plausible::invalid(
                &format!("joint_names[{i}]"),
                "an empty joint name",
            ));
        }
        for (i, name) in self.joint_names.iter().enumerate() {
            if self.joint_names[..i].contains(name) {
                return Err(plausible::invalid(
                    &format!("joint_names[{i}]"),
                    format!("'{name}' appears twice"),
                ));
            }
        }
        plausible::within("dh", self.dh.validate())?;
        plausible::count(
            "dh.rows",
            self.dh.rows.len(),
            self.joint_names.len(),
            "joint_names",
        )?;
        plausible::within("registration", self.registration.validate())?;
        self.domain.validate(self.joint_names.len())
    }
}

/// What a method may know besides the data: the nominal robot as its maker describes it.
pub struct FitContext<'a> {
    pub chain: &'a Chain,
    pub dh: &'a DhChain,
    /// The payload the user declares (for gravity torques of the elastic models).
    pub payload: Payload,
    pub regression: RegressionOptions,
    /// What the methods fitted on the same sets under this context compute alike ([`FitShare`]); `None`: each
    /// fit computes its own.
    pub share: Option<&'a FitShare<'a>>,
}

/// Named values of any type, made once ([`FitShare`]).
type Slots = Mutex<Vec<(&'static str, Arc<dyn Any + Send + Sync>)>>;

/// What several methods fitted on one pair of training and validation sets (a study's campaign) compute alike,
/// whatever the method: the tracker-frame registration, the training domain, a family of methods' own
/// preparation (the paper's candidate rows and their factorizations). The first fit that asks computes a value
/// and the others take it; a value is a function of the sets and the context alone, so every fit gets the bits
/// it would have computed itself, whichever thread came first.
pub struct FitShare<'d> {
    train: &'d Dataset,
    val: &'d Dataset,
    slots: Slots,
    /// The values made without reading the sets' extra inputs ([`FitContext::shared_without_inputs`]), apart:
    /// the fits beside these sets take them, and [`FitShare::drop_what_reads_inputs`] keeps them.
    without_inputs: Slots,
    /// The share of the same points with other extra inputs (or none), whose values that do not read the
    /// inputs ([`FitContext::shared_without_inputs`]) this one takes instead of computing them again.
    points_of: Option<&'d FitShare<'d>>,
}

impl<'d> FitShare<'d> {
    /// Values shared by the fits on `train` and `val`.
    pub fn new(train: &'d Dataset, val: &'d Dataset) -> FitShare<'d> {
        FitShare {
            train,
            val,
            slots: Slots::default(),
            without_inputs: Slots::default(),
            points_of: None,
        }
    }

    /// Values shared by the fits on `train` and `val`, which are `other`'s sets — the same points, in the
    /// same order — with other extra inputs (a trajectory campaign's samples with the motion as inputs):
    /// what does not read the inputs is taken from `other`. Refused (`None`) where the points differ.
    pub fn beside(
        other: &'d FitShare<'d>,
        train: &'d Dataset,
        val: &'d Dataset,
    ) -> Option<FitShare<'d>> {
        let same = |a: &Dataset, b: &Dataset| a.with_other_inputs_is(b);
        (same(train, other.train) && same(val, other.val)).then(|| FitShare {
            points_of: Some(other),
            ..FitShare::new(train, val)
        })
    }

    /// The training set this holds.
    pub fn train(&self) -> &'d Dataset {
        self.train
    }

    /// The validation set this holds.
    pub fn val(&self) -> &'d Dataset {
        self.val
    }

    /// Whether `train` and `val` are the sets this holds (the very values, not equal ones).
    fn holds(&self, train: &Dataset, val: &Dataset) -> bool {
        std::ptr::eq(train, self.train) && std::ptr::eq(val, self.val)
    }

    /// Drops the values that read the sets' extra inputs (the paper's factorizations, the domain), keeping
    /// those the fits beside these sets still take: their memory is not held through those fits.
    pub fn drop_what_reads_inputs(&mut self) {
        self.slots
            .get_mut()
            .unwrap_or_else(PoisonError::into_inner)
            .clear();
    }

    /// The value named `name` (of type `T`), made by `make` on first use.
    fn get<T: Any + Send + Sync>(&self, name: &'static str, make: impl FnOnce() -> T) -> Arc<T> {
        Self::get_in(&self.slots, name, make)
    }

    /// [`FitShare::get`] among `slots`.
    fn get_in<T: Any + Send + Sync>(
        slots: &Slots,
        name: &'static str,
        make: impl FnOnce() -> T,
    ) -> Arc<T> {
        let find = |slots: &[(&'static str, Arc<dyn Any + Send + Sync>)]| {
            slots
                .iter()
                .filter(|(n, _)| *n == name)
                .find_map(|(_, v)| v.clone().downcast::<T>().ok())
        };
        if let Some(v) = find(&slots.lock().unwrap_or_else(PoisonError::into_inner)) {
            return v;
        }
        // Made outside the lock: the other fits go on meanwhile, and one that made it too keeps the first.
        let made = Arc::new(make());
        let mut slots = slots.lock().unwrap_or_else(PoisonError::into_inner);
        find(&slots).unwrap_or_else(|| {
            slots.push((name, made.clone()));
            made
        })
    }
}

impl<'a> FitContext<'a> {
    /// A context with no declared payload and the default regression options (the paper's features).
    pub fn new(chain: &'a Chain, dh: &'a DhChain) -> FitContext<'a> {
        FitContext {
            chain,
            dh,
            payload: Payload::NONE,
            regression: RegressionOptions::default(),
            share: None,
        }
    }

    /// This context for fits on the sets of `share`, which share what they compute alike.
    pub fn sharing<'b>(&self, share: &'b FitShare<'b>) -> FitContext<'b>
    where
        'a: 'b,
    {
        FitContext {
            chain: self.chain,
            dh: self.dh,
            payload: self.payload,
            regression: self.regression.clone(),
            share: Some(share),
        }
    }

    /// The share that holds `train` and `val`, if any.
    fn share_of(&self, train: &Dataset, val: &Dataset) -> Option<&'a FitShare<'a>> {
        self.share.filter(|s| s.holds(train, val))
    }

    /// Whether what fits on `train` and `val` compute is shared with other fits ([`FitShare`]).
    pub fn shares(&self, train: &Dataset, val: &Dataset) -> bool {
        self.share_of(train, val).is_some()
    }

    /// The value named `name` that `make` computes from `train` and `val` (and this context), computed once
    /// for every fit that shares them ([`FitShare`]).
    pub fn shared<T: Any + Send + Sync>(
        &self,
        name: &'static str,
        train: &Dataset,
        val: &Dataset,
        make: impl FnOnce() -> T,
    ) -> Arc<T> {
        match self.share_of(train, val) {
            Some(s) => s.get(name, make),
            None => Arc::new(make()),
        }
    }

    /// [`FitContext::shared`] for a value that `make` computes without reading the sets' extra inputs: also
    /// shared with the fits on the same points with other inputs ([`FitShare::beside`]).
    pub fn shared_without_inputs<T: Any + Send + Sync>(
        &self,
        name: &'static str,
        train: &Dataset,
        val: &Dataset,
        make: impl FnOnce() -> T,
    ) -> Arc<T> {
        match self.share_of(train, val) {
            Some(s) => FitShare::get_in(&s.points_of.unwrap_or(s).without_inputs, name, make),
            None => Arc::new(make()),
        }
    }

    /// The tracker-frame registration on `train` and `val` ([`Registration::fit`] on the nominal chain),
    /// shared.
    pub fn registration(&self, train: &Dataset, val: &Dataset) -> Result<Registration> {
        self.registration_by(train, val, || Registration::fit(self.dh, train, val))
    }

    /// [`FitContext::registration`], computed by `fit` where it is not shared yet: `fit` must give
    /// [`Registration::fit`]'s bits (e.g. [`Registration::fit_at`] with flange poses the caller has).
    pub fn registration_by(
        &self,
        train: &Dataset,
        val: &Dataset,
        fit: impl Fn() -> Result<Registration>,
    ) -> Result<Registration> {
        match &*self.shared_without_inputs("registration", train, val, &fit) {
            Ok(r) => Ok(r.clone()),
            // An error is not shared: the fit says it again.
            Err(_) => fit(),
        }
    }

    /// The training domain of `train` and `val` ([`Domain::of`]), shared.
    pub fn domain(&self, train: &Dataset, val: &Dataset) -> Domain {
        (*self.shared("domain", train, val, || Domain::of(train, val))).clone()
    }

    /// What every method fitted in `world` may know: its nominal robot and the payload the user declares —
    /// none of its truth.
    pub fn of(world: &'a World) -> FitContext<'a> {
        FitContext {
            payload: world.payload(),
            ..FitContext::new(&world.nominal, &world.dh)
        }
    }

    pub fn limits(&self) -> (Vec<f64>, Vec<f64>) {
        (self.chain.lower_limits(), self.chain.upper_limits())
    }
}

/// A predicted measured point (base frame of the method's registration) and flange orientation.
#[derive(Clone, Debug)]
pub struct Prediction {
    pub position: Point3<f64>,
    /// The same by a linearized model (eq. 10), where the method has one; otherwise `position`.
    pub linearized_position: Point3<f64>,
    pub orientation: UnitQuaternion<f64>,
}

/// A fitted calibration. `Any`: the registry writes `model.json` for the model types it knows
/// (`registry::SavedModel`).
pub trait Fitted: Any + Send + Sync {
    /// What method this is.
    fn info(&self) -> &'static MethodInfo;
    /// What every model holds: joints, nominal kinematics, registration.
    fn basis(&self) -> &Basis;
    fn method(&self) -> &str {
        self.info().name
    }
    fn registration(&self) -> &Registration {
        &self.basis().registration
    }
    /// The robot's joints, in the order of `q`.
    fn joint_names(&self) -> &[String] {
        &self.basis().joint_names
    }
    /// The nominal kinematics the method corrects.
    fn dh(&self) -> &DhChain {
        &self.basis().dh
    }
    /// The prediction at `q`; a method that regresses on extra inputs ([`Fitted::input_names`]) takes them at
    /// their training means.
    fn predict(&self, q: &[f64]) -> Prediction;
    /// Names of the inputs beyond the joint angles that the model was given (e.g. `temperature`), in the order
    /// [`Fitted::predict_with`] takes their values; empty for a method that uses none.
    fn input_names(&self) -> &[String] {
        &[]
    }
    /// The prediction at `q` with the point's extra inputs (in [`Fitted::input_names`] order; empty: their
    /// training means). A method that uses none ignores them.
    fn predict_with(&self, q: &[f64], inputs: &[f64]) -> Prediction {
        let _ = inputs;
        self.predict(q)
    }
    /// [`Fitted::predict_with`]'s position and orientation, the same bits, at `pose`: a configuration with
    /// the links and frames of this model's nominal chain ([`Fitted::dh`]) computed once for every model
    /// judged there (a method that uses the nominal chain skips its own pass over it).
    fn point_at(&self, pose: &ChainPose, inputs: &[f64]) -> (Point3<f64>, UnitQuaternion<f64>) {
        let p = self.predict_with(&pose.q, inputs);
        (p.position, p.orientation)
    }
    /// The calibrated flange pose the prediction implies: the predicted orientation, placed so that it carries
    /// the mounting onto the predicted point. For a rigid model this is the model's own flange; an evaluation
    /// uses it to put the measured point elsewhere on the flange (a probe remounted between campaigns).
    fn predicted_flange(&self, q: &[f64], inputs: &[f64]) -> Isometry3<f64> {
        let p = self.predict_with(q, inputs);
        let m = self.registration().frame.mounting.coords;
        Isometry3::from_parts(
            Translation3::from(p.position.coords - p.orientation * m),
            p.orientation,
        )
    }
    /// Whether the method models the flange orientation (else its predicted orientation is the nominal one).
    fn models_orientation(&self) -> bool {
        false
    }
    /// Whether part of the model is a regression (on the joint angles or the extra inputs): only that part
    /// extrapolates outside the training domain and fades out there ([`super::domain`]), so only such a
    /// model is warned about points outside it.
    fn has_regression(&self) -> bool {
        false
    }
    /// Method-specific facts for `report.json` (kept parameters, R², rank, condition number…), given the
    /// test observations.
    fn report(&self, test: &[Observation]) -> serde_json::Value;

    /// The nominal model's measured point and flange orientation: what the controller believes.
    fn nominal(&self, q: &[f64]) -> (Point3<f64>, UnitQuaternion<f64>) {
        let f = self.dh().flange_pose(q);
        (f * self.registration().frame.mounting, f.rotation)
    }

    /// [`Fitted::nominal`] and [`Fitted::predict_with`] at `q`, the same bits: a method whose prediction
    /// passes over the nominal chain takes the nominal kinematics from that pass instead of a second one.
    fn nominal_and_prediction(
        &self,
        q: &[f64],
        inputs: &[f64],
    ) -> ((Point3<f64>, UnitQuaternion<f64>), Prediction) {
        (self.nominal(q), self.predict_with(q, inputs))
    }

    /// Joint angles, from `seed`, at which this model puts the measured point at `target` (and the flange at
    /// `orientation` when the method models it), with the extra inputs `inputs` ([`Fitted::predict_with`]).
    /// Gauss–Newton on the nominal Jacobian: every model differs from the nominal one by a fraction of a
    /// millimetre. Returns the command and the remaining distance (m).
    fn command_for(
        &self,
        target: &Point3<f64>,
        orientation: Option<&UnitQuaternion<f64>>,
        seed: &[f64],
        inputs: &[f64],
    ) -> Result<(Vec<f64>, f64)> {
        let rotation = orientation.filter(|_| self.models_orientation());
        let rows = if rotation.is_some() { 6 } else { 3 };
        let mut q = seed.to_vec();
        let mut err = f64::INFINITY;
        // The rows' fixed rotations once for every iteration's pass (the same links, bit for bit).
        let fixed = self.dh().fixed_rotations();
        for _ in 0..20 {
            // One pass over the nominal chain for the prediction and the Jacobian.
            let pose = self.dh().pose_fixed(&q, &fixed);
            let (position, orientation) = self.point_at(&pose, inputs);
            if !numeric::all_finite(position.coords.iter().chain(orientation.coords.iter())) {
                return Err(Error::Invalid(format!(
                    "the model's prediction is not a finite number at joints {}: the configuration is far \
                     outside what the model was fitted on",
                    short_list(&q)
                )));
            }
            let dp = target - position;
            let dr = rotation.map_or(Vector3::zeros(), |r| {
                (r * orientation.inverse()).scaled_axis()
            });
            err = dp.norm();
            if err > MAX_CORRECTION_M || dr.norm() > MAX_CORRECTION_RAD {
                return Err(Error::Invalid(format!(
                    "the model differs from the nominal robot here by {:.0} mm and {:.2} rad (more than {:.0} mm \
                     or {MAX_CORRECTION_RAD} rad): it is extrapolating, the configuration is outside what it \
                     was fitted on",
                    err * 1e3,
                    dr.norm(),
                    MAX_CORRECTION_M * 1e3
                )));
            }
            if err < 1e-10 && dr.norm() < 1e-10 {
                return Ok((q, err));
            }
            let mut rhs = DVector::zeros(rows);
            rhs.fixed_rows_mut::<3>(0).copy_from(&dp);
            if rows == 6 {
                rhs.fixed_rows_mut::<3>(3).copy_from(&dr);
            }
            let mounting = &self.registration().frame.mounting;
            let j = nominal_jacobian_on(self.dh(), mounting, &pose.frames);
            let step = numeric::svd(j.rows(0, rows).into_owned(), true, true, "inverse")?
                .solve(&rhs, 1e-12)
                .map_err(|e| Error::Invalid(format!("inverse: singular Jacobian ({e})")))?;
            // A step larger than any correction means the nominal Jacobian is (nearly) singular here and
            // Gauss–Newton is diverging.
            if step.norm().is_nan() || step.norm() > MAX_INVERSE_STEP_RAD {
                return Err(Error::Invalid(format!(
                    "inverse: the configuration is singular or nearly so (a correction step of {:.1e} \
                     rad, the largest sensible is {MAX_INVERSE_STEP_RAD})",
                    step.norm()
                )));
            }
            for (qi, s) in q.iter_mut().zip(step.iter()) {
                *qi += s;
            }
        }
        if err < 1e-7 {
            Ok((q, err))
        } else {
            Err(Error::Invalid(format!(
                "inverse did not converge ({err:.3e} m left): the configuration may be singular"
            )))
        }
    }

    /// The command that makes the calibrated model reach what the nominal model reaches at `q_intended`,
    /// with the extra inputs `inputs` (empty: their training means).
    fn compensate(&self, q_intended: &[f64], inputs: &[f64]) -> Result<(Vec<f64>, f64)> {
        let (p, r) = self.nominal(q_intended);
        self.command_for(&p, Some(&r), q_intended, inputs)
    }
}

/// The largest distance (m) between the calibrated and the nominal model that [`Fitted::command_for`]
/// corrects: real robots are off by millimetres (a few tenths on the iiwa, up to ~10 mm on a large arm with
/// a bad zero); a model that differs by 50 mm is extrapolating, and its command would be nonsense.
pub const MAX_CORRECTION_M: f64 = 0.05;

/// The largest rotation (rad) between the calibrated and the nominal flange that [`Fitted::command_for`]
/// corrects: a model that absorbs a nest's unknown mounting rotation (0.22 rad in `paper_iiwa_pose`) must
/// pass, a rotation of tens of degrees is a polynomial extrapolating.
pub const MAX_CORRECTION_RAD: f64 = 0.5;

/// The largest joint correction (rad, norm over the joints) one step of [`Fitted::command_for`] may take.
/// Away from a singularity a step is about the correction itself: under 0.05 m / reach plus the
/// [`MAX_CORRECTION_RAD`] of orientation (0.2 rad for the tilted nest of `paper_iiwa_pose`). At a straight
/// arm the steps of a diverging Gauss–Newton are hundreds of radians.
pub const MAX_INVERSE_STEP_RAD: f64 = 1.0;

/// Geometric Jacobian of a point fixed to the flange (rows 0–2) and of the flange rotation (rows 3–5), for the
/// nominal DH chain.
pub fn nominal_jacobian(dh: &DhChain, point_in_flange: &Point3<f64>, q: &[f64]) -> DMatrix<f64> {
    nominal_jacobian_on(dh, point_in_flange, &dh.frames(q))
}

/// [`nominal_jacobian`] on the DH frames of the configuration (`dh.frames(q)`, or a [`ChainPose`]'s).
pub fn nominal_jacobian_on(
    dh: &DhChain,
    point_in_flange: &Point3<f64>,
    frames: &[Isometry3<f64>],
) -> DMatrix<f64> {
    let n = dh.dof();
    let p = frames[n] * dh.tool * point_in_flange;
    let mut j = DMatrix::zeros(6, n);
    for (c, f) in frames.iter().take(n).enumerate() {
        let (lin, ang) = joint_column(
            &(f.rotation * Vector3::z()),
            &Point3::from(f.translation.vector),
            &p,
            dh.rows[c].prismatic,
        );
        j.fixed_view_mut::<3, 1>(0, c).copy_from(&lin);
        j.fixed_view_mut::<3, 1>(3, c).copy_from(&ang);
    }
    j
}

/// Numbers for a message: at most four, each to four significant digits (a huge one stays short).
fn short_list(values: &[f64]) -> String {
    let mut parts: Vec<String> = values.iter().take(4).map(|v| format!("{v:.4e}")).collect();
    if values.len() > 4 {
        parts.push("…".into());
    }
    format!("[{}]", parts.join(", "))
}
