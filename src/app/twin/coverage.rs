//! Which gravity torques the pilot loaded each joint with, against those the joint's range can produce.
//!
//! A compliance is identified from how the deflection changes with the torque over the pilot: a constant
//! torque's deflection is indistinguishable from the joint's zero offset, so only the pilot's span of torque
//! tells. Where the pilot spans a narrow band of what the arm can see, the compliance is read off that band and
//! carried beyond it — on a real UR10, a pilot whose shoulder torque ran −93 … −52 Nm gave a compliance twice
//! the one the arm showed over −75 … +89 Nm, and the twin built from it erred by tens of per cent on the
//! configurations outside the band. The twin says so rather than extrapolate silently.

use rand::Rng;

use crate::calib::kinematic::GravityModel;
use crate::error::Result;
use crate::rng::{Stream, derive};
use crate::robot::dh::DhChain;
use crate::robot::{Chain, Payload};

/// Configurations drawn within the joint limits for the span the arm can produce.
const SAMPLES: usize = 4000;

/// A joint whose torque span over its range is below this fraction of the most loaded joint's is not loaded by
/// gravity (a vertical axis, a wrist carrying its mass on its axis): its compliance is not identified anyway.
const LOADED_FRACTION: f64 = 0.01;

/// A pilot spanning less than half of the joint's torque span leaves more of the range outside its band than
/// inside: the compliance's answer there is an extrapolation.
pub const NARROW_FRACTION: f64 = 0.5;

/// One joint's gravity torques (Nm; N for a prismatic joint): over the pilot (its central 90 %) and over the
/// joint limits.
#[derive(Clone, Debug, serde::Serialize)]
pub struct TorqueSpan {
    pub joint: String,
    pub pilot: [f64; 2],
    pub reachable: [f64; 2],
    /// The pilot's span over the reachable one (`None` for a joint gravity does not load).
    pub covered: Option<f64>,
    /// The pilot's mean torque: what a change of this joint's compliance trades against its zero offset.
    pub pilot_mean: f64,
}

impl TorqueSpan {
    /// Whether the pilot's band is narrow against what the joint can see.
    pub fn narrow(&self) -> bool {
        self.covered.is_some_and(|c| c < NARROW_FRACTION)
    }
}

/// The pilot's band is its central 90 %: a pose or two off the band (a home pose) hardly determine a slope.
const PILOT_QUANTILES: [f64; 2] = [0.05, 0.95];

fn span(torques: &[Vec<f64>], j: usize) -> [f64; 2] {
    torques
        .iter()
        .fold([f64::INFINITY, f64::NEG_INFINITY], |[lo, hi], t| {
            [lo.min(t[j]), hi.max(t[j])]
        })
}

fn central(torques: &[Vec<f64>], j: usize) -> [f64; 2] {
    let mut v: Vec<f64> = torques.iter().map(|t| t[j]).collect();
    v.sort_by(f64::total_cmp);
    PILOT_QUANTILES.map(|p| v[((v.len() - 1) as f64 * p).round() as usize])
}

/// Per joint, the gravity torques (of the nominal inertials and the declared payload, as the elastic fit
/// computes them) over the pilot's configurations `q` (the central 90 %; an empty pilot is refused before) and over configurations drawn uniformly within the
/// joint limits (a revolute joint over one turn at most: gravity repeats itself), the pilot's included.
pub fn torque_coverage(
    chain: &Chain,
    dh: &DhChain,
    payload: Payload,
    q: &[Vec<f64>],
    seed: u64,
) -> Result<Vec<TorqueSpan>> {
    let gravity = GravityModel::new(chain, dh, payload)?;
    let (lower, upper) = (chain.lower_limits(), chain.upper_limits());
    let prismatic: Vec<bool> = dh.rows.iter().map(|r| r.prismatic).collect();
    let pilot: Vec<Vec<f64>> = q.iter().map(|q| gravity.torques(dh, q)).collect();
    let mut rng = derive(seed, Stream::Layout, &[u64::MAX - 11]);
    let mut reachable: Vec<Vec<f64>> = (0..SAMPLES)
        .map(|_| {
            let q: Vec<f64> = (0..dh.dof())
                .map(|j| {
                    let lo = lower[j];
                    let hi = if prismatic[j] {
                        upper[j]
                    } else {
                        upper[j].min(lo + std::f64::consts::TAU)
                    };
                    rng.random_range(lo..=hi.max(lo))
                })
                .collect();
            gravity.torques(dh, &q)
        })
        .collect();
    reachable.extend(pilot.iter().cloned());
    let spans: Vec<([f64; 2], [f64; 2])> = (0..dh.dof())
        .map(|j| (central(&pilot, j), span(&reachable, j)))
        .collect();
    let widest = spans.iter().map(|(_, r)| r[1] - r[0]).fold(0.0, f64::max);
    Ok(chain
        .joint_names()
        .into_iter()
        .zip(spans)
        .enumerate()
        .map(|(j, (joint, (p, r)))| {
            let width = r[1] - r[0];
            TorqueSpan {
                joint,
                pilot: p,
                reachable: r,
                covered: (width > LOADED_FRACTION * widest && width > 0.0)
                    .then(|| (p[1] - p[0]) / width),
                pilot_mean: pilot.iter().map(|t| t[j]).sum::<f64>() / pilot.len().max(1) as f64,
            }
        })
        .collect())
}

/// The warning `campaign twin` prints (one line) when the pilot's torque band is narrow on some joint.
pub fn warning(spans: &[TorqueSpan]) -> Option<String> {
    let narrow: Vec<String> = spans
        .iter()
        .filter(|s| s.narrow())
        .map(|s| {
            format!(
                "{} {:.1} … {:.1} Nm of the {:.1} … {:.1} its range can produce ({:.0} %)",
                s.joint,
                s.pilot[0],
                s.pilot[1],
                s.reachable[0],
                s.reachable[1],
                100.0 * s.covered.unwrap_or(0.0)
            )
        })
        .collect();
    (!narrow.is_empty()).then(|| {
        format!(
            "the pilot's gravity torques span a narrow band: {}; the compliances, and so the twin's answer \
             outside the pilot's workspace, are extrapolated there (measure poses that load these joints over \
             more of their range)",
            narrow.join("; ")
        )
    })
}
