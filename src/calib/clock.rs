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
//! ±`bound` and a golden-section search in the best cell, rather than as one more parameter of every method's
//! Levenberg–Marquardt, because the residual is not differentiable in δ where the interpolation switches
//! neighbours, and because one estimate then serves every method alike. The nominal model's geometric errors
//! (tenths of a millimetre) do not depend on the motion and move the minimum little; **lost motion does**: each
//! joint lags half its backlash behind the direction it moves in, which shifts the flange along the motion as a
//! clock offset does. Fitted on δ alone, the iiwa's 0.2 mrad of lost motion biased a 3 ms offset by −214 µs at
//! half speed and −378 µs at quarter speed (the bias is lost motion over speed). So near the coarse minimum
//! each joint's lost motion is fitted with δ (linearised, with a small change of the registration): an offset
//! grows with the speed, lost motion does not, and along a path whose speed varies the two separate — 3 ms
//! comes out 2980 µs with or without lost motion in the truth, at either speed (`tests/trajectory.rs`).

use nalgebra::{DMatrix, DVector, Isometry3, Matrix3xX, Point3, Vector3};

use super::rigid::centre;
use super::tracker_frame::{TrackerFrame, fit_tracker_frame};
use crate::dataset::{Dataset, JointRates};
use crate::error::{Error, Result};
use crate::robot::dh::DhChain;

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
        let centres = &self.centres;
        let n = q.len();
        let dof = dh.dof();
        let cols = 9 + dof;
        let mut a = DMatrix::<f64>::zeros(3 * n, cols);
        let mut r = DVector::<f64>::zeros(3 * n);
        for i in 0..n {
            let seen = frame.tracker_to_base * centres[i];
            let model = flanges[i] * frame.mounting;
            let e = model - seen;
            let rot = flanges[i].rotation.to_rotation_matrix();
            for k in 0..3 {
                r[3 * i + k] = e[k];
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
        let x = a
            .clone()
            .svd(true, true)
            .solve(&r, 1e-12)
            .map_err(|e| Error::Invalid(format!("clock offset: {e}")))?;
        let rest = r - a * x;
        Ok((rest.norm_squared() / n as f64).sqrt())
    }
}

impl Timeline<'_> {
    /// The joint readings shifted by `shift`, their nominal flange poses and the registration of the nominal
    /// kinematics to the measured centres there.
    fn registration(&self, dh: &DhChain, shift: f64) -> Result<Shifted> {
        let q = self.shifted(shift);
        let flanges: Vec<Isometry3<f64>> = q.iter().map(|q| dh.flange_pose(q)).collect();
        let frame = fit_tracker_frame(&self.centres, &flanges, &Point3::origin())?;
        Ok((q, flanges, frame))
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
    /// Finite-difference Jacobians at the shifted readings `q` of `line`, for the mounting of the registration
    /// there.
    fn at(line: &Timeline, dh: &DhChain, q: &[Vec<f64>], mounting: Point3<f64>) -> LostMotion {
        let h = 1e-6;
        let jacobian = q
            .iter()
            .map(|q| {
                let mut jac = Matrix3xX::zeros(q.len());
                let mut p = q.clone();
                for j in 0..q.len() {
                    p[j] = q[j] + h;
                    let plus = dh.flange_pose(&p) * mounting;
                    p[j] = q[j] - h;
                    let minus = dh.flange_pose(&p) * mounting;
                    p[j] = q[j];
                    jac.set_column(j, &((plus - minus) / (2.0 * h)));
                }
                jac
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
    const GRID: usize = 40;
    let step = 2.0 * bound_s / GRID as f64;
    let mut best = (f64::INFINITY, 0.0);
    // The grid's best registration serves the lost motion's Jacobians, and its point at zero (if it has one)
    // the residual at zero: the same computations, not repeated.
    let (mut best_q, mut best_mounting, mut at_zero) = (None, None, None);
    for k in 0..=GRID {
        let shift = -bound_s + k as f64 * step;
        let (q, _, frame) = line.registration(dh, shift)?;
        if shift == 0.0 {
            at_zero = Some(frame.rms);
        }
        if frame.rms < best.0 {
            best = (frame.rms, shift);
            (best_q, best_mounting) = (Some(q), Some(frame.mounting));
        }
    }
    // Lost motion moves the flange along the direction of motion, as a clock offset does; the two differ in
    // that an offset grows with the speed. Near the coarse minimum both are fitted.
    let lost = match (best_q, best_mounting) {
        (Some(q), Some(mounting)) => LostMotion::at(&line, dh, &q, mounting),
        // No finite residual on the grid: the registration at its first shift, as before.
        _ => {
            let (q, _, frame) = line.registration(dh, best.1)?;
            LostMotion::at(&line, dh, &q, frame.mounting)
        }
    };
    let lm = Some(&lost);
    // Golden section in the best cell and its neighbours, to 0.1 µs.
    let (mut a, mut b) = (best.1 - step, best.1 + step);
    let g = (5f64.sqrt() - 1.0) / 2.0;
    let (mut c, mut d) = (b - g * (b - a), a + g * (b - a));
    let (mut fc, mut fd) = (line.rms(dh, c, lm)?, line.rms(dh, d, lm)?);
    while b - a > 1e-7 {
        if fc < fd {
            (b, d, fd) = (d, c, fc);
            c = b - g * (b - a);
            fc = line.rms(dh, c, lm)?;
        } else {
            (a, c, fc) = (c, d, fd);
            d = a + g * (b - a);
            fd = line.rms(dh, d, lm)?;
        }
    }
    let offset_s = 0.5 * (a + b);
    Ok(ClockOffset {
        offset_s,
        rms_m: line.rms(dh, offset_s, None)?,
        rms_at_zero_m: match at_zero {
            Some(rms) => rms,
            None => line.rms(dh, 0.0, None)?,
        },
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
