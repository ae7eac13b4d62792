//! The campaign as files: `measurements.csv` holds what a real campaign yields and nothing more;
//! `truth.csv` holds what only the simulation knows, for the evaluation.
//!
//! Lengths in metres, angles in radians; floats are written in Rust's shortest round-trip form, so a file
//! read back gives the same numbers bit for bit and the same campaign gives the same bytes.

use nalgebra::{Isometry3, Point3};

use crate::campaign::Campaign;
use crate::dataset::{
    ACCELERATION_PREFIX, Dataset, FLANGE_COLUMNS, TEMPERATURE_COLUMN, TIME_COLUMN, VELOCITY_PREFIX,
};
use crate::error::{Error, Result};
use crate::output;

fn xyz_columns(prefix: &str, count: usize) -> Vec<String> {
    (1..=count)
        .flat_map(|k| ["x", "y", "z"].map(|a| format!("{prefix}{a}{k}")))
        .collect()
}

/// One csv file's records, cell by cell: numbers as `Display` writes them ([`output::display`], through ryu
/// where that is the same text), without a `String` per cell; the same bytes as writing each record's cells
/// as strings (csv's `write_record` writes field by field, then the terminator, as here).
struct Records {
    w: csv::Writer<Vec<u8>>,
    digits: ryu::Buffer,
    fallback: String,
}

impl Records {
    fn new(header: &[String]) -> Result<Records> {
        let mut w = csv::Writer::from_writer(Vec::new());
        w.write_record(header).map_err(csv_err)?;
        Ok(Records {
            w,
            digits: ryu::Buffer::new(),
            fallback: String::new(),
        })
    }

    fn text(&mut self, cell: &str) -> Result<()> {
        self.w.write_field(cell).map_err(csv_err)
    }

    fn number(&mut self, value: f64) -> Result<()> {
        let text = output::display(value, &mut self.digits, &mut self.fallback);
        self.w.write_field(text).map_err(csv_err)
    }

    fn numbers(&mut self, values: impl IntoIterator<Item = f64>) -> Result<()> {
        values.into_iter().try_for_each(|v| self.number(v))
    }

    fn pose(&mut self, pose: &Isometry3<f64>) -> Result<()> {
        let t = pose.translation.vector;
        let q = pose.rotation.quaternion();
        self.numbers([t.x, t.y, t.z, q.w, q.i, q.j, q.k])
    }

    fn points(&mut self, points: &[Point3<f64>]) -> Result<()> {
        self.numbers(points.iter().flat_map(|p| [p.x, p.y, p.z]))
    }

    fn end_record(&mut self) -> Result<()> {
        self.w.write_record(None::<&[u8]>).map_err(csv_err)
    }

    fn into_bytes(self) -> Result<Vec<u8>> {
        self.w.into_inner().map_err(|e| Error::Data {
            origin: "csv writer".into(),
            message: e.to_string(),
        })
    }
}

fn csv_err(e: csv::Error) -> Error {
    Error::Data {
        origin: "csv writer".into(),
        message: e.to_string(),
    }
}

fn reflector_count(campaign: &Campaign) -> usize {
    campaign.points.first().map_or(1, |p| p.measured.len())
}

/// `point_id, region, <joint names>, flange_x…z, flange_qw…qz, nom_x1…, x1…` (tracker frame), and
/// `temperature` (°C) when the true robot has a thermal profile. The rows are in the order the arm visited the
/// points (`point_id` is the place in that sequence).
pub fn measurements_csv(campaign: &Campaign) -> Result<Vec<u8>> {
    let k = reflector_count(campaign);
    let mut header: Vec<String> = vec!["point_id".into(), "region".into()];
    header.extend(campaign.joint_names.iter().cloned());
    header.extend(FLANGE_COLUMNS.map(String::from));
    header.extend(xyz_columns("nom_", k));
    header.extend(xyz_columns("", k));
    let temperature = campaign.points.iter().any(|p| p.temperature.is_some());
    if temperature {
        header.push(TEMPERATURE_COLUMN.into());
    }
    let time = campaign.points.iter().any(|p| p.time.is_some());
    if time {
        header.push(TIME_COLUMN.into());
    }
    let rates = campaign.points.iter().any(|p| p.rates.is_some());
    if rates {
        for prefix in [VELOCITY_PREFIX, ACCELERATION_PREFIX] {
            header.extend(campaign.joint_names.iter().map(|j| format!("{prefix}{j}")));
        }
    }
    let dof = campaign.joint_names.len();
    let mut out = Records::new(&header)?;
    for p in &campaign.points {
        out.text(&p.id.to_string())?;
        out.text(&p.region)?;
        out.numbers(p.q_cmd.iter().copied())?;
        out.pose(&p.nominal_flange)?;
        out.points(&p.nominal_reflectors)?;
        out.points(&p.measured)?;
        if temperature {
            match p.temperature {
                Some(t) => out.number(t)?,
                None => out.text("")?,
            }
        }
        if time {
            match p.time {
                Some(t) => out.number(t)?,
                None => out.text("")?,
            }
        }
        if rates {
            match &p.rates {
                Some(r) => out.numbers(r.qd.iter().chain(&r.qdd).copied())?,
                None => (0..2 * dof).try_for_each(|_| out.text(""))?,
            }
        }
        out.end_record()?;
    }
    out.into_bytes()
}

/// `point_id, true_x1…, trk_x1…, true_flange_x…qz, true_<joint names>`: the pose the true arm reached (base
/// frame), and the true reflector positions in the tracker frame without tracker noise (`trk_*`).
pub fn truth_csv(campaign: &Campaign) -> Result<Vec<u8>> {
    let k = reflector_count(campaign);
    let mut header: Vec<String> = vec!["point_id".into()];
    header.extend(xyz_columns("true_", k));
    header.extend(xyz_columns("trk_", k));
    header.extend(
        [
            "true_flange_x",
            "true_flange_y",
            "true_flange_z",
            "true_flange_qw",
            "true_flange_qx",
            "true_flange_qy",
            "true_flange_qz",
        ]
        .map(String::from),
    );
    header.extend(campaign.joint_names.iter().map(|n| format!("true_{n}")));
    let mut out = Records::new(&header)?;
    for p in &campaign.points {
        out.text(&p.id.to_string())?;
        out.points(&p.true_reflectors)?;
        out.points(&p.true_in_tracker)?;
        out.pose(&p.true_flange)?;
        out.numbers(p.q_true.iter().copied())?;
        out.end_record()?;
    }
    out.into_bytes()
}

/// The campaign as a method sees it: `measurements.csv` read back, so that nothing but what a real campaign
/// yields reaches a method. `origin` names it in messages.
pub fn as_dataset(campaign: &Campaign, origin: &str) -> Result<Dataset> {
    let csv = measurements_csv(campaign)?;
    Dataset::from_reader(csv.as_slice(), origin, &campaign.joint_names)
}

#[cfg(test)]
mod tests {
    use nalgebra::{Translation3, UnitQuaternion};

    use super::*;
    use crate::campaign::CampaignPoint;
    use crate::robot::inverse_dynamics::JointRates;

    /// The records as every cell's `to_string()` written by csv's `write_record`: what the files were before
    /// [`Records`] wrote them cell by cell.
    fn by_strings(header: &[String], rows: &[Vec<String>]) -> Vec<u8> {
        let mut w = csv::Writer::from_writer(Vec::new());
        w.write_record(header).unwrap();
        for row in rows {
            w.write_record(row).unwrap();
        }
        w.into_inner().unwrap()
    }

    /// `bytes` (a file with its header) equal to its header and `rows` written by [`by_strings`].
    fn same_as_strings(bytes: Vec<u8>, rows: &[Vec<String>]) {
        let text = String::from_utf8(bytes).unwrap();
        let header: Vec<String> = text
            .lines()
            .next()
            .unwrap()
            .split(',')
            .map(String::from)
            .collect();
        assert_eq!(text.as_bytes(), by_strings(&header, rows));
    }

    /// Both files, byte for byte as before, on values `Display` and ryu write differently (exponents, whole
    /// numbers, signed zeros, halfway ties, not-a-number) and with every optional column, present and absent.
    #[test]
    fn the_files_are_the_cells_display_text() {
        let awkward = [
            1e-7,
            -0.0,
            1e16,
            3.0,
            -691780342843863.3,
            0.1,
            f64::NAN,
            1.0 / 3.0,
            -2.5e-5,
        ];
        let v = |i: usize| awkward[i % awkward.len()];
        let point = |id: usize, optional: bool| {
            let pose = Isometry3::from_parts(
                Translation3::new(v(id), v(id + 1), v(id + 2)),
                UnitQuaternion::from_euler_angles(0.3, 0.2, -0.1),
            );
            let pts = |k: usize| vec![Point3::new(v(k), v(k + 4), v(k + 5))];
            CampaignPoint {
                id,
                region: "a,b".into(),
                q_cmd: (0..3).map(|j| v(id + j)).collect(),
                nominal_flange: pose,
                nominal_reflectors: pts(id + 1),
                measured: pts(id + 2),
                true_flange: pose,
                true_reflectors: pts(id + 3),
                true_in_tracker: pts(id + 4),
                q_true: (0..3).map(|j| v(id + j + 5)).collect(),
                temperature: optional.then(|| v(id + 6)),
                time: optional.then(|| v(id + 7)),
                rates: optional.then(|| JointRates {
                    qd: (0..3).map(|j| v(id + j)).collect(),
                    qdd: (0..3).map(|j| v(id + j + 2)).collect(),
                }),
            }
        };
        let campaign = Campaign {
            joint_names: vec!["j1".into(), "j2".into(), "j3".into()],
            points: (0..awkward.len()).map(|i| point(i, i % 3 != 0)).collect(),
            rejections: Default::default(),
        };
        let s = |x: f64| x.to_string();
        let pose = |p: &Isometry3<f64>| {
            let (t, q) = (p.translation.vector, p.rotation.quaternion());
            [t.x, t.y, t.z, q.w, q.i, q.j, q.k].map(s).to_vec()
        };
        let pts = |ps: &[Point3<f64>]| -> Vec<String> {
            ps.iter().flat_map(|p| [p.x, p.y, p.z].map(s)).collect()
        };
        let opt = |x: Option<f64>| x.map_or(String::new(), s);
        let measured: Vec<Vec<String>> = campaign
            .points
            .iter()
            .map(|p| {
                let mut row = vec![p.id.to_string(), p.region.clone()];
                row.extend(p.q_cmd.iter().map(|&q| s(q)));
                row.extend(pose(&p.nominal_flange));
                row.extend(pts(&p.nominal_reflectors));
                row.extend(pts(&p.measured));
                row.extend([opt(p.temperature), opt(p.time)]);
                match &p.rates {
                    Some(r) => row.extend(r.qd.iter().chain(&r.qdd).map(|&x| s(x))),
                    None => row.extend(std::iter::repeat_n(String::new(), 6)),
                }
                row
            })
            .collect();
        same_as_strings(measurements_csv(&campaign).unwrap(), &measured);
        let truth: Vec<Vec<String>> = campaign
            .points
            .iter()
            .map(|p| {
                let mut row = vec![p.id.to_string()];
                row.extend(pts(&p.true_reflectors));
                row.extend(pts(&p.true_in_tracker));
                row.extend(pose(&p.true_flange));
                row.extend(p.q_true.iter().map(|&q| s(q)));
                row
            })
            .collect();
        same_as_strings(truth_csv(&campaign).unwrap(), &truth);
    }
}
