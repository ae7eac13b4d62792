//! The parameters of the kinematic and elastic fits: the candidate list in priority order, and the state
//! they overwrite.

use nalgebra::{Point3, Vector3};
use serde::{Deserialize, Serialize};

use crate::calib::error_model::{ErrorModelKind, ErrorParam, FrameErrors};

/// One candidate parameter. Indices count from 0 for axes (x, y, z) and from 0 for joints.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Param {
    TrackerRotation(usize),
    TrackerTranslation(usize),
    /// The base error frame `E_0` of data already in the base frame, where there is no tracker frame to
    /// fit: fitted as the rigid motion of the measured points that the tracker frame's parameters are
    /// (the same columns), kept by the model as its inverse `E_0` before the first joint.
    BaseRotation(usize),
    BaseTranslation(usize),
    Mounting(usize),
    Error(ErrorParam),
    Compliance(usize),
}

impl Param {
    pub fn name(&self) -> String {
        const AXES: [&str; 3] = ["x", "y", "z"];
        match self {
            Param::TrackerRotation(k) => format!("tracker_r{}", AXES[*k]),
            Param::TrackerTranslation(k) => format!("tracker_{}", AXES[*k]),
            Param::BaseRotation(k) => format!("base_r{}", AXES[*k]),
            Param::BaseTranslation(k) => format!("base_{}", AXES[*k]),
            Param::Mounting(k) => format!("mount_{}", AXES[*k]),
            Param::Error(e) => e.name(),
            Param::Compliance(j) => format!("c{}", j + 1),
        }
    }

    /// Whether it is a parameter of an `n`-joint chain (compliances only when `elastic`).
    pub fn belongs_to(&self, n: usize, elastic: bool) -> bool {
        match *self {
            Param::TrackerRotation(k)
            | Param::TrackerTranslation(k)
            | Param::BaseRotation(k)
            | Param::BaseTranslation(k)
            | Param::Mounting(k) => k < 3,
            Param::Error(e) => (1..=n).contains(&e.frame) && (1..=6).contains(&e.component),
            Param::Compliance(j) => elastic && j < n,
        }
    }

    pub(super) fn is_compliance(&self) -> bool {
        matches!(self, Param::Compliance(_))
    }
}

/// Every candidate of an `n`-joint chain, in priority order.
pub fn candidates(n: usize, elastic: bool) -> Vec<Param> {
    let mut out: Vec<Param> = (0..3).map(Param::TrackerRotation).collect();
    out.extend((0..3).map(Param::TrackerTranslation));
    out.extend((0..3).map(Param::Mounting));
    out.extend(
        ErrorModelKind::RotXyzTransXyz
            .params(n)
            .into_iter()
            .map(Param::Error),
    );
    if elastic {
        out.extend((0..n).map(Param::Compliance));
    }
    out
}

/// Full parameter state: the defaults overwritten by the kept parameters.
#[derive(Clone, Debug)]
pub(super) struct State {
    pub(super) rho: Vector3<f64>,
    pub(super) t: Vector3<f64>,
    pub(super) mount: Point3<f64>,
    pub(super) errors: FrameErrors,
    pub(super) compliance: Vec<f64>,
}

impl State {
    pub(super) fn initial(n: usize, mount: Point3<f64>) -> State {
        State {
            rho: Vector3::zeros(),
            t: Vector3::zeros(),
            mount,
            errors: vec![[0.0; 6]; n],
            compliance: vec![0.0; n],
        }
    }

    pub(super) fn get(&self, p: Param) -> f64 {
        match p {
            Param::TrackerRotation(k) | Param::BaseRotation(k) => self.rho[k],
            Param::TrackerTranslation(k) | Param::BaseTranslation(k) => self.t[k],
            Param::Mounting(k) => self.mount[k],
            Param::Error(e) => self.errors[e.frame - 1][e.component - 1],
            Param::Compliance(j) => self.compliance[j],
        }
    }

    pub(super) fn set(&mut self, p: Param, v: f64) {
        match p {
            Param::TrackerRotation(k) | Param::BaseRotation(k) => self.rho[k] = v,
            Param::TrackerTranslation(k) | Param::BaseTranslation(k) => self.t[k] = v,
            Param::Mounting(k) => self.mount[k] = v,
            Param::Error(e) => self.errors[e.frame - 1][e.component - 1] = v,
            Param::Compliance(j) => self.compliance[j] = v,
        }
    }

    pub(super) fn with(base: &State, params: &[Param], values: &[f64]) -> State {
        let mut s = base.clone();
        for (&p, &v) in params.iter().zip(values) {
            s.set(p, v);
        }
        s
    }
}
