//! `cargo bench --bench calibrate [-- METHOD ...]`: time to fit each method (or only those named) on a
//! simulated campaign of 2335 points split 50 / 25 / 25 (1168 training, 583 validation), everything a fit does
//! included (registration, parameter selection, regression search, iterations), on one core. Median of
//! repeated fits, printed beside the target of issue 27 where there is one; the figures are for
//! docs/speed.md, not assertions. The paper campaign has the elastic errors a kinematic model cannot fit;
//! `geometric_only` is the case a kinematic model describes exactly.

use std::time::{Duration, Instant};

use calibench::calib::method::FitContext;
use calibench::calib::registry::MethodKind;
use calibench::calib::regression::RegressionOptions;
use calibench::dataset::{Dataset, Split, random_split};
use calibench::robot::dh::DhChain;
use calibench::scenario::Scenario;

/// The target (ms) of a fit on the paper campaign without cross terms, where issue 27 sets one.
fn target_ms(kind: MethodKind) -> Option<f64> {
    match kind {
        MethodKind::Kinematic | MethodKind::Elastic => Some(10.0),
        MethodKind::PaperRotxyz => Some(20.0),
        MethodKind::ResidualRidge => Some(40.0),
        _ => None,
    }
}

fn bench(scenario_path: &str, methods: &[MethodKind], cross_terms: bool, only: &[String]) {
    let methods: Vec<MethodKind> = methods
        .iter()
        .copied()
        .filter(|k| only.is_empty() || only.iter().any(|o| o == k.name()))
        .collect();
    if methods.is_empty() {
        return;
    }
    let scenario = Scenario::load(scenario_path).expect("run from the crate root");
    let sim = calibench::app::simulate(&scenario).expect("the scenario simulates");
    let csv = calibench::measurements::measurements_csv(&sim.campaign).expect("csv");
    let data = Dataset::from_reader(
        csv.as_slice(),
        scenario_path,
        &sim.world.nominal.joint_names(),
    )
    .expect("reads back");
    let labels = random_split(data.len(), [0.5, 0.25, 0.25], 0).expect("split");
    let pick = |s: Split| {
        data.subset(
            &(0..data.len())
                .filter(|&i| labels[i] == s)
                .collect::<Vec<_>>(),
        )
    };
    let (train, val) = (pick(Split::Train), pick(Split::Val));
    let dh = DhChain::from_chain(&sim.world.nominal).expect("DH");
    let single = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("pool");
    let ctx = FitContext {
        share: None,
        chain: &sim.world.nominal,
        dh: &dh,
        payload: scenario.world.robot.payload(),
        regression: RegressionOptions {
            cross_terms,
            ..RegressionOptions::default()
        },
    };
    for kind in methods {
        let mut runs: Vec<Duration> = (0..9)
            .map(|_| {
                let t = Instant::now();
                single
                    .install(|| kind.fit(&ctx, &train, &val))
                    .expect("fits");
                t.elapsed()
            })
            .collect();
        runs.sort();
        let target = target_ms(kind)
            .filter(|_| !cross_terms && scenario.world.name == "paper_iiwa")
            .map_or(String::new(), |t| format!(" (target ≤ {t:.0} ms)"));
        println!(
            "{:<16} fit {:<22}{} on {} training + {} validation points, one core: {:.1} ms{target}",
            scenario.world.name,
            kind.name(),
            if cross_terms { " (cross terms)" } else { "" },
            train.len(),
            val.len(),
            runs[runs.len() / 2].as_secs_f64() * 1e3
        );
    }
}

fn main() {
    // Method names to run (cargo passes `--bench` too).
    let only: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| !a.starts_with("--"))
        .collect();
    bench("scenarios/paper_iiwa.toml", &MethodKind::ALL, false, &only);
    // Only the paper's regressions and the residual models have cross terms.
    let regressions = [
        MethodKind::PaperRotz,
        MethodKind::PaperRotxyz,
        MethodKind::PaperRotxyzTransxyz,
        MethodKind::ResidualRidge,
        MethodKind::Hybrid,
    ];
    bench("scenarios/paper_iiwa.toml", &regressions, true, &only);
    bench(
        "scenarios/geometric_only.toml",
        &[MethodKind::Kinematic, MethodKind::Elastic],
        false,
        &only,
    );
}
