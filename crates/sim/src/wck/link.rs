//! The simulated bus as an in-process [`ByteLink`] on the wall clock.
//!
//! [`SimLink`] is what a client holds instead of a serial port; [`SimHandle`] reaches the
//! same [`Bus`] from any thread (push a shaft, unplug a module, read its mode). There is
//! no serving thread: the bus is brought up to the present whenever the link or a handle
//! touches it, and simulated time is the wall time since [`SimLink::new`] (plus the bus's
//! own time then).
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

#[derive(Debug)]
struct State {
    bus: Bus,
    /// How far simulated time has been fast-forwarded past the wall clock.
    skew: Duration,
}

#[derive(Debug)]
struct Shared {
    state: Mutex<State>,
    t0: Instant,
    offset: Duration,
    fast_forward: bool,
}

impl Shared {
    /// Simulated time of a wall-clock instant (at the current fast-forward skew).
    fn sim_time(&self, state: &State, at: Instant) -> Duration {
        self.offset + at.saturating_duration_since(self.t0) + state.skew
    }

    /// The bus, brought up to the present; returns it with the present's simulated time.
    fn present(&self) -> (MutexGuard<'_, State>, Duration) {
        // A panic while the bus was locked (a test closure that failed) leaves a bus that
        // is still consistent between events: keep serving it.
        let mut state = self
            .state
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        let now = self.sim_time(&state, Instant::now()).max(state.bus.now());
        state.bus.advance(now);
        (state, now)
    }
}

/// A client's end of a simulated bus, in the same process (see the [module](self) notes).
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
        Self::with_clock(bus, false)
    }

    /// Like [`SimLink::new`], but a read that would wait skips the wait instead:
    /// simulated time jumps ahead of the wall clock (and keeps running with it). Replies,
    /// timeouts and the servos' motion are what they would be; a long loop of
    /// transactions runs as fast as the processor allows.
    pub fn fast_forward(bus: Bus) -> (Self, SimHandle) {
        Self::with_clock(bus, true)
    }

    fn with_clock(bus: Bus, fast_forward: bool) -> (Self, SimHandle) {
        let baud = bus.host_bps();
        let shared = Arc::new(Shared {
            offset: bus.now(),
            state: Mutex::new(State {
                bus,
                skew: Duration::ZERO,
            }),
            t0: Instant::now(),
            fast_forward,
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
            let wait = {
                let (mut state, now) = self.shared.present();
                let bus = &mut state.bus;
                // Run the model ahead (it is deterministic) until a byte has reached the
                // host or the deadline: one sleep per byte instead of one per event.
                while bus.peek_received().is_none() {
                    match bus.next_event() {
                        Some(t) if t <= until => {
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
                    // Arrives before the deadline, in the future: wait for it.
                    Some((at, _)) if at <= until => at.saturating_sub(now),
                    // Nothing before the deadline.
                    _ if now >= until => {
                        return Err(LinkError::Timeout {
                            received: 0,
                            expected: buf.len(),
                        });
                    }
                    _ => until.saturating_sub(now),
                }
            };
            if self.shared.fast_forward {
                let (mut state, _) = self.shared.present();
                state.skew += wait;
            } else {
                std::thread::sleep(wait);
            }
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
}
