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

mod eq13;
mod fit;

use std::sync::OnceLock;

use nalgebra::{DVector, Isometry3, Point3, UnitQuaternion};
use serde::{Deserialize, Serialize};
use serde_json::json;

use super::error_model::{
    ErrorModelKind, ErrorParam, FrameErrors, error_jacobian_on, flange_pose_with_errors,
    flange_pose_with_errors_on, frame_errors,
};
use super::method::{Basis, FitContext, Fitted, Method, MethodInfo, Prediction, RobotParameters};
use super::regression::{RidgeModel, SharedFeatures, r2};
use super::tracker_frame::Observation;
use crate::dataset::Dataset;
use crate::error::Result;
use crate::robot::dh::ChainPose;
use crate::robot::plausible;
pub use fit::Identified;

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
    /// The parameter models' features, each computed once a point ([`SharedFeatures`]): built at the first
    /// prediction with the models `position` and `orientation` hold then (a fit sets them before it predicts,
    /// a file before any prediction).
    #[serde(skip)]
    pub(crate) features: OnceLock<Option<SharedFeatures>>,
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
impl PaperModel {
    /// The regression inputs at `q` with the nominal flange pose there given; `inputs`: the extra inputs in
    /// `extra_inputs` order, any other length (empty) standing for their training means.
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
        let models = || {
            self.position
                .iter()
                .chain(&self.orientation)
                .map(|m| &m.model)
        };
        let predicted = match self.shared_features() {
            Some(shared) => shared.predict(&x),
            None => models().map(|m| m.predict(&x)).collect(),
        };
        let mut position: Vec<f64> = predicted
            .into_iter()
            .zip(models())
            .map(|(p, m)| match w {
                // Weight 1 leaves the bits alone.
                1.0 => p,
                // Toward the regression's constant part (its intercept, the training mean): the model's
                // constant-parameter calibration.
                _ => m.intercept + w * (p - m.intercept),
            })
            .collect();
        let orientation = position.split_off(self.position.len());
        (position, orientation)
    }

    /// The parameter models' [`SharedFeatures`], position then orientation, where they hold every model.
    fn shared_features(&self) -> Option<&SharedFeatures> {
        let models = self.position.iter().chain(&self.orientation);
        self.features
            .get_or_init(|| SharedFeatures::of(models.clone().map(|m| &m.model)))
            .as_ref()
            .filter(|shared| shared.len() == models.count())
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
