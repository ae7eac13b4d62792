//! Classical calibration (`kinematic`) and its elasto-geometric extension (`elastic`): constant error
//! parameters fitted by Levenberg–Marquardt over all training points.
//!
//! Parameters, in priority order (earlier ones win where several describe the same motion):
//! 1. the tracker frame: a rotation vector on the left of the registration's rotation and a translation
//!    (`tracker_rx … tracker_z`), started from [`Registration::fit`];
//! 2. the mounting of the measured point in the flange frame (`mount_x … mount_z`);
//! 3. the generalized errors e_ik of every DH frame (eq. 6, `e11 … en6`), started from zero;
//! 4. for `elastic`, one compliance per joint (`c1 … cn`, rad/Nm): the commanded angles deflect by
//!    `δq_j = c_j τ_j(q)`, τ the gravity torques of the nominal inertials and the declared payload.
//!
//! Predicted point: `FK_E(q + δq) · mount`; predicted flange orientation: the rotation of `FK_E(q + δq)`.
//!
//! **Identifiable set.** Structural, so it cannot change with the data: the Jacobian of every candidate is
//! stacked over a fixed set of configurations (a fixed internal seed, uniform within the joint limits), each
//! column scaled to unit norm, and the columns are taken in the priority order above by Gram–Schmidt,
//! keeping a column only if its part orthogonal to the ones kept before it is at least [`STRUCT_REL`](identify::STRUCT_REL).
//! This is QR in a fixed column order rather than with column pivoting: exactly redundant columns (e22 and
//! e13 of the iiwa, the tracker frame and the base-side errors) have equal norms, so a pivoting QR would
//! choose between them on rounding noise; a fixed order makes the choice a property of the robot. A column
//! whose norm stays below [`VANISH_REL`](identify::VANISH_REL) of the largest of its kind (geometric, or compliance) has no
//! measurable effect anywhere and is dropped first — the compliance of a joint whose gravity torque is
//! structurally zero (joint 1 of a level arm, joint 7 of the iiwa with its on-axis link and payload) goes
//! this way. The training data must then identify that whole set: the singular values of the training
//! Jacobian (columns scaled to unit norm) give the rank and condition number that `report()` shows, and a
//! rank below the set's size is refused with the least determined parameters named.
//!
//! **What the data determine.** Structural redundancy is not the whole story: a reflector a few micrometres
//! from the last joint's axis makes the rotations about it structurally independent but unmeasurable, and a
//! small training set cannot fix every parameter. So the structural set is reduced on the training Jacobian
//! itself ([`identify::determined`]): in the same priority order, a parameter is kept only if its standard
//! deviation given the kept ones before it is below the size a real arm's parameter reaches; the others stay
//! nominal and are reported as [`Undetermined`], with the reason in words. What is left has full rank
//! unless the tracker frame or the mounting themselves are not determined (always kept, so then refused).
//!
//! **Reflector nests and 6-DoF probes.** With three reflectors the measured flange orientation is fitted too; a
//! rotation residual φ (rad) is weighted by the nest's RMS radius r (m), i.e. as the displacement `r·φ` it causes
//! at the reflectors, the quantity the tracker actually measured. A 6-DoF probe's orientation is fitted the same
//! way with r = [`PROBE_ORIENTATION_LENGTH_M`](super::tracker_frame::PROBE_ORIENTATION_LENGTH_M).
//!
//! **Solver.** The `levenberg-marquardt` crate (MINPACK's `lmder`) in coordinates whitened by the starting
//! Jacobian ([`solve::minimize`]), from the linearized (Gauss–Newton) solution: without whitening its diagonal
//! scaling zig-zags along the long valley that unmodelled elastic errors open in a weakly excited wrist. A fit
//! that does not converge within [`KinematicOptions::max_evaluations`] is an error, never a silent result.
//!
//! **Jacobian.** Analytic and exact at the current estimate: rotation parameters (tracker frame and every e_i4–6)
//! use SO(3)'s left Jacobian of their current value ([`so3_left_jacobian`](super::error_model::so3_left_jacobian)), so the derivative is not the
//! e = 0 one.
//!
//! **Files.** `params` (the candidates in priority order and the state they overwrite), `gravity` (gravity
//! torques on the DH chain for the compliances), `problem` (residuals and their analytic Jacobian), `solve`
//! (Levenberg–Marquardt in whitened coordinates), `identify` (the structural set, the rank check, the
//! identification Jacobian for design), and here the model: its fit, prediction and report.

mod gravity;
mod identify;
mod params;
mod problem;
mod solve;

use nalgebra::{DMatrix, DVector, Isometry3, Translation3, UnitQuaternion};
use serde::{Deserialize, Serialize};
use serde_json::json;

pub use gravity::GravityModel;
use identify::{Identifiability, determined, identifiability, standard_deviations, structural_set};
pub use identify::{Identification, MIN_NOISE_M, Undetermined};
use params::State;
pub use params::{Param, candidates};
use problem::{Point, Problem};
pub use solve::Termination;
use solve::minimize;

use super::domain::Domain;
use super::error_model::{ErrorFrames, FrameErrors};
use super::method::{Basis, Design, FitContext, Fitted, MethodInfo, Prediction};
use super::rigid::centre;
use super::tracker_frame::{Observation, Registration, TrackerFrame, fit_tracker_frame};
use crate::dataset::Dataset;
use crate::error::{Error, Result};
use crate::robot::plausible;

/// The largest |compliance| (rad/Nm; m/N for a prismatic joint) a saved model may have. Real joints deflect
/// by 1e-5 to 1e-3 rad under a newton-metre; one that turned a radian would hold nothing.
pub const MAX_COMPLIANCE: f64 = 1.0;

/// Tunables of the fit; the defaults are what `fit` uses.
#[derive(Clone, Debug)]
pub struct KinematicOptions {
    /// Levenberg–Marquardt stops with an error after this many residual evaluations (a well-posed fit
    /// needs about ten: the model is nearly linear in its small parameters).
    pub max_evaluations: usize,
}

impl Default for KinematicOptions {
    fn default() -> Self {
        KinematicOptions {
            max_evaluations: 400,
        }
    }
}

pub const KINEMATIC: MethodInfo = MethodInfo {
    name: "kinematic",
    summary: "classical calibration: constant DH-frame errors, tracker frame and mounting by Levenberg–Marquardt",
    takes_inputs: false,
    base: None,
    design: Design::Identification { elastic: false },
};

pub const ELASTIC: MethodInfo = MethodInfo {
    name: "elastic",
    summary: "kinematic calibration plus one joint compliance per joint under the nominal gravity torques",
    takes_inputs: false,
    base: None,
    design: Design::Identification { elastic: true },
};

fn method_from_name<'de, D: serde::Deserializer<'de>>(
    d: D,
) -> std::result::Result<&'static MethodInfo, D::Error> {
    MethodInfo::deserialize_among(d, &[&KINEMATIC, &ELASTIC])
}

/// Everything a later run needs to predict: `model.json`.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct KinematicModel {
    /// `kinematic` or `elastic`.
    #[serde(deserialize_with = "method_from_name")]
    pub method: &'static MethodInfo,
    /// The registration is the refined tracker frame and mounting: the one test data are observed through.
    #[serde(flatten)]
    pub basis: Basis,
    /// Per DH frame, the fitted [tx, ty, tz, rx, ry, rz] (zero where not kept).
    pub errors: FrameErrors,
    /// Per joint (rad/Nm; zero where not kept), `elastic` only.
    pub compliance: Option<Vec<f64>>,
    pub gravity: Option<GravityModel>,
    /// Weight of rotation residuals (m/rad): the nest's RMS radius; `None` without a nest.
    pub orientation_length_m: Option<f64>,
    /// The structurally identifiable parameters, in priority order, and their fitted values.
    pub kept: Vec<Param>,
    pub values: Vec<f64>,
    /// Standard deviation of each kept value from the training residuals (empty when there are no degrees
    /// of freedom left or the Jacobian is singular).
    #[serde(default)]
    pub std: Vec<f64>,
    /// Candidates left out as structurally redundant or without effect.
    pub dropped: Vec<Param>,
    /// Structurally identifiable parameters the training data do not determine, held at their nominal values.
    #[serde(default)]
    pub undetermined: Vec<Undetermined>,
    /// Rank and condition number of the training Jacobian (columns scaled to unit norm).
    pub rank: usize,
    pub condition_number: f64,
    /// Levenberg–Marquardt evaluations (residuals and Jacobian), and how it stopped.
    pub evaluations: usize,
    pub termination: Termination,
    /// RMS of the 3-D position residual over the training and validation points (m).
    pub train_rms_m: f64,
    pub validation_rms_m: Option<f64>,
}

impl KinematicModel {
    pub fn fit(
        elastic: bool,
        ctx: &FitContext,
        train: &Dataset,
        val: &Dataset,
    ) -> Result<KinematicModel> {
        KinematicModel::fit_with(elastic, ctx, train, val, &KinematicOptions::default())
    }

    pub fn fit_with(
        elastic: bool,
        ctx: &FitContext,
        train: &Dataset,
        val: &Dataset,
        options: &KinematicOptions,
    ) -> Result<KinematicModel> {
        let method = if elastic { &ELASTIC } else { &KINEMATIC };
        if train.is_empty() {
            return Err(Error::Invalid(format!("{method}: no training points")));
        }
        let dh = ctx.dh;
        let n = dh.dof();
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
        let registration = Registration::fit(dh, train, val)?;
        let gravity = if elastic {
            Some(GravityModel::new(ctx.chain, dh, ctx.payload)?)
        } else {
            None
        };
        let length = registration.orientation_length();
        let to_points = |obs: Vec<Observation>| -> Vec<Point> {
            obs.into_iter()
                .map(|o| Point {
                    tau: gravity
                        .as_ref()
                        .map_or_else(Vec::new, |g| g.torques(dh, &o.q)),
                    q: o.q,
                    y: o.position,
                    orientation: o.orientation,
                })
                .collect()
        };
        let base = State::initial(n, registration.frame.mounting);
        // Data in the base frame has no tracker frame to fit: the base's own errors take its place.
        let all: Vec<Param> = candidates(n, elastic)
            .into_iter()
            .filter(|p| {
                !(registration.base_frame
                    && matches!(p, Param::TrackerRotation(_) | Param::TrackerTranslation(_)))
            })
            .collect();

        // The structurally identifiable set, from configurations that do not depend on the data.
        let (lower, upper) = ctx.limits();
        let mut probe = Problem {
            dh,
            points: Vec::new(),
            length,
            base: base.clone(),
            params: all.clone(),
        };
        let structural = structural_set(&probe, &lower, &upper, &all, gravity.as_ref());
        let dropped: Vec<Param> = all
            .iter()
            .copied()
            .filter(|p| !structural.contains(p))
            .collect();

        // What the training data determine of it, at the noise the nominal model leaves: an upper bound of
        // what the fit will leave, so what is kept is determined whatever the fit explains. (Judging again at
        // the fitted residual was tried: it lets parameters of a near-axis reflector back in at some draws and
        // sizes, and the fit fails again.) The rest stays nominal and is reported.
        probe.points = to_points(registration.observe(train)?);
        probe.params = structural.clone();
        let x_struct: Vec<f64> = structural.iter().map(|&p| base.get(p)).collect();
        let j_struct = probe
            .evaluate(&x_struct, true)
            .1
            .expect("jacobian requested");
        // The noise is what the nominal model leaves after a rigid registration. Data in the base frame are
        // registered by the identity, whose residual also holds the base's own placement error — which this fit
        // identifies; judged at that residual, parameters were dropped that a tracker-frame fit keeps
        // (`kinematic` 0.208, now 0.190, against 0.134 mm in the tracker frame on the same points).
        let nominal_rms = if registration.base_frame {
            let measured: Vec<_> = train
                .measured
                .iter()
                .chain(&val.measured)
                .map(|m| centre(m))
                .collect();
            let flanges: Vec<_> = train
                .q
                .iter()
                .chain(&val.q)
                .map(|q| dh.flange_pose(q))
                .collect();
            fit_tracker_frame(&measured, &flanges, &registration.frame.mounting)?.rms
        } else {
            registration.frame.rms
        };
        let sigma = (nominal_rms / 3f64.sqrt()).max(MIN_NOISE_M);
        // Compliances are non-negative: a fit that pulls one below zero holds it at zero (the bound) and is
        // repeated without it, one at a time from the most negative — an active-set bounded least squares.
        let mut at_bound: Vec<Undetermined> = Vec::new();
        let (kept, mut undetermined, id, minimum, values, std) = loop {
            let (mut kept, mut undetermined) =
                determined(&j_struct, &structural, sigma, probe.points.len());
            let bound = |p: &Param| at_bound.iter().any(|u| u.parameter == p.name());
            kept.retain(|p| !bound(p));
            let (id, minimum, values, std) = solve_kept(&mut probe, &base, &kept, options, method)?;
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
                });
                continue;
            }
            undetermined.retain(|u| !at_bound.iter().any(|b| b.parameter == u.parameter));
            break (kept, undetermined, id, minimum, values, std);
        };
        undetermined.extend(
            structurally_dropped(&dropped)
                .into_iter()
                .filter(|u| u.parameter.starts_with('c')),
        );
        undetermined.extend(at_bound);
        let state = State::with(&base, &kept, &values);
        let rms = |points: &[Point]| -> f64 {
            let sum: f64 = points
                .iter()
                .map(|pt| {
                    let qd = state.deflected(&pt.q, &pt.tau);
                    let p = ErrorFrames::new(dh, &qd, &state.errors).flange * state.mount;
                    let v = UnitQuaternion::from_scaled_axis(state.rho) * pt.y.coords + state.t;
                    (p.coords - v).norm_squared()
                })
                .sum();
            (sum / points.len() as f64).sqrt()
        };
        let train_rms = rms(&probe.points);
        if !train_rms.is_finite() || values.iter().any(|v| !v.is_finite()) {
            return Err(Error::Invalid(format!(
                "{method}: the fit produced non-finite parameters"
            )));
        }
        let val_points = if val.is_empty() {
            Vec::new()
        } else {
            to_points(registration.observe(val)?)
        };
        let validation_rms = (!val_points.is_empty()).then(|| rms(&val_points));
        let initial = registration.frame.tracker_to_base;
        let refined = Isometry3::from_parts(
            Translation3::from(state.t),
            UnitQuaternion::from_scaled_axis(state.rho),
        ) * initial;
        Ok(KinematicModel {
            method,
            basis: Basis {
                joint_names: train.joint_names.clone(),
                dh: dh.clone(),
                registration: Registration {
                    frame: TrackerFrame {
                        tracker_to_base: refined,
                        mounting: state.mount,
                        rms: train_rms,
                        evaluations: minimum.evaluations,
                    },
                    nest: registration.nest,
                    probe_rotation: registration.probe_rotation,
                    base_frame: registration.base_frame,
                },
                domain: Domain::of(train, val),
            },
            errors: state.errors.clone(),
            compliance: elastic.then(|| state.compliance.clone()),
            gravity,
            orientation_length_m: length,
            kept,
            values,
            std,
            dropped,
            undetermined,
            rank: id.rank,
            condition_number: id.condition,
            evaluations: minimum.evaluations,
            termination: minimum.termination,
            train_rms_m: train_rms,
            validation_rms_m: validation_rms,
        })
    }

    /// A model read from a file can predict: its basis is valid ([`Basis::validate`]); one error row per DH
    /// row, translations plausible lengths and rotations plausible angles; `elastic` has one compliance per
    /// joint (at most [`MAX_COMPLIANCE`]) and a valid gravity model, `kinematic` neither; the kept
    /// parameters belong to the chain, one value each; every reported number finite.
    pub fn validate(&self) -> Result<()> {
        self.basis.validate()?;
        let n = self.basis.joint_names.len();
        let elastic = self.method.name == ELASTIC.name;
        plausible::count("errors", self.errors.len(), n, "DH rows (one per joint)")?;
        for (i, row) in self.errors.iter().enumerate() {
            for (k, &v) in row.iter().enumerate() {
                let field = format!("errors[{i}][{k}]");
                if k < 3 {
                    plausible::length(&field, v)?;
                } else {
                    plausible::angle(&field, v)?;
                }
            }
        }
        match (elastic, &self.compliance, &self.gravity) {
            (true, Some(c), Some(g)) => {
                plausible::count("compliance", c.len(), n, "joints")?;
                for (j, &v) in c.iter().enumerate() {
                    plausible::non_negative(
                        &format!("compliance[{j}]"),
                        v,
                        MAX_COMPLIANCE,
                        "compliance in rad/Nm",
                    )?;
                }
                plausible::within("gravity", g.validate(n))?;
            }
            (false, None, None) => {}
            (true, ..) => {
                return Err(plausible::invalid(
                    "compliance",
                    "the elastic method needs both compliance and gravity",
                ));
            }
            (false, ..) => {
                return Err(plausible::invalid(
                    "compliance",
                    "the kinematic method has neither compliance nor gravity (null)",
                ));
            }
        }
        if let Some(l) = self.orientation_length_m {
            plausible::non_negative(
                "orientation_length_m",
                l,
                plausible::MAX_LENGTH_M,
                "length in metres",
            )?;
        }
        plausible::count(
            "values",
            self.values.len(),
            self.kept.len(),
            "kept parameters",
        )?;
        for (field, params) in [("kept", &self.kept), ("dropped", &self.dropped)] {
            if let Some(i) = params.iter().position(|p| !p.belongs_to(n, elastic)) {
                return Err(plausible::invalid(
                    &format!("{field}[{i}]"),
                    format!(
                        "{:?} is not a parameter of {} on {n} joints",
                        params[i], self.method.name
                    ),
                ));
            }
        }
        for (i, &v) in self.values.iter().enumerate() {
            plausible::length(&format!("values[{i}]"), v)?;
        }
        if !self.std.is_empty() {
            plausible::count("std", self.std.len(), self.kept.len(), "kept parameters")?;
            for (i, &v) in self.std.iter().enumerate() {
                plausible::non_negative(&format!("std[{i}]"), v, f64::MAX, "standard deviation")?;
            }
        }
        if self.rank > self.kept.len() {
            return Err(plausible::invalid(
                "rank",
                format!(
                    "{} is above the {} kept parameters",
                    self.rank,
                    self.kept.len()
                ),
            ));
        }
        plausible::finite("condition_number", self.condition_number)?;
        let rms = |field: &str, v: f64| {
            plausible::non_negative(field, v, plausible::MAX_LENGTH_M, "RMS in metres")
        };
        rms("train_rms_m", self.train_rms_m)?;
        if let Some(v) = self.validation_rms_m {
            rms("validation_rms_m", v)?;
        }
        Ok(())
    }

    /// Per joint of an `elastic` model: the compliance (rad/Nm), its standard deviation, and whether the data
    /// determined it (else why not); empty for `kinematic`.
    pub fn compliances(&self) -> Vec<serde_json::Value> {
        let Some(c) = &self.compliance else {
            return Vec::new();
        };
        c.iter()
            .enumerate()
            .map(|(j, &value)| {
                let name = Param::Compliance(j).name();
                let std = self
                    .kept
                    .iter()
                    .position(|&p| p == Param::Compliance(j))
                    .and_then(|i| self.std.get(i));
                let why = self.undetermined.iter().find(|u| u.parameter == name);
                json!({
                    "joint": self.basis.joint_names.get(j),
                    "parameter": name,
                    "value_rad_per_nm": value,
                    "std_rad_per_nm": std,
                    "determined": why.is_none() && std.is_some(),
                    "undetermined_because": why.map(|u| &u.reason),
                })
            })
            .collect()
    }

    /// Names of the kept parameters, in priority order.
    pub fn kept_names(&self) -> Vec<String> {
        self.kept.iter().map(|p| p.name()).collect()
    }

    /// The calibrated flange pose at commanded `q`.
    pub fn flange_pose(&self, q: &[f64]) -> Isometry3<f64> {
        let qd: Vec<f64> = match (&self.gravity, &self.compliance) {
            (Some(g), Some(c)) => g
                .torques(&self.basis.dh, q)
                .iter()
                .zip(c)
                .zip(q)
                .map(|((t, c), q)| q + c * t)
                .collect(),
            _ => q.to_vec(),
        };
        ErrorFrames::new(&self.basis.dh, &qd, &self.errors).flange
    }
}

/// Levenberg–Marquardt on `kept` from the base state: the rank check first (a rank below the set's size is
/// refused, naming the least determined), then the fit, its values and their standard deviations.
fn solve_kept(
    probe: &mut Problem,
    base: &State,
    kept: &[Param],
    options: &KinematicOptions,
    method: &MethodInfo,
) -> Result<(Identifiability, solve::Minimum, Vec<f64>, Vec<f64>)> {
    probe.params = kept.to_vec();
    let x0: Vec<f64> = kept.iter().map(|&p| base.get(p)).collect();
    let (_, j0) = probe.evaluate(&x0, true);
    let id = identifiability(&j0.expect("jacobian requested"), kept);
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
        &whitening,
        options.max_evaluations.max(2),
    )
    .map_err(|why| {
        Error::Invalid(format!(
            "{method}: Levenberg–Marquardt did not converge ({why}); the data may be \
             inconsistent with a constant-error model"
        ))
    })?;
    let values: Vec<f64> = minimum.x.iter().copied().collect();
    let (r, j) = probe.evaluate(&values, true);
    let std = standard_deviations(&j.expect("jacobian requested"), &r).unwrap_or_default();
    Ok((id, minimum, values, std))
}

/// What the structural analysis drops, in words: a compliance because gravity (and the declared payload)
/// never load its joint within the limits, a frame error because at no configuration does it move the
/// measured point other than as parameters kept before it do.
fn structurally_dropped(dropped: &[Param]) -> Vec<Undetermined> {
    dropped
        .iter()
        .map(|p| Undetermined {
            parameter: p.name(),
            std: None,
            plausible: identify::plausible_size(*p).unwrap_or(0.0),
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

impl Fitted for KinematicModel {
    fn info(&self) -> &'static MethodInfo {
        self.method
    }

    fn basis(&self) -> &Basis {
        &self.basis
    }

    fn predict(&self, q: &[f64]) -> Prediction {
        let f = self.flange_pose(q);
        let position = f * self.basis.registration.frame.mounting;
        Prediction {
            position,
            linearized_position: position,
            orientation: f.rotation,
        }
    }

    fn models_orientation(&self) -> bool {
        self.basis.registration.measures_orientation()
    }

    fn report(&self, test: &[Observation]) -> serde_json::Value {
        let test_rms = (!test.is_empty()).then(|| {
            let sum: f64 = test
                .iter()
                .map(|o| (o.position - self.predict(&o.q).position).norm_squared())
                .sum();
            (sum / test.len() as f64).sqrt()
        });
        let values: serde_json::Map<String, serde_json::Value> = self
            .kept
            .iter()
            .zip(&self.values)
            .map(|(p, v)| (p.name(), json!(v)))
            .collect();
        json!({
            "kept_parameters": self.kept_names(),
            "dropped_parameters": self.dropped.iter().map(|p| p.name()).collect::<Vec<_>>(),
            "undetermined": self.undetermined,
            "std": self.kept.iter().zip(&self.std).map(|(p, s)| (p.name(), json!(s))).collect::<serde_json::Map<_, _>>(),
            "rank": self.rank,
            "condition_number": self.condition_number,
            "evaluations": self.evaluations,
            "termination": self.termination,
            "train_rms_m": self.train_rms_m,
            "validation_rms_m": self.validation_rms_m,
            "test_rms_m": test_rms,
            "orientation_length_m": self.orientation_length_m,
            "compliance_rad_per_nm": self.compliance,
            "compliances": self.compliances(),
            "values": values,
        })
    }
}
