//! The rapier reference of the arm in motion: the compliant multibody of [`super::physics`] driven along a path
//! by moving its springs' rest angles (the motor side), stepped at a small time step, so that the link side
//! follows with its full dynamics — inertia, Coriolis and centrifugal loads, and the springs' own ringing — in
//! rapier's own integrator: the reference the fast path ([`super::motion`], linearised about the quasi-static
//! deflection) is held against in `tests/motion.rs`.
//!
//! Each transmission is a spring k with a damper d across it: `τ = k (θ − q) + d (θ̇ − q̇)`. Rapier's joint
//! spring pulls toward a rest angle and its joint damping acts on the absolute joint velocity, so the rest angle
//! is set to `θ + (d/k) θ̇`: `−k (q − θ − (d/k) θ̇) − d q̇` is the same torque, and both parts stay implicit.
//! Rapier integrates them by backward Euler, which adds a numerical damping of about ω·dt/2 (ω = √(k/J), up to
//! ~900 rad/s at the iiwa's wrist): the step must be small against the physical damping ratio.

use rapier3d::prelude::Real;

use super::physics::{ANG_X, PhysicsReference};
use crate::error::{Error, Result};

impl PhysicsReference {
    /// The joint angles (rad) at each of `times` (ascending, s) of the arm whose springs' rest angles (the
    /// motor side) follow `rest_at(t)`, with `damping` (Nm·s/rad, per joint) across each transmission, starting
    /// at rest in the equilibrium of `rest_at(times[0])`, stepped at `dt` (s).
    pub fn follow(
        &mut self,
        rest_at: &dyn Fn(f64) -> Vec<f64>,
        damping: &[f64],
        times: &[f64],
        dt: f64,
    ) -> Result<Vec<Vec<f64>>> {
        let Some(&t0) = times.first() else {
            return Ok(Vec::new());
        };
        if !(dt.is_finite() && dt > 0.0)
            || times
                .windows(2)
                .any(|w| w[1].partial_cmp(&w[0]).is_none_or(|o| o.is_lt()))
        {
            return Err(Error::Invalid(format!(
                "physics reference: time step {dt} s must be positive and the times ascending"
            )));
        }
        if damping.len() != self.joints.len()
            || damping.iter().any(|d| !(d.is_finite() && *d >= 0.0))
        {
            return Err(Error::Invalid(format!(
                "physics reference: {} joint dampings for {} joints, each finite and non-negative",
                damping.len(),
                self.joints.len()
            )));
        }
        self.settle(&rest_at(t0))?;
        let links = self.dof_indices()?;
        let saved = self.world.integration_parameters.dt;
        self.world.integration_parameters.dt = dt as Real;
        {
            let (mb, _) = self
                .world
                .multibody_joints
                .get_mut(self.joints[0].handle)
                .ok_or_else(|| Error::Physics("multibody lost".into()))?;
            let dampings = mb.damping_mut();
            for (&(_, dof), d) in links.iter().zip(damping) {
                dampings[dof] = *d as Real;
            }
        }
        let n = self.joints.len();
        let mut out = Vec::with_capacity(times.len());
        let mut t = t0;
        let mut q = vec![0.0; n];
        for &target in times {
            while t + 0.5 * dt < target {
                // The implicit spring acts with the rest angle at the end of the step; the motor side's rate
                // by a central difference (the path is smooth).
                const H: f64 = 1e-5;
                let rest = rest_at(t + dt);
                let (ahead, behind) = (rest_at(t + dt + H), rest_at(t + dt - H));
                let (mb, _) = self
                    .world
                    .multibody_joints
                    .get_mut(self.joints[0].handle)
                    .ok_or_else(|| Error::Physics("multibody lost".into()))?;
                for (j, (slot, &(link_id, _))) in self.joints.iter().zip(&links).enumerate() {
                    let rate = (ahead[j] - behind[j]) / (2.0 * H);
                    let link = mb
                        .link_mut(link_id)
                        .ok_or_else(|| Error::Physics("multibody link lost".into()))?;
                    link.joint.set_spring(
                        ANG_X,
                        slot.stiffness as Real,
                        (rest[j] + damping[j] / slot.stiffness * rate) as Real,
                    );
                }
                self.world.step();
                t += dt;
            }
            self.read_q(&links, &mut q)?;
            if q.iter().any(|v| !v.is_finite()) {
                return Err(Error::Physics(format!(
                    "joint angles became non-finite at t = {t} s (dt {dt} s too large?)"
                )));
            }
            out.push(q.clone());
        }
        self.world.integration_parameters.dt = saved;
        Ok(out)
    }
}
