//! Scenario files (TOML): everything a campaign is made of, each section owned by the stage that uses it.
//! Every field is documented in `scenarios/README.md`; unknown keys are refused, so a typo is an error, not
//! a silently ignored setting.
//!
//! This module only reads and checks the file: each section's type belongs to its stage, and no stage reads
//! a scenario. [`crate::app`] builds the world from it and hands each stage its own section.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::calib::registry::MethodKind;
use crate::campaign::{CampaignConfig, RegionConfig};
use crate::error::{Error, Result};
use crate::eval::EvaluationConfig;
use crate::robot::Chain;
use crate::study::StudyConfig;
use crate::tracker::TrackerConfig;
use crate::tracker::reflector::ReflectorConfig;
use crate::truth::ErrorModel;
pub use crate::world::RobotConfig;
use crate::world::WorldConfig;

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    /// Names the results directory and every report row.
    pub name: String,
    /// Every random draw of the scenario derives from this seed.
    pub seed: u64,
    pub robot: RobotConfig,
    pub truth: ErrorModel,
    pub tracker: TrackerConfig,
    pub reflectors: ReflectorConfig,
    pub campaign: CampaignConfig,
    pub regions: Vec<RegionConfig>,
    /// What to fit on the campaign and how to judge it; no evaluation when absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub evaluation: Option<EvaluationConfig>,
    /// The sweep over training-set sizes, layouts, methods and seeds; no study when absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub study: Option<StudyConfig>,
    /// Where the scenario came from (its path), for messages; not part of the file.
    #[serde(skip)]
    pub origin: String,
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
        scenario.robot.urdf = resolve(&scenario.robot.urdf, path.parent());
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
        if self.name.trim().is_empty() || self.name.contains(['/', '\\']) {
            return Err(format!(
                "name '{}' must be non-empty and contain no path separator",
                self.name
            ));
        }
        let p = &self.robot;
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
        self.reflectors
            .validate()
            .map_err(|m| format!("reflectors: {m}"))?;
        self.campaign
            .validate()
            .and_then(|()| selection_model(&self.campaign.selection.model))
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
        if let Some(study) = &self.study {
            study
                .validate(&self.regions)
                .map_err(|m| format!("study.{m}"))?;
        }
        Ok(())
    }

    /// The parts of the scenario that make its world.
    pub fn world_config(&self) -> WorldConfig {
        WorldConfig {
            name: self.name.clone(),
            seed: self.seed,
            robot: self.robot.clone(),
            truth: self.truth.clone(),
            tracker: self.tracker.clone(),
            reflectors: self.reflectors.clone(),
        }
    }

    /// Loads the scenario's robot and checks the fields that depend on it (joint counts).
    pub fn load_robot(&self) -> Result<Chain> {
        let chain = crate::robot::load(&self.robot.urdf, self.robot.flange_link.as_deref())?;
        let scenario_err = |message: String| Error::Scenario {
            origin: self.origin.clone(),
            message,
        };
        self.truth
            .validate(chain.dof())
            .map_err(|e| scenario_err(e.detail()))?;
        if self.campaign.posture_deg.len() != chain.dof() {
            return Err(scenario_err(format!(
                "campaign.posture_deg has {} values, the robot has {} joints",
                self.campaign.posture_deg.len(),
                chain.dof()
            )));
        }
        Ok(chain)
    }
}

/// A model-based layout's `selection.model` must name a method with robot parameters to determine.
fn selection_model(name: &str) -> std::result::Result<(), String> {
    let kind = MethodKind::parse(name).map_err(|e| format!("selection.model: {}", e.detail()))?;
    if !kind.info().has_robot_parameters() {
        return Err(format!(
            "selection.model = '{name}' has no robot parameters to determine; use kinematic, elastic or a \
             paper model"
        ));
    }
    Ok(())
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
