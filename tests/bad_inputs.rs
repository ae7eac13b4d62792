//! The corpus of bad inputs (issue 14): URDFs, scenarios, CSV files, mappings, models, output paths and
//! sizes that every binary must refuse the same way — exit code 1 (never a panic's 101, never a hang: each
//! run has a time limit), exactly one `error:` line naming the file and, where there is one, the row, column
//! or key, and nothing written to `--out`. Plus two concurrent runs into one directory: one complete result
//! (or a refusal), never a mix. The inputs are derived in the test from one small simulated campaign.

use crate::common::{edit, files_under};

use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use tempfile::TempDir;

const PAPER: &str = include_str!("../scenarios/paper_iiwa.toml");
const CAMPAIGN: &str = env!("CARGO_BIN_EXE_campaign");
const CALIBRATE: &str = env!("CARGO_BIN_EXE_calibrate");
const REAL_DATA: &str = env!("CARGO_BIN_EXE_real_data");
/// Longer than any refusal takes by two orders of magnitude; a run still going then is a hang.
const TIME_LIMIT: Duration = Duration::from_secs(60);

/// The paper scenario with `points` points and no `[evaluation]`: seconds to run.
fn small_scenario(points: usize) -> String {
    let text = edit(PAPER, "points = 2335", &format!("points = {points}"));
    text.split("[evaluation]").next().unwrap().to_string()
}

/// Runs `bin` from the crate root within [`TIME_LIMIT`]; returns the exit code and stderr.
fn run(bin: &str, args: &[OsString]) -> (Option<i32>, String) {
    let mut child = Command::new(bin)
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("{bin} starts: {e}"));
    let started = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        if started.elapsed() > TIME_LIMIT {
            let _ = child.kill();
            let _ = child.wait();
            panic!("{bin} {args:?} hangs: still running after {TIME_LIMIT:?}");
        }
        std::thread::sleep(Duration::from_millis(10));
    };
    let mut stderr = String::new();
    use std::io::Read;
    child
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut stderr)
        .unwrap();
    (status.code(), stderr)
}

fn os(args: &[&dyn AsRef<std::ffi::OsStr>]) -> Vec<OsString> {
    args.iter().map(|a| a.as_ref().to_os_string()).collect()
}

/// One bad input: the command, the words its error line must hold, and the `--out` path that must be as
/// it was before.
struct Case {
    name: &'static str,
    bin: &'static str,
    args: Vec<OsString>,
    needles: Vec<String>,
    out: PathBuf,
}

/// The files under `path` (or the file itself) with their contents.
fn snapshot(path: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    if path.is_file() {
        return vec![(path.to_path_buf(), std::fs::read(path).unwrap())];
    }
    let mut v: Vec<_> = files_under(path)
        .into_iter()
        .map(|p| {
            let bytes = std::fs::read(&p).unwrap();
            (p, bytes)
        })
        .collect();
    v.sort();
    v
}

/// What a data file's rows look like: header and cells, split on commas (the project's own files quote
/// nothing).
struct Table {
    header: Vec<String>,
    rows: Vec<Vec<String>>,
}

impl Table {
    fn read(path: &Path) -> Table {
        let text = std::fs::read_to_string(path).unwrap();
        let mut lines = text.lines();
        let split = |l: &str| l.split(',').map(String::from).collect::<Vec<_>>();
        let header = split(lines.next().unwrap());
        Table {
            header,
            rows: lines.map(split).collect(),
        }
    }

    fn col(&self, name: &str) -> usize {
        self.header.iter().position(|h| h == name).unwrap()
    }

    fn write(&self, path: &Path) {
        let mut text = self.header.join(",") + "\n";
        for r in &self.rows {
            text += &(r.join(",") + "\n");
        }
        std::fs::write(path, text).unwrap();
    }
}

struct Fixture {
    dir: TempDir,
    data: PathBuf,
    model: PathBuf,
}

impl Fixture {
    fn new() -> Fixture {
        let dir = TempDir::new().unwrap();
        let scenario = dir.path().join("small.toml");
        std::fs::write(&scenario, small_scenario(40)).unwrap();
        let campaign = dir.path().join("campaign");
        let (code, err) = run(CAMPAIGN, &os(&[&scenario, &"--out", &campaign]));
        assert_eq!(code, Some(0), "the fixture campaign: {err}");
        let fit = dir.path().join("fit");
        let data = campaign.join("measurements.csv");
        let (code, err) = run(
            CALIBRATE,
            &os(&[
                &"--data",
                &data,
                &"--method",
                &"paper-rotxyz",
                &"--out",
                &fit,
            ]),
        );
        assert_eq!(code, Some(0), "the fixture fit: {err}");
        Fixture {
            model: fit.join("model.json"),
            data,
            dir,
        }
    }

    fn path(&self, name: &str) -> PathBuf {
        self.dir.path().join(name)
    }

    fn write(&self, name: &str, text: impl AsRef<[u8]>) -> PathBuf {
        let p = self.path(name);
        std::fs::write(&p, text).unwrap();
        p
    }

    /// The fixture's measurements with `change` applied, written to `name`.
    fn data_with(&self, name: &str, change: impl FnOnce(&mut Table)) -> PathBuf {
        let mut t = Table::read(&self.data);
        change(&mut t);
        let p = self.path(name);
        t.write(&p);
        p
    }
}

const URDF_HEAD: &str = r#"<robot name="r"><link name="a"/><link name="b"/><link name="c"/>"#;

fn urdf(joints: &str) -> String {
    format!("{URDF_HEAD}{joints}</robot>")
}

fn joint(name: &str, parent: &str, child: &str, extra: &str) -> String {
    format!(
        r#"<joint name="{name}" type="revolute"><parent link="{parent}"/><child link="{child}"/><axis xyz="0 0 1"/>{extra}</joint>"#
    )
}

const LIMIT: &str = r#"<limit lower="-1" upper="1" effort="1" velocity="1"/>"#;

fn cases(f: &Fixture) -> Vec<Case> {
    let mut cases = Vec::new();
    let s = |v: &[&str]| v.iter().map(|x| x.to_string()).collect::<Vec<_>>();
    let mut add = |name, bin, args: Vec<OsString>, needles: Vec<String>, out: PathBuf| {
        cases.push(Case {
            name,
            bin,
            args,
            needles,
            out,
        })
    };
    let data = &f.data;
    let p = |x: &Path| x.display().to_string();

    // URDF: through `calibrate --robot`.
    let urdfs = [
        (
            "duplicate joint names",
            urdf(&(joint("j", "a", "b", LIMIT) + &joint("j", "b", "c", LIMIT))),
            "two joints are named 'j'",
        ),
        (
            "mimic joint",
            urdf(
                &(joint("j1", "a", "b", LIMIT)
                    + &joint("j2", "b", "c", &format!(r#"{LIMIT}<mimic joint="j1"/>"#))),
            ),
            "joint 'j2' mimics 'j1'",
        ),
        (
            "revolute joint without limit",
            urdf(&(joint("j1", "a", "b", LIMIT) + &joint("j2", "b", "c", ""))),
            "joint 'j2' has no <limit>",
        ),
        ("not XML", "<robot name=".into(), "not a valid URDF"),
    ];
    for (i, (name, text, needle)) in urdfs.into_iter().enumerate() {
        let path = f.write(&format!("bad{i}.urdf"), text);
        let out = f.path(&format!("out_urdf{i}"));
        add(
            name,
            CALIBRATE,
            os(&[&"--robot", &path, &"--data", data, &"--out", &out]),
            s(&[&p(&path), needle]),
            out,
        );
    }

    // Scenarios: through `campaign`.
    let small = small_scenario(40);
    let study = "\n[study]\nsizes = [10]\nlayouts = [\"uniform\"]\nmethods = [\"nominal\", \"kinematic\"]\n\
                 seeds = 20000\ntest_points = 1000\ngrid_points = 100000\nshell_width_m = 0.05\n\
                 shell_points = 100\nclosed_loop_points = 100\n";
    let scenarios = [
        (
            "a region of 10^8 points",
            edit(&small, "points = 40", "points = 100000000"),
            vec!["regions[0]", "points = 100000000", "100000"],
        ),
        (
            "an unknown key",
            edit(&small, "points = 40", "points = 40\npointz = 3"),
            vec!["line", "pointz"],
        ),
        (
            "a NaN size",
            edit(
                &small,
                "size_m = [0.24, 0.68, 0.64]",
                "size_m = [nan, 0.68, 0.64]",
            ),
            vec!["size_m"],
        ),
        (
            "a study beyond the time budget",
            small.clone() + study,
            vec!["[study]", "--long", "hours"],
        ),
        (
            "a study of millions of campaigns",
            small.clone() + &study.replace("seeds = 20000", "seeds = 2000000"),
            vec!["study.seeds", "exceed"],
        ),
        (
            "undamped joints",
            edit(
                &small,
                "hysteresis_rad = 2e-4",
                "hysteresis_rad = 2e-4\ndamping_ratio = 0.0",
            ),
            vec!["truth.damping_ratio = 0", "(0, 2]"],
        ),
        (
            "a posture outside the joint limits",
            edit(
                &small,
                "posture_deg = [0.0, 30.0, 0.0, -90.0, 0.0, -30.0, 0.0]",
                "posture_deg = [0.0, 30.0, 0.0, -90.0, 0.0, -30.0, 200.0]",
            ),
            vec![
                "campaign.posture_deg",
                "iiwa_joint_7 = 200.00 deg",
                "limits",
            ],
        ),
        (
            "not TOML",
            "name = \"x\"\n[[regions]\n".into(),
            vec!["line 2"],
        ),
    ];
    for (i, (name, text, needles)) in scenarios.into_iter().enumerate() {
        let path = f.write(&format!("bad{i}.toml"), text);
        let out = f.path(&format!("out_scenario{i}"));
        let mut n = s(&needles);
        n.push(p(&path));
        add(name, CAMPAIGN, os(&[&path, &"--out", &out]), n, out);
    }
    let good = f.write("good.toml", &small);
    for (i, threads) in ["100000", "-1", "0"].into_iter().enumerate() {
        let out = f.path(&format!("out_threads{i}"));
        add(
            "a thread count out of range",
            CAMPAIGN,
            os(&[&good, &"--threads", &threads, &"--out", &out]),
            s(&["--threads"]),
            out,
        );
    }

    // Measurement files: through `calibrate --data`.
    let j3 = |t: &Table| t.col("iiwa_joint_3");
    let csvs: Vec<(&str, PathBuf, Vec<String>)> = vec![
        (
            "a joint value of 1e300",
            f.data_with("huge_joint.csv", |t| {
                let c = j3(t);
                t.rows[4][c] = "1e300".into();
            }),
            s(&["data row 5", "iiwa_joint_3", "1.0000e300", "limits"]),
        ),
        (
            "joint values in degrees",
            f.data_with("degrees.csv", |t| {
                for k in 1..=7 {
                    let c = t.col(&format!("iiwa_joint_{k}"));
                    for r in &mut t.rows {
                        let v: f64 = r[c].parse().unwrap();
                        r[c] = v.to_degrees().to_string();
                    }
                }
            }),
            s(&["column iiwa_joint_", "degrees?"]),
        ),
        (
            "a 10 MB cell",
            f.data_with("huge_cell.csv", |t| {
                let c = t.col("x1");
                t.rows[2][c] = "7".repeat(10_000_000);
            }),
            s(&["row 4", "column x1", "(10000000 characters)"]),
        ),
        (
            "a NaN cell",
            f.data_with("nan.csv", |t| {
                let c = t.col("y1");
                t.rows[0][c] = "NaN".into();
            }),
            s(&["row 2", "column y1", "not finite"]),
        ),
        (
            "commanded joint rates for one joint only",
            f.data_with("rates.csv", |t| {
                t.header.push("qd_iiwa_joint_1".into());
                for r in &mut t.rows {
                    r.push("0.1".into());
                }
            }),
            s(&["no column 'qd_iiwa_joint_2'", "qdd_<joint>"]),
        ),
        (
            "a short row",
            f.data_with("short.csv", |t| {
                t.rows[6].pop();
            }),
            s(&["row 8", "fields"]),
        ),
        (
            "an empty file",
            f.write("empty.csv", ""),
            s(&["empty file"]),
        ),
        (
            "random bytes",
            f.write("bytes.csv", [0xff, 0xfe, 0x00, 0x81, b',', b'\n', 0xc3]),
            s(&["UTF-8"]),
        ),
    ];
    for (i, (name, path, mut needles)) in csvs.into_iter().enumerate() {
        let out = f.path(&format!("out_csv{i}"));
        needles.push(p(&path));
        add(
            name,
            CALIBRATE,
            os(&[&"--data", &path, &"--out", &out]),
            needles,
            out,
        );
    }

    // Mappings.
    let mapping = include_str!("../mappings/ipa_ur10.toml");
    for (i, (text, key)) in [
        (
            edit(mapping, "delimiter = \";\"", "delimiter = \";;\""),
            "delimiter",
        ),
        (format!("separator = \";\"\n{mapping}"), "separator"),
    ]
    .into_iter()
    .enumerate()
    {
        let path = f.write(&format!("bad_mapping{i}.toml"), text);
        let out = f.path(&format!("out_mapping{i}"));
        add(
            "a bad mapping",
            CALIBRATE,
            os(&[&"--data", data, &"--mapping", &path, &"--out", &out]),
            s(&[&p(&path), key]),
            out,
        );
    }

    // Models and apply's data.
    let model_text = std::fs::read_to_string(&f.model).unwrap();
    let at = model_text.find("\"coef\": [").unwrap() + "\"coef\": [".len();
    let end = at + model_text[at..].find([',', ']']).unwrap();
    let huge_coef = format!("{}1e300{}", &model_text[..at], &model_text[end..]);
    let applies: Vec<(&str, PathBuf, PathBuf, Vec<String>)> = vec![
        (
            "a coefficient of 1e300",
            f.write("huge_coef.json", huge_coef),
            data.clone(),
            s(&["coef[0]", "1e300"]),
        ),
        (
            "a model that is not JSON",
            f.write("not.json", "{\"method\": "),
            data.clone(),
            s(&["not a calibrate model"]),
        ),
        (
            "apply data with a joint of 1e200",
            f.model.clone(),
            f.data_with("apply_huge.csv", |t| {
                let c = j3(t);
                t.rows[9][c] = "-1e200".into();
            }),
            s(&["data row 10", "iiwa_joint_3", "plausible"]),
        ),
    ];
    for (i, (name, model, input, mut needles)) in applies.into_iter().enumerate() {
        let out = f.path(&format!("out_apply{i}"));
        needles.push(p(if name.starts_with("apply") {
            &input
        } else {
            &model
        }));
        add(
            name,
            CALIBRATE,
            os(&[
                &"apply", &"--model", &model, &"--data", &input, &"--out", &out,
            ]),
            needles,
            out,
        );
    }

    // Output paths: an existing file as a directory, a directory of someone else's files, `dir/` as a file.
    let a_file = f.write("a_file", "precious");
    add(
        "--out naming an existing file",
        CALIBRATE,
        os(&[&"--data", data, &"--out", &a_file]),
        s(&[&p(&a_file), "is a file, not a directory"]),
        a_file.clone(),
    );
    let home = f.path("home");
    std::fs::create_dir(&home).unwrap();
    std::fs::write(home.join("thesis.tex"), "precious").unwrap();
    add(
        "--out naming a directory of other files",
        CALIBRATE,
        os(&[&"--data", data, &"--out", &home]),
        s(&[&p(&home), "thesis.tex"]),
        home.clone(),
    );
    add(
        "campaign --out naming an existing file",
        CAMPAIGN,
        os(&[&good, &"--out", &a_file]),
        s(&[&p(&a_file), "is a file"]),
        a_file.clone(),
    );
    add(
        "apply --out naming an existing file",
        CALIBRATE,
        os(&[
            &"apply", &"--model", &f.model, &"--data", data, &"--out", &a_file,
        ]),
        s(&[&p(&a_file), "is a file, not a directory"]),
        a_file.clone(),
    );

    // Flags whose real check must speak (not the argument parser's negative-number rule).
    let out = f.path("out_payload");
    add(
        "a negative payload",
        CALIBRATE,
        os(&[&"--data", data, &"--payload-kg", &"-1", &"--out", &out]),
        s(&["--payload-kg must be finite and non-negative"]),
        out,
    );
    let out = f.path("out_real0");
    add(
        "real_data --draws 0",
        REAL_DATA,
        os(&[&"--draws", &"0", &"--out", &out]),
        s(&["--draws 0"]),
        out,
    );
    let out = f.path("out_real1");
    let missing = f.path("no_such_dir");
    add(
        "real_data without its data",
        REAL_DATA,
        os(&[&"--data-dir", &missing, &"--no-curve", &"--out", &out]),
        s(&[&p(&missing), "no such directory", "--data-dir"]),
        out,
    );

    // Pilots of `campaign twin`: too few rows, a NaN, a mapping that does not match the file.
    let iiwa = PathBuf::from("robots/iiwa7.urdf");
    let nan = f.data_with("twin_nan.csv", |t| {
        let c = t.col("z1");
        t.rows[3][c] = "nan".into();
    });
    let mapping = PathBuf::from("mappings/ipa_ur10.toml");
    for (i, (name, pilot, mapping, needles)) in [
        (
            "a twin from 40 points",
            data.clone(),
            None,
            s(&["40 points", "40 more"]),
        ),
        (
            "a twin from a pilot with a NaN",
            nan.clone(),
            None,
            s(&[&p(&nan), "row 5", "column z1"]),
        ),
        (
            "a twin through a mapping that does not match",
            data.clone(),
            Some(&mapping),
            s(&[&p(data)]),
        ),
    ]
    .into_iter()
    .enumerate()
    {
        let out = f.path(&format!("out_twin{i}"));
        let mut args = os(&[
            &"twin", &"--robot", &iiwa, &"--data", &pilot, &"--out", &out,
        ]);
        if let Some(m) = mapping {
            args.extend(os(&[&"--mapping", m]));
        }
        add(name, CAMPAIGN, args, needles, out);
    }
    cases
}

#[test]
fn every_bad_input_is_one_error_line_exit_1_and_nothing_written() {
    let f = Fixture::new();
    let cases = cases(&f);
    let mut failures = Vec::new();
    for case in &cases {
        let before = snapshot(&case.out);
        let (code, stderr) = run(case.bin, &case.args);
        let lines: Vec<&str> = stderr.lines().filter(|l| !l.trim().is_empty()).collect();
        let line = lines.first().copied().unwrap_or("");
        let mut wrong = Vec::new();
        if code != Some(1) {
            wrong.push(format!("exit code {code:?}"));
        }
        if lines.len() != 1 || !line.starts_with("error: ") {
            wrong.push(format!("{} lines on stderr", lines.len()));
        }
        if line.len() > 500 {
            wrong.push(format!("a line of {} bytes", line.len()));
        }
        for needle in &case.needles {
            if !line.contains(needle.as_str()) {
                wrong.push(format!("no `{needle}`"));
            }
        }
        if snapshot(&case.out) != before {
            wrong.push(format!("{} changed", case.out.display()));
        }
        let name = case.out.file_name().unwrap().to_string_lossy().into_owned();
        let parent = case.out.parent().unwrap();
        let leftovers: Vec<String> = std::fs::read_dir(parent)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.starts_with(&format!(".{name}.")))
            .collect();
        if !leftovers.is_empty() {
            wrong.push(format!("left {leftovers:?}"));
        }
        if !wrong.is_empty() {
            let shown: String = stderr.chars().take(600).collect();
            failures.push(format!(
                "{}: {} — stderr {shown:?}",
                case.name,
                wrong.join("; ")
            ));
        }
    }
    assert!(
        failures.is_empty(),
        "{} of {} bad inputs were not refused cleanly:\n{}",
        failures.len(),
        cases.len(),
        failures.join("\n")
    );
}

/// Two fits of different methods into one directory at once, over an older result: afterwards the
/// directory holds one complete result (report, model and predictions of one method), each run either
/// wrote it or was refused with the lock's line, and no temporary is left.
#[test]
fn concurrent_runs_into_one_directory_leave_one_result_never_a_mix() {
    let f = Fixture::new();
    let out = f.path("shared");
    let fit = |method: &str| os(&[&"--data", &f.data, &"--method", &method, &"--out", &out]);
    let (code, err) = run(CALIBRATE, &fit("paper-rotz"));
    assert_eq!(code, Some(0), "{err}");
    for trial in 0..4 {
        let runs: Vec<_> = ["nominal", "paper-rotxyz"]
            .into_iter()
            .map(|m| {
                let args = fit(m);
                std::thread::spawn(move || run(CALIBRATE, &args))
            })
            .collect();
        let results: Vec<(Option<i32>, String)> =
            runs.into_iter().map(|h| h.join().unwrap()).collect();
        for (code, err) in &results {
            assert!(
                *code == Some(0)
                    || (*code == Some(1) && err.contains("is writing this directory right now")),
                "trial {trial}: {code:?} {err}"
            );
        }
        assert!(results.iter().any(|(c, _)| *c == Some(0)), "trial {trial}");
        let mut names: Vec<String> = std::fs::read_dir(&out)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        assert_eq!(
            names,
            [
                "model.json",
                "predictions.csv",
                "report.json",
                "test_points.csv"
            ]
        );
        let json = |name: &str| -> serde_json::Value {
            serde_json::from_slice(&std::fs::read(out.join(name)).unwrap()).unwrap()
        };
        let (report, model) = (json("report.json"), json("model.json"));
        assert_eq!(report["method"], model["method"], "trial {trial}: a mix");
        assert_ne!(
            model["method"], "paper-rotz",
            "trial {trial}: the old result"
        );
        let siblings: Vec<String> = std::fs::read_dir(f.dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.starts_with(".shared."))
            .collect();
        assert!(siblings.is_empty(), "trial {trial}: left {siblings:?}");
    }
}
