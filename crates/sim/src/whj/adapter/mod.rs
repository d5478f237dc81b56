//! Emulated serial-line CAN FD adapters (slcan, fdcanusb) with the simulated joints
//! behind them.
//!
//! An adapter is a sans-IO state machine ([`AdapterModel`]): it takes the host's bytes and
//! the bus's frames, each at its instant, and gives frames for the bus and bytes for the
//! host, each released at the instant its own timing model says ([`AdapterModel::poll`],
//! [`AdapterModel::next_due`]). Two drivers put it between a host and a [`WhjSimLink`]
//! (the simulated bus on its own clock):
//!
//! - [`run`]: on the wall clock, between a byte stream (a pty at a path, a TCP
//!   connection) and the bus, kept in step with the wall clock; what a simulator process
//!   serves a client program on.
//! - [`AdapterSimLink`]: the same on the virtual clock, as an in-process [`ByteLink`]: a
//!   client's read runs adapter and bus to the next byte for the host or to its deadline
//!   and returns at once, so a client suite over the adapter runs on simulated time.
//!
//! Both process events in time order: the bus is run up to the adapter's next instant
//! (handing the model each joint frame at the instant its last bit left the wire), then
//! the model releases what is due, so a frame the adapter puts on the bus starts exactly
//! when the model says. The adapter's bit rates ([`AdapterModel::bus_rates`]) become the
//! bus's ([`WhjBus::set_rates`]): a joint at other rates hears nothing.
//!
//! # Serial time
//!
//! [`SerialTime`] is the one timing option of an adapter's host link: every character
//! costs [`SerialTime::per_char`] in each direction, and a direction carries one message
//! after the other ([`SerialLine`]). The default, 10 µs a character (a USB full-speed CDC
//! link's effective rate for the short messages of these protocols, 1 Mbit/s with 10
//! bits a character), makes an slcan CAN FD frame of n data bytes (2n + 6 characters)
//! cost 60 + 20n µs each way. USB's 1 ms frame and the host controller's polling are not
//! modelled: the wire plus this serial time is the best a real adapter gives.

pub mod fdcanusb;
pub mod slcan;

use core::time::Duration;
use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use robobus_link::{ByteLink, FrameLink, FrameLinkError, LinkError};
use robobus_whj::CanFrame;
use robobus_whj::timing::BitRates;

pub use self::fdcanusb::FdcanusbAdapter;
pub use self::slcan::SlcanAdapter;
use super::bus::WhjBus;
use super::link::{WhjSimHandle, WhjSimLink};

/// Something an adapter gives out.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Output {
    /// A frame to put on the bus now.
    Bus(CanFrame),
    /// Bytes for the host now.
    Host(Vec<u8>),
}

/// An emulated serial-line CAN adapter: a sans-IO state machine on instants it is given.
pub trait AdapterModel: Send {
    /// The host's bytes arrived at `at`.
    fn host_bytes(&mut self, bytes: &[u8], at: Instant);

    /// A frame from another node reached the adapter at `at` (its last bit).
    fn bus_frame(&mut self, frame: &CanFrame, at: Instant);

    /// The next instant something is due, if anything is queued.
    fn next_due(&self) -> Option<Instant>;

    /// Releases, in order, everything due by `now` into `out`.
    fn poll(&mut self, now: Instant, out: &mut Vec<Output>);

    /// The bit rates the adapter's controller is at while it is on the bus, `None` while
    /// its channel is closed (it sends and receives nothing then).
    fn bus_rates(&self) -> Option<BitRates>;
}

impl<M: AdapterModel + ?Sized> AdapterModel for Box<M> {
    fn host_bytes(&mut self, bytes: &[u8], at: Instant) {
        (**self).host_bytes(bytes, at);
    }
    fn bus_frame(&mut self, frame: &CanFrame, at: Instant) {
        (**self).bus_frame(frame, at);
    }
    fn next_due(&self) -> Option<Instant> {
        (**self).next_due()
    }
    fn poll(&mut self, now: Instant, out: &mut Vec<Output>) {
        (**self).poll(now, out);
    }
    fn bus_rates(&self) -> Option<BitRates> {
        (**self).bus_rates()
    }
}

/// What every emulated adapter holds between its host and the bus: the host's lines on
/// their way in, frames for the bus, and bytes for the host on their way out, each with
/// the instant it is through.
#[derive(Debug, Clone)]
pub struct Queues<L> {
    /// The host's lines, each ready once its last character is through.
    pub from_host: SerialLine<L>,
    /// Bytes for the host, each released once its last character is through.
    pub to_host: SerialLine<Vec<u8>>,
    to_bus: VecDeque<(Instant, CanFrame)>,
}

impl<L> Queues<L> {
    /// Empty queues on a host link of `serial` time.
    pub const fn new(serial: SerialTime) -> Self {
        Self {
            from_host: SerialLine::new(serial),
            to_host: SerialLine::new(serial),
            to_bus: VecDeque::new(),
        }
    }

    /// Queues `frame` for the bus at `at`; `false` (dropped) when
    /// [`SerialLine::CAPACITY`] frames already wait.
    pub fn to_bus(&mut self, at: Instant, frame: CanFrame) -> bool {
        if self.to_bus.len() >= SerialLine::<()>::CAPACITY {
            return false;
        }
        self.to_bus.push_back((at, frame));
        true
    }

    /// Drops the frames not yet on the bus (the channel closed).
    pub fn clear_bus(&mut self) {
        self.to_bus.clear();
    }

    /// The next instant anything is due.
    pub fn next_due(&self) -> Option<Instant> {
        [
            self.from_host.next_due(),
            self.to_host.next_due(),
            self.to_bus.front().map(|(t, _)| *t),
        ]
        .into_iter()
        .flatten()
        .min()
    }

    /// Releases the frames for the bus and the host's bytes due by `now` into `out`, in
    /// that order (the host's lines are the adapter's to carry out first).
    pub fn release(&mut self, now: Instant, out: &mut Vec<Output>) {
        while let Some((_, frame)) = self.to_bus.front().filter(|(t, _)| *t <= now).copied() {
            self.to_bus.pop_front();
            out.push(Output::Bus(frame));
        }
        let mut bytes = Vec::new();
        while let Some((_, msg)) = self.to_host.pop_due(now) {
            bytes.extend_from_slice(&msg);
        }
        if !bytes.is_empty() {
            out.push(Output::Host(bytes));
        }
    }
}

/// The serial time of an adapter's host link: what each character costs, each way. See
/// the [module notes](self#serial-time).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SerialTime {
    /// Time per character.
    pub per_char: Duration,
}

impl SerialTime {
    /// 10 µs a character: a USB full-speed CDC link's effective rate for short messages.
    pub const USB_CDC: Self = Self {
        per_char: Duration::from_micros(10),
    };

    /// The time `chars` characters take.
    pub fn of(&self, chars: usize) -> Duration {
        self.per_char
            .saturating_mul(u32::try_from(chars).unwrap_or(u32::MAX))
    }
}

impl Default for SerialTime {
    fn default() -> Self {
        Self::USB_CDC
    }
}

/// One direction of a serial link: messages pass one after the other, each for its
/// characters' time; at most [`SerialLine::CAPACITY`] wait (more is an overrun the
/// caller is told of).
#[derive(Debug, Clone)]
pub struct SerialLine<T> {
    time: SerialTime,
    free: Option<Instant>,
    queue: VecDeque<(Instant, T)>,
}

impl<T> SerialLine<T> {
    /// Messages that may wait at once.
    pub const CAPACITY: usize = 4096;

    /// An idle line.
    pub const fn new(time: SerialTime) -> Self {
        Self {
            time,
            free: None,
            queue: VecDeque::new(),
        }
    }

    /// Queues `item` of `chars` characters, ready at `at`; returns the instant its last
    /// character is through, or `None` (dropped) when the line is full.
    pub fn send(&mut self, at: Instant, chars: usize, item: T) -> Option<Instant> {
        if self.queue.len() >= Self::CAPACITY {
            return None;
        }
        let start = self.free.map_or(at, |f| f.max(at));
        let done = start + self.time.of(chars);
        self.free = Some(done);
        self.queue.push_back((done, item));
        Some(done)
    }

    /// When the next message is through.
    pub fn next_due(&self) -> Option<Instant> {
        self.queue.front().map(|(t, _)| *t)
    }

    /// The next message if it is through by `now`, with its instant.
    pub fn pop_due(&mut self, now: Instant) -> Option<(Instant, T)> {
        if self.next_due()? <= now {
            self.queue.pop_front()
        } else {
            None
        }
    }

    /// Messages waiting.
    pub fn len(&self) -> usize {
        self.queue.len()
    }

    /// Whether nothing waits.
    pub fn is_empty(&self) -> bool {
        self.queue.is_empty()
    }
}

/// What a driver moved.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct AdapterStats {
    /// Bytes the host wrote.
    pub host_bytes_in: u64,
    /// Bytes given to the host.
    pub host_bytes_out: u64,
    /// Frames the adapter put on the bus.
    pub frames_to_bus: u64,
    /// Frames the adapter received from the bus.
    pub frames_from_bus: u64,
}

/// Moves the adapter and the bus to `until` in time order, calling `to_host` with the
/// bytes released for the host (and returning right after the first bytes if
/// `stop_at_host`, the bus's clock then at their instant). The bus link is a
/// [`WhjSimLink`], possibly wrapped.
#[allow(clippy::too_many_arguments)] // the driver's state, borrowed field by field
fn advance<B: FrameLink + ?Sized>(
    model: &mut dyn AdapterModel,
    bus: &mut B,
    handle: &WhjSimHandle,
    rates: &mut Option<BitRates>,
    until: Instant,
    stop_at_host: bool,
    stats: &mut AdapterStats,
    to_host: &mut dyn FnMut(Vec<u8>) -> Result<(), LinkError>,
) -> Result<(), LinkError> {
    let mut out = Vec::new();
    let mut gave = false;
    loop {
        let due = model.next_due().filter(|t| *t <= until);
        let upto = due.unwrap_or(until);
        match bus.recv(upto) {
            Ok(rx) => {
                stats.frames_from_bus += 1;
                model.bus_frame(&rx.frame, bus.now());
                continue;
            }
            Err(FrameLinkError::Timeout) => {}
            Err(
                FrameLinkError::BusOff { .. }
                | FrameLinkError::ErrorPassive { .. }
                | FrameLinkError::BusError { .. },
            ) => continue,
            Err(e) => {
                return Err(LinkError::Closed {
                    context: format!("the simulated bus behind the adapter: {e}"),
                });
            }
        }
        out.clear();
        model.poll(upto, &mut out);
        sync_rates(model, handle, rates);
        for o in out.drain(..) {
            match o {
                Output::Bus(frame) => {
                    stats.frames_to_bus += 1;
                    bus.send(&frame).map_err(|e| LinkError::Closed {
                        context: format!("the simulated bus behind the adapter: {e}"),
                    })?;
                }
                Output::Host(bytes) => {
                    stats.host_bytes_out += bytes.len() as u64;
                    gave = true;
                    to_host(bytes)?;
                }
            }
        }
        if due.is_none() || (stop_at_host && gave) {
            return Ok(());
        }
    }
}

/// Makes the bus's rates the adapter's (a closed channel leaves them).
fn sync_rates(model: &dyn AdapterModel, handle: &WhjSimHandle, last: &mut Option<BitRates>) {
    let now = model.bus_rates();
    if now.is_some() && now != *last {
        if let Some(r) = now {
            handle.with_bus(|b| b.set_rates(r));
        }
        *last = now;
    }
}

/// The longest the wall-clock driver waits without looking at `stop` and the joints.
const MAX_WAIT: Duration = Duration::from_millis(2);

/// Serves the adapter `model` with the simulated bus `bus` (a [`WhjSimLink`], possibly
/// wrapped in fault injection or capture; `handle` reaches its [`WhjBus`]) to the host on
/// `host`, on the wall clock, until `stop` is set. `on_serving` is called once the first
/// host byte can be taken; `observe` with the bus after every wake-up.
///
/// # Errors
/// The host link fails or closes ([`LinkError::Closed`] when a TCP client leaves), or
/// the bus link fails.
pub fn run<H: ByteLink + ?Sized, B: FrameLink + ?Sized>(
    model: &mut dyn AdapterModel,
    host: &mut H,
    bus: &mut B,
    handle: &WhjSimHandle,
    stop: &AtomicBool,
    on_serving: impl FnOnce(),
    mut observe: impl FnMut(&mut WhjBus),
) -> Result<AdapterStats, LinkError> {
    let mut stats = AdapterStats::default();
    let mut rates = None;
    let mut on_serving = Some(on_serving);
    let mut buf = [0u8; 4096];
    while !stop.load(Ordering::Relaxed) {
        let now = Instant::now();
        advance(
            model,
            bus,
            handle,
            &mut rates,
            now,
            false,
            &mut stats,
            &mut |bytes| host.write_all(&bytes),
        )?;
        handle.with_bus(&mut observe);
        let bus_next = handle.with_bus(|b| b.next_event().map(|t| now + t.saturating_sub(b.now())));
        let wake = [model.next_due(), bus_next]
            .into_iter()
            .flatten()
            .fold(now + MAX_WAIT, Instant::min);
        if let Some(ready) = on_serving.take() {
            ready();
        }
        match host.read_some(&mut buf, wake) {
            Ok(n) => {
                stats.host_bytes_in += n as u64;
                model.host_bytes(buf.get(..n).unwrap_or_default(), Instant::now());
            }
            Err(LinkError::Timeout { .. }) => {}
            Err(e) => return Err(e),
        }
    }
    Ok(stats)
}

/// An emulated adapter with simulated joints behind it as an in-process [`ByteLink`] on
/// the virtual clock: what a client opens instead of a serial port to run a suite over
/// the adapter on simulated time. A read runs adapter and bus to the next byte for the
/// host or to its deadline and returns at once; [`ByteLink::now`] is the bus's clock.
///
/// ```
/// use core::time::Duration;
/// use robobus_link::{ByteLink, FrameLink, SlcanConfig, SlcanLink};
/// use robobus_sim::whj::adapter::{AdapterSimLink, SlcanAdapter};
/// use robobus_sim::whj::{WhjBus, WhjModel, WhjSimLink};
/// use robobus_whj::CanFrame;
///
/// let (bus, _handle) = WhjSimLink::new(WhjBus::chain([1], WhjModel::Whj30, 7));
/// let port = AdapterSimLink::new(Box::new(SlcanAdapter::default()), bus);
/// let mut link = SlcanLink::open(port, "sim", &SlcanConfig::default())?;
/// let t0 = link.now();
/// link.send(&CanFrame::new_fd(CanFrame::standard_id(0x001)?, &[0x02, 0x49, 0x00])?)?;
/// let ack = link.recv(t0 + Duration::from_millis(5))?;
/// assert_eq!(ack.frame.raw_id(), 0x101);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub struct AdapterSimLink<B: FrameLink = WhjSimLink> {
    model: Box<dyn AdapterModel>,
    bus: B,
    handle: WhjSimHandle,
    rates: Option<BitRates>,
    to_host: VecDeque<u8>,
    stats: AdapterStats,
    baud: u32,
}

impl core::fmt::Debug for AdapterSimLink {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("AdapterSimLink")
            .field("stats", &self.stats)
            .finish_non_exhaustive()
    }
}

/// Bytes for the host an [`AdapterSimLink`] holds at most (more is lost, as a full USB
/// buffer loses it).
const MAX_HELD: usize = 1 << 20;

impl AdapterSimLink<WhjSimLink> {
    /// The adapter `model` in front of the simulated bus `bus`.
    pub fn new(model: Box<dyn AdapterModel>, bus: WhjSimLink) -> Self {
        let handle = bus.handle();
        Self::with_bus(model, bus, handle)
    }
}

impl<B: FrameLink> AdapterSimLink<B> {
    /// The adapter `model` in front of `bus`, a [`WhjSimLink`] wrapped (fault injection,
    /// capture) whose bus `handle` reaches.
    pub fn with_bus(model: Box<dyn AdapterModel>, bus: B, handle: WhjSimHandle) -> Self {
        Self {
            model,
            bus,
            handle,
            rates: None,
            to_host: VecDeque::new(),
            stats: AdapterStats::default(),
            baud: 115_200,
        }
    }

    /// A handle on the simulated bus.
    pub fn handle(&self) -> &WhjSimHandle {
        &self.handle
    }

    /// What was moved so far.
    pub const fn stats(&self) -> AdapterStats {
        self.stats
    }

    fn run_to(&mut self, until: Instant, stop_at_host: bool) -> Result<(), LinkError> {
        let held = &mut self.to_host;
        advance(
            &mut *self.model,
            &mut self.bus,
            &self.handle,
            &mut self.rates,
            until,
            stop_at_host,
            &mut self.stats,
            &mut |bytes| {
                let room = MAX_HELD.saturating_sub(held.len());
                held.extend(bytes.into_iter().take(room));
                Ok(())
            },
        )
    }
}

impl<B: FrameLink> ByteLink for AdapterSimLink<B> {
    fn write_all(&mut self, bytes: &[u8]) -> Result<(), LinkError> {
        // Everything due before the write happens first.
        let now = self.bus.now();
        self.run_to(now, false)?;
        self.stats.host_bytes_in += bytes.len() as u64;
        self.model.host_bytes(bytes, now);
        Ok(())
    }

    fn read_some(&mut self, buf: &mut [u8], deadline: Instant) -> Result<usize, LinkError> {
        if buf.is_empty() {
            return Ok(0);
        }
        if self.to_host.is_empty() {
            // To the first bytes for the host (the clock then at their instant), or to
            // the deadline (a deadline in the past: only what is due already).
            let until = deadline.max(self.bus.now());
            self.run_to(until, true)?;
        }
        if self.to_host.is_empty() {
            return Err(LinkError::Timeout {
                received: 0,
                expected: buf.len(),
            });
        }
        let n = buf.len().min(self.to_host.len());
        for (slot, b) in buf.iter_mut().zip(self.to_host.drain(..n)) {
            *slot = b;
        }
        Ok(n)
    }

    fn discard_input(&mut self) -> Result<(), LinkError> {
        self.to_host.clear();
        Ok(())
    }

    fn set_baud(&mut self, baud: u32) -> Result<(), LinkError> {
        // A USB CDC port takes any rate and ignores it.
        self.baud = baud;
        Ok(())
    }

    fn baud(&self) -> Option<u32> {
        Some(self.baud)
    }

    fn now(&self) -> Instant {
        self.bus.now()
    }

    fn sleep_until(&mut self, deadline: Instant) {
        if self.run_to(deadline, false).is_ok() {
            self.bus.sleep_until(deadline);
        }
    }

    fn virtual_time(&self) -> bool {
        true
    }
}

#[cfg(test)]
mod tests {
    use robobus_link::{SlcanConfig, SlcanLink};

    use super::*;
    use crate::whj::WhjModel;

    fn iap_release() -> CanFrame {
        CanFrame::new_fd(CanFrame::standard_id(0x001).unwrap(), &[0x02, 0x49, 0x00]).unwrap()
    }

    #[test]
    fn a_reply_through_the_adapter_costs_the_wire_plus_both_lines_serial_time_exactly() {
        // The same exchange on the bus alone gives the wire's share.
        let mut reference = WhjBus::chain([1], WhjModel::Whj30, 7);
        let wire = reference.request(iap_release())[0].at;

        let (bus, handle) = WhjSimLink::new(WhjBus::chain([1], WhjModel::Whj30, 7));
        let port = AdapterSimLink::new(Box::new(SlcanAdapter::default()), bus);
        let config = SlcanConfig {
            status_every: None,
            ..SlcanConfig::default()
        };
        let mut link = SlcanLink::open(port, "sim", &config).unwrap();
        assert_eq!(handle.with_bus(|b| b.rates()), BitRates::WHJ);
        let t0 = link.now();
        link.send(&iap_release()).unwrap();
        let rx = link.recv(t0 + Duration::from_millis(5)).unwrap();
        assert_eq!(rx.frame.raw_id(), 0x101);
        // "b0013024900\r" and "b1013024901\r": 12 characters each way at 10 µs.
        let serial = SerialTime::USB_CDC.of(12);
        assert_eq!(link.now() - t0, serial + wire + serial);
        // Nothing else: the receive ends exactly at its deadline.
        let deadline = link.now() + Duration::from_millis(3);
        assert!(link.recv(deadline).unwrap_err().is_timeout());
        assert_eq!(link.now(), deadline);
        assert_eq!(handle.with_bus(|b| b.stats().host_frames), 1);
    }

    #[test]
    fn joints_at_other_rates_than_the_adapters_hear_nothing() {
        let (bus, handle) = WhjSimLink::new(WhjBus::chain([1], WhjModel::Whj30, 7));
        let port = AdapterSimLink::new(Box::new(SlcanAdapter::default()), bus);
        let config = SlcanConfig {
            rates: BitRates::new(500_000, 2_000_000).unwrap(),
            status_every: None,
            ..SlcanConfig::default()
        };
        let mut link = SlcanLink::open(port, "sim", &config).unwrap();
        assert_eq!(handle.with_bus(|b| b.rates()), config.rates);
        let t0 = link.now();
        link.send(&iap_release()).unwrap();
        assert!(
            link.recv(t0 + Duration::from_millis(5))
                .unwrap_err()
                .is_timeout()
        );
    }
}
