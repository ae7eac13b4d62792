//! The twin's answer with what the pilot leaves undetermined: the twin's study run for several draws of the
//! twin — new phases of the gears' waves and new noise (a new seed), and each fitted magnitude drawn from its
//! standard deviation — and the recommendation per target gathered over the draws, so the number of points it
//! recommends comes with a range.

use rand_distr::{Distribution, Normal};
use serde::Serialize;

use super::magnitudes::TRACKER_NOISE;
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
/// zero). The tracker's noise keys share one draw: one fitted factor scales them together.
fn draw(values: &TwinValues, k: u64) -> TwinValues {
    let mut drawn = values.clone();
    drawn.seed = values.seed + DRAW_SEED_OFFSET + k;
    let mut rng = derive(drawn.seed, Stream::Perturbation, &[u64::MAX - 1]);
    let mut tracker = None;
    for m in &mut drawn.magnitudes {
        if let Some(std) = m.std.filter(|s| s.is_finite() && *s > 0.0) {
            let mut normal = || Normal::new(0.0, 1.0).map_or(0.0, |n| n.sample(&mut rng));
            let z: f64 = if TRACKER_NOISE.contains(&m.key.as_str()) {
                *tracker.get_or_insert_with(normal)
            } else {
                normal()
            };
            m.value = (m.value + std * z).max(0.0);
        }
    }
    drawn
}

#[cfg(test)]
mod tests {
    use nalgebra::{Isometry3, Point3, UnitQuaternion, Vector3};

    use super::*;
    use crate::app::twin::magnitudes::Magnitude;
    use crate::app::twin::scenario::Workspace;
    use crate::robot::Payload;
    use crate::truth::{KnownGeometry, Offset};

    /// The tracker's noise keys come from one fitted factor: a draw moves them together, by the same factor,
    /// and the other magnitudes by draws of their own.
    #[test]
    fn a_draw_moves_the_tracker_noise_keys_together() {
        let magnitude = |key: &str, value: f64, std: f64| Magnitude {
            key: key.into(),
            value,
            unit: "",
            std: Some(std),
            source: String::new(),
        };
        let values = TwinValues {
            name: "twin".into(),
            seed: 1,
            robot: "robots/ur10.urdf".into(),
            flange_link: None,
            payload: Payload {
                mass: 0.0,
                com: [0.0; 3],
            },
            geometry: KnownGeometry {
                base: Offset::ZERO,
                joint_frames: vec![Offset::ZERO; 6],
                joint_zero_rad: vec![0.0; 6],
            },
            stiffness: vec![1e5; 6],
            magnitudes: vec![
                magnitude("tracker.range_sigma_m", 8e-6, 2e-6),
                magnitude("truth.gear_wave_amplitude_rad", 1e-4, 5e-5),
                magnitude("tracker.range_sigma_per_m", 3e-6, 0.75e-6),
                magnitude("tracker.angle_sigma_rad", 5e-6, 1.25e-6),
            ],
            tracker: Isometry3::identity(),
            probe: Point3::origin(),
            facing: Vector3::z(),
            posture_deg: vec![0.0; 6],
            workspace: Workspace {
                center_m: [0.0; 3],
                size_m: [0.1; 3],
                tool: UnitQuaternion::identity(),
                cone_half_angle_deg: 10.0,
                spin_deg: 10.0,
            },
            targets_mm: vec![0.1],
            thermal: None,
        };
        let mut waves = Vec::new();
        for k in 0..8 {
            let d = draw(&values, k);
            let factor = d.magnitude("tracker.range_sigma_m") / 8e-6;
            for (key, v) in [
                ("tracker.range_sigma_per_m", 3e-6),
                ("tracker.angle_sigma_rad", 5e-6),
            ] {
                assert!(
                    (d.magnitude(key) / v - factor).abs() < 1e-12,
                    "{key}: draw {k}"
                );
            }
            waves.push(d.magnitude("truth.gear_wave_amplitude_rad") / 1e-4 - factor);
        }
        // The wave is drawn on its own: its factor is not the tracker's.
        assert!(waves.iter().any(|w| w.abs() > 1e-3), "{waves:?}");
    }
}
