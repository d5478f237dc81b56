//! The bus: owns the byte link, runs every transaction (flush, send, timed read, decode,
//! retry per [`retry_class`]).

use core::time::Duration;
use std::path::Path;
use std::time::Instant;

use robobus_link::{ByteLink, LinkError};
use robobus_wck::{
    BaudRate, Command, DataByte, ExtServoId, Position, Position10, Reply, ReplyError, ServoId,
    SyncMove, TorqueLevel, timing,
};

use super::error::WckError;
use super::policy::{RetryClass, needs_confirmation, read_back, retry_class};
use super::servo::Servo;

/// Default reply margin: added to the modelled response time of every command.
pub const DEFAULT_MARGIN: Duration = Duration::from_millis(10);

/// Default quiet time that ends the drain after a failed attempt.
pub const DEFAULT_SETTLE: Duration = Duration::from_millis(2);

/// Default time after a reply deadline during which a late reply may still arrive.
pub const DEFAULT_LATE_WINDOW: Duration = Duration::from_millis(50);

/// Default quiet time after a reply before it is credited: one module turnaround.
pub const DEFAULT_GUARD: Duration = timing::T_PROC;

/// Longest a drain after a failed attempt may last, however noisy the line.
const MAX_DRAIN: Duration = Duration::from_millis(50);

/// Most bytes one attempt keeps for its error message (the rest is only counted).
const KEEP_BYTES: usize = 16;

/// How a [`WckBus`] talks: retries, reply margin, confirmation of reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WckConfig {
    /// How many times a failed attempt of a command that is safe to repeat (see
    /// [`retry_class`]) is sent again; 0 turns retries off. Default 3 (4 attempts): with
    /// 1 % of the bytes corrupted, a read then fails in about 1 of 50 000.
    pub retries: u32,
    /// Added to the modelled response time ([`robobus_wck::timing::transaction_time`]:
    /// command and reply wire time plus the module's turnaround, 1006.6 µs or 121 ms for
    /// EEPROM writes) to get each reply deadline. Covers OS scheduling and USB-serial
    /// latency. Default [`DEFAULT_MARGIN`] (10 ms); [`WckBus::open`] adds the adapter's
    /// latency timer when it can read it.
    pub margin: Duration,
    /// How many equal replies in a row a read needs before its value is accepted; 0 and
    /// 1 turn confirmation off (the default). Replies carry no checksum, so a single
    /// flipped bit can turn a status reply into another plausible position; reading again
    /// until replies agree catches that, at the cost of extra transactions. Reads whose
    /// two reply bytes repeat one value (I gain, over-load, motion count; see
    /// [`needs_confirmation`]) already carry a check, and need one reply fewer. The retry
    /// budget grows to `(retries + 1) × confirm_reads` attempts. A moving shaft may read
    /// differently each time; such a read then fails with [`WckError::Unconfirmed`].
    ///
    /// With 1 % of the bytes corrupted, 2 leaves about one wrong value in 40 000 reads
    /// (two replies corrupted the same way), 3 about one in 30 million.
    pub confirm_reads: u8,
    /// After a failed attempt, input is drained until the line has been quiet this long
    /// (at most 50 ms or twice this, whichever is longer), so a late reply cannot be taken
    /// for the next one. Default
    /// [`DEFAULT_SETTLE`] (2 ms).
    pub settle: Duration,
    /// How long after its deadline a reply may still arrive (a module, adapter or host
    /// that was slow). wCK replies carry no ID, so such a reply would be taken for the
    /// answer to whatever is asked next. After an attempt that timed out or got a garbled
    /// reply, and after a success that needed a retry (an earlier attempt's reply may have
    /// been taken, this attempt's own is then still on its way), the next packet waits
    /// until this long after that attempt's deadline, dropping what arrives. Costs this
    /// much per silent servo; nothing while every reply is on time. A scan does not wait
    /// before each probe: it sends the next one at once and credits nothing that arrives
    /// while the window is open (it waits the window out and asks that ID again), so an
    /// empty ID costs only its reply waits (see [`WckBus::scan`]).
    pub late_window: Duration,
    /// How long the line must stay quiet after a complete reply before the reply is
    /// credited. A wCK reply carries no ID, so a byte that follows it within this time
    /// (a duplicated byte, a module answering twice, a second module) means the bytes
    /// received are not one module's one answer: the attempt fails (it is never "the first
    /// two bytes win"), the late window is waited out and the command is asked again.
    /// Default [`DEFAULT_GUARD`] (one module turnaround, 1006.6 µs): whatever answers the
    /// same command answers within a turnaround of the first answer. Bytes that arrive
    /// later still fall before the next command's earliest reply instant and fail that
    /// attempt instead (see [`WckBus::reply_wait`]).
    pub guard: Duration,
    /// The earliest a module begins to answer after a command's last byte; bytes that
    /// come sooner cannot be its reply (see [`robobus_wck::timing::earliest_reply`]).
    /// `None` (the default): the manual's turnaround for the command (1006.6 µs, 121 ms
    /// for EEPROM writes). Set it lower only for modules that answer faster, such as a
    /// simulator without processing time.
    pub min_turnaround: Option<Duration>,
}

impl Default for WckConfig {
    fn default() -> Self {
        Self {
            retries: 3,
            margin: DEFAULT_MARGIN,
            confirm_reads: 0,
            settle: DEFAULT_SETTLE,
            late_window: DEFAULT_LATE_WINDOW,
            guard: DEFAULT_GUARD,
            min_turnaround: None,
        }
    }
}

/// What a [`WckBus`] has done so far.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct WckStats {
    /// Commands issued (each counted once, whatever the attempts).
    pub commands: u64,
    /// Packets written (attempts, read-backs and probes included).
    pub attempts: u64,
    /// Attempts that were resends after a failure.
    pub retries: u64,
    /// Attempts whose reply did not arrive completely in time.
    pub timeouts: u64,
    /// Attempts whose reply failed its plausibility check.
    pub bad_replies: u64,
    /// Confirmed reads whose reply differed from the one before.
    pub mismatches: u64,
    /// Attempts whose bytes could not all be the command's one reply: bytes that arrived
    /// before any module could have answered, or more bytes than one reply (see
    /// [`WckConfig::guard`]).
    pub unattributable: u64,
}

/// Why one attempt failed.
#[derive(Debug)]
pub(crate) enum Failure {
    Timeout {
        received: Vec<u8>,
        waited: Duration,
    },
    Bad {
        bytes: Vec<u8>,
        reason: ReplyError,
    },
    /// Bytes that cannot be this command's one reply (see [`Anomaly`]).
    Unattributable {
        bytes: Vec<u8>,
        anomaly: Anomaly,
    },
    Link(LinkError),
}

/// Why the bytes of an attempt cannot be the command's one reply.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Anomaly {
    /// `early` bytes arrived before any module can have answered
    /// ([`timing::earliest_reply`]): stray bytes (an earlier reply, a duplicate, noise).
    Early { early: usize },
    /// More bytes than one reply arrived within the guard time after it: more than one
    /// answer.
    Extra { total: usize },
}

impl Anomaly {
    /// The error text: what arrived and why it cannot be the reply.
    pub(crate) fn describe(self, bytes: &[u8], reply_len: usize) -> String {
        match self {
            Self::Early { early } => format!(
                "{early} of the {} byte(s) ({}) arrived before any module can have answered",
                bytes.len().max(early),
                super::error::Hex(bytes)
            ),
            Self::Extra { total } => {
                let first = bytes.get(..reply_len).unwrap_or_default();
                let second = bytes.get(reply_len..reply_len * 2).unwrap_or_default();
                if second.len() == reply_len && first != second {
                    format!(
                        "more than one answer: two different replies ({} and {})",
                        super::error::Hex(first),
                        super::error::Hex(second)
                    )
                } else {
                    format!(
                        "more than one answer: {total} bytes ({}) where one {reply_len}-byte \
                         reply was due",
                        super::error::Hex(bytes)
                    )
                }
            }
        }
    }
}

/// A wCK bus: one UART line with up to 31 modules (IDs 0..=30; up to 254 with the
/// 10-bit commands), owned through its byte link.
///
/// Device handles borrow it: [`WckBus::servo`] gives a [`Servo`] with a typed method per
/// command of the manual. Every transaction flushes stale input, writes the packet, and
/// waits for the reply until the modelled response time plus
/// [`WckConfig::margin`]. Commands are retried per [`retry_class`].
///
/// Keep the bus in one thread (it is `Send` if the link is); other threads reach it
/// through a channel.
#[derive(Debug)]
pub struct WckBus<L> {
    link: L,
    baud: BaudRate,
    config: WckConfig,
    device: String,
    stats: WckStats,
    /// The last attempt's reply deadline.
    deadline: Option<Instant>,
    /// Input is dropped until then before the next packet (a late reply may come).
    quiet_until: Option<Instant>,
}

#[cfg(unix)]
impl WckBus<robobus_link::SerialLink> {
    /// Opens the serial port at `path` (a USB adapter, or the pty of the simulator:
    /// `robobus sim wck`) at `baud`.
    ///
    /// If the port is a USB-serial adapter whose latency timer can be read (FTDI on
    /// Linux), the timer is added to the reply margin: such an adapter holds short
    /// replies that long (16 ms by default).
    pub fn open(path: impl AsRef<Path>, baud: BaudRate) -> Result<Self, WckError> {
        let path = path.as_ref();
        let device = path.display().to_string();
        let link =
            robobus_link::SerialLink::open(path, baud.bits_per_second()).map_err(|source| {
                WckError::Link {
                    device: device.clone(),
                    command: "open",
                    source,
                }
            })?;
        let latency = link.latency_timer().unwrap_or(0);
        let mut bus = Self::new(link, baud)?.with_device_name(device);
        bus.config.margin += Duration::from_millis(u64::from(latency));
        Ok(bus)
    }
}

impl<L: ByteLink> WckBus<L> {
    /// A bus over any byte link (a pty, a fault-injecting wrapper, an in-memory pair),
    /// switched to `baud`. Input already waiting is drained until the line has been quiet
    /// for [`WckConfig::settle`] (2 ms; a late reply to a previous process is nobody's). Errors name the device as `wCK bus` until
    /// [`WckBus::with_device_name`] names it.
    pub fn new(mut link: L, baud: BaudRate) -> Result<Self, WckError> {
        let device = String::from("wCK bus");
        link.set_baud(baud.bits_per_second())
            .map_err(|source| WckError::Link {
                device: device.clone(),
                command: "set baud rate",
                source,
            })?;
        let mut bus = Self {
            link,
            baud,
            config: WckConfig::default(),
            device,
            stats: WckStats::default(),
            deadline: None,
            quiet_until: None,
        };
        // Input waiting before the first command (a late reply to a previous process,
        // still trickling in) is nobody's reply.
        bus.settle();
        Ok(bus)
    }

    /// Names the device in error messages (for example the path of a pty).
    #[must_use]
    pub fn with_device_name(mut self, name: impl Into<String>) -> Self {
        self.device = name.into();
        self
    }

    /// Replaces the configuration.
    #[must_use]
    pub fn with_config(mut self, config: WckConfig) -> Self {
        self.config = config;
        self
    }

    /// The configuration.
    pub const fn config(&self) -> &WckConfig {
        &self.config
    }

    /// The configuration, to change.
    pub const fn config_mut(&mut self) -> &mut WckConfig {
        &mut self.config
    }

    /// The device name used in errors.
    pub fn device(&self) -> &str {
        &self.device
    }

    /// The baud rate the host side of the bus runs at.
    pub const fn baud(&self) -> BaudRate {
        self.baud
    }

    /// Switches the host side (the link) to `baud`, without telling any module (to talk
    /// to modules already at that rate). To change a module's rate use
    /// [`Servo::set_baud`].
    pub fn set_host_baud(&mut self, baud: BaudRate) -> Result<(), WckError> {
        self.link
            .set_baud(baud.bits_per_second())
            .map_err(|source| self.link_error("set baud rate", source))?;
        self.baud = baud;
        Ok(())
    }

    /// Counters of what the bus has done.
    pub const fn stats(&self) -> WckStats {
        self.stats
    }

    /// The link.
    pub const fn link(&self) -> &L {
        &self.link
    }

    /// The link, mutably (bytes exchanged directly bypass the bus's bookkeeping).
    pub const fn link_mut(&mut self) -> &mut L {
        &mut self.link
    }

    /// Gives the link back.
    pub fn into_link(self) -> L {
        self.link
    }

    /// The same bus (configuration, device name, statistics) over a wrapped link, for
    /// example [`crate::ops::capture::capture_byte_link`] around the opened port; `wrap`'s
    /// error is handed back as it is.
    pub fn try_map_link<M, E>(self, wrap: impl FnOnce(L) -> Result<M, E>) -> Result<WckBus<M>, E> {
        Ok(WckBus {
            link: wrap(self.link)?,
            baud: self.baud,
            config: self.config,
            device: self.device,
            stats: self.stats,
            deadline: self.deadline,
            quiet_until: self.quiet_until,
        })
    }

    /// The link's clock (the wall clock, or a simulator's virtual clock): every deadline
    /// of the bus is taken from it.
    pub fn now(&self) -> Instant {
        self.link.now()
    }

    /// Waits until `deadline` on the link's clock, reading nothing.
    pub fn sleep_until(&mut self, deadline: Instant) {
        self.link.sleep_until(deadline);
    }

    /// A handle on the module with ID `id` (0..=30).
    pub const fn servo(&mut self, id: ServoId) -> Servo<'_, L> {
        Servo::new(self, id)
    }

    /// How long the bus waits for the reply to `command`, counted from the moment it
    /// starts writing the packet: [`timing::transaction_time`] at the bus's baud rate
    /// (command and reply wire time plus turnaround, 121 ms for EEPROM writes) plus
    /// [`WckConfig::margin`].
    pub fn reply_wait(&self, command: &Command) -> Duration {
        timing::transaction_time(command, self.baud).saturating_add(self.config.margin)
    }

    /// Sends any typed command with the policy of its [`retry_class`] and returns its
    /// checked reply (`None` for the commands without one, and for a break whose replies
    /// collided: see [`WckBus::break_all`]).
    ///
    /// ID and baud changes and motion program uploads are verified as
    /// [`Servo::set_id`], [`Servo::set_baud`] and [`Servo::upload_program`] describe.
    pub fn execute(&mut self, command: &Command) -> Result<Option<Reply>, WckError> {
        match retry_class(command) {
            RetryClass::Read | RetryClass::Idempotent => {
                if matches!(command, Command::Break) {
                    self.break_all()
                } else {
                    self.stats.commands += 1;
                    self.run(command).map(Some)
                }
            }
            RetryClass::VerifiedWrite => {
                self.stats.commands += 1;
                self.write_verified(command).map(Some)
            }
            RetryClass::Once => match *command {
                Command::IdSet { id, new_id } => {
                    self.set_id(id, new_id)?;
                    Ok(Some(Reply::Id(new_id)))
                }
                Command::BaudSet { id, baud } => {
                    self.set_module_baud(id, baud)?;
                    Ok(Some(Reply::Baud(baud)))
                }
                Command::MotionWrite { .. } => {
                    self.stats.commands += 1;
                    self.write_verified(command).map(Some)
                }
                _ => {
                    self.stats.commands += 1;
                    self.once(command).map(Some)
                }
            },
            RetryClass::NoReply => {
                self.stats.commands += 1;
                self.send(command)?;
                Ok(None)
            }
        }
    }

    /// (2) Synchronized position move: servo `i` goes to `positions[i]` for IDs
    /// `0..positions.len()` (1..=31 positions, in steps of 1.055°), all at `torque`
    /// (0 = maximum). One packet, no reply, sent once; it takes
    /// `(n + 4) × 10 / baud` seconds on the wire.
    pub fn sync_move(
        &mut self,
        torque: TorqueLevel,
        positions: &[Position],
    ) -> Result<(), WckError> {
        let sync = SyncMove::new(torque, positions).map_err(|source| WckError::Value {
            command: "synchronized position move",
            source,
        })?;
        self.stats.commands += 1;
        self.send(&Command::SyncMove(sync))
    }

    /// (6) Break: every module on the bus enters break mode (dynamic brake).
    ///
    /// Every module answers with its ID and position at the same moment, so with more
    /// than one module the replies collide. Returns `Some(Reply::Break { .. })` when the
    /// two bytes arrived and are plausible (with one module: its ID and position; with
    /// several the bytes may mix their replies), `None` when bytes arrived but are garbled
    /// (a collision: the command was heard). Resent (it is idempotent) only when nothing at
    /// all came back; a timeout error means no module answered any attempt.
    pub fn break_all(&mut self) -> Result<Option<Reply>, WckError> {
        self.stats.commands += 1;
        let command = Command::Break;
        let mut last = None;
        for attempt in 1..=self.config.retries.saturating_add(1) {
            if attempt > 1 {
                self.stats.retries += 1;
            }
            match self.exchange(&command) {
                Ok(bytes) => {
                    if let Ok(reply) = command.decode_reply(&bytes) {
                        return Ok(Some(reply));
                    }
                    self.settle();
                    return Ok(None);
                }
                Err(Failure::Timeout { received, waited }) => {
                    self.stats.timeouts += 1;
                    self.settle();
                    if !received.is_empty() {
                        return Ok(None);
                    }
                    last = Some((received, waited, attempt));
                }
                Err(Failure::Unattributable { .. }) => {
                    // Bytes came back (several modules answer at once): it was heard.
                    self.settle();
                    return Ok(None);
                }
                Err(failure) => return Err(self.failure_error(&command, failure, attempt)),
            }
        }
        let (received, waited, attempts) = last.unwrap_or_default();
        Err(self.failure_error(&command, Failure::Timeout { received, waited }, attempts))
    }

    /// (26) 10-bit position move of the module with full-byte ID `id` (0..=253; the
    /// only way to reach IDs above 30): go to `position` (0..=1023, 0.325° a step) with
    /// `torque` (0..=254). Returns the 10-bit position *before* the move. Retried (see
    /// [`retry_class`]).
    pub fn move10(
        &mut self,
        id: ExtServoId,
        torque: DataByte,
        position: Position10,
    ) -> Result<Position10, WckError> {
        let command = Command::Move10 {
            id,
            torque,
            position,
        };
        match self.execute(&command)? {
            Some(Reply::Position10(p)) => Ok(p),
            other => Err(self.unexpected(&command, other)),
        }
    }

    /// (27) 10-bit position read of the module with full-byte ID `id` (0..=253): 0..=1023,
    /// 0.325° a step.
    pub fn read10(&mut self, id: ExtServoId) -> Result<Position10, WckError> {
        let command = Command::Read10 { id };
        match self.execute(&command)? {
            Some(Reply::Position10(p)) => Ok(p),
            other => Err(self.unexpected(&command, other)),
        }
    }

    // ----- transactions -----

    /// One attempt: flush, write, read two bytes before the deadline.
    pub(crate) fn exchange(&mut self, command: &Command) -> Result<[u8; 2], Failure> {
        self.drain_late();
        self.exchange_now(command)
    }

    /// Whether a reply to an earlier attempt may still arrive (its late window is open).
    pub(crate) fn late_reply_possible(&self) -> bool {
        self.quiet_until.is_some_and(|q| q > self.link.now())
    }

    /// One attempt without waiting out an open late window first: what it receives may
    /// be an earlier attempt's late reply, so the caller must not credit it while
    /// [`WckBus::late_reply_possible`] said so (see the scan).
    pub(crate) fn exchange_now(&mut self, command: &Command) -> Result<[u8; 2], Failure> {
        self.link.discard_input().map_err(Failure::Link)?;
        let packet = command.encode();
        let wait = self.reply_wait(command);
        let start = self.link.now();
        self.link.write_all(&packet).map_err(Failure::Link)?;
        self.stats.attempts += 1;
        let deadline = start + wait;
        self.deadline = Some(deadline);
        let earliest = start
            + match self.config.min_turnaround {
                Some(t) if command.reply_len() > 0 => {
                    timing::wire_time(command.encoded_len(), self.baud)
                        .saturating_add(t.min(timing::turnaround(command)))
                }
                _ => timing::earliest_reply(command, self.baud),
            };
        let reply_len = command.reply_len();
        let guard = self.config.guard;
        let mut kept: Vec<u8> = Vec::with_capacity(reply_len);
        let (mut total, mut early) = (0usize, 0usize);
        let mut until = deadline;
        let mut buf = [0u8; KEEP_BYTES];
        loop {
            match self.link.read_some(&mut buf, until) {
                Ok(n) => {
                    // Received by now: a byte read before the earliest reply instant
                    // arrived before any module can have started answering.
                    let at = self.link.now();
                    if at < earliest {
                        early += n;
                    }
                    total += n;
                    let room = KEEP_BYTES.saturating_sub(kept.len());
                    kept.extend(buf.iter().take(n.min(room)));
                    if total - early >= reply_len {
                        // A reply's worth: the line must now stay quiet for the guard
                        // time (an anomaly is read on until quiet, at most that long
                        // past the deadline, for the error message).
                        until = (at + guard).min(deadline + guard);
                    }
                }
                Err(LinkError::Timeout { .. }) => break,
                Err(e) => return Err(Failure::Link(e)),
            }
        }
        let answered = total - early;
        let anomaly = if early > 0 && answered > 0 {
            Some(Anomaly::Early { early })
        } else if answered > reply_len {
            Some(Anomaly::Extra { total })
        } else {
            None
        };
        if let Some(anomaly) = anomaly {
            self.stats.unattributable += 1;
            self.expect_late();
            return Err(Failure::Unattributable {
                bytes: kept,
                anomaly,
            });
        }
        if answered == reply_len
            && let Some(&[a, b]) = kept.get(early..).map(|k| k.get(..2).unwrap_or_default())
        {
            return Ok([a, b]);
        }
        self.expect_late();
        Err(Failure::Timeout {
            received: kept.get(early..).unwrap_or_default().to_vec(),
            waited: wait,
        })
    }

    /// A reply to the last attempt may still come (it timed out, its reply was garbled,
    /// or it succeeded after a retry): the next packet waits out the late window first.
    pub(crate) fn expect_late(&mut self) {
        if let Some(d) = self.deadline {
            let until = d + self.config.late_window;
            self.quiet_until = Some(self.quiet_until.map_or(until, |q| q.max(until)));
        }
    }

    /// Drops input until the late window of the last doubtful attempt has passed.
    fn drain_late(&mut self) {
        let Some(until) = self.quiet_until.take() else {
            return;
        };
        // Until the link says the deadline has passed (a fast-forwarding simulator says
        // so at once, on its own clock).
        let mut buf = [0u8; 64];
        while self.link.read_some(&mut buf, until).is_ok() {}
    }

    /// Bytes that arrive within `window` after a reply (a collision or line noise makes
    /// them; a single clean module sends none). Used by the scan.
    pub(crate) fn trailing_bytes(&mut self, window: Duration) -> Result<usize, WckError> {
        let deadline = self.link.now() + window;
        let mut buf = [0u8; 16];
        let mut n = 0;
        loop {
            match self.link.read_some(&mut buf, deadline) {
                Ok(k) => n += k,
                Err(LinkError::Timeout { .. }) => return Ok(n),
                Err(source) => return Err(self.link_error("scan", source)),
            }
        }
    }

    /// One attempt, decoded; failures are counted.
    pub(crate) fn attempt(&mut self, command: &Command) -> Result<Reply, Failure> {
        let bytes = self.exchange(command).inspect_err(|f| {
            if matches!(f, Failure::Timeout { .. }) {
                self.stats.timeouts += 1;
            }
        })?;
        command.decode_reply(&bytes).map_err(|reason| {
            self.stats.bad_replies += 1;
            self.expect_late();
            Failure::Bad {
                bytes: bytes.to_vec(),
                reason,
            }
        })
    }

    /// Sends a command without a reply, once.
    fn send(&mut self, command: &Command) -> Result<(), WckError> {
        self.drain_late();
        self.link
            .discard_input()
            .and_then(|()| self.link.write_all(&command.encode()))
            .map_err(|source| self.link_error(command.name(), source))?;
        self.stats.attempts += 1;
        Ok(())
    }

    /// One attempt, no resend; a failure drains the line and becomes an error.
    fn once(&mut self, command: &Command) -> Result<Reply, WckError> {
        self.attempt(command).map_err(|f| {
            self.settle();
            self.failure_error(command, f, 1)
        })
    }

    /// How many equal replies in a row `command` needs (1 = no confirmation).
    fn agreement(&self, command: &Command) -> u32 {
        let n = u32::from(self.config.confirm_reads).max(1);
        if retry_class(command) != RetryClass::Read {
            1
        } else if needs_confirmation(command) {
            n
        } else {
            (n - 1).max(1)
        }
    }

    /// A read or idempotent command with retries (and confirmation, if configured).
    pub(crate) fn run(&mut self, command: &Command) -> Result<Reply, WckError> {
        let tries = self.config.retries.saturating_add(1);
        let needed = self.agreement(command);
        let limit = tries.saturating_mul(needed);
        let mut previous: Option<[u8; 2]> = None;
        let mut streak = 0;
        let mut failed = false;
        let mut last_error = None;
        for _ in 0..limit {
            if failed {
                self.stats.retries += 1;
            }
            match self.exchange(command) {
                Ok(bytes) => match command.decode_reply(&bytes) {
                    Ok(reply) => {
                        if failed {
                            // This may be an earlier attempt's reply; this one's is late.
                            self.expect_late();
                        }
                        if previous == Some(bytes) {
                            streak += 1;
                        } else {
                            if let Some(p) = previous {
                                self.stats.mismatches += 1;
                                last_error = Some(WckError::Unconfirmed {
                                    device: self.device.clone(),
                                    target: command.target(),
                                    command: command.name(),
                                    previous: p.to_vec(),
                                    last: bytes.to_vec(),
                                    attempts: limit,
                                });
                            }
                            previous = Some(bytes);
                            streak = 1;
                        }
                        if streak >= needed {
                            return Ok(reply);
                        }
                        failed = false;
                    }
                    Err(reason) => {
                        self.stats.bad_replies += 1;
                        self.expect_late();
                        self.settle();
                        failed = true;
                        let bytes = bytes.to_vec();
                        last_error = Some(self.failure_error(
                            command,
                            Failure::Bad { bytes, reason },
                            limit,
                        ));
                    }
                },
                Err(Failure::Link(source)) => {
                    return Err(self.link_error(command.name(), source));
                }
                Err(failure @ Failure::Unattributable { .. }) => {
                    self.settle();
                    failed = true;
                    last_error = Some(self.failure_error(command, failure, limit));
                }
                Err(failure) => {
                    self.stats.timeouts += 1;
                    self.settle();
                    failed = true;
                    last_error = Some(self.failure_error(command, failure, limit));
                }
            }
        }
        Err(last_error.unwrap_or_else(|| WckError::Unconfirmed {
            device: self.device.clone(),
            target: command.target(),
            command: command.name(),
            previous: Vec::new(),
            last: previous.map(|p| p.to_vec()).unwrap_or_default(),
            attempts: limit,
        }))
    }

    /// An EEPROM write verified by reading it back; resent only if the read-back shows
    /// it did not take (and only for [`RetryClass::VerifiedWrite`], not for the motion
    /// data write, which restarts the program).
    fn write_verified(&mut self, command: &Command) -> Result<Reply, WckError> {
        let Some(read) = read_back(command) else {
            return self.once(command);
        };
        let expected = expected_reply(command);
        let resend = retry_class(command) == RetryClass::VerifiedWrite;
        let writes = if resend {
            self.config.retries.saturating_add(1)
        } else {
            1
        };
        let mut write = 1;
        loop {
            let outcome = self.attempt(command);
            let write_failure = match outcome {
                Ok(_) => None,
                Err(Failure::Link(source)) => return Err(self.link_error(command.name(), source)),
                Err(f) => {
                    self.settle();
                    Some(f)
                }
            };
            let found = match self.run(&read) {
                Ok(found) => found,
                Err(read_error) => {
                    return Err(match write_failure {
                        Some(f) => self.failure_error(command, f, write),
                        None => read_error,
                    });
                }
            };
            if Some(found) == expected {
                return Ok(found);
            }
            if write >= writes {
                return Err(WckError::NotApplied {
                    device: self.device.clone(),
                    target: command.target(),
                    command: command.name(),
                    expected: expected.map_or_else(|| command.to_string(), |e| e.to_string()),
                    found: found.to_string(),
                });
            }
            write += 1;
            self.stats.retries += 1;
        }
    }

    /// (14) ID set, verified at the new ID (see [`Servo::set_id`]).
    pub(crate) fn set_id(&mut self, id: ServoId, new_id: ExtServoId) -> Result<(), WckError> {
        self.stats.commands += 1;
        let command = Command::IdSet { id, new_id };
        let probe_new = probe_command(new_id);
        if ExtServoId::from(id) != new_id {
            match self.exchange(&probe_new) {
                Err(Failure::Timeout { received, .. }) if received.is_empty() => {}
                Err(Failure::Link(source)) => return Err(self.link_error(command.name(), source)),
                _ => {
                    self.settle();
                    return Err(WckError::IdInUse {
                        device: self.device.clone(),
                        target: command.target(),
                        new_id: new_id.get(),
                    });
                }
            }
        }
        let write = self.attempt(&command);
        if let Err(Failure::Link(source)) = write {
            return Err(self.link_error(command.name(), source));
        }
        if write.is_err() {
            self.settle();
        }
        let Err(at_new) = self.run(&probe_new) else {
            return Ok(());
        };
        match self.run(&Command::StatusRead { id }) {
            Ok(_) => Err(WckError::NotApplied {
                device: self.device.clone(),
                target: command.target(),
                command: command.name(),
                expected: format!("an answer at ID {new_id}"),
                found: format!("it still answers at ID {id} ({})", describe(&write)),
            }),
            Err(_) => Err(WckError::NotVerified {
                device: self.device.clone(),
                target: command.target(),
                command: command.name(),
                detail: format!(
                    "{}; nothing answers at the new ID {new_id} ({at_new}) nor at the old ID {id}",
                    describe(&write)
                ),
            }),
        }
    }

    /// (7) Baud rate set, verified at the new rate (see [`Servo::set_baud`]).
    pub(crate) fn set_module_baud(&mut self, id: ServoId, baud: BaudRate) -> Result<(), WckError> {
        self.stats.commands += 1;
        let command = Command::BaudSet { id, baud };
        let old = self.baud;
        let write = self.attempt(&command);
        if let Err(Failure::Link(source)) = write {
            return Err(self.link_error(command.name(), source));
        }
        if write.is_err() {
            self.settle();
        }
        self.set_host_baud(baud)?;
        let status = Command::StatusRead { id };
        let Err(at_new) = self.run(&status) else {
            return Ok(());
        };
        self.set_host_baud(old)?;
        match self.run(&status) {
            Ok(_) => Err(WckError::NotApplied {
                device: self.device.clone(),
                target: command.target(),
                command: command.name(),
                expected: format!("an answer at {baud}"),
                found: format!("it still answers at {old} ({})", describe(&write)),
            }),
            Err(_) => Err(WckError::NotVerified {
                device: self.device.clone(),
                target: command.target(),
                command: command.name(),
                detail: format!(
                    "{}; no answer at the new rate {baud} ({at_new}) nor at the old rate {old}; \
                     the bus stays at {old}",
                    describe(&write)
                ),
            }),
        }
    }

    /// Reads and drops input until the line is quiet for [`WckConfig::settle`] (at most
    /// 50 ms or twice the settle time), then flushes.
    pub(crate) fn settle(&mut self) {
        let cap = self.link.now() + MAX_DRAIN.max(self.config.settle.saturating_mul(2));
        let mut buf = [0u8; 64];
        loop {
            let now = self.link.now();
            if now >= cap {
                break;
            }
            let deadline = (now + self.config.settle).min(cap);
            if self.link.read_some(&mut buf, deadline).is_err() {
                break;
            }
        }
        let _ = self.link.discard_input();
    }

    // ----- errors -----

    pub(crate) fn link_error(&self, command: &'static str, source: LinkError) -> WckError {
        WckError::Link {
            device: self.device.clone(),
            command,
            source,
        }
    }

    pub(crate) fn failure_error(
        &self,
        command: &Command,
        failure: Failure,
        attempts: u32,
    ) -> WckError {
        match failure {
            Failure::Timeout { received, waited } => WckError::Timeout {
                device: self.device.clone(),
                target: command.target(),
                command: command.name(),
                baud: self.baud,
                waited,
                received,
                expected: command.reply_len(),
                attempts,
            },
            Failure::Bad { bytes, reason } => WckError::BadReply {
                device: self.device.clone(),
                target: command.target(),
                command: command.name(),
                bytes,
                reason,
                attempts,
            },
            Failure::Unattributable { bytes, anomaly } => WckError::Unattributable {
                device: self.device.clone(),
                target: command.target(),
                command: command.name(),
                detail: anomaly.describe(&bytes, command.reply_len()),
                bytes,
                attempts,
            },
            Failure::Link(source) => self.link_error(command.name(), source),
        }
    }

    /// A decoded reply of the wrong shape (cannot happen: the decoder picks the variant
    /// from the command), reported instead of guessed.
    pub(crate) fn unexpected(&self, command: &Command, reply: Option<Reply>) -> WckError {
        WckError::BadReply {
            device: self.device.clone(),
            target: command.target(),
            command: command.name(),
            bytes: reply.map(|r| r.to_bytes().to_vec()).unwrap_or_default(),
            reason: ReplyError::NoReply {
                command: command.name(),
            },
            attempts: 1,
        }
    }
}

/// The reply a setting's read-back gives when the setting took.
fn expected_reply(command: &Command) -> Option<Reply> {
    Some(match *command {
        Command::GainSet { p, d, .. } => Reply::Gains { p, d },
        Command::IGainSet { i, .. } => Reply::IGain(i),
        Command::SpeedSet { speed, accel, .. } => Reply::SpeedAccel { speed, accel },
        Command::OverloadSet { overload, .. } => Reply::Overload(overload),
        Command::BoundarySet { bounds, .. } => Reply::Boundaries(bounds),
        Command::MotionWrite { ref program, .. } => Reply::MotionCount(program.count()),
        _ => return None,
    })
}

/// The read that shows whether a module answers at `id`: a status read for IDs 0..=30,
/// a 10-bit position read above.
pub(crate) fn probe_command(id: ExtServoId) -> Command {
    match ServoId::new(id.get()) {
        Ok(id) => Command::StatusRead { id },
        Err(_) => Command::Read10 { id },
    }
}

fn describe(write: &Result<Reply, Failure>) -> String {
    match write {
        Ok(reply) => format!("the module acknowledged ({reply})"),
        Err(Failure::Timeout { received, .. }) => format!(
            "its reply did not arrive ({} bytes: {})",
            received.len(),
            super::error::Hex(received)
        ),
        Err(Failure::Bad { bytes, reason }) => format!(
            "its reply was implausible ({}: {reason})",
            super::error::Hex(bytes)
        ),
        Err(Failure::Unattributable { bytes, anomaly }) => format!(
            "its reply could not be attributed ({})",
            anomaly.describe(bytes, 2)
        ),
        Err(Failure::Link(e)) => format!("link error: {e}"),
    }
}
