//! A CAN interface's health from the kernel's own netlink data (`RTM_GETLINK`): the
//! controller's state (error-active, error-warning, error-passive, bus-off, stopped), its
//! error counters, how often it went error-passive or bus-off and was restarted, its
//! automatic restart delay, its bit rates, whether it runs CAN FD or classic CAN (a
//! misconfigured adapter: WHJ joints talk CAN FD only), and the interface's error and drop
//! counts.
//!
//! [`read`] asks the kernel over a `NETLINK_ROUTE` socket; [`parse`] reads its answer
//! (bounded: a malformed or truncated message is an error, never a panic). A virtual
//! interface (`vcan`) has no controller: its state and counters are `None`.

use std::io::{self, Read as _};
use std::time::Duration;

use socket2::{Domain, Protocol, Socket, Type};

/// A CAN controller's state (`enum can_state` of `linux/can/netlink.h`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "kebab-case"))]
pub enum ControllerState {
    /// Error counters below 96: all is well.
    ErrorActive,
    /// A counter at 96 or more.
    ErrorWarning,
    /// A counter at 128 or more: the controller sends passive error flags only.
    ErrorPassive,
    /// The transmit counter passed 255: the controller is off the bus until restarted.
    BusOff,
    /// The interface is down.
    Stopped,
    /// The controller sleeps.
    Sleeping,
    /// A value this code does not know.
    Unknown(u32),
}

impl ControllerState {
    const fn of(v: u32) -> Self {
        match v {
            0 => Self::ErrorActive,
            1 => Self::ErrorWarning,
            2 => Self::ErrorPassive,
            3 => Self::BusOff,
            4 => Self::Stopped,
            5 => Self::Sleeping,
            v => Self::Unknown(v),
        }
    }

    /// As `ip -details link` names it, in lower case: `error-active`, `bus-off`, ...
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Self::ErrorActive => "error-active",
            Self::ErrorWarning => "error-warning",
            Self::ErrorPassive => "error-passive",
            Self::BusOff => "bus-off",
            Self::Stopped => "stopped",
            Self::Sleeping => "sleeping",
            Self::Unknown(_) => "unknown",
        }
    }
}

/// How often the controller changed state or was restarted, since the interface was
/// created (`struct can_device_stats`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct CanDeviceStats {
    /// Bus errors.
    pub bus_error: u32,
    /// Changes to error-warning.
    pub error_warning: u32,
    /// Changes to error-passive.
    pub error_passive: u32,
    /// Changes to bus-off.
    pub bus_off: u32,
    /// Arbitration lost.
    pub arbitration_lost: u32,
    /// Restarts of the controller.
    pub restarts: u32,
}

/// A CAN interface's health (see the [module docs](self)).
#[derive(Debug, Clone, PartialEq, Eq, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct CanHealth {
    /// The interface.
    pub iface: String,
    /// Its link kind (`can`, `vcan`, ...), if the kernel names one.
    pub kind: Option<String>,
    /// Administratively up.
    pub up: bool,
    /// The lower layer is up (a bus-off controller has no carrier).
    pub carrier: bool,
    /// The controller's state (`None`: no controller, as on vcan).
    pub state: Option<ControllerState>,
    /// The transmit error counter, where the driver reports it.
    pub tx_errors: Option<u16>,
    /// The receive error counter, where the driver reports it.
    pub rx_errors: Option<u16>,
    /// The automatic restart delay after bus-off, ms (0: restart by hand).
    pub restart_ms: Option<u32>,
    /// The nominal bit rate, bit/s.
    pub bitrate: Option<u32>,
    /// The data bit rate (CAN FD), bit/s.
    pub data_bitrate: Option<u32>,
    /// CAN FD on (`Some(false)`: the controller runs classic CAN; `None`: no controller,
    /// as on vcan, whose MTU tells instead).
    pub fd: Option<bool>,
    /// The interface's MTU: 72 carries CAN FD frames, 16 classic ones only.
    pub mtu: Option<u32>,
    /// State changes and restarts.
    pub stats: Option<CanDeviceStats>,
    /// Frames received with errors (the interface's statistics).
    pub rx_frame_errors: Option<u64>,
    /// Frames not sent because of errors.
    pub tx_frame_errors: Option<u64>,
    /// Frames dropped on receive.
    pub rx_dropped: Option<u64>,
    /// Frames dropped on send.
    pub tx_dropped: Option<u64>,
}

impl CanHealth {
    /// Whether it carries classic CAN only: a controller with CAN FD off, or an interface
    /// without a controller whose MTU is classic CAN's (16).
    #[must_use]
    pub fn classic(&self) -> bool {
        match self.fd {
            Some(fd) => !fd,
            None => self.mtu == Some(CAN_MTU),
        }
    }

    /// What is wrong and what to do, if anything: a bus-off controller (restart it), an
    /// error-passive or -warning one (frames are failing), an interface that is down, and
    /// a classic CAN interface (WHJ joints need CAN FD: the command that sets it).
    #[must_use]
    pub fn advice(&self) -> Option<String> {
        match (self.state_advice(), self.classic_advice()) {
            (Some(s), Some(c)) => Some(format!("{s}. {c}")),
            (s, c) => s.or(c),
        }
    }

    /// What a classic CAN interface needs for WHJ joints, if it is one.
    fn classic_advice(&self) -> Option<String> {
        if !self.classic() {
            return None;
        }
        let i = &self.iface;
        Some(if self.fd.is_some() {
            format!(
                "{i} is classic CAN (CAN FD off, bitrate {}, no data phase): WHJ joints talk \
                 CAN FD only, at 1000000 / 5000000 bit/s from the factory (or the pair `whj \
                 set-rates` saved). Set it: `sudo ip link set {i} down && sudo ip link set {i} \
                 type can bitrate 1000000 sample-point 0.8 dbitrate 5000000 dsample-point \
                 0.75 fd on && sudo ip link set {i} up` (an adapter that refuses `fd on` is \
                 not a CAN FD adapter)",
                self.bitrate
                    .map_or_else(|| "not set".to_owned(), |b| b.to_string())
            )
        } else {
            format!(
                "{i} carries classic CAN frames only (MTU 16): WHJ joints talk CAN FD. Set it: \
                 `sudo ip link set {i} down && sudo ip link set {i} mtu 72 up`"
            )
        })
    }

    /// What is wrong with the controller's state or the interface's, if anything.
    fn state_advice(&self) -> Option<String> {
        let i = &self.iface;
        let counters = match (self.tx_errors, self.rx_errors) {
            (Some(tx), Some(rx)) => format!(" (transmit errors {tx}, receive errors {rx})"),
            _ => String::new(),
        };
        match self.state {
            Some(ControllerState::BusOff) => Some(format!(
                "{i} is bus-off{counters}: it sends and receives nothing until restarted. Check \
                 wiring, termination and the bit rates, then restart it: `sudo ip link set {i} \
                 type can restart` (a driver that cannot: `sudo ip link set {i} down && sudo \
                 ip link set {i} up`), or restart it by itself after bus-off: `sudo ip link \
                 set {i} down && sudo ip link set {i} type can restart-ms 100 && sudo ip link \
                 set {i} up`"
            )),
            Some(ControllerState::ErrorPassive) => Some(format!(
                "{i} is error-passive{counters}: many frames are failing. Check termination \
                 (120 Ω at each end), the bit rates and sample points of every node, and that \
                 a joint is there to acknowledge"
            )),
            Some(ControllerState::ErrorWarning) => Some(format!(
                "{i} is error-warning{counters}: frames are failing now and then (termination, \
                 bit rates, noise)"
            )),
            Some(ControllerState::Stopped) => {
                Some(format!("{i} is stopped (down): `sudo ip link set {i} up`"))
            }
            _ if !self.up => Some(format!("{i} is down: `sudo ip link set {i} up`")),
            _ => None,
        }
    }
}

/// Why the health could not be read.
#[derive(Debug, thiserror::Error)]
pub enum HealthError {
    /// The interface name is not one the kernel accepts.
    #[error("{0:?} is not an interface name (1..=15 characters, no '/', no NUL)")]
    BadName(String),
    /// The kernel has no interface of that name.
    #[error("no network interface {0}")]
    NoSuchInterface(String),
    /// The netlink socket failed.
    #[error("netlink: {0}")]
    Io(#[from] io::Error),
    /// The kernel's answer did not parse.
    #[error("netlink answer: {0}")]
    Malformed(String),
}

// netlink and rtnetlink numbers (linux/netlink.h, linux/rtnetlink.h, linux/if_link.h,
// linux/can/netlink.h).
const NETLINK_ROUTE: i32 = 0;
const AF_NETLINK: i32 = 16;
const NLMSG_ERROR: u16 = 2;
const NLMSG_DONE: u16 = 3;
const RTM_NEWLINK: u16 = 16;
const RTM_GETLINK: u16 = 18;
const NLM_F_REQUEST: u16 = 1;
const IFF_UP: u32 = 1;
const IFF_LOWER_UP: u32 = 1 << 16;
const IFLA_IFNAME: u16 = 3;
const IFLA_LINKINFO: u16 = 18;
const IFLA_STATS64: u16 = 23;
const IFLA_INFO_KIND: u16 = 1;
const IFLA_INFO_DATA: u16 = 2;
const IFLA_INFO_XSTATS: u16 = 3;
const IFLA_MTU: u16 = 4;
const IFLA_CAN_BITTIMING: u16 = 1;
const IFLA_CAN_CTRLMODE: u16 = 5;
/// `CAN_CTRLMODE_FD` in `struct can_ctrlmode`'s flags.
const CAN_CTRLMODE_FD: u32 = 0x20;
/// A classic CAN interface's MTU (`CAN_MTU`; CAN FD's is 72).
const CAN_MTU: u32 = 16;
const IFLA_CAN_STATE: u16 = 4;
const IFLA_CAN_RESTART_MS: u16 = 6;
const IFLA_CAN_BERR_COUNTER: u16 = 8;
const IFLA_CAN_DATA_BITTIMING: u16 = 9;
/// The attribute type without the nested / byte-order flags.
const NLA_TYPE_MASK: u16 = 0x3fff;
const HEADER: usize = 16;
const IFINFO: usize = 16;
/// The largest answer read (one link's attributes are a few kB).
const MAX_ANSWER: usize = 64 * 1024;

/// The request for `iface`'s link, sequence number `seq`.
fn request(iface: &str, seq: u32) -> Vec<u8> {
    let name_len = iface.len() + 1;
    let attr_len = 4 + name_len;
    let len = HEADER + IFINFO + attr_len.next_multiple_of(4);
    let mut m = Vec::with_capacity(len);
    m.extend_from_slice(&u32::try_from(len).unwrap_or(u32::MAX).to_ne_bytes());
    m.extend_from_slice(&RTM_GETLINK.to_ne_bytes());
    m.extend_from_slice(&NLM_F_REQUEST.to_ne_bytes());
    m.extend_from_slice(&seq.to_ne_bytes());
    m.extend_from_slice(&0u32.to_ne_bytes());
    // struct ifinfomsg: any family, index 0 (by name), no flags.
    m.extend_from_slice(&[0; IFINFO]);
    m.extend_from_slice(&u16::try_from(attr_len).unwrap_or(u16::MAX).to_ne_bytes());
    m.extend_from_slice(&IFLA_IFNAME.to_ne_bytes());
    m.extend_from_slice(iface.as_bytes());
    m.push(0);
    m.resize(len, 0);
    m
}

/// Reads `iface`'s health from the kernel.
///
/// # Errors
///
/// [`HealthError`]: a bad name, no such interface, the socket's error, or an answer that
/// does not parse.
pub fn read(iface: &str) -> Result<CanHealth, HealthError> {
    if iface.is_empty() || iface.len() > 15 || iface.contains(['/', '\0']) {
        return Err(HealthError::BadName(iface.to_owned()));
    }
    let socket = Socket::new(
        Domain::from(AF_NETLINK),
        Type::RAW,
        Some(Protocol::from(NETLINK_ROUTE)),
    )?;
    socket.set_read_timeout(Some(Duration::from_secs(2)))?;
    let seq = 0x726f_626f; // "robo"
    socket.send(&request(iface, seq))?;
    let mut buf = vec![0u8; MAX_ANSWER];
    // A bounded number of unrelated datagrams before the answer.
    for _ in 0..64 {
        let n = (&socket).read(&mut buf)?;
        if let Some(h) = parse(buf.get(..n).unwrap_or(&[]), seq, iface)? {
            return Ok(h);
        }
    }
    Err(HealthError::Malformed(
        "no answer to the request among 64 messages".into(),
    ))
}

fn u16_at(b: &[u8], at: usize) -> Option<u16> {
    Some(u16::from_ne_bytes(b.get(at..at + 2)?.try_into().ok()?))
}

fn u32_at(b: &[u8], at: usize) -> Option<u32> {
    Some(u32::from_ne_bytes(b.get(at..at + 4)?.try_into().ok()?))
}

fn u64_at(b: &[u8], at: usize) -> Option<u64> {
    Some(u64::from_ne_bytes(b.get(at..at + 8)?.try_into().ok()?))
}

/// The attributes in `b`: (type without flags, payload).
fn attributes(b: &[u8]) -> Result<Vec<(u16, &[u8])>, HealthError> {
    let mut out = Vec::new();
    let mut at = 0;
    while at + 4 <= b.len() {
        let len = usize::from(u16_at(b, at).unwrap_or(0));
        let kind = u16_at(b, at + 2).unwrap_or(0) & NLA_TYPE_MASK;
        if len < 4 || at + len > b.len() {
            return Err(HealthError::Malformed(format!(
                "attribute {kind} of length {len} at {at} runs past {} bytes",
                b.len()
            )));
        }
        out.push((kind, &b[at + 4..at + len]));
        at += len.next_multiple_of(4);
    }
    Ok(out)
}

/// Reads one datagram of the kernel's answer to request `seq` for `iface`: the health
/// (`Some`), or `None` for a message that is not the answer (another sequence number).
///
/// # Errors
///
/// [`HealthError::NoSuchInterface`] for the kernel's "no such device",
/// [`HealthError::Io`] for another error it returns, [`HealthError::Malformed`] for bytes
/// that do not parse.
pub fn parse(bytes: &[u8], seq: u32, iface: &str) -> Result<Option<CanHealth>, HealthError> {
    let mut at = 0;
    while at + HEADER <= bytes.len() {
        let len = u32_at(bytes, at).map_or(0, |l| l as usize);
        let kind = u16_at(bytes, at + 4).unwrap_or(0);
        let their_seq = u32_at(bytes, at + 8).unwrap_or(0);
        if len < HEADER || at + len > bytes.len() {
            return Err(HealthError::Malformed(format!(
                "message of length {len} at {at} in {} bytes",
                bytes.len()
            )));
        }
        let body = &bytes[at + HEADER..at + len];
        at += len.next_multiple_of(4);
        if their_seq != seq {
            continue;
        }
        match kind {
            NLMSG_ERROR => {
                let errno = u32_at(body, 0).map_or(0, u32::cast_signed);
                return Err(if errno == -19 {
                    HealthError::NoSuchInterface(iface.to_owned())
                } else {
                    HealthError::Io(io::Error::from_raw_os_error(-errno))
                });
            }
            NLMSG_DONE => {
                return Err(HealthError::NoSuchInterface(iface.to_owned()));
            }
            RTM_NEWLINK => return link(body, iface).map(Some),
            _ => {}
        }
    }
    Ok(None)
}

/// The health in an `RTM_NEWLINK` body (`struct ifinfomsg` and its attributes).
fn link(body: &[u8], iface: &str) -> Result<CanHealth, HealthError> {
    let flags = u32_at(body, 8)
        .ok_or_else(|| HealthError::Malformed("a link message without its header".into()))?;
    let mut h = CanHealth {
        iface: iface.to_owned(),
        up: flags & IFF_UP != 0,
        carrier: flags & IFF_LOWER_UP != 0,
        ..CanHealth::default()
    };
    for (kind, value) in attributes(body.get(IFINFO..).unwrap_or(&[]))? {
        match kind {
            IFLA_IFNAME => {
                let name = value.split(|&b| b == 0).next().unwrap_or(&[]);
                h.iface = String::from_utf8_lossy(name).into_owned();
            }
            IFLA_MTU => h.mtu = u32_at(value, 0),
            IFLA_STATS64 => {
                h.rx_frame_errors = u64_at(value, 32);
                h.tx_frame_errors = u64_at(value, 40);
                h.rx_dropped = u64_at(value, 48);
                h.tx_dropped = u64_at(value, 56);
            }
            IFLA_LINKINFO => link_info(value, &mut h)?,
            _ => {}
        }
    }
    Ok(h)
}

fn link_info(value: &[u8], h: &mut CanHealth) -> Result<(), HealthError> {
    for (kind, v) in attributes(value)? {
        match kind {
            IFLA_INFO_KIND => {
                let name = v.split(|&b| b == 0).next().unwrap_or(&[]);
                h.kind = Some(String::from_utf8_lossy(name).into_owned());
            }
            IFLA_INFO_XSTATS if v.len() >= 24 => {
                let s = |i: usize| u32_at(v, i * 4).unwrap_or(0);
                h.stats = Some(CanDeviceStats {
                    bus_error: s(0),
                    error_warning: s(1),
                    error_passive: s(2),
                    bus_off: s(3),
                    arbitration_lost: s(4),
                    restarts: s(5),
                });
            }
            IFLA_INFO_DATA => {
                for (k, d) in attributes(v)? {
                    match k {
                        IFLA_CAN_STATE => h.state = u32_at(d, 0).map(ControllerState::of),
                        IFLA_CAN_RESTART_MS => h.restart_ms = u32_at(d, 0),
                        // struct can_ctrlmode { mask, flags }: the flags are what is on.
                        IFLA_CAN_CTRLMODE => {
                            h.fd = u32_at(d, 4).map(|f| f & CAN_CTRLMODE_FD != 0);
                        }
                        IFLA_CAN_BERR_COUNTER => {
                            h.tx_errors = u16_at(d, 0);
                            h.rx_errors = u16_at(d, 2);
                        }
                        IFLA_CAN_BITTIMING => h.bitrate = u32_at(d, 0).filter(|&b| b > 0),
                        IFLA_CAN_DATA_BITTIMING => {
                            h.data_bitrate = u32_at(d, 0).filter(|&b| b > 0);
                        }
                        _ => {}
                    }
                }
            }
            _ => {}
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    fn attr(kind: u16, payload: &[u8]) -> Vec<u8> {
        let len = 4 + payload.len();
        let mut a = Vec::new();
        a.extend_from_slice(&u16::try_from(len).unwrap().to_ne_bytes());
        a.extend_from_slice(&kind.to_ne_bytes());
        a.extend_from_slice(payload);
        a.resize(len.next_multiple_of(4), 0);
        a
    }

    fn message(kind: u16, seq: u32, body: &[u8]) -> Vec<u8> {
        let len = HEADER + body.len();
        let mut m = Vec::new();
        m.extend_from_slice(&u32::try_from(len).unwrap().to_ne_bytes());
        m.extend_from_slice(&kind.to_ne_bytes());
        m.extend_from_slice(&0u16.to_ne_bytes());
        m.extend_from_slice(&seq.to_ne_bytes());
        m.extend_from_slice(&0u32.to_ne_bytes());
        m.extend_from_slice(body);
        m
    }

    /// A bus-off `can0` as the kernel describes it.
    fn bus_off_can0() -> Vec<u8> {
        let mut body = vec![0u8; IFINFO];
        body[8..12].copy_from_slice(&IFF_UP.to_ne_bytes());
        body.extend(attr(IFLA_IFNAME, b"can0\0"));
        let mut stats64 = vec![0u8; 8 * 24];
        stats64[40..48].copy_from_slice(&7u64.to_ne_bytes());
        body.extend(attr(IFLA_STATS64, &stats64));
        let mut data = attr(IFLA_CAN_STATE, &3u32.to_ne_bytes());
        data.extend(attr(IFLA_CAN_RESTART_MS, &0u32.to_ne_bytes()));
        data.extend(attr(
            IFLA_CAN_BERR_COUNTER,
            &[256u16.to_ne_bytes(), 12u16.to_ne_bytes()].concat(),
        ));
        data.extend(attr(
            IFLA_CAN_BITTIMING,
            &[1_000_000u32.to_ne_bytes(); 8].concat(),
        ));
        let xstats: Vec<u8> = [0u32, 1, 2, 1, 0, 0]
            .iter()
            .flat_map(|v| v.to_ne_bytes())
            .collect();
        let mut info = attr(IFLA_INFO_KIND, b"can\0");
        info.extend(attr(IFLA_INFO_DATA | 0x8000, &data));
        info.extend(attr(IFLA_INFO_XSTATS, &xstats));
        body.extend(attr(IFLA_LINKINFO | 0x8000, &info));
        message(RTM_NEWLINK, 9, &body)
    }

    #[test]
    fn a_bus_off_controller_is_read_with_its_counters_and_advice() {
        // Another request's answer first: skipped.
        let mut bytes = message(RTM_NEWLINK, 8, &[0; IFINFO]);
        bytes.extend(bus_off_can0());
        let h = parse(&bytes, 9, "can0").unwrap().unwrap();
        assert_eq!(h.iface, "can0");
        assert_eq!(h.kind.as_deref(), Some("can"));
        assert!(h.up && !h.carrier);
        assert_eq!(h.state, Some(ControllerState::BusOff));
        assert_eq!((h.tx_errors, h.rx_errors), (Some(256), Some(12)));
        assert_eq!((h.restart_ms, h.bitrate), (Some(0), Some(1_000_000)));
        assert_eq!(h.data_bitrate, None);
        let s = h.stats.unwrap();
        assert_eq!((s.error_warning, s.error_passive, s.bus_off), (1, 2, 1));
        assert_eq!(h.tx_frame_errors, Some(7));
        let advice = h.advice().unwrap();
        assert!(
            advice.starts_with("can0 is bus-off (transmit errors 256, receive errors 12)")
                && advice.contains("sudo ip link set can0 type can restart")
                && advice.contains("restart-ms 100"),
            "{advice}"
        );
        assert_eq!(parse(&bytes, 10, "can0").unwrap(), None);
    }

    /// An error-active `IFACE` of kind `kind`, up, with MTU `mtu`, its controller's flags
    /// (`None`: no controller data, as vcan) and bit rates.
    fn link_of(kind: &[u8], mtu: u32, ctrl_flags: Option<u32>, rates: (u32, u32)) -> Vec<u8> {
        let mut body = vec![0u8; IFINFO];
        body[8..12].copy_from_slice(&(IFF_UP | IFF_LOWER_UP).to_ne_bytes());
        body.extend(attr(IFLA_IFNAME, b"can0\0"));
        body.extend(attr(IFLA_MTU, &mtu.to_ne_bytes()));
        let mut info = attr(IFLA_INFO_KIND, kind);
        if let Some(flags) = ctrl_flags {
            let mut data = attr(IFLA_CAN_STATE, &0u32.to_ne_bytes());
            // The mask: what the driver supports (FD among them); the flags: what is on.
            data.extend(attr(
                IFLA_CAN_CTRLMODE,
                &[0x3fu32.to_ne_bytes(), flags.to_ne_bytes()].concat(),
            ));
            data.extend(attr(
                IFLA_CAN_BITTIMING,
                &[rates.0.to_ne_bytes(); 8].concat(),
            ));
            data.extend(attr(
                IFLA_CAN_DATA_BITTIMING,
                &[rates.1.to_ne_bytes(); 8].concat(),
            ));
            info.extend(attr(IFLA_INFO_DATA | 0x8000, &data));
        }
        body.extend(attr(IFLA_LINKINFO | 0x8000, &info));
        message(RTM_NEWLINK, 9, &body)
    }

    #[test]
    fn a_classic_can_interface_is_reported_as_such_with_the_can_fd_command() {
        // A CAN controller with FD off (a classic adapter, or one set up without `fd on`):
        // its nominal rate, no data phase.
        let h = parse(&link_of(b"can\0", 16, Some(0x02), (500_000, 0)), 9, "can0")
            .unwrap()
            .unwrap();
        assert_eq!(
            (h.state, h.fd, h.mtu, h.bitrate, h.data_bitrate),
            (
                Some(ControllerState::ErrorActive),
                Some(false),
                Some(16),
                Some(500_000),
                None
            )
        );
        assert!(h.classic());
        assert_eq!(
            h.advice().unwrap(),
            "can0 is classic CAN (CAN FD off, bitrate 500000, no data phase): WHJ joints talk \
             CAN FD only, at 1000000 / 5000000 bit/s from the factory (or the pair `whj \
             set-rates` saved). Set it: `sudo ip link set can0 down && sudo ip link set can0 \
             type can bitrate 1000000 sample-point 0.8 dbitrate 5000000 dsample-point 0.75 \
             fd on && sudo ip link set can0 up` (an adapter that refuses `fd on` is not a CAN \
             FD adapter)"
        );
        // The same controller with FD on: nothing to say.
        let h = parse(
            &link_of(b"can\0", 72, Some(0x22), (1_000_000, 5_000_000)),
            9,
            "can0",
        )
        .unwrap()
        .unwrap();
        assert_eq!((h.fd, h.data_bitrate), (Some(true), Some(5_000_000)));
        assert!(!h.classic());
        assert_eq!(h.advice(), None);
        // Without a controller (vcan), the MTU tells.
        let vcan = |mtu| {
            parse(&link_of(b"vcan\0", mtu, None, (0, 0)), 9, "can0")
                .unwrap()
                .unwrap()
        };
        assert!(!vcan(72).classic() && vcan(72).advice().is_none());
        let classic = vcan(16);
        assert!(classic.classic() && classic.fd.is_none());
        assert!(
            classic
                .advice()
                .unwrap()
                .contains("sudo ip link set can0 down && sudo ip link set can0 mtu 72 up"),
            "{classic:?}"
        );
    }

    #[test]
    fn the_kernel_answers_for_the_loopback_interface_and_not_for_a_missing_one() {
        // Netlink asks the kernel about its own interfaces: nothing goes on a network.
        let lo = read("lo").unwrap();
        assert_eq!((lo.iface.as_str(), lo.state, lo.stats), ("lo", None, None));
        assert!(matches!(
            read("robobus-none"),
            Err(HealthError::NoSuchInterface(i)) if i == "robobus-none"
        ));
    }

    #[test]
    fn errors_and_malformed_answers_are_errors_not_panics() {
        let enodev = message(NLMSG_ERROR, 1, &(-19i32).to_ne_bytes());
        assert!(matches!(
            parse(&enodev, 1, "can9"),
            Err(HealthError::NoSuchInterface(i)) if i == "can9"
        ));
        let eperm = message(NLMSG_ERROR, 1, &(-1i32).to_ne_bytes());
        assert!(matches!(parse(&eperm, 1, "can0"), Err(HealthError::Io(_))));
        let full = bus_off_can0();
        // Every truncation either parses to less or is refused; none panics.
        for cut in 0..full.len() {
            let mut b = full[..cut].to_vec();
            if b.len() >= 4 {
                b[..4].copy_from_slice(&u32::try_from(cut).unwrap().to_ne_bytes());
            }
            let _ = parse(&b, 9, "can0");
        }
        let mut bad = full.clone();
        // An attribute claiming more than there is.
        bad[HEADER + IFINFO] = 0xff;
        assert!(matches!(
            parse(&bad, 9, "can0"),
            Err(HealthError::Malformed(_))
        ));
        for name in ["", "a/b", "a-name-longer-than-15"] {
            assert!(matches!(read(name), Err(HealthError::BadName(_))));
        }
        // A vcan-like link: no controller, no advice while up.
        let mut body = vec![0u8; IFINFO];
        body[8..12].copy_from_slice(&(IFF_UP | IFF_LOWER_UP).to_ne_bytes());
        body.extend(attr(
            IFLA_LINKINFO | 0x8000,
            &attr(IFLA_INFO_KIND, b"vcan\0"),
        ));
        let h = parse(&message(RTM_NEWLINK, 3, &body), 3, "vcan0")
            .unwrap()
            .unwrap();
        assert_eq!(
            (h.kind.as_deref(), h.state, h.advice()),
            (Some("vcan"), None, None)
        );
    }
}
