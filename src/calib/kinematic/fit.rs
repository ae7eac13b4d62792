//! The steps of [`KinematicModel::fit_with`](super::KinematicModel::fit_with), in its order: check the points,
//! choose the candidates and their structural set, the solve judged at the noise of the measurement and within
//! the compliances' bound (which decides what the data determine), the residual RMS, and the refined
//! registration (or the base error frame) the model keeps.

use nalgebra::{DMatrix, DVector, Isometry3, Translation3, UnitQuaternion};

use super::gravity::GravityModel;
use super::identify::{
    self, Identifiability, Undetermined, determined, identifiability, structural_set,
};
use super::noise::{self, Noise};
use super::params::{Param, State, candidates};
use super::problem::{Point, Problem};
use super::solve::{self, minimize};
use crate::calib::method::{FitContext, MethodInfo};
use crate::calib::tracker_frame::{Observation, Registration, TrackerFrame};
use crate::dataset::Dataset;
use crate::error::{Error, Result};
use crate::robot::dh::{ChainPose, DhChain};

/// Both sets have only finite measurements and finite joint angles, one per joint; training is not empty.
pub(super) fn check_points(
    method: &MethodInfo,
    n: usize,
    train: &Dataset,
    val: &Dataset,
) -> Result<()> {
    if train.is_empty() {
        return Err(Error::Invalid(format!("{method}: no training points")));
    }
    for data in [train, val] {
        let bad = data.q.iter().zip(&data.measured).position(|(q, m)| {
            !(q.len() == n
                && q.iter().all(|v| v.is_finite())
                && m.iter().all(|p| p.iter().all(|v| v.is_finite())))
        });
        if let Some(i) = bad {
            return Err(Error::Data {
                origin: data.origin.clone(),
                message: format!(
                    "{method}: point {} has a non-finite measurement or not {n} finite joint angles",
                    data.point_ids.get(i).map_or("?", |s| s.as_str())
                ),
            });
        }
    }
    Ok(())
}

/// The nominal chain at every training, then validation configuration, one pass each: its links are the
/// fit's points' ([`points`]), its frames give the registration's flange poses ([`registration`]) and the
/// gravity torques, the same bits as computing each from the angles again.
pub(super) fn poses(dh: &DhChain, train: &Dataset, val: &Dataset) -> Vec<ChainPose> {
    let fixed = dh.fixed_rotations();
    train
        .q
        .iter()
        .chain(&val.q)
        .map(|q| dh.pose_fixed(q, &fixed))
        .collect()
}

/// [`FitContext::registration`], from the flange poses of `poses` (of the training, then the validation
/// points) where it is not shared yet: [`Registration::fit`]'s bits.
pub(super) fn registration(
    ctx: &FitContext,
    train: &Dataset,
    val: &Dataset,
    poses: &[ChainPose],
) -> Result<Registration> {
    ctx.registration_by(train, val, || {
        let flanges: Vec<Isometry3<f64>> = poses.iter().map(|p| p.flange(ctx.dh)).collect();
        Registration::fit_at(ctx.dh, train, val, &flanges)
    })
}

/// The points of the fit: the observations with their poses' links and the nominal gravity torques at them
/// (`elastic`).
pub(super) fn points(
    dh: &DhChain,
    gravity: Option<&GravityModel>,
    obs: Vec<Observation>,
    poses: Vec<ChainPose>,
) -> Vec<Point> {
    obs.into_iter()
        .zip(poses)
        .map(|(o, pose)| {
            let tau = gravity.map_or_else(Vec::new, |g| g.torques_on(dh, &pose.frames));
            Point::with_links(pose.links, o.position, o.orientation, tau)
        })
        .collect()
}

/// The candidates of a chain of `n` joints, in priority order.
pub(super) fn candidates_to_fit(n: usize, elastic: bool, base_frame: bool) -> Vec<Param> {
    // Data in the base frame has no tracker frame to fit: the base error frame E_0 takes its place (the
    // identity registration would otherwise leave the base's placement error to the frames after joint 1,
    // which cannot hold a tilt before it).
    candidates(n, elastic)
        .into_iter()
        .map(|p| match p {
            Param::TrackerRotation(k) if base_frame => Param::BaseRotation(k),
            Param::TrackerTranslation(k) if base_frame => Param::BaseTranslation(k),
            p => p,
        })
        .collect()
}

/// The structurally identifiable set of `all` and the candidates it leaves out, from configurations that do
/// not depend on the data.
pub(super) fn structural(
    probe: &Problem,
    ctx: &FitContext,
    all: &[Param],
    gravity: Option<&GravityModel>,
) -> (Vec<Param>, Vec<Param>) {
    let (lower, upper) = ctx.limits();
    let structural = structural_set(probe, &lower, &upper, all, gravity);
    let dropped: Vec<Param> = all
        .iter()
        .copied()
        .filter(|p| !structural.contains(p))
        .collect();
    (structural, dropped)
}

/// The structural set at the base state on the training points: its residuals and Jacobian, and the triangle
/// `R` of the Jacobian's QR (`RᵀR = JᵀJ`): the lengths of its columns and the angles between them, which are
/// all that judging what the data determine reads ([`determined`]), in as many rows as there are parameters
/// instead of three per point — the judgement runs several times a fit.
pub(super) struct AtBase {
    structural: Vec<Param>,
    residual: DVector<f64>,
    jacobian: DMatrix<f64>,
    pub(super) triangle: DMatrix<f64>,
}

impl AtBase {
    /// The residuals and Jacobian of `kept` at the base state, as evaluating `kept` alone gives them: the
    /// state is the base state either way and a column depends on its own parameter only, so they are the
    /// structural Jacobian's columns (the same bits, one evaluation of every point fewer per fit of a set).
    /// `None` where `kept` is not within the structural set.
    fn of(&self, kept: &[Param]) -> Option<(DVector<f64>, DMatrix<f64>)> {
        let columns: Vec<usize> = kept
            .iter()
            .map(|p| self.structural.iter().position(|s| s == p))
            .collect::<Option<_>>()?;
        Some((
            self.residual.clone(),
            self.jacobian.select_columns(columns.iter()),
        ))
    }

    /// The triangle's columns of `kept` (`TᵀT = JᵀJ` of `kept`'s Jacobian at the base state, in as many rows
    /// as the structural set has parameters); `None` where `kept` is not within the structural set.
    fn triangle_of(&self, kept: &[Param]) -> Option<DMatrix<f64>> {
        let columns: Vec<usize> = kept
            .iter()
            .map(|p| self.structural.iter().position(|s| s == p))
            .collect::<Option<_>>()?;
        Some(self.triangle.select_columns(columns.iter()))
    }
}

/// [`AtBase`] of the structural set on the probe's points.
pub(super) fn jacobian_at_base(probe: &mut Problem, base: &State, structural: &[Param]) -> AtBase {
    probe.params = structural.to_vec();
    let x_struct: Vec<f64> = structural.iter().map(|&p| base.get(p)).collect();
    let (residual, j) = probe.evaluate(&x_struct, true);
    let jacobian = j.expect("jacobian requested");
    let triangle = if jacobian.nrows() > jacobian.ncols() {
        jacobian.clone().qr().r()
    } else {
        jacobian.clone()
    };
    AtBase {
        structural: structural.to_vec(),
        residual,
        jacobian,
        triangle,
    }
}

/// What [`solve_within_bounds`] leaves: the kept parameters, their values and standard deviations, the
/// identifiability and the minimum it reached, the structurally identifiable parameters the data do not
/// determine, and the compliances held at their bound.
pub(super) struct Solution {
    pub(super) kept: Vec<Param>,
    pub(super) undetermined: Vec<Undetermined>,
    pub(super) id: Identifiability,
    pub(super) minimum: solve::Minimum,
    pub(super) values: Vec<f64>,
    pub(super) std: Vec<f64>,
    pub(super) at_bound: Vec<Undetermined>,
    /// The residual rows at the fitted values.
    pub(super) residual: DVector<f64>,
    /// The noise the kept set was judged at.
    pub(super) noise: Noise,
}

/// How many times [`solve_judged`] judges the kept set again at the fitted residual and refits: the set
/// settles after one or two.
const MAX_REJUDGEMENTS: usize = 4;

/// The parameters of `structural` the data determine, judged at the noise of the measurement and fitted
/// ([`super::noise`]): first at `start` (the nominal model's residual), then, as long as judging at the
/// fitted model's own residual (at least `floor`) keeps another set, refitted with that set — so the set a
/// fit ends with is the one its own residual determines (checked once more after the last fit). A set met
/// before ends the search (the last fit stands), and so does a refit that fails: the set before it, whose fit
/// converged, stands, judged at the noise it was judged at.
#[allow(clippy::too_many_arguments)]
pub(super) fn solve_judged(
    probe: &mut Problem,
    base: &State,
    at_base: &AtBase,
    structural: &[Param],
    start: Noise,
    floor: Noise,
    max_evaluations: usize,
    method: &MethodInfo,
) -> Result<Solution> {
    let mut solution = solve_within_bounds(
        probe,
        base,
        at_base,
        structural,
        start,
        max_evaluations,
        method,
    )?;
    let mut tried = vec![solution.kept.clone()];
    for _ in 0..MAX_REJUDGEMENTS {
        let at_fit = noise::fitted(&solution.residual, solution.kept.len(), floor);
        let (mut kept, mut undetermined) =
            determined(&at_base.triangle, structural, at_fit, probe.points.len());
        let bound = |name: &str| solution.at_bound.iter().any(|b| b.parameter == name);
        kept.retain(|p| !bound(&p.name()));
        if kept == solution.kept {
            undetermined.retain(|u| !bound(&u.parameter));
            solution.undetermined = undetermined;
            solution.noise = at_fit;
            break;
        }
        if tried.contains(&kept) {
            break;
        }
        tried.push(kept);
        match solve_within_bounds(
            probe,
            base,
            at_base,
            structural,
            at_fit,
            max_evaluations,
            method,
        ) {
            Ok(refit) => solution = refit,
            Err(_) => break,
        }
    }
    Ok(solution)
}

/// The parameters of `structural` that the data determine at `noise`, fitted by Levenberg–Marquardt in at
/// most `max_evaluations` evaluations.
fn solve_within_bounds(
    probe: &mut Problem,
    base: &State,
    at_base: &AtBase,
    structural: &[Param],
    noise: Noise,
    max_evaluations: usize,
    method: &MethodInfo,
) -> Result<Solution> {
    // Compliances are non-negative: a fit that pulls one below zero holds it at zero (the bound) and is
    // repeated without it, one at a time from the most negative — an active-set bounded least squares.
    let mut at_bound: Vec<Undetermined> = Vec::new();
    loop {
        let (mut kept, mut undetermined) =
            determined(&at_base.triangle, structural, noise, probe.points.len());
        let bound = |p: &Param| at_bound.iter().any(|u| u.parameter == p.name());
        kept.retain(|p| !bound(p));
        let Fit {
            id,
            minimum,
            values,
            std,
            residual,
        } = solve_kept(probe, base, at_base, &kept, max_evaluations, method)?;
        let negative = kept
            .iter()
            .zip(&values)
            .enumerate()
            .filter(|(_, (p, v))| p.is_compliance() && **v < 0.0)
            .min_by(|a, b| a.1.1.total_cmp(b.1.1))
            .map(|(i, _)| i);
        if let Some(i) = negative {
            let sd = std.get(i).copied();
            at_bound.push(Undetermined {
                parameter: kept[i].name(),
                std: sd,
                plausible: identify::PLAUSIBLE_COMPLIANCE,
                reason: format!(
                    "the data pull it below zero ({:.2e}{} rad/Nm), which no joint is; held at 0, the bound",
                    values[i],
                    sd.map_or(String::new(), |s| format!(" ± {s:.1e}"))
                ),
                at_bound: true,
            });
            continue;
        }
        undetermined.retain(|u| !at_bound.iter().any(|b| b.parameter == u.parameter));
        return Ok(Solution {
            kept,
            undetermined,
            id,
            minimum,
            values,
            std,
            at_bound,
            residual,
            noise,
        });
    }
}

/// The registration the model keeps: the tracker frame refined by the fitted rotation and translation, the
/// fitted mounting, and the fit's RMS and evaluations.
pub(super) fn refined(
    registration: Registration,
    state: &State,
    train_rms: f64,
    evaluations: usize,
) -> Registration {
    let initial = registration.frame.tracker_to_base;
    // In the base frame the fitted rigid motion is the base error frame the model keeps
    // ([`base_error`]); the registration stays the identity.
    let refined = if registration.base_frame {
        initial
    } else {
        measured_motion(state) * initial
    };
    Registration {
        frame: TrackerFrame {
            tracker_to_base: refined,
            mounting: state.mount,
            rms: train_rms,
            evaluations,
        },
        nest: registration.nest,
        probe_rotation: registration.probe_rotation,
        base_frame: registration.base_frame,
    }
}

/// What [`solve_kept`] leaves: the identifiability, the minimum, the values, their standard deviations and
/// the residual rows there.
struct Fit {
    id: Identifiability,
    minimum: solve::Minimum,
    values: Vec<f64>,
    std: Vec<f64>,
    residual: DVector<f64>,
}

/// The rigid motion the tracker-frame (or base-frame) parameters apply to the measured points.
fn measured_motion(state: &State) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::from(state.t),
        UnitQuaternion::from_scaled_axis(state.rho),
    )
}

/// For data in the base frame, the base error frame `E_0`: the model predicts `E_0 · FK_E(q)`, which is the
/// fit of the measured points moved by the inverse of `E_0`.
pub(super) fn base_error(registration: &Registration, state: &State) -> Option<Isometry3<f64>> {
    registration
        .base_frame
        .then(|| measured_motion(state).inverse())
}

/// Levenberg–Marquardt on `kept` from the base state (at most `max_evaluations` evaluations): the rank check first (a rank below the set's size is
/// refused, naming the least determined), then the fit, its values and their standard deviations.
fn solve_kept(
    probe: &mut Problem,
    base: &State,
    at_base: &AtBase,
    kept: &[Param],
    max_evaluations: usize,
    method: &MethodInfo,
) -> Result<Fit> {
    probe.params = kept.to_vec();
    let x0: Vec<f64> = kept.iter().map(|&p| base.get(p)).collect();
    let (r0, j0) = at_base.of(kept).unwrap_or_else(|| {
        let (r0, j0) = probe.evaluate(&x0, true);
        (r0, j0.expect("jacobian requested"))
    });
    // The rank check reads the Jacobian only through its Gram matrix: the structural triangle's columns have
    // the same one, in about 30 rows instead of 3 per point (two QRs of 3504 × 30 fewer a fit).
    let id = match at_base.triangle_of(kept) {
        Some(triangle) => identifiability(&triangle, kept),
        None => identifiability(&j0, kept),
    };
    if id.rank < kept.len() {
        let weakest = if id.weakest.is_empty() {
            String::new()
        } else {
            format!("; least determined: {}", id.weakest.join(", "))
        };
        return Err(Error::Invalid(format!(
            "{method}: the training points do not identify the model: rank {} of {} \
             (condition number {:.1e}){weakest}; measure more points and vary every joint",
            id.rank,
            kept.len(),
            id.condition
        )));
    }
    let k = kept.len();
    let whitening = id
        .whitening
        .clone()
        .unwrap_or_else(|| DMatrix::identity(k, k));
    let minimum = minimize(
        probe,
        &DVector::from_vec(x0),
        (r0, j0),
        &whitening,
        max_evaluations.max(2),
    )
    .map_err(|why| {
        Error::Invalid(format!(
            "{method}: Levenberg–Marquardt did not converge ({why}); the data may be \
             inconsistent with a constant-error model"
        ))
    })?;
    let values: Vec<f64> = minimum.x.iter().copied().collect();
    let std = minimum.std.clone().unwrap_or_default();
    let residual = minimum.residual.clone();
    Ok(Fit {
        id,
        minimum,
        values,
        std,
        residual,
    })
}

/// What the structural analysis drops, in words: a compliance because gravity (and the declared payload)
/// never load its joint within the limits, a frame error because at no configuration does it move the
/// measured point other than as parameters kept before it do.
pub(super) fn structurally_dropped(dropped: &[Param]) -> Vec<Undetermined> {
    dropped
        .iter()
        .map(|p| Undetermined {
            parameter: p.name(),
            std: None,
            plausible: identify::plausible_size(*p).unwrap_or(0.0),
            at_bound: false,
            reason: if p.is_compliance() {
                "gravity and the declared payload load this joint nowhere within the joint limits (its axis \
                 stays vertical, or the masses it carries sit on it), so its compliance deflects nothing the \
                 tracker could measure; held at 0"
            } else {
                "at every configuration within the joint limits it moves the measured point only as parameters \
                 kept before it do, or not at all (e.g. a rotation about the axis the reflector sits on); \
                 structurally redundant, held at 0"
            }
            .into(),
        })
        .collect()
}
