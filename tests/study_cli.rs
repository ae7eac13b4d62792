//! The study through the `campaign` binary: thread-count independence of the files a person or a script reads,
//! bad study inputs, and an interrupted run leaving nothing behind.

use std::path::Path;
use std::process::{Command, Output};
use std::time::Duration;

use crate::common::{assert_clean_failure, edit, files_under, read};

const DEFAULT: &str = include_str!("../scenarios/default.toml");

/// The default study made small: two sizes, two layouts, three methods, two seeds, small shared sets.
pub fn small_study() -> String {
    let mut text = edit(
        DEFAULT,
        "sizes = [15, 30, 60, 125, 250, 500, 1000]",
        "sizes = [20, 40]",
    );
    text = edit(
        &text,
        r#"layouts = ["uniform", "grid", "sobol", "latin-hypercube", "d-optimal"]"#,
        r#"layouts = ["uniform", "d-optimal"]"#,
    );
    text = edit(
        &text,
        r#"methods = ["nominal", "paper-rotz", "paper-rotxyz", "paper-rotxyz-transxyz", "kinematic", "elastic",
           "residual-ridge", "hybrid", "hybrid-kinematic"]"#,
        r#"methods = ["nominal", "paper-rotz", "hybrid"]"#,
    );
    text = edit(&text, "seeds = 5 ", "seeds = 2 ");
    text = edit(&text, "test_points = 500 ", "test_points = 60 ");
    text = edit(&text, "grid_points = 1000 ", "grid_points = 60 ");
    text = edit(&text, "shell_points = 200", "shell_points = 30");
    text = edit(&text, "closed_loop_points = 100", "closed_loop_points = 20");
    // The trajectory comparison on one size, one seed, one speed.
    text = edit(&text, "sizes = [30, 125]", "sizes = [20]");
    text = edit(&text, "speeds = [0.25, 0.5, 1.0]", "speeds = [0.5]");
    text = edit(&text, "seeds = 3\n", "seeds = 1\n");
    edit(&text, "points = 2335", "points = 200")
}

fn campaign(scenario: &Path, out: &Path, threads: &str) -> Output {
    Command::new(env!("CARGO_BIN_EXE_campaign"))
        .arg(scenario)
        .arg("--out")
        .arg(out)
        .args(["--threads", threads])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("the campaign binary starts")
}

#[test]
fn metrics_and_summary_do_not_depend_on_the_thread_count() {
    let dir = tempfile::tempdir().unwrap();
    let scenario = dir.path().join("small.toml");
    std::fs::write(&scenario, small_study()).unwrap();
    let (one, two) = (dir.path().join("one"), dir.path().join("two"));
    for (out, threads) in [(&one, "1"), (&two, "2")] {
        let o = campaign(&scenario, out, threads);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
    for file in [
        "metrics.csv",
        "summary.md",
        "answer.csv",
        "measurements.csv",
    ] {
        assert_eq!(
            read(&one.join(file)),
            read(&two.join(file)),
            "{file} differs between 1 and 2 threads"
        );
    }
    let metrics = String::from_utf8(read(&one.join("metrics.csv"))).unwrap();
    // The answer of a real (small) study, recomputed from its metrics.csv.
    crate::answer::check(
        &metrics,
        &String::from_utf8(read(&one.join("answer.csv"))).unwrap(),
        &String::from_utf8(read(&one.join("summary.md"))).unwrap(),
        &[0.5, 0.3, 0.2, 0.1, 0.05],
    );
    // 1 region × 2 layouts × 3 methods × 2 sizes × 2 seeds, plus the header.
    assert_eq!(metrics.lines().count(), 1 + 24);
    for name in [
        "campaign.rrd",
        "plots/learning_curves_paper.png",
        "plots/histogram_hybrid.png",
        "plots/tracker_time_paper.png",
        "trajectory.csv",
    ] {
        assert!(one.join(name).is_file(), "{name} missing");
    }
    // The recording shows the trajectory (the 20-target path at speed 0.5, with `hybrid`'s error) and the
    // tracker-time comparison (stop and go and the one speed).
    let entities = crate::recording::decode(&read(&one.join("campaign.rrd")));
    let current = &entities["world/trajectory/current"];
    let samples = current.timeline_rows["time"];
    assert!(samples > 20, "{samples} samples on the time timeline");
    assert_eq!(
        entities["tracker_time/paper/20/hybrid"].times["tracker_s"].len(),
        2
    );

    // The default study fits the regressions on the trajectory also with the motion's torques as inputs (whether
    // that helps is tests/trajectory.rs's question: here, at 20 targets and half speed, it does not).
    let trajectory = String::from_utf8(read(&one.join("trajectory.csv"))).unwrap();
    let mean_of = |method: &str| -> f64 {
        let rows: Vec<&str> = trajectory
            .lines()
            .filter(|l| l.split(',').nth(1) == Some(method))
            .collect();
        assert_eq!(rows.len(), 1, "{method}: {rows:?}");
        rows[0].split(',').nth(10).unwrap().parse().unwrap()
    };
    let (plain, moving) = (mean_of("paper-rotz"), mean_of("paper-rotz + motion"));
    eprintln!("paper-rotz on the trajectory: {plain} mm, with the motion as inputs {moving} mm");
    assert!(plain.is_finite() && moving.is_finite());
    mean_of("hybrid + motion");
    // `nominal` regresses on nothing: no motion variant.
    assert!(!trajectory.contains("nominal + motion"));
}

#[test]
fn bad_study_inputs_are_one_line_and_write_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let cases = [
        ("sizes = [20, 40]", "sizes = []", "study.sizes"),
        ("sizes = [20, 40]", "sizes = [20, 5000]", "5000"),
        (
            r#"methods = ["nominal", "paper-rotz", "hybrid"]"#,
            r#"methods = ["nominal", "magic"]"#,
            "magic",
        ),
        (
            r#"layouts = ["uniform", "d-optimal"]"#,
            r#"layouts = ["uniform", "spiral"]"#,
            "spiral",
        ),
        (
            "limit_margin_deg = 2.0",
            "limit_margin_deg = 2.0\nselection = { model = \"residual-ridge\" }",
            "selection.model",
        ),
        (
            "limit_margin_deg = 2.0",
            "limit_margin_deg = 2.0\nselection = { pool_min = 5000, pool_max = 100 }",
            "pool_max",
        ),
    ];
    for (i, (from, to, needle)) in cases.iter().enumerate() {
        let scenario = dir.path().join(format!("bad{i}.toml"));
        std::fs::write(&scenario, edit(&small_study(), from, to)).unwrap();
        let out = dir.path().join(format!("out{i}"));
        assert_clean_failure(&campaign(&scenario, &out, "2"), &out, &[needle]);
    }
}

#[test]
fn an_interrupted_study_leaves_no_partial_files() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let mut child = Command::new(env!("CARGO_BIN_EXE_campaign"))
        .arg("--out")
        .arg(&out)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .expect("the campaign binary starts");
    // The default study takes far longer than this; everything is written at its very end.
    std::thread::sleep(Duration::from_millis(1500));
    child.kill().expect("the study is still running");
    child.wait().unwrap();
    let left = files_under(&out);
    assert!(left.is_empty(), "an interrupted run left {left:?}");
}
