//! What the three files of the study's rerun recording share — `recording`, its `blueprint` and
//! `trajectory_recording` —: the timeline names, entity-path names, colours and colour scales, conversions to
//! rerun's `f32`, and the error of a failed recording. It imports none of them, so their imports run one way.

use nalgebra::{Point3, Vector3};

use crate::error::Error;

/// The sequence timeline of the detail campaign's points.
pub const POINT_TIMELINE: &str = "point";
/// The sequence timeline of the learning curves.
pub const N_TRAIN_TIMELINE: &str = "n_train";
/// The learning curves' log timeline: round(1000 · log10 n_train), so 2000 is 100 points and 3000 is 1000; the
/// viewer opens on it.
pub const N_TRAIN_LOG_TIMELINE: &str = "n_train_log";

/// A scenario name as one entity-path part: `[A-Za-z0-9_.-]` kept, anything else `_`.
pub fn sanitize(name: &str) -> String {
    let s: String = name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.') {
                c
            } else {
                '_'
            }
        })
        .collect();
    if s.is_empty() { "_".into() } else { s }
}

/// The viridis colour of `value` on a `0..=scale` axis (same unit), clamped.
pub fn viridis(value: f64, scale: f64) -> [u8; 4] {
    const STOPS: [[f64; 3]; 9] = [
        [68.0, 1.0, 84.0],
        [71.0, 44.0, 122.0],
        [59.0, 81.0, 139.0],
        [44.0, 113.0, 142.0],
        [33.0, 144.0, 141.0],
        [39.0, 173.0, 129.0],
        [92.0, 200.0, 99.0],
        [170.0, 220.0, 50.0],
        [253.0, 231.0, 37.0],
    ];
    let t = if scale > 0.0 && value.is_finite() {
        (value / scale).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let x = t * (STOPS.len() - 1) as f64;
    let i = (x.floor() as usize).min(STOPS.len() - 2);
    let f = x - i as f64;
    let c = |k: usize| (STOPS[i][k] + f * (STOPS[i + 1][k] - STOPS[i][k])).round() as u8;
    [c(0), c(1), c(2), 255]
}

/// The smallest 1-2-5 number ≥ `value` (and ≥ 0.001), for colour scales in mm.
pub(super) fn nice_ceiling(value: f64) -> f64 {
    let v = if value.is_finite() {
        value.max(1e-3)
    } else {
        1e-3
    };
    let decade = 10f64.powi(v.log10().floor() as i32);
    [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * decade)
        .find(|c| *c >= v * (1.0 - 1e-12))
        .unwrap_or(10.0 * decade)
}

/// A distinct colour per series index: Tableau's ten, as the PNG plots use.
pub(super) fn palette(i: usize) -> [u8; 4] {
    const TAB10: [[u8; 4]; 10] = [
        [31, 119, 180, 255],
        [255, 127, 14, 255],
        [44, 160, 44, 255],
        [214, 39, 40, 255],
        [148, 103, 189, 255],
        [140, 86, 75, 255],
        [227, 119, 194, 255],
        [127, 127, 127, 255],
        [188, 189, 34, 255],
        [23, 190, 207, 255],
    ];
    TAB10[i % TAB10.len()]
}

pub(super) fn rerun_error(e: impl std::fmt::Display) -> Error {
    Error::io(
        "campaign.rrd",
        std::io::Error::other(format!("rerun recording: {e}")),
    )
}

pub(super) fn f3(v: &Vector3<f64>) -> [f32; 3] {
    [v.x as f32, v.y as f32, v.z as f32]
}

pub(super) fn p3(p: &Point3<f64>) -> [f32; 3] {
    [p.x as f32, p.y as f32, p.z as f32]
}
