//! Results that do not mislead (issue 13): "Measured" is one number per data set whatever the method, and a
//! calibration worse than nominal is flagged.

use std::path::{Path, PathBuf};

use calibench::app::calibrate::{FitOptions, fit};
use calibench::calib::registry::MethodKind;
use calibench::calib::regression::RegressionOptions;
use calibench::eval::split::SplitRule;
use calibench::eval::transfer::TestRegistration;
use calibench::robot::Payload;
use calibench::scenario::Scenario;
use tempfile::TempDir;

/// A paper_iiwa campaign of `points` points written as `measurements.csv` and `truth.csv` into `dir`.
fn campaign(dir: &Path, points: usize) -> (PathBuf, PathBuf) {
    let text = std::fs::read_to_string("scenarios/paper_iiwa.toml").unwrap();
    let text = text.replacen("points = 2335", &format!("points = {points}"), 1);
    let scenario = Scenario::parse(&text, "paper_iiwa (edited)").unwrap();
    let sim = calibench::app::simulate(&scenario).unwrap();
    let data = dir.join("measurements.csv");
    let truth = dir.join("truth.csv");
    std::fs::write(
        &data,
        calibench::measurements::measurements_csv(&sim.campaign).unwrap(),
    )
    .unwrap();
    std::fs::write(
        &truth,
        calibench::measurements::truth_csv(&sim.campaign).unwrap(),
    )
    .unwrap();
    (data, truth)
}

pub fn options(data: &Path, method: MethodKind, out: PathBuf) -> FitOptions {
    FitOptions {
        data: data.to_path_buf(),
        mapping: None,
        test_data: None,
        test_mapping: None,
        test_registration: TestRegistration::Refit,
        ignore_inputs: false,
        robot: "robots/iiwa7.urdf".into(),
        flange_link: None,
        method,
        payload: Payload::NONE,
        truth: None,
        out,
        split: SplitRule::default(),
        regression: RegressionOptions::default(),
    }
}

/// The same data and split: the "Measured" statistics (test split and against the truth) are bit for bit the
/// same for every method, and a method with its own refined registration reports its own "before" apart.
#[test]
fn measured_is_one_number_per_data_set() {
    let dir = TempDir::new().unwrap();
    let (data, truth) = campaign(dir.path(), 240);
    let mut measured: Option<(String, String)> = None;
    for method in [
        MethodKind::Nominal,
        MethodKind::PaperRotxyz,
        MethodKind::Kinematic,
        MethodKind::Elastic,
        MethodKind::ResidualRidge,
        MethodKind::Hybrid,
    ] {
        let mut o = options(&data, method, dir.path().join(method.name()));
        o.truth = Some(truth.clone());
        let outcome = fit(&o).unwrap();
        let r = &outcome.report;
        let before = serde_json::to_string(&r.test.before).unwrap();
        let truth_before = serde_json::to_string(&r.truth.as_ref().unwrap().before).unwrap();
        eprintln!(
            "{}: measured {:.4} mm (own registration {:?}), after {:.4} mm",
            method.name(),
            r.test.before.mean_mm,
            r.test.own_registration_before.as_ref().map(|s| s.mean_mm),
            r.test.after.mean_mm
        );
        match &measured {
            None => measured = Some((before, truth_before)),
            Some((b, t)) => {
                assert_eq!(b, &before, "{}", method.name());
                assert_eq!(t, &truth_before, "{}", method.name());
            }
        }
        // The printed table shows the same column.
        assert!(outcome.tables.contains("Measured"));
        if method == MethodKind::Kinematic {
            let own = r
                .test
                .own_registration_before
                .as_ref()
                .expect("reported apart");
            assert_ne!(own.mean_mm, r.test.before.mean_mm);
        }
    }
}
