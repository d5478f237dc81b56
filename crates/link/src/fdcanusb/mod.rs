//! mjbots' fdcanusb: a USB CAN FD adapter that speaks a text line protocol over a serial
//! port (USB CDC: `/dev/ttyACM0`, `COM8`, `/dev/cu.usbmodem*`), on every OS.
//!
//! [`FdcanusbLink`] is a [`FrameLink`] over any [`ByteLink`] to such an adapter: the port
//! itself, a TCP endpoint (`socket://`), or a pty or memory link to an emulated one. The
//! protocol's lines are [`codec`]'s pure functions.
//!
//! Opening ([`FdcanusbLink::open`]) configures the adapter before anything reaches the
//! bus: `can off` (an adapter may start on the bus), `conf set` of the nominal and data
//! bit rates (the joints': 1 and 5 Mbit/s), CAN FD format with bit-rate switch and
//! automatic retransmission, each read back with `conf get`, then `can on` and one
//! `can status`. Every command must be answered within [`FdcanusbConfig::reply_timeout`];
//! a silent port, one that answers something that is not the protocol, or a setting the
//! adapter refuses or does not keep ends the open with an [`AdapterError`] that names
//! it, and no frame has been sent.
//!
//! Sending writes `can std` (or `can ext`) with the frame's own format flags and waits for
//! the adapter's `OK`; `rcv` lines that arrive meanwhile are queued for
//! [`FrameLink::recv`], which waits to its exact deadline on the byte link. The
//! acceptance filters are applied here, in software. Every
//! [`FdcanusbConfig::status_every`], the next send or receive also asks `can status`
//! (without waiting for it): the controller's bus-off, error-passive and error-warning
//! states, and the frames the adapter had to drop, come back from `recv` as the errors a
//! `SocketCAN` interface gives ([`FrameLinkError::BusOff`],
//! [`FrameLinkError::ErrorPassive`], [`FrameLinkError::BusError`]). Dropping the link
//! takes the adapter off the bus (`can off`).
//!
//! Everything is bounded: lines ([`codec::MAX_LINE`]), the queue of received frames
//! ([`MAX_QUEUED`]; beyond it frames are dropped and reported as an overrun), the
//! commands in flight ([`MAX_PENDING`]) and the errors waiting to be reported.

pub mod codec;

use std::collections::VecDeque;
use std::io;
use std::time::{Duration, Instant, SystemTime};

use robobus_whj::frame::CanFrame;

use self::codec::{
    AUTOMATIC_RETRANSMISSION, BITRATE, BITRATE_SWITCH, Command, DeviceLine, FD_BITRATE,
    FDCAN_FRAME, Line, LineSplitter, Status,
};
use crate::adapter::{AdapterError, AdapterErrorKind, escape_bytes};
use crate::byte::{ByteLink, LinkError};
use crate::frame_link::{BusErrorKind, FrameLink, FrameLinkError, IdFilter, Received, passes};

/// The nominal bit rate of WHJ joints, bit/s.
pub const JOINT_BITRATE: u32 = 1_000_000;
/// The data bit rate of WHJ joints, bit/s.
pub const JOINT_FD_BITRATE: u32 = 5_000_000;
/// How long a command may wait for its `OK` by default.
pub const DEFAULT_REPLY_TIMEOUT: Duration = Duration::from_millis(500);
/// How often the controller's state is asked by default.
pub const DEFAULT_STATUS_EVERY: Duration = Duration::from_millis(250);
/// Received frames held for [`FrameLink::recv`] at most.
pub const MAX_QUEUED: usize = 4096;
/// Commands whose final line has not come, at most (then the adapter is not answering).
pub const MAX_PENDING: usize = 64;
/// Bus errors held for [`FrameLink::recv`] at most (older ones give way).
const MAX_EVENTS: usize = 16;
/// The nominal bit rates an fdcanusb takes, bit/s.
const BITRATE_RANGE: core::ops::RangeInclusive<u32> = 10_000..=1_000_000;
/// The data bit rates an fdcanusb takes, bit/s.
const FD_BITRATE_RANGE: core::ops::RangeInclusive<u32> = 125_000..=8_000_000;
/// The `SocketCAN` error class of a controller problem (an receive overrun is one).
const CAN_ERR_CRTL: u32 = 0x0004;
/// How long dropping the link waits for the adapter's `OK` to `can off`.
const CLOSE_WAIT: Duration = Duration::from_millis(100);
/// Garbage lines logged one by one before they are only counted.
const GARBAGE_LOGGED: u64 = 5;

/// How [`FdcanusbLink::open`] sets the adapter up.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FdcanusbConfig {
    /// Nominal (arbitration) bit rate, bit/s (default the joints' 1 Mbit/s).
    pub bitrate: u32,
    /// Data bit rate, bit/s (default the joints' 5 Mbit/s).
    pub fd_bitrate: u32,
    /// Whether an unacknowledged frame is sent again (default: yes, as a `SocketCAN`
    /// interface does unless told one-shot).
    pub automatic_retransmission: bool,
    /// How long each command may wait for its final line.
    pub reply_timeout: Duration,
    /// How often `can status` is asked while the link is used.
    pub status_every: Duration,
}

impl Default for FdcanusbConfig {
    fn default() -> Self {
        Self {
            bitrate: JOINT_BITRATE,
            fd_bitrate: JOINT_FD_BITRATE,
            automatic_retransmission: true,
            reply_timeout: DEFAULT_REPLY_TIMEOUT,
            status_every: DEFAULT_STATUS_EVERY,
        }
    }
}

/// What an fdcanusb link skipped or dropped while it was used.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FdcanusbStats {
    /// Frames received and queued (before the filters).
    pub received: u64,
    /// Frames the acceptance filters dropped.
    pub filtered: u64,
    /// Frames dropped because [`MAX_QUEUED`] were waiting.
    pub overrun: u64,
    /// Remote frames skipped.
    pub remote: u64,
    /// Lines that were not the protocol (skipped).
    pub garbage: u64,
    /// `can status` questions sent.
    pub status_polls: u64,
}

/// What a command in flight expects.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Expect {
    /// A final line only.
    Final,
    /// One reply line, then the final line.
    Reply,
    /// A `can status` asked by the link itself: its answer changes the bus state.
    Poll,
}

#[derive(Debug)]
struct Pending {
    seq: u64,
    expect: Expect,
    reply: Option<String>,
}

/// How a command ended.
#[derive(Debug)]
enum Answer {
    Ok(Option<String>),
    Err(String),
}

/// Why a command the link waits for did not end with `OK`.
#[derive(Debug)]
enum Failure {
    Silent(Duration),
    Refused(String),
    Garbage(String),
    Link(LinkError),
    Busy,
}

/// The controller state the link last heard of.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum BusState {
    Active,
    Warning,
    Passive,
    Off,
}

/// A CAN FD link through an fdcanusb on `L`. See the [module notes](self).
#[derive(Debug)]
pub struct FdcanusbLink<L: ByteLink> {
    link: L,
    /// `fdcanusb:PORT`, the name bus errors carry.
    name: String,
    port: String,
    config: FdcanusbConfig,
    lines: LineSplitter,
    frames: VecDeque<Received>,
    events: VecDeque<FrameLinkError>,
    filters: Vec<IdFilter>,
    pending: VecDeque<Pending>,
    next_seq: u64,
    /// The last command that ended, with how.
    done: Option<(u64, Answer)>,
    /// During open: a line that is not the protocol ends the open.
    opening: bool,
    bus: BusState,
    overruns_seen: Option<u32>,
    /// The queue is full and frames are being dropped.
    overflowing: bool,
    last_poll: Option<Instant>,
    on: bool,
    /// The first bytes heard while opening, for messages.
    heard: Vec<u8>,
    stats: FdcanusbStats,
}

impl<L: ByteLink> FdcanusbLink<L> {
    /// Configures the fdcanusb on `link` (named `port` in messages) as `config` says and
    /// switches it on the bus. See the [module notes](self).
    ///
    /// # Errors
    /// [`AdapterError`]: a bit rate out of range (nothing was written), a silent port, an
    /// answer that is not the protocol, a refused command or a setting not kept. In every
    /// case no frame has been sent.
    pub fn open(link: L, port: &str, config: FdcanusbConfig) -> Result<Self, AdapterError> {
        check_rate(port, BITRATE, config.bitrate, &BITRATE_RANGE)?;
        check_rate(port, FD_BITRATE, config.fd_bitrate, &FD_BITRATE_RANGE)?;
        let mut this = Self {
            link,
            name: format!("fdcanusb:{port}"),
            port: port.to_owned(),
            config,
            lines: LineSplitter::new(),
            frames: VecDeque::new(),
            events: VecDeque::new(),
            filters: Vec::new(),
            pending: VecDeque::new(),
            next_seq: 0,
            done: None,
            opening: true,
            bus: BusState::Active,
            overruns_seen: None,
            overflowing: false,
            last_poll: None,
            on: false,
            heard: Vec::new(),
            stats: FdcanusbStats::default(),
        };
        this.link
            .discard_input()
            .map_err(|source| this.port_error(&source))?;
        this.configure()?;
        this.opening = false;
        Ok(this)
    }

    /// The open's command sequence.
    fn configure(&mut self) -> Result<(), AdapterError> {
        // An adapter may start on the bus (the firmware's autostart); `ERR` here is one
        // that is off already.
        match self.command(&Command::CanOff, Expect::Final) {
            Ok(_) | Err(Failure::Refused(_)) => {}
            Err(f) => return Err(self.open_error("can off", f)),
        }
        let c = self.config;
        let settings: [(&'static str, u32, String); 5] = [
            (
                BITRATE,
                c.bitrate,
                format!(
                    "an fdcanusb takes {}..={} bit/s",
                    BITRATE_RANGE.start(),
                    BITRATE_RANGE.end()
                ),
            ),
            (
                FD_BITRATE,
                c.fd_bitrate,
                format!(
                    "an fdcanusb takes {}..={} bit/s",
                    FD_BITRATE_RANGE.start(),
                    FD_BITRATE_RANGE.end()
                ),
            ),
            (FDCAN_FRAME, 1, "allowed: 0 or 1".into()),
            (BITRATE_SWITCH, 1, "allowed: 0 or 1".into()),
            (
                AUTOMATIC_RETRANSMISSION,
                u32::from(c.automatic_retransmission),
                "allowed: 0 or 1".into(),
            ),
        ];
        for (setting, value, allowed) in &settings {
            let set = Command::ConfSet {
                key: (*setting).into(),
                value: value.to_string(),
            };
            match self.command(&set, Expect::Final) {
                Ok(_) => {}
                Err(Failure::Refused(details)) => {
                    return Err(self.not_taken(
                        setting,
                        *value,
                        &format!("it answered ERR {details}"),
                        allowed,
                    ));
                }
                Err(f) => return Err(self.open_error(&set.to_string(), f)),
            }
            let get = Command::ConfGet {
                key: (*setting).into(),
            };
            let kept = match self.command(&get, Expect::Reply) {
                Ok(reply) => reply.unwrap_or_default(),
                Err(f) => return Err(self.open_error(&get.to_string(), f)),
            };
            if parse_setting(&kept) != Some(*value) {
                return Err(self.not_taken(
                    setting,
                    *value,
                    &format!("it kept {:?}", codec::quote(&kept)),
                    allowed,
                ));
            }
        }
        match self.command(&Command::CanOn, Expect::Final) {
            Ok(_) => self.on = true,
            Err(f) => return Err(self.open_error("can on", f)),
        }
        let status = match self.command(&Command::CanStatus, Expect::Reply) {
            Ok(reply) => reply.unwrap_or_default(),
            // Early firmware answers `ERR not implemented`: the controller's state is
            // then not known, and not asked again.
            Err(Failure::Refused(details)) => {
                tracing::warn!(
                    port = %self.port,
                    %details,
                    "fdcanusb: no `can status` in this firmware; bus-off and error-passive \
                     will not be reported"
                );
                self.config.status_every = Duration::MAX;
                self.last_poll = Some(self.link.now());
                return Ok(());
            }
            Err(f) => return Err(self.open_error("can status", f)),
        };
        match codec::parse_status(&status) {
            Ok(s) => {
                self.last_poll = Some(self.link.now());
                self.apply_status(&s);
                Ok(())
            }
            Err(e) => Err(self.open_error("can status", Failure::Garbage(e.to_string()))),
        }
    }

    fn adapter_error(&self, kind: AdapterErrorKind, detail: String) -> AdapterError {
        AdapterError::new("fdcanusb", self.port.clone(), kind, detail)
    }

    fn not_taken(&self, setting: &str, value: u32, answer: &str, allowed: &str) -> AdapterError {
        let kind = if setting == BITRATE || setting == FD_BITRATE {
            AdapterErrorKind::RateUnsupported
        } else {
            AdapterErrorKind::Refused
        };
        self.adapter_error(
            kind,
            format!(
                "cannot set {setting} to {value}: {answer} (the joints need {setting} {value}; \
                 {allowed}); nothing was sent to a joint"
            ),
        )
    }

    fn port_error(&self, source: &LinkError) -> AdapterError {
        let kind = match source {
            LinkError::NoSuchDevice { .. } => AdapterErrorKind::NoPort,
            _ => AdapterErrorKind::Io,
        };
        self.adapter_error(kind, source.to_string())
    }

    fn open_error(&self, command: &str, f: Failure) -> AdapterError {
        let garbage = |got: String| {
            self.adapter_error(
                AdapterErrorKind::Garbage,
                format!(
                    "answered `{command}` with {got}, not the fdcanusb protocol: is the device \
                     on this port an fdcanusb? (nothing was sent to a joint)"
                ),
            )
        };
        // Silence after part of a line that never ended is an answer in another protocol
        // (an slcan adapter's BEL, for one).
        let silent = |waited: Duration| {
            if self.lines.is_mid_line() && !self.heard.is_empty() {
                garbage(format!("\"{}\"", escape_bytes(&self.heard, 48)))
            } else {
                self.adapter_error(
                    AdapterErrorKind::NotAnswering,
                    format!(
                        "no answer to `{command}` within {} ms: is an fdcanusb on this port, \
                         plugged in and powered? (nothing was sent to a joint)",
                        waited.as_millis()
                    ),
                )
            }
        };
        match f {
            Failure::Silent(waited) => silent(waited),
            Failure::Busy => silent(self.config.reply_timeout),
            Failure::Refused(details) => self.adapter_error(
                AdapterErrorKind::Refused,
                format!(
                    "refused `{command}`: ERR {} (nothing was sent to a joint)",
                    codec::quote(&details)
                ),
            ),
            Failure::Garbage(got) => garbage(got),
            Failure::Link(source) => self.port_error(&source),
        }
    }

    /// What the link skipped and dropped so far.
    pub const fn stats(&self) -> FdcanusbStats {
        self.stats
    }

    /// The port, as given to [`FdcanusbLink::open`].
    pub fn port(&self) -> &str {
        &self.port
    }

    /// Writes `cmd` and waits for its final line (the reply line too when `expect` is
    /// [`Expect::Reply`]), up to the reply timeout; lines of other kinds that arrive
    /// meanwhile are handled as they come.
    fn command(&mut self, cmd: &Command, expect: Expect) -> Result<Option<String>, Failure> {
        let line = codec::encode_command(cmd);
        self.heard.clear();
        self.exchange(line.as_bytes(), expect)
    }

    fn exchange(&mut self, bytes: &[u8], expect: Expect) -> Result<Option<String>, Failure> {
        if self.pending.len() >= MAX_PENDING {
            return Err(Failure::Busy);
        }
        self.link.write_all(bytes).map_err(Failure::Link)?;
        let seq = self.push_pending(expect);
        self.wait_for(seq)
    }

    fn push_pending(&mut self, expect: Expect) -> u64 {
        let seq = self.next_seq;
        self.next_seq += 1;
        self.pending.push_back(Pending {
            seq,
            expect,
            reply: None,
        });
        seq
    }

    /// Reads until command `seq` ended, or the reply timeout passed.
    fn wait_for(&mut self, seq: u64) -> Result<Option<String>, Failure> {
        let start = self.link.now();
        let deadline = start + self.config.reply_timeout;
        loop {
            if let Some((s, _)) = &self.done
                && *s == seq
                && let Some((_, answer)) = self.done.take()
            {
                return match answer {
                    Answer::Ok(reply) => Ok(reply),
                    Answer::Err(details) => Err(Failure::Refused(details)),
                };
            }
            match self.read_some(deadline) {
                Ok(()) => {}
                // Silent until the deadline: the reply timeout, said as configured (the
                // clock read after a wake-up on a loaded machine says a little more).
                Err(Failure::Silent(_)) => return Err(Failure::Silent(self.config.reply_timeout)),
                Err(e) => return Err(e),
            }
        }
    }

    /// One read of the byte link (up to `deadline`), its lines handled.
    fn read_some(&mut self, deadline: Instant) -> Result<(), Failure> {
        let mut buf = [0u8; 512];
        let n = match self.link.read_some(&mut buf, deadline) {
            Ok(n) => n,
            Err(LinkError::Timeout { .. }) => return Err(Failure::Silent(Duration::ZERO)),
            Err(e) => return Err(Failure::Link(e)),
        };
        let now = SystemTime::now();
        if self.opening && self.heard.len() < 64 {
            let room = 64 - self.heard.len();
            self.heard.extend(buf.iter().take(n.min(room)));
        }
        let mut lines = core::mem::take(&mut self.lines);
        let mut bad = None;
        lines.feed(buf.get(..n).unwrap_or_default(), |line| {
            if bad.is_some() {
                return;
            }
            if let Err(got) = self.handle_line(line, now) {
                bad = Some(got);
            }
        });
        self.lines = lines;
        match bad {
            Some(got) => Err(Failure::Garbage(got)),
            None => Ok(()),
        }
    }

    /// Handles one line; `Err` with the quoted line when it is not the protocol and the
    /// link is opening (afterwards such lines are counted and skipped).
    fn handle_line(&mut self, line: Line<'_>, now: SystemTime) -> Result<(), String> {
        let text = match line {
            Line::Text(text) => text,
            Line::Garbage { len } => {
                return self.garbage(format!("{len} bytes that are not a line of text"));
            }
        };
        let parsed = match codec::parse_device_line(text) {
            Ok(p) => p,
            Err(e) => return self.garbage(e.to_string()),
        };
        match parsed {
            DeviceLine::Rcv(rcv) => {
                if self.on {
                    self.queue_frame(rcv.frame, now);
                }
                Ok(())
            }
            DeviceLine::RcvRemote => {
                self.stats.remote += 1;
                Ok(())
            }
            DeviceLine::Ok | DeviceLine::Err(_) => {
                let Some(front) = self.pending.pop_front() else {
                    return self.garbage(format!("{:?} answering no command", codec::quote(text)));
                };
                if front.expect == Expect::Reply
                    && front.reply.is_none()
                    && parsed == DeviceLine::Ok
                {
                    return self.garbage("OK without the reply line".into());
                }
                let answer = match parsed {
                    DeviceLine::Err(details) => Answer::Err(details),
                    _ => Answer::Ok(front.reply),
                };
                if front.expect == Expect::Poll {
                    self.poll_answered(answer);
                } else {
                    self.done = Some((front.seq, answer));
                }
                Ok(())
            }
            DeviceLine::Text(text) => match self.pending.front_mut() {
                Some(p) if p.expect != Expect::Final && p.reply.is_none() => {
                    p.reply = Some(text);
                    Ok(())
                }
                _ => self.garbage(format!("{:?}", codec::quote(&text))),
            },
        }
    }

    fn garbage(&mut self, what: String) -> Result<(), String> {
        self.stats.garbage += 1;
        if self.opening {
            return Err(what);
        }
        if self.stats.garbage <= GARBAGE_LOGGED {
            tracing::warn!(port = %self.port, line = %what, "fdcanusb: skipping a line that is not the protocol");
        }
        Ok(())
    }

    fn queue_frame(&mut self, frame: CanFrame, now: SystemTime) {
        self.stats.received += 1;
        if !passes(&self.filters, &frame) {
            self.stats.filtered += 1;
            return;
        }
        if self.frames.len() >= MAX_QUEUED {
            self.stats.overrun += 1;
            // Once per overflow, as a controller reports its receive overrun.
            if !self.overflowing {
                self.overflowing = true;
                tracing::warn!(port = %self.port, "fdcanusb: frames are arriving faster than they are read; dropping");
                self.push_event(FrameLinkError::BusError {
                    iface: self.name.clone(),
                    kind: BusErrorKind::Other {
                        class: CAN_ERR_CRTL,
                    },
                });
            }
            return;
        }
        self.overflowing = false;
        self.frames.push_back(Received {
            frame,
            timestamp: Some(now),
        });
    }

    fn push_event(&mut self, e: FrameLinkError) {
        if self.events.len() >= MAX_EVENTS {
            self.events.pop_front();
        }
        self.events.push_back(e);
    }

    /// The answer to a `can status` the link asked by itself.
    fn poll_answered(&mut self, answer: Answer) {
        match answer {
            Answer::Ok(reply) => match codec::parse_status(reply.as_deref().unwrap_or_default()) {
                Ok(s) => self.apply_status(&s),
                Err(e) => {
                    let _ = self.garbage(e.to_string());
                }
            },
            // The adapter left the bus by itself (reset, or its own error handling).
            Answer::Err(details) if details.contains("BusOn") => {
                if self.bus != BusState::Off {
                    tracing::warn!(port = %self.port, %details, "fdcanusb is off the bus");
                    self.bus = BusState::Off;
                    self.push_event(FrameLinkError::BusOff {
                        iface: self.name.clone(),
                    });
                }
            }
            Answer::Err(details) => {
                let _ = self.garbage(format!("ERR {} to can status", codec::quote(&details)));
            }
        }
    }

    /// A status report: a change of the controller's state becomes the error a
    /// `SocketCAN` error frame gives, and so do frames the adapter dropped.
    fn apply_status(&mut self, s: &Status) {
        let state = if s.bus_off {
            BusState::Off
        } else if s.error_passive {
            BusState::Passive
        } else if s.warning {
            BusState::Warning
        } else {
            BusState::Active
        };
        if state != self.bus {
            let iface = self.name.clone();
            let event = match state {
                BusState::Off => FrameLinkError::BusOff { iface },
                BusState::Passive => FrameLinkError::ErrorPassive { iface },
                BusState::Warning => FrameLinkError::BusError {
                    iface,
                    kind: BusErrorKind::ErrorWarning,
                },
                BusState::Active if self.bus == BusState::Off => FrameLinkError::BusError {
                    iface,
                    kind: BusErrorKind::Restarted,
                },
                // Back to error active: `SocketCAN` reports it as a controller message.
                BusState::Active => FrameLinkError::BusError {
                    iface,
                    kind: BusErrorKind::Other {
                        class: CAN_ERR_CRTL,
                    },
                },
            };
            self.bus = state;
            self.push_event(event);
        }
        if let Some(n) = s.rx_overruns {
            if let Some(seen) = self.overruns_seen
                && n > seen
            {
                tracing::warn!(port = %self.port, dropped = n - seen, "fdcanusb dropped received frames");
                self.push_event(FrameLinkError::BusError {
                    iface: self.name.clone(),
                    kind: BusErrorKind::Other {
                        class: CAN_ERR_CRTL,
                    },
                });
            }
            self.overruns_seen = Some(n);
        }
    }

    /// The bytes of `can status` when one is due (and none is in flight).
    fn status_poll_due(&mut self) -> Option<&'static str> {
        let now = self.link.now();
        let due = self
            .last_poll
            .is_none_or(|t| now.saturating_duration_since(t) >= self.config.status_every);
        if !due || self.pending.iter().any(|p| p.expect == Expect::Poll) {
            return None;
        }
        if self.pending.len() >= MAX_PENDING {
            return None;
        }
        self.last_poll = Some(now);
        self.stats.status_polls += 1;
        Some("can status\n")
    }

    fn link_error(&self, e: LinkError) -> FrameLinkError {
        match e {
            LinkError::Closed { context } => FrameLinkError::Closed {
                context: format!("{}: {context}", self.name),
            },
            other => FrameLinkError::io(self.name.clone(), io::Error::other(other.to_string())),
        }
    }
}

fn check_rate(
    port: &str,
    setting: &'static str,
    value: u32,
    range: &core::ops::RangeInclusive<u32>,
) -> Result<(), AdapterError> {
    if range.contains(&value) {
        Ok(())
    } else {
        Err(AdapterError::new(
            "fdcanusb",
            port,
            AdapterErrorKind::RateUnsupported,
            format!(
                "{setting} {value} bit/s is out of range for an fdcanusb (allowed: {}..={}); \
                 nothing was sent",
                range.start(),
                range.end()
            ),
        ))
    }
}

/// A `conf get` value as a number (`true` / `false` as 1 / 0).
fn parse_setting(text: &str) -> Option<u32> {
    match text.trim() {
        "true" => Some(1),
        "false" => Some(0),
        t => t.parse().ok(),
    }
}

impl<L: ByteLink> FrameLink for FdcanusbLink<L> {
    fn send(&mut self, frame: &CanFrame) -> Result<(), FrameLinkError> {
        let line = codec::encode_send(frame).map_err(|reason| FrameLinkError::Unsendable {
            context: self.name.clone(),
            reason,
        })?;
        if self.pending.len() >= MAX_PENDING {
            return Err(FrameLinkError::io(
                self.name.clone(),
                io::Error::new(
                    io::ErrorKind::TimedOut,
                    format!("the adapter left {MAX_PENDING} commands unanswered"),
                ),
            ));
        }
        let mut bytes = line.into_bytes();
        let poll = self.status_poll_due();
        if let Some(p) = poll {
            bytes.extend_from_slice(p.as_bytes());
        }
        if let Err(e) = self.link.write_all(&bytes) {
            return Err(self.link_error(e));
        }
        let seq = self.push_pending(Expect::Final);
        if poll.is_some() {
            self.push_pending(Expect::Poll);
        }
        match self.wait_for(seq) {
            Ok(_) => Ok(()),
            Err(Failure::Silent(waited)) => Err(FrameLinkError::io(
                self.name.clone(),
                io::Error::new(
                    io::ErrorKind::TimedOut,
                    format!(
                        "the adapter did not answer a frame it was given within {} ms",
                        waited.as_millis()
                    ),
                ),
            )),
            Err(Failure::Refused(details)) if details.contains("BusOn") => {
                self.bus = BusState::Off;
                Err(FrameLinkError::BusOff {
                    iface: self.name.clone(),
                })
            }
            Err(Failure::Refused(details)) => Err(FrameLinkError::Unsendable {
                context: self.name.clone(),
                reason: format!("the adapter answered ERR {details}"),
            }),
            Err(Failure::Link(e)) => Err(self.link_error(e)),
            Err(Failure::Garbage(_) | Failure::Busy) => Err(FrameLinkError::io(
                self.name.clone(),
                io::Error::other("the adapter stopped answering"),
            )),
        }
    }

    fn recv(&mut self, deadline: Instant) -> Result<Received, FrameLinkError> {
        loop {
            if let Some(e) = self.events.pop_front() {
                return Err(e);
            }
            if let Some(rx) = self.frames.pop_front() {
                return Ok(rx);
            }
            if let Some(poll) = self.status_poll_due() {
                if let Err(e) = self.link.write_all(poll.as_bytes()) {
                    return Err(self.link_error(e));
                }
                self.push_pending(Expect::Poll);
            }
            match self.read_some(deadline) {
                Err(Failure::Silent(_)) => {
                    // Whatever the last read completed is still delivered.
                    if let Some(e) = self.events.pop_front() {
                        return Err(e);
                    }
                    return self.frames.pop_front().ok_or(FrameLinkError::Timeout);
                }
                Err(Failure::Link(e)) => return Err(self.link_error(e)),
                // Lines that are not the protocol are counted and skipped once open.
                Ok(()) | Err(Failure::Garbage(_) | Failure::Refused(_) | Failure::Busy) => {}
            }
        }
    }

    fn set_filters(&mut self, filters: &[IdFilter]) -> Result<(), FrameLinkError> {
        self.filters = filters.to_vec();
        let before = self.frames.len();
        let kept = &self.filters;
        self.frames.retain(|rx| passes(kept, &rx.frame));
        self.stats.filtered += (before - self.frames.len()) as u64;
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

    /// `false`: the firmware refuses `can std` without data.
    fn sends_empty_frames(&self) -> bool {
        false
    }

    /// 1.5 ms: the adapter's USB full-speed transfers (1 ms frames apart) and its
    /// buffering of received frames until a transfer takes them.
    fn reply_allowance(&self) -> Duration {
        crate::frame_link::USB_ADAPTER_REPLY_ALLOWANCE
    }
}

impl<L: ByteLink> Drop for FdcanusbLink<L> {
    fn drop(&mut self) {
        if !self.on {
            return;
        }
        self.on = false;
        if self.link.write_all(b"can off\n").is_err() {
            return;
        }
        let seq = self.push_pending(Expect::Final);
        self.config.reply_timeout = self.config.reply_timeout.min(CLOSE_WAIT);
        let _ = self.wait_for(seq);
    }
}

#[cfg(test)]
mod tests;
