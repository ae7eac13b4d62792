//! One interface for every calibration method: fit on training data (validation data for hyper-parameters),
//! predict the measured point and the flange orientation for joint angles, and invert — the joint command
//! that makes the calibrated model reach a target, which is what a controller is sent.

use nalgebra::{DMatrix, DVector, Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use super::kinematic::KinematicModel;
use super::paper::PaperModel;
use super::regression::RegressionOptions;
use super::residual::{HybridModel, ResidualModel};
use super::tracker_frame::{Observation, Registration};
use crate::dataset::Dataset;
use crate::error::{Error, Result};
use crate::robot::dh::DhChain;
use crate::robot::{Chain, Payload};

/// The methods a user can fit. `oracle` is not here: it needs the truth, and only the evaluation has it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum MethodKind {
    Nominal,
    PaperRotz,
    PaperRotxyz,
    PaperRotxyzTransxyz,
    Kinematic,
    Elastic,
    ResidualRidge,
    Hybrid,
    HybridKinematic,
}

impl MethodKind {
    pub const ALL: [MethodKind; 9] = [
        MethodKind::Nominal,
        MethodKind::PaperRotz,
        MethodKind::PaperRotxyz,
        MethodKind::PaperRotxyzTransxyz,
        MethodKind::Kinematic,
        MethodKind::Elastic,
        MethodKind::ResidualRidge,
        MethodKind::Hybrid,
        MethodKind::HybridKinematic,
    ];

    pub fn name(self) -> &'static str {
        match self {
            MethodKind::Nominal => "nominal",
            MethodKind::PaperRotz => "paper-rotz",
            MethodKind::PaperRotxyz => "paper-rotxyz",
            MethodKind::PaperRotxyzTransxyz => "paper-rotxyz-transxyz",
            MethodKind::Kinematic => "kinematic",
            MethodKind::Elastic => "elastic",
            MethodKind::ResidualRidge => "residual-ridge",
            MethodKind::Hybrid => "hybrid",
            MethodKind::HybridKinematic => "hybrid-kinematic",
        }
    }

    pub fn parse(name: &str) -> Result<MethodKind> {
        MethodKind::ALL
            .into_iter()
            .find(|m| m.name() == name)
            .ok_or_else(|| {
                let names: Vec<&str> = MethodKind::ALL.iter().map(|m| m.name()).collect();
                Error::Invalid(format!(
                    "unknown method '{name}'; choose one of {}",
                    names.join(", ")
                ))
            })
    }
}

/// What a method may know besides the data: the nominal robot as its maker describes it.
pub struct FitContext<'a> {
    pub chain: &'a Chain,
    pub dh: &'a DhChain,
    /// The payload the user declares (for gravity torques of the elastic models).
    pub payload: Payload,
    pub regression: RegressionOptions,
}

impl<'a> FitContext<'a> {
    /// A context with no declared payload and the default regression options (the paper's features).
    pub fn new(chain: &'a Chain, dh: &'a DhChain) -> FitContext<'a> {
        FitContext {
            chain,
            dh,
            payload: Payload::NONE,
            regression: RegressionOptions::default(),
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

/// A fitted calibration.
pub trait Fitted: Send + Sync {
    fn method(&self) -> &str;
    fn registration(&self) -> &Registration;
    /// The robot's joints, in the order of `q`.
    fn joint_names(&self) -> &[String];
    /// The nominal kinematics the method corrects.
    fn dh(&self) -> &DhChain;
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
    /// Method-specific facts for `report.json` (kept parameters, R², rank, condition number…), given the
    /// test observations.
    fn report(&self, test: &[Observation]) -> serde_json::Value;
    /// What `model.json` holds.
    fn save(&self) -> SavedModel;

    /// The nominal model's measured point and flange orientation: what the controller believes.
    fn nominal(&self, q: &[f64]) -> (Point3<f64>, UnitQuaternion<f64>) {
        let f = self.dh().flange_pose(q);
        (f * self.registration().frame.mounting, f.rotation)
    }

    /// Joint angles, from `seed`, at which this model puts the measured point at `target` (and the flange at
    /// `orientation` when the method models it). Gauss–Newton on the nominal Jacobian: every model differs
    /// from the nominal one by a fraction of a millimetre. Returns the command and the remaining distance (m).
    fn command_for(
        &self,
        target: &Point3<f64>,
        orientation: Option<&UnitQuaternion<f64>>,
        seed: &[f64],
    ) -> Result<(Vec<f64>, f64)> {
        let rotation = orientation.filter(|_| self.models_orientation());
        let rows = if rotation.is_some() { 6 } else { 3 };
        let mut q = seed.to_vec();
        let mut err = f64::INFINITY;
        for _ in 0..20 {
            let pred = self.predict(&q);
            let dp = target - pred.position;
            let dr = rotation.map_or(Vector3::zeros(), |r| {
                (r * pred.orientation.inverse()).scaled_axis()
            });
            err = dp.norm();
            if err < 1e-10 && dr.norm() < 1e-10 {
                return Ok((q, err));
            }
            let mut rhs = DVector::zeros(rows);
            rhs.fixed_rows_mut::<3>(0).copy_from(&dp);
            if rows == 6 {
                rhs.fixed_rows_mut::<3>(3).copy_from(&dr);
            }
            let j = nominal_jacobian(self.dh(), &self.registration().frame.mounting, &q);
            let step = j
                .rows(0, rows)
                .into_owned()
                .svd(true, true)
                .solve(&rhs, 1e-12)
                .map_err(|e| Error::Invalid(format!("inverse: singular Jacobian ({e})")))?;
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

    /// The command that makes the calibrated model reach what the nominal model reaches at `q_intended`.
    fn compensate(&self, q_intended: &[f64]) -> Result<(Vec<f64>, f64)> {
        let (p, r) = self.nominal(q_intended);
        self.command_for(&p, Some(&r), q_intended)
    }
}

/// Geometric Jacobian of a point fixed to the flange (rows 0–2) and of the flange rotation (rows 3–5), for the
/// nominal DH chain.
pub fn nominal_jacobian(dh: &DhChain, point_in_flange: &Point3<f64>, q: &[f64]) -> DMatrix<f64> {
    let frames = dh.frames(q);
    let n = dh.dof();
    let p = frames[n] * dh.tool * point_in_flange;
    DMatrix::from_fn(6, n, |r, c| {
        let f = &frames[c];
        let z = f.rotation * Vector3::z();
        let col = if dh.rows[c].prismatic {
            [z.x, z.y, z.z, 0.0, 0.0, 0.0]
        } else {
            let v = z.cross(&(p - Point3::from(f.translation.vector)));
            [v.x, v.y, v.z, z.x, z.y, z.z]
        };
        col[r]
    })
}

/// `model.json`: any fitted method, tagged by kind, so `calibrate apply` can load what `calibrate` saved.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(tag = "model", rename_all = "kebab-case")]
pub enum SavedModel {
    Paper(PaperModel),
    Kinematic(Box<KinematicModel>),
    Residual(ResidualModel),
    Hybrid(HybridModel),
}

impl SavedModel {
    pub fn into_fitted(self) -> Box<dyn Fitted> {
        match self {
            SavedModel::Paper(m) => Box::new(m),
            SavedModel::Kinematic(m) => m,
            SavedModel::Residual(m) => Box::new(m),
            SavedModel::Hybrid(m) => Box::new(m.into_fitted()),
        }
    }
}

/// Fits `kind` on `train`, with `val` for its hyper-parameters.
pub fn fit(
    kind: MethodKind,
    ctx: &FitContext,
    train: &Dataset,
    val: &Dataset,
) -> Result<Box<dyn Fitted>> {
    use super::error_model::ErrorModelKind as E;
    let paper = |k: Option<E>| -> Result<Box<dyn Fitted>> {
        Ok(Box::new(PaperModel::fit(k, ctx, train, val)?))
    };
    match kind {
        MethodKind::Nominal => paper(None),
        MethodKind::PaperRotz => paper(Some(E::RotZ)),
        MethodKind::PaperRotxyz => paper(Some(E::RotXyz)),
        MethodKind::PaperRotxyzTransxyz => paper(Some(E::RotXyzTransXyz)),
        MethodKind::Kinematic => Ok(Box::new(KinematicModel::fit(false, ctx, train, val)?)),
        MethodKind::Elastic => Ok(Box::new(KinematicModel::fit(true, ctx, train, val)?)),
        MethodKind::ResidualRidge => Ok(Box::new(ResidualModel::fit(ctx, train, val)?)),
        MethodKind::Hybrid => Ok(Box::new(HybridModel::fit(
            MethodKind::Elastic,
            ctx,
            train,
            val,
        )?)),
        MethodKind::HybridKinematic => Ok(Box::new(HybridModel::fit(
            MethodKind::Kinematic,
            ctx,
            train,
            val,
        )?)),
    }
}
