//! The arm in motion (issue 16): the fast path (`TrueRobot::follow`: quasi-static deflection plus the linearised
//! joint vibration about it) against two integrations of the compliant, damped joints' full nonlinear dynamics:
//! the rapier f64 multibody driven along the same path (`MotionReference::follow`) and an f64 Runge–Kutta written
//! here.

use calibench::campaign::trajectory::Path;
use calibench::robot::Frames;
use calibench::robot::inverse_dynamics::{Workspace, inverse_dynamics};
use calibench::scenario::Scenario;
use calibench::truth::robot::Deflection;
use calibench::truth::{PathPoint, TrueRobot, TrueState, motion};
use nalgebra::{DMatrix, DVector, Vector3};

use crate::common::IDEAL_ELASTIC;

/// Rapier's steps (s): its backward Euler is first order in the step (measured: 45.6, 22.8, 11.5 and 5.9 µm from
/// the f64 Runge–Kutta below at 0.1, 0.05, 0.025 and 0.0125 ms), so two runs are extrapolated to a zero step
/// (Richardson), which lands 1.7 µm from it whichever pair is taken.
const RAPIER_DT: [f64; 2] = [1e-4, 5e-5];

/// The step of the independent f64 integration (s): classic Runge–Kutta, 0.13 rad per step at the fastest
/// joint mode (the wrist's, ~2600 rad/s).
const RK4_DT: f64 = 5e-5;

struct Comparison {
    /// Largest flange distance between the fast path and the f64 integration of the full model (m).
    against_f64: f64,
    /// Largest flange distance between the fast path and rapier, extrapolated to a zero step (m).
    against_rapier: f64,
    /// Largest flange distance between the two references: rapier extrapolated and the f64 integration (m).
    references: f64,
    /// Largest flange displacement due to the motion, as the fast path computes it (m).
    dynamic: f64,
    /// Largest flange distance between the motion's quasi-static part alone and the f64 integration (m).
    quasi_static: f64,
}

/// The full flexible-joint model `M(q) q̈ + h(q, q̇) = K (θ − q) + D (θ̇ − q̇)` integrated in f64 by classic
/// Runge–Kutta from the static equilibrium at `times[0]`, with the library's inverse dynamics for M and h (checked
/// on its own in `robot::inverse_dynamics`): the joint angles at `times`.
fn integrate_f64(
    robot: &TrueRobot,
    rest_at: &dyn Fn(f64) -> Vec<f64>,
    times: &[f64],
) -> Vec<Vec<f64>> {
    let n = robot.chain.dof();
    let (k, d) = (&robot.perturbation.stiffness, robot.transmission_damping());
    let mut frames = Frames::new(&robot.chain);
    let mut ws = Workspace::new(&robot.chain);
    let zero = vec![0.0; n];
    let mut accel = |t: f64, q: &[f64], v: &[f64]| -> Vec<f64> {
        let h = 1e-6;
        let (theta, ahead, behind) = (rest_at(t), rest_at(t + h), rest_at(t - h));
        robot.kinematics(q, &[], 1.0, &mut frames);
        let mut bias = vec![0.0; n];
        let g = robot.gravity;
        inverse_dynamics(
            &robot.chain,
            &frames,
            &robot.payload,
            &g,
            v,
            &zero,
            &mut ws,
            &mut bias,
        );
        let mut m = DMatrix::zeros(n, n);
        let mut column = vec![0.0; n];
        for j in 0..n {
            let mut unit = zero.clone();
            unit[j] = 1.0;
            let none = Vector3::zeros();
            inverse_dynamics(
                &robot.chain,
                &frames,
                &robot.payload,
                &none,
                &zero,
                &unit,
                &mut ws,
                &mut column,
            );
            m.set_column(j, &DVector::from_column_slice(&column));
        }
        let force = DVector::from_fn(n, |i, _| {
            let rate = (ahead[i] - behind[i]) / (2.0 * h);
            k[i] * (theta[i] - q[i]) + d[i] * (rate - v[i]) - bias[i]
        });
        m.lu().solve(&force).unwrap().as_slice().to_vec()
    };
    let mut state = TrueState::new(robot);
    state.q0 = rest_at(times[0]);
    robot.deflect(&mut state).unwrap();
    let (mut q, mut v, mut t) = (state.q.clone(), zero.clone(), times[0]);
    let axpy = |x: &[f64], y: &[f64], s: f64| -> Vec<f64> {
        x.iter().zip(y).map(|(a, b)| a + s * b).collect()
    };
    let mut out = Vec::with_capacity(times.len());
    for &target in times {
        while t + 0.5 * RK4_DT < target {
            let h = RK4_DT;
            let a1 = accel(t, &q, &v);
            let (q2, v2) = (axpy(&q, &v, h / 2.0), axpy(&v, &a1, h / 2.0));
            let a2 = accel(t + h / 2.0, &q2, &v2);
            let (q3, v3) = (axpy(&q, &v2, h / 2.0), axpy(&v, &a2, h / 2.0));
            let a3 = accel(t + h / 2.0, &q3, &v3);
            let (q4, v4) = (axpy(&q, &v3, h), axpy(&v, &a3, h));
            let a4 = accel(t + h, &q4, &v4);
            for i in 0..n {
                q[i] += h / 6.0 * (v[i] + 2.0 * v2[i] + 2.0 * v3[i] + v4[i]);
                v[i] += h / 6.0 * (a1[i] + 2.0 * a2[i] + 2.0 * a3[i] + a4[i]);
            }
            t += h;
        }
        out.push(q.clone());
    }
    out
}

/// Along a 3-waypoint move of every joint at `speed` × the limits (acceleration 5 rad/s², the default study's),
/// sampled at 100 Hz through 0.3 s of ringing down after it, the fast path against the references.
fn compare(speed: f64) -> Comparison {
    compare_at(5.0, speed, None, true)
}

/// [`compare`] under the acceleration limit `amax` (rad/s²), the fast path at the integration step `step` (the
/// one [`motion::Resolution::for_peak_acceleration`] gives the path, with its grid, when `None`), against rapier
/// as well when `rapier`.
fn compare_at(amax: f64, speed: f64, step: Option<f64>, rapier: bool) -> Comparison {
    let s = Scenario::parse(IDEAL_ELASTIC, "ideal_elastic.toml").unwrap();
    let world = calibench::app::world(&s).unwrap();
    let start = s.campaign.posture_rad();
    let robot = &world.robot;
    let via: Vec<f64> = start
        .iter()
        .enumerate()
        .map(|(j, q)| q + 0.35 * if j % 2 == 0 { 1.0 } else { -1.0 })
        .collect();
    let end: Vec<f64> = start.iter().map(|q| q + 0.1).collect();
    let vmax: Vec<f64> = world.nominal.joints.iter().map(|j| j.velocity).collect();
    let path = Path::plan(&[start, via, end], &vmax, amax, speed).unwrap();
    let times: Vec<f64> = (0..)
        .map(|k| k as f64 * 0.01)
        .take_while(|t| *t <= path.duration() + 0.3)
        .collect();
    let at = |t: f64| path.at(t);
    let resolution = match step {
        Some(step_s) => motion::Resolution {
            step_s,
            knot_s: motion::KNOT_S,
        },
        None => motion::Resolution::for_peak_acceleration(path.peak_acceleration()),
    };
    let fast = robot.follow_stepped(&at, &times, resolution, None).unwrap();
    let n = world.nominal.dof();
    let rest_at = |t: f64| {
        let mut q0 = vec![0.0; n];
        robot.unloaded_angles(&path.at(t).q, &mut q0);
        q0
    };
    let mut state = TrueState::new(robot);
    let mut flange = |q: Vec<f64>| {
        let tilt = Vec::new();
        robot.reach_with_angles(&Deflection { q, tilt }, 1.0, None, &mut state);
        state.frames.flange.translation.vector
    };
    let reference: Vec<_> = integrate_f64(robot, &rest_at, &times)
        .into_iter()
        .map(&mut flange)
        .collect();
    let [coarse, fine] = RAPIER_DT.map(|dt| {
        if !rapier {
            return reference.clone();
        }
        let mut physics = robot.motion_reference().unwrap();
        let q = physics.follow(robot, &rest_at, &times, dt).unwrap();
        q.into_iter().map(&mut flange).collect::<Vec<_>>()
    });
    let mut quasi = TrueState::new(robot);
    let mut c = Comparison {
        against_f64: 0.0,
        against_rapier: 0.0,
        references: 0.0,
        dynamic: 0.0,
        quasi_static: 0.0,
    };
    for (k, (f, &t)) in fast.iter().zip(&times).enumerate() {
        let x = f.flange.translation.vector;
        c.against_f64 = c.against_f64.max((x - reference[k]).norm());
        let rapier = 2.0 * fine[k] - coarse[k];
        c.against_rapier = c.against_rapier.max((x - rapier).norm());
        c.references = c.references.max((rapier - reference[k]).norm());
        c.dynamic = c.dynamic.max(f.dynamic_m);
        let PathPoint { q, qd, qdd, .. } = path.at(t);
        robot.unloaded_angles(&q, &mut quasi.q0);
        robot.deflect_moving(&mut quasi, Some((&qd, &qdd))).unwrap();
        let missed = (quasi.frames.flange.translation.vector - reference[k]).norm();
        c.quasi_static = c.quasi_static.max(missed);
    }
    c
}

#[test]
fn the_fast_path_agrees_with_rapier_in_motion() {
    let c = compare(1.0);
    eprintln!(
        "full speed: fast path against rapier (f64, extrapolated) {:.2} µm at most, against the f64 Runge–Kutta \
         {:.2} µm (the two references {:.2} µm apart); the quasi-static part alone misses by {:.1} µm, the dynamic \
         deflection is up to {:.1} µm",
        c.against_rapier * 1e6,
        c.against_f64 * 1e6,
        c.references * 1e6,
        c.quasi_static * 1e6,
        c.dynamic * 1e6
    );
    // Issue 16: within 5 µm of rapier's multibody along a path at the default speed (full speed here, the
    // hardest), ringing down included; the two references agree with each other first. The motion must matter
    // for any of this to mean something: the dynamic deflection and what the quasi-static part misses are far
    // above the bound.
    assert!(c.references <= 5e-6, "{} µm", c.references * 1e6);
    assert!(c.against_rapier <= 5e-6, "{} µm", c.against_rapier * 1e6);
    assert!(c.against_f64 <= 5e-6, "{} µm", c.against_f64 * 1e6);
    assert!(c.dynamic > 500e-6, "{} µm", c.dynamic * 1e6);
    assert!(c.quasi_static > 100e-6, "{} µm", c.quasi_static * 1e6);
}

/// A slower path takes a longer integration step and grid ([`motion::Resolution::for_peak_acceleration`]: 2.83
/// ms at half the acceleration, 4 ms at a quarter) and a faster one shorter ones, each within what the fast path
/// misses at full speed with the resolution that was measured there, or within the 5 µm bound where the
/// acceleration is beyond the measured one (at 10 rad/s², 2 ms misses by more than the bound).
#[test]
fn the_step_follows_the_acceleration_at_the_full_speed_accuracy() {
    let full = compare_at(5.0, 1.0, None, false).against_f64;
    let mut lines = vec![format!("full speed, 2 ms: {:.2} µm", full * 1e6)];
    for speed in [0.5, 0.25] {
        let c = compare_at(5.0, speed, None, false);
        lines.push(format!("speed {speed}: {:.2} µm", c.against_f64 * 1e6));
        assert!(c.against_f64 <= full, "{}", lines.join("; "));
    }
    let [fixed, ruled] =
        [Some(motion::MOTION_STEP_S), None].map(|step| compare_at(10.0, 1.0, step, false));
    lines.push(format!(
        "10 rad/s²: {:.2} µm at 2 ms, {:.2} µm at the rule's step",
        fixed.against_f64 * 1e6,
        ruled.against_f64 * 1e6
    ));
    eprintln!("{}", lines.join("; "));
    assert!(
        fixed.against_f64 > 5e-6 && ruled.against_f64 <= 5e-6,
        "{}",
        lines.join("; ")
    );
    let at = motion::Resolution::for_peak_acceleration;
    assert_eq!(at(4.99), motion::Resolution::MEASURED);
    assert!(at(2.49).step_s > 1.4 * motion::MOTION_STEP_S);
    assert_eq!(at(0.86).step_s, 2.0 * motion::MOTION_STEP_S);
    assert_eq!(at(0.86).knot_s, 2.0 * motion::KNOT_S);
    assert!(at(9.98).step_s < 0.71 * motion::MOTION_STEP_S);
}
