//! Reading campaigns back: the files the campaign writes give back its numbers bit for bit, column order
//! does not matter, real-tracker files without the optional columns read, every fault is a one-line
//! error naming row and column, and the seeded split is exact and reproducible.

use std::sync::OnceLock;

use calibench::app::simulate;
use calibench::campaign::Campaign;
use calibench::dataset::{Dataset, Split, TruthTable as Truth, random_split};
use calibench::measurements::{measurements_csv, truth_csv};
use calibench::scenario::Scenario;
use calibench::{Error, Result};

const PAPER_POSE: &str = include_str!("../scenarios/paper_iiwa_pose.toml");

/// A 30-point paper_iiwa_pose campaign, simulated once for all tests.
fn campaign() -> &'static Campaign {
    static CAMPAIGN: OnceLock<Campaign> = OnceLock::new();
    CAMPAIGN.get_or_init(|| {
        assert_eq!(PAPER_POSE.matches("points = 875").count(), 1);
        let text = PAPER_POSE.replacen("points = 875", "points = 30", 1);
        let scenario = Scenario::parse(&text, "small paper_iiwa_pose").unwrap();
        simulate(&scenario).unwrap().campaign
    })
}

fn joints() -> Vec<String> {
    campaign().joint_names.clone()
}

fn read(text: &str, joints: &[String]) -> Result<Dataset> {
    Dataset::from_reader(text.as_bytes(), "test.csv", joints)
}

fn bits(p: &nalgebra::Point3<f64>) -> [u64; 3] {
    [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()]
}

fn bits_all(points: &[nalgebra::Point3<f64>]) -> Vec<[u64; 3]> {
    points.iter().map(bits).collect()
}

fn pose_bits(pose: &nalgebra::Isometry3<f64>) -> [u64; 7] {
    let t = pose.translation.vector;
    let q = pose.rotation.quaternion();
    [t.x, t.y, t.z, q.w, q.i, q.j, q.k].map(f64::to_bits)
}

fn measurements_text() -> String {
    String::from_utf8(measurements_csv(campaign()).unwrap()).unwrap()
}

/// `text` with its columns rearranged: `keep(name)` selects them, then reversed.
fn rearrange(text: &str, keep: impl Fn(&str) -> bool) -> String {
    let mut reader = csv::Reader::from_reader(text.as_bytes());
    let headers: Vec<String> = reader.headers().unwrap().iter().map(String::from).collect();
    let cols: Vec<usize> = (0..headers.len())
        .rev()
        .filter(|&i| keep(&headers[i]))
        .collect();
    let mut writer = csv::Writer::from_writer(Vec::new());
    writer
        .write_record(cols.iter().map(|&i| &headers[i]))
        .unwrap();
    for record in reader.records() {
        let record = record.unwrap();
        writer
            .write_record(cols.iter().map(|&i| &record[i]))
            .unwrap();
    }
    String::from_utf8(writer.into_inner().unwrap()).unwrap()
}

fn message(result: Result<impl std::fmt::Debug>) -> String {
    match result.unwrap_err() {
        Error::Data { origin, message } => {
            assert!(!message.contains('\n'), "multi-line: {message}");
            assert!(!origin.is_empty());
            message
        }
        other => panic!("not a data error: {other}"),
    }
}

fn assert_message(result: Result<impl std::fmt::Debug>, parts: &[&str]) {
    let m = message(result);
    for part in parts {
        assert!(m.contains(part), "'{m}' lacks '{part}'");
    }
}

#[test]
fn campaign_files_read_back_bit_for_bit() {
    let c = campaign();
    assert_eq!(c.points.len(), 30);
    let dir = tempfile::tempdir().unwrap();
    let m_path = dir.path().join("measurements.csv");
    let t_path = dir.path().join("truth.csv");
    std::fs::write(&m_path, measurements_csv(c).unwrap()).unwrap();
    std::fs::write(&t_path, truth_csv(c).unwrap()).unwrap();

    let d = Dataset::read(&m_path, &c.joint_names).unwrap();
    assert_eq!(d.len(), 30);
    assert!(!d.is_empty());
    assert_eq!(d.reflectors(), 3);
    assert_eq!(d.origin, m_path.display().to_string());
    assert!(d.split.is_none());
    let nominal = d.nominal_reflectors.as_ref().unwrap();
    let flange = d.nominal_flange.as_ref().unwrap();
    let regions = d.regions.as_ref().unwrap();
    for (i, p) in c.points.iter().enumerate() {
        assert_eq!(d.point_ids[i], p.id.to_string());
        assert_eq!(regions[i], p.region);
        let q: Vec<u64> = d.q[i].iter().map(|v| v.to_bits()).collect();
        let q_cmd: Vec<u64> = p.q_cmd.iter().map(|v| v.to_bits()).collect();
        assert_eq!(q, q_cmd);
        assert_eq!(bits_all(&d.measured[i]), bits_all(&p.measured));
        assert_eq!(bits_all(&nominal[i]), bits_all(&p.nominal_reflectors));
        assert_eq!(pose_bits(&flange[i]), pose_bits(&p.nominal_flange));
    }

    let t = Truth::read(&t_path).unwrap();
    assert_eq!(t.point_ids, d.point_ids);
    for (i, p) in c.points.iter().enumerate() {
        assert_eq!(bits_all(&t.in_base[i]), bits_all(&p.true_reflectors));
        assert_eq!(bits_all(&t.in_tracker[i]), bits_all(&p.true_in_tracker));
    }
}

#[test]
fn column_order_does_not_matter() {
    let text = measurements_text();
    let original = read(&text, &joints()).unwrap();
    let reversed = read(&rearrange(&text, |_| true), &joints()).unwrap();
    assert_eq!(format!("{original:?}"), format!("{reversed:?}"));
}

#[test]
fn real_tracker_files_without_optional_columns() {
    let text = measurements_text();
    let joints = joints();
    let bare = rearrange(&text, |h| {
        joints.iter().any(|j| j == h) || h.len() == 2 && "xyz".contains(&h[..1])
    });
    let d = read(&bare, &joints).unwrap();
    let full = read(&text, &joints).unwrap();
    assert_eq!(d.len(), 30);
    assert!(d.nominal_reflectors.is_none());
    assert!(d.nominal_flange.is_none());
    assert!(d.regions.is_none());
    assert!(d.split.is_none());
    // Without point_id, ids are the rows as a spreadsheet numbers them.
    assert_eq!(d.point_ids[0], "2");
    assert_eq!(d.point_ids[29], "31");
    assert_eq!(d.q, full.q);
    assert_eq!(d.measured, full.measured);

    // One reflector, a split column, whitespace and case in the split values.
    let one = "j1, j2, x1, y1, z1, split, point_id\n\
               0.1, 0.2, 1, 2, 3, Train, a\n\
               0.3, 0.4, 4, 5, 6, validation, b\n\
               0.5, 0.6, 7, 8, 9, TEST, c\n\
               0.7, 0.8, 1e-3, -2.5, 0, val, d\n";
    let d = read(one, &["j1".into(), "j2".into()]).unwrap();
    assert_eq!(d.reflectors(), 1);
    assert_eq!(d.point_ids, ["a", "b", "c", "d"]);
    assert_eq!(
        d.split.as_deref().unwrap(),
        [Split::Train, Split::Val, Split::Test, Split::Val]
    );
    assert_eq!(d.q[3], [0.7, 0.8]);
    assert_eq!(d.measured[3][0], nalgebra::Point3::new(1e-3, -2.5, 0.0));

    let sub = d.subset(&[2, 0]);
    assert_eq!(sub.point_ids, ["c", "a"]);
    assert_eq!(sub.q, [d.q[2].clone(), d.q[0].clone()]);
    assert_eq!(sub.split.unwrap(), [Split::Test, Split::Train]);
    assert_eq!(sub.measured, [d.measured[2].clone(), d.measured[0].clone()]);
}

#[test]
fn errors_name_row_and_column() {
    let j: Vec<String> = vec!["j1".into(), "j2".into()];
    let missing = std::path::Path::new("/nonexistent/measurements.csv");
    let err = Dataset::read(missing, &j).unwrap_err();
    assert!(matches!(&err, Error::Data { origin, .. } if origin.contains("/nonexistent/")));
    assert!(err.to_string().contains("cannot read"), "{err}");
    assert!(Truth::read(missing).is_err());

    assert_message(read("", &j), &["empty file"]);
    assert_message(read("j1,j2,x1,y1,z1\n", &j), &["no data rows"]);
    assert_message(
        read("j1,x1,y1,z1\n0,1,2,3\n", &j),
        &[
            "no column 'j2'",
            "joint 2",
            "the header has: j1, x1, y1, z1",
        ],
    );
    // A long header is shown truncated.
    let long: Vec<String> = (0..40).map(|i| format!("c{i}")).collect();
    let m = message(read(
        &format!("{}\n{}\n", long.join(","), long.join(",")),
        &j,
    ));
    assert!(
        m.contains("c11, …") && m.contains("(40 columns)") && !m.contains("c12"),
        "{m}"
    );

    assert_message(read("j1,j2,y1,z1\n0,0,1,2\n", &j), &["'x1'"]);
    assert_message(read("j1,j2,x1,y1\n0,0,1,2\n", &j), &["'z1'"]);
    assert_message(
        read("j1,j2,x1,y1,z1,x2,y2,z2\n0,0,1,2,3,4,5,6\n", &j),
        &["x2, y2, z2", "no x3, y3, z3", "only 1 or 3 reflectors"],
    );
    assert_message(
        read("j1,j2,x1,y1,z1,x2,z2\n0,0,1,2,3,4,6\n", &j),
        &["no column 'y2'"],
    );
    let head = "point_id,j1,j2,x1,y1,z1";
    assert_message(
        read(&format!("{head}\na,0,0,1,2,3\nb,0,abc,1,2,3\n"), &j),
        &["row 3, column j2: 'abc' is not a number"],
    );
    assert_message(
        read(&format!("{head}\na,0,0,1,NaN,3\n"), &j),
        &["row 2, column y1: 'NaN' is not finite"],
    );
    assert_message(
        read(&format!("{head}\na,0,0,1,2,-inf\n"), &j),
        &["row 2, column z1: '-inf' is not finite"],
    );
    assert_message(
        read(&format!("{head}\na,0,0,1,2,\n"), &j),
        &["row 2, column z1: empty"],
    );
    assert_message(
        read(&format!("{head}\na,0,0,1,2,3\nb,0,0,1,2\n"), &j),
        &["row 3: 5 fields, the header has 6"],
    );
    assert_message(
        read(&format!("{head}\na,0,0,1,2,3,4\n"), &j),
        &["row 2: 7 fields, the header has 6"],
    );
    assert_message(
        read(
            &format!("{head},split\na,0,0,1,2,3,train\nb,0,0,1,2,3,holdout\n"),
            &j,
        ),
        &["row 3, column split: 'holdout' is not a split"],
    );
    assert_message(
        read(
            &format!("{head}\na,0,0,1,2,3\nb,0,0,1,2,3\na,0,0,1,2,3\n"),
            &j,
        ),
        &["row 4, column point_id: 'a' repeats row 2"],
    );
    assert_message(
        read(&format!("{head},nom_x1,nom_z1\na,0,0,1,2,3,4,5\n"), &j),
        &["no column 'nom_y1'", "nom_x1"],
    );
    assert_message(
        read(
            &format!(
                "{head},flange_x,flange_y,flange_z,flange_qw,flange_qx,flange_qy\na,0,0,1,2,3,0,0,0,1,0,0\n"
            ),
            &j,
        ),
        &["no column 'flange_qz'"],
    );
    assert_message(
        read(
            &format!(
                "{head},flange_x,flange_y,flange_z,flange_qw,flange_qx,flange_qy,flange_qz\na,0,0,1,2,3,0,0,0,2,0,0,0\n"
            ),
            &j,
        ),
        &["row 2, columns flange_qw…flange_qz", "norm"],
    );
    assert_message(
        read("j1,j2,x1,y1,z1,x1\n0,0,1,2,3,4\n", &j),
        &["'x1' appears twice"],
    );
    // Not UTF-8 on the second data row.
    let mut bytes = format!("{head}\na,0,0,1,2,3\n").into_bytes();
    bytes.extend_from_slice(b"b,0,\xff,1,2,3\n");
    assert_message(
        Dataset::from_reader(&bytes[..], "bytes.csv", &j),
        &["row 3", "UTF-8"],
    );

    assert_message(
        Truth::from_reader(
            "point_id,true_x1,true_y1,true_z1\n0,1,2,3\n".as_bytes(),
            "t",
        ),
        &["trk_x1"],
    );
}

#[test]
fn truth_aligns_to_dataset_order() {
    let c = campaign();
    let truth = Truth::from_reader(&truth_csv(c).unwrap()[..], "truth.csv").unwrap();
    let data = read(&measurements_text(), &c.joint_names).unwrap();
    let shuffled = data.subset(&[7, 3, 29, 0]);
    let aligned = truth.clone().aligned_to(&shuffled).unwrap();
    assert_eq!(aligned.point_ids, ["7", "3", "29", "0"]);
    // Already in the data's order: the same table.
    let in_order = truth.clone().aligned_to(&data).unwrap();
    assert_eq!(in_order.point_ids, truth.point_ids);
    assert_eq!(in_order.in_base, truth.in_base);
    assert_eq!(in_order.in_tracker, truth.in_tracker);
    for (k, &i) in [7, 3, 29, 0].iter().enumerate() {
        assert_eq!(aligned.in_base[k], c.points[i].true_reflectors);
        assert_eq!(aligned.in_tracker[k], c.points[i].true_in_tracker);
    }

    let partial = Truth::from_reader(
        "point_id,true_x1,true_y1,true_z1,trk_x1,trk_y1,trk_z1\na,1,2,3,4,5,6\nb,7,8,9,10,11,12\n"
            .as_bytes(),
        "t.csv",
    )
    .unwrap();
    let j: Vec<String> = vec!["j".into()];
    let data = read("point_id,j,x1,y1,z1\nb,0,1,2,3\na,0,1,2,3\nc,0,1,2,3\n", &j).unwrap();
    assert_message(partial.clone().aligned_to(&data), &["no point_id 'c'"]);
    let two = data.subset(&[0, 1]);
    let aligned = partial.aligned_to(&two).unwrap();
    assert_eq!(aligned.point_ids, ["b", "a"]);
    assert_eq!(aligned.in_base[0][0], nalgebra::Point3::new(7.0, 8.0, 9.0));
    assert_eq!(
        aligned.in_tracker[1][0],
        nalgebra::Point3::new(4.0, 5.0, 6.0)
    );
}

#[test]
fn random_split_is_exact_and_seeded() {
    let count = |labels: &[Split], s: Split| labels.iter().filter(|&&l| l == s).count();
    let a = random_split(2335, [0.5, 0.25, 0.25], 42).unwrap();
    assert_eq!(a.len(), 2335);
    assert_eq!(
        [Split::Train, Split::Val, Split::Test].map(|s| count(&a, s)),
        [1168, 583, 584]
    );
    assert_eq!(a, random_split(2335, [0.5, 0.25, 0.25], 42).unwrap());
    assert_ne!(a, random_split(2335, [0.5, 0.25, 0.25], 43).unwrap());
    // Small and awkward counts still label every point once, each count within one of n·fraction.
    for n in 3..60 {
        for f in [
            [0.5, 0.25, 0.25],
            [0.45, 0.45, 0.1],
            [1.0 / 3.0; 3],
            [0.7, 0.2, 0.1],
        ] {
            let Ok(labels) = random_split(n, f, 7) else {
                assert!(f.iter().any(|x| x * (n as f64) < 1.5), "n {n}, {f:?}");
                continue;
            };
            for (k, s) in [Split::Train, Split::Val, Split::Test]
                .into_iter()
                .enumerate()
            {
                let c = count(&labels, s) as f64;
                assert!(
                    c >= 1.0 && (c - f[k] * n as f64).abs() < 1.0 + 1e-9,
                    "n {n}, {f:?}"
                );
            }
        }
    }
    assert_eq!(
        random_split(10, [0.45, 0.45, 0.1], 1)
            .unwrap()
            .iter()
            .filter(|&&l| l == Split::Test)
            .count(),
        1
    );

    for (n, f) in [
        (100, [0.5, 0.25, 0.2]),
        (100, [0.5, 0.6, -0.1]),
        (100, [f64::NAN, 0.5, 0.5]),
        (100, [1.0, 0.0, 0.0]),
        (2, [0.5, 0.25, 0.25]),
        (0, [0.5, 0.25, 0.25]),
    ] {
        let err = random_split(n, f, 1).unwrap_err();
        assert!(!err.to_string().contains('\n'));
    }
    let err = random_split(2, [0.5, 0.25, 0.25], 1)
        .unwrap_err()
        .to_string();
    assert!(err.contains("empty"), "{err}");
    let err = random_split(100, [0.5, 0.25, 0.2], 1)
        .unwrap_err()
        .to_string();
    assert!(err.contains("sum to"), "{err}");
}

#[test]
fn joints_only_files_and_byte_order_mark() {
    let j: Vec<String> = vec!["j1".into(), "j2".into()];
    let (ids, q) = calibench::dataset::joints_from_reader(
        "\u{feff}j2,j1,note\n0.5,0.25,x\n1,2,y\n".as_bytes(),
        "cmd.csv",
        &j,
    )
    .unwrap();
    assert_eq!(ids, ["2", "3"]);
    assert_eq!(q, [[0.25, 0.5], [2.0, 1.0]]);
    assert_message(
        calibench::dataset::joints_from_reader("j1,j2\n0,oops\n".as_bytes(), "cmd.csv", &j),
        &["row 2, column j2: 'oops' is not a number"],
    );
    let d = read("\u{feff}j1,j2,x1,y1,z1\n0,0,1,2,3\n", &j).unwrap();
    assert_eq!(d.q, [[0.0, 0.0]]);
}

/// `mappings/README.md`'s examples: each `toml` block is a mapping, followed by a `csv` block of the export it
/// reads; every example describes the same measurement, so all must read to the same joint angles, point and
/// (where mapped) orientation and temperature; a block whose first line names a shipped file is that file.
#[test]
fn mapping_examples_read_alike() {
    use calibench::dataset::mapping::ColumnMapping;
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let page = std::fs::read_to_string(root.join("mappings/README.md")).unwrap();
    let mut blocks: Vec<(String, String)> = Vec::new();
    let mut current: Option<(String, String)> = None;
    for line in page.lines() {
        match (line.strip_prefix("```"), &mut current) {
            (Some(info), None) => current = Some((info.trim().to_string(), String::new())),
            (Some(_), Some(_)) => blocks.push(current.take().unwrap()),
            (None, Some((_, text))) => {
                text.push_str(line);
                text.push('\n');
            }
            (None, None) => {}
        }
    }
    let chain = calibench::robot::load(root.join("robots/ur10.urdf"), None).unwrap();
    let mut read = Vec::new();
    for pair in blocks.windows(2) {
        let [(kind, mapping), (next, export)] = pair else {
            unreachable!()
        };
        if kind != "toml" {
            continue;
        }
        assert_eq!(
            next, "csv",
            "a mapping example without its export:\n{mapping}"
        );
        let parsed = ColumnMapping::from_toml(mapping, "mappings/README.md").unwrap();
        if let Some(file) = mapping.lines().next().and_then(|l| l.strip_prefix("# "))
            && file.starts_with("mappings/")
        {
            assert_eq!(
                parsed,
                ColumnMapping::load(&root.join(file)).unwrap(),
                "{file}"
            );
        }
        let data = parsed
            .from_reader(export.as_bytes(), "example", &chain)
            .unwrap();
        read.push((parsed, data));
    }
    assert!(read.len() >= 3, "{} examples", read.len());
    let (_, first) = &read[0];
    for (mapping, data) in &read {
        assert_eq!(data.q.len(), 1);
        for (a, b) in data.q[0].iter().zip(&first.q[0]) {
            assert!(
                (a - b).abs() < 1e-9,
                "joints {:?} against {:?}",
                data.q[0],
                first.q[0]
            );
        }
        let distance = (data.measured[0][0] - first.measured[0][0]).norm();
        assert!(distance < 1e-9, "point off by {distance} m");
        if let (Some(o), Some(f)) = (&data.measured_orientation, &first.measured_orientation) {
            assert!(
                o[0].angle_to(&f[0]) < 1e-8,
                "orientation off by {} rad",
                o[0].angle_to(&f[0])
            );
        }
        if let (Some(i), Some(f)) = (&data.extra_inputs, &first.extra_inputs) {
            assert!((i.values[0][0] - f.values[0][0]).abs() < 1e-6);
        }
        assert_eq!(
            data.base_frame,
            mapping.position.frame == calibench::dataset::mapping::PositionFrame::Base
        );
    }
    assert!(first.measured_orientation.is_some());
    assert!(
        read.iter()
            .filter(|(_, d)| d.measured_orientation.is_some())
            .count()
            >= 2
    );
    assert!(read.iter().any(|(_, d)| d.base_frame));
}
