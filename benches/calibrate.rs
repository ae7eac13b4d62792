//! `cargo bench --bench calibrate`: time to fit each method of the paper on the paper campaign (2335 points,
//! split 50 / 25 / 25: 1168 training, 583 validation), input selection, degree and α search included, on
//! one core. Median of repeated fits; the figures are for the README, not assertions.

use std::time::{Duration, Instant};

use calibench::calib::method::{FitContext, MethodKind, fit};
use calibench::calib::regression::RegressionOptions;
use calibench::dataset::{Dataset, Split, random_split};
use calibench::robot::dh::DhChain;
use calibench::scenario::Scenario;

fn main() {
    let scenario = Scenario::load("scenarios/paper_iiwa.toml").expect("run from the crate root");
    let sim = calibench::campaign::simulate(&scenario).expect("the paper scenario simulates");
    let csv = calibench::measurements::measurements_csv(&sim.campaign).expect("csv");
    let data = Dataset::from_reader(csv.as_slice(), "paper campaign", &sim.nominal.joint_names())
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
    let dh = DhChain::from_chain(&sim.nominal).expect("DH");
    let single = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("pool");
    let methods = [
        MethodKind::Nominal,
        MethodKind::PaperRotz,
        MethodKind::PaperRotxyz,
        MethodKind::PaperRotxyzTransxyz,
    ];
    for cross_terms in [false, true] {
        let ctx = FitContext {
            chain: &sim.nominal,
            dh: &dh,
            payload: scenario.robot.payload(),
            regression: RegressionOptions {
                cross_terms,
                ..RegressionOptions::default()
            },
        };
        for kind in methods {
            if cross_terms && kind == MethodKind::Nominal {
                continue;
            }
            let mut runs: Vec<Duration> = (0..9)
                .map(|_| {
                    let t = Instant::now();
                    single
                        .install(|| fit(kind, &ctx, &train, &val))
                        .expect("fits");
                    t.elapsed()
                })
                .collect();
            runs.sort();
            println!(
                "fit {:<22}{} on {} training + {} validation points, one core: {:.1} ms",
                kind.name(),
                if cross_terms { " (cross terms)" } else { "" },
                train.len(),
                val.len(),
                runs[runs.len() / 2].as_secs_f64() * 1e3
            );
        }
    }
}
