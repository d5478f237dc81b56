//! The simulated WHJ bus as an in-process [`FrameLink`] on a virtual clock.
//!
//! [`WhjSimLink`] is what a client holds instead of a CAN socket; [`WhjSimHandle`] reaches
//! the same [`WhjBus`] from any thread (inspect a joint, inject a fault, unplug the bus).
//! There is no serving thread and no wall clock: the link's clock ([`FrameLink::now`]) is
//! a fixed base instant plus the bus's simulated time, a receive runs the simulation to
//! the next frame that reaches the host (or to its deadline) and returns at once, and a
//! sleep ([`FrameLink::sleep_until`]) runs it to the sleep's end. A client on this link
//! therefore sees exactly the wire's timing, whatever the machine's load: a test can assert
//! exact instants and counts.

use core::time::Duration;
use std::collections::VecDeque;
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::time::{Instant, SystemTime};

use robobus_link::frame_link::passes;
use robobus_link::{FrameLink, FrameLinkError, IdFilter, Received};
use robobus_whj::CanFrame;

use super::bus::{Delivered, WhjBus};
use crate::faults::FaultSchedule;

#[derive(Debug)]
struct State {
    bus: WhjBus,
    /// Joint frames that reached the host and were not received yet, in wire order.
    inbox: VecDeque<Delivered>,
    faults: FaultSchedule,
    unplugged: bool,
}

impl State {
    /// Simulates up to `t` (applying the device faults due by then) and queues what
    /// reached the host.
    fn run_until(&mut self, t: Duration) {
        while let Some(due) = self.faults.next_due().filter(|due| *due <= t) {
            let delivered = self.bus.run_until(due);
            self.take(delivered);
            for f in self.faults.take_due(due) {
                self.bus.apply_fault(f);
            }
        }
        let delivered = self.bus.run_until(t);
        self.take(delivered);
    }

    fn take(&mut self, delivered: Vec<Delivered>) {
        if !self.unplugged {
            self.inbox.extend(delivered);
        }
    }
}

#[derive(Debug)]
struct Shared {
    state: Mutex<State>,
    /// The link-clock instant of the bus's time zero.
    base: Instant,
    /// The wall-clock time stamped on frames received at the bus's time zero.
    wall_base: SystemTime,
}

impl Shared {
    fn lock(&self) -> MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(PoisonError::into_inner)
    }

    fn sim_time(&self, at: Instant) -> Duration {
        at.saturating_duration_since(self.base)
    }
}

/// A client's end of a simulated WHJ bus on virtual time: no serving thread; a receive
/// runs the simulation to the next frame for the host or to its deadline and returns at
/// once, and the link's clock is a fixed base instant plus simulated time.
///
/// ```
/// use core::time::Duration;
/// use robobus_link::FrameLink;
/// use robobus_sim::whj::{WhjBus, WhjModel, WhjSimLink};
/// use robobus_whj::CanFrame;
///
/// let (mut link, handle) = WhjSimLink::new(WhjBus::chain([1], WhjModel::Whj30, 7));
/// let t0 = link.now();
/// // Release joint 1 from its bootloader (IAP_FLAG := 0) and take its acknowledgement.
/// link.send(&CanFrame::new_fd(CanFrame::standard_id(0x001)?, &[0x02, 0x49, 0x00])?)?;
/// let ack = link.recv(t0 + Duration::from_millis(5))?;
/// assert_eq!(ack.frame.raw_id(), 0x101);
/// // Simulated time moved only as far as the acknowledgement's last bit.
/// assert!(link.now() - t0 < Duration::from_millis(1));
/// assert_eq!(handle.with_bus(|b| b.stats().host_frames), 1);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Debug)]
pub struct WhjSimLink {
    shared: Arc<Shared>,
    filters: Vec<IdFilter>,
}

/// Reaches the bus behind a [`WhjSimLink`] from any thread. Cheap to clone.
#[derive(Debug, Clone)]
pub struct WhjSimHandle {
    shared: Arc<Shared>,
}

impl WhjSimLink {
    /// A link to `bus`, whose simulated time continues from its current time, and a
    /// handle on the bus.
    pub fn new(bus: WhjBus) -> (Self, WhjSimHandle) {
        Self::with_faults(bus, FaultSchedule::default())
    }

    /// Like [`WhjSimLink::new`], with device faults applied at their simulation times.
    pub fn with_faults(bus: WhjBus, faults: FaultSchedule) -> (Self, WhjSimHandle) {
        let since_zero = bus.now();
        let now = Instant::now();
        let shared = Arc::new(Shared {
            base: now.checked_sub(since_zero).unwrap_or(now),
            wall_base: SystemTime::now()
                .checked_sub(since_zero)
                .unwrap_or(SystemTime::UNIX_EPOCH),
            state: Mutex::new(State {
                bus,
                inbox: VecDeque::new(),
                faults,
                unplugged: false,
            }),
        });
        let handle = WhjSimHandle {
            shared: Arc::clone(&shared),
        };
        (
            Self {
                shared,
                filters: Vec::new(),
            },
            handle,
        )
    }

    /// A handle on the bus.
    pub fn handle(&self) -> WhjSimHandle {
        WhjSimHandle {
            shared: Arc::clone(&self.shared),
        }
    }
}

impl WhjSimHandle {
    /// Runs `f` on the bus (at its current simulated time).
    pub fn with_bus<R>(&self, f: impl FnOnce(&mut WhjBus) -> R) -> R {
        f(&mut self.shared.lock().bus)
    }

    /// The link-clock instant now (the same as the link's [`FrameLink::now`]).
    pub fn now(&self) -> Instant {
        self.shared.base + self.shared.lock().bus.now()
    }

    /// Unplugs (`true`) or replugs (`false`) the bus: while unplugged, the host's frames
    /// are lost and nothing reaches it; simulated time still runs.
    pub fn set_unplugged(&self, unplugged: bool) {
        let mut s = self.shared.lock();
        s.unplugged = unplugged;
        if unplugged {
            s.inbox.clear();
        }
    }
}

impl FrameLink for WhjSimLink {
    fn send(&mut self, frame: &CanFrame) -> Result<(), FrameLinkError> {
        let mut s = self.shared.lock();
        if !s.unplugged {
            let now = s.bus.now();
            s.bus.submit(*frame, now);
        }
        Ok(())
    }

    fn recv(&mut self, deadline: Instant) -> Result<Received, FrameLinkError> {
        let until = self.shared.sim_time(deadline);
        let mut s = self.shared.lock();
        loop {
            while let Some(d) = s.inbox.pop_front() {
                if passes(&self.filters, &d.frame) {
                    return Ok(Received {
                        frame: d.frame,
                        timestamp: Some(self.shared.wall_base + d.at),
                    });
                }
            }
            let now = s.bus.now();
            if now >= until {
                return Err(FrameLinkError::Timeout);
            }
            // The next instant anything happens (a frame starts or ends, a fault is due),
            // but at most the deadline. Everything due at the present is taken at once, so
            // time moves forward on every pass.
            let next = s
                .bus
                .next_event()
                .into_iter()
                .chain(s.faults.next_due())
                .fold(until, Duration::min)
                .max(now);
            s.run_until(next);
        }
    }

    fn set_filters(&mut self, filters: &[IdFilter]) -> Result<(), FrameLinkError> {
        self.filters = filters.to_vec();
        Ok(())
    }

    fn now(&self) -> Instant {
        self.shared.base + self.shared.lock().bus.now()
    }

    fn virtual_time(&self) -> bool {
        true
    }

    /// Zero: each frame is handed over at the simulated instant its end crossed the wire.
    fn reply_allowance(&self) -> Duration {
        Duration::ZERO
    }

    fn sleep_until(&mut self, deadline: Instant) {
        let until = self.shared.sim_time(deadline);
        let mut s = self.shared.lock();
        if until > s.bus.now() {
            s.run_until(until);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::whj::WhjModel;

    fn iap_release() -> CanFrame {
        CanFrame::new_fd(CanFrame::standard_id(0x001).unwrap(), &[0x02, 0x49, 0x00]).unwrap()
    }

    #[test]
    fn a_reply_is_received_at_the_instant_its_last_bit_leaves_the_wire() {
        // The same exchange on the bus alone gives the reference instant.
        let mut reference = WhjBus::chain([1], WhjModel::Whj30, 7);
        let expected = reference.request(iap_release())[0];

        let (mut link, handle) = WhjSimLink::new(WhjBus::chain([1], WhjModel::Whj30, 7));
        let t0 = link.now();
        link.send(&iap_release()).unwrap();
        let rx = link.recv(t0 + Duration::from_millis(5)).unwrap();
        assert_eq!(rx.frame, expected.frame);
        assert_eq!(link.now() - t0, expected.at);
        assert_eq!(handle.now(), link.now());
        // Nothing else comes: the receive times out exactly at its deadline.
        let deadline = link.now() + Duration::from_millis(3);
        assert!(link.recv(deadline).unwrap_err().is_timeout());
        assert_eq!(link.now(), deadline);
    }

    #[test]
    fn sleeping_advances_the_simulation_and_keeps_what_arrived() {
        let (mut link, _handle) = WhjSimLink::new(WhjBus::chain([1], WhjModel::Whj30, 7));
        let t0 = link.now();
        link.send(&iap_release()).unwrap();
        link.sleep_until(t0 + Duration::from_millis(10));
        assert_eq!(link.now() - t0, Duration::from_millis(10));
        // The reply arrived during the sleep; a receive with a past deadline gets it.
        assert_eq!(link.recv(t0).unwrap().frame.raw_id(), 0x101);
        link.set_filters(&[IdFilter::standard(0x102)]).unwrap();
        link.send(&iap_release()).unwrap();
        assert!(
            link.recv(t0 + Duration::from_millis(20))
                .unwrap_err()
                .is_timeout()
        );
    }

    #[test]
    fn an_unplugged_bus_loses_the_hosts_frames() {
        let (mut link, handle) = WhjSimLink::new(WhjBus::chain([1], WhjModel::Whj30, 7));
        handle.set_unplugged(true);
        let t0 = link.now();
        link.send(&iap_release()).unwrap();
        assert!(
            link.recv(t0 + Duration::from_millis(5))
                .unwrap_err()
                .is_timeout()
        );
        assert_eq!(handle.with_bus(|b| b.stats().host_frames), 0);
        handle.set_unplugged(false);
        link.send(&iap_release()).unwrap();
        assert_eq!(
            link.recv(t0 + Duration::from_millis(10))
                .unwrap()
                .frame
                .raw_id(),
            0x101
        );
    }
}
