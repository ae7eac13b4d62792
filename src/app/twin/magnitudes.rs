//! The magnitudes of what no method models, fitted to what the pilot shows of them.
//!
//! A pilot of a few hundred points tells three things apart: the noise (the spread of configurations it
//! measured more than once: the arm's repeatability with the tracker's noise), what a method of constant
//! parameters cannot follow (the elastic fit's error on points it was not fitted on, once the identified
//! geometry and compliance are in the twin: the strain-wave gears' transmission error at the wave generator's
//! frequencies, a deterministic, rough function of the joint angles, is what reproduces it on real arms), and
//! the rest. Each fitted magnitude is the one for which the pilot replayed through the twin gives the real
//! pilot's statistic, averaged over [`SEEDS`] draws of the twin (the gears' phases, the noise); its standard
//! deviation is the statistic's spread over those draws carried through the fit. What the pilot cannot tell
//! stays at a cited typical value, and says so.

use nalgebra::Point3;
use serde::Serialize;

use super::pilot::{self, Repeats};
use crate::calib::method::FitContext;
use crate::calib::registry::PHYSICAL;
use crate::dataset::Dataset;
use crate::error::Result;
use crate::scenario::Scenario;

/// Draws of the twin each statistic is averaged over.
pub const SEEDS: u64 = 4;

/// Where a magnitude comes from.
#[derive(Clone, Debug, Serialize)]
pub struct Magnitude {
    /// The `[truth]` or `[tracker]` key.
    pub key: String,
    pub value: f64,
    pub unit: &'static str,
    /// One standard deviation, where the pilot determines the value.
    pub std: Option<f64>,
    /// What it was fitted to, or why it stays at its cited default (with the source).
    pub source: String,
}

/// The typical values a twin starts from, and keeps where the pilot cannot tell: each with its source (the
/// same as `scenarios/README.md` gives for the shipped scenarios).
pub struct Default {
    pub key: &'static str,
    pub value: f64,
    pub unit: &'static str,
    pub source: &'static str,
}

pub const GEAR_RATIO: u32 = 101;
pub const GEAR_RATIO_SOURCE: &str = "assumed: the common strain-wave ratio (Harmonic Drive CSG: 100, plus the \
     flexspline's one tooth); arms use 100–160";
/// Where the fit of the gears' wave starts (rad): a catalogue's ≤ 1 arcmin transmission accuracy.
const GEAR_WAVE_START_RAD: f64 = 1.5e-4;
/// Where the fit of the repeatability starts (rad).
const REPEATABILITY_START_RAD: f64 = 2e-5;

pub const DEFAULTS: &[Default] = &[
    Default {
        key: "truth.repeatability_rad",
        value: 1e-5,
        unit: "rad",
        source: "ISO 9283 repeatability of industrial arms, 0.02–0.1 mm at about 1 m (1e-5 rad the lower end)",
    },
    Default {
        key: "truth.hysteresis_rad",
        value: 2e-5,
        unit: "rad",
        source: "lost motion of robot joints 2e-5–2e-4 rad, catalogue ≤ 1 arcmin (Harmonic Drive CSG); the lower end",
    },
    Default {
        key: "truth.link_mass_spread",
        value: 0.1,
        unit: "relative",
        source: "identified link masses 5–15 % off CAD (Swevers et al. 2007), the middle",
    },
    Default {
        key: "truth.link_com_m",
        value: 0.01,
        unit: "m",
        source: "centres of mass 0.5–2 cm off CAD (Swevers et al. 2007), the middle",
    },
    Default {
        key: "truth.cable_kg_per_m",
        value: 0.3,
        unit: "kg/m",
        source: "a dress pack's 0.3–1.0 kg/m (igus triflex), the lower end",
    },
    Default {
        key: "truth.tilt_stiffness_nm_per_rad",
        value: 5e5,
        unit: "Nm/rad",
        source: "output-bearing moment stiffness 1e5–1e6 Nm/rad (Harmonic Drive CSG-2UH), the middle",
    },
    Default {
        key: "tracker.range_sigma_m",
        value: 8e-6,
        unit: "m",
        source: TRACKER_NOISE_SOURCE,
    },
    Default {
        key: "tracker.range_sigma_per_m",
        value: 3e-6,
        unit: "m/m",
        source: TRACKER_NOISE_SOURCE,
    },
    Default {
        key: "tracker.angle_sigma_rad",
        value: 5e-6,
        unit: "rad",
        source: TRACKER_NOISE_SOURCE,
    },
];

/// The tracker's random noise: scaled down together where a pilot's repeated configurations lie closer together
/// than the specification's noise alone puts them.
pub const TRACKER_NOISE: [&str; 3] = [
    "tracker.range_sigma_m",
    "tracker.range_sigma_per_m",
    "tracker.angle_sigma_rad",
];
const TRACKER_NOISE_SOURCE: &str = "Leica AT960 MPE ±(15 µm + 6 µm/m) for a 3-D point taken as 2σ: a \
     specification's bound, the upper end";

/// A joint's stiffness before the pilot, per newton metre of the effort limit its description declares
/// (Nm/rad per Nm). A joint is sized for its torque, and its gear's stiffness grows with its size; by how much
/// varies by kind of arm. The real UR10's joints, fitted on each IPA series that determines them (docs/twin.md),
/// are 200–340 times their URDF's effort limits at the shoulder, 600–1050 at the elbow, 120–570 at wrist 1; the
/// default scenario's iiwa, a torque sensor in series with each gear, 60–190. The middle of 60–1050 on a
/// logarithmic scale; the prior's standard deviation, as large as its compliance, leaves the pilot to say which.
pub const STIFFNESS_PER_EFFORT: f64 = 250.0;
/// The stiffness before the pilot of a joint whose description declares no effort limit: a strain-wave
/// gear's K3, 1.2e5–2.5e5 Nm/rad for Harmonic Drive CSG sizes 25–32, lowered for the wrists.
const STIFFNESS_WITHOUT_EFFORT_NM_PER_RAD: f64 = 1e5;

/// A joint's stiffness before the pilot (Nm/rad) and where it comes from: [`STIFFNESS_PER_EFFORT`] times its
/// declared effort limit (Nm), or the cited default where it declares none.
pub fn typical_stiffness(effort_nm: f64) -> (f64, String) {
    if effort_nm.is_finite() && effort_nm > 0.0 {
        (
            STIFFNESS_PER_EFFORT * effort_nm,
            format!(
                "{STIFFNESS_PER_EFFORT} × the joint's effort limit of {effort_nm} Nm (arms measured: 60–1050 ×)"
            ),
        )
    } else {
        (
            STIFFNESS_WITHOUT_EFFORT_NM_PER_RAD,
            "a strain-wave gear's K3 1.2e5–2.5e5 Nm/rad (CSG 25–32), lowered for the wrists; the description \
             declares no effort limit"
                .into(),
        )
    }
}

/// The tracker's magnitudes a twin assumes and a pilot cannot test: a laser tracker's specification.
pub const TRACKER_SOURCE: &str = "Leica AT960: systematic errors within its MPE (Muralikrishnan et al. 2009); \
     T-Mac orientation ±0.01°";

/// The pilot's statistics the fit matches: the elastic fit's held-out mean (mm) and the repeats.
#[derive(Clone, Debug)]
pub struct Targets {
    pub elastic_mm: f64,
    pub repeats: Option<Repeats>,
}

/// A twin's statistics over [`SEEDS`] draws: the elastic held-out means (mm) and the repeats' mean distances (m).
pub type Statistics = (Vec<f64>, Vec<f64>);

/// The twin `scenario`'s [`Statistics`], with its probe at `probe` (flange frame).
pub fn simulate(
    scenario: &Scenario,
    probe: &Point3<f64>,
    pilot: &Dataset,
    ctx: &FitContext,
    seed: u64,
) -> Result<Statistics> {
    let mut elastic = Vec::new();
    let mut repeats = Vec::new();
    for s in 0..SEEDS {
        let replayed = replay(scenario, pilot, s)?;
        let held = pilot::held_out(&replayed, ctx, &[PHYSICAL], seed);
        elastic.push(held[0].mean_mm.unwrap_or(f64::NAN));
        if let Some(r) = Repeats::of(&replayed, ctx.chain, probe) {
            repeats.push(r.mean_distance_m);
        }
    }
    Ok((elastic, repeats))
}

/// The pilot's configurations, in order, measured by draw `s` of the twin `scenario`.
pub fn replay(scenario: &Scenario, pilot: &Dataset, s: u64) -> Result<Dataset> {
    let mut drawn = scenario.clone();
    drawn.world.seed = scenario.world.seed + s;
    let r = super::super::replay::replay(&mut drawn, pilot, 0)?;
    super::super::replay::as_dataset(&r, pilot)
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len() as f64
}

fn std(v: &[f64]) -> f64 {
    let m = mean(v);
    (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (v.len() as f64 - 1.0).max(1.0)).sqrt()
}

/// One magnitude `x` fitted so that a statistic `f(x)` reaches `target`, where `f² ≈ a + b x²` (an error
/// source adds its variance): `f` at 0 and at `start` give `a` and `b`, the root is refined once at the answer.
/// Returns the value, its standard deviation (the statistic's spread over the draws, carried through), and
/// `None` in place of both when the target is below what everything else already gives.
pub fn fit_one(
    target: f64,
    start: f64,
    mut f: impl FnMut(f64) -> Result<Vec<f64>>,
) -> Result<Option<(f64, f64)>> {
    let at_zero = mean(&f(0.0)?);
    if target.partial_cmp(&at_zero) != Some(std::cmp::Ordering::Greater) {
        return Ok(None);
    }
    let mut x0 = start;
    let mut f0 = mean(&f(x0)?);
    let mut x = x0;
    let mut spread = 0.0;
    for _ in 0..2 {
        let b = (f0 * f0 - at_zero * at_zero) / (x0 * x0);
        if b.is_nan() || b <= 0.0 {
            return Ok(None);
        }
        x = ((target * target - at_zero * at_zero) / b).sqrt();
        let values = f(x)?;
        spread = std(&values);
        x0 = x;
        f0 = mean(&values);
    }
    // f² = a + b x²: df/dx = b x / f.
    let b = (f0 * f0 - at_zero * at_zero) / (x * x);
    let sigma = if b > 0.0 {
        spread * f0 / (b * x)
    } else {
        f64::NAN
    };
    Ok(Some((x, sigma)))
}

pub const GEAR_WAVE_START: f64 = GEAR_WAVE_START_RAD;
pub const REPEATABILITY_START: f64 = REPEATABILITY_START_RAD;
