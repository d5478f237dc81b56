//! An emulated mjbots fdcanusb (USB CAN FD adapter with a text line protocol), device side.
//!
//! What it does, command by command (see [`robobus_link::fdcanusb::codec`] for the lines):
//!
//! - every line is carried out when its last character is through the host link
//!   ([`SerialTime`]), in order, and answered with its reply lines, if any, and `OK`, or
//!   with `ERR <details>`: an unknown or malformed command, `can on` while on, `can off`
//!   while off, `conf set` while on (the configuration is locked on the bus), a setting it
//!   does not have or a value it cannot take, `can status` or a frame while off;
//! - `conf get` / `conf set` know `can.bitrate`, `can.fd_bitrate`, `can.fdcan_frame`,
//!   `can.bitrate_switch`, `can.automatic_retransmission`, `can.restricted_mode`,
//!   `can.bus_monitor` and `can.termination`. A bit rate outside what the adapter can make
//!   ([`FdcanusbAdapter::with_max_rates`]; by default 10 kbit/s..=1 Mbit/s nominal,
//!   125 kbit/s..=8 Mbit/s data) is refused naming the range: the real firmware takes any
//!   number here and fails later, the emulation refuses where a client can be told;
//! - it powers up off the bus (its autostart off) at the rates it is made with; `can on`
//!   puts it on the bus at the configured rates (a joint at other rates hears nothing),
//!   `can off` takes it off (frames queued for the bus are dropped);
//! - `can std` / `can ext` put the frame on the bus at the instant the line is carried
//!   out, in the format its flags ask (the `can.fdcan_frame` / `can.bitrate_switch`
//!   defaults otherwise); a frame from the bus reaches the host as a `rcv` line with the
//!   adapter's microsecond clock (`t`, from power-up) and `f-1` (no filter), after the
//!   answers queued before it, each character taking its serial time;
//! - `can status` answers `lec dlec err warn busoff pexc tdc` as the firmware does, and
//!   `rxovf`: the frames it dropped because more than [`SerialLine::CAPACITY`](super::SerialLine::CAPACITY) lines were
//!   waiting for the host. The controller states can be set by a test
//!   ([`FdcanusbAdapter::set_status`]); the simulated bus has no acknowledgement errors to
//!   raise them by itself.
//!
//! Bounded: a line longer than [`MAX_LINE`](robobus_link::fdcanusb::codec::MAX_LINE), or
//! with bytes that are not text, is skipped to its end and refused; more than
//! [`SerialLine::CAPACITY`](super::SerialLine::CAPACITY) messages waiting in either direction drop the newest.

use std::time::Instant;

use robobus_link::fdcanusb::codec::{
    self, AUTOMATIC_RETRANSMISSION, BITRATE, BITRATE_SWITCH, Command, FD_BITRATE, FDCAN_FRAME,
    Line, LineSplitter, Status,
};
use robobus_whj::CanFrame;
use robobus_whj::timing::BitRates;

use super::{AdapterModel, Output, Queues, SerialTime};

/// The slowest nominal bit rate the adapter makes, bit/s.
pub const MIN_BITRATE: u32 = 10_000;
/// The fastest nominal bit rate the adapter makes by default, bit/s.
pub const MAX_BITRATE: u32 = 1_000_000;
/// The slowest data bit rate the adapter makes, bit/s.
pub const MIN_FD_BITRATE: u32 = 125_000;
/// The fastest data bit rate the adapter makes by default, bit/s.
pub const MAX_FD_BITRATE: u32 = 8_000_000;

/// A line from the host, complete.
#[derive(Debug, Clone)]
enum HostLine {
    Text(String),
    /// An over-long line or one with bytes that are not text: refused.
    Bad,
}

/// The settings `conf get` / `conf set` reach.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[allow(clippy::struct_excessive_bools)] // the firmware's own settings, one field each
struct Conf {
    bitrate: u32,
    fd_bitrate: u32,
    fdcan_frame: bool,
    bitrate_switch: bool,
    automatic_retransmission: bool,
    restricted_mode: bool,
    bus_monitor: bool,
    termination: bool,
}

/// The emulated adapter. See the [module notes](self).
#[derive(Debug, Clone)]
pub struct FdcanusbAdapter {
    splitter: LineSplitter,
    q: Queues<HostLine>,
    conf: Conf,
    /// The rates the controller is at while on the bus (taken at `can on`).
    active: Option<BitRates>,
    max_bitrate: u32,
    max_fd_bitrate: u32,
    status: Status,
    rx_overruns: u32,
    /// The adapter's clock starts at the first instant it is given.
    epoch: Option<Instant>,
}

impl Default for FdcanusbAdapter {
    fn default() -> Self {
        Self::new(BitRates::WHJ, SerialTime::default())
    }
}

impl FdcanusbAdapter {
    /// An adapter powered up off the bus, configured to `rates` (what `conf get` answers
    /// until the host sets others), with `serial` time on its host link.
    pub fn new(rates: BitRates, serial: SerialTime) -> Self {
        Self {
            splitter: LineSplitter::new(),
            q: Queues::new(serial),
            conf: Conf {
                bitrate: rates.nominal.get(),
                fd_bitrate: rates.data.get(),
                fdcan_frame: true,
                bitrate_switch: true,
                automatic_retransmission: false,
                restricted_mode: false,
                bus_monitor: false,
                termination: true,
            },
            active: None,
            max_bitrate: MAX_BITRATE,
            max_fd_bitrate: MAX_FD_BITRATE,
            status: Status::default(),
            rx_overruns: 0,
            epoch: None,
        }
    }

    /// The same adapter, able to make nominal rates up to `nominal` and data rates up to
    /// `data` (bit/s) only: an adapter that cannot be set to the joints' rates.
    #[must_use]
    pub const fn with_max_rates(mut self, nominal: u32, data: u32) -> Self {
        self.max_bitrate = nominal;
        self.max_fd_bitrate = data;
        self
    }

    /// Whether the adapter is on the bus.
    pub const fn is_on(&self) -> bool {
        self.active.is_some()
    }

    /// Sets the controller state `can status` reports (its `rxovf` stays the adapter's).
    pub fn set_status(&mut self, status: Status) {
        self.status = status;
    }

    /// The frames the adapter dropped because its line to the host was full.
    pub const fn rx_overruns(&self) -> u32 {
        self.rx_overruns
    }

    /// Queues bytes for the host at `at`; `false` when the line to the host is full.
    fn answer(&mut self, at: Instant, text: &str) -> bool {
        let bytes = text.as_bytes().to_vec();
        self.q.to_host.send(at, bytes.len(), bytes).is_some()
    }

    fn ok(&mut self, at: Instant) {
        self.answer(at, codec::OK_LINE);
    }

    fn refuse(&mut self, at: Instant, details: &str) {
        self.answer(at, &codec::encode_err(details));
    }

    /// The microsecond clock a `rcv` line carries (wraps at 2³², as a 32-bit counter).
    #[allow(clippy::cast_possible_truncation)] // the counter wraps on purpose
    fn micros(&mut self, at: Instant) -> u32 {
        let epoch = *self.epoch.get_or_insert(at);
        at.saturating_duration_since(epoch).as_micros() as u32
    }

    fn get(&self, key: &str) -> Option<String> {
        let c = &self.conf;
        let flag = |b: bool| u8::from(b).to_string();
        Some(match key {
            BITRATE => c.bitrate.to_string(),
            FD_BITRATE => c.fd_bitrate.to_string(),
            FDCAN_FRAME => flag(c.fdcan_frame),
            BITRATE_SWITCH => flag(c.bitrate_switch),
            AUTOMATIC_RETRANSMISSION => flag(c.automatic_retransmission),
            "can.restricted_mode" => flag(c.restricted_mode),
            "can.bus_monitor" => flag(c.bus_monitor),
            "can.termination" => flag(c.termination),
            _ => return None,
        })
    }

    /// Sets `key` to `value`, or the details of `ERR`.
    fn set(&mut self, key: &str, value: &str) -> Result<(), String> {
        let number = || {
            value
                .parse::<u32>()
                .map_err(|_| format!("{key}: {value:?} is not a number"))
        };
        let flag = || match value {
            "0" | "false" => Ok(false),
            "1" | "true" => Ok(true),
            _ => Err(format!("{key}: {value:?} is not 0 or 1")),
        };
        let rate = |min: u32, max: u32| {
            let n = number()?;
            if (min..=max).contains(&n) {
                Ok(n)
            } else {
                Err(format!(
                    "{key} {n} cannot be set (allowed: {min}..={max} bit/s)"
                ))
            }
        };
        let c = &mut self.conf;
        match key {
            BITRATE => c.bitrate = rate(MIN_BITRATE, self.max_bitrate)?,
            FD_BITRATE => c.fd_bitrate = rate(MIN_FD_BITRATE, self.max_fd_bitrate)?,
            FDCAN_FRAME => c.fdcan_frame = flag()?,
            BITRATE_SWITCH => c.bitrate_switch = flag()?,
            AUTOMATIC_RETRANSMISSION => c.automatic_retransmission = flag()?,
            "can.restricted_mode" => c.restricted_mode = flag()?,
            "can.bus_monitor" => c.bus_monitor = flag()?,
            "can.termination" => c.termination = flag()?,
            _ => return Err(format!("unknown key {}", codec::quote(key))),
        }
        Ok(())
    }

    /// Carries out one line at `at`.
    fn carry_out(&mut self, line: &HostLine, at: Instant) {
        let HostLine::Text(line) = line else {
            self.refuse(at, "line too long or not text");
            return;
        };
        let command = match codec::parse_command(line) {
            Ok(c) => c,
            Err(e) => {
                self.refuse(at, &e.0);
                return;
            }
        };
        let on = self.active.is_some();
        match command {
            Command::CanOn if on => self.refuse(at, "already in BusOn"),
            Command::CanOn => {
                self.active = BitRates::new(self.conf.bitrate, self.conf.fd_bitrate);
                self.ok(at);
            }
            Command::CanOff if !on => self.refuse(at, "already in BusOff"),
            Command::CanOff => {
                self.active = None;
                self.q.clear_bus();
                self.ok(at);
            }
            Command::CanStatus if !on => self.refuse(at, "not in BusOn"),
            Command::CanStatus => {
                let status = Status {
                    rx_overruns: Some(self.rx_overruns),
                    ..self.status
                };
                let reply = format!("{}{}", codec::encode_status(&status), codec::OK_LINE);
                self.answer(at, &reply);
            }
            Command::ConfGet { key } => match self.get(&key) {
                Some(value) => {
                    let reply = format!("{value}\r\n{}", codec::OK_LINE);
                    self.answer(at, &reply);
                }
                None => self.refuse(at, &format!("unknown key {}", codec::quote(&key))),
            },
            Command::ConfSet { .. } if on => {
                self.refuse(at, "configuration is locked while in BusOn");
            }
            Command::ConfSet { key, value } => match self.set(&key, &value) {
                Ok(()) => self.ok(at),
                Err(details) => self.refuse(at, &details),
            },
            Command::Send(_) if !on => self.refuse(at, "not in BusOn state"),
            Command::Send(_) if self.conf.bus_monitor => {
                self.refuse(at, "bus monitor mode sends nothing");
            }
            Command::Send(req) => {
                match req.frame(self.conf.fdcan_frame, self.conf.bitrate_switch) {
                    Err(details) => self.refuse(at, &details),
                    Ok(frame) => {
                        if self.q.to_bus(at, frame) {
                            self.ok(at);
                        } else {
                            self.refuse(at, "transmit queue full");
                        }
                    }
                }
            }
        }
    }
}

impl AdapterModel for FdcanusbAdapter {
    fn host_bytes(&mut self, bytes: &[u8], at: Instant) {
        self.micros(at);
        let mut lines = Vec::new();
        self.splitter.feed(bytes, |line| {
            lines.push(match line {
                Line::Text(t) => (t.len() + 1, HostLine::Text(t.to_owned())),
                Line::Garbage { len } => (len.saturating_add(1), HostLine::Bad),
            });
        });
        for (chars, line) in lines {
            // A full line from the host is lost, as an overrun USB buffer loses it.
            let _ = self.q.from_host.send(at, chars, line);
        }
    }

    fn bus_frame(&mut self, frame: &CanFrame, at: Instant) {
        if self.active.is_none() {
            return;
        }
        let t = self.micros(at);
        let line = codec::encode_rcv(frame, Some(t), Some(-1));
        if !self.answer(at, &line) {
            self.rx_overruns = self.rx_overruns.saturating_add(1);
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
        self.active
    }
}

#[cfg(test)]
mod tests {
    use core::time::Duration;

    use super::super::SerialLine;
    use super::*;

    /// Feeds `input` at `t0` and runs the adapter until nothing is due: the bytes for the
    /// host, the frames for the bus, and the instant the last thing was due.
    fn drive(
        a: &mut FdcanusbAdapter,
        t0: Instant,
        input: &str,
    ) -> (String, Vec<CanFrame>, Instant) {
        a.host_bytes(input.as_bytes(), t0);
        let (mut host, mut bus, mut last) = (Vec::new(), Vec::new(), t0);
        let mut out = Vec::new();
        while let Some(t) = a.next_due() {
            last = t;
            a.poll(t, &mut out);
            for o in out.drain(..) {
                match o {
                    Output::Host(b) => host.extend(b),
                    Output::Bus(f) => bus.push(f),
                }
            }
        }
        (String::from_utf8(host).unwrap(), bus, last)
    }

    fn fd(id: u16, data: &[u8]) -> CanFrame {
        CanFrame::new_fd(CanFrame::standard_id(id).unwrap(), data).unwrap()
    }

    #[test]
    fn it_starts_off_the_bus_and_answers_every_command_as_the_protocol_says() {
        let mut a = FdcanusbAdapter::default();
        let t0 = Instant::now();
        assert_eq!(a.bus_rates(), None);
        let (host, bus, _) = drive(
            &mut a,
            t0,
            "can std 1 01\ncan status\ncan off\nconf get can.bitrate\n\
             conf set can.fd_bitrate 2000000\nconf get can.fd_bitrate\nconf set can.x 1\n\
             conf set can.bitrate_switch 2\ncan on\ncan on\nconf set can.bitrate 500000\n\
             can status\nhello\n",
        );
        assert_eq!(
            host,
            "ERR not in BusOn state\r\nERR not in BusOn\r\nERR already in BusOff\r\n\
             1000000\r\nOK\r\nOK\r\n2000000\r\nOK\r\nERR unknown key can.x\r\n\
             ERR can.bitrate_switch: \"2\" is not 0 or 1\r\nOK\r\nERR already in BusOn\r\n\
             ERR configuration is locked while in BusOn\r\n\
             lec=0 dlec=0 err=0 warn=0 busoff=0 pexc=0 tdc=0 rxovf=0\r\nOK\r\n\
             ERR unknown command\r\n"
        );
        assert!(bus.is_empty());
        assert_eq!(a.bus_rates(), BitRates::new(1_000_000, 2_000_000));
    }

    #[test]
    fn a_rate_it_cannot_make_is_refused_naming_the_range() {
        let mut a = FdcanusbAdapter::default().with_max_rates(1_000_000, 2_000_000);
        let (host, _, _) = drive(
            &mut a,
            Instant::now(),
            "conf set can.fd_bitrate 5000000\nconf set can.bitrate 2000000\n",
        );
        assert_eq!(
            host,
            "ERR can.fd_bitrate 5000000 cannot be set (allowed: 125000..=2000000 bit/s)\r\n\
             ERR can.bitrate 2000000 cannot be set (allowed: 10000..=1000000 bit/s)\r\n"
        );
    }

    #[test]
    fn a_frame_line_costs_its_characters_each_way_and_goes_out_when_carried_out() {
        let mut a = FdcanusbAdapter::default();
        let t0 = Instant::now();
        drive(&mut a, t0, "can on\n");
        let t1 = t0 + Duration::from_millis(1);
        let line = "can std 201 50C30000 BF\n";
        let (host, bus, last) = drive(&mut a, t1, line);
        assert_eq!(host, "OK\r\n");
        assert_eq!(bus, [fd(0x201, &[0x50, 0xC3, 0, 0])]);
        // 24 characters in, 4 out, 10 µs each.
        assert_eq!(last - t1, Duration::from_micros(280));
        // Flags decide the format; without them the defaults do.
        let (_, bus, _) = drive(
            &mut a,
            t1,
            "can std 7 01 bF\ncan std 7 01 f\ncan std 7 01\n",
        );
        assert_eq!(
            bus,
            [
                fd(7, &[1]).with_brs(false),
                CanFrame::new_classic(CanFrame::standard_id(7).unwrap(), &[1]).unwrap(),
                fd(7, &[1]),
            ]
        );
    }

    #[test]
    fn a_frame_from_the_bus_reaches_the_host_as_a_rcv_line_with_the_adapters_clock() {
        let mut a = FdcanusbAdapter::default();
        let t0 = Instant::now();
        // Off the bus, nothing is passed on.
        a.bus_frame(&fd(0x101, &[2, 0x49, 1]), t0);
        assert_eq!(a.next_due(), None);
        drive(&mut a, t0, "can on\n");
        let at = t0 + Duration::from_micros(1500);
        a.bus_frame(&fd(0x101, &[2, 0x49, 1]), at);
        let (host, _, last) = drive(&mut a, at, "");
        let line = "rcv 101 024901 e B F r t1500 f-1\r\n";
        assert_eq!(host, line);
        assert_eq!(last - at, Duration::from_micros(10 * line.len() as u64));
    }

    #[test]
    fn status_reports_the_set_state_and_the_frames_it_dropped() {
        let mut a = FdcanusbAdapter::default();
        let t0 = Instant::now();
        drive(&mut a, t0, "can on\n");
        a.set_status(Status {
            bus_off: true,
            ..Status::default()
        });
        // A flood the host link cannot carry: the newest lines are dropped and counted.
        let n = SerialLine::<()>::CAPACITY + 5;
        for _ in 0..n {
            a.bus_frame(&fd(0x501, &[0; 16]), t0);
        }
        assert_eq!(a.rx_overruns(), 5);
        let (flood, _, last) = drive(&mut a, t0, "");
        assert_eq!(flood.lines().count(), SerialLine::<()>::CAPACITY);
        let (host, _, _) = drive(&mut a, last, "can status\n");
        assert_eq!(
            host,
            "lec=0 dlec=0 err=0 warn=0 busoff=1 pexc=0 tdc=0 rxovf=5\r\nOK\r\n"
        );
    }

    #[test]
    fn over_long_and_binary_lines_are_refused_whole() {
        let mut a = FdcanusbAdapter::default();
        let long = format!("conf get {}\n\x07\x07\ncan off\n", "x".repeat(10_000));
        let (host, _, _) = drive(&mut a, Instant::now(), &long);
        assert_eq!(
            host,
            "ERR line too long or not text\r\nERR line too long or not text\r\n\
             ERR already in BusOff\r\n"
        );
    }
}
