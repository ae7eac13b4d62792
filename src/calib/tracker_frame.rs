//! The tracker frame and the reflector mounting, from measured points and nominal kinematics.
//!
//! A measured point `y_i` (tracker frame) is the reflector at `m` (flange frame) on the flange at pose `F_i`:
//! `T·y_i = F_i·m`. Neither the tracker pose `T` nor the true mounting `m` is known. The closed form
//! ([`register_points`] onto the nominally mounted points) gives `T` for a guessed `m`; Levenberg–Marquardt
//! then refines `T` and `m` together. For a reflector nest the point is the nest centre: a rotation of the
//! nest about its centre moves no centre, and is a constant rotation of the last frame that the orientation
//! models carry (the paper's Table 2).
//!
//! A 6-DoF probe (a T-Mac: the tracker measures its frame, position and orientation) is the other source of
//! orientation. Its rotation on the flange is unknown; the registration estimates it as the rotation mean of
//! `F_i⁻¹·T·O_i` over the registration points (nominal flange `F_i`, measured probe orientation `O_i`, tracker
//! rotation `T` from the points), so the observed flange orientation `T·O_i·P⁻¹` agrees with the nominal one on
//! average and the methods model what varies — exactly where a nest's orientation goes.

use levenberg_marquardt::LevenbergMarquardt;
use nalgebra::{
    DMatrix, DVector, Isometry3, Matrix3, Point3, Translation3, UnitQuaternion, Vector3,
};
use serde::{Deserialize, Serialize};

use super::reduced::{Small, Tall, gram_rows};
use super::rigid::{centre, register_points};
use crate::dataset::Dataset;
use crate::error::{Error, Result};
use crate::numeric;
use crate::robot::dh::DhChain;
use crate::robot::plausible;

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
    /// A 6-DoF probe's rotation in the flange frame, when the data measures the probe's orientation.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub probe_rotation: Option<UnitQuaternion<f64>>,
    /// The data was in the robot's base frame: the frame is the identity and stays so in every refit.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub base_frame: bool,
}

/// The weight (m/rad) of a 6-DoF probe's rotation residual against its position residual where a method fits
/// both (`kinematic`): an angle counts as the displacement it causes 0.1 m away, the size of the probe. A
/// nest uses its own RMS radius.
pub const PROBE_ORIENTATION_LENGTH_M: f64 = 0.1;

/// One measured point as a method sees it, in the base frame.
#[derive(Clone, Debug)]
pub struct Observation {
    pub q: Vec<f64>,
    /// The measured point (reflector, nest centre or probe origin), registered into the base frame.
    pub position: Point3<f64>,
    /// The measured flange orientation (a nest or a 6-DoF probe).
    pub orientation: Option<UnitQuaternion<f64>>,
    /// The point's inputs beyond the joint angles (`Dataset::extra_inputs`; empty without).
    pub inputs: Vec<f64>,
}

impl TrackerFrame {
    /// A frame read from a file is usable: a proper pose and mounting of plausible size, a finite RMS.
    pub fn validate(&self) -> Result<()> {
        plausible::pose("tracker_to_base", &self.tracker_to_base)?;
        plausible::point("mounting", &self.mounting)?;
        plausible::non_negative("rms", self.rms, plausible::MAX_LENGTH_M, "RMS in metres")
    }
}

impl Registration {
    /// A registration read from a file is usable ([`TrackerFrame::validate`]); a nest has at least the three
    /// reflectors that measure an orientation, each at a plausible place; a probe rotation is a rotation.
    pub fn validate(&self) -> Result<()> {
        plausible::within("frame", self.frame.validate())?;
        if let Some(nest) = &self.nest {
            if nest.len() < 3 {
                return Err(plausible::invalid(
                    "nest",
                    format!(
                        "{} reflectors; a nest has at least 3 (null without one)",
                        nest.len()
                    ),
                ));
            }
            for (k, p) in nest.iter().enumerate() {
                plausible::point(&format!("nest[{k}]"), p)?;
            }
        }
        if let Some(r) = &self.probe_rotation {
            plausible::rotation("probe_rotation", r)?;
        }
        Ok(())
    }

    /// Registers on the training and validation points together (everything a method may fit on; the test
    /// split stays untouched). The mounting guess comes from the `nom_*` columns when the data has them.
    pub fn fit(dh: &DhChain, train: &Dataset, val: &Dataset) -> Result<Registration> {
        let fixed = dh.fixed_rotations();
        let flanges: Vec<Isometry3<f64>> = train
            .q
            .iter()
            .chain(&val.q)
            .map(|q| dh.flange_pose_fixed(q, &fixed))
            .collect();
        Registration::fit_at(dh, train, val, &flanges)
    }

    /// [`Registration::fit`] with the nominal flange poses of the training, then the validation configurations
    /// given (a method that computes the chain's frames anyway passes them on).
    pub fn fit_at(
        dh: &DhChain,
        train: &Dataset,
        val: &Dataset,
        flanges: &[Isometry3<f64>],
    ) -> Result<Registration> {
        assert_eq!(
            flanges.len(),
            train.len() + val.len(),
            "one flange pose per training and validation point"
        );
        let centres: Vec<Point3<f64>> = train
            .measured
            .iter()
            .chain(&val.measured)
            .map(|m| centre(m))
            .collect();
        let guess = match &train.nominal_reflectors {
            Some(nom) if !train.is_empty() => flanges[0].inverse() * centre(&nom[0]),
            _ => Point3::origin(),
        };
        let base_frame = train.base_frame || val.base_frame;
        let frame = if base_frame {
            fit_mounting(&centres, flanges)?
        } else {
            fit_tracker_frame(&centres, flanges, &guess)?
        };
        let probe_rotation = match (&train.measured_orientation, &val.measured_orientation) {
            (Some(a), Some(b)) => Some(probe_rotation(
                &frame,
                flanges,
                &a.iter().chain(b).copied().collect::<Vec<_>>(),
            )?),
            (None, None) => None,
            _ => {
                return Err(Error::Invalid(
                    "registration: the training and validation data must both measure the orientation, or neither"
                        .into(),
                ));
            }
        };
        Ok(Registration {
            frame,
            nest: nest_geometry(dh, train)?,
            probe_rotation,
            base_frame,
        })
    }

    /// Whether observations carry a measured flange orientation (a reflector nest or a 6-DoF probe).
    pub fn measures_orientation(&self) -> bool {
        self.nest.is_some() || self.probe_rotation.is_some()
    }

    /// The length (m) that weighs a rotation residual against a position residual: the nest's RMS radius, or
    /// [`PROBE_ORIENTATION_LENGTH_M`] for a 6-DoF probe; `None` without measured orientation.
    pub fn orientation_length(&self) -> Option<f64> {
        match (&self.nest, self.probe_rotation) {
            (Some(nest), _) => Some(
                (nest.iter().map(|p| p.coords.norm_squared()).sum::<f64>() / nest.len() as f64)
                    .sqrt(),
            ),
            (None, Some(_)) => Some(PROBE_ORIENTATION_LENGTH_M),
            (None, None) => None,
        }
    }

    /// The dataset's points as observations: positions, orientations (nest or probe) and extra inputs.
    pub fn observe(&self, data: &Dataset) -> Result<Vec<Observation>> {
        let mut obs = self.observe_points(&data.q, &data.measured)?;
        self.orient_by_probe(data, &mut obs);
        for (i, o) in obs.iter_mut().enumerate() {
            o.inputs = data.extra_inputs_of(i).to_vec();
        }
        Ok(obs)
    }

    /// [`Registration::observe`] of `data` into `obs`, its observations by another registration: the positions
    /// and orientations become this one's, the joint angles and inputs (which no registration changes) stay.
    /// `residual-ridge` registers again every round.
    pub(super) fn observe_again(&self, data: &Dataset, obs: &mut [Observation]) -> Result<()> {
        if obs.len() != data.len() {
            return Err(Error::Invalid(format!(
                "registration: {} observations of {} points",
                obs.len(),
                data.len()
            )));
        }
        for (o, points) in obs.iter_mut().zip(&data.measured) {
            (o.position, o.orientation) = self.measure(points)?;
        }
        self.orient_by_probe(data, obs);
        Ok(())
    }

    /// A 6-DoF probe's measured orientations into `obs` (observations of `data`).
    fn orient_by_probe(&self, data: &Dataset, obs: &mut [Observation]) {
        if let (Some(probe), Some(measured)) = (self.probe_rotation, &data.measured_orientation) {
            for (o, m) in obs.iter_mut().zip(measured) {
                o.orientation = Some(self.flange_orientation(m, &probe));
            }
        }
    }

    /// The flange orientation (base frame) that a probe orientation measured in the tracker frame implies.
    pub fn flange_orientation(
        &self,
        measured: &UnitQuaternion<f64>,
        probe: &UnitQuaternion<f64>,
    ) -> UnitQuaternion<f64> {
        self.frame.tracker_to_base.rotation * measured * probe.inverse()
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
                let (position, orientation) = self.measure(points)?;
                Ok(Observation {
                    q: q.clone(),
                    position,
                    orientation,
                    inputs: Vec::new(),
                })
            })
            .collect()
    }

    /// The base-frame position of one point's measurements (tracker frame, per reflector) and, with a nest,
    /// the flange orientation they measure.
    fn measure(
        &self,
        points: &[Point3<f64>],
    ) -> Result<(Point3<f64>, Option<UnitQuaternion<f64>>)> {
        let orientation = match &self.nest {
            Some(nest) if points.len() == nest.len() => {
                let c = centre(points);
                let local: Vec<Point3<f64>> = points.iter().map(|p| Point3::from(p - c)).collect();
                let fit = register_points(nest, &local)?;
                Some(self.frame.tracker_to_base.rotation * fit.transform.rotation)
            }
            _ => None,
        };
        Ok((self.frame.to_base(&centre(points)), orientation))
    }
}

/// The probe's rotation in the flange frame: the rotation mean (the chordal L2 mean, the projection of the
/// summed rotation matrices onto SO(3)) of `F_i⁻¹·T·O_i` over the points.
pub fn probe_rotation(
    frame: &TrackerFrame,
    flanges: &[Isometry3<f64>],
    measured: &[UnitQuaternion<f64>],
) -> Result<UnitQuaternion<f64>> {
    if flanges.len() != measured.len() || measured.is_empty() {
        return Err(Error::Invalid(format!(
            "probe rotation: {} measured orientations for {} flange poses",
            measured.len(),
            flanges.len()
        )));
    }
    let t = frame.tracker_to_base.rotation;
    let sum: Matrix3<f64> = flanges
        .iter()
        .zip(measured)
        .map(|(f, o)| {
            (f.rotation.inverse() * t * o)
                .to_rotation_matrix()
                .into_inner()
        })
        .sum();
    mean_rotation(&sum)
}

/// The rotation nearest (Frobenius) to `sum`, a sum of rotation matrices.
fn mean_rotation(sum: &Matrix3<f64>) -> Result<UnitQuaternion<f64>> {
    let svd = numeric::svd(*sum, true, true, "probe rotation")?;
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return Err(Error::Invalid(
            "probe rotation: SVD returned no basis".into(),
        ));
    };
    let d = (u * v_t).determinant().signum();
    let r = u * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d)) * v_t;
    Ok(UnitQuaternion::from_rotation_matrix(
        &nalgebra::Rotation3::from_matrix_unchecked(r),
    ))
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

/// The mounting alone, for measurements already in the base frame (the frame is the identity): the least-squares
/// `m` of `y_i = F_i·m`, in closed form `m = mean(R_iᵀ (y_i − t_i))`.
pub fn fit_mounting(measured: &[Point3<f64>], flanges: &[Isometry3<f64>]) -> Result<TrackerFrame> {
    if measured.len() != flanges.len() || measured.is_empty() {
        return Err(Error::Invalid(format!(
            "mounting: {} measured points for {} flange poses",
            measured.len(),
            flanges.len()
        )));
    }
    let n = measured.len() as f64;
    let mounting = Point3::from(
        measured
            .iter()
            .zip(flanges)
            .map(|(y, f)| f.inverse_transform_point(y).coords)
            .sum::<Vector3<f64>>()
            / n,
    );
    let rms = (measured
        .iter()
        .zip(flanges)
        .map(|(y, f)| (y - f * mounting).norm_squared())
        .sum::<f64>()
        / n)
        .sqrt();
    if !rms.is_finite() {
        return Err(Error::Invalid("mounting: the points are not finite".into()));
    }
    Ok(TrackerFrame {
        tracker_to_base: Isometry3::identity(),
        mounting,
        rms,
        evaluations: 0,
    })
}

/// Fits the tracker frame and the mounting. `mounting_guess`: the nominal mounting, or the flange origin when
/// unknown (the refinement is linear in the mounting and the translation, so a poor guess costs iterations,
/// not the answer). Needs the flange orientation to vary over the points, or the mounting is not observable.
pub fn fit_tracker_frame(
    measured: &[Point3<f64>],
    flanges: &[Isometry3<f64>],
    mounting_guess: &Point3<f64>,
) -> Result<TrackerFrame> {
    fit_frame(measured, flanges, mounting_guess, None)
}

/// [`fit_tracker_frame`] with the mounting refitted only along `directions` (orthonormal, flange frame) and
/// kept at `mounting` across them: where the flange does not turn about a direction over the points, a
/// mounting offset along it is a shift of the tracker frame and the data cannot tell them apart.
pub fn fit_tracker_frame_along(
    measured: &[Point3<f64>],
    flanges: &[Isometry3<f64>],
    mounting: &Point3<f64>,
    directions: &[Vector3<f64>],
) -> Result<TrackerFrame> {
    fit_frame(measured, flanges, mounting, Some(directions))
}

/// The directions (flange frame, orthonormal) about which the flange turns by at least `min_turn` rad RMS over
/// `flanges`: the mounting components that the points observe. The eigenvectors of
/// `Σ (R_i − R̄)ᵀ(R_i − R̄) / n`, whose eigenvalue is the mean square of how far `R_i·u` moves, about
/// the squared angle for small turns.
pub fn turning_directions(flanges: &[Isometry3<f64>], min_turn: f64) -> Vec<Vector3<f64>> {
    if flanges.is_empty() {
        return Vec::new();
    }
    let rotations: Vec<Matrix3<f64>> = flanges
        .iter()
        .map(|f| f.rotation.to_rotation_matrix().into_inner())
        .collect();
    let mean = rotations.iter().sum::<Matrix3<f64>>() / rotations.len() as f64;
    let spread = rotations
        .iter()
        .map(|r| (r - mean).transpose() * (r - mean))
        .sum::<Matrix3<f64>>()
        / rotations.len() as f64;
    // Non-finite flange poses observe no direction.
    let Ok(eigen) = numeric::symmetric_eigen3(spread, "turning directions") else {
        return Vec::new();
    };
    (0..3)
        .filter(|&k| eigen.eigenvalues[k] >= min_turn * min_turn)
        .map(|k| eigen.eigenvectors.column(k).normalize())
        .collect()
}

fn fit_frame(
    measured: &[Point3<f64>],
    flanges: &[Isometry3<f64>],
    mounting_guess: &Point3<f64>,
    directions: Option<&[Vector3<f64>]>,
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
    let problem = RegistrationProblem {
        measured,
        flanges,
        base_rotation: first.transform.rotation,
        mounting: *mounting_guess,
        directions,
        params: {
            let t = first.transform.translation.vector;
            let mut p = vec![0.0, 0.0, 0.0, t.x, t.y, t.z];
            match directions {
                None => p.extend([mounting_guess.x, mounting_guess.y, mounting_guess.z]),
                Some(d) => p.extend(d.iter().map(|_| 0.0)),
            }
            DVector::from_vec(p)
        },
    };
    let (small, report) = LevenbergMarquardt::new()
        .with_patience(200)
        .minimize(Small::new(problem));
    let problem = small.inner;
    if !report.termination.was_successful() {
        return Err(Error::Invalid(format!(
            "tracker frame: the least-squares refinement failed: {}",
            numeric::stopped(&report.termination)
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

/// Parameters: a rotation vector applied on the left of the closed-form rotation, the translation, the mounting
/// (or, with `directions`, its offsets from `mounting` along them).
struct RegistrationProblem<'a> {
    measured: &'a [Point3<f64>],
    flanges: &'a [Isometry3<f64>],
    base_rotation: UnitQuaternion<f64>,
    mounting: Point3<f64>,
    directions: Option<&'a [Vector3<f64>]>,
    params: DVector<f64>,
}

impl RegistrationProblem<'_> {
    fn unpack(&self) -> (Isometry3<f64>, Point3<f64>) {
        let p = &self.params;
        let rotation =
            UnitQuaternion::from_scaled_axis(Vector3::new(p[0], p[1], p[2])) * self.base_rotation;
        let mounting = match self.directions {
            None => Point3::new(p[6], p[7], p[8]),
            Some(d) => d
                .iter()
                .enumerate()
                .fold(self.mounting, |m, (k, u)| m + u * p[6 + k]),
        };
        (
            Isometry3::from_parts(Translation3::new(p[3], p[4], p[5]), rotation),
            mounting,
        )
    }
}

impl Tall for RegistrationProblem<'_> {
    fn set_params(&mut self, x: &DVector<f64>) {
        self.params.copy_from(x);
    }

    fn params(&self) -> DVector<f64> {
        self.params.clone()
    }

    fn residuals_into(&self, r: &mut DVector<f64>) {
        let (t, m) = self.unpack();
        if r.len() != 3 * self.measured.len() {
            *r = DVector::zeros(3 * self.measured.len());
        }
        for (i, (y, f)) in self.measured.iter().zip(self.flanges).enumerate() {
            r.fixed_rows_mut::<3>(3 * i).copy_from(&(t * y - f * m));
        }
    }

    /// Exact in the translation and mounting; in the rotation, the derivative of a left perturbation at the
    /// current estimate, which is the true one to first order in the (micro-radian) correction. The
    /// translation's and the mounting's columns do not depend on the parameters: written once per buffer.
    fn jacobian_into(&self, j: &mut DMatrix<f64>) {
        let shape = (3 * self.measured.len(), self.params.len());
        if j.shape() != shape {
            *j = DMatrix::zeros(shape.0, shape.1);
            for (i, f) in self.flanges.iter().enumerate() {
                j.fixed_view_mut::<3, 3>(3 * i, 3)
                    .copy_from(&Matrix3::identity());
                let r = f.rotation.to_rotation_matrix().into_inner();
                match self.directions {
                    None => j.fixed_view_mut::<3, 3>(3 * i, 6).copy_from(&(-r)),
                    Some(d) => {
                        for (k, u) in d.iter().enumerate() {
                            j.fixed_view_mut::<3, 1>(3 * i, 6 + k)
                                .copy_from(&(-(r * u)));
                        }
                    }
                }
            }
        }
        let (t, _) = self.unpack();
        for (i, y) in self.measured.iter().enumerate() {
            let v = t.rotation * y.coords;
            j.fixed_view_mut::<3, 3>(3 * i, 0)
                .copy_from(&(-v.cross_matrix()));
        }
    }

    /// Only the rotation's columns move (`jacobian_into`): the products of the others are kept.
    fn gram_into(&self, j: &DMatrix<f64>, g: &mut DMatrix<f64>) {
        gram_rows(j, 3, g);
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

    /// A reused Jacobian buffer, whose constant columns are written once, holds the same bits as a fresh one.
    #[test]
    fn a_reused_jacobian_buffer_is_a_fresh_one() {
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let f = flanges(20, &mut rng);
        let y: Vec<Point3<f64>> = f
            .iter()
            .map(|fi| fi * Point3::new(0.01, 0.0, 0.03))
            .collect();
        let directions = [Vector3::x(), Vector3::z()];
        for directions in [None, Some(&directions[..])] {
            let mut problem = RegistrationProblem {
                measured: &y,
                flanges: &f,
                base_rotation: UnitQuaternion::from_euler_angles(0.1, 0.2, 0.3),
                mounting: Point3::new(0.0, 0.0, 0.03),
                directions,
                params: DVector::from_fn(6 + directions.map_or(3, |d| d.len()), |k, _| {
                    0.01 * k as f64
                }),
            };
            let mut reused = DMatrix::zeros(0, 0);
            problem.jacobian_into(&mut reused);
            let moved = problem.params.map(|p| p + 0.3);
            problem.set_params(&moved);
            problem.jacobian_into(&mut reused);
            let mut fresh = DMatrix::zeros(0, 0);
            problem.jacobian_into(&mut fresh);
            let bits = |m: &DMatrix<f64>| m.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&reused), bits(&fresh));
            assert_eq!(reused.shape(), (60, problem.params.len()));
        }
    }

    #[test]
    fn too_few_points_is_an_error() {
        let mut rng = ChaCha8Rng::seed_from_u64(8);
        let f = flanges(3, &mut rng);
        let y: Vec<Point3<f64>> = f.iter().map(|fi| fi * Point3::origin()).collect();
        assert!(fit_tracker_frame(&y, &f, &Point3::origin()).is_err());
    }
}
