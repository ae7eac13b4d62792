//! The clock offset between a tracker and a robot controller, estimated from a campaign measured on the fly.
//!
//! A file pairs each tracker sample (stamped by the tracker's clock) with the joint readings the controller
//! logged at the same stamp by its own clock. If the clocks differ by δ, the arm was at the readings of time
//! t + δ when the tracker saw it at t, and the pair disagrees by the arm's motion over δ — 1 mm per ms at 1 m/s,
//! more than every other error of a calibration. δ is a nuisance parameter: it is estimated first, the joint
//! readings are re-evaluated at t + δ (quadratic interpolation through each sample and its neighbours in time),
//! and every method then fits on the corrected data as on points measured at rest.
//!
//! The estimate minimises the RMS residual of the rigid registration of the nominal kinematics (tracker frame
//! and reflector mounting, [`fit_tracker_frame`]) over δ: a 1-D problem, solved by a grid scan over
//! ±`bound` and Brent's search in the best cell, rather than as one more parameter of every method's
//! Levenberg–Marquardt, because one estimate then serves every method alike (each row is interpolated through
//! the same neighbours in time whatever δ, so the residual is smooth in δ and Brent's parabolic steps converge
//! in a few evaluations; the grid finds the valley first). The nominal model's geometric errors
//! (tenths of a millimetre) do not depend on the motion and move the minimum little; **lost motion does**: each
//! joint lags half its backlash behind the direction it moves in, which shifts the flange along the motion as a
//! clock offset does. Fitted on δ alone, the iiwa's 0.2 mrad of lost motion biased a 3 ms offset by −214 µs at
//! half speed and −378 µs at quarter speed (the bias is lost motion over speed). So near the coarse minimum
//! each joint's lost motion is fitted with δ (linearised, with a small change of the registration): an offset
//! grows with the speed, lost motion does not, and along a path whose speed varies the two separate — 3 ms
//! comes out 2980 µs with or without lost motion in the truth, at either speed (`tests/trajectory.rs`).

use std::cell::RefCell;

use argmin::core::{CostFunction, Executor, State};
use argmin::solver::brent::BrentOpt;
use nalgebra::{DMatrix, Isometry3, Matrix3xX, Point3, Vector3};

use super::rigid::centre;
use super::tracker_frame::{TrackerFrame, fit_tracker_frame};
use crate::dataset::{Dataset, JointRates};
use crate::error::{Error, Result};
use crate::robot::dh::DhChain;
use crate::robot::kinematics::joint_column;

/// The estimated offset and the registration residual it leaves.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClockOffset {
    /// Controller clock minus tracker clock (s).
    pub offset_s: f64,
    /// RMS registration residual of the nominal kinematics at that offset (m).
    pub rms_m: f64,
    /// The same at zero offset (m): how much the offset mattered.
    pub rms_at_zero_m: f64,
}

/// The rows of `data` in time order, and each row's joint readings as a function of a time shift.
struct Timeline<'a> {
    data: &'a Dataset,
    time: &'a [f64],
    /// Row indices sorted by time.
    order: Vec<usize>,
    /// The measured reflector centres, in row order (they do not move with the shift).
    centres: Vec<Point3<f64>>,
}

impl<'a> Timeline<'a> {
    fn of(data: &'a Dataset) -> Result<Timeline<'a>> {
        let time = data.time.as_deref().ok_or_else(|| Error::Data {
            origin: data.origin.clone(),
            message: "no `time` column: the clock offset needs a campaign measured on the fly"
                .into(),
        })?;
        if data.len() < 3 {
            return Err(Error::Data {
                origin: data.origin.clone(),
                message: format!("{} samples: the clock offset needs at least 3", data.len()),
            });
        }
        if let Some(i) = time.iter().position(|t| !t.is_finite()) {
            return Err(Error::Data {
                origin: data.origin.clone(),
                message: format!(
                    "point {}: time {} is not a number",
                    data.point_ids[i], time[i]
                ),
            });
        }
        let mut order: Vec<usize> = (0..data.len()).collect();
        order.sort_by(|&a, &b| time[a].total_cmp(&time[b]));
        if let Some(w) = order.windows(2).find(|w| time[w[0]] == time[w[1]]) {
            return Err(Error::Data {
                origin: data.origin.clone(),
                message: format!(
                    "points {} and {} have the same time {}",
                    data.point_ids[w[0]], data.point_ids[w[1]], time[w[0]]
                ),
            });
        }
        let centres = data.measured.iter().map(|m| centre(m)).collect();
        Ok(Timeline {
            data,
            time,
            order,
            centres,
        })
    }

    /// Joint readings of every row at its time + `shift`, in row order: the quadratic through the row and its
    /// two neighbours in time (the two nearest at either end).
    fn shifted(&self, shift: f64) -> Vec<Vec<f64>> {
        self.shifted_rows(&self.data.q, shift)
    }

    /// Any per-row vectors (`rows`, in row order) re-evaluated the same way.
    fn shifted_rows(&self, rows: &[Vec<f64>], shift: f64) -> Vec<Vec<f64>> {
        let n = self.order.len();
        let mut out = vec![Vec::new(); n];
        for (k, &row) in self.order.iter().enumerate() {
            let mid = k.clamp(1, n - 2);
            let idx = [self.order[mid - 1], self.order[mid], self.order[mid + 1]];
            let ts = idx.map(|i| self.time[i]);
            let t = self.time[row] + shift;
            let w = [
                (t - ts[1]) * (t - ts[2]) / ((ts[0] - ts[1]) * (ts[0] - ts[2])),
                (t - ts[0]) * (t - ts[2]) / ((ts[1] - ts[0]) * (ts[1] - ts[2])),
                (t - ts[0]) * (t - ts[1]) / ((ts[2] - ts[0]) * (ts[2] - ts[1])),
            ];
            let q = rows;
            out[row] = (0..q[row].len())
                .map(|j| w[0] * q[idx[0]][j] + w[1] * q[idx[1]][j] + w[2] * q[idx[2]][j])
                .collect();
        }
        out
    }

    /// The direction each joint moves in at every row (+1, −1, or 0 at rest), from its neighbours in time.
    fn directions(&self) -> Vec<Vec<f64>> {
        let n = self.order.len();
        let q = &self.data.q;
        let mut out = vec![Vec::new(); n];
        for (k, &row) in self.order.iter().enumerate() {
            let (a, b) = (
                self.order[k.saturating_sub(1)],
                self.order[(k + 1).min(n - 1)],
            );
            out[row] = (0..q[row].len())
                .map(|j| {
                    let d = q[b][j] - q[a][j];
                    if d > 0.0 {
                        1.0
                    } else if d < 0.0 {
                        -1.0
                    } else {
                        0.0
                    }
                })
                .collect();
        }
        out
    }

    /// RMS residual (m) of the registration of the nominal kinematics at time shift `shift`; with
    /// `lost_motion`, after also fitting, linearised about that registration, a small change of the tracker
    /// frame and the mounting together with each joint's lost motion (half a band against the direction the
    /// joint moves in, [`crate::truth`]'s model of it).
    fn rms(&self, dh: &DhChain, shift: f64, lost_motion: Option<&LostMotion>) -> Result<f64> {
        let (q, flanges, frame) = self.registration(dh, shift)?;
        let Some(lm) = lost_motion else {
            return Ok(frame.rms);
        };
        let n = q.len();
        let cols = 9 + dh.dof();
        if 3 * n <= cols {
            // As many unknowns as residuals: the fit leaves none.
            return Ok(0.0);
        }
        // Householder QR of [A | r] leaves the least-squares residual of r on A's columns as the last diagonal
        // element of R, without solving for the parameters (which the residual alone does not need).
        let a = self.lost_motion_system(&flanges, &frame, lm);
        let rest = a.qr().r()[(cols, cols)];
        Ok(rest.abs() / (n as f64).sqrt())
    }
}

impl Timeline<'_> {
    /// The joint readings shifted by `shift`, their nominal flange poses and the registration of the nominal
    /// kinematics to the measured centres there.
    fn registration(&self, dh: &DhChain, shift: f64) -> Result<Shifted> {
        let q = self.shifted(shift);
        let fixed = dh.fixed_rotations();
        let flanges: Vec<Isometry3<f64>> =
            q.iter().map(|q| dh.flange_pose_fixed(q, &fixed)).collect();
        let frame = fit_tracker_frame(&self.centres, &flanges, &Point3::origin())?;
        Ok((q, flanges, frame))
    }

    /// The linearised lost-motion fit at a registration, as one matrix `[A | r]` (3n × (9 + dof + 1)): per
    /// row, the tracker frame's small rotation and translation, the mounting, each joint's lost motion, and the
    /// registration's residual.
    fn lost_motion_system(
        &self,
        flanges: &[Isometry3<f64>],
        frame: &TrackerFrame,
        lm: &LostMotion,
    ) -> DMatrix<f64> {
        let centres = &self.centres;
        let (n, dof) = (flanges.len(), lm.direction.first().map_or(0, Vec::len));
        let cols = 9 + dof;
        let mut a = DMatrix::<f64>::zeros(3 * n, cols + 1);
        for i in 0..n {
            let seen = frame.tracker_to_base * centres[i];
            let model = flanges[i] * frame.mounting;
            let e = model - seen;
            let rot = flanges[i].rotation.to_rotation_matrix();
            for k in 0..3 {
                a[(3 * i + k, cols)] = e[k];
                // d(seen): a small rotation ω and translation of the tracker frame.
                let unit = Vector3::ith(k, 1.0);
                let omega_col = unit.cross(&seen.coords);
                for c in 0..3 {
                    a[(3 * i + c, k)] = omega_col[c];
                    a[(3 * i + c, 3 + k)] = unit[c];
                    // −d(model): the mounting.
                    a[(3 * i + c, 6 + k)] = -rot[(c, k)];
                }
            }
            for j in 0..dof {
                let col = lm.jacobian[i].column(j) * (-0.5 * lm.direction[i][j]);
                for c in 0..3 {
                    a[(3 * i + c, 9 + j)] = -col[c];
                }
            }
        }
        a
    }
}

/// The clock-offset grid: shifts −bound + k·step, k = 0..=GRID.
const GRID: usize = 40;

/// The scan's first pass takes every COARSE-th grid point.
const COARSE: usize = 4;
const _: () = assert!(
    GRID.is_multiple_of(COARSE),
    "the coarse pass ends at the grid's last point"
);

/// The grid's best point and what it serves: its readings and mounting (the lost motion's Jacobians) and the
/// residual at zero shift.
struct Scan {
    /// RMS residual, grid index.
    best: (f64, usize),
    /// The best point's shift (s); zero while no residual is finite.
    shift: f64,
    q: Option<Vec<Vec<f64>>>,
    mounting: Option<Point3<f64>>,
    at_zero: Option<f64>,
}

impl Timeline<'_> {
    /// The grid point with the smallest registration residual (the first of equals), found from every
    /// [`COARSE`]-th point, then downhill from the lowest of those between its two neighbours: where the
    /// residual falls and then rises along the grid, as the arm's motion over the shift makes it, the same point
    /// as a scan of all 41, from 12 to 15 registrations (11 coarse). Where the coarse residuals do not fall
    /// strictly then rise strictly (a tie, a non-finite value, two valleys), every point is scanned.
    fn scan(&self, dh: &DhChain, bound_s: f64, step: f64) -> Result<Scan> {
        let mut scan = Scan {
            best: (f64::INFINITY, usize::MAX),
            shift: 0.0,
            q: None,
            mounting: None,
            at_zero: None,
        };
        let mut coarse = Vec::with_capacity(GRID / COARSE + 1);
        let visit = |k: usize, scan: &mut Scan| -> Result<f64> {
            let shift = -bound_s + k as f64 * step;
            let (q, _, frame) = self.registration(dh, shift)?;
            if shift == 0.0 {
                scan.at_zero = Some(frame.rms);
            }
            // In grid order, the first of equals: ties (of finite residuals) go to the lower index.
            let tie = frame.rms == scan.best.0 && frame.rms.is_finite() && k < scan.best.1;
            if frame.rms < scan.best.0 || tie {
                (scan.best, scan.shift) = ((frame.rms, k), shift);
                (scan.q, scan.mounting) = (Some(q), Some(frame.mounting));
            }
            Ok(frame.rms)
        };
        for k in (0..=GRID).step_by(COARSE) {
            coarse.push(visit(k, &mut scan)?);
        }
        let lowest = (0..coarse.len()).fold(0, |b, i| if coarse[i] < coarse[b] { i } else { b });
        let valley = coarse.iter().all(|r| r.is_finite())
            && coarse[..=lowest].windows(2).all(|w| w[0] > w[1])
            && coarse[lowest..].windows(2).all(|w| w[0] < w[1]);
        if !valley {
            for k in (0..=GRID).filter(|k| !k.is_multiple_of(COARSE)) {
                visit(k, &mut scan)?;
            }
            return Ok(scan);
        }
        // Along the valley the grid's lowest point is where the residual stops falling, within COARSE − 1
        // points of the coarse lowest: down to the left while it does not rise (the first of equals), else
        // down to the right while it falls.
        let centre = lowest * COARSE;
        let (mut k, mut low) = (centre, coarse[lowest]);
        while k > centre.saturating_sub(COARSE - 1) {
            let r = visit(k - 1, &mut scan)?;
            if r > low {
                break;
            }
            (k, low) = (k - 1, r);
        }
        if k == centre {
            while k < (centre + COARSE - 1).min(GRID) {
                let r = visit(k + 1, &mut scan)?;
                if r >= low {
                    break;
                }
                (k, low) = (k + 1, r);
            }
        }
        Ok(scan)
    }
}

/// What [`Timeline::registration`] gives: readings, flange poses, registration.
type Shifted = (Vec<Vec<f64>>, Vec<Isometry3<f64>>, TrackerFrame);

/// What the joint lost motion contributes, per row: the position Jacobian of the measured point and the
/// direction each joint moves in.
struct LostMotion {
    jacobian: Vec<Matrix3xX<f64>>,
    direction: Vec<Vec<f64>>,
}

impl LostMotion {
    /// The Jacobians at the shifted readings `q` of `line`, for the mounting of the registration there: each
    /// joint's column from the frames of one pass (axis × lever arm), where central differences took two flange
    /// poses per joint for the same columns within 1e-8 m/rad, their own error.
    fn at(line: &Timeline, dh: &DhChain, q: &[Vec<f64>], mounting: Point3<f64>) -> LostMotion {
        let fixed = dh.fixed_rotations();
        let jacobian = q
            .iter()
            .map(|q| {
                let frames = dh.frames_fixed(q, &fixed);
                let n = q.len();
                let point = frames[n] * dh.tool * mounting;
                let columns: Vec<Vector3<f64>> = (0..n)
                    .map(|j| {
                        let f = &frames[j];
                        let axis = f.rotation * Vector3::z();
                        let anchor = Point3::from(f.translation.vector);
                        joint_column(&axis, &anchor, &point, dh.rows[j].prismatic).0
                    })
                    .collect();
                Matrix3xX::from_columns(&columns)
            })
            .collect();
        LostMotion {
            jacobian,
            direction: line.directions(),
        }
    }
}

/// The clock offset of `data` (a campaign with a `time` column), searched within ±`bound_s`.
pub fn estimate(dh: &DhChain, data: &Dataset, bound_s: f64) -> Result<ClockOffset> {
    if !(bound_s.is_finite() && bound_s > 0.0 && bound_s <= 1.0) {
        return Err(Error::Invalid(format!(
            "clock offset bound {bound_s} s: between 0 and 1 s"
        )));
    }
    let line = Timeline::of(data)?;
    let step = 2.0 * bound_s / GRID as f64;
    let scan = line.scan(dh, bound_s, step)?;
    let best = scan.shift;
    // Lost motion moves the flange along the direction of motion, as a clock offset does; the two differ in
    // that an offset grows with the speed. Near the coarse minimum both are fitted.
    let lost = match (scan.q, scan.mounting) {
        (Some(q), Some(mounting)) => LostMotion::at(&line, dh, &q, mounting),
        // No finite residual on the grid: the registration at zero shift, as before.
        _ => {
            let (q, _, frame) = line.registration(dh, best)?;
            LostMotion::at(&line, dh, &q, frame.mounting)
        }
    };
    let lm = Some(&lost);
    // The mean square (its minimum is the RMS's) is nearly a parabola in the shift near its minimum, where
    // Brent's parabolic steps land within the tolerance in a few evaluations.
    let offset_s = brent(
        |shift| Ok(line.rms(dh, shift, lm)?.powi(2)),
        (best - step, best + step),
        TOLERANCE_S,
    )?;
    Ok(ClockOffset {
        offset_s,
        rms_m: line.rms(dh, offset_s, None)?,
        rms_at_zero_m: match scan.at_zero {
            Some(rms) => rms,
            None => line.rms(dh, 0.0, None)?,
        },
    })
}

/// The search's tolerance (s): it ends with the minimum bracketed within 4 × 0.025 µs = 0.1 µs, as the golden
/// section before it did.
const TOLERANCE_S: f64 = 0.025e-6;

/// Brent's minimisation of `f` on `[a, b]` (Brent 1973, *Algorithms for Minimization without Derivatives*,
/// ch. 5; argmin's `BrentOpt`): a parabola through the three best points where its vertex falls inside the
/// bracket and the step shrinks fast enough, a golden-section step otherwise; until the best point is within
/// `2 tol` of the bracket's middle (the bracket then at most `4 tol` wide). The first error of `f` ends it.
fn brent(f: impl FnMut(f64) -> Result<f64>, (a, b): (f64, f64), tol: f64) -> Result<f64> {
    struct Cost<'a, F> {
        f: RefCell<F>,
        error: &'a RefCell<Option<Error>>,
    }
    impl<F: FnMut(f64) -> Result<f64>> CostFunction for Cost<'_, F> {
        type Param = f64;
        type Output = f64;
        fn cost(&self, x: &f64) -> std::result::Result<f64, argmin::core::Error> {
            (self.f.borrow_mut())(*x).map_err(|e| {
                let message = e.to_string();
                self.error.borrow_mut().get_or_insert(e);
                argmin::core::Error::msg(message)
            })
        }
    }
    let error = RefCell::new(None);
    let cost = Cost {
        f: RefCell::new(f),
        error: &error,
    };
    // The relative tolerance at its floor (√ε · |x| ≈ 5e-11 s at a few milliseconds): `tol` decides.
    let solver = BrentOpt::new(a, b).set_tolerance(f64::EPSILON.sqrt(), tol);
    // A parabolic step must be under half the step before last, which keeps the count within a small multiple
    // of the golden section's (23 from a 5 ms cell to 0.1 µs): 200 bounds it against a non-finite `f`.
    let run = Executor::new(cost, solver)
        .configure(|state| state.max_iters(200))
        .run();
    let best = run.ok().and_then(|r| r.state().get_best_param().copied());
    if let Some(e) = error.take() {
        return Err(e);
    }
    best.ok_or_else(|| {
        Error::Invalid("clock offset: Brent's search found no finite minimum".into())
    })
}

/// `data` with each row's joint readings re-evaluated at its time + `offset_s`: what the arm's controller read
/// when the tracker measured it.
pub fn corrected(data: &Dataset, offset_s: f64) -> Result<Dataset> {
    let timeline = Timeline::of(data)?;
    let q = timeline.shifted(offset_s);
    let mut out = data.clone();
    out.q = q;
    // The commanded rates logged with the readings move with them.
    if let Some(rates) = &data.rates {
        let pick = |f: fn(&JointRates) -> &Vec<f64>| -> Vec<Vec<f64>> {
            timeline.shifted_rows(
                &rates.iter().map(|r| f(r).clone()).collect::<Vec<_>>(),
                offset_s,
            )
        };
        let (qd, qdd) = (pick(|r| &r.qd), pick(|r| &r.qdd));
        out.rates = Some(
            qd.into_iter()
                .zip(qdd)
                .map(|(qd, qdd)| JointRates { qd, qdd })
                .collect(),
        );
    }
    // The nominal columns were computed from the uncorrected readings; they are not the methods' inputs.
    out.nominal_flange = None;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use nalgebra::{Translation3, UnitQuaternion};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::*;
    use crate::robot::urdf;

    /// The iiwa's nominal arm along a smooth path, 30 s sampled at 10 Hz, seen by a tracker (10 µm noise)
    /// whose clock runs `offset_s` behind the controller's.
    fn moving(offset_s: f64) -> (DhChain, Dataset) {
        let chain = urdf::load_file("robots/iiwa7.urdf", None).unwrap();
        let dh = DhChain::from_chain(&chain).unwrap();
        let posture = [0.0, 0.5, 0.0, -1.6, 0.0, -0.5, 0.0];
        let q = |t: f64| -> Vec<f64> {
            (0..7)
                .map(|j| posture[j] + 0.4 * (0.2 * (j + 1) as f64 * t + j as f64).sin())
                .collect()
        };
        let tracker = Isometry3::from_parts(
            Translation3::new(3.0, 0.2, -0.4),
            UnitQuaternion::from_euler_angles(0.02, -0.01, 3.1),
        );
        let mounting = Point3::new(0.001, -0.002, 0.03);
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let time: Vec<f64> = (0..300).map(|k| 0.1 * k as f64).collect();
        let measured = time
            .iter()
            .map(|&t| {
                let noise = Vector3::from_fn(|_, _| rng.random_range(-1e-5..1e-5));
                let seen = tracker.inverse() * (dh.flange_pose(&q(t + offset_s)) * mounting);
                vec![seen + noise]
            })
            .collect();
        let mut data = Dataset::in_memory(
            "moving",
            (1..=7).map(|j| format!("j{j}")).collect(),
            time.iter().map(|&t| q(t)).collect(),
            measured,
        );
        data.time = Some(time);
        (dh, data)
    }

    /// The scan finds the grid point a scan of every point finds, from fewer registrations, and the offset
    /// comes out within 50 µs (issue 16's tolerance; the quadratic interpolation of 10 Hz readings biases it).
    #[test]
    fn the_scan_finds_the_full_grids_best_point() {
        let (dh, data) = moving(0.0123);
        let line = Timeline::of(&data).unwrap();
        let bound = 0.05;
        let step = 2.0 * bound / GRID as f64;
        let every: Vec<f64> = (0..=GRID)
            .map(|k| line.rms(&dh, -bound + k as f64 * step, None).unwrap())
            .collect();
        let first_lowest = (0..=GRID).fold(0, |b, k| if every[k] < every[b] { k } else { b });
        let scan = line.scan(&dh, bound, step).unwrap();
        assert_eq!(scan.best, (every[first_lowest], first_lowest));
        assert_eq!(scan.at_zero, Some(every[GRID / 2]));
        let found = estimate(&dh, &data, bound).unwrap();
        assert!(
            (found.offset_s - 0.0123).abs() < 50e-6,
            "{}",
            found.offset_s
        );
    }

    /// Brent's search ends within its bracket's tolerance of a known minimum, from a few evaluations on a
    /// near-parabola and within the golden section's count on a function no parabola fits (|x − c|).
    #[test]
    fn brents_search_finds_a_known_minimum() {
        let tol = 0.025e-6;
        for (centre, sharp) in [
            (0.003_101_7, false),
            (-0.001_234_5, false),
            (0.000_777, true),
        ] {
            let mut count = 0;
            let found = brent(
                |x| {
                    count += 1;
                    let d = x - centre;
                    Ok(if sharp {
                        d.abs()
                    } else {
                        1e-7 + 0.2 * d * d + 30.0 * d * d * d
                    })
                },
                (centre - 0.0021, centre + 0.0029),
                tol,
            )
            .unwrap();
            assert!(
                (found - centre).abs() <= 4.0 * tol,
                "{found} against {centre}"
            );
            assert!(count <= if sharp { 30 } else { 12 }, "{count} evaluations");
        }
    }

    /// The lost motion's Jacobian (axis × lever arm) is the central difference of the measured point.
    #[test]
    fn the_lost_motions_jacobian_is_the_finite_differences() {
        let (dh, data) = moving(0.003);
        let line = Timeline::of(&data).unwrap();
        let mounting = Point3::new(0.001, -0.002, 0.03);
        let q = &data.q[..20];
        let lm = LostMotion::at(&line, &dh, q, mounting);
        let h = 1e-6;
        for (q, jac) in q.iter().zip(&lm.jacobian) {
            for j in 0..q.len() {
                let at = |dq: f64| {
                    let mut p = q.clone();
                    p[j] += dq;
                    dh.flange_pose(&p) * mounting
                };
                let diff = (at(h) - at(-h)) / (2.0 * h);
                assert!(
                    (jac.column(j) - diff).norm() < 1e-8,
                    "joint {j}: {jac} against {diff}"
                );
            }
        }
    }

    /// The lost-motion fit's residual from the QR of `[A | r]` is the residual of the least-squares solution
    /// by SVD, to rounding.
    #[test]
    fn the_qr_residual_is_the_least_squares_residual() {
        let (dh, data) = moving(0.003);
        let line = Timeline::of(&data).unwrap();
        let (q, _, frame) = line.registration(&dh, 0.003).unwrap();
        let lm = LostMotion::at(&line, &dh, &q, frame.mounting);
        for shift in [0.0025, 0.003, 0.0041] {
            let (_, flanges, frame) = line.registration(&dh, shift).unwrap();
            let system = line.lost_motion_system(&flanges, &frame, &lm);
            let cols = system.ncols() - 1;
            let (a, r) = (system.columns(0, cols).into_owned(), system.column(cols));
            let x = a.clone().svd(true, true).solve(&r, 1e-12).unwrap();
            let by_svd = ((r - a * x).norm_squared() / flanges.len() as f64).sqrt();
            let by_qr = line.rms(&dh, shift, Some(&lm)).unwrap();
            assert!(
                (by_qr - by_svd).abs() <= 1e-9 * by_svd,
                "{shift}: {by_qr} against {by_svd}"
            );
        }
    }
}
