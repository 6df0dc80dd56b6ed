//! A progress bar on a terminal for work units that take over a second in all (the bar appears
//! after one second and never on a pipe or a file).

use std::io::IsTerminal;
use std::time::{Duration, Instant};

/// Counts finished units of `len`; thread-safe.
pub struct Progress {
    bar: indicatif::ProgressBar,
    started: Instant,
    show: bool,
}

impl Progress {
    /// A bar for `len` units labelled `what` (e.g. `dial … profiles`).
    pub fn new(len: usize, what: &str, unit: &str) -> Progress {
        let bar = indicatif::ProgressBar::hidden();
        bar.set_length(len as u64);
        bar.set_style(
            indicatif::ProgressStyle::with_template(&format!(
                "{{spinner}} {what} {{bar:40}} {{pos}}/{{len}} {unit}, {{elapsed}} (eta {{eta}})"
            ))
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        Progress {
            bar,
            started: Instant::now(),
            show: std::io::stderr().is_terminal(),
        }
    }

    /// One more unit done.
    pub fn tick(&self) {
        self.reach(
            self.bar.position() as usize + 1,
            self.bar.length().unwrap_or(0) as usize,
        );
    }

    /// `done` of `total` units done (a caller that reports positions, as the transport does);
    /// the bar shows once the work has taken a second, on a terminal.
    pub fn reach(&self, done: usize, total: usize) {
        self.bar.set_length(total as u64);
        self.bar.set_position(done as u64);
        if self.show && self.bar.is_hidden() && self.started.elapsed() > Duration::from_secs(1) {
            self.bar
                .set_draw_target(indicatif::ProgressDrawTarget::stderr());
        }
    }

    /// Remove the bar.
    pub fn finish(&self) {
        self.bar.finish_and_clear();
    }
}
