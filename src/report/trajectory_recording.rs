//! The trajectory part of the study's recording (issue 16): the detail trajectory as a path in 3D with its
//! samples coloured by the detail method's error, on a `time` timeline, and the tracker-time comparison as time
//! series over a `tracker_s` timeline. Entity paths are listed in [`super::recording`]'s table.

use rerun::{LineStrips3D, Points3D, RecordingStream, Scalars, SeriesLines, TextDocument};

use super::rerun_common::{nice_ceiling, p3, palette, rerun_error, sanitize, viridis};
use super::trajectory::comparison;
use crate::error::Result;
use crate::study::StudyResult;
use crate::study::trajectory::TrajectoryDetail;

/// The tracker's clock along the detail trajectory (a duration timeline, s).
pub const TIME_TIMELINE: &str = "time";
/// The tracker time a way of measuring costs (a sequence timeline, whole seconds): the x axis of the
/// tracker-time comparison.
pub const TRACKER_TIMELINE: &str = "tracker_s";

/// Logs the trajectory entities; nothing without `[study.trajectory]`.
pub(super) fn log_trajectory(rec: &RecordingStream, study: &StudyResult) -> Result<()> {
    if let Some(d) = &study.trajectory_detail {
        log_detail_trajectory(rec, d)?;
    }
    log_tracker_time(rec, study)
}

/// The detail trajectory: its path, its samples coloured by the detail method's error, the current sample on
/// the `time` timeline, and its legend.
fn log_detail_trajectory(rec: &RecordingStream, d: &TrajectoryDetail) -> Result<()> {
    let positions: Vec<[f32; 3]> = d.samples.iter().map(|s| p3(&s.true_position)).collect();
    let scale_mm = nice_ceiling(
        d.samples
            .iter()
            .map(|s| s.error_after * 1e3)
            .fold(0.0, f64::max),
    );
    let colors: Vec<[u8; 4]> = d
        .samples
        .iter()
        .map(|s| viridis(s.error_after * 1e3, scale_mm))
        .collect();
    rec.log_static(
        "world/trajectory/path",
        &LineStrips3D::new([positions.clone()])
            .with_colors([[150u8, 150, 150, 255]])
            .with_radii([0.0008f32]),
    )
    .map_err(rerun_error)?;
    rec.log_static(
        "world/trajectory/samples",
        &Points3D::new(positions.clone())
            .with_colors(colors.clone())
            .with_radii([0.003f32]),
    )
    .map_err(rerun_error)?;
    for ((s, p), c) in d.samples.iter().zip(&positions).zip(&colors) {
        rec.set_duration_secs(TIME_TIMELINE, s.t);
        rec.log(
            "world/trajectory/current",
            &Points3D::new([*p]).with_colors([*c]).with_radii([0.008f32]),
        )
        .map_err(rerun_error)?;
    }
    rec.reset_time();
    let legend = format!(
        "# Trajectory\n\n\
         The path of region `{}` through {} targets at speed {} (seed 0), as the reflector really moved; its \
         {} samples (`world/trajectory/samples`) coloured by the error of `{}` there (viridis, 0 – {scale_mm} \
         mm: what the static model leaves of the arm in motion). The `{TIME_TIMELINE}` timeline moves the \
         current sample. The tracker-time comparison (`tracker_time/…`) is plotted over the \
         `{TRACKER_TIMELINE}` timeline (tracker seconds): select it in the time panel.\n",
        d.region,
        d.n_targets,
        d.speed,
        d.samples.len(),
        d.method
    );
    rec.log_static("legend_trajectory", &TextDocument::from_markdown(legend))
        .map_err(rerun_error)?;
    Ok(())
}

/// The tracker-time comparison: a series per (region, targets, method) over the `tracker_s` timeline.
fn log_tracker_time(rec: &RecordingStream, study: &StudyResult) -> Result<()> {
    for row in comparison(study) {
        let path = format!(
            "tracker_time/{}/{}/{}",
            sanitize(&row.region),
            row.n_targets,
            sanitize(&row.label())
        );
        let color = palette(super::trajectory::method_index(study, row.method));
        rec.log_static(
            path.as_str(),
            &SeriesLines::new()
                .with_names([format!("{}, {} targets (mm)", row.label(), row.n_targets)])
                .with_colors([color])
                .with_widths([2.0f32]),
        )
        .map_err(rerun_error)?;
        let mut points: Vec<(i64, f64)> = std::iter::once(row.stop)
            .chain(row.speeds.iter().map(|(_, m)| *m))
            .filter_map(|m| Some((m.tracker_s?.round() as i64, m.mean_mm?)))
            .collect();
        points.sort_by_key(|p| p.0);
        for (t, v) in points {
            rec.set_time_sequence(TRACKER_TIMELINE, t);
            rec.log(path.as_str(), &Scalars::single(v))
                .map_err(rerun_error)?;
        }
        rec.reset_time();
    }
    Ok(())
}
