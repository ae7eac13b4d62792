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

use nalgebra::{DMatrix, DVector, Isometry3, Matrix3xX, Point3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use super::error_model::{
    ErrorModelKind, ErrorParam, FrameErrors, error_jacobian, flange_pose_with_errors, frame_errors,
    select_params,
};
use super::registration::register_points;
use super::regression::{RegressionOptions, RidgeModel, fit_all};
use super::tracker_frame::{TrackerFrame, fit_tracker_frame};
use crate::dataset::Dataset;
use crate::error::{Error, Result};
use crate::eval::centre;
use crate::robot::dh::DhChain;

/// Singular values below this fraction of the largest are treated as zero in the minimum-norm solves: the
/// paper's indistinguishable parameters (eq. 14–16, 22) make `J_e` rank-deficient by construction.
const PINV_REL_EPS: f64 = 1e-10;

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct ParameterModel {
    pub param: ErrorParam,
    pub name: String,
    pub model: RidgeModel,
}

/// Everything a later run needs to predict: `model.json`.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct PaperModel {
    /// `nominal` or `paper-rotz` / `paper-rotxyz` / `paper-rotxyz-transxyz`.
    pub method: String,
    pub kind: Option<ErrorModelKind>,
    pub joint_names: Vec<String>,
    /// The nominal kinematics the model corrects (DH form of the robot's URDF).
    pub dh: DhChain,
    pub frame: TrackerFrame,
    /// A reflector nest about its centre, in the flange frame (m); orientation is measured from it.
    pub nest: Option<Vec<Point3<f64>>>,
    /// Names of the regression's candidate inputs: the joint angles (rad), then the nominal TCP x, y, z (m).
    pub candidates: Vec<String>,
    pub position: Vec<ParameterModel>,
    pub orientation: Vec<ParameterModel>,
}

/// One point as the method sees it, in the base frame.
#[derive(Clone, Debug)]
pub struct Observation {
    pub q: Vec<f64>,
    /// Measured point (reflector or nest centre), registered into the base frame.
    pub position: Point3<f64>,
    /// Measured flange orientation (nests only).
    pub orientation: Option<UnitQuaternion<f64>>,
}

/// A predicted pose of the measured point and the flange orientation.
#[derive(Clone, Debug)]
pub struct Prediction {
    pub position: Point3<f64>,
    /// The same by the linearized model `p_R + J_e e` (eq. 10).
    pub linearized_position: Point3<f64>,
    pub orientation: UnitQuaternion<f64>,
}

/// Per-point identified error parameters (eq. 13), for the regression and for R² on the test split.
#[derive(Clone, Debug)]
pub struct Identified {
    pub position: Vec<Vec<f64>>,
    pub orientation: Vec<Vec<f64>>,
}

pub fn method_name(kind: Option<ErrorModelKind>) -> &'static str {
    match kind {
        None => "nominal",
        Some(ErrorModelKind::RotZ) => "paper-rotz",
        Some(ErrorModelKind::RotXyz) => "paper-rotxyz",
        Some(ErrorModelKind::RotXyzTransXyz) => "paper-rotxyz-transxyz",
    }
}

impl PaperModel {
    /// Fits on `train`, choosing hyper-parameters on `val`. Joint limits decide where the parameter selection
    /// samples configurations.
    pub fn fit(
        kind: Option<ErrorModelKind>,
        dh: &DhChain,
        limits: (&[f64], &[f64]),
        train: &Dataset,
        val: &Dataset,
        options: &RegressionOptions,
    ) -> Result<PaperModel> {
        if train.is_empty() || val.is_empty() {
            return Err(Error::Invalid(format!(
                "{} training and {} validation points: both sets must be non-empty",
                train.len(),
                val.len()
            )));
        }
        // Registration sees every point the method may fit on; the test split stays untouched.
        let fit_points: Vec<(Vec<f64>, Point3<f64>)> = train
            .q
            .iter()
            .zip(&train.measured)
            .chain(val.q.iter().zip(&val.measured))
            .map(|(q, m)| (q.clone(), centre(m)))
            .collect();
        let flanges: Vec<Isometry3<f64>> =
            fit_points.iter().map(|(q, _)| dh.flange_pose(q)).collect();
        let centres: Vec<Point3<f64>> = fit_points.iter().map(|(_, c)| *c).collect();
        let guess = match &train.nominal_reflectors {
            Some(nom) => dh.flange_pose(&train.q[0]).inverse() * centre(&nom[0]),
            None => Point3::origin(),
        };
        let frame = fit_tracker_frame(&centres, &flanges, &guess)?;
        let nest = nest_geometry(dh, train)?;

        let mut model = PaperModel {
            method: method_name(kind).to_string(),
            kind,
            joint_names: train.joint_names.clone(),
            dh: dh.clone(),
            frame,
            nest,
            candidates: train
                .joint_names
                .iter()
                .cloned()
                .chain(["tcp_x", "tcp_y", "tcp_z"].map(String::from))
                .collect(),
            position: Vec::new(),
            orientation: Vec::new(),
        };
        let Some(kind) = kind else {
            return Ok(model);
        };
        let selection = select_params(dh, limits.0, limits.1, kind);
        // Three coordinates per point: with fewer than there are parameters not even a constant model of the
        // parameters is determined, and the per-parameter regressions would fit noise.
        if 3 * train.len() < selection.position.len() {
            return Err(Error::Invalid(format!(
                "{} training points measure {} coordinates, fewer than the {} error parameters of {}: \
                 the model cannot be identified; measure more points or choose a smaller model",
                train.len(),
                3 * train.len(),
                selection.position.len(),
                method_name(Some(kind))
            )));
        }
        let orientation_params = if model.nest.is_some() {
            selection.orientation_only.clone()
        } else {
            Vec::new()
        };
        let (obs_train, obs_val) = (model.observe(train)?, model.observe(val)?);
        let id_train = model.identify(&obs_train, &selection.position, &orientation_params);
        let id_val = model.identify(&obs_val, &selection.position, &orientation_params);
        let (x_train, x_val) = (
            model.candidate_matrix(&obs_train),
            model.candidate_matrix(&obs_val),
        );
        let regress = |params: &[ErrorParam],
                       y_train: &[Vec<f64>],
                       y_val: &[Vec<f64>]|
         -> Result<Vec<ParameterModel>> {
            if params.is_empty() {
                return Ok(Vec::new());
            }
            let to_matrix =
                |rows: &[Vec<f64>]| DMatrix::from_fn(rows.len(), params.len(), |r, c| rows[r][c]);
            let fitted = fit_all(
                &x_train,
                &to_matrix(y_train),
                &x_val,
                &to_matrix(y_val),
                options,
            )?;
            Ok(params
                .iter()
                .zip(fitted)
                .map(|(p, m)| ParameterModel {
                    param: *p,
                    name: p.name(),
                    model: m,
                })
                .collect())
        };
        model.position = regress(&selection.position, &id_train.position, &id_val.position)?;
        model.orientation = regress(
            &orientation_params,
            &id_train.orientation,
            &id_val.orientation,
        )?;
        Ok(model)
    }

    /// The dataset's measurements in the base frame.
    pub fn observe(&self, data: &Dataset) -> Result<Vec<Observation>> {
        self.observe_points(&data.q, &data.measured)
    }

    /// Measurements (tracker frame, per reflector) of configurations `q`, in the base frame.
    pub fn observe_points(
        &self,
        q: &[Vec<f64>],
        measured: &[Vec<Point3<f64>>],
    ) -> Result<Vec<Observation>> {
        q.iter()
            .zip(measured)
            .map(|(q, points)| {
                let orientation = match &self.nest {
                    Some(nest) if points.len() == nest.len() => {
                        let c = centre(points);
                        let local: Vec<Point3<f64>> =
                            points.iter().map(|p| Point3::from(p - c)).collect();
                        let fit = register_points(nest, &local)?;
                        Some(self.frame.tracker_to_base.rotation * fit.transform.rotation)
                    }
                    _ => None,
                };
                Ok(Observation {
                    q: q.clone(),
                    position: self.frame.to_base(&centre(points)),
                    orientation,
                })
            })
            .collect()
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
        for o in observations {
            let flange = self.dh.flange_pose(&o.q);
            if !position_params.is_empty() {
                let j = error_jacobian(&self.dh, &o.q, &self.frame.mounting, position_params);
                let dp = o.position - flange * self.frame.mounting;
                id.position
                    .push(min_norm(j.fixed_rows::<3>(0).into_owned(), dp));
            }
            if let (false, Some(measured)) = (orientation_params.is_empty(), o.orientation) {
                let j = error_jacobian(&self.dh, &o.q, &self.frame.mounting, orientation_params);
                // The relative rotation, in the base frame, is what J_e linearizes; eq. 25's difference of
                // rotation vectors equals it only to first order near the identity.
                let dw = (measured * flange.rotation.inverse()).scaled_axis();
                id.orientation
                    .push(min_norm(j.fixed_rows::<3>(3).into_owned(), dw));
            }
        }
        id
    }

    /// Regression inputs of each observation: joint angles, then the nominal TCP position.
    fn candidate_matrix(&self, observations: &[Observation]) -> DMatrix<f64> {
        let rows: Vec<Vec<f64>> = observations
            .iter()
            .map(|o| self.candidates_of(&o.q))
            .collect();
        DMatrix::from_fn(rows.len(), self.candidates.len(), |r, c| rows[r][c])
    }

    fn candidates_of(&self, q: &[f64]) -> Vec<f64> {
        let tcp = self.dh.flange_pose(q) * self.frame.mounting;
        q.iter().copied().chain([tcp.x, tcp.y, tcp.z]).collect()
    }

    /// Modelled error parameters at configuration `q`.
    pub fn parameters(&self, q: &[f64]) -> (Vec<f64>, Vec<f64>) {
        let x = self.candidates_of(q);
        let eval = |models: &[ParameterModel]| models.iter().map(|m| m.model.predict(&x)).collect();
        (eval(&self.position), eval(&self.orientation))
    }

    fn frame_errors_of(&self, models: &[ParameterModel], values: &[f64]) -> FrameErrors {
        let params: Vec<ErrorParam> = models.iter().map(|m| m.param).collect();
        frame_errors(self.dh.dof(), &params, values)
    }

    /// Predicted measured point and flange orientation for configuration `q`.
    pub fn predict(&self, q: &[f64]) -> Prediction {
        let (ep, eo) = self.parameters(q);
        let nominal = self.dh.flange_pose(q);
        let position =
            flange_pose_with_errors(&self.dh, q, &self.frame_errors_of(&self.position, &ep))
                * self.frame.mounting;
        let orientation =
            flange_pose_with_errors(&self.dh, q, &self.frame_errors_of(&self.orientation, &eo))
                .rotation;
        let linearized_position = if self.position.is_empty() {
            nominal * self.frame.mounting
        } else {
            let params: Vec<ErrorParam> = self.position.iter().map(|m| m.param).collect();
            let j = error_jacobian(&self.dh, q, &self.frame.mounting, &params);
            nominal * self.frame.mounting + j.fixed_rows::<3>(0) * DVector::from_vec(ep)
        };
        Prediction {
            position,
            linearized_position,
            orientation,
        }
    }

    /// The nominal prediction: what the controller believes ("before").
    pub fn nominal(&self, q: &[f64]) -> (Point3<f64>, UnitQuaternion<f64>) {
        let f = self.dh.flange_pose(q);
        (f * self.frame.mounting, f.rotation)
    }

    /// Joint angles that make the calibrated model put the measured point (and, with a nest model, the
    /// flange orientation) where the nominal model puts them at `q_intended`: the command a controller should
    /// be sent. Gauss–Newton on the nominal Jacobian, since model and nominal differ by a fraction of a
    /// millimetre. Returns the command and the remaining position error (m).
    pub fn compensate(&self, q_intended: &[f64]) -> Result<(Vec<f64>, f64)> {
        let (target_p, target_r) = self.nominal(q_intended);
        let use_rotation = !self.orientation.is_empty();
        let mut q = q_intended.to_vec();
        let mut err = f64::INFINITY;
        for _ in 0..20 {
            let pred = self.predict(&q);
            let dp = target_p - pred.position;
            let dr = (target_r * pred.orientation.inverse()).scaled_axis();
            err = dp.norm();
            if err < 1e-10 && (!use_rotation || dr.norm() < 1e-10) {
                return Ok((q, err));
            }
            let j = self.nominal_jacobian(&q);
            let rows = if use_rotation { 6 } else { 3 };
            let mut rhs = DVector::zeros(rows);
            rhs.fixed_rows_mut::<3>(0).copy_from(&dp);
            if use_rotation {
                rhs.fixed_rows_mut::<3>(3).copy_from(&dr);
            }
            let step = j
                .rows(0, rows)
                .into_owned()
                .svd(true, true)
                .solve(&rhs, 1e-12)
                .map_err(|e| Error::Invalid(format!("compensation: singular Jacobian ({e})")))?;
            for (qi, s) in q.iter_mut().zip(step.iter()) {
                *qi += s;
            }
        }
        if err < 1e-7 {
            Ok((q, err))
        } else {
            Err(Error::Invalid(format!(
                "compensation did not converge ({err:.3e} m left): the configuration may be singular"
            )))
        }
    }

    /// Geometric Jacobian of the measured point (rows 0–2) and the flange rotation (rows 3–5), nominal model.
    fn nominal_jacobian(&self, q: &[f64]) -> DMatrix<f64> {
        let frames = self.dh.frames(q);
        let n = self.dh.dof();
        let p = frames[n] * self.dh.tool * self.frame.mounting;
        DMatrix::from_fn(6, n, |r, c| {
            let f = &frames[c];
            let z = f.rotation * Vector3::z();
            let col = if self.dh.rows[c].prismatic {
                [z.x, z.y, z.z, 0.0, 0.0, 0.0]
            } else {
                let v = z.cross(&(p - Point3::from(f.translation.vector)));
                [v.x, v.y, v.z, z.x, z.y, z.z]
            };
            col[r]
        })
    }
}

/// The nest about its centre in the flange frame, from the nominal reflector positions of the first point.
fn nest_geometry(dh: &DhChain, data: &Dataset) -> Result<Option<Vec<Point3<f64>>>> {
    if data.reflectors() < 3 {
        return Ok(None);
    }
    let Some(nominal) = &data.nominal_reflectors else {
        return Err(Error::Data {
            origin: data.origin.clone(),
            message: "three reflectors but no nom_x1 … nom_z3 columns: the nest geometry on the flange is unknown"
                .into(),
        });
    };
    let flange_inv = dh.flange_pose(&data.q[0]).inverse();
    let local: Vec<Point3<f64>> = nominal[0].iter().map(|p| flange_inv * p).collect();
    let c = centre(&local);
    Ok(Some(local.iter().map(|p| Point3::from(p - c)).collect()))
}

fn min_norm(j: Matrix3xX<f64>, rhs: Vector3<f64>) -> Vec<f64> {
    let svd = j.svd(true, true);
    let tol = svd.singular_values.max() * PINV_REL_EPS;
    svd.solve(&rhs, tol)
        .map(|x| x.iter().copied().collect())
        .unwrap_or_else(|_| vec![0.0; j_cols(&svd)])
}

fn j_cols(svd: &nalgebra::SVD<f64, nalgebra::U3, nalgebra::Dyn>) -> usize {
    svd.v_t.as_ref().map_or(0, |v| v.ncols())
}
