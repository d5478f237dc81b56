//! The driver proper: the link and the [`Session`] behind one lock ([`CoreLock`]), one
//! step of the session's calling order ([`Core::step`]), and the publishing of what the
//! session polls out (telemetry, cycle reports, the loop's end) whenever the lock is let
//! go ([`CoreGuard`]). The bus's own thread ([`background`]) is here too.

use core::fmt;
use core::time::Duration;
use std::ops::{Deref, DerefMut};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, TryRecvError};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Instant;

use robobus_link::{FrameLink, FrameLinkError, wait};

use super::mailbox::CyclicMailbox;
use super::{Shared, lock};
use crate::whj::session::{Event, Session};

/// How often the bus thread reads unsolicited frames while nothing else uses the bus
/// (rarely: on a link whose receive timeout rounds up to the kernel tick, an empty read
/// costs a tick).
pub(super) const DRAIN_INTERVAL: Duration = Duration::from_millis(100);

/// What the bus's own thread is told.
#[derive(Debug)]
pub(super) enum Wake {
    /// A cyclic loop started, or replies to a broadcast frame are due.
    Work,
    Shutdown,
}

/// The link and the session, and how many threads wait for them.
pub(super) struct CoreLock {
    core: Mutex<Core>,
    /// Threads waiting for `core` (the bus thread lets them in between its steps).
    waiters: AtomicUsize,
}

impl fmt::Debug for CoreLock {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("CoreLock").finish_non_exhaustive()
    }
}

impl CoreLock {
    pub(super) fn new(core: Core) -> Self {
        Self {
            core: Mutex::new(core),
            waiters: AtomicUsize::new(0),
        }
    }

    /// The core, published when the guard is dropped.
    pub(super) fn lock(&self) -> CoreGuard<'_> {
        self.waiters.fetch_add(1, Ordering::AcqRel);
        let g = lock(&self.core);
        self.waiters.fetch_sub(1, Ordering::AcqRel);
        CoreGuard(g)
    }
}

/// The locked core: whatever the session has to publish is published before the lock is
/// let go, so a caller that reads the telemetry or a loop's reports after a call sees
/// what that call did.
pub(super) struct CoreGuard<'a>(MutexGuard<'a, Core>);

impl Deref for CoreGuard<'_> {
    type Target = Core;

    fn deref(&self) -> &Core {
        &self.0
    }
}

impl DerefMut for CoreGuard<'_> {
    fn deref_mut(&mut self) -> &mut Core {
        &mut self.0
    }
}

impl Drop for CoreGuard<'_> {
    fn drop(&mut self) {
        self.0.publish();
    }
}

/// The driver: the link and the session it feeds.
pub(super) struct Core {
    pub(super) link: Box<dyn FrameLink + Send>,
    pub(super) session: Session,
    pub(super) shared: Arc<Shared>,
    /// The running loop's handle side: its targets, its reports and its end go through it.
    pub(super) cyclic: Option<Arc<CyclicMailbox>>,
    pub(super) last_drain: Instant,
    pub(super) closed: bool,
}

impl Core {
    pub(super) fn now(&self) -> Instant {
        self.link.now()
    }

    /// One step of the session: time passes, due frames go out, then one frame (or
    /// error) is received, or the link's clock is left to run, until the next event or
    /// `until`, whichever is first. With `listen`, the step receives even when the session
    /// awaits nothing (frames that answer a broadcast land in the telemetry).
    pub(super) fn step(&mut self, until: Instant, listen: bool) {
        if self.closed {
            return;
        }
        if !self.transmit() {
            return;
        }
        // A tick's report or a reply is published before the wait.
        self.publish();
        let now = self.link.now();
        let wake = self.session.next_deadline(now).min(until).max(now);
        if listen || self.session.awaiting() || self.session.broadcast_pending(now) {
            self.last_drain = now;
            let expected = self.session.earliest_reply(now);
            match wait::recv(&mut *self.link, wake, expected, self.session.wait_mode()) {
                Ok(rx) => {
                    let at = self.link.now();
                    self.session.handle_frame(&rx.frame, at);
                }
                Err(FrameLinkError::Timeout) => {}
                Err(e) => self.link_error(&e),
            }
        } else if wake > now {
            wait::sleep_until(&mut *self.link, wake, self.session.wait_mode());
        }
        // Whatever became due meanwhile (a tick, the next queued request) goes out now.
        if !self.closed {
            self.transmit();
        }
    }

    /// Lets time pass in the session and sends what is due; `false` if the link closed.
    fn transmit(&mut self) -> bool {
        if self.session.cyclic_due(self.link.now()) {
            // Frames received before the next cycle's command goes out answer earlier
            // commands: take them before the tick (the loop does not read between a
            // closed cycle and the next tick, and a late-running thread reaches the tick
            // with frames still queued).
            self.drain();
            if self.closed {
                return false;
            }
            if let Some(targets) = self.cyclic.as_ref().and_then(|m| m.take_targets()) {
                self.session.set_cyclic_targets(targets);
            }
        }
        if self.session.hold_ends(self.link.now()) {
            // A second answer received by the end of a hold counts: taken before the hold
            // credits its reply.
            self.drain();
            if self.closed {
                return false;
            }
        }
        let now = self.link.now();
        self.session.handle_timeout(now);
        while let Some(tx) = self.session.poll_transmit(now) {
            match self.link.send(&tx.frame) {
                Ok(()) => self.session.handle_sent(),
                Err(e) => {
                    self.session.handle_send_failed(&tx, &e, self.link.now());
                    if matches!(e, FrameLinkError::Closed { .. }) {
                        self.fatal(&e);
                        return false;
                    }
                }
            }
        }
        true
    }

    /// Picks up frames that arrived while nothing was awaited, without waiting.
    pub(super) fn drain(&mut self) {
        self.last_drain = self.link.now();
        for _ in 0..64 {
            if self.closed {
                return;
            }
            let now = self.link.now();
            match self.link.recv(now) {
                Ok(rx) => self.session.handle_frame(&rx.frame, now),
                Err(FrameLinkError::Timeout) => return,
                Err(e) => {
                    self.link_error(&e);
                    return;
                }
            }
        }
    }

    fn link_error(&mut self, e: &FrameLinkError) {
        let now = self.link.now();
        match e {
            FrameLinkError::Closed { .. } => self.fatal(e),
            FrameLinkError::BusOff { .. }
            | FrameLinkError::ErrorPassive { .. }
            | FrameLinkError::BusError { .. } => self.session.handle_link_error(e, now),
            // A transient operating-system error: back off briefly.
            _ => {
                self.session.handle_link_error(e, now);
                self.link.sleep_until(now + Duration::from_millis(1));
            }
        }
    }

    /// The link is gone: every transaction fails, the loop ends, the bus stops.
    pub(super) fn fatal(&mut self, e: &FrameLinkError) {
        let detail = e.to_string();
        tracing::error!(error = %detail, "WHJ bus link failed");
        *lock(&self.shared.fatal) = Some(detail.clone());
        self.session.handle_closed(&detail);
        self.closed = true;
    }

    /// Publishes what the session polls out: the telemetry that changed, whether a loop
    /// runs, the loop's reports and its end into its mailbox.
    pub(super) fn publish(&mut self) {
        if self.session.telemetry_changed() {
            self.session
                .poll_telemetry(&mut lock(&self.shared.telemetry));
        }
        self.shared
            .cyclic_running
            .store(self.session.cyclic_running(), Ordering::Release);
        while let Some(event) = self.session.poll_event() {
            match event {
                Event::Cycle(report) => {
                    if let Some(m) = &self.cyclic {
                        m.push_report(report);
                    }
                }
                Event::CyclicEnded(stats) => {
                    if let Some(m) = self.cyclic.take() {
                        m.finish(stats);
                    }
                }
            }
        }
    }
}

/// The bus's own thread: runs the cyclic loop while one runs, receives the replies to a
/// broadcast frame while they are due; otherwise picks up unsolicited frames every
/// [`DRAIN_INTERVAL`] while nothing else uses the bus.
pub(super) fn background(core: &CoreLock, wake: &Receiver<Wake>) {
    let mut wait = DRAIN_INTERVAL;
    loop {
        match wake.recv_timeout(wait) {
            Ok(Wake::Shutdown) | Err(RecvTimeoutError::Disconnected) => return,
            Ok(Wake::Work) | Err(RecvTimeoutError::Timeout) => {}
        }
        loop {
            let mut c = core.lock();
            if c.closed {
                wait = DRAIN_INTERVAL;
                break;
            }
            let now = c.now();
            if c.session.cyclic_running() || c.session.broadcast_pending(now) {
                let until = now + DRAIN_INTERVAL;
                c.step(until, false);
                drop(c);
                // Callers waiting for the lock go first.
                for _ in 0..1000 {
                    if core.waiters.load(Ordering::Acquire) == 0 {
                        break;
                    }
                    std::thread::yield_now();
                }
                match wake.try_recv() {
                    Ok(Wake::Shutdown) | Err(TryRecvError::Disconnected) => return,
                    Ok(Wake::Work) | Err(TryRecvError::Empty) => {}
                }
                continue;
            }
            let now = c.now();
            if c.session.is_idle() && now.saturating_duration_since(c.last_drain) >= DRAIN_INTERVAL
            {
                c.drain();
            }
            wait = (c.last_drain + DRAIN_INTERVAL)
                .saturating_duration_since(now)
                .max(Duration::from_millis(1));
            break;
        }
    }
}
