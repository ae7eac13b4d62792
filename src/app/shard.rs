//! A study run as shards and merged: `campaign SCENARIO --shard K/N` computes shard K's campaigns
//! ([`crate::study::shard`]) and writes them as a shard directory; `campaign merge DIR...` checks that the
//! shards belong together and writes the unsharded run's files from them.
//!
//! A shard directory holds `shard.json` (the manifest: the scenario itself and its SHA-256, K, N, the
//! campaigns held), `study.cbor` (the shard's runs, detail and limits, every number bit for bit) and
//! `metrics.csv` (its rows, for reading). The merge rebuilds the world from the manifest's scenario — the
//! scenario's own campaign and evaluation are deterministic and cheap — and hands the shards' study to the same
//! writer as an unsharded run ([`super::campaign::run`]), so the files are the same bytes.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use super::campaign::{self, CampaignOptions, CampaignRun};
use crate::error::{Error, Result};
use crate::output;
use crate::report::metrics::metrics_csv;
use crate::scenario::Scenario;
use crate::study::StudyPart;
use crate::study::shard::{Shard, assemble};
use crate::study::sweep::{self, Progress, RunOptions};

/// The files of a shard directory.
pub const SHARD_OUTPUTS: &[&str] = &["shard.json", "study.cbor", "metrics.csv"];

const FORMAT: &str = "calibench study shard 1";

/// `shard.json`.
#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct Manifest {
    format: String,
    /// SHA-256 of the scenario as JSON (its parsed content: formatting and comments of the file do not count).
    scenario_sha256: String,
    scenario: Scenario,
    shard: usize,
    shards: usize,
    /// Global indices of the campaigns this shard ran, and how many the study has.
    campaigns: Vec<usize>,
    total_campaigns: usize,
    runs: usize,
}

/// What a shard run did, for the binary to print.
pub struct ShardRun {
    pub scenario: String,
    pub shard: Shard,
    pub campaigns: usize,
    pub total_campaigns: usize,
    pub runs: usize,
    pub failed: usize,
    pub out: PathBuf,
}

impl ShardRun {
    /// What `campaign --shard` prints.
    pub fn text(&self) -> String {
        format!(
            "scenario '{}', shard {}: {} of {} campaigns, {} runs ({} failed) in {}; merge every shard's \
             directory with `campaign merge`\n",
            self.scenario,
            self.shard,
            self.campaigns,
            self.total_campaigns,
            self.runs,
            self.failed,
            self.out.display()
        )
    }
}

fn fingerprint(scenario: &Scenario) -> Result<String> {
    let json = serde_json::to_vec(scenario)
        .map_err(|e| Error::Invalid(format!("scenario as JSON: {e}")))?;
    Ok(Sha256::digest(&json)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect())
}

/// Runs shard `shard` of the scenario's `[study]` and writes the shard directory (`out`, or
/// `results/<name>-shard-K-of-N`). The study's time budget is checked for this shard's share.
pub fn run_shard(
    scenario: &Scenario,
    shard: Shard,
    out: Option<&Path>,
    timings: bool,
    long: bool,
) -> Result<ShardRun> {
    let out = out.map(Path::to_path_buf).unwrap_or_else(|| {
        PathBuf::from("results").join(format!(
            "{}-shard-{}-of-{}",
            scenario.world.name, shard.index, shard.count
        ))
    });
    output::check_dir(&out, SHARD_OUTPUTS)?;
    let threads = rayon::current_num_threads() * shard.count;
    super::check_study_budget(scenario, threads, long)?;
    let config = super::study_config(scenario)?;
    let world = super::world(scenario)?;
    let part = sweep::run_part(
        &world,
        &scenario.campaign,
        &scenario.regions,
        config,
        RunOptions {
            progress: Progress::Auto,
            timings,
        },
        shard,
    )?;
    let manifest = Manifest {
        format: FORMAT.into(),
        scenario_sha256: fingerprint(scenario)?,
        scenario: scenario.clone(),
        shard: shard.index,
        shards: shard.count,
        campaigns: part.campaigns.clone(),
        total_campaigns: part.total_campaigns,
        runs: part.runs.len(),
    };
    let mut cbor = Vec::new();
    ciborium::into_writer(&part, &mut cbor)
        .map_err(|e| Error::Invalid(format!("study.cbor: {e}")))?;
    let rows = metrics_csv(&assemble(
        &world,
        &scenario.regions,
        config,
        vec![part.clone()],
    ))?;
    let json = serde_json::to_vec_pretty(&manifest)
        .map_err(|e| Error::Invalid(format!("shard.json: {e}")))?;
    output::write_dir(
        &out,
        &[
            ("shard.json", json),
            ("study.cbor", cbor),
            ("metrics.csv", rows),
        ],
        SHARD_OUTPUTS,
    )?;
    Ok(ShardRun {
        scenario: scenario.world.name.clone(),
        shard,
        campaigns: part.campaigns.len(),
        total_campaigns: part.total_campaigns,
        runs: part.runs.len(),
        failed: part.runs.iter().filter(|r| r.failure.is_some()).count(),
        out,
    })
}

fn in_dir(dir: &Path, file: &str, message: impl std::fmt::Display) -> Error {
    Error::Invalid(format!("{}: {message}", dir.join(file).display()))
}

/// Reads one shard directory: its manifest (checked against its own scenario) and its part.
fn read_shard(dir: &Path) -> Result<(Manifest, StudyPart)> {
    let text = std::fs::read_to_string(dir.join("shard.json")).map_err(|e| {
        in_dir(
            dir,
            "shard.json",
            format!("cannot read ({e}); is it a shard directory?"),
        )
    })?;
    let manifest: Manifest = serde_json::from_str(&text)
        .map_err(|e| in_dir(dir, "shard.json", format!("not a shard manifest: {e}")))?;
    if manifest.format != FORMAT {
        return Err(in_dir(
            dir,
            "shard.json",
            format!("format '{}', this build reads '{FORMAT}'", manifest.format),
        ));
    }
    if fingerprint(&manifest.scenario)? != manifest.scenario_sha256 {
        return Err(in_dir(
            dir,
            "shard.json",
            "the scenario does not match its scenario_sha256 (edited by hand?)",
        ));
    }
    let bytes = std::fs::read(dir.join("study.cbor"))
        .map_err(|e| in_dir(dir, "study.cbor", format!("cannot read: {e}")))?;
    let part: StudyPart = ciborium::from_reader(bytes.as_slice())
        .map_err(|e| in_dir(dir, "study.cbor", format!("not a shard's study: {e}")))?;
    let shard = Shard {
        index: manifest.shard,
        count: manifest.shards,
    };
    if part.shard != shard
        || part.campaigns != manifest.campaigns
        || part.runs.len() != manifest.runs
        || part.total_campaigns != manifest.total_campaigns
    {
        return Err(in_dir(
            dir,
            "study.cbor",
            "does not match shard.json (files of different shards mixed?)",
        ));
    }
    Ok((manifest, part))
}

/// Merges shard directories into the unsharded run's output directory (`out`, or `results/<name>`): refuses
/// shards of different scenarios or shard counts, a shard given twice and a missing one, naming it.
pub fn merge(dirs: &[PathBuf], out: Option<PathBuf>) -> Result<CampaignRun> {
    let first_dir = dirs
        .first()
        .ok_or_else(|| Error::Invalid("merge: no shard directories given".into()))?;
    let mut by_index: BTreeMap<usize, (&PathBuf, StudyPart)> = BTreeMap::new();
    let mut first: Option<Manifest> = None;
    for dir in dirs {
        let (manifest, part) = read_shard(dir)?;
        if let Some(f) = &first {
            if manifest.scenario_sha256 != f.scenario_sha256 {
                return Err(in_dir(
                    dir,
                    "shard.json",
                    format!(
                        "scenario '{}' ({}…) differs from {}'s '{}' ({}…): shards of different studies",
                        manifest.scenario.world.name,
                        &manifest.scenario_sha256[..12],
                        first_dir.display(),
                        f.scenario.world.name,
                        &f.scenario_sha256[..12]
                    ),
                ));
            }
            if manifest.shards != f.shards {
                return Err(in_dir(
                    dir,
                    "shard.json",
                    format!(
                        "shard {}/{} of a split into {}, {} is of a split into {}",
                        manifest.shard,
                        manifest.shards,
                        manifest.shards,
                        first_dir.display(),
                        f.shards
                    ),
                ));
            }
        }
        if let Some((other, _)) = by_index.get(&manifest.shard) {
            return Err(Error::Invalid(format!(
                "shard {}/{} given twice: {} and {}",
                manifest.shard,
                manifest.shards,
                other.display(),
                dir.display()
            )));
        }
        by_index.insert(manifest.shard, (dir, part));
        if first.is_none() {
            first = Some(manifest);
        }
    }
    let manifest = first.expect("at least one shard read");
    if let Some(missing) = (0..manifest.shards).find(|k| !by_index.contains_key(k)) {
        let absent = (0..manifest.shards)
            .filter(|k| !by_index.contains_key(k))
            .count();
        return Err(Error::Invalid(format!(
            "shard {missing}/{} is missing ({absent} of {} absent): every shard's directory is needed",
            manifest.shards, manifest.shards
        )));
    }
    // Each shard holds exactly its campaigns: then every campaign is computed exactly once.
    for (dir, part) in by_index.values() {
        let expected: Vec<usize> = (0..manifest.total_campaigns)
            .filter(|&i| part.shard.holds(i))
            .collect();
        if part.campaigns != expected {
            return Err(in_dir(
                dir,
                "shard.json",
                format!(
                    "holds campaigns {:?}…, shard {} of a study of {} campaigns holds {:?}…",
                    &part.campaigns[..part.campaigns.len().min(4)],
                    part.shard,
                    manifest.total_campaigns,
                    &expected[..expected.len().min(4)]
                ),
            ));
        }
    }
    let mut scenario = manifest.scenario;
    scenario.origin = first_dir.join("shard.json").display().to_string();
    let parts = by_index.into_values().map(|(_, p)| p).collect();
    campaign::run(
        scenario,
        &CampaignOptions {
            out,
            // The shards decided what the fit_ms column holds.
            timings: true,
            parts: Some(parts),
            ..CampaignOptions::default()
        },
    )
}
