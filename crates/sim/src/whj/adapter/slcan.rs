//! An emulated slcan CAN FD adapter (`CANable` 2.0 class, slcan firmware with the CAN FD
//! extension), device side.
//!
//! What it does, command by command (see [`robobus_link::slcan::codec`] for the lines):
//!
//! - every line is carried out when its last character is through the host link
//!   ([`SerialTime`]), in order, and answered `\r`, or BEL when it cannot be carried out:
//!   an unknown or malformed command, `O` / `L` while open, `C` while closed, `S` / `Y` /
//!   `M` / `A` while open (rates change only on a closed channel), `F` or a frame while
//!   closed, a frame in listen-only mode;
//! - `V` answers `V1013`, `N` the serial number (`NRB01` by default), `F` the status flags
//!   as two hex digits (the overrun flags are cleared by reading them, as Lawicel's are);
//! - a frame is put on the bus at the instant its line is carried out; a frame from the
//!   bus reaches the host as its line, after the answers queued before it, each character
//!   taking its serial time;
//! - while the channel is closed the adapter is off the bus: it sends nothing, and the
//!   joints' frames are not passed on. Open, it is at the rates `S` / `Y` set (the
//!   power-up rates until then): a joint at other rates hears nothing.
//!
//! Bounded: a line longer than [`MAX_LINE`](robobus_link::slcan::codec::MAX_LINE) is
//! refused whole; more than [`SerialLine::CAPACITY`](super::SerialLine::CAPACITY) messages waiting in either direction
//! drop the newest and raise the overrun flags.

use std::time::Instant;

use robobus_link::slcan::codec::{
    self, ACK, BEL, Command, LineSplitter, Message, STATUS_OVERRUN, STATUS_RX_FULL, STATUS_TX_FULL,
};
use robobus_whj::CanFrame;
use robobus_whj::timing::BitRates;

use super::{AdapterModel, Output, Queues, SerialTime};

/// What `V` answers (after the `V`): hardware 10, software 13.
pub const VERSION: &str = "1013";

/// A line from the host, complete.
#[derive(Debug, Clone)]
enum HostLine {
    Line(Vec<u8>),
    /// An over-long line or a BEL from the host: refused.
    Bad,
}

/// The emulated adapter. See the [module notes](self).
#[derive(Debug, Clone)]
pub struct SlcanAdapter {
    splitter: LineSplitter,
    q: Queues<HostLine>,
    open: bool,
    listen_only: bool,
    nominal: u8,
    data: u8,
    flags: u8,
    serial: String,
}

impl Default for SlcanAdapter {
    fn default() -> Self {
        Self::new(BitRates::WHJ, SerialTime::default())
    }
}

impl SlcanAdapter {
    /// An adapter powered up at `rates` (its channel closed), with `serial` time on its
    /// host link. Rates without an slcan code start at 1 Mbit/s / 5 Mbit/s; check them
    /// first with [`SlcanAdapter::check_rates`].
    pub fn new(rates: BitRates, serial: SerialTime) -> Self {
        Self {
            splitter: LineSplitter::new(),
            q: Queues::new(serial),
            open: false,
            listen_only: false,
            nominal: codec::nominal_code(rates.nominal.get()).unwrap_or(8),
            data: codec::data_code(rates.data.get()).unwrap_or(5),
            flags: 0,
            serial: "RB01".into(),
        }
    }

    /// Whether an slcan adapter can be at `rates`; the error names the rate and the rates
    /// allowed.
    ///
    /// # Errors
    /// A message for the option that set the rate.
    pub fn check_rates(rates: BitRates) -> Result<(), String> {
        if codec::nominal_code(rates.nominal.get()).is_none() {
            return Err(format!(
                "nominal bit rate {} bit/s: an slcan adapter cannot be set to it (allowed: {})",
                rates.nominal,
                codec::list_rates(codec::NOMINAL_RATES)
            ));
        }
        if codec::data_code(rates.data.get()).is_none() {
            return Err(format!(
                "data bit rate {} bit/s: an slcan adapter cannot be set to it (allowed: {})",
                rates.data,
                codec::list_rates(codec::DATA_RATES.map(|d| d.1))
            ));
        }
        Ok(())
    }

    /// Whether the channel is open.
    pub const fn is_open(&self) -> bool {
        self.open
    }

    /// Raises status flags (a test's bus-off or error-passive), reported by the next `F`.
    pub fn raise(&mut self, flags: u8) {
        self.flags |= flags;
    }

    /// Clears status flags.
    pub fn clear(&mut self, flags: u8) {
        self.flags &= !flags;
    }

    fn answer(&mut self, at: Instant, bytes: Vec<u8>) {
        let len = bytes.len();
        if self.q.to_host.send(at, len, bytes).is_none() {
            self.flags |= STATUS_RX_FULL | STATUS_OVERRUN;
        }
    }

    fn ok(&mut self, at: Instant) {
        self.answer(at, vec![ACK]);
    }

    fn refuse(&mut self, at: Instant) {
        self.answer(at, vec![BEL]);
    }

    /// Carries out one line at `at`.
    fn carry_out(&mut self, line: &HostLine, at: Instant) {
        let HostLine::Line(line) = line else {
            self.refuse(at);
            return;
        };
        let Ok(command) = codec::parse_command(line) else {
            self.refuse(at);
            return;
        };
        let closed = !self.open;
        match command {
            Command::Empty => self.ok(at),
            Command::Open | Command::Listen if closed => {
                self.open = true;
                self.listen_only = command == Command::Listen;
                self.flags = 0;
                self.ok(at);
            }
            Command::Close if !closed => {
                self.open = false;
                self.q.clear_bus();
                self.ok(at);
            }
            Command::Nominal(code) if closed => {
                self.nominal = code;
                self.ok(at);
            }
            Command::Data(code) if closed => {
                self.data = code;
                self.ok(at);
            }
            Command::Silent(_) | Command::AutoRetransmit(_) if closed => self.ok(at),
            Command::Version => self.answer(at, format!("V{VERSION}\r").into_bytes()),
            Command::Serial => {
                let serial = format!("N{}\r", self.serial);
                self.answer(at, serial.into_bytes());
            }
            Command::Status if !closed => {
                let flags = self.flags;
                // Lawicel: the overrun flags are cleared by reading them.
                self.flags &= !(STATUS_RX_FULL | STATUS_TX_FULL | STATUS_OVERRUN);
                self.answer(at, format!("F{flags:02X}\r").into_bytes());
            }
            Command::Frame(frame) if !closed && !self.listen_only => {
                if self.q.to_bus(at, frame) {
                    self.ok(at);
                } else {
                    self.flags |= STATUS_TX_FULL;
                    self.refuse(at);
                }
            }
            _ => self.refuse(at),
        }
    }
}

impl AdapterModel for SlcanAdapter {
    fn host_bytes(&mut self, bytes: &[u8], at: Instant) {
        let mut lines = Vec::new();
        self.splitter.feed(bytes, |m| {
            lines.push(match m {
                Message::Line(line) => HostLine::Line(line),
                Message::Bel | Message::Overlong => HostLine::Bad,
            });
        });
        for line in lines {
            let chars = match &line {
                HostLine::Line(l) => l.len() + 1,
                HostLine::Bad => 1,
            };
            if self.q.from_host.send(at, chars, line).is_none() {
                self.flags |= STATUS_TX_FULL | STATUS_OVERRUN;
            }
        }
    }

    fn bus_frame(&mut self, frame: &CanFrame, at: Instant) {
        if self.open {
            self.answer(at, codec::encode_frame(frame));
        }
    }

    fn next_due(&self) -> Option<Instant> {
        self.q.next_due()
    }

    fn poll(&mut self, now: Instant, out: &mut Vec<Output>) {
        while let Some((at, line)) = self.q.from_host.pop_due(now) {
            self.carry_out(&line, at);
        }
        self.q.release(now, out);
    }

    fn bus_rates(&self) -> Option<BitRates> {
        if !self.open {
            return None;
        }
        let nominal = *codec::NOMINAL_RATES.get(usize::from(self.nominal))?;
        BitRates::new(nominal, codec::data_rate(self.data)?)
    }
}

#[cfg(test)]
mod tests {
    use core::time::Duration;

    use super::super::SerialLine;
    use super::*;

    fn drive(a: &mut SlcanAdapter, t0: Instant, input: &[u8]) -> (Vec<u8>, Vec<CanFrame>, Instant) {
        a.host_bytes(input, t0);
        let mut host = Vec::new();
        let mut bus = Vec::new();
        let mut last = t0;
        while let Some(t) = a.next_due() {
            let mut out = Vec::new();
            a.poll(t, &mut out);
            last = t;
            for o in out {
                match o {
                    Output::Bus(f) => bus.push(f),
                    Output::Host(b) => host.extend(b),
                }
            }
        }
        (host, bus, last)
    }

    #[test]
    fn every_command_is_answered_as_the_protocol_says() {
        let mut a = SlcanAdapter::default();
        let t0 = Instant::now();
        let (host, bus, _) = drive(
            &mut a,
            t0,
            b"C\rV\rN\rF\rS8\rY5\rY3\rM0\rA1\rb0011AA\rO\rO\rS6\rF\rb0011AA\rQ\r\r",
        );
        assert_eq!(
            String::from_utf8_lossy(&host),
            "\x07V1013\rNRB01\r\x07\r\r\x07\r\r\x07\r\x07\x07F00\r\r\x07\r"
        );
        assert_eq!(bus.len(), 1);
        assert_eq!(a.bus_rates(), Some(BitRates::WHJ));
    }

    #[test]
    fn a_frame_line_costs_its_characters_each_way_and_goes_out_when_carried_out() {
        let mut a = SlcanAdapter::default();
        let t0 = Instant::now();
        drive(&mut a, t0, b"O\r");
        let t1 = t0 + Duration::from_millis(1);
        // 12 characters: on the bus 120 µs after they were written.
        a.host_bytes(b"b0073010A00\r", t1);
        assert_eq!(a.next_due(), Some(t1 + Duration::from_micros(120)));
        let mut out = Vec::new();
        a.poll(t1 + Duration::from_micros(120), &mut out);
        assert!(matches!(out.as_slice(), [Output::Bus(f)] if f.raw_id() == 0x007));
        // The acknowledgement is one character later.
        assert_eq!(a.next_due(), Some(t1 + Duration::from_micros(130)));
        out.clear();
        a.poll(t1 + Duration::from_micros(130), &mut out);
        assert_eq!(out, [Output::Host(vec![ACK])]);
        // A 16-byte frame from the bus: 2 * 16 + 6 = 38 characters, 380 µs.
        let fb = CanFrame::new_fd(CanFrame::standard_id(0x507).unwrap(), &[0u8; 16]).unwrap();
        let t2 = t1 + Duration::from_millis(1);
        a.bus_frame(&fb, t2);
        assert_eq!(a.next_due(), Some(t2 + Duration::from_micros(380)));
    }

    #[test]
    fn a_closed_channel_passes_nothing_and_a_listen_only_one_sends_nothing() {
        let mut a = SlcanAdapter::default();
        let t0 = Instant::now();
        let fb = CanFrame::new_fd(CanFrame::standard_id(0x107).unwrap(), &[1]).unwrap();
        a.bus_frame(&fb, t0);
        assert_eq!(a.next_due(), None);
        assert_eq!(a.bus_rates(), None);
        let (host, bus, _) = drive(&mut a, t0, b"L\rb0011AA\r");
        assert_eq!(host, b"\r\x07");
        assert!(bus.is_empty());
    }

    #[test]
    fn over_long_lines_and_a_flood_are_bounded() {
        let mut a = SlcanAdapter::default();
        let t0 = Instant::now();
        let mut input = vec![b'b'; 10_000];
        input.extend_from_slice(b"\rV\r");
        let (host, _, _) = drive(&mut a, t0, &input);
        assert_eq!(host, b"\x07V1013\r");
        drive(&mut a, t0, b"O\r");
        let flood = b"\r".repeat(SerialLine::<()>::CAPACITY + 10);
        a.host_bytes(&flood, t0);
        assert_eq!(a.q.from_host.len(), SerialLine::<()>::CAPACITY);
        drive(&mut a, t0, b"");
        let (host, _, _) = drive(&mut a, t0, b"F\r");
        assert!(
            host.ends_with(b"F0A\r"),
            "{:?}",
            String::from_utf8_lossy(&host[host.len() - 8..])
        );
        assert_eq!(
            SlcanAdapter::check_rates(BitRates::new(500_000, 500_000).unwrap()).unwrap_err(),
            "data bit rate 500000 bit/s: an slcan adapter cannot be set to it (allowed: 1000000, 2000000, 4000000, 5000000)"
        );
    }
}
