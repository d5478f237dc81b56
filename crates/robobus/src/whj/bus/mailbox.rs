//! [`CyclicMailbox`]: where a running loop's handle and the driver meet. The handle
//! leaves its latest targets; the driver hands them to the session at the next tick and
//! leaves the reports the session polls out, and the loop's final statistics when it
//! ends. Neither waits for the other's lock.

use std::collections::VecDeque;
use std::sync::{Condvar, Mutex};
use std::time::Instant;

use super::lock;
use crate::whj::session::cyclic::{CycleReport, CyclicStats};

/// The most reports a mailbox keeps for its reader; older ones are dropped (and counted).
const REPORT_QUEUE: usize = 256;

/// One loop's exchange between its handle and the driver.
#[derive(Debug, Default)]
pub(crate) struct CyclicMailbox {
    /// Targets set since the last tick took them.
    targets: Mutex<Option<Vec<i32>>>,
    reports: Mutex<Reports>,
    cv: Condvar,
}

/// What [`CyclicMailbox::try_report`] found.
#[derive(Debug)]
pub(crate) enum Polled {
    /// The oldest report not yet taken.
    Report(CycleReport),
    /// None yet.
    Empty,
    /// None, and the loop ended.
    Ended,
}

#[derive(Debug, Default)]
struct Reports {
    queue: VecDeque<CycleReport>,
    latest: Option<CycleReport>,
    /// Reports dropped because nobody read them.
    dropped: u64,
    /// The loop's statistics once it ended.
    ended: Option<CyclicStats>,
}

impl CyclicMailbox {
    /// The handle's side: the targets for the next tick.
    pub(crate) fn set_targets(&self, targets: Vec<i32>) {
        *lock(&self.targets) = Some(targets);
    }

    /// The driver's side: targets set since the last call.
    pub(crate) fn take_targets(&self) -> Option<Vec<i32>> {
        lock(&self.targets).take()
    }

    /// The driver's side: a cycle closed.
    pub(crate) fn push_report(&self, report: CycleReport) {
        let mut r = lock(&self.reports);
        if r.queue.len() >= REPORT_QUEUE {
            r.queue.pop_front();
            r.dropped += 1;
        }
        r.latest = Some(report.clone());
        r.queue.push_back(report);
        drop(r);
        self.cv.notify_all();
    }

    /// The driver's side: the loop ended with `stats`; readers waiting are woken.
    pub(crate) fn finish(&self, stats: CyclicStats) {
        lock(&self.reports).ended = Some(stats);
        self.cv.notify_all();
    }

    /// The oldest report not yet taken, without waiting.
    pub(crate) fn try_report(&self) -> Polled {
        let mut r = lock(&self.reports);
        match r.queue.pop_front() {
            Some(report) => Polled::Report(report),
            None if r.ended.is_some() => Polled::Ended,
            None => Polled::Empty,
        }
    }

    /// Waits on the wall clock until `deadline` for a report (oldest first); `None` on
    /// timeout or once the loop ended.
    pub(crate) fn wait_report(&self, deadline: Instant) -> Option<CycleReport> {
        let mut r = lock(&self.reports);
        loop {
            if let Some(rep) = r.queue.pop_front() {
                return Some(rep);
            }
            if r.ended.is_some() {
                return None;
            }
            let now = Instant::now();
            if now >= deadline {
                return None;
            }
            r = self
                .cv
                .wait_timeout(r, deadline - now)
                .map_or_else(|e| e.into_inner().0, |(g, _)| g);
        }
    }

    /// Drops the reports not yet taken.
    pub(crate) fn clear_reports(&self) {
        lock(&self.reports).queue.clear();
    }

    /// The most recent report.
    pub(crate) fn latest(&self) -> Option<CycleReport> {
        lock(&self.reports).latest.clone()
    }

    /// The loop's final statistics, once it ended.
    pub(crate) fn ended(&self) -> Option<CyclicStats> {
        lock(&self.reports).ended.clone()
    }

    /// `stats` with the reports this mailbox dropped counted in.
    pub(crate) fn with_dropped(&self, mut stats: CyclicStats) -> CyclicStats {
        stats.reports_dropped += lock(&self.reports).dropped;
        stats
    }
}
