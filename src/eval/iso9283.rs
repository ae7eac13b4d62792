//! ISO 9283's pose accuracy and repeatability of the simulated arm, before and after calibration. The
//! scenario's `[iso9283]` places the standard's test cube in a region ([`crate::campaign::iso_cube`]) and runs
//! its cycles on the true arm — repeatability, lost motion and the links' temperature as the sequence makes
//! them — commanded by every method the `[evaluation]` fitted (on its training split): the nominal model
//! (before calibration), each calibration (after) and the oracle (the true robot's own inverse, the floor).
//! Each aims at the five points in its own registered frame through its inverse, as the closed loop does
//! ([`super::judge`]); the tracker measures every attempt, and its true pose maps the measurement into the base
//! frame. AP and RP per point ([`super::pose_accuracy`]) go to `iso9283.csv` and the printed table.

use std::fmt::Write as _;

use nalgebra::{Point3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use super::accuracy::Fits;
use super::ground_truth::world_to_method;
use super::oracle::{Oracle, nest_rotation};
use super::pose_accuracy::{PoseAccuracy, pose_accuracy};
use crate::calib::method::{Fitted, MethodInfo};
use crate::calib::rigid::{centre, register_points};
use crate::campaign::iso_cube::{CYCLE, IsoCube, POINT_NAMES};
use crate::campaign::{CampaignConfig, Generator, RegionConfig, Simulation};
use crate::error::{Error, Result};
use crate::robot::Payload;
use crate::truth::TrueRobot;
use crate::world::World;

/// The standard's number of cycles.
fn default_cycles() -> usize {
    30
}

/// More cycles than this is not a pose test but a drift test (the standard's 8 hours are another test).
const MAX_CYCLES: usize = 10_000;

/// The `[iso9283]` section of a scenario: where the test cube goes and how the test is run.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Iso9283Config {
    /// The region whose box holds the cube; the first region when absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub region: Option<String>,
    /// Cycles P1 → P5 → P4 → P3 → P2 (the standard's 30).
    #[serde(default = "default_cycles")]
    pub cycles: usize,
    /// Seconds into the true robot's warm-up (`[truth] thermal`) at which the first cycle starts: 0 tests the
    /// arm cold. Absent: the arm warm, at the profile's end temperature, as the standard tests it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub warm_up_s: Option<f64>,
    /// The test load on the flange (kg) and its centre of mass (m, flange frame); the campaign's payload when
    /// absent. The methods are not told: they were fitted with the campaign's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub payload_kg: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub payload_com_m: Option<[f64; 3]>,
}

impl Iso9283Config {
    /// Checks the values and that the region is one of `regions`.
    pub fn validate(&self, regions: &[RegionConfig]) -> std::result::Result<(), String> {
        self.region_index(regions)?;
        if !(pose_cycles_ok(self.cycles)) {
            return Err(format!(
                "cycles = {}: between 3 (RP needs the spread of the attempts) and {MAX_CYCLES} (the standard's \
                 is 30)",
                self.cycles
            ));
        }
        if let Some(w) = self.warm_up_s.filter(|w| !(w.is_finite() && *w >= 0.0)) {
            return Err(format!("warm_up_s = {w} must be finite and non-negative"));
        }
        if let Some(m) = self.payload_kg.filter(|m| !(m.is_finite() && *m >= 0.0)) {
            return Err(format!("payload_kg = {m} must be finite and non-negative"));
        }
        if let Some(c) = self
            .payload_com_m
            .filter(|c| !c.iter().all(|v| v.is_finite()))
        {
            return Err(format!("payload_com_m = {c:?} must be finite"));
        }
        Ok(())
    }

    /// The index of the cube's region in `regions`.
    pub fn region_index(&self, regions: &[RegionConfig]) -> std::result::Result<usize, String> {
        match &self.region {
            None if regions.is_empty() => Err("no region to place the cube in".into()),
            None => Ok(0),
            Some(name) => regions.iter().position(|r| &r.name == name).ok_or_else(|| {
                let names: Vec<&str> = regions.iter().map(|r| r.name.as_str()).collect();
                format!(
                    "region = '{name}' is not a region of the scenario ({})",
                    names.join(", ")
                )
            }),
        }
    }

    /// The load the true arm carries in the test.
    fn payload(&self, campaign: Payload) -> Payload {
        Payload {
            mass: self.payload_kg.unwrap_or(campaign.mass),
            com: self.payload_com_m.unwrap_or(campaign.com),
        }
    }
}

fn pose_cycles_ok(cycles: usize) -> bool {
    (3..=MAX_CYCLES).contains(&cycles)
}

/// The cube as reports give it (mm, base frame).
#[derive(Clone, Debug, Serialize)]
pub struct CubeReport {
    pub region: String,
    /// The flange cube's centre and edge, and the box's smallest side (the edge before shrinking).
    pub centre_mm: [f64; 3],
    pub edge_mm: f64,
    pub largest_edge_mm: f64,
    /// P1–P5 of the measured point (reflector or nest centre): the commanded positions.
    pub points_mm: [[f64; 3]; 5],
}

/// One method's test: AP and RP at P1–P5, or why its commands could not be computed.
#[derive(Clone, Debug)]
pub struct IsoMethod {
    pub method: &'static MethodInfo,
    pub points: std::result::Result<Vec<PoseAccuracy>, String>,
}

/// The test of every method.
#[derive(Clone, Debug)]
pub struct Iso9283 {
    pub cube: CubeReport,
    pub cycles: usize,
    pub warm_up_s: Option<f64>,
    pub payload_kg: f64,
    /// Whether the probe gives the orientation (a nest of reflectors).
    pub orientation: bool,
    pub methods: Vec<IsoMethod>,
}

/// What every method aims at: the commanded poses of the measured point and of the reflectors (world).
struct Targets {
    /// P1–P5 of the measured point.
    tcp: [Point3<f64>; 5],
    /// Each point's reflectors where the commanded flange pose puts them.
    reflectors: [Vec<Point3<f64>>; 5],
    /// The nest's true rotation on the flange, for nests.
    nest: Option<UnitQuaternion<f64>>,
}

/// The test cube of one region of a world, ready to run cycles of any commands.
pub struct IsoTest<'a> {
    generator: Generator<'a>,
    r: u64,
    pub cube: IsoCube,
    targets: Targets,
}

/// Each attempt's deviation from the commanded pose, per point P1–P5 in attempt order: position (attained −
/// commanded, m, base frame) and, for a nest, rotation (the rotation vector carrying the commanded reflectors
/// onto the measured ones, rad).
#[derive(Clone, Debug)]
pub struct Attempts {
    pub positions: [Vec<Vector3<f64>>; 5],
    pub rotations: Option<[Vec<Vector3<f64>>; 5]>,
}

impl<'a> IsoTest<'a> {
    /// The cube of `regions[r]` in `world`, planned with the campaign's posture and obstacles (`campaign`).
    pub fn new(
        world: &'a World,
        campaign: &'a CampaignConfig,
        regions: &[RegionConfig],
        r: usize,
    ) -> Result<IsoTest<'a>> {
        let generator = Generator {
            world,
            config: campaign,
            seed: world.seed(),
            selector: None,
        };
        let cube = generator.iso_cube(r as u64, &regions[r])?;
        let actual = &world.mounting.actual;
        let measured_point = centre(actual);
        // The cube's flange poses carrying the true mounting, as the closed loop's targets do.
        let targets = Targets {
            tcp: cube.flanges.map(|f| f * measured_point),
            reflectors: cube.flanges.map(|f| actual.iter().map(|p| f * p).collect()),
            nest: nest_rotation(&world.mounting)?,
        };
        Ok(IsoTest {
            generator,
            r: r as u64,
            cube,
            targets,
        })
    }

    /// The commanded positions P1–P5 of the measured point (reflector or nest centre), world frame.
    pub fn points(&self) -> &[Point3<f64>; 5] {
        &self.targets.tcp
    }

    /// `model`'s commands for P1–P5: its inverse, from the nominal commands, at the points (and for a nest the
    /// commanded orientation, when it models it) mapped into its registered frame; why not at the first point
    /// where its inverse fails.
    pub fn commands_of(&self, model: &dyn Fitted) -> std::result::Result<[Vec<f64>; 5], String> {
        let to_method = world_to_method(&self.generator.world.tracker.pose, model);
        let with_orientation = model.registration().measures_orientation();
        let mut commands: [Vec<f64>; 5] = Default::default();
        for (k, command) in commands.iter_mut().enumerate() {
            let rotation = self
                .targets
                .nest
                .filter(|_| with_orientation)
                .map(|n| to_method.rotation * self.cube.flanges[k].rotation * n);
            let target = to_method * self.targets.tcp[k];
            *command = model
                .command_for(&target, rotation.as_ref(), &self.cube.q_nominal[k], &[])
                .map_err(|e| format!("{}: {}", POINT_NAMES[k], e.detail()))?
                .0;
        }
        Ok(commands)
    }

    /// `cycles` cycles of `commands` (P1–P5) on the true arm, begun `warm_up_s` into its warm-up (`None`:
    /// warm), each attempt measured by the tracker and mapped into the world frame by its true pose.
    pub fn measure(
        &self,
        commands: &[Vec<f64>; 5],
        cycles: usize,
        warm_up_s: Option<f64>,
    ) -> Result<Attempts> {
        let world = self.generator.world;
        let visits =
            self.generator
                .iso_cycles(self.r, &self.cube.region, commands, cycles, warm_up_s)?;
        let mut positions: [Vec<Vector3<f64>>; 5] = Default::default();
        let mut rotations: [Vec<Vector3<f64>>; 5] = Default::default();
        for (v, visit) in visits.iter().enumerate() {
            let k = CYCLE[v % CYCLE.len()];
            let measured: Vec<Point3<f64>> = visit
                .measured
                .iter()
                .map(|m| world.tracker.pose * m)
                .collect();
            positions[k].push(centre(&measured) - self.targets.tcp[k]);
            if self.targets.nest.is_some() {
                let deviation = register_points(&self.targets.reflectors[k], &measured)?;
                rotations[k].push(deviation.transform.rotation.scaled_axis());
            }
        }
        Ok(Attempts {
            positions,
            rotations: self.targets.nest.map(|_| rotations),
        })
    }
}

impl Attempts {
    /// AP and RP at P1–P5.
    pub fn accuracy(&self) -> Result<Vec<PoseAccuracy>> {
        (0..5)
            .map(|k| {
                let rotations = self.rotations.as_ref().map(|r| r[k].as_slice());
                pose_accuracy(&self.positions[k], rotations).ok_or_else(|| {
                    Error::Invalid(format!(
                        "ISO 9283 test: no finite measurement at {}",
                        POINT_NAMES[k]
                    ))
                })
            })
            .collect()
    }
}

/// Runs the test of `config` in the simulation for every method of `fits` and the oracle. A method whose
/// inverse fails at a point is reported as failed, with the reason, and the others go on.
pub fn run(
    sim: &Simulation,
    campaign: &CampaignConfig,
    regions: &[RegionConfig],
    config: &Iso9283Config,
    fits: &Fits,
) -> Result<Iso9283> {
    let r = config.region_index(regions).map_err(Error::Invalid)?;
    let loaded = loaded_world(&sim.world, config.payload(sim.world.payload()))?;
    let world = loaded.as_ref().unwrap_or(&sim.world);
    let test = IsoTest::new(world, campaign, regions, r)?;
    // The evaluation's oracle: the true robot as the campaign measured it, registered on the training data.
    let oracle = Oracle::new(&sim.world)?.registered_on(&[&fits.train, &fits.val])?;
    let mut models: Vec<(
        &'static MethodInfo,
        std::result::Result<&dyn Fitted, String>,
    )> = fits
        .models
        .iter()
        .map(|(kind, m)| {
            let model = m.as_deref().map_err(|e| format!("not fitted: {e}"));
            (kind.info(), model)
        })
        .collect();
    models.push((oracle.info(), Ok(&oracle)));
    let mut methods = Vec::new();
    for (method, model) in models {
        let points = match model.and_then(|m| test.commands_of(m)) {
            Ok(commands) => Ok(test
                .measure(&commands, config.cycles, config.warm_up_s)?
                .accuracy()?),
            Err(e) => Err(e),
        };
        methods.push(IsoMethod { method, points });
    }
    Ok(Iso9283 {
        cube: cube_report(&test.cube, test.points()),
        cycles: config.cycles,
        warm_up_s: config.warm_up_s,
        payload_kg: world.robot.payload.mass,
        orientation: test.targets.nest.is_some(),
        methods,
    })
}

/// `world` with the true arm carrying `payload`, when it differs from the campaign's.
fn loaded_world(world: &World, payload: Payload) -> Result<Option<World>> {
    if payload == world.robot.payload {
        return Ok(None);
    }
    let mut robot = TrueRobot::new(&world.nominal, world.robot.perturbation.clone(), payload)?;
    robot.set_approach(world.robot.approach());
    let mut config = world.config.clone();
    config.robot.payload_kg = payload.mass;
    config.robot.payload_com_m = payload.com;
    Ok(Some(World {
        config,
        nominal: world.nominal.clone(),
        dh: world.dh.clone(),
        robot,
        tracker: world.tracker.clone(),
        mounting: world.mounting.clone(),
    }))
}

fn cube_report(cube: &IsoCube, points: &[Point3<f64>; 5]) -> CubeReport {
    let mm = |p: &Point3<f64>| [p.x * 1e3, p.y * 1e3, p.z * 1e3];
    CubeReport {
        region: cube.region.clone(),
        centre_mm: mm(&cube.centre),
        edge_mm: cube.edge_m * 1e3,
        largest_edge_mm: cube.largest_edge_m * 1e3,
        points_mm: points.each_ref().map(mm),
    }
}

impl Iso9283 {
    /// `iso9283.csv`: one row per method and point, positions in mm, orientations in rad.
    pub fn csv(&self) -> Result<Vec<u8>> {
        let mut w = csv::Writer::from_writer(Vec::new());
        let err = |e: csv::Error| Error::Invalid(format!("iso9283.csv: {e}"));
        let mut header: Vec<&str> = vec![
            "method", "point", "x_mm", "y_mm", "z_mm", "attempts", "ap_mm", "ap_x_mm", "ap_y_mm",
            "ap_z_mm", "rp_mm",
        ];
        if self.orientation {
            header.extend([
                "ap_a_rad", "ap_b_rad", "ap_c_rad", "rp_a_rad", "rp_b_rad", "rp_c_rad",
            ]);
        }
        header.push("error");
        w.write_record(&header).map_err(err)?;
        for m in &self.methods {
            for (k, name) in POINT_NAMES.iter().enumerate() {
                let mut row = vec![m.method.name.to_string(), name.to_string()];
                row.extend(self.cube.points_mm[k].map(|v| v.to_string()));
                match &m.points {
                    Ok(points) => row.extend(self.numbers(&points[k])),
                    Err(e) => {
                        row.resize(header.len() - 1, String::new());
                        row.push(e.clone());
                    }
                }
                w.write_record(&row).map_err(err)?;
            }
        }
        w.into_inner()
            .map_err(|e| Error::Invalid(format!("iso9283.csv: {e}")))
    }

    /// A point's numbers for the CSV, the error column empty.
    fn numbers(&self, a: &PoseAccuracy) -> Vec<String> {
        let mm = a.in_mm();
        let mut out = vec![a.attempts.to_string(), mm.ap_mm.to_string()];
        out.extend(mm.ap_xyz_mm.map(|v| v.to_string()));
        out.push(mm.rp_mm.map_or(String::new(), |v| v.to_string()));
        if self.orientation {
            out.extend(
                mm.ap_abc_rad
                    .unwrap_or([f64::NAN; 3])
                    .map(|v| v.to_string()),
            );
            out.extend(
                mm.rp_abc_rad
                    .map_or([""; 3].map(String::from), |r| r.map(|v| v.to_string())),
            );
        }
        out.push(String::new());
        out
    }

    /// The table a person reads: AP and RP per point and method (mm), and the orientation's where measured.
    pub fn table(&self) -> String {
        let c = &self.cube;
        let shrunk = if c.edge_mm < c.largest_edge_mm {
            format!(
                ", shrunk from the box's {:.1} mm until the arm reached every point",
                c.largest_edge_mm
            )
        } else {
            ", the largest that fits the region's box".into()
        };
        let warm = match self.warm_up_s {
            None => "the arm warm".to_string(),
            Some(s) => format!("starting {s} s into the arm's warm-up"),
        };
        let mut out = format!(
            "ISO 9283 pose accuracy AP and repeatability RP (mm): cube of edge {:.1} mm centred at [{:.1}, \
             {:.1}, {:.1}] mm in region '{}'{shrunk}; {} cycles P1 → P5 → P4 → P3 → P2 on the true arm \
             ({warm}, {} kg on the flange), each method commanding through its inverse, measured by the \
             tracker\n",
            c.edge_mm,
            c.centre_mm[0],
            c.centre_mm[1],
            c.centre_mm[2],
            c.region,
            self.cycles,
            self.payload_kg
        );
        self.block(&mut out, |a| Some(a.ap * 1e3), |a| a.rp.map(|r| r * 1e3), 4);
        if self.orientation {
            out.push_str(
                "orientation (mrad): AP = ‖(AP_a, AP_b, AP_c)‖, RP = the largest of RP_a, RP_b, RP_c\n",
            );
            self.block(
                &mut out,
                |a| a.orientation_ap().map(|v| v * 1e3),
                |a| a.orientation_rp().map(|v| v * 1e3),
                4,
            );
        }
        out
    }

    /// One block of the table: a header, then AP and RP at P1–P5 for every method.
    fn block(
        &self,
        out: &mut String,
        ap: fn(&PoseAccuracy) -> Option<f64>,
        rp: fn(&PoseAccuracy) -> Option<f64>,
        digits: usize,
    ) {
        let _ = write!(out, "  {:<22} |", "method");
        for what in ["AP", "RP"] {
            for name in POINT_NAMES {
                let _ = write!(out, " {:>8}", format!("{what} {name}"));
            }
            out.push_str(" |");
        }
        out.push('\n');
        for m in &self.methods {
            let _ = write!(out, "  {:<22} |", m.method);
            match &m.points {
                Ok(points) => {
                    for pick in [ap, rp] {
                        for a in points {
                            match pick(a) {
                                Some(v) => {
                                    let _ = write!(out, " {v:>8.digits$}");
                                }
                                None => {
                                    let _ = write!(out, " {:>8}", "-");
                                }
                            }
                        }
                        out.push_str(" |");
                    }
                }
                Err(e) => {
                    let _ = write!(out, " failed: {e}");
                }
            }
            out.push('\n');
        }
    }
}
