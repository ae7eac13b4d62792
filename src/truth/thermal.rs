//! Thermal growth of the arm over a campaign: the links warm up from a start to an end temperature with one
//! time constant while the arm visits its points at a steady pace, and every link length grows by
//! `α (T − T_ref)`.

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

/// The `[truth] thermal` table: a warm-up `T(t) = T_end + (T_start − T_end) e^(−t/τ)` with `t` the time of a
/// point (its place in the campaign's sequence × `seconds_per_point`), and the links' expansion coefficient.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ThermalProfile {
    /// Temperature of the links at the first point (°C).
    pub start_c: f64,
    /// Temperature they settle at (°C); also the temperature of the ground-truth evaluation (the arm in use).
    pub end_c: f64,
    /// Time constant of the warm-up (s), > 0.
    pub time_constant_s: f64,
    /// Time from one point to the next (s), ≥ 0.
    pub seconds_per_point: f64,
    /// Linear expansion coefficient of the links (1/K), ≥ 0.
    pub expansion_per_k: f64,
    /// Temperature at which the links have their nominal lengths (°C).
    pub reference_c: f64,
}

impl ThermalProfile {
    pub fn validate(&self) -> Result<()> {
        let finite = [
            ("start_c", self.start_c),
            ("end_c", self.end_c),
            ("reference_c", self.reference_c),
        ];
        for (name, v) in finite {
            if !v.is_finite() {
                return Err(Error::Invalid(format!(
                    "truth.thermal.{name} = {v} must be finite"
                )));
            }
        }
        if !(self.time_constant_s.is_finite() && self.time_constant_s > 0.0) {
            return Err(Error::Invalid(format!(
                "truth.thermal.time_constant_s = {} must be finite and positive",
                self.time_constant_s
            )));
        }
        for (name, v) in [
            ("seconds_per_point", self.seconds_per_point),
            ("expansion_per_k", self.expansion_per_k),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(Error::Invalid(format!(
                    "truth.thermal.{name} = {v} must be finite and non-negative"
                )));
            }
        }
        Ok(())
    }

    /// The temperature (°C) at the `k`-th point of a campaign's sequence (from 0).
    pub fn temperature(&self, k: usize) -> f64 {
        self.temperature_at(k as f64 * self.seconds_per_point)
    }

    /// The temperature (°C) `t` seconds into the campaign (a trajectory's clock).
    pub fn temperature_at(&self, t: f64) -> f64 {
        self.end_c + (self.start_c - self.end_c) * (-t / self.time_constant_s).exp()
    }

    /// The factor every link length is multiplied by at `temperature` (°C).
    pub fn scale(&self, temperature: f64) -> f64 {
        1.0 + self.expansion_per_k * (temperature - self.reference_c)
    }
}
