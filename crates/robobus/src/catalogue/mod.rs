//! The catalogue: one request type for every device operation of both families, one
//! dispatcher, a station of open buses, and the [`telemetry`] stream that front ends
//! subscribe to.
//!
//! A [`Request`] is plain data: the CLI's arguments, a JSON document from a web page or a
//! pub/sub bridge, or Python keyword arguments all become one. [`plan()`] turns it into the
//! exact packets / frames the CLI's `--dry-run` prints ([`Plan::to_text`]); [`run`]
//! executes the same plan on a [`Station`]'s bus and returns the [`Report`] envelope.
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
//! | op | arguments (units) | report `results` / `summary` | confirm |
//! |---|---|---|---|
//! | `wck.scan` | `ids`="0-30", `all_bauds` | found servos; summary: scan report | - |
//! | `wck.status` | `ids` | id, load, position, degrees | - |
//! | `wck.move` | `id`, `position` (0..=254), `torque` (0..=4) | `load_before`, `position_before` | - |
//! | `wck.move10` | `id` (0..=253), `position` (0..=1023), `torque` (0..=254) | reply fields | - |
//! | `wck.read10` | `id` | position10 | - |
//! | `wck.sync-move` | `positions` [0..=254], `torque` | (no reply) | - |
//! | `wck.passive` | `ids` | position | - |
//! | `wck.wheel` | `id`, `direction` (ccw/cw), `speed` (0..=15), `duration` s, `on_stop` | wheel fields, `ran_ms` | - |
//! | `wck.brake` | - | break fields | - |
//! | `wck.get` | `param` (gains, i-gain, speed, overload, bounds, io), `id` | the parameter | - |
//! | `wck.set` | `param`, `id`, `p` `d` / `i` / `speed` `accel` / `milliamps` / `lower` `upper` / `outputs`, `runtime` | read-back | EEPROM unless runtime |
//! | `wck.set-id` | `id`, `new_id` | verified at the new ID | ID |
//! | `wck.set-baud` | `id`, `rate` bit/s | verified at the new rate | EEPROM |
//! | `wck.program.upload` | `id`, `program` (text form) | read-back | EEPROM |
//! | `wck.program.download` | `id` | the program | - |
//! | `wck.program.check` | `program`, `id`=0 | summary: instructions, upload packet (nothing sent) | - |
//! | `wck.teach` | `ids` 0..N-1, `rate_hz` (0.1..=200), `duration` s (0.1..=3600), `torque`, `on_stop` | summary: poses | - |
//! | `wck.play` | `motion` (keyframe text), `rate_hz`=50, `on_stop` | summary: play report | - |
//! | `wck.sample` | `ids` | `position_deg`, `speed_deg_s`, `load` | - |
//! | `wck.tune` | `id`, `gains` (`[[P, D], ...]`), `amplitude`=20, `hold_ms`=1000, `torque`, `keep` (`none`, `runtime`, `eeprom`) | one row per gain set: `rise_ms`, `overshoot_pct`, `settling_ms`, `steady_state_error`; `summary`: `start`, `target`, `best`, `kept` and each set's trace | EEPROM with `keep: eeprom` |
//! | `wck.backup` | `id` | the settings (`p_gain`, `d_gain`, `i_gain`, `speed`, `accel`, `overload`, `lower`, `upper`); `summary` is the settings file | - |
//! | `wck.diff` | `id`, `settings` (a settings file's text), `factory` or `other` (a servo) | one row per group that differs (`setting`, `a`, `b`) | - |
//! | `wck.restore` | `id`, `settings` or `factory` | one row per group written (only those that differ, each verified); `summary`: `written` | EEPROM |
//! | `whj.scan` | `joints`="1-30" | identity per joint; summary: duplicates | - |
//! | `whj.info` | `joint` | identity, unique ID, limits, status | - |
//! | `whj.status` | `joints`, `broadcast`, `end_board` | status per joint (and `end-board`) | - |
//! | `whj.enable` / `whj.disable` | `joints` | enabled | - |
//! | `whj.mode` | `joints`, `mode` (open-loop, current, speed, position) | mode | - |
//! | `whj.move` | `joint`, `degrees` (±360), `max_speed` deg/s (0.1..=180)=10, `rate_hz` (1..=1000)=200, `from`, `on_stop` | move report | - |
//! | `whj.speed` | `joint`, `rpm` (±37.5), `duration` s (0.01..=3600), `on_stop` | target report | - |
//! | `whj.current` | `joint`, `milliamps` (±30000), `duration`, `model`, `on_stop` | target report | - |
//! | `whj.zero` | `joint` | zero report | - |
//! | `whj.clear` | `joints` | error before / after | - |
//! | `whj.save` | `joints` | saved | flash |
//! | `whj.read` | `joints`, `register` (name or address), `count`, `broadcast`, `end_board` | one row per register | - |
//! | `whj.write` | `joints`, `register`, `value` (register unit; counts with `raw`), `broadcast`, `end_board` (`REG=VALUE`), `model` | read-back | register class / flash |
//! | `whj.registers` | - | the register table (nothing sent) | - |
//! | `whj.set-id` | `joint`, `new_id` | set-id report | ID |
//! | `whj.wave` | `joint`, `shape`, `mode`, `amplitude`, `frequency` Hz=0.5, `offset`, `duration` s=4, `rate_hz`=200, `broadcast`, `model`, `on_stop` | last feedback; summary: wave statistics | - |
//! | `whj.release-iap` | `joints` | identity (connect / IAP release) | - |
//! | `whj.sample` | `joints`, `broadcast` | position, speed, current, enabled, error | - |
//! | `whj.backup` | `joint` | model, firmware, settings count; `summary` is the settings file (every register the joint keeps in flash, raw and in its unit) | - |
//! | `whj.defaults` | `joint` | model, firmware, settings count; `summary` is the settings file of the values the vendor documents for them (for `whj.restore`; not the factory-tuned gains and limits, nor the ID and bit rates) | - |
//! | `whj.end-board` | `action` (`status`, `power`, `io`, `force`), `volts` (0 / 12 / 24), `channel` (1 / 2), `mode` (`input` / `output`), `confirm` | one row `end-board`: status (`model`, `version`, `tool_volts`, the channels' direction and level, buttons, gripper / hand in position, `error`), a write's `register`, `read_back`, `meaning`, or the force sensor's raw `fx`..`mz` | register (power on, a channel's direction) |
//! | `whj.set-rates` | `joints`, `bitrate` (250k / 500k / 1M), `dbitrate` (250k..5M, ≥ bitrate), `confirm` | per joint: `before`, `after` (bit/s, read back), `saved`; `summary.next` (only when a joint saved): power-cycle, set the adapter, and how to find a lost joint | register |
//! | `whj.can-health` | - | one row, the interface: `kind`, `up`, `carrier`, `state` (`error-active` ... `bus-off`), `tx_errors`, `rx_errors`, `restart_ms`, `bitrate`, `data_bitrate`, `fd`, `mtu`, `classic` (CAN FD off: the advice sets it), `stats` (state changes, restarts), frame error and drop counts, `advice`; a bus without a CAN controller (UDP, simulated) is a row that says so | - |
//! | `whj.diff` | `joint`, `settings` (a settings file's text) or `other` (a joint) | one row per setting that differs (`a`, `b`, values and unit); against a file only the settings it holds, `summary.left_out` counting the joint's settings it leaves out | - |
//! | `whj.restore` | `joint`, `settings` | one row per differing setting: written or skipped (the bus identity is never written); `summary`: `written`, `saved`, `differ_after` | flash (and the `confirm` registers the file sets) |
//! | `robot.sample` | - | per joint of the station's robot file, by name: `position_deg`, `speed_deg_s`, `current_ma`, `load`, `enabled`, `error` | - |
//! | `robot.calibrate` | `seconds` (0.1..=600), `rate_hz`=20 (1..=100), `zero` (`end` / `keep`), `margin_deg`=2 (0..=30), `passive`=true | per joint by name: `samples`, `min_deg`, `max_deg`, `zero_deg`, `offset_rad` and `limits_rad` for the file (and their values before); `summary`: `readings`, `interrupted` | - |
//! | `robot.play` | `trajectory` (the CSV text: `time_s`, a column per joint of the robot file, degrees), `rate_hz`=50 (1..=500), `torque`=2 (wCK, 0..=4) | per joint by name: `commands`, `failed`, `start_deg`, `target_deg`, `position_deg`, `tracking_max_deg`, `tracking_rms_deg`; `summary`: `lead_in_s`, `duration_s`, `ticks`, `overruns`, `buses`, `skew_ms` and `late_ms` (`p50`, `p99`, `max`), `interrupted` | - |
//! | `robot.teach` | `seconds` (0.1..=3600), `rate_hz`=20 (1..=100), `joints` (names; none: all), `hold_ma`=0 (WHJ current while moved by hand, ±2000), `confirm` | per joint by name: `samples`, `failed`, `min_deg`, `max_deg`, `ended` (`holding`); `summary`: `trajectory` (the CSV `robot.play` plays), `points`, `dropped`, `readings`, `interrupted` | limp joints |
//! | `robot.teleop` | `map` (1..=64 of `leader`, `follower`, `scale`=1 (±10), `offset_deg`=0 (±360), `limits_deg`), `rate_hz`=50 (1..=200), `seconds` (0.1..=86400; none: until stopped), `leader_timeout_ms`=500 (10..=10000), `passive_leader`=true | per follower joint by name: `leader`, `commands`, `limited`, `failed`, `target_deg`, `position_deg`, `tracking_max_deg`, `tracking_rms_deg`; `summary`: `cycles`, `commanded`, `held`, `overruns`, `seconds`, `rate_hz`, `latency_ms` (`p50`, `p99`, `max`), `leaders` (readings, failures), `leader_lost`, `interrupted` | - |
//! | `host.ports` | - | one row per serial port the OS lists (`id`: `COM3`, `/dev/cu.usbserial-A10K`, `/dev/ttyUSB0`): `kind` (`usb`, `pci`, `bluetooth`, `unknown`), `vid`, `pid`, `manufacturer`, `product`, `serial_number`, `adapter` (recognised: `FTDI FT232R`, `CANable 2.0 (slcan firmware)`, ...), `use_for` (`wCK bus: --port PORT`, `CAN FD adapter: --bus slcan:PORT`), `latency_timer_ms` (Linux), `latency_advice` (this OS's); `summary`: `os`, `ports`, `left_out`, `where`. No port is opened | - |
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
pub mod follow;
pub mod guard;
pub mod host;
pub mod jog;
#[cfg(feature = "sim")]
pub mod live;
pub mod plan;
pub mod play;
pub mod robot;
pub mod teach;
pub mod telemetry;
pub mod teleop;
pub mod wck;
pub mod whj;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

pub use crate::error::ErrorKind;
pub use dispatch::{
    GONE_AFTER, Interaction, NoInteraction, confirmation, plan, plan_at, run, run_with, validate,
};
pub use effect::{Effect, Moved};
pub use plan::{Family, Plan, PlanStep};
pub use telemetry::{Delivery, Sample, Subscriber, Telemetry};

/// One request: an operation and its arguments (see the [module docs](self)).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(tag = "op")]
#[allow(missing_docs)] // each variant is documented by its argument struct
pub enum Request {
    #[serde(rename = "wck.scan")]
    WckScan(wck::Scan),
    #[serde(rename = "wck.status")]
    WckStatus(wck::Status),
    #[serde(rename = "wck.move")]
    WckMove(wck::Move),
    #[serde(rename = "wck.move10")]
    WckMove10(wck::Move10),
    #[serde(rename = "wck.read10")]
    WckRead10(wck::Read10),
    #[serde(rename = "wck.sync-move")]
    WckSyncMove(wck::SyncMove),
    #[serde(rename = "wck.passive")]
    WckPassive(wck::Passive),
    #[serde(rename = "wck.wheel")]
    WckWheel(wck::Wheel),
    #[serde(rename = "wck.brake")]
    WckBrake(wck::Brake),
    #[serde(rename = "wck.get")]
    WckGet(wck::Get),
    #[serde(rename = "wck.set")]
    WckSet(wck::Set),
    #[serde(rename = "wck.set-id")]
    WckSetId(wck::SetId),
    #[serde(rename = "wck.set-baud")]
    WckSetBaud(wck::SetBaud),
    #[serde(rename = "wck.program.upload")]
    WckProgramUpload(wck::ProgramUpload),
    #[serde(rename = "wck.program.download")]
    WckProgramDownload(wck::ProgramDownload),
    #[serde(rename = "wck.program.check")]
    WckProgramCheck(wck::ProgramCheck),
    #[serde(rename = "wck.teach")]
    WckTeach(wck::Teach),
    #[serde(rename = "wck.play")]
    WckPlay(wck::Play),
    #[serde(rename = "wck.sample")]
    WckSample(wck::Sample),
    #[serde(rename = "wck.tune")]
    WckTune(wck::Tune),
    #[serde(rename = "wck.backup")]
    WckBackup(wck::Backup),
    #[serde(rename = "wck.diff")]
    WckDiff(wck::Diff),
    #[serde(rename = "wck.restore")]
    WckRestore(wck::Restore),
    #[serde(rename = "whj.scan")]
    WhjScan(whj::Scan),
    #[serde(rename = "whj.info")]
    WhjInfo(whj::Info),
    #[serde(rename = "whj.status")]
    WhjStatus(whj::Status),
    #[serde(rename = "whj.enable")]
    WhjEnable(whj::Enable),
    #[serde(rename = "whj.disable")]
    WhjDisable(whj::Disable),
    #[serde(rename = "whj.mode")]
    WhjMode(whj::Mode),
    #[serde(rename = "whj.move")]
    WhjMove(whj::Move),
    #[serde(rename = "whj.speed")]
    WhjSpeed(whj::Speed),
    #[serde(rename = "whj.current")]
    WhjCurrent(whj::Current),
    #[serde(rename = "whj.zero")]
    WhjZero(whj::Zero),
    #[serde(rename = "whj.clear")]
    WhjClear(whj::Clear),
    #[serde(rename = "whj.save")]
    WhjSave(whj::Save),
    #[serde(rename = "whj.read")]
    WhjRead(whj::Read),
    #[serde(rename = "whj.write")]
    WhjWrite(whj::Write),
    #[serde(rename = "whj.registers")]
    WhjRegisters(whj::Registers),
    #[serde(rename = "whj.set-id")]
    WhjSetId(whj::SetId),
    #[serde(rename = "whj.wave")]
    WhjWave(whj::Wave),
    #[serde(rename = "whj.release-iap")]
    WhjReleaseIap(whj::ReleaseIap),
    #[serde(rename = "whj.sample")]
    WhjSample(whj::Sample),
    #[serde(rename = "whj.backup")]
    WhjBackup(whj::Backup),
    #[serde(rename = "whj.defaults")]
    WhjDefaults(whj::Defaults),
    #[serde(rename = "whj.end-board")]
    WhjEndBoard(whj::EndBoard),
    #[serde(rename = "whj.set-rates")]
    WhjSetRates(whj::SetRates),
    #[serde(rename = "whj.can-health")]
    WhjCanHealth(whj::CanHealth),
    #[serde(rename = "whj.diff")]
    WhjDiff(whj::Diff),
    #[serde(rename = "whj.restore")]
    WhjRestore(whj::Restore),
    #[serde(rename = "robot.sample")]
    RobotSample(robot::Sample),
    #[serde(rename = "robot.calibrate")]
    RobotCalibrate(robot::Calibrate),
    #[serde(rename = "robot.teleop")]
    RobotTeleop(teleop::Teleop),
    #[serde(rename = "robot.play")]
    RobotPlay(play::Play),
    #[serde(rename = "robot.teach")]
    RobotTeach(teach::Teach),
    #[serde(rename = "host.ports")]
    HostPorts(host::Ports),
}

macro_rules! each_variant {
    ($self:ident, $r:ident => $e:expr) => {
        match $self {
            Request::WckScan($r) => $e,
            Request::WckStatus($r) => $e,
            Request::WckMove($r) => $e,
            Request::WckMove10($r) => $e,
            Request::WckRead10($r) => $e,
            Request::WckSyncMove($r) => $e,
            Request::WckPassive($r) => $e,
            Request::WckWheel($r) => $e,
            Request::WckBrake($r) => $e,
            Request::WckGet($r) => $e,
            Request::WckSet($r) => $e,
            Request::WckSetId($r) => $e,
            Request::WckSetBaud($r) => $e,
            Request::WckProgramUpload($r) => $e,
            Request::WckProgramDownload($r) => $e,
            Request::WckProgramCheck($r) => $e,
            Request::WckTeach($r) => $e,
            Request::WckPlay($r) => $e,
            Request::WckSample($r) => $e,
            Request::WckTune($r) => $e,
            Request::WckBackup($r) => $e,
            Request::WckDiff($r) => $e,
            Request::WckRestore($r) => $e,
            Request::WhjScan($r) => $e,
            Request::WhjInfo($r) => $e,
            Request::WhjStatus($r) => $e,
            Request::WhjEnable($r) => $e,
            Request::WhjDisable($r) => $e,
            Request::WhjMode($r) => $e,
            Request::WhjMove($r) => $e,
            Request::WhjSpeed($r) => $e,
            Request::WhjCurrent($r) => $e,
            Request::WhjZero($r) => $e,
            Request::WhjClear($r) => $e,
            Request::WhjSave($r) => $e,
            Request::WhjRead($r) => $e,
            Request::WhjWrite($r) => $e,
            Request::WhjRegisters($r) => $e,
            Request::WhjSetId($r) => $e,
            Request::WhjWave($r) => $e,
            Request::WhjReleaseIap($r) => $e,
            Request::WhjSample($r) => $e,
            Request::WhjBackup($r) => $e,
            Request::WhjDefaults($r) => $e,
            Request::WhjEndBoard($r) => $e,
            Request::WhjSetRates($r) => $e,
            Request::WhjCanHealth($r) => $e,
            Request::WhjDiff($r) => $e,
            Request::WhjRestore($r) => $e,
            // A robot request acts on the station's robot file, not on one bus.
            Request::RobotSample(_)
            | Request::RobotCalibrate(_)
            | Request::RobotTeleop(_)
            | Request::RobotPlay(_)
            | Request::RobotTeach(_) => None,
            // A host request names no bus.
            Request::HostPorts(_) => None,
        }
    };
}

impl Request {
    /// The operation's name (`"wck.status"`).
    pub fn op(&self) -> String {
        serde_json::to_value(self)
            .ok()
            .and_then(|v| v.get("op").and_then(|o| o.as_str().map(str::to_owned)))
            .unwrap_or_default()
    }

    /// The family the request is for.
    pub const fn family(&self) -> Family {
        match self {
            Self::WckScan(_)
            | Self::WckStatus(_)
            | Self::WckMove(_)
            | Self::WckMove10(_)
            | Self::WckRead10(_)
            | Self::WckSyncMove(_)
            | Self::WckPassive(_)
            | Self::WckWheel(_)
            | Self::WckBrake(_)
            | Self::WckGet(_)
            | Self::WckSet(_)
            | Self::WckSetId(_)
            | Self::WckSetBaud(_)
            | Self::WckProgramUpload(_)
            | Self::WckProgramDownload(_)
            | Self::WckProgramCheck(_)
            | Self::WckTune(_)
            | Self::WckBackup(_)
            | Self::WckDiff(_)
            | Self::WckRestore(_)
            | Self::WckTeach(_)
            | Self::WckPlay(_)
            | Self::WckSample(_) => Family::Wck,
            Self::RobotSample(_)
            | Self::RobotCalibrate(_)
            | Self::RobotTeleop(_)
            | Self::RobotPlay(_)
            | Self::RobotTeach(_) => Family::Robot,
            Self::HostPorts(_) => Family::Host,
            _ => Family::Whj,
        }
    }

    /// The request with `confirm: true` (what a front end sends once the user has
    /// confirmed; a request that needs no confirmation is returned as it is).
    #[must_use]
    pub fn confirmed(mut self) -> Self {
        match &mut self {
            Self::WckSet(r) => r.confirm = true,
            Self::WckSetId(r) => r.confirm = true,
            Self::WckSetBaud(r) => r.confirm = true,
            Self::WckProgramUpload(r) => r.confirm = true,
            Self::WhjSave(r) => r.confirm = true,
            Self::WhjWrite(r) => r.confirm = true,
            Self::WhjSetId(r) => r.confirm = true,
            Self::WhjRestore(r) => r.confirm = true,
            Self::WckRestore(r) => r.confirm = true,
            Self::WckTune(r) => r.confirm = true,
            Self::RobotTeach(r) => r.confirm = true,
            Self::WhjEndBoard(r) => r.confirm = true,
            Self::WhjSetRates(r) => r.confirm = true,
            _ => {}
        }
        self
    }

    /// The bus it names, if any.
    pub fn bus(&self) -> Option<&str> {
        each_variant!(self, r => r.bus.as_deref())
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

/// What a request did: the envelope of every operation's report (see the
/// [module docs](self)).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Report {
    /// The operation (`"whj.status"`).
    pub op: String,
    /// The bus it ran on (the station's name).
    pub bus: String,
    /// One object per device (or register): `id` and the report's fields, or `id`,
    /// `kind` and `error`.
    pub results: Vec<serde_json::Value>,
    /// The whole run's report, where the operation has one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub summary: Option<serde_json::Value>,
    /// The worst failure kind among the devices (`no-device`, `device`, ...), if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub failed: Option<String>,
    /// The message of that failure.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
}

impl Report {
    /// The worst failure as an [`ErrorKind`] (for an exit code), if any.
    pub fn failed_kind(&self) -> Option<ErrorKind> {
        let k = self.failed.as_deref()?;
        [
            ErrorKind::BadInput,
            ErrorKind::Refused,
            ErrorKind::NoDevice,
            ErrorKind::Device,
            ErrorKind::Link,
            ErrorKind::Interrupted,
            ErrorKind::NotAvailable,
        ]
        .into_iter()
        .find(|e| kind_name(*e) == k)
    }
}

/// The JSON name of an error kind (`no-device`).
pub fn kind_name(k: ErrorKind) -> String {
    k.name().to_owned()
}

/// The JSON Schema of [`Request`] (one of the operations, each with its arguments).
pub fn request_schema() -> serde_json::Value {
    serde_json::to_value(schemars::schema_for!(Request)).unwrap_or_default()
}

/// The JSON Schema of [`Report`].
pub fn report_schema() -> serde_json::Value {
    serde_json::to_value(schemars::schema_for!(Report)).unwrap_or_default()
}

/// The JSON Schema of [`Plan`].
pub fn plan_schema() -> serde_json::Value {
    serde_json::to_value(schemars::schema_for!(Plan)).unwrap_or_default()
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
