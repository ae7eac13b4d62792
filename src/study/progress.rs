//! Progress of a sweep on stderr: a bar on a terminal, plain lines in a log.
//!
//! Runs differ a lot in cost (a 1000-point fit against a 15-point one), so progress counts *work*, each run
//! weighted by its campaign's points plus a share of the shared evaluation sets ([`run_weight`]); the time left
//! is the elapsed time scaled by the work left, which a rate over run counts underestimates badly when the small
//! runs finish first.

use std::io::IsTerminal;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::time::Duration;

use indicatif::{ProgressBar, ProgressState, ProgressStyle};

use super::StudyConfig;

/// How the sweep reports progress on stderr.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Progress {
    /// A progress bar when stderr is a terminal, otherwise [`Progress::Lines`].
    Auto,
    /// A plain line every 10 % of the work.
    Lines,
    /// Nothing.
    Hidden,
}

/// The work of one run with `n` training points: its campaign's points, plus a quarter of the points every run
/// is evaluated on (test set, grid, shell, closed loop), a rough share of the cost that does not grow with `n`.
pub(super) fn run_weight(config: &StudyConfig, n: usize) -> u64 {
    let evaluated =
        config.test_points + config.grid_points + config.shell_points + config.closed_loop_points;
    (config.campaign_points(n) + evaluated / 4).max(1) as u64
}

/// Counts finished runs and work and shows it: a bar on a terminal, else a line every 10 %.
pub(super) struct Counter {
    bar: Option<ProgressBar>,
    lines: bool,
    runs: AtomicUsize,
    work: AtomicU64,
    total_runs: usize,
    total_work: u64,
}

/// `3m05s`, `42s`: short enough for an 80-column line.
fn short(d: Duration) -> String {
    let s = d.as_secs();
    if s >= 60 {
        format!("{}m{:02}s", s / 60, s % 60)
    } else {
        format!("{s}s")
    }
}

impl Counter {
    pub(super) fn new(progress: Progress, total_runs: usize, total_work: u64) -> Counter {
        let progress = match progress {
            Progress::Auto if std::io::stderr().is_terminal() => None,
            Progress::Auto => Some(Progress::Lines),
            other => Some(other),
        };
        let bar = progress.is_none().then(|| {
            let bar = ProgressBar::new(total_work.max(1));
            // At most 70 columns: "study 1m05s [========================>       ] 100 % 12m30s left".
            if let Ok(style) =
                ProgressStyle::with_template("study {since} [{bar:28}] {percent:>3} % {left} left")
            {
                bar.set_style(
                    style
                        .with_key("since", |s: &ProgressState, w: &mut dyn std::fmt::Write| {
                            let _ = w.write_str(&short(s.elapsed()));
                        })
                        .with_key("left", |s: &ProgressState, w: &mut dyn std::fmt::Write| {
                            let text = match (s.pos(), s.len()) {
                                (0, _) | (_, None) => "?".to_string(),
                                (done, Some(all)) => short(
                                    s.elapsed()
                                        .mul_f64(all.saturating_sub(done) as f64 / done as f64),
                                ),
                            };
                            let _ = w.write_str(&text);
                        })
                        .progress_chars("=> "),
                );
            }
            bar
        });
        let lines = progress == Some(Progress::Lines);
        if lines {
            eprintln!("study: {total_runs} runs");
        }
        Counter {
            bar,
            lines,
            runs: AtomicUsize::new(0),
            work: AtomicU64::new(0),
            total_runs,
            total_work: total_work.max(1),
        }
    }

    /// `runs` more runs done, of `weight` work each.
    pub(super) fn add(&self, runs: usize, weight: u64) {
        let work = runs as u64 * weight;
        let before = self.work.fetch_add(work, Ordering::Relaxed);
        let after = before + work;
        let done_runs = self.runs.fetch_add(runs, Ordering::Relaxed) + runs;
        if let Some(bar) = &self.bar {
            bar.inc(work);
        }
        if self.lines {
            let tenth = |k: u64| k * 10 / self.total_work;
            if tenth(after) > tenth(before) {
                eprintln!(
                    "study: {} % ({done_runs} of {} runs)",
                    tenth(after) * 10,
                    self.total_runs
                );
            }
        }
    }

    pub(super) fn finish(&self) {
        if let Some(bar) = &self.bar {
            bar.finish_and_clear();
        }
    }
}
