//! The `d-optimal` layout: the campaign plans and measures a pool, and this chooses from it the
//! configurations that determine the design model's parameters best ([`d_optimal`]).

use nalgebra::{DMatrix, Point3};

use super::model::DesignModel;
use super::select::{SelectOptions, d_optimal};
use crate::calib::method::FitContext;
use crate::calib::registry::MethodKind;
use crate::campaign::config::SelectionConfig;
use crate::campaign::{LayoutKind, Selector};
use crate::error::{Error, Result};

/// D-optimal choice of a campaign's points for one design model.
pub struct DOptimal<'a> {
    pub model: DesignModel<'a>,
    pub options: SelectOptions,
}

impl<'a> DOptimal<'a> {
    /// The selector of `selection` when any of `layouts` chooses its points for a model, else `None`.
    pub fn when_needed(
        layouts: impl IntoIterator<Item = LayoutKind>,
        selection: &SelectionConfig,
        ctx: &FitContext<'a>,
        reflectors: &[Point3<f64>],
    ) -> Result<Option<DOptimal<'a>>> {
        if layouts.into_iter().any(|d| d.selects()) {
            DOptimal::for_selection(selection, ctx, reflectors).map(Some)
        } else {
            Ok(None)
        }
    }

    /// The selector a campaign's `selection` asks for: the design model of `selection.model`, with the
    /// nominal reflector positions `reflectors` (flange frame).
    pub fn for_selection(
        selection: &SelectionConfig,
        ctx: &FitContext<'a>,
        reflectors: &[Point3<f64>],
    ) -> Result<DOptimal<'a>> {
        let model =
            DesignModel::for_method(selection.model, ctx, reflectors)?.ok_or_else(|| {
                Error::Invalid(format!(
                    "campaign.selection.model = '{}' has no parameters to design for",
                    selection.model
                ))
            })?;
        Ok(DOptimal {
            model,
            options: SelectOptions {
                max_exchanges: selection.max_exchanges,
                ..SelectOptions::default()
            },
        })
    }
}

impl Selector for DOptimal<'_> {
    fn choose(&self, pool: &[&[f64]], want: usize) -> Result<Vec<usize>> {
        let rows: Vec<DMatrix<f64>> = pool.iter().map(|q| self.model.jacobian(&[q])).collect();
        Ok(d_optimal(&rows, want, &self.options)?.chosen)
    }
}

/// A space-filling choice in the joint angles: greedy maximin (each next point the candidate farthest from those
/// chosen), each joint scaled by the pool's own range. The layout for methods that fit functions of the
/// configuration (the paper's regressions, `residual-ridge`): they need their inputs covered evenly, not the
/// extremes that determine constant parameters.
pub struct SpaceFilling;

impl Selector for SpaceFilling {
    fn choose(&self, pool: &[&[f64]], want: usize) -> Result<Vec<usize>> {
        let Some(first) = pool.first() else {
            return Err(Error::Invalid(
                "space-filling: the candidate pool is empty".into(),
            ));
        };
        if want == 0 || want > pool.len() {
            return Err(Error::Invalid(format!(
                "space-filling: cannot choose {want} of {} candidates",
                pool.len()
            )));
        }
        let dof = first.len();
        let (mut lo, mut hi) = (vec![f64::INFINITY; dof], vec![f64::NEG_INFINITY; dof]);
        for q in pool {
            for (j, &v) in q.iter().enumerate().take(dof) {
                lo[j] = lo[j].min(v);
                hi[j] = hi[j].max(v);
            }
        }
        let scaled: Vec<Vec<f64>> = pool
            .iter()
            .map(|q| {
                (0..dof)
                    .map(|j| {
                        let span = hi[j] - lo[j];
                        if span > 0.0 {
                            (q[j] - lo[j]) / span
                        } else {
                            0.0
                        }
                    })
                    .collect()
            })
            .collect();
        let d2 =
            |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f64>();
        // Start at the candidate nearest the pool's centre; ties go to the lower index, so the choice is
        // deterministic.
        let centre: Vec<f64> = (0..dof)
            .map(|j| scaled.iter().map(|q| q[j]).sum::<f64>() / scaled.len() as f64)
            .collect();
        let start = (0..scaled.len())
            .min_by(|&a, &b| d2(&scaled[a], &centre).total_cmp(&d2(&scaled[b], &centre)))
            .expect("the pool is not empty");
        let mut nearest: Vec<f64> = scaled.iter().map(|q| d2(q, &scaled[start])).collect();
        let mut chosen = vec![start];
        nearest[start] = f64::NEG_INFINITY;
        while chosen.len() < want {
            let next = (0..nearest.len())
                .max_by(|&a, &b| nearest[a].total_cmp(&nearest[b]).then(b.cmp(&a)))
                .expect("the pool is not empty");
            chosen.push(next);
            nearest[next] = f64::NEG_INFINITY;
            for (i, q) in scaled.iter().enumerate() {
                if nearest[i] > f64::NEG_INFINITY {
                    nearest[i] = nearest[i].min(d2(q, &scaled[next]));
                }
            }
        }
        chosen.sort_unstable();
        Ok(chosen)
    }
}

/// How a method's `d-optimal` points are chosen in a study: D-optimal on its own identification Jacobian for
/// the constant-parameter models (`kinematic`, `elastic` and the hybrids on them), space-filling in the joint
/// angles for the methods that regress on them (the paper's models, `residual-ridge`) and for `nominal`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PointDesign {
    /// D-optimal for the parameters of this method (a hybrid's base).
    Parameters(MethodKind),
    SpaceFilling,
}

impl PointDesign {
    pub fn of(kind: MethodKind) -> PointDesign {
        use crate::calib::method::RobotParameters as Model;
        let info = kind.info();
        match info.parameters {
            Model::Identification { .. } => {
                PointDesign::Parameters(info.base.and_then(MethodKind::of).unwrap_or(kind))
            }
            Model::ErrorModel(_) | Model::None => PointDesign::SpaceFilling,
        }
    }

    /// The selector of this design.
    pub fn selector<'a>(
        self,
        ctx: &FitContext<'a>,
        reflectors: &[Point3<f64>],
        selection: &SelectionConfig,
    ) -> Result<Box<dyn Selector + 'a>> {
        match self {
            PointDesign::SpaceFilling => Ok(Box::new(SpaceFilling)),
            PointDesign::Parameters(kind) => {
                let selection = SelectionConfig {
                    model: kind,
                    ..selection.clone()
                };
                Ok(Box::new(DOptimal::for_selection(
                    &selection, ctx, reflectors,
                )?))
            }
        }
    }

    /// In words, for the summary.
    pub fn describe(self) -> String {
        match self {
            PointDesign::Parameters(kind) => {
                format!("D-optimal for `{}`'s own parameters", kind.info().name)
            }
            PointDesign::SpaceFilling => "space-filling in the joint angles".into(),
        }
    }
}
