//! Progress of the `curve` job's stages, reported through a callback (never printed by the
//! library itself).
//!
//! The pipeline calls [`Progress::finished`] when a stage ends (the names of the report's
//! `timings`) and [`Progress::cg`] on every CG iteration of the fit. [`Silent`] ignores them;
//! [`Terminal`] draws an indicatif spinner on stderr naming the running stage, and stays off
//! when stderr is not a terminal.

use std::io::IsTerminal;
use std::time::Duration;

/// Receiver of stage progress.
pub trait Progress: Sync {
    /// Stage `name` has ended.
    fn finished(&self, _name: &str) {}
    /// The fit's CG solve reached `iteration` with relative residual `rel_residual`.
    fn cg(&self, _iteration: usize, _rel_residual: f64) {}
}

/// No progress output.
pub struct Silent;

impl Progress for Silent {}

/// The stage that runs after `finished` ends (for the spinner's label).
fn next_stage(finished: &str) -> &'static str {
    match finished {
        "read" => "topology",
        "topology" => "spline space",
        "spline" => "fit",
        "fit" => "certificate",
        "validity" | "snap" => "sampling",
        "sample" => "quality",
        "elastic_sample" | "elastic" => "elastic analogy",
        "quality" | "elastic_validity" => "writing",
        _ => "working",
    }
}

/// An indicatif spinner on stderr with the running stage and the elapsed time; hidden when
/// stderr is not a terminal or `quiet` is set. Short jobs finish before the first redraw
/// (4 per second) and leave nothing behind: the spinner is cleared at the end.
pub struct Terminal {
    bar: indicatif::ProgressBar,
}

impl Terminal {
    pub fn new(quiet: bool) -> Self {
        let bar = if quiet || !std::io::stderr().is_terminal() {
            indicatif::ProgressBar::hidden()
        } else {
            let bar = indicatif::ProgressBar::with_draw_target(
                None,
                indicatif::ProgressDrawTarget::stderr_with_hz(4),
            );
            bar.set_style(
                indicatif::ProgressStyle::with_template("{spinner} [{elapsed}] {msg}")
                    .expect("valid template"),
            );
            bar.enable_steady_tick(Duration::from_millis(250));
            bar
        };
        bar.set_message("reading");
        Terminal { bar }
    }

    /// Remove the spinner (call before printing the summary).
    pub fn clear(&self) {
        self.bar.finish_and_clear();
    }
}

impl Progress for Terminal {
    fn finished(&self, name: &str) {
        self.bar.set_message(next_stage(name));
    }
    fn cg(&self, iteration: usize, rel_residual: f64) {
        self.bar.set_message(format!(
            "fit: CG iteration {iteration}, relative residual {rel_residual:.1e}"
        ));
    }
}

impl Drop for Terminal {
    fn drop(&mut self) {
        self.bar.finish_and_clear();
    }
}
