//! The twin's answer with what the pilot leaves undetermined: the twin's study run for several draws of the
//! twin — new phases of the gears' waves and new noise (a new seed), and each fitted magnitude drawn from its
//! standard deviation — and the recommendation per target gathered over the draws, so the number of points it
//! recommends comes with a range.

use rand_distr::{Distribution, Normal};
use serde::Serialize;

use super::scenario::TwinValues;
use crate::calib::registry::MethodKind;
use crate::campaign::LayoutKind;
use crate::error::Result;
use crate::report::answer::{STATISTICS, answers};
use crate::rng::{Stream, derive};
use crate::study::sweep::RunOptions;

/// Seeds of the answer's draws start here, apart from the pilot statistics' draws.
const DRAW_SEED_OFFSET: u64 = 1000;

/// One target's answer over the draws of the twin.
#[derive(Clone, Debug, Serialize)]
pub struct RangeRow {
    pub target_mm: f64,
    /// The (method, layout) recommended in most draws, and in how many.
    pub method: Option<MethodKind>,
    pub layout: Option<LayoutKind>,
    pub chosen_in: usize,
    /// For that method and layout, the points it needs in each draw (`None`: not reached).
    pub points: Vec<Option<usize>>,
}

impl RangeRow {
    /// `median [min–max]` of the draws that reach the target, and how many do not.
    pub fn points_text(&self) -> String {
        let mut reached: Vec<usize> = self.points.iter().flatten().copied().collect();
        if reached.is_empty() {
            return "not reached".into();
        }
        reached.sort_unstable();
        let missing = self.points.len() - reached.len();
        let median = reached[reached.len() / 2];
        let mut text = format!("{median} [{}–{}]", reached[0], reached[reached.len() - 1]);
        if missing > 0 {
            text += &format!(", not reached in {missing} of {}", self.points.len());
        }
        text
    }
}

/// The twin's study over `draws` draws of the twin, on the ground-truth mean: per target, the recommendation.
pub fn answer_range(values: &TwinValues, draws: usize) -> Result<Vec<RangeRow>> {
    let mut per_draw = Vec::with_capacity(draws);
    for k in 0..draws as u64 {
        let drawn = draw(values, k);
        let scenario = drawn.scenario()?;
        let study = super::super::run_study(&scenario, RunOptions::QUIET)?;
        per_draw.push(answers(&study));
    }
    let Some(first) = per_draw.first() else {
        return Ok(Vec::new());
    };
    let mean = STATISTICS[0].0;
    Ok(first
        .iter()
        .enumerate()
        .filter(|(_, a)| a.statistic == mean)
        .map(|(i, a)| {
            let chosen: Vec<Option<(MethodKind, LayoutKind)>> = per_draw
                .iter()
                .map(|d| d[i].recommendation().map(|c| (c.method, c.layout)))
                .collect();
            let majority = chosen
                .iter()
                .flatten()
                .max_by_key(|pick| chosen.iter().filter(|c| c.as_ref() == Some(pick)).count())
                .copied();
            let points = per_draw
                .iter()
                .map(|d| {
                    let (m, l) = majority?;
                    d[i].cells
                        .iter()
                        .find(|c| c.method == m && c.layout == l)?
                        .n_train
                })
                .collect();
            RangeRow {
                target_mm: a.target_mm,
                method: majority.map(|p| p.0),
                layout: majority.map(|p| p.1),
                chosen_in: chosen
                    .iter()
                    .filter(|c| **c == majority && c.is_some())
                    .count(),
                points,
            }
        })
        .collect())
}

/// Draw `k` of the twin: its own seed, and each magnitude with a standard deviation drawn from it (never below
/// zero).
fn draw(values: &TwinValues, k: u64) -> TwinValues {
    let mut drawn = values.clone();
    drawn.seed = values.seed + DRAW_SEED_OFFSET + k;
    let mut rng = derive(drawn.seed, Stream::Perturbation, &[u64::MAX - 1]);
    for m in &mut drawn.magnitudes {
        if let Some(std) = m.std.filter(|s| s.is_finite() && *s > 0.0) {
            let z: f64 = Normal::new(0.0, 1.0).map_or(0.0, |n| n.sample(&mut rng));
            m.value = (m.value + std * z).max(0.0);
        }
    }
    drawn
}
