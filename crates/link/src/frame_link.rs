//! Frame links: the transport under a WHJ (CAN FD) bus.
//!
//! A [`FrameLink`] sends and receives [`CanFrame`]s with deadlines. Implementations:
//! [`crate::SocketCanLink`] (Linux `SocketCAN`, CAN FD), [`crate::UdpBus`] (python-can's
//! `udp_multicast` virtual bus), [`crate::MemoryBusEndpoint`] (in-memory, deterministic);
//! wrappers ([`crate::FaultyFrameLink`], [`crate::CaptureFrameLink`]) and
//! [`crate::ReplayFrameLink`] implement the same trait.

use core::time::Duration;
use std::io;
use std::time::{Instant, SystemTime};

use robobus_whj::frame::CanFrame;

/// A frame that arrived, with the time it arrived if the link knows it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Received {
    /// The frame.
    pub frame: CanFrame,
    /// Wall-clock receive time (kernel timestamp on `SocketCAN`, receive time elsewhere,
    /// the capture's time on a replay).
    pub timestamp: Option<SystemTime>,
}

/// An acceptance filter: a frame passes when its identifier format matches `extended`
/// and `frame_id & mask == id & mask` (`SocketCAN`'s `can_filter` semantics).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct IdFilter {
    /// Identifier bits to match.
    pub id: u32,
    /// Which identifier bits must match (`0x7FF` = exact for 11-bit IDs).
    pub mask: u32,
    /// Whether the filter is for 29-bit (extended) identifiers.
    pub extended: bool,
}

impl IdFilter {
    /// A filter matching exactly one 11-bit identifier.
    pub const fn standard(id: u16) -> Self {
        Self {
            id: id as u32,
            mask: 0x7FF,
            extended: false,
        }
    }

    /// A filter over 11-bit identifiers: `frame_id & mask == id & mask`.
    pub const fn standard_masked(id: u16, mask: u16) -> Self {
        Self {
            id: id as u32,
            mask: mask as u32,
            extended: false,
        }
    }

    /// A filter matching exactly one 29-bit identifier.
    pub const fn extended(id: u32) -> Self {
        Self {
            id,
            mask: 0x1FFF_FFFF,
            extended: true,
        }
    }

    /// Whether `frame` passes this filter.
    pub fn matches(&self, frame: &CanFrame) -> bool {
        frame.is_extended() == self.extended
            && (frame.raw_id() & self.mask) == (self.id & self.mask)
    }
}

/// Whether `frame` passes a filter list: an empty list accepts everything, otherwise any
/// one matching filter suffices.
pub fn passes(filters: &[IdFilter], frame: &CanFrame) -> bool {
    filters.is_empty() || filters.iter().any(|f| f.matches(frame))
}

/// A controller state change or bus error reported by the CAN hardware (`SocketCAN` error
/// frames).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BusErrorKind {
    /// The controller went bus-off: it sends and receives nothing until restarted.
    BusOff,
    /// The controller is error passive (error counter ≥ 128).
    ErrorPassive,
    /// The controller reached the error-warning level (error counter ≥ 96).
    ErrorWarning,
    /// The controller restarted after bus-off.
    Restarted,
    /// No node acknowledged a sent frame (nobody else on the bus, or wrong bit rate).
    NoAck,
    /// Another bus or protocol error; the raw `SocketCAN` error class bits.
    Other {
        /// `can_id & CAN_ERR_MASK` of the error frame.
        class: u32,
    },
}

/// Why a frame-link operation failed.
#[derive(Debug, thiserror::Error)]
pub enum FrameLinkError {
    /// Nothing (that passed the filters) arrived before the deadline.
    #[error("timed out: no frame arrived before the deadline")]
    Timeout,
    /// The link is gone (peer dropped, replay exhausted, injected disconnect).
    #[error("link closed: {context}")]
    Closed {
        /// What was closed.
        context: String,
    },
    /// The controller reported bus-off. The link stays open; receiving continues.
    #[error("CAN interface {iface} is bus-off: {}", bus_off_advice(iface))]
    BusOff {
        /// The interface.
        iface: String,
    },
    /// The controller reported error-passive. The link stays open.
    #[error(
        "CAN interface {iface} is error passive: many frames are failing (check termination, bit rate, and that another node acknowledges)"
    )]
    ErrorPassive {
        /// The interface.
        iface: String,
    },
    /// Another error frame from the controller. The link stays open.
    #[error("CAN interface {iface} reported a bus error: {kind:?}")]
    BusError {
        /// The interface.
        iface: String,
        /// What the error frame said.
        kind: BusErrorKind,
    },
    /// The interface exists but is not configured for CAN FD (MTU is not 72).
    #[error(
        "CAN interface {iface} is not CAN FD capable (MTU {mtu}, need 72): for vcan run `ip link set {iface} mtu 72`; for hardware configure `fd on` with a data bitrate"
    )]
    NotFdCapable {
        /// The interface.
        iface: String,
        /// Its MTU (16 = classic CAN only).
        mtu: u32,
    },
    /// There is no network interface with this name.
    #[error("no network interface named {iface}: check `ip link show`{hint}")]
    NoSuchInterface {
        /// The interface.
        iface: String,
        /// Extra advice (e.g. that this kernel has no CAN support at all).
        hint: String,
    },
    /// The interface exists but is not a CAN interface.
    #[error("network interface {iface} is not a CAN interface (link type {link_type}, CAN is 280)")]
    NotCan {
        /// The interface.
        iface: String,
        /// Its ARPHRD link type.
        link_type: u32,
    },
    /// The running kernel has no `SocketCAN` support (`socket(AF_CAN)` fails with
    /// EAFNOSUPPORT).
    #[error(
        "this kernel has no SocketCAN support (socket(AF_CAN) failed with EAFNOSUPPORT) while opening {iface}: load the `can` and `can-raw` modules, or use the UDP bus / User-Mode Linux instead"
    )]
    NoCanSupport {
        /// The interface that was being opened.
        iface: String,
    },
    /// The frame cannot be carried by this link.
    #[error("frame cannot be sent on {context}: {reason}")]
    Unsendable {
        /// Which link.
        context: String,
        /// Why not.
        reason: String,
    },
    /// Any other operating-system error.
    #[error("{context}: {source}")]
    Io {
        /// What was being done, on what.
        context: String,
        /// The underlying error.
        #[source]
        source: io::Error,
    },
}

/// What to do about a bus-off on `iface`: restart a `SocketCAN` interface; open a
/// serial-line adapter's bus (`slcan:COM8`, named with its kind) again.
fn bus_off_advice(iface: &str) -> String {
    if iface.contains(':') {
        "check wiring, termination and bit rate, then open the bus again (the adapter \
         restarts its controller when its channel is opened)"
            .to_owned()
    } else {
        format!(
            "check wiring, termination and bit rate, then restart it (`sudo ip link set {iface} \
             type can restart`, or down and up; `restart-ms 100`, set while it is down, \
             restarts it by itself)"
        )
    }
}

impl FrameLinkError {
    /// An [`FrameLinkError::Io`] with its context.
    pub fn io(context: impl Into<String>, source: io::Error) -> Self {
        Self::Io {
            context: context.into(),
            source,
        }
    }

    /// Whether this is a [`FrameLinkError::Timeout`].
    pub const fn is_timeout(&self) -> bool {
        matches!(self, Self::Timeout)
    }
}

/// What [`FrameLink::reply_allowance`] says for a link that does not know its own: the
/// scheduling of a host thread that forwards frames one by one (0.15 ms).
pub const DEFAULT_REPLY_ALLOWANCE: Duration = Duration::from_micros(150);

/// [`FrameLink::reply_allowance`] of a USB CAN adapter (slcan, fdcanusb): 1.5 ms. The
/// adapter hands received frames to the host in USB full-speed transfers, 1 ms frames
/// apart, and buffers its text lines until a transfer takes them, so a frame that followed
/// another on the wire may come one transfer later, and the host's thread runs after that.
pub(crate) const USB_ADAPTER_REPLY_ALLOWANCE: Duration = Duration::from_micros(1_500);

/// A CAN FD bus endpoint: send frames, receive frames with a deadline.
pub trait FrameLink {
    /// Sends one frame.
    fn send(&mut self, frame: &CanFrame) -> Result<(), FrameLinkError>;

    /// Receives the next frame that passes the filters, waiting until `deadline` at most.
    /// Controller errors (bus-off, error-passive) are returned as errors; the link stays
    /// usable afterwards.
    fn recv(&mut self, deadline: Instant) -> Result<Received, FrameLinkError>;

    /// Replaces the acceptance filters (empty = accept everything). See [`IdFilter`].
    fn set_filters(&mut self, filters: &[IdFilter]) -> Result<(), FrameLinkError>;

    /// The link's clock: the instant deadlines passed to [`FrameLink::recv`] are compared
    /// with. The wall clock, except on a simulated bus on virtual time.
    fn now(&self) -> Instant {
        Instant::now()
    }

    /// Lets the link's clock reach `deadline` (frames arriving meanwhile stay queued for
    /// [`FrameLink::recv`]). Sleeps on the wall clock, except on a simulated bus on virtual
    /// time, where simulated time advances at once.
    fn sleep_until(&mut self, deadline: Instant) {
        std::thread::sleep(deadline.saturating_duration_since(Instant::now()));
    }

    /// Whether the link's clock is virtual: it moves only while the link is driven
    /// (receive, sleep), so nothing may wait on the wall clock for it. `false` except on
    /// a simulated bus on virtual time.
    fn virtual_time(&self) -> bool {
        false
    }

    /// Whether the link can send a frame without data bytes. `true` except through an
    /// adapter whose protocol cannot write one (mjbots' fdcanusb): a client then asks
    /// what it would ask with such a frame another way (WHJ's status query by broadcast).
    fn sends_empty_frames(&self) -> bool {
        true
    }

    /// How much later than the wire this link may deliver a frame that followed another
    /// on the wire back to back: how long after receiving the first a receiver may still
    /// be handed the second, beyond the second's own wire time. A client that waits for a
    /// second answer to one request (a WHJ duplicate check) waits one frame plus this.
    /// Each link says its own: zero where frames are handed over in wire order the
    /// instant they are complete (an in-memory bus, a simulator on virtual time), a
    /// driver's interrupt and queue on `SocketCAN`, a USB frame and an adapter's
    /// buffering on USB adapters (slcan, fdcanusb); [`DEFAULT_REPLY_ALLOWANCE`] for a
    /// link that does not say. Wrappers pass their inner link's through.
    fn reply_allowance(&self) -> Duration {
        DEFAULT_REPLY_ALLOWANCE
    }
}

/// The clock methods of a [`FrameLink`] that wraps another, forwarded to the wrapped
/// link (the field named): `now`, `sleep_until`, `virtual_time`, what the wrapped link
/// can carry (`sends_empty_frames`) and how late it delivers (`reply_allowance`). For use inside an `impl FrameLink for Wrapper`
/// block.
#[macro_export]
macro_rules! forward_frame_link_clock {
    ($field:tt) => {
        fn now(&self) -> ::std::time::Instant {
            $crate::FrameLink::now(&self.$field)
        }

        fn sleep_until(&mut self, deadline: ::std::time::Instant) {
            $crate::FrameLink::sleep_until(&mut self.$field, deadline);
        }

        fn virtual_time(&self) -> bool {
            $crate::FrameLink::virtual_time(&self.$field)
        }

        fn sends_empty_frames(&self) -> bool {
            $crate::FrameLink::sends_empty_frames(&self.$field)
        }

        fn reply_allowance(&self) -> ::core::time::Duration {
            $crate::FrameLink::reply_allowance(&self.$field)
        }
    };
}

/// `FrameLink` for a pointer to a link (`&mut T`, `Box<T>`): every method the link's own.
macro_rules! frame_link_through {
    ($($pointer:ty),+) => {$(
        impl<T: FrameLink + ?Sized> FrameLink for $pointer {
            fn send(&mut self, frame: &CanFrame) -> Result<(), FrameLinkError> {
                (**self).send(frame)
            }
            fn recv(&mut self, deadline: Instant) -> Result<Received, FrameLinkError> {
                (**self).recv(deadline)
            }
            fn set_filters(&mut self, filters: &[IdFilter]) -> Result<(), FrameLinkError> {
                (**self).set_filters(filters)
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
            fn sends_empty_frames(&self) -> bool {
                (**self).sends_empty_frames()
            }
            fn reply_allowance(&self) -> Duration {
                (**self).reply_allowance()
            }
        }
    )+};
}

frame_link_through!(&mut T, Box<T>);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn filters_match_like_socketcan() {
        let id = CanFrame::standard_id(0x215).unwrap();
        let f = CanFrame::new_fd(id, &[1, 2, 3, 4]).unwrap();
        assert!(IdFilter::standard(0x215).matches(&f));
        assert!(!IdFilter::standard(0x216).matches(&f));
        assert!(IdFilter::standard_masked(0x200, 0x700).matches(&f));
        assert!(!IdFilter::standard_masked(0x100, 0x700).matches(&f));
        assert!(!IdFilter::extended(0x215).matches(&f));
        assert!(passes(&[], &f));
        assert!(passes(
            &[IdFilter::standard(1), IdFilter::standard(0x215)],
            &f
        ));
        assert!(!passes(&[IdFilter::standard(1)], &f));
        let e = CanFrame::new_fd(CanFrame::extended_id(0x215).unwrap(), &[]).unwrap();
        assert!(IdFilter::extended(0x215).matches(&e));
        assert!(!IdFilter::standard(0x215).matches(&e));
    }
}
