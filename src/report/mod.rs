//! The report of a study: `metrics.csv` (one tidy row per run), `summary.md` (tables a person reads), PNG plots,
//! and the rerun recording `campaign.rrd`. Millimetres in everything a person reads.

pub mod plots;
pub mod recording;
pub mod summary;
