//! Gravity torques on the nominal DH chain, for the elastic model's deflections.

use nalgebra::{Isometry3, Point3, Vector3};
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::robot::dh::DhChain;
use crate::robot::dynamics::{GRAVITY, GravityJoint, gravity_pass};
use crate::robot::kinematics::{Frames, forward_kinematics};
use crate::robot::plausible;
use crate::robot::{Chain, Payload};

/// The largest gravity component (m/s²) a saved model may have: ten times the Earth's, which no robot cell
/// sees, while a mistyped exponent is far beyond.
pub const MAX_GRAVITY: f64 = 100.0;

/// The nominal inertials re-expressed in the DH frames, so gravity torques need only the DH chain (and the
/// saved model needs no URDF): body j + 1 (moved by joint j) in DH frame j + 1, the payload in the flange frame.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct GravityModel {
    /// Per moving body: mass (kg) and centre of mass in its DH frame (m).
    pub masses: Vec<f64>,
    pub coms: Vec<[f64; 3]>,
    pub payload: Payload,
    pub gravity: [f64; 3],
}

impl GravityModel {
    pub fn new(chain: &Chain, dh: &DhChain, payload: Payload) -> Result<GravityModel> {
        let n = chain.dof();
        if dh.dof() != n {
            return Err(Error::Invalid(format!(
                "the DH chain has {} joints, the URDF chain {n}",
                dh.dof()
            )));
        }
        if !(payload.mass.is_finite() && payload.mass >= 0.0)
            || payload.com.iter().any(|c| !c.is_finite())
        {
            return Err(Error::Invalid(format!(
                "payload {payload:?} must be finite, mass ≥ 0"
            )));
        }
        let q0 = vec![0.0; n];
        let mut fk = Frames::new(chain);
        forward_kinematics(chain, &q0, &mut fk);
        let dh_frames = dh.frames(&q0);
        let mut masses = Vec::with_capacity(n);
        let mut coms = Vec::with_capacity(n);
        for i in 0..n {
            let body = &chain.bodies[i + 1];
            let com = dh_frames[i + 1].inverse() * (fk.body[i + 1] * body.inertial.com);
            masses.push(body.inertial.mass);
            coms.push([com.x, com.y, com.z]);
        }
        // The payload's centre is given in the chain's flange frame, which is the DH chain's (tool) flange.
        Ok(GravityModel {
            masses,
            coms,
            payload,
            gravity: [GRAVITY.x, GRAVITY.y, GRAVITY.z],
        })
    }

    /// A model read from a file can give torques on an `n`-joint chain: one mass and centre per joint, masses
    /// in [0, [`plausible::MAX_MASS_KG`]], centres at plausible lengths, gravity finite and at most
    /// `MAX_GRAVITY`.
    pub fn validate(&self, n: usize) -> Result<()> {
        plausible::count("masses", self.masses.len(), n, "joints")?;
        plausible::count("coms", self.coms.len(), n, "joints")?;
        let mass = |field: &str, m: f64| {
            plausible::non_negative(field, m, plausible::MAX_MASS_KG, "mass in kg")
        };
        for (i, (&m, c)) in self.masses.iter().zip(&self.coms).enumerate() {
            mass(&format!("masses[{i}]"), m)?;
            plausible::lengths(&format!("coms[{i}]"), c)?;
        }
        mass("payload.mass", self.payload.mass)?;
        plausible::lengths("payload.com", &self.payload.com)?;
        for (k, &g) in self.gravity.iter().enumerate() {
            plausible::bounded(
                &format!("gravity[{k}]"),
                g,
                MAX_GRAVITY,
                "acceleration in m/s²",
            )?;
        }
        Ok(())
    }

    /// Gravity torques (Nm; N for a prismatic joint) at `q` of the nominal DH chain, as
    /// [`crate::robot::dynamics::gravity_torques`] gives them on the URDF chain.
    pub fn torques(&self, dh: &DhChain, q: &[f64]) -> Vec<f64> {
        self.torques_on(dh, &dh.frames(q))
    }

    /// [`GravityModel::torques`] on the DH frames of the configuration (`dh.frames(q)`, or a
    /// [`ChainPose`](crate::robot::dh::ChainPose)'s).
    pub fn torques_on(&self, dh: &DhChain, frames: &[Isometry3<f64>]) -> Vec<f64> {
        let n = dh.dof();
        let mut out = vec![0.0; n];
        gravity_pass(
            &self.payload,
            &(frames[n] * dh.tool),
            &Vector3::from(self.gravity),
            &mut out,
            |i| GravityJoint {
                mass: self.masses[i],
                com: frames[i + 1] * Point3::from(self.coms[i]),
                axis: frames[i].rotation * Vector3::z(),
                anchor: Point3::from(frames[i].translation.vector),
                prismatic: dh.rows[i].prismatic,
            },
        );
        out
    }
}
