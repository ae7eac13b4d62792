//! Progress of a sweep on stderr: a bar on a terminal, plain lines in a log.
//!
//! Runs differ a lot in cost (a 1000-point fit against a 15-point one), so progress counts *work*, each run
//! weighted by its campaign's points plus a share of the shared evaluation sets ([`run_weight`]); the time left
//! is the elapsed time scaled by the work left, which a rate over run counts underestimates badly when the small
//! runs finish first.

use std::io::IsTerminal;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressState, ProgressStyle};

use super::StudyConfig;

/// How the sweep reports progress on stderr.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Progress {
    /// A progress bar when stderr is a terminal, otherwise [`Progress::Lines`].
    Auto,
    /// A plain line every two seconds: elapsed time, share of the work done, runs done, time left.
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

/// What the sweep's threads count and the reporter reads.
struct Tally {
    runs: AtomicUsize,
    work: AtomicU64,
    total_runs: usize,
    total_work: u64,
    start: Instant,
    done: AtomicBool,
}

impl Tally {
    /// `study 1m05s: 42 % (660 of 1575 runs), 1m30s left`.
    fn line(&self) -> String {
        let work = self.work.load(Ordering::Relaxed);
        let elapsed = self.start.elapsed();
        let left = match work {
            0 => "time left unknown".to_string(),
            w => format!(
                "{} left",
                short(elapsed.mul_f64(self.total_work.saturating_sub(w) as f64 / w as f64))
            ),
        };
        format!(
            "study {}: {} % ({} of {} runs), {left}",
            short(elapsed),
            work * 100 / self.total_work,
            self.runs.load(Ordering::Relaxed),
            self.total_runs
        )
    }
}

/// Counts finished runs and work and shows it: a bar on a terminal, redrawn every second; in a log a line every
/// [`LINE_EVERY`], whether or not a run finished (a study's first runs can take longer than that).
pub(super) struct Counter {
    bar: Option<ProgressBar>,
    tally: Arc<Tally>,
    reporter: Mutex<Option<JoinHandle<()>>>,
}

/// How often a log gets a progress line.
const LINE_EVERY: Duration = Duration::from_secs(2);

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
        let tally = Arc::new(Tally {
            runs: AtomicUsize::new(0),
            work: AtomicU64::new(0),
            total_runs,
            total_work: total_work.max(1),
            start: Instant::now(),
            done: AtomicBool::new(false),
        });
        let bar = progress.is_none().then(|| bar(total_work));
        let reporter = (progress == Some(Progress::Lines)).then(|| {
            eprintln!("study: {total_runs} runs");
            let tally = Arc::clone(&tally);
            std::thread::spawn(move || {
                let mut last = Instant::now();
                while !tally.done.load(Ordering::Relaxed) {
                    std::thread::sleep(Duration::from_millis(50));
                    if last.elapsed() >= LINE_EVERY && !tally.done.load(Ordering::Relaxed) {
                        eprintln!("{}", tally.line());
                        last = Instant::now();
                    }
                }
            })
        });
        Counter {
            bar,
            tally,
            reporter: Mutex::new(reporter),
        }
    }

    /// `runs` more runs done, of `weight` work each.
    pub(super) fn add(&self, runs: usize, weight: u64) {
        let work = runs as u64 * weight;
        self.tally.work.fetch_add(work, Ordering::Relaxed);
        self.tally.runs.fetch_add(runs, Ordering::Relaxed);
        if let Some(bar) = &self.bar {
            bar.inc(work);
        }
    }

    pub(super) fn finish(&self) {
        if let Some(bar) = &self.bar {
            bar.finish_and_clear();
        }
        self.tally.done.store(true, Ordering::Relaxed);
        if let Some(reporter) = self.reporter.lock().ok().and_then(|mut r| r.take()) {
            let _ = reporter.join();
        }
    }
}

impl Drop for Counter {
    /// A sweep that stops on an error stops the reporter too.
    fn drop(&mut self) {
        self.finish();
    }
}

/// The terminal's bar: at most 70 columns, "study 1m05s [=====>    ] 100 % 12m30s left", redrawn every second
/// so that the clock moves while a long run is fitted.
fn bar(total_work: u64) -> ProgressBar {
    let bar = ProgressBar::new(total_work.max(1));
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
    bar.enable_steady_tick(Duration::from_secs(1));
    bar
}
