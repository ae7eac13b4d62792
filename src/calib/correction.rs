//! Ridge models of what a reference prediction leaves: the residual correction of `residual-ridge` (on the
//! nominal prediction) and of the hybrids (on their base's), one ridge polynomial per component of the
//! measured point's offset and, with a reflector nest, of the flange's rotation vector, on the joint angles
//! and the data's extra inputs, chosen on the validation data by [`fit_all`].
//!
//! A residual model must not make its reference worse on the data that chose it. A component whose fitted
//! model has a larger validation sum of squares than no correction at all is replaced by zero, and a group
//! (position, orientation) whose mean validation error (distance, angle) would grow is dropped as a whole;
//! so on the validation data the corrected model is never worse than its reference in either measure.

use std::borrow::Cow;

use nalgebra::{DMatrix, Point3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};
use serde_json::json;

use super::regression::{Candidates, RegressionOptions, RidgeModel, r2};
use super::tracker_frame::Observation;
use crate::dataset::MOTION_INPUT_PREFIX;
use crate::error::{Error, Result};
use crate::robot::plausible;

/// Names of the modelled components: measured-point offsets (m) and flange rotation vector (rad), base frame.
const POSITION_NAMES: [&str; 3] = ["dx", "dy", "dz"];
const ORIENTATION_NAMES: [&str; 3] = ["rx", "ry", "rz"];

/// A reference prediction: the measured point and the flange orientation.
pub(super) type Reference = (Point3<f64>, UnitQuaternion<f64>);
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

/// Weight below 1 (outside the training domain): `v` toward the constant part of each component's regression,
/// its intercept (the training mean). Weight 1 leaves the bits alone.
fn toward(models: &[ComponentModel], v: Vector3<f64>, weight: f64) -> Vector3<f64> {
    if weight == 1.0 {
        return v;
    }
    let c = Vector3::from_fn(|k, _| models[k].model.intercept);
    c + (v - c) * weight
}

/// `reference` moved by the position offset `dp` and turned by the rotation vector `dw`.
fn corrected(reference: &Reference, dp: Vector3<f64>, dw: Option<Vector3<f64>>) -> Reference {
    // A zero rotation leaves the reference's bits alone, as a zero offset does.
    let orientation = match dw {
        Some(w) if w != Vector3::zeros() => UnitQuaternion::from_scaled_axis(w) * reference.1,
        _ => reference.1,
    };
    (reference.0 + dp, orientation)
}

pub(super) fn mean(values: impl Iterator<Item = f64>) -> f64 {
    let (sum, n) = values.fold((0.0, 0usize), |(s, n), v| (s + v, n + 1));
    if n == 0 { 0.0 } else { sum / n as f64 }
}

/// What a residual fit needs besides the reference predictions, prepared once for every fit on the same
/// points (`residual-ridge` refits its residual each registration round): the checked candidate rows, the
/// extra inputs' means, and the regression's features of the rows.
pub(super) struct ResidualSetup {
    candidates: Vec<String>,
    input_means: Vec<f64>,
    x_val_rows: Vec<Vec<f64>>,
    regression: Candidates,
}

impl ResidualSetup {
    /// The setup of observations `train` and `val` (their joint angles and extra inputs; the positions and
    /// orientations come with each fit).
    pub(super) fn new(
        joint_names: &[String],
        extra_inputs: &[String],
        train: &[Observation],
        val: &[Observation],
    ) -> Result<ResidualSetup> {
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
        let x_val = candidate_matrix(val, dof, extra);
        Ok(ResidualSetup {
            candidates: joint_names.iter().chain(extra_inputs).cloned().collect(),
            input_means,
            x_val_rows: (0..val.len())
                .map(|r| x_val.row(r).iter().copied().collect())
                .collect(),
            regression: Candidates::new(candidate_matrix(train, dof, extra), x_val)
                .keeping_factors(),
        })
    }
}

/// One component's modelled values, [`RidgeModel::predict`]'s bits: at the training points where the search's
/// feature columns say them ([`Candidates::fitted`]), and at the validation points.
struct Values {
    train: Option<Vec<f64>>,
    val: Vec<f64>,
}

impl Values {
    /// Those of a zero model: `predict` gives +0.0 everywhere.
    fn zero(&mut self) {
        if let Some(t) = &mut self.train {
            t.fill(0.0);
        }
        self.val.fill(0.0);
    }

    /// The values at the training points (none where the search's columns do not say them).
    fn at_train(&self) -> &[f64] {
        self.train.as_deref().unwrap_or_default()
    }

    fn at_val(&self) -> &[f64] {
        &self.val
    }
}

/// The vectors of a group's three components at row `i` of `side`.
fn vector_at(group: &[Values], side: fn(&Values) -> &[f64], i: usize) -> Vector3<f64> {
    Vector3::new(side(&group[0])[i], side(&group[1])[i], side(&group[2])[i])
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
        let mut setup = ResidualSetup::new(joint_names, extra_inputs, train, val)?;
        let refs_train: Vec<Reference> = train.iter().map(|o| reference(&o.q)).collect();
        let refs_val: Vec<Reference> = val.iter().map(|o| reference(&o.q)).collect();
        Ok(ResidualCorrection::fit_prepared(
            &mut setup,
            (train, &refs_train),
            (val, &refs_val),
            orientation,
            opts,
        )?
        .0)
    }

    /// [`ResidualCorrection::fit`] on a setup of the same observations' rows, with the reference predictions
    /// of the training and validation observations given; with it the modelled position offset at every
    /// training point, then every validation point ([`ResidualCorrection::correction`]'s bits), where the
    /// search's feature columns say them.
    pub(super) fn fit_prepared(
        setup: &mut ResidualSetup,
        (train, refs_train): (&[Observation], &[Reference]),
        (val, refs_val): (&[Observation], &[Reference]),
        orientation: bool,
        opts: &RegressionOptions,
    ) -> Result<(ResidualCorrection, Option<Vec<Vector3<f64>>>)> {
        let res = |obs: &[Observation], refs: &[Reference]| -> Vec<_> {
            obs.iter()
                .zip(refs)
                .map(|(o, r)| residual_of(o, r))
                .collect()
        };
        let (res_train, res_val) = (res(train, refs_train), res(val, refs_val));
        let with_orientation =
            orientation && res_train.iter().chain(&res_val).all(|r| r.1.is_some());
        let x_val_rows = &setup.x_val_rows;
        let regression = &mut setup.regression;
        let mut regress = |names: [&str; 3],
                           component: &dyn Fn(&Residual) -> Vector3<f64>|
         -> Result<(Vec<ComponentModel>, Vec<Values>)> {
            let matrix =
                |rows: &[Residual]| DMatrix::from_fn(rows.len(), 3, |r, c| component(&rows[r])[c]);
            let y_val = matrix(&res_val);
            let models = regression.fit(&matrix(&res_train), &y_val, opts)?;
            let regression = &*regression;
            Ok(names
                .iter()
                .zip(models)
                .enumerate()
                .map(|(k, (name, model))| {
                    // `predict` at the validation rows, from the search's feature columns where they say it.
                    let mut values = match regression.fitted(&model) {
                        Some((train, val)) => Values {
                            train: Some(train),
                            val,
                        },
                        None => Values {
                            train: None,
                            val: x_val_rows.iter().map(|x| model.predict(x)).collect(),
                        },
                    };
                    // No worse than no correction, in the validation sum of squares.
                    let y: Vec<f64> = y_val.column(k).iter().copied().collect();
                    let sse_model: f64 = y
                        .iter()
                        .zip(&values.val)
                        .map(|(a, b)| (a - b).powi(2))
                        .sum();
                    let sse_zero: f64 = y.iter().map(|a| a * a).sum();
                    let kept = sse_model < sse_zero;
                    if !kept {
                        values.zero();
                    }
                    let model = ComponentModel {
                        name: name.to_string(),
                        kept,
                        model: if kept {
                            model
                        } else {
                            zero_model(r2(&y, &vec![0.0; y.len()]))
                        },
                    };
                    (model, values)
                })
                .unzip())
        };
        let (position, mut position_values) = regress(POSITION_NAMES, &|r| r.0)?;
        let (orientation, mut orientation_values) = if with_orientation {
            regress(ORIENTATION_NAMES, &|r| r.1.unwrap_or_default())?
        } else {
            (Vec::new(), Vec::new())
        };
        let mut correction = ResidualCorrection {
            candidates: setup.candidates.clone(),
            input_means: setup.input_means.clone(),
            position,
            orientation,
        };
        correction.prune(val, refs_val, &mut position_values, &mut orientation_values);
        let offsets = position_values.iter().all(|v| v.train.is_some()).then(|| {
            (0..train.len())
                .map(|i| vector_at(&position_values, Values::at_train, i))
                .chain((0..val.len()).map(|i| vector_at(&position_values, Values::at_val, i)))
                .collect()
        });
        Ok((correction, offsets))
    }

    /// Drops a group whose mean validation error (distance, angle) would grow, evaluated as predictions are
    /// made ([`corrected`]) from the components' values at the validation points (`position`, `orientation`:
    /// `predict`'s bits; zeroed with their group).
    fn prune(
        &mut self,
        val: &[Observation],
        refs: &[Reference],
        position: &mut [Values],
        orientation: &mut [Values],
    ) {
        let at = |group: &[Values], i: usize| vector_at(group, Values::at_val, i);
        let corrected: Vec<Reference> = refs
            .iter()
            .enumerate()
            .map(|(i, r)| {
                let dw = (!self.orientation.is_empty()).then(|| at(orientation, i));
                corrected(r, at(position, i), dw)
            })
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
            position.iter_mut().for_each(Values::zero);
        }
        if !self.orientation.is_empty() && angle(&corrected) > angle(refs) {
            let ys = residuals
                .iter()
                .map(|r| r.1.unwrap_or_default())
                .collect::<Vec<_>>();
            zero_group(&mut self.orientation, &ys);
            orientation.iter_mut().for_each(Values::zero);
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
    fn row<'a>(&self, q: &'a [f64], inputs: &[f64]) -> Cow<'a, [f64]> {
        let extra = if inputs.len() == self.input_means.len() {
            inputs
        } else {
            &self.input_means
        };
        // Without extra inputs the row is the configuration itself.
        if extra.is_empty() {
            return Cow::Borrowed(q);
        }
        Cow::Owned(q.iter().chain(extra).copied().collect())
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
    pub(super) fn apply_with_offset(
        &self,
        q: &[f64],
        inputs: &[f64],
        reference: &Reference,
        weight: f64,
    ) -> (Reference, Vector3<f64>) {
        let (dp, dw) = self.correction(q, inputs);
        let dp = self.weighted_position(dp, weight);
        let dw = dw.map(|w| toward(&self.orientation, w, weight));
        (corrected(reference, dp, dw), dp)
    }

    /// The modelled position offset `dp` at a point of weight `weight` ([`toward`]).
    pub(super) fn weighted_position(&self, dp: Vector3<f64>, weight: f64) -> Vector3<f64> {
        toward(&self.position, dp, weight)
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
