//! The `calibrate export` job: a saved model whose correction is a change of the robot's geometry (the DH-frame
//! errors of the kinematic and elastic fits) written as a robot description that any driver, IK solver or
//! `calibrate --robot` loads as the robot: the URDF it was fitted on with its joint origins corrected, or its DH
//! table (`robots/README.md`'s format).
//!
//! The DH-frame errors become offsets of the description's joint frames by `calib::kinematic::geometry` (the
//! conversion the twin's truth uses); the file is read back before it is written and must predict the model's
//! poses to [`MATCH_M`] at [`CHECK_CONFIGURATIONS`] configurations within the joint limits, else nothing is
//! written. An elastic model's compliances travel beside the kinematics (`<calibench:compliance>` elements, a
//! table's `compliance` fields), which loaders of the kinematics ignore: loaded as a robot, the file is the
//! unloaded arm, and the agreement is that of the model's geometry (its prediction without the deflection).

use std::any::Any;
use std::path::{Path, PathBuf};

use nalgebra::Isometry3;
use rand::Rng;

use crate::calib::error_model::flange_pose_with_errors;
use crate::calib::kinematic::{ELASTIC, KINEMATIC, KinematicModel, geometry};
use crate::calib::registry::SavedModel;
use crate::error::{Error, Result};
use crate::output;
use crate::rng::{Stream, derive};
use crate::robot::description::{self, is_dh_table, read_text};
use crate::robot::dh::DhChain;
use crate::robot::export::{Correction, at, chain_urdf, corrected_urdf};
use crate::robot::{Chain, flange_pose, urdf};

/// Configurations the written file is checked at.
pub const CHECK_CONFIGURATIONS: usize = 200;
/// The largest difference (m; rotations as the displacement at 1 m) the file may have from the model.
pub const MATCH_M: f64 = 1e-9;
/// How close (m, rad) the robot's DH table must be to the model's to be the robot it was fitted on.
const SAME_ROBOT: f64 = 1e-9;
/// Seed of the configurations the conversion is fitted and checked at: the file must not depend on a flag.
const SEED: u64 = 26;

/// The written file's kind.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ExportFormat {
    /// The robot's URDF with its joint origins corrected: `robot.urdf`.
    Urdf,
    /// A standard DH table (robots/README.md): `robot.toml`.
    Dh,
}

impl ExportFormat {
    /// The file written into the output directory.
    pub fn file_name(self) -> &'static str {
        match self {
            ExportFormat::Urdf => "robot.urdf",
            ExportFormat::Dh => "robot.toml",
        }
    }
}

/// What to export: the flags of `calibrate export`.
#[derive(Clone, Debug, clap::Args)]
pub struct ExportOptions {
    /// A `model.json` written by `calibrate` (a kinematic or elastic fit).
    #[arg(long)]
    pub model: PathBuf,
    /// The robot description `calibrate` was run with (checked against the model's DH table).
    #[arg(long, default_value = "robots/iiwa7.urdf")]
    pub robot: PathBuf,
    /// The flange link `calibrate` was run with [default: the chain's last link].
    #[arg(long)]
    pub flange_link: Option<String>,
    /// The written description.
    #[arg(long, value_enum)]
    pub format: ExportFormat,
    /// Output directory (relative to the current directory): it receives `robot.urdf` or `robot.toml`,
    /// replaced all at once.
    #[arg(long, default_value = "results/calibrate/export")]
    pub out: PathBuf,
}

/// What [`export`] wrote.
#[derive(Clone, Debug)]
pub struct ExportOutcome {
    pub file: PathBuf,
    pub method: String,
    /// The largest difference (m) between the written file, read back, and the model's geometry.
    pub max_difference_m: f64,
    /// Whether compliances were written beside the kinematics.
    pub compliance: bool,
}

impl ExportOutcome {
    /// The lines `calibrate export` prints.
    pub fn text(&self) -> String {
        let mut s = format!(
            "{}: the {} model as a robot; read back, it predicts the model's poses within {:.1e} m \
             ({CHECK_CONFIGURATIONS} configurations)\n",
            self.file.display(),
            self.method,
            self.max_difference_m
        );
        if self.compliance {
            s.push_str(
                "the joint compliances are written beside the kinematics, which loaders ignore: as a robot \
                 the file is the unloaded arm\n",
            );
        }
        s
    }
}

/// Writes the model of `options.model` as a robot description into `options.out`.
pub fn export(options: &ExportOptions) -> Result<ExportOutcome> {
    let name = options.format.file_name();
    let others = [ExportFormat::Urdf.file_name(), ExportFormat::Dh.file_name()];
    output::check_dir(&options.out, &others)?;
    let fitted = SavedModel::read(&options.model)?;
    let any: &dyn Any = fitted.as_ref();
    let Some(model) = any.downcast_ref::<KinematicModel>() else {
        return Err(Error::Data {
            origin: options.model.display().to_string(),
            message: format!(
                "a {} model is not a robot description (only {} and {} models change the robot's geometry); \
                 use `calibrate apply --model {}` for its predicted poses and corrected joint commands",
                fitted.method(),
                KINEMATIC.name,
                ELASTIC.name,
                options.model.display()
            ),
        });
    };
    let chain = crate::robot::load(&options.robot, options.flange_link.as_deref())?;
    same_robot(&chain, model, &options.robot)?;
    let correction = correction(&chain, model)?;
    let compliance = model.compliance.as_deref();
    let header = header(options, model);
    let text = match options.format {
        ExportFormat::Urdf if is_dh_table(&options.robot) => {
            chain_urdf(&chain, &correction, compliance, &header)?
        }
        ExportFormat::Urdf => {
            let original = read_text(&options.robot)?;
            let origin = options.robot.display().to_string();
            let flange = options.flange_link.as_deref();
            corrected_urdf(&original, &origin, flange, &correction, compliance, &header)?
        }
        ExportFormat::Dh => description::to_toml(&correction.chain(&chain), compliance, &header)?,
    };
    let back = match options.format {
        ExportFormat::Urdf => urdf::load_str(&text, name, None)?,
        ExportFormat::Dh => description::from_toml(&text, name)?,
    };
    let worst = max_difference(&back, model, CHECK_CONFIGURATIONS, SEED);
    if worst.is_nan() || worst > MATCH_M {
        return Err(Error::Invalid(format!(
            "{name}: read back, it differs from the model by {worst:.1e} m (at most {MATCH_M:.0e}); nothing \
             was written"
        )));
    }
    output::write_dir(&options.out, &[(name, text.into_bytes())], &others)?;
    Ok(ExportOutcome {
        file: options.out.join(name),
        method: model.method.name.to_string(),
        max_difference_m: worst,
        compliance: compliance.is_some(),
    })
}

/// The DH-frame errors of `model` as corrections of `chain`'s joint origins, base and flange, the probe at the
/// model's mounting.
pub fn correction(chain: &Chain, model: &KinematicModel) -> Result<Correction> {
    let ranges: Vec<(f64, f64)> = chain
        .joints
        .iter()
        .map(|j| {
            let bound = |v: f64, turn: f64| if v.is_finite() { v } else { turn };
            (
                bound(j.lower, -std::f64::consts::PI),
                bound(j.upper, std::f64::consts::PI),
            )
        })
        .collect();
    let (known, flange, _) = geometry::known_geometry(chain, model, &ranges, SEED)?;
    Ok(Correction {
        base: known.base.isometry(),
        joints: chain
            .joints
            .iter()
            .zip(&known.joint_frames)
            .zip(&known.joint_zero_rad)
            .map(|((joint, frame), &zero)| frame.isometry() * joint.motion(zero))
            .collect(),
        probe: flange * at(&model.basis.registration.frame.mounting.coords),
    })
}

/// The largest difference (m; a rotation as the displacement it causes at 1 m) between `robot`'s flange and the
/// model's geometry at its measured point, at `count` configurations drawn within `robot`'s joint limits (one
/// turn either way for a continuous joint).
pub fn max_difference(robot: &Chain, model: &KinematicModel, count: usize, seed: u64) -> f64 {
    let mut rng = derive(seed, Stream::Layout, &[u64::MAX - 26]);
    let mounting = at(&model.basis.registration.frame.mounting.coords);
    let turn = 2.0 * std::f64::consts::PI;
    (0..count)
        .map(|_| {
            let q: Vec<f64> = robot
                .joints
                .iter()
                .map(|j| rng.random_range(j.lower.max(-turn)..=j.upper.min(turn)))
                .collect();
            let want: Isometry3<f64> =
                flange_pose_with_errors(&model.basis.dh, &q, &model.errors) * mounting;
            let got = flange_pose(robot, &q);
            let dp = (got.translation.vector - want.translation.vector).norm();
            dp.max(got.rotation.angle_to(&want.rotation))
        })
        .fold(0.0, f64::max)
}

/// `chain` is the robot `model` was fitted on: the same joints and, to [`SAME_ROBOT`], the same DH table.
fn same_robot(chain: &Chain, model: &KinematicModel, path: &Path) -> Result<()> {
    let refuse = |what: String| Error::Data {
        origin: path.display().to_string(),
        message: format!(
            "not the robot the model was fitted on ({what}); give the --robot and --flange-link `calibrate` \
             was run with"
        ),
    };
    let names = chain.joint_names();
    if names != model.basis.joint_names {
        return Err(refuse(format!(
            "joints {:?}, the model's {:?}",
            names, model.basis.joint_names
        )));
    }
    let dh = DhChain::from_chain(chain)?;
    let theirs = &model.basis.dh;
    for (i, (a, b)) in dh.rows.iter().zip(&theirs.rows).enumerate() {
        let diff = [
            a.theta_offset - b.theta_offset,
            a.d - b.d,
            a.a - b.a,
            a.alpha - b.alpha,
            a.beta - b.beta,
        ];
        if diff.iter().any(|v| v.abs() > SAME_ROBOT) || a.prismatic != b.prismatic {
            return Err(refuse(format!("DH row {} differs", i + 1)));
        }
    }
    for (what, a, b) in [
        ("base", dh.base, theirs.base),
        ("tool", dh.tool, theirs.tool),
    ] {
        let off = a.inverse() * b;
        if off.translation.vector.norm() > SAME_ROBOT || off.rotation.angle() > SAME_ROBOT {
            return Err(refuse(format!("the DH {what} frame differs")));
        }
    }
    Ok(())
}

/// The comment an exported file opens with: what it is and what its extras mean.
fn header(options: &ExportOptions, model: &KinematicModel) -> String {
    let mut s = format!(
        "calibench `calibrate export` of {} (a {} model: {} kept parameters, {:.4} mm RMS on its training \
         points),\nfitted on {}. The joint origins are moved by the identified errors; the measured point is \
         the flange\n({}).\n",
        options.model.display(),
        model.method.name,
        model.kept.len(),
        model.train_rms_m * 1e3,
        options.robot.display(),
        match options.format {
            ExportFormat::Urdf => "link calibench_probe, after the chain's last link",
            ExportFormat::Dh => "the table's tool frame",
        }
    );
    if model.compliance.is_some() {
        s.push_str(
            "Joint compliances (rad/Nm, under the gravity torques of the nominal masses) are written beside \
             the kinematics\n(`compliance` fields, <calibench:compliance> elements of namespace urn:calibench); \
             loaders of the\nkinematics ignore them: as a robot this file is the unloaded arm.\n",
        );
    }
    s
}
