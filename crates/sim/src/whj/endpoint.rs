//! Serving a simulated bus on a real [`FrameLink`] (python-can UDP bus, `SocketCAN`) on the
//! wall clock.
//!
//! Every frame the link receives enters the bus model at its arrival time as a host
//! frame: it still takes its wire time, arbitration and the joints' processing delay, so
//! a client sees the latency a real 1 / 5 Mbit/s bus would give it. Each joint frame is
//! sent on the link as soon as the wall clock passes the instant its last bit would
//! leave the wire. One thread owns the bus; [`serve`] returns when `stop` is set.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use robobus_link::{FrameLink, FrameLinkError, MemoryBus, WaitMode, wait};

use super::bus::WhjBus;
use crate::faults::FaultSchedule;
use crate::lateness::{Lateness, LatenessSummary};

/// How long [`serve`] waits at most between two looks at `stop` (and at the joints'
/// timers).
const MAX_WAIT: Duration = Duration::from_millis(2);

/// What [`serve`] did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ServeStats {
    /// Frames received from the link.
    pub received: u64,
    /// Frames the joints sent on the link.
    pub sent: u64,
    /// Largest delay between a frame's due time and its send, over all sent frames.
    pub max_lateness: Duration,
    /// Bus errors reported by the link (bus-off, error passive) that were skipped.
    pub bus_errors: u64,
    /// How late the frames were sent after their release instants (p50, p99).
    pub lateness: LatenessSummary,
    /// How the serving thread waited.
    pub wait: WaitMode,
}

/// A simulated bus served by [`serve`] on a thread of its own, until [`Served::stop`] (or
/// drop): what a test, an example or an in-process demo starts instead of hand-rolling
/// the thread and its stop flag.
#[derive(Debug)]
pub struct Served {
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<Result<(WhjBus, ServeStats), FrameLinkError>>>,
}

impl Served {
    /// Serves `bus` on `link` on a new thread named `name`.
    ///
    /// Errors: the thread cannot be started.
    pub fn spawn<L: FrameLink + Send + 'static>(
        name: &str,
        mut bus: WhjBus,
        mut link: L,
    ) -> std::io::Result<Self> {
        Self::start(name, move |stop| {
            serve(&mut bus, &mut link, stop).map(|stats| (bus, stats))
        })
    }

    /// [`Served::spawn`] in the precise mode ([`serve_precise`]): the thread polls for
    /// frames and spins to each release instant, one core busy while it serves.
    ///
    /// Errors: the thread cannot be started.
    pub fn spawn_precise<L: FrameLink + Send + 'static>(
        name: &str,
        mut bus: WhjBus,
        mut link: L,
    ) -> std::io::Result<Self> {
        Self::start(name, move |stop| {
            serve_precise(&mut bus, &mut link, stop).map(|stats| (bus, stats))
        })
    }

    /// [`Served::spawn`] with device faults applied at their simulation times (see
    /// [`serve_with`]); returns once the loop serves, so the faults' times and a client's
    /// first frame count from the same start.
    ///
    /// Errors: the thread cannot be started.
    pub fn spawn_with<L: FrameLink + Send + 'static>(
        name: &str,
        mut bus: WhjBus,
        mut link: L,
        faults: FaultSchedule,
    ) -> std::io::Result<Self> {
        let (ready, serving) = std::sync::mpsc::channel();
        let served = Self::start(name, move |stop| {
            serve_with(&mut bus, &mut link, stop, faults, move || {
                let _ = ready.send(());
            })
            .map(|stats| (bus, stats))
        })?;
        // An error before the loop serves ends the thread: `stop` reports it.
        let _ = serving.recv();
        Ok(served)
    }

    /// [`Served::spawn`] with `observe` called with the bus as it is served (see
    /// [`serve_observed`]).
    ///
    /// Errors: the thread cannot be started.
    pub fn spawn_observed<L: FrameLink + Send + 'static>(
        name: &str,
        mut bus: WhjBus,
        mut link: L,
        observe: impl FnMut(&mut WhjBus) + Send + 'static,
    ) -> std::io::Result<Self> {
        Self::start(name, move |stop| {
            serve_observed(
                &mut bus,
                &mut link,
                stop,
                FaultSchedule::default(),
                || {},
                observe,
            )
            .map(|stats| (bus, stats))
        })
    }

    /// Runs `serving` with the stop flag on a new thread named `name`.
    fn start(
        name: &str,
        serving: impl FnOnce(&AtomicBool) -> Result<(WhjBus, ServeStats), FrameLinkError>
        + Send
        + 'static,
    ) -> std::io::Result<Self> {
        let stop = Arc::new(AtomicBool::new(false));
        let flag = Arc::clone(&stop);
        let thread = std::thread::Builder::new()
            .name(name.to_owned())
            .spawn(move || serving(&flag))?;
        Ok(Self {
            stop,
            thread: Some(thread),
        })
    }

    /// Stops serving and returns the bus (the joints as the clients left them) and what
    /// was served.
    ///
    /// Errors: the link failed while serving; a panic of the serving thread is resumed.
    pub fn stop(mut self) -> Result<(WhjBus, ServeStats), FrameLinkError> {
        self.halt()
            .unwrap_or_else(|| unreachable!("a Served is stopped once"))
    }

    fn halt(&mut self) -> Option<Result<(WhjBus, ServeStats), FrameLinkError>> {
        self.stop.store(true, Ordering::Relaxed);
        let thread = self.thread.take()?;
        Some(match thread.join() {
            Ok(r) => r,
            Err(panic) => std::panic::resume_unwind(panic),
        })
    }
}

impl Drop for Served {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// Serves `bus` on a new in-memory CAN FD bus, on a thread of its own (a [`Served`] named
/// `robobus-sim-whj`): the shortest way to a simulated WHJ bus in a test, an example or a
/// demo. Open clients on the returned bus's endpoints (`JointBus::open(wire.endpoint())`).
///
/// Errors: the thread cannot be started.
pub fn spawn(bus: WhjBus) -> std::io::Result<(Served, MemoryBus)> {
    let wire = MemoryBus::new();
    let served = Served::spawn("robobus-sim-whj", bus, wire.endpoint())?;
    Ok((served, wire))
}

/// Serve `bus` on `link` until `stop` is set. The bus's time 0 is the call's start.
///
/// Errors: a link that fails to send or receive (other than a timeout or a reported bus
/// error, which are counted and skipped).
pub fn serve<L: FrameLink + ?Sized>(
    bus: &mut WhjBus,
    link: &mut L,
    stop: &AtomicBool,
) -> Result<ServeStats, FrameLinkError> {
    serve_with(bus, link, stop, FaultSchedule::default(), || {})
}

/// [`serve`] in the precise mode: instead of sleeping until the next frame is due or a
/// frame arrives, the loop polls the link without blocking and sends each frame when the
/// wall clock reaches its release instant, so the replies keep their modelled timing
/// however slowly the machine wakes threads. One core stays busy while it serves; for
/// benchmarks that measure a client against a device that keeps its timing.
///
/// Errors: as [`serve`].
pub fn serve_precise<L: FrameLink + ?Sized>(
    bus: &mut WhjBus,
    link: &mut L,
    stop: &AtomicBool,
) -> Result<ServeStats, FrameLinkError> {
    serve_loop(
        bus,
        link,
        stop,
        FaultSchedule::default(),
        || {},
        |_| {},
        WaitMode::SPIN,
    )
}

/// [`serve`] with device faults applied at their simulation times, and `on_serving`
/// called once the loop is about to take its first frame (announce readiness there:
/// nothing a client sends is missed from then on).
pub fn serve_with<L: FrameLink + ?Sized>(
    bus: &mut WhjBus,
    link: &mut L,
    stop: &AtomicBool,
    faults: FaultSchedule,
    on_serving: impl FnOnce(),
) -> Result<ServeStats, FrameLinkError> {
    serve_observed(bus, link, stop, faults, on_serving, |_| {})
}

/// [`serve_with`] with `observe` called with the bus after every frame received and every
/// wake-up (at least every few milliseconds): how a front end shows the simulated joints'
/// own state (not read over the bus) while they are served, or acts on them (a hand that
/// moves a joint).
pub fn serve_observed<L: FrameLink + ?Sized>(
    bus: &mut WhjBus,
    link: &mut L,
    stop: &AtomicBool,
    faults: FaultSchedule,
    on_serving: impl FnOnce(),
    observe: impl FnMut(&mut WhjBus),
) -> Result<ServeStats, FrameLinkError> {
    serve_loop(
        bus,
        link,
        stop,
        faults,
        on_serving,
        observe,
        WaitMode::Sleep,
    )
}

fn serve_loop<L: FrameLink + ?Sized>(
    bus: &mut WhjBus,
    link: &mut L,
    stop: &AtomicBool,
    mut faults: FaultSchedule,
    on_serving: impl FnOnce(),
    mut observe: impl FnMut(&mut WhjBus),
    wait: WaitMode,
) -> Result<ServeStats, FrameLinkError> {
    let origin = Instant::now()
        .checked_sub(bus.now())
        .unwrap_or_else(Instant::now);
    let mut stats = ServeStats {
        wait,
        ..ServeStats::default()
    };
    let mut lateness = Lateness::new();
    let mut on_serving = Some(on_serving);
    while !stop.load(Ordering::Relaxed) {
        let now = origin.elapsed();
        while let Some(due) = faults.next_due().filter(|t| *t <= now) {
            // Frames up to the fault's instant first, then the fault.
            for d in bus.run_until(due) {
                link.send(&d.frame)?;
                stats.sent += 1;
            }
            for f in faults.take_due(due) {
                tracing::info!(fault = %f, "device fault");
                bus.apply_fault(f);
            }
        }
        for d in bus.run_until(now) {
            tracing::trace!(frame = ?d.frame, due = ?d.at, "tx");
            link.send(&d.frame)?;
            stats.sent += 1;
            let late = origin.elapsed().saturating_sub(d.at);
            stats.max_lateness = stats.max_lateness.max(late);
            lateness.record(late);
        }
        let wake = bus
            .next_event()
            .into_iter()
            .chain(faults.next_due())
            .fold(now + MAX_WAIT, Duration::min);
        if let Some(ready) = on_serving.take() {
            ready();
        }
        // A host frame may come at any time: the precise mode polls from now on.
        match wait::recv(link, origin + wake, Instant::now(), wait) {
            Ok(rx) => {
                tracing::trace!(frame = ?rx.frame, "rx");
                stats.received += 1;
                bus.submit(rx.frame, origin.elapsed());
            }
            Err(FrameLinkError::Timeout) => {}
            Err(
                FrameLinkError::BusOff { .. }
                | FrameLinkError::ErrorPassive { .. }
                | FrameLinkError::BusError { .. },
            ) => {
                stats.bus_errors += 1;
            }
            Err(e) => return Err(e),
        }
        observe(bus);
    }
    stats.lateness = lateness.summary();
    Ok(stats)
}
