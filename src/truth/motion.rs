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
//! computed every [`RELINEARIZE_S`] of path and interpolated between, and δ_s solved every [`KNOT_S`] and at each
//! sample, interpolated by a cubic between where it is smooth; a slower path takes all three longer in
//! proportion to its own time scale ([`Resolution::for_peak_acceleration`]). The rapier f64 multibody
//! ([`super::physics_motion`]) integrates the full nonlinear model; `tests/motion.rs` holds the two together to
//! 5 µm at the flange.
//!
//! The controller logs its motor encoders: the motor angle it reads back is the command it tracked, so a servo
//! lag between command and motor does not enter a (logged angles, measured point) pair; the clock offset between
//! the controller's log and the tracker's does, and is the tracker's concern ([`crate::tracker::motion`]).

use std::collections::VecDeque;

use nalgebra::{DMatrix, DVector, Isometry3, Vector3};
use rand_chacha::ChaCha8Rng;

use super::command::{Command, PathPoint};
use super::history::Visit;
use super::robot::{Deflection, TrueRobot, TrueState};
use crate::error::{Error, Result};
use crate::robot::Frames;
use crate::robot::inverse_dynamics::{
    Workspace, geometry_from, inverse_dynamics, inverse_dynamics_from, mass_matrix_column,
};

pub use super::resolution::{
    KNOT_S, MOTION_STEP_S, RELINEARIZE_KNOTS, RELINEARIZE_S, Resolution, STEP_ACCELERATION_RAD_S2,
};

/// How far the command's accelerations at a node may miss the cubic through the grid's four (rad/s²) for the
/// node to take δ_s from the cubic: within a quintic segment they miss by rounding (~1e-15), across a waypoint
/// by the jump of the jerk times a fraction of the grid step (~1e-2). Through a joint's compliance times its
/// inertia (≲ 1e-3 s²) a miss of this size is ≲ 1e-9 rad of δ_s.
pub const ACCELERATION_TOL: f64 = 1e-6;

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
    /// Scratch of [`Remainder::step`], kept between nodes.
    scratch: Scratch,
}

/// Buffers of one trapezoidal step: three vectors and the step's matrix.
struct Scratch {
    x: DVector<f64>,
    product: DVector<f64>,
    rhs: DVector<f64>,
    matrix: DMatrix<f64>,
}

/// One exact quasi-static solve on the grid of [`KNOT_S`].
struct Knot {
    index: i64,
    quasi_static: DVector<f64>,
    tilt: Vec<Vector3<f64>>,
    /// The direction each joint last moved in there.
    direction: Vec<f64>,
    /// Each joint's spring slope there: which segment of its soft-zone curve the torque is on.
    slopes: Vec<f64>,
    /// The commanded accelerations there (rad/s²).
    qdd: Vec<f64>,
}

/// The grid's solves around the walk's node, solved ahead of it in time order with their own history of
/// directions, and the linearisations at every [`RELINEARIZE_KNOTS`]-th of them.
struct Grid {
    state: TrueState,
    visit: Visit,
    /// From the knot before the current node's grid interval on, in index order.
    knots: VecDeque<Knot>,
    /// The next knot to solve (`None` before the first).
    next: Option<i64>,
    /// The linearisations (knot index, matrices) from the last at or before the current node on.
    linear: VecDeque<(i64, Linear)>,
    /// Knots dropped behind the walk, their vectors reused by the next solves.
    spare: Vec<Knot>,
    /// The command at the knot being solved.
    point: PathPoint,
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
        path: &dyn Command,
        times: &[f64],
        noise: Option<&mut ChaCha8Rng>,
    ) -> Result<Vec<MotionSample>> {
        self.follow_stepped(path, times, Resolution::MEASURED, noise)
    }

    /// [`TrueRobot::follow`] at `resolution`.
    pub fn follow_stepped(
        &self,
        path: &dyn Command,
        times: &[f64],
        resolution: Resolution,
        mut noise: Option<&mut ChaCha8Rng>,
    ) -> Result<Vec<MotionSample>> {
        let Resolution { step_s, knot_s } = resolution;
        if !(step_s.is_finite() && step_s > 0.0 && knot_s.is_finite() && knot_s > 0.0) {
            return Err(Error::Invalid(format!(
                "motion: integration step {step_s} s and grid spacing {knot_s} s must be positive"
            )));
        }
        if let Some(t) = times.iter().find(|t| !t.is_finite()) {
            return Err(Error::Invalid(format!(
                "motion: sample time {t} s is not a finite number"
            )));
        }
        let mut order: Vec<usize> = (0..times.len()).collect();
        order.sort_by(|&a, &b| times[a].total_cmp(&times[b]));
        let damping = self.transmission_damping();
        let mut walk = Walk::new(self, path, &damping, knot_s);
        let mut reached: Vec<Option<Reached>> = (0..times.len()).map(|_| None).collect();
        let mut last: Option<f64> = None;
        for &i in &order {
            let target = times[i];
            if let Some(previous) = last {
                // Nodes between samples further apart than a step, evenly spaced.
                let gap = target - previous;
                let steps = (gap / step_s).ceil() as usize;
                for k in 1..steps {
                    walk.advance(previous + gap * k as f64 / steps as f64, false)?;
                }
            }
            walk.advance(target, true)?;
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
        workspaces: &mut [Workspace; 2],
        frames: &mut Frames,
    ) -> Linear {
        let n = self.chain.dof();
        // The passes' workspace, and the base pass's motion, which each column's pass shares up to its joint.
        let [ws, kept] = workspaces;
        let mut m = DMatrix::zeros(n, n);
        let mut c = DMatrix::zeros(n, n);
        let mut s = DMatrix::zeros(n, n);
        let (mut base, mut ahead) = (vec![0.0; n], vec![0.0; n]);
        let (chain, payload, gravity) = (&self.chain, &self.payload, &self.gravity);
        inverse_dynamics(
            chain,
            &state.frames,
            payload,
            gravity,
            qd,
            qdd,
            ws,
            &mut base,
        );
        kept.copy_motion_from(ws, n);
        // Forward differences: their error (a step's share of the curvature) is a millionth of the sensitivity,
        // below what the remainder needs.
        const RATE: f64 = 1e-3;
        const ANGLE: f64 = 1e-6;
        let (mut faster, mut q) = (qd.to_vec(), state.q.clone());
        // M and C on the state's frames first, each pass reusing the base pass's geometry; then S, whose passes
        // each have frames of their own.
        for j in 0..n {
            mass_matrix_column(chain, &state.frames, payload, j, ws, &mut ahead);
            m.column_mut(j).copy_from_slice(&ahead);
            faster.copy_from_slice(qd);
            faster[j] += RATE;
            ws.copy_motion_from(kept, j);
            inverse_dynamics_from(
                chain,
                &state.frames,
                payload,
                &faster,
                qdd,
                ws,
                &mut ahead,
                j,
            );
            for (i, (a, b)) in ahead.iter().zip(&base).enumerate() {
                c[(i, j)] = (a - b) / RATE;
            }
        }
        for j in 0..n {
            q.copy_from_slice(&state.q);
            q[j] += ANGLE;
            // Joint j's angle moves the frames from body j + 1 on: those before, and their geometry, are the
            // state's (the last column moved body j and joint j's frame; both are computed again).
            frames.body[j] = state.frames.body[j];
            self.kinematics_from(&q, &state.tilt, state.scale, frames, j);
            geometry_from(chain, frames, payload, ws, j);
            ws.copy_motion_from(kept, j);
            inverse_dynamics_from(chain, frames, payload, qd, qdd, ws, &mut ahead, j);
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
    /// The spacing of the grid's exact quasi-static solves (s).
    knot_s: f64,
    path: &'a dyn Command,
    damping: &'a [f64],
    /// The quasi-static solve at the last node solved exactly.
    state: TrueState,
    /// The static solve at the same command (for the dynamic part's size).
    still: TrueState,
    /// The direction each joint last moved in and the links' temperature, at the current node.
    visit: Visit,
    grid: Grid,
    remainder: Option<Remainder>,
    /// The quasi-static deflection and tilts at the current node (interpolated, then solved where exact).
    quasi_static: DVector<f64>,
    tilt: Vec<Vector3<f64>>,
    /// What the command's accelerations miss the grid's cubic by at the current node (rad/s²).
    accel: Vec<f64>,
    /// The linearisation at the current node, interpolated between the grid's.
    linear: Linear,
    /// The command at the current node.
    point: PathPoint,
    /// The linearisation's workspaces: its passes', its base pass's motion.
    ws: [Workspace; 2],
    frames: Frames,
}

/// The command at `t` into `p`, checked against the robot's joint count.
fn command(path: &dyn Command, n: usize, t: f64, p: &mut PathPoint) -> Result<()> {
    path.sample(t, p);
    if p.q.len() != n || p.qd.len() != n || p.qdd.len() != n {
        return Err(Error::Invalid(format!(
            "motion: the path gives {} angles at t = {t} s, the robot has {n} joints",
            p.q.len()
        )));
    }
    Ok(())
}

/// The links' temperature at time `t` (s), the unloaded angles at the command `p` and the link lengths: where
/// a quasi-static solve starts from.
fn unload(robot: &TrueRobot, t: f64, p: &PathPoint, visit: &mut Visit, state: &mut TrueState) {
    visit.temperature = robot
        .perturbation
        .thermal
        .as_ref()
        .map(|th| th.temperature_at(t));
    robot.unloaded_angles_after(&p.q, visit, &mut state.q0);
    state.scale = robot.length_scale(visit);
}

/// A joint at rest keeps the direction it last moved in.
fn turn(visit: &mut Visit, qd: &[f64]) {
    for (d, v) in visit.direction.iter_mut().zip(qd) {
        if *v != 0.0 {
            *d = v.signum();
        }
    }
}

impl Walk<'_> {
    fn new<'a>(
        robot: &'a TrueRobot,
        path: &'a dyn Command,
        damping: &'a [f64],
        knot_s: f64,
    ) -> Walk<'a> {
        let n = robot.chain.dof();
        let visit = || Visit {
            direction: vec![1.0; n],
            temperature: None,
        };
        let zeros = || DMatrix::zeros(n, n);
        Walk {
            robot,
            knot_s,
            path,
            damping,
            state: TrueState::new(robot),
            still: TrueState::new(robot),
            visit: visit(),
            grid: Grid {
                state: TrueState::new(robot),
                visit: visit(),
                knots: VecDeque::new(),
                next: None,
                linear: VecDeque::new(),
                spare: Vec::new(),
                point: PathPoint::default(),
            },
            remainder: None,
            quasi_static: DVector::zeros(n),
            tilt: vec![Vector3::zeros(); n],
            accel: vec![0.0; n],
            linear: Linear {
                m: zeros(),
                c: zeros(),
                s: zeros(),
            },
            point: PathPoint::default(),
            ws: [Workspace::new(&robot.chain), Workspace::new(&robot.chain)],
            frames: Frames::new(&robot.chain),
        }
    }

    /// Moves to time `t`: the quasi-static deflection there — from the grid's solves, or solved when `exact`
    /// or where the grid's cubic does not hold — then one trapezoidal step of the deflection.
    fn advance(&mut self, t: f64, exact: bool) -> Result<()> {
        let robot = self.robot;
        let n = robot.chain.dof();
        // Out of `self` while the grid is solved; put back below for the next node's reuse.
        let mut p = std::mem::take(&mut self.point);
        command(self.path, n, t, &mut p)?;
        turn(&mut self.visit, &p.qd);
        let here = (t / self.knot_s).floor() as i64;
        self.solve_through(here)?;
        let smooth = self.interpolate(t, here, &p.qdd);
        if exact || !smooth {
            let state = &mut self.state;
            unload(robot, t, &p, &mut self.visit, state);
            // From the grid's cubic: a fraction of the iterations.
            for ((q, q0), d) in state.q.iter_mut().zip(&state.q0).zip(&self.quasi_static) {
                *q = q0 - d;
            }
            state.tilt.copy_from_slice(&self.tilt);
            robot.deflect_from_guess(state, Some((&p.qd[..], &p.qdd[..])))?;
            for ((d, q0), q) in self.quasi_static.iter_mut().zip(&state.q0).zip(&state.q) {
                *d = q0 - q;
            }
        }
        self.interpolate_linear(t);
        match &mut self.remainder {
            None => {
                self.remainder = Some(Remainder {
                    t,
                    z: self.quasi_static.clone(),
                    v: DVector::zeros(n),
                    a: DVector::zeros(n),
                    scratch: Scratch {
                        x: DVector::zeros(n),
                        product: DVector::zeros(n),
                        rhs: DVector::zeros(n),
                        matrix: DMatrix::zeros(n, n),
                    },
                });
            }
            Some(r) => r.step(t, &self.quasi_static, &self.linear)?,
        }
        self.point = p;
        Ok(())
    }

    /// Solves the grid's knots a node in grid interval `here` needs: the two on each side of it and the next
    /// linearisation; drops those behind.
    fn solve_through(&mut self, here: i64) -> Result<()> {
        let linear_here = here.div_euclid(RELINEARIZE_KNOTS) * RELINEARIZE_KNOTS;
        let last = (here + 2).max(linear_here + RELINEARIZE_KNOTS);
        let mut next = *self.grid.next.get_or_insert((here - 1).min(linear_here));
        while next <= last {
            self.solve_knot(next)?;
            next += 1;
            self.grid.next = Some(next);
        }
        let grid = &mut self.grid;
        while grid.knots.front().is_some_and(|k| k.index < here - 1) {
            grid.spare.extend(grid.knots.pop_front());
        }
        while grid.linear.get(1).is_some_and(|l| l.0 <= linear_here) {
            grid.linear.pop_front();
        }
        Ok(())
    }

    /// The exact quasi-static solve at knot `index`, from the last knots' trend, and its linearisation on
    /// every [`RELINEARIZE_KNOTS`]-th knot.
    fn solve_knot(&mut self, index: i64) -> Result<()> {
        let robot = self.robot;
        let n = robot.chain.dof();
        let t = index as f64 * self.knot_s;
        let grid = &mut self.grid;
        command(self.path, n, t, &mut grid.point)?;
        let p = &grid.point;
        turn(&mut grid.visit, &p.qd);
        let state = &mut grid.state;
        unload(robot, t, p, &mut grid.visit, state);
        let motion = Some((&p.qd[..], &p.qdd[..]));
        let mut behind = grid.knots.iter().rev();
        match (behind.next(), behind.next()) {
            (Some(last), before) => {
                for (j, (q, q0)) in state.q.iter_mut().zip(&state.q0).enumerate() {
                    let d = last.quasi_static[j];
                    let ahead = before.map_or(0.0, |b| d - b.quasi_static[j]);
                    *q = q0 - d - ahead;
                }
                robot.deflect_from_guess(state, motion)?;
            }
            (None, _) => {
                robot.deflect_moving(state, motion)?;
            }
        }
        let mut knot = grid.spare.pop().unwrap_or_else(|| Knot {
            index,
            quasi_static: DVector::zeros(n),
            tilt: Vec::new(),
            direction: Vec::new(),
            slopes: Vec::new(),
            qdd: Vec::new(),
        });
        knot.index = index;
        for ((d, q0), q) in knot.quasi_static.iter_mut().zip(&state.q0).zip(&state.q) {
            *d = q0 - q;
        }
        knot.slopes.clear();
        knot.slopes
            .extend((0..n).map(|i| robot.tangent_stiffness(i, state.tau()[i])));
        for (to, from) in [
            (&mut knot.direction, &grid.visit.direction),
            (&mut knot.qdd, &p.qdd),
        ] {
            to.clear();
            to.extend_from_slice(from);
        }
        knot.tilt.clear();
        knot.tilt.extend_from_slice(&state.tilt);
        if index.rem_euclid(RELINEARIZE_KNOTS) == 0 {
            let linear = robot.linearize(
                state,
                &p.qd,
                &p.qdd,
                self.damping,
                &mut self.ws,
                &mut self.frames,
            );
            grid.linear.push_back((index, linear));
        }
        grid.knots.push_back(knot);
        Ok(())
    }

    /// The cubic through the four knots about `t` (grid interval `here`) into the quasi-static deflection and
    /// tilts of the node: whether it holds there, i.e. the four knots and the node move each joint in the same
    /// direction, load each spring on the same segment of its curve, and the same cubic gives the command's
    /// accelerations `qdd` at the node.
    fn interpolate(&mut self, t: f64, here: i64, qdd: &[f64]) -> bool {
        let u = t / self.knot_s - here as f64;
        // Lagrange's weights on the knots at −1, 0, 1, 2.
        let weights = [
            -u * (u - 1.0) * (u - 2.0) / 6.0,
            (u + 1.0) * (u - 1.0) * (u - 2.0) / 2.0,
            -(u + 1.0) * u * (u - 2.0) / 2.0,
            (u + 1.0) * u * (u - 1.0) / 6.0,
        ];
        let knots = self.grid.knots.range(..4);
        self.quasi_static.fill(0.0);
        self.tilt.fill(Vector3::zeros());
        let mut smooth = true;
        let accel = &mut self.accel;
        accel.copy_from_slice(qdd);
        for (knot, w) in knots.zip(weights) {
            for (a, b) in accel.iter_mut().zip(&knot.qdd) {
                *a -= w * b;
            }
            self.quasi_static.axpy(w, &knot.quasi_static, 1.0);
            for (out, tilt) in self.tilt.iter_mut().zip(&knot.tilt) {
                *out += tilt * w;
            }
            smooth &=
                knot.direction == self.visit.direction && knot.slopes == self.grid.knots[0].slopes;
        }
        smooth && accel.iter().all(|a| a.abs() <= ACCELERATION_TOL)
    }

    /// The grid's linearisations about `t`, interpolated linearly in time.
    fn interpolate_linear(&mut self, t: f64) {
        let [(ia, a), (ib, b)] = [&self.grid.linear[0], &self.grid.linear[1]];
        let w = (t / self.knot_s - *ia as f64) / (ib - ia) as f64;
        for (out, (a, b)) in [
            (&mut self.linear.m, (&a.m, &b.m)),
            (&mut self.linear.c, (&a.c, &b.c)),
            (&mut self.linear.s, (&a.s, &b.s)),
        ] {
            // Over the contiguous storage: nalgebra's element iterators cost more than the arithmetic.
            let (a, b) = (a.as_slice(), b.as_slice());
            for ((o, x), y) in out.as_mut_slice().iter_mut().zip(a).zip(b) {
                *o = x + w * (y - x);
            }
        }
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
    /// `S + C a₁ + M a₀` (each product whole before it is added): the bits of the allocating form (nalgebra's
    /// products), without its allocations but the LU's (nalgebra's, on a copy of the step's matrix).
    fn step(&mut self, t: f64, quasi_static: &DVector<f64>, linear: &Linear) -> Result<()> {
        let h = t - self.t;
        if h > 0.0 {
            let Linear { m, c, s } = linear;
            let Scratch {
                x,
                product,
                rhs,
                matrix,
            } = &mut self.scratch;
            let (a0, a1) = (4.0 / (h * h), 2.0 / h);
            rhs.gemv(1.0, s, quasi_static, 0.0);
            x.copy_from(&self.z);
            *x *= a0;
            x.axpy(4.0 / h, &self.v, 1.0);
            *x += &self.a;
            product.gemv(1.0, m, x, 0.0);
            *rhs += &*product;
            x.copy_from(&self.z);
            *x *= a1;
            *x += &self.v;
            product.gemv(1.0, c, x, 0.0);
            *rhs += &*product;
            for (((out, s), c), m) in matrix.iter_mut().zip(s.iter()).zip(c.iter()).zip(m.iter()) {
                *out = s + c * a1 + m * a0;
            }
            if !matrix.clone().lu().solve_mut(rhs) {
                return Err(singular(t));
            }
            for (((zi, old), v), a) in rhs
                .iter()
                .zip(self.z.iter_mut())
                .zip(self.v.iter_mut())
                .zip(self.a.iter_mut())
            {
                let d = zi - *old;
                *a = d * a0 - *v * (4.0 / h) - *a;
                *v = d * a1 - *v;
                *old = *zi;
            }
            self.t = t;
        }
        Ok(())
    }
}
