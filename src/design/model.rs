//! The model a campaign is designed for: its parameters and, per configuration, the rows of the
//! identification Jacobian that a measurement there adds.
//!
//! - `kinematic` and `elastic` (and the hybrids, through their parametric part): the structurally
//!   identifiable set a fit keeps — tracker frame, mounting, DH frame errors and, for `elastic`, compliances
//!   ([`Identification`]).
//! - The paper's models: the error parameters E of their error model ([`select_params`]) at the measured
//!   point. The paper fits each E_i as a function of the configuration; a constant E is the degree-0 part of
//!   that function, so a campaign that cannot determine the constant cannot determine the function either.
//!   The tracker frame is registered beforehand and is not part of the paper's parameters.
//! - `nominal` and `residual-ridge` identify no parameters of the robot: they have no design model.
//!
//! **Scaling.** Indices such as O3 depend on the units of the columns (metres per radian, per metre, per
//! rad/Nm). Each column is divided by its RMS per row over a fixed set of configurations drawn uniformly
//! within the joint limits (fixed seed), so a column has unit RMS on a "typical" configuration and the
//! indices of two campaigns of the same model compare. The D-criterion's ranking of campaigns does not
//! depend on the scaling at all.

use nalgebra::{DMatrix, Point3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::calib::error_model::{ErrorModelKind, ErrorParam, error_jacobian, select_params};
use crate::calib::kinematic::Identification;
use crate::calib::method::{FitContext, RobotParameters};
use crate::calib::registry::MethodKind;
use crate::calib::rigid::centre;
use crate::error::{Error, Result};
use crate::robot::chain::sample_within;
use crate::robot::dh::DhChain;

/// Configurations of the column scaling.
const SCALE_SAMPLES: usize = 200;
/// Fixed, so the scaling is a property of the robot and the model alone.
const SCALE_SEED: u64 = 0x0b5e_7ab1;

enum JacobianSource<'a> {
    Kinematic(Box<Identification<'a>>),
    Paper {
        dh: &'a DhChain,
        params: Vec<ErrorParam>,
        point: Point3<f64>,
    },
}

/// A model's identification Jacobian per configuration, columns scaled (see the module notes).
pub struct DesignModel<'a> {
    /// The method whose parameters these are (`kinematic` for `hybrid-kinematic`, `elastic` for `hybrid`).
    pub method: MethodKind,
    names: Vec<String>,
    scale: Vec<f64>,
    basis: JacobianSource<'a>,
}

impl<'a> DesignModel<'a> {
    /// The design model of `method`; `None` for methods without robot parameters (`nominal`,
    /// `residual-ridge`). `reflectors`: the nominal reflector positions in the flange frame (one reflector
    /// measures a point, three or more a nest whose orientation the kinematic models fit too).
    pub fn for_method(
        method: MethodKind,
        ctx: &FitContext<'a>,
        reflectors: &[Point3<f64>],
    ) -> Result<Option<DesignModel<'a>>> {
        if reflectors.is_empty() {
            return Err(Error::Invalid(
                "experiment design: no reflector on the flange".into(),
            ));
        }
        let mount = centre(reflectors);
        // A nest's rotation residuals are weighted by its RMS radius, as the kinematic fit does.
        let length = (reflectors.len() >= 3).then(|| {
            (reflectors
                .iter()
                .map(|p| (p - mount).norm_squared())
                .sum::<f64>()
                / reflectors.len() as f64)
                .sqrt()
        });
        let paper = |kind: ErrorModelKind| {
            let (lower, upper) = ctx.limits();
            let all = select_params(ctx.dh, &lower, &upper, kind).position;
            let reference = reference_configurations(ctx);
            let j = error_rows(ctx.dh, &as_slices(&reference), &mount, &all);
            JacobianSource::Paper {
                dh: ctx.dh,
                params: independent_columns(&j)
                    .into_iter()
                    .map(|c| all[c])
                    .collect(),
                point: mount,
            }
        };
        let info = method.info();
        let basis = match info.parameters {
            RobotParameters::None => return Ok(None),
            RobotParameters::ErrorModel(kind) => paper(kind),
            RobotParameters::Identification { elastic } => JacobianSource::Kinematic(Box::new(
                Identification::new(elastic, ctx, mount, length)?,
            )),
        };
        // A hybrid's parameters are its base's.
        let method = match info.base {
            Some(base) => MethodKind::of(base).ok_or_else(|| {
                Error::Invalid(format!("{method}: its base {base} is not a listed method"))
            })?,
            None => method,
        };
        let names = match &basis {
            JacobianSource::Kinematic(id) => id.params().iter().map(|p| p.name()).collect(),
            JacobianSource::Paper { params, .. } => params.iter().map(|p| p.name()).collect(),
        };
        let mut model = DesignModel {
            method,
            names,
            scale: Vec::new(),
            basis,
        };
        model.scale = model.column_scale(ctx);
        Ok(Some(model))
    }

    /// Parameter names, in column order.
    pub fn params(&self) -> &[String] {
        &self.names
    }

    /// Rows a configuration adds: 3 for a point, 6 with a nest's orientation.
    pub fn rows_per_point(&self) -> usize {
        match &self.basis {
            JacobianSource::Kinematic(id) => id.rows_per_point(),
            JacobianSource::Paper { .. } => 3,
        }
    }

    /// The scaled Jacobian over the configurations `qs`, stacked in their order.
    pub fn jacobian(&self, qs: &[&[f64]]) -> DMatrix<f64> {
        let mut j = self.raw(qs);
        for (mut col, s) in j.column_iter_mut().zip(&self.scale) {
            col *= *s;
        }
        j
    }

    fn raw(&self, qs: &[&[f64]]) -> DMatrix<f64> {
        match &self.basis {
            JacobianSource::Kinematic(id) => id.jacobian(qs),
            JacobianSource::Paper { dh, params, point } => error_rows(dh, qs, point, params),
        }
    }

    /// 1 / (RMS per row) of each column over the fixed reference configurations; 1 for a column that
    /// vanishes there.
    fn column_scale(&self, ctx: &FitContext) -> Vec<f64> {
        let reference = reference_configurations(ctx);
        let j = self.raw(&as_slices(&reference));
        let rows = j.nrows().max(1) as f64;
        j.column_iter()
            .map(|c| {
                let rms = c.norm() / rows.sqrt();
                if rms > 0.0 && rms.is_finite() {
                    1.0 / rms
                } else {
                    1.0
                }
            })
            .collect()
    }
}

/// The fixed configurations of the scaling and of the paper models' independent set: uniform within the
/// joint limits, fixed seed.
fn reference_configurations(ctx: &FitContext) -> Vec<Vec<f64>> {
    let (lower, upper) = ctx.limits();
    let mut rng = ChaCha8Rng::seed_from_u64(SCALE_SEED);
    (0..SCALE_SAMPLES)
        .map(|_| {
            lower
                .iter()
                .zip(&upper)
                .map(|(&lo, &hi)| sample_within(lo, hi, &mut rng))
                .collect()
        })
        .collect()
}

fn as_slices(qs: &[Vec<f64>]) -> Vec<&[f64]> {
    qs.iter().map(Vec::as_slice).collect()
}

/// Position rows of the paper's error Jacobian at `point`, stacked over `qs`.
fn error_rows(
    dh: &DhChain,
    qs: &[&[f64]],
    point: &Point3<f64>,
    params: &[ErrorParam],
) -> DMatrix<f64> {
    let mut j = DMatrix::zeros(3 * qs.len(), params.len());
    for (i, q) in qs.iter().enumerate() {
        let rows = error_jacobian(dh, q, point, params);
        j.view_mut((3 * i, 0), (3, params.len()))
            .copy_from(&rows.fixed_rows::<3>(0));
    }
    j
}

/// Part of a unit column orthogonal to the columns kept before it below which it is redundant (as the
/// kinematic fit's structural set decides).
const REDUNDANT_REL: f64 = 1e-7;

/// The columns of `j` kept in order when each must add a direction the kept ones lack: the paper's error
/// parameters overlap as constants (a rotation about parallel axes of two frames moves the point alike), and
/// the paper resolves that per point by the minimum-norm solution; a constant-error design can determine only
/// the independent ones.
fn independent_columns(j: &DMatrix<f64>) -> Vec<usize> {
    let mut kept: Vec<usize> = Vec::new();
    for c in 0..j.ncols() {
        let norm = j.column(c).norm();
        if norm == 0.0 {
            continue;
        }
        let mut m = DMatrix::zeros(j.nrows(), kept.len() + 1);
        for (i, &k) in kept.iter().chain(std::iter::once(&c)).enumerate() {
            let col = j.column(k);
            m.set_column(i, &(col / col.norm()));
        }
        let r = m.qr().r();
        if r[(kept.len(), kept.len())].abs() >= REDUNDANT_REL {
            kept.push(c);
        }
    }
    kept
}
