//! The true arm in motion: following a commanded joint-space path, sampled at the tracker's instants.
//!
//! The motor side of each joint follows the command; the link side hangs on the transmission, a spring of the
//! joint's stiffness K with a viscous damper D across it (Spong's flexible-joint model). With θ the unloaded
//! angles (command, zero offset, gear error, lost motion by the direction each joint moves in) and `z = θ − q`
//! the joints' deflection, the true links obey
//!
//! ```text
//! M(q) q̈ + h(q, q̇) = K z + D ż
//! ```
//!
//! The fast path splits that into what the static path already solves and a small linear remainder. The
//! quasi-static deflection δ_s carries the full inverse-dynamics torque of the motion at the commanded rates
//! ([`TrueRobot::deflect_moving`], nonlinear springs, tilt and thermal growth included). Linearised about it,
//! the deflection obeys
//!
//! ```text
//! M z̈ + (D + B) ż + (K_t + A) z = (K_t + A) δ_s(t)
//! ```
//!
//! (A = ∂τ/∂q, B = ∂τ/∂q̇ of the inverse dynamics τ, K_t the springs' slope): a mass–spring–damper driven by
//! the quasi-static deflection, so that a still arm settles exactly where the static path puts it and a moving
//! one lags and rings about it. That system is integrated by the trapezoidal rule (Newmark's average
//! acceleration: no numerical damping, second order) at steps of at most [`MOTION_STEP_S`], with M, A and B
//! refreshed every [`RELINEARIZE_S`] of path. The rapier f64 multibody ([`super::physics_motion`]) integrates
//! the full nonlinear model; `tests/motion.rs` holds the two together to 5 µm at the flange.
//!
//! The controller logs its motor encoders: the motor angle it reads back is the command it tracked, so a servo
//! lag between command and motor does not enter a (logged angles, measured point) pair; the clock offset between
//! the controller's log and the tracker's does, and is the tracker's concern ([`crate::tracker::motion`]).

use nalgebra::{DMatrix, DVector, Isometry3, Vector3};
use rand_chacha::ChaCha8Rng;

use super::history::Visit;
use super::robot::{Deflection, TrueRobot, TrueState};
use crate::error::{Error, Result};
use crate::robot::Frames;
use crate::robot::inverse_dynamics::{Workspace, inverse_dynamics};

/// The longest step of the deflection's integration (s). The slowest modes of an arm's joints (11–14 Hz for
/// the iiwa) are then resolved to 0.2 % in frequency by the trapezoidal rule; the fast ones (the wrist's, up to
/// ~400 Hz) are barely excited by a smooth path and stay near their quasi-static answer. Measured in
/// `tests/motion.rs` against an f64 integration of the full model: 3.0 µm at most at 2 ms, 2.3 µm at 1 ms,
/// 2.1 µm at 0.25 ms (the rest is the linearisation), each halving doubling the cost.
pub const MOTION_STEP_S: f64 = 2e-3;

/// How long the mass matrix and the torque's sensitivities are kept (s of path): they change with the posture,
/// a few per cent over this at full speed, and only the small dynamic remainder depends on them.
pub const RELINEARIZE_S: f64 = 0.02;

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

/// The linearised joint dynamics about the quasi-static state: `M z̈ + C ż + S z = S δ_s`.
struct Linear {
    m: DMatrix<f64>,
    c: DMatrix<f64>,
    s: DMatrix<f64>,
}

/// The deflection's state in the trapezoidal integration: `z`, `ż`, `z̈`, the quasi-static deflection it is
/// driven by, at the last node.
struct Remainder {
    t: f64,
    z: DVector<f64>,
    v: DVector<f64>,
    a: DVector<f64>,
    quasi_static: DVector<f64>,
    /// The node before the last: its time and quasi-static deflection (for the next solve's first guess).
    before: Option<(f64, DVector<f64>)>,
    linear: Linear,
    linearized_at: f64,
    /// Scratch of [`Remainder::step`], kept between nodes.
    scratch: Scratch,
}

/// Buffers of one trapezoidal step: two vectors and the step's matrix.
struct Scratch {
    x: DVector<f64>,
    product: DVector<f64>,
    matrix: DMatrix<f64>,
}

/// The settled arm at a sample, before repeatability noise.
struct Reached {
    settled: Deflection,
    scale: f64,
    dynamic_m: f64,
}

impl TrueRobot {
    /// The arm following the commanded `path` (a function of controller time), sampled at `times` (s, any
    /// order): one [`MotionSample`] per time. It starts at the earliest time in its quasi-static state (at rest
    /// for a path that starts at rest). A joint at rest keeps the direction it last moved in (lost motion);
    /// repeatability noise is drawn from `noise`, sample by sample in the order of `times`, when given.
    pub fn follow(
        &self,
        path: &dyn Fn(f64) -> PathPoint,
        times: &[f64],
        noise: Option<&mut ChaCha8Rng>,
    ) -> Result<Vec<MotionSample>> {
        self.follow_stepped(path, times, MOTION_STEP_S, noise)
    }

    /// [`TrueRobot::follow`] with the integration's longest step `step_s` (s).
    pub fn follow_stepped(
        &self,
        path: &dyn Fn(f64) -> PathPoint,
        times: &[f64],
        step_s: f64,
        mut noise: Option<&mut ChaCha8Rng>,
    ) -> Result<Vec<MotionSample>> {
        if !(step_s.is_finite() && step_s > 0.0) {
            return Err(Error::Invalid(format!(
                "motion: integration step {step_s} s must be positive"
            )));
        }
        if let Some(t) = times.iter().find(|t| !t.is_finite()) {
            return Err(Error::Invalid(format!(
                "motion: sample time {t} s is not a finite number"
            )));
        }
        let n = self.chain.dof();
        let mut order: Vec<usize> = (0..times.len()).collect();
        order.sort_by(|&a, &b| times[a].total_cmp(&times[b]));
        let damping = self.transmission_damping();
        let mut walk = Walk {
            robot: self,
            path,
            damping: &damping,
            state: TrueState::new(self),
            still: TrueState::new(self),
            visit: Visit {
                direction: vec![1.0; n],
                temperature: None,
            },
            remainder: None,
            ws: Workspace::new(&self.chain),
            frames: Frames::new(&self.chain),
        };
        let mut reached: Vec<Option<Reached>> = (0..times.len()).map(|_| None).collect();
        let mut last: Option<f64> = None;
        for &i in &order {
            let target = times[i];
            if let Some(previous) = last {
                // Nodes between samples further apart than a step, evenly spaced.
                let gap = target - previous;
                let steps = (gap / step_s).ceil() as usize;
                for k in 1..steps {
                    walk.advance(previous + gap * k as f64 / steps as f64)?;
                }
            }
            walk.advance(target)?;
            reached[i] = Some(walk.reached()?);
            last = Some(target);
        }
        let mut state = TrueState::new(self);
        reached
            .into_iter()
            .zip(times)
            .map(|(r, &t)| {
                let r =
                    r.ok_or_else(|| Error::Invalid("motion: a sample was not reached".into()))?;
                self.reach_with_angles(&r.settled, r.scale, noise.as_deref_mut(), &mut state);
                Ok(MotionSample {
                    t,
                    q: state.q.clone(),
                    flange: state.frames.flange,
                    dynamic_m: r.dynamic_m,
                })
            })
            .collect()
    }

    /// M, C = D + B and S = K_t + A at the quasi-static state of `state` (frames at its angles, `tau` the load
    /// torque) moving at (`qd`, `qdd`).
    fn linearize(
        &self,
        state: &TrueState,
        qd: &[f64],
        qdd: &[f64],
        damping: &[f64],
        ws: &mut Workspace,
        frames: &mut Frames,
    ) -> Linear {
        let n = self.chain.dof();
        let torque = |frames: &Frames,
                      gravity: &Vector3<f64>,
                      qd: &[f64],
                      qdd: &[f64],
                      ws: &mut Workspace,
                      out: &mut [f64]| {
            inverse_dynamics(
                &self.chain,
                frames,
                &self.payload,
                gravity,
                qd,
                qdd,
                ws,
                out,
            );
        };
        let zero = vec![0.0; n];
        let mut m = DMatrix::zeros(n, n);
        let mut c = DMatrix::zeros(n, n);
        let mut s = DMatrix::zeros(n, n);
        let (mut base, mut ahead) = (vec![0.0; n], vec![0.0; n]);
        torque(&state.frames, &self.gravity, qd, qdd, ws, &mut base);
        // Forward differences: their error (a step's share of the curvature) is a millionth of the sensitivity,
        // below what the remainder needs.
        const RATE: f64 = 1e-3;
        const ANGLE: f64 = 1e-6;
        let (mut unit, mut faster, mut q) = (zero.clone(), qd.to_vec(), state.q.clone());
        for j in 0..n {
            unit.fill(0.0);
            unit[j] = 1.0;
            torque(
                &state.frames,
                &Vector3::zeros(),
                &zero,
                &unit,
                ws,
                &mut ahead,
            );
            m.column_mut(j).copy_from_slice(&ahead);
            faster.copy_from_slice(qd);
            faster[j] += RATE;
            torque(&state.frames, &self.gravity, &faster, qdd, ws, &mut ahead);
            for (i, (a, b)) in ahead.iter().zip(&base).enumerate() {
                c[(i, j)] = (a - b) / RATE;
            }
            q.copy_from_slice(&state.q);
            q[j] += ANGLE;
            self.kinematics(&q, &state.tilt, state.scale, frames);
            torque(frames, &self.gravity, qd, qdd, ws, &mut ahead);
            for (i, (a, b)) in ahead.iter().zip(&base).enumerate() {
                s[(i, j)] = (a - b) / ANGLE;
            }
        }
        for i in 0..n {
            c[(i, i)] += damping[i];
            s[(i, i)] += self.tangent_stiffness(i, state.tau()[i]);
        }
        Linear { m, c, s }
    }
}

/// The walk along the path, node by node in time order.
struct Walk<'a> {
    robot: &'a TrueRobot,
    path: &'a dyn Fn(f64) -> PathPoint,
    damping: &'a [f64],
    /// The quasi-static solve at the current node.
    state: TrueState,
    /// The static solve at the same command (for the dynamic part's size).
    still: TrueState,
    /// The direction each joint last moved in and the links' temperature, at the current node.
    visit: Visit,
    remainder: Option<Remainder>,
    ws: Workspace,
    frames: Frames,
}

impl Walk<'_> {
    /// Moves to time `t`: the quasi-static solve there, then one trapezoidal step of the deflection.
    fn advance(&mut self, t: f64) -> Result<()> {
        let robot = self.robot;
        let p = (self.path)(t);
        let n = robot.chain.dof();
        if p.q.len() != n || p.qd.len() != n || p.qdd.len() != n {
            return Err(Error::Invalid(format!(
                "motion: the path gives {} angles at t = {t} s, the robot has {n} joints",
                p.q.len()
            )));
        }
        for (d, v) in self.visit.direction.iter_mut().zip(&p.qd) {
            if *v != 0.0 {
                *d = v.signum();
            }
        }
        self.visit.temperature = robot
            .perturbation
            .thermal
            .as_ref()
            .map(|th| th.temperature_at(t));
        let visit = &self.visit;
        let state = &mut self.state;
        robot.unloaded_angles_after(&p.q, visit, &mut state.q0);
        state.scale = robot.length_scale(visit);
        match &self.remainder {
            // From the last nodes' deflection, extrapolated along its trend, and the last tilt.
            Some(r) => {
                let trend = match &r.before {
                    Some((t_before, before)) if r.t > *t_before => {
                        Some(((t - r.t) / (r.t - t_before), before))
                    }
                    _ => None,
                };
                for (j, (q, q0)) in state.q.iter_mut().zip(&state.q0).enumerate() {
                    let d = r.quasi_static[j];
                    let ahead = trend.map_or(0.0, |(f, before)| f * (d - before[j]));
                    *q = q0 - d - ahead;
                }
                robot.deflect_from_guess(state, Some((&p.qd[..], &p.qdd[..])))?;
            }
            None => {
                robot.deflect_moving(state, Some((&p.qd[..], &p.qdd[..])))?;
            }
        }
        let quasi_static =
            DVector::from_iterator(n, state.q0.iter().zip(&state.q).map(|(q0, q)| q0 - q));
        let stale = self
            .remainder
            .as_ref()
            .is_none_or(|r| t - r.linearized_at >= RELINEARIZE_S);
        let linear = stale.then(|| {
            robot.linearize(
                state,
                &p.qd,
                &p.qdd,
                self.damping,
                &mut self.ws,
                &mut self.frames,
            )
        });
        match (&mut self.remainder, linear) {
            (None, linear) => {
                let linear = linear.expect("a first node is always linearised");
                self.remainder = Some(Remainder {
                    t,
                    z: quasi_static.clone(),
                    v: DVector::zeros(n),
                    a: DVector::zeros(n),
                    quasi_static,
                    before: None,
                    linear,
                    linearized_at: t,
                    scratch: Scratch {
                        x: DVector::zeros(n),
                        product: DVector::zeros(n),
                        matrix: DMatrix::zeros(n, n),
                    },
                });
            }
            (Some(r), linear) => {
                if let Some(linear) = linear {
                    // The acceleration at the last node, consistent with the new matrices.
                    let force = &linear.s * (&r.quasi_static - &r.z) - &linear.c * &r.v;
                    r.a = linear
                        .m
                        .clone()
                        .lu()
                        .solve(&force)
                        .ok_or_else(|| singular(t))?;
                    r.linear = linear;
                    r.linearized_at = t;
                }
                r.step(t, &quasi_static)?;
            }
        }
        Ok(())
    }

    /// The arm at the current node: the link angles `θ − z` with the quasi-static tilt, and how far the motion
    /// moved the flange from the arm standing still at the same command.
    fn reached(&mut self) -> Result<Reached> {
        let robot = self.robot;
        let r = self
            .remainder
            .as_ref()
            .ok_or_else(|| Error::Invalid("motion: no node reached yet".into()))?;
        let state = &self.state;
        let q: Vec<f64> = state
            .q0
            .iter()
            .zip(r.z.iter())
            .map(|(q0, z)| q0 - z)
            .collect();
        robot.kinematics(&q, &state.tilt, state.scale, &mut self.frames);
        let still = &mut self.still;
        still.q0.copy_from_slice(&state.q0);
        still.scale = state.scale;
        // From the quasi-static solve: the static one differs from it by the motion's share alone.
        still.q.copy_from_slice(&state.q);
        still.tilt.copy_from_slice(&state.tilt);
        robot.deflect_from_guess(still, None)?;
        let dynamic_m =
            (self.frames.flange.translation.vector - still.frames.flange.translation.vector).norm();
        Ok(Reached {
            settled: Deflection {
                q,
                tilt: state.tilt.clone(),
            },
            scale: state.scale,
            dynamic_m,
        })
    }
}

fn singular(t: f64) -> Error {
    Error::Physics(format!(
        "motion: the arm's mass matrix is singular at t = {t} s (a link without mass or inertia?)"
    ))
}

impl Remainder {
    /// One trapezoidal (Newmark average-acceleration) step to time `t`, driven by `quasi_static` there.
    ///
    /// In place, in the order of the expressions `s δ + M (z a₀ + v 4/h + a) + C (z a₁ + v)` and
    /// `S + C a₁ + M a₀` (each product whole before it is added): the bits of the allocating form, without its
    /// dozen allocations per node.
    fn step(&mut self, t: f64, quasi_static: &DVector<f64>) -> Result<()> {
        let h = t - self.t;
        if h > 0.0 {
            let Linear { m, c, s } = &self.linear;
            let Scratch { x, product, matrix } = &mut self.scratch;
            let (a0, a1) = (4.0 / (h * h), 2.0 / h);
            let mut rhs = s * quasi_static;
            x.copy_from(&self.z);
            *x *= a0;
            x.axpy(4.0 / h, &self.v, 1.0);
            *x += &self.a;
            product.gemv(1.0, m, x, 0.0);
            rhs += &*product;
            x.copy_from(&self.z);
            *x *= a1;
            *x += &self.v;
            product.gemv(1.0, c, x, 0.0);
            rhs += &*product;
            for (((out, s), c), m) in matrix.iter_mut().zip(s.iter()).zip(c.iter()).zip(m.iter()) {
                *out = s + c * a1 + m * a0;
            }
            if !matrix.clone().lu().solve_mut(&mut rhs) {
                return Err(singular(t));
            }
            let z = rhs;
            for (((zi, old), v), a) in z
                .iter()
                .zip(self.z.iter())
                .zip(self.v.iter_mut())
                .zip(self.a.iter_mut())
            {
                let d = zi - old;
                *a = d * a0 - *v * (4.0 / h) - *a;
                *v = d * a1 - *v;
            }
            self.z = z;
            let before = self
                .before
                .get_or_insert_with(|| (0.0, DVector::zeros(quasi_static.len())));
            before.0 = self.t;
            std::mem::swap(&mut before.1, &mut self.quasi_static);
            self.quasi_static.copy_from(quasi_static);
            self.t = t;
        } else {
            self.quasi_static.copy_from(quasi_static);
        }
        Ok(())
    }
}
