//! The host bounds table and the confirmation rule: the one source of the limits every
//! front end applies before anything is sent (the CLI's option parsers read them too).
//!
//! These are host policies on top of the devices' own limits (a WHJ joint's position
//! limits, its model's peak speed and its current limit, which the operations check once
//! the joint is connected).

use serde::Serialize;

pub use crate::ops::Bound;
use crate::ops::OpError;
pub use crate::ops::whj::FRAME_RATE_HZ;
use crate::ops::whj::{MAX_DEG, MAX_MA, MAX_RPM};

/// WHJ target angle (`move <DEGREES>`, `--from`).
pub const ANGLE_DEG: Bound = Bound {
    what: "angle (degrees)",
    unit: "deg",
    min: -MAX_DEG,
    max: MAX_DEG,
};
/// WHJ move speed (`--max-speed`).
pub const MOVE_SPEED_DEG_S: Bound = Bound {
    what: "speed (degrees/s)",
    unit: "deg/s",
    min: 0.1,
    max: 180.0,
};
/// WHJ speed target (`speed <RPM>`).
pub const SPEED_RPM: Bound = Bound {
    what: "speed (RPM)",
    unit: "RPM",
    min: -MAX_RPM,
    max: MAX_RPM,
};
/// WHJ current target (`current <MILLIAMPS>`).
pub const CURRENT_MA: Bound = Bound {
    what: "current (mA)",
    unit: "mA",
    min: -MAX_MA,
    max: MAX_MA,
};
/// WHJ target duration (`--duration` of speed / current).
pub const TARGET_DURATION_S: Bound = Bound {
    what: "duration (s)",
    unit: "s",
    min: 0.01,
    max: 3600.0,
};
/// wCK rates (`--rate-hz` of teach and play).
pub const WCK_RATE_HZ: Bound = Bound {
    what: "rate",
    unit: "Hz",
    min: 0.1,
    max: 200.0,
};
/// wCK durations (`--duration` of wheel and teach).
pub const WCK_DURATION_S: Bound = Bound {
    what: "duration",
    unit: "s",
    min: 0.1,
    max: 3600.0,
};

/// The bounds table, for a front end to show (`robobus schema` prints it too).
pub const BOUNDS: &[(&str, Bound)] = &[
    ("whj.angle", ANGLE_DEG),
    ("whj.move.max_speed", MOVE_SPEED_DEG_S),
    ("whj.rate_hz", FRAME_RATE_HZ),
    ("whj.speed.rpm", SPEED_RPM),
    ("whj.current.milliamps", CURRENT_MA),
    ("whj.duration", TARGET_DURATION_S),
    ("wck.rate_hz", WCK_RATE_HZ),
    ("wck.duration", WCK_DURATION_S),
];

/// Why a request needs `confirm: true` (the CLI's `--yes`): what it rewrites.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, schemars::JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum ConfirmClass {
    /// Runs without confirmation.
    None,
    /// Rewrites a wCK servo's EEPROM or a WHJ joint's flash.
    NonVolatile,
    /// Changes a device's ID (and saves it).
    Id,
    /// Writes a WHJ register of the `confirm` safety class (bit rates, IAP, brake,
    /// calibration) or an end-board register.
    Register,
}

/// The text a refusal and a prompt say for non-volatile memory (the CLI's prompt).
pub const NON_VOLATILE_TEXT: &str =
    "This rewrites the device's non-volatile memory (EEPROM / flash).";

/// How a refusal for want of confirmation ends: how to confirm, in the request's JSON
/// and on the command line (a front end with its own wording replaces it:
/// [`crate::frontend::wording`]).
pub const CONFIRM_HOW: &str = "Confirm with `confirm: true` (the CLI's --yes); nothing was sent";

/// The refusal of a request that needs confirmation and lacks it: `what` (the CLI's
/// prompt text) and how to confirm ([`CONFIRM_HOW`]); [`crate::ErrorKind::Refused`],
/// nothing sent.
pub fn refused(what: &str) -> OpError {
    OpError::Refused(format!("{what} {CONFIRM_HOW}"))
}
