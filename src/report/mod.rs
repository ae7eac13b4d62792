//! The report of a study: `metrics.csv` (one tidy row per run) and `outside.csv` ([`metrics`]), `summary.md`
//! (text and tables a person reads: [`summary`], [`tables`]) from the aggregates over seeds ([`aggregate`]), PNG
//! plots, and the rerun recording `campaign.rrd`. Millimetres in everything a person reads.

pub mod aggregate;
pub mod metrics;
pub mod plots;
pub mod recording;
pub mod summary;
pub mod tables;
