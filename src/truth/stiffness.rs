//! Joint stiffness beyond one constant per joint: the soft zone of a strain-wave gear (a torsional stiffness
//! that grows with the load, as the catalogues give it: K1 up to T1, K2 up to T2, K3 above) and the compliance
//! about the two axes perpendicular to a joint (its output bearing's tilt, the bending of the link it carries),
//! which responds to the part of the gravity moment that the joint's own spring never sees.

use nalgebra::{Unit, Vector3};
use serde::{Deserialize, Serialize};

/// Piecewise-linear torsional stiffness of one joint (Harmonic Drive's catalogue form): stiffness `k1` for
/// |τ| ≤ `t1`, `k2` for `t1` < |τ| ≤ `t2`, `k3` above; odd in the torque.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
pub struct SoftZone {
    /// Torque limits of the first two ranges (Nm), 0 ≤ t1 ≤ t2.
    pub t1: f64,
    pub t2: f64,
    /// Stiffness in each range (Nm/rad), each > 0.
    pub k1: f64,
    pub k2: f64,
    pub k3: f64,
}

impl SoftZone {
    /// The joint's deflection (rad) under torque `tau` (Nm): the catalogue's torsion curve.
    #[inline]
    pub fn deflection(&self, tau: f64) -> f64 {
        let t = tau.abs();
        let theta = if t <= self.t1 {
            t / self.k1
        } else if t <= self.t2 {
            self.t1 / self.k1 + (t - self.t1) / self.k2
        } else {
            self.t1 / self.k1 + (self.t2 - self.t1) / self.k2 + (t - self.t2) / self.k3
        };
        theta.copysign(tau)
    }

    /// The linear spring `τ = k (θ − offset)` that equals the curve on the range deflection `theta` lies in:
    /// (stiffness, offset). A solver with linear springs only (rapier) follows the curve with it.
    pub fn segment(&self, theta: f64) -> (f64, f64) {
        let a = theta.abs();
        let th1 = self.t1 / self.k1;
        let th2 = th1 + (self.t2 - self.t1) / self.k2;
        let (k, offset) = if a <= th1 {
            (self.k1, 0.0)
        } else if a <= th2 {
            (self.k2, th1 - self.t1 / self.k2)
        } else {
            (self.k3, th2 - self.t2 / self.k3)
        };
        (k, offset.copysign(theta))
    }
}

/// The tilt (rotation vector in the joint's frame, rad) a perpendicular compliance `compliance` (rad/Nm) gives
/// under the moment `moment_local` (Nm, in the joint's frame): the moment's part perpendicular to the `axis`.
#[inline]
pub fn tilt(
    axis: &Unit<Vector3<f64>>,
    moment_local: &Vector3<f64>,
    compliance: f64,
) -> Vector3<f64> {
    (moment_local - axis.into_inner() * axis.dot(moment_local)) * compliance
}
