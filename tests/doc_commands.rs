//! The documentation's commands cannot drift from the tools: every command line in a shell code block of the
//! README, the `docs/` pages and the folders' READMEs that runs one of the binaries (`cargo run [--release]
//! [--bin X] [-- ARGS]`, `target/release/X ARGS`) must parse with that binary's own parser (`calibench::cli`),
//! and every repository path a command line names must exist. Paths outside the repository (`/tmp/…`), under
//! `results/`, placeholders (`DIR/…`, `<…>`, `{…}`, `$VAR`) and what a command writes (`--out`) are not
//! checked; nor is anything after a `cd` in the same block. A synopsis's optional parts (`[--threads N]`) are
//! left out before parsing.

use std::path::{Path, PathBuf};

use clap::Parser;
use clap::error::ErrorKind;

use calibench::cli;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// README.md, every `docs/*.md`, and the README of every top-level folder.
fn pages() -> Vec<PathBuf> {
    let mut pages = vec![root().join("README.md")];
    let mut more: Vec<PathBuf> = Vec::new();
    if let Ok(entries) = std::fs::read_dir(root().join("docs")) {
        more.extend(
            entries
                .flatten()
                .map(|e| e.path())
                .filter(|p| p.extension().is_some_and(|x| x == "md")),
        );
    }
    for dir in repository_dirs(&root()) {
        let readme = root().join(&dir).join("README.md");
        if readme.is_file() && dir != "docs" {
            more.push(readme);
        }
    }
    more.sort();
    pages.extend(more);
    pages
}

/// The top-level folders of the repository a path may start with (not build products or generated results).
fn repository_dirs(root: &Path) -> Vec<String> {
    let mut dirs: Vec<String> = std::fs::read_dir(root)
        .unwrap()
        .flatten()
        .filter(|e| e.path().is_dir())
        .filter_map(|e| e.file_name().to_str().map(String::from))
        .filter(|n| !matches!(n.as_str(), "target" | "results" | ".git"))
        .collect();
    dirs.sort();
    dirs
}

/// One command line of a page: where it is, and its words.
#[derive(Debug)]
pub(crate) struct CommandLine {
    pub(crate) at: String,
    pub(crate) text: String,
    /// Whether its relative paths are relative to the repository root (no `cd` before it in its block).
    from_root: bool,
}

/// The command lines of the shell code blocks of `text` (`sh`, `bash`, `shell`, `console`), continuations
/// joined, comments and prompts removed; `name` names the page in messages.
pub(crate) fn shell_lines(name: &str, text: &str) -> Vec<CommandLine> {
    let mut out = Vec::new();
    let (mut in_block, mut shell, mut from_root) = (false, false, true);
    let mut pending: Option<(usize, String)> = None;
    for (i, line) in text.lines().enumerate() {
        let trimmed = line.trim_start();
        if let Some(info) = trimmed.strip_prefix("```") {
            if in_block {
                in_block = false;
            } else {
                in_block = true;
                shell = matches!(info.trim(), "sh" | "bash" | "shell" | "console");
                from_root = true;
            }
            pending = None;
            continue;
        }
        if !in_block || !shell {
            continue;
        }
        let code = strip_comment(trimmed.strip_prefix("$ ").unwrap_or(trimmed));
        let (start, mut joined) = pending.take().unwrap_or((i + 1, String::new()));
        let code = code.trim_end();
        if let Some(head) = code.strip_suffix('\\') {
            joined.push_str(head);
            joined.push(' ');
            pending = Some((start, joined));
            continue;
        }
        joined.push_str(code);
        if joined.trim().is_empty() {
            continue;
        }
        let starts_with_cd = joined.split_whitespace().next() == Some("cd");
        if starts_with_cd || joined.contains("&& cd ") || joined.contains("; cd ") {
            from_root = false;
        }
        out.push(CommandLine {
            at: format!("{name}:{start}"),
            text: joined,
            from_root,
        });
    }
    out
}

/// `line` without its comment: a `#` that starts a word outside quotes.
fn strip_comment(line: &str) -> &str {
    let (mut single, mut double, mut previous) = (false, false, ' ');
    for (i, c) in line.char_indices() {
        match c {
            '\'' if !double => single = !single,
            '"' if !single => double = !double,
            '#' if !single && !double && previous.is_whitespace() => return &line[..i],
            _ => {}
        }
        previous = c;
    }
    line
}

/// The commands of a line's words, split at `|`, `||`, `&&`, `;` and `&`.
fn commands(words: &[String]) -> Vec<Vec<String>> {
    let mut out = vec![Vec::new()];
    for w in words {
        if matches!(w.as_str(), "|" | "||" | "&&" | ";" | "&") {
            out.push(Vec::new());
        } else if let Some(head) = w.strip_suffix(';') {
            out.last_mut().unwrap().push(head.to_string());
            out.push(Vec::new());
        } else {
            out.last_mut().unwrap().push(w.clone());
        }
    }
    out.retain(|c| !c.is_empty());
    out
}

/// The binary a command runs and its arguments, if it runs one of ours (`default_run`: `cargo run` without
/// `--bin`).
fn invocation(words: &[String], default_run: &str) -> Option<(String, Vec<String>)> {
    for (k, w) in words.iter().enumerate() {
        if w == "cargo" && words.get(k + 1).is_some_and(|r| r == "run") {
            let rest = &words[k + 2..];
            let end = rest.iter().position(|a| a == "--").unwrap_or(rest.len());
            let cargo_args = &rest[..end];
            let bin = cargo_args
                .iter()
                .position(|a| a == "--bin")
                .and_then(|b| cargo_args.get(b + 1).cloned())
                .unwrap_or_else(|| default_run.to_string());
            let args = rest
                .get(end + 1..)
                .map(<[String]>::to_vec)
                .unwrap_or_default();
            return Some((bin, args));
        }
        let path = w.strip_prefix("./").unwrap_or(w);
        if let Some(bin) = path.strip_prefix("target/release/") {
            return Some((bin.to_string(), words[k + 1..].to_vec()));
        }
    }
    None
}

/// `args` without a synopsis's optional groups (`[--threads N]`).
fn without_optional_groups(args: &[String]) -> Vec<String> {
    let mut out = Vec::new();
    let mut depth = 0usize;
    for a in args {
        if depth == 0 && !a.starts_with('[') {
            out.push(a.clone());
            continue;
        }
        depth += a.matches('[').count();
        depth -= a.matches(']').count().min(depth);
    }
    out
}

/// Parses `args` with binary `bin`'s own parser; `Err` with clap's first line. `--help` and `--version` parse.
fn parse(bin: &str, args: &[String]) -> Result<(), String> {
    let argv = std::iter::once(bin.to_string()).chain(args.iter().cloned());
    let parsed = match bin {
        "calibrate" => cli::calibrate::Cli::try_parse_from(argv).map(drop),
        "campaign" => cli::campaign::Args::try_parse_from(argv).map(drop),
        "real_data" => cli::real_data::Cli::try_parse_from(argv).map(drop),
        other => return Err(format!("no binary named {other} (src/bin)")),
    };
    match parsed {
        Ok(()) => Ok(()),
        Err(e) if matches!(e.kind(), ErrorKind::DisplayHelp | ErrorKind::DisplayVersion) => Ok(()),
        Err(e) => Err(e.to_string().lines().next().unwrap_or_default().to_string()),
    }
}

/// The repository paths `words` name (values of `--out` and placeholders left out): relative, starting with a
/// folder of the repository.
fn repository_paths(words: &[String], dirs: &[String]) -> Vec<String> {
    let mut out = Vec::new();
    let mut previous = "";
    for w in words {
        let (flag, value) = match w.split_once('=') {
            Some((f, v)) if f.starts_with("--") => (f, v),
            _ => (previous, w.as_str()),
        };
        previous = w;
        if flag == "--out" || value.contains(['{', '}', '*', '<', '>', '$', '…', '[', ']']) {
            continue;
        }
        let path = value.strip_prefix("./").unwrap_or(value);
        let Some((first, _)) = path.split_once('/') else {
            continue;
        };
        if dirs.iter().any(|d| d == first) {
            out.push(path.trim_end_matches('/').to_string());
        }
    }
    out
}

/// What is wrong with the command lines of `text` (page `name`), against the repository at `root`; also the
/// number of binary invocations checked.
fn faults(name: &str, text: &str, root: &Path, default_run: &str) -> (Vec<String>, usize) {
    let dirs = repository_dirs(root);
    let mut faults = Vec::new();
    let mut checked = 0;
    for line in shell_lines(name, text) {
        let Some(words) = shlex::split(&line.text) else {
            faults.push(format!("{}: unbalanced quotes: {}", line.at, line.text));
            continue;
        };
        for command in commands(&words) {
            if let Some((bin, args)) = invocation(&command, default_run) {
                checked += 1;
                if let Err(e) = parse(&bin, &without_optional_groups(&args)) {
                    faults.push(format!("{}: `{}`: {e}", line.at, command.join(" ")));
                }
            }
            for flag in ["--bench", "--test"] {
                if let Some(k) = command.iter().position(|w| w == flag)
                    && command.first().is_some_and(|c| c == "cargo")
                {
                    let target = command.get(k + 1).cloned().unwrap_or_default();
                    let file = if flag == "--bench" {
                        format!("benches/{target}.rs")
                    } else {
                        format!("tests/{target}.rs")
                    };
                    if !root.join(&file).is_file() {
                        faults.push(format!("{}: {flag} {target}: no {file}", line.at));
                    }
                }
            }
            if line.from_root {
                for path in repository_paths(&command, &dirs) {
                    if !root.join(&path).exists() {
                        faults.push(format!(
                            "{}: no such file in the repository: {path}",
                            line.at
                        ));
                    }
                }
            }
        }
    }
    (faults, checked)
}

fn default_run() -> String {
    let manifest = std::fs::read_to_string(root().join("Cargo.toml")).unwrap();
    manifest
        .lines()
        .find_map(|l| l.trim().strip_prefix("default-run = "))
        .map(|v| v.trim_matches('"').to_string())
        .unwrap_or_default()
}

#[test]
fn every_documented_command_parses_and_names_existing_files() {
    let (mut all, mut checked) = (Vec::new(), 0);
    for page in pages() {
        let text = std::fs::read_to_string(&page).unwrap();
        let name = page.strip_prefix(root()).unwrap().display().to_string();
        let (faults, n) = faults(&name, &text, &root(), &default_run());
        all.extend(faults);
        checked += n;
    }
    assert!(all.is_empty(), "{all:#?}");
    assert!(checked > 0, "no command of the binaries found in the docs");
}

/// The checker finds what it looks for: a flag a binary does not have, a missing file, a missing bench; and
/// takes continuations, comments, `--out`, `/tmp`, `results/`, optional groups and other blocks as intended.
#[test]
fn the_doc_checker_sees_bad_commands() {
    let page = "intro\n\n```sh\n\
        cargo run --release --bin calibrate -- --data scenarios/missing.csv \\\n    --no-such-flag   # a comment\n\
        target/release/campaign scenarios/paper_iiwa.toml --out scenarios/made_by_it [--threads N]\n\
        cargo run --release -- scenarios/default.toml --out /tmp/x && cargo bench --bench nothing_here\n\
        cargo run --release --bin nobody\n\
        ```\n\n```toml\ncargo run --bin calibrate -- --bad\n```\n\n```sh\ncd /tmp\nls robots/absent.urdf\n```\n";
    let (faults, checked) = faults("page.md", page, &root(), "campaign");
    assert_eq!(checked, 4, "{faults:#?}");
    let expect = [
        "page.md:4: `cargo run --release --bin calibrate -- --data scenarios/missing.csv --no-such-flag`",
        "page.md:4: no such file in the repository: scenarios/missing.csv",
        "page.md:7: --bench nothing_here: no benches/nothing_here.rs",
        "page.md:8: `cargo run --release --bin nobody`: no binary named nobody",
    ];
    assert_eq!(faults.len(), expect.len(), "{faults:#?}");
    for (fault, e) in faults.iter().zip(expect) {
        assert!(fault.starts_with(e), "{fault} is not {e}");
    }
}
