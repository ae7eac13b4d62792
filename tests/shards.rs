//! A study split into shards (`campaign --shard K/N`, three processes) and merged (`campaign merge`) gives the
//! unsharded run's files byte for byte; a merge with a shard missing, doubled or from another study is refused
//! on one line naming it.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use crate::common::{edit, read};
use crate::study_cli::small_study;

fn campaign(args: &[&std::ffi::OsStr]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_campaign"))
        .args(args)
        .args(["--threads", "1"])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("the campaign binary starts")
}

fn ok(o: Output) -> Output {
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    o
}

/// Runs the three shards of `scenario` as three processes at once; their directories.
fn shards(scenario: &Path, dir: &Path, tag: &str) -> Vec<PathBuf> {
    let outs: Vec<PathBuf> = (0..3).map(|k| dir.join(format!("{tag}-{k}"))).collect();
    let children: Vec<_> = outs
        .iter()
        .enumerate()
        .map(|(k, out)| {
            Command::new(env!("CARGO_BIN_EXE_campaign"))
                .arg(scenario)
                .args(["--shard", &format!("{k}/3"), "--threads", "1", "--out"])
                .arg(out)
                .current_dir(env!("CARGO_MANIFEST_DIR"))
                .output()
        })
        .collect();
    for child in children {
        ok(child.expect("a shard starts"));
    }
    outs
}

fn merge(dirs: &[&PathBuf], out: &Path) -> Output {
    let mut args: Vec<&std::ffi::OsStr> = vec!["merge".as_ref()];
    args.extend(dirs.iter().map(|d| d.as_os_str()));
    args.extend(["--out".as_ref(), out.as_os_str()]);
    campaign(&args)
}

/// The one error line of a refused merge.
fn refusal(o: &Output) -> String {
    assert_eq!(o.status.code(), Some(1), "the merge must be refused");
    let err = String::from_utf8_lossy(&o.stderr).trim().to_string();
    assert_eq!(err.lines().count(), 1, "one line: {err}");
    err
}

#[test]
fn three_shards_merged_equal_the_unsharded_study() {
    let dir = tempfile::tempdir().unwrap();
    let scenario = dir.path().join("small.toml");
    std::fs::write(&scenario, small_study()).unwrap();
    let whole = dir.path().join("whole");
    ok(campaign(&[
        scenario.as_os_str(),
        "--out".as_ref(),
        whole.as_os_str(),
    ]));
    let parts = shards(&scenario, dir.path(), "shard");
    // Each shard holds some runs, and together exactly the study's.
    let rows = |p: &Path| {
        String::from_utf8(read(&p.join("metrics.csv")))
            .unwrap()
            .lines()
            .count()
            - 1
    };
    let counts: Vec<usize> = parts.iter().map(|p| rows(p)).collect();
    assert!(counts.iter().all(|&c| c > 0), "{counts:?}");
    assert_eq!(counts.iter().sum::<usize>(), rows(&whole));

    let merged = dir.path().join("merged");
    // Given in another order than 0, 1, 2: the order of the directories does not matter.
    ok(merge(&[&parts[2], &parts[0], &parts[1]], &merged));
    for file in [
        "metrics.csv",
        "summary.md",
        "answer.csv",
        "outside.csv",
        "measurements.csv",
        "truth.csv",
        "campaign.json",
    ] {
        assert!(
            read(&whole.join(file)) == read(&merged.join(file)),
            "{file} of the merged shards differs from the unsharded run's"
        );
    }

    // A shard missing, a shard given twice.
    let e = refusal(&merge(&[&parts[0], &parts[2]], &dir.path().join("m1")));
    assert!(e.contains("shard 1/3 is missing"), "{e}");
    let e = refusal(&merge(
        &[&parts[0], &parts[1], &parts[1], &parts[2]],
        &dir.path().join("m2"),
    ));
    assert!(
        e.contains("shard 1/3 given twice") && e.contains("shard-1"),
        "{e}"
    );
    assert!(!dir.path().join("m1").exists() && !dir.path().join("m2").exists());

    // A shard of another study (another seed) is refused, naming its directory.
    let other = dir.path().join("other.toml");
    std::fs::write(&other, edit(&small_study(), "seed = 2019", "seed = 7")).unwrap();
    let stranger = dir.path().join("stranger-1");
    ok(campaign(&[
        other.as_os_str(),
        "--shard".as_ref(),
        "1/3".as_ref(),
        "--out".as_ref(),
        stranger.as_os_str(),
    ]));
    let e = refusal(&merge(
        &[&parts[0], &stranger, &parts[2]],
        &dir.path().join("m3"),
    ));
    assert!(
        e.contains("stranger-1") && e.contains("different studies"),
        "{e}"
    );
}

#[test]
fn bad_shard_arguments_are_refused_on_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let scenario = dir.path().join("small.toml");
    std::fs::write(&scenario, small_study()).unwrap();
    for bad in ["3/3", "1/0", "x/2"] {
        let o = campaign(&[scenario.as_os_str(), "--shard".as_ref(), bad.as_ref()]);
        let e = refusal(&o);
        assert!(e.contains("--shard") && e.contains(bad), "{e}");
    }
    let e = refusal(&merge(&[&dir.path().to_path_buf()], &dir.path().join("m")));
    assert!(e.contains("shard.json"), "{e}");
}

/// `scripts/slurm/submit.sh` with a stand-in `sbatch` that records its arguments: the caller's
/// `--cpus-per-task`, `--time`, `--partition` and `--mem` reach every shard, the last two the merge job as well;
/// without them sbatch gets none (the scripts' `#SBATCH` defaults hold); a wrong option is refused.
#[cfg(unix)]
#[test]
fn submit_passes_the_callers_slurm_options_to_sbatch() {
    use std::os::unix::fs::PermissionsExt;
    let dir = tempfile::tempdir().unwrap();
    let bin = dir.path().join("bin");
    std::fs::create_dir(&bin).unwrap();
    let sbatch = bin.join("sbatch");
    // Job ids 101, 102, ... in call order; each call's arguments one per line in LOG.<id>.
    std::fs::write(
        &sbatch,
        "#!/usr/bin/env bash\nn=$(( $(cat \"$SBATCH_LOG.count\" 2>/dev/null || echo 100) + 1 ))\n\
         echo \"$n\" > \"$SBATCH_LOG.count\"\nprintf '%s\\n' \"$@\" > \"$SBATCH_LOG.$n\"\necho \"$n\"\n",
    )
    .unwrap();
    std::fs::set_permissions(&sbatch, std::fs::Permissions::from_mode(0o755)).unwrap();
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let submit = |tag: &str, options: &[&str]| {
        let log = dir.path().join(tag);
        let path = format!(
            "{}:{}",
            bin.display(),
            std::env::var("PATH").unwrap_or_default()
        );
        let o = Command::new("bash")
            .arg(root.join("scripts/slurm/submit.sh"))
            .args(options)
            .arg("scenarios/default.toml")
            .arg("3")
            .arg(dir.path().join(format!("results-{tag}")))
            .arg(env!("CARGO_BIN_EXE_campaign"))
            .env("PATH", path)
            .env("SBATCH_LOG", &log)
            .current_dir(root)
            .output()
            .expect("bash starts");
        let calls: Vec<Vec<String>> = (101..=102)
            .map(|id| {
                std::fs::read_to_string(format!("{}.{id}", log.display()))
                    .map(|t| t.lines().map(String::from).collect())
                    .unwrap_or_default()
            })
            .collect();
        (o, calls)
    };
    let options = [
        "--cpus-per-task",
        "8",
        "--time",
        "04:00:00",
        "--partition",
        "batch",
        "--mem",
        "16G",
    ];
    let (o, calls) = submit("given", &options);
    let o = ok(o);
    let (shard, merge) = (&calls[0], &calls[1]);
    assert!(shard.iter().any(|a| a == "--array=0-2"), "{shard:?}");
    for given in [
        "--cpus-per-task=8",
        "--time=04:00:00",
        "--partition=batch",
        "--mem=16G",
    ] {
        assert!(shard.contains(&given.to_string()), "{given}: {shard:?}");
    }
    assert!(
        merge.iter().any(|a| a == "--dependency=afterok:101"),
        "{merge:?}"
    );
    for (given, passed) in [
        ("--partition=batch", true),
        ("--mem=16G", true),
        ("--cpus-per-task=8", false),
        ("--time=04:00:00", false),
    ] {
        assert_eq!(
            merge.contains(&given.to_string()),
            passed,
            "{given}: {merge:?}"
        );
    }
    assert!(String::from_utf8_lossy(&o.stdout).contains("array job 101"));

    let (o, calls) = submit("defaults", &[]);
    ok(o);
    for call in &calls {
        assert!(!call.is_empty());
        for option in ["--cpus-per-task", "--time", "--partition", "--mem"] {
            assert!(
                !call.iter().any(|a| a.starts_with(option)),
                "{option}: {call:?}"
            );
        }
    }

    for (bad, needle) in [
        (&["--nodes", "2"][..], "unknown option --nodes"),
        (&["--time", ""][..], "--time needs a value"),
    ] {
        let (o, calls) = submit("bad", bad);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{bad:?}: {err}");
        assert!(err.contains(needle), "{bad:?}: {err}");
        assert!(
            calls.iter().all(|c| c.is_empty()),
            "{bad:?} submitted {calls:?}"
        );
    }
}
