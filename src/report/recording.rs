//! The rerun recording of a study, `campaign.rrd`: open it with the viewer of the same version
//! (`pip install "rerun-sdk==0.36.*"`, then `rerun results/<scenario>/campaign.rrd`).
//!
//! Everything is in metres, in the world frame, Z up ([`ViewCoordinates::RIGHT_HAND_Z_UP`] logged statically at
//! the root). The wall-clock `log_time` timeline is off and the recording id is fixed (`calibench-<scenario>`);
//! the recording is named `calibench study '<scenario>'`. It carries its blueprint (the viewer's layout, made
//! active when it opens: [`super::blueprint`]).
//!
//! # Timelines
//!
//! * `point` (sequence): the index of the detail campaign's point; the robot is drawn at that point.
//! * `n_train` (sequence): the training-set size of the learning curves.
//! * `n_train_log` (sequence): the same sizes as round(1000 · log10 n) — a log axis for the curves, on which the
//!   viewer opens (2000 = 100 points, 3000 = 1000).
//! * `time` (duration): the tracker's clock along the detail trajectory (`[study.trajectory]`).
//! * `tracker_s` (sequence): tracker seconds, the x axis of the tracker-time comparison.
//!
//! The robot's first pose is also logged at time 0 of both `n_train` timelines, so it stays drawn there.
//! Everything else is static.
//!
//! # Entity paths
//!
//! Names taken from the scenario (regions, methods) keep `[A-Za-z0-9_.-]`; any other character becomes `_`.
//! Layouts use their scenario spelling (`uniform`, `latin-hypercube`, …).
//!
//! | path | archetypes | timeline, rows |
//! |---|---|---|
//! | `/` | `ViewCoordinates` (right-handed, Z up) | static |
//! | `world/robot/link_<i>` | `Transform3D` (world ← body `i`, nominal FK at `q_cmd`; body 0 is the base) | `point`, one row per detail point; `n_train` and `n_train_log`, one row (the first point) |
//! | `world/robot/link_<i>/cylinders` | `Cylinders3D`, the body's cylinder colliders in its frame | static |
//! | `world/robot/link_<i>/capsules` | `Capsules3D` | static |
//! | `world/robot/link_<i>/spheres` | `Ellipsoids3D` | static |
//! | `world/robot/link_<i>/boxes` | `Boxes3D` | static |
//! | `world/robot/skeleton` | `LineStrips3D` through the joint anchors to the flange | `point` |
//! | `world/robot/flange` | `Transform3D` (world ← true flange) + `TransformAxes3D` | `point` (transform), static (axes) |
//! | `world/regions/<region>` | `Boxes3D` (wireframe, labelled) | static |
//! | `world/tracker` | `Transform3D` (world ← tracker) + `TransformAxes3D` + `Ellipsoids3D` (the head) | static |
//! | `world/tracker/beams` | `LineStrips3D`, one beam per detail point, in the tracker frame | static |
//! | `world/tracker/beam` | `LineStrips3D`, the beam to the current point | `point` |
//! | `world/points/before` | `Points3D` at the true positions, coloured by \|error before\| | static |
//! | `world/arrows/before_x<f>` | `Arrows3D`, error before calibration × `f` | static |
//! | `world/arrows/after_x<g>_<method>` | `Arrows3D`, error after the detail method × `g` (its own factor) | static |
//! | `world/grid/<method>` | `Points3D`, the ground-truth grid coloured by the detail method's residual | static |
//! | `histograms/<method>/before`, `histograms/<method>/after` | `BarChart` (counts; abscissa = bin centres, mm) | static |
//! | `curves/<region>/<layout>/<method>` | `SeriesLines` (named `<method> (mm)`, coloured as in the PNG, static) + `Scalars` (median over OK seeds of the ground-truth mean error, mm) | `n_train` and `n_train_log`, one row per size with an OK seed |
//! | `legend` | `TextDocument` (markdown): the colour scales and the arrow factor | static |
//! | `world/trajectory/path` | `LineStrips3D`, the detail trajectory's true reflector path (`[study.trajectory]`) | static |
//! | `world/trajectory/samples` | `Points3D`, its samples coloured by the detail method's error there | static |
//! | `world/trajectory/current` | `Points3D`, the sample at the tracker's time | `time` (duration, s), one row per sample |
//! | `legend_trajectory` | `TextDocument` (markdown): what the trajectory shows and its colour scale | static |
//! | `tracker_time/<region>/<targets>/<method>` | `SeriesLines` + `Scalars` (median ground-truth mean, mm): stop and go and each speed at their tracker time | `tracker_s` (sequence, whole seconds), one row per way of measuring |
//! | `summary` | `TextDocument` (markdown): the study summary | static |
//!
//! # Colours
//!
//! Errors map linearly onto the viridis colormap (dark purple = 0 → yellow = top of scale), in millimetres.
//! The measured points and the before arrows share one scale, the largest error before calibration rounded up in
//! the 1-2-5 sequence; the after arrows and the residual grid have their own scales, their largest values rounded
//! up the same way. The `legend` document states every scale.
//!
//! # Arrow magnification
//!
//! The arrow factor `f` is the largest 1-2-5 number (at least 1) that keeps the longest error-before arrow under
//! 0.1 m ([`arrow_factor`]); the after arrows get their own factor `g` the same way ([`arrow_factor_after`]) —
//! at `f`, a calibrated arm's arrows would be invisible. Both factors are part of the entity paths.

use std::collections::BTreeMap;

use nalgebra::{Isometry3, Point3, Vector3};
use rerun::{
    Arrows3D, BarChart, Boxes3D, Capsules3D, Cylinders3D, Ellipsoids3D, FillMode, LineStrips3D,
    Points3D, Quaternion, RecordingStream, RecordingStreamBuilder, Scalars, SeriesLines,
    TextDocument, Transform3D, TransformAxes3D, ViewCoordinates,
};

use crate::error::{Error, Result};
use crate::robot::kinematics::{Frames, forward_kinematics};
use crate::robot::{Body, Chain, Shape};
use crate::study::{DetailPoint, StudyResult};

pub use super::rerun_common::{
    N_TRAIN_LOG_TIMELINE, N_TRAIN_TIMELINE, POINT_TIMELINE, sanitize, viridis,
};
use super::rerun_common::{f3, nice_ceiling, p3, palette, rerun_error};
use super::summary::Summary;

/// The application id of every recording.
pub const APPLICATION_ID: &str = "calibench";

/// The position of `n` training points on [`N_TRAIN_LOG_TIMELINE`].
pub fn log_time(n: usize) -> i64 {
    (1000.0 * (n.max(1) as f64).log10()).round() as i64
}
/// Bins of every histogram.
pub const HISTOGRAM_BINS: usize = 20;

/// The longest error-before arrow stays under this length (m).
const ARROW_TARGET_M: f64 = 0.1;

/// The `.rrd` bytes of the study's recording (see the module documentation for what it holds).
///
/// The recording shows the study's summary as its `summary` document, so it takes the rendered [`Summary`]
/// (the one written as `summary.md`): the summary exists before the recording does.
///
/// The recording goes to an in-memory sink (`RecordingStreamBuilder::memory`) and is encoded at the end, so the
/// caller writes the file atomically and a failed study leaves no partial recording behind.
pub fn record(study: &StudyResult, chain: &Chain, summary: &Summary) -> Result<Vec<u8>> {
    let name = sanitize(&study.world.name);
    let (rec, storage) = RecordingStreamBuilder::new(APPLICATION_ID)
        .recording_id(format!("calibench-{name}"))
        // Named after the scenario, which the viewer shows in its recording list.
        .recording_name(format!("calibench study '{}'", study.world.name))
        .send_properties(true)
        // Forced on: the recording is an output of the harness, whatever the `RERUN` environment says.
        .enabled(true)
        .memory()
        .map_err(rerun_error)?;
    rec.set_log_time_enabled(false);
    rec.set_log_tick_enabled(false);

    log_all(&rec, study, chain, summary)?;
    super::blueprint::send(
        &rec,
        APPLICATION_ID,
        &name,
        &super::blueprint::study_layout(study, chain),
    )?;

    let bytes = storage.drain_as_bytes().map_err(rerun_error)?;
    Ok(bytes)
}

/// The magnification of the error arrows: the largest 1-2-5 number (at least 1) with
/// `max |error_before| × factor ≤ 0.1 m`.
pub fn arrow_factor(points: &[DetailPoint]) -> u64 {
    let max = points
        .iter()
        .map(|p| p.error_before.norm())
        .filter(|v| v.is_finite())
        .fold(0.0, f64::max);
    if max <= 0.0 {
        return 1;
    }
    let wanted = ARROW_TARGET_M / max;
    if wanted < 1.0 {
        return 1;
    }
    let decade = 10f64.powi(wanted.log10().floor() as i32);
    let mantissa = [5.0, 2.0, 1.0]
        .into_iter()
        .find(|m| m * decade <= wanted * (1.0 + 1e-12))
        .unwrap_or(1.0);
    (mantissa * decade).round().clamp(1.0, 1e9) as u64
}

/// The magnification of the error-after arrows: as [`arrow_factor`], on the errors after calibration, so that
/// they are as visible as the ones before (at the before factor, a calibrated arm's arrows vanish).
pub fn arrow_factor_after(points: &[DetailPoint]) -> u64 {
    let swapped: Vec<DetailPoint> = points
        .iter()
        .map(|p| DetailPoint {
            error_before: p.error_after,
            ..p.clone()
        })
        .collect();
    arrow_factor(&swapped)
}

fn quat(iso: &Isometry3<f64>) -> Quaternion {
    let q = iso.rotation.into_inner().coords;
    Quaternion::from_xyzw([q.x as f32, q.y as f32, q.z as f32, q.w as f32])
}

fn transform(iso: &Isometry3<f64>) -> Transform3D {
    Transform3D::from_translation_rotation(f3(&iso.translation.vector), quat(iso))
}

fn mm(m: f64) -> f64 {
    m * 1e3
}

fn log_all(
    rec: &RecordingStream,
    study: &StudyResult,
    chain: &Chain,
    summary: &Summary,
) -> Result<()> {
    rec.log_static("/", &ViewCoordinates::RIGHT_HAND_Z_UP())
        .map_err(rerun_error)?;

    let detail = &study.detail;
    let before_scale_mm = nice_ceiling(
        detail
            .points
            .iter()
            .map(|p| mm(p.error_before.norm()))
            .fold(0.0, f64::max),
    );
    let grid_scale_mm = nice_ceiling(
        detail
            .grid
            .iter()
            .map(|g| mm(g.residual))
            .fold(0.0, f64::max),
    );
    let factor = arrow_factor(&detail.points);
    let after_factor = arrow_factor_after(&detail.points);
    let after_scale_mm = nice_ceiling(
        detail
            .points
            .iter()
            .map(|p| mm(p.error_after.norm()))
            .fold(0.0, f64::max),
    );

    log_robot(rec, study, chain)?;
    log_regions(rec, study, chain)?;
    log_tracker(rec, study)?;
    log_points(
        rec,
        study,
        [before_scale_mm, after_scale_mm, grid_scale_mm],
        [factor, after_factor],
    )?;
    log_histograms(rec, study)?;
    log_curves(rec, study)?;
    super::trajectory_recording::log_trajectory(rec, study)?;

    let legend = format!(
        "# Legend\n\n\
         * Colormap: viridis, linear, dark purple = 0 mm, yellow = top of scale.\n\
         * Measured points (`world/points/before`) and the arrows of the error before calibration \
         (`world/arrows/before_x{factor}`, magnified ×{factor}): 0 – {before_scale_mm} mm.\n\
         * Arrows of the error after `{method}` (`world/arrows/after_x{after_factor}_{method}`, magnified \
         ×{after_factor}, so they show): 0 – {after_scale_mm} mm.\n\
         * Ground-truth grid (`world/grid/{method}`): 0 – {grid_scale_mm} mm (residual of `{method}`).\n\
         * Learning curves: the x axis is the `{N_TRAIN_LOG_TIMELINE}` timeline, 1000 · log10(training points): \
         1000 = 10, 2000 = 100, 3000 = 1000 points (the `{N_TRAIN_TIMELINE}` timeline has the plain counts).\n\
         * Robot drawn with the nominal model at each point's commanded joints (timeline `point`).\n",
        method = sanitize(detail.method.name()),
    );
    rec.log_static("legend", &TextDocument::from_markdown(legend))
        .map_err(rerun_error)?;
    rec.log_static("summary", &TextDocument::from_markdown(summary.markdown()))
        .map_err(rerun_error)?;
    Ok(())
}

fn log_robot(rec: &RecordingStream, study: &StudyResult, chain: &Chain) -> Result<()> {
    for (i, body) in chain.bodies.iter().enumerate() {
        log_colliders(rec, &format!("world/robot/link_{i}"), colliders(body))?;
    }
    rec.log_static("world/robot/flange", &TransformAxes3D::new(0.1f32))
        .map_err(rerun_error)?;
    log_poses(rec, study, chain)
}

/// A body's colliders, in its frame, grouped by rerun archetype: cylinders and capsules (lengths, radii,
/// centres or starts, rotations), spheres (centres, radii), boxes (centres, half sizes, rotations).
struct Colliders {
    cylinders: (Vec<f32>, Vec<f32>, Vec<[f32; 3]>, Vec<Quaternion>),
    capsules: (Vec<f32>, Vec<f32>, Vec<[f32; 3]>, Vec<Quaternion>),
    spheres: (Vec<[f32; 3]>, Vec<f32>),
    boxes: (Vec<[f32; 3]>, Vec<[f32; 3]>, Vec<Quaternion>),
}

fn colliders(body: &Body) -> Colliders {
    let mut cylinders = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut capsules = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut spheres = (Vec::new(), Vec::new());
    let mut boxes = (Vec::new(), Vec::new(), Vec::new());
    for collider in &body.colliders {
        let o = &collider.origin;
        match collider.shape {
            Shape::Cylinder { radius, length } => {
                cylinders.0.push(length as f32);
                cylinders.1.push(radius as f32);
                cylinders.2.push(f3(&o.translation.vector));
                cylinders.3.push(quat(o));
            }
            Shape::Capsule { radius, length } => {
                // Rerun's capsule starts at its frame's origin and runs along +z; ours is centred.
                let start = o * Point3::new(0.0, 0.0, -length / 2.0);
                capsules.0.push(length as f32);
                capsules.1.push(radius as f32);
                capsules.2.push(p3(&start));
                capsules.3.push(quat(o));
            }
            Shape::Sphere { radius } => {
                spheres.0.push(f3(&o.translation.vector));
                spheres.1.push(radius as f32);
            }
            Shape::Cuboid { half_extents } => {
                boxes.0.push(f3(&o.translation.vector));
                boxes.1.push(half_extents.map(|h| h as f32));
                boxes.2.push(quat(o));
            }
        }
    }
    Colliders {
        cylinders,
        capsules,
        spheres,
        boxes,
    }
}

/// The static shapes of one link, under `path`.
fn log_colliders(rec: &RecordingStream, path: &str, shapes: Colliders) -> Result<()> {
    let link_color = [255, 140, 0, 160];
    let Colliders {
        cylinders,
        capsules,
        spheres,
        boxes,
    } = shapes;
    if !cylinders.0.is_empty() {
        let n = cylinders.0.len();
        rec.log_static(
            format!("{path}/cylinders"),
            &Cylinders3D::from_lengths_and_radii(cylinders.0, cylinders.1)
                .with_centers(cylinders.2)
                .with_quaternions(cylinders.3)
                .with_colors(vec![link_color; n])
                .with_fill_mode(FillMode::Solid),
        )
        .map_err(rerun_error)?;
    }
    if !capsules.0.is_empty() {
        let n = capsules.0.len();
        rec.log_static(
            format!("{path}/capsules"),
            &Capsules3D::from_lengths_and_radii(capsules.0, capsules.1)
                .with_translations(capsules.2)
                .with_quaternions(capsules.3)
                .with_colors(vec![link_color; n])
                .with_fill_mode(FillMode::Solid),
        )
        .map_err(rerun_error)?;
    }
    if !spheres.0.is_empty() {
        let n = spheres.0.len();
        rec.log_static(
            format!("{path}/spheres"),
            &Ellipsoids3D::from_centers_and_radii(spheres.0, spheres.1)
                .with_colors(vec![link_color; n])
                .with_fill_mode(FillMode::Solid),
        )
        .map_err(rerun_error)?;
    }
    if !boxes.0.is_empty() {
        let n = boxes.0.len();
        rec.log_static(
            format!("{path}/boxes"),
            &Boxes3D::from_centers_and_half_sizes(boxes.0, boxes.1)
                .with_quaternions(boxes.2)
                .with_colors(vec![link_color; n])
                .with_fill_mode(FillMode::Solid),
        )
        .map_err(rerun_error)?;
    }
    Ok(())
}

/// The robot at every detail point on the `point` timeline (and at the first on the curves' timelines), its
/// skeleton, its true flange and the tracker's beam to the point.
fn log_poses(rec: &RecordingStream, study: &StudyResult, chain: &Chain) -> Result<()> {
    let mut frames = Frames::new(chain);
    let tracker = &study.detail.tracker;
    for (k, point) in study.detail.points.iter().enumerate() {
        if point.q_cmd.len() != chain.dof() {
            return Err(Error::Invalid(format!(
                "recording: detail point {k} has {} joints, the robot {}",
                point.q_cmd.len(),
                chain.dof()
            )));
        }
        forward_kinematics(chain, &point.q_cmd, &mut frames);
        if k == 0 {
            // The first pose on the curves' timelines too, so the robot stays drawn there.
            rec.reset_time();
            rec.set_time_sequence(N_TRAIN_TIMELINE, 0);
            rec.set_time_sequence(N_TRAIN_LOG_TIMELINE, 0);
            for (i, body) in frames.body.iter().enumerate() {
                rec.log(format!("world/robot/link_{i}"), &transform(body))
                    .map_err(rerun_error)?;
            }
            rec.reset_time();
        }
        rec.set_time_sequence(POINT_TIMELINE, k as i64);
        for (i, body) in frames.body.iter().enumerate() {
            rec.log(format!("world/robot/link_{i}"), &transform(body))
                .map_err(rerun_error)?;
        }
        let mut skeleton = vec![p3(&Point3::from(chain.base.translation.vector))];
        skeleton.extend((0..chain.dof()).map(|i| p3(&frames.anchor(i))));
        skeleton.push(f3(&frames.flange.translation.vector));
        rec.log(
            "world/robot/skeleton",
            &LineStrips3D::new([skeleton])
                .with_radii([0.004f32])
                .with_colors([[90, 90, 90, 255]]),
        )
        .map_err(rerun_error)?;
        rec.log("world/robot/flange", &transform(&point.true_flange))
            .map_err(rerun_error)?;
        let target = tracker.inverse_transform_point(&point.true_position);
        rec.log(
            "world/tracker/beam",
            &LineStrips3D::new([[[0.0f32; 3], p3(&target)]])
                .with_radii([0.0015f32])
                .with_colors([[255, 40, 40, 255]]),
        )
        .map_err(rerun_error)?;
    }
    rec.reset_time();
    Ok(())
}

fn log_regions(rec: &RecordingStream, study: &StudyResult, chain: &Chain) -> Result<()> {
    for (i, region) in study.regions.iter().enumerate() {
        // Regions are boxes in the robot's base frame.
        let pose = chain.base * nalgebra::Translation3::from(Vector3::from(region.center_m));
        rec.log_static(
            format!("world/regions/{}", sanitize(&region.name)),
            &Boxes3D::from_centers_and_half_sizes(
                [f3(&pose.translation.vector)],
                [region.size_m.map(|s| (s / 2.0) as f32)],
            )
            .with_quaternions([quat(&pose)])
            .with_colors([palette(i)])
            .with_radii([0.002f32])
            .with_fill_mode(FillMode::MajorWireframe)
            .with_labels([region.name.clone()]),
        )
        .map_err(rerun_error)?;
    }
    Ok(())
}

fn log_tracker(rec: &RecordingStream, study: &StudyResult) -> Result<()> {
    let tracker = &study.detail.tracker;
    rec.log_static("world/tracker", &transform(tracker))
        .map_err(rerun_error)?;
    rec.log_static("world/tracker", &TransformAxes3D::new(0.2f32))
        .map_err(rerun_error)?;
    rec.log_static(
        "world/tracker",
        &Ellipsoids3D::from_centers_and_radii([[0.0f32; 3]], [0.08])
            .with_colors([[40, 40, 40, 255]])
            .with_fill_mode(FillMode::Solid)
            .with_labels(["tracker"]),
    )
    .map_err(rerun_error)?;
    let beams: Vec<[[f32; 3]; 2]> = study
        .detail
        .points
        .iter()
        .map(|p| {
            [
                [0.0; 3],
                p3(&tracker.inverse_transform_point(&p.true_position)),
            ]
        })
        .collect();
    rec.log_static(
        "world/tracker/beams",
        &LineStrips3D::new(beams)
            .with_radii([0.0005f32])
            .with_colors([[255, 80, 80, 90]]),
    )
    .map_err(rerun_error)?;
    Ok(())
}

fn log_points(
    rec: &RecordingStream,
    study: &StudyResult,
    [before_scale_mm, after_scale_mm, grid_scale_mm]: [f64; 3],
    [factor, after_factor]: [u64; 2],
) -> Result<()> {
    let detail = &study.detail;
    let positions: Vec<[f32; 3]> = detail.points.iter().map(|p| p3(&p.true_position)).collect();
    let colors_before: Vec<[u8; 4]> = detail
        .points
        .iter()
        .map(|p| viridis(mm(p.error_before.norm()), before_scale_mm))
        .collect();
    rec.log_static(
        "world/points/before",
        &Points3D::new(positions.clone())
            .with_colors(colors_before.clone())
            .with_radii([0.005f32]),
    )
    .map_err(rerun_error)?;

    let f = factor as f64;
    rec.log_static(
        format!("world/arrows/before_x{factor}"),
        &Arrows3D::from_vectors(detail.points.iter().map(|p| f3(&(p.error_before * f))))
            .with_origins(positions.clone())
            .with_colors(colors_before)
            .with_radii([0.002f32]),
    )
    .map_err(rerun_error)?;
    let g = after_factor as f64;
    rec.log_static(
        format!(
            "world/arrows/after_x{after_factor}_{}",
            sanitize(detail.method.name())
        ),
        &Arrows3D::from_vectors(detail.points.iter().map(|p| f3(&(p.error_after * g))))
            .with_origins(positions)
            .with_colors(
                detail
                    .points
                    .iter()
                    .map(|p| viridis(mm(p.error_after.norm()), after_scale_mm))
                    .collect::<Vec<_>>(),
            )
            .with_radii([0.002f32]),
    )
    .map_err(rerun_error)?;

    rec.log_static(
        format!("world/grid/{}", sanitize(detail.method.name())),
        &Points3D::new(detail.grid.iter().map(|g| p3(&g.true_position)))
            .with_colors(
                detail
                    .grid
                    .iter()
                    .map(|g| viridis(mm(g.residual), grid_scale_mm))
                    .collect::<Vec<_>>(),
            )
            .with_radii([0.003f32]),
    )
    .map_err(rerun_error)?;
    Ok(())
}

fn log_histograms(rec: &RecordingStream, study: &StudyResult) -> Result<()> {
    let histograms = &study.detail.histograms;
    // One set of bins (mm) for every method and both sides, so the bars compare.
    let top = histograms
        .values()
        .flat_map(|h| h.before.iter().chain(&h.after))
        .filter(|v| v.is_finite())
        .fold(0.0, |a: f64, &b| a.max(mm(b)));
    let top = if top > 0.0 { top } else { 1e-3 };
    let width = top / HISTOGRAM_BINS as f64;
    let centres: Vec<f64> = (0..HISTOGRAM_BINS)
        .map(|b| (b as f64 + 0.5) * width)
        .collect();
    for (method, ba) in histograms {
        for (side, values, color) in [
            ("before", &ba.before, [214, 39, 40, 150]),
            ("after", &ba.after, [31, 119, 180, 150]),
        ] {
            let mut counts = vec![0u32; HISTOGRAM_BINS];
            for v in values.iter().filter(|v| v.is_finite()) {
                let b = ((mm(*v) / width) as usize).min(HISTOGRAM_BINS - 1);
                counts[b] += 1;
            }
            rec.log_static(
                format!("histograms/{}/{side}", sanitize(method.name())),
                &BarChart::new(counts)
                    .with_abscissa(centres.clone())
                    .with_widths(vec![width as f32; HISTOGRAM_BINS])
                    .with_color(color),
            )
            .map_err(rerun_error)?;
        }
    }
    Ok(())
}

/// The learning curves: per (region, layout, method), the median over OK seeds of the ground-truth mean
/// error at each training-set size (mm).
pub fn learning_curves(
    study: &StudyResult,
) -> BTreeMap<(String, String, String), Vec<(usize, f64)>> {
    let mut groups: BTreeMap<(String, String, String), BTreeMap<usize, Vec<f64>>> = BTreeMap::new();
    for run in &study.runs {
        let Some(truth) = run.truth.as_ref().filter(|_| run.failure.is_none()) else {
            continue;
        };
        if !truth.mean.is_finite() {
            continue;
        }
        let key = (
            sanitize(&run.key.region),
            run.key.layout.name().to_string(),
            sanitize(run.key.method.name()),
        );
        groups
            .entry(key)
            .or_default()
            .entry(run.key.n_train)
            .or_default()
            .push(mm(truth.mean));
    }
    groups
        .into_iter()
        .map(|(key, sizes)| {
            let curve = sizes
                .into_iter()
                .map(|(n, mut v)| {
                    v.sort_by(f64::total_cmp);
                    let m = v.len() / 2;
                    let median = if v.len() % 2 == 1 {
                        v[m]
                    } else {
                        (v[m - 1] + v[m]) / 2.0
                    };
                    (n, median)
                })
                .collect();
            (key, curve)
        })
        .collect()
}

fn log_curves(rec: &RecordingStream, study: &StudyResult) -> Result<()> {
    let curves = learning_curves(study);
    // Colours by the study's method order, the PNG's.
    let methods: Vec<String> = study
        .config
        .methods
        .iter()
        .map(|m| sanitize(m.name()))
        .collect();
    for ((region, layout, method), points) in &curves {
        let path = format!("curves/{region}/{layout}/{method}");
        let color = palette(methods.iter().position(|m| m == method).unwrap_or(0));
        rec.log_static(
            path.as_str(),
            &SeriesLines::new()
                .with_names([format!("{method} (mm)")])
                .with_colors([color])
                .with_widths([2.0f32]),
        )
        .map_err(rerun_error)?;
        for &(n, value) in points {
            rec.set_time_sequence(N_TRAIN_TIMELINE, n as i64);
            rec.set_time_sequence(N_TRAIN_LOG_TIMELINE, log_time(n));
            rec.log(path.as_str(), &Scalars::single(value))
                .map_err(rerun_error)?;
        }
        rec.reset_time();
    }
    Ok(())
}
