//! Numerical inverse kinematics of a tool frame on the flange, to a full 6-DOF pose.
//!
//! Damped least squares with Levenberg–Marquardt damping reaches the target from far away and becomes a
//! Gauss–Newton iteration near it, which is what takes the error down to 1e-11.
//!
//! Joint limits are not imposed while reaching: clamping the iterates creates false local minima at the
//! limits, from which most seeds of a target near the limits never escape. The iteration reaches the
//! solution manifold freely (revolute joints wrapped by 2π toward the middle of their range), and for a
//! redundant arm then *slides along* the manifold, in the Jacobian's null space, to bring every joint
//! back inside its limits (less the margin). What cannot be brought inside is rejected and the next seed
//! is tried.
//!
//! For a redundant arm (the iiwa's seven joints) the solution is a curve, not a point. The solver picks
//! the point of that curve nearest a *posture* (locally: a projected gradient flow in the null space,
//! `(I − J⁺J)·k·(q_posture − q)`), so a campaign controls the elbow through the posture and gets the same
//! elbow for the same target and posture. Null-space steps are taken separately, once the task is nearly
//! solved, alternating with pure task steps; mixing the two in one damped step would let the posture
//! disturb the task and stall the final convergence. They stop when the posture has settled, and the last
//! steps are pure Newton steps.
//!
//! The seed picks the inverse-kinematics branch (shoulder, elbow, wrist flips); the posture only moves the
//! arm within it. Random restarts (seeded, so reproducible) cover seeds that lead nowhere.

use nalgebra::{DVector, Isometry3, Matrix6, Matrix6xX, Point3, UnitQuaternion, Vector3, Vector6};
use rand_chacha::ChaCha8Rng;

use super::chain::{Chain, JointKind, sample_within};
use super::kinematics::{Frames, forward_kinematics, point_jacobian_into};

#[derive(Clone, Debug, PartialEq)]
pub struct IkOptions {
    /// Iteration budget of one attempt (one seed); a solve costs at most `(restarts + 1) * max_iters`.
    pub max_iters: usize,
    /// m
    pub tol_position: f64,
    /// rad
    pub tol_rotation: f64,
    /// Extra random seeds tried after the given seed fails.
    pub restarts: usize,
    /// Fraction of the null-space-projected posture error removed by the first posture step (later ones
    /// adapt); 0 turns the posture off.
    pub posture_gain: f64,
    /// rad (or m for a prismatic joint): a solution closer than this to a limit is rejected.
    pub limit_margin: f64,
}

impl Default for IkOptions {
    fn default() -> Self {
        IkOptions {
            max_iters: 200,
            tol_position: 1e-11,
            tol_rotation: 1e-11,
            restarts: 10,
            posture_gain: 0.5,
            // A real controller stops short of the hard limits; about half a degree keeps campaign poses
            // commandable on the robot.
            limit_margin: 1e-2,
        }
    }
}

#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum IkError {
    #[error(
        "inverse kinematics did not converge (best residual {position_error:.3e} m, {rotation_error:.3e} rad)"
    )]
    NotConverged {
        position_error: f64,
        rotation_error: f64,
    },
    #[error("the target is reached only outside or within the margin of the joint limits")]
    JointLimits,
}

#[derive(Clone, Debug, PartialEq)]
pub struct IkSolution {
    pub q: Vec<f64>,
    /// m, at `q`
    pub position_error: f64,
    /// rad, at `q`
    pub rotation_error: f64,
    /// Summed over all attempts: the cost of the solve.
    pub iterations: usize,
    /// Seeds tried, 1 when the given seed succeeded.
    pub attempts: usize,
}

/// Residual below which null-space steps start (combined norm of m and rad): farther out the arm is not
/// yet on the target's self-motion manifold, so steering along it is wasted.
const NEAR: f64 = 1e-3;
/// The null-space motion has settled when a step moves no joint by more than this (rad): it fixes the
/// elbow far below anything a tracker can see, and is well above the round-off floor of the step.
const NULL_SETTLED: f64 = 1e-9;
/// Projected posture gradients (rad) below which the secant update of the posture boost stops: there the
/// gradients are round-off and their ratio is noise.
const SECANT_FLOOR: f64 = 1e-8;
/// Joints are brought this far inside the margin, so that the last Newton steps (which ignore limits
/// and move by ~1e-9) cannot push them back into it.
const CLEARANCE: f64 = 1e-6;
/// A joint whose null-space share (the diagonal of `I − J⁺J`) is below this cannot be moved back inside
/// its limits along the self-motion manifold; the attempt is given up.
const REPAIR_MIN_SHARE: f64 = 1e-6;
/// Largest joint motion of one step (rad); damping alone lets a near-singular first step fly off.
const MAX_STEP: f64 = 0.5;
const LAMBDA_INIT: f64 = 1e-3;
/// Small enough that the last steps are Newton steps (contraction λ/σ² ≈ 1e-10 for the iiwa), large
/// enough to keep the 6×6 system positive definite for chains with fewer than six joints.
const LAMBDA_MIN: f64 = 1e-12;
const LAMBDA_MAX: f64 = 1e8;
/// Damping of the null-space projector: nearly exact, so null-space steps barely move the tool.
const LAMBDA_NULL: f64 = 1e-12;
/// An attempt that has not quartered its squared residual for this many iterations is at a local minimum.
const STALL_ITERS: usize = 20;

/// Reusable workspace: one per thread, reused across thousands of solves without allocating.
#[derive(Clone, Debug)]
pub struct IkSolver {
    opts: IkOptions,
    frames: Frames,
    jac: Matrix6xX<f64>,
    q: DVector<f64>,
    trial: DVector<f64>,
    dq: DVector<f64>,
    z: DVector<f64>,
    posture: DVector<f64>,
    /// Previous unboosted posture gradient, for the secant update, if the last step was a clean one.
    grad_prev: DVector<f64>,
    grad_prev_valid: bool,
    boost: f64,
}

enum Outcome {
    Converged,
    Failed,
}

impl IkSolver {
    pub fn new(chain: &Chain, opts: IkOptions) -> Self {
        let n = chain.dof();
        IkSolver {
            opts,
            frames: Frames::new(chain),
            jac: Matrix6xX::zeros(n),
            q: DVector::zeros(n),
            trial: DVector::zeros(n),
            dq: DVector::zeros(n),
            z: DVector::zeros(n),
            posture: DVector::zeros(n),
            grad_prev: DVector::zeros(n),
            grad_prev_valid: false,
            boost: 1.0,
        }
    }

    pub fn options(&self) -> &IkOptions {
        &self.opts
    }

    /// target: desired world pose of `tool` (a frame given in the flange frame; identity = flange).
    /// seed: first starting configuration; posture: null-space target (None = seed). Random restarts
    /// are drawn from `rng` within the limits, and only when an attempt fails, so a solve that succeeds
    /// first time leaves `rng` untouched.
    ///
    /// # Panics
    /// If `seed` or `posture` does not have one value per joint (a caller bug, as in
    /// [`forward_kinematics`]).
    pub fn solve(
        &mut self,
        chain: &Chain,
        target: &Isometry3<f64>,
        tool: &Isometry3<f64>,
        seed: &[f64],
        posture: Option<&[f64]>,
        rng: &mut ChaCha8Rng,
    ) -> Result<IkSolution, IkError> {
        let n = chain.dof();
        assert_eq!(seed.len(), n, "seed length must equal the chain's dof");
        let posture = posture.unwrap_or(seed);
        assert_eq!(
            posture.len(),
            n,
            "posture length must equal the chain's dof"
        );
        if self.q.len() != n {
            *self = IkSolver::new(chain, self.opts.clone());
        }
        let finite = |p: &Isometry3<f64>| {
            p.translation.vector.iter().all(|v| v.is_finite())
                && p.rotation.coords.iter().all(|v| v.is_finite())
        };
        if !finite(target) || !finite(tool) || !seed.iter().chain(posture).all(|v| v.is_finite()) {
            return Err(IkError::NotConverged {
                position_error: f64::NAN,
                rotation_error: f64::NAN,
            });
        }
        self.posture.copy_from_slice(posture);

        let margin = self.opts.limit_margin.max(0.0);
        let mut iterations = 0;
        let mut best = (f64::INFINITY, f64::INFINITY);
        let mut near_limit = false;
        for attempt in 0..=self.opts.restarts {
            if attempt == 0 {
                self.q.copy_from_slice(seed);
            } else {
                for (qi, j) in self.q.iter_mut().zip(&chain.joints) {
                    *qi = sample_within(j.lower + margin, j.upper - margin, rng);
                }
            }
            let (outcome, iters) = self.attempt(chain, target, tool);
            iterations += iters;
            let (pe, re) = pose_error(target, &(self.frames.flange * tool));
            match outcome {
                Outcome::Converged => {
                    let clear = chain
                        .joints
                        .iter()
                        .zip(self.q.iter())
                        .all(|(j, &v)| v >= j.lower + margin && v <= j.upper - margin);
                    if clear {
                        return Ok(IkSolution {
                            q: self.q.as_slice().to_vec(),
                            position_error: pe,
                            rotation_error: re,
                            iterations,
                            attempts: attempt + 1,
                        });
                    }
                    near_limit = true;
                }
                Outcome::Failed => {
                    if pe.hypot(re) < best.0.hypot(best.1) {
                        best = (pe, re);
                    }
                }
            }
        }
        if near_limit {
            Err(IkError::JointLimits)
        } else {
            Err(IkError::NotConverged {
                position_error: best.0,
                rotation_error: best.1,
            })
        }
    }

    /// One seed, from `self.q`. Leaves the last iterate in `self.q` and its frames in `self.frames`.
    fn attempt(
        &mut self,
        chain: &Chain,
        target: &Isometry3<f64>,
        tool: &Isometry3<f64>,
    ) -> (Outcome, usize) {
        let (max_iters, tol_p, tol_r) = (
            self.opts.max_iters,
            self.opts.tol_position,
            self.opts.tol_rotation,
        );
        let converged = |e: &Vector6<f64>| {
            e.fixed_rows::<3>(0).norm() <= tol_p && e.fixed_rows::<3>(3).norm() <= tol_r
        };
        // Null-space steps stop in time to leave Newton steps for the final convergence.
        let null_budget = max_iters - max_iters / 4;
        let mut null_on = true;
        self.grad_prev_valid = false;
        self.boost = 1.0;
        let mut lambda = LAMBDA_INIT;
        wrap_revolute(chain, &mut self.q);
        let mut e = self.residual(chain, target, tool);
        let mut f = e.norm_squared();
        let mut f_ref = f;
        let mut since_progress = 0;

        for iter in 0..max_iters {
            if iter >= null_budget {
                null_on = false;
            }
            if converged(&e) && !null_on {
                return (Outcome::Converged, iter);
            }
            let near = f.sqrt() < NEAR;
            self.jacobian(chain, tool);

            if near && null_on {
                let (_, settled) = self.null_step(chain);
                if settled {
                    null_on = false;
                }
                e = self.residual(chain, target, tool);
                f = e.norm_squared();
                if converged(&e) {
                    continue;
                }
                self.jacobian(chain, tool);
            }

            // Task step: Levenberg–Marquardt, retried with more damping until it reduces the residual.
            loop {
                if self.task_step(&e, lambda) {
                    self.trial.copy_from(&self.q);
                    self.trial += &self.dq;
                    wrap_revolute(chain, &mut self.trial);
                    forward_kinematics(chain, self.trial.as_slice(), &mut self.frames);
                    let e_trial = residual_of(target, &(self.frames.flange * tool));
                    let f_trial = e_trial.norm_squared();
                    if f_trial < f {
                        std::mem::swap(&mut self.q, &mut self.trial);
                        e = e_trial;
                        f = f_trial;
                        lambda = (lambda * 0.1).max(LAMBDA_MIN);
                        break;
                    }
                }
                lambda *= 10.0;
                if lambda > LAMBDA_MAX {
                    forward_kinematics(chain, self.q.as_slice(), &mut self.frames);
                    return (Outcome::Failed, iter + 1);
                }
            }

            if f < 0.25 * f_ref {
                f_ref = f;
                since_progress = 0;
            } else if !near {
                since_progress += 1;
                if since_progress > STALL_ITERS {
                    return (Outcome::Failed, iter + 1);
                }
            }
        }
        let outcome = if converged(&e) {
            Outcome::Converged
        } else {
            Outcome::Failed
        };
        (outcome, max_iters)
    }

    /// Forward kinematics at `self.q` and the residual there.
    fn residual(
        &mut self,
        chain: &Chain,
        target: &Isometry3<f64>,
        tool: &Isometry3<f64>,
    ) -> Vector6<f64> {
        forward_kinematics(chain, self.q.as_slice(), &mut self.frames);
        residual_of(target, &(self.frames.flange * tool))
    }

    /// Jacobian of the tool frame at the frames in `self.frames`.
    fn jacobian(&mut self, chain: &Chain, tool: &Isometry3<f64>) {
        let point = Point3::from((self.frames.flange * tool).translation.vector);
        point_jacobian_into(chain, &self.frames, &point, &mut self.jac);
    }

    /// Damped least-squares step `dq = Jᵀ (J Jᵀ + λI)⁻¹ e` into `self.dq`. The 6×6 form is used whatever
    /// the dof: it equals `(JᵀJ + λI)⁻¹ Jᵀ e` and stays allocation-free. False if the system could not be
    /// factored or the step is not finite (the caller then raises λ).
    fn task_step(&mut self, e: &Vector6<f64>, lambda: f64) -> bool {
        let Some(chol) = gram(&self.jac, lambda).cholesky() else {
            return false;
        };
        let y = chol.solve(e);
        self.dq.gemv_tr(1.0, &self.jac, &y, 0.0);
        limit_step(&mut self.dq);
        self.dq.iter().all(|v| v.is_finite())
    }

    /// One null-space step from `self.q` (using `self.jac` there, which it overwrites). A joint outside
    /// its bounds (the limits less margin and clearance) is brought back first, the worst one, exactly to
    /// first order; with every joint inside, the arm moves toward the posture. Joints on a bound that the
    /// motion would push outward are held (their columns leave the projector), and the step stops where
    /// another joint meets its bound. Returns the largest joint motion and whether the step the solver
    /// wanted (before being cut short at a bound) was negligible.
    fn null_step(&mut self, chain: &Chain) -> (f64, bool) {
        let inset = self.opts.limit_margin.max(0.0) + CLEARANCE;
        let bounds = |j: usize| joint_bounds(chain, inset, j);
        let worst = self.worst_violation(&bounds);
        let repair = worst.1 != 0.0;
        if repair {
            self.z.fill(0.0);
            self.z[worst.0] = worst.1;
        } else if self.opts.posture_gain > 0.0 {
            self.z.copy_from(&self.posture);
            self.z -= &self.q;
            self.z *= self.opts.posture_gain;
        } else {
            return (0.0, true);
        }
        // The joint being repaired moves by its own share, whatever its bounds say.
        let repaired = repair.then_some(worst.0);

        let Some(held_any) = self.project_holding(&bounds, repaired) else {
            return (0.0, true);
        };

        if repair {
            // Scaled by its own share of the motion, the step moves the joint by exactly `delta`.
            let share = self.dq[worst.0] / worst.1;
            self.grad_prev_valid = false;
            self.boost = 1.0;
            if share.is_nan() || share < REPAIR_MIN_SHARE {
                return (0.0, true);
            }
            self.dq /= share;
        } else {
            self.boost_posture_step(held_any);
        }
        let clipped = limit_step(&mut self.dq);
        let wanted = self.dq.amax();

        let alpha = self.room(&bounds, repaired);
        self.dq *= alpha;
        for i in 0..self.q.len() {
            let (lo, hi) = bounds(i);
            let inside = lo <= self.q[i] && self.q[i] <= hi;
            self.q[i] += self.dq[i];
            if inside {
                self.q[i] = self.q[i].clamp(lo, hi);
            }
        }
        // A step cut short says nothing about the curvature; the next ratio must not use it.
        self.grad_prev_valid = !(repair || held_any || clipped || alpha < 1.0);
        (self.dq.amax(), wanted <= NULL_SETTLED)
    }

    /// The joint furthest outside its bounds and the signed motion that brings it back; `(0, 0.0)` when every
    /// joint is inside.
    fn worst_violation(&self, bounds: &impl Fn(usize) -> (f64, f64)) -> (usize, f64) {
        let mut worst = (0, 0.0_f64);
        for i in 0..self.q.len() {
            let (lo, hi) = bounds(i);
            let delta = self.q[i].clamp(lo, hi) - self.q[i];
            if delta.abs() > worst.1.abs() {
                worst = (i, delta);
            }
        }
        worst
    }

    /// Projected motion `(I − J⁺J) z` into `self.dq`, with an active set of held joints: a joint on a bound that
    /// the motion would push outward (other than `repaired`) is held, its column of `self.jac` and its share of
    /// `self.z` zeroed, and the projection repeated. Whether any joint is held; `None` if the projector could
    /// not be factored.
    fn project_holding(
        &mut self,
        bounds: &impl Fn(usize) -> (f64, f64),
        repaired: Option<usize>,
    ) -> Option<bool> {
        let n = self.q.len();
        let mut held_any = false;
        for _ in 0..=n {
            let chol = gram(&self.jac, LAMBDA_NULL).cholesky()?;
            let mut jz = Vector6::zeros();
            jz.gemv(1.0, &self.jac, &self.z, 0.0);
            let y = chol.solve(&jz);
            self.dq.copy_from(&self.z);
            self.dq.gemv_tr(-1.0, &self.jac, &y, 1.0);
            let mut newly_held = false;
            for i in 0..n {
                if repaired == Some(i) {
                    continue;
                }
                let (lo, hi) = bounds(i);
                let (qi, di) = (self.q[i], self.dq[i]);
                if ((qi <= lo && di < 0.0) || (qi >= hi && di > 0.0))
                    && self.jac.column(i).amax() > 0.0
                {
                    self.z[i] = 0.0;
                    self.jac.column_mut(i).fill(0.0);
                    newly_held = true;
                }
            }
            held_any |= newly_held;
            if !newly_held {
                break;
            }
        }
        Some(held_any)
    }

    /// Scales the posture step in `self.dq` by the boost, after updating the boost from the previous step's
    /// gradient when that step was a clean one and no joint is `held_any` now.
    fn boost_posture_step(&mut self, held_any: bool) {
        // The plain projected step converges linearly, and slowly when the posture is far from the
        // self-motion manifold (the posture distance is then flat along it: rates of 0.9 per step on
        // the iiwa). The boost is a secant estimate of the inverse curvature along the manifold:
        // successive gradients shrink by 1 − boost·k·h, and boost ← boost / (1 − ratio) turns the
        // next step into a Newton step toward the same point. Bounded so that one noisy ratio cannot
        // run away.
        if self.grad_prev_valid && !held_any {
            let prev = self.grad_prev.norm_squared();
            if prev > SECANT_FLOOR * SECANT_FLOOR {
                let ratio = (self.dq.dot(&self.grad_prev) / prev).clamp(-4.0, 0.95);
                self.boost = (self.boost / (1.0 - ratio)).clamp(0.05, 1e3);
            }
        }
        self.grad_prev.copy_from(&self.dq);
        self.dq *= self.boost;
    }

    /// The fraction of `self.dq` that stops where a joint inside its bounds meets one (1 when none does); the
    /// joint being `repaired` and joints already outside do not limit it.
    fn room(&self, bounds: &impl Fn(usize) -> (f64, f64), repaired: Option<usize>) -> f64 {
        let mut alpha = 1.0_f64;
        for i in 0..self.q.len() {
            let (lo, hi) = bounds(i);
            let (qi, di) = (self.q[i], self.dq[i]);
            if repaired == Some(i) || qi < lo || qi > hi {
                continue;
            }
            let room = if di > 0.0 { hi - qi } else { qi - lo };
            if di.abs() * alpha > room {
                alpha = room / di.abs();
            }
        }
        alpha
    }
}

/// Joint `j`'s bounds: its limits less `inset` on each side, or their midpoint when the range is narrower
/// than that.
fn joint_bounds(chain: &Chain, inset: f64, j: usize) -> (f64, f64) {
    let (lo, hi) = (chain.joints[j].lower + inset, chain.joints[j].upper - inset);
    if lo <= hi {
        (lo, hi)
    } else {
        (0.5 * (lo + hi), 0.5 * (lo + hi))
    }
}

/// `J Jᵀ + λI` without forming `Jᵀ` (which would allocate). Each entry sums the joints in ascending order from
/// zero, as nalgebra's `row(r).dot(&row(c))` does (its eight-way partial sums stay zero on a single row), all
/// 21 entries in one pass over the columns instead of 21 passes over strided rows.
fn gram(jac: &Matrix6xX<f64>, lambda: f64) -> Matrix6<f64> {
    let mut sums = [[0.0_f64; 6]; 6];
    for col in jac.as_slice().chunks_exact(6) {
        let col: &[f64; 6] = col.try_into().expect("a column has six rows");
        for r in 0..6 {
            for c in 0..=r {
                sums[r][c] += col[r] * col[c];
            }
        }
    }
    let mut a = Matrix6::from_diagonal_element(lambda);
    for r in 0..6 {
        for c in 0..=r {
            a[(r, c)] += sums[r][c];
            if r != c {
                a[(c, r)] += sums[r][c];
            }
        }
    }
    a
}

/// True if the step was shortened.
fn limit_step(dq: &mut DVector<f64>) -> bool {
    let largest = dq.amax();
    let clip = largest > MAX_STEP;
    if clip {
        *dq *= MAX_STEP / largest;
    }
    clip
}

/// Moves each revolute joint by a multiple of 2π to the value nearest the middle of its range (the pose
/// is unchanged), so that a solution found outside the range but equivalent to one inside is not lost.
/// Joints with a range of 2π or more (continuous ones) are left alone: any value is as good.
fn wrap_revolute(chain: &Chain, q: &mut DVector<f64>) {
    use std::f64::consts::TAU;
    for (qi, j) in q.iter_mut().zip(&chain.joints) {
        if j.kind == JointKind::Revolute && j.upper - j.lower < TAU {
            let mid = 0.5 * (j.lower + j.upper);
            *qi -= TAU * ((*qi - mid) / TAU).round();
        }
    }
}

/// World-frame residual `[p_target − p; log(R_target Rᵀ)]`: the twist that would carry the current
/// pose onto the target, to first order.
fn residual_of(target: &Isometry3<f64>, current: &Isometry3<f64>) -> Vector6<f64> {
    let dp = target.translation.vector - current.translation.vector;
    let dr = rotation_log(&(target.rotation * current.rotation.inverse()));
    Vector6::new(dp.x, dp.y, dp.z, dr.x, dr.y, dr.z)
}

/// Rotation vector of a unit quaternion, accurate down to round-off. nalgebra's `angle()` goes through
/// `acos(w)`, which cannot resolve angles below about 3e-8 rad — far above the 1e-11 tolerance.
fn rotation_log(q: &UnitQuaternion<f64>) -> Vector3<f64> {
    let (w, v) = (q.quaternion().w, q.quaternion().imag());
    let (w, v) = if w < 0.0 { (-w, -v) } else { (w, v) };
    let s = v.norm();
    if s == 0.0 {
        Vector3::zeros()
    } else {
        v * (2.0 * s.atan2(w) / s)
    }
}

/// Distance (m) and rotation angle (rad) between two poses, accurate to round-off (see `rotation_log`).
pub fn pose_error(target: &Isometry3<f64>, actual: &Isometry3<f64>) -> (f64, f64) {
    let e = residual_of(target, actual);
    (e.fixed_rows::<3>(0).norm(), e.fixed_rows::<3>(3).norm())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robot::kinematics::flange_pose;
    use crate::robot::urdf::load_str;
    use rand::{Rng, SeedableRng};
    use std::f64::consts::FRAC_PI_2;

    /// The iiwa 7 R800 from its standard DH table (a = 0): joint i's origin is Tz(d_{i−1}) Rx(α_{i−1}).
    fn iiwa_dh_urdf() -> String {
        let d = [0.34, 0.0, 0.40, 0.0, 0.40, 0.0, 0.126];
        let alpha = [
            -FRAC_PI_2, FRAC_PI_2, FRAC_PI_2, -FRAC_PI_2, -FRAC_PI_2, FRAC_PI_2, 0.0,
        ];
        let limits_deg = [170.0, 120.0, 170.0, 120.0, 170.0, 120.0, 175.0_f64];
        let mut s = String::from("<robot name=\"iiwa_dh\">\n<link name=\"link0\"/>\n");
        for i in 0..7 {
            let (z, roll) = if i == 0 {
                (0.0, 0.0)
            } else {
                (d[i - 1], alpha[i - 1])
            };
            let lim = limits_deg[i].to_radians();
            s += &format!(
                "<link name=\"link{}\"/>\n<joint name=\"j{}\" type=\"revolute\"><parent link=\"link{}\"/>\
                 <child link=\"link{}\"/><origin xyz=\"0 0 {z}\" rpy=\"{roll} 0 0\"/><axis xyz=\"0 0 1\"/>\
                 <limit lower=\"{}\" upper=\"{}\" effort=\"100\" velocity=\"1\"/></joint>\n",
                i + 1,
                i + 1,
                i,
                i + 1,
                -lim,
                lim
            );
        }
        s += &format!(
            "<link name=\"flange\"/>\n<joint name=\"jf\" type=\"fixed\"><parent link=\"link7\"/>\
             <child link=\"flange\"/><origin xyz=\"0 0 {}\" rpy=\"{} 0 0\"/></joint>\n</robot>\n",
            d[6], alpha[6]
        );
        s
    }

    /// The hand-written Gram matrix has the bits of nalgebra's row dot products.
    #[test]
    fn gram_matches_nalgebra_bit_for_bit() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for n in [1, 6, 7, 9] {
            let jac = Matrix6xX::from_fn(n, |_, _| {
                rng.random_range(-2.0..2.0) * 10f64.powi(rng.random_range(-8..3))
            });
            let lambda = 1e-3;
            let mut expected = Matrix6::from_diagonal_element(lambda);
            for r in 0..6 {
                for c in 0..=r {
                    let v = jac.row(r).dot(&jac.row(c));
                    expected[(r, c)] += v;
                    if r != c {
                        expected[(c, r)] += v;
                    }
                }
            }
            let got = gram(&jac, lambda);
            assert!(
                got.iter()
                    .zip(expected.iter())
                    .all(|(a, b)| a.to_bits() == b.to_bits()),
                "{n}"
            );
        }
    }

    fn iiwa_dh() -> Chain {
        load_str(&iiwa_dh_urdf(), "inline iiwa DH", Some("flange")).expect("inline URDF loads")
    }

    fn iiwa_urdf() -> Option<Chain> {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("robots/iiwa7.urdf");
        path.exists()
            .then(|| crate::robot::urdf::load_file(&path, None).expect("robots/iiwa7.urdf loads"))
    }

    fn random_config(chain: &Chain, inset: f64, rng: &mut ChaCha8Rng) -> Vec<f64> {
        chain
            .joints
            .iter()
            .map(|j| rng.random_range(j.lower + inset..=j.upper - inset))
            .collect()
    }

    fn home_with_noise(n: usize, rng: &mut ChaCha8Rng) -> Vec<f64> {
        (0..n).map(|_| rng.random_range(-0.2..=0.2)).collect()
    }

    fn tool() -> Isometry3<f64> {
        Isometry3::new(
            Vector3::new(0.03, -0.02, 0.15),
            Vector3::new(0.2, -0.1, 0.3),
        )
    }

    /// Success rate without and with restarts, and the worst error of the successes.
    fn round_trip(chain: &Chain, cases: usize) {
        let opts = IkOptions::default();
        let inset = opts.limit_margin + 0.02;
        let mut no_restart = IkSolver::new(
            chain,
            IkOptions {
                restarts: 0,
                ..opts.clone()
            },
        );
        let mut with_restarts = IkSolver::new(chain, opts);
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let tool = tool();
        let (mut ok_first, mut ok_all, mut iters, mut attempts) = (0, 0, 0, 0);
        for _ in 0..cases {
            let q_true = random_config(chain, inset, &mut rng);
            let target = flange_pose(chain, &q_true) * tool;
            let seed = home_with_noise(chain.dof(), &mut rng);
            let check = |sol: &IkSolution| {
                assert!(chain.within_limits(&sol.q));
                let (pe, re) = pose_error(&target, &(flange_pose(chain, &sol.q) * tool));
                assert!(pe <= 1e-9 && re <= 1e-9, "{pe:e} m, {re:e} rad");
            };
            if let Ok(sol) = no_restart.solve(chain, &target, &tool, &seed, None, &mut rng) {
                check(&sol);
                ok_first += 1;
            }
            let sol = with_restarts
                .solve(chain, &target, &tool, &seed, None, &mut rng)
                .unwrap_or_else(|e| panic!("{e} for q = {q_true:?}"));
            check(&sol);
            iters += sol.iterations;
            attempts += sol.attempts;
            ok_all += 1;
        }
        eprintln!(
            "{}: {ok_first}/{cases} without restarts, {ok_all}/{cases} with; {:.1} iterations, {:.2} attempts per solve",
            chain.name,
            iters as f64 / cases as f64,
            attempts as f64 / cases as f64
        );
        assert!(
            ok_first * 100 >= cases * 95,
            "{ok_first}/{cases} without restarts"
        );
        assert_eq!(ok_all, cases);
    }

    #[test]
    fn ik_round_trip_dh_chain() {
        round_trip(&iiwa_dh(), 300);
    }

    #[test]
    fn ik_round_trip_iiwa_urdf() {
        if let Some(chain) = iiwa_urdf() {
            round_trip(&chain, 300);
        }
    }

    #[test]
    fn ik_unreachable_target_is_not_converged() {
        let chain = iiwa_dh();
        let mut solver = IkSolver::new(&chain, IkOptions::default());
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let target = Isometry3::translation(2.0, 0.0, 0.5);
        let seed = vec![0.1; 7];
        match solver.solve(
            &chain,
            &target,
            &Isometry3::identity(),
            &seed,
            None,
            &mut rng,
        ) {
            Err(IkError::NotConverged { position_error, .. }) => {
                // The arm reaches about 1.27 m from the shoulder at 0.34 m height.
                assert!(position_error > 0.5, "{position_error}");
            }
            other => panic!("expected NotConverged, got {other:?}"),
        }
        let nan = Isometry3::translation(f64::NAN, 0.0, 0.5);
        assert!(matches!(
            solver.solve(&chain, &nan, &Isometry3::identity(), &seed, None, &mut rng),
            Err(IkError::NotConverged { .. })
        ));
    }

    #[test]
    fn ik_posture_moves_the_elbow() {
        let chain = iiwa_dh();
        let mut solver = IkSolver::new(&chain, IkOptions::default());
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let q0 = [0.3, 0.7, 0.0, -1.2, 0.2, 0.8, 0.1];
        let tool = tool();
        let target = flange_pose(&chain, &q0) * tool;
        let mut q3 = Vec::new();
        for p3 in [-1.0, -0.5, 0.0, 0.5, 1.0] {
            let mut posture = q0;
            posture[2] = p3;
            let sol = solver
                .solve(&chain, &target, &tool, &q0, Some(&posture), &mut rng)
                .expect("reachable");
            assert_eq!(sol.attempts, 1);
            let (pe, re) = pose_error(&target, &(flange_pose(&chain, &sol.q) * tool));
            assert!(pe <= 1e-9 && re <= 1e-9, "{pe:e} m, {re:e} rad");
            // At the posture optimum, q − posture is orthogonal to the self-motion (J's null space).
            forward_kinematics(&chain, &sol.q, &mut solver.frames);
            let point = Point3::from((solver.frames.flange * tool).translation.vector);
            let jac = crate::robot::kinematics::point_jacobian(&chain, &solver.frames, &point);
            let pinv = jac.clone().pseudo_inverse(1e-12).unwrap();
            let diff = DVector::from_column_slice(&sol.q) - DVector::from_column_slice(&posture);
            let off_optimum = &diff - &pinv * (&jac * &diff);
            assert!(off_optimum.norm() < 1e-8, "{}", off_optimum.norm());
            q3.push(sol.q[2]);
        }
        for w in q3.windows(2) {
            assert!(
                w[1] > w[0] + 0.1,
                "elbow does not follow the posture: {q3:?}"
            );
        }
    }

    #[test]
    fn ik_is_deterministic() {
        let chain = iiwa_dh();
        let tool = tool();
        let run = || {
            let mut solver = IkSolver::new(&chain, IkOptions::default());
            let mut rng = ChaCha8Rng::seed_from_u64(11);
            let (mut bits, mut restarted) = (Vec::new(), 0);
            for _ in 0..60 {
                let q = random_config(&chain, 0.1, &mut rng);
                let target = flange_pose(&chain, &q) * tool;
                // A seed on the limits and a posture beyond them, so that some solves need restarts.
                let seed: Vec<f64> = chain.joints.iter().map(|j| j.upper).collect();
                let posture: Vec<f64> = chain.joints.iter().map(|j| j.upper + 1.0).collect();
                let sol = solver
                    .solve(&chain, &target, &tool, &seed, Some(&posture), &mut rng)
                    .unwrap();
                bits.extend(sol.q.iter().map(|v| v.to_bits()));
                bits.push(sol.attempts as u64);
                restarted += usize::from(sol.attempts > 1);
            }
            (bits, restarted)
        };
        let (first, restarted) = run();
        assert!(
            restarted >= 3,
            "only {restarted} solves used random restarts"
        );
        assert_eq!(first, run().0);
    }

    #[test]
    fn ik_solution_on_the_margin_is_joint_limits() {
        // Planar 2R arm: a full pose fixes both joints, so the only solution is the one we put near a limit.
        let urdf = r#"<robot name="planar2">
            <link name="a"/><link name="b"/><link name="c"/><link name="tip"/>
            <joint name="j1" type="revolute"><parent link="a"/><child link="b"/>
              <axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
            <joint name="j2" type="revolute"><parent link="b"/><child link="c"/><origin xyz="0.5 0 0"/>
              <axis xyz="0 0 1"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
            <joint name="jt" type="fixed"><parent link="c"/><child link="tip"/><origin xyz="0.4 0 0"/></joint>
        </robot>"#;
        let chain = load_str(urdf, "planar2", Some("tip")).unwrap();
        let opts = IkOptions {
            limit_margin: 0.01,
            restarts: 3,
            ..IkOptions::default()
        };
        let mut solver = IkSolver::new(&chain, opts);
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let id = Isometry3::identity();
        let near = flange_pose(&chain, &[0.995, 0.4]);
        assert_eq!(
            solver.solve(&chain, &near, &id, &[0.0, 0.0], None, &mut rng),
            Err(IkError::JointLimits)
        );
        let clear = flange_pose(&chain, &[0.9, 0.4]);
        let sol = solver
            .solve(&chain, &clear, &id, &[0.0, 0.0], None, &mut rng)
            .unwrap();
        assert!((sol.q[0] - 0.9).abs() < 1e-9 && (sol.q[1] - 0.4).abs() < 1e-9);
    }

    #[test]
    fn ik_rotation_log_resolves_tiny_angles() {
        let axis = Vector3::new(0.3, -0.5, 0.8).normalize();
        for angle in [1e-14, 1e-11, 1e-6, 1.0, 3.0] {
            let r = UnitQuaternion::from_scaled_axis(axis * angle);
            let v = rotation_log(&r);
            assert!(
                (v - axis * angle).norm() <= 1e-15 * angle.max(1.0),
                "{angle}: {v:?}"
            );
        }
    }
}
