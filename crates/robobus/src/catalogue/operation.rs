//! What every operation of the catalogue is: the [`Operation`] trait, its typed
//! [`Report`], and the context a run gets ([`RunCx`]).
//!
//! One operation is one file: its request (a serde + schemars struct), its report row and
//! summary types, how it is checked and planned, what it does to its devices and how it
//! runs. One row of the registry (`catalogue/mod.rs`) registers it for the dispatcher,
//! the published schemas, the operation table, and every front end that speaks the
//! catalogue (CLI, studio, Python, the bridge).

use std::fmt::Debug;
use std::time::Duration;

use robobus_wck::BaudRate;
use schemars::JsonSchema;
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use super::bounds::ConfirmClass;
use super::effect::{Effect, Moved};
use super::plan::{Family, Plan};
use crate::error::ErrorKind;
use crate::ops::{Control, DeviceResult, OpError, worst_kind};
use crate::station::Station;

/// The operation table's columns for one operation: its arguments (with units and
/// defaults), what its report holds, and what it needs confirmed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OpDoc {
    /// The arguments, their units, ranges and defaults (`ids`="0-30", `all_bauds`).
    pub args: &'static str,
    /// What the report's `results` and `summary` hold.
    pub report: &'static str,
    /// What needs `confirm: true` (`-`: nothing).
    pub confirm: &'static str,
}

/// What a request needs confirmed before it runs.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Confirm {
    /// The class of what it changes (EEPROM, flash, an ID, a register).
    pub class: ConfirmClass,
    /// The question a front end asks the user (set when `class` is not `None`).
    pub text: Option<String>,
}

impl Confirm {
    /// Nothing to confirm.
    pub const NONE: Self = Self {
        class: ConfirmClass::None,
        text: None,
    };

    /// `class`, asked with `text`.
    pub fn of(class: ConfirmClass, text: impl Into<String>) -> Self {
        if class == ConfirmClass::None {
            return Self::NONE;
        }
        Self {
            class,
            text: Some(text.into()),
        }
    }
}

/// One operation of the catalogue (see the [module docs](self)).
///
/// The dispatcher calls [`check`](Operation::check) first and refuses a request that
/// needs confirmation and lacks it ([`ErrorKind::Refused`], nothing sent) before
/// [`run`](Operation::run) is called: an operation's `run` never asks again.
pub trait Operation:
    Debug + Clone + PartialEq + Serialize + DeserializeOwned + JsonSchema + Send + Sync + 'static
{
    /// Its name in JSON (`"wck.status"`), the registry's key.
    const OP: &'static str;
    /// The family it acts on.
    const FAMILY: Family;
    /// Its row of the operation table.
    const DOC: OpDoc;
    /// One row of its report's `results`.
    type Row: Serialize + JsonSchema;
    /// Its report's `summary` (`()` when it has none).
    type Summary: Serialize + JsonSchema;

    /// The bus it names (`None`: the station's only one of the family, or none at all).
    fn bus(&self) -> Option<&str> {
        None
    }

    /// What it does to its devices (the facts read-only mode and arming are built on).
    fn effect(&self) -> Effect;

    /// The devices a [`Effect::Motion`] request sets moving, validated as a run
    /// validates them (`None` for any other request).
    #[allow(clippy::result_large_err)] // OpError carries the client errors by value
    fn moved(&self) -> Result<Option<Moved>, OpError> {
        Ok(None)
    }

    /// Whether the request carries `confirm: true`.
    fn confirmed(&self) -> bool {
        false
    }

    /// Sets `confirm: true` (what a front end sends once its user confirmed); a request
    /// that has nothing to confirm is left as it is.
    fn confirm(&mut self) {}

    /// Validates the arguments against the protocol's ranges and the host bounds, as a
    /// run validates them, without a station, and says what needs confirming.
    #[allow(clippy::result_large_err)] // OpError carries the client errors by value
    fn check(&self) -> Result<Confirm, OpError>;

    /// The exact packets / frames a run sends (the CLI's `--dry-run`), with the wCK
    /// packets shown at `baud`; nothing is opened.
    #[allow(clippy::result_large_err)] // OpError carries the client errors by value
    fn plan(&self, baud: BaudRate) -> Result<Plan, OpError>;

    /// Runs it on the station (checked and confirmed already).
    #[allow(clippy::result_large_err)] // OpError carries the client errors by value
    fn run(&self, cx: &mut RunCx<'_, '_>) -> Result<Report<Self::Row, Self::Summary>, OpError>;
}

/// What a run gets: the station, the caller's stop token and progress, and the front
/// end's [`Interaction`].
pub struct RunCx<'r, 'c> {
    /// The open buses (and robot file) the request runs on.
    pub station: &'r Station,
    /// The stop token and progress callback.
    pub control: &'r mut Control<'c>,
    /// What the front end offers while it runs.
    pub interaction: &'r mut dyn Interaction,
}

impl Debug for RunCx<'_, '_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RunCx").finish_non_exhaustive()
    }
}

/// What an interactive operation asks of its front end while it runs (today: `wck.teach`
/// by events, and each pose as it is recorded). The defaults suit a front end with no
/// user at hand: no events (a recording by events then runs until the stop token), the
/// poses kept in the report's summary.
pub trait Interaction {
    /// `wck.teach` by events: waits at most `wait` for the user's next action.
    fn teach_event(&mut self, wait: Duration) -> crate::ops::wck::TeachEvent {
        std::thread::sleep(wait);
        crate::ops::wck::TeachEvent::Nothing
    }

    /// `wck.teach`: a pose was recorded (an error ends the recording, the servos in their
    /// `on_stop` state).
    #[allow(clippy::result_large_err)] // OpError carries the client errors by value
    fn pose(&mut self, pose: &crate::ops::wck::Pose) -> Result<(), OpError> {
        let _ = pose;
        Ok(())
    }

    /// `robot.play`: one tick was sent (a front end records it; an error ends the run
    /// where it is).
    #[allow(clippy::result_large_err)] // OpError carries the client errors by value
    fn play_tick(&mut self, tick: &PlayTick<'_>) -> Result<(), OpError> {
        let _ = tick;
        Ok(())
    }

    /// `robot.play` of positions: the handle through which the front end blends a newer
    /// trajectory into the run between two of its ticks
    /// ([`Blend`](crate::catalogue::robot::Blend)); `None` (the default): none.
    fn play_blend(&self) -> Option<std::sync::Arc<crate::catalogue::robot::Blend>> {
        None
    }

    /// Whether the report's summary lists every pose (`false`: only their count, for a
    /// front end that writes them elsewhere as they come).
    fn keep_poses(&self) -> bool {
        true
    }
}

/// One tick, as a front end records it: the time since the start of the lead-in, and per
/// joint (by name, in the trajectory's order) the target sent (the trajectory's, or short
/// of it for a lagging WHJ joint) and the position it reported (`None`: no reply this
/// tick), degrees.
#[derive(Debug, Clone, Copy)]
pub struct PlayTick<'a> {
    /// Seconds since the run started (the lead-in included).
    pub t_s: f64,
    /// The joints' names.
    pub joints: &'a [String],
    /// Each joint's target this tick, degrees.
    pub targets: &'a [f64],
    /// Each joint's reported position this tick, degrees.
    pub positions: &'a [Option<f64>],
}

/// The [`Interaction`] of a front end without one: the defaults.
#[derive(Debug, Clone, Copy, Default)]
pub struct NoInteraction;

impl Interaction for NoInteraction {}

/// What a request did: the envelope of every operation's report, typed by the
/// operation's row `R` and summary `S` ([`Report`] without parameters is the JSON form
/// every front end carries: `R` and `S` are then JSON values).
///
/// `{"op", "bus", "results": [...], "summary"?, "failed"?, "error"?}`: `results` holds one
/// object per device (or per register), its ID under `id` for both families (a
/// broadcast's end board: `"end-board"`), beside the operation's report fields or `kind`
/// and `error`; `summary` the operation's whole-run report (scan, play, wave statistics);
/// `failed` the worst kind among the devices (`no-device` for a silent one), which a front
/// end maps to its exit code.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
#[serde(bound(
    serialize = "R: Serialize, S: Serialize",
    deserialize = "R: Deserialize<'de>, S: Deserialize<'de>"
))]
pub struct Report<R = serde_json::Value, S = serde_json::Value> {
    /// The operation (`"whj.status"`).
    pub op: String,
    /// The bus it ran on (the station's name; `robot` for the robot file, `host` for the
    /// host computer).
    pub bus: String,
    /// One row per device (or register).
    pub results: Vec<R>,
    /// The whole run's report, where the operation has one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub summary: Option<S>,
    /// The worst failure kind among the devices, if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub failed: Option<ErrorKind>,
    /// The message of that failure (every failed device's, joined by `; `).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
}

impl<R, S> Report<R, S> {
    /// An empty report of `op` on `bus`.
    pub fn new(op: &str, bus: &str) -> Self {
        Self {
            op: op.to_owned(),
            bus: bus.to_owned(),
            results: Vec::new(),
            summary: None,
            failed: None,
            error: None,
        }
    }

    /// A report of `op` on `bus` with these rows.
    pub fn with_rows(op: &str, bus: &str, results: Vec<R>) -> Self {
        Self {
            results,
            ..Self::new(op, bus)
        }
    }

    /// The summary set.
    #[must_use]
    pub fn summary(mut self, summary: S) -> Self {
        self.summary = Some(summary);
        self
    }

    /// Marks the run failed with `kind` and `error` (a failure already marked stays
    /// first: the messages are joined).
    pub fn fail(&mut self, kind: ErrorKind, error: impl Into<String>) {
        let error = error.into();
        if self.failed.is_none() {
            self.failed = Some(kind);
        }
        self.error = Some(match self.error.take() {
            Some(e) => format!("{e}; {error}"),
            None => error,
        });
    }

    /// The worst failure, for an exit code.
    pub const fn failed_kind(&self) -> Option<ErrorKind> {
        self.failed
    }
}

impl<R: Serialize, S: Serialize> Report<R, S> {
    /// The JSON form every front end carries (rows and summary as JSON values).
    pub fn erase(self) -> Report {
        Report {
            op: self.op,
            bus: self.bus,
            results: self
                .results
                .iter()
                .map(|r| serde_json::to_value(r).unwrap_or(serde_json::Value::Null))
                .collect(),
            summary: self
                .summary
                .and_then(|s| serde_json::to_value(s).ok())
                .filter(|s| !s.is_null()),
            failed: self.failed,
            error: self.error,
        }
    }
}

impl<I: Serialize, T: Serialize> Report<DeviceResult<I, T>, ()> {
    /// Per-device results as rows, with the worst failure and every failed device's
    /// message.
    pub fn devices(op: &str, bus: &str, results: Vec<DeviceResult<I, T>>) -> Self {
        Self::devices_with(op, bus, results)
    }
}

impl<I: Serialize, T: Serialize, S> Report<DeviceResult<I, T>, S> {
    /// [`Report::devices`] for an operation that also has a summary.
    pub fn devices_with(op: &str, bus: &str, results: Vec<DeviceResult<I, T>>) -> Self {
        let kind = worst_kind(&results);
        let mut r = Self::with_rows(op, bus, results);
        if let Some(kind) = kind {
            let text: Vec<String> = r
                .results
                .iter()
                .filter_map(|d| d.failure().map(|f| f.error.clone()))
                .collect();
            r.failed = Some(kind);
            r.error = Some(text.join("; "));
        }
        r
    }
}

/// `a == b` for two `&'static str` in a constant (the registry checks that each row's
/// name is its operation's [`Operation::OP`]).
#[must_use]
pub const fn same_name(a: &str, b: &str) -> bool {
    let (a, b) = (a.as_bytes(), b.as_bytes());
    if a.len() != b.len() {
        return false;
    }
    let mut i = 0;
    while i < a.len() {
        if a[i] != b[i] {
            return false;
        }
        i += 1;
    }
    true
}
