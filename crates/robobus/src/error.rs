//! Error kinds: one classification of every library error, for every front end.
//!
//! Each error type of the library has a `kind()`, beside the type. A front end maps the
//! kind once: the command line to its exit code, the Python package to an exception class,
//! the web studio to an HTTP status. The kinds:
//!
//! | kind | meaning | `robobus` exit code |
//! | --- | --- | --- |
//! | [`ErrorKind::BadInput`] | a value out of range or malformed, a file that does not parse; nothing was sent | 2 |
//! | [`ErrorKind::Refused`] | refused for safety or because of the device's state (a gated register, an ID in use, an implausible position); nothing was sent | 2 |
//! | [`ErrorKind::NoDevice`] | no device answered in time, or the port / interface does not exist | 3 |
//! | [`ErrorKind::Device`] | the device answered with an error, a malformed reply, or a state other than the one asked for | 1 |
//! | [`ErrorKind::Link`] | the link failed (I/O error, port busy, permission, bus off) | 1 |
//! | [`ErrorKind::Interrupted`] | stopped by the caller's stop token; devices were brought to the chosen safe state | 130 |
//! | [`ErrorKind::NotAvailable`] | the operation needs something this build or machine does not have | 4 |

use robobus_link::{FrameLinkError, LinkError, OpenError};
use serde::Serialize;

/// What kind of failure an error is (see the [module docs](self) for the table).
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, serde::Deserialize, schemars::JsonSchema,
)]
#[serde(rename_all = "kebab-case")]
#[non_exhaustive]
pub enum ErrorKind {
    /// Bad input: nothing was sent.
    BadInput,
    /// Refused for safety or device state: nothing was sent.
    Refused,
    /// No device answered, or the device path does not exist.
    NoDevice,
    /// The device answered with an error or an implausible reply.
    Device,
    /// The link failed.
    Link,
    /// Stopped by the caller; devices are in the chosen safe state.
    Interrupted,
    /// Not available in this build or on this machine.
    NotAvailable,
}

impl ErrorKind {
    /// The kebab-case name used in JSON reports (`"no-device"`).
    pub const fn name(self) -> &'static str {
        match self {
            Self::BadInput => "bad-input",
            Self::Refused => "refused",
            Self::NoDevice => "no-device",
            Self::Device => "device",
            Self::Link => "link",
            Self::Interrupted => "interrupted",
            Self::NotAvailable => "not-available",
        }
    }
}

impl core::fmt::Display for ErrorKind {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.name())
    }
}

/// The kind of a link error: a missing device is [`ErrorKind::NoDevice`], a timeout too;
/// everything else is [`ErrorKind::Link`].
pub fn link_error_kind(e: &LinkError) -> ErrorKind {
    match e {
        LinkError::Timeout { .. }
        | LinkError::NoSuchDevice { .. }
        | LinkError::Unreachable { .. } => ErrorKind::NoDevice,
        LinkError::UnsupportedBaud { .. } | LinkError::NotAvailable { .. } => {
            ErrorKind::NotAvailable
        }
        LinkError::BadPort(_) => ErrorKind::BadInput,
        _ => ErrorKind::Link,
    }
}

/// The kind of a bus that cannot be opened ([`robobus_link::FrameLinkSpec::open`]): a
/// kernel without SocketCAN (or an OS without the bus) is [`ErrorKind::NotAvailable`], an
/// interface that is missing or unusable [`ErrorKind::NoDevice`], a UDP bus that cannot be
/// joined [`ErrorKind::Link`]; a serial-line adapter's port as its link error says, an
/// adapter that is silent or answers garbage [`ErrorKind::NoDevice`], a rate it cannot be
/// set to [`ErrorKind::BadInput`], a refused setup [`ErrorKind::Device`].
pub fn open_error_kind(e: &OpenError) -> ErrorKind {
    use robobus_link::AdapterErrorKind as A;
    match e {
        OpenError::Port { source, .. } => link_error_kind(source),
        OpenError::Adapter(a) => match a.kind {
            A::NoPort | A::NotAnswering | A::Garbage => ErrorKind::NoDevice,
            A::RateUnsupported => ErrorKind::BadInput,
            A::Refused => ErrorKind::Device,
            A::Io => ErrorKind::Link,
        },
        OpenError::NoInterface {
            source: FrameLinkError::NoCanSupport { .. },
            ..
        }
        | OpenError::Unsupported(_) => ErrorKind::NotAvailable,
        OpenError::NoInterface { .. } => ErrorKind::NoDevice,
        OpenError::Udp { .. } => ErrorKind::Link,
    }
}
