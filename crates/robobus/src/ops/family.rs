//! Which family of devices something is for: the one vocabulary of the catalogue's
//! requests and plans, the station's buses and the front ends.

use schemars::JsonSchema;
use serde::Serialize;

/// Which family a plan or a request is for.
#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    Eq,
    PartialOrd,
    Ord,
    Hash,
    Serialize,
    serde::Deserialize,
    JsonSchema,
)]
#[serde(rename_all = "lowercase")]
pub enum Family {
    /// wCK servos on a UART.
    Wck,
    /// WHJ joints on CAN FD.
    Whj,
    /// A robot file's joints, on the buses of both families it names.
    Robot,
    /// The host computer itself (its serial ports): no bus.
    Host,
}
