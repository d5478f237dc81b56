//! The wCK operations (`wck.*`), one file each: its request (one struct per `robobus
//! wck` subcommand, its arguments under the CLI's names, `-` written `_`), its typed
//! report rows and summary, its check, plan and run through [`crate::ops::wck`]. Here:
//! what they share (the request macro, the argument parsers, the confirmation question,
//! the plan and row helpers); with the `cli` feature, the `cli` module: the value parsers of
//! the requests as command-line arguments.

use std::time::Duration;

use robobus_wck::program::Program;
use robobus_wck::{BaudRate, Command, Position, ServoId, TorqueLevel};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::args::{WckOnStop, byte};
use super::bounds::{self, ConfirmClass, NON_VOLATILE_TEXT};
use crate::ops::OpError;
use crate::ops::wck::settings::WckSettings;
use crate::ops::wck::{self as ops, WckPlan};

const fn default_hold() -> WckOnStop {
    WckOnStop::Hold
}
const fn default_passive() -> WckOnStop {
    WckOnStop::Passive
}

macro_rules! request {
    // `cli`: the request is also a `robobus` subcommand's arguments (`clap::Args`, with the
    // `cli` feature): each field's doc comment is its help; `bus` is the command's own.
    (cli $(#[$m:meta])* $name:ident { $($(#[$fm:meta])* $f:ident : $t:ty),* $(,)? }) => {
        $(#[$m])*
        #[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
        #[cfg_attr(feature = "cli", derive(clap::Args))]
        #[serde(deny_unknown_fields)]
        pub struct $name {
            /// The bus it acts on (the station's name for it); needed only when the
            /// station holds more than one bus of the family.
            #[serde(default, skip_serializing_if = "Option::is_none")]
            #[cfg_attr(feature = "cli", arg(skip))]
            pub bus: Option<String>,
            $($(#[$fm])* pub $f: $t,)*
        }
    };
    ($(#[$m:meta])* $name:ident { $($(#[$fm:meta])* $f:ident : $t:ty),* $(,)? }) => {
        $(#[$m])*
        #[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
        #[serde(deny_unknown_fields)]
        pub struct $name {
            /// The bus it acts on (the station's name for it); needed only when the
            /// station holds more than one bus of the family.
            #[serde(default, skip_serializing_if = "Option::is_none")]
            pub bus: Option<String>,
            $($(#[$fm])* pub $f: $t,)*
        }
    };
}
pub(crate) use request;

#[cfg(feature = "cli")]
pub mod cli;
mod program_check;
pub use program_check::{Instruction, ProgramCheck, ProgramCheckSummary, UploadPacket};
mod play;
pub use play::Play;
mod tune;
pub use tune::{KeepArg, Tune, TuneRow};
mod backup;
pub use backup::Backup;
mod diff;
pub use diff::{Diff, DiffSummary};
mod restore;
pub use restore::{Restore, RestoreSummary};
mod sample;
pub use sample::Sample;
mod teach;
pub use teach::{MAX_POSE_MS, Teach, TeachSummary};
mod set_baud;
pub use set_baud::{SetBaud, SetBaudRow};
mod program_upload;
pub use program_upload::ProgramUpload;
mod program_download;
pub use program_download::ProgramDownload;
mod common;
pub use common::{All, ParamRow};
mod scan;
pub use scan::{Scan, ScanSummary};
mod status;
pub use status::{Status, StatusRow};
mod r#move;
pub use r#move::{Move, MoveRow};
mod move10;
pub use move10::{Move10, Move10Row};
mod read10;
pub use read10::{Read10, Read10Row};
mod sync_move;
pub use sync_move::{SyncMove, SyncMoveRow};
mod passive;
pub use passive::{Passive, PassiveRow};
mod wheel;
pub use wheel::{Direction, Wheel, WheelRow};
mod brake;
pub use brake::{Brake, BrakeRow};
mod get;
pub use get::Get;
mod set;
pub use set::Set;
mod set_id;
pub use set_id::{SetId, SetIdRow};

/// A servo parameter (`wck get` / `wck set`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum Param {
    /// P and D gains.
    Gains,
    /// I gain.
    IGain,
    /// Speed level and acceleration range.
    Speed,
    /// Over-load threshold.
    Overload,
    /// Movement boundaries.
    Bounds,
    /// Digital outputs and A/D input.
    Io,
}

/// The settings a request names: its file's, or the factory ones with `factory`.
fn settings_of(text: Option<&String>, factory: bool) -> R<Option<WckSettings>> {
    match (text, factory) {
        (Some(_), true) => Err(OpError::invalid(
            "settings / factory",
            "both",
            "give one: a settings file or the factory settings",
        )),
        (Some(t), false) => WckSettings::parse(t).map(Some),
        (None, true) => Ok(Some(WckSettings::factory())),
        (None, false) => Ok(None),
    }
}

/// The plan of reading a servo's settings.
fn settings_reads(plan: &mut WckPlan, id: ServoId) {
    for c in [
        Command::GainRead { id },
        Command::IGainRead { id },
        Command::SpeedRead { id },
        Command::OverloadRead { id },
        Command::BoundaryRead { id },
    ] {
        plan.push(c);
    }
}

type R<T> = Result<T, OpError>;

fn sid(v: u32) -> R<ServoId> {
    byte("<ID>", v, ServoId::new)
}
fn pos(option: &str, v: u32) -> R<Position> {
    byte(option, v, Position::new)
}
fn torque(v: u32) -> R<TorqueLevel> {
    byte("--torque", v, TorqueLevel::new)
}
fn need(option: &str, v: Option<u32>) -> R<u32> {
    v.ok_or_else(|| OpError::invalid(option, "(missing)", "this parameter needs it"))
}
fn secs(option: &str, v: f64) -> R<Duration> {
    bounds::WCK_DURATION_S
        .check(option, v)
        .map(Duration::from_secs_f64)
}

fn each(ids: &[ServoId], f: impl Fn(ServoId) -> Command) -> WckPlan {
    let mut plan = WckPlan::default();
    for &id in ids {
        plan.push(f(id));
    }
    plan
}

fn program(text: &str) -> R<Program> {
    Program::parse(text).map_err(|e| {
        OpError::invalid(
            "program",
            format!("{}:{}", e.line, e.column),
            e.kind.to_string(),
        )
    })
}

/// The text a refusal of an unconfirmed wCK request says.
pub(crate) const fn confirm_text(class: ConfirmClass) -> &'static str {
    match class {
        ConfirmClass::Id => "This changes a servo's ID (EEPROM).",
        _ => NON_VOLATILE_TEXT,
    }
}

/// What a wCK request of `class` needs confirmed (the question for `class`).
pub(crate) fn confirm_of(class: ConfirmClass) -> super::Confirm {
    super::Confirm::of(class, confirm_text(class))
}

/// The plan of a wCK request: `plan`'s packets at `baud`, with what it needs confirmed.
pub(crate) fn plan_of(
    op: &str,
    plan: &WckPlan,
    baud: BaudRate,
    class: ConfirmClass,
) -> super::Plan {
    let mut p = super::Plan::wck(op, plan, baud);
    p.confirm = class;
    p.confirm_text = (class != ConfirmClass::None).then(|| confirm_text(class).to_owned());
    p
}

/// The servos a wCK motion request sets moving (on the bus it names).
pub(crate) fn moved(bus: Option<&str>, ids: Vec<u8>) -> super::Moved {
    super::Moved {
        family: super::Family::Wck,
        bus: bus.map(str::to_owned),
        ids,
        servo: crate::ops::whj::ServoLoop::Position,
    }
}

/// Servos `0..n` (the servos a request for "servos 0..N-1" moves).
pub(crate) fn servos(n: usize) -> Vec<u8> {
    (0..n).filter_map(|i| u8::try_from(i).ok()).collect()
}

/// A row of one servo: its `id` beside the value's fields.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, JsonSchema)]
pub struct IdRow<T> {
    /// The servo.
    pub id: u8,
    /// The value.
    #[serde(flatten)]
    pub value: T,
}

/// The size of a servo's motion program: `wck.program.upload`'s read-back,
/// `wck.program.download`'s reading.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, JsonSchema)]
pub struct ProgramCount {
    /// How many instructions the servo's program holds.
    pub instructions: u8,
}

impl ProgramCount {
    /// The count a motion data reply carries (`None`: another reply).
    pub(crate) const fn of(reply: robobus_wck::Reply) -> Option<Self> {
        match reply {
            robobus_wck::Reply::MotionCount(n) => Some(Self {
                instructions: n.get(),
            }),
            _ => None,
        }
    }
}

/// The row type of a report without rows (its `results` are always empty).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, JsonSchema)]
pub enum NoRow {}

pub(crate) use ops::confirm_reads_for;
