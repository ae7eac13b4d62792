//! How finely the true arm in motion ([`super::motion`]) is resolved in path time: the integration's step, the
//! grid of exact quasi-static solves and the linearisations on it, as measured on a full-speed move, and the same
//! for a path of any acceleration ([`Resolution::for_peak_acceleration`]).

/// The longest step of the deflection's integration (s). The slowest modes of an arm's joints (11–14 Hz for
/// the iiwa) are then resolved to 0.2 % in frequency by the trapezoidal rule; the fast ones (the wrist's, up to
/// ~400 Hz) are barely excited by a smooth path and stay near their quasi-static answer. Measured in
/// `tests/motion.rs` against an f64 integration of the full model, with δ_s and the matrices taken as below:
/// 1.71 µm at most at 2 ms (the two references are 1.68 µm apart), nearly all of it the trapezoidal rule's own
/// error, second order in the step: 3.33 ms missed by 4.8 µm, 4 ms by 5.96 µm (docs/speed.md).
pub const MOTION_STEP_S: f64 = 2e-3;

/// The largest commanded joint acceleration (rad/s²) of the move [`MOTION_STEP_S`] was measured on:
/// `tests/motion.rs`'s, at full speed under the default study's limit of 5 rad/s².
pub const STEP_ACCELERATION_RAD_S2: f64 = 5.0;

/// The walk's resolution in path time: the integration's longest step and the spacing of the grid's exact
/// quasi-static solves (the linearisations every [`RELINEARIZE_KNOTS`] of them).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Resolution {
    pub step_s: f64,
    pub knot_s: f64,
}

impl Resolution {
    /// [`MOTION_STEP_S`] and [`KNOT_S`], as measured.
    pub const MEASURED: Resolution = Resolution {
        step_s: MOTION_STEP_S,
        knot_s: KNOT_S,
    };

    /// For a path whose commanded joint accelerations reach `peak` (rad/s²) at most: [`Resolution::MEASURED`]
    /// × √2 for each halving of the acceleration below [`STEP_ACCELERATION_RAD_S2`] (at most two: a 4 ms step),
    /// ÷ √2 for each doubling above it (at most four: 0.5 ms); a path within (½, 1] of it takes the measured
    /// resolution itself.
    ///
    /// Why √2: under the joints' velocity and acceleration limits scaled alike, a path whose accelerations are k²
    /// times smaller runs k times slower in time, whether its legs are bound by the velocity limits (k times
    /// slower rates) or by the acceleration limit: time runs √(5 rad/s² / peak) times slower along it. The grid
    /// of quasi-static solves follows the path's own time scale (δ_s is the path's torque through the springs;
    /// the gear's wave too moves with the joints' rates). The integration's error is second order in the step
    /// and grows with the dynamic deflection the accelerations drive, so h²·peak held at most at its measured
    /// value holds it near the measured one. Measured in `tests/motion.rs` (the flange against the f64
    /// Runge–Kutta, docs/speed.md):
    ///
    /// | move | measured resolution | this one |
    /// |---|---:|---:|
    /// | a quarter of the acceleration (speed 0.25) | 0.13 µm | 0.41 µm (4 ms, 20 ms) |
    /// | half (speed 0.5) | 0.64 µm | 1.17 µm (2.83 ms, 14.1 ms) |
    /// | full speed | 1.71 µm | 1.71 µm (2 ms, 10 ms) |
    /// | twice (10 rad/s²) | 5.29 µm | 2.75 µm (1.41 ms, 7.1 ms) |
    ///
    /// Above the measured acceleration the error grows faster than the rule assumes (the linearisation about
    /// the quasi-static state misses more of a larger dynamic deflection), so the shorter steps there hold it
    /// within the 5 µm bound, not at 1.71 µm.
    pub fn for_peak_acceleration(peak: f64) -> Resolution {
        let halvings = (STEP_ACCELERATION_RAD_S2 / peak).log2().floor();
        if halvings.is_nan() {
            return Resolution::MEASURED;
        }
        let dilation = 2f64.powf(halvings.clamp(-4.0, 2.0) / 2.0);
        Resolution {
            step_s: MOTION_STEP_S * dilation,
            knot_s: KNOT_S * dilation,
        }
    }
}

/// The spacing of the exact quasi-static solves (s): [`TrueRobot::deflect_moving`] runs on the grid k · KNOT_S
/// of path time and at every sample; the integration's nodes between take δ_s from the cubic through the four
/// nearest grid solves. Within a path's quintic segment the command's acceleration is a cubic in time and δ_s
/// (the inverse-dynamics torque through the springs) is smooth; where it is not, the nodes solve exactly: the
/// command's accelerations miss the same cubic by more than [`ACCELERATION_TOL`] (a waypoint, where the jerk
/// jumps, or the path's ends), a joint reverses (lost motion moves θ and the torque with it) or a spring's torque
/// changes segment of its soft-zone curve between the four solves.
///
/// [`TrueRobot::deflect_moving`]: super::robot::TrueRobot::deflect_moving
/// [`ACCELERATION_TOL`]: super::motion::ACCELERATION_TOL
/// Measured (see docs/speed.md): the cubic misses
/// the exact δ_s by 1.4e-9 rad at most along `tests/motion.rs`'s move, 2.3e-7 rad along a full-speed path of the
/// default scenario (its gear's wave at 160 and 320 cycles a turn, faster than the grid); 20 ms knots gave
/// 2.2e-8 and 3.6e-7 rad for no less work (more nodes fall back to exact solves).
pub const KNOT_S: f64 = 0.01;

/// How far apart (in [`KNOT_S`] grid steps) the mass matrix and the torque's sensitivities are computed at the
/// grid's solves; the nodes between take them interpolated linearly in time. They change with the posture, a
/// few per cent over 20 ms at full speed, and only the small dynamic remainder depends on them. In
/// `tests/motion.rs` (flange against rapier / the f64 Runge–Kutta): 40 ms 2.13 / 1.71 µm, 80 ms 2.70 / 2.22 µm,
/// 160 ms 5.08 / 4.61 µm; holding each for 20 ms instead, as before, gave 3.42 / 2.99 µm.
pub const RELINEARIZE_KNOTS: i64 = 4;

/// [`RELINEARIZE_KNOTS`] in seconds of path.
pub const RELINEARIZE_S: f64 = KNOT_S * RELINEARIZE_KNOTS as f64;
