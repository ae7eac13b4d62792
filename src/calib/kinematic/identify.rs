//! Which parameters the kinematic fit keeps (structural, fixed configurations), whether the training data
//! identify them (rank, condition number), and the identification Jacobian for experiment design.

use crate::numeric;
use nalgebra::{DMatrix, DVector, Point3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::gravity::GravityModel;
use super::noise::Noise;
use super::params::{Param, State, candidates};
use super::problem::{Point, Problem};
use crate::calib::method::FitContext;
use crate::error::Result;
use crate::robot::chain::sample_within;
use crate::robot::dh::FixedRotations;

/// Configurations of the structural analysis: enough that every parameter acting anywhere acts in many.
pub(super) const STRUCT_SAMPLES: usize = 200;
/// Fixed, so the identifiable set is the same in every run.
pub(super) const STRUCT_SEED: u64 = 0x6b1e_7a71;
/// Part of a unit column orthogonal to the kept ones below which it is redundant. Exact redundancies leave
/// ≤ 1e-13; the weakest independent parameter of the iiwa over its joint range leaves 2e-3 (a test says so).
pub(super) const STRUCT_REL: f64 = 1e-7;
/// A column below this fraction of the largest of its kind acts nowhere: the iiwa's joint-7 compliance column
/// is 2e-10 (1e-8 with a nest) of joint 2's, as link 7 and the payload sit on its axis.
pub(super) const VANISH_REL: f64 = 1e-6;
/// Singular values of the (column-scaled) training Jacobian below this fraction of the largest are zero.
pub(super) const RANK_REL: f64 = 1e-10;

/// Gram–Schmidt in priority order over the columns of `problem`'s Jacobian at its base state.
pub(super) fn structural_columns(problem: &Problem, candidates: &[Param]) -> Vec<Param> {
    structural_analysis(problem, candidates)
        .into_iter()
        .filter(|a| a.kept)
        .map(|a| a.param)
        .collect()
}

/// One candidate in the structural analysis: its column's norm relative to the largest of its kind, and
/// the part of its unit column orthogonal to the columns kept before it.
#[derive(Debug)]
pub(super) struct Analysed {
    pub(super) param: Param,
    /// Read by the test that checks the margins of the decisions.
    #[cfg_attr(not(test), allow(dead_code))]
    pub(super) relative_norm: f64,
    #[cfg_attr(not(test), allow(dead_code))]
    pub(super) rest: f64,
    pub(super) kept: bool,
}

pub(super) fn structural_analysis(problem: &Problem, candidates: &[Param]) -> Vec<Analysed> {
    let values: Vec<f64> = candidates.iter().map(|&p| problem.base.get(p)).collect();
    let (_, j) = problem.evaluate(&values, true);
    let j = j.expect("jacobian requested");
    let norms: Vec<f64> = (0..j.ncols()).map(|c| j.column(c).norm()).collect();
    let largest = |compliance: bool| {
        candidates
            .iter()
            .zip(&norms)
            .filter(|(p, _)| p.is_compliance() == compliance)
            .map(|(_, &n)| n)
            .fold(0.0, f64::max)
    };
    let (geo_max, comp_max) = (largest(false), largest(true));
    let mut basis: Vec<DVector<f64>> = Vec::new();
    let mut out = Vec::with_capacity(candidates.len());
    for (c, &prm) in candidates.iter().enumerate() {
        let scale = if prm.is_compliance() {
            comp_max
        } else {
            geo_max
        };
        let relative_norm = norms[c] / scale;
        if relative_norm.is_nan() || relative_norm <= VANISH_REL {
            out.push(Analysed {
                param: prm,
                relative_norm,
                rest: 0.0,
                kept: false,
            });
            continue;
        }
        let mut v = j.column(c) / norms[c];
        // Modified Gram–Schmidt, one pass: a column in the span of the kept ones leaves a rest of rounding
        // times their condition (≤ 9e-14 on the iiwa, asserted below 1e-10 by
        // `structural_decisions_are_clear_cut`), far below `STRUCT_REL`; a second pass would only refine
        // rests that lie on one side of the threshold by orders of magnitude already.
        for b in &basis {
            let d = b.dot(&v);
            v.axpy(-d, b, 1.0);
        }
        let rest = v.norm();
        let kept = rest >= STRUCT_REL;
        if kept {
            basis.push(v / rest);
        }
        out.push(Analysed {
            param: prm,
            relative_norm,
            rest,
            kept,
        });
    }
    out
}

/// Rank and condition number of the training Jacobian (columns scaled to unit norm), and the names of the
/// parameters that weigh most in its null space when it is rank-deficient.
pub(super) struct Identifiability {
    pub(super) rank: usize,
    pub(super) condition: f64,
    pub(super) weakest: Vec<String>,
    /// `S` with `J·S` orthonormal (full rank only): the coordinates Levenberg–Marquardt works in.
    pub(super) whitening: Option<DMatrix<f64>>,
}

/// `j` is the Jacobian or any matrix with its Gram matrix `JᵀJ` (such as its QR triangle's columns): all
/// that is read are the column norms and the singular values, which the Gram matrix fixes.
pub(super) fn identifiability(j: &DMatrix<f64>, params: &[Param]) -> Identifiability {
    let mut scaled = j.clone();
    let mut norms = Vec::with_capacity(j.ncols());
    for mut col in scaled.column_iter_mut() {
        let n = col.norm();
        if n > 0.0 {
            col /= n;
        }
        norms.push(if n > 0.0 { n } else { 1.0 });
    }
    let k = params.len();
    // Reduce a tall matrix to its triangle first: same singular values, a much smaller SVD.
    let square = if scaled.nrows() > k {
        scaled.qr().r()
    } else {
        scaled
    };
    let whitening = (square.nrows() == k)
        .then(|| square.clone().try_inverse())
        .flatten()
        .map(|r_inv| {
            let mut s = r_inv;
            for (mut row, n) in s.row_iter_mut().zip(&norms) {
                row /= *n;
            }
            s
        });
    // A non-finite Jacobian (joint values far outside the robot's range) identifies nothing.
    let Ok(svd) = numeric::svd(square, false, true, "identifiability") else {
        return Identifiability {
            rank: 0,
            condition: f64::INFINITY,
            weakest: Vec::new(),
            whitening: None,
        };
    };
    let s = &svd.singular_values;
    let smax = s.max();
    let rank = s.iter().filter(|&&v| v > RANK_REL * smax).count();
    let smin = if s.len() < k { 0.0 } else { s.min() };
    let condition = if smin > 0.0 {
        smax / smin
    } else {
        f64::INFINITY
    };
    let mut weakest = Vec::new();
    if rank < k
        && let Some(vt) = &svd.v_t
    {
        // Rows of Vᵀ for the vanishing singular values span (part of) the null space; weigh each parameter
        // by its share in them.
        let mut weight = vec![0.0; k];
        for (i, sv) in s.iter().enumerate() {
            if *sv <= RANK_REL * smax {
                for (c, w) in weight.iter_mut().enumerate() {
                    *w += vt[(i, c)].powi(2);
                }
            }
        }
        let mut order: Vec<usize> = (0..k).collect();
        order.sort_by(|&a, &b| weight[b].total_cmp(&weight[a]));
        weakest = order
            .into_iter()
            .take(4)
            .filter(|&c| weight[c] > 1e-3)
            .map(|c| params[c].name())
            .collect();
    }
    Identifiability {
        rank,
        condition,
        weakest,
        whitening,
    }
}

/// The largest size a parameter of a real arm has, against which "the data determine it" is judged: a
/// frame error of 5 mm or 10 mrad is already a damaged arm (catalogue arms are built to tenths of a
/// millimetre and a few milliradians; the UR10 fitted here errs by 0.3 mm and 0.5–0.8 mrad), and a joint that turns 10 mrad under a newton-metre holds no load
/// (measured arms: 1e-6 to 3e-4 rad/Nm). The tracker frame (or, for data in the base frame, the base error
/// frame, which holds the base's placement in whatever frame the data were put in) and the mounting have no
/// such size: they are kept whatever the data, and must be determined (else the fit is refused).
pub fn plausible_size(p: Param) -> Option<f64> {
    match p {
        Param::TrackerRotation(_)
        | Param::TrackerTranslation(_)
        | Param::BaseRotation(_)
        | Param::BaseTranslation(_)
        | Param::Mounting(_) => None,
        Param::Error(e) if e.component <= 3 => Some(PLAUSIBLE_LENGTH_M),
        Param::Error(_) => Some(PLAUSIBLE_ANGLE_RAD),
        Param::Compliance(_) => Some(PLAUSIBLE_COMPLIANCE),
    }
}

/// See [`plausible_size`].
pub(super) const PLAUSIBLE_LENGTH_M: f64 = 0.005;
pub(super) const PLAUSIBLE_ANGLE_RAD: f64 = 0.01;
pub(super) const PLAUSIBLE_COMPLIANCE: f64 = 0.01;

/// A parameter the training data do not determine: its standard deviation from these points (at the
/// assumed noise), and why, in words.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Undetermined {
    pub parameter: String,
    /// Standard deviation the data would give it (its unit: m, rad or rad/Nm); `None` when it has no
    /// effect of its own at all.
    pub std: Option<f64>,
    pub plausible: f64,
    pub reason: String,
    /// A compliance the data pull below zero, held at the bound: then `std` is the data's on the bound's
    /// estimate. Not saved (a fresh fit's, for what builds on the fit: a twin).
    #[serde(skip)]
    pub at_bound: bool,
}

fn unit(p: Param) -> &'static str {
    match p {
        Param::Compliance(_) => "rad/Nm",
        Param::Error(e) if e.component <= 3 => "m",
        _ => "rad",
    }
}

/// Which structurally identifiable parameters the training data determine: Gram–Schmidt over the training
/// Jacobian's columns (or those of any matrix with the same `JᵀJ`, such as its QR triangle) in priority order (unscaled: a column's size is its effect), keeping a parameter when
/// its standard deviation given the ones kept before it, `σ / rest` at the measurement's `noise` σ, is below
/// its [`plausible_size`].
/// The rest are held at their nominal values (zero error, no compliance) and returned with the reason. A
/// column may be weak because it barely moves the measured point at these configurations (a reflector on
/// the last joint's axis and that joint's rotation about it; an unloaded joint's compliance; too few
/// points), or because its effect is nearly that of parameters kept before it.
pub(super) fn determined(
    j: &DMatrix<f64>,
    params: &[Param],
    noise: Noise,
    points: usize,
) -> (Vec<Param>, Vec<Undetermined>) {
    let sigma = noise.sigma_m;
    let mut basis: Vec<DVector<f64>> = Vec::new();
    let mut kept_cols: Vec<(usize, DVector<f64>)> = Vec::new();
    let mut kept = Vec::new();
    let mut undetermined = Vec::new();
    for (c, &prm) in params.iter().enumerate() {
        let col = j.column(c).into_owned();
        let norm = col.norm();
        let mut v = col.clone();
        for _ in 0..2 {
            for b in &basis {
                let d = b.dot(&v);
                v.axpy(-d, b, 1.0);
            }
        }
        let rest = v.norm();
        let std = if rest > 0.0 {
            sigma / rest
        } else {
            f64::INFINITY
        };
        match plausible_size(prm) {
            Some(size) if std.is_nan() || std > size => {
                let u = unit(prm);
                // RMS displacement of a measured point (mm) if the parameter had its plausible size.
                let effect = norm * size / (points.max(1) as f64).sqrt() * 1e3;
                let own = if norm > 0.0 { rest / norm } else { 0.0 };
                let reason = if own < 0.1 {
                    let twin = kept_cols
                        .iter()
                        .max_by(|a, b| {
                            let cos = |w: &DVector<f64>| (w.dot(&col) / (w.norm() * norm)).abs();
                            cos(&a.1).total_cmp(&cos(&b.1))
                        })
                        .map_or(String::new(), |(k, _)| {
                            format!(" (most of all {})", params[*k].name())
                        });
                    format!(
                        "its effect on these points is nearly that of parameters kept before it{twin}: only {:.1} % \
                         is its own, so the data would give it a standard deviation of {std:.2e} {u} (at {:.2e} mm \
                         of noise, {}), more than the {size} {u} a real arm's parameter reaches",
                        own * 100.0,
                        sigma * 1e3,
                        noise.source_text()
                    )
                } else {
                    format!(
                        "it barely moves the measured points at these configurations ({effect:.2e} mm RMS at its \
                         plausible size of {size} {u}, against {:.2e} mm of noise, {}), so the data would give it \
                         a standard deviation of {std:.2e} {u}; e.g. a rotation about an axis the reflector sits \
                         on, or a joint gravity does not load",
                        sigma * 1e3,
                        noise.source_text()
                    )
                };
                undetermined.push(Undetermined {
                    parameter: prm.name(),
                    std: std.is_finite().then_some(std),
                    plausible: size,
                    reason,
                    at_bound: false,
                });
            }
            _ => {
                if rest > 0.0 {
                    basis.push(v / rest);
                }
                kept_cols.push((c, col));
                kept.push(prm);
            }
        }
    }
    (kept, undetermined)
}

/// The structurally identifiable parameters among `candidates`, in their order (see the module notes):
/// the Jacobian at the start of `problem` over configurations drawn with a fixed seed, each carrying its
/// gravity torques when compliances are candidates.
pub(super) fn structural_set(
    problem: &Problem,
    lower: &[f64],
    upper: &[f64],
    candidates: &[Param],
    gravity: Option<&GravityModel>,
) -> Vec<Param> {
    let mut rng = ChaCha8Rng::seed_from_u64(STRUCT_SEED);
    let n = problem.dh.dof();
    let fixed = problem.dh.fixed_rotations();
    let points = (0..STRUCT_SAMPLES)
        .map(|_| {
            let q: Vec<f64> = (0..n)
                .map(|i| sample_within(lower[i], upper[i], &mut rng))
                .collect();
            synthetic_point(problem, gravity, &q, &fixed)
        })
        .collect();
    let structural = Problem {
        dh: problem.dh,
        points,
        length: problem.length,
        base: problem.base.clone(),
        params: candidates.to_vec(),
    };
    structural_columns(&structural, candidates)
}

/// A point that the initial state of `problem` fits exactly, so the Jacobian there is the one at the start:
/// its links, flange and gravity torques from one pass over the chain (`fixed`, its rows' fixed rotations).
pub(super) fn synthetic_point(
    problem: &Problem,
    gravity: Option<&GravityModel>,
    q: &[f64],
    fixed: &FixedRotations,
) -> Point {
    let pose = problem.dh.pose_fixed(q, fixed);
    let flange = pose.flange(problem.dh);
    let tau = gravity.map_or_else(Vec::new, |g| g.torques_on(problem.dh, &pose.frames));
    Point::with_links(
        pose.links,
        flange * problem.base.mount,
        problem.length.map(|_| flange.rotation),
        tau,
    )
}

/// The identification Jacobian of `kinematic` (or `elastic`) at the nominal model, before anything is
/// measured: what experiment design ([`crate::design`]) needs. The parameters are the structurally
/// identifiable set a fit would keep; the rows of a configuration are those its measured point would add
/// (3, or 6 when orientation is fitted). The tracker frame is taken as the base frame: the columns of a
/// tracker rotation about another point differ from these by tracker-translation columns, which changes no
/// observability index that is invariant to such reparametrization (the determinant up to a constant, and
/// the rank).
pub struct Identification<'a> {
    problem: Problem<'a>,
    gravity: Option<GravityModel>,
}

impl<'a> Identification<'a> {
    /// `mount`: the measured point in the flange frame (a nest's centroid); `length`: the weight of rotation
    /// rows (m/rad, a nest's RMS radius), `None` for a position-only measurement.
    pub fn new(
        elastic: bool,
        ctx: &FitContext<'a>,
        mount: Point3<f64>,
        length: Option<f64>,
    ) -> Result<Identification<'a>> {
        let n = ctx.dh.dof();
        let gravity = if elastic {
            Some(GravityModel::new(ctx.chain, ctx.dh, ctx.payload)?)
        } else {
            None
        };
        let all = candidates(n, elastic);
        let (lower, upper) = ctx.limits();
        let mut problem = Problem {
            dh: ctx.dh,
            points: Vec::new(),
            length,
            base: State::initial(n, mount),
            params: all.clone(),
        };
        problem.params = structural_set(&problem, &lower, &upper, &all, gravity.as_ref());
        Ok(Identification { problem, gravity })
    }

    /// The structurally identifiable parameters: the columns of [`Identification::jacobian`].
    pub fn params(&self) -> &[Param] {
        &self.problem.params
    }

    /// Rows per configuration: 3 for a point, 6 with orientation.
    pub fn rows_per_point(&self) -> usize {
        if self.problem.length.is_some() { 6 } else { 3 }
    }

    /// The Jacobian of the predicted measurement over the configurations `qs`, stacked in their order.
    pub fn jacobian(&self, qs: &[&[f64]]) -> DMatrix<f64> {
        let s = &self.problem;
        let fixed = s.dh.fixed_rotations();
        let probe = Problem {
            dh: s.dh,
            points: qs
                .iter()
                .map(|q| synthetic_point(s, self.gravity.as_ref(), q, &fixed))
                .collect(),
            length: s.length,
            base: s.base.clone(),
            params: s.params.clone(),
        };
        let x0: Vec<f64> = s.params.iter().map(|&p| s.base.get(p)).collect();
        probe.evaluate(&x0, true).1.expect("jacobian requested")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robot::Payload;
    use crate::robot::dh::DhChain;
    use crate::robot::urdf;

    /// The structural decisions are far from their thresholds: what is kept is independent by orders of
    /// magnitude, what is dropped is redundant to rounding (or acts nowhere), for position-only and nest
    /// campaigns, kinematic and elastic.
    #[test]
    fn structural_decisions_are_clear_cut() {
        let chain = urdf::load_file("robots/iiwa7.urdf", None).unwrap();
        let dh = DhChain::from_chain(&chain).unwrap();
        let payload = Payload {
            mass: 0.4,
            com: [0.0, 0.0, 0.03],
        };
        let gravity = GravityModel::new(&chain, &dh, payload).unwrap();
        let (lower, upper) = (chain.lower_limits(), chain.upper_limits());
        for length in [None, Some(0.05)] {
            let problem = Problem {
                dh: &dh,
                points: Vec::new(),
                length,
                base: State::initial(7, Point3::new(0.0006, -0.0004, 0.0302)),
                params: Vec::new(),
            };
            let all = candidates(7, true);
            let mut rng = ChaCha8Rng::seed_from_u64(STRUCT_SEED);
            let points = (0..STRUCT_SAMPLES)
                .map(|_| {
                    let q: Vec<f64> = (0..7)
                        .map(|i| sample_within(lower[i], upper[i], &mut rng))
                        .collect();
                    let f = dh.flange_pose(&q);
                    let tau = gravity.torques(&dh, &q);
                    Point::new(
                        &dh,
                        &q,
                        f * problem.base.mount,
                        length.map(|_| f.rotation),
                        tau,
                    )
                })
                .collect();
            let structural = Problem {
                points,
                params: all.clone(),
                ..problem
            };
            let analysis = structural_analysis(&structural, &all);
            let min_kept = analysis
                .iter()
                .filter(|a| a.kept)
                .map(|a| a.rest.min(a.relative_norm))
                .fold(f64::INFINITY, f64::min);
            // Dropped as acting nowhere (relative norm) or as redundant (rest).
            let vanishing = analysis
                .iter()
                .filter(|a| !a.kept && a.rest == 0.0)
                .map(|a| a.relative_norm)
                .fold(0.0, f64::max);
            let redundant = analysis
                .iter()
                .filter(|a| !a.kept && a.rest > 0.0)
                .map(|a| a.rest)
                .fold(0.0, f64::max);
            let names = |kept: bool| -> Vec<String> {
                analysis
                    .iter()
                    .filter(|a| a.kept == kept)
                    .map(|a| a.param.name())
                    .collect()
            };
            eprintln!(
                "nest {length:?}: kept {} (weakest {min_kept:.1e}); dropped {:?} (largest norm {vanishing:.1e}, \
                 largest rest {redundant:.1e})",
                names(true).len(),
                names(false),
            );
            assert!(min_kept > 1e-4, "{min_kept}");
            assert!(vanishing < 1e-7, "{vanishing}");
            assert!(redundant < 1e-10, "{redundant}");
        }
    }
}
