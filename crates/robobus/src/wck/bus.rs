//! The bus: owns the byte link, runs every transaction (flush, send, timed read, decode,
//! retry per [`retry_class`]).

use core::time::Duration;
use std::path::Path;
use std::time::Instant;

use robobus_link::{ByteLink, LinkError, PortSpec, WaitMode};
use robobus_wck::{
    BaudRate, Command, DataByte, ExtServoId, Position, Position10, Reply, SyncMove, TorqueLevel,
    timing,
};

use super::error::WckError;
use super::policy::{RetryClass, retry_class};
mod transaction;
mod verify;

pub(crate) use transaction::{Anomaly, Failure};

/// Default reply margin: added to the modelled response time of every command.
pub const DEFAULT_MARGIN: Duration = Duration::from_millis(10);

/// Default quiet time that ends the drain after a failed attempt.
pub const DEFAULT_SETTLE: Duration = Duration::from_millis(2);

/// Default time after a reply deadline during which a late reply may still arrive.
pub const DEFAULT_LATE_WINDOW: Duration = Duration::from_millis(50);

/// How far apart two modules' turnarounds for one command may be (firmware and clock
/// spread; the simulator's `BusConfig::max_skew`): two modules at one ID both start
/// answering within this of each other.
pub const TURNAROUND_SPREAD: Duration = Duration::from_micros(3);

/// The quiet time after a reply before it is credited, at `baud`: one byte time plus
/// [`TURNAROUND_SPREAD`] (86.8 + 3 µs at 115200 bit/s, 10.9 + 3 µs at 921600, 2.08 ms
/// + 3 µs at 4800). What the default [`WckConfig::guard`] waits, and why it is enough:
///
/// - a byte the link repeats (a duplicated byte, which shifts the reply by one: `a a b`
///   instead of `a b`) follows the reply's last byte on the wire at once: it is complete
///   one byte time after it;
/// - a second module at the same ID (an impostor) starts its answer within the spread of
///   turnarounds after the first, so its answer overlaps the first one's and its last
///   byte (or whatever the host's UART makes of the two) is complete at most the spread
///   plus one byte time after the first one's last byte;
/// - anything later cannot have changed the two bytes already received: a module that
///   answers the same command twice (its same two bytes again, within a turnaround of
///   the first answer), an impostor whose turnaround lies further off, noise. The next
///   transaction catches it instead. Its command may go out at once (the wCK line is
///   full duplex: the host's command and a module's answer travel on different wires and
///   cannot collide), and no module can answer it before the command's wire time plus a
///   turnaround (1006.6 µs; [`WckConfig::min_turnaround`] if set lower), so a byte that
///   arrives before then fails that attempt, and only it ([`WckError::Unattributable`],
///   retried after the late window), and is never credited. A byte that arrives between
///   two transactions is dropped before the next packet ([`WckStats::dropped`]).
pub const fn reply_guard(baud: BaudRate) -> Duration {
    timing::byte_time(baud).saturating_add(TURNAROUND_SPREAD)
}

/// Added to the reply margin when [`WckBus::open`] opens a pseudo-terminal. A pty has no
/// wire: whatever answers on it (`robobus sim wck`, a bridge to a remote port) is a
/// process, and on a loaded machine the scheduler holds it past the 10 ms default margin
/// now and then (with four busy processes on two cores, 4 of 40 fresh simulators had
/// servos missing from their first scan). A reply so held would make a present servo
/// look absent; 50 ms more covers such stalls, at the cost of 50 ms per silent attempt.
pub const PTY_MARGIN: Duration = Duration::from_millis(50);

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
    /// [`needs_confirmation`](super::needs_confirmation)) already carry a check, and need one
    /// reply fewer. The retry budget grows to `(retries + 1) × confirm_reads` attempts. A
    /// moving shaft may read differently each time; such a read then fails with
    /// [`WckError::Unconfirmed`].
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
    /// empty ID costs only its reply waits (see [`WckBus::scan`]). Opening a bus waits
    /// out [`DEFAULT_LATE_WINDOW`] once, for the late replies of a program that used the
    /// port before (see [`WckBus::new`]).
    pub late_window: Duration,
    /// How long the line must stay quiet after a complete reply before the reply is
    /// credited. A wCK reply carries no ID and no checksum, so a byte that follows it
    /// within this time (a byte the link duplicated, a second module at the same ID) means
    /// the bytes received are not one module's one answer: the attempt fails with
    /// [`WckError::Unattributable`] (it is never "the first two bytes win"), the late
    /// window is waited out and the command is asked again.
    ///
    /// `None` (the default): [`reply_guard`] at the bus's baud rate, one byte time plus the
    /// modules' [`TURNAROUND_SPREAD`] (89.8 µs at 115200 bit/s, 13.9 µs at 921600):
    /// whatever can change the reply's two bytes comes within it. A byte that comes later
    /// (a module answering twice, noise) is caught by the next transaction: it arrives
    /// before any module can have answered that command, which fails that attempt and
    /// only it (see [`reply_guard`]). `Some(d)` waits `d` instead (a USB adapter that may
    /// deliver the bytes of one answer in two transfers needs its latency timer).
    ///
    /// `Some(Duration::ZERO)` turns the check off: a reply is credited as soon as its last
    /// byte is read (bytes read with it still fail it), so a byte the link duplicates
    /// within the reply (`a a b`) is credited as the reply `a a`, a wrong value, and a
    /// second module at the same ID goes unnoticed (its overlapping answer may read as a
    /// plausible, wrong value); its extra bytes then only fail the next command's attempt.
    /// Only for a bus whose modules are known to answer alone over a link that does not
    /// duplicate bytes.
    pub guard: Option<Duration>,
    /// The earliest a module begins to answer after a command's last byte; bytes that
    /// come sooner cannot be its reply (see [`robobus_wck::timing::earliest_reply`]).
    /// `None` (the default): the manual's turnaround for the command (1006.6 µs, 121 ms
    /// for EEPROM writes). Set it lower only for modules that answer faster, such as a
    /// simulator without processing time.
    pub min_turnaround: Option<Duration>,
    /// How replies are waited for: in the kernel ([`WaitMode::Sleep`], the default), or
    /// polling from shortly before the earliest instant a reply can arrive until it comes
    /// or its deadline passes ([`WaitMode::Spin`]: no thread wake-up on the reply's path,
    /// one core busy while a reply is due). Replies are credited the same way in both.
    pub wait: WaitMode,
}

impl Default for WckConfig {
    fn default() -> Self {
        Self {
            retries: 3,
            margin: DEFAULT_MARGIN,
            confirm_reads: 0,
            settle: DEFAULT_SETTLE,
            late_window: DEFAULT_LATE_WINDOW,
            guard: None,
            min_turnaround: None,
            wait: WaitMode::Sleep,
        }
    }
}

impl WckConfig {
    /// The quiet time [`WckConfig::guard`] asks for after a reply at `baud`:
    /// [`reply_guard`] unless set.
    pub fn guard_at(&self, baud: BaudRate) -> Duration {
        self.guard.unwrap_or_else(|| reply_guard(baud))
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
    /// Bytes received outside any reply and dropped: left on the line before a packet was
    /// sent (a late reply to an earlier request, or to a previous program on the same
    /// port), or arriving while a late window was waited out or the line settled.
    pub dropped: u64,
}

/// A wCK bus: one UART line with up to 31 modules (IDs 0..=30; up to 254 with the
/// 10-bit commands), owned through its byte link.
///
/// Device handles borrow it: [`WckBus::servo`] gives a [`Servo`](super::Servo) with a typed method per
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

/// Added to the reply margin when [`WckBus::open`] opens a TCP address
/// (`socket://HOST:PORT`): whatever answers there is a process, as behind a pty
/// ([`PTY_MARGIN`]), and a local network adds well under a millisecond. A link over a
/// slower network needs a larger [`WckConfig::margin`].
pub const TCP_MARGIN: Duration = PTY_MARGIN;

/// The link [`WckBus::open`] opens: whatever the port address names (a serial port, a
/// pty, a TCP connection), named by it.
pub struct PortLink {
    link: Box<dyn ByteLink + Send>,
    port: PortSpec,
}

impl PortLink {
    /// Opens `port` at `baud` (see [`PortSpec::open`]).
    ///
    /// # Errors
    /// What [`PortSpec::open`] reports.
    pub fn open(port: &PortSpec, baud: u32) -> Result<Self, LinkError> {
        Ok(Self {
            link: port.open(baud)?,
            port: port.clone(),
        })
    }

    /// The address it was opened by.
    pub const fn port(&self) -> &PortSpec {
        &self.port
    }
}

impl core::fmt::Debug for PortLink {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("PortLink")
            .field("port", &self.port)
            .finish_non_exhaustive()
    }
}

impl ByteLink for PortLink {
    fn write_all(&mut self, bytes: &[u8]) -> Result<(), LinkError> {
        self.link.write_all(bytes)
    }
    fn read_some(&mut self, buf: &mut [u8], deadline: Instant) -> Result<usize, LinkError> {
        self.link.read_some(buf, deadline)
    }
    fn read_exact(&mut self, buf: &mut [u8], deadline: Instant) -> Result<(), LinkError> {
        self.link.read_exact(buf, deadline)
    }
    fn discard_input(&mut self) -> Result<(), LinkError> {
        self.link.discard_input()
    }
    robobus_link::forward_byte_link_rate_and_clock!(link);
}

impl WckBus<PortLink> {
    /// Opens the port `port` names at `baud`: a serial device (a USB adapter, the pty of
    /// the simulator `robobus sim wck`), a Windows COM port (`COM12`), or a simulator
    /// over TCP (`socket://127.0.0.1:5600`); see [`PortSpec`].
    ///
    /// If the port is a USB-serial adapter whose latency timer can be read (FTDI on
    /// Linux), the timer is added to the reply margin: such an adapter holds short
    /// replies that long (16 ms by default). If it is a pseudo-terminal (the simulator),
    /// [`PTY_MARGIN`] is added instead; over TCP, [`TCP_MARGIN`].
    ///
    /// # Errors
    /// [`WckError::Link`] naming the port: an address that does not parse
    /// ([`LinkError::BadPort`], nothing opened), or what opening it reports.
    pub fn open(port: impl AsRef<Path>, baud: BaudRate) -> Result<Self, WckError> {
        let port = port.as_ref();
        let spec = PortSpec::from_os(port.as_os_str()).map_err(|e| WckError::Link {
            device: port.display().to_string(),
            command: "open",
            source: e.into(),
        })?;
        Self::open_port(&spec, baud)
    }

    /// [`WckBus::open`] with the address parsed.
    ///
    /// # Errors
    /// [`WckError::Link`] naming the port.
    pub fn open_port(port: &PortSpec, baud: BaudRate) -> Result<Self, WckError> {
        let device = port.to_string();
        let link =
            PortLink::open(port, baud.bits_per_second()).map_err(|source| WckError::Link {
                device: device.clone(),
                command: "open",
                source,
            })?;
        let mut bus = Self::new(link, baud)?.with_device_name(device);
        bus.config.margin += port_margin(port);
        Ok(bus)
    }
}

/// What a port adds to the reply margin: an adapter's latency timer, [`PTY_MARGIN`] for
/// a pty, [`TCP_MARGIN`] for TCP.
fn port_margin(port: &PortSpec) -> Duration {
    match port {
        PortSpec::Tcp { .. } => TCP_MARGIN,
        PortSpec::Device(path) if is_pty(path) => PTY_MARGIN,
        PortSpec::Device(path) => latency_timer(path),
        PortSpec::Com(_) => Duration::ZERO,
    }
}

#[cfg(unix)]
fn latency_timer(path: &Path) -> Duration {
    Duration::from_millis(u64::from(
        robobus_link::usb_latency_timer(path).unwrap_or(0),
    ))
}

#[cfg(not(unix))]
const fn latency_timer(_path: &Path) -> Duration {
    Duration::ZERO
}

/// Whether `path` is a pseudo-terminal's slave: on Linux a character device with a Unix
/// 98 pty major number (136..=143); on macOS `/dev/ttysNNN` (symlinks resolved); on
/// other Unix systems a device under `/dev/pts/`.
#[cfg(target_os = "linux")]
fn is_pty(path: &Path) -> bool {
    use std::os::unix::fs::{FileTypeExt as _, MetadataExt as _};
    std::fs::metadata(path).is_ok_and(|m| {
        let rdev = m.rdev();
        let major = ((rdev >> 8) & 0xfff) | ((rdev >> 32) & !0xfff);
        m.file_type().is_char_device() && (136..=143).contains(&major)
    })
}

#[cfg(all(unix, not(target_os = "linux")))]
fn is_pty(path: &Path) -> bool {
    use std::os::unix::fs::FileTypeExt as _;
    let Ok(real) = std::fs::canonicalize(path) else {
        return false;
    };
    let is_char = std::fs::metadata(&real).is_ok_and(|m| m.file_type().is_char_device());
    let macos_slave = real
        .strip_prefix("/dev")
        .ok()
        .and_then(|p| p.to_str())
        .and_then(|name| name.strip_prefix("ttys"))
        .is_some_and(|n| !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()));
    is_char && (macos_slave || real.starts_with("/dev/pts/"))
}

#[cfg(not(unix))]
const fn is_pty(_path: &Path) -> bool {
    false
}

impl<L: ByteLink> WckBus<L> {
    /// A bus over any byte link (a pty, a fault-injecting wrapper, an in-memory pair),
    /// switched to `baud`. Input already waiting is drained until the line has been quiet
    /// for [`WckConfig::settle`] (2 ms), then for a late window ([`DEFAULT_LATE_WINDOW`],
    /// 50 ms), dropping what arrives: a late reply to a program that used the port before
    /// is nobody's (a reply that program waited for may arrive up to a late window after
    /// its last deadline, which was before this bus was made). The bytes dropped are
    /// counted ([`WckStats::dropped`]). Errors name the device as `wCK bus` until
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
        // still trickling in) is nobody's reply; one still on its way may come up to a
        // late window after that process's last deadline, which was before now.
        bus.settle();
        bus.quiet_until = Some(bus.link.now() + DEFAULT_LATE_WINDOW);
        bus.drain_late();
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
    /// [`Servo::set_baud`](super::Servo::set_baud).
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
    /// [`Servo::set_id`](super::Servo::set_id), [`Servo::set_baud`](super::Servo::set_baud)
    /// and [`Servo::upload_program`](super::Servo::upload_program) describe.
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
}
