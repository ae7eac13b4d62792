//! The command an arm in motion follows: a joint-space path's samples ([`super::motion`]).

/// One commanded sample of a joint-space path: time (s), angles (rad), velocities (rad/s), accelerations
/// (rad/s²), controller coordinates.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PathPoint {
    pub t: f64,
    pub q: Vec<f64>,
    pub qd: Vec<f64>,
    pub qdd: Vec<f64>,
}

/// A commanded joint-space path (a function of controller time): what [`super::TrueRobot::follow`] walks along.
pub trait Command {
    /// The sample at `t` into `out`, whose vectors it may reuse: the walk asks for one per node.
    fn sample(&self, t: f64, out: &mut PathPoint);
}

impl<F: Fn(f64) -> PathPoint> Command for F {
    fn sample(&self, t: f64, out: &mut PathPoint) {
        *out = self(t);
    }
}
