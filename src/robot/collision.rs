//! Collision geometry of a chain for campaign feasibility: self-collision, world obstacles, and the
//! tracker's line of sight.
//!
//! The shapes are parry's (through rapier's re-export), built once per chain and posed per query from a
//! [`Frames`]. Parry works in f32; to keep its resolution (about 1e-7 m) independent of where the robot stands
//! in the world, every query is expressed in f64 relative to one of the two objects and only that relative pose
//! is rounded to f32.

use nalgebra::{Isometry3, Point3, Vector3};
use rapier3d::parry::math::{Pose, Rot3, Vector};
use rapier3d::parry::query::{Ray, intersection_test};
use rapier3d::parry::shape::SharedShape;
use serde::{Deserialize, Serialize};

use super::chain::{Chain, Shape};
use super::kinematics::{Frames, forward_kinematics};

/// A world-fixed, axis-aligned box (m), such as the table the robot stands on or a fixture in the cell.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Obstacle {
    pub name: String,
    pub center: [f64; 3],
    pub half_extents: [f64; 3],
}

/// A shape whose bounding sphere stays this far from an obstacle's box skips parry's exact test (m): a thousand
/// times the f32 rounding of a pose a few metres out, so the exact test could not have found them touching.
const OBSTACLE_CLEARANCE_M: f64 = 1e-3;

/// One parry shape fixed to a body.
#[derive(Clone)]
struct BodyShape {
    /// Pose in the body frame, with parry's own axis convention already folded in.
    local: Isometry3<f64>,
    shape: SharedShape,
    /// Centre of the shape's bounding sphere in the body frame and its radius: a cheap f64 rejection test
    /// before the exact (and, for cylinders, iterative) parry query.
    bound_center: Point3<f64>,
    bound_radius: f64,
}

/// Parry shapes of every body of a chain, and the body pairs worth testing for self-collision.
#[derive(Clone)]
pub struct CollisionModel {
    bodies: Vec<Vec<BodyShape>>,
    pairs: Vec<(usize, usize)>,
}

impl std::fmt::Debug for CollisionModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CollisionModel")
            .field(
                "shapes_per_body",
                &self.bodies.iter().map(Vec::len).collect::<Vec<_>>(),
            )
            .field("pairs", &self.pairs)
            .finish()
    }
}

fn to_pose(iso: &Isometry3<f64>) -> Pose {
    let t = iso.translation.vector;
    let q = iso.rotation.quaternion();
    Pose::from_parts(
        Vector::new(t.x as f32, t.y as f32, t.z as f32),
        Rot3::from_xyzw(q.i as f32, q.j as f32, q.k as f32, q.w as f32).normalize(),
    )
}

fn to_vector(v: &Vector3<f64>) -> Vector {
    Vector::new(v.x as f32, v.y as f32, v.z as f32)
}

/// Parry shape for one URDF primitive, and the rotation that maps parry's axis onto the URDF one.
fn parry_shape(shape: &Shape) -> (SharedShape, Isometry3<f64>) {
    match *shape {
        // Parry's cylinder is along y, URDF's along z: a quarter turn about x maps y onto z.
        Shape::Cylinder { radius, length } => (
            SharedShape::cylinder((length / 2.0) as f32, radius as f32),
            Isometry3::rotation(Vector3::x() * std::f64::consts::FRAC_PI_2),
        ),
        Shape::Capsule { radius, length } => (
            SharedShape::capsule_z((length / 2.0) as f32, radius as f32),
            Isometry3::identity(),
        ),
        Shape::Sphere { radius } => (SharedShape::ball(radius as f32), Isometry3::identity()),
        Shape::Cuboid { half_extents: h } => (
            SharedShape::cuboid(h[0] as f32, h[1] as f32, h[2] as f32),
            Isometry3::identity(),
        ),
    }
}

impl BodyShape {
    fn new(shape: SharedShape, local: Isometry3<f64>) -> Self {
        let sphere = shape.compute_local_bounding_sphere();
        let c = sphere.center();
        BodyShape {
            bound_center: local * Point3::new(c.x as f64, c.y as f64, c.z as f64),
            bound_radius: sphere.radius() as f64,
            local,
            shape,
        }
    }
}

/// Whether two posed shapes overlap (touching counts), pose of `b` taken relative to `a` in f64.
fn shapes_intersect(
    a: &BodyShape,
    a_world: &Isometry3<f64>,
    b: &BodyShape,
    b_world: &Isometry3<f64>,
) -> bool {
    let ca = a_world * a.bound_center;
    let cb = b_world * b.bound_center;
    let reach = a.bound_radius + b.bound_radius;
    if (ca - cb).norm_squared() > reach * reach * (1.0 + 1e-6) + 1e-12 {
        return false;
    }
    let a_pose = a_world * a.local;
    let b_in_a = a_pose.inv_mul(&(b_world * b.local));
    // Every pair of the primitives above is supported by parry's dispatcher; an unsupported pair (a future
    // shape kind) is reported as a collision so that it can never let an infeasible configuration through.
    intersection_test(
        &Pose::IDENTITY,
        a.shape.as_ref(),
        &to_pose(&b_in_a),
        b.shape.as_ref(),
    )
    .map(|hit| hit.intersecting)
    .unwrap_or(true)
}

impl CollisionModel {
    /// Self-collision pairs: all body pairs except adjacent ones (i, i+1) and any pair already touching at
    /// q = 0. Pairs touching at home are dropped because a URDF whose enclosing primitives overlap there (a
    /// housing reaching past the next joint) would otherwise be "in collision" everywhere; such a pair cannot
    /// be separated by the joints between them in a way the primitives represent faithfully anyway.
    pub fn new(chain: &Chain) -> Self {
        let bodies: Vec<Vec<BodyShape>> = chain
            .bodies
            .iter()
            .map(|body| {
                body.colliders
                    .iter()
                    .map(|c| {
                        let (shape, axis_fix) = parry_shape(&c.shape);
                        BodyShape::new(shape, c.origin * axis_fix)
                    })
                    .collect()
            })
            .collect();

        let mut model = CollisionModel {
            bodies,
            pairs: Vec::new(),
        };
        let mut home = Frames::new(chain);
        forward_kinematics(chain, &vec![0.0; chain.dof()], &mut home);
        let n = model.bodies.len();
        let mut pairs = Vec::new();
        for i in 0..n {
            for j in i + 2..n {
                if model.bodies[i].is_empty() || model.bodies[j].is_empty() {
                    continue;
                }
                if !model.bodies_intersect(&home, i, j) {
                    pairs.push((i, j));
                }
            }
        }
        model.pairs = pairs;
        model
    }

    /// Body pairs tested by [`Self::self_collision`], lower index first.
    pub fn pairs(&self) -> &[(usize, usize)] {
        &self.pairs
    }

    fn bodies_intersect(&self, frames: &Frames, i: usize, j: usize) -> bool {
        let (wi, wj) = (&frames.body[i], &frames.body[j]);
        self.bodies[i].iter().any(|a| {
            self.bodies[j]
                .iter()
                .any(|b| shapes_intersect(a, wi, b, wj))
        })
    }

    /// First colliding body pair, if any, for the configuration in `frames`.
    pub fn self_collision(&self, frames: &Frames) -> Option<(usize, usize)> {
        self.pairs
            .iter()
            .copied()
            .find(|&(i, j)| self.bodies_intersect(frames, i, j))
    }

    /// First body that intersects the obstacle. Body 0 is skipped: the base stands on the table (or is
    /// bolted to the fixture), so it touches by construction.
    pub fn hits_obstacle(&self, frames: &Frames, obstacle: &Obstacle) -> Option<usize> {
        let (h, c) = (obstacle.half_extents, obstacle.center);
        // A table's bounding sphere holds the whole arm, so the pair test's sphere check never rejects; a shape
        // whose own sphere stays clear of the box by far more than parry's f32 resolution is disjoint from it.
        let clear = |s: &BodyShape, body: &Isometry3<f64>| {
            let centre = body * s.bound_center;
            let outside = (0..3)
                .map(|i| ((centre[i] - c[i]).abs() - h[i]).max(0.0).powi(2))
                .sum::<f64>();
            let reach = s.bound_radius + OBSTACLE_CLEARANCE_M;
            outside > reach * reach
        };
        let mut boxed = None;
        (1..self.bodies.len()).find(|&b| {
            self.bodies[b].iter().any(|s| {
                if clear(s, &frames.body[b]) {
                    return false;
                }
                let boxed = boxed.get_or_insert_with(|| {
                    BodyShape::new(
                        SharedShape::cuboid(h[0] as f32, h[1] as f32, h[2] as f32),
                        Isometry3::identity(),
                    )
                });
                let box_world = Isometry3::translation(c[0], c[1], c[2]);
                shapes_intersect(boxed, &box_world, s, &frames.body[b])
            })
        })
    }

    /// Distance along the beam at which it first enters body `b`, within `reach`.
    fn body_entry(
        &self,
        frames: &Frames,
        b: usize,
        from: &Point3<f64>,
        dir: &Vector3<f64>,
        reach: f64,
    ) -> Option<f64> {
        self.bodies[b]
            .iter()
            .filter_map(|s| {
                // Cheap rejection: the bounding sphere against the segment's reach.
                let c = frames.body[b] * s.bound_center;
                let t = (c - from).dot(dir).clamp(0.0, reach);
                if (from + dir * t - c).norm() > s.bound_radius * (1.0 + 1e-6) + 1e-9 {
                    return None;
                }
                let world = frames.body[b] * s.local;
                let o = world.inverse_transform_point(from);
                let v = world.inverse_transform_vector(dir);
                let ray = Ray::new(to_vector(&o.coords), to_vector(&v));
                s.shape
                    .cast_local_ray(&ray, reach as f32, true)
                    .map(f64::from)
            })
            .min_by(f64::total_cmp)
    }

    /// Unit direction and usable length of the beam, or `None` when nothing of it is left to block.
    fn beam(
        from: &Point3<f64>,
        to: &Point3<f64>,
        end_clearance: f64,
    ) -> Option<(Vector3<f64>, f64)> {
        let d = to - from;
        let length = d.norm();
        let reach = length - end_clearance.max(0.0);
        (reach > 0.0 && length.is_finite()).then(|| (d / length, reach))
    }

    /// The body the segment `from` → `to` enters first (nearest `from`), ignoring the last `end_clearance`
    /// metres before `to`: the reflector sits on the flange and its own mount must not block its beam.
    /// A segment starting inside a shape is blocked by that body.
    pub fn segment_hit(
        &self,
        frames: &Frames,
        from: &Point3<f64>,
        to: &Point3<f64>,
        end_clearance: f64,
    ) -> Option<usize> {
        let (dir, reach) = Self::beam(from, to, end_clearance)?;
        (0..self.bodies.len())
            .filter_map(|b| Some((b, self.body_entry(frames, b, from, &dir, reach)?)))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(b, _)| b)
    }

    /// Whether the tracker's beam from `from` to `to` is blocked by the robot; see [`Self::segment_hit`].
    pub fn segment_blocked(
        &self,
        frames: &Frames,
        from: &Point3<f64>,
        to: &Point3<f64>,
        end_clearance: f64,
    ) -> bool {
        Self::beam(from, to, end_clearance).is_some_and(|(dir, reach)| {
            (0..self.bodies.len()).any(|b| self.body_entry(frames, b, from, &dir, reach).is_some())
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Every body against `obstacle` by parry's exact test alone, as before the sphere check.
    fn hits_exactly(model: &CollisionModel, frames: &Frames, obstacle: &Obstacle) -> Option<usize> {
        let (h, c) = (obstacle.half_extents, obstacle.center);
        let boxed = BodyShape::new(
            SharedShape::cuboid(h[0] as f32, h[1] as f32, h[2] as f32),
            Isometry3::identity(),
        );
        let box_world = Isometry3::translation(c[0], c[1], c[2]);
        (1..model.bodies.len()).find(|&b| {
            model.bodies[b]
                .iter()
                .any(|s| shapes_intersect(&boxed, &box_world, s, &frames.body[b]))
        })
    }

    /// The sphere check changes no answer: random iiwa configurations against a table under the base and boxes
    /// placed about the arm, hits and misses both frequent.
    #[test]
    fn obstacle_check_agrees_with_the_exact_test() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("robots/iiwa7.urdf");
        let chain = crate::robot::urdf::load_file(&path, None).expect("robots/iiwa7.urdf loads");
        let model = CollisionModel::new(&chain);
        let mut frames = Frames::new(&chain);
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let (mut hits, mut misses) = (0, 0);
        for k in 0..3000 {
            let q: Vec<f64> = chain
                .joints
                .iter()
                .map(|j| rng.random_range(j.lower..=j.upper))
                .collect();
            forward_kinematics(&chain, &q, &mut frames);
            let obstacle = if k % 2 == 0 {
                Obstacle {
                    name: "table".into(),
                    center: [0.0, 0.0, -0.05 + rng.random_range(0.0..0.3)],
                    half_extents: [1.5, 1.5, 0.049],
                }
            } else {
                let c = [
                    rng.random_range(-0.8..0.8),
                    rng.random_range(-0.8..0.8),
                    rng.random_range(0.0..1.2),
                ];
                let h = [
                    rng.random_range(0.01..0.2),
                    rng.random_range(0.01..0.2),
                    rng.random_range(0.01..0.2),
                ];
                Obstacle {
                    name: "box".into(),
                    center: c,
                    half_extents: h,
                }
            };
            let exact = hits_exactly(&model, &frames, &obstacle);
            assert_eq!(
                model.hits_obstacle(&frames, &obstacle),
                exact,
                "{q:?} {obstacle:?}"
            );
            if exact.is_some() {
                hits += 1;
            } else {
                misses += 1;
            }
        }
        assert!(hits > 300 && misses > 300, "{hits} hits, {misses} misses");
    }
}
