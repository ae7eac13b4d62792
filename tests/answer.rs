//! The answer to the planning question, recomputed from `metrics.csv` alone (independently of the library's
//! aggregation) and compared with `answer.csv` and with the first table of `summary.md`.

use std::collections::{BTreeMap, HashMap};

use calibench::report::answer::{answer_csv, answer_text};
use calibench::report::metrics::metrics_csv;
use calibench::report::summary::summary_md;

/// Rows of a CSV as column → cell.
type Row = HashMap<String, String>;
/// (region, statistic, target) → (points, median, method, layout) of the recommendation.
type Recommended = BTreeMap<(String, String, String), (usize, f64, String, String)>;

fn rows(text: &str) -> Vec<Row> {
    let mut r = csv::Reader::from_reader(text.as_bytes());
    let header: Vec<String> = r.headers().unwrap().iter().map(String::from).collect();
    r.records()
        .map(|rec| {
            header
                .iter()
                .cloned()
                .zip(rec.unwrap().iter().map(String::from))
                .collect()
        })
        .collect()
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.partial_cmp(b).unwrap());
    let x = 0.5 * (v.len() - 1) as f64;
    let i = x.floor() as usize;
    if i + 1 < v.len() {
        v[i] + (v[i + 1] - v[i]) * x.fract()
    } else {
        v[i]
    }
}

/// (region, statistic, target, method, layout) → (fewest points reaching the target in ≥ 80 % of the rows of
/// that size, the median of the statistic there over the successful rows).
type Key = (String, String, String, String, String);

fn recompute(metrics: &str, targets: &[f64]) -> BTreeMap<Key, Option<(usize, f64)>> {
    let rows = rows(metrics);
    let mut groups: BTreeMap<(String, String, String, usize), Vec<&Row>> = BTreeMap::new();
    for r in &rows {
        groups
            .entry((
                r["region"].clone(),
                r["method"].clone(),
                r["distribution"].clone(),
                r["n_train"].parse().unwrap(),
            ))
            .or_default()
            .push(r);
    }
    let mut out = BTreeMap::new();
    for statistic in ["truth_mean_mm", "truth_p95_mm"] {
        for &t in targets {
            for ((region, method, layout, n), runs) in &groups {
                let key = (
                    region.clone(),
                    statistic.to_string(),
                    format!("{t}"),
                    method.clone(),
                    layout.clone(),
                );
                let ok: Vec<f64> = runs
                    .iter()
                    .filter(|r| r["status"] == "ok")
                    .map(|r| r[statistic].parse::<f64>().unwrap())
                    .collect();
                let reaching = ok.iter().filter(|v| **v <= t).count();
                let entry = out.entry(key).or_insert(None);
                // Groups iterate by ascending size, so the first size that reaches is the fewest.
                if entry.is_none() && 5 * reaching >= 4 * runs.len() {
                    *entry = Some((*n, median(ok)));
                }
            }
        }
    }
    out
}

/// The cells of the markdown table under `heading`: first column → the other cells.
fn table(md: &str, heading: &str) -> Vec<Vec<String>> {
    let start = md
        .find(heading)
        .unwrap_or_else(|| panic!("no {heading:?} in\n{md}"));
    md[start + heading.len()..]
        .lines()
        .skip_while(|l| !l.starts_with('|'))
        .take_while(|l| l.starts_with('|'))
        .skip(2)
        .map(|l| {
            l.trim_matches('|')
                .split(" | ")
                .map(|c| c.trim().to_string())
                .collect()
        })
        .collect()
}

/// `answer.csv` and the answer tables of `summary.md` agree with the recomputation from `metrics.csv`.
pub fn check(metrics: &str, answer: &str, summary: &str, targets: &[f64]) {
    let expected = recompute(metrics, targets);
    let answer_rows = rows(answer);
    assert_eq!(answer_rows.len(), expected.len(), "one row per cell");
    let mut recommended = Recommended::new();
    for r in &answer_rows {
        let key: Key = (
            r["region"].clone(),
            r["statistic"].clone(),
            r["target_mm"].clone(),
            r["method"].clone(),
            r["distribution"].clone(),
        );
        let want = expected[&key];
        let got = (!r["n_train"].is_empty()).then(|| r["n_train"].parse::<usize>().unwrap());
        assert_eq!(got, want.map(|w| w.0), "{key:?}");
        if let Some((n, med)) = want {
            let written: f64 = r["median_mm"].parse().unwrap();
            assert_eq!(r["median_mm"], format!("{med:.4}"), "{key:?}: {written}");
            let best = recommended
                .entry((key.0.clone(), key.1.clone(), key.2.clone()))
                .or_insert((usize::MAX, f64::INFINITY, String::new(), String::new()));
            if (n, med) < (best.0, best.1) {
                *best = (n, med, key.3.clone(), key.4.clone());
            }
        }
    }
    // Exactly the recomputed recommendation is flagged.
    for r in &answer_rows {
        let best = recommended.get(&(
            r["region"].clone(),
            r["statistic"].clone(),
            r["target_mm"].clone(),
        ));
        let is = best.is_some_and(|b| b.2 == r["method"] && b.3 == r["distribution"]);
        assert_eq!(r["recommended"], is.to_string(), "{r:?}");
    }

    // The summary opens with the answer, and its first table holds the same recommendations.
    let first = summary.find("\n## ").map(|i| &summary[i + 1..]).unwrap();
    assert!(first.starts_with("## The answer"), "{first}");
    let regions: Vec<String> = {
        let mut v: Vec<String> = answer_rows.iter().map(|r| r["region"].clone()).collect();
        v.dedup();
        v
    };
    for region in regions {
        for (statistic, name) in [
            ("truth_mean_mm", "Ground-truth mean"),
            ("truth_p95_mm", "Ground-truth p95"),
        ] {
            let rows = table(summary, &format!("### {name} ≤ target, region `{region}`"));
            assert_eq!(rows.len(), targets.len());
            for (row, t) in rows.iter().zip(targets) {
                assert!(row[0].starts_with(&format!("{t}")), "{row:?}");
                match recommended.get(&(region.clone(), statistic.to_string(), format!("{t}"))) {
                    Some((n, med, method, layout)) => {
                        assert_eq!(row[1], format!("`{method}`, {layout}"), "{row:?}");
                        assert_eq!(row[2], n.to_string());
                        assert!(row[4].starts_with(&format!("{med:.4}")), "{row:?}");
                    }
                    None => assert_eq!(row[1], "no method in this study"),
                }
                // Every method's cell is a number of points or an explicit "not up to N (plateau …)".
                for c in &row[5..] {
                    assert!(
                        c.starts_with("not up to ")
                            || c.split(' ').next().unwrap().parse::<usize>().is_ok(),
                        "{c:?}"
                    );
                }
            }
        }
    }
}

#[test]
fn the_answer_of_a_hand_made_study_is_recomputed_from_metrics_csv() {
    let s = crate::report::study(false);
    let metrics = String::from_utf8(metrics_csv(&s).unwrap()).unwrap();
    let answer = String::from_utf8(answer_csv(&s).unwrap()).unwrap();
    let summary = summary_md(&s).unwrap();
    check(&metrics, &answer, &summary, &s.config.targets_mm);

    // Known cells: elastic on uniform falls to 0.035 mm (± 3 %) at 60 points, so the 0.05 mm target is
    // reached there; on sobol one run of three at 60 points failed, so 2 of 3 (< 80 %) and 120 points.
    let rows = rows(&answer);
    let find = |stat: &str, t: &str, m: &str, d: &str| {
        rows.iter()
            .find(|r| {
                r["statistic"] == stat
                    && r["target_mm"] == t
                    && r["method"] == m
                    && r["distribution"] == d
            })
            .unwrap()
            .clone()
    };
    assert_eq!(
        find("truth_mean_mm", "0.05", "elastic", "uniform")["n_train"],
        "60"
    );
    assert_eq!(
        find("truth_mean_mm", "0.05", "elastic", "sobol")["n_train"],
        "120"
    );
    // paper-rotxyz levels off at 0.16 mm: not the 0.1 mm target, with that plateau stated.
    let never = find("truth_mean_mm", "0.1", "paper-rotxyz", "uniform");
    assert_eq!(never["n_train"], "");
    assert_eq!(never["plateau_mm"], "0.1600");
    assert!(
        summary.contains("not up to 240 (plateau 0.1600)"),
        "{summary}"
    );
    // Hours: 60 training + 30 validation points at 6 s each.
    assert_eq!(
        find("truth_mean_mm", "0.05", "elastic", "uniform")["tracker_hours"],
        "0.15"
    );
    // The limits are stated, and a target below them says so.
    assert!(
        summary.contains("below the tracker noise (0.0300 mm)"),
        "{summary}"
    );
    assert!(summary.contains("**Limits of the measurement"));
    // The console shows the recommendations within 80 columns.
    let text = answer_text(&s);
    assert!(text.contains("elastic, uniform"), "{text}");
    for line in text.lines() {
        assert!(line.chars().count() <= 80, "{line:?}");
    }
}
