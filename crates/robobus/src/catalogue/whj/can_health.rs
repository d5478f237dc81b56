//! `whj.can-health`: the bus's CAN interface as the kernel reports it (Linux's netlink);
//! on other systems it says where to look instead.

use robobus_wck::BaudRate;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::{R, plan_of};
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::plan::WhjSteps;
use crate::catalogue::wck::request;
use crate::catalogue::{Effect, Family, Plan};
use crate::ops::OpError;

request!(cli
    /// `whj.can-health`: the bus's CAN interface as the kernel reports it (netlink): the
    /// controller's state (error-active, error-warning, error-passive, bus-off), its error
    /// counters, its state changes and restarts, and the advice for bus-off and
    /// error-passive. Nothing is sent on the bus; a UDP or simulated bus is a row without
    /// a controller.
    /// A telemetry stream can take it.
    CanHealth {}
);

/// The one row: the bus's CAN interface, or a bus without one.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, JsonSchema)]
pub struct CanHealthRow {
    /// The interface (`can0`), or the bus's name when it has none.
    pub id: String,
    /// Its link kind (`can`, `vcan`, ...); null without a CAN interface.
    pub kind: Option<String>,
    /// The controller's state; null without a controller (vcan, a UDP or simulated bus).
    pub state: Option<ControllerState>,
    /// What is wrong and what to do, if anything (a bus without a CAN interface: that it
    /// has no controller).
    pub advice: Option<String>,
    /// The interface's state and counters (left out for a bus without a CAN interface).
    #[serde(flatten)]
    pub interface: Option<Interface>,
}

/// A CAN controller's state, as `ip -details link` names it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, JsonSchema)]
#[serde(rename_all = "kebab-case")]
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
    /// A value the kernel gave that robobus does not know.
    Unknown(u32),
}

/// A CAN interface's state and counters.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, JsonSchema)]
pub struct Interface {
    /// The interface.
    pub iface: String,
    /// Administratively up.
    pub up: bool,
    /// The lower layer is up (a bus-off controller has no carrier).
    pub carrier: bool,
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
    /// CAN FD on (null: no controller, as on vcan, whose MTU tells instead).
    pub fd: Option<bool>,
    /// The MTU: 72 carries CAN FD frames, 16 classic ones only.
    pub mtu: Option<u32>,
    /// State changes and restarts.
    pub stats: Option<DeviceStats>,
    /// Frames received with errors.
    pub rx_frame_errors: Option<u64>,
    /// Frames not sent because of errors.
    pub tx_frame_errors: Option<u64>,
    /// Frames dropped on receive.
    pub rx_dropped: Option<u64>,
    /// Frames dropped on send.
    pub tx_dropped: Option<u64>,
    /// Classic CAN only (FD off, or MTU 16 without a controller): WHJ joints cannot hear
    /// it; `advice` gives the CAN FD command.
    pub classic: bool,
}

/// How often the controller changed state or was restarted since the interface was
/// created.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, JsonSchema)]
pub struct DeviceStats {
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

#[cfg(target_os = "linux")]
impl From<robobus_link::socketcan::health::CanHealth> for CanHealthRow {
    fn from(h: robobus_link::socketcan::health::CanHealth) -> Self {
        use robobus_link::socketcan::health::ControllerState as S;
        let (advice, classic) = (h.advice(), h.classic());
        let robobus_link::socketcan::health::CanHealth {
            iface,
            kind,
            up,
            carrier,
            state,
            tx_errors,
            rx_errors,
            restart_ms,
            bitrate,
            data_bitrate,
            fd,
            mtu,
            stats,
            rx_frame_errors,
            tx_frame_errors,
            rx_dropped,
            tx_dropped,
        } = h;
        Self {
            id: iface.clone(),
            kind,
            state: state.map(|s| match s {
                S::ErrorActive => ControllerState::ErrorActive,
                S::ErrorWarning => ControllerState::ErrorWarning,
                S::ErrorPassive => ControllerState::ErrorPassive,
                S::BusOff => ControllerState::BusOff,
                S::Stopped => ControllerState::Stopped,
                S::Sleeping => ControllerState::Sleeping,
                S::Unknown(v) => ControllerState::Unknown(v),
            }),
            advice,
            interface: Some(Interface {
                iface,
                up,
                carrier,
                tx_errors,
                rx_errors,
                restart_ms,
                bitrate,
                data_bitrate,
                fd,
                mtu,
                stats: stats.map(|s| DeviceStats {
                    bus_error: s.bus_error,
                    error_warning: s.error_warning,
                    error_passive: s.error_passive,
                    bus_off: s.bus_off,
                    arbitration_lost: s.arbitration_lost,
                    restarts: s.restarts,
                }),
                rx_frame_errors,
                tx_frame_errors,
                rx_dropped,
                tx_dropped,
                classic,
            }),
        }
    }
}

impl Operation for CanHealth {
    const OP: &'static str = "whj.can-health";
    const FAMILY: Family = Family::Whj;
    const DOC: OpDoc = OpDoc {
        args: "-",
        report: "one row, the interface (`id`): `kind`, `up`, `carrier`, `state` \
                 (`error-active`, `error-warning`, `error-passive`, `bus-off`, `stopped`; null \
                 without a controller, as on vcan), `tx_errors`, `rx_errors` (where the driver \
                 reports them), `restart_ms`, `bitrate`, `data_bitrate`, `fd` (CAN FD on; null \
                 without a controller), `mtu`, `classic` (FD off, or MTU 16 without a \
                 controller: WHJ joints cannot hear it; `advice` gives the CAN FD command), \
                 `stats` (changes to error-warning, error-passive, bus-off; restarts; bus \
                 errors), frame error and drop counts, `advice`. Nothing is sent on the bus; a \
                 bus without a CAN interface (UDP, simulated) is a row without a controller \
                 (`kind` and `state` null, `advice` says so). A telemetry stream takes it",
        confirm: "-",
    };
    type Row = CanHealthRow;
    type Summary = ();

    fn bus(&self) -> Option<&str> {
        self.bus.as_deref()
    }

    fn effect(&self) -> Effect {
        Effect::Read
    }

    fn check(&self) -> R<Confirm> {
        Ok(Confirm::NONE)
    }

    fn plan(&self, _baud: BaudRate) -> R<Plan> {
        let mut p = WhjSteps::default();
        p.notes.push(
            "reads the CAN interface's state from the kernel (netlink); nothing is sent on \
             the bus"
                .into(),
        );
        Ok(plan_of(Self::OP, p, true, Confirm::NONE))
    }

    /// On the station's WHJ bus: its interface is the bus's address (`can0`) or, for a
    /// robot file's bus, the file's `iface`. A bus without one (UDP, a simulator) is a row
    /// without a controller that says so.
    #[cfg(target_os = "linux")]
    fn run(&self, cx: &mut RunCx<'_, '_>) -> Result<Report<CanHealthRow, ()>, OpError> {
        use robobus_link::socketcan::health::{self, HealthError};
        let port = cx.station.whj(self.bus())?;
        let name = port.name();
        let iface = port.can_interface();
        let row = match iface.map(health::read) {
            None | Some(Err(HealthError::NoSuchInterface(_) | HealthError::BadName(_))) => {
                CanHealthRow {
                    id: name.to_owned(),
                    kind: None,
                    state: None,
                    advice: Some(format!(
                        "{name} is not a CAN interface (a UDP or simulated bus): it has no \
                         CAN controller"
                    )),
                    interface: None,
                }
            }
            Some(Err(e)) => {
                return Err(OpError::Device(format!("{}: {e}", iface.unwrap_or(name))));
            }
            Some(Ok(h)) => h.into(),
        };
        Ok(Report::with_rows(Self::OP, name, vec![row]))
    }

    /// A CAN controller's state is read from Linux's SocketCAN only: the error says where
    /// to look instead.
    #[cfg(not(target_os = "linux"))]
    fn run(&self, cx: &mut RunCx<'_, '_>) -> Result<Report<CanHealthRow, ()>, OpError> {
        let port = cx.station.whj(self.bus())?;
        Err(OpError::NotAvailable(format!(
            "whj.can-health on {}: a CAN controller's state is read from Linux's SocketCAN \
             (netlink) only; on this system run `robobus whj monitor` on the bus (an \
             adapter's bus-off, error-passive and overruns show there) or `robobus doctor`",
            port.name()
        )))
    }
}

#[cfg(all(test, target_os = "linux"))]
mod tests {
    use robobus_link::socketcan::health::{CanDeviceStats, CanHealth, ControllerState as S};
    use serde_json::{Value, json};

    use super::CanHealthRow;

    /// A controller's health with every field set, as the kernel reports a classic CAN
    /// adapter gone error-passive.
    fn health(state: S) -> CanHealth {
        CanHealth {
            iface: "can1".into(),
            kind: Some("slcan".into()),
            up: true,
            carrier: true,
            state: Some(state),
            tx_errors: Some(130),
            rx_errors: Some(4),
            restart_ms: Some(100),
            bitrate: Some(1_000_000),
            data_bitrate: None,
            fd: Some(false),
            mtu: Some(16),
            stats: Some(CanDeviceStats {
                bus_error: 1,
                error_warning: 2,
                error_passive: 3,
                bus_off: 4,
                arbitration_lost: 5,
                restarts: 6,
            }),
            rx_frame_errors: Some(7),
            tx_frame_errors: Some(8),
            rx_dropped: Some(9),
            tx_dropped: Some(10),
        }
    }

    #[test]
    fn an_interfaces_row_is_the_kernels_health_with_its_advice_classic_and_id() {
        for state in [S::ErrorPassive, S::BusOff, S::Unknown(9)] {
            let h = health(state);
            // The row as the catalogue has always written it: the health's own fields,
            // its advice, whether it is classic CAN, and the interface as the ID.
            let mut want = serde_json::to_value(&h).unwrap();
            want["advice"] = h.advice().map_or(Value::Null, Value::from);
            want["classic"] = Value::from(h.classic());
            want["id"] = Value::from(h.iface.clone());
            let got = serde_json::to_value(CanHealthRow::from(h)).unwrap();
            assert_eq!(got, want);
        }
        let row = serde_json::to_value(CanHealthRow::from(health(S::Unknown(9)))).unwrap();
        assert_eq!(
            (&row["state"], &row["classic"], &row["stats"]["bus_off"]),
            (&json!({"unknown": 9}), &json!(true), &json!(4))
        );
    }
}
