//! The test cube of ISO 9283 placed in a region, and its cycles measured on the true arm.
//!
//! The cube is the largest with edges parallel to the base frame inside the region's box, centred on it (the
//! region is where the arm is used), shrunk about the centre until the nominal arm reaches its five points
//! at the region's nominal tool orientation (joint limits, self-collision and obstacles as a campaign checks
//! them). Like a region, the cube bounds flange positions. Its points lie on the diagonal plane through the
//! cube's two edges parallel to base y at (−x, −z) and (+x, +z) — corners C1 (−,−,−), C2 (−,+,−), C7 (+,+,+),
//! C8 (+,−,+): P1 at the centre, P2–P5 on the plane's diagonals at 10 % of their length from C1, C2, C7 and
//! C8. A cycle visits P1 → P5 → P4 → P3 → P2, and the cycles are one sequence of the true arm (after an
//! unmeasured visit to P2, so that every P1 is approached from P2), so the direction each joint arrives from
//! and the links' temperature are those of the test.

use nalgebra::{Isometry3, Point3, Vector3};

use super::generator::Generator;
use super::points::{CampaignPoint, Rejections};
use super::region::RegionConfig;
use super::sequence::{REPLAY_ATTEMPT, Stop};
use crate::error::{Error, Result};

/// The standard's names of the five points, in the order of [`IsoCube::flanges`].
pub const POINT_NAMES: [&str; 5] = ["P1", "P2", "P3", "P4", "P5"];

/// One cycle: P1 → P5 → P4 → P3 → P2, as indices into the points.
pub const CYCLE: [usize; 5] = [0, 4, 3, 2, 1];

/// P2–P5 lie this fraction of the diagonal's length from their corners (the standard's 10 % ± 2 %).
pub const CORNER_FRACTION: f64 = 0.1;

/// The corners C1, C2, C7, C8 of the measuring plane, as the signs of their offset from the centre: P2–P5
/// lie near them in this order.
const PLANE_CORNERS: [[f64; 3]; 4] = [
    [-1.0, -1.0, -1.0],
    [-1.0, 1.0, -1.0],
    [1.0, 1.0, 1.0],
    [1.0, -1.0, 1.0],
];

/// A point out of reach shrinks the cube by this factor about its centre, at most [`SHRINK_TRIES`] times
/// (down to 0.9²⁰ ≈ 12 % of the box's smallest side).
const SHRINK: f64 = 0.9;
const SHRINK_TRIES: usize = 20;

/// The cube's points are planned as a ground-truth set with this number: the evaluation's sets are 0–2, so
/// they draw from streams of their own.
const ISO_SET: u64 = 3;

/// The test's repeatability and tracker noise draw with this attempt index: above the replay's
/// ([`REPLAY_ATTEMPT`], and the next one for a probe's orientation noise) and the planned and ground-truth
/// attempts below it. Every method's test draws the same noise at the same visit.
pub const ISO_ATTEMPT: u64 = REPLAY_ATTEMPT + 2;

/// The noise stream of the unmeasured lead-in visit, apart from every cycle's.
const LEAD_IN_STREAM: u64 = u64::MAX;

/// The test cube placed in a region.
#[derive(Clone, Debug)]
pub struct IsoCube {
    pub region: String,
    /// The cube's centre (flange position, base frame, m).
    pub centre: Point3<f64>,
    pub edge_m: f64,
    /// The region box's smallest side: the edge before any shrinking.
    pub largest_edge_m: f64,
    /// The flange poses P1–P5 reach on the nominal model at `q_nominal`: the commanded poses.
    pub flanges: [Isometry3<f64>; 5],
    /// The nominal inverse kinematics of P1–P5 from the region's anchor (rad).
    pub q_nominal: [Vec<f64>; 5],
}

/// P1–P5 of a cube of edge `edge` centred at `centre`, edges parallel to the base axes.
pub fn cube_points(centre: &Point3<f64>, edge: f64) -> [Point3<f64>; 5] {
    let to_point = (1.0 - 2.0 * CORNER_FRACTION) * edge / 2.0;
    let mut points = [*centre; 5];
    for (p, signs) in points[1..].iter_mut().zip(PLANE_CORNERS) {
        *p = centre + Vector3::from(signs) * to_point;
    }
    points
}

impl Generator<'_> {
    /// The test cube of `region` (index `r` in the scenario): the largest the arm reaches (see the module).
    pub fn iso_cube(&self, r: u64, region: &RegionConfig) -> Result<IsoCube> {
        let largest = region.size_m.iter().fold(f64::INFINITY, |a, b| a.min(*b));
        if largest.is_nan() || largest <= 0.0 {
            return Err(Error::Unreachable(format!(
                "region '{}': a side of size_m {:?} is zero, so no test cube fits in its box",
                region.name, region.size_m
            )));
        }
        // One orientation: the region's nominal tool orientation, without its cone and spin.
        let fixed = RegionConfig {
            cone_half_angle_deg: 0.0,
            spin_deg: 0.0,
            ..region.clone()
        };
        let centre = Point3::from(region.center_m);
        let size = Vector3::from(region.size_m);
        let corner = region.min_corner();
        let mut edge = largest;
        let mut last = Rejections::default();
        for _ in 0..SHRINK_TRIES {
            let unit: Vec<[f64; 3]> = cube_points(&centre, edge)
                .iter()
                .map(|p| (p - corner).component_div(&size).into())
                .collect();
            let (points, counts) = self.ground_truth(r, ISO_SET, &fixed, &unit)?;
            if points.len() == unit.len() {
                let flanges = std::array::from_fn(|k| points[k].nominal_flange);
                let q_nominal = std::array::from_fn(|k| points[k].q_cmd.clone());
                return Ok(IsoCube {
                    region: region.name.clone(),
                    centre,
                    edge_m: edge,
                    largest_edge_m: largest,
                    flanges,
                    q_nominal,
                });
            }
            last = counts;
            edge *= SHRINK;
        }
        Err(Error::Unreachable(format!(
            "region '{}': no ISO 9283 test cube whose five points the arm reaches, from an edge of {:.0} mm \
             down to {:.0} mm (at the smallest: {})",
            region.name,
            largest * 1e3,
            edge / SHRINK * 1e3,
            last.describe()
        )))
    }

    /// `cycles` cycles P1 → P5 → P4 → P3 → P2 of the commands `commands` (one per point, P1–P5) measured as
    /// one sequence of the true arm from the campaign's posture, begun `start_s` seconds into its warm-up
    /// (`None`: warm). The arm first goes to P2 unmeasured, so that the first P1 is approached as every other
    /// (from P2). The points come in visit order; visit `c · 5 + i` is point `CYCLE[i]` of cycle `c`. Region
    /// `r` keys the noise, so the test of every method draws the same noise at the same visit.
    pub fn iso_cycles(
        &self,
        r: u64,
        region: &str,
        commands: &[Vec<f64>; 5],
        cycles: usize,
        start_s: Option<f64>,
    ) -> Result<Vec<CampaignPoint>> {
        let stop = |k: usize, stream: u64| Stop {
            region: region.to_string(),
            q_cmd: commands[k].clone(),
            stream: [r, ISO_ATTEMPT, stream],
        };
        let lead_in = stop(CYCLE[CYCLE.len() - 1], LEAD_IN_STREAM);
        let stops: Vec<Stop> = std::iter::once(lead_in)
            .chain((0..cycles).flat_map(|c| {
                CYCLE
                    .iter()
                    .map(move |&k| stop(k, (c * CYCLE.len() + k) as u64))
            }))
            .collect();
        let mut visits = self.measure_sequence_at(&stops, start_s)?;
        visits.remove(0);
        Ok(visits)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_five_points_are_the_standards() {
        let c = Point3::new(0.6, -0.1, 0.4);
        let a = 0.25;
        let p = cube_points(&c, a);
        assert_eq!(p[0], c);
        let diagonal = a * 3f64.sqrt();
        for (k, signs) in PLANE_CORNERS.iter().enumerate() {
            let corner = c + Vector3::from(*signs) * a / 2.0;
            let opposite = c - Vector3::from(*signs) * a / 2.0;
            // 10 % of the diagonal from its corner, on the diagonal to the opposite corner.
            assert!(((p[k + 1] - corner).norm() - 0.1 * diagonal).abs() < 1e-15);
            assert!(((p[k + 1] - opposite).norm() - 0.9 * diagonal).abs() < 1e-15);
        }
        // All five on one plane: through the centre, normal to (1, 0, −1).
        let normal = Vector3::new(1.0, 0.0, -1.0);
        assert!(p.iter().all(|q| (q - c).dot(&normal).abs() < 1e-15));
        // P2–P5 go round the plane's rectangle: consecutive ones an edge or the plane's width apart.
        assert!(((p[1] - p[2]).norm() - 0.8 * a).abs() < 1e-15);
        assert!(((p[2] - p[3]).norm() - 0.8 * a * 2f64.sqrt()).abs() < 1e-15);
    }
}
