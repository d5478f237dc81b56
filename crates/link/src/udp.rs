//! A virtual CAN FD bus over IPv4 UDP multicast that speaks python-can's `udp_multicast`
//! wire format byte for byte (see [`crate::pycan`]), so python-can scripts,
//! `python -m can.viewer` and `python -m can.logger` can join the same bus.
//!
//! Sockets stay on the loopback interface: `IP_MULTICAST_IF = 127.0.0.1`,
//! `IP_MULTICAST_LOOP = 1`, TTL 1, and the group is joined on 127.0.0.1, so nothing leaves
//! the machine. python-can itself sets its sockets up without an interface address; to mix
//! with python-can peers, run both inside a private network namespace with
//! `ip link set lo up; ip route add 224.0.0.0/4 dev lo` (this crate's tests do exactly that).
//!
//! A sender receives its own datagrams back (multicast loop); [`UdpBus`] drops them by
//! remembering the exact bytes of its recent datagrams. Timestamps are float64 seconds and
//! strictly increasing per endpoint, so another endpoint's datagram is never byte-identical
//! to one of ours in practice; and since each remembered datagram cancels only one echo, a
//! byte-identical foreign datagram would still be delivered.
//!
//! # On each system
//!
//! Waits end at their exact deadline. On Unix the non-blocking socket is waited on with
//! `ppoll` (nanoseconds; macOS: `poll` in whole milliseconds, then a poll without blocking
//! for the rest, see [`crate::pty`]). Windows has neither: there the socket blocks in a
//! peek with a read timeout (`SO_RCVTIMEO`, whole milliseconds) until [`WINDOWS_FINE_WAIT`]
//! before the deadline, since the system timer may end it late by up to a tick, and the
//! rest is polled without blocking in short sleeps. Windows refuses to bind a socket to a
//! multicast address, so the socket binds `0.0.0.0:PORT` there, and buses on other groups
//! that share the port stay apart because Windows delivers a socket only the groups it
//! joined (not under wine, which hands the socket to Linux: there give each bus its own
//! port).

use std::collections::VecDeque;
use std::io;
use std::net::{Ipv4Addr, SocketAddrV4, UdpSocket};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use robobus_whj::frame::CanFrame;
use socket2::{Domain, Protocol, Socket, Type};

use crate::frame_link::{FrameLink, FrameLinkError, IdFilter, Received, passes};
use crate::pycan;

/// How long a send may wait for room in the socket buffer before it fails.
const SEND_TIMEOUT: Duration = Duration::from_secs(1);
/// Windows: the last stretch of a wait that is polled instead of waited in the kernel (a
/// read timeout may end up to a system timer tick, 15.6 ms by default, late).
pub const WINDOWS_FINE_WAIT: Duration = Duration::from_millis(16);
/// Windows: the sleep between two polls of the last stretch.
#[cfg(windows)]
const WINDOWS_POLL_SLEEP: Duration = Duration::from_micros(200);

/// python-can's default IPv4 group.
pub const DEFAULT_GROUP: Ipv4Addr = Ipv4Addr::new(239, 74, 163, 2);
/// python-can's default port.
pub const DEFAULT_PORT: u16 = 43113;
/// How many of our own datagrams are remembered for echo filtering.
const ECHO_MEMORY: usize = 1024;
/// Datagrams `recv` skips (echoes, filtered, malformed) before it checks its deadline.
const SKIP_BEFORE_DEADLINE_CHECK: u32 = 64;
/// Malformed datagrams logged one by one (at WARN) before the rest are only counted.
const MALFORMED_LOGGED: u64 = 5;
/// After the first [`MALFORMED_LOGGED`], at most one summary line per this interval.
const MALFORMED_SUMMARY_EVERY: Duration = Duration::from_secs(1);

/// Where a [`UdpBus`] lives.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct UdpBusConfig {
    /// Multicast group (default 239.74.163.2, python-can's).
    pub group: Ipv4Addr,
    /// UDP port (default 43113, python-can's).
    pub port: u16,
    /// Interface address for sending and joining (default 127.0.0.1: loopback only).
    pub interface: Ipv4Addr,
    /// Multicast TTL (default 1: never routed).
    pub ttl: u32,
}

impl Default for UdpBusConfig {
    fn default() -> Self {
        Self {
            group: DEFAULT_GROUP,
            port: DEFAULT_PORT,
            interface: Ipv4Addr::LOCALHOST,
            ttl: 1,
        }
    }
}

/// Counters of what [`UdpBus`] dropped while receiving.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct UdpBusStats {
    /// Our own datagrams that came back and were dropped.
    pub echoes: u64,
    /// Datagrams that were not valid python-can messages (skipped; the first few logged
    /// one by one, then one summary line per second at most).
    pub malformed: u64,
    /// Valid python-can messages a [`CanFrame`] cannot carry (remote / error frames).
    pub unsupported: u64,
    /// Frames dropped by the acceptance filters.
    pub filtered: u64,
}

/// An endpoint on the python-can compatible UDP multicast bus.
///
/// ```no_run
/// use std::time::{Duration, Instant};
/// use robobus_link::{FrameLink, UdpBus, UdpBusConfig};
/// use robobus_whj::CanFrame;
///
/// let mut bus = UdpBus::open(&UdpBusConfig::default())?;
/// bus.send(&CanFrame::new_fd(CanFrame::standard_id(0x07)?, &[1, 2, 3, 4])?)?;
/// let reply = bus.recv(Instant::now() + Duration::from_millis(50));
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Debug)]
pub struct UdpBus {
    socket: UdpSocket,
    dest: SocketAddrV4,
    sent: VecDeque<Vec<u8>>,
    last_timestamp: f64,
    filters: Vec<IdFilter>,
    stats: UdpBusStats,
    /// Malformed datagrams not logged yet, and when the last line about them was.
    malformed_unlogged: u64,
    malformed_logged_at: Option<Instant>,
}

impl UdpBus {
    /// Joins the bus described by `config`.
    pub fn open(config: &UdpBusConfig) -> Result<Self, FrameLinkError> {
        let ctx = |what: &str| format!("UDP bus {}:{}: {what}", config.group, config.port);
        if !config.group.is_multicast() {
            return Err(FrameLinkError::io(
                ctx("opening"),
                io::Error::new(
                    io::ErrorKind::InvalidInput,
                    format!("{} is not a multicast address (224.0.0.0/4)", config.group),
                ),
            ));
        }
        // Bound to the group address: only this group's datagrams arrive, so buses on
        // other groups sharing the port stay separate. Windows refuses to bind a multicast
        // address: there the socket binds 0.0.0.0, and Windows delivers a socket only the
        // groups it joined itself.
        let mut socket = multicast_socket(config, config.group);
        if cfg!(windows)
            && socket
                .as_ref()
                .is_err_and(|(_, e)| e.kind() == io::ErrorKind::AddrNotAvailable)
        {
            socket = multicast_socket(config, Ipv4Addr::UNSPECIFIED);
        }
        let socket = socket.map_err(|(what, e)| {
            let what = if what == "creating socket" {
                what.to_owned()
            } else {
                format!(
                    "setting up multicast on interface {} (is the loopback interface up?)",
                    config.interface
                )
            };
            FrameLinkError::io(ctx(&what), e)
        })?;
        // Best effort: a larger receive buffer rides out a stalled process without
        // dropping datagrams (at 1 kHz a 200 ms stall queues 200 frames, and each small
        // datagram costs about 1 KiB of buffer). The kernel caps it at
        // net.core.rmem_max (208 KiB by default).
        let _ = socket.set_recv_buffer_size(4 << 20);
        // Non-blocking: `recv` waits with `ppoll` (exact deadlines) instead of
        // `SO_RCVTIMEO`, which the kernel rounds up to its tick (4 ms at HZ=250).
        socket
            .set_nonblocking(true)
            .map_err(|e| FrameLinkError::io(ctx("setting non-blocking mode"), e))?;
        Ok(Self {
            socket: socket.into(),
            dest: SocketAddrV4::new(config.group, config.port),
            sent: VecDeque::with_capacity(ECHO_MEMORY),
            last_timestamp: 0.0,
            filters: Vec::new(),
            stats: UdpBusStats::default(),
            malformed_unlogged: 0,
            malformed_logged_at: None,
        })
    }

    /// Counts a malformed datagram and logs it, rate-limited: the first
    /// [`MALFORMED_LOGGED`] one by one, then one summary per [`MALFORMED_SUMMARY_EVERY`],
    /// so a flood cannot flood the log.
    fn note_malformed(&mut self, error: &pycan::DecodeError, len: usize) {
        self.stats.malformed += 1;
        let now = Instant::now();
        if self.stats.malformed <= MALFORMED_LOGGED {
            tracing::warn!(bus = %self.dest, error = %error, len, "skipping malformed datagram");
            if self.stats.malformed == MALFORMED_LOGGED {
                tracing::warn!(
                    bus = %self.dest,
                    "further malformed datagrams are counted and summarised at most once per second"
                );
            }
            self.malformed_logged_at = Some(now);
            return;
        }
        self.malformed_unlogged += 1;
        let due = self
            .malformed_logged_at
            .is_none_or(|t| now.duration_since(t) >= MALFORMED_SUMMARY_EVERY);
        if due {
            self.log_malformed_summary(Some(error));
            self.malformed_logged_at = Some(now);
        }
    }

    fn log_malformed_summary(&mut self, last: Option<&pycan::DecodeError>) {
        if self.malformed_unlogged == 0 {
            return;
        }
        let last = last.map(ToString::to_string).unwrap_or_default();
        tracing::warn!(
            bus = %self.dest,
            skipped = self.malformed_unlogged,
            total = self.stats.malformed,
            last_error = %last,
            "skipped more malformed datagrams"
        );
        self.malformed_unlogged = 0;
    }

    /// What was dropped so far.
    pub const fn stats(&self) -> UdpBusStats {
        self.stats
    }

    /// Sends `frame` and returns the exact datagram that went out.
    pub fn send_datagram(&mut self, frame: &CanFrame) -> Result<Vec<u8>, FrameLinkError> {
        let now = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map_or(0.0, |d| d.as_secs_f64());
        // Strictly increasing timestamps keep every datagram of ours distinct.
        let ts = if now > self.last_timestamp {
            now
        } else {
            self.last_timestamp.next_up()
        };
        self.last_timestamp = ts;
        let datagram = pycan::encode(frame, ts);
        if self.sent.len() == ECHO_MEMORY {
            self.sent.pop_front();
        }
        self.sent.push_back(datagram.clone());
        let deadline = Instant::now() + SEND_TIMEOUT;
        loop {
            match self.socket.send_to(&datagram, self.dest) {
                Ok(_) => return Ok(datagram),
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => {
                    let writable = wait_writable(&self.socket, deadline)
                        .map_err(|e| self.io_error("waiting to send on", e))?;
                    if !writable {
                        return Err(self.io_error("sending to", e));
                    }
                }
                Err(e) => return Err(self.io_error("sending to", e)),
            }
        }
    }

    fn io_error(&self, what: &str, e: io::Error) -> FrameLinkError {
        FrameLinkError::io(format!("{what} UDP bus {}", self.dest), e)
    }

    /// Waits until a datagram can be read or `deadline` passes; returns whether one can.
    fn wait_readable(&self, deadline: Instant) -> Result<bool, FrameLinkError> {
        if Instant::now() >= deadline {
            return Ok(false);
        }
        wait_readable(&self.socket, deadline).map_err(|e| self.io_error("waiting on", e))
    }

    /// Removes `datagram` from the echo memory if it is one of ours.
    fn is_own_echo(&mut self, datagram: &[u8]) -> bool {
        if let Some(i) = self.sent.iter().position(|d| d.as_slice() == datagram) {
            self.sent.remove(i);
            true
        } else {
            false
        }
    }
}

/// A UDP socket bound to `bind_to`:`config.port` that has joined `config.group` on
/// `config.interface`; an error says which step failed (`creating socket` or the set-up).
fn multicast_socket(
    config: &UdpBusConfig,
    bind_to: Ipv4Addr,
) -> Result<Socket, (&'static str, io::Error)> {
    let socket = Socket::new(Domain::IPV4, Type::DGRAM, Some(Protocol::UDP))
        .map_err(|e| ("creating socket", e))?;
    let setup = || -> io::Result<()> {
        socket.set_reuse_address(true)?;
        #[cfg(unix)]
        socket.set_reuse_port(true)?;
        socket.bind(&SocketAddrV4::new(bind_to, config.port).into())?;
        socket.set_multicast_if_v4(&config.interface)?;
        socket.set_multicast_loop_v4(true)?;
        socket.set_multicast_ttl_v4(config.ttl)?;
        socket.join_multicast_v4(&config.group, &config.interface)?;
        Ok(())
    };
    setup().map_err(|e| ("setting up multicast", e))?;
    Ok(socket)
}

/// Waits until `socket` can send or `deadline` passes; returns whether it can.
#[cfg(unix)]
fn wait_writable(socket: &UdpSocket, deadline: Instant) -> io::Result<bool> {
    crate::pty::wait_for(socket, nix::poll::PollFlags::POLLOUT, deadline)
}

/// Waits until `socket` has a datagram or `deadline` passes; returns whether it has.
#[cfg(unix)]
fn wait_readable(socket: &UdpSocket, deadline: Instant) -> io::Result<bool> {
    crate::pty::wait_readable(socket, deadline)
}

/// Waits until `socket` can send or `deadline` passes (Windows: a full send buffer is rare
/// on UDP; it is retried in short sleeps).
#[cfg(windows)]
#[expect(
    clippy::unnecessary_wraps,
    reason = "the same signature as the Unix wait, which can fail"
)]
fn wait_writable(_socket: &UdpSocket, deadline: Instant) -> io::Result<bool> {
    let remaining = deadline.saturating_duration_since(Instant::now());
    std::thread::sleep(remaining.min(WINDOWS_POLL_SLEEP));
    Ok(Instant::now() < deadline)
}

/// Waits until `socket` has a datagram or `deadline` passes (Windows; see the [module
/// notes](self)): blocks in a peek with a read timeout until [`WINDOWS_FINE_WAIT`] before
/// the deadline, then peeks without blocking in short sleeps until the deadline.
#[cfg(windows)]
fn wait_readable(socket: &UdpSocket, deadline: Instant) -> io::Result<bool> {
    /// `WSAEMSGSIZE`: a datagram larger than the peek's buffer is there.
    const MSG_SIZE: i32 = 10040;
    let mut buf = [0u8; 2048];
    loop {
        let remaining = deadline.saturating_duration_since(Instant::now());
        let coarse = remaining.saturating_sub(WINDOWS_FINE_WAIT);
        // Whole milliseconds, at least one: a zero SO_RCVTIMEO would wait forever.
        let blocking = coarse >= Duration::from_millis(1);
        if blocking {
            socket.set_nonblocking(false)?;
            socket.set_read_timeout(Some(Duration::from_millis(
                u64::try_from(coarse.as_millis()).unwrap_or(u64::MAX),
            )))?;
        }
        let peeked = socket.peek(&mut buf);
        if blocking {
            socket.set_nonblocking(true)?;
        }
        match peeked {
            Ok(_) => return Ok(true),
            Err(e) if e.raw_os_error() == Some(MSG_SIZE) => return Ok(true),
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::WouldBlock
                        | io::ErrorKind::TimedOut
                        | io::ErrorKind::Interrupted
                ) => {}
            Err(e) => return Err(e),
        }
        if remaining.is_zero() {
            return Ok(false);
        }
        if !blocking {
            std::thread::sleep(remaining.min(WINDOWS_POLL_SLEEP));
        }
    }
}

impl Drop for UdpBus {
    fn drop(&mut self) {
        self.log_malformed_summary(None);
    }
}

impl FrameLink for UdpBus {
    fn send(&mut self, frame: &CanFrame) -> Result<(), FrameLinkError> {
        self.send_datagram(frame).map(drop)
    }

    fn recv(&mut self, deadline: Instant) -> Result<Received, FrameLinkError> {
        let mut buf = [0u8; 2048];
        let mut skipped = 0u32;
        loop {
            let n = match self.socket.recv(&mut buf) {
                Ok(n) => n,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                Err(e)
                    if matches!(
                        e.kind(),
                        io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut
                    ) =>
                {
                    if !self.wait_readable(deadline)? {
                        return Err(FrameLinkError::Timeout);
                    }
                    continue;
                }
                Err(e) => return Err(self.io_error("receiving from", e)),
            };
            let timestamp = Some(SystemTime::now());
            let datagram = buf.get(..n).unwrap_or_default();
            if self.is_own_echo(datagram) {
                self.stats.echoes += 1;
                // Our own frame comes back first and an answer to it only later: wait for
                // it instead of finding the socket empty first (one call less per reply).
                if Instant::now() < deadline && !self.wait_readable(deadline)? {
                    return Err(FrameLinkError::Timeout);
                }
                continue;
            }
            match pycan::decode_frame(datagram) {
                Ok((frame, _)) => {
                    if passes(&self.filters, &frame) {
                        return Ok(Received { frame, timestamp });
                    }
                    self.stats.filtered += 1;
                }
                Err(e @ pycan::DecodeError::NotADataFrame { .. }) => {
                    self.stats.unsupported += 1;
                    tracing::debug!(bus = %self.dest, error = %e, "skipping datagram");
                }
                Err(e) => self.note_malformed(&e, n),
            }
            // A stream of datagrams we skip must not hold a caller past its deadline (a
            // few are still looked through, so a deadline in the past finds a frame
            // queued behind an echo).
            skipped += 1;
            if skipped >= SKIP_BEFORE_DEADLINE_CHECK && Instant::now() >= deadline {
                return Err(FrameLinkError::Timeout);
            }
        }
    }

    /// 0.2 ms: every frame is a datagram that its sender's process writes when its
    /// thread runs, and the host's network stack delivers to each member's socket.
    fn reply_allowance(&self) -> Duration {
        Duration::from_micros(200)
    }

    fn set_filters(&mut self, filters: &[IdFilter]) -> Result<(), FrameLinkError> {
        self.filters = filters.to_vec();
        Ok(())
    }
}
