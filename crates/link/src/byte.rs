//! Byte links: the transport under a wCK (UART) bus.
//!
//! A [`ByteLink`] moves raw bytes with deadlines. Implementations: [`crate::SerialLink`]
//! (a real serial port), [`crate::PtyLink`] (either side of a pseudo-terminal pair),
//! [`crate::MemoryByteLink`] (an in-memory pair for deterministic tests); wrappers
//! ([`crate::FaultyByteLink`], [`crate::CaptureByteLink`]) implement the same trait.

use std::io;
use std::path::PathBuf;
use std::time::Instant;

/// Why a byte-link operation failed.
#[derive(Debug, thiserror::Error)]
pub enum LinkError {
    /// The deadline passed before enough bytes arrived. For [`ByteLink::read_exact`] the
    /// first `received` bytes of the buffer hold what did arrive.
    #[error("timed out: {received} of {expected} bytes arrived before the deadline")]
    Timeout {
        /// Bytes that arrived before the deadline.
        received: usize,
        /// Bytes that were asked for.
        expected: usize,
    },
    /// A write could not complete in time: nobody is draining the other side (a pty
    /// nobody reads, a stalled adapter).
    #[error(
        "write timed out: {written} of {total} bytes written (is anything reading the other side?)"
    )]
    WriteTimeout {
        /// Bytes the OS accepted before the timeout.
        written: usize,
        /// Bytes that were to be written.
        total: usize,
    },
    /// The other side is gone (pty closed, memory peer dropped, replay exhausted,
    /// injected disconnect).
    #[error("link closed: {context}")]
    Closed {
        /// What was closed and how it was noticed.
        context: String,
    },
    /// The device path does not exist.
    #[error(
        "serial device {path} does not exist: check the adapter is plugged in and the path \
         (ls -l /dev/serial/by-id/ lists USB adapters)"
    )]
    NoSuchDevice {
        /// The path that was opened.
        path: PathBuf,
    },
    /// The device is in use by another program.
    #[error(
        "serial device {path} is busy: another program has it open (check with `fuser {path}` \
         and close the other program)"
    )]
    Busy {
        /// The path that was opened.
        path: PathBuf,
    },
    /// The process may not open the device.
    #[error(
        "no permission to open {path}: add the user to the group owning it (often `dialout`) \
         or check its mode"
    )]
    PermissionDenied {
        /// The path that was opened.
        path: PathBuf,
    },
    /// A stable link path cannot be taken: another live simulator serves it, or something
    /// that is not a stale link of ours is there (left untouched).
    #[error("cannot create the link {path}: {reason}")]
    PathInUse {
        /// The link path asked for.
        path: PathBuf,
        /// What is there and what to do.
        reason: String,
    },
    /// The baud rate cannot be set on this link.
    #[error("baud rate {baud} is not supported by {context}")]
    UnsupportedBaud {
        /// The requested baud rate.
        baud: u32,
        /// Which link refused it.
        context: String,
    },
    /// Nothing accepts a connection at a network address (`socket://HOST:PORT`):
    /// refused, unreachable, or no answer in time.
    #[error(
        "nothing answers at {address}: {reason} (is the simulator or serial server running \
         and listening there?)"
    )]
    Unreachable {
        /// The address, as `socket://HOST:PORT`.
        address: String,
        /// Why the connection failed.
        reason: String,
    },
    /// This kind of port does not exist on this operating system (a COM port outside
    /// Windows).
    #[error("{what} is not available on this system: {instead}")]
    NotAvailable {
        /// What was asked for.
        what: String,
        /// What to use instead.
        instead: String,
    },
    /// A port address that does not parse ([`crate::PortSpec`]); nothing was opened.
    #[error(transparent)]
    BadPort(#[from] crate::port::PortSpecError),
    /// Any other operating-system error.
    #[error("{context}: {source}")]
    Io {
        /// What was being done, on which path.
        context: String,
        /// The underlying error.
        #[source]
        source: io::Error,
    },
}

impl LinkError {
    /// An [`LinkError::Io`] with its context.
    pub fn io(context: impl Into<String>, source: io::Error) -> Self {
        Self::Io {
            context: context.into(),
            source,
        }
    }

    /// Whether this is a [`LinkError::Timeout`].
    pub const fn is_timeout(&self) -> bool {
        matches!(self, Self::Timeout { .. })
    }
}

/// A bidirectional byte stream with deadlines (a UART, a pty, a test pipe).
///
/// All reads take an absolute deadline ([`Instant`]); a deadline in the past means "only
/// what is already there". Bytes are never reordered or duplicated by a correct link.
pub trait ByteLink {
    /// Writes all of `bytes`, blocking until the OS accepted them (at most a link-specific
    /// write timeout, then [`LinkError::WriteTimeout`]).
    fn write_all(&mut self, bytes: &[u8]) -> Result<(), LinkError>;

    /// Reads at least one byte into `buf` and returns how many arrived, waiting until
    /// `deadline` at most. Returns [`LinkError::Timeout`] with `received: 0` if nothing
    /// arrived in time. An empty `buf` returns `Ok(0)` at once.
    fn read_some(&mut self, buf: &mut [u8], deadline: Instant) -> Result<usize, LinkError>;

    /// Fills `buf` completely before `deadline`, or fails with [`LinkError::Timeout`]
    /// saying how many bytes arrived (they are at the start of `buf`).
    fn read_exact(&mut self, buf: &mut [u8], deadline: Instant) -> Result<(), LinkError> {
        let mut filled = 0;
        while filled < buf.len() {
            let rest = buf.get_mut(filled..).unwrap_or_default();
            match self.read_some(rest, deadline) {
                Ok(n) => filled += n,
                Err(LinkError::Timeout { .. }) => {
                    return Err(LinkError::Timeout {
                        received: filled,
                        expected: buf.len(),
                    });
                }
                Err(e) => return Err(e),
            }
        }
        Ok(())
    }

    /// Drops every byte received but not yet read (stale replies, line noise).
    fn discard_input(&mut self) -> Result<(), LinkError>;

    /// Changes the line rate. On a pty it is only a termios setting (a pty does not pace
    /// bytes); links without a line rate accept and remember it.
    fn set_baud(&mut self, baud: u32) -> Result<(), LinkError>;

    /// The current line rate, if the link has one.
    fn baud(&self) -> Option<u32>;

    /// The link's clock: what its deadlines are measured against. The wall clock, unless
    /// the link is a simulation on a clock of its own (a virtual-clock simulator, where
    /// time moves only when the client waits).
    fn now(&self) -> Instant {
        Instant::now()
    }

    /// Waits until `deadline` on the link's clock (see [`ByteLink::now`]) without reading.
    fn sleep_until(&mut self, deadline: Instant) {
        std::thread::sleep(deadline.saturating_duration_since(Instant::now()));
    }

    /// Whether the link's clock is virtual: it moves only while the link is driven
    /// (read, sleep), so nothing may wait on the wall clock for it. `false` except on a
    /// simulated bus on virtual time (as [`FrameLink::virtual_time`](crate::FrameLink::virtual_time)).
    fn virtual_time(&self) -> bool {
        false
    }
}

/// The rate and clock methods of a [`ByteLink`] that wraps another, forwarded to the
/// wrapped link (the field named): `set_baud`, `baud`, `now`, `sleep_until`,
/// `virtual_time`. For use
/// inside an `impl ByteLink for Wrapper` block.
#[macro_export]
macro_rules! forward_byte_link_rate_and_clock {
    ($field:tt) => {
        fn set_baud(&mut self, baud: u32) -> ::core::result::Result<(), $crate::LinkError> {
            $crate::ByteLink::set_baud(&mut self.$field, baud)
        }

        fn baud(&self) -> ::core::option::Option<u32> {
            $crate::ByteLink::baud(&self.$field)
        }

        fn now(&self) -> ::std::time::Instant {
            $crate::ByteLink::now(&self.$field)
        }

        fn sleep_until(&mut self, deadline: ::std::time::Instant) {
            $crate::ByteLink::sleep_until(&mut self.$field, deadline);
        }

        fn virtual_time(&self) -> bool {
            $crate::ByteLink::virtual_time(&self.$field)
        }
    };
}

/// `ByteLink` for a pointer to a link (`&mut T`, `Box<T>`): every method the link's own.
macro_rules! byte_link_through {
    ($($pointer:ty),+) => {$(
        impl<T: ByteLink + ?Sized> ByteLink for $pointer {
            fn write_all(&mut self, bytes: &[u8]) -> Result<(), LinkError> {
                (**self).write_all(bytes)
            }
            fn read_some(&mut self, buf: &mut [u8], deadline: Instant) -> Result<usize, LinkError> {
                (**self).read_some(buf, deadline)
            }
            fn read_exact(&mut self, buf: &mut [u8], deadline: Instant) -> Result<(), LinkError> {
                (**self).read_exact(buf, deadline)
            }
            fn discard_input(&mut self) -> Result<(), LinkError> {
                (**self).discard_input()
            }
            fn set_baud(&mut self, baud: u32) -> Result<(), LinkError> {
                (**self).set_baud(baud)
            }
            fn baud(&self) -> Option<u32> {
                (**self).baud()
            }
            fn now(&self) -> Instant {
                (**self).now()
            }
            fn sleep_until(&mut self, deadline: Instant) {
                (**self).sleep_until(deadline);
            }
            fn virtual_time(&self) -> bool {
                (**self).virtual_time()
            }
        }
    )+};
}

byte_link_through!(&mut T, Box<T>);
