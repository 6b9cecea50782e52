//! The stage clock: runs a [`Stage`], announces it to the [`Progress`] receiver and adds its
//! seconds to the report's `timings` under [`Stage::key`].
//!
//! A stage that runs several times (the fit and the certificate after a demotion round) is
//! timed as the sum of its runs.

use super::CurveError;
use crate::progress::{Progress, Stage};
use std::collections::BTreeMap;
use std::time::Instant;

pub(crate) struct Clock<'p> {
    timings: BTreeMap<String, f64>,
    progress: &'p dyn Progress,
}

impl<'p> Clock<'p> {
    pub(crate) fn new(progress: &'p dyn Progress) -> Self {
        Clock {
            timings: BTreeMap::new(),
            progress,
        }
    }

    /// The receiver of progress (the fit's CG iterations go there directly).
    pub(crate) fn progress(&self) -> &'p dyn Progress {
        self.progress
    }

    /// Run `work` as `stage`.
    pub(crate) fn run<T>(&mut self, stage: Stage, work: impl FnOnce() -> T) -> T {
        self.progress.started(stage);
        let t = Instant::now();
        let out = work();
        self.add(stage, t.elapsed().as_secs_f64());
        self.progress.finished(stage);
        out
    }

    /// Stop here when the receiver of progress asks for it.
    pub(crate) fn check(&self) -> Result<(), CurveError> {
        if self.progress.cancelled() {
            Err(CurveError::Cancelled)
        } else {
            Ok(())
        }
    }

    /// Add `seconds` measured elsewhere (a part of a stage such as [`Stage::FitCg`]).
    pub(crate) fn add(&mut self, stage: Stage, seconds: f64) {
        *self.timings.entry(stage.key().to_string()).or_insert(0.0) += seconds;
    }

    /// Set `stage` to `seconds` (the whole job's [`Stage::Total`]).
    pub(crate) fn set(&mut self, stage: Stage, seconds: f64) {
        self.timings.insert(stage.key().to_string(), seconds);
    }

    pub(crate) fn into_timings(self) -> BTreeMap<String, f64> {
        self.timings
    }
}
