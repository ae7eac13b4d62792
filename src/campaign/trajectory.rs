//! Measuring on the fly: a smooth joint-space path through the campaign's planned targets, timed under the
//! robot's joint limits, executed by the true arm in motion ([`crate::truth::motion`]) and sampled by the tracker
//! as it moves.
//!
//! The path is one quintic Hermite segment per pair of consecutive waypoints (the campaign's posture, then its
//! targets in visiting order), with zero acceleration and a via velocity at every target: the arm passes through
//! the targets without stopping, and position, velocity and acceleration are continuous. A via velocity is the
//! mean of the two neighbouring segments' mean velocities, or zero for a joint that turns back there (no
//! overshoot). Each segment's duration starts from the rest-to-rest quintic's peak velocity (15/8 of the mean)
//! and acceleration (10/√3 Δ/T²) at `speed` × the limits and is stretched until the sampled peaks respect them.
//!
//! The tracker samples at `sample_rate_hz`; its samples are stamped by its own clock, the controller logs its
//! joint readings by its own. A file pairs each tracker sample with the joint readings logged at the same stamp,
//! so a clock offset δ between the two makes the pair disagree by the arm's motion over δ (1 ms at 1 m/s is 1 mm);
//! timestamp jitter adds a random part of the same kind, which grows with speed as a tracker's dynamic error
//! does. `measurements.csv` gains a `time` column (tracker clock, s); every `keep_every`-th sample is kept.

use nalgebra::Point3;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

use super::config::TrajectoryConfig;
use super::points::{BEAM_END_CLEARANCE_M, Campaign, CampaignPoint, Visited};
use crate::error::{Error, Result};
use crate::rng::{Stream, derive};
use crate::robot::collision::CollisionModel;
use crate::robot::{Frames, JointRates, forward_kinematics};
use crate::truth::{Command, MotionSample, PathPoint, motion};
use crate::world::World;

/// The most samples a trajectory campaign keeps: the same bound as a region's point count.
pub const MAX_SAMPLES: usize = 1_000_000;

/// One quintic segment from `q0` to `q1` with end velocities `v0`, `v1` and zero end accelerations.
#[derive(Clone, Debug)]
struct Segment {
    start: f64,
    duration: f64,
    q0: Vec<f64>,
    q1: Vec<f64>,
    v0: Vec<f64>,
    v1: Vec<f64>,
}

/// The quintic Hermite basis at `s` ∈ [0, 1] of a segment, and its first and second derivatives: the same for
/// every joint, so computed once per sample.
struct Basis {
    h: [f64; 4],
    d: [f64; 3],
    dd: [f64; 3],
}

impl Basis {
    fn at(s: f64) -> Basis {
        let (s2, s3, s4, s5) = (s * s, s * s * s, s.powi(4), s.powi(5));
        Basis {
            h: [
                1.0 - 10.0 * s3 + 15.0 * s4 - 6.0 * s5,
                s - 6.0 * s3 + 8.0 * s4 - 3.0 * s5,
                -4.0 * s3 + 7.0 * s4 - 3.0 * s5,
                10.0 * s3 - 15.0 * s4 + 6.0 * s5,
            ],
            d: [
                -30.0 * s2 + 60.0 * s3 - 30.0 * s4,
                1.0 - 18.0 * s2 + 32.0 * s3 - 15.0 * s4,
                -12.0 * s2 + 28.0 * s3 - 15.0 * s4,
            ],
            dd: [
                -60.0 * s + 180.0 * s2 - 120.0 * s3,
                -36.0 * s + 96.0 * s2 - 60.0 * s3,
                -24.0 * s + 84.0 * s2 - 60.0 * s3,
            ],
        }
    }
}

impl Segment {
    /// Angle, velocity and acceleration of joint `j` at `s` ∈ [0, 1] of the segment.
    fn eval(&self, j: usize, s: f64) -> (f64, f64, f64) {
        self.eval_with(j, &Basis::at(s))
    }

    /// [`Segment::eval`] with the basis at its `s`.
    fn eval_with(&self, j: usize, b: &Basis) -> (f64, f64, f64) {
        let t = self.duration;
        let (p0, p1, v0, v1) = (self.q0[j], self.q1[j], self.v0[j], self.v1[j]);
        let [h0, h1, h4, h5] = b.h;
        let [d0, d1, d4] = b.d;
        let [dd0, dd1, dd4] = b.dd;
        (
            p0 * h0 + p1 * h5 + t * (v0 * h1 + v1 * h4),
            (p1 - p0) * (-d0) / t + v0 * d1 + v1 * d4,
            (p1 - p0) * (-dd0) / (t * t) + (v0 * dd1 + v1 * dd4) / t,
        )
    }
}

/// How many equal parts of each segment [`Path::plan`] checks the velocity and acceleration limits at the ends
/// of (and [`Path::peak_acceleration`] reads the accelerations at).
const CHECKS_PER_SEGMENT: usize = 40;

/// A timed joint-space path through waypoints.
#[derive(Clone, Debug)]
pub struct Path {
    segments: Vec<Segment>,
}

impl Path {
    /// The path through `waypoints` (at least two) at `speed` × the velocity limits `vmax` (rad/s, per joint)
    /// and the acceleration limit `amax` (rad/s²).
    pub fn plan(waypoints: &[Vec<f64>], vmax: &[f64], amax: f64, speed: f64) -> Result<Path> {
        if waypoints.len() < 2 {
            return Err(Error::Invalid(
                "a trajectory needs at least two waypoints".into(),
            ));
        }
        let n = vmax.len();
        let (vlim, alim): (Vec<f64>, f64) =
            (vmax.iter().map(|v| v * speed).collect(), amax * speed);
        let mut durations: Vec<f64> = waypoints
            .windows(2)
            .map(|w| {
                (0..n)
                    .map(|j| {
                        let d = (w[1][j] - w[0][j]).abs();
                        (1.875 * d / vlim[j]).max((5.7735 * d / alim).sqrt())
                    })
                    .fold(1e-3, f64::max)
            })
            .collect();
        for _ in 0..30 {
            let path = Path::with(waypoints, &durations);
            let mut stretched = false;
            for (k, seg) in path.segments.iter().enumerate() {
                let mut ratio: f64 = 1.0;
                for step in 0..=CHECKS_PER_SEGMENT {
                    let s = step as f64 / CHECKS_PER_SEGMENT as f64;
                    for (j, vl) in vlim.iter().enumerate() {
                        let (_, v, a) = seg.eval(j, s);
                        ratio = ratio.max(v.abs() / vl).max((a.abs() / alim).sqrt());
                    }
                }
                if ratio > 1.0 + 1e-9 {
                    durations[k] *= ratio * 1.01;
                    stretched = true;
                }
            }
            if !stretched {
                return Ok(path);
            }
        }
        Ok(Path::with(waypoints, &durations))
    }

    fn with(waypoints: &[Vec<f64>], durations: &[f64]) -> Path {
        let n = waypoints[0].len();
        let m = waypoints.len();
        let via = |k: usize| -> Vec<f64> {
            if k == 0 || k == m - 1 {
                return vec![0.0; n];
            }
            (0..n)
                .map(|j| {
                    let a = (waypoints[k][j] - waypoints[k - 1][j]) / durations[k - 1];
                    let b = (waypoints[k + 1][j] - waypoints[k][j]) / durations[k];
                    if a * b <= 0.0 { 0.0 } else { 0.5 * (a + b) }
                })
                .collect()
        };
        let mut start = 0.0;
        let segments = (0..m - 1)
            .map(|k| {
                let s = Segment {
                    start,
                    duration: durations[k],
                    q0: waypoints[k].clone(),
                    q1: waypoints[k + 1].clone(),
                    v0: via(k),
                    v1: via(k + 1),
                };
                start += durations[k];
                s
            })
            .collect();
        Path { segments }
    }

    /// The largest commanded joint acceleration along the path (rad/s²), at the points of each segment where
    /// [`Path::plan`] holds the accelerations to their limit ([`CHECKS_PER_SEGMENT`]).
    pub fn peak_acceleration(&self) -> f64 {
        self.segments
            .iter()
            .flat_map(|seg| {
                (0..=CHECKS_PER_SEGMENT).flat_map(move |step| {
                    let basis = Basis::at(step as f64 / CHECKS_PER_SEGMENT as f64);
                    (0..seg.q0.len()).map(move |j| seg.eval_with(j, &basis).2.abs())
                })
            })
            .fold(0.0, f64::max)
    }

    /// Total duration (s).
    pub fn duration(&self) -> f64 {
        self.segments.last().map_or(0.0, |s| s.start + s.duration)
    }

    /// The segment the path is on at time `t` (clamped to the path): segment k ends at waypoint k + 1.
    pub fn segment(&self, t: f64) -> usize {
        let t = t.clamp(0.0, self.duration());
        self.segments
            .partition_point(|s| s.start + s.duration < t)
            .min(self.segments.len() - 1)
    }

    /// The commanded sample at time `t` (clamped to the path).
    pub fn at(&self, t: f64) -> PathPoint {
        let mut p = PathPoint::default();
        self.sample(t, &mut p);
        p
    }
}

impl Command for Path {
    /// [`Path::at`] into `out`'s vectors.
    fn sample(&self, t: f64, out: &mut PathPoint) {
        let t = t.clamp(0.0, self.duration());
        let k = self.segment(t);
        let seg = &self.segments[k];
        let s = ((t - seg.start) / seg.duration).clamp(0.0, 1.0);
        let n = seg.q0.len();
        let basis = Basis::at(s);
        out.t = t;
        for v in [&mut out.q, &mut out.qd, &mut out.qdd] {
            v.resize(n, 0.0);
        }
        for j in 0..n {
            (out.q[j], out.qd[j], out.qdd[j]) = seg.eval_with(j, &basis);
        }
    }
}

/// A campaign measured on the fly, with what it cost and what the motion did.
pub struct TrajectoryCampaign {
    pub campaign: Campaign,
    /// The path's duration: the tracker time the campaign takes (s).
    pub duration_s: f64,
    /// Per kept sample, the flange displacement due to the motion (m).
    pub dynamic_m: Vec<f64>,
    /// Samples the tracker did not record because a reflector faced away from it (outside its acceptance
    /// cone) or a link blocked the beam: the targets were checked when planned, the path between them is not.
    pub lost_acceptance_cone: usize,
    pub lost_line_of_sight: usize,
}

/// Measures `planned` (a stop-and-go campaign's targets, in its visiting order) on the fly in `world`: the path
/// from `posture` through the targets, executed by the true arm, sampled by the tracker. Every draw comes from
/// `seed`.
pub fn measure(
    world: &World,
    planned: &Campaign,
    posture: &[f64],
    config: &TrajectoryConfig,
    seed: u64,
) -> Result<TrajectoryCampaign> {
    config.validate().map_err(Error::Invalid)?;
    let path = path_through(world, planned, posture, config)?;
    let stamps = tracker_stamps(path.duration(), config)?;
    let mut rng = derive(seed, Stream::Measurement, &[u64::MAX, 0]);
    let truth_times = arm_times(&stamps, config, &mut rng)?;
    // The walk's resolution from the path's accelerations: a slower path takes longer steps at the same accuracy.
    let resolution = motion::Resolution::for_peak_acceleration(path.peak_acceleration());
    let moved = world
        .robot
        .follow_stepped(&path, &truth_times, resolution, Some(&mut rng))?;
    let recorded = record(world, planned, &path, &stamps, &moved, &mut rng);
    if recorded.campaign.points.is_empty() {
        return Err(Error::Invalid(format!(
            "trajectory: the tracker lost the beam at every one of the {} samples ({} \
             outside the acceptance cone, {} blocked)",
            moved.len(),
            recorded.lost_acceptance_cone,
            recorded.lost_line_of_sight
        )));
    }
    Ok(recorded)
}

/// The timed path from `posture` through the planned targets, under the joints' velocity limits (1 rad/s where
/// the URDF gives none).
fn path_through(
    world: &World,
    planned: &Campaign,
    posture: &[f64],
    config: &TrajectoryConfig,
) -> Result<Path> {
    let mut waypoints = vec![posture.to_vec()];
    waypoints.extend(planned.points.iter().map(|p| p.q_cmd.clone()));
    let vmax: Vec<f64> = world
        .nominal
        .joints
        .iter()
        .map(|j| {
            if j.velocity.is_finite() {
                j.velocity
            } else {
                1.0
            }
        })
        .collect();
    Path::plan(&waypoints, &vmax, config.acceleration_rad_s2, config.speed)
}

/// The tracker clock's stamps of the kept samples over a path of `duration` seconds; an error above
/// [`MAX_SAMPLES`].
fn tracker_stamps(duration: f64, config: &TrajectoryConfig) -> Result<Vec<f64>> {
    let dt = 1.0 / config.sample_rate_hz;
    let total = (duration / dt).floor() as usize + 1;
    let kept: Vec<usize> = (0..total).step_by(config.keep_every).collect();
    if kept.len() > MAX_SAMPLES {
        return Err(Error::Invalid(format!(
            "trajectory: {} samples kept over {duration:.1} s, above {MAX_SAMPLES}; raise keep_every",
            kept.len()
        )));
    }
    // The tracker stamps sample k at k·dt by its clock.
    Ok(kept.iter().map(|&k| k as f64 * dt).collect())
}

/// The controller times at which the arm was where the tracker saw it at each of `stamps`: the stamp plus the
/// clock offset and the stamp's jitter, drawn from `rng` one per stamp.
fn arm_times(stamps: &[f64], config: &TrajectoryConfig, rng: &mut ChaCha8Rng) -> Result<Vec<f64>> {
    let jitter = Normal::new(0.0, config.jitter_s.max(0.0))
        .map_err(|e| Error::Invalid(format!("trajectory.jitter_s: {e}")))?;
    // The arm was at the tracker's sample k at controller time k·dt + offset.
    Ok(stamps
        .iter()
        .map(|&s| s + config.clock_offset_s + jitter.sample(rng))
        .collect())
}

/// What the tracker records of the arm's motion `moved` at `stamps`: a measured point for every sample where
/// it sees every reflector, with the joint readings the controller logged at the same stamp; the samples
/// where the beam broke are counted, not measured. The measurement noise is drawn from `rng`.
fn record(
    world: &World,
    planned: &Campaign,
    path: &Path,
    stamps: &[f64],
    moved: &[MotionSample],
    rng: &mut ChaCha8Rng,
) -> TrajectoryCampaign {
    let mut frames = Frames::new(&world.nominal);
    let collision = CollisionModel::new(&world.nominal);
    let origin = world.tracker.origin();
    let (mut lost_acceptance_cone, mut lost_line_of_sight) = (0, 0);
    let mut points = Vec::with_capacity(stamps.len());
    let mut dynamic_m = Vec::with_capacity(stamps.len());
    for (k, (s, m)) in stamps.iter().zip(moved).enumerate() {
        let true_reflectors: Vec<Point3<f64>> =
            world.mounting.actual.iter().map(|p| m.flange * p).collect();
        // Where the beam breaks the tracker records nothing (it relocks when the reflector is seen again). The
        // links are placed at the true angles with nominal geometry: a fraction of a millimetre, against the
        // beam's clearance.
        let facing = m.flange.rotation * world.mounting.facing;
        if !true_reflectors
            .iter()
            .all(|p| world.tracker.in_acceptance_cone(p, &facing))
        {
            lost_acceptance_cone += 1;
            continue;
        }
        forward_kinematics(&world.nominal, &m.q, &mut frames);
        if true_reflectors
            .iter()
            .any(|p| collision.segment_blocked(&frames, &origin, p, BEAM_END_CLEARANCE_M))
        {
            lost_line_of_sight += 1;
            continue;
        }
        // The controller logs its commanded angles, velocities and accelerations at its own stamp.
        let PathPoint {
            q: logged, qd, qdd, ..
        } = path.at(*s);
        forward_kinematics(&world.nominal, &logged, &mut frames);
        let visited = Visited {
            id: k,
            // A sample belongs to the region of the target the arm is heading for.
            region: planned.points[path.segment(*s)].region.clone(),
            q_cmd: logged,
            nominal_flange: frames.flange,
            true_flange: m.flange,
            q_true: m.q.clone(),
        };
        points.push(CampaignPoint {
            time: Some(*s),
            rates: Some(JointRates { qd, qdd }),
            ..CampaignPoint::measured(world, visited, rng)
        });
        dynamic_m.push(m.dynamic_m);
    }
    TrajectoryCampaign {
        campaign: Campaign {
            joint_names: planned.joint_names.clone(),
            points,
            rejections: planned.rejections.clone(),
        },
        duration_s: path.duration(),
        dynamic_m,
        lost_acceptance_cone,
        lost_line_of_sight,
    }
}
