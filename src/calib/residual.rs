//! Data-driven correction of what a model leaves: `residual-ridge` and `hybrid`.
//!
//! `residual-ridge` registers the tracker frame and the mounting as every method does, then models the
//! residual of each observation against the nominal prediction directly: one ridge polynomial per component
//! (the measured point's 3 coordinates in the base frame and, with a reflector nest, the 3 components of the
//! relative rotation vector of the flange), on the joint angles only, with inputs, degree and α chosen on the
//! validation data by [`fit_all`](super::regression::fit_all). It knows nothing of kinematics; it is what a physical model must beat.
//!
//! The registration on nominal points absorbs part of any error into the tracker pose and the mounting, and
//! what it absorbs (a small rotation times the TCP position, the flange rotation times a mounting offset) is
//! a product of joints that a sum of per-joint polynomials cannot represent. So `residual-ridge` alternates:
//! register onto the nominal points plus the modelled residual, refit the residual, until the validation
//! error stops improving (on a smooth field of two joints the error against the truth falls from 12 to
//! 4 µm). The saved registration is the last one, its `rms` that of the registered points against nominal
//! plus modelled residual. `hybrid` keeps its base's registration: a physical base model has the rigid
//! motions in its own parameters.
//!
//! `hybrid` fits a physical base method first (`elastic`, or `kinematic` for `hybrid-kinematic`) and models
//! the residual of the base's prediction the same way, on the base's registration.
//!
//! Both model the residual with a [`ResidualCorrection`] (file `correction`), which never makes its
//! reference worse on the validation data.

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};
use serde_json::json;

pub use super::correction::{ComponentModel, ResidualCorrection};
use super::correction::{Reference, ResidualSetup, mean};
use super::domain::Domain;
use super::kinematic::{ELASTIC, KINEMATIC};
use super::method::{Basis, FitContext, Fitted, Method, MethodInfo, Prediction, RobotParameters};
use super::rigid::centre;
use super::tracker_frame::{
    Observation, Registration, fit_mounting, fit_tracker_frame, probe_rotation,
};
use crate::dataset::Dataset;
use crate::error::{Error, Result};
use crate::robot::dh::{ChainPose, DhChain};
use crate::robot::plausible;

pub const RESIDUAL_RIDGE: MethodInfo = MethodInfo {
    name: "residual-ridge",
    summary: "the nominal prediction plus ridge models of its residual on the joint angles (and extra inputs)",
    takes_inputs: true,
    base: None,
    parameters: RobotParameters::None,
};

pub const HYBRID: MethodInfo = hybrid(
    "hybrid",
    &ELASTIC,
    "base elastic (constant geometry and joint compliances) plus ridge models of its residual on the joint \
     angles (and extra inputs)",
);
pub const HYBRID_KINEMATIC: MethodInfo = hybrid(
    "hybrid-kinematic",
    &KINEMATIC,
    "base kinematic (constant geometry only, no compliance) plus ridge models of its residual on the joint \
     angles (and extra inputs)",
);

/// A hybrid on a base that has no hybrid of its own above (tests build them on every method). It is named
/// `hybrid-<base>` ([`HybridModel::method`]); what else it is depends on the base, which this cannot say.
pub const HYBRID_ON_OTHER_BASE: MethodInfo = MethodInfo {
    name: "hybrid-<base>",
    summary: "a base method's prediction plus ridge models of its residual",
    takes_inputs: true,
    base: None,
    parameters: RobotParameters::None,
};

/// The hybrid on `base`: its residual is data-driven, its parameters and design model are the base's;
/// `summary` names the base (a user chooses by it).
const fn hybrid(
    name: &'static str,
    base: &'static MethodInfo,
    summary: &'static str,
) -> MethodInfo {
    MethodInfo {
        name,
        summary,
        takes_inputs: true,
        base: Some(base),
        parameters: base.parameters,
    }
}

/// `residual-ridge`.
pub struct ResidualRidge;

impl Method for ResidualRidge {
    fn info(&self) -> &'static MethodInfo {
        &RESIDUAL_RIDGE
    }

    fn fit(&self, ctx: &FitContext, train: &Dataset, val: &Dataset) -> Result<Box<dyn Fitted>> {
        Ok(Box::new(ResidualModel::fit(ctx, train, val)?))
    }
}

/// A hybrid on `base`: fits the base, then the residual of its predictions. The hybrid's own check of the
/// sets runs first, so a hybrid on too few points fails under its own name.
pub struct Hybrid {
    pub base: &'static dyn Method,
}

impl Method for Hybrid {
    fn info(&self) -> &'static MethodInfo {
        HybridModel::on_base(self.base.info()).0
    }

    fn fit(&self, ctx: &FitContext, train: &Dataset, val: &Dataset) -> Result<Box<dyn Fitted>> {
        Ok(Box::new(self.fit_hybrid(ctx, train, val)?))
    }
}

impl Hybrid {
    /// [`Method::fit`] with the hybrid's own type, whose base a caller can ask for.
    pub fn fit_hybrid(
        &self,
        ctx: &FitContext,
        train: &Dataset,
        val: &Dataset,
    ) -> Result<HybridFitted> {
        HybridModel::check_sets(self.base.info(), train, val)?;
        HybridModel::fit(self.base.fit(ctx, train, val)?, ctx, train, val)
    }
}

/// `residual-ridge` alternates registration and residual model at most this many rounds, and stops once
/// `STALLED_ROUNDS` rounds in a row lowered the mean validation error by less than `ROUND_GAIN` (relative).
const REGISTRATION_ROUNDS: usize = 40;
const ROUND_GAIN: f64 = 1e-3;
const STALLED_ROUNDS: usize = 3;

fn check_sets(method: &str, train: &Dataset, val: &Dataset) -> Result<()> {
    if train.is_empty() || val.is_empty() {
        return Err(Error::Invalid(format!(
            "{method}: {} training and {} validation points: both sets must be non-empty",
            train.len(),
            val.len()
        )));
    }
    Ok(())
}

/// `residual-ridge`: the nominal prediction plus a ridge model of its residual, with the registration refitted
/// alongside (module notes).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ResidualModel {
    #[serde(flatten)]
    pub basis: Basis,
    pub residual: ResidualCorrection,
}

impl ResidualModel {
    pub fn fit(ctx: &FitContext, train: &Dataset, val: &Dataset) -> Result<ResidualModel> {
        check_sets(RESIDUAL_RIDGE.name, train, val)?;
        let mut registration = ctx.registration(train, val)?;
        let centres: Vec<Point3<f64>> = train
            .measured
            .iter()
            .chain(&val.measured)
            .map(|m| centre(m))
            .collect();
        let q: Vec<&Vec<f64>> = train.q.iter().chain(&val.q).collect();
        let inputs: Vec<&[f64]> = (0..train.len())
            .map(|i| train.extra_inputs_of(i))
            .chain((0..val.len()).map(|i| val.extra_inputs_of(i)))
            .collect();
        let orientations: Option<Vec<UnitQuaternion<f64>>> =
            match (&train.measured_orientation, &val.measured_orientation) {
                (Some(a), Some(b)) => Some(a.iter().chain(b).copied().collect()),
                _ => None,
            };
        let extra_inputs = train.extra_input_names().to_vec();
        let flanges: Vec<Isometry3<f64>> = q.iter().map(|q| ctx.dh.flange_pose(q)).collect();
        // The rounds refit on the same points: their candidate rows, domain and nominal flange poses are the
        // same every round; only the registration moves.
        let domain = ctx.domain(train, val);
        let (mut obs_train, mut obs_val) =
            (registration.observe(train)?, registration.observe(val)?);
        let mut setup =
            ResidualSetup::new(&train.joint_names, &extra_inputs, &obs_train, &obs_val)?;
        let mut best: Option<(f64, Registration, ResidualCorrection)> = None;
        let mut stalled = 0;
        for _ in 0..REGISTRATION_ROUNDS {
            // `nominal_reference` of each point, from its flange pose computed once.
            let refs: Vec<Reference> = flanges
                .iter()
                .map(|f| (f * registration.frame.mounting, f.rotation))
                .collect();
            let (refs_train, refs_val) = refs.split_at(train.len());
            let (residual, offsets) = ResidualCorrection::fit_prepared(
                &mut setup,
                (&obs_train, refs_train),
                (&obs_val, refs_val),
                registration.measures_orientation(),
                &ctx.regression,
            )?;
            // The modelled offset at every training and validation point, from the search's feature
            // columns (the same bits as `correction` there) where they can say.
            let offsets: Vec<Vector3<f64>> = offsets.unwrap_or_else(|| {
                q.iter()
                    .zip(&inputs)
                    .map(|(q, x)| residual.correction(q, x).0)
                    .collect()
            });
            let error = validation_error(
                (&domain, &residual),
                &obs_val,
                refs_val,
                &offsets[train.len()..],
            );
            // Register again onto the nominal points plus this round's modelled residual.
            let shifted: Vec<Isometry3<f64>> = flanges
                .iter()
                .zip(&offsets)
                .map(|(f, dp)| Translation3::from(*dp) * f)
                .collect();
            match &best {
                Some((b, ..)) if error >= b * (1.0 - ROUND_GAIN) => stalled += 1,
                _ => stalled = 0,
            }
            if best.as_ref().is_none_or(|(b, ..)| error < *b) {
                best = Some((error, registration.clone(), residual));
            }
            if stalled >= STALLED_ROUNDS {
                break;
            }
            registration.frame = if registration.base_frame {
                fit_mounting(&centres, &shifted)?
            } else {
                fit_tracker_frame(&centres, &shifted, &registration.frame.mounting)?
            };
            if let (Some(_), Some(measured)) = (registration.probe_rotation, &orientations) {
                registration.probe_rotation =
                    Some(probe_rotation(&registration.frame, &flanges, measured)?);
            }
            registration.observe_again(train, &mut obs_train)?;
            registration.observe_again(val, &mut obs_val)?;
        }
        let (_, registration, residual) = best.expect("at least one round");
        Ok(ResidualModel {
            basis: Basis {
                joint_names: train.joint_names.clone(),
                dh: ctx.dh.clone(),
                registration,
                domain,
            },
            residual,
        })
    }

    /// A model read from a file can predict: a valid basis ([`Basis::validate`]) and a valid correction
    /// on its joints ([`ResidualCorrection::validate`]).
    pub fn validate(&self) -> Result<()> {
        self.basis.validate()?;
        plausible::within("residual", self.residual.validate(&self.basis.joint_names))
    }

    fn reference(&self, q: &[f64]) -> Reference {
        nominal_reference(&self.basis.dh, &self.basis.registration, q)
    }

    /// `reference` (the nominal prediction at `q`) with the residual added, weighted by the domain.
    fn corrected(&self, q: &[f64], inputs: &[f64], reference: &Reference) -> Reference {
        let w = self.basis.domain.weight(q, inputs);
        self.residual.apply_with_offset(q, inputs, reference, w).0
    }
}

/// `predict_with`'s mean position error on the validation points of a model with `domain` and `residual`, with
/// their references and modelled offsets given.
fn validation_error(
    (domain, residual): (&Domain, &ResidualCorrection),
    val: &[Observation],
    refs: &[Reference],
    offsets: &[Vector3<f64>],
) -> f64 {
    mean(val.iter().zip(refs).zip(offsets).map(|((o, r), dp)| {
        let w = domain.weight(&o.q, &o.inputs);
        (o.position - (r.0 + residual.weighted_position(*dp, w))).norm()
    }))
}

fn nominal_reference(dh: &DhChain, registration: &Registration, q: &[f64]) -> Reference {
    let f = dh.flange_pose(q);
    (f * registration.frame.mounting, f.rotation)
}

impl Fitted for ResidualModel {
    fn info(&self) -> &'static MethodInfo {
        &RESIDUAL_RIDGE
    }

    fn basis(&self) -> &Basis {
        &self.basis
    }

    fn predict(&self, q: &[f64]) -> Prediction {
        self.predict_with(q, &[])
    }

    fn input_names(&self) -> &[String] {
        self.residual.extra_inputs()
    }

    fn has_regression(&self) -> bool {
        true
    }

    /// Outside the training domain the residual is weighted as [`super::domain::Domain::weight`] says.
    fn predict_with(&self, q: &[f64], inputs: &[f64]) -> Prediction {
        let (position, orientation) = self.corrected(q, inputs, &self.reference(q));
        Prediction {
            position,
            linearized_position: position,
            orientation,
        }
    }

    fn point_at(&self, pose: &ChainPose, inputs: &[f64]) -> (Point3<f64>, UnitQuaternion<f64>) {
        // `nominal_reference`'s flange, from the pose's frames: the same products.
        let f = pose.flange(&self.basis.dh);
        let reference = (f * self.basis.registration.frame.mounting, f.rotation);
        self.corrected(&pose.q, inputs, &reference)
    }

    fn models_orientation(&self) -> bool {
        !self.residual.orientation.is_empty()
    }

    fn report(&self, test: &[Observation]) -> serde_json::Value {
        json!({ "residual": self.residual.report(&|q| self.reference(q), test) })
    }
}

/// `hybrid`: a base method's prediction plus a ridge model of its residual. This and the base's saved model
/// are what `model.json` holds.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct HybridModel {
    /// `hybrid` (elastic base), `hybrid-kinematic`, or `hybrid-<base>` for any other base.
    pub method: String,
    pub residual: ResidualCorrection,
}

/// A [`HybridModel`] with its base ready to predict.
pub struct HybridFitted {
    saved: HybridModel,
    info: &'static MethodInfo,
    base: Box<dyn Fitted>,
}

/// The hybrids that have a name of their own; any other base's is `hybrid-<base>`.
const NAMED: [&MethodInfo; 2] = [&HYBRID, &HYBRID_KINEMATIC];

impl HybridModel {
    /// The hybrid on `base`: its description and name.
    fn on_base(base: &MethodInfo) -> (&'static MethodInfo, String) {
        match NAMED
            .into_iter()
            .find(|h| h.base.is_some_and(|b| b.name == base.name))
        {
            Some(h) => (h, h.name.to_string()),
            None => (&HYBRID_ON_OTHER_BASE, format!("hybrid-{}", base.name)),
        }
    }

    /// The hybrid's check of the training and validation sets, before its base is fitted on them.
    pub fn check_sets(base: &MethodInfo, train: &Dataset, val: &Dataset) -> Result<()> {
        check_sets(&HybridModel::on_base(base).1, train, val)
    }

    /// Fits the residual of `base`'s predictions (the base fitted on the same `train` and `val`).
    pub fn fit(
        base: Box<dyn Fitted>,
        ctx: &FitContext,
        train: &Dataset,
        val: &Dataset,
    ) -> Result<HybridFitted> {
        let method = HybridModel::on_base(base.info()).1;
        check_sets(&method, train, val)?;
        let registration = base.registration();
        let (obs_train, obs_val) = (registration.observe(train)?, registration.observe(val)?);
        let reference = |q: &[f64]| base_reference(base.as_ref(), q);
        let extra_inputs = train.extra_input_names().to_vec();
        let residual = ResidualCorrection::fit(
            base.joint_names(),
            &extra_inputs,
            &reference,
            &obs_train,
            &obs_val,
            registration.measures_orientation(),
            &ctx.regression,
        )?;
        Ok(HybridModel { method, residual }.on(base))
    }

    /// A hybrid read from a file fits `base` (itself checked already): the name is the hybrid's on that base
    /// and the correction is valid on the base's joints.
    pub fn validate(&self, base: &dyn Fitted) -> Result<()> {
        let want = HybridModel::on_base(base.info()).1;
        if self.method != want {
            return Err(plausible::invalid(
                "method",
                format!(
                    "'{}' on a {} base; that hybrid is '{want}'",
                    self.method,
                    base.method()
                ),
            ));
        }
        plausible::within("residual", self.residual.validate(base.joint_names()))
    }

    /// This residual model on `base` (the one it was fitted against).
    pub fn on(self, base: Box<dyn Fitted>) -> HybridFitted {
        HybridFitted {
            info: HybridModel::on_base(base.info()).0,
            saved: self,
            base,
        }
    }
}

fn base_reference(base: &dyn Fitted, q: &[f64]) -> Reference {
    let p = base.predict(q);
    (p.position, p.orientation)
}

impl HybridFitted {
    pub fn base(&self) -> &dyn Fitted {
        self.base.as_ref()
    }

    pub fn model(&self) -> &HybridModel {
        &self.saved
    }
}

impl Fitted for HybridFitted {
    fn info(&self) -> &'static MethodInfo {
        self.info
    }

    /// The base's: the residual is modelled on the base's registration.
    fn basis(&self) -> &Basis {
        self.base.basis()
    }

    /// The name it was fitted under: `hybrid-<base>` on a base without a hybrid of its own.
    fn method(&self) -> &str {
        &self.saved.method
    }

    fn predict(&self, q: &[f64]) -> Prediction {
        self.predict_with(q, &[])
    }

    fn input_names(&self) -> &[String] {
        self.saved.residual.extra_inputs()
    }

    fn has_regression(&self) -> bool {
        true
    }

    /// The base predicts from the joint angles (its residual was fitted against exactly that); the extra
    /// inputs go to the residual model.
    fn point_at(&self, pose: &ChainPose, inputs: &[f64]) -> (Point3<f64>, UnitQuaternion<f64>) {
        let p = self.base.point_at(pose, &[]);
        let w = self.basis().domain.weight(&pose.q, inputs);
        self.saved
            .residual
            .apply_with_offset(&pose.q, inputs, &p, w)
            .0
    }

    fn predict_with(&self, q: &[f64], inputs: &[f64]) -> Prediction {
        let p = self.base.predict(q);
        let w = self.basis().domain.weight(q, inputs);
        let ((position, orientation), dp) =
            self.saved
                .residual
                .apply_with_offset(q, inputs, &(p.position, p.orientation), w);
        Prediction {
            position,
            linearized_position: p.linearized_position + dp,
            orientation,
        }
    }

    fn models_orientation(&self) -> bool {
        self.base.models_orientation() || !self.saved.residual.orientation.is_empty()
    }

    fn report(&self, test: &[Observation]) -> serde_json::Value {
        json!({
            "base_method": self.base.method(),
            "base": self.base.report(test),
            "residual": self
                .saved
                .residual
                .report(&|q| base_reference(self.base.as_ref(), q), test),
        })
    }
}
