//! Helpers shared by the integration tests: those that drive the binaries here, the synthetic robot in
//! [`synthetic`].
#![allow(dead_code)]

pub mod synthetic;

use std::path::{Path, PathBuf};
use std::process::Output;

/// `text` with `from` replaced by `to`, which must occur exactly once (so a changed shipped scenario fails
/// loudly here instead of silently testing something else).
pub fn edit(text: &str, from: &str, to: &str) -> String {
    assert_eq!(
        text.matches(from).count(),
        1,
        "expected exactly one `{from}` in the scenario"
    );
    text.replacen(from, to, 1)
}

pub fn read(path: &Path) -> Vec<u8> {
    std::fs::read(path).unwrap_or_else(|e| panic!("read {}: {e}", path.display()))
}

pub fn files_under(dir: &Path) -> Vec<PathBuf> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    entries
        .map(|e| e.expect("directory entry").path())
        .flat_map(|p| if p.is_dir() { files_under(&p) } else { vec![p] })
        .collect()
}

/// A failed run: non-zero exit, one non-empty `error:` line on stderr containing every `needles` entry, no
/// panic, and no file in `out`. Returns the line.
pub fn assert_clean_failure(output: &Output, out: &Path, needles: &[&str]) -> String {
    let stderr = String::from_utf8_lossy(&output.stderr).into_owned();
    assert!(
        !output.status.success(),
        "expected a failure, got success; stderr: {stderr}"
    );
    assert!(
        !stderr.contains("panicked"),
        "the binary panicked: {stderr}"
    );
    let lines: Vec<&str> = stderr.lines().collect();
    assert_eq!(
        lines.len(),
        1,
        "stderr must be exactly one line: {stderr:?}"
    );
    let line = lines[0];
    assert!(
        line.starts_with("error: ") && line.len() > "error: ".len(),
        "stderr must be a non-empty `error:` line: {line:?}"
    );
    for needle in needles {
        assert!(
            line.contains(needle),
            "{line:?} does not mention {needle:?}"
        );
    }
    let left = files_under(out);
    assert!(left.is_empty(), "a failed run left files behind: {left:?}");
    line.to_string()
}

/// The truth `elastic` matches exactly (no error source of issue 12), for consistency tests.
pub const IDEAL_ELASTIC: &str = include_str!("../../scenarios/ideal_elastic.toml");
const PAPER_POSE: &str = include_str!("../../scenarios/paper_iiwa_pose.toml");

/// `paper_iiwa_pose.toml` (its nest, payload and region) with the `[truth]` and `[tracker]` of
/// `ideal_elastic.toml`: a full-pose campaign of a robot the `elastic` model describes exactly.
pub fn ideal_elastic_pose() -> String {
    with_ideal_truth(PAPER_POSE)
}

/// `scenario` (a scenario's text) with `ideal_elastic.toml`'s `[truth]` and `[tracker]` in place of its own:
/// the truth `elastic` describes exactly, for tests whose claim is the harness's consistency.
pub fn with_ideal_truth(scenario: &str) -> String {
    let span = |text: &str| {
        let start = text.find("\n[truth]\n").expect("a [truth] section");
        let end = text
            .find("\n[reflectors]\n")
            .expect("a [reflectors] section");
        (start, end)
    };
    let (a, b) = span(scenario);
    let (c, d) = span(IDEAL_ELASTIC);
    format!(
        "{}{}{}",
        &scenario[..a],
        &IDEAL_ELASTIC[c..d],
        &scenario[b..]
    )
}
