//! The virtual clock: a host that talks to a [`Bus`] in simulated time, jumping from one
//! event to the next (deterministic, much faster than real time).

use core::time::Duration;

use robobus_wck::Command;

use super::bus::Bus;

/// A host on a [`Bus`], with its own notion of "now" that only moves when the host waits.
///
/// ```
/// use core::time::Duration;
/// use robobus_sim::wck::{Bus, BusConfig, Model, VirtualHost};
///
/// let bus = Bus::with_servos(BusConfig::default(), Model::W1108, [0]);
/// let mut host = VirtualHost::new(bus);
/// host.sleep(Duration::from_millis(70)); // past the 65 ms after power-up
/// // Status read of servo 0: FF A0 00 20 -> load, position.
/// let reply = host.transact(&[0xFF, 0xA0, 0x00, 0x20], 2, Duration::from_millis(10));
/// assert_eq!(reply, vec![0, 127]);
/// ```
#[derive(Debug)]
pub struct VirtualHost {
    bus: Bus,
    now: Duration,
}

impl VirtualHost {
    /// A host at the bus's current time.
    pub fn new(bus: Bus) -> Self {
        let now = bus.now();
        Self { bus, now }
    }

    /// The host's current time.
    pub const fn now(&self) -> Duration {
        self.now
    }

    /// The bus.
    pub const fn bus(&self) -> &Bus {
        &self.bus
    }

    /// The bus, to change (servos' test API, faults, baud).
    pub fn bus_mut(&mut self) -> &mut Bus {
        &mut self.bus
    }

    /// Gives the bus back.
    pub fn into_bus(self) -> Bus {
        self.bus
    }

    /// Lets simulated time pass until `t` (the bus runs; received bytes queue up).
    pub fn advance_to(&mut self, t: Duration) {
        if t > self.now {
            self.now = t;
        }
        self.bus.advance(self.now);
    }

    /// Lets `d` of simulated time pass.
    pub fn sleep(&mut self, d: Duration) {
        self.advance_to(self.now + d);
    }

    /// Drops every byte received so far (a host flushing its input).
    pub fn flush_input(&mut self) {
        while self.bus.pop_received().is_some() {}
    }

    /// Writes `bytes` now; returns when the last one is out on the wire. Time does not
    /// move.
    pub fn send(&mut self, bytes: &[u8]) -> Duration {
        self.bus.host_send(self.now, bytes)
    }

    /// Waits for `n` bytes, at most until `deadline`; returns what arrived, each with the
    /// instant its stop bit ended. Time moves to the last byte's arrival (or the deadline).
    pub fn receive_until(&mut self, n: usize, deadline: Duration) -> Vec<(Duration, u8)> {
        let mut out = Vec::with_capacity(n);
        loop {
            while out.len() < n {
                match self.bus.pop_received() {
                    Some(b) => out.push(b),
                    None => break,
                }
            }
            if out.len() >= n || self.now >= deadline {
                if let Some(&(t, _)) = out.last() {
                    self.now = self.now.max(t);
                }
                return out;
            }
            let next = self
                .bus
                .next_event()
                .filter(|t| *t <= deadline)
                .unwrap_or(deadline)
                .max(self.now + Duration::from_nanos(1))
                .min(deadline.max(self.now));
            self.now = next;
            self.bus.advance(next);
        }
    }

    /// Writes `bytes` and waits (at most `timeout` after the last byte is out) for `n`
    /// reply bytes. Stale input is flushed first.
    pub fn transact(&mut self, bytes: &[u8], n: usize, timeout: Duration) -> Vec<u8> {
        self.transact_timed(bytes, n, timeout)
            .into_iter()
            .map(|(_, b)| b)
            .collect()
    }

    /// Like [`VirtualHost::transact`], with the arrival time of each byte.
    pub fn transact_timed(
        &mut self,
        bytes: &[u8],
        n: usize,
        timeout: Duration,
    ) -> Vec<(Duration, u8)> {
        self.bus.advance(self.now);
        self.flush_input();
        let end = self.send(bytes);
        self.receive_until(n, end + timeout)
    }

    /// Sends a typed command and waits for its reply (if it has one) for up to 200 ms
    /// after the command is out (longer than an EEPROM write). Returns the reply bytes,
    /// possibly fewer than expected.
    pub fn command(&mut self, cmd: &Command) -> Vec<u8> {
        let packet = cmd.encode();
        let n = cmd.reply_len();
        if n == 0 {
            let end = self.send(packet.as_bytes());
            self.advance_to(end);
            return Vec::new();
        }
        self.transact(packet.as_bytes(), n, Duration::from_millis(200))
    }
}
