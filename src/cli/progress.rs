//! Progress of long commands (simulate, study, crossval, bench-diagnosis, demo): a bar with the
//! rate and the time left on a terminal, drawn on standard error; nothing at all when standard
//! error is not a terminal (piped, redirected, under CI), so logs and captured output stay clean.

use std::io::IsTerminal;
use std::time::Duration;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// A bar over `total` units of work, or a hidden one off a terminal.
pub struct Progress {
    bar: ProgressBar,
}

impl Progress {
    /// `what` names the work ("identifications", "cases"); `unit` the items counted.
    pub fn new(what: &str, total: usize) -> Progress {
        Progress::with_target(what, total, std::io::stderr().is_terminal())
    }

    fn with_target(what: &str, total: usize, visible: bool) -> Progress {
        let target = if visible { ProgressDrawTarget::stderr() } else { ProgressDrawTarget::hidden() };
        let bar = ProgressBar::with_draw_target(Some(total as u64), target);
        bar.set_style(
            ProgressStyle::with_template(
                "{msg:>16} {wide_bar} {pos}/{len}  {per_sec:>9}  {elapsed} elapsed, ETA {eta}",
            )
            .expect("the template is valid"),
        );
        bar.set_message(what.to_string());
        if visible {
            bar.enable_steady_tick(Duration::from_millis(250));
        }
        Progress { bar }
    }

    /// A spinner counting steps of unknown number (the demo's), with the elapsed time.
    pub fn steps(what: &str) -> Progress {
        let visible = std::io::stderr().is_terminal();
        let target = if visible { ProgressDrawTarget::stderr() } else { ProgressDrawTarget::hidden() };
        let bar = ProgressBar::with_draw_target(None, target);
        bar.set_style(
            ProgressStyle::with_template("{spinner} {msg} — step {pos}, {elapsed} elapsed")
                .expect("the template is valid"),
        );
        bar.set_message(what.to_string());
        if visible {
            bar.enable_steady_tick(Duration::from_millis(120));
        }
        Progress { bar }
    }

    /// Record `done` of the total (safe from several threads).
    pub fn set(&self, done: usize, total: usize) {
        if self.bar.length() != Some(total as u64) {
            self.bar.set_length(total as u64);
        }
        self.bar.set_position(done as u64);
    }

    /// A callback for the library's `progress: &(dyn Fn(done, total) + Sync)` parameters.
    pub fn callback(&self) -> impl Fn(usize, usize) + Sync + '_ {
        move |done, total| self.set(done, total)
    }

    /// Say which stage is running (a step of the demo).
    pub fn stage(&self, msg: &str) {
        self.bar.set_message(msg.to_string());
    }

    /// Print a line above the bar (or plainly on standard error without one).
    pub fn line(&self, s: &str) {
        if self.visible() { self.bar.println(s) } else { eprintln!("{s}") }
    }

    /// Advance by one unit.
    pub fn inc(&self) {
        self.bar.inc(1);
    }

    /// Whether anything is drawn.
    pub fn visible(&self) -> bool {
        !self.bar.is_hidden()
    }
}

impl Drop for Progress {
    /// The bar leaves the terminal as it found it; the command's own output follows.
    fn drop(&mut self) {
        self.bar.finish_and_clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_hidden_bar_counts_but_draws_nothing() {
        let p = Progress::with_target("runs", 10, false);
        assert!(!p.visible());
        let f = p.callback();
        f(3, 10);
        assert_eq!(p.bar.position(), 3);
        f(4, 12);
        assert_eq!((p.bar.position(), p.bar.length()), (4, Some(12)));
        p.inc();
        assert_eq!(p.bar.position(), 5);
    }
}
