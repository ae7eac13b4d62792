//! What the measurement itself leaves, per region: the tracker's noise on one measured point and the arm's
//! repeatability at the flange. The answer states them beside the targets: a target below the repeatability
//! cannot be held in use whatever the calibration (the ground truth of the study is noise-free), and one below
//! the tracker's noise is reached only on average, never verified point by point.

use nalgebra::Point3;
use serde::{Deserialize, Serialize};

use crate::campaign::Campaign;
use crate::robot::kinematics::{Frames, forward_kinematics, point_jacobian};
use crate::world::World;

/// The mean length of a 3-D Gaussian error whose per-axis RMS is σ, divided by σ: 2·√(2/π) (exact when the
/// error is isotropic, the approximation used for both limits).
const MEAN_NORM_PER_SIGMA: f64 = 1.595_769_121_605_730_8;

/// The limits of one region, over its test set (m).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Limits {
    pub region: String,
    /// Mean 3-D length of the tracker's random error on one point.
    pub tracker_noise_mean: f64,
    /// Mean 3-D length of the flange displacement from the joints' repeatability.
    pub repeatability_mean: f64,
}

impl Limits {
    /// The limits at the measured points of `campaign` (the region's test set).
    pub fn of(world: &World, region: &str, campaign: &Campaign) -> Limits {
        let chain = &world.nominal;
        let sigma_q = world.robot.perturbation.repeatability_rad;
        let mut frames = Frames::new(chain);
        let local = world
            .mounting
            .nominal
            .first()
            .copied()
            .unwrap_or_else(Point3::origin);
        let (mut noise, mut repeat, mut count) = (0.0, 0.0, 0usize);
        for p in &campaign.points {
            let Some(in_tracker) = p.true_in_tracker.first() else {
                continue;
            };
            noise += world.tracker.noise_at(&(world.tracker.pose * in_tracker));
            forward_kinematics(chain, &p.q_cmd, &mut frames);
            let at = frames.flange * local;
            let j = point_jacobian(chain, &frames, &at);
            // Per-axis RMS of J δq with δq ~ N(0, σ² I): σ √(trace(J_v J_vᵀ) / 3).
            let trace = j.rows(0, 3).iter().map(|v| v * v).sum::<f64>();
            repeat += sigma_q * (trace / 3.0).sqrt();
            count += 1;
        }
        let mean = |sum: f64| {
            if count == 0 {
                0.0
            } else {
                MEAN_NORM_PER_SIGMA * sum / count as f64
            }
        };
        Limits {
            region: region.to_string(),
            tracker_noise_mean: mean(noise),
            repeatability_mean: mean(repeat),
        }
    }
}
