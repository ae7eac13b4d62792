//! Scenario files (TOML): everything a campaign is made of, each section owned by the stage that uses it.
//! Every field is documented in `scenarios/README.md`; unknown keys are refused, so a typo is an error, not
//! a silently ignored setting.
//!
//! This module only reads and checks the file: each section's type belongs to its stage, and no stage reads
//! a scenario. [`crate::app`] builds the world from it and hands each stage its own section.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::campaign::{CampaignConfig, RegionConfig};
use crate::error::{Error, Result};
use crate::eval::{EvaluationConfig, Iso9283Config};
use crate::robot::Chain;
use crate::study::StudyConfig;
use crate::tracker::TrackerConfig;
use crate::tracker::reflector::ReflectorConfig;
use crate::truth::ErrorModel;
pub use crate::world::RobotConfig;
use crate::world::WorldConfig;

/// A scenario: its world (name, seed, robot, true errors, tracker, reflectors) and what the stages do in it. The
/// file writes every section at the top level; it is read and written through `ScenarioFile`.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(from = "ScenarioFile", into = "ScenarioFile")]
pub struct Scenario {
    /// What the scenario's world is made of: its name, seed, robot, true errors, tracker and reflectors.
    pub world: WorldConfig,
    pub campaign: CampaignConfig,
    pub regions: Vec<RegionConfig>,
    /// What to fit on the campaign and how to judge it; no evaluation when absent.
    pub evaluation: Option<EvaluationConfig>,
    /// ISO 9283's test cube run with every method the evaluation fits; no test when absent.
    pub iso9283: Option<Iso9283Config>,
    /// The sweep over training-set sizes, layouts, methods and seeds; no study when absent.
    pub study: Option<StudyConfig>,
    /// Where the scenario came from (its path), for messages; not part of the file.
    pub origin: String,
}

/// A scenario as its file writes it, every section at the top level. A flattened [`WorldConfig`] cannot stand
/// in for the world's keys: serde's `flatten` neither refuses unknown keys (`deny_unknown_fields`) nor keeps
/// the line and column of a fault inside the world's sections.
#[derive(Serialize, Deserialize)]
#[serde(rename = "Scenario", deny_unknown_fields)]
struct ScenarioFile {
    /// Names the results directory and every report row.
    name: String,
    /// Every random draw of the scenario derives from this seed.
    seed: u64,
    robot: RobotConfig,
    truth: ErrorModel,
    tracker: TrackerConfig,
    reflectors: ReflectorConfig,
    campaign: CampaignConfig,
    regions: Vec<RegionConfig>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    evaluation: Option<EvaluationConfig>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    iso9283: Option<Iso9283Config>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    study: Option<StudyConfig>,
}

impl From<ScenarioFile> for Scenario {
    fn from(f: ScenarioFile) -> Scenario {
        Scenario {
            world: WorldConfig {
                name: f.name,
                seed: f.seed,
                robot: f.robot,
                truth: f.truth,
                tracker: f.tracker,
                reflectors: f.reflectors,
            },
            campaign: f.campaign,
            regions: f.regions,
            evaluation: f.evaluation,
            iso9283: f.iso9283,
            study: f.study,
            origin: String::new(),
        }
    }
}

impl From<Scenario> for ScenarioFile {
    fn from(s: Scenario) -> ScenarioFile {
        let w = s.world;
        ScenarioFile {
            name: w.name,
            seed: w.seed,
            robot: w.robot,
            truth: w.truth,
            tracker: w.tracker,
            reflectors: w.reflectors,
            campaign: s.campaign,
            regions: s.regions,
            evaluation: s.evaluation,
            iso9283: s.iso9283,
            study: s.study,
        }
    }
}

impl Scenario {
    /// Reads and checks a scenario file.
    pub fn load(path: impl AsRef<Path>) -> Result<Scenario> {
        let path = path.as_ref();
        let origin = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| Error::Scenario {
            origin: origin.clone(),
            message: format!("cannot read: {e}"),
        })?;
        let mut scenario = Scenario::parse(&text, &origin)?;
        scenario.world.robot.urdf = resolve(&scenario.world.robot.urdf, path.parent());
        Ok(scenario)
    }

    /// Parses scenario text; `origin` names it in messages. Errors carry the line and column of the fault.
    pub fn parse(text: &str, origin: &str) -> Result<Scenario> {
        let mut scenario: Scenario = toml::from_str(text).map_err(|e| {
            let location = e
                .span()
                .map(|span| {
                    let before = &text[..span.start.min(text.len())];
                    let line = before.matches('\n').count() + 1;
                    let line_start = before.rfind('\n').map_or(0, |i| i + 1);
                    let column = before.len() - line_start + 1;
                    // A bad value's span points at the value: name the key written before it on its line.
                    let key = text[line_start..]
                        .lines()
                        .next()
                        .and_then(|l| l.split_once('='))
                        .map(|(k, _)| k.trim())
                        .filter(|k| {
                            !k.is_empty()
                                && !k.starts_with('[')
                                && !e.message().contains(&format!("`{k}`"))
                        })
                        .map(|k| format!("`{}{k}`: ", section_of(before)))
                        .unwrap_or_default();
                    format!("line {line}, column {column}: {key}")
                })
                .unwrap_or_default();
            Error::Scenario {
                origin: origin.to_string(),
                message: format!("{location}{}", e.message().trim().replace('\n', " ")),
            }
        })?;
        scenario.validate().map_err(|message| Error::Scenario {
            origin: origin.to_string(),
            message,
        })?;
        scenario.origin = origin.to_string();
        Ok(scenario)
    }

    /// Checks that need no robot: the robot-dependent ones happen in [`Scenario::load_robot`].
    fn validate(&self) -> std::result::Result<(), String> {
        let w = &self.world;
        if w.name.trim().is_empty() || w.name.contains(['/', '\\']) {
            return Err(format!(
                "name '{}' must be non-empty and contain no path separator",
                w.name
            ));
        }
        let p = &w.robot;
        if !(p.payload_kg.is_finite() && p.payload_kg >= 0.0)
            || p.payload_com_m.iter().any(|c| !c.is_finite())
        {
            return Err(
                "robot.payload_kg must be finite and non-negative, payload_com_m finite".into(),
            );
        }
        if self.regions.is_empty() {
            return Err("no [[regions]]: a campaign needs at least one".into());
        }
        for (i, r) in self.regions.iter().enumerate() {
            r.validate()
                .map_err(|m| format!("regions[{i}] ('{}'): {m}", r.name))?;
            if self.regions[..i].iter().any(|o| o.name == r.name) {
                return Err(format!("regions[{i}]: the name '{}' is used twice", r.name));
            }
        }
        w.reflectors
            .validate()
            .map_err(|m| format!("reflectors: {m}"))?;
        self.campaign
            .validate()
            .map_err(|m| format!("campaign: {m}"))?;
        if self.campaign.trajectory.is_some() && (self.evaluation.is_some() || self.study.is_some())
        {
            return Err(
                "campaign.trajectory measures the campaign on the fly, while [evaluation] and [study] judge \
                 campaigns measured at rest; drop one (a study compares the two with [study.trajectory])"
                    .into(),
            );
        }
        if let Some(evaluation) = &self.evaluation {
            evaluation
                .validate()
                .map_err(|m| format!("evaluation: {m}"))?;
        }
        if let Some(iso) = &self.iso9283 {
            if self.evaluation.is_none() {
                return Err("iso9283: the test commands the arm through the methods [evaluation] fits; add an \
                            [evaluation] section"
                    .into());
            }
            iso.validate(&self.regions)
                .map_err(|m| format!("iso9283.{m}"))?;
        }
        if let Some(study) = &self.study {
            study
                .validate(&self.regions)
                .map_err(|m| format!("study.{m}"))?;
        }
        Ok(())
    }

    /// Loads the scenario's robot and checks the fields that depend on it (joint counts).
    pub fn load_robot(&self) -> Result<Chain> {
        let robot = &self.world.robot;
        let chain = crate::robot::load(&robot.urdf, robot.flange_link.as_deref())?;
        let scenario_err = |message: String| Error::Scenario {
            origin: self.origin.clone(),
            message,
        };
        self.world
            .truth
            .validate(chain.dof())
            .map_err(|e| scenario_err(e.detail()))?;
        if self.campaign.posture_deg.len() != chain.dof() {
            return Err(scenario_err(format!(
                "campaign.posture_deg has {} values, the robot has {} joints",
                self.campaign.posture_deg.len(),
                chain.dof()
            )));
        }
        // A posture outside the limits is one the arm cannot take: inverse kinematics drawn toward it would
        // start from there and the campaign's anchor would be no pose of the arm.
        let posture = self.campaign.posture_rad();
        if let Some((j, v)) = chain
            .joints
            .iter()
            .zip(&posture)
            .find(|(j, v)| !j.within_limits(**v))
        {
            return Err(scenario_err(format!(
                "campaign.posture_deg: {} = {:.2} deg is outside the joint's limits [{:.2}, {:.2}] deg",
                j.name,
                v.to_degrees(),
                j.lower.to_degrees(),
                j.upper.to_degrees()
            )));
        }
        Ok(chain)
    }
}

/// The table a line of `before`'s end belongs to, as a key prefix (`study.`, `regions.`); empty at the top.
fn section_of(before: &str) -> String {
    before
        .lines()
        .rev()
        .map(str::trim)
        .find(|l| l.starts_with('['))
        .map(|l| l.trim_matches(|c| c == '[' || c == ']').trim())
        .map_or(String::new(), |s| format!("{s}."))
}

fn resolve(path: &Path, scenario_dir: Option<&Path>) -> PathBuf {
    if path.is_absolute() || path.exists() {
        return path.to_path_buf();
    }
    match scenario_dir {
        Some(dir) if dir.join(path).exists() => dir.join(path),
        _ => path.to_path_buf(),
    }
}
