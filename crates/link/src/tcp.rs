//! Byte links over TCP: pyserial's `socket://HOST:PORT`, for simulators on systems
//! without pseudo-terminals (and serial servers).
//!
//! - [`TcpByteLink`] is the client: it connects with a timeout, turns Nagle's algorithm
//!   off (`TCP_NODELAY`: a 4-byte wCK command leaves at once), and ends every read at its
//!   deadline as the pty link does (`ppoll` on Linux, `poll` on other Unix systems, the
//!   socket's read timeout elsewhere). A TCP stream has no line rate: [`ByteLink::set_baud`]
//!   records the rate and changes nothing (the server's own rate applies: a simulator's
//!   `--baud`). A closed connection is [`LinkError::Closed`].
//! - [`TcpServer`] is the side a simulator serves: a listener (on 127.0.0.1 unless told
//!   otherwise) that serves one client at a time, as one serial port has one program
//!   using it. When the client disconnects, the next connection is accepted, as a port
//!   that is closed and opened again. A connection that comes while a client is served is
//!   accepted and closed at once (the newcomer's first read finds the link closed), so
//!   at most one connection is ever held and none waits in a queue. Reply bytes written
//!   while no client is connected are dropped, as on a line nobody listens to.

use std::io::{self, Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream, ToSocketAddrs};
use std::time::{Duration, Instant};

use crate::byte::{ByteLink, LinkError};
use crate::port::PortSpec;

/// How long a write may wait for the peer to take the bytes before it fails (client) or
/// the peer is dropped (server).
pub const WRITE_TIMEOUT: Duration = Duration::from_secs(2);

/// How many bytes one drain of the input reads at most.
const MAX_DISCARD: usize = 64 * 1024;

/// The rate a link records until told otherwise (wCK's factory rate).
const DEFAULT_BAUD: u32 = 115_200;

/// Whether an I/O error means the connection is gone.
fn is_disconnect(e: &io::Error) -> bool {
    matches!(
        e.kind(),
        io::ErrorKind::ConnectionReset
            | io::ErrorKind::ConnectionAborted
            | io::ErrorKind::BrokenPipe
            | io::ErrorKind::UnexpectedEof
            | io::ErrorKind::NotConnected
    )
}

#[cfg(unix)]
mod wait {
    //! Waiting on descriptors until a deadline: `ppoll` (nanoseconds) on Linux, `poll`
    //! (whole milliseconds, rounded up) on other Unix systems.
    use std::io;
    use std::time::Instant;

    use nix::errno::Errno;
    use nix::poll::PollFd;

    /// Waits until one of `fds` has its events or `deadline` passes; `Ok(false)` on
    /// timeout. The revents of `fds` say which.
    pub(super) fn until(fds: &mut [PollFd<'_>], deadline: Instant) -> io::Result<bool> {
        loop {
            let remaining = deadline.saturating_duration_since(Instant::now());
            #[cfg(any(target_os = "linux", target_os = "android"))]
            let r = nix::poll::ppoll(
                fds,
                Some(nix::sys::time::TimeSpec::from_duration(remaining)),
                None,
            );
            #[cfg(not(any(target_os = "linux", target_os = "android")))]
            let r = {
                let ms = remaining.as_nanos().div_ceil(1_000_000);
                let timeout =
                    nix::poll::PollTimeout::try_from(ms).unwrap_or(nix::poll::PollTimeout::MAX);
                nix::poll::poll(fds, timeout)
            };
            match r {
                Ok(0) if Instant::now() >= deadline => return Ok(false),
                Ok(0) | Err(Errno::EINTR) => {}
                Ok(_) => return Ok(true),
                Err(e) => return Err(io::Error::from_raw_os_error(e as i32)),
            }
        }
    }
}

/// Reads what is there into `buf` before `deadline`: `Ok(None)` when nothing came in
/// time, `Ok(Some(0))` at end of stream.
#[cfg(unix)]
fn read_until(
    stream: &mut TcpStream,
    buf: &mut [u8],
    deadline: Instant,
) -> io::Result<Option<usize>> {
    use nix::poll::{PollFd, PollFlags};
    loop {
        match stream.read(buf) {
            Ok(n) => return Ok(Some(n)),
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => {
                let mut fds = [PollFd::new(
                    std::os::fd::AsFd::as_fd(stream),
                    PollFlags::POLLIN,
                )];
                if !wait::until(&mut fds, deadline)? {
                    return Ok(None);
                }
            }
            Err(e) => return Err(e),
        }
    }
}

/// Reads what is there into `buf` before `deadline` (the socket blocks, with a read
/// timeout): `Ok(None)` when nothing came in time, `Ok(Some(0))` at end of stream.
#[cfg(not(unix))]
fn read_until(
    stream: &mut TcpStream,
    buf: &mut [u8],
    deadline: Instant,
) -> io::Result<Option<usize>> {
    loop {
        let remaining = deadline.saturating_duration_since(Instant::now());
        let r = if remaining.is_zero() {
            stream.set_nonblocking(true)?;
            let r = stream.read(buf);
            stream.set_nonblocking(false)?;
            r
        } else {
            stream.set_read_timeout(Some(remaining))?;
            stream.read(buf)
        };
        match r {
            Ok(n) => return Ok(Some(n)),
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut
                ) =>
            {
                if Instant::now() >= deadline {
                    return Ok(None);
                }
            }
            Err(e) => return Err(e),
        }
    }
}

/// Writes all of `bytes` within [`WRITE_TIMEOUT`]: `Ok(Err(written))` on timeout.
fn write_within(stream: &mut TcpStream, bytes: &[u8]) -> io::Result<Result<(), usize>> {
    let deadline = Instant::now() + WRITE_TIMEOUT;
    let mut written = 0;
    while let Some(rest) = bytes.get(written..).filter(|r| !r.is_empty()) {
        match stream.write(rest) {
            Ok(0) => return Err(io::ErrorKind::WriteZero.into()),
            Ok(n) => written += n,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut
                ) =>
            {
                if !wait_writable(stream, deadline)? {
                    return Ok(Err(written));
                }
            }
            Err(e) => return Err(e),
        }
    }
    Ok(Ok(()))
}

#[cfg(unix)]
fn wait_writable(stream: &TcpStream, deadline: Instant) -> io::Result<bool> {
    use nix::poll::{PollFd, PollFlags};
    let mut fds = [PollFd::new(
        std::os::fd::AsFd::as_fd(stream),
        PollFlags::POLLOUT,
    )];
    wait::until(&mut fds, deadline)
}

/// The socket blocks with a write timeout: a timed-out write is the end of the wait.
#[cfg(not(unix))]
#[allow(clippy::unnecessary_wraps)] // the signature of the Unix version, which polls
fn wait_writable(_stream: &TcpStream, deadline: Instant) -> io::Result<bool> {
    Ok(Instant::now() < deadline)
}

/// Drops what has arrived and not been read (at most [`MAX_DISCARD`] bytes); `Ok(false)`
/// when the stream has ended.
fn drain(stream: &mut TcpStream) -> io::Result<bool> {
    #[cfg(not(unix))]
    stream.set_nonblocking(true)?;
    let mut scratch = [0u8; 512];
    let mut dropped = 0;
    let mut open = true;
    while dropped < MAX_DISCARD {
        match stream.read(&mut scratch) {
            Ok(0) => {
                open = false;
                break;
            }
            Ok(n) => dropped += n,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => break,
            Err(e) => {
                #[cfg(not(unix))]
                let _ = stream.set_nonblocking(false);
                return Err(e);
            }
        }
    }
    #[cfg(not(unix))]
    stream.set_nonblocking(false)?;
    Ok(open)
}

/// Whether a connection is still open: a peek finds data or nothing yet, not its end.
fn alive(stream: &TcpStream) -> bool {
    #[cfg(not(unix))]
    if stream.set_nonblocking(true).is_err() {
        return false;
    }
    let open = match stream.peek(&mut [0u8; 1]) {
        Ok(n) => n > 0,
        Err(e) => e.kind() == io::ErrorKind::WouldBlock,
    };
    #[cfg(not(unix))]
    let _ = stream.set_nonblocking(false);
    open
}

/// Sets a connected stream up: no Nagle delay; non-blocking on Unix (reads wait in
/// `poll`), blocking with a write timeout elsewhere.
fn prepare(stream: &TcpStream) -> io::Result<()> {
    stream.set_nodelay(true)?;
    #[cfg(unix)]
    stream.set_nonblocking(true)?;
    #[cfg(not(unix))]
    {
        stream.set_nonblocking(false)?;
        stream.set_write_timeout(Some(WRITE_TIMEOUT))?;
    }
    Ok(())
}

/// The client side of a TCP byte link (`socket://HOST:PORT`). See the [module notes](self).
#[derive(Debug)]
pub struct TcpByteLink {
    stream: TcpStream,
    address: String,
    baud: u32,
}

impl TcpByteLink {
    /// Connects to `host:port`, trying each address the host resolves to for at most
    /// `timeout`. (A host name is resolved by the system first, which has its own
    /// timeout; an IP address is used as it is.)
    ///
    /// # Errors
    /// [`LinkError::Unreachable`] when nothing accepts the connection (refused, no route,
    /// no answer within `timeout`, a host name that does not resolve), [`LinkError::Io`]
    /// when the socket cannot be set up.
    pub fn connect(host: &str, port: u16, timeout: Duration) -> Result<Self, LinkError> {
        let address = PortSpec::Tcp {
            host: host.to_owned(),
            port,
        }
        .to_string();
        let unreachable = |reason: String| LinkError::Unreachable {
            address: address.clone(),
            reason,
        };
        let addrs: Vec<SocketAddr> = (host, port)
            .to_socket_addrs()
            .map_err(|e| unreachable(format!("the host does not resolve ({e})")))?
            .collect();
        let mut last = None;
        for addr in &addrs {
            match TcpStream::connect_timeout(addr, timeout) {
                Ok(stream) => return Self::from_stream(stream, address),
                Err(e) => last = Some(e),
            }
        }
        Err(unreachable(match last {
            Some(e) if e.kind() == io::ErrorKind::ConnectionRefused => {
                "connection refused".to_owned()
            }
            Some(e) if e.kind() == io::ErrorKind::TimedOut => {
                format!("no answer within {} ms", timeout.as_millis())
            }
            Some(e) => e.to_string(),
            None => "the host resolves to no address".to_owned(),
        }))
    }

    /// A link over a stream that is already connected; `address` names it in messages.
    ///
    /// # Errors
    /// [`LinkError::Io`] when the socket cannot be set up.
    pub fn from_stream(stream: TcpStream, address: String) -> Result<Self, LinkError> {
        prepare(&stream).map_err(|e| LinkError::io(format!("setting up {address}"), e))?;
        Ok(Self {
            stream,
            address,
            baud: DEFAULT_BAUD,
        })
    }

    /// The address as `socket://HOST:PORT`.
    pub fn address(&self) -> &str {
        &self.address
    }

    fn closed(&self, how: &str) -> LinkError {
        LinkError::Closed {
            context: format!(
                "{}: {how} (the simulator or server stopped, or it serves another client: \
                 it serves one at a time)",
                self.address
            ),
        }
    }

    fn fail(&self, what: &str, e: io::Error) -> LinkError {
        if is_disconnect(&e) {
            self.closed(&format!("connection lost ({e})"))
        } else {
            LinkError::io(format!("{what} {}", self.address), e)
        }
    }
}

impl ByteLink for TcpByteLink {
    fn write_all(&mut self, bytes: &[u8]) -> Result<(), LinkError> {
        match write_within(&mut self.stream, bytes) {
            Ok(Ok(())) => Ok(()),
            Ok(Err(written)) => Err(LinkError::WriteTimeout {
                written,
                total: bytes.len(),
            }),
            Err(e) => Err(self.fail("writing to", e)),
        }
    }

    fn read_some(&mut self, buf: &mut [u8], deadline: Instant) -> Result<usize, LinkError> {
        if buf.is_empty() {
            return Ok(0);
        }
        match read_until(&mut self.stream, buf, deadline) {
            Ok(Some(0)) => Err(self.closed("the other side closed the connection")),
            Ok(Some(n)) => Ok(n),
            Ok(None) => Err(LinkError::Timeout {
                received: 0,
                expected: buf.len(),
            }),
            Err(e) => Err(self.fail("reading from", e)),
        }
    }

    fn discard_input(&mut self) -> Result<(), LinkError> {
        match drain(&mut self.stream) {
            Ok(true) => Ok(()),
            Ok(false) => Err(self.closed("the other side closed the connection")),
            Err(e) => Err(self.fail("draining", e)),
        }
    }

    /// Records the rate: a TCP stream has no line rate (the server's applies).
    fn set_baud(&mut self, baud: u32) -> Result<(), LinkError> {
        if baud == 0 {
            return Err(LinkError::UnsupportedBaud {
                baud,
                context: self.address.clone(),
            });
        }
        self.baud = baud;
        Ok(())
    }

    fn baud(&self) -> Option<u32> {
        Some(self.baud)
    }
}

/// What a [`TcpServer`] has done.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct TcpServerStats {
    /// Connections served.
    pub accepted: u64,
    /// Connections closed at once because another client was being served.
    pub refused: u64,
    /// Served clients that went away (closed, reset, or stalled a write for
    /// [`WRITE_TIMEOUT`]).
    pub disconnects: u64,
}

/// The side a simulator serves over TCP: one client at a time. See the [module notes](self).
#[derive(Debug)]
pub struct TcpServer {
    listener: TcpListener,
    local: SocketAddr,
    client: Option<(TcpStream, SocketAddr)>,
    baud: u32,
    stats: TcpServerStats,
}

impl TcpServer {
    /// Listens on exactly `addr` (port 0 picks a free port: see
    /// [`TcpServer::local_addr`]). The rate recorded is `baud`.
    ///
    /// # Errors
    /// [`LinkError::Io`] naming the address (in use, not an address of this machine).
    pub fn bind(addr: SocketAddr, baud: u32) -> Result<Self, LinkError> {
        let io_err = |e| LinkError::io(format!("listening on {addr}"), e);
        let listener = TcpListener::bind(addr).map_err(io_err)?;
        listener.set_nonblocking(true).map_err(io_err)?;
        let local = listener.local_addr().map_err(io_err)?;
        Ok(Self {
            listener,
            local,
            client: None,
            baud,
            stats: TcpServerStats::default(),
        })
    }

    /// The address it listens on (the port chosen, if 0 was asked for).
    pub const fn local_addr(&self) -> SocketAddr {
        self.local
    }

    /// What a client names to reach it: `socket://127.0.0.1:5600`.
    pub fn port_spec(&self) -> PortSpec {
        PortSpec::tcp(self.local)
    }

    /// The client being served, if any.
    pub fn client(&self) -> Option<SocketAddr> {
        self.client.as_ref().map(|(_, a)| *a)
    }

    /// What it has done so far.
    pub const fn stats(&self) -> TcpServerStats {
        self.stats
    }

    /// Accepts what waits on the listener: the first becomes the client if there is
    /// none, every other one is closed at once.
    fn accept_pending(&mut self) -> Result<(), LinkError> {
        loop {
            match self.listener.accept() {
                Ok((stream, peer)) => {
                    if self.client.as_ref().is_some_and(|(c, _)| !alive(c)) {
                        // The client closed and the newcomer is its successor (the
                        // close had not been read yet).
                        self.drop_client("closed the connection");
                    }
                    if self.client.is_some() {
                        self.stats.refused += 1;
                        tracing::info!(%peer, "refused: a client is being served");
                        drop(stream);
                    } else if prepare(&stream).is_ok() {
                        self.stats.accepted += 1;
                        tracing::info!(%peer, "client connected");
                        self.client = Some((stream, peer));
                    }
                }
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => return Ok(()),
                Err(e)
                    if e.kind() == io::ErrorKind::Interrupted
                        || is_disconnect(&e)
                        || e.kind() == io::ErrorKind::ConnectionRefused => {}
                Err(e) => {
                    return Err(LinkError::io(format!("accepting on {}", self.local), e));
                }
            }
        }
    }

    fn drop_client(&mut self, why: &str) {
        if let Some((_, peer)) = self.client.take() {
            self.stats.disconnects += 1;
            tracing::info!(%peer, why, "client gone");
        }
    }

    /// Waits for the listener or the client until `deadline`; `Ok(false)` on timeout.
    #[cfg(unix)]
    fn wait(&self, deadline: Instant) -> io::Result<bool> {
        use nix::poll::{PollFd, PollFlags};
        use std::os::fd::AsFd as _;
        let listener = PollFd::new(self.listener.as_fd(), PollFlags::POLLIN);
        match &self.client {
            Some((stream, _)) => {
                let mut fds = [listener, PollFd::new(stream.as_fd(), PollFlags::POLLIN)];
                wait::until(&mut fds, deadline)
            }
            None => wait::until(&mut [listener], deadline),
        }
    }
}

/// How long one wait of the server lasts at most without `poll` (new connections are
/// looked at between waits).
#[cfg(not(unix))]
const SERVER_STEP: Duration = Duration::from_millis(5);

impl ByteLink for TcpServer {
    /// Writes to the client; without one the bytes are dropped. A client that is gone or
    /// takes nothing for [`WRITE_TIMEOUT`] is dropped (the next connection is served).
    fn write_all(&mut self, bytes: &[u8]) -> Result<(), LinkError> {
        let Some((stream, _)) = self.client.as_mut() else {
            return Ok(());
        };
        match write_within(stream, bytes) {
            Ok(Ok(())) => {}
            Ok(Err(_)) => self.drop_client("a write stalled"),
            Err(e) => self.drop_client(&e.to_string()),
        }
        Ok(())
    }

    /// Reads from the client, accepting one first if there is none; a client that
    /// disconnects is dropped and the wait goes on for the next.
    fn read_some(&mut self, buf: &mut [u8], deadline: Instant) -> Result<usize, LinkError> {
        if buf.is_empty() {
            return Ok(0);
        }
        let timeout = LinkError::Timeout {
            received: 0,
            expected: buf.len(),
        };
        loop {
            self.accept_pending()?;
            #[cfg(unix)]
            let result = match self.client.as_mut() {
                Some((stream, _)) => match stream.read(buf) {
                    Err(e) if e.kind() == io::ErrorKind::WouldBlock => None,
                    r => Some(r),
                },
                None => None,
            };
            #[cfg(not(unix))]
            let result = {
                let step = deadline.min(Instant::now() + SERVER_STEP);
                if let Some((stream, _)) = self.client.as_mut() {
                    read_until(stream, buf, step).transpose()
                } else {
                    std::thread::sleep(step.saturating_duration_since(Instant::now()));
                    None
                }
            };
            match result {
                Some(Ok(0)) => self.drop_client("closed the connection"),
                Some(Ok(n)) => return Ok(n),
                Some(Err(e)) if e.kind() == io::ErrorKind::Interrupted => {}
                Some(Err(e)) => self.drop_client(&e.to_string()),
                None => {
                    #[cfg(unix)]
                    let more = self
                        .wait(deadline)
                        .map_err(|e| LinkError::io(format!("waiting on {}", self.local), e))?;
                    #[cfg(not(unix))]
                    let more = Instant::now() < deadline;
                    if !more {
                        return Err(timeout);
                    }
                }
            }
        }
    }

    fn discard_input(&mut self) -> Result<(), LinkError> {
        if let Some((stream, _)) = self.client.as_mut()
            && !drain(stream).unwrap_or(false)
        {
            self.drop_client("closed the connection");
        }
        Ok(())
    }

    /// Records the rate (the simulator paces its replies itself).
    fn set_baud(&mut self, baud: u32) -> Result<(), LinkError> {
        self.baud = baud;
        Ok(())
    }

    fn baud(&self) -> Option<u32> {
        Some(self.baud)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn loopback() -> SocketAddr {
        "127.0.0.1:0".parse().unwrap()
    }

    fn soon() -> Instant {
        Instant::now() + Duration::from_secs(2)
    }

    #[test]
    fn client_and_server_exchange_bytes_and_the_spec_names_the_chosen_port() {
        let mut server = TcpServer::bind(loopback(), 115_200).unwrap();
        assert_ne!(server.local_addr().port(), 0);
        let spec = server.port_spec();
        assert_eq!(
            spec.to_string(),
            format!("socket://{}", server.local_addr())
        );
        let mut client = spec.open(57_600).unwrap();
        assert_eq!(client.baud(), Some(57_600));
        client.write_all(&[0xFF, 0x03, 0x7F, 0x7C]).unwrap();
        let mut cmd = [0u8; 4];
        server.read_exact(&mut cmd, soon()).unwrap();
        assert_eq!(cmd, [0xFF, 0x03, 0x7F, 0x7C]);
        server.write_all(&[0x12, 0x7F]).unwrap();
        let mut reply = [0u8; 2];
        client.read_exact(&mut reply, soon()).unwrap();
        assert_eq!(reply, [0x12, 0x7F]);
        assert_eq!(server.stats().accepted, 1);
    }

    #[test]
    fn a_read_ends_at_its_deadline_with_what_arrived() {
        let mut server = TcpServer::bind(loopback(), 115_200).unwrap();
        let mut client = server.port_spec().open(115_200).unwrap();
        client.write_all(&[1]).unwrap();
        let mut one = [0u8; 1];
        server.read_exact(&mut one, soon()).unwrap();
        server.write_all(&[7]).unwrap();
        let mut two = [0u8; 2];
        let deadline = Instant::now() + Duration::from_millis(30);
        let e = client.read_exact(&mut two, deadline).unwrap_err();
        assert!(
            matches!(
                e,
                LinkError::Timeout {
                    received: 1,
                    expected: 2
                }
            ),
            "{e:?}"
        );
        assert_eq!(two[0], 7);
        assert!(Instant::now() >= deadline);
    }

    #[test]
    fn a_second_client_is_closed_while_one_is_served_and_served_once_it_leaves() {
        let mut server = TcpServer::bind(loopback(), 115_200).unwrap();
        let spec = server.port_spec();
        let mut first = spec.open(115_200).unwrap();
        first.write_all(&[1]).unwrap();
        let mut b = [0u8; 1];
        server.read_exact(&mut b, soon()).unwrap();

        let mut second = spec.open(115_200).unwrap();
        // The server looks at the listener while it waits for input.
        let _ = server.read_some(&mut b, Instant::now() + Duration::from_millis(50));
        let e = second.read_some(&mut b, soon()).unwrap_err();
        assert!(matches!(e, LinkError::Closed { .. }), "{e:?}");
        assert!(e.to_string().contains("one at a time"), "{e}");
        assert_eq!(server.stats().refused, 1);

        // The first leaves; a third is served, as a port closed and opened again.
        drop(first);
        let mut third = spec.open(115_200).unwrap();
        third.write_all(&[3]).unwrap();
        server.read_exact(&mut b, soon()).unwrap();
        assert_eq!(b, [3]);
        assert_eq!(server.stats().accepted, 2);
        assert_eq!(server.stats().disconnects, 1);
        server.write_all(&[9]).unwrap();
        third.read_exact(&mut b, soon()).unwrap();
        assert_eq!(b, [9]);
    }

    #[test]
    fn a_server_that_stops_is_a_closed_link_for_the_client() {
        let server = TcpServer::bind(loopback(), 115_200).unwrap();
        let spec = server.port_spec();
        let mut client = spec.open(115_200).unwrap();
        drop(server);
        let mut b = [0u8; 1];
        let e = client.read_some(&mut b, soon()).unwrap_err();
        assert!(matches!(e, LinkError::Closed { .. }), "{e:?}");
        assert!(e.to_string().contains(&spec.to_string()), "{e}");
    }

    #[test]
    fn nothing_listening_is_unreachable_naming_the_address() {
        // A port that was free a moment ago: bind, note it, close.
        let addr = TcpListener::bind(loopback()).unwrap().local_addr().unwrap();
        let spec = PortSpec::tcp(addr);
        let Err(e) = spec.open(115_200) else {
            panic!("connected to a closed port");
        };
        assert!(matches!(e, LinkError::Unreachable { .. }), "{e:?}");
        let text = e.to_string();
        assert!(
            text.contains(&spec.to_string()) && text.contains("refused"),
            "{text}"
        );
    }

    #[test]
    fn bytes_written_without_a_client_are_dropped() {
        let mut server = TcpServer::bind(loopback(), 115_200).unwrap();
        server.write_all(&[1, 2, 3]).unwrap();
        let mut client = server.port_spec().open(115_200).unwrap();
        client.write_all(&[5]).unwrap();
        let mut b = [0u8; 1];
        server.read_exact(&mut b, soon()).unwrap();
        let e = client
            .read_some(&mut b, Instant::now() + Duration::from_millis(20))
            .unwrap_err();
        assert!(e.is_timeout(), "{e:?}");
    }
}
