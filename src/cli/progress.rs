//! The progress bar: `crate::progress::Progress` drawn with indicatif on stderr, and only when
//! stderr is a terminal (indicatif hides itself otherwise). Phases whose work is not known
//! ahead (reading an input) get a spinner with the elapsed time.

use std::time::Duration;

use crate::progress::Unit;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// A progress bar for long phases (one at a time).
pub struct Bar(ProgressBar);

impl Bar {
    /// A bar drawn on stderr.
    pub fn new() -> Bar {
        Bar(ProgressBar::with_draw_target(
            None,
            ProgressDrawTarget::stderr(),
        ))
    }

    /// A spinner for `phase`, ticking on its own until [`crate::progress::Progress::finish`].
    pub fn spin(&self, phase: &str) {
        let bar = &self.0;
        bar.reset();
        if let Ok(style) = ProgressStyle::with_template("{spinner} {msg} ({elapsed})") {
            bar.set_style(style);
        }
        bar.set_message(phase.to_owned());
        bar.enable_steady_tick(Duration::from_millis(120));
    }
}

impl crate::progress::Progress for Bar {
    fn start(&self, phase: &str, total: u64, unit: Unit) {
        let bar = &self.0;
        bar.disable_steady_tick();
        bar.reset();
        bar.set_length(total);
        let template = match unit {
            Unit::Bytes => "{msg} [{bar:40}] {bytes}/{total_bytes} ({eta})",
            Unit::Steps => "{msg} [{bar:40}] {pos}/{len} ({eta})",
        };
        if let Ok(style) = ProgressStyle::with_template(template) {
            bar.set_style(style.progress_chars("=> "));
        }
        bar.set_message(phase.to_owned());
    }

    fn advance(&self, n: u64) {
        self.0.inc(n);
    }

    fn finish(&self) {
        self.0.disable_steady_tick();
        self.0.finish_and_clear();
    }
}
