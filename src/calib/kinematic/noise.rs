//! The noise of the measurement, against which [`determined`](super::identify::determined) judges whether
//! the training data determine a parameter: a parameter is determined when its standard deviation at this
//! noise is below the size a real arm's parameter reaches.
//!
//! Three estimates, in the order the fit uses them:
//! - **the nominal model's residual** after a rigid registration: where the fit starts. An upper bound of what
//!   the fit leaves (most of it is the very error the fit removes), so what it keeps is determined whatever
//!   the fit explains, and a parameter of a reflector a few micrometres from an axis is not let in before
//!   anything is fitted;
//! - **the fitted model's own residual**, `√(Σr² / (m − k))` over the m residual rows and k kept parameters:
//!   what the set is judged at again after each fit, until judging at its own residual keeps the set it was
//!   fitted with;
//! - **a floor** neither may go below: the scatter of the configurations measured more than once, where the
//!   training and validation data have enough of them ([`MIN_REPEAT_DOF`]), else the tracker's
//!   specification ([`SPEC_NOISE_M`]). The residual of a fit with few degrees of freedom left can fall below
//!   the noise; judged there, parameters of little effect would pass.

use nalgebra::{DVector, Point3};
use serde::{Deserialize, Serialize};

use crate::calib::rigid::centre;
use crate::calib::tracker_frame::{Registration, fit_tracker_frame};
use crate::dataset::{Dataset, repeat_groups};
use crate::error::Result;
use crate::robot::dh::DhChain;

/// The smallest measurement noise (m, per coordinate) the determination assumes, whatever the estimate: a
/// tracker's resolution, so that exactly repeated noise-free points do not make
/// parameters of sub-micrometre effect "determined".
pub const MIN_NOISE_M: f64 = 2e-6;

/// A laser tracker's noise per coordinate (m) when nothing better is known: the RMS over the three axes of
/// the typical errors, which Leica states are half of the maximum permissible errors (Leica Absolute Tracker
/// AT500/AT960 user manual, §2.8.1–2.8.2: transverse e_T = ±15 µm + 6 µm/m on each of the two axes across
/// the beam, range e_ADM = ±10 µm + 0.3 µm/m), at 3 m, where the shipped scenarios place the tracker:
/// `√((2 · 16.5² + 5.45²) / 3)` µm.
pub const SPEC_NOISE_M: f64 = 13.8e-6;

/// Degrees of freedom (3 per measurement beyond the first of its configuration) the repeated configurations
/// must give before their scatter stands for the noise: below ten repeated measurements the estimate is off
/// by more than 13 % (one standard deviation of a χ² with 30 degrees of freedom).
pub const MIN_REPEAT_DOF: usize = 30;

/// Where a noise estimate comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum NoiseSource {
    NominalResidual,
    FittedResidual,
    RepeatedConfigurations,
    TrackerSpecification,
}

/// A noise estimate: σ per coordinate (m) and where it comes from.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Noise {
    pub sigma_m: f64,
    pub source: NoiseSource,
}

impl Noise {
    /// The larger of `self` and `floor` (and never below [`MIN_NOISE_M`]).
    pub fn at_least(self, floor: Noise) -> Noise {
        let n = if self.sigma_m.is_nan() || self.sigma_m < floor.sigma_m {
            floor
        } else {
            self
        };
        Noise {
            sigma_m: n.sigma_m.max(MIN_NOISE_M),
            ..n
        }
    }

    /// Where it comes from, in words.
    pub fn source_text(&self) -> &'static str {
        match self.source {
            NoiseSource::NominalResidual => "the nominal model's residual",
            NoiseSource::FittedResidual => "the fitted model's residual",
            NoiseSource::RepeatedConfigurations => "the scatter of repeated configurations",
            NoiseSource::TrackerSpecification => "the tracker's specification",
        }
    }
}

/// The floor: the scatter of the configurations measured more than once in `train` and `val` (joint angles
/// equal to 1 mrad), pooled, where they give at least [`MIN_REPEAT_DOF`] degrees of freedom; else
/// [`SPEC_NOISE_M`].
pub(super) fn floor(train: &Dataset, val: &Dataset) -> Noise {
    let q: Vec<&[f64]> = train.q.iter().chain(&val.q).map(Vec::as_slice).collect();
    let points: Vec<Point3<f64>> = train
        .measured
        .iter()
        .chain(&val.measured)
        .map(|m| centre(m))
        .collect();
    let (mut sum, mut dof) = (0.0, 0);
    for group in repeat_groups(&q) {
        let members: Vec<Point3<f64>> = group.iter().map(|&i| points[i]).collect();
        let mean = centre(&members);
        sum += members
            .iter()
            .map(|p| (p - mean).norm_squared())
            .sum::<f64>();
        dof += 3 * (members.len() - 1);
    }
    if dof >= MIN_REPEAT_DOF && sum.is_finite() {
        Noise {
            sigma_m: (sum / dof as f64).sqrt().max(MIN_NOISE_M),
            source: NoiseSource::RepeatedConfigurations,
        }
    } else {
        Noise {
            sigma_m: SPEC_NOISE_M,
            source: NoiseSource::TrackerSpecification,
        }
    }
}

/// The nominal model's residual per coordinate after a rigid registration (at least `floor`). Data in the
/// base frame are registered by the identity, whose residual also holds the base's own placement error —
/// which the fit identifies; judged at that residual, parameters were dropped that a tracker-frame fit
/// keeps, so those are judged at a rigid registration's residual too.
pub(super) fn nominal(
    dh: &DhChain,
    registration: &Registration,
    train: &Dataset,
    val: &Dataset,
    floor: Noise,
) -> Result<Noise> {
    let nominal_rms = if registration.base_frame {
        let measured: Vec<_> = train
            .measured
            .iter()
            .chain(&val.measured)
            .map(|m| centre(m))
            .collect();
        let flanges: Vec<_> = train
            .q
            .iter()
            .chain(&val.q)
            .map(|q| dh.flange_pose(q))
            .collect();
        fit_tracker_frame(&measured, &flanges, &registration.frame.mounting)?.rms
    } else {
        registration.frame.rms
    };
    Ok(Noise {
        sigma_m: nominal_rms / 3f64.sqrt(),
        source: NoiseSource::NominalResidual,
    }
    .at_least(floor))
}

/// The fitted model's residual per row, `√(Σr² / (m − k))` for `k` fitted parameters (at least `floor`;
/// the floor alone when no degree of freedom is left).
pub(super) fn fitted(residual: &DVector<f64>, k: usize, floor: Noise) -> Noise {
    let m = residual.len();
    let sigma = if m > k {
        (residual.norm_squared() / (m - k) as f64).sqrt()
    } else {
        f64::NAN
    };
    Noise {
        sigma_m: sigma,
        source: NoiseSource::FittedResidual,
    }
    .at_least(floor)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The specification's constant is the arithmetic its note states: half the MPE at 3 m, RMS over the
    /// two transverse axes and the range.
    #[test]
    fn the_specification_constant_is_half_the_mpe_at_three_metres() {
        let d: f64 = 3.0;
        let transverse = 0.5 * (15e-6 + 6e-6 * d);
        let range = 0.5 * (10e-6 + 0.3e-6 * d);
        let sigma = ((2.0 * transverse * transverse + range * range) / 3.0).sqrt();
        assert!((sigma - SPEC_NOISE_M).abs() < 0.05e-6, "{sigma}");
    }

    /// Repeated configurations give their pooled scatter: pairs of points ±d apart along x have a
    /// per-coordinate σ of √(2d²/3) over 3 degrees of freedom each; with fewer than ten repeated
    /// measurements the specification stands.
    #[test]
    fn the_floor_is_the_scatter_of_repeated_configurations_when_there_are_enough() {
        let d = 20e-6;
        let data = |pairs: usize| {
            let mut q = Vec::new();
            let mut measured = Vec::new();
            for i in 0..pairs {
                for s in [-1.0, 1.0] {
                    q.push(vec![0.1 * i as f64, 0.2]);
                    measured.push(vec![Point3::new(1.0 + s * d, i as f64, 0.0)]);
                }
            }
            // One configuration measured once: no part of the scatter.
            q.push(vec![5.0, 5.0]);
            measured.push(vec![Point3::new(9.0, 9.0, 9.0)]);
            Dataset::in_memory("r", vec!["a".into(), "b".into()], q, measured)
        };
        let empty = Dataset::in_memory("v", vec!["a".into(), "b".into()], vec![], vec![]);
        let n = floor(&data(10), &empty);
        assert_eq!(n.source, NoiseSource::RepeatedConfigurations);
        assert!(
            (n.sigma_m - (2.0 * d * d / 3.0).sqrt()).abs() < 1e-12,
            "{n:?}"
        );
        let few = floor(&data(9), &empty);
        assert_eq!(few.source, NoiseSource::TrackerSpecification);
        assert_eq!(few.sigma_m, SPEC_NOISE_M);
    }
}
