//! `cargo bench --bench calibrate`: time to fit each method on a simulated campaign of 2335 points split
//! 50 / 25 / 25 (1168 training, 583 validation), everything a fit does included (registration, parameter
//! selection, regression search, iterations), on one core. Median of repeated fits; the figures are for the
//! README, not assertions. The paper campaign has the elastic errors a kinematic model cannot fit;
//! `geometric_only` is the case a kinematic model describes exactly.

use std::time::{Duration, Instant};

use calibench::calib::method::FitContext;
use calibench::calib::registry::MethodKind;
use calibench::calib::regression::RegressionOptions;
use calibench::dataset::{Dataset, Split, random_split};
use calibench::robot::dh::DhChain;
use calibench::scenario::Scenario;

fn bench(scenario_path: &str, methods: &[MethodKind], cross_terms: bool) {
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
        chain: &sim.world.nominal,
        dh: &dh,
        payload: scenario.world.robot.payload(),
        regression: RegressionOptions {
            cross_terms,
            ..RegressionOptions::default()
        },
    };
    for &kind in methods {
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
        println!(
            "{:<16} fit {:<22}{} on {} training + {} validation points, one core: {:.1} ms",
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
    bench("scenarios/paper_iiwa.toml", &MethodKind::ALL, false);
    // Only the paper's regressions and the residual models have cross terms.
    let regressions = [
        MethodKind::PaperRotz,
        MethodKind::PaperRotxyz,
        MethodKind::PaperRotxyzTransxyz,
        MethodKind::ResidualRidge,
        MethodKind::Hybrid,
    ];
    bench("scenarios/paper_iiwa.toml", &regressions, true);
    bench(
        "scenarios/geometric_only.toml",
        &[MethodKind::Kinematic, MethodKind::Elastic],
        false,
    );
}
