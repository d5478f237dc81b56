//! Links: the layer that moves bytes and CAN FD frames for robobus clients and simulators.
//!
//! Two small traits with deadlines, and everything else composes around them:
//!
//! - [`ByteLink`] (wCK servos, UART): [`SerialLink`] (a real port), [`PtyPair`] /
//!   [`PtyLink`] (a simulator as a serial device any program opens by path),
//!   [`TcpByteLink`] / [`TcpServer`] (a simulator over TCP, pyserial's
//!   `socket://HOST:PORT`, on every OS), [`MemoryByteLink`] (deterministic tests).
//!   [`PortSpec`] turns a user's `--port` (a device path, `COM12`, `socket://…`) into one.
//! - [`FrameLink`] (WHJ joints, CAN FD): [`SocketCanLink`] (Linux `SocketCAN`), [`UdpBus`]
//!   (python-can's `udp_multicast` virtual bus), [`SlcanLink`] (an `slcan` CAN FD adapter
//!   on any byte link), [`MemoryBus`] (deterministic tests).
//! - Wrappers implementing the same traits: [`FaultyByteLink`] / [`FaultyFrameLink`]
//!   (seeded fault injection), [`CaptureByteLink`] / [`CaptureFrameLink`] (hex log /
//!   candump log capture), [`ReplayByteLink`] / [`ReplayFrameLink`] (play a capture back);
//!   [`CaptureReader`] reads a capture file of either format back, line by line.
//!
//! ```
//! use std::time::{Duration, Instant};
//! use robobus_link::{FaultConfig, FaultyFrameLink, FrameLink, IdFilter, MemoryBus};
//! use robobus_whj::CanFrame;
//!
//! let bus = MemoryBus::new();
//! let mut host = bus.endpoint();
//! let mut joint = bus.endpoint();
//! joint.set_filters(&[IdFilter::standard(0x07)])?;
//!
//! // Wrappers compose: a link that flips bits in 1 % of the frames, reproducibly.
//! let mut host = FaultyFrameLink::new(&mut host, FaultConfig { corrupt: 0.01, ..FaultConfig::seeded(42) });
//! let frame = CanFrame::new_fd(CanFrame::standard_id(0x07)?, &[0x01, 0x0A, 0x00, 0x00])?;
//! host.send(&frame)?;
//! let got = joint.recv(Instant::now() + Duration::from_millis(100))?;
//! assert_eq!(got.frame.raw_id(), 0x07);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! A simulator serves a wCK bus behind a pseudo-terminal that any program opens by path:
//!
//! ```
//! use std::time::{Duration, Instant};
//! use robobus_link::{ByteLink, PtyOptions, PtyPair, SerialLink};
//!
//! let PtyPair { mut master, slave, slave_path } = PtyPair::open(&PtyOptions::default())?;
//! drop(slave); // the client opens the path itself
//! let mut client = SerialLink::open(&slave_path, 115_200)?;
//! client.write_all(&[0xFF, 0x03, 0x7F, 0x7C])?;
//! let mut cmd = [0u8; 4];
//! master.read_exact(&mut cmd, Instant::now() + Duration::from_secs(1))?;
//! master.write_all(&[0x12, 0x7F])?; // a real simulator waits for the wire time first
//! let mut reply = [0u8; 2];
//! client.read_exact(&mut reply, Instant::now() + Duration::from_secs(1))?;
//! assert_eq!(reply, [0x12, 0x7F]);
//! # Ok::<(), robobus_link::LinkError>(())
//! ```
//!
//! Virtual CAN without kernel support: [`UdpBus`] (python-can's wire format, in
//! [`pycan`]); real `SocketCAN` on a kernel without CAN: User-Mode Linux (below). A pty
//! does not pace bytes and has no modem lines ([`pty`]); FTDI adapters hold short replies
//! back for their latency timer ([`serial`]).
//!
//! # Waiting for a deadline
//!
//! Every wait ends at its exact deadline, not at the next kernel tick: the pty and UDP
//! links wait in `ppoll` (nanosecond timeout), `SocketCanLink` polls its non-blocking
//! socket the same way (`SO_RCVTIMEO`, which Linux rounds up to whole ticks of 4-20 ms,
//! made replies one to two ticks late), `SerialLink` through `serialport`'s `ppoll`, the
//! memory links on a condition variable. Where a wait counts whole milliseconds (macOS's
//! `poll`, Windows' COM timeouts and `SO_RCVTIMEO`), the rest before the deadline is
//! polled without blocking, so no wait ends early (see [`pty`], [`serial`], [`udp`]).
//!
//! # On each operating system
//!
//! Linux has everything. macOS and Windows have [`SerialLink`], [`UdpBus`], the TCP links
//! and the serial-line CAN FD adapters; ptys are Unix's (Linux, macOS); `SocketCAN` and the
//! sysfs USB latency timer are Linux's, and answer elsewhere with the not-available errors
//! ([`LinkError::NotAvailable`], [`OpenError::Unsupported`]) naming what to use instead.
//!
//! # Tests that provision outside programs
//!
//! `cargo test` installs what the interop tests need and fails loudly if it cannot:
//! `scripts/py/ensure-venv` makes `target/pyenv` with python-can and msgpack (the python-can
//! exchange runs in a private network namespace made with `unshare -n`);
//! `scripts/uml/ensure-uml` unpacks User-Mode Linux and can-utils into `target/uml`, and
//! `scripts/uml/run-in-uml` boots it with a CAN FD `vcan0` to run the `SocketCAN` test.

pub mod adapter;
pub mod byte;
pub mod capture;
pub mod fault;
pub mod fdcanusb;
pub mod frame_link;
pub mod memory;
pub mod port;
#[cfg(unix)]
pub mod pty;
pub mod pycan;
#[cfg(any(unix, windows))]
pub mod serial;
pub mod slcan;
#[cfg(target_os = "linux")]
pub mod socketcan;
pub mod spec;
pub mod tcp;
#[cfg(any(unix, windows))]
pub mod udp;
pub mod wait;

pub use adapter::{AdapterError, AdapterErrorKind};
pub use byte::{ByteLink, LinkError};
pub use capture::{
    CandumpError, CandumpRecord, CandumpWriter, CaptureByteLink, CaptureFrameLink, CaptureReader,
    HexRecord, ReplayByteLink, ReplayFrameLink, read_candump, read_hex_log,
};
pub use fault::{FaultConfig, FaultStats, FaultyByteLink, FaultyFrameLink};
pub use fdcanusb::{FdcanusbConfig, FdcanusbLink};
pub use frame_link::{
    BusErrorKind, DEFAULT_REPLY_ALLOWANCE, FrameLink, FrameLinkError, IdFilter, Received,
};
pub use memory::{MemoryBus, MemoryBusEndpoint, MemoryByteLink};
pub use port::{PortSpec, PortSpecError};
#[cfg(unix)]
pub use pty::{PtyLink, PtyOptions, PtyPair, PtySymlink};
#[cfg(any(unix, windows))]
pub use serial::{LATENCY_TIMER_ADVICE, SerialLink, set_usb_latency_timer, usb_latency_timer};
pub use slcan::{SlcanConfig, SlcanLink, SlcanStats};
#[cfg(target_os = "linux")]
pub use socketcan::SocketCanLink;
pub use spec::{FrameLinkSpec, OpenError, SpecError};
pub use tcp::{TcpByteLink, TcpServer, TcpServerStats};
#[cfg(any(unix, windows))]
pub use udp::{UdpBus, UdpBusConfig, UdpBusStats};
pub use wait::{WaitMode, WaitModeError};
