//! calibench: a benchmark harness for robot absolute-accuracy calibration.
//!
//! Modules follow the pipeline of a calibration campaign (the README's module table says what each holds).
//! Each imports only modules written before it in this order (the `module_order` test checks it):
//!
//! - `error`, `output`, `rng`, `numeric` (decompositions that refuse non-finite input): serve every stage;
//! - `robot` (the nominal chain: URDF, DH form, kinematics, IK, collisions) → `truth` (the true robot) →
//!   `tracker` (instrument and reflectors) → `world` (the simulated world built once: nominal and true robot,
//!   tracker, mounting, seed) → `dataset` (the measurement file format a method reads) → `calib`
//!   (registration and the calibration methods; the list of methods is what a campaign designed for one, a
//!   study and a report name) → `campaign` (regions, layouts, feasibility, the simulated measurement) →
//!   `measurements` (a campaign written in the dataset format) → `design` (observability and model-based point
//!   choice, which a campaign's `d-optimal` layout is handed as its selector) → `eval` (judging fitted methods
//!   against the truth) → `study` (sweeps) → `report` (files a person reads);
//! - `scenario` reads and checks the TOML file whose sections are the stages' own configurations, and
//!   `app` builds the world from it and runs the job each binary asks for. No stage imports either.

pub mod error;
pub mod output;
pub mod rng;
pub mod numeric;

pub mod robot;
pub mod truth;
pub mod tracker;
pub mod world;
pub mod dataset;
pub mod calib;
pub mod campaign;
pub mod measurements;
pub mod design;
pub mod eval;
pub mod study;
pub mod report;

pub mod scenario;
pub mod app;

pub use error::{Error, Result};

#[cfg(test)]
mod module_order {
    use std::path::Path;

    /// The top-level modules in the order `pub mod` declares them above.
    fn order() -> Vec<String> {
        include_str!("lib.rs")
            .lines()
            .filter_map(|l| l.strip_prefix("pub mod ")?.strip_suffix(';'))
            .map(String::from)
            .collect()
    }

    /// The top-level modules a source text names through `crate::` outside comments, `crate::{a, b}` included.
    fn imports(text: &str, modules: &[String]) -> Vec<String> {
        let mut found = Vec::new();
        for line in text.lines().map(str::trim).filter(|l| !l.starts_with("//")) {
            for (i, _) in line.match_indices("crate::") {
                let rest = &line[i + "crate::".len()..];
                let names: Vec<&str> = match rest.strip_prefix('{') {
                    Some(group) => group.split([',', '}']).map(str::trim).collect(),
                    None => vec![rest],
                };
                for name in names {
                    let name: String = name
                        .chars()
                        .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                        .collect();
                    if modules.contains(&name) && !found.contains(&name) {
                        found.push(name);
                    }
                }
            }
        }
        found
    }

    fn sources(path: &Path, out: &mut Vec<(String, String)>) {
        if path.is_dir() {
            for entry in std::fs::read_dir(path).unwrap() {
                sources(&entry.unwrap().path(), out);
            }
        } else if path.is_file() && path.extension().is_some_and(|e| e == "rs") {
            out.push((
                path.display().to_string(),
                std::fs::read_to_string(path).unwrap(),
            ));
        }
    }

    #[test]
    fn every_module_imports_only_modules_before_it() {
        let modules = order();
        assert!(modules.len() >= 15, "lib.rs declares {modules:?}");
        let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
        let mut violations = Vec::new();
        for (place, module) in modules.iter().enumerate() {
            let mut files = Vec::new();
            sources(&src.join(module), &mut files);
            sources(&src.join(format!("{module}.rs")), &mut files);
            assert!(!files.is_empty(), "no source for module {module}");
            for (file, text) in files {
                for used in imports(&text, &modules) {
                    let at = modules.iter().position(|m| *m == used).unwrap();
                    if at > place {
                        violations.push(format!("{file} ({module}) imports {used}"));
                    }
                }
            }
        }
        assert!(
            violations.is_empty(),
            "imports against the order of lib.rs: {violations:#?}"
        );
    }

    #[test]
    fn the_checker_sees_grouped_and_plain_imports() {
        let modules: Vec<String> = ["robot", "calib", "eval"].map(String::from).to_vec();
        let text =
            "use crate::robot::Chain;\n// crate::eval in a comment\nuse crate::{calib, x};\n";
        assert_eq!(imports(text, &modules), ["robot", "calib"]);
    }
}
