//! Property tests of the readers and of applying a model (issue 14): random bytes, and valid files with
//! numbers replaced by extremes (±1e300, NaN, infinities, subnormals), go to the CSV, scenario (TOML), URDF
//! and model readers and to a fitted model's prediction and inverse, in process. Whatever the input, each
//! returns (a value or an error) and never panics; a hang fails the test by never finishing.

use std::sync::OnceLock;

use proptest::prelude::*;

use calibench::calib::error_model::FrameErrors;
use calibench::calib::method::FitContext;
use calibench::calib::method::Fitted;
use calibench::calib::registry::{MethodKind, SavedModel};
use calibench::dataset::Dataset;
use calibench::dataset::range::JointRange;
use calibench::robot::dh::DhChain;
use calibench::robot::urdf;
use calibench::scenario::Scenario;

use crate::common::synthetic::{Extra, synthetic};

const PAPER: &str = include_str!("../scenarios/paper_iiwa.toml");
const IIWA: &str = include_str!("../robots/iiwa7.urdf");

/// Numbers that have broken numeric code: overflow, NaN, infinities, subnormals, zero, and ordinary ones.
fn extreme() -> impl Strategy<Value = f64> {
    prop_oneof![
        Just(1e300),
        Just(-1e300),
        Just(f64::NAN),
        Just(f64::INFINITY),
        Just(f64::NEG_INFINITY),
        Just(5e-324),
        Just(-2.2e-308),
        Just(0.0),
        Just(f64::MAX),
        -10.0..10.0f64,
    ]
}

/// `text` with its `k`-th number (counting runs of digits, modulo their count) replaced by `v`.
fn replace_number(text: &str, k: usize, v: &str) -> String {
    let bytes = text.as_bytes();
    let mut spans = Vec::new();
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i].is_ascii_digit() {
            let start = i;
            while i < bytes.len() && (bytes[i].is_ascii_digit() || bytes[i] == b'.') {
                i += 1;
            }
            spans.push((start, i));
        } else {
            i += 1;
        }
    }
    if spans.is_empty() {
        return text.to_string();
    }
    let (a, b) = spans[k % spans.len()];
    format!("{}{v}{}", &text[..a], &text[b..])
}

/// A number as a file may write it (TOML spells NaN and infinities `nan`, `inf`).
fn spelled(v: f64) -> String {
    if v.is_nan() {
        "nan".into()
    } else if v.is_infinite() {
        if v > 0.0 { "inf".into() } else { "-inf".into() }
    } else {
        format!("{v:e}")
    }
}

struct Fitted2 {
    models: Vec<Box<dyn Fitted>>,
    saved: Vec<String>,
    data: String,
    names: Vec<String>,
}

/// Two models (the paper's and a residual polynomial, the one most prone to overflow) fitted once on a
/// small synthetic campaign, their files, and the campaign as CSV text.
fn fitted() -> &'static Fitted2 {
    static FITTED: OnceLock<Fitted2> = OnceLock::new();
    FITTED.get_or_init(|| {
        let mut errors: FrameErrors = vec![[0.0; 6]; 7];
        errors[2] = [1.5e-4, -1e-4, 2e-4, 4e-4, -3e-4, 5e-4];
        let s = synthetic(&errors, 120, 3, &Extra::default());
        let train = s.data.subset(&(0..80).collect::<Vec<_>>());
        let val = s.data.subset(&(80..120).collect::<Vec<_>>());
        let ctx = FitContext::new(&s.chain, &s.dh);
        let models: Vec<Box<dyn Fitted>> = [MethodKind::PaperRotxyz, MethodKind::ResidualRidge]
            .into_iter()
            .map(|m| m.fit(&ctx, &train, &val).unwrap())
            .collect();
        let saved = models
            .iter()
            .map(|m| serde_json::to_string(&SavedModel::of(m.as_ref()).unwrap()).unwrap())
            .collect();
        let names = s.chain.joint_names();
        let mut data = names.join(",") + ",x1,y1,z1\n";
        for (q, p) in s.data.q.iter().zip(&s.data.measured) {
            let cells: Vec<String> = q.iter().map(|v| v.to_string()).collect();
            data += &format!("{},{},{},{}\n", cells.join(","), p[0].x, p[0].y, p[0].z);
        }
        Fitted2 {
            models,
            saved,
            data,
            names,
        }
    })
}

/// What `calibrate apply` does with a configuration: the range check, then prediction and inverse.
fn apply_like(model: &dyn Fitted, q: &[f64]) {
    let prismatic = vec![false; q.len()];
    let _ = JointRange::plausible(model.joint_names(), &prismatic).check(
        "fuzz.csv",
        &[],
        &[q.to_vec()],
    );
    let _ = model.predict(q);
    let _ = model.compensate(q, &[]);
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn the_csv_reader_takes_any_bytes(bytes in proptest::collection::vec(any::<u8>(), 0..400)) {
        let names = fitted().names.clone();
        let _ = Dataset::from_reader(bytes.as_slice(), "fuzz.csv", &names);
    }

    #[test]
    fn the_csv_reader_and_range_check_take_extreme_numbers(k in 0usize..10_000, v in extreme()) {
        let f = fitted();
        let text = replace_number(&f.data, k, &spelled(v));
        if let Ok(d) = Dataset::from_reader(text.as_bytes(), "fuzz.csv", &f.names) {
            let (chain, _) = crate::common::synthetic::iiwa();
            let _ = JointRange::of_chain(&chain, "iiwa7.urdf").check(&d.origin, &d.point_ids, &d.q);
        }
    }

    #[test]
    fn the_scenario_reader_takes_any_text(text in "\\PC{0,300}") {
        let _ = Scenario::parse(&text, "fuzz.toml");
    }

    #[test]
    fn the_scenario_reader_takes_extreme_numbers(k in 0usize..10_000, v in extreme()) {
        let text = replace_number(PAPER, k, &spelled(v));
        let _ = Scenario::parse(&text, "fuzz.toml");
    }

    #[test]
    fn the_urdf_reader_takes_any_text(text in "\\PC{0,300}") {
        let _ = urdf::load_str(&text, "fuzz.urdf", None);
    }

    #[test]
    fn the_urdf_reader_and_dh_form_take_extreme_numbers(k in 0usize..10_000, v in extreme()) {
        let text = replace_number(IIWA, k, &spelled(v));
        if let Ok(chain) = urdf::load_str(&text, "fuzz.urdf", None) {
            let _ = DhChain::from_chain(&chain);
        }
    }

    #[test]
    fn the_model_reader_takes_extreme_numbers_and_its_model_applies(
        which in 0usize..2,
        k in 0usize..10_000,
        v in extreme(),
        q in proptest::collection::vec(extreme(), 7),
    ) {
        let f = fitted();
        // JSON has no NaN or infinity: those become a string, which the reader must refuse.
        let value = if v.is_finite() { format!("{v:e}") } else { format!("\"{v}\"") };
        let text = replace_number(&f.saved[which], k, &value);
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("model.json");
        std::fs::write(&path, &text).unwrap();
        if let Ok(model) = SavedModel::read(&path) {
            apply_like(model.as_ref(), &q);
        }
    }

    #[test]
    fn the_model_reader_takes_any_bytes(bytes in proptest::collection::vec(any::<u8>(), 0..300)) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("model.json");
        std::fs::write(&path, &bytes).unwrap();
        let _ = SavedModel::read(&path);
    }

    #[test]
    fn a_fitted_model_applies_to_extreme_configurations(
        which in 0usize..2,
        q in proptest::collection::vec(extreme(), 7),
    ) {
        apply_like(fitted().models[which].as_ref(), &q);
    }
}
