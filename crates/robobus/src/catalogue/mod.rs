//! The catalogue: one request type for every device operation of both families, one
//! dispatcher that runs them on a [station](crate::station) of open buses, and the
//! [`telemetry`] stream that front ends subscribe to.
//!
//! A [`Request`] is plain data: the CLI's arguments, a JSON document from a web page or a
//! pub/sub bridge, or Python keyword arguments all become one. [`plan()`] turns it into the
//! exact packets / frames the CLI's `--dry-run` prints ([`Plan::to_text`]); [`run`]
//! executes the same plan on a [`Station`](crate::station::Station)'s bus and returns the
//! [`Report`] envelope.
//! Validation (the protocol's ranged newtypes, the host [`bounds`] table), the confirmation
//! rule and the safe state on stop are decided here, not in a front end: a request that
//! needs `confirm: true` and lacks it is refused with [`ErrorKind::Refused`] before
//! anything is sent.
//!
//! # JSON form
//!
//! An object with the operation under `op` and its arguments beside it, named as the CLI's
//! arguments and options (`--all-bauds` is `all_bauds`), in the CLI's units. Unknown
//! fields are refused. `bus` names the station's bus when it holds more than one of the
//! family. ID lists are the CLI's text (`"0-5,7"`) or an array (`[0, 1]`).
//!
//! ```json
//! {"op": "wck.status", "ids": "0-2"}
//! {"op": "whj.move", "joint": 1, "degrees": 30, "max_speed": 20}
//! {"op": "whj.write", "joints": "1", "register": "SYS_ID", "value": 2, "confirm": true}
//! ```
//!
//! # The operations
//!
//! The table is generated from the registry (a test keeps it so: `UPDATE_SNAPSHOTS=1`
//! rewrites it):
//!
#![doc = include_str!("operations.md")]
//!
//! # Report
//!
//! `{"op", "bus", "results": [...], "summary"?, "failed"?}`: `results` holds one object
//! per device (or per register), its ID under `id` for both families (a broadcast's end
//! board: `"end-board"`), beside the operation's typed report fields or `kind` and
//! `error`; `summary` the operation's whole-run report (scan, play, wave statistics);
//! `failed` the worst kind among the devices (`no-device` for a silent one), which a
//! front end maps to its exit code. The CLI's `--json` uses the same field names (its WHJ
//! rows name the ID `joint`).

pub mod args;
pub mod bounds;
mod dispatch;
pub mod effect;
#[cfg(test)]
mod fixture;
pub mod host;
pub mod operation;
pub mod plan;
pub mod registry;
pub mod robot;
pub mod telemetry;
pub mod wck;
pub mod whj;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use operation::Operation;
use registry::registry;

pub use crate::error::ErrorKind;
pub use dispatch::{confirmation, plan, plan_at, run, run_typed, run_with, validate};
pub use effect::{Effect, Moved};
pub use operation::{Confirm, Interaction, NoInteraction, OpDoc, Report, RunCx};
pub use plan::{Family, Plan, PlanStep};
pub use registry::{DynOperation, OpInfo};
pub use telemetry::{Delivery, Sample, Subscriber, Telemetry};
pub use whj::GONE_AFTER;

registry! {
    "wck.scan" => WckScan(wck::Scan),
    "wck.status" => WckStatus(wck::Status),
    "wck.move" => WckMove(wck::Move),
    "wck.move10" => WckMove10(wck::Move10),
    "wck.read10" => WckRead10(wck::Read10),
    "wck.sync-move" => WckSyncMove(wck::SyncMove),
    "wck.passive" => WckPassive(wck::Passive),
    "wck.wheel" => WckWheel(wck::Wheel),
    "wck.brake" => WckBrake(wck::Brake),
    "wck.get" => WckGet(wck::Get),
    "wck.set" => WckSet(wck::Set),
    "wck.set-id" => WckSetId(wck::SetId),
    "wck.set-baud" => WckSetBaud(wck::SetBaud),
    "wck.program.upload" => WckProgramUpload(wck::ProgramUpload),
    "wck.program.download" => WckProgramDownload(wck::ProgramDownload),
    "wck.program.check" => WckProgramCheck(wck::ProgramCheck),
    "wck.teach" => WckTeach(wck::Teach),
    "wck.play" => WckPlay(wck::Play),
    "wck.sample" => WckSample(wck::Sample),
    "wck.tune" => WckTune(wck::Tune),
    "wck.backup" => WckBackup(wck::Backup),
    "wck.diff" => WckDiff(wck::Diff),
    "wck.restore" => WckRestore(wck::Restore),
    "whj.scan" => WhjScan(whj::Scan),
    "whj.info" => WhjInfo(whj::Info),
    "whj.status" => WhjStatus(whj::Status),
    "whj.enable" => WhjEnable(whj::Enable),
    "whj.disable" => WhjDisable(whj::Disable),
    "whj.mode" => WhjMode(whj::Mode),
    "whj.move" => WhjMove(whj::Move),
    "whj.speed" => WhjSpeed(whj::Speed),
    "whj.current" => WhjCurrent(whj::Current),
    "whj.zero" => WhjZero(whj::Zero),
    "whj.clear" => WhjClear(whj::Clear),
    "whj.save" => WhjSave(whj::Save),
    "whj.read" => WhjRead(whj::Read),
    "whj.write" => WhjWrite(whj::Write),
    "whj.registers" => WhjRegisters(whj::Registers),
    "whj.set-id" => WhjSetId(whj::SetId),
    "whj.wave" => WhjWave(whj::Wave),
    "whj.release-iap" => WhjReleaseIap(whj::ReleaseIap),
    "whj.sample" => WhjSample(whj::Sample),
    "whj.backup" => WhjBackup(whj::Backup),
    "whj.defaults" => WhjDefaults(whj::Defaults),
    "whj.end-board" => WhjEndBoard(whj::EndBoard),
    "whj.set-rates" => WhjSetRates(whj::SetRates),
    "whj.can-health" => WhjCanHealth(whj::CanHealth),
    "whj.diff" => WhjDiff(whj::Diff),
    "whj.restore" => WhjRestore(whj::Restore),
    "robot.sample" => RobotSample(robot::Sample),
    "robot.calibrate" => RobotCalibrate(robot::Calibrate),
    "robot.teleop" => RobotTeleop(robot::Teleop),
    "robot.play" => RobotPlay(robot::Play),
    "robot.teach" => RobotTeach(robot::Teach),
    "host.ports" => HostPorts(host::Ports),
    // What adding an operation takes (a test fixture: its file and this row).
    #[cfg(test)]
    "test.echo" => TestEcho(fixture::Echo),
}

impl Request {
    /// The operation's name (`"wck.status"`).
    pub fn op(&self) -> &'static str {
        self.operation().op()
    }

    /// The family the request is for.
    pub fn family(&self) -> Family {
        self.operation().family()
    }

    /// The request with `confirm: true` (what a front end sends once the user has
    /// confirmed; a request that needs no confirmation is returned as it is).
    #[must_use]
    pub fn confirmed(mut self) -> Self {
        self.operation_mut().confirm();
        self
    }

    /// The bus it names, if any.
    pub fn bus(&self) -> Option<&str> {
        self.operation().bus()
    }

    /// What the request does to its devices.
    pub fn effect(&self) -> Effect {
        self.operation().effect()
    }

    /// The devices a [`Effect::Motion`] request sets moving (`None` for any other
    /// request), validated as a run validates them.
    #[allow(clippy::result_large_err)] // OpError carries the client errors by value
    pub fn moved(&self) -> Result<Option<Moved>, crate::ops::OpError> {
        self.operation().moved()
    }

    /// Parses one request from JSON text. Bad JSON, an unknown operation or an unknown
    /// field is [`ErrorKind::BadInput`].
    pub fn parse(text: &str) -> Result<Self, crate::ops::OpError> {
        serde_json::from_str(text).map_err(|e| {
            crate::ops::OpError::invalid(
                "request",
                "JSON",
                format!("{e} (one request object, as `robobus schema` describes)"),
            )
        })
    }

    /// Parses one request, or a JSON array of them, from JSON text. Unknown operations and
    /// unknown fields are [`ErrorKind::BadInput`].
    pub fn parse_many(text: &str) -> Result<Vec<Self>, crate::ops::OpError> {
        let value: serde_json::Value = serde_json::from_str(text)
            .map_err(|e| crate::ops::OpError::invalid("request", "JSON", e.to_string()))?;
        let items = match value {
            serde_json::Value::Array(items) => items,
            one => vec![one],
        };
        items
            .into_iter()
            .enumerate()
            .map(|(n, v)| {
                serde_json::from_value(v).map_err(|e| {
                    crate::ops::OpError::invalid(
                        format!("request {}", n + 1),
                        "JSON",
                        e.to_string(),
                    )
                })
            })
            .collect()
    }
}

/// The JSON name of an error kind (`no-device`).
pub fn kind_name(k: ErrorKind) -> String {
    k.name().to_owned()
}

/// The JSON Schema of [`Request`] (one of the operations, each with its arguments).
pub fn request_schema() -> serde_json::Value {
    registry::root_schema::<Request>()
}

/// The JSON Schema of every operation's [`Report`]: one of them, each with its `op` and
/// its own typed rows and summary.
pub fn report_schema() -> serde_json::Value {
    registry::report_schema(&operations())
}

/// The operation table (Markdown), generated from the registry: what
/// `catalogue/operations.md` holds and the module docs show.
pub fn operation_table() -> String {
    registry::operation_table(&operations())
}

/// The JSON Schema of [`Plan`].
pub fn plan_schema() -> serde_json::Value {
    registry::root_schema::<Plan>()
}

/// The host [`bounds`] table as JSON, by name.
pub fn bounds_json() -> serde_json::Value {
    serde_json::to_value(
        bounds::BOUNDS
            .iter()
            .map(|(k, b)| (k.to_string(), b))
            .collect::<std::collections::BTreeMap<_, _>>(),
    )
    .unwrap_or_default()
}

/// Every schema in one object: `request`, `report`, `plan` and `bounds` (what
/// `robobus schema` prints and a web studio serves).
pub fn schemas() -> serde_json::Value {
    serde_json::json!({
        "request": request_schema(),
        "report": report_schema(),
        "plan": plan_schema(),
        "bounds": bounds_json(),
    })
}
