//! Levenberg–Marquardt on the kinematic problem, in whitened coordinates.

use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt, TerminationReason};
use nalgebra::{DMatrix, DVector, Dyn, Owned};
use serde::{Deserialize, Serialize};

use super::problem::Problem;

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

/// Convergence tolerances of [`minimize`] (the crate's `gtol`, `xtol`, `ftol`), relative.
const LM_GTOL: f64 = 1e-10;
const LM_XTOL: f64 = 1e-10;
const LM_FTOL: f64 = 1e-12;

pub(super) struct Minimum {
    pub(super) x: DVector<f64>,
    pub(super) evaluations: usize,
    pub(super) termination: Termination,
}

/// The least-squares problem in whitened coordinates `x = x0 + S·z`, for the `levenberg-marquardt` crate.
/// `S` makes `J(x0)·S` orthonormal: the trust region is then a ball in the data's metric, and steps follow
/// the long, gently curved valleys of a weakly excited campaign instead of zig-zagging across them, which
/// keeps the iterations (each a QR of the full Jacobian) to a handful.
struct Whitened<'a> {
    problem: &'a Problem<'a>,
    x0: &'a DVector<f64>,
    s: &'a DMatrix<f64>,
    z: DVector<f64>,
    r: DVector<f64>,
    /// The Jacobian at `z`, computed when the crate asks for it: it does so only at accepted steps, so
    /// rejected trial points cost a residual evaluation alone.
    jz: std::cell::OnceCell<Option<DMatrix<f64>>>,
}

impl Whitened<'_> {
    fn x(&self) -> DVector<f64> {
        self.x0 + self.s * &self.z
    }
}

impl LeastSquaresProblem<f64, Dyn, Dyn> for Whitened<'_> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, Dyn>;
    type ParameterStorage = Owned<f64, Dyn>;

    fn set_params(&mut self, z: &DVector<f64>) {
        self.z.copy_from(z);
        self.r = self.problem.evaluate(self.x().as_slice(), false).0;
        self.jz = std::cell::OnceCell::new();
    }

    fn params(&self) -> DVector<f64> {
        self.z.clone()
    }

    fn residuals(&self) -> Option<DVector<f64>> {
        self.r.iter().all(|v| v.is_finite()).then(|| self.r.clone())
    }

    fn jacobian(&self) -> Option<DMatrix<f64>> {
        self.jz
            .get_or_init(|| {
                let (_, j) = self.problem.evaluate(self.x().as_slice(), true);
                j.map(|j| j * self.s)
            })
            .clone()
            .filter(|j| j.iter().all(|v| v.is_finite()))
    }
}

/// Levenberg–Marquardt (the `levenberg-marquardt` crate, MINPACK's algorithm) on the whitened problem, from
/// `x0`. A run that stops for any reason but convergence is an error, never a silent result.
pub(super) fn minimize(
    problem: &Problem,
    x0: &DVector<f64>,
    s: &DMatrix<f64>,
    max_evaluations: usize,
) -> std::result::Result<Minimum, String> {
    let k = x0.len();
    let mut problem = Whitened {
        problem,
        x0,
        s,
        z: DVector::zeros(k),
        r: DVector::zeros(0),
        jz: std::cell::OnceCell::new(),
    };
    // The linearized solution first (classical calibration's first estimate): in whitened coordinates the
    // Jacobian has orthonormal columns, so the Gauss–Newton step is a product. The problem is nearly linear
    // in its small parameters, so Levenberg–Marquardt then only polishes; if the step does not help, it
    // starts from the nominal model instead.
    problem.set_params(&DVector::zeros(k));
    let start_norm = problem.r.norm();
    let gauss_newton = problem.jacobian().map(|jz| -(jz.tr_mul(&problem.r)));
    let mut evaluations_before = 1;
    if let Some(z0) = gauss_newton {
        problem.set_params(&z0);
        evaluations_before += 1;
        // A NaN norm counts as no improvement.
        if problem.r.norm().partial_cmp(&start_norm) != Some(std::cmp::Ordering::Less) {
            problem.set_params(&DVector::zeros(k));
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
    Ok(Minimum {
        x: problem.x(),
        evaluations,
        termination,
    })
}
