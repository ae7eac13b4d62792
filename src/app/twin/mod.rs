//! `campaign twin`: a twin of one measured arm, built from a short pilot campaign, so that the planning question
//! is answered for that arm rather than for a random one of its kind.
//!
//! Steps, each returning what the next takes: read and check the pilot ([`pilot`]); identify the arm — its
//! geometry and joint compliances by the elastic fit, carried over to the truth's joint frames
//! (`calib::kinematic::geometry`); measure the pilot's own statistics; fit the magnitudes of what no method models to
//! them ([`magnitudes`], [`fit`]); say which gravity torques the pilot covers against what each joint's range can produce
//! ([`coverage`]: a compliance is extrapolated outside the pilot's band, and a narrow band is warned about) and
//! how far the fit's compliances stray on the twin's own replays of the pilot ([`compliance`]); write
//! `twin.toml` ([`scenario`]), `twin.json` and `twin.md` ([`report`]).

pub mod answer;
pub mod compliance;
pub mod coverage;
pub mod fit;
pub mod magnitudes;
pub mod pilot;
pub mod report;
pub mod scenario;
pub mod thermal;

use std::path::PathBuf;

use nalgebra::{Isometry3, Point3, UnitQuaternion, Vector3};

use self::magnitudes::{DEFAULTS, Magnitude, SEEDS, Targets};
use self::pilot::{HeldOut, Repeats};
use self::scenario::{TwinValues, Workspace};
use crate::calib::kinematic::{KinematicModel, geometry};
use crate::calib::method::{FitContext, Fitted};
use crate::calib::registry::{MethodKind, PHYSICAL};
use crate::dataset::{Dataset, random_train_val};
use crate::error::{Error, Result};
use crate::eval::split::Parts;
use crate::output;
use crate::robot::dh::DhChain;
use crate::robot::{Chain, Payload};
use crate::truth::KnownGeometry;

/// The files a twin writes.
const OUTPUTS: [&str; 3] = ["twin.toml", "twin.json", "twin.md"];

/// What to build a twin from (the flags of `campaign twin`).
#[derive(Clone, Debug)]
pub struct TwinOptions {
    pub robot: PathBuf,
    pub flange_link: Option<String>,
    pub data: PathBuf,
    pub mapping: Option<PathBuf>,
    /// Drop the pilot's extra inputs (its temperature) so no method regresses on them.
    pub ignore_inputs: bool,
    /// The mass on the flange (the elastic fit's gravity torques, the twin's truth).
    pub payload: Payload,
    pub seed: u64,
    /// Draws of the twin its study is run for, to give the answer with a range (0: none).
    pub answer_draws: usize,
    pub out: PathBuf,
}

/// The arm as the pilot identifies it.
pub struct Identified {
    /// The elastic fit with the prior's pull ([`with_prior`]): what the twin is.
    pub model: KinematicModel,
    /// Per kept parameter, the fit's own value and standard deviation, before the prior.
    pub raw: Vec<(f64, f64)>,
    pub geometry: KnownGeometry,
    /// The last DH frame's error, an offset of the flange the URDF chain cannot hold: the probe carries it.
    pub flange: Isometry3<f64>,
    /// The largest difference between the model's rigid kinematics and the twin's (m).
    pub geometry_match_m: f64,
    /// Per joint: the compliance (rad/Nm) and its standard deviation, where the pilot determines it.
    pub compliance: Vec<Option<(f64, f64)>>,
    /// Per joint: the twin's stiffness (Nm/rad) where the fit keeps no compliance, and its source
    /// ([`unkept_stiffness`]).
    pub unkept_stiffness: Vec<(f64, String)>,
    /// Per joint: the pilot's range (rad).
    pub ranges: Vec<(f64, f64)>,
}

/// The pilot's statistics, real and replayed through the twin.
pub struct Statistics {
    pub real: Vec<HeldOut>,
    /// Per method, the twin's held-out means over its draws (mm).
    pub twin: Vec<(MethodKind, Vec<f64>)>,
    pub real_repeats: Option<Repeats>,
    pub twin_repeats: Vec<f64>,
}

/// What [`run`] built.
pub struct TwinOutcome {
    pub values: TwinValues,
    /// The pilot's points.
    pub points: usize,
    pub identified_parameters: usize,
    pub statistics: Statistics,
    /// The twin's answer over its draws (empty without `answer_draws`).
    pub answer: Vec<answer::RangeRow>,
    /// Per joint, the gravity torques the pilot loaded it with against those its range can produce.
    pub coverage: Vec<coverage::TorqueSpan>,
    /// Per identified compliance, the elastic fit's error on the twin's replays of the pilot.
    pub compliance: Vec<compliance::ComplianceCheck>,
    pub out: PathBuf,
}

impl TwinOutcome {
    /// What `campaign twin` prints.
    pub fn text(&self) -> String {
        report::console(self)
    }

    /// The line `campaign twin` warns with when the pilot's torque band is narrow on some joint.
    pub fn warning(&self) -> Option<String> {
        coverage::warning(&self.coverage)
    }
}

/// Builds the twin of the arm that measured `options.data` and writes `twin.toml`, `twin.json` and `twin.md`
/// into `options.out`, all or none.
pub fn run(options: &TwinOptions) -> Result<TwinOutcome> {
    output::check_dir(&options.out, &OUTPUTS)?;
    let chain = crate::robot::load(&options.robot, options.flange_link.as_deref())?;
    let dh = DhChain::from_chain(&chain)?;
    let (pilot, temperature) = pilot::read(
        &chain,
        &options.robot,
        &options.data,
        options.mapping.as_deref(),
        options.ignore_inputs,
    )?;
    pilot::check(&pilot, &chain)?;
    let ctx = FitContext {
        payload: options.payload,
        ..FitContext::new(&chain, &dh)
    };
    let identified = identify(&pilot, &ctx, &chain, options.seed)?;
    let coverage = coverage::torque_coverage(&chain, &dh, options.payload, &pilot.q, options.seed)?;
    let real = pilot::held_out(&pilot, &ctx, &MethodKind::ALL, options.seed);
    let mut values = initial_values(options, &pilot, &identified, &real)?;
    let targets = Targets {
        elastic_mm: elastic_mean(&real).ok_or_else(|| Error::Data {
            origin: pilot.origin.clone(),
            message:
                "the elastic fit fails on the pilot's folds: the pilot cannot identify the arm"
                    .into(),
        })?,
        repeats: Repeats::of(&pilot, &chain, &values.probe),
    };
    values.thermal = temperature.map(|t| thermal::warm_up(&t, pilot.time.as_deref()));
    fit::magnitudes(&mut values, &pilot, &ctx, &targets, options.seed)?;
    let compliance = compliance::check(&values, &identified, &pilot, &ctx, options.seed)?;
    let statistics = statistics(&values, &pilot, &ctx, real, targets.repeats, options.seed)?;
    let answer = answer::answer_range(&values, options.answer_draws)?;
    let outcome = TwinOutcome {
        answer,
        coverage,
        compliance,
        points: pilot.len(),
        identified_parameters: identified.model.kept.len(),
        values,
        statistics,
        out: options.out.clone(),
    };
    let files = report::files(&outcome, &identified, options)?;
    output::write_dir(&options.out, &files, &[])?;
    Ok(outcome)
}

fn elastic_mean(held: &[HeldOut]) -> Option<f64> {
    held.iter().find(|h| h.method == PHYSICAL)?.mean_mm
}

/// The elastic fit on the pilot (two thirds training, one third validation), its geometry in the truth's
/// terms and its compliances.
fn identify(pilot: &Dataset, ctx: &FitContext, chain: &Chain, seed: u64) -> Result<Identified> {
    let labels = random_train_val(pilot.len(), 2.0 / 3.0, seed)?;
    let Parts { train, val, .. } = Parts::of(pilot, labels);
    let fitted = KinematicModel::fit(true, ctx, &train, &val)
        .map_err(|e| e.in_data(&pilot.origin, "identifying the arm (elastic fit)"))?;
    let typical: Vec<(f64, String)> = chain
        .joints
        .iter()
        .map(|j| magnitudes::typical_stiffness(j.effort))
        .collect();
    let prior: Vec<f64> = typical.iter().map(|(k, _)| 1.0 / k).collect();
    let (model, raw) = with_prior(fitted, &prior);
    let unkept_stiffness = typical
        .into_iter()
        .enumerate()
        .map(|(j, t)| unkept_stiffness(&model, j, t))
        .collect();
    let ranges: Vec<(f64, f64)> = (0..chain.dof())
        .map(|j| {
            pilot
                .q
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), q| {
                    (lo.min(q[j]), hi.max(q[j]))
                })
        })
        .collect();
    let (geometry, flange, geometry_match_m) =
        geometry::known_geometry(chain, &model, &ranges, seed)?;
    let compliance = (0..chain.dof())
        .map(|j| {
            let name = format!("c{}", j + 1);
            let k = model.kept.iter().position(|p| p.name() == name)?;
            let value = model.values[k];
            let std = model.std.get(k).copied().unwrap_or(f64::NAN);
            (value > 0.0).then_some((value, std))
        })
        .collect();
    Ok(Identified {
        raw,
        model,
        geometry,
        flange,
        geometry_match_m,
        compliance,
        unkept_stiffness,
        ranges,
    })
}

/// The twin's stiffness of joint `j` where the fit keeps no compliance for it, and its source. Where the data
/// pull the compliance below zero and the fit holds it at the bound, the data say the joint is stiff, with the
/// standard deviation they give: the bound is drawn toward the prior as [`with_prior`] draws a fitted value
/// (a rigid arm's twin stays rigid). Elsewhere the pilot says nothing of it: the prior's `typical` stiffness.
fn unkept_stiffness(model: &KinematicModel, j: usize, typical: (f64, String)) -> (f64, String) {
    let name = crate::calib::kinematic::Param::Compliance(j).name();
    let bound = model
        .undetermined
        .iter()
        .find(|u| u.parameter == name && u.at_bound);
    match bound
        .and_then(|u| u.std)
        .filter(|s| s.is_finite() && *s > 0.0)
    {
        Some(sigma) => {
            // The posterior mean of 0 ± sigma with the prior mu ± mu.
            let mu = 1.0 / typical.0;
            let c = mu * sigma * sigma / (sigma * sigma + mu * mu);
            (
                1.0 / c,
                format!(
                    "the data pull it below zero; held at 0 ± {sigma:.1e} rad/Nm and drawn toward the prior \
                     (the stiffness of {}) by that standard deviation: {c:.2e} rad/Nm",
                    typical.1
                ),
            )
        }
        None => (
            typical.0,
            format!(
                "cited default: the pilot does not determine this joint's compliance; {}",
                typical.1
            ),
        ),
    }
}

/// Typical errors of an arm's joint frames (m, rad), the prior a twin's geometry is drawn toward where the
/// pilot says little: industrial arms' identified joint-frame errors are 0.1–1 mm and 0.1–1 mrad (Mooring,
/// Roth and Driels 1991; Nubiola and Bonev 2013 for an ABB IRB 1600); the upper middle, so that what the pilot
/// determines keeps its value.
const TYPICAL_FRAME_TRANSLATION_M: f64 = 5e-4;
const TYPICAL_FRAME_ROTATION_RAD: f64 = 1e-3;

/// The fit's geometric errors and compliances, each drawn toward its typical value by what its standard
/// deviation leaves open: the mean of the posterior with a normal prior of the typical size,
/// `(v/σ² + μ/τ²) / (1/σ² + 1/τ²)`. A pilot determines some parameters well and others hardly (a fifth of its
/// size, measured in the pilot's corner of the joint space); taken at face value, the poorly determined ones
/// act with their full, noisy size wherever the twin is used — on a real UR10, a twin from 200 points of one
/// series then erred 25–65 % more than the arm on the others. The tracker frame and the mounting are the
/// registration, not the arm, and stay as fitted. A joint's compliance is drawn toward `compliance[j]`, the
/// inverse of its typical stiffness, give or take as much. Returns the model and each kept parameter's fitted
/// value and standard deviation.
fn with_prior(mut model: KinematicModel, compliance: &[f64]) -> (KinematicModel, Vec<(f64, f64)>) {
    use crate::calib::kinematic::Param;
    let raw: Vec<(f64, f64)> = model
        .values
        .iter()
        .enumerate()
        .map(|(k, &v)| (v, model.std.get(k).copied().unwrap_or(f64::NAN)))
        .collect();
    for (k, p) in model.kept.clone().iter().enumerate() {
        let (prior, tau) = match p {
            Param::Error(e) if e.component <= 3 => (0.0, TYPICAL_FRAME_TRANSLATION_M),
            Param::Error(_) => (0.0, TYPICAL_FRAME_ROTATION_RAD),
            Param::Compliance(j) => (compliance[*j], compliance[*j]),
            _ => continue,
        };
        let (v, sigma) = raw[k];
        if !(sigma.is_finite() && sigma > 0.0) {
            continue;
        }
        let (wv, wp) = (1.0 / (sigma * sigma), 1.0 / (tau * tau));
        let pulled = (v * wv + prior * wp) / (wv + wp);
        model.values[k] = pulled;
        if let Some(s) = model.std.get_mut(k) {
            *s = (1.0 / (wv + wp)).sqrt();
        }
        match p {
            Param::Error(e) => model.errors[e.frame - 1][e.component - 1] = pulled,
            Param::Compliance(j) => {
                if let Some(c) = model.compliance.as_mut() {
                    c[*j] = pulled;
                }
            }
            _ => {}
        }
    }
    (model, raw)
}

/// The twin before its magnitudes are fitted: identified geometry and stiffness, cited magnitudes, the gears'
/// wave off, the tracker and probe where the pilot registered them, the pilot's workspace.
fn initial_values(
    options: &TwinOptions,
    pilot: &Dataset,
    identified: &Identified,
    real: &[HeldOut],
) -> Result<TwinValues> {
    let stiffness = identified
        .compliance
        .iter()
        .zip(&identified.unkept_stiffness)
        .map(|(c, (unkept, _))| c.map_or(*unkept, |(c, _)| 1.0 / c))
        .collect();
    let mut magnitudes: Vec<Magnitude> = DEFAULTS
        .iter()
        .map(|d| Magnitude {
            key: d.key.to_string(),
            value: d.value,
            unit: d.unit,
            std: None,
            source: format!("cited default: {}", d.source),
        })
        .collect();
    magnitudes.push(Magnitude {
        key: "truth.gear_wave_amplitude_rad".into(),
        value: 0.0,
        unit: "rad",
        std: None,
        source: "not fitted yet".into(),
    });
    let registration = identified.model.registration();
    let name = options.data.file_stem().map_or("twin".to_string(), |s| {
        format!("twin_{}", s.to_string_lossy())
    });
    Ok(TwinValues {
        name,
        seed: options.seed,
        robot: options.robot.display().to_string(),
        flange_link: options.flange_link.clone(),
        payload: options.payload,
        geometry: identified.geometry.clone(),
        stiffness,
        magnitudes,
        tracker: registration.frame.tracker_to_base,
        probe: identified.flange * registration.frame.mounting,
        facing: identified.flange.rotation * facing(pilot, &identified.model),
        posture_deg: median_configuration(pilot)
            .iter()
            .map(|q| q.to_degrees())
            .collect(),
        workspace: workspace(pilot, &identified.model),
        targets_mm: targets(real),
        thermal: None,
    })
}

/// Five accuracies to plan for, spaced evenly on a log scale from 5 % above the best held-out mean of the
/// pilot's methods to 10 % below its nominal one, at two significant digits.
fn targets(real: &[HeldOut]) -> Vec<f64> {
    let means: Vec<f64> = real.iter().filter_map(|h| h.mean_mm).collect();
    let best = means.iter().copied().fold(f64::INFINITY, f64::min) * 1.05;
    let worst = real
        .iter()
        .find(|h| h.method == crate::calib::registry::REFERENCE)
        .and_then(|h| h.mean_mm)
        .unwrap_or(best * 2.0)
        * 0.9;
    let (hi, lo) = (worst.max(best * 1.2), best);
    let round = |x: f64| format!("{x:.1e}").parse::<f64>().unwrap_or(x);
    let mut out: Vec<f64> = (0..5)
        .map(|k| round(hi * (lo / hi).powf(k as f64 / 4.0)))
        .collect();
    out.dedup();
    out
}

/// The direction from the probe toward the tracker, in the flange frame, averaged over the pilot: where a
/// reflector facing the tracker points.
fn facing(pilot: &Dataset, model: &KinematicModel) -> Vector3<f64> {
    let tracker = model
        .registration()
        .frame
        .tracker_to_base
        .translation
        .vector;
    let mut sum = Vector3::zeros();
    for q in &pilot.q {
        let f = model.flange_pose(q);
        let probe = f * model.registration().frame.mounting;
        sum += f.rotation.inverse() * (tracker - probe.coords).normalize();
    }
    sum.try_normalize(1e-9).unwrap_or(Vector3::z())
}

/// Per joint, the median of the pilot's angles.
fn median_configuration(pilot: &Dataset) -> Vec<f64> {
    let n = pilot.q.first().map_or(0, Vec::len);
    (0..n)
        .map(|j| {
            let mut v: Vec<f64> = pilot.q.iter().map(|q| q[j]).collect();
            v.sort_by(f64::total_cmp);
            v[v.len() / 2]
        })
        .collect()
}

/// Where the pilot's probe was (the central 90 % of each axis, at least 5 cm wide) and how the flange was
/// turned there (the mean orientation, the cone and spin holding 90 % of the pilot's).
fn workspace(pilot: &Dataset, model: &KinematicModel) -> Workspace {
    let mounting = model.registration().frame.mounting;
    let poses: Vec<_> = pilot.q.iter().map(|q| model.flange_pose(q)).collect();
    let points: Vec<Point3<f64>> = poses.iter().map(|f| f * mounting).collect();
    let quantile = |mut v: Vec<f64>, p: f64| {
        v.sort_by(f64::total_cmp);
        v[((v.len() - 1) as f64 * p).round() as usize]
    };
    let mut center_m = [0.0; 3];
    let mut size_m = [0.0; 3];
    for k in 0..3 {
        let axis: Vec<f64> = points.iter().map(|p| p[k]).collect();
        let (lo, hi) = (quantile(axis.clone(), 0.05), quantile(axis, 0.95));
        center_m[k] = 0.5 * (lo + hi);
        size_m[k] = (hi - lo).max(0.05);
    }
    let first = poses[0].rotation;
    let sum = poses.iter().fold(nalgebra::Vector4::zeros(), |acc, f| {
        let q = f.rotation.coords;
        acc + if q.dot(&first.coords) < 0.0 { -q } else { q }
    });
    let tool = UnitQuaternion::from_quaternion(nalgebra::Quaternion::from(sum));
    let z = tool * Vector3::z();
    let cone: Vec<f64> = poses
        .iter()
        .map(|f| (f.rotation * Vector3::z()).angle(&z).to_degrees())
        .collect();
    let spin: Vec<f64> = poses
        .iter()
        .map(|f| {
            let r = tool.inverse() * f.rotation;
            (2.0 * r.k.atan2(r.w)).abs().to_degrees()
        })
        .collect();
    Workspace {
        center_m,
        size_m,
        tool,
        cone_half_angle_deg: quantile(cone, 0.9).clamp(5.0, 80.0),
        spin_deg: quantile(spin, 0.9).clamp(5.0, 180.0),
    }
}

/// Every method on the pilot, real, and on the pilot replayed through each of the twin's draws.
fn statistics(
    values: &TwinValues,
    pilot: &Dataset,
    ctx: &FitContext,
    real: Vec<HeldOut>,
    real_repeats: Option<Repeats>,
    seed: u64,
) -> Result<Statistics> {
    let scenario = values.scenario()?;
    let mut twin: Vec<(MethodKind, Vec<f64>)> =
        MethodKind::ALL.iter().map(|&m| (m, Vec::new())).collect();
    let mut twin_repeats = Vec::new();
    for s in 0..SEEDS {
        let replayed = magnitudes::replay(&scenario, pilot, s)?;
        for (h, (_, means)) in pilot::held_out(&replayed, ctx, &MethodKind::ALL, seed)
            .iter()
            .zip(twin.iter_mut())
        {
            means.extend(h.mean_mm);
        }
        if let Some(r) = Repeats::of(&replayed, ctx.chain, &values.probe) {
            twin_repeats.push(r.mean_distance_m);
        }
    }
    Ok(Statistics {
        real,
        twin,
        real_repeats,
        twin_repeats,
    })
}
