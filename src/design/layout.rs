//! The `d-optimal` layout: the campaign plans and measures a pool, and this chooses from it the
//! configurations that determine the design model's parameters best ([`d_optimal`]).

use nalgebra::{DMatrix, Point3};

use super::model::DesignModel;
use super::select::{SelectOptions, d_optimal};
use crate::calib::method::FitContext;
use crate::calib::registry::MethodKind;
use crate::campaign::region::SelectionConfig;
use crate::campaign::{DistributionKind, Selector};
use crate::error::{Error, Result};

/// D-optimal choice of a campaign's points for one design model.
pub struct DOptimal<'a> {
    pub model: DesignModel<'a>,
    pub options: SelectOptions,
}

impl<'a> DOptimal<'a> {
    /// The selector of `selection` when any of `layouts` chooses its points for a model, else `None`.
    pub fn when_needed(
        layouts: impl IntoIterator<Item = DistributionKind>,
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
        let model = DesignModel::for_method(MethodKind::parse(&selection.model)?, ctx, reflectors)?
            .ok_or_else(|| {
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
