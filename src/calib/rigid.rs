//! Least-squares rigid registration of two point sets (Kabsch / Umeyama without scale).
//!
//! The tracker reports points in its own frame, whose pose in the robot base frame is unknown; the paper
//! (and every method here) first expresses the tracker data in the base frame by the rigid transform that
//! best maps the controller's nominal points onto the measured ones. The closed form via the SVD of the
//! cross-covariance is exact and needs no starting guess, which matters because the tracker can sit
//! anywhere in the cell.

use nalgebra::{Isometry3, Matrix3, Point3, Translation3, UnitQuaternion, Vector3};

use crate::error::{Error, Result};
use crate::numeric;

/// The fitted transform with what is left over, so callers can judge the fit (and spot outliers) without
/// recomputing it.
#[derive(Clone, Debug)]
pub struct RigidFit {
    /// Maps `from` points onto `to` points: `to_i ≈ transform * from_i`.
    pub transform: Isometry3<f64>,
    /// Root mean square of `residuals`, metres.
    pub rms: f64,
    /// `|to_i - transform * from_i|` per point, metres, in input order.
    pub residuals: Vec<f64>,
}

/// Below this ratio of the second to the first singular value of the cross-covariance, the rotation about
/// the sets' main axis is decided by rounding error rather than by the data, so the sets count as
/// collinear. Exactly collinear points in floating point land near 1e-16; real campaigns, far above 1e-6.
const COLLINEAR_TOL: f64 = 1e-10;

/// Below this ratio of the RMS spread about the centroid to the coordinate magnitude, the points are one
/// point written several times with rounding differences.
const COINCIDENT_TOL: f64 = 1e-12;

/// The centre of a point's reflectors: the reflector itself for a position campaign, the nest centre for a
/// nest (about which an unknown nest rotation turns, so its position error is the robot's alone).
pub fn centre(points: &[Point3<f64>]) -> Point3<f64> {
    Point3::from(points.iter().map(|p| p.coords).sum::<Vector3<f64>>() / points.len().max(1) as f64)
}

/// Finds the rigid `T` minimizing `Σ |to_i - T·from_i|²`.
///
/// The rotation is always proper (det = +1): when the unconstrained optimum of the orthogonal Procrustes
/// problem is a reflection (mirrored data, or planar sets where the SVD's third axis has a free sign), the
/// correction of Umeyama (1991) gives the best rotation instead, since a reflection is never a physical pose.
///
/// Errors (`Error::Invalid`): lengths differ, fewer than 3 points, a NaN or infinite coordinate, or either
/// set collinear or coincident, where the rotation is not unique.
pub fn register_points(from: &[Point3<f64>], to: &[Point3<f64>]) -> Result<RigidFit> {
    if from.len() != to.len() {
        return Err(Error::Invalid(format!(
            "registration: {} source points but {} target points",
            from.len(),
            to.len()
        )));
    }
    let n = from.len();
    if n < 3 {
        return Err(Error::Invalid(format!(
            "registration: needs at least 3 point pairs, got {n}"
        )));
    }
    for (name, set) in [("source", from), ("target", to)] {
        if let Some(i) = set
            .iter()
            .position(|p| !p.coords.iter().all(|c| c.is_finite()))
        {
            return Err(Error::Invalid(format!(
                "registration: {name} point {i} is not finite: {:?}",
                set[i].coords.as_slice()
            )));
        }
    }

    let c_from = centroid(from);
    let c_to = centroid(to);
    for (name, set, c) in [("source", from, &c_from), ("target", to, &c_to)] {
        let spread = (set.iter().map(|p| (p - c).norm_squared()).sum::<f64>() / n as f64).sqrt();
        let magnitude = set.iter().map(|p| p.coords.amax()).fold(0.0, f64::max);
        if spread == 0.0 || spread <= COINCIDENT_TOL * magnitude {
            return Err(Error::Invalid(format!(
                "registration: {name} points are coincident (spread {spread:.3e} m)"
            )));
        }
    }

    // Cross-covariance H = Σ (a_i - ā)(b_i - b̄)ᵀ; the optimal rotation maximizes tr(R H).
    let mut h = Matrix3::<f64>::zeros();
    for (a, b) in from.iter().zip(to) {
        h += (a - c_from) * (b - c_to).transpose();
    }
    if !h.iter().all(|x| x.is_finite()) {
        return Err(Error::Invalid(
            "registration: coordinates too large for a finite cross-covariance".into(),
        ));
    }
    let svd = numeric::svd(h, true, true, "registration")?;
    let s = svd.singular_values; // sorted, largest first
    if s[1] <= COLLINEAR_TOL * s[0] {
        return Err(Error::Invalid(format!(
            "registration: points are collinear (singular values {:.3e}, {:.3e}, {:.3e})",
            s[0], s[1], s[2]
        )));
    }
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return Err(Error::Invalid("registration: SVD returned no basis".into()));
    };
    let v = v_t.transpose();
    // Flip the axis of the smallest singular value when V·Uᵀ would be a reflection: this is the rotation
    // closest to the reflection, and the optimum over SO(3) (Umeyama 1991, Lemma).
    let d = if (v * u.transpose()).determinant() < 0.0 {
        -1.0
    } else {
        1.0
    };
    let r = v * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d)) * u.transpose();
    let rotation =
        UnitQuaternion::from_rotation_matrix(&nalgebra::Rotation3::from_matrix_unchecked(r));
    // Translation from the unit quaternion actually returned, so the centroids map onto each other exactly.
    let translation = Translation3::from(c_to.coords - rotation * c_from.coords);
    let transform = Isometry3::from_parts(translation, rotation);

    let residuals: Vec<f64> = from
        .iter()
        .zip(to)
        .map(|(a, b)| (b - transform * a).norm())
        .collect();
    let rms = (residuals.iter().map(|r| r * r).sum::<f64>() / n as f64).sqrt();
    Ok(RigidFit {
        transform,
        rms,
        residuals,
    })
}

fn centroid(points: &[Point3<f64>]) -> Point3<f64> {
    let sum: Vector3<f64> = points.iter().map(|p| p.coords).sum();
    Point3::from(sum / points.len() as f64)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, Normal};

    fn random_points(rng: &mut ChaCha8Rng, n: usize, half: f64) -> Vec<Point3<f64>> {
        (0..n)
            .map(|_| {
                Point3::new(
                    rng.random_range(-half..half),
                    rng.random_range(-half..half),
                    rng.random_range(-half..half),
                )
            })
            .collect()
    }

    fn truth() -> Isometry3<f64> {
        Isometry3::new(Vector3::new(1.2, -0.7, 2.5), Vector3::new(0.4, -1.1, 2.3))
    }

    fn rotation_error(a: &Isometry3<f64>, b: &Isometry3<f64>) -> f64 {
        a.rotation.rotation_to(&b.rotation).angle()
    }

    fn translation_error(a: &Isometry3<f64>, b: &Isometry3<f64>) -> f64 {
        (a.translation.vector - b.translation.vector).norm()
    }

    #[test]
    fn recovers_known_transform_exactly() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let from = random_points(&mut rng, 20, 0.5);
        let t = truth();
        let to: Vec<_> = from.iter().map(|p| t * p).collect();
        let fit = register_points(&from, &to).unwrap();
        assert!(rotation_error(&fit.transform, &t) <= 1e-12);
        assert!(translation_error(&fit.transform, &t) <= 1e-12);
        assert!(fit.rms <= 1e-12);
        assert_eq!(fit.residuals.len(), 20);
        assert!(fit.residuals.iter().all(|r| *r <= 1e-12));
    }

    #[test]
    fn three_points_suffice() {
        let from = [
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(0.0, 1.0, 0.0),
        ];
        let t = truth();
        let to: Vec<_> = from.iter().map(|p| t * p).collect();
        let fit = register_points(&from, &to).unwrap();
        assert!(rotation_error(&fit.transform, &t) <= 1e-12);
        assert!(translation_error(&fit.transform, &t) <= 1e-12);
    }

    #[test]
    fn noisy_fit_is_close_to_truth() {
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        let n = 200;
        let sigma = 50e-6;
        let from = random_points(&mut rng, n, 0.5);
        let t = truth();
        let noise = Normal::new(0.0, sigma).unwrap();
        let to: Vec<_> = from
            .iter()
            .map(|p| {
                t * p
                    + Vector3::new(
                        noise.sample(&mut rng),
                        noise.sample(&mut rng),
                        noise.sample(&mut rng),
                    )
            })
            .collect();
        let fit = register_points(&from, &to).unwrap();
        // Expected errors: ~σ/(0.3 m·√n) ≈ 1e-5 rad and ~σ/√n ≈ 4e-6 m; bounds are several times that.
        assert!(rotation_error(&fit.transform, &t) < 5e-5);
        assert!(translation_error(&fit.transform, &t) < 2e-5);
        // 3D residual RMS of a 6-parameter fit: σ·√(3 - 6/n).
        let expected = sigma * (3.0 - 6.0 / n as f64).sqrt();
        assert!(
            (fit.rms / expected - 1.0).abs() < 0.15,
            "rms {} vs {}",
            fit.rms,
            expected
        );
        // The fit is no worse than the truth in its own criterion.
        let cost = |iso: &Isometry3<f64>| -> f64 {
            from.iter()
                .zip(&to)
                .map(|(a, b)| (b - iso * a).norm_squared())
                .sum()
        };
        assert!(cost(&fit.transform) <= cost(&t));
    }

    #[test]
    fn mirrored_data_yields_proper_rotation() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let from = random_points(&mut rng, 30, 0.5);
        // Mirror in z: the unconstrained orthogonal optimum is this reflection, with zero residual.
        let to: Vec<_> = from.iter().map(|p| Point3::new(p.x, p.y, -p.z)).collect();

        let c_from = centroid(&from);
        let c_to = centroid(&to);
        let mut h = Matrix3::zeros();
        for (a, b) in from.iter().zip(&to) {
            h += (a - c_from) * (b - c_to).transpose();
        }
        let svd = h.svd(true, true);
        let naive = svd.v_t.unwrap().transpose() * svd.u.unwrap().transpose();
        assert!(
            naive.determinant() < -0.99,
            "naive solution is a reflection"
        );

        let fit = register_points(&from, &to).unwrap();
        let r = fit.transform.rotation.to_rotation_matrix().into_inner();
        assert!((r.determinant() - 1.0).abs() < 1e-12);
        assert!((r.transpose() * r - Matrix3::identity()).norm() < 1e-12);
        assert!(fit.rms > 0.01, "a rotation cannot reproduce a mirror image");

        // Optimal among rotations: small perturbations never lower the cost.
        let cost = |iso: &Isometry3<f64>| -> f64 {
            from.iter()
                .zip(&to)
                .map(|(a, b)| (b - iso * a).norm_squared())
                .sum()
        };
        let best = cost(&fit.transform);
        for k in 0..6 {
            for sign in [-1.0, 1.0] {
                let mut delta = [0.0; 6];
                delta[k] = sign * 1e-3;
                let step = Isometry3::new(
                    Vector3::new(delta[0], delta[1], delta[2]),
                    Vector3::new(delta[3], delta[4], delta[5]),
                );
                assert!(cost(&(step * fit.transform)) >= best);
            }
        }
    }

    #[test]
    fn planar_points_recover_rotation_not_reflection() {
        // Coplanar sets: the rotation and its mirror through the plane both fit exactly; the SVD's
        // third axis has an arbitrary sign, so only the determinant fix makes the answer a rotation.
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let from: Vec<_> = (0..12)
            .map(|_| {
                Point3::new(
                    rng.random_range(-0.5..0.5),
                    rng.random_range(-0.5..0.5),
                    0.3,
                )
            })
            .collect();
        let t = truth();
        let to: Vec<_> = from.iter().map(|p| t * p).collect();
        let fit = register_points(&from, &to).unwrap();
        let r = fit.transform.rotation.to_rotation_matrix().into_inner();
        assert!((r.determinant() - 1.0).abs() < 1e-12);
        assert!(rotation_error(&fit.transform, &t) <= 1e-12);
        assert!(translation_error(&fit.transform, &t) <= 1e-12);
    }

    #[test]
    fn rejects_bad_input() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let from = random_points(&mut rng, 10, 0.5);
        let to: Vec<_> = from.iter().map(|p| truth() * p).collect();

        assert!(matches!(
            register_points(&from, &to[..9]),
            Err(Error::Invalid(_))
        ));
        assert!(matches!(
            register_points(&from[..2], &to[..2]),
            Err(Error::Invalid(_))
        ));

        let mut nan = to.clone();
        nan[4].y = f64::NAN;
        assert!(matches!(
            register_points(&from, &nan),
            Err(Error::Invalid(_))
        ));
        let mut inf = from.clone();
        inf[0].x = f64::INFINITY;
        assert!(matches!(register_points(&inf, &to), Err(Error::Invalid(_))));
    }

    #[test]
    fn rejects_collinear_and_coincident() {
        let dir = Vector3::new(0.3, -0.5, 0.8).normalize();
        let base = Point3::new(0.1, 0.2, 0.3);
        let line: Vec<_> = (0..10).map(|i| base + dir * (0.137 * i as f64)).collect();
        let line_to: Vec<_> = line.iter().map(|p| truth() * p).collect();
        let err = register_points(&line, &line_to).unwrap_err();
        assert!(err.to_string().contains("collinear"), "{err}");

        // A good source set registered onto a collinear target is just as ambiguous.
        let mut rng = ChaCha8Rng::seed_from_u64(6);
        let cloud = random_points(&mut rng, 10, 0.5);
        assert!(register_points(&cloud, &line_to).is_err());

        let same = vec![Point3::new(0.1, 0.1, 0.1); 5];
        let err = register_points(&same, &same).unwrap_err();
        assert!(err.to_string().contains("coincident"), "{err}");
    }
}
