//! Joint values a robot can take. A data file's joint columns are checked against the robot's limits (or,
//! when only a saved model is at hand, against what a joint value can plausibly be) before any method sees
//! them: a value far outside drove predictions to overflow (1e300 rad) or silently cost half a metre of
//! accuracy (degrees read as radians).

use crate::error::{Error, Result};
use crate::robot::Chain;
use crate::robot::JointKind;
use crate::robot::plausible::{MAX_ANGLE_RAD, MAX_LENGTH_M};

/// Slack on a limit for the rounding of a file: joint values are written to 5–6 decimals.
pub const LIMIT_SLACK: f64 = 1e-4;

/// The joint values a data file may hold, with the words that say where they come from.
#[derive(Clone, Debug)]
pub struct JointRange {
    pub names: Vec<String>,
    pub lower: Vec<f64>,
    pub upper: Vec<f64>,
    pub prismatic: Vec<bool>,
    /// Where the bounds come from, for the message ("the limits of robots/ur10.urdf").
    pub source: String,
}

impl JointRange {
    /// The robot's own limits (a continuous joint has none); `robot` names its file.
    pub fn of_chain(chain: &Chain, robot: &str) -> JointRange {
        JointRange {
            names: chain.joint_names(),
            lower: chain.lower_limits(),
            upper: chain.upper_limits(),
            prismatic: chain
                .joints
                .iter()
                .map(|j| j.kind == JointKind::Prismatic)
                .collect(),
            source: format!("the limits of {robot}"),
        }
    }

    /// What a joint value can plausibly be when the limits are unknown (a saved model keeps only the DH
    /// table): within ±3π rad for a revolute joint, ±100 m for a prismatic one (`robot::plausible`).
    pub fn plausible(names: &[String], prismatic: &[bool]) -> JointRange {
        let bound = |p: &bool| if *p { MAX_LENGTH_M } else { MAX_ANGLE_RAD };
        JointRange {
            names: names.to_vec(),
            lower: prismatic.iter().map(|p| -bound(p)).collect(),
            upper: prismatic.iter().map(bound).collect(),
            prismatic: prismatic.to_vec(),
            source: "the plausible range of a joint value".into(),
        }
    }

    /// Every configuration within range, or one error naming the file (`origin`), the point (its id and
    /// its place among the data rows) and the joint. When most revolute values exceed 2π the file is in
    /// degrees, and the message says so.
    pub fn check(&self, origin: &str, ids: &[String], q: &[Vec<f64>]) -> Result<()> {
        let err = |message: String| Error::Data {
            origin: origin.to_string(),
            message,
        };
        let (mut revolute, mut beyond_turn) = (0usize, 0usize);
        for row in q {
            for (v, p) in row.iter().zip(&self.prismatic) {
                if !p {
                    revolute += 1;
                    beyond_turn += usize::from(v.abs() > std::f64::consts::TAU + LIMIT_SLACK);
                }
            }
        }
        let degrees = beyond_turn * 2 > revolute;
        for (i, row) in q.iter().enumerate() {
            for (k, &v) in row.iter().enumerate() {
                let (lo, hi) = (self.lower[k], self.upper[k]);
                if v >= lo - LIMIT_SLACK && v <= hi + LIMIT_SLACK {
                    continue;
                }
                let unit = if self.prismatic[k] { "m" } else { "rad" };
                let id = ids.get(i).map_or_else(|| (i + 2).to_string(), Clone::clone);
                let hint = if degrees {
                    format!(
                        "; {beyond_turn} of {revolute} joint values exceed 2π: degrees? The file must hold \
                         radians (a mapping reads degrees with [joints] unit = \"deg\")"
                    )
                } else {
                    String::new()
                };
                return Err(err(format!(
                    "point '{id}' (data row {}), column {}: {} {unit} is outside {} [{}, {}]{hint}",
                    i + 1,
                    self.names[k],
                    short(v),
                    self.source,
                    short(lo),
                    short(hi),
                )));
            }
        }
        Ok(())
    }
}

/// A number for a message: plain when moderate, in exponent form when huge or tiny (1e300 stays short).
pub fn short(v: f64) -> String {
    if v == 0.0 || (1e-4..1e6).contains(&v.abs()) {
        format!("{}", (v * 1e6).round() / 1e6)
    } else {
        format!("{v:.4e}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn range() -> JointRange {
        JointRange {
            names: vec!["a".into(), "b".into()],
            lower: vec![-3.0, -1.0],
            upper: vec![3.0, 1.0],
            prismatic: vec![false, true],
            source: "the limits of r.urdf".into(),
        }
    }

    #[test]
    fn within_and_at_the_limits_passes() {
        let q = vec![vec![3.0, -1.0], vec![-3.00005, 0.5]];
        range().check("f.csv", &[], &q).unwrap();
    }

    #[test]
    fn outside_names_the_point_joint_and_bound() {
        let q = vec![vec![0.0, 0.0], vec![1e300, 0.0]];
        let e = range()
            .check("f.csv", &["p1".into(), "p2".into()], &q)
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "data f.csv: point 'p2' (data row 2), column a: 1.0000e300 rad is outside the limits of r.urdf [-3, 3]"
        );
    }

    #[test]
    fn degrees_are_named_as_such() {
        let q = vec![vec![90.0, 0.0], vec![-45.0, 0.0], vec![1.0, 0.0]];
        let e = range().check("f.csv", &[], &q).unwrap_err().to_string();
        assert!(e.contains("2 of 3 joint values exceed 2π: degrees?"), "{e}");
    }
}
