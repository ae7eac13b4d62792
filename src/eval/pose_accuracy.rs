//! ISO 9283's pose accuracy and pose repeatability of one commanded pose from its attempts (the standard's
//! §7.2, as its published summaries give it; `docs/iso9283.md` says which parts the harness follows):
//!
//! - **AP** = ‖barycentre of the attained positions − commanded position‖, with its components x̄ − x_c,
//!   ȳ − y_c, z̄ − z_c;
//! - **RP** = l̄ + 3·S_l, where l_j is attempt j's distance from the barycentre, l̄ their mean and
//!   S_l = √(Σ (l_j − l̄)² / (n − 1));
//! - orientation: AP_a, AP_b, AP_c the mean deviation about the base x, y and z axes, RP_a, RP_b, RP_c = 3·S of
//!   each (the standard's ±3·S).
//!
//! An attempt enters as its deviation from the commanded pose (attained − commanded), so the commanded pose may
//! differ slightly from attempt to attempt, as the logged joints of a real file's repeats do.

use nalgebra::Vector3;
use serde::Serialize;

/// RP needs the spread of the distances: with two attempts both lie at half their separation and S_l is 0.
pub const MIN_ATTEMPTS_FOR_RP: usize = 3;

/// AP and RP of one commanded pose (SI units: m, rad).
#[derive(Clone, Debug, PartialEq)]
pub struct PoseAccuracy {
    pub attempts: usize,
    /// Barycentre minus commanded position (m, base frame): AP's components.
    pub offset: Vector3<f64>,
    /// AP (m).
    pub ap: f64,
    /// RP (m); `None` below [`MIN_ATTEMPTS_FOR_RP`] attempts.
    pub rp: Option<f64>,
    /// Where the orientation is measured.
    pub orientation: Option<OrientationAccuracy>,
}

/// The orientation part: per base axis x, y, z (the standard's a, b, c), rad.
#[derive(Clone, Debug, PartialEq)]
pub struct OrientationAccuracy {
    /// AP_a, AP_b, AP_c: the mean deviation about each axis.
    pub ap: [f64; 3],
    /// RP_a, RP_b, RP_c: 3·S of each deviation; `None` below [`MIN_ATTEMPTS_FOR_RP`] attempts.
    pub rp: Option<[f64; 3]>,
}

/// [`PoseAccuracy`] in a report's units: millimetres and radians.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct PoseAccuracyMm {
    pub attempts: usize,
    pub ap_mm: f64,
    pub ap_xyz_mm: [f64; 3],
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rp_mm: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ap_abc_rad: Option<[f64; 3]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rp_abc_rad: Option<[f64; 3]>,
}

/// AP and RP from each attempt's position deviation `positions` (attained − commanded, m) and, where the
/// orientation is measured, its rotation deviation `rotations` (rotation vectors in the base frame, rad, one
/// per attempt). `None` without an attempt or with a non-finite deviation.
pub fn pose_accuracy(
    positions: &[Vector3<f64>],
    rotations: Option<&[Vector3<f64>]>,
) -> Option<PoseAccuracy> {
    let n = positions.len();
    let finite = |v: &Vector3<f64>| v.iter().all(|x| x.is_finite());
    if n == 0
        || !positions.iter().all(finite)
        || rotations.is_some_and(|r| r.len() != n || !r.iter().all(finite))
    {
        return None;
    }
    let offset = mean(positions);
    let l: Vec<f64> = positions.iter().map(|p| (p - offset).norm()).collect();
    let rp = (n >= MIN_ATTEMPTS_FOR_RP).then(|| {
        let l_mean = l.iter().sum::<f64>() / n as f64;
        l_mean + 3.0 * sample_std(&l, l_mean)
    });
    let orientation = rotations.map(|r| {
        let ap = mean(r);
        OrientationAccuracy {
            ap: [ap.x, ap.y, ap.z],
            rp: (n >= MIN_ATTEMPTS_FOR_RP).then(|| {
                [0, 1, 2].map(|k| {
                    let values: Vec<f64> = r.iter().map(|v| v[k]).collect();
                    3.0 * sample_std(&values, ap[k])
                })
            }),
        }
    });
    Some(PoseAccuracy {
        attempts: n,
        offset,
        ap: offset.norm(),
        rp,
        orientation,
    })
}

impl PoseAccuracy {
    pub fn in_mm(&self) -> PoseAccuracyMm {
        PoseAccuracyMm {
            attempts: self.attempts,
            ap_mm: self.ap * 1e3,
            ap_xyz_mm: [self.offset.x, self.offset.y, self.offset.z].map(|v| v * 1e3),
            rp_mm: self.rp.map(|r| r * 1e3),
            ap_abc_rad: self.orientation.as_ref().map(|o| o.ap),
            rp_abc_rad: self.orientation.as_ref().and_then(|o| o.rp),
        }
    }

    /// The size of the orientation's AP: the norm of (AP_a, AP_b, AP_c), rad.
    pub fn orientation_ap(&self) -> Option<f64> {
        self.orientation
            .as_ref()
            .map(|o| Vector3::from(o.ap).norm())
    }

    /// The largest of RP_a, RP_b, RP_c, rad.
    pub fn orientation_rp(&self) -> Option<f64> {
        self.orientation
            .as_ref()
            .and_then(|o| o.rp)
            .map(|r| r.iter().fold(0.0, |a: f64, b| a.max(*b)))
    }
}

fn mean(values: &[Vector3<f64>]) -> Vector3<f64> {
    values.iter().sum::<Vector3<f64>>() / values.len() as f64
}

/// The standard deviation with the n − 1 denominator, about `mean`.
fn sample_std(values: &[f64], mean: f64) -> f64 {
    let n = values.len();
    if n < 2 {
        return 0.0;
    }
    (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_known_cloud() {
        // Four attempts at ±1 mm along x and y around a barycentre 2 mm above the command: AP 2 mm, every
        // attempt 1 mm from the barycentre, so S_l = 0 and RP = 1 mm.
        let p = [
            Vector3::new(1e-3, 0.0, 2e-3),
            Vector3::new(-1e-3, 0.0, 2e-3),
            Vector3::new(0.0, 1e-3, 2e-3),
            Vector3::new(0.0, -1e-3, 2e-3),
        ];
        let a = pose_accuracy(&p, None).unwrap();
        assert!((a.ap - 2e-3).abs() < 1e-15);
        assert!((a.rp.unwrap() - 1e-3).abs() < 1e-15);
        assert!(a.orientation.is_none());
        // Distances 1 and 3 mm (two each): l̄ = 2, S_l = √(4/3), RP = 2 + 3·√(4/3) mm.
        let q = [
            Vector3::new(1e-3, 0.0, 0.0),
            Vector3::new(-1e-3, 0.0, 0.0),
            Vector3::new(0.0, 3e-3, 0.0),
            Vector3::new(0.0, -3e-3, 0.0),
        ];
        let b = pose_accuracy(&q, None).unwrap();
        assert!(b.ap < 1e-15);
        assert!((b.rp.unwrap() - (2e-3 + 3.0 * (4.0f64 / 3.0).sqrt() * 1e-3)).abs() < 1e-15);
    }

    #[test]
    fn orientation_and_too_few_attempts() {
        let p = [Vector3::zeros(), Vector3::zeros()];
        let r = [
            Vector3::new(1e-3, 0.0, -2e-3),
            Vector3::new(3e-3, 0.0, -2e-3),
        ];
        let a = pose_accuracy(&p, Some(&r)).unwrap();
        let o = a.orientation.as_ref().unwrap();
        assert_eq!(o.ap, [2e-3, 0.0, -2e-3]);
        assert!(o.rp.is_none() && a.rp.is_none(), "two attempts give no RP");
        assert!(pose_accuracy(&[], None).is_none());
        assert!(pose_accuracy(&[Vector3::new(f64::NAN, 0.0, 0.0)], None).is_none());
        assert!(pose_accuracy(&p, Some(&r[..1])).is_none());
    }
}
