//! The sizes a saved robot or calibration number can have, for checking a file (`model.json`) on load.
//!
//! Every check returns `Error::Invalid("<field>: <what is wrong>")`, the field named by its path in the file
//! (`dh.rows[2].d`); [`within`] prefixes the path of the object that holds it, so the loader can put the
//! file's name in front and have one line that says where and what.
//!
//! The bounds are far outside anything a real robot, tracker or fit produces and far inside what overflows:
//! their only job is to refuse numbers that could not have come from a calibration in metres and radians
//! (a 1e300 typed into a file, a value scaled by mistake), before they turn into predictions of 1e296 m.

use nalgebra::{Isometry3, Point3, UnitQuaternion, Vector3};

use crate::error::{Error, Result};

/// Lengths (m): DH `d` and `a`, base and tool offsets, the tracker's position, the mounting, a nest's
/// reflectors, translation errors, centres of mass. The largest industrial arms reach about 4 m and a laser
/// tracker measures to about 80 m, so no length of a robot cell, nor any error of one, reaches 100 m.
pub const MAX_LENGTH_M: f64 = 100.0;

/// Angles (rad): DH `theta_offset` and `alpha` (derived within ±π), rotation errors (rotation vectors, a
/// fraction of a radian in practice). A turn and a half covers every way of writing an angle without a
/// full extra turn; beyond it the number is not an angle someone measured.
pub const MAX_ANGLE_RAD: f64 = 3.0 * std::f64::consts::PI;

/// A stored rotation (quaternion) is unit to rounding; one off by more than this is not a rotation.
pub const UNIT_TOLERANCE: f64 = 1e-6;

/// Masses (kg): of one link or the payload. The heaviest industrial robots weigh a few tonnes in all.
pub const MAX_MASS_KG: f64 = 1e4;

/// `field: message` as an invalid-input error.
pub fn invalid(field: &str, message: impl std::fmt::Display) -> Error {
    Error::Invalid(format!("{field}: {message}"))
}

/// `result` with `prefix.` in front of its field path.
pub fn within(prefix: &str, result: Result<()>) -> Result<()> {
    result.map_err(|e| match e {
        Error::Invalid(message) => Error::Invalid(format!("{prefix}.{message}")),
        other => other,
    })
}

/// A finite number.
pub fn finite(field: &str, v: f64) -> Result<()> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(invalid(field, format!("{v} is not a finite number")))
    }
}

/// A finite number with `|v| <= max`; `what` names the quantity in the message.
pub fn bounded(field: &str, v: f64, max: f64, what: &str) -> Result<()> {
    finite(field, v)?;
    if v.abs() <= max {
        Ok(())
    } else {
        Err(invalid(
            field,
            format!("{v:e} is not a plausible {what} (at most {max} in magnitude)"),
        ))
    }
}

/// A finite number in `[0, max]`.
pub fn non_negative(field: &str, v: f64, max: f64, what: &str) -> Result<()> {
    bounded(field, v, max, what)?;
    if v >= 0.0 {
        Ok(())
    } else {
        Err(invalid(
            field,
            format!("{v:e} is negative; a {what} is not"),
        ))
    }
}

pub fn length(field: &str, v: f64) -> Result<()> {
    bounded(field, v, MAX_LENGTH_M, "length in metres")
}

pub fn angle(field: &str, v: f64) -> Result<()> {
    bounded(field, v, MAX_ANGLE_RAD, "angle in radians")
}

/// Each coordinate a [`length`]; `field[k]` names the bad one.
pub fn lengths(field: &str, v: &[f64]) -> Result<()> {
    v.iter()
        .enumerate()
        .try_for_each(|(k, &x)| length(&format!("{field}[{k}]"), x))
}

pub fn point(field: &str, p: &Point3<f64>) -> Result<()> {
    lengths(field, p.coords.as_slice())
}

pub fn translation(field: &str, v: &Vector3<f64>) -> Result<()> {
    lengths(field, v.as_slice())
}

/// Finite, and unit to [`UNIT_TOLERANCE`] (a file holds it as written; nothing renormalises it).
pub fn rotation(field: &str, q: &UnitQuaternion<f64>) -> Result<()> {
    let c = q.coords;
    for (k, &v) in c.iter().enumerate() {
        finite(&format!("{field}[{k}]"), v)?;
    }
    let norm = c.norm();
    if (norm - 1.0).abs() <= UNIT_TOLERANCE {
        Ok(())
    } else {
        Err(invalid(
            field,
            format!("a quaternion of norm {norm:e} is not a rotation (norm 1)"),
        ))
    }
}

/// A pose as a file writes it: `field.rotation` and `field.translation`.
pub fn pose(field: &str, t: &Isometry3<f64>) -> Result<()> {
    rotation(&format!("{field}.rotation"), &t.rotation)?;
    translation(&format!("{field}.translation"), &t.translation.vector)
}

/// `got` entries where `want` are needed; `of` says what `want` counts.
pub fn count(field: &str, got: usize, want: usize, of: &str) -> Result<()> {
    if got == want {
        Ok(())
    } else {
        Err(invalid(field, format!("{got} entries for {want} {of}")))
    }
}
