//! The `[campaign]` section: how the arm is posed, what stands in its way, how a model-based layout builds and
//! chooses from its pool, and `[campaign.trajectory]` for measuring on the fly. The regions are their own
//! sections ([`super::region`]).

use serde::{Deserialize, Serialize};

use crate::calib::registry::{CLASSICAL, MethodKind};
use crate::robot::collision::Obstacle;

/// The largest candidate pool of a model-based layout, on the same grounds as a region's point cap
/// (`MAX_REGION_POINTS`): every candidate is planned and its identification Jacobian kept.
pub const MAX_POOL: usize = 100_000;

fn default_limit_margin() -> f64 {
    2.0
}

/// How the arm is posed for a campaign, and what stands in its way.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct CampaignConfig {
    /// The posture inverse kinematics starts from and is drawn toward in the null space (deg, per joint).
    /// It fixes the arm's branch (elbow up or down, wrist flip) for the whole campaign.
    pub posture_deg: Vec<f64>,
    /// Per-point random change of the posture target (deg, uniform ±): varies the redundancy (the iiwa's
    /// elbow) within the branch. 0 keeps one redundancy resolution for the whole campaign.
    #[serde(default)]
    pub posture_spread_deg: f64,
    /// Solutions closer than this to a joint limit are rejected (deg).
    #[serde(default = "default_limit_margin")]
    pub limit_margin_deg: f64,
    /// Boxes in the scene the arm must not touch (a table, fixtures), base frame.
    #[serde(default)]
    pub obstacles: Vec<Obstacle>,
    /// How model-based layouts (`d-optimal`) build their candidate pool and choose from it.
    #[serde(default)]
    pub selection: SelectionConfig,
    /// `[campaign.trajectory]`: measure the planned targets on the fly, along one smooth path, instead of
    /// stopping at each ([`super::trajectory`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub trajectory: Option<TrajectoryConfig>,
}

impl CampaignConfig {
    /// The posture in radians: where a campaign starts and what its inverse kinematics is drawn toward.
    pub fn posture_rad(&self) -> Vec<f64> {
        self.posture_deg.iter().map(|d| d.to_radians()).collect()
    }

    pub fn validate(&self) -> std::result::Result<(), String> {
        if self.posture_deg.iter().any(|v| !v.is_finite()) {
            return Err("posture_deg must be finite".into());
        }
        for (name, v) in [
            ("posture_spread_deg", self.posture_spread_deg),
            ("limit_margin_deg", self.limit_margin_deg),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(format!("{name} = {v} must be finite and non-negative"));
            }
        }
        for o in &self.obstacles {
            if !o
                .center
                .iter()
                .chain(&o.half_extents)
                .all(|v| v.is_finite())
                || o.half_extents.iter().any(|h| *h <= 0.0)
            {
                return Err(format!(
                    "obstacle '{}' needs finite centre and positive half_extents",
                    o.name
                ));
            }
        }
        if let Some(t) = &self.trajectory {
            t.validate()?;
        }
        self.selection.validate()
    }
}

/// The candidate pool and the model of a model-based layout. The pool is a uniform layout of
/// `clamp(pool_factor · N, pool_min, pool_max)` targets for N points, planned and measured like any campaign
/// point; the feasible ones are the candidates.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct SelectionConfig {
    /// The method whose parameters the points must determine (`kinematic`, `elastic`, or a paper model).
    pub model: MethodKind,
    pub pool_factor: f64,
    pub pool_min: usize,
    pub pool_max: usize,
    /// Per-candidate random change of the posture target (deg, uniform ±), so that the pool holds several
    /// redundancy resolutions (the iiwa's elbow) and the selection can use them. Replaces
    /// `posture_spread_deg` for the pool when larger.
    pub posture_spread_deg: f64,
    /// Exchange steps of the DETMAX phase at most; absent: twice the number of points.
    pub max_exchanges: Option<usize>,
}

impl Default for SelectionConfig {
    fn default() -> Self {
        SelectionConfig {
            model: CLASSICAL,
            pool_factor: 20.0,
            pool_min: 2000,
            pool_max: 4000,
            posture_spread_deg: 20.0,
            max_exchanges: None,
        }
    }
}

impl SelectionConfig {
    /// Pool targets for a campaign of `n` points (never fewer than `n`).
    pub fn pool(&self, n: usize) -> usize {
        ((self.pool_factor * n as f64).ceil() as usize)
            .clamp(self.pool_min, self.pool_max.max(self.pool_min))
            .max(n)
    }

    /// Checks the model (a method with robot parameters to determine) and the pool.
    pub fn validate(&self) -> std::result::Result<(), String> {
        if !(self.pool_factor.is_finite() && self.pool_factor >= 1.0) {
            return Err(format!(
                "selection.pool_factor = {} must be finite and at least 1",
                self.pool_factor
            ));
        }
        if self.pool_max > MAX_POOL {
            return Err(format!(
                "selection.pool_max = {} exceeds {MAX_POOL}",
                self.pool_max
            ));
        }
        if self.max_exchanges.is_some_and(|m| m > 100 * MAX_POOL) {
            return Err(format!(
                "selection.max_exchanges exceeds {}",
                100 * MAX_POOL
            ));
        }
        if self.pool_max < self.pool_min || self.pool_min == 0 {
            return Err(format!(
                "selection: pool_min = {} must be positive and at most pool_max = {}",
                self.pool_min, self.pool_max
            ));
        }
        if !(self.posture_spread_deg.is_finite() && self.posture_spread_deg >= 0.0) {
            return Err(format!(
                "selection.posture_spread_deg = {} must be finite and non-negative",
                self.posture_spread_deg
            ));
        }
        if !self.model.info().has_robot_parameters() {
            return Err(format!(
                "selection.model = '{}' has no robot parameters to determine; use kinematic, elastic or a \
                 paper model",
                self.model
            ));
        }
        Ok(())
    }
}

/// `[campaign.trajectory]`: measure on the fly instead of stop and go. Magnitudes and their sources in
/// `scenarios/README.md`.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct TrajectoryConfig {
    /// Fraction of every joint's velocity and acceleration limit the path may use, in (0, 1].
    pub speed: f64,
    /// Joint acceleration limit (rad/s², every joint).
    pub acceleration_rad_s2: f64,
    /// The tracker's sample rate (Hz).
    pub sample_rate_hz: f64,
    /// Keep every k-th sample in the campaign (1: all).
    #[serde(default = "one")]
    pub keep_every: usize,
    /// The controller's clock minus the tracker's (s): the joint readings paired with a tracker sample are
    /// those the controller logged `clock_offset_s` before the arm was where the tracker saw it.
    #[serde(default)]
    pub clock_offset_s: f64,
    /// Standard deviation of each sample's timestamp (s).
    #[serde(default)]
    pub jitter_s: f64,
}

fn one() -> usize {
    1
}

impl TrajectoryConfig {
    pub fn validate(&self) -> std::result::Result<(), String> {
        let positive = |v: f64, max: f64, what: &str| {
            if v.is_finite() && v > 0.0 && v <= max {
                Ok(())
            } else {
                Err(format!("trajectory.{what} = {v}: must be in (0, {max}]"))
            }
        };
        positive(self.speed, 1.0, "speed")?;
        positive(self.acceleration_rad_s2, 1e3, "acceleration_rad_s2")?;
        positive(self.sample_rate_hz, 1e5, "sample_rate_hz")?;
        if self.keep_every == 0 {
            return Err("trajectory.keep_every = 0: must be at least 1".into());
        }
        for (what, v) in [
            ("clock_offset_s", self.clock_offset_s),
            ("jitter_s", self.jitter_s),
        ] {
            if !(v.is_finite() && v.abs() <= 1.0) || (what == "jitter_s" && v < 0.0) {
                return Err(format!("trajectory.{what} = {v}: at most 1 s in magnitude"));
            }
        }
        Ok(())
    }
}
