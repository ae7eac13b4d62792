//! The method of Schillreff, Nykolaychuk and Ortmeier (the paper in `shared/paper/`), and its `nominal`
//! baseline (registration only, the "Measured" column).
//!
//! 1. Register the tracker frame and the reflector mounting ([`fit_tracker_frame`]).
//! 2. For every training and validation point, solve `Δp = J_e e` for the generalized error parameters that
//!    move the measured point (eq. 13, minimum norm); with a reflector nest also `Δw = J_e e` for the
//!    parameters that only turn the flange (§4.1, §4.3).
//! 3. Model each parameter by ridge regression on polynomial features of the joint angles and the nominal TCP
//!    position, inputs by correlation, degree and α by validation R² (§3).
//! 4. Predict: the modelled `E_i` go into the full kinematics (eq. 6); position from the position parameters,
//!    orientation from the orientation parameters, each attributed as it was identified.

use nalgebra::{DMatrix, DVector, Isometry3, Point3, UnitQuaternion};
use serde::{Deserialize, Serialize};
use serde_json::json;

use super::error_model::{
    ErrorModelKind, ErrorParam, FrameErrors, error_jacobian_on, flange_pose_with_errors,
    flange_pose_with_errors_on, frame_errors, select_params,
};
use super::method::{Basis, FitContext, Fitted, Method, MethodInfo, Prediction, RobotParameters};
use super::min_norm::min_norm;
use super::regression::{RegressionOptions, RidgeModel, SharedCandidates, r2};
use super::tracker_frame::Observation;
use crate::dataset::Dataset;
use crate::error::{Error, Result};
use crate::robot::dh::ChainPose;
use crate::robot::plausible;

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct ParameterModel {
    pub param: ErrorParam,
    pub name: String,
    pub model: RidgeModel,
}

pub const NOMINAL: MethodInfo = MethodInfo {
    name: "nominal",
    summary: "the nominal model on the registered tracker frame and mounting (the paper's \"Measured\")",
    takes_inputs: false,
    base: None,
    parameters: RobotParameters::None,
};

pub const PAPER_ROTZ: MethodInfo = paper_method(
    "paper-rotz",
    ErrorModelKind::RotZ,
    "the paper's method, error model RotZ (eq. 7): one rotation about z per DH frame, each a ridge regression \
     on the configuration (and extra inputs)",
);
pub const PAPER_ROTXYZ: MethodInfo = paper_method(
    "paper-rotxyz",
    ErrorModelKind::RotXyz,
    "the paper's method, error model RotXYZ (eq. 8): rotations about x, y and z per DH frame, each a ridge \
     regression on the configuration (and extra inputs)",
);
pub const PAPER_ROTXYZ_TRANSXYZ: MethodInfo = paper_method(
    "paper-rotxyz-transxyz",
    ErrorModelKind::RotXyzTransXyz,
    "the paper's method, error model RotXYZ+TransXYZ (eq. 5): rotations and translations along x, y and z per \
     DH frame, each a ridge regression on the configuration (and extra inputs)",
);

/// The paper's method with one of its error models; `summary` says which (a user chooses by it).
const fn paper_method(
    name: &'static str,
    kind: ErrorModelKind,
    summary: &'static str,
) -> MethodInfo {
    MethodInfo {
        name,
        summary,
        takes_inputs: true,
        base: None,
        parameters: RobotParameters::ErrorModel(kind),
    }
}

/// The method of error model `kind`; `None`: `nominal`.
pub fn info_of(kind: Option<ErrorModelKind>) -> &'static MethodInfo {
    match kind {
        None => &NOMINAL,
        Some(ErrorModelKind::RotZ) => &PAPER_ROTZ,
        Some(ErrorModelKind::RotXyz) => &PAPER_ROTXYZ,
        Some(ErrorModelKind::RotXyzTransXyz) => &PAPER_ROTXYZ_TRANSXYZ,
    }
}

/// `nominal` (`None`) and the paper's method with each error model: one fitting.
pub struct Paper(pub Option<ErrorModelKind>);

impl Method for Paper {
    fn info(&self) -> &'static MethodInfo {
        info_of(self.0)
    }

    fn fit(&self, ctx: &FitContext, train: &Dataset, val: &Dataset) -> Result<Box<dyn Fitted>> {
        Ok(Box::new(PaperModel::fit(self.0, ctx, train, val)?))
    }
}

fn method_from_name<'de, D: serde::Deserializer<'de>>(
    d: D,
) -> std::result::Result<&'static MethodInfo, D::Error> {
    MethodInfo::deserialize_among(
        d,
        &[&NOMINAL, &PAPER_ROTZ, &PAPER_ROTXYZ, &PAPER_ROTXYZ_TRANSXYZ],
    )
}

/// Everything a later run needs to predict: `model.json`.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct PaperModel {
    /// `nominal` or `paper-rotz` / `paper-rotxyz` / `paper-rotxyz-transxyz`.
    #[serde(deserialize_with = "method_from_name")]
    pub method: &'static MethodInfo,
    pub kind: Option<ErrorModelKind>,
    #[serde(flatten)]
    pub basis: Basis,
    /// Names of the regression's candidate inputs: the joint angles (rad), the nominal TCP x, y, z (m), then
    /// the data's extra inputs (`extra_inputs`).
    pub candidates: Vec<String>,
    /// The data's inputs beyond the joint angles (e.g. `temperature`), offered to the regression.
    #[serde(default)]
    pub extra_inputs: Vec<String>,
    /// Their training means: what [`Fitted::predict`] assumes when it is not told them.
    #[serde(default)]
    pub extra_input_means: Vec<f64>,
    pub position: Vec<ParameterModel>,
    pub orientation: Vec<ParameterModel>,
}

impl PaperModel {
    /// A model read from a file can predict: its basis is valid ([`Basis::validate`]); the method matches the
    /// error model; the candidates (where a regression reads them) are the joints, `tcp_x`, `tcp_y`, `tcp_z`
    /// and the extra inputs, with one training mean per extra input; every parameter model is a parameter of the error model on this chain,
    /// named as it, once, and a valid regression on those candidates.
    pub fn validate(&self) -> Result<()> {
        self.basis.validate()?;
        if self.method.name != info_of(self.kind).name {
            return Err(plausible::invalid(
                "method",
                format!(
                    "'{}' with kind {}: that error model is the method '{}'",
                    self.method.name,
                    self.kind.map_or("null", |k| k.name()),
                    info_of(self.kind).name
                ),
            ));
        }
        let joints = &self.basis.joint_names;
        let n = joints.len();
        let want: Vec<String> = joints
            .iter()
            .cloned()
            .chain(["tcp_x", "tcp_y", "tcp_z"].map(String::from))
            .chain(self.extra_inputs.iter().cloned())
            .collect();
        // Only the regressions read the candidates: a model without any (nominal) predicts whatever they are.
        let regresses = !(self.position.is_empty() && self.orientation.is_empty());
        if regresses && self.candidates != want {
            return Err(plausible::invalid(
                "candidates",
                format!(
                    "[{}] are not the joint_names, tcp_x, tcp_y, tcp_z and the extra_inputs [{}]",
                    self.candidates.join(", "),
                    want.join(", ")
                ),
            ));
        }
        plausible::count(
            "extra_input_means",
            self.extra_input_means.len(),
            self.extra_inputs.len(),
            "extra_inputs",
        )?;
        for (k, &v) in self.extra_input_means.iter().enumerate() {
            plausible::finite(&format!("extra_input_means[{k}]"), v)?;
        }
        let components = self.kind.map_or(&[][..], |k| k.components());
        for (group, models) in [
            ("position", &self.position),
            ("orientation", &self.orientation),
        ] {
            for (i, m) in models.iter().enumerate() {
                let field = format!("{group}[{i}]");
                let p = m.param;
                if !(1..=n).contains(&p.frame) || !components.contains(&p.component) {
                    return Err(plausible::invalid(
                        &format!("{field}.param"),
                        format!(
                            "frame {} component {} is not a parameter of {} on {n} joints",
                            p.frame,
                            p.component,
                            self.kind.map_or("the nominal model (none)", |k| k.name())
                        ),
                    ));
                }
                if m.name != p.name() {
                    return Err(plausible::invalid(
                        &format!("{field}.name"),
                        format!("'{}' for parameter {}", m.name, p.name()),
                    ));
                }
                if models[..i].iter().any(|o| o.param == p) {
                    return Err(plausible::invalid(
                        &format!("{field}.param"),
                        format!("{} appears twice", p.name()),
                    ));
                }
                plausible::within(
                    &format!("{field}.model"),
                    m.model.validate(self.candidates.len()),
                )?;
            }
        }
        Ok(())
    }
}

/// What the paper's error models fitted on the same sets start from alike, after the registration: the
/// observations, and the regressions' candidate rows with the factorizations their searches compute.
struct Prepared {
    obs_train: Vec<Observation>,
    obs_val: Vec<Observation>,
    candidates: SharedCandidates,
}

impl Prepared {
    /// `model`: the registered model ([`PaperModel::registered`]) of `train` and `val`.
    fn of(model: &PaperModel, train: &Dataset, val: &Dataset) -> Result<Prepared> {
        let registration = &model.basis.registration;
        let (obs_train, obs_val) = (registration.observe(train)?, registration.observe(val)?);
        let candidates = SharedCandidates::new(
            model.candidate_matrix(&obs_train),
            model.candidate_matrix(&obs_val),
        );
        Ok(Prepared {
            obs_train,
            obs_val,
            candidates,
        })
    }
}

/// Per-point identified error parameters (eq. 13), for the regression and for R² on the test split.
#[derive(Clone, Debug)]
pub struct Identified {
    pub position: Vec<Vec<f64>>,
    pub orientation: Vec<Vec<f64>>,
}

impl PaperModel {
    /// Fits on `train`, choosing hyper-parameters on `val`; `kind = None` is the `nominal` method.
    pub fn fit(
        kind: Option<ErrorModelKind>,
        ctx: &FitContext,
        train: &Dataset,
        val: &Dataset,
    ) -> Result<PaperModel> {
        let mut model = PaperModel::registered(kind, ctx, train, val)?;
        let Some(kind) = kind else {
            return Ok(model);
        };
        let (lower, upper) = ctx.limits();
        let selection = select_params(ctx.dh, &lower, &upper, kind);
        check_identifiable(kind, train.len(), selection.position.len())?;
        let orientation_params = if model.basis.registration.measures_orientation() {
            selection.orientation_only.clone()
        } else {
            Vec::new()
        };
        // The observations and candidate rows are every error model's on these sets: shared with the other
        // paper methods fitted on them (an error is not shared: this fit meets it again).
        let shared = ctx.shared("paper", train, val, || Prepared::of(&model, train, val));
        let own;
        let prepared = match &*shared {
            Ok(p) => p,
            Err(_) => {
                own = Prepared::of(&model, train, val)?;
                &own
            }
        };
        let (obs_train, obs_val) = (&prepared.obs_train, &prepared.obs_val);
        let id_train = model.identify(obs_train, &selection.position, &orientation_params);
        let id_val = model.identify(obs_val, &selection.position, &orientation_params);
        // Position and orientation parameters regress on the same candidates, and parameters with the same
        // ranking of the candidates (of this error model or another) on the same structures.
        let candidates = &prepared.candidates;
        let regress = |params: &[ErrorParam], y_train: &[Vec<f64>], y_val: &[Vec<f64>]| {
            regress(params, candidates, y_train, y_val, &ctx.regression)
        };
        model.position = regress(&selection.position, &id_train.position, &id_val.position)?;
        model.orientation = regress(
            &orientation_params,
            &id_train.orientation,
            &id_val.orientation,
        )?;
        Ok(model)
    }

    /// The `nominal` model: the registered tracker frame and mounting, the candidates of the regressions and
    /// the extra inputs' defaults, with no parameter model yet.
    fn registered(
        kind: Option<ErrorModelKind>,
        ctx: &FitContext,
        train: &Dataset,
        val: &Dataset,
    ) -> Result<PaperModel> {
        if train.is_empty() || val.is_empty() {
            return Err(Error::Invalid(format!(
                "{} training and {} validation points: both sets must be non-empty",
                train.len(),
                val.len()
            )));
        }
        let dh = ctx.dh;
        let registration = ctx.registration(train, val)?;
        let extra_inputs = train.extra_input_names().to_vec();
        if val.extra_input_names() != extra_inputs.as_slice() {
            return Err(Error::Invalid(format!(
                "the training data has extra inputs [{}], the validation data [{}]",
                extra_inputs.join(", "),
                val.extra_input_names().join(", ")
            )));
        }
        // Training means, and zero for the motion (the arm at rest): what a prediction takes unless told.
        let extra_input_means = train.input_defaults();
        Ok(PaperModel {
            method: info_of(kind),
            kind,
            basis: Basis {
                joint_names: train.joint_names.clone(),
                dh: dh.clone(),
                registration,
                domain: ctx.domain(train, val),
            },
            candidates: train
                .joint_names
                .iter()
                .cloned()
                .chain(["tcp_x", "tcp_y", "tcp_z"].map(String::from))
                .chain(extra_inputs.iter().cloned())
                .collect(),
            extra_inputs,
            extra_input_means,
            position: Vec::new(),
            orientation: Vec::new(),
        })
    }

    /// Eq. 13 per point: minimum-norm error parameters explaining each observation's deviation.
    pub fn identify(
        &self,
        observations: &[Observation],
        position_params: &[ErrorParam],
        orientation_params: &[ErrorParam],
    ) -> Identified {
        let mut id = Identified {
            position: Vec::with_capacity(observations.len()),
            orientation: Vec::with_capacity(observations.len()),
        };
        let dh = &self.basis.dh;
        for o in observations {
            // One pass over the chain for the flange pose and the Jacobians' frames.
            let frames = dh.frames(&o.q);
            let flange = frames[dh.dof()] * dh.tool;
            if !position_params.is_empty() {
                let j = error_jacobian_on(
                    dh,
                    &frames,
                    &self.basis.registration.frame.mounting,
                    position_params,
                );
                let dp = o.position - flange * self.basis.registration.frame.mounting;
                id.position
                    .push(min_norm(j.fixed_rows::<3>(0).into_owned(), dp));
            }
            if let (false, Some(measured)) = (orientation_params.is_empty(), o.orientation) {
                let j = error_jacobian_on(
                    dh,
                    &frames,
                    &self.basis.registration.frame.mounting,
                    orientation_params,
                );
                // The relative rotation, in the base frame, is what J_e linearizes; eq. 25's difference of
                // rotation vectors equals it only to first order near the identity.
                let dw = (measured * flange.rotation.inverse()).scaled_axis();
                id.orientation
                    .push(min_norm(j.fixed_rows::<3>(3).into_owned(), dw));
            }
        }
        id
    }

    /// Regression inputs of each observation: joint angles, the nominal TCP position, the extra inputs.
    fn candidate_matrix(&self, observations: &[Observation]) -> DMatrix<f64> {
        let rows: Vec<Vec<f64>> = observations
            .iter()
            .map(|o| self.candidates_of(&o.q, &o.inputs))
            .collect();
        DMatrix::from_fn(rows.len(), self.candidates.len(), |r, c| rows[r][c])
    }

    /// `inputs`: the extra inputs in `extra_inputs` order; any other length (empty) stands for their
    /// training means.
    fn candidates_of(&self, q: &[f64], inputs: &[f64]) -> Vec<f64> {
        self.candidates_at(q, inputs, &self.basis.dh.flange_pose(q))
    }

    /// [`PaperModel::candidates_of`] with the nominal flange pose at `q` given.
    fn candidates_at(&self, q: &[f64], inputs: &[f64], flange: &Isometry3<f64>) -> Vec<f64> {
        let tcp = flange * self.basis.registration.frame.mounting;
        let extra = if inputs.len() == self.extra_inputs.len() {
            inputs
        } else {
            &self.extra_input_means
        };
        q.iter()
            .copied()
            .chain([tcp.x, tcp.y, tcp.z])
            .chain(extra.iter().copied())
            .collect()
    }

    /// Modelled error parameters at configuration `q` (extra inputs at their training means).
    pub fn parameters(&self, q: &[f64]) -> (Vec<f64>, Vec<f64>) {
        self.parameters_with(q, &[])
    }

    /// Modelled error parameters at configuration `q` with extra inputs `inputs` (empty: their means).
    /// Outside the training domain the regressions are weighted as [`super::domain::Domain::weight`] says.
    pub fn parameters_with(&self, q: &[f64], inputs: &[f64]) -> (Vec<f64>, Vec<f64>) {
        // `nominal` has no parameter: nothing to place in the domain or regress.
        if self.position.is_empty() && self.orientation.is_empty() {
            return (Vec::new(), Vec::new());
        }
        self.parameters_at(q, inputs, &self.basis.dh.flange_pose(q))
    }

    /// [`PaperModel::parameters_with`] with the nominal flange pose at `q` given.
    fn parameters_at(
        &self,
        q: &[f64],
        inputs: &[f64],
        flange: &Isometry3<f64>,
    ) -> (Vec<f64>, Vec<f64>) {
        if self.position.is_empty() && self.orientation.is_empty() {
            return (Vec::new(), Vec::new());
        }
        let w = self.basis.domain.weight(q, inputs);
        let x = self.candidates_at(q, inputs, flange);
        // Weight 1 leaves the bits alone.
        let eval = |models: &[ParameterModel]| {
            models
                .iter()
                .map(|m| match w {
                    1.0 => m.model.predict(&x),
                    // Toward the regression's constant part (its intercept, the training mean): the
                    // model's constant-parameter calibration.
                    _ => m.model.intercept + w * (m.model.predict(&x) - m.model.intercept),
                })
                .collect()
        };
        (eval(&self.position), eval(&self.orientation))
    }

    fn frame_errors_of(&self, models: &[ParameterModel], values: &[f64]) -> FrameErrors {
        let params: Vec<ErrorParam> = models.iter().map(|m| m.param).collect();
        frame_errors(self.basis.dh.dof(), &params, values)
    }

    /// Predicted measured point and flange orientation for configuration `q` and extra inputs `inputs`.
    fn prediction(&self, q: &[f64], inputs: &[f64]) -> Prediction {
        let dh = &self.basis.dh;
        let mounting = self.basis.registration.frame.mounting;
        // `nominal`: the nominal chain alone (`predicted_at`'s flange, the same products).
        if self.position.is_empty() && self.orientation.is_empty() {
            let flange = dh.flange_pose(q);
            let position = flange * mounting;
            return Prediction {
                position,
                linearized_position: position,
                orientation: flange.rotation,
            };
        }
        // One pass over the chain for the nominal pose, the Jacobian's frames and the links of the chain
        // with errors (`flange_pose` multiplies the same links in the same order).
        let pose = dh.pose(q);
        let (position, orientation, ep) = self.predicted_at(&pose, inputs);
        let nominal = pose.flange(dh) * mounting;
        let linearized_position = if self.position.is_empty() {
            nominal
        } else {
            let params: Vec<ErrorParam> = self.position.iter().map(|m| m.param).collect();
            let j = error_jacobian_on(dh, &pose.frames, &mounting, &params);
            nominal + j.fixed_rows::<3>(0) * DVector::from_vec(ep)
        };
        Prediction {
            position,
            linearized_position,
            orientation,
        }
    }

    /// The predicted measured point and flange orientation at `pose` (of the model's nominal chain), and the
    /// position parameters there.
    fn predicted_at(
        &self,
        pose: &ChainPose,
        inputs: &[f64],
    ) -> (Point3<f64>, UnitQuaternion<f64>, Vec<f64>) {
        let dh = &self.basis.dh;
        let nominal = pose.flange(dh);
        let (ep, eo) = self.parameters_at(&pose.q, inputs, &nominal);
        // Without parameters the chain with errors is the nominal one, bit for bit (zero rows are skipped).
        let with_errors = |models: &[ParameterModel], values: &[f64]| {
            if models.is_empty() {
                nominal
            } else {
                let errors = self.frame_errors_of(models, values);
                flange_pose_with_errors_on(dh, pose.links.iter().copied(), &errors)
            }
        };
        let position = with_errors(&self.position, &ep) * self.basis.registration.frame.mounting;
        let orientation = with_errors(&self.orientation, &eo).rotation;
        (position, orientation, ep)
    }
}

/// Three coordinates per point: with fewer than there are parameters not even a constant model of the
/// parameters is determined, and the per-parameter regressions would fit noise.
fn check_identifiable(kind: ErrorModelKind, n_train: usize, n_params: usize) -> Result<()> {
    if 3 * n_train < n_params {
        return Err(Error::Invalid(format!(
            "{} training points measure {} coordinates, fewer than the {} error parameters of {}: \
             the model cannot be identified; measure more points or choose a smaller model",
            n_train,
            3 * n_train,
            n_params,
            info_of(Some(kind)).name
        )));
    }
    Ok(())
}

/// One ridge model per parameter of `params`, on the training candidate rows (chosen on the validation
/// rows); the rows of `y_train` and `y_val` hold the parameters' identified values per point.
fn regress(
    params: &[ErrorParam],
    candidates: &SharedCandidates,
    y_train: &[Vec<f64>],
    y_val: &[Vec<f64>],
    opts: &RegressionOptions,
) -> Result<Vec<ParameterModel>> {
    if params.is_empty() {
        return Ok(Vec::new());
    }
    let to_matrix =
        |rows: &[Vec<f64>]| DMatrix::from_fn(rows.len(), params.len(), |r, c| rows[r][c]);
    let fitted = candidates.fit(&to_matrix(y_train), &to_matrix(y_val), opts)?;
    Ok(params
        .iter()
        .zip(fitted)
        .map(|(p, m)| ParameterModel {
            param: *p,
            name: p.name(),
            model: m,
        })
        .collect())
}

impl Fitted for PaperModel {
    fn info(&self) -> &'static MethodInfo {
        self.method
    }

    fn basis(&self) -> &Basis {
        &self.basis
    }

    fn predict(&self, q: &[f64]) -> Prediction {
        self.prediction(q, &[])
    }

    fn input_names(&self) -> &[String] {
        &self.extra_inputs
    }

    fn predict_with(&self, q: &[f64], inputs: &[f64]) -> Prediction {
        self.prediction(q, inputs)
    }

    fn point_at(&self, pose: &ChainPose, inputs: &[f64]) -> (Point3<f64>, UnitQuaternion<f64>) {
        let (position, orientation, _) = self.predicted_at(pose, inputs);
        (position, orientation)
    }

    /// The error parameters of the paper's models are regressions; `nominal` has none.
    fn has_regression(&self) -> bool {
        self.kind.is_some()
    }

    /// Without orientation parameters the flange turns as the position parameters turn it (their frames are
    /// rigid), so a point elsewhere on the flange moves with them.
    fn predicted_flange(&self, q: &[f64], inputs: &[f64]) -> nalgebra::Isometry3<f64> {
        let nominal = self.basis.dh.flange_pose(q);
        let (ep, eo) = self.parameters_at(q, inputs, &nominal);
        // Without position parameters the chain with errors is the nominal one, bit for bit.
        let position = if self.position.is_empty() {
            nominal
        } else {
            flange_pose_with_errors(
                &self.basis.dh,
                q,
                &self.frame_errors_of(&self.position, &ep),
            )
        };
        if self.orientation.is_empty() {
            return position;
        }
        let rotation = flange_pose_with_errors(
            &self.basis.dh,
            q,
            &self.frame_errors_of(&self.orientation, &eo),
        )
        .rotation;
        let m = self.basis.registration.frame.mounting;
        nalgebra::Isometry3::from_parts(
            nalgebra::Translation3::from((position * m).coords - rotation * m.coords),
            rotation,
        )
    }

    fn models_orientation(&self) -> bool {
        !self.orientation.is_empty()
    }

    /// The kept parameters and, per parameter, R² on validation and test data (eq. 20): the identified values
    /// of the test points against the modelled ones.
    fn report(&self, test: &[Observation]) -> serde_json::Value {
        let pos: Vec<ErrorParam> = self.position.iter().map(|m| m.param).collect();
        let ori: Vec<ErrorParam> = self.orientation.iter().map(|m| m.param).collect();
        let id = self.identify(test, &pos, &ori);
        let modelled: Vec<(Vec<f64>, Vec<f64>)> = test
            .iter()
            .map(|o| self.parameters_with(&o.q, &o.inputs))
            .collect();
        let mut r2s = serde_json::Map::new();
        for (models, identified, group) in [
            (&self.position, &id.position, 0),
            (&self.orientation, &id.orientation, 1),
        ] {
            for (k, m) in models.iter().enumerate() {
                let y: Vec<f64> = identified.iter().map(|row| row[k]).collect();
                let y_hat: Vec<f64> = modelled
                    .iter()
                    .map(|(p, o)| if group == 0 { p[k] } else { o[k] })
                    .collect();
                let test_r2 = (!y.is_empty()).then(|| r2(&y, &y_hat));
                r2s.insert(
                    m.name.clone(),
                    json!({ "validation": m.model.validation_r2, "test": test_r2 }),
                );
            }
        }
        json!({
            "kept_parameters": {
                "position": self.position.iter().map(|m| m.name.clone()).collect::<Vec<_>>(),
                "orientation": self.orientation.iter().map(|m| m.name.clone()).collect::<Vec<_>>(),
            },
            "r2": r2s,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calib::min_norm::{PINV_REL_EPS, min_norm_full_rank};
    use crate::numeric;
    use crate::robot::dh::DhChain;
    use crate::robot::urdf;
    use nalgebra::{Matrix3, Matrix3xX, Vector3};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// The SVD's minimum-norm solution, as `min_norm` computed it before the closed form.
    fn by_svd(j: Matrix3xX<f64>, rhs: Vector3<f64>) -> Vec<f64> {
        let svd = numeric::svd(j, true, true, "test").unwrap();
        let tol = svd.singular_values.max() * PINV_REL_EPS;
        svd.solve(&rhs, tol).unwrap().iter().copied().collect()
    }

    /// The minimum-norm solution from a Householder QR of `Jᵀ = QR` (backward stable): `x = Q R⁻ᵀ Δ`.
    fn by_qr(j: &Matrix3xX<f64>, rhs: Vector3<f64>) -> Vec<f64> {
        let qr = j.transpose().qr();
        let r = qr.r();
        let y = Matrix3::from_fn(|a, b| r[(b, a)])
            .solve_lower_triangular(&rhs)
            .unwrap();
        (qr.q() * nalgebra::DVector::from_column_slice(y.as_slice()))
            .iter()
            .copied()
            .collect()
    }

    fn relative(a: &[f64], b: &[f64]) -> f64 {
        let d = a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum::<f64>();
        (d / b.iter().map(|v| v * v).sum::<f64>()).sqrt()
    }

    /// Eq. 13 on the iiwa's Jacobians at random configurations, for each error model: the closed form is the
    /// minimum-norm solution of a QR of `Jᵀ` to 1e-12 of its norm (nalgebra's SVD of the wide `J`, the
    /// previous way, is further off: up to 1e-6, its residual as large), and solves the equation; a
    /// Jacobian whose rows are dependent goes to the SVD.
    #[test]
    fn closed_form_min_norm_is_the_qrs() {
        let chain = urdf::load_file("robots/iiwa7.urdf", None).unwrap();
        let dh = DhChain::from_chain(&chain).unwrap();
        let lower: Vec<f64> = chain.joints.iter().map(|j| j.lower).collect();
        let upper: Vec<f64> = chain.joints.iter().map(|j| j.upper).collect();
        let mounting = nalgebra::Point3::new(0.01, -0.02, 0.05);
        let mut rng = ChaCha8Rng::seed_from_u64(13);
        let (mut closed, mut worst, mut worst_svd) = (0, 0.0f64, 0.0f64);
        for kind in [
            ErrorModelKind::RotZ,
            ErrorModelKind::RotXyz,
            ErrorModelKind::RotXyzTransXyz,
        ] {
            let params = select_params(&dh, &lower, &upper, kind).position;
            for _ in 0..300 {
                let q: Vec<f64> = lower
                    .iter()
                    .zip(&upper)
                    .map(|(&lo, &hi)| rng.random_range(lo..hi))
                    .collect();
                let frames = dh.frames(&q);
                let j = error_jacobian_on(&dh, &frames, &mounting, &params)
                    .fixed_rows::<3>(0)
                    .into_owned();
                let rhs = Vector3::from_fn(|_, _| rng.random_range(-1e-3..1e-3));
                let want = by_qr(&j, rhs);
                let got = min_norm(j.clone(), rhs);
                if min_norm_full_rank(&j, &rhs).is_some() {
                    closed += 1;
                }
                worst = worst.max(relative(&got, &want));
                worst_svd = worst_svd.max(relative(&by_svd(j.clone(), rhs), &want));
                let x = nalgebra::DVector::from_vec(got);
                assert!((&j * x - rhs).norm() <= 1e-12 * rhs.norm());
            }
        }
        assert!(
            worst <= 1e-12,
            "closed form off the QR's by {worst:e} of the norm"
        );
        assert!(worst_svd <= 1e-5, "the SVD off the QR's by {worst_svd:e}");
        assert!(closed >= 890, "closed form on {closed} of 900 Jacobians");
        // Two equal rows: rank 2, the SVD's pseudo-inverse.
        let j = Matrix3xX::from_row_slice(&[1.0, 2.0, 0.5, 1.0, 2.0, 0.5, 0.0, 1.0, 3.0]);
        let rhs = Vector3::new(1.0, 1.0, 2.0);
        assert!(min_norm_full_rank(&j, &rhs).is_none());
        assert_eq!(min_norm(j.clone(), rhs), by_svd(j, rhs));
    }
}
