//! Requests about the host computer itself rather than a bus: `host.ports`, the serial
//! ports its OS knows ([`crate::ops::ports`]). Nothing is opened or sent.

use robobus_wck::BaudRate;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::effect::Effect;
use super::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use super::plan::{Family, Plan};
use crate::ops::OpError;
use crate::ops::ports::{self, Os, PortInfo};

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

/// The summary of `host.ports`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, JsonSchema)]
pub struct PortsSummary {
    /// The system asked.
    pub os: Os,
    /// How many ports the report lists.
    pub ports: usize,
    /// Ports left out past [`ports::MAX_PORTS`].
    pub left_out: usize,
    /// Where this OS puts serial ports.
    #[serde(rename = "where")]
    pub where_: &'static str,
}

impl Operation for Ports {
    const OP: &'static str = "host.ports";
    const FAMILY: Family = Family::Host;
    const DOC: OpDoc = OpDoc {
        args: "-",
        report: "one row per serial port the OS lists (`id`: `COM3` on Windows, \
                 `/dev/cu.usbserial-A10K` on macOS, `/dev/ttyUSB0` / `/dev/ttyACM0` on Linux; a \
                 simulator's pseudo-terminal is not a port the OS lists): `kind` (`usb`, `pci`, \
                 `bluetooth`, `unknown`), `vid`, `pid` (numbers), `manufacturer`, `product`, \
                 `serial_number`, `adapter` (recognised from robobus's table: `FTDI FT232R`, \
                 `WCH CH340`, `Silicon Labs CP210x`, `CANable 2.0 (slcan firmware)`, `mjbots \
                 fdcanusb`, ...), `use_for` (`wCK bus: --port PORT`, `CAN FD adapter: --bus \
                 slcan:PORT`, `CAN FD adapter: --bus fdcanusb:PORT`), `latency_timer_ms` (an \
                 FTDI adapter's, read from sysfs on Linux; null elsewhere), `latency_advice` (how \
                 to set it to 1 ms on this OS; null when nothing is to be done); `summary`: \
                 `os`, `ports`, `left_out` (past 256), `where` (where this OS puts serial \
                 ports). No port is opened, nothing is sent; the station's buses are not used",
        confirm: "-",
    };
    type Row = PortInfo;
    type Summary = PortsSummary;

    fn effect(&self) -> Effect {
        Effect::Read
    }

    fn check(&self) -> Result<Confirm, OpError> {
        Ok(Confirm::NONE)
    }

    fn plan(&self, _baud: BaudRate) -> Result<Plan, OpError> {
        Ok(Plan::notes_only(
            Self::OP,
            Family::Host,
            vec![PORTS_NOTE.to_owned()],
        ))
    }

    /// One row per port (`id` the port, then [`PortInfo`]'s fields). Nothing of the
    /// station is used: the host's own serial ports.
    fn run(&self, _cx: &mut RunCx<'_, '_>) -> Result<Report<PortInfo, PortsSummary>, OpError> {
        let list = ports::list()?;
        let summary = PortsSummary {
            os: list.os,
            ports: list.ports.len(),
            left_out: list.left_out,
            where_: ports::where_ports_are(list.os),
        };
        Ok(Report::with_rows(Self::OP, HOST, list.ports).summary(summary))
    }
}
