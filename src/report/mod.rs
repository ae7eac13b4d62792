//! The report of a study: `metrics.csv` (one tidy row per run) and `outside.csv` ([`metrics`]), the answer
//! to the planning question (`answer.csv`, [`answer`]), `summary.md`
//! (text and tables a person reads: [`summary`], [`tables`]) from the aggregates over seeds ([`aggregate`]), PNG
//! plots, and the rerun recording `campaign.rrd`. Millimetres in everything a person reads.

pub mod aggregate;
pub mod answer;
pub mod blueprint;
pub mod metrics;
pub mod plots;
pub mod recording;
pub mod rerun_common;
pub mod summary;
pub mod tables;
pub mod trajectory;
pub mod trajectory_recording;

use crate::error::Result;
use crate::robot::Chain;
use crate::study::StudyResult;

/// Every file of a study's report (name, bytes), in the order they are written: `metrics.csv`, `outside.csv`,
/// `answer.csv`,
/// the plots, `campaign.rrd` (the robot drawn from `chain`) and `summary.md`.
pub fn study_files(study: &StudyResult, chain: &Chain) -> Result<Vec<(String, Vec<u8>)>> {
    // Rendered first: the recording shows it (`recording::record` takes it).
    let summary = summary::Summary::of(study)?;
    // The tables, the plots and the recording read the study alone: made side by side, the report's second of
    // one thread at the study's end takes about half as long.
    let ((tables, plots), recording) = rayon::join(
        || {
            rayon::join(
                || -> Result<Vec<(String, Vec<u8>)>> {
                    let mut files = vec![
                        ("metrics.csv".to_string(), metrics::metrics_csv(study)?),
                        ("outside.csv".to_string(), metrics::outside_csv(study)?),
                        ("answer.csv".to_string(), answer::answer_csv(study)?),
                    ];
                    if let Some(csv) = trajectory::trajectory_csv(study)? {
                        files.push(("trajectory.csv".to_string(), csv));
                    }
                    Ok(files)
                },
                || -> Result<Vec<(String, Vec<u8>)>> {
                    let mut files = plots::learning_curves_png(study)?;
                    files.extend(plots::histograms_png(study)?);
                    files.extend(plots::tracker_time_png(study)?);
                    Ok(files)
                },
            )
        },
        || recording::record(study, chain, &summary),
    );
    let mut files = tables?;
    files.extend(plots?);
    files.push(("campaign.rrd".into(), recording?));
    files.push(("summary.md".into(), summary.into_bytes()));
    Ok(files)
}
