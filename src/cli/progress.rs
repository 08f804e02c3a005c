//! The progress bar: `fmrh::store::Progress` drawn with indicatif on stderr, and only when
//! stderr is a terminal (indicatif hides itself otherwise).

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
}

impl fmrh::store::Progress for Bar {
    fn start(&self, phase: &str, total: u64) {
        let bar = &self.0;
        bar.reset();
        bar.set_length(total);
        if let Ok(style) =
            ProgressStyle::with_template("{msg} [{bar:40}] {bytes}/{total_bytes} ({eta})")
        {
            bar.set_style(style.progress_chars("=> "));
        }
        bar.set_message(phase.to_owned());
    }

    fn advance(&self, n: u64) {
        self.0.inc(n);
    }

    fn finish(&self) {
        self.0.finish_and_clear();
    }
}
