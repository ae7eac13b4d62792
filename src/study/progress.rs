//! Progress of a sweep on stderr: a bar on a terminal, plain lines in a log.

use std::io::IsTerminal;
use std::sync::atomic::{AtomicUsize, Ordering};

use indicatif::{ProgressBar, ProgressStyle};

/// How the sweep reports progress on stderr.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Progress {
    /// A progress bar when stderr is a terminal, otherwise [`Progress::Lines`].
    Auto,
    /// A plain line every 10 % of the runs.
    Lines,
    /// Nothing.
    Hidden,
}

/// Counts finished runs and shows it: a bar on a terminal, else a line every 10 %.
pub(super) struct Counter {
    bar: Option<ProgressBar>,
    lines: bool,
    done: AtomicUsize,
    total: usize,
}

impl Counter {
    pub(super) fn new(progress: Progress, total: usize) -> Counter {
        let progress = match progress {
            Progress::Auto if std::io::stderr().is_terminal() => None,
            Progress::Auto => Some(Progress::Lines),
            other => Some(other),
        };
        let bar = progress.is_none().then(|| {
            let bar = ProgressBar::new(total as u64);
            if let Ok(style) = ProgressStyle::with_template(
                "study {elapsed_precise} [{bar:40}] {pos}/{len} runs, {eta} left",
            ) {
                bar.set_style(style.progress_chars("=> "));
            }
            bar
        });
        let lines = progress == Some(Progress::Lines);
        if lines {
            eprintln!("study: {total} runs");
        }
        Counter {
            bar,
            lines,
            done: AtomicUsize::new(0),
            total,
        }
    }

    pub(super) fn add(&self, runs: usize) {
        let before = self.done.fetch_add(runs, Ordering::Relaxed);
        let after = before + runs;
        if let Some(bar) = &self.bar {
            bar.inc(runs as u64);
        }
        if self.lines && self.total > 0 {
            let tenth = |k: usize| k * 10 / self.total;
            if tenth(after) > tenth(before) {
                eprintln!(
                    "study: {} % ({after} of {} runs)",
                    tenth(after) * 10,
                    self.total
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
