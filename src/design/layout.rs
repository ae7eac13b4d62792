//! The `d-optimal` layout: the campaign plans and measures a pool, and this chooses from it the
//! configurations that determine the design model's parameters best ([`d_optimal`]).

use std::cmp::Ordering;

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
        let columns = scaled_columns(pool, first.len());
        let n = pool.len();
        let centre: Vec<f64> = columns
            .chunks_exact(n)
            .map(|column| column.iter().sum::<f64>() / n as f64)
            .collect();
        // Start at the candidate nearest the pool's centre; ties go to the lower index, so the choice is
        // deterministic.
        let mut nearest = vec![0.0; n];
        squared_distances(&columns, |j| centre[j], &mut nearest);
        let start = first_extreme(&nearest, Ordering::Less);
        let all = columns.as_slice();
        let point = |c: usize| move |j: usize| all[j * n + c];
        squared_distances(&columns, point(start), &mut nearest);
        let mut chosen = vec![start];
        nearest[start] = f64::NEG_INFINITY;
        let mut distance = vec![0.0; n];
        while chosen.len() < want {
            let next = first_extreme(&nearest, Ordering::Greater);
            chosen.push(next);
            nearest[next] = f64::NEG_INFINITY;
            squared_distances(&columns, point(next), &mut distance);
            for (v, d) in nearest.iter_mut().zip(&distance) {
                if *v > f64::NEG_INFINITY {
                    *v = v.min(*d);
                }
            }
        }
        chosen.sort_unstable();
        Ok(chosen)
    }
}

/// The pool scaled joint by joint to its own range (a joint without range to 0), joint-major: joint j of
/// candidate c at `j * pool.len() + c`, so that a pick's distances run over the pool one joint at a time.
fn scaled_columns(pool: &[&[f64]], dof: usize) -> Vec<f64> {
    let (mut lo, mut hi) = (vec![f64::INFINITY; dof], vec![f64::NEG_INFINITY; dof]);
    for q in pool {
        for (j, &v) in q.iter().enumerate().take(dof) {
            lo[j] = lo[j].min(v);
            hi[j] = hi[j].max(v);
        }
    }
    let mut columns = vec![0.0; dof * pool.len()];
    for (j, column) in columns.chunks_exact_mut(pool.len()).enumerate() {
        let span = hi[j] - lo[j];
        for (v, q) in column.iter_mut().zip(pool) {
            *v = if span > 0.0 {
                (q[j] - lo[j]) / span
            } else {
                0.0
            };
        }
    }
    columns
}

/// Every candidate's squared distance to the point whose joint j is `point(j)`, into `out`. Each sum adds the
/// joints' squares in joint order, as a sum over one candidate's joints would (its start, ±0, vanishes
/// against a square), for the whole pool a joint at a time so that the pool's candidates go in step.
fn squared_distances(columns: &[f64], point: impl Fn(usize) -> f64, out: &mut [f64]) {
    for (j, column) in columns.chunks_exact(out.len()).enumerate() {
        let p = point(j);
        if j == 0 {
            for (o, x) in out.iter_mut().zip(column) {
                let t = x - p;
                *o = t * t;
            }
        } else {
            for (o, x) in out.iter_mut().zip(column) {
                let t = x - p;
                *o += t * t;
            }
        }
    }
}

/// The index of the first value that no later one passes in `direction` (total order): the least or
/// greatest value, ties to the lower index.
fn first_extreme(values: &[f64], direction: Ordering) -> usize {
    let mut best = 0;
    for (i, v) in values.iter().enumerate().skip(1) {
        if v.total_cmp(&values[best]) == direction {
            best = i;
        }
    }
    best
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

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// The greedy maximin as first written, one candidate's joints at a time: the reference the joint-major
    /// form must equal.
    fn maximin_by_rows(pool: &[&[f64]], want: usize) -> Vec<usize> {
        let dof = pool[0].len();
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
        let centre: Vec<f64> = (0..dof)
            .map(|j| scaled.iter().map(|q| q[j]).sum::<f64>() / scaled.len() as f64)
            .collect();
        let start = (0..scaled.len())
            .min_by(|&a, &b| d2(&scaled[a], &centre).total_cmp(&d2(&scaled[b], &centre)))
            .unwrap();
        let mut nearest: Vec<f64> = scaled.iter().map(|q| d2(q, &scaled[start])).collect();
        let mut chosen = vec![start];
        nearest[start] = f64::NEG_INFINITY;
        while chosen.len() < want {
            let next = (0..nearest.len())
                .max_by(|&a, &b| nearest[a].total_cmp(&nearest[b]).then(b.cmp(&a)))
                .unwrap();
            chosen.push(next);
            nearest[next] = f64::NEG_INFINITY;
            for (i, q) in scaled.iter().enumerate() {
                if nearest[i] > f64::NEG_INFINITY {
                    nearest[i] = nearest[i].min(d2(q, &scaled[next]));
                }
            }
        }
        chosen.sort_unstable();
        chosen
    }

    /// Random pools, some with coarse values (many equal distances, so the ties decide), repeated
    /// candidates and a joint without range: the same choice as the row-by-row reference at every size.
    #[test]
    fn space_filling_is_the_row_by_row_maximin() {
        let mut rng = ChaCha8Rng::seed_from_u64(27);
        for trial in 0..12 {
            let (count, dof) = (40 + 37 * trial, 1 + trial % 7);
            let coarse = trial % 3 == 0;
            let mut pool: Vec<Vec<f64>> = (0..count)
                .map(|_| {
                    (0..dof)
                        .map(|j| match (j, coarse) {
                            (1, _) if trial % 4 == 1 => 0.25,
                            (_, true) => f64::from(rng.random_range(0..4_i32)) * 0.5 - 1.0,
                            _ => rng.random_range(-2.9..2.9),
                        })
                        .collect()
                })
                .collect();
            let twins: Vec<Vec<f64>> = pool.iter().step_by(9).cloned().collect();
            pool.extend(twins);
            let refs: Vec<&[f64]> = pool.iter().map(|q| q.as_slice()).collect();
            for want in [1, 2, count / 3, count] {
                assert_eq!(
                    SpaceFilling.choose(&refs, want).unwrap(),
                    maximin_by_rows(&refs, want),
                    "trial {trial}, {want} of {}",
                    refs.len()
                );
            }
        }
    }
}
