//! The simulated bus as an in-process [`ByteLink`] on the wall clock.
//!
//! [`SimLink`] is what a client holds instead of a serial port; [`SimHandle`] reaches the
//! same [`Bus`] from any thread (push a shaft, unplug a module, read its mode). There is
//! no serving thread: the bus is brought up to the present whenever the link or a handle
//! touches it, and simulated time is the wall time since [`SimLink::new`] (plus the bus's
//! own time then). On a [`SimLink::virtual_clock`] link there is no wall clock at all:
//! simulated time moves only when the client waits, and the link's
//! [`ByteLink::now`] tells it.
//!
//! Unlike a pty endpoint, where the simulator is a thread that must be scheduled to
//! answer in time, the answer is here a consequence of the model: a read returns every
//! byte whose stop bit ended before the read's deadline, even if the reading thread was
//! descheduled well past that deadline, exactly as a serial port's kernel buffer keeps a
//! real module's reply while the host process is stalled. Results therefore do not
//! depend on how loaded the machine is; only the pace does. Bytes are never handed out
//! before their arrival instant: a read waits (sleeps) until then.

use core::time::Duration;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Instant;

use robobus_link::{ByteLink, LinkError};

use super::bus::Bus;

struct State {
    bus: Bus,
    /// How far simulated time has been moved past the wall clock (fast-forward), or how
    /// far it has moved at all (virtual clock).
    skew: Duration,
    /// Changes to make at simulated instants ([`SimHandle::at`]), in the order given.
    jobs: Vec<(Duration, Job)>,
}

type Job = Box<dyn FnOnce(&mut Bus) + Send>;

impl core::fmt::Debug for State {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("State")
            .field("bus", &self.bus)
            .field("skew", &self.skew)
            .field("jobs", &self.jobs.len())
            .finish()
    }
}

impl State {
    /// The earliest instant a job is due.
    fn next_job(&self) -> Option<Duration> {
        self.jobs.iter().map(|(t, _)| *t).min()
    }

    /// Brings the bus to `now`, running every job due by then at its instant.
    fn advance(&mut self, now: Duration) {
        while let Some(t) = self.next_job().filter(|t| *t <= now) {
            self.bus.advance(t);
            if let Some(i) = self.jobs.iter().position(|(at, _)| *at == t) {
                let (_, job) = self.jobs.remove(i);
                job(&mut self.bus);
            }
        }
        self.bus.advance(now);
    }
}

/// Where simulated time comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Clock {
    /// The wall clock; a read that would wait sleeps.
    Wall,
    /// The wall clock, but a read that would wait jumps ahead instead.
    FastForward,
    /// No wall clock: time moves only when the client waits.
    Virtual,
}

#[derive(Debug)]
struct Shared {
    state: Mutex<State>,
    t0: Instant,
    offset: Duration,
    clock: Clock,
}

impl Shared {
    /// Simulated time of an instant on the link's clock.
    fn sim_time(&self, state: &State, at: Instant) -> Duration {
        let since = at.saturating_duration_since(self.t0);
        match self.clock {
            Clock::Virtual => self.offset + since,
            Clock::Wall | Clock::FastForward => self.offset + since + state.skew,
        }
    }

    /// The bus, brought up to the present; returns it with the present's simulated time.
    fn present(&self) -> (MutexGuard<'_, State>, Duration) {
        // A panic while the bus was locked (a test closure that failed) leaves a bus that
        // is still consistent between events: keep serving it.
        let mut state = self
            .state
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        let now = match self.clock {
            Clock::Virtual => self.offset + state.skew,
            Clock::Wall | Clock::FastForward => self.sim_time(&state, Instant::now()),
        }
        .max(state.bus.now());
        state.advance(now);
        (state, now)
    }

    /// The link clock's instant of the present (the inverse of [`Shared::sim_time`]).
    fn now(&self) -> Instant {
        let (state, now) = self.present();
        let skew = match self.clock {
            Clock::Virtual => Duration::ZERO,
            Clock::Wall | Clock::FastForward => state.skew,
        };
        self.t0 + now.saturating_sub(self.offset + skew)
    }

    /// Lets simulated time pass until `from + wait` (`from` is the present the wait was
    /// measured from): a sleep on the wall clock, a jump otherwise.
    fn wait(&self, from: Duration, wait: Duration) {
        match self.clock {
            Clock::Wall => std::thread::sleep(wait),
            Clock::FastForward => self.present().0.skew += wait,
            Clock::Virtual => {
                let (mut state, _) = self.present();
                // The model may have run ahead of `from` (it is deterministic): the clock
                // goes to the end of the wait, not past it.
                state.skew = state.skew.max((from + wait).saturating_sub(self.offset));
            }
        }
    }
}

/// A client's end of a simulated bus, in the same process (see the notes at the top of
/// `wck/link.rs`).
///
/// ```
/// use core::time::Duration;
/// use std::time::Instant;
/// use robobus_link::ByteLink;
/// use robobus_sim::wck::{Bus, BusConfig, Model, SimLink};
///
/// let (mut link, handle) = SimLink::new(Bus::with_servos(BusConfig::default(), Model::W1108, [0]));
/// std::thread::sleep(Duration::from_millis(70)); // past the 65 ms after power-up
/// link.write_all(&[0xFF, 0xA0, 0x00, 0x20])?; // status read of servo 0
/// let mut reply = [0u8; 2];
/// link.read_exact(&mut reply, Instant::now() + Duration::from_millis(20))?;
/// assert_eq!(reply, [0, 127]);
/// assert_eq!(handle.with_bus(|b| b.stats().replies), 1);
/// # Ok::<(), robobus_link::LinkError>(())
/// ```
#[derive(Debug)]
pub struct SimLink {
    shared: Arc<Shared>,
    baud: u32,
}

/// Reaches the bus behind a [`SimLink`] from any thread. Cheap to clone.
#[derive(Debug, Clone)]
pub struct SimHandle {
    shared: Arc<Shared>,
}

impl SimLink {
    /// A link to `bus`, whose simulated time continues from its current time, and a
    /// handle on the bus. The link starts at the bus's host baud rate.
    pub fn new(bus: Bus) -> (Self, SimHandle) {
        Self::with_clock(bus, Clock::Wall)
    }

    /// Like [`SimLink::new`], but a read that would wait skips the wait instead:
    /// simulated time jumps ahead of the wall clock (and keeps running with it). Replies,
    /// timeouts and the servos' motion are what they would be; a long loop of
    /// transactions runs as fast as the processor allows.
    pub fn fast_forward(bus: Bus) -> (Self, SimHandle) {
        Self::with_clock(bus, Clock::FastForward)
    }

    /// Like [`SimLink::new`], on a virtual clock: simulated time stands still until the
    /// client waits, and then jumps at once to the moment the wait ends (the reply's last
    /// byte, or the deadline). [`ByteLink::now`] is a fixed instant (taken when the link
    /// was made) plus the simulated time since; deadlines and [`ByteLink::sleep_until`]
    /// are measured on that clock, so a client that takes its time only from the link runs
    /// the same way on any machine, however loaded, and in no wall time. The link's
    /// [`ByteLink::virtual_time`] says so.
    pub fn virtual_clock(bus: Bus) -> (Self, SimHandle) {
        Self::with_clock(bus, Clock::Virtual)
    }

    fn with_clock(bus: Bus, clock: Clock) -> (Self, SimHandle) {
        let baud = bus.host_bps();
        let shared = Arc::new(Shared {
            offset: bus.now(),
            state: Mutex::new(State {
                bus,
                skew: Duration::ZERO,
                jobs: Vec::new(),
            }),
            t0: Instant::now(),
            clock,
        });
        let handle = SimHandle {
            shared: Arc::clone(&shared),
        };
        (Self { shared, baud }, handle)
    }

    /// A handle on the bus.
    pub fn handle(&self) -> SimHandle {
        SimHandle {
            shared: Arc::clone(&self.shared),
        }
    }
}

impl SimHandle {
    /// Runs `f` on the bus, brought up to the present first.
    pub fn with_bus<R>(&self, f: impl FnOnce(&mut Bus) -> R) -> R {
        let (mut state, _) = self.shared.present();
        f(&mut state.bus)
    }

    /// The bus's simulated time now.
    pub fn now(&self) -> Duration {
        self.shared.present().1
    }

    /// Runs `f` on the bus at simulated time `at` (at once if that has passed): an
    /// unplugged module, a pushed shaft at an exact instant of a client's run. On the
    /// virtual clock the client's waits stop there, so `f` sees the bus at `at` exactly.
    pub fn at(&self, at: Duration, f: impl FnOnce(&mut Bus) + Send + 'static) {
        let (mut state, _) = self.shared.present();
        state.jobs.push((at, Box::new(f)));
        let now = state.bus.now();
        state.advance(now);
    }

    /// Lets `d` of simulated time pass: on a virtual-clock or fast-forwarding link at once,
    /// on the wall clock by sleeping.
    pub fn sleep(&self, d: Duration) {
        let now = self.now();
        self.shared.wait(now, d);
    }
}

impl ByteLink for SimLink {
    fn write_all(&mut self, bytes: &[u8]) -> Result<(), LinkError> {
        let (mut state, now) = self.shared.present();
        state.bus.host_send(now, bytes);
        Ok(())
    }

    fn read_some(&mut self, buf: &mut [u8], deadline: Instant) -> Result<usize, LinkError> {
        if buf.is_empty() {
            return Ok(0);
        }
        let until = {
            let (state, _) = self.shared.present();
            self.shared.sim_time(&state, deadline)
        };
        loop {
            let (from, wait) = {
                let (mut state, now) = self.shared.present();
                // Jobs still to come are after `now`; the model may not run past them.
                let horizon = state.next_job().map_or(until, |t| t.min(until));
                let bus = &mut state.bus;
                // Run the model ahead (it is deterministic) until a byte has reached the
                // host or the deadline: one sleep per byte instead of one per event.
                while bus.peek_received().is_none() {
                    match bus.next_event() {
                        Some(t) if t <= horizon => {
                            let step = t.max(bus.now() + Duration::from_nanos(100));
                            bus.advance(step);
                        }
                        _ => break,
                    }
                }
                match bus.peek_received() {
                    // Arrived by now (and by the deadline): hand out what has.
                    Some((at, _)) if at <= now && at <= until => {
                        let mut n = 0;
                        for slot in buf.iter_mut() {
                            match bus.peek_received() {
                                Some((at, byte)) if at <= now && at <= until => {
                                    *slot = byte;
                                    bus.pop_received();
                                    n += 1;
                                }
                                _ => break,
                            }
                        }
                        return Ok(n);
                    }
                    // Arrives before the deadline (and the next job), in the future: wait.
                    Some((at, _)) if at <= horizon => (now, at.saturating_sub(now)),
                    // Nothing before the deadline.
                    _ if now >= until => {
                        return Err(LinkError::Timeout {
                            received: 0,
                            expected: buf.len(),
                        });
                    }
                    // Nothing before the next job (or the deadline): wait until then.
                    _ => (now, horizon.saturating_sub(now)),
                }
            };
            self.shared.wait(from, wait);
        }
    }

    fn discard_input(&mut self) -> Result<(), LinkError> {
        let (mut state, _) = self.shared.present();
        while state.bus.pop_received().is_some() {}
        Ok(())
    }

    fn set_baud(&mut self, baud: u32) -> Result<(), LinkError> {
        let (mut state, _) = self.shared.present();
        state.bus.set_host_bps(baud);
        self.baud = baud;
        Ok(())
    }

    fn baud(&self) -> Option<u32> {
        Some(self.baud)
    }

    fn now(&self) -> Instant {
        self.shared.now()
    }

    fn sleep_until(&mut self, deadline: Instant) {
        let (now, wait) = {
            let (state, now) = self.shared.present();
            (
                now,
                self.shared.sim_time(&state, deadline).saturating_sub(now),
            )
        };
        if !wait.is_zero() {
            self.shared.wait(now, wait);
        }
    }

    fn virtual_time(&self) -> bool {
        self.shared.clock == Clock::Virtual
    }
}
