//! The one integration-test crate: every `tests/*.rs` file is a module of it, so the library and its heavy
//! dependencies (rerun, rapier) are linked into one test binary instead of one per file. A new test file must
//! be declared below; `every_test_file_is_a_module_of_the_suite` fails until it is.

mod common;

mod bad_inputs;
mod answer;
mod calibrate;
mod calibrate_cli;
mod campaign;
mod curve;
mod dataset;
mod design;
mod doc_commands;
mod evaluation;
mod export;
mod honest;
mod identify;
mod iso9283;
mod kinematic;
mod magnitudes;
mod motion;
mod real_data;
mod recipes;
mod recording;
mod replay;
mod report;
mod residual;
mod robot;
mod robot_toml;
mod robustness;
mod shards;
mod study;
mod study_cli;
mod tracker;
mod trajectory;
mod truth;
mod truth_effects;
mod twin;
mod ur10;

/// Cargo no longer discovers test files (`autotests = false`), so a file not declared here would silently
/// never run.
#[test]
fn every_test_file_is_a_module_of_the_suite() {
    let declared: Vec<&str> = include_str!("suite.rs")
        .lines()
        .filter_map(|line| line.strip_prefix("mod ")?.strip_suffix(';'))
        .collect();
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests");
    let mut missing = vec![];
    for entry in std::fs::read_dir(&dir).expect("read tests/") {
        let path = entry.expect("directory entry").path();
        if path.extension().is_none_or(|e| e != "rs") {
            continue;
        }
        let name = path.file_stem().unwrap().to_str().unwrap().to_string();
        if name != "suite" && !declared.contains(&name.as_str()) {
            missing.push(name);
        }
    }
    assert!(
        missing.is_empty(),
        "tests/*.rs files not declared as modules in tests/suite.rs (they would never run): {missing:?}"
    );
}
