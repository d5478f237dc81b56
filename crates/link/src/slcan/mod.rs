//! CAN FD through a serial-line `slcan` adapter (`CANable` 2.0 class, `slcan` firmware with the
//! CAN FD extension): [`SlcanLink`] is a [`FrameLink`] over any [`ByteLink`] (a USB CDC
//! serial port, a TCP socket to a simulator, an in-process emulation).
//!
//! Opening configures the adapter before anything reaches a joint: the channel is closed
//! (`C`; never an empty line first: the `CANable` 2.0 firmware carries out its previous
//! command again on an empty line, which after a frame is that frame sent once more), the
//! adapter must answer `V` with its version (`V…`, or the `CANable` 2.0 firmware's build and
//! source without the `V`, taken once the adapter has answered `C` the `slcan` way) within
//! [`SlcanConfig::answer_timeout`] (a dead port or one that answers garbage is an
//! [`AdapterError`] naming the port and what was expected), the nominal and data rates are
//! set (`S8` / `Y5` for the WHJ bus's 1 / 5 Mbit/s; rates the adapter has no code for are
//! refused before anything is written) and the channel is opened in normal mode (`O`).
//! Each command must be acknowledged by `\r`; BEL is a refusal.
//!
//! Frames are sent as they are (`b` lines for the joints' CAN FD frames with bit-rate
//! switch) without waiting for the adapter's acknowledgement, which is taken later while
//! receiving: a send costs no round trip over USB. [`FrameLink::recv`] decodes lines until
//! its deadline, filters in software, and returns exactly at the deadline when nothing
//! passes (a deadline in the past: only what has already arrived). Status: at most every
//! [`SlcanConfig::status_every`] a receive first asks for the status flags (`F`, two bytes
//! written, never a wait); their answer maps to the errors `SocketCAN` gives
//! ([`FrameLinkError::BusOff`], [`FrameLinkError::ErrorPassive`], error warning, and
//! overruns as a controller error). A frame the adapter refuses (BEL: its transmit queue
//! is full) is reported the same way as an overrun. Dropping the link closes the channel
//! (`C`).
//!
//! The line codec, host and adapter side, is in [`codec`].

pub mod codec;

use core::time::Duration;
use std::collections::VecDeque;
use std::time::{Instant, SystemTime};

use robobus_whj::frame::CanFrame;
use robobus_whj::timing::BitRates;

use self::codec::{
    Command, LineSplitter, Message, NOMINAL_RATES, Reply, STATUS_BUS_ERROR, STATUS_ERROR_PASSIVE,
    STATUS_ERROR_WARNING, STATUS_OVERRUN, STATUS_RX_FULL, STATUS_TX_FULL,
};
use crate::adapter::{AdapterError, AdapterErrorKind, escape_bytes};
use crate::byte::{ByteLink, LinkError};
use crate::frame_link::{BusErrorKind, FrameLink, FrameLinkError, IdFilter, Received, passes};

/// `SocketCAN`'s controller-problem error class, which it reports overruns under.
pub const CAN_ERR_CRTL: u32 = 0x0004;

/// Commands sent and not answered yet that are remembered (an adapter that never answers
/// cannot grow the list).
const MAX_OUTSTANDING: usize = 1024;
/// Bytes read per look at the port.
const READ_CHUNK: usize = 1024;
/// Garbage an adapter may send while being opened before it is given up on.
const MAX_OPEN_GARBAGE: usize = 4096;
/// Frames and errors decoded but not received yet (one read's worth at most, bounded
/// anyway).
const MAX_QUEUED: usize = 4096;

/// How an [`SlcanLink`] sets its adapter up.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SlcanConfig {
    /// The bus's bit rates (default: the WHJ bus's 1 Mbit/s nominal, 5 Mbit/s data).
    pub rates: BitRates,
    /// How long the adapter may take to answer each command while opening (default
    /// 500 ms).
    pub answer_timeout: Duration,
    /// How often the status flags are asked for at most (default 100 ms; `None`: never).
    pub status_every: Option<Duration>,
}

impl Default for SlcanConfig {
    fn default() -> Self {
        Self {
            rates: BitRates::WHJ,
            answer_timeout: Duration::from_millis(500),
            status_every: Some(Duration::from_millis(100)),
        }
    }
}

impl SlcanConfig {
    /// The `S` and `Y` codes of the rates.
    ///
    /// # Errors
    /// [`AdapterErrorKind::RateUnsupported`] naming the rate and the rates allowed.
    pub fn codes(&self, port: &str) -> Result<(u8, u8), AdapterError> {
        let bad = |detail: String| {
            AdapterError::new("slcan", port, AdapterErrorKind::RateUnsupported, detail)
        };
        let nominal = self.rates.nominal.get();
        let data = self.rates.data.get();
        let s = codec::nominal_code(nominal).ok_or_else(|| {
            bad(format!(
                "nominal bit rate {nominal} bit/s cannot be set (allowed: {} bit/s, S0..S8)",
                codec::list_rates(NOMINAL_RATES)
            ))
        })?;
        let y = codec::data_code(data).ok_or_else(|| {
            bad(format!(
                "data bit rate {data} bit/s cannot be set (allowed: {} bit/s, Y1 / Y2 / Y4 / Y5)",
                codec::list_rates(codec::DATA_RATES.map(|d| d.1))
            ))
        })?;
        Ok((s, y))
    }
}

/// What an [`SlcanLink`] skipped or was told.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SlcanStats {
    /// Lines that were neither a frame nor an answer (and over-long lines).
    pub garbage: u64,
    /// Frames the adapter refused (BEL).
    pub refused: u64,
    /// Frames dropped by the acceptance filters.
    pub filtered: u64,
    /// Status requests (`F`) sent.
    pub status_polls: u64,
}

/// What a command sent and not answered yet waits for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Outstanding {
    Frame,
    Status,
}

/// Whether a line can be a version text: printable ASCII and spaces, at least one
/// character.
fn is_version_text(line: &[u8]) -> bool {
    !line.is_empty() && line.iter().all(|&b| b.is_ascii_graphic() || b == b' ')
}

/// A CAN FD bus through an slcan adapter on a byte link. See the [module notes](self).
#[derive(Debug)]
pub struct SlcanLink<L: ByteLink> {
    link: L,
    port: String,
    splitter: LineSplitter,
    queue: VecDeque<Result<Received, FrameLinkError>>,
    outstanding: VecDeque<Outstanding>,
    filters: Vec<IdFilter>,
    status_every: Option<Duration>,
    last_status_poll: Option<Instant>,
    status: u8,
    version: String,
    stats: SlcanStats,
}

impl<L: ByteLink> SlcanLink<L> {
    /// Sets up the adapter on `link` (named `port` in messages) and opens its channel.
    ///
    /// # Errors
    /// [`AdapterError`]: a rate the adapter cannot be set to (nothing written), no answer
    /// or garbage within the answer timeout, a refused command, a failing port.
    pub fn open(mut link: L, port: &str, config: &SlcanConfig) -> Result<Self, AdapterError> {
        let (s, y) = config.codes(port)?;
        let io = |what: &str, e: &LinkError| {
            AdapterError::new("slcan", port, AdapterErrorKind::Io, format!("{what}: {e}"))
        };
        link.discard_input()
            .map_err(|e| io("discarding old input", &e))?;
        let mut this = Self {
            link,
            port: port.to_owned(),
            splitter: LineSplitter::new(),
            queue: VecDeque::new(),
            outstanding: VecDeque::new(),
            filters: Vec::new(),
            status_every: config.status_every,
            last_status_poll: None,
            status: 0,
            version: String::new(),
            stats: SlcanStats::default(),
        };
        // The channel is closed so the rates can be set; its answer is skipped until `V`'s.
        // No empty line: the CANable 2.0 firmware repeats its last command on one (a
        // frame a program sent last would go out again).
        this.write_open(b"C\r")?;
        this.write_open(&codec::encode_command(&Command::Version))?;
        this.version = this.await_version(config.answer_timeout)?;
        for (command, what) in [
            (
                Command::Nominal(s),
                format!("S{s} (nominal {} bit/s)", config.rates.nominal),
            ),
            (
                Command::Data(y),
                format!("Y{y} (data {} bit/s)", config.rates.data),
            ),
            (Command::Open, "O (open the channel)".to_owned()),
        ] {
            this.write_open(&codec::encode_command(&command))?;
            this.await_ack(&what, config.answer_timeout)?;
        }
        tracing::debug!(port, version = %this.version, "slcan adapter open");
        Ok(this)
    }

    fn adapter_error(&self, kind: AdapterErrorKind, detail: String) -> AdapterError {
        AdapterError::new("slcan", self.port.clone(), kind, detail)
    }

    fn write_open(&mut self, bytes: &[u8]) -> Result<(), AdapterError> {
        self.link.write_all(bytes).map_err(|e| {
            self.adapter_error(
                AdapterErrorKind::Io,
                format!("writing {:?}: {e}", escape_bytes(bytes, 16)),
            )
        })
    }

    /// Reads the adapter's messages while opening until `done` takes one or the
    /// deadline passes; `done` is also told whether the adapter has answered the `slcan`
    /// way (`\r`, BEL, a reply) before this message.
    fn await_open<T>(
        &mut self,
        what: &str,
        timeout: Duration,
        mut done: impl FnMut(&Reply, bool) -> Option<Result<T, String>>,
    ) -> Result<T, AdapterError> {
        let deadline = self.link.now() + timeout;
        let mut garbage: Vec<u8> = Vec::new();
        let mut heard = false;
        let mut buf = [0u8; READ_CHUNK];
        loop {
            let n = match self.link.read_some(&mut buf, deadline) {
                Ok(n) => n,
                Err(LinkError::Timeout { .. }) => {
                    let (kind, detail) = if garbage.is_empty() {
                        let heard = if heard {
                            "it answered the commands before, not this one"
                        } else {
                            "is it an slcan adapter, and is the port right?"
                        };
                        (
                            AdapterErrorKind::NotAnswering,
                            format!(
                                "no answer to {what} within {} ms ({heard})",
                                timeout.as_millis()
                            ),
                        )
                    } else {
                        (
                            AdapterErrorKind::Garbage,
                            format!(
                                "answered {what} with \"{}\", not the slcan protocol",
                                escape_bytes(&garbage, 48)
                            ),
                        )
                    };
                    return Err(self.adapter_error(kind, detail));
                }
                Err(e) => {
                    return Err(self.adapter_error(AdapterErrorKind::Io, format!("reading: {e}")));
                }
            };
            let mut messages = Vec::new();
            self.splitter
                .feed(buf.get(..n).unwrap_or_default(), |m| messages.push(m));
            for m in messages {
                let reply = match &m {
                    Message::Line(line) => codec::parse_reply(Some(line)),
                    Message::Bel => Reply::Refused,
                    Message::Overlong => Reply::Garbage(b"(an over-long line)".to_vec()),
                };
                if let Some(result) = done(&reply, heard) {
                    return result
                        .map_err(|detail| self.adapter_error(AdapterErrorKind::Refused, detail));
                }
                match reply {
                    Reply::Garbage(line) => {
                        garbage.extend_from_slice(&line);
                        garbage.push(b'\r');
                    }
                    _ => heard = true,
                }
            }
            if garbage.len() > MAX_OPEN_GARBAGE {
                return Err(self.adapter_error(
                    AdapterErrorKind::Garbage,
                    format!(
                        "answered {what} with \"{}\", not the slcan protocol",
                        escape_bytes(&garbage, 48)
                    ),
                ));
            }
        }
    }

    fn await_version(&mut self, timeout: Duration) -> Result<String, AdapterError> {
        self.await_open(
            "V (version, expected V<version>\\r)",
            timeout,
            |r, heard| match r {
                Reply::Version(v) => Some(Ok(v.clone())),
                // The CANable 2.0 firmware answers `V` with "<build> <source>", without the
                // `V`: text from an adapter that has just answered `C` the slcan way.
                Reply::Garbage(line) if heard && is_version_text(line) => {
                    Some(Ok(String::from_utf8_lossy(line).into_owned()))
                }
                _ => None,
            },
        )
    }

    fn await_ack(&mut self, what: &str, timeout: Duration) -> Result<(), AdapterError> {
        let expected = format!("{what}, expected \\r");
        let refused = format!("refused {what} (answered BEL)");
        self.await_open(&expected, timeout, |r, _| match r {
            Reply::Ack => Some(Ok(())),
            Reply::Refused => Some(Err(refused.clone())),
            _ => None,
        })
    }

    /// The version the adapter answered `V` with (after the `V`).
    pub fn version(&self) -> &str {
        &self.version
    }

    /// What was skipped or reported so far.
    pub const fn stats(&self) -> SlcanStats {
        self.stats
    }

    /// The byte link under the adapter.
    pub const fn inner(&self) -> &L {
        &self.link
    }

    /// The bus's name in errors: `slcan:PORT`.
    fn iface(&self) -> String {
        format!("slcan:{}", self.port)
    }

    fn push(&mut self, item: Result<Received, FrameLinkError>) {
        if self.queue.len() < MAX_QUEUED {
            self.queue.push_back(item);
        }
    }

    fn expect(&mut self, what: Outstanding) {
        if self.outstanding.len() >= MAX_OUTSTANDING {
            self.outstanding.pop_front();
        }
        self.outstanding.push_back(what);
    }

    /// Applies one message from the adapter.
    fn take(&mut self, m: &Message) {
        let reply = match m {
            Message::Line(line) => codec::parse_reply(Some(line)),
            Message::Bel => Reply::Refused,
            Message::Overlong => Reply::Garbage(Vec::new()),
        };
        match reply {
            Reply::Ack | Reply::TxAck => {
                self.outstanding.pop_front();
            }
            Reply::Refused => match self.outstanding.pop_front() {
                Some(Outstanding::Status) => {
                    tracing::debug!(port = %self.port, "the adapter does not answer F; status not polled");
                    self.status_every = None;
                }
                Some(Outstanding::Frame) | None => {
                    self.stats.refused += 1;
                    tracing::warn!(port = %self.port, "the slcan adapter refused a frame (BEL)");
                    let iface = self.iface();
                    self.push(Err(FrameLinkError::BusError {
                        iface,
                        kind: BusErrorKind::Other {
                            class: CAN_ERR_CRTL,
                        },
                    }));
                }
            },
            Reply::Frame(frame) => {
                if passes(&self.filters, &frame) {
                    self.push(Ok(Received {
                        frame,
                        timestamp: Some(SystemTime::now()),
                    }));
                } else {
                    self.stats.filtered += 1;
                }
            }
            Reply::Status(flags) => {
                if self.outstanding.front() == Some(&Outstanding::Status) {
                    self.outstanding.pop_front();
                }
                self.apply_status(flags);
            }
            Reply::Version(_) | Reply::Serial(_) => {}
            Reply::Garbage(line) => {
                self.stats.garbage += 1;
                tracing::debug!(port = %self.port, line = %escape_bytes(&line, 48), "skipping a line that is not slcan");
            }
        }
    }

    /// The errors a status answer reports, as `SocketCAN` reports them: state changes
    /// once, overruns every time they are flagged.
    fn apply_status(&mut self, flags: u8) {
        let iface = self.iface();
        let rose = flags & !self.status;
        let fell = self.status & !flags;
        self.status = flags;
        if rose & STATUS_BUS_ERROR != 0 {
            self.push(Err(FrameLinkError::BusOff {
                iface: iface.clone(),
            }));
        } else if fell & STATUS_BUS_ERROR != 0 {
            self.push(Err(FrameLinkError::BusError {
                iface: iface.clone(),
                kind: BusErrorKind::Restarted,
            }));
        }
        if rose & STATUS_ERROR_PASSIVE != 0 {
            self.push(Err(FrameLinkError::ErrorPassive {
                iface: iface.clone(),
            }));
        }
        if rose & STATUS_ERROR_WARNING != 0 {
            self.push(Err(FrameLinkError::BusError {
                iface: iface.clone(),
                kind: BusErrorKind::ErrorWarning,
            }));
        }
        if flags & (STATUS_RX_FULL | STATUS_TX_FULL | STATUS_OVERRUN) != 0 {
            self.push(Err(FrameLinkError::BusError {
                iface,
                kind: BusErrorKind::Other {
                    class: CAN_ERR_CRTL,
                },
            }));
        }
    }

    /// Asks for the status flags if the last request is [`SlcanConfig::status_every`]
    /// old and its answer came.
    fn poll_status(&mut self) -> Result<(), FrameLinkError> {
        let Some(every) = self.status_every else {
            return Ok(());
        };
        let now = self.link.now();
        if self
            .last_status_poll
            .is_some_and(|t| now.saturating_duration_since(t) < every)
            || self.outstanding.contains(&Outstanding::Status)
        {
            return Ok(());
        }
        self.last_status_poll = Some(now);
        self.stats.status_polls += 1;
        self.write(&codec::encode_command(&Command::Status))?;
        self.expect(Outstanding::Status);
        Ok(())
    }

    fn write(&mut self, bytes: &[u8]) -> Result<(), FrameLinkError> {
        self.link.write_all(bytes).map_err(|e| match e {
            LinkError::Closed { .. } => FrameLinkError::Closed {
                context: format!("slcan adapter on {}: {e}", self.port),
            },
            e => FrameLinkError::io(
                format!("writing to the slcan adapter on {}", self.port),
                std::io::Error::other(e.to_string()),
            ),
        })
    }
}

impl<L: ByteLink> FrameLink for SlcanLink<L> {
    fn send(&mut self, frame: &CanFrame) -> Result<(), FrameLinkError> {
        self.write(&codec::encode_frame(frame))?;
        self.expect(Outstanding::Frame);
        Ok(())
    }

    fn recv(&mut self, deadline: Instant) -> Result<Received, FrameLinkError> {
        self.poll_status()?;
        let mut buf = [0u8; READ_CHUNK];
        loop {
            if let Some(item) = self.queue.pop_front() {
                return item;
            }
            let n = match self.link.read_some(&mut buf, deadline) {
                Ok(n) => n,
                Err(LinkError::Timeout { .. }) => return Err(FrameLinkError::Timeout),
                Err(e @ LinkError::Closed { .. }) => {
                    return Err(FrameLinkError::Closed {
                        context: format!("slcan adapter on {}: {e}", self.port),
                    });
                }
                Err(e) => {
                    return Err(FrameLinkError::io(
                        format!("reading from the slcan adapter on {}", self.port),
                        std::io::Error::other(e.to_string()),
                    ));
                }
            };
            let mut messages = Vec::new();
            self.splitter
                .feed(buf.get(..n).unwrap_or_default(), |m| messages.push(m));
            for m in &messages {
                self.take(m);
            }
            // A stream of lines that all get skipped ends at the deadline too.
            if self.queue.is_empty() && self.link.now() >= deadline {
                return Err(FrameLinkError::Timeout);
            }
        }
    }

    fn set_filters(&mut self, filters: &[IdFilter]) -> Result<(), FrameLinkError> {
        self.filters = filters.to_vec();
        Ok(())
    }

    fn now(&self) -> Instant {
        self.link.now()
    }

    fn sleep_until(&mut self, deadline: Instant) {
        self.link.sleep_until(deadline);
    }

    fn virtual_time(&self) -> bool {
        self.link.virtual_time()
    }

    /// 1.5 ms: the adapter's USB full-speed transfers (1 ms frames apart) and its
    /// buffering of received frames until a transfer takes them.
    fn reply_allowance(&self) -> Duration {
        crate::frame_link::USB_ADAPTER_REPLY_ALLOWANCE
    }
}

impl<L: ByteLink> Drop for SlcanLink<L> {
    fn drop(&mut self) {
        // Best effort: an adapter left open keeps acknowledging frames on the bus.
        let _ = self.link.write_all(&codec::encode_command(&Command::Close));
    }
}

#[cfg(test)]
mod tests {
    use std::sync::{Arc, Mutex};
    use std::thread::JoinHandle;

    use super::*;
    use crate::MemoryByteLink;

    type Answer = Box<dyn FnMut(&[u8]) -> Vec<u8> + Send>;

    /// A scripted adapter on the far end of a memory pipe: every line the host writes is
    /// recorded and answered by `answer`.
    struct Scripted {
        lines: Arc<Mutex<Vec<Vec<u8>>>>,
        /// Bytes to push to the host unasked.
        push: Arc<Mutex<Vec<u8>>>,
        thread: Option<JoinHandle<()>>,
    }

    impl Scripted {
        fn start(mut answer: Answer) -> (MemoryByteLink, Self) {
            let (host, mut dev) = MemoryByteLink::pair();
            let lines = Arc::new(Mutex::new(Vec::new()));
            let push: Arc<Mutex<Vec<u8>>> = Arc::new(Mutex::new(Vec::new()));
            let (l, p) = (Arc::clone(&lines), Arc::clone(&push));
            let thread = std::thread::spawn(move || {
                let mut splitter = LineSplitter::new();
                let mut buf = [0u8; 256];
                loop {
                    let unasked = core::mem::take(&mut *p.lock().unwrap());
                    if !unasked.is_empty() && dev.write_all(&unasked).is_err() {
                        return;
                    }
                    let n = match dev.read_some(&mut buf, Instant::now() + Duration::from_millis(2))
                    {
                        Ok(n) => n,
                        Err(LinkError::Timeout { .. }) => continue,
                        Err(_) => return,
                    };
                    let mut got = Vec::new();
                    splitter.feed(&buf[..n], |m| got.push(m));
                    for m in got {
                        if let Message::Line(line) = m {
                            let reply = answer(&line);
                            l.lock().unwrap().push(line);
                            if !reply.is_empty() && dev.write_all(&reply).is_err() {
                                return;
                            }
                        }
                    }
                }
            });
            (
                host,
                Self {
                    lines,
                    push,
                    thread: Some(thread),
                },
            )
        }

        fn lines(&self) -> Vec<String> {
            self.lines
                .lock()
                .unwrap()
                .iter()
                .map(|l| String::from_utf8_lossy(l).into_owned())
                .collect()
        }

        fn push(&self, bytes: &[u8]) {
            self.push.lock().unwrap().extend_from_slice(bytes);
        }

        fn join(mut self) -> Vec<String> {
            if let Some(t) = self.thread.take() {
                t.join().unwrap();
            }
            self.lines()
        }
    }

    /// A conforming adapter: acknowledges everything, `V1013`, status flags from `flags`.
    fn conforming(flags: Arc<Mutex<u8>>) -> Answer {
        Box::new(move |line: &[u8]| match line.first() {
            Some(b'V') => b"V1013\r".to_vec(),
            Some(b'F') => format!("F{:02X}\r", *flags.lock().unwrap()).into_bytes(),
            _ => b"\r".to_vec(),
        })
    }

    fn fast() -> SlcanConfig {
        SlcanConfig {
            answer_timeout: Duration::from_millis(200),
            ..SlcanConfig::default()
        }
    }

    fn fd(id: u16, data: &[u8]) -> CanFrame {
        CanFrame::new_fd(CanFrame::standard_id(id).unwrap(), data).unwrap()
    }

    #[test]
    fn opening_sets_1_and_5_mbit_and_opens_then_frames_go_out_as_b_lines() {
        let (host, adapter) = Scripted::start(conforming(Arc::default()));
        let mut link = SlcanLink::open(
            host,
            "/dev/ttyACM0",
            &SlcanConfig {
                status_every: None,
                ..fast()
            },
        )
        .unwrap();
        assert_eq!(link.version(), "1013");
        link.send(&fd(0x007, &[0x01, 0x0A, 0x00])).unwrap();
        adapter.push(b"b1073010A00\r");
        let rx = link.recv(Instant::now() + Duration::from_secs(2)).unwrap();
        assert_eq!(rx.frame, fd(0x107, &[0x01, 0x0A, 0x00]));
        drop(link);
        assert_eq!(
            adapter.join(),
            ["C", "V", "S8", "Y5", "O", "b0073010A00", "C"]
        );
    }

    #[test]
    fn a_rate_the_adapter_cannot_set_is_refused_before_anything_is_written() {
        let (host, adapter) = Scripted::start(conforming(Arc::default()));
        for (rates, named) in [
            (
                BitRates::new(1_000_000, 500_000).unwrap(),
                "data bit rate 500000 bit/s cannot be set (allowed: 1000000, 2000000, 4000000, 5000000 bit/s, Y1 / Y2 / Y4 / Y5)",
            ),
            (
                BitRates::new(800_000, 5_000_000).unwrap(),
                "nominal bit rate 800000 bit/s cannot be set (allowed: 10000, 20000, 50000, 100000, 125000, 250000, 500000, 750000, 1000000 bit/s, S0..S8)",
            ),
        ] {
            let e = SlcanConfig { rates, ..fast() }.codes("COM8").unwrap_err();
            assert_eq!(e.kind, AdapterErrorKind::RateUnsupported);
            assert_eq!(e.to_string(), format!("slcan adapter on COM8: {named}"));
        }
        let rates = BitRates::new(1_000_000, 500_000).unwrap();
        let e = SlcanLink::open(host, "COM8", &SlcanConfig { rates, ..fast() }).unwrap_err();
        assert_eq!(e.kind, AdapterErrorKind::RateUnsupported);
        assert!(adapter.join().is_empty());
    }

    #[test]
    fn a_silent_port_is_an_error_naming_it_within_the_answer_timeout_and_no_frame_is_sent() {
        let (host, adapter) = Scripted::start(Box::new(|_: &[u8]| Vec::new()));
        let t0 = Instant::now();
        let e = SlcanLink::open(host, "/dev/ttyUSB3", &fast()).unwrap_err();
        let took = t0.elapsed();
        assert_eq!(e.kind, AdapterErrorKind::NotAnswering);
        assert_eq!(
            e.to_string(),
            "slcan adapter on /dev/ttyUSB3: no answer to V (version, expected V<version>\\r) \
             within 200 ms (is it an slcan adapter, and is the port right?)"
        );
        assert!(
            took >= Duration::from_millis(200) && took < Duration::from_secs(2),
            "{took:?}"
        );
        let lines = adapter.join();
        // The channel is closed again on the way out; no frame was ever written.
        assert_eq!(lines, ["C", "V", "C"]);
    }

    #[test]
    fn an_adapter_answering_garbage_is_named_with_what_it_said() {
        let (host, adapter) = Scripted::start(Box::new(|_: &[u8]| b"AT+OK hello\r\n".to_vec()));
        let e = SlcanLink::open(host, "COM8", &fast()).unwrap_err();
        assert_eq!(e.kind, AdapterErrorKind::Garbage);
        assert!(
            e.to_string()
                .starts_with("slcan adapter on COM8: answered V (version, expected V<version>\\r) with \"AT+OK hello\\r"),
            "{e}"
        );
        assert!(!adapter.join().iter().any(|l| l.starts_with('b')));
    }

    #[test]
    fn the_canable_2_firmware_is_opened_without_an_empty_line_and_its_bare_version_taken() {
        // The CANable 2.0 firmware answers V with "<build> <source>" (no V), and carries
        // out its previous command again on an empty line (a frame would go out twice).
        let (host, adapter) = Scripted::start(Box::new(|line: &[u8]| match line {
            b"V" => b"a1b2c3d4 github.com/normaldotcom/canable2-fw\r".to_vec(),
            b"" => b"b0073010A00\r".to_vec(),
            _ => b"\r".to_vec(),
        }));
        let link = SlcanLink::open(host, "COM8", &fast()).unwrap();
        assert_eq!(
            link.version(),
            "a1b2c3d4 github.com/normaldotcom/canable2-fw"
        );
        drop(link);
        let lines = adapter.join();
        assert_eq!(lines, ["C", "V", "S8", "Y5", "O", "C"]);
    }

    #[test]
    fn a_bare_version_text_from_a_port_that_never_answered_the_slcan_way_is_garbage() {
        let (host, adapter) = Scripted::start(Box::new(|_: &[u8]| b"OK ready\r".to_vec()));
        let e = SlcanLink::open(host, "COM8", &fast()).unwrap_err();
        assert_eq!(e.kind, AdapterErrorKind::Garbage);
        assert!(e.to_string().contains("\"OK ready\\r"), "{e}");
        assert_eq!(adapter.join(), ["C", "V", "C"]);
    }

    #[test]
    fn a_refused_rate_is_an_error_and_the_channel_is_not_opened() {
        let (host, adapter) = Scripted::start(Box::new(|line: &[u8]| match line {
            b"V" => b"V1013\r".to_vec(),
            b"Y5" => b"\x07".to_vec(),
            _ => b"\r".to_vec(),
        }));
        let e = SlcanLink::open(host, "COM8", &fast()).unwrap_err();
        assert_eq!(e.kind, AdapterErrorKind::Refused);
        assert_eq!(
            e.to_string(),
            "slcan adapter on COM8: refused Y5 (data 5000000 bit/s) (answered BEL)"
        );
        let lines = adapter.join();
        assert!(!lines.iter().any(|l| l == "O"), "{lines:?}");
    }

    #[test]
    fn status_flags_map_to_the_errors_socketcan_gives_and_are_polled_at_most_every_100_ms() {
        let flags = Arc::new(Mutex::new(0u8));
        let (host, adapter) = Scripted::start(conforming(Arc::clone(&flags)));
        let mut link = SlcanLink::open(host, "COM8", &fast()).unwrap();
        let short = |link: &mut SlcanLink<MemoryByteLink>| {
            link.recv(Instant::now() + Duration::from_millis(30))
        };
        // First receive polls; all clear: a timeout at the deadline.
        assert!(short(&mut link).unwrap_err().is_timeout());
        *flags.lock().unwrap() = STATUS_BUS_ERROR | STATUS_ERROR_PASSIVE;
        // Within 100 ms of the last poll: no new poll, nothing reported.
        assert!(short(&mut link).unwrap_err().is_timeout());
        assert_eq!(link.stats().status_polls, 1);
        std::thread::sleep(Duration::from_millis(100));
        let e = short(&mut link).unwrap_err();
        assert_eq!(
            e.to_string(),
            "CAN interface slcan:COM8 is bus-off: check wiring, termination and bit rate, then \
             open the bus again (the adapter restarts its controller when its channel is opened)"
        );
        assert!(matches!(e, FrameLinkError::BusOff { iface } if iface == "slcan:COM8"));
        assert!(matches!(
            short(&mut link),
            Err(FrameLinkError::ErrorPassive { .. })
        ));
        *flags.lock().unwrap() = STATUS_OVERRUN;
        std::thread::sleep(Duration::from_millis(100));
        assert!(matches!(
            short(&mut link),
            Err(FrameLinkError::BusError {
                kind: BusErrorKind::Restarted,
                ..
            })
        ));
        assert!(matches!(
            short(&mut link),
            Err(FrameLinkError::BusError {
                kind: BusErrorKind::Other {
                    class: CAN_ERR_CRTL
                },
                ..
            })
        ));
        assert!(short(&mut link).unwrap_err().is_timeout());
        assert_eq!(link.stats().status_polls, 3);
        drop(link);
        let polls = adapter.join().iter().filter(|l| *l == "F").count();
        assert_eq!(polls, 3);
    }

    #[test]
    fn a_receive_filters_in_software_skips_garbage_and_ends_at_its_deadline() {
        let (host, adapter) = Scripted::start(conforming(Arc::default()));
        let mut link = SlcanLink::open(
            host,
            "COM8",
            &SlcanConfig {
                status_every: None,
                ..fast()
            },
        )
        .unwrap();
        link.set_filters(&[IdFilter::standard(0x107)]).unwrap();
        adapter.push(b"b1051AA\rnonsense\r\x07b1071BB\r");
        // In stream order: the BEL (no frame outstanding: the adapter refused one), then
        // the frame that passes; 0x105 filtered, the nonsense skipped.
        let e = link.recv(Instant::now() + Duration::from_secs(2));
        assert!(
            matches!(
                e,
                Err(FrameLinkError::BusError {
                    kind: BusErrorKind::Other {
                        class: CAN_ERR_CRTL
                    },
                    ..
                })
            ),
            "{e:?}"
        );
        let rx = link.recv(Instant::now() + Duration::from_secs(2)).unwrap();
        assert_eq!(rx.frame, fd(0x107, &[0xBB]));
        assert_eq!(
            link.stats(),
            SlcanStats {
                garbage: 1,
                refused: 1,
                filtered: 1,
                status_polls: 0
            }
        );
        let deadline = Instant::now() + Duration::from_millis(20);
        assert!(link.recv(deadline).unwrap_err().is_timeout());
        assert!(Instant::now() >= deadline);
        drop(link);
        drop(adapter);
    }
}
