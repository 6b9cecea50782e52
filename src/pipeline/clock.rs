//! The stage clock: runs a [`Stage`], announces it to the [`Progress`] receiver and adds its
//! seconds to the report's `timings` under [`Stage::key`].
//!
//! A stage that runs several times (the fit and the certificate after a demotion round) is
//! timed as the sum of its runs. The distributed job runs its stages on the same clock, which
//! also keeps each rank's peak memory at the end of every stage ([`Clock::with_peaks`]).
//! With a GPU ([`Clock::counting`]) it also keeps what each stage moved to and from the device
//! and dispatched ([`GpuTraffic`], the report's `gpu_traffic`), under the same keys.

use super::CurveError;
use crate::exec::gpu::{Backend, GpuTraffic};
use crate::progress::{Progress, Stage};
use std::collections::BTreeMap;
use std::time::Instant;

pub(crate) struct Clock<'p> {
    timings: BTreeMap<String, f64>,
    /// The peak memory at the end of each stage, by key, when kept.
    peaks: Option<BTreeMap<String, u64>>,
    /// The backend whose device traffic is counted per stage, and the counts by key.
    gpu: Option<(Backend, BTreeMap<String, GpuTraffic>)>,
    progress: &'p dyn Progress,
}

impl<'p> Clock<'p> {
    pub(crate) fn new(progress: &'p dyn Progress) -> Self {
        Clock {
            timings: BTreeMap::new(),
            peaks: None,
            gpu: None,
            progress,
        }
    }

    /// This clock, also keeping each stage's traffic on `backend`'s device (nothing on the
    /// CPU).
    pub(crate) fn counting(mut self, backend: &Backend) -> Self {
        if backend.traffic().is_some() {
            self.gpu = Some((backend.clone(), BTreeMap::new()));
        }
        self
    }

    /// Each stage's traffic on the device, by key (every stage run, zeros included), when
    /// counted.
    pub(crate) fn gpu_traffic(&self) -> Option<BTreeMap<String, GpuTraffic>> {
        self.gpu.as_ref().map(|(_, t)| t.clone())
    }

    /// A clock that also keeps the process's peak memory ([`peak_memory_bytes`]) at the end
    /// of every stage.
    pub(crate) fn with_peaks(progress: &'p dyn Progress) -> Self {
        Clock {
            peaks: Some(BTreeMap::new()),
            ..Clock::new(progress)
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
        let before = self.gpu.as_ref().and_then(|(backend, _)| backend.traffic());
        let out = work();
        if let (Some((backend, traffic)), Some(before)) = (&mut self.gpu, before) {
            let after = backend.traffic().unwrap_or(before);
            *traffic.entry(stage.key().to_string()).or_default() += after - before;
        }
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
        if let Some(peaks) = &mut self.peaks {
            peaks.insert(stage.key().to_string(), peak_memory_bytes());
        }
    }

    /// Set `stage` to `seconds` (the whole job's [`Stage::Total`]).
    pub(crate) fn set(&mut self, stage: Stage, seconds: f64) {
        self.timings.insert(stage.key().to_string(), seconds);
    }

    /// The seconds of the stages so far, by key.
    pub(crate) fn timings(&self) -> &BTreeMap<String, f64> {
        &self.timings
    }

    /// The peak memory at the end of each stage so far, by key (empty unless kept).
    pub(crate) fn peaks(&self) -> BTreeMap<String, u64> {
        self.peaks.clone().unwrap_or_default()
    }

    pub(crate) fn into_timings(self) -> BTreeMap<String, f64> {
        self.timings
    }
}

/// Peak resident memory of this process (Linux `VmHWM`), bytes; 0 where unknown.
pub fn peak_memory_bytes() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
                .and_then(|l| l.split_whitespace().nth(1)?.parse::<u64>().ok())
        })
        .map_or(0, |kb| kb * 1024)
}
