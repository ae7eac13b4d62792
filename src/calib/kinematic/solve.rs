//! Levenberg–Marquardt on the kinematic problem, in whitened coordinates.

use std::cell::Cell;

use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt, TerminationReason};
use nalgebra::{DMatrix, DVector, Dyn, Owned};
use serde::{Deserialize, Serialize};

use super::problem::Problem;
use crate::calib::reduced::{Reduced, gram, reduce, reduce_gram};

/// How the minimization ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Termination {
    /// The residuals are orthogonal to every Jacobian column to [`LM_GTOL`].
    Gradient,
    /// The trust region shrank below [`LM_XTOL`] of the (scaled) correction.
    Step,
    /// Actual and predicted relative reductions of the sum of squares are below [`LM_FTOL`].
    Objective,
}

/// Convergence tolerances of [`minimize`] (the crate's `gtol`, `xtol`, `ftol`), relative. The run stops where
/// a step's actual and predicted reductions of ‖r‖² are both below `LM_FTOL` of it: the sum of squares is
/// then within about that share of its minimum, i.e. the answer within about `√LM_FTOL·‖r‖` of the exact
/// one in the whitened coordinates, where a standard deviation is `‖r‖/√(m − k)` — at 1e-10, 1e-5·√(m − k)
/// of a standard deviation at most (MINPACK's default is 1.5e-8). At 1e-12 the last steps chased reductions
/// of 1e-13 of ‖r‖², which Gauss–Newton's linear convergence on a curved valley yields a tenth at a time
/// (four of a 1168-point kinematic fit's fifteen evaluations; docs/speed.md).
const LM_GTOL: f64 = 1e-10;
const LM_XTOL: f64 = 1e-10;
const LM_FTOL: f64 = 1e-10;

pub(super) struct Minimum {
    pub(super) x: DVector<f64>,
    pub(super) evaluations: usize,
    pub(super) termination: Termination,
    /// The residual rows at `x`.
    pub(super) residual: DVector<f64>,
    /// The standard deviations of `x` from the residual ([`standard_deviations`]), `None` where they are
    /// not defined.
    pub(super) std: Option<Vec<f64>>,
}

/// The least-squares problem in whitened coordinates `x = x0 + S·z`, for the `levenberg-marquardt` crate.
/// `S` makes `J(x0)·S` orthonormal: the trust region is then a ball in the data's metric, and steps follow
/// the long, gently curved valleys of a weakly excited campaign instead of zig-zagging across them, which
/// keeps the iterations to a handful. The crate sees the equivalent small problem ([`reduced`]): the
/// whitened Jacobian's columns are near orthonormal, so its Gram matrix is as well conditioned as a
/// problem gets. That Gram matrix and gradient are `Sᵀ(JᵀJ)S` and `Sᵀ(Jᵀr)`: `J·S` itself (m × k times
/// k × k) is never formed, except where they do not make a well-conditioned small problem.
/// `S = D⁻¹R₀⁻¹` (`J₀D⁻¹ = Q₀R₀`, `D` the column norms of `J₀`): upper triangular.
struct Whitened<'a> {
    problem: &'a Problem<'a>,
    x0: &'a DVector<f64>,
    s: &'a DMatrix<f64>,
    /// The evaluation at the current point.
    at: Evaluation,
    /// Whether the crate took the Jacobian at `z`: it does so only at the points it accepts.
    accepted: Cell<bool>,
    /// The last accepted point and its evaluation, set aside while the crate tries steps from it: when
    /// its last try fails it asks for that point again, which is then restored instead of evaluated anew
    /// (the same computation: the same bits).
    anchor: Option<Evaluation>,
    /// Buffers of an evaluation no longer needed, reused by the next one (no new zeroed matrices).
    spare: Option<Evaluation>,
}

/// One point's evaluation; its buffers are reused from point to point.
struct Evaluation {
    z: DVector<f64>,
    /// The residual rows at `z`.
    r: DVector<f64>,
    /// The Jacobian at `z` (unwhitened).
    j: DMatrix<f64>,
    /// The whitened gradient `(J·S)ᵀr` at `z`.
    gz: DVector<f64>,
    /// The small problem at `z`, `None` where the residuals or the Jacobian are not finite. Every point the
    /// crate tries gets its Jacobian, since the small residuals are expressed through it.
    small: Option<Reduced>,
}

impl Evaluation {
    /// At `z = 0` of k parameters, its buffers empty (the first evaluation sizes them).
    fn empty(k: usize) -> Evaluation {
        Evaluation {
            z: DVector::zeros(k),
            r: DVector::zeros(0),
            j: DMatrix::zeros(0, 0),
            gz: DVector::zeros(0),
            small: None,
        }
    }
}

impl Whitened<'_> {
    fn x(&self) -> DVector<f64> {
        self.x0 + self.s * &self.at.z
    }

    /// The start `z = 0` (`x = x0`), whose residuals `r0` and Jacobian `j0` the caller has evaluated.
    fn start(&mut self, r0: DVector<f64>, j0: DMatrix<f64>) {
        self.at.z.fill(0.0);
        self.at.r = r0;
        self.at.j = j0;
        self.whiten_and_reduce();
        self.accepted.set(false);
        self.anchor = None;
    }

    /// The evaluation at `z` out of the problem, leaving the spare buffers (or empty ones, resized by the
    /// next evaluation) in its place.
    fn take(&mut self) -> Evaluation {
        let k = self.at.z.len();
        let spare = self.spare.take().unwrap_or_else(|| Evaluation::empty(k));
        self.put(spare)
    }

    /// `evaluation` into the problem; the one it replaces is returned.
    fn put(&mut self, evaluation: Evaluation) -> Evaluation {
        std::mem::replace(&mut self.at, evaluation)
    }

    /// The small problem at `z` from `Sᵀ(JᵀJ)S` and `Sᵀ(Jᵀr)`: one m × k × k product (`JᵀJ`) instead of
    /// two (`J·S`, then its Gram matrix). Forming `JᵀJ` of the unwhitened `J` squares its condition
    /// number (that of the column-scaled `J` about 1e4 on a campaign), so the whitened Gram matrix carries
    /// rounding errors of about 1e-8 relative instead of 1e-12 — enough for Levenberg–Marquardt's steps and
    /// trust region; the gradient, which fixes where the fit stops, is `Sᵀ(Jᵀr)` either way within a few
    /// units of `ε·cond`. Where the small problem is not well conditioned or not finite, `J·S` is formed
    /// and reduced by [`reduce`] (a QR where needed) as before.
    fn whiten_and_reduce(&mut self) {
        let e = &mut self.at;
        let (m, k) = e.j.shape();
        if m > k + 1 {
            let g = gram(&e.j);
            let gram_z = self.s.tr_mul(&(&g * self.s));
            e.gz = self.s.tr_mul(&e.j.tr_mul(&e.r));
            e.small = reduce_gram(&gram_z, &e.gz, e.r.norm_squared());
            if e.small.is_some() {
                return;
            }
        }
        let jz = &e.j * self.s;
        e.gz = jz.tr_mul(&e.r);
        e.small = reduce(&jz, &e.r);
    }
}

impl LeastSquaresProblem<f64, Dyn, Dyn> for Whitened<'_> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, Dyn>;
    type ParameterStorage = Owned<f64, Dyn>;

    fn set_params(&mut self, z: &DVector<f64>) {
        let same = |a: &DVector<f64>| {
            a.iter()
                .zip(z.iter())
                .all(|(a, b)| a.to_bits() == b.to_bits())
        };
        if self.anchor.as_ref().is_some_and(|a| same(&a.z)) {
            let anchor = self.anchor.take().expect("checked");
            self.spare = Some(self.put(anchor));
            self.accepted.set(true);
            return;
        }
        if self.accepted.replace(false) {
            // The anchor before it is not asked for again: its buffers take the new evaluation.
            self.spare = self.anchor.take().or(self.spare.take());
            self.anchor = Some(self.take());
        }
        self.at.z.copy_from(z);
        let x = self.x();
        self.problem
            .evaluate_into(x.as_slice(), &mut self.at.r, Some(&mut self.at.j));
        self.whiten_and_reduce();
    }

    fn params(&self) -> DVector<f64> {
        self.at.z.clone()
    }

    fn residuals(&self) -> Option<DVector<f64>> {
        self.at.small.as_ref().map(|s| s.residuals.clone())
    }

    fn jacobian(&self) -> Option<DMatrix<f64>> {
        self.accepted.set(true);
        self.at.small.as_ref().map(|s| s.jacobian.clone())
    }
}

/// Levenberg–Marquardt (the `levenberg-marquardt` crate, MINPACK's algorithm) on the whitened problem, from
/// `x0`, where the residuals are `r0` and the Jacobian `j0` (the rank check's evaluation, not done again).
/// A run that stops for any reason but convergence is an error, never a silent result.
pub(super) fn minimize(
    problem: &Problem,
    x0: &DVector<f64>,
    (r0, j0): (DVector<f64>, DMatrix<f64>),
    s: &DMatrix<f64>,
    max_evaluations: usize,
) -> std::result::Result<Minimum, String> {
    let k = x0.len();
    let mut problem = Whitened {
        problem,
        x0,
        s,
        at: Evaluation::empty(k),
        accepted: Cell::new(false),
        anchor: None,
        spare: None,
    };
    // The linearized solution first (classical calibration's first estimate): in whitened coordinates the
    // Jacobian has orthonormal columns, so the Gauss–Newton step is a product. The problem is nearly linear
    // in its small parameters, so Levenberg–Marquardt then only polishes; if the step does not help, it
    // starts from the nominal model instead.
    problem.start(r0, j0);
    let start_norm = problem.at.r.norm();
    let gauss_newton = problem.at.small.is_some().then(|| -&problem.at.gz);
    // The start's evaluation counts once, here (the rank check's).
    let mut evaluations_before = 1;
    if let Some(z0) = gauss_newton {
        // The start is kept aside, not evaluated again, should the step not help.
        let start = problem.take();
        problem.set_params(&z0);
        evaluations_before += 1;
        // A NaN norm counts as no improvement.
        if problem.at.r.norm().partial_cmp(&start_norm) != Some(std::cmp::Ordering::Less) {
            problem.spare = Some(problem.put(start));
        } else {
            problem.spare = Some(start);
        }
    }
    // The crate's patience counts evaluations in units of (parameters + 1).
    let patience = (max_evaluations / (k + 1)).max(1);
    let (problem, report) = LevenbergMarquardt::new()
        .with_ftol(LM_FTOL)
        .with_xtol(LM_XTOL)
        .with_gtol(LM_GTOL)
        .with_patience(patience)
        .minimize(problem);
    let termination = match report.termination {
        TerminationReason::Orthogonal => Termination::Gradient,
        TerminationReason::Converged { xtol: true, .. } => Termination::Step,
        TerminationReason::Converged { .. } | TerminationReason::ResidualsZero => {
            Termination::Objective
        }
        TerminationReason::LostPatience => {
            return Err(format!(
                "no convergence within {max_evaluations} evaluations"
            ));
        }
        other => return Err(crate::numeric::stopped(&other)),
    };
    // The crate counts patience in units of (parameters + 1) evaluations; the cap is the caller's, exactly.
    let evaluations = report.number_of_evaluations + evaluations_before;
    if evaluations > max_evaluations {
        return Err(format!(
            "no convergence within {max_evaluations} evaluations"
        ));
    }
    // The crate's last evaluation is at its answer (it goes back to it after a rejected step), so the
    // residuals and the small problem there are the solution's.
    let std = problem.at.small.as_ref().and_then(|small| {
        standard_deviations(&small.jacobian.rows(0, k).into_owned(), s, &problem.at.r)
    });
    Ok(Minimum {
        x: problem.x(),
        evaluations,
        termination,
        std,
        residual: problem.at.r,
    })
}

/// Standard deviations of the parameters, `s·√((JᵀJ)⁻¹)ₖₖ` with `s²` the residual sum of squares over the
/// degrees of freedom, from the triangle `R` of the whitened Jacobian `J·S` (`RᵀR = (JS)ᵀJS`, so
/// `(JᵀJ)⁻¹ = S R⁻¹ R⁻ᵀ Sᵀ`: the row norms of `S R⁻¹`); `None` without degrees of freedom or where `R` is
/// singular.
fn standard_deviations(
    r: &DMatrix<f64>,
    s: &DMatrix<f64>,
    residual: &DVector<f64>,
) -> Option<Vec<f64>> {
    let (m, k) = (residual.len(), r.ncols());
    if m <= k {
        return None;
    }
    let s2 = residual.norm_squared() / (m - k) as f64;
    let t = s * r.clone().try_inverse()?;
    let std: Vec<f64> = t
        .row_iter()
        .map(|row| (s2 * row.norm_squared()).sqrt())
        .collect();
    std.iter().all(|v| v.is_finite()).then_some(std)
}
