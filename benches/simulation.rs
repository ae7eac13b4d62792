//! `cargo bench --bench simulation`: the speed of the simulation half, as the README reports it.
//!
//! - the fast true-robot path (perturbed kinematics + fixed-point static deflection + tracker), one core;
//! - one pose settled by the rapier multibody reference;
//! - generating the paper campaign (`scenarios/paper_iiwa.toml`, 2335 points), all cores and one core.
//!
//! Plain timing with medians over repeats, no harness: the figures are for people, not for assertions.

use std::time::{Duration, Instant};

use nalgebra::Point3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use calibench::campaign::Generator;
use calibench::scenario::Scenario;
use calibench::truth::TrueState;
use calibench::truth::physics::SettleOptions;

fn median(mut v: Vec<Duration>) -> Duration {
    v.sort();
    v[v.len() / 2]
}

fn main() {
    let scenario = Scenario::load("scenarios/paper_iiwa.toml").expect("run from the crate root");
    let sim = calibench::app::simulate(&scenario).expect("the paper scenario simulates");
    let (nominal, robot, tracker, mounting) = (
        &sim.world.nominal,
        &sim.world.robot,
        &sim.world.tracker,
        &sim.world.mounting,
    );

    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let commands: Vec<Vec<f64>> = (0..20_000)
        .map(|_| {
            nominal
                .joints
                .iter()
                .map(|j| rng.random_range(0.7 * j.lower..0.7 * j.upper))
                .collect()
        })
        .collect();

    // Fast path, one thread: every pose is a full reach (deflection, noise) and a tracker measurement.
    let mut state = TrueState::new(robot);
    let mut sink: Point3<f64> = Point3::origin();
    let mut runs = Vec::new();
    for _ in 0..7 {
        let t = Instant::now();
        for q in &commands {
            robot
                .reach(q, Some(&mut rng), &mut state)
                .expect("deflection converges");
            let reflector = state.frames.flange * mounting.actual[0];
            let m = tracker.measure(&reflector, &mut rng);
            sink.x += m.x;
        }
        runs.push(t.elapsed());
    }
    let per_pose = median(runs).as_secs_f64() / commands.len() as f64;
    let iterations: usize = commands
        .iter()
        .map(|q| {
            robot.unloaded_angles(q, &mut state.q0);
            robot.deflect(&mut state).expect("deflection converges")
        })
        .sum();
    println!(
        "fast true-robot path (kinematics + fixed-point deflection + tracker), one core: {:.0} poses/s \
         ({:.2} µs per pose, {:.1} fixed-point iterations on average)",
        1.0 / per_pose,
        per_pose * 1e6,
        iterations as f64 / commands.len() as f64
    );

    // The physics reference.
    let mut physics = robot
        .physics_reference(SettleOptions::default())
        .expect("rapier world");
    let sample = &commands[..200];
    let t = Instant::now();
    let mut steps = 0;
    for q in sample {
        robot.unloaded_angles(q, &mut state.q0);
        steps += physics.settle(&state.q0).expect("settles").steps;
    }
    let per_settle = t.elapsed().as_secs_f64() / sample.len() as f64;
    println!(
        "rapier-settled pose: {:.3} ms per pose ({:.1} steps on average)",
        per_settle * 1e3,
        steps as f64 / sample.len() as f64
    );

    // The paper campaign, as the binary generates it (without writing files).
    let setup = Generator {
        world: &sim.world,
        config: &scenario.campaign,
        seed: sim.world.seed(),
        selector: None,
    };
    for threads in [rayon::current_num_threads(), 1] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("pool");
        let runs: Vec<Duration> = (0..5)
            .map(|_| {
                let t = Instant::now();
                let c = pool
                    .install(|| setup.run(&scenario.regions))
                    .expect("campaign");
                assert_eq!(c.points.len(), 2335);
                t.elapsed()
            })
            .collect();
        println!(
            "paper campaign (2335 points, IK + feasibility + truth + tracker), {threads} thread(s): {:.3} s",
            median(runs).as_secs_f64()
        );
    }
    // Keeps the measured work from being optimized away.
    if sink.x.is_nan() {
        println!("{sink}");
    }
}
