//! Exit codes, and the error kinds that select them.
//!
//! Every error is an [`anyhow::Error`]; its exit code is decided by [`Exit::of`]: a CLI
//! marker type at its root ([`Usage`] (code 2), [`Timeout`] (3), [`NotAvailable`] (4),
//! [`ProblemsFound`] (5), [`Interrupted`] (130)), else the [`ErrorKind`] of the library
//! error in its chain ([`Exit::of_kind`], one `match`). Anything else is a runtime error (1).
//! Errors from clap's own parsing exit with 2 as well (clap's convention).

use std::fmt::{self, Write as _};

use robobus::ops::OpError;
use robobus::wck::WckError;
use robobus::whj::WhjError;
use robobus::{ActuatorError, ErrorKind, RobotError};

/// The process exit codes, as `robobus --help` documents them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub(crate) enum Exit {
    /// Device or runtime error: I/O, a device reported an error, a malformed reply.
    Runtime = 1,
    /// Usage or validation error: nothing was opened or sent.
    Usage = 2,
    /// No device answered in time.
    Timeout = 3,
    /// The command needs something this build or machine does not have (e.g. SocketCAN).
    NotAvailable = 4,
    /// `robobus doctor` found at least one problem.
    ProblemsFound = 5,
    /// Interrupted by Ctrl-C / SIGTERM.
    Interrupted = 130,
}

impl Exit {
    /// The exit code of a library error kind: the one `match` from
    /// [`robobus::ErrorKind`] to the documented table.
    #[allow(clippy::match_same_arms)] // each documented kind named, the wildcard for new ones
    pub(crate) const fn of_kind(kind: ErrorKind) -> Self {
        match kind {
            ErrorKind::BadInput | ErrorKind::Refused => Self::Usage,
            ErrorKind::NoDevice => Self::Timeout,
            ErrorKind::Device | ErrorKind::Link => Self::Runtime,
            ErrorKind::Interrupted => Self::Interrupted,
            ErrorKind::NotAvailable => Self::NotAvailable,
            // ErrorKind is non_exhaustive: a kind added later is a runtime error until
            // it is given its own code here.
            _ => Self::Runtime,
        }
    }

    /// The exit code for an error: the marker type at the root of its chain, else the
    /// [`ErrorKind`] of the first library error in it, else a runtime error.
    pub(crate) fn of(err: &anyhow::Error) -> Self {
        if err.downcast_ref::<Usage>().is_some() {
            Self::Usage
        } else if err.downcast_ref::<Timeout>().is_some() {
            Self::Timeout
        } else if err.downcast_ref::<NotAvailable>().is_some() {
            Self::NotAvailable
        } else if err.downcast_ref::<ProblemsFound>().is_some() {
            Self::ProblemsFound
        } else if err.downcast_ref::<Interrupted>().is_some() {
            Self::Interrupted
        } else if let Some(kind) = library_kind(err) {
            Self::of_kind(kind)
        } else {
            Self::Runtime
        }
    }
}

/// Longest run of non-blank characters an error message repeats whole.
const LONGEST_ECHO: usize = 64;

/// `text` with every run of non-blank characters longer than [`LONGEST_ECHO`] cut to its
/// first characters and its length (`1234…(100000 characters)`): a 100,000-digit argument
/// is named, not echoed whole.
pub(crate) fn cut_long(text: &str) -> String {
    let mut out = String::with_capacity(text.len().min(4096));
    let mut rest = text;
    while !rest.is_empty() {
        let blank = rest
            .find(|c: char| !c.is_whitespace())
            .unwrap_or(rest.len());
        out.push_str(&rest[..blank]);
        rest = &rest[blank..];
        let word = rest.find(char::is_whitespace).unwrap_or(rest.len());
        let w = &rest[..word];
        let chars = w.chars().count();
        if chars > LONGEST_ECHO {
            out.extend(w.chars().take(LONGEST_ECHO / 2));
            let _ = write!(out, "…({chars} characters)");
        } else {
            out.push_str(w);
        }
        rest = &rest[word..];
    }
    out
}

/// The kind of an error as `--json` names it: the library's [`ErrorKind::name`] where the
/// chain holds a library error, else the CLI marker's own (`bad-input`, `no-device`,
/// `not-available`, `problems-found`, `interrupted`), else `runtime`.
pub(crate) fn kind_name(err: &anyhow::Error) -> &'static str {
    if let Some(kind) = library_kind(err) {
        return kind.name();
    }
    match Exit::of(err) {
        Exit::Usage => ErrorKind::BadInput.name(),
        Exit::Timeout => ErrorKind::NoDevice.name(),
        Exit::NotAvailable => ErrorKind::NotAvailable.name(),
        Exit::ProblemsFound => "problems-found",
        Exit::Interrupted => ErrorKind::Interrupted.name(),
        Exit::Runtime => "runtime",
    }
}

/// The kind of the first library error in the chain, if any.
fn library_kind(err: &anyhow::Error) -> Option<ErrorKind> {
    err.chain().find_map(|cause| {
        if let Some(e) = cause.downcast_ref::<OpError>() {
            Some(e.kind())
        } else if let Some(e) = cause.downcast_ref::<WckError>() {
            Some(e.kind())
        } else if let Some(e) = cause.downcast_ref::<WhjError>() {
            Some(e.kind())
        } else if let Some(e) = cause.downcast_ref::<RobotError>() {
            Some(e.kind())
        } else if let Some(e) = cause.downcast_ref::<ActuatorError>() {
            Some(e.kind())
        } else if let Some(e) = cause.downcast_ref::<robobus_link::OpenError>() {
            Some(robobus::error::open_error_kind(e))
        } else {
            cause
                .downcast_ref::<robobus_link::LinkError>()
                .map(robobus::error::link_error_kind)
        }
    })
}

/// The text of an error and its causes, joined by `: `, leaving out a cause whose text
/// the message already carries (library errors often print their source themselves, so
/// anyhow's `{:#}` would say the same thing twice).
pub(crate) fn message(err: &anyhow::Error) -> String {
    let mut text = String::new();
    for cause in err.chain() {
        let part = cause.to_string();
        if text.contains(&part) {
            continue;
        }
        if !text.is_empty() {
            text.push_str(": ");
        }
        text.push_str(&part);
    }
    text
}

/// A usage or validation error (exit code 2). The message names the option, the value and
/// what is allowed.
#[derive(Debug)]
pub(crate) struct Usage(pub(crate) String);

impl fmt::Display for Usage {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for Usage {}

/// A usage error as an [`anyhow::Error`].
pub(crate) fn usage(message: impl Into<String>) -> anyhow::Error {
    anyhow::Error::new(Usage(message.into()))
}

/// No device answered before the deadline (exit code 3).
#[derive(Debug)]
#[allow(dead_code)] // raised by the client-backed commands once they are wired in
pub(crate) struct Timeout(pub(crate) String);

impl fmt::Display for Timeout {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for Timeout {}

/// The command needs a part that is not in this build (exit code 4).
#[derive(Debug)]
pub(crate) struct NotAvailable(pub(crate) String);

impl fmt::Display for NotAvailable {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for NotAvailable {}

/// `doctor` found problems (exit code 5); the report has been printed already.
#[derive(Debug)]
pub(crate) struct ProblemsFound(pub(crate) usize);

impl fmt::Display for ProblemsFound {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} check(s) failed; see the fixes above", self.0)
    }
}

impl std::error::Error for ProblemsFound {}

/// Interrupted by Ctrl-C / SIGTERM (exit code 130).
#[derive(Debug)]
#[allow(dead_code)] // raised by the client-backed commands once they are wired in
pub(crate) struct Interrupted;

impl fmt::Display for Interrupted {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("interrupted")
    }
}

impl std::error::Error for Interrupted {}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn long_values_are_cut_in_messages() {
        let long = "9".repeat(100_000);
        let text = cut_long(&format!("invalid value '{long}' for '<POSITION>'"));
        assert_eq!(
            text,
            format!(
                "invalid value '{}…(100002 characters) for '<POSITION>'",
                "9".repeat(31)
            )
        );
        assert_eq!(cut_long("a  b\nc"), "a  b\nc");
    }

    #[test]
    fn a_cause_the_message_already_carries_is_said_once() {
        #[derive(Debug)]
        struct Inner;
        impl fmt::Display for Inner {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("device busy")
            }
        }
        impl std::error::Error for Inner {}
        #[derive(Debug)]
        struct Outer(Inner);
        impl fmt::Display for Outer {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                write!(f, "link error during open: {}", self.0)
            }
        }
        impl std::error::Error for Outer {
            fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
                Some(&self.0)
            }
        }
        let e = anyhow::Error::new(Outer(Inner)).context("opening /dev/ttyUSB0");
        assert_eq!(
            message(&e),
            "opening /dev/ttyUSB0: link error during open: device busy"
        );
        assert_eq!(format!("{e:#}").matches("device busy").count(), 2);
        let plain = anyhow::anyhow!("timeout").context("reading J1");
        assert_eq!(message(&plain), "reading J1: timeout");
    }

    #[test]
    fn markers_select_their_codes_even_with_context() {
        use anyhow::Context as _;
        let e: anyhow::Result<()> = Err(usage("bad")).context("while parsing");
        assert_eq!(Exit::of(&e.unwrap_err()), Exit::Usage);
        assert_eq!(
            Exit::of(&anyhow::Error::new(NotAvailable("x".into()))),
            Exit::NotAvailable
        );
        assert_eq!(Exit::of(&anyhow::anyhow!("io")), Exit::Runtime);
        assert_eq!(
            Exit::of(&anyhow::Error::new(Timeout("t".into()))),
            Exit::Timeout
        );
        assert_eq!(
            Exit::of(&anyhow::Error::new(Interrupted)),
            Exit::Interrupted
        );
    }

    #[test]
    fn every_library_error_kind_has_its_documented_code() {
        use robobus::ErrorKind as K;
        let table = [
            (K::BadInput, 2),
            (K::Refused, 2),
            (K::NoDevice, 3),
            (K::Device, 1),
            (K::Link, 1),
            (K::Interrupted, 130),
            (K::NotAvailable, 4),
        ];
        for (kind, code) in table {
            assert_eq!(Exit::of_kind(kind) as u8, code, "{kind}");
        }
        let e = anyhow::Error::new(OpError::Refused("no".into())).context("whj set-id");
        assert_eq!(Exit::of(&e), Exit::Usage);
        let e = anyhow::Error::new(robobus::whj::WhjError::Closed);
        assert_eq!(Exit::of(&e), Exit::Runtime);
        let e = anyhow::Error::new(OpError::Interrupted { detail: None });
        assert_eq!(Exit::of(&e), Exit::Interrupted);
    }
}
