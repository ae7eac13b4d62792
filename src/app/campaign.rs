//! The `campaign` job: simulate the scenario's campaign, evaluate the listed methods when it has an
//! `[evaluation]`, run its `[study]` when it has one, and write every result file at once.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use serde::Serialize;
use serde_json::{Value, json};

use crate::campaign::{Simulation, trajectory};
use crate::error::{Error, Result};
use crate::eval::iso9283::{self, Iso9283};
use crate::eval::{self, Budget, Evaluation, Stats};
use crate::report::answer::answer_text;
use crate::report::metrics::worse_than_nominal;
use crate::scenario::Scenario;
use crate::study::shard::assemble;
use crate::study::sweep::{self, Progress, RunOptions};
use crate::study::{StudyPart, StudyResult};
use crate::tracker::TrackerConfig;
use crate::{measurements, output, report};

/// Every file a campaign may write at the top of its directory; a rerun replaces any of them (a file the
/// new run does not write, such as an `evaluation.json`, does not survive).
const OUTPUTS: &[&str] = &[
    "measurements.csv",
    "truth.csv",
    "campaign.json",
    "evaluation.json",
    "iso9283.csv",
    "metrics.csv",
    "outside.csv",
    "answer.csv",
    "trajectory.csv",
    "summary.md",
    "plots",
    "campaign.rrd",
];

/// How to run the job.
#[derive(Clone, Debug, Default)]
pub struct CampaignOptions {
    /// Output directory; `results/<scenario name>` when absent.
    pub out: Option<PathBuf>,
    /// Keep the wall-clock fit times in the study's `fit_ms` column (otherwise NaN, so that the files are
    /// byte-identical for the same scenario whatever the machine and thread count).
    pub timings: bool,
    /// Replay this real campaign instead of the scenario's regions (its `[evaluation]` and `[study]` are not
    /// run then).
    pub replay: Option<ReplaySource>,
    /// Run a study above the time budget ([`super::STUDY_BUDGET_S`]).
    pub long: bool,
    /// The study's runs as computed by shards ([`super::shard::merge`]): the study is assembled from them
    /// instead of being run.
    pub parts: Option<Vec<StudyPart>>,
}

/// A real campaign to replay: the file, and the column mapping it is read through (a `measurements.csv`
/// without one).
#[derive(Clone, Debug)]
pub struct ReplaySource {
    pub file: PathBuf,
    pub mapping: Option<PathBuf>,
}

/// What the job did, for the binary to print.
pub struct CampaignRun {
    pub scenario: Scenario,
    pub sim: Simulation,
    /// How long the campaign took to simulate.
    pub generated: Duration,
    /// The measured errors after rigid registration (the paper's Table 1 "Measured" column), m.
    pub measured: Stats,
    pub budget: Budget,
    pub evaluation: Option<(Evaluation, Duration)>,
    /// With `[iso9283]`: the standard's test of every evaluated method.
    pub iso9283: Option<Iso9283>,
    pub study: Option<(StudyResult, Duration)>,
    /// With `--replay`: what placed the tracker and the reflector.
    pub replay: Option<ReplayReport>,
    /// With `[campaign.trajectory]`: what measuring on the fly took and did.
    pub motion: Option<MotionReport>,
    /// Where the files went.
    pub out: PathBuf,
}

/// Runs `scenario` and writes `measurements.csv`, `truth.csv`, `campaign.json`, and, as the scenario asks,
/// `evaluation.json` and the study's files, into the output directory, all or none.
pub fn run(mut scenario: Scenario, options: &CampaignOptions) -> Result<CampaignRun> {
    if let Some(out) = &options.out {
        output::check_dir(out, OUTPUTS)?;
    }
    if options.parts.is_none() {
        super::check_study_budget(&scenario, rayon::current_num_threads(), options.long)?;
    }
    let started = Instant::now();
    let (sim, replay) = simulate_or_replay(&mut scenario, options)?;
    let (sim, motion) = match replay {
        None => on_the_fly(&scenario, sim)?,
        Some(_) => (sim, None),
    };
    if replay.is_some() {
        scenario.evaluation = None;
        scenario.iso9283 = None;
        scenario.study = None;
    }
    let generated = started.elapsed();
    let campaign = &sim.campaign;

    let measured = eval::measured(campaign)?;
    let commands: Vec<Vec<f64>> = campaign.points.iter().map(|p| p.q_cmd.clone()).collect();
    let world = &sim.world;
    let budget = Budget::of(&world.nominal, &world.robot, &world.mounting, &commands)?;

    let out = options
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("results").join(&scenario.world.name));
    let report = campaign_json(
        &scenario,
        &sim,
        &measured,
        &budget,
        replay.as_ref(),
        motion.as_ref(),
    )?;
    let mut files: Vec<(String, Vec<u8>)> = vec![
        (
            "measurements.csv".into(),
            measurements::measurements_csv(campaign)?,
        ),
        ("truth.csv".into(), measurements::truth_csv(campaign)?),
        ("campaign.json".into(), to_json("campaign.json", &report)?),
    ];
    let (evaluation, iso9283) = evaluate(&scenario, &sim)?;
    if let Some((evaluation, _)) = &evaluation {
        files.push((
            "evaluation.json".into(),
            to_json("evaluation.json", evaluation)?,
        ));
    }
    if let Some(iso) = &iso9283 {
        files.push(("iso9283.csv".into(), iso.csv()?));
    }
    let study = study(&scenario, &sim, options)?;
    if let Some((study, _)) = &study {
        files.extend(report::study_files(study, &world.nominal)?);
    }
    if let Some(iso) = &iso9283 {
        with_iso9283(&mut files, &scenario.world.name, iso);
    }
    output::write_dir(&out, &files, OUTPUTS)?;
    Ok(CampaignRun {
        scenario,
        sim,
        generated,
        measured,
        budget,
        evaluation,
        iso9283,
        study,
        replay,
        motion,
        out,
    })
}

/// `summary.md` with the ISO 9283 section at its end; a campaign without a study gets one holding only that.
fn with_iso9283(files: &mut Vec<(String, Vec<u8>)>, name: &str, iso: &iso9283::Iso9283) {
    let section = report::summary::iso9283_md(iso);
    match files.iter_mut().find(|(f, _)| f == "summary.md") {
        Some((_, bytes)) => bytes.extend(format!("\n{section}").into_bytes()),
        None => files.push((
            "summary.md".into(),
            format!("# Campaign `{name}`\n\n{section}").into_bytes(),
        )),
    }
}

/// The scenario's campaign, or with `--replay` the real campaign's configurations measured in the scenario's
/// world (which the replay places where the real tracker and reflector were).
fn simulate_or_replay(
    scenario: &mut Scenario,
    options: &CampaignOptions,
) -> Result<(Simulation, Option<ReplayReport>)> {
    let Some(source) = &options.replay else {
        return Ok((super::simulate(scenario)?, None));
    };
    if scenario.campaign.trajectory.is_some() {
        return Err(Error::Scenario {
            origin: scenario.origin.clone(),
            message: "campaign.trajectory with --replay: a replay reproduces the real campaign's points as \
                      they were measured; drop one"
                .into(),
        });
    }
    let data = super::replay::read(
        &scenario.load_robot()?,
        &source.file,
        source.mapping.as_deref(),
    )?;
    let replay = super::replay::replay(scenario, &data, 0)?;
    let frame = &replay.registration.frame;
    let report = ReplayReport {
        file: source.file.clone(),
        mapping: source.mapping.clone(),
        rows: data.len(),
        registration_rms_m: frame.rms,
        mounting_m: frame.mounting.coords.into(),
        placement_residual_rad: replay.placement_residual_rad,
    };
    Ok((replay.sim, Some(report)))
}

/// With `[campaign.trajectory]`, the campaign measured on the fly: the planned targets become the waypoints of
/// one path, sampled as the arm moves.
fn on_the_fly(scenario: &Scenario, sim: Simulation) -> Result<(Simulation, Option<MotionReport>)> {
    let Some(config) = &scenario.campaign.trajectory else {
        return Ok((sim, None));
    };
    let moved = trajectory::measure(
        &sim.world,
        &sim.campaign,
        &scenario.campaign.posture_rad(),
        config,
        sim.world.seed(),
    )
    .map_err(|e| e.in_scenario(&scenario.origin))?;
    let motion = MotionReport {
        targets: sim.campaign.points.len(),
        samples: moved.campaign.points.len(),
        duration_s: moved.duration_s,
        clock_offset_s: config.clock_offset_s,
        dynamic_max_mm: moved.dynamic_m.iter().fold(0.0, |a: f64, d| a.max(*d)) * 1e3,
        lost_acceptance_cone: moved.lost_acceptance_cone,
        lost_line_of_sight: moved.lost_line_of_sight,
    };
    let sim = Simulation {
        world: sim.world,
        campaign: moved.campaign,
    };
    Ok((sim, Some(motion)))
}

/// `campaign.json`: the scenario, the campaign's size and rejections, the drawn truth, the measured errors and
/// the error budget, and what a replay or a motion did.
fn campaign_json(
    scenario: &Scenario,
    sim: &Simulation,
    measured: &Stats,
    budget: &Budget,
    replay: Option<&ReplayReport>,
    motion: Option<&MotionReport>,
) -> Result<Value> {
    let (world, campaign) = (&sim.world, &sim.campaign);
    let q = world.tracker.pose.rotation.quaternion();
    let report = json!({
        "scenario": scenario,
        "points": campaign.points.len(),
        "rejections": campaign.rejections,
        "truth": {
            "perturbation": world.robot.perturbation,
            "mounting": world.mounting,
            "tracker_pose": {
                "translation_m": <[f64; 3]>::from(world.tracker.pose.translation.vector),
                "rotation_quaternion_wxyz": [q.w, q.i, q.j, q.k],
            },
        },
        "measured_mm": measured.scaled(1e3),
        "error_budget_mm": {
            "all_systematic": budget.all_systematic.scaled(1e3),
            "elastic_only": budget.elastic_only.scaled(1e3),
            "rigid_only": budget.rigid_only.scaled(1e3),
        },
    });
    let mut report = report;
    if let Some(r) = replay {
        report["replay"] =
            serde_json::to_value(r).map_err(|e| Error::Invalid(format!("campaign.json: {e}")))?;
    }
    if let Some(m) = motion {
        report["trajectory"] =
            serde_json::to_value(m).map_err(|e| Error::Invalid(format!("campaign.json: {e}")))?;
    }
    Ok(report)
}

/// An evaluation and how long it took.
type Timed = (Evaluation, Duration);

/// The scenario's `[evaluation]`, timed, when it has one, and its `[iso9283]` test of the same fitted methods.
fn evaluate(scenario: &Scenario, sim: &Simulation) -> Result<(Option<Timed>, Option<Iso9283>)> {
    let Some(config) = &scenario.evaluation else {
        return Ok((None, None));
    };
    let started = Instant::now();
    let (campaign, regions) = (&scenario.campaign, &scenario.regions);
    let fits = eval::fit_all(sim, config)?;
    let evaluation = eval::judge_all(sim, campaign, regions, config, &fits)?;
    let took = started.elapsed();
    let iso = match &scenario.iso9283 {
        Some(iso) => Some(
            iso9283::run(sim, campaign, regions, iso, &fits)
                .map_err(|e| e.in_scenario(&scenario.origin))?,
        ),
        None => None,
    };
    Ok((Some((evaluation, took)), iso))
}

/// The scenario's `[study]`, timed, when it has one: run here, or assembled from the shards' parts.
fn study(
    scenario: &Scenario,
    sim: &Simulation,
    options: &CampaignOptions,
) -> Result<Option<(StudyResult, Duration)>> {
    if scenario.study.is_none() {
        return Ok(None);
    }
    let started = Instant::now();
    let config = super::study_config(scenario)?;
    let world = &sim.world;
    let study = match &options.parts {
        Some(parts) => assemble(world, &scenario.regions, config, parts.clone()),
        None => sweep::run_study(
            world,
            &scenario.campaign,
            &scenario.regions,
            config,
            RunOptions {
                progress: Progress::Auto,
                timings: options.timings,
            },
        )?,
    };
    Ok(Some((study, started.elapsed())))
}

/// A campaign measured on the fly (`campaign.json`'s `trajectory`).
#[derive(Clone, Debug, Serialize)]
pub struct MotionReport {
    /// The planned targets the path passes through.
    pub targets: usize,
    /// The tracker samples kept: the campaign's points.
    pub samples: usize,
    /// The path's duration: the tracker time the campaign takes (s).
    pub duration_s: f64,
    /// The controller's clock minus the tracker's, as simulated (s): what `calibrate` should find.
    pub clock_offset_s: f64,
    /// The largest flange displacement due to the motion over the kept samples (mm).
    pub dynamic_max_mm: f64,
    /// Samples the tracker missed between the targets: a reflector turned out of its acceptance cone, or a link
    /// in the beam.
    pub lost_acceptance_cone: usize,
    pub lost_line_of_sight: usize,
}

/// How a replay placed the simulated tracker and reflector (`campaign.json`'s `replay`).
#[derive(Clone, Debug, Serialize)]
pub struct ReplayReport {
    pub file: PathBuf,
    pub mapping: Option<PathBuf>,
    pub rows: usize,
    /// RMS of the registration of the real data on the nominal robot (m): how far the nominal robot is from
    /// the real one, with the real tracker's noise.
    pub registration_rms_m: f64,
    /// The registered point on the flange, the simulated reflector's nominal position (m).
    pub mounting_m: [f64; 3],
    /// The angle between the registered tracker rotation and the scenario's yaw and tilts written from it (rad).
    pub placement_residual_rad: f64,
}

fn to_json(name: &str, value: &impl serde::Serialize) -> Result<Vec<u8>> {
    serde_json::to_vec_pretty(value).map_err(|e| Error::Invalid(format!("{name}: {e}")))
}

impl CampaignRun {
    /// What `campaign` prints: the campaign, its errors before calibration, and what the replay, the
    /// evaluation and the study did.
    pub fn text(&self) -> String {
        let mut text = self.campaign_text();
        text += &self.errors_text();
        if let Some(r) = &self.replay {
            text += &r.text(&self.scenario.world.tracker);
        }
        if let Some((evaluation, took)) = &self.evaluation {
            text += &evaluation.table();
            text += &format!(
                "evaluated {} methods in {:.2} s\n",
                evaluation.methods.len(),
                took.as_secs_f64()
            );
        }
        if let Some(iso) = &self.iso9283 {
            text += &iso.table();
        }
        if let Some((study, took)) = &self.study {
            text += &study_text(study, *took);
        }
        text + &format!("wrote {}\n", self.out.display())
    }

    /// The campaign's size, each region's rejections, and the motion when measured on the fly.
    fn campaign_text(&self) -> String {
        let campaign = &self.sim.campaign;
        let mut text = format!(
            "scenario '{}': {} points in {:.2} s\n",
            self.scenario.world.name,
            campaign.points.len(),
            self.generated.as_secs_f64()
        );
        for (region, r) in &campaign.rejections {
            text += &format!(
                "  region '{region}': {} used of {} feasible from {} candidates (rejected: {} out of reach, {} joint limits, \
                 {} self-collision, {} obstacle, {} line of sight, {} acceptance cone)\n",
                r.used,
                r.feasible,
                r.candidates,
                r.out_of_reach,
                r.joint_limits,
                r.self_collision,
                r.environment_collision,
                r.line_of_sight,
                r.acceptance_cone
            );
        }
        if let Some(m) = &self.motion {
            text += &m.text();
        }
        text
    }

    /// The measured errors and the error budget (mm).
    fn errors_text(&self) -> String {
        let row = |name: &str, s: &Stats| {
            let s = s.scaled(1e3);
            format!(
                "  {name:<34} mean {:.4}  std {:.4}  max {:.4}  rms {:.4}  p95 {:.4}\n",
                s.mean, s.std, s.max, s.rms, s.p95
            )
        };
        let mut text = if self.study.is_some() {
            "the scenario's own campaign before calibration (not the study's answer, which follows), distance \
             errors after rigid registration (mm):\n"
                .to_string()
        } else {
            "distance errors of the reflector (or nest centre) after rigid registration (mm):\n"
                .to_string()
        };
        text += &row("measured (paper's Table 1 column)", &self.measured);
        text += &row("true, all systematic errors", &self.budget.all_systematic);
        text += &row("true, elastic deflection only", &self.budget.elastic_only);
        text += &row("true, rigid errors only", &self.budget.rigid_only);
        text
    }
}

impl MotionReport {
    fn text(&self) -> String {
        format!(
            "  measured on the fly: {} samples along one path through {} targets, {:.1} s of tracker time; motion \
             moved the flange by up to {:.3} mm; clock offset {:.1} µs (calibrate estimates and removes it); \
             beam lost at {} samples ({} acceptance cone, {} line of sight)\n",
            self.samples,
            self.targets,
            self.duration_s,
            self.dynamic_max_mm,
            self.clock_offset_s * 1e6,
            self.lost_acceptance_cone + self.lost_line_of_sight,
            self.lost_acceptance_cone,
            self.lost_line_of_sight
        )
    }
}

impl ReplayReport {
    /// Where the replay placed the tracker (the scenario's, rewritten by the replay) and the reflector.
    fn text(&self, t: &TrackerConfig) -> String {
        let m = self.mounting_m.map(|v| v * 1e3);
        format!(
            "replayed {} rows of {}: real data registered with RMS {:.4} mm; tracker placed at [{:.4}, {:.4}, {:.4}] m, \
             yaw {:.4}°, tilts [{:.4}, {:.4}]° (decomposition residual {:.1e} rad); reflector at \
             [{:.3}, {:.3}, {:.3}] mm on the flange\n",
            self.rows,
            self.file.display(),
            self.registration_rms_m * 1e3,
            t.position_m[0],
            t.position_m[1],
            t.position_m[2],
            t.yaw_deg,
            t.tilt_deg[0],
            t.tilt_deg[1],
            self.placement_residual_rad,
            m[0],
            m[1],
            m[2]
        )
    }
}

/// The study's runs, failures and flags, then its answer.
fn study_text(study: &StudyResult, took: Duration) -> String {
    let failed = study.runs.iter().filter(|r| r.failure.is_some()).count();
    let worse = study
        .runs
        .iter()
        .filter(|r| worse_than_nominal(r, study) == Some(true))
        .count();
    format!(
        "study: {} runs ({} failed, reasons in metrics.csv; {} worse than nominal, flagged there) in {:.1} s; \
         see summary.md, answer.csv, plots/ and campaign.rrd (open with `rerun campaign.rrd`, rerun-sdk 0.36)\n",
        study.runs.len(),
        failed,
        worse,
        took.as_secs_f64()
    ) + &answer_text(study)
}
