//! Argument types shared by the requests of both families.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::ops::{IdList, ListId, OpError, SafeState};

/// A list of device IDs: the CLI's text form (`"0-5,7"`) or a JSON array (`[0, 1, 2]`).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(untagged)]
pub enum Ids {
    /// `"0-5,7"`: IDs and ranges, as on the command line.
    Text(String),
    /// `[0, 1, 2]`.
    List(Vec<u32>),
}

impl Ids {
    /// The IDs, parsed by the one ID-list parser ([`IdList`]), in the order given.
    #[allow(clippy::result_large_err)] // OpError carries the client errors by value
    pub fn parse<T: ListId>(&self, option: &str) -> Result<Vec<T>, OpError> {
        let text = match self {
            Self::Text(s) => s.clone(),
            Self::List(v) if v.is_empty() => {
                return Err(OpError::invalid(option, "[]", "an empty list of IDs"));
            }
            Self::List(v) => v
                .iter()
                .map(ToString::to_string)
                .collect::<Vec<_>>()
                .join(","),
        };
        let list: IdList<T> = text
            .parse()
            .map_err(|e: String| OpError::invalid(option, &text, e))?;
        Ok(list.into_vec())
    }

    /// [`Ids::parse`], sorted and without repeats (the CLI's WHJ joint lists).
    #[allow(clippy::result_large_err)] // OpError carries the client errors by value
    pub fn parse_sorted<T: ListId>(&self, option: &str) -> Result<Vec<T>, OpError> {
        let text = match self {
            Self::Text(s) => s.clone(),
            Self::List(v) => v
                .iter()
                .map(ToString::to_string)
                .collect::<Vec<_>>()
                .join(","),
        };
        let list: IdList<T> = text
            .parse()
            .map_err(|e: String| OpError::invalid(option, &text, e))?;
        Ok(list.sorted().into_vec())
    }
}

impl From<&str> for Ids {
    fn from(s: &str) -> Self {
        Self::Text(s.to_owned())
    }
}

/// What a wCK servo is left in when a loop ends or is stopped (the CLI's `--on-stop`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum WckOnStop {
    /// Release the torque.
    Passive,
    /// Dynamic brake on every servo of the bus.
    Break,
    /// Keep the current position, with torque.
    Hold,
}

impl From<WckOnStop> for SafeState {
    fn from(o: WckOnStop) -> Self {
        match o {
            WckOnStop::Passive => Self::Passive,
            WckOnStop::Break => Self::Break,
            WckOnStop::Hold => Self::Hold,
        }
    }
}

/// What a WHJ joint is left in when a move, wave or target is stopped (`--on-stop`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum WhjOnStop {
    /// Stay enabled and hold the present position (speed / current: target 0).
    #[default]
    Hold,
    /// Disable the drive.
    Disable,
}

impl From<WhjOnStop> for SafeState {
    fn from(o: WhjOnStop) -> Self {
        match o {
            WhjOnStop::Hold => Self::Hold,
            WhjOnStop::Disable => Self::Disable,
        }
    }
}

/// A number or an integer field that must fit a byte-sized protocol value: the protocol
/// newtype's own range check gives the message.
#[allow(clippy::result_large_err)] // OpError carries the client errors by value
pub(crate) fn byte<T, E: std::fmt::Display>(
    option: &str,
    v: u32,
    new: impl Fn(u8) -> Result<T, E>,
) -> Result<T, OpError> {
    let Ok(b) = u8::try_from(v) else {
        // Past a byte: the type's own range if it is narrower (its message, for the
        // largest byte, names the range; the value in it is replaced by the one given).
        let reason = match new(u8::MAX) {
            Err(e) => e.to_string().replace("255", &v.to_string()),
            Ok(_) => "out of range 0..=255".into(),
        };
        return Err(OpError::invalid(option, v, reason));
    };
    new(b).map_err(|e| OpError::invalid(option, v, e.to_string()))
}
