//! Bus addresses: the one way to turn a user's `--bus` value into a CAN FD frame link.
//!
//! Syntax ([`FrameLinkSpec`]'s `FromStr`):
//!
//! - `udp`: python-can's `udp_multicast` bus on its default group and port
//!   (239.74.163.2:43113), loopback only;
//! - `udp:GROUP:PORT`: the same on another multicast group (224.0.0.0/4) and port 1..=65535;
//! - `slcan:PORT[@BAUD]`: an `slcan` CAN FD adapter (`CANable` 2.0 class) on a serial port
//!   (`/dev/ttyACM0`, `COM8`) or a TCP one (`socket://127.0.0.1:5601`), see
//!   [`crate::PortSpec`]; `BAUD` is the serial line's rate (default 115200; a USB adapter
//!   ignores it);
//! - `fdcanusb:PORT`: mjbots' fdcanusb (its text line protocol over USB CDC) on a serial
//!   port or a TCP one, the same port forms;
//! - anything else: a `SocketCAN` interface name (1..=15 characters, no `/`, `:` or space),
//!   such as `can0` or `vcan0`.
//!
//! ```
//! use robobus_link::FrameLinkSpec;
//! let spec: FrameLinkSpec = "udp:239.1.2.3:5000".parse()?;
//! assert_eq!(spec.to_string(), "udp:239.1.2.3:5000");
//! assert_eq!("vcan0".parse::<FrameLinkSpec>()?, FrameLinkSpec::SocketCan("vcan0".into()));
//! assert!("udp:10.0.0.1:5000".parse::<FrameLinkSpec>().is_err());
//! # Ok::<(), robobus_link::SpecError>(())
//! ```

use std::fmt;
use std::net::Ipv4Addr;
use std::str::FromStr;

use crate::adapter::{AdapterError, AdapterErrorKind};
use crate::byte::LinkError;
use crate::frame_link::{FrameLink, FrameLinkError};
use crate::port::PortSpec;

/// Where a CAN FD bus is: the python-can compatible UDP multicast bus or a `SocketCAN`
/// interface.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum FrameLinkSpec {
    /// python-can `udp_multicast` on this group and port (loopback only).
    Udp {
        /// Multicast group.
        group: Ipv4Addr,
        /// UDP port.
        port: u16,
    },
    /// A `SocketCAN` interface (`can0`, `vcan0`).
    SocketCan(String),
    /// An slcan CAN FD adapter on a serial or TCP port.
    Slcan {
        /// The port.
        port: PortSpec,
        /// The serial line's rate (`None`: [`SLCAN_DEFAULT_BAUD`]).
        baud: Option<u32>,
    },
    /// mjbots' fdcanusb on a serial or TCP port.
    Fdcanusb {
        /// The port.
        port: PortSpec,
    },
}

/// The serial line rate an fdcanusb's port is opened at (its USB CDC port ignores it).
pub const FDCANUSB_BAUD: u32 = 115_200;

/// The serial line rate an slcan adapter is opened at unless `@BAUD` says otherwise
/// (python-can's default; a USB CDC adapter ignores it).
pub const SLCAN_DEFAULT_BAUD: u32 = 115_200;
/// The serial line rates `@BAUD` accepts.
pub const SLCAN_BAUDS: core::ops::RangeInclusive<u32> = 300..=12_000_000;

/// A bus address that does not parse; the message names the value and the syntax.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("bus {value:?}: {reason}")]
pub struct SpecError {
    /// The address as given (at most its first 64 characters).
    pub value: String,
    /// What is wrong and what is allowed.
    pub reason: String,
}

/// A bus that cannot be opened.
#[derive(Debug, thiserror::Error)]
pub enum OpenError {
    /// The `SocketCAN` interface does not exist or cannot be opened (like a serial port
    /// that is not there: no device).
    #[error("opening SocketCAN interface {iface}: {source}")]
    NoInterface {
        /// The interface.
        iface: String,
        /// Why.
        source: FrameLinkError,
    },
    /// The UDP bus cannot be joined.
    #[error("joining the UDP bus {group}:{port}: {source}")]
    Udp {
        /// Multicast group.
        group: Ipv4Addr,
        /// Port.
        port: u16,
        /// Why.
        source: FrameLinkError,
    },
    /// This kind of bus does not exist on this operating system.
    #[error("{0}")]
    Unsupported(String),
    /// The port of a serial-line adapter cannot be opened.
    #[error("opening the adapter's port {port}: {source}")]
    Port {
        /// The port as given.
        port: String,
        /// Why.
        source: LinkError,
    },
    /// A serial-line adapter that does not answer, answers garbage, refuses its setup or
    /// cannot be set to the bus's rates.
    #[error(transparent)]
    Adapter(#[from] AdapterError),
}

impl OpenError {
    /// The adapter failure's kind, for an [`OpenError::Adapter`].
    pub const fn adapter_kind(&self) -> Option<AdapterErrorKind> {
        match self {
            Self::Adapter(e) => Some(e.kind),
            _ => None,
        }
    }
}

/// python-can's default `udp_multicast` group.
const DEFAULT_GROUP: Ipv4Addr = Ipv4Addr::new(239, 74, 163, 2);
/// python-can's default `udp_multicast` port.
const DEFAULT_PORT: u16 = 43113;

impl FrameLinkSpec {
    /// The default UDP bus (`udp`).
    pub const fn default_udp() -> Self {
        Self::Udp {
            group: DEFAULT_GROUP,
            port: DEFAULT_PORT,
        }
    }

    /// A human description: `udp_multicast 239.74.163.2:43113`, `SocketCAN vcan0`.
    pub fn describe(&self) -> String {
        match self {
            Self::Udp { group, port } => format!("udp_multicast {group}:{port}"),
            Self::SocketCan(iface) => format!("SocketCAN {iface}"),
            Self::Slcan { port, .. } => format!("slcan adapter on {}", port.describe()),
            Self::Fdcanusb { port } => format!("fdcanusb on {}", port.describe()),
        }
    }

    /// The interface name a candump log of this bus carries: the `SocketCAN` interface,
    /// or `udp` for the UDP bus.
    pub fn candump_iface(&self) -> &str {
        match self {
            Self::SocketCan(iface) => iface,
            Self::Udp { .. } => "udp",
            Self::Slcan { .. } => "slcan",
            Self::Fdcanusb { .. } => "fdcanusb",
        }
    }

    /// Opens the link.
    ///
    /// # Errors
    /// [`OpenError`] naming the interface or group.
    pub fn open(&self) -> Result<Box<dyn FrameLink + Send>, OpenError> {
        match self {
            #[cfg(any(unix, windows))]
            Self::Udp { group, port } => {
                let cfg = crate::udp::UdpBusConfig {
                    group: *group,
                    port: *port,
                    ..crate::udp::UdpBusConfig::default()
                };
                crate::udp::UdpBus::open(&cfg)
                    .map(|l| Box::new(l) as Box<dyn FrameLink + Send>)
                    .map_err(|source| OpenError::Udp {
                        group: *group,
                        port: *port,
                        source,
                    })
            }
            #[cfg(not(any(unix, windows)))]
            Self::Udp { .. } => Err(OpenError::Unsupported(
                "the UDP multicast bus needs a Unix or Windows host".into(),
            )),
            #[cfg(target_os = "linux")]
            Self::SocketCan(iface) => crate::socketcan::SocketCanLink::open(iface)
                .map(|l| Box::new(l) as Box<dyn FrameLink + Send>)
                .map_err(|source| OpenError::NoInterface {
                    iface: iface.clone(),
                    source,
                }),
            #[cfg(not(target_os = "linux"))]
            Self::SocketCan(iface) => Err(OpenError::Unsupported(format!(
                "SocketCAN interface {iface}: SocketCAN exists on Linux only; use --bus udp"
            ))),
            Self::Slcan { port, baud } => {
                let name = port.to_string();
                let link = port
                    .open(baud.unwrap_or(SLCAN_DEFAULT_BAUD))
                    .map_err(|source| OpenError::Port {
                        port: name.clone(),
                        source,
                    })?;
                crate::slcan::SlcanLink::open(link, &name, &crate::slcan::SlcanConfig::default())
                    .map(|l| Box::new(l) as Box<dyn FrameLink + Send>)
                    .map_err(OpenError::Adapter)
            }
            Self::Fdcanusb { port } => {
                let name = port.to_string();
                let link = port.open(FDCANUSB_BAUD).map_err(|source| OpenError::Port {
                    port: name.clone(),
                    source,
                })?;
                crate::fdcanusb::FdcanusbLink::open(
                    link,
                    &name,
                    crate::fdcanusb::FdcanusbConfig::default(),
                )
                .map(|l| Box::new(l) as Box<dyn FrameLink + Send>)
                .map_err(OpenError::Adapter)
            }
        }
    }
}

impl fmt::Display for FrameLinkSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Udp { group, port } if *group == DEFAULT_GROUP && *port == DEFAULT_PORT => {
                f.write_str("udp")
            }
            Self::Udp { group, port } => write!(f, "udp:{group}:{port}"),
            Self::SocketCan(iface) => f.write_str(iface),
            Self::Slcan { port, baud: None } => write!(f, "slcan:{port}"),
            Self::Slcan {
                port,
                baud: Some(baud),
            } => write!(f, "slcan:{port}@{baud}"),
            Self::Fdcanusb { port } => write!(f, "fdcanusb:{port}"),
        }
    }
}

impl FromStr for FrameLinkSpec {
    type Err = SpecError;

    fn from_str(s: &str) -> Result<Self, SpecError> {
        let err = |reason: String| SpecError {
            value: s.chars().take(64).collect(),
            reason,
        };
        if s == "udp" {
            return Ok(Self::default_udp());
        }
        if let Some(rest) = s.strip_prefix("udp:") {
            let (group, port) = rest.rsplit_once(':').ok_or_else(|| {
                err("expected udp:GROUP:PORT, e.g. udp:239.74.163.2:43113".into())
            })?;
            let group: Ipv4Addr = group
                .parse()
                .map_err(|_| err(format!("{:?} is not an IPv4 address", short(group))))?;
            if !group.is_multicast() {
                return Err(err(format!(
                    "{group} is not a multicast group (allowed: 224.0.0.0/4)"
                )));
            }
            let port: u16 = port.parse().map_err(|_| {
                err(format!(
                    "port {:?} is not a number (allowed: 1..=65535)",
                    short(port)
                ))
            })?;
            if port == 0 {
                return Err(err("port 0 (allowed: 1..=65535)".into()));
            }
            return Ok(Self::Udp { group, port });
        }
        if let Some(rest) = s.strip_prefix("slcan:") {
            return parse_slcan(rest).map_err(err);
        }
        if let Some(port) = s.strip_prefix("fdcanusb:") {
            if port.is_empty() {
                return Err(err("expected fdcanusb:PORT, e.g. fdcanusb:/dev/ttyACM0, \
                                fdcanusb:COM8 or fdcanusb:socket://127.0.0.1:5602"
                    .into()));
            }
            let port = port.parse::<PortSpec>().map_err(|e| err(e.to_string()))?;
            return Ok(Self::Fdcanusb { port });
        }
        if s.is_empty() || s.len() > 15 || s.contains(['/', ' ', ':']) {
            return Err(err(
                "expected udp, udp:GROUP:PORT, slcan:PORT[@BAUD] or fdcanusb:PORT (e.g. \
                 slcan:COM8, fdcanusb:/dev/ttyACM0), or a SocketCAN interface such as vcan0 \
                 (1..=15 characters, no '/', ':' or space)"
                    .into(),
            ));
        }
        Ok(Self::SocketCan(s.to_owned()))
    }
}

/// `PORT[@BAUD]` of `slcan:PORT[@BAUD]`.
fn parse_slcan(rest: &str) -> Result<FrameLinkSpec, String> {
    let (port, baud) = match rest.rsplit_once('@') {
        Some((port, baud)) => {
            let baud = baud
                .parse::<u32>()
                .ok()
                .filter(|b| SLCAN_BAUDS.contains(b))
                .ok_or_else(|| {
                    format!(
                        "serial rate {:?} is not a number in {}..={} (slcan:PORT[@BAUD], e.g. \
                         slcan:/dev/ttyACM0@115200)",
                        short(baud),
                        SLCAN_BAUDS.start(),
                        SLCAN_BAUDS.end()
                    )
                })?;
            (port, Some(baud))
        }
        None => (rest, None),
    };
    if port.is_empty() {
        return Err(
            "expected slcan:PORT[@BAUD], e.g. slcan:/dev/ttyACM0, slcan:COM8 or \
                    slcan:socket://127.0.0.1:5601"
                .into(),
        );
    }
    let port = port.parse::<PortSpec>().map_err(|e| e.to_string())?;
    Ok(FrameLinkSpec::Slcan { port, baud })
}

/// At most 32 characters of a user's text, for messages.
fn short(s: &str) -> String {
    s.chars().take(32).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_every_form_and_refuses_the_rest() {
        assert_eq!("udp".parse(), Ok(FrameLinkSpec::default_udp()));
        assert_eq!(
            "udp:239.1.2.3:5000".parse(),
            Ok(FrameLinkSpec::Udp {
                group: Ipv4Addr::new(239, 1, 2, 3),
                port: 5000
            })
        );
        let e = "udp:10.0.0.1:5000".parse::<FrameLinkSpec>().unwrap_err();
        assert!(e.to_string().contains("224.0.0.0/4"), "{e}");
        assert!("udp:239.1.2.3".parse::<FrameLinkSpec>().is_err());
        assert!("udp:239.1.2.3:0".parse::<FrameLinkSpec>().is_err());
        assert_eq!(
            "vcan0".parse(),
            Ok(FrameLinkSpec::SocketCan("vcan0".into()))
        );
        assert!("a/b".parse::<FrameLinkSpec>().is_err());
        let long = "x".repeat(65_536);
        let e = long.parse::<FrameLinkSpec>().unwrap_err();
        assert!(e.to_string().len() < 300);
        for s in ["udp", "udp:239.1.2.3:5000", "can0"] {
            assert_eq!(s.parse::<FrameLinkSpec>().unwrap().to_string(), s);
        }
    }

    #[test]
    fn slcan_addresses_parse_print_back_and_bad_ones_name_the_syntax() {
        assert_eq!(
            "slcan:/dev/ttyACM0".parse(),
            Ok(FrameLinkSpec::Slcan {
                port: PortSpec::Device("/dev/ttyACM0".into()),
                baud: None
            })
        );
        assert_eq!(
            "slcan:COM8@921600".parse(),
            Ok(FrameLinkSpec::Slcan {
                port: PortSpec::Com(8),
                baud: Some(921_600)
            })
        );
        for s in [
            "slcan:/dev/ttyACM0",
            "slcan:COM8",
            "slcan:COM8@921600",
            "slcan:socket://127.0.0.1:5601",
            "slcan:socket://127.0.0.1:5601@115200",
        ] {
            let spec = s.parse::<FrameLinkSpec>().unwrap();
            assert_eq!(spec.to_string(), s);
            assert_eq!(spec.candump_iface(), "slcan");
        }
        assert_eq!(
            "slcan:COM8".parse::<FrameLinkSpec>().unwrap().describe(),
            "slcan adapter on serial port COM8"
        );
        for (bad, says) in [
            ("slcan:", "expected slcan:PORT[@BAUD]"),
            (
                "slcan:COM8@fast",
                "serial rate \"fast\" is not a number in 300..=12000000",
            ),
            ("slcan:COM8@0", "is not a number in 300..=12000000"),
            ("slcan:socket://127.0.0.1", "port \"socket://127.0.0.1\""),
            ("foo:/dev/ttyACM0", "slcan:PORT[@BAUD]"),
        ] {
            let e = bad.parse::<FrameLinkSpec>().unwrap_err().to_string();
            assert!(e.contains(says), "{bad}: {e}");
        }
    }

    #[test]
    fn fdcanusb_addresses_parse_print_back_and_bad_ones_name_the_syntax() {
        assert_eq!(
            "fdcanusb:/dev/ttyACM0".parse(),
            Ok(FrameLinkSpec::Fdcanusb {
                port: PortSpec::Device("/dev/ttyACM0".into()),
            })
        );
        assert_eq!(
            "fdcanusb:COM8".parse(),
            Ok(FrameLinkSpec::Fdcanusb {
                port: PortSpec::Com(8)
            })
        );
        for s in [
            "fdcanusb:/dev/ttyACM0",
            "fdcanusb:COM8",
            "fdcanusb:socket://127.0.0.1:5602",
        ] {
            let spec = s.parse::<FrameLinkSpec>().unwrap();
            assert_eq!(spec.to_string(), s);
            assert_eq!(spec.candump_iface(), "fdcanusb");
        }
        assert_eq!(
            "fdcanusb:COM8".parse::<FrameLinkSpec>().unwrap().describe(),
            "fdcanusb on serial port COM8"
        );
        for (bad, says) in [
            ("fdcanusb:", "expected fdcanusb:PORT"),
            ("fdcanusb:socket://127.0.0.1", "port \"socket://127.0.0.1\""),
            ("fdcan:/dev/ttyACM0", "or fdcanusb:PORT (e.g."),
        ] {
            let e = bad.parse::<FrameLinkSpec>().unwrap_err().to_string();
            assert!(e.contains(says), "{bad}: {e}");
        }
    }
}
