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
//!   `app` builds the world from it and runs the job each binary asks for; `cli` holds the binaries' command
//!   lines (parsed by the binaries, and by a test of the documentation's commands). No stage imports them.

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
pub mod cli;

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

/// The house rules a newcomer can rely on, checked on the source text: rooms of bounded size, imports one way
/// inside every folder too, and a method's name spoken only where the methods are listed.
#[cfg(test)]
mod house_rules {
    use std::collections::BTreeMap;
    use std::path::{Path, PathBuf};

    const MAX_FILE_LINES: usize = 700;
    const MAX_FUNCTION_LINES: usize = 100;
    const MAX_BINARY_LINES: usize = 200;

    fn sources(dir: &Path, out: &mut Vec<PathBuf>) {
        for entry in std::fs::read_dir(dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                sources(&path, out);
            } else if path.extension().is_some_and(|e| e == "rs") {
                out.push(path);
            }
        }
    }

    fn src() -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("src")
    }

    /// Every source file and its text, paths relative to `src/`.
    fn files() -> Vec<(String, String)> {
        let mut paths = Vec::new();
        sources(&src(), &mut paths);
        paths.sort();
        paths
            .into_iter()
            .map(|p| {
                let text = std::fs::read_to_string(&p).unwrap();
                let rel = p.strip_prefix(src()).unwrap().display().to_string();
                (rel, text)
            })
            .collect()
    }

    /// The lines of a file before its unit tests.
    fn body(text: &str) -> Vec<&str> {
        text.lines()
            .take_while(|l| !l.starts_with("#[cfg(test)]"))
            .collect()
    }

    /// A line without its comment and with its string and character literals emptied, for counting braces.
    fn code_of(line: &str) -> String {
        let mut out = String::new();
        let mut chars = line.chars().peekable();
        let mut in_string = false;
        while let Some(c) = chars.next() {
            match c {
                '\\' if in_string => {
                    chars.next();
                }
                '"' => in_string = !in_string,
                '/' if !in_string && chars.peek() == Some(&'/') => break,
                '\'' if !in_string => {
                    // A character literal ('{', '\\'') is skipped; a lifetime ('a) is kept.
                    let rest: String = chars.clone().take(3).collect();
                    if rest.starts_with('\\') {
                        let skip = rest.find('\'').map_or(0, |i| i + 1);
                        (0..skip.max(3)).for_each(|_| {
                            chars.next();
                        });
                    } else if rest.chars().nth(1) == Some('\'') {
                        chars.next();
                        chars.next();
                    } else {
                        out.push(c);
                    }
                }
                _ if in_string => {}
                _ => out.push(c),
            }
        }
        out
    }

    /// Each function of `lines`: its name, first line (1-based) and length in lines, signature to closing brace.
    fn functions(lines: &[&str]) -> Vec<(String, usize, usize)> {
        let mut found = Vec::new();
        for (i, line) in lines.iter().enumerate() {
            let code = code_of(line);
            let Some(at) = code.find("fn ") else {
                continue;
            };
            let before = code[..at].trim();
            let is_item = before.split_whitespace().all(|w| {
                [
                    "pub",
                    "pub(crate)",
                    "pub(super)",
                    "const",
                    "async",
                    "unsafe",
                    "extern",
                ]
                .contains(&w)
            });
            if !is_item {
                continue;
            }
            let name: String = code[at + 3..]
                .chars()
                .take_while(|c| c.is_alphanumeric() || *c == '_')
                .collect();
            let mut depth = 0i64;
            let mut opened = false;
            for (j, l) in lines[i..].iter().enumerate() {
                let c = code_of(l);
                if !opened && c.trim_end().ends_with(';') && !c.contains('{') {
                    break;
                }
                for ch in c.chars() {
                    match ch {
                        '{' => {
                            depth += 1;
                            opened = true;
                        }
                        '}' => depth -= 1,
                        _ => {}
                    }
                }
                if opened && depth == 0 {
                    found.push((name, i + 1, j + 1));
                    break;
                }
            }
        }
        found
    }

    #[test]
    fn rooms_are_small() {
        let mut faults = Vec::new();
        for (file, text) in files() {
            let lines = body(&text);
            let limit = if file.starts_with("bin/") {
                MAX_BINARY_LINES
            } else {
                MAX_FILE_LINES
            };
            if lines.len() > limit {
                faults.push(format!("{file}: {} lines (at most {limit})", lines.len()));
            }
            for (name, at, length) in functions(&lines) {
                if length > MAX_FUNCTION_LINES {
                    faults.push(format!(
                        "{file}:{at}: fn {name} has {length} lines (at most {MAX_FUNCTION_LINES})"
                    ));
                }
            }
        }
        assert!(faults.is_empty(), "{faults:#?}");
    }

    /// The sibling files a file of a folder imports (`super::b`, `crate::<folder>::b`, `super::{b, c}`).
    fn siblings(folder: &str, text: &str, names: &[String]) -> Vec<String> {
        let mut out = Vec::new();
        for line in text.lines().map(str::trim).filter(|l| !l.starts_with("//")) {
            let module = format!("crate::{}::", folder.replace('/', "::"));
            for prefix in ["super::", module.as_str()] {
                for (i, _) in line.match_indices(prefix) {
                    let rest = &line[i + prefix.len()..];
                    let group: Vec<&str> = match rest.strip_prefix('{') {
                        Some(g) => g.split([',', '}']).collect(),
                        None => vec![rest],
                    };
                    for item in group {
                        let name: String = item
                            .trim()
                            .chars()
                            .take_while(|c| c.is_alphanumeric() || *c == '_')
                            .collect();
                        if names.contains(&name) && !out.contains(&name) {
                            out.push(name);
                        }
                    }
                }
            }
        }
        out
    }

    #[test]
    fn imports_inside_a_folder_run_one_way() {
        let mut folders: BTreeMap<String, Vec<(String, String)>> = BTreeMap::new();
        for (file, text) in files() {
            let path = Path::new(&file);
            let (Some(dir), Some(stem)) = (path.parent(), path.file_stem()) else {
                continue;
            };
            let stem = stem.to_string_lossy().to_string();
            if dir.as_os_str().is_empty() || stem == "mod" {
                continue;
            }
            folders
                .entry(dir.display().to_string())
                .or_default()
                .push((stem, text));
        }
        let mut circles = Vec::new();
        for (folder, files) in &folders {
            let names: Vec<String> = files.iter().map(|(n, _)| n.clone()).collect();
            let edges: BTreeMap<&str, Vec<String>> = files
                .iter()
                .map(|(n, t)| (n.as_str(), siblings(folder, t, &names)))
                .collect();
            // Depth-first search for a way back to where it started.
            for start in &names {
                let mut stack = vec![(start.clone(), vec![start.clone()])];
                while let Some((at, path)) = stack.pop() {
                    for next in &edges[at.as_str()] {
                        if next == start {
                            circles.push(format!("{folder}: {} -> {start}", path.join(" -> ")));
                        } else if !path.contains(next) {
                            let mut longer = path.clone();
                            longer.push(next.clone());
                            stack.push((next.clone(), longer));
                        }
                    }
                }
            }
        }
        assert!(circles.is_empty(), "import circles: {circles:#?}");
    }

    /// A method is a `MethodKind` outside `calib/`: nothing else spells a method's name or picks a variant
    /// (the binaries' argument parsers, `bin/` and `cli/`, read names, which is their job).
    #[test]
    fn method_names_are_spoken_only_in_calib() {
        let names: Vec<String> = crate::calib::registry::MethodKind::ALL
            .iter()
            .map(|m| format!("\"{}\"", m.name()))
            .collect();
        let mut faults = Vec::new();
        for (file, text) in files() {
            if file.starts_with("calib/") || file.starts_with("bin/") || file.starts_with("cli/") {
                continue;
            }
            for (i, line) in body(&text).iter().enumerate() {
                let code = line.split("//").next().unwrap_or_default();
                let literal = names.iter().find(|n| code.contains(n.as_str()));
                let variant = code.contains("MethodKind::")
                    && code.split("MethodKind::").skip(1).any(|rest| {
                        rest.starts_with(|c: char| c.is_ascii_uppercase())
                            && !rest.starts_with("ALL")
                    });
                if literal.is_some() || variant {
                    faults.push(format!("{file}:{}: {}", i + 1, line.trim()));
                }
            }
        }
        assert!(faults.is_empty(), "{faults:#?}");
    }

    #[test]
    fn the_checkers_see_what_they_look_for() {
        let text = "pub fn a() {\n    let s = \"}\";\n    let c = '{';\n}\nfn b(x: &'a str);\n";
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(functions(&lines), vec![("a".to_string(), 1, 4)]);
        let names = ["b".to_string(), "c".to_string()];
        let imports = siblings(
            "report",
            "use super::{b, x};\nuse crate::report::c::Y;\n",
            &names,
        );
        assert_eq!(imports, ["b", "c"]);
    }
}
