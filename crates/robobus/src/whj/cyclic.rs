//! The cyclic servo loop's handle: [`JointBus::cyclic`] starts the loop in the bus's
//! session, and [`Cyclic`] sets its targets and reads its reports and statistics through
//! the loop's mailbox. The loop itself (the ticks, the feedback matching, the
//! statistics) is the session's pure state (`session/cyclic.rs`); its values
//! ([`CyclicConfig`], [`CycleReport`], [`CyclicStats`], ...) are defined there.

use core::time::Duration;
use std::sync::Arc;
use std::time::Instant;

use robobus_whj::JointId;
use robobus_whj::units::{Current, Position, TargetSpeed};

use super::bus::{CyclicMailbox, JointBus, Polled};
use super::error::WhjError;
use super::session::cyclic::{CycleReport, CyclicConfig, CyclicSetup, CyclicStats, ServoMode};

mod owned;
pub use owned::OwnedCyclic;

/// A running cyclic loop (see [`JointBus::cyclic`]). Stops when dropped.
///
/// Set targets at any time ([`Cyclic::set_positions`], ...); the bus thread sends the
/// latest ones at every tick. Read what happened with [`Cyclic::next_report`] (one
/// [`CycleReport`] per cycle, queued up to 256) or [`Cyclic::latest`], and the statistics
/// with [`Cyclic::stats`].
#[derive(Debug)]
pub struct Cyclic<'a> {
    bus: owned::BusRef<'a>,
    mailbox: Arc<CyclicMailbox>,
    config: CyclicConfig,
    stopped: bool,
}

impl JointBus {
    /// Starts a cyclic servo loop. In position mode the loop starts by holding each
    /// joint's present position (read with a status query). The joints should be enabled
    /// in the matching work mode. Only one loop runs per bus; while it runs, single servo
    /// commands to its joints are refused ([`WhjError::Busy`]); register reads and writes
    /// still work between its frames.
    pub fn cyclic(&self, config: CyclicConfig) -> Result<Cyclic<'_>, WhjError> {
        config
            .validate()
            .map_err(|reason| WhjError::InvalidConfig { reason })?;
        if self.cyclic_running() {
            return Err(WhjError::InvalidConfig {
                reason: "a cyclic loop is already running on this bus".into(),
            });
        }
        let initial = if config.mode == ServoMode::Position {
            config
                .joints
                .iter()
                .map(|j| Ok(self.joint_unchecked(*j).status()?.position.raw()))
                .collect::<Result<Vec<_>, WhjError>>()?
        } else {
            vec![0; config.joints.len()]
        };
        let mailbox = Arc::new(CyclicMailbox::default());
        let setup = CyclicSetup {
            config: config.clone(),
            initial,
            step_limit_deg: self.config().step_limit_deg,
        };
        self.start_cyclic(setup, Arc::clone(&mailbox))?;
        Ok(Cyclic {
            bus: owned::BusRef::Borrowed(self),
            mailbox,
            config,
            stopped: false,
        })
    }
}

impl Cyclic<'_> {
    /// The joints, in target / feedback order.
    pub fn joints(&self) -> &[JointId] {
        &self.config.joints
    }

    /// The loop's configuration.
    pub const fn config(&self) -> &CyclicConfig {
        &self.config
    }

    fn set_raw(&self, mode: ServoMode, raw: Vec<i32>) -> Result<(), WhjError> {
        if mode != self.config.mode {
            return Err(WhjError::InvalidConfig {
                reason: format!("{mode:?} targets given to a {:?} loop", self.config.mode),
            });
        }
        if raw.len() != self.config.joints.len() {
            return Err(WhjError::InvalidConfig {
                reason: format!(
                    "{} targets given for {} joints",
                    raw.len(),
                    self.config.joints.len()
                ),
            });
        }
        self.mailbox.set_targets(raw);
        Ok(())
    }

    /// Sets the position targets (one per joint; position mode). With smoothing on, far
    /// targets are approached along the speed / acceleration-limited profile; in any
    /// case the set-point sent stays within the step limit of the last measured position.
    pub fn set_positions(&self, targets: &[Position]) -> Result<(), WhjError> {
        self.set_raw(
            ServoMode::Position,
            targets.iter().map(|p| p.raw()).collect(),
        )
    }

    /// Sets the speed targets (0.002 RPM counts; speed mode).
    pub fn set_speeds(&self, targets: &[TargetSpeed]) -> Result<(), WhjError> {
        self.set_raw(ServoMode::Speed, targets.iter().map(|s| s.raw()).collect())
    }

    /// Sets the current targets (model current counts; current mode).
    pub fn set_currents(&self, targets: &[Current]) -> Result<(), WhjError> {
        self.set_raw(
            ServoMode::Current,
            targets.iter().map(|c| c.raw()).collect(),
        )
    }

    /// Waits up to `timeout` for the next cycle's report (oldest first). `None` on
    /// timeout or once the loop has stopped. On a bus with a virtual clock the wait runs
    /// the bus, and `timeout` is of its time.
    pub fn next_report(&self, timeout: Duration) -> Option<CycleReport> {
        if self.bus.virtual_time() {
            return self.drive_to_report(timeout);
        }
        self.mailbox.wait_report(Instant::now() + timeout)
    }

    /// [`Cyclic::next_report`] on a virtual clock: runs the bus (and so the loop) until a
    /// report is there or `timeout` of the bus's time has passed.
    fn drive_to_report(&self, timeout: Duration) -> Option<CycleReport> {
        let deadline = self.bus.now() + timeout;
        loop {
            match self.mailbox.try_report() {
                Polled::Report(report) => return Some(report),
                Polled::Ended => return None,
                Polled::Empty => {}
            }
            let now = self.bus.now();
            if now >= deadline {
                return None;
            }
            self.bus.sleep_until(deadline.min(now + self.config.period));
        }
    }

    /// Drops queued reports (e.g. before waiting for a fresh one).
    pub fn clear_reports(&self) {
        self.mailbox.clear_reports();
    }

    /// The most recent report, if any cycle has finished.
    pub fn latest(&self) -> Option<CycleReport> {
        self.mailbox.latest()
    }

    /// Statistics so far (final once the loop stopped).
    pub fn stats(&self) -> CyclicStats {
        self.bus.cyclic_stats(&self.mailbox)
    }

    /// Stops the loop and returns its statistics.
    pub fn stop(mut self) -> CyclicStats {
        self.halt();
        self.stats()
    }

    fn halt(&mut self) {
        if !self.stopped {
            self.stopped = true;
            self.bus.stop_cyclic(&self.mailbox);
        }
    }
}

impl Drop for Cyclic<'_> {
    fn drop(&mut self) {
        self.halt();
    }
}
