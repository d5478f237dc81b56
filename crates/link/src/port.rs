//! Port addresses: the one way to turn a user's `--port` value into a byte link.
//!
//! Syntax ([`PortSpec`]'s `FromStr`):
//!
//! - `socket://HOST:PORT`: a TCP connection (pyserial's convention), for a simulator that
//!   serves its bus over TCP (`robobus sim wck --listen 127.0.0.1:5600`) or a serial
//!   server. `HOST` is an IPv4 address, an IPv6 address in brackets (`[::1]`) or a host
//!   name; `PORT` is 1..=65535. Only the host the user names is contacted.
//! - `COMn` (1..=256; any case, with or without the `\\.\` prefix): a Windows serial
//!   port. `COM12` opens as `\\.\COM12`, the form Windows needs for COM10 and above.
//! - anything else: a serial device path (`/dev/ttyUSB0`, `/dev/cu.usbserial-A1`, a pty
//!   slave such as `/dev/pts/3` or a simulator's symlink).
//!
//! ```
//! use robobus_link::PortSpec;
//! let spec: PortSpec = "socket://127.0.0.1:5600".parse()?;
//! assert_eq!(spec.to_string(), "socket://127.0.0.1:5600");
//! assert_eq!("com12".parse::<PortSpec>()?, PortSpec::Com(12));
//! assert_eq!(r"\\.\COM12".parse::<PortSpec>()?.to_string(), "COM12");
//! assert!("socket://127.0.0.1".parse::<PortSpec>().is_err());
//! # Ok::<(), robobus_link::PortSpecError>(())
//! ```

use std::fmt;
use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::time::Duration;

use crate::byte::{ByteLink, LinkError};

/// The forms a port address takes, for error and help texts.
pub const PORT_SYNTAX: &str = "a serial device path (/dev/ttyUSB0, /dev/cu.usbserial-A1), \
     a Windows port (COM3, COM12 or \\\\.\\COM12), or socket://HOST:PORT (a simulator or \
     serial server over TCP, e.g. socket://127.0.0.1:5600)";

/// Highest COM port number accepted (Windows' classic limit).
pub const MAX_COM: u16 = 256;

/// Longest device path accepted (Linux's `PATH_MAX`).
pub const MAX_PATH_LEN: usize = 4096;

/// How long [`PortSpec::open`] waits for a TCP connection to be accepted.
pub const CONNECT_TIMEOUT: Duration = Duration::from_secs(2);

/// Where a byte link is: a serial device, a Windows COM port, or a TCP address.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum PortSpec {
    /// A serial device by path (Unix: `/dev/ttyUSB0`, `/dev/cu.usbserial-A1`, a pty).
    Device(PathBuf),
    /// A Windows COM port by number (`COM3` is `Com(3)`).
    Com(u16),
    /// pyserial's `socket://HOST:PORT`: a TCP connection to `host` (an IP address or a
    /// host name, without brackets) on `port`.
    Tcp {
        /// The host as given (an IPv6 address without its brackets).
        host: String,
        /// TCP port, 1..=65535.
        port: u16,
    },
}

/// A port address that does not parse; the message names the value and the forms allowed.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("port {value:?}: {reason}")]
pub struct PortSpecError {
    /// The address as given (at most its first 64 characters).
    pub value: String,
    /// What is wrong and what is allowed.
    pub reason: String,
}

impl PortSpec {
    /// The TCP address `socket://HOST:PORT` of a socket address (a simulator's listener).
    pub fn tcp(addr: std::net::SocketAddr) -> Self {
        Self::Tcp {
            host: addr.ip().to_string(),
            port: addr.port(),
        }
    }

    /// A human description: `serial port /dev/ttyUSB0`, `serial port COM12`,
    /// `TCP socket://127.0.0.1:5600`.
    pub fn describe(&self) -> String {
        match self {
            Self::Device(_) | Self::Com(_) => format!("serial port {self}"),
            Self::Tcp { .. } => format!("TCP {self}"),
        }
    }

    /// Whether this is a TCP address.
    pub const fn is_tcp(&self) -> bool {
        matches!(self, Self::Tcp { .. })
    }

    /// The device path, for a [`PortSpec::Device`].
    pub fn device_path(&self) -> Option<&Path> {
        match self {
            Self::Device(p) => Some(p),
            _ => None,
        }
    }

    /// The name Windows opens a COM port by (`\\.\COM12`), for a [`PortSpec::Com`].
    pub fn com_device_name(&self) -> Option<String> {
        match self {
            Self::Com(n) => Some(format!(r"\\.\COM{n}")),
            _ => None,
        }
    }

    /// Reads a port address from a path-like value (a device path that may not be UTF-8
    /// is taken as a path as it is).
    ///
    /// # Errors
    /// As [`PortSpec::from_str`] for text.
    pub fn from_os(value: &std::ffi::OsStr) -> Result<Self, PortSpecError> {
        if let Some(text) = value.to_str() {
            return text.parse();
        }
        let path = PathBuf::from(value);
        if path.as_os_str().len() > MAX_PATH_LEN {
            return Err(PortSpecError {
                value: path.to_string_lossy().chars().take(64).collect(),
                reason: format!("longer than {MAX_PATH_LEN} bytes"),
            });
        }
        Ok(Self::Device(path))
    }

    /// Opens the link at `baud` 8N1: a serial port ([`crate::SerialLink`]) or a TCP
    /// connection ([`crate::TcpByteLink`], which records the rate: a TCP stream has no
    /// line rate, the server's own applies).
    ///
    /// # Errors
    /// [`LinkError::NoSuchDevice`] (no such device), [`LinkError::Unreachable`] (nothing
    /// listens at the TCP address), [`LinkError::NotAvailable`] (a COM port outside
    /// Windows, a device path on Windows), or what opening the port reports.
    pub fn open(&self, baud: u32) -> Result<Box<dyn ByteLink + Send>, LinkError> {
        match self {
            Self::Device(path) => open_device(path, baud),
            Self::Com(n) => open_com(*n, baud),
            Self::Tcp { host, port } => {
                let mut link = crate::tcp::TcpByteLink::connect(host, *port, CONNECT_TIMEOUT)?;
                link.set_baud(baud)?;
                Ok(Box::new(link))
            }
        }
    }
}

/// Opens a serial port by the name the OS gives it (a path; `\\.\COM12` on Windows).
#[cfg(any(unix, windows))]
fn open_serial(name: &Path, baud: u32) -> Result<Box<dyn ByteLink + Send>, LinkError> {
    crate::serial::SerialLink::open(name, baud).map(|l| Box::new(l) as Box<dyn ByteLink + Send>)
}

/// Serial ports are not built for this system.
#[cfg(not(any(unix, windows)))]
fn open_serial(name: &Path, _baud: u32) -> Result<Box<dyn ByteLink + Send>, LinkError> {
    Err(LinkError::NotAvailable {
        what: format!("serial port {}", name.display()),
        instead: "this build has no serial ports; reach a simulator as socket://HOST:PORT".into(),
    })
}

#[cfg(not(windows))]
fn open_device(path: &Path, baud: u32) -> Result<Box<dyn ByteLink + Send>, LinkError> {
    open_serial(path, baud)
}

#[cfg(windows)]
fn open_device(path: &Path, _baud: u32) -> Result<Box<dyn ByteLink + Send>, LinkError> {
    Err(LinkError::NotAvailable {
        what: format!("serial device path {}", path.display()),
        instead: "name the port as COMn (COM3), or a simulator as socket://HOST:PORT".into(),
    })
}

#[cfg(windows)]
fn open_com(n: u16, baud: u32) -> Result<Box<dyn ByteLink + Send>, LinkError> {
    open_serial(Path::new(&format!(r"\\.\COM{n}")), baud)
}

#[cfg(not(windows))]
fn open_com(n: u16, _baud: u32) -> Result<Box<dyn ByteLink + Send>, LinkError> {
    Err(LinkError::NotAvailable {
        what: format!("COM{n}"),
        instead: "COM ports are Windows names; name the device path (/dev/ttyUSB0 on \
                  Linux, /dev/cu.usbserial-* on macOS), or a simulator as socket://HOST:PORT"
            .into(),
    })
}

impl fmt::Display for PortSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Device(path) => write!(f, "{}", path.display()),
            Self::Com(n) => write!(f, "COM{n}"),
            Self::Tcp { host, port } if host.contains(':') => {
                write!(f, "socket://[{host}]:{port}")
            }
            Self::Tcp { host, port } => write!(f, "socket://{host}:{port}"),
        }
    }
}

impl FromStr for PortSpec {
    type Err = PortSpecError;

    fn from_str(s: &str) -> Result<Self, PortSpecError> {
        let err = |reason: String| PortSpecError {
            value: s.chars().take(64).collect(),
            reason,
        };
        if s.trim().is_empty() {
            return Err(err(format!("empty (expected {PORT_SYNTAX})")));
        }
        if s.len() > MAX_PATH_LEN {
            return Err(err(format!(
                "{} bytes long (at most {MAX_PATH_LEN}; expected {PORT_SYNTAX})",
                s.len()
            )));
        }
        if s.chars().any(char::is_control) {
            return Err(err(format!(
                "contains a control character (expected {PORT_SYNTAX})"
            )));
        }
        if let Some((scheme, rest)) = s.split_once("://") {
            if scheme.eq_ignore_ascii_case("socket") {
                return parse_socket(rest).map_err(err);
            }
            return Err(err(format!(
                "{:?} is not a port scheme robobus speaks (only socket://HOST:PORT; \
                 expected {PORT_SYNTAX})",
                short(scheme)
            )));
        }
        if let Some(n) = parse_com(s) {
            return n.map(Self::Com).map_err(err);
        }
        Ok(Self::Device(PathBuf::from(s)))
    }
}

/// `Some` if `s` is a COM name (`COM7`, `com7`, `\\.\COM7`): its number or why not.
fn parse_com(s: &str) -> Option<Result<u16, String>> {
    let name = s.strip_prefix(r"\\.\").unwrap_or(s);
    let digits = name
        .get(..3)
        .filter(|p| p.eq_ignore_ascii_case("com"))
        .and_then(|_| name.get(3..))?;
    if digits.is_empty() || !digits.bytes().all(|b| b.is_ascii_digit()) {
        // `COMx` that is not a number: a path only if it does not look like a COM name.
        return if s.starts_with(r"\\.\") {
            Some(Err(format!(
                "{:?} is not a COM port number (allowed: COM1..=COM{MAX_COM})",
                short(digits)
            )))
        } else {
            None
        };
    }
    match digits.parse::<u16>() {
        Ok(n) if (1..=MAX_COM).contains(&n) => Some(Ok(n)),
        _ => Some(Err(format!(
            "COM{} is not a COM port (allowed: COM1..=COM{MAX_COM})",
            short(digits)
        ))),
    }
}

/// The `HOST:PORT` after `socket://`.
fn parse_socket(rest: &str) -> Result<PortSpec, String> {
    const FORM: &str = "expected socket://HOST:PORT, e.g. socket://127.0.0.1:5600";
    if rest.contains(['/', '?', '#', '@']) {
        return Err(format!(
            "only HOST:PORT may follow socket:// (no path, options or user); {FORM}"
        ));
    }
    let (host, port) = if let Some(bracketed) = rest.strip_prefix('[') {
        let (host, after) = bracketed
            .split_once(']')
            .ok_or_else(|| format!("an IPv6 address needs its closing ']'; {FORM}"))?;
        let port = after
            .strip_prefix(':')
            .ok_or_else(|| format!("no port after [{}]; {FORM}", short(host)))?;
        if host.parse::<std::net::Ipv6Addr>().is_err() {
            return Err(format!("[{}] is not an IPv6 address; {FORM}", short(host)));
        }
        (host, port)
    } else {
        let (host, port) = rest
            .rsplit_once(':')
            .ok_or_else(|| format!("no port; {FORM}"))?;
        if host.contains(':') {
            return Err(format!(
                "an IPv6 address goes in brackets (socket://[::1]:5600); {FORM}"
            ));
        }
        if !valid_host(host) {
            return Err(format!(
                "{:?} is not an IP address or host name (letters, digits, '-' and '.'); {FORM}",
                short(host)
            ));
        }
        (host, port)
    };
    let port = match port.parse::<u16>() {
        Ok(0) => return Err(format!("port 0 (allowed: 1..=65535); {FORM}")),
        Ok(p) => p,
        Err(_) => {
            return Err(format!(
                "port {:?} is not a number (allowed: 1..=65535); {FORM}",
                short(port)
            ));
        }
    };
    Ok(PortSpec::Tcp {
        host: host.to_owned(),
        port,
    })
}

/// A host name or IPv4 address: 1..=253 characters of letters, digits, `-` and `.`.
fn valid_host(host: &str) -> bool {
    (1..=253).contains(&host.len())
        && host
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b == b'-' || b == b'.')
}

/// At most 32 characters of a user's text, for messages.
fn short(s: &str) -> String {
    s.chars().take(32).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tcp(host: &str, port: u16) -> PortSpec {
        PortSpec::Tcp {
            host: host.into(),
            port,
        }
    }

    #[test]
    fn every_form_parses_to_its_kind() {
        assert_eq!(
            "/dev/ttyUSB0".parse(),
            Ok(PortSpec::Device("/dev/ttyUSB0".into()))
        );
        assert_eq!(
            "/dev/cu.usbserial-A1".parse(),
            Ok(PortSpec::Device("/dev/cu.usbserial-A1".into()))
        );
        assert_eq!(
            "/dev/pts/3".parse(),
            Ok(PortSpec::Device("/dev/pts/3".into()))
        );
        assert_eq!("COM3".parse(), Ok(PortSpec::Com(3)));
        assert_eq!("com12".parse(), Ok(PortSpec::Com(12)));
        assert_eq!(r"\\.\COM12".parse(), Ok(PortSpec::Com(12)));
        assert_eq!(r"\\.\cOm7".parse(), Ok(PortSpec::Com(7)));
        assert_eq!("COM256".parse(), Ok(PortSpec::Com(256)));
        assert_eq!(
            "socket://127.0.0.1:5600".parse(),
            Ok(tcp("127.0.0.1", 5600))
        );
        assert_eq!("SOCKET://localhost:1".parse(), Ok(tcp("localhost", 1)));
        assert_eq!("socket://[::1]:65535".parse(), Ok(tcp("::1", 65535)));
        assert_eq!(
            "socket://sim-host.local:5600".parse(),
            Ok(tcp("sim-host.local", 5600))
        );
        // Names that only start like a COM port are paths.
        assert_eq!("COMPASS".parse(), Ok(PortSpec::Device("COMPASS".into())));
        assert_eq!("./com3".parse(), Ok(PortSpec::Device("./com3".into())));
    }

    #[test]
    fn display_round_trips_in_the_canonical_form() {
        for s in [
            "/dev/ttyUSB0",
            "/dev/cu.usbserial-A1",
            "COM3",
            "COM12",
            "socket://127.0.0.1:5600",
            "socket://[::1]:5600",
            "socket://localhost:80",
        ] {
            let spec: PortSpec = s.parse().unwrap();
            assert_eq!(spec.to_string(), s);
            assert_eq!(spec.to_string().parse::<PortSpec>().unwrap(), spec);
        }
        assert_eq!("com12".parse::<PortSpec>().unwrap().to_string(), "COM12");
        assert_eq!(
            r"\\.\COM12".parse::<PortSpec>().unwrap().to_string(),
            "COM12"
        );
        assert_eq!(
            PortSpec::Com(12).com_device_name().as_deref(),
            Some(r"\\.\COM12")
        );
        assert_eq!(
            PortSpec::tcp("127.0.0.1:5600".parse().unwrap()),
            tcp("127.0.0.1", 5600)
        );
    }

    #[test]
    fn describe_names_the_kind_and_the_address() {
        assert_eq!(
            PortSpec::Device("/dev/ttyUSB0".into()).describe(),
            "serial port /dev/ttyUSB0"
        );
        assert_eq!(PortSpec::Com(3).describe(), "serial port COM3");
        assert_eq!(
            tcp("127.0.0.1", 5600).describe(),
            "TCP socket://127.0.0.1:5600"
        );
    }

    #[test]
    fn bad_addresses_name_the_value_and_the_forms_allowed() {
        let cases = [
            ("", "empty"),
            ("   ", "empty"),
            ("COM0", "COM1..=COM256"),
            ("COM257", "COM1..=COM256"),
            ("COM99999999", "COM1..=COM256"),
            (r"\\.\COMx", "COM1..=COM256"),
            ("socket://127.0.0.1", "no port"),
            ("socket://127.0.0.1:0", "port 0"),
            ("socket://127.0.0.1:65536", "1..=65535"),
            ("socket://127.0.0.1:http", "1..=65535"),
            ("socket://:5600", "not an IP address or host name"),
            ("socket://::1:5600", "brackets"),
            ("socket://[::1]5600", "no port"),
            ("socket://[::1:5600", "closing"),
            ("socket://[nope]:5600", "not an IPv6"),
            ("socket://127.0.0.1:5600?logging=debug", "only HOST:PORT"),
            ("socket://127.0.0.1:5600/x", "only HOST:PORT"),
            ("socket://a b:5600", "not an IP address"),
            ("rfc2217://127.0.0.1:5600", "only socket://"),
            ("loop://", "only socket://"),
            ("/dev/tty\nUSB0", "control character"),
        ];
        for (value, why) in cases {
            let e = value.parse::<PortSpec>().unwrap_err();
            let text = e.to_string();
            assert!(text.contains(why), "{value:?}: {text}");
            assert!(
                text.contains(&format!("{:?}", value.chars().take(64).collect::<String>())),
                "{value:?}: {text}"
            );
        }
        // The forms are named where the value is no kind at all.
        let e = "".parse::<PortSpec>().unwrap_err().to_string();
        assert!(
            e.contains("socket://HOST:PORT") && e.contains("COM3"),
            "{e}"
        );
        // A huge value is named, not echoed.
        let long = "x".repeat(100_000);
        let e = long.parse::<PortSpec>().unwrap_err();
        assert!(e.to_string().len() < 600, "{}", e.to_string().len());
    }

    #[test]
    fn a_non_utf8_path_is_a_device_path() {
        #[cfg(unix)]
        {
            use std::os::unix::ffi::OsStrExt as _;
            let raw = std::ffi::OsStr::from_bytes(b"/dev/tty\xffUSB0");
            assert_eq!(
                PortSpec::from_os(raw),
                Ok(PortSpec::Device(PathBuf::from(raw)))
            );
        }
        assert_eq!(
            PortSpec::from_os(std::ffi::OsStr::new("COM4")),
            Ok(PortSpec::Com(4))
        );
    }

    #[cfg(not(windows))]
    #[test]
    fn a_com_port_outside_windows_is_not_available_naming_what_to_use() {
        let Err(e) = PortSpec::Com(7).open(115_200) else {
            panic!("COM7 opened outside Windows");
        };
        assert!(matches!(e, LinkError::NotAvailable { .. }), "{e:?}");
        let text = e.to_string();
        assert!(text.contains("COM7") && text.contains("/dev/"), "{text}");
    }
}
