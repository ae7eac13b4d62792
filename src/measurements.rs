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

fn xyz_columns(prefix: &str, count: usize) -> Vec<String> {
    (1..=count)
        .flat_map(|k| ["x", "y", "z"].map(|a| format!("{prefix}{a}{k}")))
        .collect()
}

fn pose_cells(pose: &Isometry3<f64>) -> [String; 7] {
    let t = pose.translation.vector;
    let q = pose.rotation.quaternion();
    [t.x, t.y, t.z, q.w, q.i, q.j, q.k].map(|v| v.to_string())
}

fn point_cells(points: &[Point3<f64>]) -> impl Iterator<Item = String> + '_ {
    points
        .iter()
        .flat_map(|p| [p.x, p.y, p.z].map(|v| v.to_string()))
}

fn csv_bytes(header: Vec<String>, rows: impl Iterator<Item = Vec<String>>) -> Result<Vec<u8>> {
    let err = |e: csv::Error| Error::Data {
        origin: "csv writer".into(),
        message: e.to_string(),
    };
    let mut w = csv::Writer::from_writer(Vec::new());
    w.write_record(&header).map_err(err)?;
    for row in rows {
        w.write_record(&row).map_err(err)?;
    }
    w.into_inner().map_err(|e| Error::Data {
        origin: "csv writer".into(),
        message: e.to_string(),
    })
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
    let rows = campaign.points.iter().map(move |p| {
        let mut row = vec![p.id.to_string(), p.region.clone()];
        row.extend(p.q_cmd.iter().map(|q| q.to_string()));
        row.extend(pose_cells(&p.nominal_flange));
        row.extend(point_cells(&p.nominal_reflectors));
        row.extend(point_cells(&p.measured));
        if temperature {
            row.push(p.temperature.map_or(String::new(), |t| t.to_string()));
        }
        if time {
            row.push(p.time.map_or(String::new(), |t| t.to_string()));
        }
        if rates {
            match &p.rates {
                Some(r) => row.extend(r.qd.iter().chain(&r.qdd).map(|v| v.to_string())),
                None => row.extend(std::iter::repeat_n(String::new(), 2 * dof)),
            }
        }
        row
    });
    csv_bytes(header, rows)
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
    let rows = campaign.points.iter().map(|p| {
        let mut row = vec![p.id.to_string()];
        row.extend(point_cells(&p.true_reflectors));
        row.extend(point_cells(&p.true_in_tracker));
        row.extend(pose_cells(&p.true_flange));
        row.extend(p.q_true.iter().map(|q| q.to_string()));
        row
    });
    csv_bytes(header, rows)
}

/// The campaign as a method sees it: `measurements.csv` read back, so that nothing but what a real campaign
/// yields reaches a method. `origin` names it in messages.
pub fn as_dataset(campaign: &Campaign, origin: &str) -> Result<Dataset> {
    let csv = measurements_csv(campaign)?;
    Dataset::from_reader(csv.as_slice(), origin, &campaign.joint_names)
}
