//! ISO 9283's pose accuracy and repeatability on measured data that repeats the points of test cubes (the
//! IPA UR10's series D measures cubes of 400, 250 and 100 mm, each as its centre then its eight corners, the
//! centres again for every size and one cube three times).
//!
//! The rows are grouped by commanded pose — the nominal flange pose of their joints, equal within
//! [`POSE_TOL_M`] and [`POSE_TOL_RAD`] (a real controller logs a repeated goal a few hundredths of a
//! millimetre apart) — and a cube is a row followed by eight rows at the corners of a cube centred on it.
//! At every point of a cube, each visit's error is the measured position (through a model's registration of
//! the file) minus what the model predicts at its joints, and AP and RP follow from the errors of all the
//! visits of that commanded pose ([`super::pose_accuracy`]):
//!
//! - **before** calibration, the nominal model: the command is the controller's, so AP is the measured
//!   barycentre's distance from the commanded position;
//! - **after**, the calibrated model: a user commanding through it sends the joints at which it predicts the
//!   target, so AP is the barycentre's distance from its prediction at the logged joints — its prediction
//!   error averaged over the repeats;
//! - RP is the arm's and is taken from the nominal model's errors (the two models' differ by micrometres).

use std::collections::HashMap;
use std::fmt::Write as _;

use nalgebra::{Isometry3, Point3, Vector3};
use serde::Serialize;

use super::pose_accuracy::{MIN_ATTEMPTS_FOR_RP, PoseAccuracyMm, pose_accuracy};
use super::transfer::predicted_flanges;
use crate::calib::method::Fitted;
use crate::calib::tracker_frame::Registration;
use crate::dataset::Dataset;
use crate::error::{Error, Result};

/// Rows whose commanded flange positions lie this close (m) are one commanded pose: series D logs the goal
/// of a repeated point up to 0.06 mm apart, and its nearest distinct goals are 0.9 mm apart.
pub const POSE_TOL_M: f64 = 2.5e-4;
/// … and whose commanded flange orientations lie this close (rad).
pub const POSE_TOL_RAD: f64 = 1e-3;
/// A cube's corners lie at ± half its edge from its centre along each base axis within this (m): the
/// nominal model puts the logged joints of a controller's calibrated commands up to a few millimetres off.
pub const CUBE_TOL_M: f64 = 2e-3;

/// A model and the registration the file is seen through.
pub struct Side<'a> {
    pub model: &'a dyn Fitted,
    pub registration: &'a Registration,
}

/// `report.json`'s `iso9283`: the cubes found, each point's AP before and after calibration and its RP.
#[derive(Clone, Debug, Serialize)]
pub struct CubesReport {
    pub data: String,
    /// The calibrated model ("after").
    pub method: String,
    pub pose_tolerance_mm: f64,
    pub pose_tolerance_rad: f64,
    /// Distinct commanded poses in the file, and those visited more than once.
    pub poses: usize,
    pub repeated_poses: usize,
    pub cubes: Vec<Cube>,
}

/// One cube: every block of rows that measured it, and its nine points.
#[derive(Clone, Debug, Serialize)]
pub struct Cube {
    /// The commanded measured point at its centre (mm, base frame, nominal model).
    pub centre_mm: [f64; 3],
    pub edge_mm: f64,
    /// The `point_id` of each block's first row (its centre).
    pub blocks: Vec<String>,
    pub points: Vec<CubePoint>,
}

/// One point of a cube, over every visit of its commanded pose in the file.
#[derive(Clone, Debug, Serialize)]
pub struct CubePoint {
    /// `centre`, or the corner's side of the centre along x, y and z (`+-+`).
    pub role: String,
    pub point_ids: Vec<String>,
    /// RP (and the orientation's) from the nominal model's errors.
    pub before: PoseAccuracyMm,
    pub after: PoseAccuracyMm,
}

/// Each row's error under one model: position (m) and, where measured, orientation (rotation vector, rad).
struct Errors {
    positions: Vec<Vector3<f64>>,
    rotations: Vec<Option<Vector3<f64>>>,
}

fn errors(data: &Dataset, side: &Side) -> Result<Errors> {
    let observations = side.registration.observe(data)?;
    let flanges = predicted_flanges(side.model, data)?;
    let mounting = side.registration.frame.mounting;
    let positions = observations
        .iter()
        .zip(&flanges)
        .map(|(o, f)| o.position - f * mounting)
        .collect();
    let rotations = observations
        .iter()
        .zip(&flanges)
        .map(|(o, f)| {
            o.orientation
                .map(|r| (r * f.rotation.inverse()).scaled_axis())
        })
        .collect();
    Ok(Errors {
        positions,
        rotations,
    })
}

/// The cubes of `data` and AP and RP at their points, before (`before`: the nominal model) and after
/// (`after`: the calibrated one) calibration; `None` when the file holds no cube or repeats none of their
/// points.
pub fn cubes(data: &Dataset, before: &Side, after: &Side) -> Result<Option<CubesReport>> {
    let commanded: Vec<Isometry3<f64>> = data
        .q
        .iter()
        .map(|q| before.model.dh().flange_pose(q))
        .collect();
    let pose = group_poses(&commanded);
    let poses = pose.iter().max().map_or(0, |m| m + 1);
    let mut visits = vec![Vec::new(); poses];
    for (row, &p) in pose.iter().enumerate() {
        visits[p].push(row);
    }
    let blocks = find_blocks(&commanded);
    let repeated = |row: usize| visits[pose[row]].len() > 1;
    if !blocks.iter().any(|b| (b.start..b.start + 9).any(repeated)) {
        return Ok(None);
    }
    let (e_before, e_after) = (errors(data, before)?, errors(data, after)?);
    let stats = |e: &Errors, rows: &[usize]| -> Result<PoseAccuracyMm> {
        let positions: Vec<Vector3<f64>> = rows.iter().map(|&r| e.positions[r]).collect();
        let rotations: Option<Vec<Vector3<f64>>> = rows.iter().map(|&r| e.rotations[r]).collect();
        pose_accuracy(&positions, rotations.as_deref())
            .map(|a| a.in_mm())
            .ok_or_else(|| Error::Data {
                origin: data.origin.clone(),
                message: format!(
                    "row {}: an error that is not a finite number",
                    data.point_ids[rows[0]]
                ),
            })
    };
    let mounting = before.registration.frame.mounting;
    let mut cubes: Vec<(usize, Cube)> = Vec::new();
    for block in &blocks {
        let centre_pose = pose[block.start];
        let id = data.point_ids[block.start].clone();
        if let Some((_, cube)) = cubes.iter_mut().find(|(p, c)| {
            *p == centre_pose && (c.edge_mm - block.edge_m * 1e3).abs() < CUBE_TOL_M * 1e3
        }) {
            cube.blocks.push(id);
            continue;
        }
        let mut points = Vec::new();
        for (offset, role) in block.roles() {
            let rows = &visits[pose[block.start + offset]];
            points.push(CubePoint {
                role,
                point_ids: rows.iter().map(|&r| data.point_ids[r].clone()).collect(),
                before: stats(&e_before, rows)?,
                after: stats(&e_after, rows)?,
            });
        }
        let c = commanded[block.start] * mounting;
        cubes.push((
            centre_pose,
            Cube {
                centre_mm: [c.x, c.y, c.z].map(|v| v * 1e3),
                edge_mm: block.edge_m * 1e3,
                blocks: vec![id],
                points,
            },
        ));
    }
    Ok(Some(CubesReport {
        data: data.origin.clone(),
        method: after.model.method().to_string(),
        pose_tolerance_mm: POSE_TOL_M * 1e3,
        pose_tolerance_rad: POSE_TOL_RAD,
        poses,
        repeated_poses: visits.iter().filter(|v| v.len() > 1).count(),
        cubes: cubes.into_iter().map(|(_, c)| c).collect(),
    }))
}

/// The commanded pose of each row, numbered in the order of their first rows: a row joins the earliest pose
/// whose first row lies within the tolerances, found through a grid of cells of the position tolerance.
fn group_poses(commanded: &[Isometry3<f64>]) -> Vec<usize> {
    let cell = |f: &Isometry3<f64>| {
        f.translation
            .vector
            .map(|v| (v / POSE_TOL_M).floor() as i64)
    };
    let mut grid: HashMap<[i64; 3], Vec<usize>> = HashMap::new();
    let mut first_rows: Vec<usize> = Vec::new();
    let mut pose = Vec::with_capacity(commanded.len());
    for (row, f) in commanded.iter().enumerate() {
        let c = cell(f);
        let mut found: Option<usize> = None;
        for d in 0..27i64 {
            let key = [c[0] + d % 3 - 1, c[1] + (d / 3) % 3 - 1, c[2] + d / 9 - 1];
            for &p in grid.get(&key).into_iter().flatten() {
                let g = &commanded[first_rows[p]];
                let close = (g.translation.vector - f.translation.vector).norm() <= POSE_TOL_M
                    && g.rotation.angle_to(&f.rotation) <= POSE_TOL_RAD;
                if close && found.is_none_or(|q| p < q) {
                    found = Some(p);
                }
            }
        }
        let p = found.unwrap_or_else(|| {
            first_rows.push(row);
            grid.entry([c[0], c[1], c[2]])
                .or_default()
                .push(first_rows.len() - 1);
            first_rows.len() - 1
        });
        pose.push(p);
    }
    pose
}

/// Nine rows that measure a cube: the centre at `start`, then its eight corners.
struct Block {
    start: usize,
    edge_m: f64,
    /// Each corner's side of the centre along x, y, z, in row order.
    signs: [[bool; 3]; 8],
}

impl Block {
    /// Each point's row offset from the block's start and its role.
    fn roles(&self) -> Vec<(usize, String)> {
        let mut roles = vec![(0, "centre".to_string())];
        for (j, s) in self.signs.iter().enumerate() {
            let role: String = s.iter().map(|&p| if p { '+' } else { '-' }).collect();
            roles.push((j + 1, role));
        }
        roles
    }
}

/// The blocks of rows that measure a cube, in file order, none overlapping.
fn find_blocks(commanded: &[Isometry3<f64>]) -> Vec<Block> {
    let mut blocks = Vec::new();
    let mut start = 0;
    while start + 9 <= commanded.len() {
        match block_at(commanded, start) {
            Some(block) => {
                blocks.push(block);
                start += 9;
            }
            None => start += 1,
        }
    }
    blocks
}

/// Whether rows `start + 1 ..= start + 8` are the corners of a cube centred on row `start`: each offset
/// ±h along every axis within [`CUBE_TOL_M`], all eight sign patterns, h above the tolerance.
fn block_at(commanded: &[Isometry3<f64>], start: usize) -> Option<Block> {
    let centre = Point3::from(commanded[start].translation.vector);
    let offsets: Vec<Vector3<f64>> = commanded[start + 1..start + 9]
        .iter()
        .map(|f| Point3::from(f.translation.vector) - centre)
        .collect();
    let h = offsets.iter().map(|d| d.abs().sum()).sum::<f64>() / 24.0;
    if h.is_nan()
        || h <= CUBE_TOL_M
        || offsets
            .iter()
            .any(|d| d.iter().any(|v| (v.abs() - h).abs() > CUBE_TOL_M))
    {
        return None;
    }
    let signs: [[bool; 3]; 8] = std::array::from_fn(|j| [0, 1, 2].map(|k| offsets[j][k] > 0.0));
    let mut distinct = signs.to_vec();
    distinct.sort_unstable();
    distinct.dedup();
    (distinct.len() == 8).then_some(Block {
        start,
        edge_m: 2.0 * h,
        signs,
    })
}

impl CubesReport {
    /// The table `calibrate` prints: per cube its centre, edge, blocks and visits, AP before and after (mean
    /// and max over its nine points) and the largest RP; the orientation's AP where the data measures it.
    pub fn table(&self) -> String {
        let with_orientation = self
            .cubes
            .iter()
            .flat_map(|c| &c.points)
            .any(|p| p.before.ap_abc_rad.is_some());
        let mut out = format!(
            "ISO 9283 pose accuracy on the test cubes of {} (mm): {} cubes, {} of {} commanded poses visited more \
             than once (rows within {} mm and {} rad are one pose); AP at a point from all its visits (a point \
             visited once: its error), mean and max over the cube's nine points; RP = l̄ + 3·S_l, the largest \
             over the points visited at least {MIN_ATTEMPTS_FOR_RP} times\n",
            self.data,
            self.cubes.len(),
            self.repeated_poses,
            self.poses,
            self.pose_tolerance_mm,
            self.pose_tolerance_rad
        );
        let _ = write!(
            out,
            "  {:<28} {:>7} {:>6} {:>6} | {:>17} | {:>17} | {:>7}",
            "centre (mm, base frame)",
            "edge",
            "blocks",
            "visits",
            "AP nominal",
            format!("AP {}", self.method),
            "RP"
        );
        if with_orientation {
            let _ = write!(out, " | {:>19}", "AP orientation mrad");
        }
        out.push('\n');
        for cube in &self.cubes {
            out += &cube.row(with_orientation);
        }
        out
    }
}

impl Cube {
    fn row(&self, with_orientation: bool) -> String {
        let mean_max = |v: Vec<f64>| {
            let max = v.iter().fold(0.0, |a: f64, b| a.max(*b));
            (v.iter().sum::<f64>() / v.len().max(1) as f64, max)
        };
        let (b_mean, b_max) = mean_max(self.points.iter().map(|p| p.before.ap_mm).collect());
        let (a_mean, a_max) = mean_max(self.points.iter().map(|p| p.after.ap_mm).collect());
        let rp = self
            .points
            .iter()
            .filter_map(|p| p.before.rp_mm)
            .reduce(f64::max);
        let visits = self.points.iter().map(|p| p.point_ids.len());
        let (fewest, most) = (visits.clone().min().unwrap_or(0), visits.max().unwrap_or(0));
        let c = self.centre_mm;
        let mut row = format!(
            "  [{:>7.1}, {:>7.1}, {:>7.1}]  {:>7.1} {:>6} {:>6} | {:>8.4} {:>8.4} | {:>8.4} {:>8.4} | {:>7}",
            c[0],
            c[1],
            c[2],
            self.edge_mm,
            self.blocks.len(),
            if fewest == most {
                most.to_string()
            } else {
                format!("{fewest}-{most}")
            },
            b_mean,
            b_max,
            a_mean,
            a_max,
            rp.map_or("-".to_string(), |r| format!("{r:.4}"))
        );
        if with_orientation {
            let norm =
                |p: &PoseAccuracyMm| p.ap_abc_rad.map_or(0.0, |v| Vector3::from(v).norm() * 1e3);
            let (_, b) = mean_max(self.points.iter().map(|p| norm(&p.before)).collect());
            let (_, a) = mean_max(self.points.iter().map(|p| norm(&p.after)).collect());
            let _ = write!(row, " | max {b:>6.3} → {a:>6.3}");
        }
        row.push('\n');
        row
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};

    fn at(x: f64, y: f64, z: f64) -> Isometry3<f64> {
        Isometry3::from_parts(Translation3::new(x, y, z), UnitQuaternion::identity())
    }

    #[test]
    fn poses_group_within_the_tolerance_and_cubes_are_found() {
        let h = 0.05;
        let mut rows = vec![at(0.5, 0.0, 0.4)];
        for s in 0..8 {
            let sign = |b: usize| if s & b != 0 { h } else { -h };
            rows.push(at(0.5 + sign(1), sign(2), 0.4 + sign(4)));
        }
        // The same cube again, 0.1 mm off, then its centre 1 mm off (another pose), a stray row.
        let again: Vec<_> = rows
            .iter()
            .map(|f| Translation3::new(1e-4, 0.0, 0.0) * f)
            .collect();
        rows.extend(again);
        rows.push(at(0.501, 0.0, 0.4));
        rows.push(at(0.2, 0.2, 0.2));
        let pose = group_poses(&rows);
        assert_eq!(&pose[..9], &(0..9).collect::<Vec<_>>()[..]);
        assert_eq!(&pose[9..18], &pose[..9], "0.1 mm apart: the same poses");
        assert_eq!(pose[18], 9, "1 mm apart: a new pose");
        assert_eq!(pose[19], 10);
        let blocks = find_blocks(&rows);
        assert_eq!(blocks.iter().map(|b| b.start).collect::<Vec<_>>(), [0, 9]);
        assert!((blocks[0].edge_m - 2.0 * h).abs() < 1e-12);
        // A corner 3 mm off its place is no cube.
        rows[3] = Translation3::new(0.0, 3e-3, 0.0) * rows[3];
        assert_eq!(find_blocks(&rows[..9]).len(), 0);
    }
}
