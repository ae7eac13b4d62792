//! The laser tracker (frame, noise, acceptance cone) and the collision model that decides line of sight and
//! feasibility.

use calibench::robot::collision::{CollisionModel, Obstacle};
use calibench::robot::kinematics::forward_kinematics;
use calibench::robot::{Chain, Frames, urdf};
use calibench::tracker::{Tracker, TrackerConfig};
use nalgebra::{Point3, Rotation3, Translation3, Vector3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

fn iiwa() -> Chain {
    urdf::load_file("robots/iiwa7.urdf", None).expect("the shipped URDF loads")
}

fn frames_at(chain: &Chain, q_deg: [f64; 7]) -> Frames {
    let q: Vec<f64> = q_deg.iter().map(|d| d.to_radians()).collect();
    assert!(chain.within_limits(&q), "test configuration within limits");
    let mut frames = Frames::new(chain);
    forward_kinematics(chain, &q, &mut frames);
    frames
}

fn config(position_m: [f64; 3], yaw_deg: f64) -> TrackerConfig {
    TrackerConfig {
        position_m,
        yaw_deg,
        tilt_deg: [0.0, 0.0],
        range_sigma_m: 0.0,
        range_sigma_per_m: 0.0,
        angle_sigma_rad: 0.0,
        acceptance_half_angle_deg: 30.0,
        orientation_sigma_rad: 0.0,
        range_offset_m: 0.0,
        range_scale: 0.0,
        azimuth_eccentricity_rad: [0.0; 2],
        elevation_eccentricity_rad: [0.0; 2],
        vertical_index_offset_rad: 0.0,
    }
}

#[test]
fn noise_free_measurement_is_the_point_in_the_tracker_frame() {
    let mut cfg = config([2.5, -1.0, 0.3], 37.0);
    cfg.tilt_deg = [0.5, -0.3];
    let tracker = Tracker::new(cfg).unwrap();
    // The frame built independently: yaw about z, then the tilts about y and x.
    let rot = Rotation3::from_axis_angle(&Vector3::z_axis(), 37f64.to_radians())
        * Rotation3::from_axis_angle(&Vector3::y_axis(), (-0.3f64).to_radians())
        * Rotation3::from_axis_angle(&Vector3::x_axis(), 0.5f64.to_radians());
    let by_hand = Translation3::new(2.5, -1.0, 0.3) * rot;
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    for p in [
        Point3::new(0.4, 0.2, 0.9),
        Point3::new(-0.3, 0.6, 0.2),
        Point3::new(2.5, -1.0, 1.3),
    ] {
        let m = tracker.measure(&p, &mut rng);
        assert!((m - tracker.pose.inverse_transform_point(&p)).norm() < 1e-12);
        assert!((m - by_hand.inverse_transform_point(&p)).norm() < 1e-12);
    }
    assert!((tracker.origin() - Point3::new(2.5, -1.0, 0.3)).norm() < 1e-15);
}

#[test]
fn measurements_are_deterministic_and_draw_three_normals_whatever_the_noise() {
    let p = Point3::new(0.5, 0.1, 0.7);
    let mut noisy_cfg = config([3.0, 0.5, 0.4], -20.0);
    noisy_cfg.range_sigma_m = 1e-5;
    noisy_cfg.angle_sigma_rad = 2e-6;
    let noisy = Tracker::new(noisy_cfg).unwrap();
    let quiet = Tracker::new(config([3.0, 0.5, 0.4], -20.0)).unwrap();
    let (mut a, mut b) = (ChaCha8Rng::seed_from_u64(9), ChaCha8Rng::seed_from_u64(9));
    assert_eq!(noisy.measure(&p, &mut a), noisy.measure(&p, &mut b));
    // The random stream stays aligned when a tracker without noise measures instead.
    quiet.measure(&p, &mut a);
    noisy.measure(&p, &mut b);
    assert_eq!(noisy.measure(&p, &mut a), noisy.measure(&p, &mut b));
}

#[test]
fn noise_is_range_along_the_beam_and_angular_across_it() {
    let mut cfg = config([2.0, -1.5, 0.5], 20.0);
    cfg.tilt_deg = [1.0, -0.5];
    cfg.range_sigma_m = 10e-6;
    cfg.range_sigma_per_m = 5e-6;
    cfg.angle_sigma_rad = 5e-6;
    let tracker = Tracker::new(cfg).unwrap();
    // A point 3 m away in the tracker frame, at azimuth 0.4 rad and elevation 0.1 rad.
    let (r, az, el) = (3.0f64, 0.4f64, 0.1f64);
    let radial = Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin());
    let across_az = Vector3::new(-az.sin(), az.cos(), 0.0);
    let across_el = radial.cross(&across_az);
    let p_tracker = Point3::from(radial * r);
    let p_world = tracker.pose * p_tracker;

    let n = 20_000;
    let mut rng = ChaCha8Rng::seed_from_u64(42);
    let (mut s_r, mut s_a, mut s_e, mut s_all) = (0.0, 0.0, 0.0, 0.0);
    let mut mean = Vector3::zeros();
    for _ in 0..n {
        let d = tracker.measure(&p_world, &mut rng) - p_tracker;
        s_r += d.dot(&radial).powi(2);
        s_a += d.dot(&across_az).powi(2);
        s_e += d.dot(&across_el).powi(2);
        s_all += d.norm_squared();
        mean += d;
    }
    let nf = n as f64;
    let std = |s: f64| (s / nf).sqrt();
    let expect_r = 10e-6 + 5e-6 * r;
    let expect_az = r * el.cos() * 5e-6;
    let expect_el = r * 5e-6;
    for (got, want, what) in [
        (std(s_r), expect_r, "range"),
        (std(s_a), expect_az, "azimuth"),
        (std(s_e), expect_el, "elevation"),
        (std(s_all / 3.0), tracker.noise_at(&p_world), "noise_at"),
    ] {
        assert!(
            (got / want - 1.0).abs() < 0.05,
            "{what}: empirical {got:e} m, expected {want:e} m"
        );
    }
    // Unbiased: the mean error is within 4 standard errors of zero.
    assert!((mean / nf).norm() < 4.0 * expect_r / nf.sqrt());
}

#[test]
fn tracker_config_is_validated_and_defaults_the_cone() {
    let toml_text = r#"
        position_m = [2.0, 0.0, 1.0]
        yaw_deg = 10.0
        range_sigma_m = 1e-5
        range_sigma_per_m = 5e-6
        angle_sigma_rad = 2e-6
    "#;
    let cfg: TrackerConfig = toml::from_str(toml_text).unwrap();
    assert_eq!(cfg.acceptance_half_angle_deg, 30.0);
    assert_eq!(cfg.tilt_deg, [0.0, 0.0]);
    assert!(toml::from_str::<TrackerConfig>(&format!("{toml_text}\nspeed = 1.0")).is_err());
    assert!(Tracker::new(cfg.clone()).is_ok());

    let mut bad = cfg.clone();
    bad.range_sigma_m = -1e-6;
    assert!(Tracker::new(bad).is_err());
    let mut bad = cfg.clone();
    bad.angle_sigma_rad = f64::NAN;
    assert!(Tracker::new(bad).is_err());
    let mut bad = cfg.clone();
    bad.position_m[1] = f64::INFINITY;
    assert!(Tracker::new(bad).is_err());
    for cone in [0.0, 90.0, -5.0, f64::NAN] {
        let mut bad = cfg.clone();
        bad.acceptance_half_angle_deg = cone;
        assert!(Tracker::new(bad).is_err(), "cone {cone}");
    }
}

#[test]
fn acceptance_cone_accepts_29_degrees_and_rejects_31() {
    let tracker = Tracker::new(config([2.0, 0.0, 1.0], 55.0)).unwrap();
    let reflector = Point3::new(0.0, 0.0, 1.0);
    // The beam runs along +x from the reflector; tilt the facing away from it about two different axes.
    for axis in [Vector3::z_axis(), Vector3::y_axis()] {
        for (deg, seen) in [(0.0, true), (29.0, true), (31.0, false), (150.0, false)] {
            let facing = Rotation3::from_axis_angle(&axis, f64::to_radians(deg)) * Vector3::x();
            assert_eq!(
                tracker.in_acceptance_cone(&reflector, &(facing * 0.5)),
                seen,
                "{deg} deg about {axis:?}"
            );
        }
    }
    assert!(!tracker.in_acceptance_cone(&reflector, &Vector3::zeros()));
}

#[test]
fn beam_through_link_4_is_blocked_and_a_beam_beside_the_arm_is_not() {
    let chain = iiwa();
    let model = CollisionModel::new(&chain);
    let home = frames_at(&chain, [0.0; 7]);
    // iiwa_link_4 spans z 0.74..0.915 at home, radius 0.065; at z = 0.8 the beam also grazes the sphere
    // over A4 (iiwa_link_3, radius 0.07) behind link 4's surface, so link 4 is the first body entered.
    let tracker = Tracker::new(config([2.0, 0.0, 0.8], 180.0)).unwrap();
    let from = tracker.origin();
    let behind = Point3::new(-0.5, 0.0, 0.8);
    assert!(model.segment_blocked(&home, &from, &behind, 0.0));
    assert_eq!(model.segment_hit(&home, &from, &behind, 0.0), Some(4));
    // Same tracker, a point 0.5 m to the side: the beam passes 0.4 m from the arm's axis.
    let beside = Point3::new(-0.5, 0.5, 0.8);
    // A steep beam crosses link 3 (below A4) and link 4 (above it): the body reported is the one entered first.
    let (low, high) = (Point3::new(0.5, 0.0, 0.3), Point3::new(-0.5, 0.0, 1.3));
    assert_eq!(model.segment_hit(&home, &low, &high, 0.0), Some(3));
    assert_eq!(model.segment_hit(&home, &high, &low, 0.0), Some(4));
    assert!(!model.segment_blocked(&home, &from, &beside, 0.0));
    // A point short of the arm is not blocked by what lies beyond it.
    assert!(!model.segment_blocked(&home, &from, &Point3::new(0.2, 0.0, 0.8), 0.0));
}

#[test]
fn end_clearance_ignores_only_the_last_metres_of_the_beam() {
    let chain = iiwa();
    let model = CollisionModel::new(&chain);
    let home = frames_at(&chain, [0.0; 7]);
    // A reflector 6 cm off the flange axis, seen from the far side: the beam crosses iiwa_link_7
    // (radius 0.05, z 1.231..1.266) between 0.01 and 0.11 m before the reflector.
    let reflector = Point3::new(0.06, 0.0, 1.25);
    let from = Point3::new(-2.0, 0.0, 1.25);
    assert_eq!(model.segment_hit(&home, &from, &reflector, 0.02), Some(7));
    assert!(!model.segment_blocked(&home, &from, &reflector, 0.12));
    // Clearance longer than the beam: nothing left to block.
    assert!(!model.segment_blocked(&home, &from, &reflector, 5.0));
}

#[test]
fn self_collision_free_at_home_and_when_the_arm_folds_onto_its_base() {
    let chain = iiwa();
    let model = CollisionModel::new(&chain);
    // Every non-adjacent pair is checked on the shipped URDF: nothing touches at home.
    assert_eq!(model.pairs().len(), 21);
    assert_eq!(model.self_collision(&frames_at(&chain, [0.0; 7])), None);
    // Elbow bent hard, upper arm upright: still free.
    assert_eq!(
        model.self_collision(&frames_at(&chain, [0.0, 0.0, 0.0, 115.0, 0.0, 0.0, 0.0])),
        None
    );
    // Shoulder down to horizontal, elbow folded back, wrist bent back: the flange lands on the base.
    let folded = frames_at(&chain, [0.0, -90.0, 0.0, 115.0, 0.0, -60.0, 0.0]);
    let flange = folded.flange.translation.vector;
    assert!(
        flange.xy().norm() < 0.15 && flange.z < 0.15,
        "flange at {flange:?}"
    );
    let hit = model.self_collision(&folded);
    assert!(matches!(hit, Some((0, 6 | 7))), "{hit:?}");
}

#[test]
fn pairs_touching_at_home_are_not_checked() {
    // Blow up iiwa_link_1's collision sphere (over A2) so that it reaches iiwa_link_3 at home.
    let xml = std::fs::read_to_string("robots/iiwa7.urdf").unwrap();
    let needle = "<collision>\n      <origin xyz=\"0 0 0.1925\" rpy=\"0 0 0\"/>\n      <geometry><sphere radius=\"0.07\"/>";
    assert_eq!(xml.matches(needle).count(), 1);
    let fat = xml.replace(needle, &needle.replace("0.07", "0.2"));
    let chain = urdf::load_str(&fat, "fat", None).unwrap();
    let model = CollisionModel::new(&chain);
    assert!(!model.pairs().contains(&(1, 3)));
    assert!(model.pairs().contains(&(1, 4)));
    assert_eq!(model.self_collision(&frames_at(&chain, [0.0; 7])), None);
}

#[test]
fn table_is_hit_only_when_the_arm_points_into_it() {
    let chain = iiwa();
    let model = CollisionModel::new(&chain);
    let table = Obstacle {
        name: "table".into(),
        center: [0.3, 0.0, -0.025],
        half_extents: [1.0, 1.0, 0.025],
    };
    assert_eq!(
        model.hits_obstacle(&frames_at(&chain, [0.0; 7]), &table),
        None
    );
    // Shoulder at 90°: the arm is horizontal at z = 0.34, well above the table.
    let level = [0.0, 90.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    assert_eq!(model.hits_obstacle(&frames_at(&chain, level), &table), None);
    // Shoulder at 110°: the wrist dips to the table top.
    let down = [0.0, 110.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    let hit = model.hits_obstacle(&frames_at(&chain, down), &table);
    assert!(matches!(hit, Some(b) if b >= 5), "{hit:?}");
    // The same box lifted out of reach is not hit.
    let high = Obstacle {
        center: [0.3, 0.0, 2.0],
        ..table
    };
    assert_eq!(model.hits_obstacle(&frames_at(&chain, down), &high), None);
}

#[test]
fn systematic_errors_move_the_measurement_by_their_size() {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let base = config([2.0, -1.5, 0.5], 20.0);
    let exact = Tracker::new(base.clone()).unwrap();
    let p = Point3::new(0.6, 0.2, 0.8);
    let truth = exact.measure(&p, &mut rng);
    let range = truth.coords.norm();
    let beam = truth.coords / range;
    // A range offset and a scale error shift the point along the beam by exactly offset + scale · range.
    let ranged = Tracker::new(TrackerConfig {
        range_offset_m: 12e-6,
        range_scale: 1e-6,
        ..base.clone()
    })
    .unwrap();
    let shift = ranged.measure(&p, &mut rng) - truth;
    let along = 12e-6 + 1e-6 * range;
    assert!(
        (shift - beam * along).norm() < 1e-12,
        "{shift:?} vs {along} along the beam"
    );
    // An index offset of the elevation turns the point about the horizontal axis across the beam by its
    // angle: range · offset, perpendicular to the beam.
    let indexed = Tracker::new(TrackerConfig {
        vertical_index_offset_rad: 5e-6,
        ..base.clone()
    })
    .unwrap();
    let shift = indexed.measure(&p, &mut rng) - truth;
    // Along the beam only to second order: range · δ² / 2, below 1e-10 m here.
    assert!(shift.dot(&beam).abs() < 1e-10);
    assert!(
        (shift.norm() - range * 5e-6).abs() < 1e-11,
        "{}",
        shift.norm()
    );
    assert!(shift.z > 0.0, "a positive index offset raises the point");
    // The azimuth encoder's eccentricity is a first harmonic of the azimuth: e0 cos(az) + e1 sin(az), across
    // the beam in the horizontal plane by the horizontal distance times that angle.
    let eccentric = Tracker::new(TrackerConfig {
        azimuth_eccentricity_rad: [4e-6, -3e-6],
        ..base
    })
    .unwrap();
    let shift = eccentric.measure(&p, &mut rng) - truth;
    let az = truth.y.atan2(truth.x);
    let angle = 4e-6 * az.cos() - 3e-6 * az.sin();
    let horizontal = truth.x.hypot(truth.y);
    assert!(shift.z.abs() < 1e-12);
    assert!((shift.norm() - horizontal * angle.abs()).abs() < 1e-11);
}
