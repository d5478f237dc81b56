//! Requests about the host computer itself rather than a bus: `host.ports`, the serial
//! ports its OS knows ([`crate::ops::ports`]). Nothing is opened or sent.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use serde_json::json;

use super::Report;
use crate::ops::OpError;
use crate::ops::ports;

/// `host.ports`: the serial ports of this machine as its OS lists them (COM ports on
/// Windows, `/dev/cu.*` on macOS, `/dev/ttyUSB*` / `/dev/ttyACM*` and on-board UARTs on
/// Linux; a simulator's pseudo-terminal is not among them): kind, USB IDs and strings,
/// the adapter robobus recognises and what it is for (`wCK bus: --port PORT`, `CAN FD
/// adapter: --bus slcan:PORT`), and this OS's latency-timer advice. Read-only: no port is
/// opened.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Ports {}

/// What a plan of `host.ports` says (it sends nothing).
pub const PORTS_NOTE: &str = "lists the serial ports the OS knows; no port is opened and \
                              nothing is sent";

/// The bus name of a host report.
pub const HOST: &str = "host";

/// Runs `host.ports`: one row per port (`id` the port, then [`ports::PortInfo`]'s
/// fields); `summary`: `os`, `ports` (how many), `left_out` (past
/// [`ports::MAX_PORTS`]), `where` (where this OS puts serial ports).
#[allow(clippy::result_large_err)] // OpError carries the client errors by value
pub fn ports_report(op: &str) -> Result<Report, OpError> {
    let list = ports::list()?;
    Ok(Report {
        op: op.to_owned(),
        bus: HOST.to_owned(),
        results: list
            .ports
            .iter()
            .filter_map(|p| serde_json::to_value(p).ok())
            .collect(),
        summary: Some(json!({
            "os": list.os,
            "ports": list.ports.len(),
            "left_out": list.left_out,
            "where": ports::where_ports_are(list.os),
        })),
        failed: None,
        error: None,
    })
}
