//! Pseudo-terminal pairs: a simulator holds the master side, any program opens the slave
//! side by path as if it were a serial port.
//!
//! Both sides are put in raw mode (`cfmakeraw`) before anything else can touch them, so
//! no byte is ever echoed, translated or swallowed as a control character. A pty does not
//! pace bytes: the baud rate is only a termios setting, and any wire timing must come from
//! the simulator.
//!
//! A pty has no modem lines: `TIOCMGET` / `TIOCMSET` / `TIOCMBIS` / `TIOCMBIC` (DTR, RTS,
//! CTS, DSR) fail with `ENOTTY` on either side. Programs that only use termios work
//! (pyserial, which ignores `ENOTTY` when it sets DTR / RTS on open, but raises if they
//! are set or read later; minicom, picocom, screen, this crate's [`crate::SerialLink`]);
//! programs that insist on the modem lines cannot open a pty, for example .NET / mono
//! `System.IO.Ports` (`SerialPort.Open` sets DTR and RTS).
//!
//! Unix only (Linux and macOS): Windows has no pseudo-terminals, and a simulator serves
//! its bus over TCP there. Waits end at their exact deadline on both: Linux waits in
//! `ppoll` (nanoseconds); macOS has no `ppoll`, so it waits in `poll` for the whole
//! milliseconds before the deadline and polls without blocking for the rest (under one
//! millisecond). The speed constants are Linux's; macOS keeps the rate in termios as the
//! number itself, so both accept the same rates.

use std::fs::File;
use std::io::{self, Read, Write};
use std::os::fd::{AsFd, OwnedFd};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use nix::errno::Errno;
use nix::fcntl::{FcntlArg, OFlag};
use nix::poll::{PollFd, PollFlags};
#[cfg(any(target_os = "linux", target_os = "android"))]
use nix::sys::termios::BaudRate;
use nix::sys::termios::{self, SetArg, SpecialCharacterIndices};

use crate::byte::{ByteLink, LinkError};

/// A rate as termios takes it: a speed constant on Linux, the number itself on the BSDs
/// (macOS).
#[cfg(any(target_os = "linux", target_os = "android"))]
type Speed = BaudRate;
/// A rate as termios takes it: a speed constant on Linux, the number itself on the BSDs
/// (macOS).
#[cfg(not(any(target_os = "linux", target_os = "android")))]
type Speed = u32;

/// The termios speed constants robobus uses, with their baud rates.
#[cfg(any(target_os = "linux", target_os = "android"))]
const BAUD_TABLE: [(u32, BaudRate); 19] = [
    (1200, BaudRate::B1200),
    (2400, BaudRate::B2400),
    (4800, BaudRate::B4800),
    (9600, BaudRate::B9600),
    (19_200, BaudRate::B19200),
    (38_400, BaudRate::B38400),
    (57_600, BaudRate::B57600),
    (115_200, BaudRate::B115200),
    (230_400, BaudRate::B230400),
    (460_800, BaudRate::B460800),
    (500_000, BaudRate::B500000),
    (576_000, BaudRate::B576000),
    (921_600, BaudRate::B921600),
    (1_000_000, BaudRate::B1000000),
    (1_152_000, BaudRate::B1152000),
    (1_500_000, BaudRate::B1500000),
    (2_000_000, BaudRate::B2000000),
    (3_000_000, BaudRate::B3000000),
    (4_000_000, BaudRate::B4000000),
];

/// Maps a baud rate to a termios speed constant (the standard rates 1200..=4000000).
#[cfg(any(target_os = "linux", target_os = "android"))]
fn termios_baud(baud: u32) -> Option<Speed> {
    BAUD_TABLE.iter().find(|(b, _)| *b == baud).map(|(_, r)| *r)
}

/// The rates robobus sets on a pty: the ones Linux has constants for.
#[cfg(not(any(target_os = "linux", target_os = "android")))]
const RATES: [u32; 19] = [
    1200, 2400, 4800, 9600, 19_200, 38_400, 57_600, 115_200, 230_400, 460_800, 500_000, 576_000,
    921_600, 1_000_000, 1_152_000, 1_500_000, 2_000_000, 3_000_000, 4_000_000,
];

/// Checks a baud rate against the standard rates 1200..=4000000 (termios holds the number).
#[cfg(not(any(target_os = "linux", target_os = "android")))]
fn termios_baud(baud: u32) -> Option<Speed> {
    RATES.contains(&baud).then_some(baud)
}

fn errno_io(e: Errno) -> io::Error {
    io::Error::from_raw_os_error(e as i32)
}

/// Puts a terminal in raw mode at `baud` (8N1, no flow control, no echo).
fn make_raw(fd: impl AsFd, baud: Speed) -> Result<(), Errno> {
    let mut t = termios::tcgetattr(&fd)?;
    termios::cfmakeraw(&mut t);
    termios::cfsetspeed(&mut t, baud)?;
    // cfmakeraw leaves VMIN=1/VTIME=0; the slave side's reads raise VMIN to the bytes
    // they wait for (see `PtyLink::read_exact`).
    termios::tcsetattr(&fd, SetArg::TCSANOW, &t)
}

/// How long a write may wait for the other side to drain before it fails (default;
/// see [`PtyLink::set_write_timeout`]).
pub const WRITE_TIMEOUT: Duration = Duration::from_secs(2);

/// Waits until `fd` is readable or `deadline` passes; returns whether it is readable
/// (or hung up, which the following read reports). See [`wait_for`].
pub(crate) fn wait_readable(fd: impl AsFd, deadline: Instant) -> io::Result<bool> {
    wait_for(fd, PollFlags::POLLIN, deadline)
}

/// Waits until `fd` is ready for `what` or `deadline` passes; returns whether it is.
/// `ppoll` with a nanosecond timeout: no rounding to the kernel tick, unlike
/// `SO_RCVTIMEO`.
#[cfg(any(target_os = "linux", target_os = "android", target_os = "freebsd"))]
pub(crate) fn wait_for(fd: impl AsFd, what: PollFlags, deadline: Instant) -> io::Result<bool> {
    use nix::sys::time::TimeSpec;
    loop {
        let remaining = deadline.saturating_duration_since(Instant::now());
        let mut fds = [PollFd::new(fd.as_fd(), what)];
        match nix::poll::ppoll(&mut fds, Some(TimeSpec::from_duration(remaining)), None) {
            Ok(0) => return Ok(false),
            Ok(_) => return Ok(true),
            Err(Errno::EINTR) => {}
            Err(e) => return Err(errno_io(e)),
        }
    }
}

/// Waits until `fd` is ready for `what` or `deadline` passes; returns whether it is.
/// Without `ppoll` (macOS): `poll` for the whole milliseconds left (rounded down, so it
/// never wakes after the deadline), then polls without blocking for the rest under one
/// millisecond, so the wait ends at the deadline as it does with `ppoll`.
#[cfg(not(any(target_os = "linux", target_os = "android", target_os = "freebsd")))]
pub(crate) fn wait_for(fd: impl AsFd, what: PollFlags, deadline: Instant) -> io::Result<bool> {
    use nix::poll::PollTimeout;
    loop {
        let remaining = deadline.saturating_duration_since(Instant::now());
        let timeout = PollTimeout::try_from(remaining).unwrap_or(PollTimeout::MAX);
        let mut fds = [PollFd::new(fd.as_fd(), what)];
        match nix::poll::poll(&mut fds, timeout) {
            Ok(0) if remaining.is_zero() => return Ok(false),
            Ok(0) => {
                if timeout == PollTimeout::ZERO {
                    std::thread::yield_now();
                }
            }
            Ok(_) => return Ok(true),
            Err(Errno::EINTR) => {}
            Err(e) => return Err(errno_io(e)),
        }
    }
}

/// Options for [`PtyPair::open`].
#[derive(Debug, Clone)]
pub struct PtyOptions {
    /// Initial baud rate recorded in termios (no pacing happens). Default 115200.
    pub baud: u32,
    /// If set, a symbolic link at this path points to the slave device (e.g.
    /// `/tmp/robobus-wck`), so programs can use a stable name. Only a stale link of its
    /// own kind there is replaced; anything else is an error ([`PtySymlink::create`]).
    /// Removed when the master is dropped, if it still points to this pty.
    pub symlink: Option<PathBuf>,
}

impl Default for PtyOptions {
    fn default() -> Self {
        Self {
            baud: 115_200,
            symlink: None,
        }
    }
}

/// A freshly opened pseudo-terminal pair.
#[derive(Debug)]
pub struct PtyPair {
    /// The master side (what a simulator drives). It keeps a slave descriptor open so the
    /// master never sees a hang-up when a program closes and reopens the slave path.
    pub master: PtyLink,
    /// The slave side as a link (for in-process tests). Drop it if an outside program is
    /// going to use [`PtyPair::slave_path`].
    pub slave: PtyLink,
    /// The slave device path (`/dev/pts/N`).
    pub slave_path: PathBuf,
}

impl PtyPair {
    /// Opens a pty pair in raw mode.
    pub fn open(options: &PtyOptions) -> Result<Self, LinkError> {
        let baud = termios_baud(options.baud).ok_or_else(|| LinkError::UnsupportedBaud {
            baud: options.baud,
            context: "pty (termios)".into(),
        })?;
        let pty = nix::pty::openpty(None, None)
            .map_err(|e| LinkError::io("opening a pseudo-terminal pair", errno_io(e)))?;
        let nonblocking = |fd: &OwnedFd| {
            nix::fcntl::fcntl(fd, FcntlArg::F_SETFL(OFlag::O_NONBLOCK | OFlag::O_RDWR)).map(drop)
        };
        // `openpty` does not set close-on-exec: without it every child process (a
        // simulator's client, a test's subprocess) would inherit the master and keep the
        // pty alive, so closing it would never hang up the slave side.
        let cloexec = |fd: &OwnedFd| {
            nix::fcntl::fcntl(fd, FcntlArg::F_SETFD(nix::fcntl::FdFlag::FD_CLOEXEC)).map(drop)
        };
        cloexec(&pty.master)
            .and_then(|()| cloexec(&pty.slave))
            .map_err(|e| LinkError::io("setting close-on-exec on the pty", errno_io(e)))?;
        make_raw(&pty.slave, baud)
            .and_then(|()| make_raw(&pty.master, baud))
            .and_then(|()| nonblocking(&pty.master))
            .and_then(|()| nonblocking(&pty.slave))
            .map_err(|e| LinkError::io("setting the pty to raw mode", errno_io(e)))?;
        let slave_path = nix::unistd::ttyname(&pty.slave)
            .map_err(|e| LinkError::io("finding the pty slave's path", errno_io(e)))?;
        let keep_slave = pty
            .slave
            .try_clone()
            .map_err(|e| LinkError::io("duplicating the pty slave descriptor", e))?;
        let symlink = match &options.symlink {
            Some(link) => Some(PtySymlink::create(link, &slave_path)?),
            None => None,
        };
        let name = slave_path.display().to_string();
        Ok(Self {
            master: PtyLink {
                file: File::from(pty.master),
                baud: options.baud,
                name: format!("pty master of {name}"),
                _keep_slave: Some(keep_slave),
                symlink,
                write_timeout: WRITE_TIMEOUT,
                vmin: None,
            },
            slave: PtyLink {
                file: File::from(pty.slave),
                baud: options.baud,
                name,
                _keep_slave: None,
                symlink: None,
                write_timeout: WRITE_TIMEOUT,
                vmin: Some(1),
            },
            slave_path,
        })
    }
}

/// Whether `path` names a pty slave device (`/dev/pts/N` on Linux, `/dev/ttysN` on
/// macOS); a dangling symlink to one is a stale pty link.
fn is_pty_slave_path(path: &Path) -> bool {
    if cfg!(any(target_os = "linux", target_os = "android")) {
        path.starts_with("/dev/pts/")
    } else {
        path.to_str()
            .and_then(|p| p.strip_prefix("/dev/ttys"))
            .is_some_and(|n| !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()))
    }
}

/// A symbolic link at a stable path (e.g. `/tmp/wck0`) to a pty slave, owned by this
/// process: made by [`PtySymlink::create`], removed on drop, but only if it still points to
/// our pty (another simulator may have taken the path over since).
///
/// While it lives, an exclusive `flock` on `PATH.lock` (holding our process ID) marks the
/// path as served by a live simulator. [`PtySymlink::create`] replaces only a stale link
/// of its own kind: a dangling symlink to a pty slave (`/dev/pts/N`, macOS `/dev/ttysN`), or a symlink left by a simulator
/// that is gone (its lock file is still there, but nobody holds it). It refuses, with
/// [`LinkError::PathInUse`], a path another live simulator serves, a symlink somebody else
/// made to an existing file, and anything that is not a symlink (a regular file, a
/// directory, a device): none of these is touched.
#[derive(Debug)]
pub struct PtySymlink {
    path: PathBuf,
    target: PathBuf,
    lock_path: PathBuf,
    _lock: nix::fcntl::Flock<File>,
}

fn in_use(path: &Path, reason: impl Into<String>) -> LinkError {
    LinkError::PathInUse {
        path: path.to_path_buf(),
        reason: reason.into(),
    }
}

impl PtySymlink {
    /// Makes `link` point to `target` (a pty slave, `/dev/pts/N`), replacing only a stale
    /// link of its own kind (see the [type docs](Self)).
    pub fn create(link: &Path, target: &Path) -> Result<Self, LinkError> {
        let mut lock_path = link.as_os_str().to_owned();
        lock_path.push(".lock");
        let lock_path = PathBuf::from(lock_path);
        let lock_existed = std::fs::symlink_metadata(&lock_path).is_ok();
        let file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(&lock_path)
            .map_err(|e| {
                LinkError::io(format!("creating the lock file {}", lock_path.display()), e)
            })?;
        let mut lock =
            match nix::fcntl::Flock::lock(file, nix::fcntl::FlockArg::LockExclusiveNonblock) {
                Ok(lock) => lock,
                Err((mut file, Errno::EWOULDBLOCK)) => {
                    let mut pid = String::new();
                    let _ = file.read_to_string(&mut pid);
                    let pid = pid.trim();
                    let who = if pid.is_empty() {
                        "another simulator".to_owned()
                    } else {
                        format!("another simulator (process {pid})")
                    };
                    return Err(in_use(
                        link,
                        format!(
                            "{who} serves it (its lock {} is held); stop it or pick another path",
                            lock_path.display()
                        ),
                    ));
                }
                Err((_, e)) => {
                    return Err(LinkError::io(
                        format!("locking {}", lock_path.display()),
                        errno_io(e),
                    ));
                }
            };
        let claim = |lock: &mut nix::fcntl::Flock<File>| -> Result<(), LinkError> {
            match std::fs::symlink_metadata(link) {
                Err(e) if e.kind() == io::ErrorKind::NotFound => {}
                Err(e) => return Err(LinkError::io(format!("examining {}", link.display()), e)),
                Ok(meta) if meta.file_type().is_symlink() => {
                    let old = std::fs::read_link(link).map_err(|e| {
                        LinkError::io(format!("reading symlink {}", link.display()), e)
                    })?;
                    let dangling = std::fs::metadata(link).is_err();
                    let stale_pty = dangling && is_pty_slave_path(&old);
                    // A lock file nobody held: the simulator that made the link is gone.
                    if !(stale_pty || lock_existed) {
                        return Err(in_use(
                            link,
                            format!(
                                "it is a symlink to {} that robobus did not make; remove it \
                                 yourself if it is stale, or pick another path",
                                old.display()
                            ),
                        ));
                    }
                    std::fs::remove_file(link).map_err(|e| {
                        LinkError::io(format!("removing stale symlink {}", link.display()), e)
                    })?;
                }
                Ok(meta) => {
                    let kind = if meta.is_dir() {
                        "a directory"
                    } else if meta.is_file() {
                        "a regular file"
                    } else {
                        "a file that is not a symlink"
                    };
                    return Err(in_use(
                        link,
                        format!("{kind} is there (left untouched); remove it or pick another path"),
                    ));
                }
            }
            lock.set_len(0)
                .and_then(|()| lock.write_all(format!("{}\n", std::process::id()).as_bytes()))
                .map_err(|e| LinkError::io(format!("writing {}", lock_path.display()), e))?;
            std::os::unix::fs::symlink(target, link)
                .map_err(|e| LinkError::io(format!("creating pty symlink {}", link.display()), e))
        };
        if let Err(e) = claim(&mut lock) {
            if !lock_existed {
                let _ = std::fs::remove_file(&lock_path);
            }
            return Err(e);
        }
        Ok(Self {
            path: link.to_path_buf(),
            target: target.to_path_buf(),
            lock_path,
            _lock: lock,
        })
    }

    /// The link's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The pty slave it points to.
    pub fn target(&self) -> &Path {
        &self.target
    }
}

impl Drop for PtySymlink {
    fn drop(&mut self) {
        // Only our own link: another simulator may have replaced it (after we were
        // stopped and restarted, say), and a user may have put a file there.
        if std::fs::read_link(&self.path).is_ok_and(|t| t == self.target) {
            let _ = std::fs::remove_file(&self.path);
        }
        // Still locked by us here, so nobody else's lock file is removed.
        let _ = std::fs::remove_file(&self.lock_path);
    }
}

/// How many bytes one drain of the input reads at most (a pty holds a few kilobytes;
/// a peer that writes faster than this is drained cannot keep a discard going).
const MAX_DISCARD: usize = 64 * 1024;

/// One side of a pseudo-terminal pair (see [`PtyPair`]).
///
/// A read of the slave side that waits for `n` bytes ([`ByteLink::read_exact`]) sets the
/// terminal's VMIN to `n` (at most 255; kept until another count is needed), so the
/// kernel reports the descriptor readable only once all of them are there: one `ppoll`
/// and one `read` per reply, however the other side paces its bytes. VMIN stays 1 on the
/// master side (termios calls on a master reach the slave's settings).
#[derive(Debug)]
pub struct PtyLink {
    file: File,
    baud: u32,
    name: String,
    _keep_slave: Option<OwnedFd>,
    symlink: Option<PtySymlink>,
    write_timeout: Duration,
    /// The VMIN termios holds for this side; `None` on the master, which leaves it alone.
    vmin: Option<u8>,
}

impl PtyLink {
    /// How long a write may wait for the other side to drain before it fails with
    /// [`LinkError::WriteTimeout`] (a pty holds a few kilobytes).
    pub fn set_write_timeout(&mut self, timeout: Duration) {
        self.write_timeout = timeout;
    }

    /// The stable symlink this master created, if any.
    pub fn symlink(&self) -> Option<&Path> {
        self.symlink.as_ref().map(PtySymlink::path)
    }

    /// Makes the descriptor readable only once `n` bytes (1..=255) are there (slave side;
    /// a termios call only when the count changes).
    fn wake_at(&mut self, n: usize) -> Result<(), LinkError> {
        let want = u8::try_from(n.clamp(1, 255)).unwrap_or(u8::MAX);
        if self.vmin.is_none_or(|v| v == want) {
            return Ok(());
        }
        let mut t = termios::tcgetattr(&self.file)
            .map_err(|e| LinkError::io(format!("reading termios of {}", self.name), errno_io(e)))?;
        if let Some(c) = t
            .control_chars
            .get_mut(SpecialCharacterIndices::VMIN as usize)
        {
            *c = want;
        }
        termios::tcsetattr(&self.file, SetArg::TCSANOW, &t)
            .map_err(|e| LinkError::io(format!("setting VMIN on {}", self.name), errno_io(e)))?;
        self.vmin = Some(want);
        Ok(())
    }

    /// Reads what is there without waiting: `Ok(None)` when nothing is.
    fn read_now(&mut self, buf: &mut [u8]) -> Result<Option<usize>, LinkError> {
        loop {
            match self.file.read(buf) {
                Ok(0) if !buf.is_empty() => {
                    return Err(LinkError::Closed {
                        context: format!("{}: end of file", self.name),
                    });
                }
                Ok(n) => return Ok(Some(n)),
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => return Ok(None),
                Err(e) => return Err(self.closed_or_io("reading from", e)),
            }
        }
    }

    fn closed_or_io(&self, what: &str, e: io::Error) -> LinkError {
        // Linux reports a pty whose other side is gone as EIO.
        if e.raw_os_error() == Some(Errno::EIO as i32) {
            LinkError::Closed {
                context: format!("{}: other side closed", self.name),
            }
        } else {
            LinkError::io(format!("{what} {}", self.name), e)
        }
    }
}

impl ByteLink for PtyLink {
    fn write_all(&mut self, bytes: &[u8]) -> Result<(), LinkError> {
        let deadline = Instant::now() + self.write_timeout;
        let mut written = 0;
        while let Some(rest) = bytes.get(written..).filter(|r| !r.is_empty()) {
            match self.file.write(rest) {
                Ok(n) => written += n,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => {
                    let ready = wait_for(&self.file, PollFlags::POLLOUT, deadline)
                        .map_err(|e| LinkError::io(format!("waiting on {}", self.name), e))?;
                    if !ready {
                        return Err(LinkError::WriteTimeout {
                            written,
                            total: bytes.len(),
                        });
                    }
                }
                Err(e) => return Err(self.closed_or_io("writing to", e)),
            }
        }
        Ok(())
    }

    fn read_some(&mut self, buf: &mut [u8], deadline: Instant) -> Result<usize, LinkError> {
        if buf.is_empty() {
            return Ok(0);
        }
        self.wake_at(1)?;
        loop {
            let ready = wait_readable(&self.file, deadline)
                .map_err(|e| LinkError::io(format!("waiting on {}", self.name), e))?;
            if !ready {
                return Err(LinkError::Timeout {
                    received: 0,
                    expected: buf.len(),
                });
            }
            if let Some(n) = self.read_now(buf)? {
                return Ok(n);
            }
        }
    }

    fn read_exact(&mut self, buf: &mut [u8], deadline: Instant) -> Result<(), LinkError> {
        let mut filled = 0;
        while let Some(rest) = buf.get_mut(filled..).filter(|r| !r.is_empty()) {
            let want = rest.len();
            self.wake_at(want)?;
            let ready = wait_readable(&self.file, deadline)
                .map_err(|e| LinkError::io(format!("waiting on {}", self.name), e))?;
            // After a timeout this collects what did arrive (fewer than VMIN bytes).
            filled += self.read_now(rest)?.unwrap_or(0);
            if !ready && filled < buf.len() {
                return Err(LinkError::Timeout {
                    received: filled,
                    expected: buf.len(),
                });
            }
        }
        Ok(())
    }

    fn discard_input(&mut self) -> Result<(), LinkError> {
        // A read that finds nothing first waits for the bytes the other side has written
        // but the kernel has not yet passed on, so draining by reads drops everything
        // written before the call (one `read` when nothing is there).
        let mut scratch = [0u8; 256];
        let mut dropped = 0;
        while dropped < MAX_DISCARD {
            match self.read_now(&mut scratch)? {
                Some(n) => dropped += n,
                None => break,
            }
        }
        Ok(())
    }

    fn set_baud(&mut self, baud: u32) -> Result<(), LinkError> {
        let rate = termios_baud(baud).ok_or_else(|| LinkError::UnsupportedBaud {
            baud,
            context: self.name.clone(),
        })?;
        let mut t = termios::tcgetattr(&self.file)
            .map_err(|e| LinkError::io(format!("reading termios of {}", self.name), errno_io(e)))?;
        termios::cfsetspeed(&mut t, rate)
            .and_then(|()| termios::tcsetattr(&self.file, SetArg::TCSANOW, &t))
            .map_err(|e| LinkError::io(format!("setting baud on {}", self.name), errno_io(e)))?;
        self.baud = baud;
        Ok(())
    }

    fn baud(&self) -> Option<u32> {
        Some(self.baud)
    }
}

/// The output baud rate termios currently holds for a terminal, in bit/s, or `None` for
/// rate 0 (hang-up).
///
/// Any rate is reported, including arbitrary ones set through `termios2` (`BOTHER`), as
/// the `serialport` crate does: this reads the terminal with `TCGETS2` (via `rustix`), so a
/// client's choice of API can never make the reader fail. (`nix`'s `cfgetospeed` panics
/// on `BOTHER`, which is why it is not used here.)
pub fn termios_speed(fd: impl AsFd) -> Result<Option<u32>, LinkError> {
    let t = rustix::termios::tcgetattr(&fd)
        .map_err(|e| LinkError::io("reading termios", io::Error::from(e)))?;
    let rate = t.output_speed();
    Ok((rate != 0).then_some(rate))
}

impl AsFd for PtyLink {
    fn as_fd(&self) -> std::os::fd::BorrowedFd<'_> {
        self.file.as_fd()
    }
}
