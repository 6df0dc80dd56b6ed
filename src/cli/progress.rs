//! Progress of work that can take more than a couple of seconds, one facility for every
//! command: on a terminal a bar with the elapsed time and an ETA (indicatif), appearing after
//! one second; otherwise (stderr a pipe or a file: a subprocess, a batch job) a log line on
//! stderr every 10 % or every 10 s, whichever comes first, once the work has taken 2 s:
//!
//! ```text
//! run: 45 % (45/100 batches), 12 s elapsed, ~15 s left
//! ```
//!
//! and a last line when it ends. `--quiet` silences both. The library reports through a
//! callback (`&dyn Fn(done, total)` or `&dyn Fn()` per unit) that the command builds from a
//! [`Progress`]; the library never prints.

use std::io::IsTerminal;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// `--quiet`: no progress at all.
static QUIET: AtomicBool = AtomicBool::new(false);

/// Silence every progress report of this process (`lidarsim --quiet …`).
pub fn set_quiet(quiet: bool) {
    QUIET.store(quiet, Ordering::Relaxed);
}

/// Whether `--quiet` was given (for reports that do not go through [`Progress`]).
pub fn quiet() -> bool {
    QUIET.load(Ordering::Relaxed)
}

/// When a log line is written off a terminal: not before the work has run this long
/// (`LIDARSIM_PROGRESS_AFTER_S` sets another, e.g. 0 to log from the start).
const LOG_AFTER: Duration = Duration::from_secs(2);

fn log_after() -> Duration {
    std::env::var("LIDARSIM_PROGRESS_AFTER_S")
        .ok()
        .and_then(|v| v.trim().parse::<f64>().ok())
        .filter(|s| s.is_finite() && *s >= 0.0)
        .map_or(LOG_AFTER, Duration::from_secs_f64)
}

/// When the library's own progress lines (a scene's first Mie computation) start: as the
/// log lines here, never with `--quiet`.
pub fn library_lines_after_s() -> Option<f64> {
    (!quiet()).then(|| log_after().as_secs_f64())
}

const LOG_EVERY: Duration = Duration::from_secs(10);
const LOG_STEP_PERCENT: f64 = 10.0;

/// How progress is shown.
enum Mode {
    /// Nothing (`--quiet`).
    Quiet,
    /// An indicatif bar on a terminal.
    Bar(indicatif::ProgressBar),
    /// Log lines on stderr.
    Log(Mutex<LogState>),
}

struct LogState {
    done: usize,
    total: usize,
    /// When and at what percentage the last line was written (none yet: `None`).
    last: Option<(Instant, f64)>,
    /// No line before the work has run this long.
    after: Duration,
}

/// Counts finished units of `len`; thread-safe.
pub struct Progress {
    mode: Mode,
    what: String,
    unit: String,
    started: Instant,
}

impl Progress {
    /// Progress of `len` units (`unit`: "profiles", "batches"…) of the work `what` (`dial`,
    /// `transport`…).
    pub fn new(len: usize, what: &str, unit: &str) -> Progress {
        let mode = if QUIET.load(Ordering::Relaxed) {
            Mode::Quiet
        } else if std::io::stderr().is_terminal() {
            let bar = indicatif::ProgressBar::hidden();
            bar.set_length(len as u64);
            bar.set_style(
                indicatif::ProgressStyle::with_template(&format!(
                    "{{spinner}} {what} {{bar:40}} {{pos}}/{{len}} {unit}, {{elapsed}} (eta {{eta}})"
                ))
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
            );
            Mode::Bar(bar)
        } else {
            Mode::Log(Mutex::new(LogState {
                done: 0,
                total: len,
                last: None,
                after: log_after(),
            }))
        };
        Progress {
            mode,
            what: what.to_string(),
            unit: unit.to_string(),
            started: Instant::now(),
        }
    }

    /// One more unit done.
    pub fn tick(&self) {
        match &self.mode {
            Mode::Quiet => {}
            Mode::Bar(bar) => self.reach(
                bar.position() as usize + 1,
                bar.length().unwrap_or(0) as usize,
            ),
            Mode::Log(state) => {
                let mut s = state.lock().unwrap_or_else(|e| e.into_inner());
                s.done += 1;
                self.log(&mut s);
            }
        }
    }

    fn log(&self, s: &mut LogState) {
        let elapsed = self.started.elapsed();
        if let Some(line) = log_line(s, elapsed, Instant::now(), &self.what, &self.unit) {
            eprintln!("{line}");
        }
    }

    /// `done` of `total` units done (a caller that reports positions, as the transport does).
    pub fn reach(&self, done: usize, total: usize) {
        match &self.mode {
            Mode::Quiet => {}
            Mode::Bar(bar) => {
                bar.set_length(total as u64);
                bar.set_position(done as u64);
                if bar.is_hidden() && self.started.elapsed() > Duration::from_secs(1) {
                    bar.set_draw_target(indicatif::ProgressDrawTarget::stderr());
                }
            }
            Mode::Log(state) => {
                let mut s = state.lock().unwrap_or_else(|e| e.into_inner());
                s.done = s.done.max(done);
                s.total = total;
                self.log(&mut s);
            }
        }
    }

    /// The work has ended: remove the bar, or (off a terminal, if any line was written) say
    /// how long it took.
    pub fn finish(&self) {
        match &self.mode {
            Mode::Quiet => {}
            Mode::Bar(bar) => bar.finish_and_clear(),
            Mode::Log(state) => {
                let s = state.lock().unwrap_or_else(|e| e.into_inner());
                if s.last.is_some() {
                    eprintln!(
                        "{}: done, {} {} in {}",
                        self.what,
                        s.done,
                        self.unit,
                        seconds(self.started.elapsed())
                    );
                }
            }
        }
    }
}

/// The log line due now, if one is: after `s.after` ([`LOG_AFTER`]), then every [`LOG_STEP_PERCENT`] %
/// or [`LOG_EVERY`], whichever comes first.
fn log_line(
    s: &mut LogState,
    elapsed: Duration,
    now: Instant,
    what: &str,
    unit: &str,
) -> Option<String> {
    if elapsed < s.after || s.total == 0 || s.done >= s.total {
        return None;
    }
    let percent = 100.0 * s.done as f64 / s.total as f64;
    let due = match s.last {
        None => true,
        Some((at, p)) => now.duration_since(at) >= LOG_EVERY || percent - p >= LOG_STEP_PERCENT,
    };
    if !due {
        return None;
    }
    s.last = Some((now, percent));
    Some(format_line(what, unit, s.done, s.total, elapsed))
}

/// `run: 45 % (45/100 batches), 12 s elapsed, ~15 s left`.
fn format_line(what: &str, unit: &str, done: usize, total: usize, elapsed: Duration) -> String {
    let fraction = done as f64 / total as f64;
    let left = if done > 0 {
        let s = elapsed.as_secs_f64() * (1.0 - fraction) / fraction;
        format!(", ~{} left", seconds(Duration::from_secs_f64(s)))
    } else {
        String::new()
    };
    format!(
        "{what}: {:.0} % ({done}/{total} {unit}), {} elapsed{left}",
        (100.0 * fraction).floor(),
        seconds(elapsed)
    )
}

/// `12 s`, `3 min 5 s`, `2 h 3 min`.
fn seconds(d: Duration) -> String {
    let s = d.as_secs_f64().round() as u64;
    match s {
        0..60 => format!("{s} s"),
        60..3600 => format!("{} min {} s", s / 60, s % 60),
        _ => format!("{} h {} min", s / 3600, (s % 3600) / 60),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_log_line_says_how_far_how_long_and_how_long_left() {
        assert_eq!(
            format_line("run", "batches", 45, 100, Duration::from_secs(12)),
            "run: 45 % (45/100 batches), 12 s elapsed, ~15 s left"
        );
        assert_eq!(
            format_line("dial", "profiles", 0, 7, Duration::from_secs(3)),
            "dial: 0 % (0/7 profiles), 3 s elapsed"
        );
        assert_eq!(seconds(Duration::from_secs(185)), "3 min 5 s");
        assert_eq!(seconds(Duration::from_secs(7380)), "2 h 3 min");
    }

    #[test]
    fn log_lines_come_every_ten_percent_or_ten_seconds_after_two() {
        let t0 = Instant::now();
        let mut s = LogState {
            done: 5,
            total: 100,
            last: None,
            after: LOG_AFTER,
        };
        let at = |secs: u64| (Duration::from_secs(secs), t0 + Duration::from_secs(secs));
        let (e, n) = at(1);
        assert_eq!(log_line(&mut s, e, n, "w", "u"), None, "before 2 s");
        let (e, n) = at(2);
        assert!(log_line(&mut s, e, n, "w", "u").is_some());
        s.done = 10;
        let (e, n) = at(3);
        assert_eq!(log_line(&mut s, e, n, "w", "u"), None, "5 % and 1 s later");
        s.done = 15;
        assert!(log_line(&mut s, e, n, "w", "u").is_some(), "10 % later");
        s.done = 16;
        let (e, n) = at(13);
        assert!(log_line(&mut s, e, n, "w", "u").is_some(), "10 s later");
        s.done = 100;
        let (e, n) = at(30);
        assert_eq!(
            log_line(&mut s, e, n, "w", "u"),
            None,
            "done: the last line says so"
        );
    }
}
