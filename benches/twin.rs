//! `cargo bench --bench twin`: `campaign twin` on a 200-row pilot, whole: reading, identification, the
//! magnitudes' fit, the pilot's statistics over the twin's draws, the answer over 5 draws of the twin's study,
//! the files. The pilot is the first 200 rows of the real UR10 series C (in the repository's `data/`, or
//! `../shared/data/` beside it). Median of 3 runs on every core; the figure is for the docs, not an assertion.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use calibench::app::twin::{self, TwinOptions};
use calibench::robot::Payload;

fn series_c() -> Option<PathBuf> {
    ["data", "../shared/data"]
        .iter()
        .map(|d| Path::new(d).join("ipa-ur10/Series_C/measurements_random_poses.csv"))
        .find(|p| p.is_file())
}

fn main() {
    let Some(c) = series_c() else {
        println!("twin: the UR10 series C is not here (data/ipa-ur10); nothing to time");
        return;
    };
    let dir = tempfile::TempDir::new().expect("a temporary directory");
    let text = std::fs::read_to_string(&c).expect("series C reads");
    let pilot: String = text.lines().take(201).map(|l| format!("{l}\n")).collect();
    let file = dir.path().join("pilot.csv");
    std::fs::write(&file, pilot).expect("the pilot writes");
    let mut runs: Vec<Duration> = (0..3)
        .map(|k| {
            let started = Instant::now();
            twin::run(&TwinOptions {
                robot: "robots/ur10.urdf".into(),
                flange_link: None,
                data: file.clone(),
                mapping: Some("mappings/ipa_ur10.toml".into()),
                ignore_inputs: true,
                payload: Payload {
                    mass: 1.2,
                    com: [0.0, 0.0, 0.07],
                },
                seed: 1,
                answer_draws: 5,
                out: dir.path().join(format!("twin{k}")),
            })
            .expect("the twin builds");
            started.elapsed()
        })
        .collect();
    runs.sort();
    println!(
        "campaign twin, 200-row pilot (series C), answer over 5 draws: median {:.1} s (min {:.1}, max {:.1}) on {} threads",
        runs[1].as_secs_f64(),
        runs[0].as_secs_f64(),
        runs[2].as_secs_f64(),
        rayon::current_num_threads()
    );
}
