//! Linux `SocketCAN`, CAN FD, through the `socketcan` crate.
//!
//! Opening checks the interface before touching a socket, so every failure says what to
//! fix: no such interface (and whether the kernel has CAN support at all), not a CAN
//! interface, not CAN FD capable (MTU 72 needed), or no `AF_CAN` in this kernel. The socket
//! receives CAN FD and classic frames, kernel timestamps (`SO_TIMESTAMPNS`) and error
//! frames; bus-off and error-passive reports come back from [`FrameLink::recv`] as
//! [`FrameLinkError::BusOff`] / [`FrameLinkError::ErrorPassive`].
//!
//! Kernels without CAN (like the development machines) can still run the real thing under
//! User-Mode Linux: `scripts/uml/ensure-uml` and `scripts/uml/run-in-uml` boot one with a CAN FD
//! `vcan0`.

pub mod health;

use std::io;
use std::path::Path;
use std::time::{Duration, Instant};

use robobus_whj::frame::CanFrame;
use socketcan::id::FdFlags;
use socketcan::{
    CanAnyFrame, CanDataFrame, CanFdFrame, CanFilter, EmbeddedFrame, Socket, SocketOptions,
};

use crate::frame_link::{BusErrorKind, FrameLink, FrameLinkError, IdFilter, Received, passes};

/// `ARPHRD_CAN`, the link type of CAN interfaces in `/sys/class/net/<iface>/type`.
const ARPHRD_CAN: u32 = 280;
/// MTU of a CAN FD interface (`sizeof(struct canfd_frame)`).
const CANFD_MTU: u32 = 72;
/// MTU range of a CAN XL interface (`CANXL_MIN_MTU..=CANXL_MAX_MTU`); these carry CAN FD
/// frames too (vcan on kernels with CAN XL defaults to 2060).
const CANXL_MTUS: std::ops::RangeInclusive<u32> = 76..=2060;
/// How long a send may wait for room in the socket's send queue before it fails.
const SEND_TIMEOUT: Duration = Duration::from_secs(1);
/// Linux's `AF_CAN`.
const AF_CAN: i32 = 29;
/// Linux's `CAN_RAW` protocol.
const CAN_RAW: i32 = 1;
const CAN_EFF_FLAG: u32 = 0x8000_0000;
const CAN_RTR_FLAG: u32 = 0x4000_0000;

// SocketCAN error classes (linux/can/error.h) and controller status bits (data[1]).
const CAN_ERR_CRTL: u32 = 0x0004;
const CAN_ERR_ACK: u32 = 0x0020;
const CAN_ERR_BUSOFF: u32 = 0x0040;
const CAN_ERR_RESTARTED: u32 = 0x0100;
const CAN_ERR_CRTL_RX_WARNING: u8 = 0x04;
const CAN_ERR_CRTL_TX_WARNING: u8 = 0x08;
const CAN_ERR_CRTL_RX_PASSIVE: u8 = 0x10;
const CAN_ERR_CRTL_TX_PASSIVE: u8 = 0x20;

/// What a `SocketCAN` error frame reports, from its error class bits (`can_id & CAN_ERR_MASK`)
/// and data (`linux/can/error.h`). Bus-off wins over error-passive over warnings.
pub fn classify_error_frame(class: u32, data: &[u8]) -> BusErrorKind {
    let ctrl = data.get(1).copied().unwrap_or(0);
    if class & CAN_ERR_BUSOFF != 0 {
        BusErrorKind::BusOff
    } else if class & CAN_ERR_CRTL != 0
        && ctrl & (CAN_ERR_CRTL_RX_PASSIVE | CAN_ERR_CRTL_TX_PASSIVE) != 0
    {
        BusErrorKind::ErrorPassive
    } else if class & CAN_ERR_CRTL != 0
        && ctrl & (CAN_ERR_CRTL_RX_WARNING | CAN_ERR_CRTL_TX_WARNING) != 0
    {
        BusErrorKind::ErrorWarning
    } else if class & CAN_ERR_RESTARTED != 0 {
        BusErrorKind::Restarted
    } else if class & CAN_ERR_ACK != 0 {
        BusErrorKind::NoAck
    } else {
        BusErrorKind::Other { class }
    }
}

/// Whether this kernel supports `AF_CAN` sockets (`false` when `socket(AF_CAN)` fails with
/// EAFNOSUPPORT).
pub fn kernel_has_can() -> bool {
    use socket2::{Domain, Protocol, Socket as RawSocket, Type};
    match RawSocket::new(
        Domain::from(AF_CAN),
        Type::RAW,
        Some(Protocol::from(CAN_RAW)),
    ) {
        Ok(_) => true,
        Err(e) => e.raw_os_error() != Some(nix::errno::Errno::EAFNOSUPPORT as i32),
    }
}

fn read_sysfs_u32(path: &Path) -> Option<u32> {
    std::fs::read_to_string(path).ok()?.trim().parse().ok()
}

/// Checks `iface` in sysfs under `net_dir` (normally `/sys/class/net`): it must exist, be
/// a CAN interface and have a CAN FD MTU (72, or a CAN XL MTU, which carries FD too).
pub fn check_interface_at(net_dir: &Path, iface: &str) -> Result<(), FrameLinkError> {
    let bad_name = iface.is_empty() || iface.len() > 15 || iface.contains(['/', ' ']);
    let dir = net_dir.join(iface);
    if bad_name || !dir.exists() {
        return Err(FrameLinkError::NoSuchInterface {
            iface: iface.to_owned(),
            hint: "; create a virtual one with `ip link add dev vcan0 type vcan && ip link set vcan0 mtu 72 up`".to_owned(),
        });
    }
    if let Some(link_type) = read_sysfs_u32(&dir.join("type"))
        && link_type != ARPHRD_CAN
    {
        return Err(FrameLinkError::NotCan {
            iface: iface.to_owned(),
            link_type,
        });
    }
    if let Some(mtu) = read_sysfs_u32(&dir.join("mtu"))
        && mtu != CANFD_MTU
        && !CANXL_MTUS.contains(&mtu)
    {
        return Err(FrameLinkError::NotFdCapable {
            iface: iface.to_owned(),
            mtu,
        });
    }
    Ok(())
}

/// A CAN FD raw socket bound to one interface.
#[derive(Debug)]
pub struct SocketCanLink {
    socket: socketcan::CanFdSocket,
    iface: String,
    filters: Vec<IdFilter>,
}

impl SocketCanLink {
    /// Opens `iface` (e.g. `can0`, `vcan0`) for CAN FD, with error frames and timestamps.
    pub fn open(iface: &str) -> Result<Self, FrameLinkError> {
        // On a kernel without SocketCAN no CAN interface can exist: say that, not that
        // this one is missing.
        if !kernel_has_can() {
            return Err(FrameLinkError::NoCanSupport {
                iface: iface.to_owned(),
            });
        }
        check_interface_at(Path::new("/sys/class/net"), iface)?;
        let socket = socketcan::CanFdSocket::open(iface).map_err(|e| open_error(iface, e))?;
        let ctx = |what: &str| format!("configuring CAN socket on {iface}: {what}");
        socket
            .set_error_filter_accept_all()
            .map_err(|e| FrameLinkError::io(ctx("error frames"), e))?;
        socket
            .set_recv_timestamp(true)
            .map_err(|e| FrameLinkError::io(ctx("timestamps"), e))?;
        // Non-blocking: `recv` waits with `ppoll` up to the exact deadline. `SO_RCVTIMEO`
        // (what a blocking read with a timeout uses) is rounded up to whole kernel ticks,
        // which made every reply one to two ticks late (4-8 ms on a HZ=250 host, 12-20 ms
        // in User-Mode Linux).
        socket
            .set_nonblocking(true)
            .map_err(|e| FrameLinkError::io(ctx("non-blocking mode"), e))?;
        Ok(Self {
            socket,
            iface: iface.to_owned(),
            filters: Vec::new(),
        })
    }

    /// The interface name.
    pub fn iface(&self) -> &str {
        &self.iface
    }

    fn bus_error(&self, kind: BusErrorKind) -> FrameLinkError {
        let iface = self.iface.clone();
        match kind {
            BusErrorKind::BusOff => FrameLinkError::BusOff { iface },
            BusErrorKind::ErrorPassive => FrameLinkError::ErrorPassive { iface },
            kind => FrameLinkError::BusError { iface, kind },
        }
    }
}

fn open_error(iface: &str, e: io::Error) -> FrameLinkError {
    match e.raw_os_error() {
        Some(code) if code == nix::errno::Errno::EAFNOSUPPORT as i32 => {
            FrameLinkError::NoCanSupport {
                iface: iface.to_owned(),
            }
        }
        Some(code) if code == nix::errno::Errno::ENODEV as i32 => FrameLinkError::NoSuchInterface {
            iface: iface.to_owned(),
            hint: String::new(),
        },
        _ => FrameLinkError::io(format!("opening CAN interface {iface}"), e),
    }
}

fn to_socketcan(frame: &CanFrame) -> Option<CanAnyFrame> {
    if frame.is_fd() {
        let mut flags = FdFlags::empty();
        if frame.brs() {
            flags |= FdFlags::BRS;
        }
        if frame.esi() {
            flags |= FdFlags::ESI;
        }
        CanFdFrame::with_flags(frame.id(), frame.data(), flags).map(CanAnyFrame::Fd)
    } else {
        CanDataFrame::new(frame.id(), frame.data()).map(CanAnyFrame::Normal)
    }
}

impl FrameLink for SocketCanLink {
    fn send(&mut self, frame: &CanFrame) -> Result<(), FrameLinkError> {
        let out = to_socketcan(frame).ok_or_else(|| FrameLinkError::Unsendable {
            context: self.iface.clone(),
            reason: format!("socketcan refused {frame:?}"),
        })?;
        let deadline = Instant::now() + SEND_TIMEOUT;
        loop {
            match self.socket.write_frame(&out) {
                Ok(()) => return Ok(()),
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => {
                    let writable =
                        crate::pty::wait_for(&self.socket, nix::poll::PollFlags::POLLOUT, deadline)
                            .map_err(|e| {
                                FrameLinkError::io(format!("waiting to send on {}", self.iface), e)
                            })?;
                    if !writable {
                        return Err(FrameLinkError::io(format!("sending on {}", self.iface), e));
                    }
                }
                Err(e) => return Err(FrameLinkError::io(format!("sending on {}", self.iface), e)),
            }
        }
    }

    fn recv(&mut self, deadline: Instant) -> Result<Received, FrameLinkError> {
        loop {
            // Wait in `ppoll` until a frame is queued or the exact deadline (a deadline in
            // the past still takes a frame that is already there). Polling first costs one
            // system call less than a read that fails with EAGAIN when nothing is queued,
            // the usual case for a request / reply exchange.
            let readable = crate::pty::wait_readable(&self.socket, deadline)
                .map_err(|e| FrameLinkError::io(format!("waiting on {}", self.iface), e))?;
            if !readable {
                return Err(FrameLinkError::Timeout);
            }
            let (any, ts) = match self.socket.read_frame_with_timestamp() {
                Ok(x) => x,
                Err(e)
                    if matches!(
                        e.kind(),
                        io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut
                    ) =>
                {
                    continue;
                }
                Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                Err(e) => {
                    return Err(FrameLinkError::io(
                        format!("receiving on {}", self.iface),
                        e,
                    ));
                }
            };
            let frame = match any {
                CanAnyFrame::Fd(f) => CanFrame::new_fd(f.id(), f.data())
                    .map(|c| c.with_brs(f.is_brs()).with_esi(f.is_esi())),
                CanAnyFrame::Normal(f) => CanFrame::new_classic(f.id(), f.data()),
                CanAnyFrame::Remote(_) => continue,
                CanAnyFrame::Error(e) => {
                    return Err(self.bus_error(classify_error_frame(e.error_bits(), e.data())));
                }
            };
            match frame {
                Ok(frame) if passes(&self.filters, &frame) => {
                    return Ok(Received {
                        frame,
                        timestamp: Some(ts),
                    });
                }
                Ok(_) => {}
                Err(e) => tracing::warn!(iface = %self.iface, error = %e, "skipping frame"),
            }
        }
    }

    /// 50 µs: the controller's receive interrupt and the kernel's receive queue, which
    /// hands frames over in wire order (stamped by the kernel as they come).
    fn reply_allowance(&self) -> Duration {
        Duration::from_micros(50)
    }

    fn set_filters(&mut self, filters: &[IdFilter]) -> Result<(), FrameLinkError> {
        let result = if filters.is_empty() {
            self.socket.set_filter_accept_all()
        } else {
            let kernel: Vec<CanFilter> = filters
                .iter()
                .map(|f| {
                    let eff = if f.extended { CAN_EFF_FLAG } else { 0 };
                    CanFilter::new(f.id | eff, f.mask | CAN_EFF_FLAG | CAN_RTR_FLAG)
                })
                .collect();
            self.socket.set_filters(&kernel)
        };
        result.map_err(|e| FrameLinkError::io(format!("setting filters on {}", self.iface), e))?;
        self.filters = filters.to_vec();
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn error_frames_map_to_controller_states() {
        assert_eq!(
            classify_error_frame(CAN_ERR_BUSOFF, &[]),
            BusErrorKind::BusOff
        );
        assert_eq!(
            classify_error_frame(CAN_ERR_BUSOFF | CAN_ERR_CRTL, &[0, CAN_ERR_CRTL_TX_PASSIVE]),
            BusErrorKind::BusOff
        );
        assert_eq!(
            classify_error_frame(CAN_ERR_CRTL, &[0, CAN_ERR_CRTL_RX_PASSIVE]),
            BusErrorKind::ErrorPassive
        );
        assert_eq!(
            classify_error_frame(CAN_ERR_CRTL, &[0, CAN_ERR_CRTL_TX_WARNING]),
            BusErrorKind::ErrorWarning
        );
        assert_eq!(
            classify_error_frame(CAN_ERR_RESTARTED, &[]),
            BusErrorKind::Restarted
        );
        assert_eq!(classify_error_frame(CAN_ERR_ACK, &[]), BusErrorKind::NoAck);
        assert_eq!(
            classify_error_frame(0x02, &[]),
            BusErrorKind::Other { class: 0x02 }
        );
        // Truncated data never panics.
        assert_eq!(
            classify_error_frame(CAN_ERR_CRTL, &[]),
            BusErrorKind::Other {
                class: CAN_ERR_CRTL
            }
        );
    }

    #[test]
    fn interface_checks_name_the_interface_and_the_fix() {
        let dir = tempfile::tempdir().unwrap();
        let net = dir.path();
        for (name, ty, mtu) in [
            ("vcan0", "280", "72"),
            ("vcan1", "280", "16"),
            ("eth0", "1", "1500"),
            ("vcan2", "280", "2060"),
        ] {
            std::fs::create_dir(net.join(name)).unwrap();
            std::fs::write(net.join(name).join("type"), format!("{ty}\n")).unwrap();
            std::fs::write(net.join(name).join("mtu"), format!("{mtu}\n")).unwrap();
        }
        check_interface_at(net, "vcan0").unwrap();
        check_interface_at(net, "vcan2").unwrap();
        let e = check_interface_at(net, "vcan1").unwrap_err();
        assert!(matches!(&e, FrameLinkError::NotFdCapable { iface, mtu: 16 } if iface == "vcan1"));
        assert!(e.to_string().contains("mtu 72"), "{e}");
        let e = check_interface_at(net, "eth0").unwrap_err();
        assert!(matches!(&e, FrameLinkError::NotCan { iface, link_type: 1 } if iface == "eth0"));
        let e = check_interface_at(net, "can7").unwrap_err();
        assert!(matches!(&e, FrameLinkError::NoSuchInterface { iface, .. } if iface == "can7"));
        assert!(e.to_string().contains("can7"));
        assert!(check_interface_at(net, "../etc").is_err());
    }

    #[test]
    fn os_errors_on_open_are_named() {
        let e = open_error(
            "vcan0",
            io::Error::from_raw_os_error(nix::errno::Errno::EAFNOSUPPORT as i32),
        );
        assert!(matches!(&e, FrameLinkError::NoCanSupport { iface } if iface == "vcan0"));
        assert!(e.to_string().contains("EAFNOSUPPORT") && e.to_string().contains("vcan0"));
        let e = open_error(
            "can3",
            io::Error::from_raw_os_error(nix::errno::Errno::ENODEV as i32),
        );
        assert!(matches!(&e, FrameLinkError::NoSuchInterface { iface, .. } if iface == "can3"));
    }

    #[test]
    fn opening_a_missing_interface_on_this_machine_is_a_clear_error() {
        let e = SocketCanLink::open("robobus-nope0").unwrap_err();
        let text = e.to_string();
        assert!(text.contains("robobus-nope0"), "{text}");
        // Which error depends on the kernel: without SocketCAN no interface can exist.
        if kernel_has_can() {
            assert!(
                matches!(&e, FrameLinkError::NoSuchInterface { iface, .. } if iface == "robobus-nope0")
            );
            assert!(text.contains("ip link"), "{text}");
        } else {
            assert!(
                matches!(&e, FrameLinkError::NoCanSupport { iface } if iface == "robobus-nope0")
            );
            assert!(text.contains("EAFNOSUPPORT"), "{text}");
        }
    }
}
