//! Measuring on the fly (issue 16): the arm in motion against the arm at rest, a known clock offset recovered
//! from a trajectory campaign, and the path's timing against the joint limits.

use calibench::calib::clock;
use calibench::campaign::TrajectoryConfig;
use calibench::campaign::trajectory::{self, Path};
use calibench::measurements::as_dataset;
use calibench::robot::dh::DhChain;
use calibench::scenario::Scenario;
use calibench::truth::{TrueState, Visit};

/// paper_iiwa with `points` targets.
fn scenario(points: usize) -> Scenario {
    let text = std::fs::read_to_string("scenarios/paper_iiwa.toml").unwrap();
    Scenario::parse(
        &text.replacen("points = 2335", &format!("points = {points}"), 1),
        "paper_iiwa (edited)",
    )
    .unwrap()
}

fn config(offset: f64) -> TrajectoryConfig {
    TrajectoryConfig {
        speed: 0.5,
        acceleration_rad_s2: 5.0,
        sample_rate_hz: 1000.0,
        keep_every: 10,
        clock_offset_s: offset,
        jitter_s: 5e-6,
    }
}

/// A path that stops at every target and dwells there (each joint having just moved toward it, rest to rest):
/// at the stops, once the joints' vibration has died down, the arm in motion is the arm at rest to far below
/// the tracker's noise, with the same lost motion and thermal state as the static campaign's sequence gives it.
#[test]
fn at_the_stops_the_moving_arm_is_the_static_arm() {
    let s = scenario(12);
    let sim = calibench::app::simulate(&s).unwrap();
    let robot = &sim.world.robot;
    let posture = s.campaign.posture_rad();
    let commands: Vec<&[f64]> = sim
        .campaign
        .points
        .iter()
        .map(|p| p.q_cmd.as_slice())
        .collect();
    let visits =
        calibench::truth::history::sequence(&robot.perturbation, &posture, commands.clone());
    // The stops at the times the static sequence measures its points (so the warm-up is at the same stage).
    let every = robot
        .perturbation
        .thermal
        .as_ref()
        .map_or(5.0, |t| t.seconds_per_point);
    let vmax: Vec<f64> = sim
        .world
        .nominal
        .joints
        .iter()
        .map(|j| j.velocity)
        .collect();
    // Leg k moves from the previous stop to stop k in the first part of ((k − 1)·every, k·every], then dwells.
    let mut previous = posture.clone();
    let legs: Vec<Path> = commands
        .iter()
        .map(|q| {
            let leg = Path::plan(&[previous.clone(), q.to_vec()], &vmax, 5.0, 1.0).unwrap();
            assert!(leg.duration() < 0.6 * every, "{} s", leg.duration());
            previous = q.to_vec();
            leg
        })
        .collect();
    let at = |t: f64| {
        let k = ((t / every).ceil().max(0.0) as usize).min(legs.len() - 1);
        let mut p = legs[k].at(t - (k as f64 - 1.0) * every);
        p.t = t;
        p
    };
    // The stops, and a sample in the middle of every move.
    let times: Vec<f64> = (0..commands.len())
        .flat_map(|k| {
            let stop = k as f64 * every;
            [stop - every + 0.5 * legs[k].duration(), stop]
        })
        .collect();
    let moved = robot.follow(&at, &times, None).unwrap();
    let mut state = TrueState::new(robot);
    let (mut moving, mut worst) = (0.0f64, 0.0f64);
    for (k, (q, visit)) in commands.iter().zip(&visits).enumerate() {
        let visit = Visit {
            direction: visit.direction.clone(),
            temperature: visit.temperature,
        };
        robot.reach_after(q, &visit, None, &mut state).unwrap();
        let stop = &moved[2 * k + 1];
        assert!(stop.dynamic_m < 1e-8, "stop {k}: {} m", stop.dynamic_m);
        worst = worst
            .max((stop.flange.translation.vector - state.frames.flange.translation.vector).norm());
        moving = moving.max(moved[2 * k].dynamic_m);
    }
    // The tracker's noise is micrometres; the stops agree to a thousandth of one.
    assert!(worst < 1e-9, "{worst} m");
    // On the way the arm is loaded by its motion: the dynamic part is not small.
    assert!(moving > 10e-6, "{moving} m");
}

/// The planned path passes through every waypoint and keeps every joint within speed × its limits.
#[test]
fn the_path_respects_the_limits_and_passes_the_waypoints() {
    let waypoints = vec![
        vec![0.0, 0.0, 0.0],
        vec![0.5, -0.3, 1.0],
        vec![0.6, 0.2, 0.4],
        vec![-0.2, 0.1, 0.4],
    ];
    let vmax = [1.0, 2.0, 1.5];
    let path = Path::plan(&waypoints, &vmax, 4.0, 0.5).unwrap();
    let t_end = path.duration();
    let (mut peak_v, mut peak_a) = (0.0f64, 0.0f64);
    let steps = 20_000;
    for k in 0..=steps {
        let p = path.at(t_end * k as f64 / steps as f64);
        for (j, v) in vmax.iter().enumerate() {
            peak_v = peak_v.max(p.qd[j].abs() / (0.5 * v));
            peak_a = peak_a.max(p.qdd[j].abs() / (0.5 * 4.0));
        }
    }
    assert!(
        peak_v <= 1.0 + 1e-6 && peak_a <= 1.0 + 1e-3,
        "{peak_v} {peak_a}"
    );
    assert!(peak_v > 0.5, "the path uses its speed: {peak_v}");
    // Through the waypoints: the ends exactly, the vias somewhere along the way.
    assert_eq!(path.at(0.0).q, waypoints[0]);
    let end = path.at(t_end).q;
    assert!(
        end.iter()
            .zip(&waypoints[3])
            .all(|(a, b)| (a - b).abs() < 1e-12)
    );
    for w in &waypoints[1..3] {
        let closest = (0..=steps)
            .map(|k| {
                let q = path.at(t_end * k as f64 / steps as f64).q;
                q.iter()
                    .zip(w)
                    .map(|(a, b)| (a - b).abs())
                    .fold(0.0, f64::max)
            })
            .fold(f64::INFINITY, f64::min);
        assert!(closest < 1e-3, "{closest}");
    }
}

/// A 3 ms clock offset between tracker and controller is recovered from a trajectory campaign (issue 16:
/// within 50 µs), and correcting for it brings the registration back to what the arm's errors leave.
#[test]
fn a_known_clock_offset_is_recovered() {
    let s = scenario(60);
    let sim = calibench::app::simulate(&s).unwrap();
    let posture = s.campaign.posture_rad();
    let measured =
        trajectory::measure(&sim.world, &sim.campaign, &posture, &config(0.003), 7).unwrap();
    let data = as_dataset(&measured.campaign, "trajectory").unwrap();
    assert!(data.time.is_some());
    let dh = DhChain::from_chain(&sim.world.nominal).unwrap();
    let found = clock::estimate(&dh, &data, 0.05).unwrap();
    eprintln!(
        "{} samples over {:.1} s: offset {:.2} µs (true 3000), registration RMS {:.4} mm at it, {:.4} mm at 0; \
         dynamic deflection up to {:.4} mm",
        data.len(),
        measured.duration_s,
        found.offset_s * 1e6,
        found.rms_m * 1e3,
        found.rms_at_zero_m * 1e3,
        measured.dynamic_m.iter().fold(0.0f64, |a, b| a.max(*b)) * 1e3
    );
    assert!(
        (found.offset_s - 0.003).abs() <= 50e-6,
        "{} s",
        found.offset_s
    );
    assert!(found.rms_m < 0.5 * found.rms_at_zero_m);
    let corrected = clock::corrected(&data, found.offset_s).unwrap();
    assert_eq!(corrected.len(), data.len());
}

/// Issue 16, item 4: a regression given the motion as inputs (per joint, the torque the commanded motion needs
/// beyond gravity) describes the inertial deflection of a trajectory and, judged at rest (inputs zero) on the
/// static ground-truth grid, beats the same model fitted on the same samples without them. At full speed,
/// where the motion deflects the arm most.
#[test]
fn the_motion_as_inputs_lets_a_regression_describe_the_inertial_deflection() {
    use calibench::calib::method::FitContext;
    use calibench::calib::motion_inputs::with_motion_inputs;
    use calibench::calib::registry::MethodKind;
    use calibench::eval::GroundTruth;
    use calibench::eval::Stats;
    use calibench::eval::judge::{truth_errors, truth_errors_with};

    let s = scenario(60);
    let sim = calibench::app::simulate(&s).unwrap();
    let world = &sim.world;
    let mut full = config(0.0);
    full.speed = 1.0;
    let measured =
        trajectory::measure(world, &sim.campaign, &s.campaign.posture_rad(), &full, 11).unwrap();
    let data = as_dataset(&measured.campaign, "trajectory").unwrap();
    let ctx = FitContext::of(world);
    let moving = with_motion_inputs(&data, &world.nominal, &ctx.payload).unwrap();
    let inputs = &moving.extra_inputs.as_ref().unwrap().values;
    // The path starts at rest: no motion torque there.
    assert!(inputs[0].iter().all(|t| t.abs() < 1e-9), "{:?}", inputs[0]);
    let peak = inputs.iter().flatten().fold(0.0f64, |a, t| a.max(t.abs()));
    assert!(peak > 1.0, "the motion needs {peak} Nm at most");

    let (train, val): (Vec<usize>, Vec<usize>) = (0..data.len()).partition(|i| i % 3 != 2);
    let mut evaluation = s.evaluation.clone().unwrap();
    evaluation.grid_points = 300;
    evaluation.shell_points = 0;
    evaluation.closed_loop_points = 0;
    let truth =
        GroundTruth::build(world, &s.campaign, &s.regions, &evaluation.ground_truth()).unwrap();
    let kind = MethodKind::parse("paper-rotxyz").unwrap();
    let plain = kind
        .fit(&ctx, &data.subset(&train), &data.subset(&val))
        .unwrap();
    let with = kind
        .fit(&ctx, &moving.subset(&train), &moving.subset(&val))
        .unwrap();
    assert_eq!(with.input_names().len(), 7);
    let mean = |e: Vec<f64>| Stats::of(&e).unwrap().mean * 1e3;
    let plain_mm = mean(truth_errors(plain.as_ref(), &truth, &truth.grid.points).position);
    let with_mm =
        mean(truth_errors_with(with.as_ref(), &truth, &truth.grid.points, &[0.0; 7]).position);
    eprintln!(
        "{} samples over {:.1} s at full speed, motion torques up to {peak:.1} Nm: paper-rotxyz {plain_mm:.4} mm \
         without, {with_mm:.4} mm with the motion as inputs (static grid)",
        data.len(),
        measured.duration_s
    );
    assert!(
        with_mm < plain_mm,
        "{with_mm} mm with, {plain_mm} mm without"
    );
}

/// Between the targets the tracker loses the reflector where it turns out of its acceptance cone: those samples
/// are missing and counted, every sample kept faces the tracker, and kept + lost are all the samples. A narrow
/// cone (the targets are still checked against it when planned) makes the path leave it.
#[test]
fn samples_outside_the_acceptance_cone_are_lost() {
    let text = std::fs::read_to_string("scenarios/paper_iiwa.toml").unwrap();
    let narrow = text.replacen("points = 2335", "points = 30", 1).replacen(
        "acceptance_half_angle_deg = 30.0",
        "acceptance_half_angle_deg = 17.0",
        1,
    );
    let s = Scenario::parse(&narrow, "paper_iiwa (narrow cone)").unwrap();
    let sim = calibench::app::simulate(&s).unwrap();
    let world = &sim.world;
    let cfg = config(0.0);
    let measured =
        trajectory::measure(world, &sim.campaign, &s.campaign.posture_rad(), &cfg, 3).unwrap();
    let kept = measured.campaign.points.len();
    let total = (measured.duration_s * cfg.sample_rate_hz).floor() as usize / cfg.keep_every + 1;
    eprintln!(
        "{kept} samples kept of {total}: {} lost outside the cone, {} to a blocked beam",
        measured.lost_acceptance_cone, measured.lost_line_of_sight
    );
    assert!(measured.lost_acceptance_cone > 0);
    assert_eq!(
        kept + measured.lost_acceptance_cone + measured.lost_line_of_sight,
        total
    );
    for p in &measured.campaign.points {
        let facing = p.true_flange.rotation * world.mounting.facing;
        assert!(
            world
                .tracker
                .in_acceptance_cone(&p.true_reflectors[0], &facing)
        );
    }
}
