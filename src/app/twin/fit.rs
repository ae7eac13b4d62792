//! The magnitudes of what no method models, fitted to the pilot's statistics through the twin: each fit
//! replays the pilot through the twin at trial values ([`magnitudes::simulate`]) until the twin's statistic
//! meets the pilot's.

use super::magnitudes::{self, SEEDS, TRACKER_NOISE, Targets};
use super::pilot::Repeats;
use super::scenario::TwinValues;
use crate::calib::method::FitContext;
use crate::dataset::Dataset;
use crate::error::Result;

/// What every fit replays the pilot with: its configurations, the fits' context and the seed.
#[derive(Clone, Copy)]
struct Replays<'a> {
    pilot: &'a Dataset,
    ctx: &'a FitContext<'a>,
    seed: u64,
}

impl Replays<'_> {
    /// The twin `values`' [`magnitudes::Statistics`] on the pilot's configurations.
    fn statistics(&self, values: &TwinValues) -> Result<magnitudes::Statistics> {
        magnitudes::simulate(
            &values.scenario()?,
            &values.probe,
            self.pilot,
            self.ctx,
            self.seed,
        )
    }
}

/// Fits the repeatability to the pilot's repeats (when it has some) and the gears' wave to the elastic fit's
/// held-out error; when even without the wave the twin errs more than the pilot, scales the cited inertial and
/// tilt magnitudes down instead.
pub fn magnitudes(
    values: &mut TwinValues,
    pilot: &Dataset,
    ctx: &FitContext,
    targets: &Targets,
    seed: u64,
) -> Result<()> {
    let replays = Replays { pilot, ctx, seed };
    if let Some(repeats) = targets.repeats {
        fit_repeatability(values, replays, repeats)?;
    }
    let key = "truth.gear_wave_amplitude_rad";
    let fitted = magnitudes::fit_one(targets.elastic_mm, magnitudes::GEAR_WAVE_START, |x| {
        let mut v = values.clone();
        v.set(key, x);
        Ok(replays.statistics(&v)?.0)
    })?;
    match fitted {
        Some((x, std)) => {
            values.set(key, x);
            set_source(
                values,
                key,
                Some(std),
                format!(
                    "fitted: the elastic fit's error on the pilot's held-out points, {:.4} mm, reproduced on the \
                     pilot replayed through the twin (mean of {SEEDS} draws)",
                    targets.elastic_mm
                ),
            );
        }
        None => {
            set_source(
                values,
                key,
                None,
                format!(
                    "0: without it the twin already errs at least the pilot's {:.4} mm held out (elastic)",
                    targets.elastic_mm
                ),
            );
            scale_smooth_sources(values, replays, targets)?;
        }
    }
    Ok(())
}

fn set_source(values: &mut TwinValues, key: &str, std: Option<f64>, source: String) {
    if let Some(m) = values.magnitudes.iter_mut().find(|m| m.key == key) {
        m.std = std;
        m.source = source;
    }
}

/// The repeatability that gives the pilot's spread of repeated configurations.
fn fit_repeatability(values: &mut TwinValues, replays: Replays, repeats: Repeats) -> Result<()> {
    let key = "truth.repeatability_rad";
    let fitted = magnitudes::fit_one(
        repeats.mean_distance_m,
        magnitudes::REPEATABILITY_START,
        |x| {
            let mut v = values.clone();
            v.set(key, x);
            Ok(replays.statistics(&v)?.1)
        },
    )?;
    let (value, std, source) = match fitted {
        Some((x, s)) => (
            x,
            Some(s),
            format!(
                "fitted: the pilot's {} repeated configurations lie {:.4} mm from their groups' means",
                repeats.groups,
                repeats.mean_distance_m * 1e3
            ),
        ),
        None => (
            0.0,
            None,
            format!(
                "0: the tracker's noise alone spreads repeated configurations more than the pilot's {:.4} mm",
                repeats.mean_distance_m * 1e3
            ),
        ),
    };
    values.set(key, value);
    set_source(values, key, std, source);
    if fitted.is_none() {
        fit_tracker_noise(values, replays, repeats)?;
    }
    Ok(())
}

/// Where the pilot's repeated configurations lie closer together than the tracker's specified noise alone puts
/// them (the arm repeating exactly), the tracker is quieter than its specification, a bound taken as 2σ: its
/// random noise, scaled by one factor in [0, 1], gives the pilot's spread. Where even no noise spreads them more
/// (the cited lost motion, a warm-up between repeats), the specification stays and the source says so.
fn fit_tracker_noise(values: &mut TwinValues, replays: Replays, repeats: Repeats) -> Result<()> {
    let base: Vec<f64> = TRACKER_NOISE.iter().map(|k| values.magnitude(k)).collect();
    let fitted = fit_scale(
        values,
        &TRACKER_NOISE,
        repeats.mean_distance_m,
        |r| r.1,
        replays,
    )?;
    let spread = repeats.mean_distance_m * 1e3;
    let (s, std, source) = match fitted {
        Some((s, std)) if s < 1.0 => (
            s,
            Some(std),
            format!(
                "the specification × {s:.2}: the pilot's {} repeated configurations lie {spread:.4} mm from \
                 their groups' means, closer than the specification's noise alone puts them",
                repeats.groups
            ),
        ),
        _ => (
            1.0,
            None,
            format!(
                "the specification: the pilot's repeats ({spread:.4} mm) are spread more by what else the twin \
                 carries than by the tracker"
            ),
        ),
    };
    *values = scaled(values, &TRACKER_NOISE, s);
    for (k, b) in TRACKER_NOISE.iter().zip(&base) {
        set_source(values, k, std.map(|std| std * b), source.clone());
    }
    Ok(())
}

/// `values` with the magnitudes `keys` multiplied by `s`.
fn scaled(values: &TwinValues, keys: &[&str], s: f64) -> TwinValues {
    let mut v = values.clone();
    for k in keys {
        v.set(k, values.magnitude(k) * s);
    }
    v
}

/// The one factor on the magnitudes `keys` that brings a statistic of the twin to `target`, with its standard
/// deviation ([`magnitudes::fit_one`] from 1): `statistic` picks the elastic held-out means or the repeats'
/// spreads of [`magnitudes::simulate`].
fn fit_scale(
    values: &TwinValues,
    keys: &[&str],
    target: f64,
    statistic: fn(magnitudes::Statistics) -> Vec<f64>,
    replays: Replays,
) -> Result<Option<(f64, f64)>> {
    magnitudes::fit_one(target, 1.0, |s| {
        replays.statistics(&scaled(values, keys, s)).map(statistic)
    })
}

/// The error sources of smooth effect (true inertials, cable, bearing tilt) scaled by one factor in [0, 1] so
/// the elastic fit's held-out error meets the pilot's.
fn scale_smooth_sources(
    values: &mut TwinValues,
    replays: Replays,
    targets: &Targets,
) -> Result<()> {
    const SMOOTH: [&str; 3] = [
        "truth.link_mass_spread",
        "truth.link_com_m",
        "truth.cable_kg_per_m",
    ];
    let fitted = fit_scale(values, &SMOOTH, targets.elastic_mm, |r| r.0, replays)?;
    let s = fitted.map_or(0.0, |(s, _)| s.min(1.0));
    *values = scaled(values, &SMOOTH, s);
    for k in SMOOTH {
        set_source(
            values,
            k,
            None,
            format!(
                "cited default × {s:.2}: scaled down with the other smooth sources so the twin's held-out \
                 elastic error meets the pilot's {:.4} mm",
                targets.elastic_mm
            ),
        );
    }
    Ok(())
}
