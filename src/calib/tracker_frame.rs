//! The tracker frame and the reflector mounting, from measured points and nominal kinematics.
//!
//! A measured point `y_i` (tracker frame) is the reflector at `m` (flange frame) on the flange at pose `F_i`:
//! `T·y_i = F_i·m`. Neither the tracker pose `T` nor the true mounting `m` is known. The closed form
//! ([`register_points`] onto the nominally mounted points) gives `T` for a guessed `m`; Levenberg–Marquardt
//! then refines `T` and `m` together. For a reflector nest the point is the nest centre: a rotation of the
//! nest about its centre moves no centre, and is a constant rotation of the last frame that the orientation
//! models carry (the paper's Table 2).

use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
use nalgebra::{
    DMatrix, DVector, Dyn, Isometry3, Matrix3, Owned, Point3, Translation3, UnitQuaternion, Vector3,
};
use serde::{Deserialize, Serialize};

use super::registration::{centre, register_points};
use crate::dataset::Dataset;
use crate::error::{Error, Result};
use crate::robot::dh::DhChain;

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct TrackerFrame {
    /// Maps tracker coordinates to the robot base frame.
    pub tracker_to_base: Isometry3<f64>,
    /// The measured point (reflector, or nest centre) in the flange frame, m.
    pub mounting: Point3<f64>,
    /// RMS of `|T·y_i − F_i·m|` over the points used, m.
    pub rms: f64,
    /// Residual evaluations of the refinement.
    pub evaluations: usize,
}

impl TrackerFrame {
    pub fn to_base(&self, tracker_point: &Point3<f64>) -> Point3<f64> {
        self.tracker_to_base * tracker_point
    }
}

/// What every method starts from: the tracker frame, the mounting of the measured point, and for a reflector
/// nest its geometry about its centre (flange frame), from which the flange orientation is measured.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Registration {
    pub frame: TrackerFrame,
    pub nest: Option<Vec<Point3<f64>>>,
}

/// One measured point as a method sees it, in the base frame.
#[derive(Clone, Debug)]
pub struct Observation {
    pub q: Vec<f64>,
    /// The measured point (reflector or nest centre), registered into the base frame.
    pub position: Point3<f64>,
    /// The measured flange orientation (nests only).
    pub orientation: Option<UnitQuaternion<f64>>,
}

impl Registration {
    /// Registers on the training and validation points together (everything a method may fit on; the test
    /// split stays untouched). The mounting guess comes from the `nom_*` columns when the data has them.
    pub fn fit(dh: &DhChain, train: &Dataset, val: &Dataset) -> Result<Registration> {
        let q: Vec<&Vec<f64>> = train.q.iter().chain(&val.q).collect();
        let centres: Vec<Point3<f64>> = train
            .measured
            .iter()
            .chain(&val.measured)
            .map(|m| centre(m))
            .collect();
        let flanges: Vec<Isometry3<f64>> = q.iter().map(|q| dh.flange_pose(q)).collect();
        let guess = match &train.nominal_reflectors {
            Some(nom) if !train.is_empty() => {
                dh.flange_pose(&train.q[0]).inverse() * centre(&nom[0])
            }
            _ => Point3::origin(),
        };
        Ok(Registration {
            frame: fit_tracker_frame(&centres, &flanges, &guess)?,
            nest: nest_geometry(dh, train)?,
        })
    }

    pub fn observe(&self, data: &Dataset) -> Result<Vec<Observation>> {
        self.observe_points(&data.q, &data.measured)
    }

    /// Measurements (tracker frame, per reflector) of configurations `q`, in the base frame.
    pub fn observe_points(
        &self,
        q: &[Vec<f64>],
        measured: &[Vec<Point3<f64>>],
    ) -> Result<Vec<Observation>> {
        q.iter()
            .zip(measured)
            .map(|(q, points)| {
                let orientation = match &self.nest {
                    Some(nest) if points.len() == nest.len() => {
                        let c = centre(points);
                        let local: Vec<Point3<f64>> =
                            points.iter().map(|p| Point3::from(p - c)).collect();
                        let fit = register_points(nest, &local)?;
                        Some(self.frame.tracker_to_base.rotation * fit.transform.rotation)
                    }
                    _ => None,
                };
                Ok(Observation {
                    q: q.clone(),
                    position: self.frame.to_base(&centre(points)),
                    orientation,
                })
            })
            .collect()
    }
}

/// The nest about its centre in the flange frame, from the nominal reflector positions of the first point.
fn nest_geometry(dh: &DhChain, data: &Dataset) -> Result<Option<Vec<Point3<f64>>>> {
    if data.reflectors() < 3 || data.is_empty() {
        return Ok(None);
    }
    let Some(nominal) = &data.nominal_reflectors else {
        return Err(Error::Data {
            origin: data.origin.clone(),
            message: "three reflectors but no nom_x1 … nom_z3 columns: the nest geometry on the flange is unknown"
                .into(),
        });
    };
    let flange_inv = dh.flange_pose(&data.q[0]).inverse();
    let local: Vec<Point3<f64>> = nominal[0].iter().map(|p| flange_inv * p).collect();
    let c = centre(&local);
    Ok(Some(local.iter().map(|p| Point3::from(p - c)).collect()))
}

/// Fits the tracker frame and the mounting. `mounting_guess`: the nominal mounting, or the flange origin when
/// unknown (the refinement is linear in the mounting and the translation, so a poor guess costs iterations,
/// not the answer). Needs the flange orientation to vary over the points, or the mounting is not observable.
pub fn fit_tracker_frame(
    measured: &[Point3<f64>],
    flanges: &[Isometry3<f64>],
    mounting_guess: &Point3<f64>,
) -> Result<TrackerFrame> {
    if measured.len() != flanges.len() {
        return Err(Error::Invalid(format!(
            "tracker frame: {} measured points for {} flange poses",
            measured.len(),
            flanges.len()
        )));
    }
    if measured.len() < 4 {
        return Err(Error::Invalid(format!(
            "tracker frame: needs at least 4 points to fit the tracker frame and the mounting, got {}",
            measured.len()
        )));
    }
    let nominal: Vec<Point3<f64>> = flanges.iter().map(|f| f * mounting_guess).collect();
    let first = register_points(measured, &nominal)?;
    let problem = Problem {
        measured,
        flanges,
        base_rotation: first.transform.rotation,
        params: {
            let t = first.transform.translation.vector;
            DVector::from_vec(vec![
                0.0,
                0.0,
                0.0,
                t.x,
                t.y,
                t.z,
                mounting_guess.x,
                mounting_guess.y,
                mounting_guess.z,
            ])
        },
    };
    let (problem, report) = LevenbergMarquardt::new()
        .with_patience(200)
        .minimize(problem);
    if !report.termination.was_successful() {
        return Err(Error::Invalid(format!(
            "tracker frame: the least-squares refinement did not converge ({:?})",
            report.termination
        )));
    }
    let (transform, mounting) = problem.unpack();
    let residual2: f64 = measured
        .iter()
        .zip(flanges)
        .map(|(y, f)| (transform * y - f * mounting).norm_squared())
        .sum();
    Ok(TrackerFrame {
        tracker_to_base: transform,
        mounting,
        rms: (residual2 / measured.len() as f64).sqrt(),
        evaluations: report.number_of_evaluations,
    })
}

/// Parameters: a rotation vector applied on the left of the closed-form rotation, the translation, the mounting.
struct Problem<'a> {
    measured: &'a [Point3<f64>],
    flanges: &'a [Isometry3<f64>],
    base_rotation: UnitQuaternion<f64>,
    params: DVector<f64>,
}

impl Problem<'_> {
    fn unpack(&self) -> (Isometry3<f64>, Point3<f64>) {
        let p = &self.params;
        let rotation =
            UnitQuaternion::from_scaled_axis(Vector3::new(p[0], p[1], p[2])) * self.base_rotation;
        (
            Isometry3::from_parts(Translation3::new(p[3], p[4], p[5]), rotation),
            Point3::new(p[6], p[7], p[8]),
        )
    }
}

impl LeastSquaresProblem<f64, Dyn, Dyn> for Problem<'_> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, Dyn>;
    type ParameterStorage = Owned<f64, Dyn>;

    fn set_params(&mut self, x: &DVector<f64>) {
        self.params.copy_from(x);
    }

    fn params(&self) -> DVector<f64> {
        self.params.clone()
    }

    fn residuals(&self) -> Option<DVector<f64>> {
        let (t, m) = self.unpack();
        let mut r = DVector::zeros(3 * self.measured.len());
        for (i, (y, f)) in self.measured.iter().zip(self.flanges).enumerate() {
            r.fixed_rows_mut::<3>(3 * i).copy_from(&(t * y - f * m));
        }
        Some(r)
    }

    /// Exact in the translation and mounting; in the rotation, the derivative of a left perturbation at the
    /// current estimate, which is the true one to first order in the (micro-radian) correction.
    fn jacobian(&self) -> Option<DMatrix<f64>> {
        let (t, _) = self.unpack();
        let mut j = DMatrix::zeros(3 * self.measured.len(), 9);
        for (i, (y, f)) in self.measured.iter().zip(self.flanges).enumerate() {
            let v = t.rotation * y.coords;
            j.fixed_view_mut::<3, 3>(3 * i, 0)
                .copy_from(&(-v.cross_matrix()));
            j.fixed_view_mut::<3, 3>(3 * i, 3)
                .copy_from(&Matrix3::identity());
            j.fixed_view_mut::<3, 3>(3 * i, 6)
                .copy_from(&(-f.rotation.to_rotation_matrix().into_inner()));
        }
        Some(j)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, Normal};

    fn flanges(n: usize, rng: &mut ChaCha8Rng) -> Vec<Isometry3<f64>> {
        (0..n)
            .map(|_| {
                Isometry3::from_parts(
                    Translation3::new(
                        rng.random_range(0.4..0.8),
                        rng.random_range(-0.3..0.3),
                        rng.random_range(0.2..0.7),
                    ),
                    UnitQuaternion::from_euler_angles(
                        rng.random_range(-0.4..0.4),
                        1.0 + rng.random_range(-0.4..0.4),
                        rng.random_range(-0.6..0.6),
                    ),
                )
            })
            .collect()
    }

    #[test]
    fn recovers_a_known_tracker_frame_and_mounting() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let f = flanges(300, &mut rng);
        let truth = Isometry3::from_parts(
            Translation3::new(2.9, 0.4, 1.7),
            UnitQuaternion::from_euler_angles(0.01, -0.02, 3.2),
        );
        let mount = Point3::new(0.0007, -0.0004, 0.0312);
        let noise = Normal::new(0.0, 15e-6).unwrap();
        let measured: Vec<Point3<f64>> = f
            .iter()
            .map(|fi| {
                let p = truth.inverse_transform_point(&(fi * mount));
                p + Vector3::from_fn(|_, _| noise.sample(&mut rng))
            })
            .collect();
        // Starting from the flange origin, 31 mm off.
        let fit = fit_tracker_frame(&measured, &f, &Point3::origin()).unwrap();
        assert!(
            (fit.mounting - mount).norm() < 2e-5,
            "mounting off by {}",
            (fit.mounting - mount).norm()
        );
        let t = fit.tracker_to_base;
        assert!((t.translation.vector - truth.translation.vector).norm() < 1e-4);
        assert!((t.rotation * truth.rotation.inverse()).angle() < 1e-5);
        // The residual is the noise: 15 µm per axis, √3·15 µm in 3-D.
        assert!(fit.rms > 15e-6 && fit.rms < 35e-6, "rms {}", fit.rms);
    }

    #[test]
    fn too_few_points_is_an_error() {
        let mut rng = ChaCha8Rng::seed_from_u64(8);
        let f = flanges(3, &mut rng);
        let y: Vec<Point3<f64>> = f.iter().map(|fi| fi * Point3::origin()).collect();
        assert!(fit_tracker_frame(&y, &f, &Point3::origin()).is_err());
    }
}
