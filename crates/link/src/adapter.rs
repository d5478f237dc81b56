//! What can go wrong opening a serial-line CAN FD adapter (slcan, fdcanusb): one error type
//! for every adapter protocol, with a kind to match on.

use std::fmt::{self, Write as _};

/// Why a serial-line CAN adapter could not be opened or configured.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum AdapterErrorKind {
    /// The port does not exist or cannot be opened.
    NoPort,
    /// Nothing answered within the time an adapter answers in.
    NotAnswering,
    /// Something answered, but not in the adapter's protocol.
    Garbage,
    /// A bit rate the adapter cannot be set to was asked for (bad input: nothing was sent
    /// to a joint).
    RateUnsupported,
    /// The adapter refused a configuration command.
    Refused,
    /// Reading or writing the port failed.
    Io,
}

/// A serial-line CAN adapter that could not be opened or configured: the port, what was
/// being done and what was expected. Nothing was sent to a joint.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub struct AdapterError {
    /// The adapter protocol (`slcan`, `fdcanusb`).
    pub protocol: &'static str,
    /// The port as given (`/dev/ttyACM0`, `COM8`, `socket://127.0.0.1:5601`).
    pub port: String,
    /// What kind of failure.
    pub kind: AdapterErrorKind,
    /// What happened and what was expected or allowed.
    pub detail: String,
}

impl fmt::Display for AdapterError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} adapter on {}: {}",
            self.protocol, self.port, self.detail
        )
    }
}

impl AdapterError {
    /// An error of `kind` for the adapter of `protocol` on `port`.
    pub fn new(
        protocol: &'static str,
        port: impl Into<String>,
        kind: AdapterErrorKind,
        detail: impl Into<String>,
    ) -> Self {
        Self {
            protocol,
            port: port.into(),
            kind,
            detail: detail.into(),
        }
    }
}

/// `bytes` as printable text for a message: at most `max` bytes, control characters and
/// non-ASCII as `\r`, `\a`, `\xNN`.
pub fn escape_bytes(bytes: &[u8], max: usize) -> String {
    let mut out = String::new();
    for &b in bytes.iter().take(max) {
        match b {
            b'\r' => out.push_str("\\r"),
            b'\n' => out.push_str("\\n"),
            0x07 => out.push_str("\\a"),
            0x20..=0x7E => out.push(char::from(b)),
            _ => {
                let _ = write!(out, "\\x{b:02X}");
            }
        }
    }
    if bytes.len() > max {
        let _ = write!(out, "…({} bytes)", bytes.len());
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn escaped_bytes_are_printable_and_bounded() {
        assert_eq!(escape_bytes(b"V1013\r\x07\xff", 16), "V1013\\r\\a\\xFF");
        assert_eq!(escape_bytes(&[b'x'; 100], 4), "xxxx…(100 bytes)");
        let e = AdapterError::new("slcan", "COM8", AdapterErrorKind::NotAnswering, "no answer");
        assert_eq!(e.to_string(), "slcan adapter on COM8: no answer");
    }
}
