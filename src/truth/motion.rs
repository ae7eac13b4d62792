//! The true arm in motion: following a commanded joint-space path, sampled at the tracker's instants.
//!
//! At each sample the arm is where the static path would put it (zero offsets, gear error, lost motion by the
//! direction each joint is moving in, thermal growth by the time since the start) but its compliant joints carry
//! the full inverse-dynamics torque of the true links — the torque that accelerates them besides the one that
//! holds them against gravity ([`TrueRobot::deflect_moving`]). That is quasi-static: the deflection follows the
//! load at once, without the transmission's own vibration, which for a joint of stiffness k carrying inertia J
//! rings at √(k/J) (tens of hertz for the iiwa) and is damped within a few periods — a rapier multibody reference
//! of that transient is not built yet (issue 16).
//!
//! The controller logs its motor encoders: the motor angle it reads back is the command it tracked, so a servo
//! lag between command and motor does not enter a (logged angles, measured point) pair; the clock offset between
//! the controller's log and the tracker's does, and is the tracker's concern ([`crate::tracker::motion`]).

use nalgebra::Isometry3;
use rand_chacha::ChaCha8Rng;

use super::history::Visit;
use super::robot::{TrueRobot, TrueState};
use crate::error::Result;

/// One commanded sample of a joint-space path: time (s), angles (rad), velocities (rad/s), accelerations
/// (rad/s²), controller coordinates.
#[derive(Clone, Debug, PartialEq)]
pub struct PathPoint {
    pub t: f64,
    pub q: Vec<f64>,
    pub qd: Vec<f64>,
    pub qdd: Vec<f64>,
}

/// Where the true arm is at one path sample.
#[derive(Clone, Debug)]
pub struct MotionSample {
    pub t: f64,
    /// Link-side joint angles of the true arm (rad).
    pub q: Vec<f64>,
    /// The true flange pose (world frame).
    pub flange: Isometry3<f64>,
    /// How far the motion moved the flange from where the arm would stand still at the same command (m): the
    /// dynamic deflection, which no static model describes.
    pub dynamic_m: f64,
}

impl TrueRobot {
    /// The arm following `path`, one [`MotionSample`] per point. A joint at rest keeps the direction it last
    /// moved in (lost motion); repeatability noise is drawn from `noise` when given.
    pub fn follow(
        &self,
        path: &[PathPoint],
        mut noise: Option<&mut ChaCha8Rng>,
    ) -> Result<Vec<MotionSample>> {
        let mut state = TrueState::new(self);
        let mut still = TrueState::new(self);
        let mut direction = vec![1.0; self.chain.dof()];
        let mut out = Vec::with_capacity(path.len());
        for p in path {
            for (d, v) in direction.iter_mut().zip(&p.qd) {
                if *v != 0.0 {
                    *d = v.signum();
                }
            }
            let visit = Visit {
                direction: direction.clone(),
                temperature: self
                    .perturbation
                    .thermal
                    .as_ref()
                    .map(|t| t.temperature_at(p.t)),
            };
            self.unloaded_angles_after(&p.q, &visit, &mut state.q0);
            state.scale = self.length_scale(&visit);
            let moving = p.qd.iter().chain(&p.qdd).any(|v| *v != 0.0);
            self.deflect_moving(&mut state, moving.then_some((&p.qd[..], &p.qdd[..])))?;
            let dynamic_m = if moving {
                still.q0.copy_from_slice(&state.q0);
                still.scale = state.scale;
                self.deflect(&mut still)?;
                (state.frames.flange.translation.vector - still.frames.flange.translation.vector)
                    .norm()
            } else {
                0.0
            };
            self.add_noise(noise.as_deref_mut(), &mut state);
            out.push(MotionSample {
                t: p.t,
                q: state.q.clone(),
                flange: state.frames.flange,
                dynamic_m,
            });
        }
        Ok(out)
    }
}
