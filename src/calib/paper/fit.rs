//! Fitting the paper's method (steps 1–3 of [`super`]): the registration, eq. 13 at every training and
//! validation point, one ridge model per error parameter.

use nalgebra::{DMatrix, Isometry3};

use super::eq13::min_norm;
use super::{PaperModel, ParameterModel, info_of};
use crate::calib::error_model::{ErrorModelKind, ErrorParam, error_jacobian_on, select_params};
use crate::calib::method::{Basis, FitContext};
use crate::calib::regression::{RegressionOptions, SharedCandidates};
use crate::calib::tracker_frame::{Observation, Registration};
use crate::dataset::Dataset;
use crate::error::{Error, Result};
use crate::robot::dh::DhChain;

/// The nominal chain's frames at every training, then validation point, and the flange poses among them: one
/// pass over the chain per point gives the registration its flange poses, eq. 13 its Jacobians' frames and the
/// regression its nominal TCP positions, for every error model fitted on the same sets.
struct ChainFrames {
    frames: Vec<Vec<Isometry3<f64>>>,
    flanges: Vec<Isometry3<f64>>,
}

impl ChainFrames {
    fn of(dh: &DhChain, train: &Dataset, val: &Dataset) -> ChainFrames {
        let fixed = dh.fixed_rotations();
        let frames: Vec<Vec<Isometry3<f64>>> = train
            .q
            .iter()
            .chain(&val.q)
            .map(|q| dh.frames_fixed(q, &fixed))
            .collect();
        let flanges = frames.iter().map(|f| f[dh.dof()] * dh.tool).collect();
        ChainFrames { frames, flanges }
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
    /// `model`: the registered model ([`PaperModel::registered`]) of `train` and `val`; `flanges`: the nominal
    /// flange poses of the training, then the validation points.
    fn of(
        model: &PaperModel,
        flanges: &[Isometry3<f64>],
        train: &Dataset,
        val: &Dataset,
    ) -> Result<Prepared> {
        let registration = &model.basis.registration;
        let (obs_train, obs_val) = (registration.observe(train)?, registration.observe(val)?);
        let (flanges_train, flanges_val) = flanges.split_at(train.len());
        let candidates = SharedCandidates::new(
            model.candidate_matrix(&obs_train, flanges_train),
            model.candidate_matrix(&obs_val, flanges_val),
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
        let Some(kind) = kind else {
            return PaperModel::registered(None, ctx, train, val, None);
        };
        let frames = ctx.shared_without_inputs("paper frames", train, val, || {
            ChainFrames::of(ctx.dh, train, val)
        });
        let mut model = PaperModel::registered(Some(kind), ctx, train, val, Some(&frames.flanges))?;
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
        let shared = ctx.shared("paper", train, val, || {
            Prepared::of(&model, &frames.flanges, train, val)
        });
        let own;
        let prepared = match &*shared {
            Ok(p) => p,
            Err(_) => {
                own = Prepared::of(&model, &frames.flanges, train, val)?;
                &own
            }
        };
        let (frames_train, frames_val) = frames.frames.split_at(train.len());
        let id_train = model.identify_at(
            &prepared.obs_train,
            frames_train,
            &selection.position,
            &orientation_params,
        );
        let id_val = model.identify_at(
            &prepared.obs_val,
            frames_val,
            &selection.position,
            &orientation_params,
        );
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
        // Shared features of the models just set, not of any prediction made without them.
        model.features = Default::default();
        Ok(model)
    }

    /// The `nominal` model: the registered tracker frame and mounting, the candidates of the regressions and
    /// the extra inputs' defaults, with no parameter model yet. `flanges`: the nominal flange poses of the
    /// training, then the validation points, where the caller has them.
    fn registered(
        kind: Option<ErrorModelKind>,
        ctx: &FitContext,
        train: &Dataset,
        val: &Dataset,
        flanges: Option<&[Isometry3<f64>]>,
    ) -> Result<PaperModel> {
        if train.is_empty() || val.is_empty() {
            return Err(Error::Invalid(format!(
                "{} training and {} validation points: both sets must be non-empty",
                train.len(),
                val.len()
            )));
        }
        let dh = ctx.dh;
        let registration = ctx.registration_by(train, val, || match flanges {
            Some(flanges) => Registration::fit_at(dh, train, val, flanges),
            None => Registration::fit(dh, train, val),
        })?;
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
            features: Default::default(),
        })
    }

    /// Eq. 13 per point: minimum-norm error parameters explaining each observation's deviation.
    pub fn identify(
        &self,
        observations: &[Observation],
        position_params: &[ErrorParam],
        orientation_params: &[ErrorParam],
    ) -> Identified {
        let dh = &self.basis.dh;
        let fixed = dh.fixed_rotations();
        let frames: Vec<Vec<Isometry3<f64>>> = observations
            .iter()
            .map(|o| dh.frames_fixed(&o.q, &fixed))
            .collect();
        self.identify_at(observations, &frames, position_params, orientation_params)
    }

    /// [`PaperModel::identify`] with each observation's frames of the nominal chain ([`DhChain::frames`]) given.
    fn identify_at(
        &self,
        observations: &[Observation],
        frames: &[Vec<Isometry3<f64>>],
        position_params: &[ErrorParam],
        orientation_params: &[ErrorParam],
    ) -> Identified {
        let mut id = Identified {
            position: Vec::with_capacity(observations.len()),
            orientation: Vec::with_capacity(observations.len()),
        };
        let dh = &self.basis.dh;
        for (o, frames) in observations.iter().zip(frames) {
            let flange = frames[dh.dof()] * dh.tool;
            if !position_params.is_empty() {
                let j = error_jacobian_on(
                    dh,
                    frames,
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
                    frames,
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

    /// Regression inputs of each observation at its nominal flange pose: joint angles, the nominal TCP
    /// position, the extra inputs.
    fn candidate_matrix(
        &self,
        observations: &[Observation],
        flanges: &[Isometry3<f64>],
    ) -> DMatrix<f64> {
        let rows: Vec<Vec<f64>> = observations
            .iter()
            .zip(flanges)
            .map(|(o, flange)| self.candidates_at(&o.q, &o.inputs, flange))
            .collect();
        DMatrix::from_fn(rows.len(), self.candidates.len(), |r, c| rows[r][c])
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
