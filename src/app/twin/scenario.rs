//! A twin as a scenario file: the identified geometry and compliance, the fitted and the cited magnitudes,
//! the tracker and the probe where the pilot registered them, and a study over the pilot's workspace. The text
//! is written from the values (each magnitude with its source beside it) and read back through the scenario
//! parser, so what `campaign DIR/twin.toml` runs is what was checked here.

use std::fmt::Write as _;

use nalgebra::{Point3, UnitQuaternion, Vector3};

use super::magnitudes::{GEAR_RATIO, GEAR_RATIO_SOURCE, Magnitude, TRACKER_SOURCE};
use crate::calib::registry::{MethodKind, PHYSICAL};
use crate::error::Result;
use crate::robot::Payload;
use crate::scenario::Scenario;
use crate::truth::{KnownGeometry, Offset};

/// What a twin's scenario is made of.
#[derive(Clone, Debug)]
pub struct TwinValues {
    pub name: String,
    pub seed: u64,
    /// The robot description, as the scenario names it.
    pub robot: String,
    pub flange_link: Option<String>,
    pub payload: Payload,
    pub geometry: KnownGeometry,
    /// Per joint, the true stiffness (Nm/rad).
    pub stiffness: Vec<f64>,
    /// Every other magnitude of the truth, by key (`truth.gear_wave_amplitude_rad`), with its source.
    pub magnitudes: Vec<Magnitude>,
    /// The tracker's pose, world ← tracker (the pilot's registration).
    pub tracker: nalgebra::Isometry3<f64>,
    /// The probe's (or reflector's) position on the flange, and the direction it faces (flange frame).
    pub probe: Point3<f64>,
    pub facing: Vector3<f64>,
    pub posture_deg: Vec<f64>,
    pub workspace: Workspace,
    /// The accuracies the study answers for (mm): between what the pilot's best method and no calibration give.
    pub targets_mm: Vec<f64>,
    /// The warm-up the pilot's temperature column shows, with where its values come from; none without one.
    pub thermal: Option<(crate::truth::ThermalProfile, String)>,
}

/// The box the pilot measured in, and the flange orientations it used.
#[derive(Clone, Debug)]
pub struct Workspace {
    pub center_m: [f64; 3],
    pub size_m: [f64; 3],
    pub tool: UnitQuaternion<f64>,
    pub cone_half_angle_deg: f64,
    pub spin_deg: f64,
}

impl TwinValues {
    pub fn magnitude(&self, key: &str) -> f64 {
        self.magnitudes
            .iter()
            .find(|m| m.key == key)
            .map_or(0.0, |m| m.value)
    }

    pub fn set(&mut self, key: &str, value: f64) {
        if let Some(m) = self.magnitudes.iter_mut().find(|m| m.key == key) {
            m.value = value;
        }
    }

    /// The scenario, read from [`TwinValues::text`].
    pub fn scenario(&self) -> Result<Scenario> {
        Scenario::parse(&self.text(), &format!("the twin '{}'", self.name))
    }

    /// `twin.toml`.
    pub fn text(&self) -> String {
        let mut out = String::new();
        self.head(&mut out);
        self.truth(&mut out);
        self.tracker(&mut out);
        self.rest(&mut out);
        out
    }

    fn head(&self, out: &mut String) {
        let _ = writeln!(
            out,
            "# A twin of one measured arm, built by `campaign twin` from a pilot campaign. twin.json holds every\n\
             # identified value and magnitude with its standard deviation and what it was fitted to; twin.md the\n\
             # pilot's statistics, real beside twin.\n\n\
             name = {:?}\nseed = {}\n\n[robot]\nurdf = {:?}",
            self.name, self.seed, self.robot
        );
        if let Some(link) = &self.flange_link {
            let _ = writeln!(out, "flange_link = {link:?}");
        }
        let _ = writeln!(
            out,
            "payload_kg = {:?}\npayload_com_m = {:?}\n",
            self.payload.mass, self.payload.com
        );
    }

    fn truth(&self, out: &mut String) {
        let n = self.stiffness.len();
        let _ = writeln!(
            out,
            "[truth]\n# The geometry and the joints' stiffness are the pilot's (elastic fit, [truth.geometry] below):\n\
             # nothing of them is drawn.\nframe_translation_m = 0.0\nframe_rotation_rad = 0.0\njoint_zero_rad = 0.0\n\
             base_translation_m = 0.0\nbase_rotation_rad = 0.0\nstiffness_nm_per_rad = {:?}\nstiffness_spread = 0.0",
            self.stiffness
        );
        for m in &self.magnitudes {
            let Some(key) = m.key.strip_prefix("truth.") else {
                continue;
            };
            let value = if key == "tilt_stiffness_nm_per_rad" {
                format!("{:?}", vec![m.value; n])
            } else {
                format!("{:?}", m.value)
            };
            let _ = writeln!(out, "# {}\n{key} = {value}", m.source);
        }
        let _ = writeln!(
            out,
            "# {GEAR_RATIO_SOURCE}\ngear_ratio = {:?}\ndeflection = \"fixed-point\"",
            vec![GEAR_RATIO; n]
        );
        match &self.thermal {
            Some((t, source)) => {
                let _ = writeln!(
                    out,
                    "# {source}\nthermal = {{ start_c = {:?}, end_c = {:?}, time_constant_s = {:?}, \
                     seconds_per_point = {:?}, expansion_per_k = {:?}, reference_c = {:?} }}\n",
                    t.start_c,
                    t.end_c,
                    t.time_constant_s,
                    t.seconds_per_point,
                    t.expansion_per_k,
                    t.reference_c
                );
            }
            None => out.push_str(
                "# No warm-up: the pilot has no temperature column, or a constant one.\n\n",
            ),
        }
        let offset = |o: &Offset| {
            format!(
                "{{ translation = {:?}, rotation = {:?} }}",
                o.translation, o.rotation
            )
        };
        let frames: Vec<String> = self.geometry.joint_frames.iter().map(offset).collect();
        let _ = writeln!(
            out,
            "[truth.geometry]   # identified from the pilot: offsets of the base and of each joint frame (m, rad)\n\
             base = {}\njoint_frames = [\n    {},\n]\njoint_zero_rad = {:?}\n",
            offset(&self.geometry.base),
            frames.join(",\n    "),
            self.geometry.joint_zero_rad
        );
    }

    fn tracker(&self, out: &mut String) {
        let (roll, pitch, yaw) = self.tracker.rotation.euler_angles();
        let _ = writeln!(
            out,
            "[tracker]   # where the pilot's tracker stood (its registration); a replay places it anew\n\
             position_m = {:?}\nyaw_deg = {:?}\ntilt_deg = {:?}",
            <[f64; 3]>::from(self.tracker.translation.vector),
            yaw.to_degrees(),
            [roll.to_degrees(), pitch.to_degrees()]
        );
        for m in &self.magnitudes {
            if let Some(key) = m.key.strip_prefix("tracker.") {
                let _ = writeln!(out, "# {}\n{key} = {:?}", m.source, m.value);
            }
        }
        let _ = writeln!(
            out,
            "# {TRACKER_SOURCE}\norientation_sigma_rad = 8.7e-5\nacceptance_half_angle_deg = 45.0\n\
             range_offset_m = 5e-6\nazimuth_eccentricity_rad = [2e-6, -1e-6]\n\
             elevation_eccentricity_rad = [1e-6, 2e-6]\nvertical_index_offset_rad = 2e-6\n"
        );
        let _ = writeln!(
            out,
            "[reflectors]   # the probe where the pilot registered it\nnominal_m = [{:?}]\nfacing = {:?}\n\
             mount_translation_m = 0.0\n",
            <[f64; 3]>::from(self.probe.coords),
            <[f64; 3]>::from(self.facing)
        );
    }

    fn rest(&self, out: &mut String) {
        let w = &self.workspace;
        let (roll, pitch, yaw) = w.tool.euler_angles();
        let _ = writeln!(
            out,
            "[campaign]\nposture_deg = {:?}   # the pilot's median configuration\nposture_spread_deg = 0.0\n\
             limit_margin_deg = 2.0\n\n\
             [[regions]]   # the pilot's workspace: where its probe was, oriented as it was\nname = \"pilot\"\n\
             center_m = {:?}\nsize_m = {:?}\npoints = 1500\nlayout = \"uniform\"\ntool_rpy_deg = {:?}\n\
             cone_half_angle_deg = {:?}\nspin_deg = {:?}\n",
            self.posture_deg,
            w.center_m,
            w.size_m,
            [roll.to_degrees(), pitch.to_degrees(), yaw.to_degrees()],
            w.cone_half_angle_deg,
            w.spin_deg
        );
        let methods: Vec<String> = MethodKind::ALL
            .iter()
            .map(|m| format!("{:?}", m.name()))
            .collect();
        let _ = writeln!(
            out,
            "[study]   # the planning question for this arm, in the pilot's workspace\n\
             sizes = [25, 50, 100, 200, 400, 800]\nlayouts = [\"uniform\", \"sobol\"]\nmethods = [{}]\nseeds = 3\n\
             validation_ratio = 0.5\ntest_points = 300\ngrid_points = 600\nshell_width_m = 0.05\nshell_points = 100\n\
             closed_loop_points = 50\ndetail_method = {:?}\n\
             targets_mm = {:?}   # between the pilot's best held-out mean and its nominal one",
            methods.join(", "),
            PHYSICAL.name(),
            self.targets_mm
        );
    }
}
