//! Data-driven correction of what a model leaves: `residual-ridge` and `hybrid`.
//!
//! `residual-ridge` registers the tracker frame and the mounting as every method does, then models the
//! residual of each observation against the nominal prediction directly: one ridge polynomial per component
//! (the measured point's 3 coordinates in the base frame and, with a reflector nest, the 3 components of the
//! relative rotation vector of the flange), on the joint angles only, with inputs, degree and α chosen on the
//! validation data by [`fit_all`]. It knows nothing of kinematics; it is what a physical model must beat.
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
//! A residual model must not make its reference worse on the data that chose it. A component whose fitted
//! model has a larger validation sum of squares than no correction at all is replaced by zero, and a group
//! (position, orientation) whose mean validation error (distance, angle) would grow is dropped as a whole;
//! so on the validation data the corrected model is never worse than its reference in either measure.

use nalgebra::{DMatrix, Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};
use serde_json::json;

use super::domain::Domain;
use super::kinematic::{ELASTIC, KINEMATIC};
use super::method::{Basis, Design, FitContext, Fitted, MethodInfo, Prediction};
use super::regression::{RegressionOptions, RidgeModel, fit_all, r2};
use super::rigid::centre;
use super::tracker_frame::{
    Observation, Registration, fit_mounting, fit_tracker_frame, probe_rotation,
};
use crate::dataset::{Dataset, MOTION_INPUT_PREFIX};
use crate::error::{Error, Result};
use crate::robot::dh::DhChain;
use crate::robot::plausible;

pub const RESIDUAL_RIDGE: MethodInfo = MethodInfo {
    name: "residual-ridge",
    summary: "the nominal prediction plus ridge models of its residual on the joint angles (and extra inputs)",
    takes_inputs: true,
    base: None,
    design: Design::None,
};

pub const HYBRID: MethodInfo = hybrid("hybrid", &ELASTIC);
pub const HYBRID_KINEMATIC: MethodInfo = hybrid("hybrid-kinematic", &KINEMATIC);

/// A hybrid on a base that has no hybrid of its own above (tests build them on every method). It is named
/// `hybrid-<base>` ([`HybridModel::method`]); what else it is depends on the base, which this cannot say.
pub const HYBRID_ON_OTHER_BASE: MethodInfo = MethodInfo {
    name: "hybrid-<base>",
    summary: "a base method's prediction plus ridge models of its residual",
    takes_inputs: true,
    base: None,
    design: Design::None,
};

/// The hybrid on `base`: its residual is data-driven, its parameters and design model are the base's.
const fn hybrid(name: &'static str, base: &'static MethodInfo) -> MethodInfo {
    MethodInfo {
        name,
        summary: "a base method's prediction plus ridge models of its residual",
        takes_inputs: true,
        base: Some(base),
        design: base.design,
    }
}

/// `residual-ridge` alternates registration and residual model at most this many rounds, and stops once
/// `STALLED_ROUNDS` rounds in a row lowered the mean validation error by less than `ROUND_GAIN` (relative).
const REGISTRATION_ROUNDS: usize = 40;
const ROUND_GAIN: f64 = 1e-3;
const STALLED_ROUNDS: usize = 3;

/// Names of the modelled components: measured-point offsets (m) and flange rotation vector (rad), base frame.
const POSITION_NAMES: [&str; 3] = ["dx", "dy", "dz"];
const ORIENTATION_NAMES: [&str; 3] = ["rx", "ry", "rz"];

/// A reference prediction: the measured point and the flange orientation.
type Reference = (Point3<f64>, UnitQuaternion<f64>);
/// A residual: position offset and, when measured, rotation vector.
type Residual = (Vector3<f64>, Option<Vector3<f64>>);

/// One modelled residual component.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct ComponentModel {
    pub name: String,
    /// False when the validation data rejected the fitted model; `model` then predicts exactly zero.
    pub kept: bool,
    pub model: RidgeModel,
}

/// Ridge models of the residual of some reference prediction, on the joint angles (and the data's extra inputs).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct ResidualCorrection {
    /// Names of the regression's candidate inputs: the joint angles (rad), then the data's extra inputs.
    pub candidates: Vec<String>,
    /// Training means of the extra inputs (the candidates after the joints): what a prediction assumes when
    /// it is not told them.
    #[serde(default)]
    pub input_means: Vec<f64>,
    /// `dx`, `dy`, `dz`: added to the reference's measured point.
    pub position: Vec<ComponentModel>,
    /// `rx`, `ry`, `rz` (with a reflector nest, else empty): the rotation `exp(r)` applied on the left of
    /// the reference's flange orientation.
    pub orientation: Vec<ComponentModel>,
}

/// The residual of an observation against a reference: position offset and, when measured, the relative
/// rotation in the base frame.
fn residual_of(o: &Observation, r: &Reference) -> Residual {
    (
        o.position - r.0,
        o.orientation.map(|m| (m * r.1.inverse()).scaled_axis()),
    )
}

/// A model that predicts exactly zero.
fn zero_model(validation_r2: f64) -> RidgeModel {
    RidgeModel {
        inputs: Vec::new(),
        degree: 0,
        alpha: 0.0,
        cross_terms: false,
        input_mean: Vec::new(),
        input_scale: Vec::new(),
        feature_mean: Vec::new(),
        feature_scale: Vec::new(),
        coef: Vec::new(),
        intercept: 0.0,
        validation_r2,
    }
}

/// Candidate rows: the joint angles, then the extra inputs.
fn candidate_matrix(observations: &[Observation], dof: usize, extra: usize) -> DMatrix<f64> {
    DMatrix::from_fn(observations.len(), dof + extra, |r, c| {
        let o = &observations[r];
        if c < dof { o.q[c] } else { o.inputs[c - dof] }
    })
}

fn eval(models: &[ComponentModel], x: &[f64]) -> Vector3<f64> {
    Vector3::new(
        models[0].model.predict(x),
        models[1].model.predict(x),
        models[2].model.predict(x),
    )
}

/// Replaces every model of a group by zero; `y`: the group's validation residuals.
fn zero_group(models: &mut [ComponentModel], y: &[Vector3<f64>]) {
    for (k, m) in models.iter_mut().enumerate() {
        let yk: Vec<f64> = y.iter().map(|v| v[k]).collect();
        m.kept = false;
        m.model = zero_model(r2(&yk, &vec![0.0; yk.len()]));
    }
}

fn mean(values: impl Iterator<Item = f64>) -> f64 {
    let (sum, n) = values.fold((0.0, 0usize), |(s, n), v| (s + v, n + 1));
    if n == 0 { 0.0 } else { sum / n as f64 }
}

impl ResidualCorrection {
    /// Fits the residuals of `train` against `reference`, choosing on `val`. The orientation is modelled when
    /// `orientation` is set and every training and validation observation measures it. `extra_inputs`: names
    /// of the observations' inputs beyond the joint angles, offered to the regression as candidates.
    pub fn fit(
        joint_names: &[String],
        extra_inputs: &[String],
        reference: &dyn Fn(&[f64]) -> Reference,
        train: &[Observation],
        val: &[Observation],
        orientation: bool,
        opts: &RegressionOptions,
    ) -> Result<ResidualCorrection> {
        let dof = joint_names.len();
        if let Some(o) = train.iter().chain(val).find(|o| o.q.len() != dof) {
            return Err(Error::Invalid(format!(
                "residual model: a configuration has {} joint angles, the robot {dof} joints",
                o.q.len()
            )));
        }
        let extra = extra_inputs.len();
        if let Some(o) = train.iter().chain(val).find(|o| o.inputs.len() != extra) {
            return Err(Error::Invalid(format!(
                "residual model: a point has {} extra inputs, the model {extra} ({})",
                o.inputs.len(),
                extra_inputs.join(", ")
            )));
        }
        // Training means, and zero for the motion (the arm at rest): what a prediction takes unless told.
        let input_means: Vec<f64> = (0..extra)
            .map(|k| {
                if extra_inputs[k].starts_with(MOTION_INPUT_PREFIX) {
                    0.0
                } else {
                    train.iter().map(|o| o.inputs[k]).sum::<f64>() / train.len().max(1) as f64
                }
            })
            .collect();
        let refs_train: Vec<Reference> = train.iter().map(|o| reference(&o.q)).collect();
        let refs_val: Vec<Reference> = val.iter().map(|o| reference(&o.q)).collect();
        let res = |obs: &[Observation], refs: &[Reference]| -> Vec<_> {
            obs.iter()
                .zip(refs)
                .map(|(o, r)| residual_of(o, r))
                .collect()
        };
        let (res_train, res_val) = (res(train, &refs_train), res(val, &refs_val));
        let with_orientation =
            orientation && res_train.iter().chain(&res_val).all(|r| r.1.is_some());
        let (x_train, x_val) = (
            candidate_matrix(train, dof, extra),
            candidate_matrix(val, dof, extra),
        );
        let regress = |names: [&str; 3],
                       component: &dyn Fn(&Residual) -> Vector3<f64>|
         -> Result<Vec<ComponentModel>> {
            let matrix =
                |rows: &[Residual]| DMatrix::from_fn(rows.len(), 3, |r, c| component(&rows[r])[c]);
            let y_val = matrix(&res_val);
            let models = fit_all(&x_train, &matrix(&res_train), &x_val, &y_val, opts)?;
            Ok(names
                .iter()
                .zip(models)
                .enumerate()
                .map(|(k, (name, model))| {
                    // No worse than no correction, in the validation sum of squares.
                    let y: Vec<f64> = y_val.column(k).iter().copied().collect();
                    let fitted: Vec<f64> = (0..val.len())
                        .map(|r| model.predict(x_val.row(r).transpose().as_slice()))
                        .collect();
                    let sse_model: f64 = y.iter().zip(&fitted).map(|(a, b)| (a - b).powi(2)).sum();
                    let sse_zero: f64 = y.iter().map(|a| a * a).sum();
                    let kept = sse_model < sse_zero;
                    ComponentModel {
                        name: name.to_string(),
                        kept,
                        model: if kept {
                            model
                        } else {
                            zero_model(r2(&y, &vec![0.0; y.len()]))
                        },
                    }
                })
                .collect())
        };
        let mut correction = ResidualCorrection {
            candidates: joint_names.iter().chain(extra_inputs).cloned().collect(),
            input_means,
            position: regress(POSITION_NAMES, &|r| r.0)?,
            orientation: if with_orientation {
                regress(ORIENTATION_NAMES, &|r| r.1.unwrap_or_default())?
            } else {
                Vec::new()
            },
        };
        correction.prune(val, &refs_val);
        Ok(correction)
    }

    /// Drops a group whose mean validation error (distance, angle) would grow, evaluated exactly as
    /// predictions are made.
    fn prune(&mut self, val: &[Observation], refs: &[Reference]) {
        let corrected: Vec<Reference> = val
            .iter()
            .zip(refs)
            .map(|(o, r)| self.apply(&o.q, &o.inputs, r))
            .collect();
        let distance =
            |rs: &[Reference]| mean(val.iter().zip(rs).map(|(o, r)| (o.position - r.0).norm()));
        let angle = |rs: &[Reference]| {
            mean(
                val.iter()
                    .zip(rs)
                    .filter_map(|(o, r)| o.orientation.map(|m| (m * r.1.inverse()).angle())),
            )
        };
        let residuals: Vec<_> = val
            .iter()
            .zip(refs)
            .map(|(o, r)| residual_of(o, r))
            .collect();
        if distance(&corrected) > distance(refs) {
            let ys = residuals.iter().map(|r| r.0).collect::<Vec<_>>();
            zero_group(&mut self.position, &ys);
        }
        if !self.orientation.is_empty() && angle(&corrected) > angle(refs) {
            let ys = residuals
                .iter()
                .map(|r| r.1.unwrap_or_default())
                .collect::<Vec<_>>();
            zero_group(&mut self.orientation, &ys);
        }
    }

    /// A correction read from a file can predict on a chain with `joint_names`: its candidates are those
    /// joints then one per training mean of an extra input; three position components `dx`, `dy`, `dz`, and
    /// three orientation components `rx`, `ry`, `rz` or none; each a valid regression on the candidates.
    pub fn validate(&self, joint_names: &[String]) -> Result<()> {
        let n = joint_names.len();
        let extra = self.input_means.len();
        if self.candidates.len() != n + extra || self.candidates[..n] != *joint_names {
            return Err(plausible::invalid(
                "candidates",
                format!(
                    "[{}] are not the {n} joint names [{}] followed by one name per input_means entry ({extra})",
                    self.candidates.join(", "),
                    joint_names.join(", ")
                ),
            ));
        }
        for (k, &v) in self.input_means.iter().enumerate() {
            plausible::finite(&format!("input_means[{k}]"), v)?;
        }
        for (group, models, names, optional) in [
            ("position", &self.position, POSITION_NAMES, false),
            ("orientation", &self.orientation, ORIENTATION_NAMES, true),
        ] {
            if !(models.len() == 3 || optional && models.is_empty()) {
                return Err(plausible::invalid(
                    group,
                    format!(
                        "{} components; the model has {}the three {}",
                        models.len(),
                        if optional { "none or " } else { "" },
                        names.join(", ")
                    ),
                ));
            }
            for (k, (m, name)) in models.iter().zip(names).enumerate() {
                if m.name != name {
                    return Err(plausible::invalid(
                        &format!("{group}[{k}].name"),
                        format!("'{}' where '{name}' belongs", m.name),
                    ));
                }
                plausible::within(
                    &format!("{group}[{k}].model"),
                    m.model.validate(self.candidates.len()),
                )?;
            }
        }
        Ok(())
    }

    /// Names of the extra inputs (the candidates after the joint angles).
    pub fn extra_inputs(&self) -> &[String] {
        &self.candidates[self.candidates.len() - self.input_means.len()..]
    }

    /// The candidate row at `q` with extra inputs `inputs` (any other length than the model's, e.g. empty:
    /// their training means).
    fn row(&self, q: &[f64], inputs: &[f64]) -> Vec<f64> {
        let extra = if inputs.len() == self.input_means.len() {
            inputs
        } else {
            &self.input_means
        };
        q.iter().chain(extra).copied().collect()
    }

    /// The modelled position offset and rotation vector at `q` with extra inputs `inputs` (empty: their means).
    pub fn correction(&self, q: &[f64], inputs: &[f64]) -> (Vector3<f64>, Option<Vector3<f64>>) {
        let x = self.row(q, inputs);
        (
            eval(&self.position, &x),
            (!self.orientation.is_empty()).then(|| eval(&self.orientation, &x)),
        )
    }

    /// `reference` corrected at `q` with extra inputs `inputs`.
    pub fn apply(&self, q: &[f64], inputs: &[f64], reference: &Reference) -> Reference {
        self.apply_with_offset(q, inputs, reference, 1.0).0
    }

    /// `reference` corrected at `q`, and the position offset added.
    fn apply_with_offset(
        &self,
        q: &[f64],
        inputs: &[f64],
        reference: &Reference,
        weight: f64,
    ) -> (Reference, Vector3<f64>) {
        let (mut dp, mut dw) = self.correction(q, inputs);
        // Weight below 1 (outside the training domain): toward the constant part of each component's
        // regression, its intercept (the training mean). Weight 1 leaves the bits alone.
        if weight != 1.0 {
            let toward = |models: &[ComponentModel], v: Vector3<f64>| {
                let c = Vector3::from_fn(|k, _| models[k].model.intercept);
                c + (v - c) * weight
            };
            dp = toward(&self.position, dp);
            dw = dw.map(|w| toward(&self.orientation, w));
        }
        // A zero rotation leaves the reference's bits alone, as a zero offset does.
        let orientation = match dw {
            Some(w) if w != Vector3::zeros() => UnitQuaternion::from_scaled_axis(w) * reference.1,
            _ => reference.1,
        };
        ((reference.0 + dp, orientation), dp)
    }

    /// Per component: kept or not, inputs, degree, α, R² on validation and on `test` (its residuals against
    /// `reference`).
    pub fn report(
        &self,
        reference: &dyn Fn(&[f64]) -> Reference,
        test: &[Observation],
    ) -> serde_json::Value {
        let res: Vec<_> = test
            .iter()
            .map(|o| residual_of(o, &reference(&o.q)))
            .collect();
        let mut components = serde_json::Map::new();
        for (models, orientation) in [(&self.position, false), (&self.orientation, true)] {
            for (k, m) in models.iter().enumerate() {
                let (y, y_hat): (Vec<f64>, Vec<f64>) = test
                    .iter()
                    .zip(&res)
                    .filter_map(|(o, (dp, dw))| {
                        let v = if orientation { (*dw)?[k] } else { dp[k] };
                        Some((v, m.model.predict(&self.row(&o.q, &o.inputs))))
                    })
                    .unzip();
                let test_r2 = (!y.is_empty()).then(|| r2(&y, &y_hat));
                components.insert(
                    m.name.clone(),
                    json!({
                        "kept": m.kept,
                        "inputs": m.model.inputs.iter().map(|&i| self.candidates[i].clone()).collect::<Vec<_>>(),
                        "degree": m.model.degree,
                        "alpha": m.model.alpha,
                        "cross_terms": m.model.cross_terms,
                        "r2": { "validation": m.model.validation_r2, "test": test_r2 },
                    }),
                );
            }
        }
        json!({ "candidates": self.candidates, "components": components })
    }
}

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
        let mut registration = Registration::fit(ctx.dh, train, val)?;
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
        let mut best: Option<(f64, ResidualModel)> = None;
        let mut stalled = 0;
        for _ in 0..REGISTRATION_ROUNDS {
            let (obs_train, obs_val) = (registration.observe(train)?, registration.observe(val)?);
            let reference = |q: &[f64]| nominal_reference(ctx.dh, &registration, q);
            let residual = ResidualCorrection::fit(
                &train.joint_names,
                &extra_inputs,
                &reference,
                &obs_train,
                &obs_val,
                registration.measures_orientation(),
                &ctx.regression,
            )?;
            let model = ResidualModel {
                basis: Basis {
                    joint_names: train.joint_names.clone(),
                    dh: ctx.dh.clone(),
                    registration: registration.clone(),
                    domain: Domain::of(train, val),
                },
                residual,
            };
            let error = mean(
                obs_val
                    .iter()
                    .map(|o| (o.position - model.predict_with(&o.q, &o.inputs).position).norm()),
            );
            // Register again onto the nominal points plus this round's modelled residual.
            let shifted: Vec<Isometry3<f64>> = flanges
                .iter()
                .zip(q.iter().zip(&inputs))
                .map(|(f, (q, x))| Translation3::from(model.residual.correction(q, x).0) * f)
                .collect();
            match &best {
                Some((b, _)) if error >= b * (1.0 - ROUND_GAIN) => stalled += 1,
                _ => stalled = 0,
            }
            if best.as_ref().is_none_or(|(b, _)| error < *b) {
                best = Some((error, model));
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
        }
        Ok(best.expect("at least one round").1)
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

    /// Outside the training domain the residual is evaluated as [`Domain::regression_inputs`] says.
    fn predict_with(&self, q: &[f64], inputs: &[f64]) -> Prediction {
        let (qc, ic, w) = self.basis.domain.regression_inputs(q, inputs);
        let ((position, orientation), _) =
            self.residual
                .apply_with_offset(&qc, &ic, &self.reference(q), w);
        Prediction {
            position,
            linearized_position: position,
            orientation,
        }
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

    /// The base predicts from the joint angles (its residual was fitted against exactly that); the extra
    /// inputs go to the residual model.
    fn predict_with(&self, q: &[f64], inputs: &[f64]) -> Prediction {
        let p = self.base.predict(q);
        let (qc, ic, w) = self.basis().domain.regression_inputs(q, inputs);
        let ((position, orientation), dp) =
            self.saved
                .residual
                .apply_with_offset(&qc, &ic, &(p.position, p.orientation), w);
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
