//! What a reach depends on besides its command: the arm's history. Lost motion makes a joint's error depend on
//! the direction it last moved in, and the links' temperature on when in the campaign a point was measured; so
//! the order in which a campaign visits its points is part of the campaign.

use super::perturbation::Perturbation;

/// The history of one reach.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Visit {
    /// The direction each joint last moved in (+1 or −1), one per joint; empty: unknown, no lost motion
    /// (the middle of the hysteresis band).
    pub direction: Vec<f64>,
    /// Temperature of the links (°C); `None`: the reference temperature (nominal lengths).
    pub temperature: Option<f64>,
}

/// A joint that has not moved yet is taken to have arrived moving in the positive direction.
const FIRST_DIRECTION: f64 = 1.0;

/// The direction of each joint's motion from `from` to `to`, where a joint that does not move keeps `previous`.
fn step(from: &[f64], to: &[f64], previous: &[f64]) -> Vec<f64> {
    from.iter()
        .zip(to)
        .zip(previous)
        .map(|((a, b), &p)| {
            if b > a {
                1.0
            } else if b < a {
                -1.0
            } else {
                p
            }
        })
        .collect()
}

/// The visits of a campaign that goes from `start` (its posture) through `commands` in order: each joint's
/// direction is the sign of its last change of command, and the temperature that of the point's place in the
/// sequence (when the robot has a thermal profile). Any sequence — a simulated campaign, a replayed real one —
/// gets its history this way.
pub fn sequence<'a>(
    perturbation: &Perturbation,
    start: &[f64],
    commands: impl IntoIterator<Item = &'a [f64]>,
) -> Vec<Visit> {
    sequence_at(perturbation, start, commands, Some(0.0))
}

/// [`sequence`] begun `start_s` seconds into the thermal profile (the arm has run that long before the first
/// point); `None`: the arm warm, every point at the profile's end temperature (the arm in use).
pub fn sequence_at<'a>(
    perturbation: &Perturbation,
    start: &[f64],
    commands: impl IntoIterator<Item = &'a [f64]>,
    start_s: Option<f64>,
) -> Vec<Visit> {
    let mut previous_q = start.to_vec();
    let mut direction = vec![FIRST_DIRECTION; start.len()];
    commands
        .into_iter()
        .enumerate()
        .map(|(k, q)| {
            direction = step(&previous_q, q, &direction);
            previous_q.clear();
            previous_q.extend_from_slice(q);
            Visit {
                direction: direction.clone(),
                temperature: perturbation.thermal.as_ref().map(|t| match start_s {
                    Some(s) => t.temperature_at(s + k as f64 * t.seconds_per_point),
                    None => t.end_c,
                }),
            }
        })
        .collect()
}

/// How an evaluation pose is reached: straight from `from` (the campaign's posture), each joint moving
/// toward its command, the links at the end temperature of the warm-up (the arm in use).
pub fn approach(perturbation: &Perturbation, from: &[f64], q: &[f64]) -> Visit {
    Visit {
        direction: step(from, q, &vec![FIRST_DIRECTION; q.len()]),
        temperature: perturbation.thermal.as_ref().map(|t| t.end_c),
    }
}
