//! The study report from hand-made results: `metrics.csv`'s exact header and cells, `summary.md`'s numbers
//! recomputed from `metrics.csv`, the points-needed rule, byte-identical output, PNGs that decode.

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use calibench::calib::registry::MethodKind;
use calibench::campaign::LayoutKind;
use calibench::design::Indices;
use calibench::eval::Stats;
use calibench::report::aggregate::{CurvePoint, Spread, learning_curves, points_needed};
use calibench::report::metrics::metrics_csv;
use calibench::report::plots::{histograms_png, learning_curves_png};
use calibench::report::summary::summary_md;
use calibench::scenario::Scenario;
use calibench::study::{Detail, Histogram, RunKey, RunMetrics, StudyConfig, StudyResult};
use nalgebra::Isometry3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const SIZES: [usize; 4] = [30, 60, 120, 240];
const SEEDS: u64 = 3;

/// Stats (m) whose mean is `mean_m` and the others derived from it.
fn stats(mean_m: f64) -> Stats {
    Stats {
        n: 100,
        mean: mean_m,
        max: 3.1 * mean_m,
        std: 0.52 * mean_m,
        rms: 1.13 * mean_m,
        p95: 2.05 * mean_m,
    }
}

/// Median ground-truth mean (mm) of each method's learning curve, by size: `nominal` flat, `paper-rotxyz`
/// plateaus far above the floor, `elastic` comes within 1.5 × the floor (0.025 mm) and 10 % of its plateau
/// at 120 points (with uniform) or 60 (with sobol).
fn truth_mm(method: &str, d: LayoutKind, n: usize) -> f64 {
    let i = SIZES.iter().position(|&s| s == n).unwrap();
    match (method, d) {
        ("nominal", _) => 0.40,
        ("paper-rotxyz", _) => [0.50, 0.25, 0.17, 0.16][i],
        ("elastic", LayoutKind::Sobol) => [0.20, 0.032, 0.031, 0.030][i],
        ("elastic", _) => [0.20, 0.035, 0.031, 0.030][i],
        _ => unreachable!(),
    }
}

pub fn study(orientation: bool) -> StudyResult {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios/paper_iiwa.toml");
    let scenario = Scenario::load(&path).expect("the shipped scenario loads");
    let regions = scenario.regions.clone();
    let methods = ["nominal", "paper-rotxyz", "elastic"];
    let layouts = [LayoutKind::Uniform, LayoutKind::Sobol];
    let config = StudyConfig {
        sizes: SIZES.to_vec(),
        layouts: layouts.to_vec(),
        methods: methods
            .iter()
            .map(|m| MethodKind::parse(m).unwrap())
            .collect(),
        seeds: SEEDS,
        validation_ratio: 0.5,
        test_points: 500,
        grid_points: 2000,
        shell_width_m: 0.05,
        shell_points: 500,
        closed_loop_points: 200,
        detail_method: None,
        distance_bands_m: vec![0.025, 0.05],
        targets_mm: vec![0.3, 0.1, 0.05, 0.02],
        move_s: 3.0,
        settle_s: 2.0,
        measure_s: 1.0,
        trajectory: None,
    };
    let mut runs = Vec::new();
    for region in &regions {
        for &d in &layouts {
            for m in methods {
                for n in SIZES {
                    for seed in 0..SEEDS {
                        // Seeds scatter ±3 % about the median (seed 1 is the median).
                        let f =
                            1.0 + 0.03 * (seed as f64 - 1.0) * if seed == 2 { 1.7 } else { 1.0 };
                        let t = truth_mm(m, d, n) * f * 1e-3;
                        let failed =
                            m == "elastic" && d == LayoutKind::Sobol && n == 60 && seed == 2;
                        let ori = |x: f64| orientation.then(|| stats(x));
                        runs.push(RunMetrics {
                            key: RunKey {
                                region: region.name.clone(),
                                layout: d,
                                method: MethodKind::parse(m).unwrap(),
                                n_train: n,
                                seed,
                            },
                            failure: failed
                                .then(|| "singular normal equations,\n  \"rank 3\"".to_string()),
                            test: Some(stats(t * 1.05 + 1.234_567_891e-6)),
                            truth: Some(stats(t)),
                            outside: Some(stats(t * 1.7)),
                            closed_loop: Some(stats(t * 1.1)),
                            floor_mean: Some(0.025e-3 * (1.0 + 0.01 * seed as f64)),
                            test_orientation: ori(t * 2.0),
                            truth_orientation: ori(t * 1.5),
                            // Indices grow with the size, as they do for a campaign.
                            by_distance: Vec::new(),
                            observability: (m != "nominal").then(|| Indices {
                                points: n,
                                params: 31,
                                rank: 31,
                                o1: 0.8 + 0.001 * seed as f64,
                                o2: 1e-3 * (1.0 + n as f64 / 100.0),
                                o3: 0.123_456_789 * (n as f64).sqrt(),
                                logdet: 31.0 * (n as f64).ln() - 12.345_678_9,
                            }),
                            fit_ms: 3.0 + n as f64 * 0.0731 + seed as f64,
                        });
                    }
                }
            }
        }
    }
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let mut histograms = BTreeMap::new();
    let before: Vec<f64> = (0..500)
        .map(|_| 0.45e-3 * (-2.0 * (1.0 - rng.random::<f64>()).ln()).sqrt())
        .collect();
    for (m, scale) in [("nominal", 1.0), ("paper-rotxyz", 0.4), ("elastic", 0.08)] {
        let after = before
            .iter()
            .map(|b| scale * b * (0.5 + rng.random::<f64>()))
            .collect();
        histograms.insert(
            MethodKind::parse(m).unwrap(),
            Histogram {
                before: before.clone(),
                after,
            },
        );
    }
    StudyResult {
        detail: Detail {
            region: regions[0].name.clone(),
            layout: LayoutKind::Uniform,
            method: MethodKind::Elastic,
            n_train: 240,
            points: Vec::new(),
            grid: Vec::new(),
            histograms,
            tracker: Isometry3::identity(),
        },
        world: scenario.world.clone(),
        config,
        regions,
        runs,
        orientation,
        limits: vec![calibench::study::Limits {
            region: "paper".into(),
            tracker_noise_mean: 0.03e-3,
            repeatability_mean: 0.012e-3,
        }],
        trajectory: Vec::new(),
        trajectory_detail: None,
    }
}

/// `metrics.csv` as rows of column → cell.
fn parse_csv(bytes: &[u8]) -> (Vec<String>, Vec<HashMap<String, String>>) {
    let mut r = csv::Reader::from_reader(bytes);
    let header: Vec<String> = r.headers().unwrap().iter().map(String::from).collect();
    let rows = r
        .records()
        .map(|rec| {
            let rec = rec.unwrap();
            assert_eq!(rec.len(), header.len());
            header
                .iter()
                .cloned()
                .zip(rec.iter().map(String::from))
                .collect()
        })
        .collect();
    (header, rows)
}

/// Median, q1, q3 by linear interpolation (numpy's default), written independently of the library.
fn quartiles(mut v: Vec<f64>) -> (f64, f64, f64) {
    v.sort_by(|a, b| a.partial_cmp(b).unwrap());
    let q = |p: f64| {
        let x = p * (v.len() - 1) as f64;
        let (i, frac) = (x.floor() as usize, x.fract());
        if i + 1 < v.len() {
            v[i] + (v[i + 1] - v[i]) * frac
        } else {
            v[i]
        }
    };
    (q(0.5), q(0.25), q(0.75))
}

/// The `column` values of the successful rows of one (region, layout, method, size).
fn values(
    rows: &[HashMap<String, String>],
    layout: &str,
    method: &str,
    n: usize,
    column: &str,
) -> Vec<f64> {
    rows.iter()
        .filter(|r| {
            r["region"] == "paper"
                && r["distribution"] == layout
                && r["method"] == method
                && r["n_train"] == n.to_string()
                && r["status"] == "ok"
        })
        .map(|r| r[column].parse::<f64>().unwrap())
        .collect()
}

/// The header and rows of the first markdown table after `heading`, each as its cells.
fn table_rows(md: &str, heading: &str) -> (Vec<String>, Vec<Vec<String>>) {
    let start = md
        .find(heading)
        .unwrap_or_else(|| panic!("no heading {heading:?} in\n{md}"));
    let lines: Vec<Vec<String>> = md[start + heading.len()..]
        .lines()
        .skip_while(|l| !l.starts_with('|'))
        .take_while(|l| l.starts_with('|'))
        .map(|l| {
            l.trim_matches('|')
                .split(" | ")
                .map(|c| c.trim().to_string())
                .collect()
        })
        .collect();
    (lines[0].clone(), lines[2..].to_vec())
}

/// The cells of the markdown table row starting with `| first |` in the section whose heading is `heading`.
fn table_row(md: &str, heading: &str, first: &str) -> Vec<String> {
    let start = md
        .find(heading)
        .unwrap_or_else(|| panic!("no heading {heading:?} in\n{md}"));
    let section = &md[start + heading.len()..];
    let section = &section[..section.find("\n#").unwrap_or(section.len())];
    let line = section
        .lines()
        .find(|l| l.starts_with(&format!("| {first} |")))
        .unwrap_or_else(|| panic!("no row {first:?} under {heading:?}"));
    line.trim_matches('|')
        .split(" | ")
        .skip(1)
        .map(|c| c.trim().to_string())
        .collect()
}

#[test]
fn metrics_header_is_exact() {
    let (header, rows) = parse_csv(&metrics_csv(&study(false)).unwrap());
    assert_eq!(
        header,
        "scenario,region,distribution,method,n_train,seed,status,worse_than_nominal,test_mean_mm,test_max_mm,test_std_mm,\
         test_rms_mm,test_p95_mm,truth_mean_mm,truth_max_mm,truth_p95_mm,outside_mean_mm,\
         closed_loop_mean_mm,floor_mean_mm,o1,o2,o3,logdet,fit_ms"
            .split(',')
            .collect::<Vec<_>>()
    );
    assert_eq!(rows.len(), 2 * 3 * 4 * SEEDS as usize);
    let (header, _) = parse_csv(&metrics_csv(&study(true)).unwrap());
    assert_eq!(
        &header[24..],
        [
            "test_ori_mean_rad",
            "test_ori_max_rad",
            "test_ori_std_rad",
            "truth_ori_mean_rad"
        ]
    );
}

#[test]
fn metrics_rows_hold_millimetres_and_failures_leave_empty_cells() {
    let s = study(true);
    let (_, rows) = parse_csv(&metrics_csv(&s).unwrap());
    // Rows follow the run order.
    for (row, run) in rows.iter().zip(&s.runs) {
        assert_eq!(row["scenario"], "paper_iiwa");
        assert_eq!(row["method"], run.key.method.name());
        assert_eq!(row["seed"], run.key.seed.to_string());
        assert_eq!(row["distribution"], run.key.layout.name());
        assert_eq!(row["fit_ms"], format!("{:.1}", run.fit_ms));
        if let Some(t) = &run.truth
            && run.failure.is_none()
        {
            let mm: f64 = row["truth_mean_mm"].parse().unwrap();
            assert!((mm - t.mean * 1e3).abs() < 1e-6, "{mm} vs {}", t.mean);
            let rad: f64 = row["truth_ori_mean_rad"].parse().unwrap();
            assert!((rad - run.truth_orientation.unwrap().mean).abs() < 1e-9);
            match run.observability {
                Some(o) => {
                    // Seven significant digits, whatever the magnitude.
                    for (column, v) in [("o1", o.o1), ("o3", o.o3), ("logdet", o.logdet)] {
                        let written: f64 = row[column].parse().unwrap();
                        assert!(
                            (written - v).abs() <= 5e-7 * v.abs(),
                            "{column}: {written} vs {v}"
                        );
                    }
                }
                None => assert_eq!(row["o1"], ""),
            }
        }
    }
    let failed: Vec<_> = rows.iter().filter(|r| r["status"] != "ok").collect();
    assert_eq!(failed.len(), 1);
    assert_eq!(
        failed[0]["status"],
        "failed: singular normal equations, \"rank 3\""
    );
    for column in [
        "test_mean_mm",
        "truth_mean_mm",
        "floor_mean_mm",
        "test_ori_mean_rad",
    ] {
        assert_eq!(failed[0][column], "", "{column}");
    }
    assert!(!failed[0]["fit_ms"].is_empty());
}

#[test]
fn the_same_study_gives_the_same_bytes() {
    let (a, b) = (study(true), study(true));
    assert_eq!(metrics_csv(&a).unwrap(), metrics_csv(&b).unwrap());
    assert_eq!(summary_md(&a).unwrap(), summary_md(&b).unwrap());
    assert_eq!(
        learning_curves_png(&a).unwrap(),
        learning_curves_png(&b).unwrap()
    );
}

#[test]
fn summary_numbers_are_the_aggregates_of_metrics_csv() {
    let s = study(true);
    let (_, rows) = parse_csv(&metrics_csv(&s).unwrap());
    let md = summary_md(&s).unwrap();
    let methods = ["nominal", "paper-rotxyz", "elastic"];

    // Learning curves: median [q1–q3] of the ground-truth mean per size, the floor last.
    for layout in ["uniform", "sobol"] {
        let heading = format!("#### Region `paper`, {layout} layout");
        for n in SIZES {
            let row = table_row(&md, &heading, &n.to_string());
            assert_eq!(row.len(), methods.len() + 1);
            for (m, cell) in methods.iter().zip(&row) {
                let v = values(&rows, layout, m, n, "truth_mean_mm");
                let (med, q1, q3) = quartiles(v.clone());
                let expected = format!("{med:.4} [{q1:.4}–{q3:.4}]");
                assert!(
                    cell.starts_with(&expected),
                    "{layout} {m} {n}: {cell:?} vs {expected:?}"
                );
                assert_eq!(cell.contains("failed"), v.len() < SEEDS as usize);
            }
            // The floor: one value per seed (the first successful row of that seed).
            let mut seen = Vec::new();
            let floor: Vec<f64> = rows
                .iter()
                .filter(|r| r["distribution"] == layout && r["n_train"] == n.to_string())
                .filter(|r| r["status"] == "ok")
                .filter(|r| {
                    let fresh = !seen.contains(&r["seed"]);
                    seen.push(r["seed"].clone());
                    fresh
                })
                .map(|r| r["floor_mean_mm"].parse().unwrap())
                .collect();
            let (med, q1, q3) = quartiles(floor);
            assert_eq!(row[3], format!("{med:.4} [{q1:.4}–{q3:.4}]"));
        }
    }

    // Table 1 and Table 2 at the largest size, one table each: a row per method and layout, medians over
    // the successful seeds; the fit-time column is there because the hand-made runs have times.
    for (heading, checks, decimals) in [
        (
            "### Table 1 — region `paper`, 240 training points",
            &[
                ("test mean", "test_mean_mm"),
                ("test max", "test_max_mm"),
                ("test p95", "test_p95_mm"),
                ("truth mean", "truth_mean_mm"),
                ("closed loop mean", "closed_loop_mean_mm"),
            ][..],
            4,
        ),
        (
            "### Table 2 — region `paper`, 240 training points",
            &[("test max", "test_ori_max_rad")][..],
            6,
        ),
    ] {
        let (header, body) = table_rows(&md, heading);
        assert_eq!(body.len(), methods.len() * 2, "{heading}");
        for (label, column) in checks {
            let at = header.iter().position(|h| h == label).unwrap();
            for layout in ["uniform", "sobol"] {
                for m in methods {
                    let row = body
                        .iter()
                        .find(|r| r[0] == format!("`{m}`") && r[1] == layout)
                        .unwrap();
                    let (med, _, _) = quartiles(values(&rows, layout, m, 240, column));
                    assert_eq!(
                        row[at],
                        format!("{med:.decimals$}"),
                        "{layout} {m} {column}"
                    );
                }
            }
        }
    }
    assert!(md.contains("240 × 680 × 640 mm"), "{md}");
}

fn point(n: usize, truth: f64, floor: f64) -> CurvePoint {
    let s = |x: f64| Spread {
        n: 3,
        median: x,
        q1: 0.9 * x,
        q3: 1.1 * x,
    };
    CurvePoint {
        n_train: n,
        runs: 3,
        failed: 0,
        truth: Some(s(truth)),
        floor: Some(s(floor)),
    }
}

#[test]
fn points_needed_is_the_first_size_near_both_plateau_and_floor() {
    // Within 10 % of the plateau (0.030) from 120 on, within 1.5 × the floor from 60 on: 120.
    let reaches = [
        point(30, 0.2, 0.025),
        point(60, 0.035, 0.025),
        point(120, 0.032, 0.025),
        point(240, 0.030, 0.025),
    ];
    assert_eq!(points_needed(&reaches), Some(120));
    // Flat from 60 but 6 × the floor: never.
    let plateaus = [
        point(30, 0.5, 0.025),
        point(60, 0.16, 0.025),
        point(120, 0.16, 0.025),
        point(240, 0.16, 0.025),
    ];
    assert_eq!(points_needed(&plateaus), None);
    // A size without a successful run is skipped; the plateau is the largest size with a result.
    let mut gap = reaches.clone();
    gap[2].truth = None;
    gap[3].truth = None;
    assert_eq!(points_needed(&gap), Some(60));

    // The same rule on the hand-made study, and as summary.md shows it.
    let s = study(false);
    let curves = learning_curves(&s);
    let find = |m: &str, d: LayoutKind| {
        let c = curves
            .iter()
            .find(|c| c.method.name() == m && c.layout == d)
            .unwrap();
        points_needed(&c.points)
    };
    assert_eq!(find("elastic", LayoutKind::Uniform), Some(120));
    assert_eq!(find("elastic", LayoutKind::Sobol), Some(60));
    assert_eq!(find("paper-rotxyz", LayoutKind::Uniform), None);
    // The verdicts compare with the targets, not with the floor.
    let md = summary_md(&s).unwrap();
    let verdict = &md[md.find("## Verdict").unwrap()..md.find("## Details").unwrap()];
    assert!(
        verdict.contains(
            "**elastic**: levels off at 0.0300 mm (best layout uniform, within 10 % from 120 points) — more \
             points do not help; its model is the limit; its smallest target reached is 0.05 mm (mean), from 60 \
             points with uniform."
        ),
        "{verdict}"
    );
    assert!(
        verdict
            .contains("its smallest target reached is 0.3 mm (mean), from 60 points with uniform"),
        "{verdict}"
    );
    assert!(!verdict.contains("floor"), "{verdict}");
    // paper-rotxyz at 30 points (0.50 mm) is worse than no calibration (0.40 mm) in every seed and layout.
    assert!(
        md.contains("6 of 47 successful runs have a ground-truth mean above `nominal`'s"),
        "{md}"
    );
    // The details follow the answer and the curves; no section is empty.
    let order: Vec<usize> = [
        "## The answer",
        "## Learning curves",
        "## Verdict",
        "## Details",
        "### Table 1",
        "### Runs where calibration made the arm worse",
    ]
    .iter()
    .map(|h| md.find(h).unwrap_or_else(|| panic!("{h} missing")))
    .collect();
    assert!(order.windows(2).all(|w| w[0] < w[1]), "{order:?}");
}

#[test]
fn plots_are_pngs_and_write_into_a_subdirectory() {
    let s = study(false);
    let curves = learning_curves_png(&s).unwrap();
    let hist = histograms_png(&s).unwrap();
    assert_eq!(
        curves.iter().map(|(n, _)| n.as_str()).collect::<Vec<_>>(),
        ["plots/learning_curves_paper.png"]
    );
    assert_eq!(hist.len(), 3);
    assert!(
        hist.iter()
            .any(|(n, _)| n == "plots/histogram_paper-rotxyz.png")
    );
    for (name, png) in curves.iter().chain(&hist) {
        assert!(png.starts_with(b"\x89PNG\r\n\x1a\n"), "{name}");
        assert!(png.len() > 10_000, "{name}: {} bytes", png.len());
        // IHDR: width and height.
        let w = u32::from_be_bytes(png[16..20].try_into().unwrap());
        let h = u32::from_be_bytes(png[20..24].try_into().unwrap());
        assert!(w >= 800 && h >= 500, "{name}: {w} × {h}");
    }

    let dir = tempfile::tempdir().unwrap();
    let mut files: Vec<(&str, Vec<u8>)> = vec![
        ("metrics.csv", metrics_csv(&s).unwrap()),
        ("summary.md", summary_md(&s).unwrap().into_bytes()),
    ];
    files.extend(
        curves
            .iter()
            .chain(&hist)
            .map(|(n, b)| (n.as_str(), b.clone())),
    );
    calibench::output::write_files(dir.path(), &files).unwrap();
    for (name, bytes) in &files {
        assert_eq!(&std::fs::read(dir.path().join(name)).unwrap(), bytes);
    }
    let leftovers: Vec<_> = std::fs::read_dir(dir.path().join("plots"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".partial"))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");

    // To look at the output: REPORT_TEST_OUT=/some/dir cargo test --release --test suite report::
    if let Ok(out) = std::env::var("REPORT_TEST_OUT") {
        calibench::output::write_files(Path::new(&out), &files).unwrap();
    }
}

/// A calibration worse than nominal on the same campaign is flagged in `metrics.csv` and counted in
/// `summary.md`: here `paper-rotxyz` at 30 points (0.50 against 0.40 mm), and nothing else.
#[test]
fn runs_worse_than_nominal_are_flagged() {
    let s = study(false);
    let (_, rows) = parse_csv(&metrics_csv(&s).unwrap());
    let mut flagged = 0;
    for r in &rows {
        let expected = match (r["method"].as_str(), r["n_train"].as_str()) {
            ("nominal", _) => "",
            _ if r["status"] != "ok" => "",
            ("paper-rotxyz", "30") => "true",
            _ => "false",
        };
        assert_eq!(r["worse_than_nominal"], expected, "{r:?}");
        flagged += usize::from(expected == "true");
    }
    assert_eq!(flagged, 2 * SEEDS as usize * s.regions.len());
    let summary = calibench::report::summary::summary_md(&s).unwrap();
    assert!(
        summary.contains(&format!("**{flagged} runs end worse than `nominal`**"))
            && summary.contains("`paper-rotxyz` at 30 points"),
        "{summary}"
    );
}
