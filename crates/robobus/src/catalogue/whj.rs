//! The WHJ operations (`whj.*`): one file per operation (its request, under the CLI's
//! names with `-` written `_`, its typed report, check, plan and run through
//! [`crate::ops::whj`]), and what they share here: the joint-ID and register parsers, the
//! joint model's current scale, `plan_of`, the connect note every plan opens with, and
//! `bus_report` / `joint_report`, the report of rows run on the station's bus.

use std::time::Duration;

use robobus_whj::units::CurrentScale;
use robobus_whj::{JointId, RegisterAddr, RegisterInfo, Request as Wire, WorkMode};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::args::Ids;
use super::bounds;
use super::plan::WhjSteps;
use crate::ops::OpError;
use crate::ops::whj::{self as ops, ServoLoop, TargetArgs};
use crate::whj::JointBusConfig;

mod backup;
mod can_health;
#[cfg(feature = "cli")]
pub mod cli;
mod defaults;
mod diff;
mod end_board;
mod registers;
mod release_iap;
mod restore;
mod sample;
mod set_id;
mod set_rates;
mod settings;
mod wave;
mod write;

pub use backup::Backup;
pub use can_health::{CanHealth, CanHealthRow, ControllerState, DeviceStats, Interface};
pub use defaults::Defaults;
pub use diff::{Diff, DiffSummary};
pub use end_board::{EndBoard, EndBoardAction, EndBoardRow, IoMode};
pub use registers::{RegisterRow, Registers};
pub use release_iap::{ReleaseIap, Released};
pub use restore::{Restore, RestoreSummary};
pub use sample::Sample;
pub use set_id::SetId;
pub use set_rates::{SetRates, SetRatesSummary};
pub use settings::SettingsRow;
pub use wave::{GONE_AFTER, Shape, Wave, WaveMode, WaveRow};
pub use write::Write;

mod clear;
mod current;
mod disable;
mod enable;
mod info;
mod mode;
mod r#move;
mod read;
mod save;
mod scan;
mod speed;
mod status;
mod zero;

pub use clear::Clear;
pub use current::Current;
pub use disable::Disable;
pub use enable::Enable;
pub use info::Info;
pub use mode::Mode;
pub use r#move::Move;
pub use read::Read;
pub use save::Save;
pub use scan::{Scan, ScanSummary};
pub use speed::Speed;
pub use status::{Status, StatusRow};
pub use zero::Zero;

/// Work mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum ModeName {
    /// Open loop (PWM duty; not recommended).
    OpenLoop,
    /// Current (torque) servo.
    Current,
    /// Speed servo.
    Speed,
    /// Position servo (factory default).
    Position,
}

/// Joint model (current scale).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum Model {
    /// WHJ03.
    Whj03,
    /// WHJ10.
    Whj10,
    /// WHJ30.
    Whj30,
    /// WHJ60 (2 mA per count).
    Whj60,
    /// WHJ120 (2 mA per count).
    Whj120,
}

impl Model {
    const fn scale(self) -> CurrentScale {
        match self {
            Self::Whj60 | Self::Whj120 => CurrentScale::TwoMilliamps,
            _ => CurrentScale::OneMilliamp,
        }
    }
}

type R<T> = Result<T, OpError>;

fn joint(option: &str, v: u32) -> R<JointId> {
    JointId::new(u8::try_from(v).unwrap_or(u8::MAX)).map_err(|_| {
        OpError::invalid(
            option,
            v,
            robobus_whj::JointIdError { value: v }.to_string(),
        )
    })
}

/// A register by name or address (as `robobus whj read` takes it).
pub fn parse_register(s: &str) -> Result<(RegisterAddr, Option<&'static RegisterInfo>), String> {
    let t = s.trim();
    if let Some(v) = parse_u32(t) {
        let raw = u8::try_from(v).unwrap_or(u8::MAX);
        let addr = RegisterAddr::new(raw)
            .map_err(|_| robobus_whj::RegisterAddrError { value: v }.to_string())?;
        return Ok((addr, RegisterInfo::by_addr(addr)));
    }
    RegisterInfo::by_name(t)
        .map(|i| (i.addr, Some(i)))
        .ok_or_else(|| {
            format!(
                "no register is named `{t}` (names as in `robobus whj registers`, e.g. \
             SYS_TEMP, cur_position; or an address 0x00..=0x91)"
            )
        })
}

fn parse_u32(t: &str) -> Option<u32> {
    match t.strip_prefix("0x").or_else(|| t.strip_prefix("0X")) {
        Some(h) => u32::from_str_radix(h, 16).ok(),
        None => t.parse().ok(),
    }
}

/// An end-board register by name or address 0x00..=0x7F.
pub fn parse_end_board_register(s: &str) -> Result<u8, String> {
    let t = s.trim();
    if let Some(v) = parse_u32(t) {
        return u8::try_from(v)
            .ok()
            .filter(|a| *a < 0x80)
            .ok_or_else(|| format!("end-board register {v:#x} is out of range 0x00..=0x7F"));
    }
    robobus_whj::broadcast::EndBoardRegister::by_name(t)
        .map(|r| r.addr)
        .ok_or_else(|| format!("no end-board register is named `{t}`"))
}

const fn work_mode(m: ModeName) -> WorkMode {
    match m {
        ModeName::OpenLoop => WorkMode::OpenLoop,
        ModeName::Current => WorkMode::Current,
        ModeName::Speed => WorkMode::Speed,
        ModeName::Position => WorkMode::Position,
    }
}

fn step_limit() -> f64 {
    JointBusConfig::default().step_limit_deg
}

fn each(joints: &[JointId], f: impl Fn(JointId) -> Wire) -> WhjSteps {
    let mut p = WhjSteps::default();
    for &j in joints {
        p.push(f(j));
    }
    p
}

fn scale_for(model: Option<Model>, dry_run: bool, option: &str) -> R<CurrentScale> {
    match model {
        Some(m) => Ok(m.scale()),
        None if dry_run => Err(OpError::invalid(
            option,
            "(no model)",
            "converting mA to counts needs the joint model in a plan: give model (--model) \
             whj03|whj10|whj30|whj60|whj120",
        )),
        None => Ok(CurrentScale::OneMilliamp),
    }
}

fn one_joint(joints: &[JointId], what: &str) -> R<JointId> {
    match joints {
        [one] => Ok(*one),
        _ => Err(OpError::invalid(
            what,
            joints.len(),
            "one joint, unless broadcast is asked for (--broadcast; joints 1..=7 then share one frame)",
        )),
    }
}

fn target_steps(args: &TargetArgs, scale: CurrentScale) -> R<WhjSteps> {
    let mut p = WhjSteps::default();
    p.push(ops::target_request(args, scale)?);
    let what = if args.servo == ServoLoop::Speed {
        "speed"
    } else {
        "current"
    };
    match args.duration {
        Some(d) => {
            let zero = TargetArgs {
                value: 0.0,
                ..*args
            };
            #[allow(clippy::cast_possible_truncation)] // <= 3600 s
            p.push_at(d.as_micros() as u64, ops::target_request(&zero, scale)?);
            p.notes.push(format!(
                "{what} target, then target 0 after {} s (also on Ctrl-C); the joint must be \
                 enabled and in {what} mode",
                d.as_secs_f64()
            ));
        }
        None => p.notes.push(format!(
            "the joint keeps this {what} target after the command exits: stop it with \
             `robobus whj {what} {} 0` or `robobus whj disable {}`; the joint must be enabled \
             and in {what} mode",
            args.joint.get(),
            args.joint.get()
        )),
    }
    Ok(p)
}

/// Heads `steps`' notes with the connect a real run sends each of its joints first
/// ([`super::plan::connect_note`]).
pub(crate) fn connect_first(steps: &mut WhjSteps) {
    let mut joints: Vec<JointId> = Vec::new();
    for (_, r) in &steps.steps {
        if let Some(j) = r.joint()
            && !joints.contains(&j)
        {
            joints.push(j);
        }
    }
    if let Some(note) = super::plan::connect_note(&joints) {
        steps.notes.insert(0, note);
    }
}

/// The plan of a WHJ operation `op`: `steps` as frames, headed by the connect a real run
/// sends each joint first (`connect`: `false` for the connect itself and for an
/// operation that sends nothing to a joint), with what it needs confirmed.
pub(crate) fn plan_of(
    op: &str,
    mut steps: WhjSteps,
    connect: bool,
    confirm: super::operation::Confirm,
) -> super::plan::Plan {
    if connect {
        connect_first(&mut steps);
    }
    let mut plan = super::plan::Plan::whj(op, &steps);
    plan.confirm = confirm.class;
    plan.confirm_text = confirm.text;
    plan
}

/// Whether a timed motion is run first on the simulator seeded with the real joints
/// ([`crate::ops::preflight`]): in a request `"preflight": true` (always), `false`
/// (never) or left out (by default: when the plan lasts at most 60 s, which the simulator
/// runs in well under a second); on the command line `--preflight` / `--no-preflight`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(from = "Option<bool>", into = "Option<bool>")]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct PreflightArg {
    /// Run the motion on the simulator seeded with the joint first, and refuse it before
    /// its first frame if the simulated joint would fault or be clamped (the default for
    /// plans of at most 60 s).
    #[cfg_attr(feature = "cli", arg(long, conflicts_with = "no_preflight"))]
    preflight: bool,
    /// Do not run the pre-flight on the simulator.
    #[cfg_attr(feature = "cli", arg(long))]
    no_preflight: bool,
}

impl PreflightArg {
    /// Asked for always (`Some(true)`), never (`Some(false)`), or by default (`None`).
    pub const fn asked(self) -> Option<bool> {
        match (self.preflight, self.no_preflight) {
            (true, _) => Some(true),
            (false, true) => Some(false),
            (false, false) => None,
        }
    }

    /// Not asked either way (left out of a request's JSON).
    pub const fn is_default(&self) -> bool {
        !self.preflight && !self.no_preflight
    }
}

impl From<Option<bool>> for PreflightArg {
    fn from(v: Option<bool>) -> Self {
        Self {
            preflight: v == Some(true),
            no_preflight: v == Some(false),
        }
    }
}

impl From<PreflightArg> for Option<bool> {
    fn from(v: PreflightArg) -> Self {
        v.asked()
    }
}

impl JsonSchema for PreflightArg {
    fn schema_name() -> std::borrow::Cow<'static, str> {
        "Preflight".into()
    }

    fn json_schema(generator: &mut schemars::SchemaGenerator) -> schemars::Schema {
        <Option<bool>>::json_schema(generator)
    }
}

/// The note a plan gets when its run is pre-flown on the simulator: what is read first
/// and what refuses it.
pub(crate) fn preflight_note(joint: JointId, asked: Option<bool>, plan_s: f64) -> Option<String> {
    let plan = Duration::try_from_secs_f64(plan_s).unwrap_or(Duration::MAX);
    crate::ops::preflight::wanted(asked, plan).then(|| {
        format!(
            "pre-flight: before the first frame joint {j}'s identity, status, mode and settings \
             (whj backup's registers) are read, and these frames run on the simulator seeded \
             with them, faster than real time; a set-point the simulated joint could not \
             follow (clamped to the step limit), error bits it latched, a failed run or a \
             protection derating refuse the run, naming the frame, its time and the reason, \
             nothing sent to the joint (--no-preflight runs it without)",
            j = joint.get()
        )
    })
}

/// The joints of a request's `joints` list, sorted (the CLI's `<JOINTS>`).
pub(crate) fn joint_list(joints: &Ids) -> R<Vec<JointId>> {
    joints.parse_sorted::<JointId>("<JOINTS>")
}

/// The joints `ids` a WHJ motion request on `bus` sets moving, running `servo`.
pub(crate) fn moved(bus: Option<&str>, ids: Vec<u8>, servo: ServoLoop) -> super::Moved {
    super::Moved {
        family: super::Family::Whj,
        bus: bus.map(str::to_owned),
        ids,
        servo,
    }
}

/// One joint's row of a report whose run fails as a whole when that joint does.
pub(crate) type JointRow<T> = crate::ops::DeviceResult<u8, T>;

/// The report of `op` on the station's WHJ bus `bus` (the only one when `None`): `rows`
/// runs it on that bus, a row per joint.
pub(crate) fn bus_report<T: Serialize>(
    cx: &super::operation::RunCx<'_, '_>,
    op: &str,
    bus: Option<&str>,
    rows: impl FnOnce(&crate::whj::JointBus) -> R<Vec<JointRow<T>>>,
) -> R<super::operation::Report<JointRow<T>, ()>> {
    let port = cx.station.whj(bus)?;
    let rows = rows(port.bus())?;
    Ok(super::operation::Report::devices(op, port.name(), rows))
}

/// The report of `op` on joint `j` of the station's WHJ bus `bus`: `run` runs it there,
/// its one row (a failure fails the run as a whole).
pub(crate) fn joint_report<T: Serialize>(
    cx: &super::operation::RunCx<'_, '_>,
    op: &str,
    bus: Option<&str>,
    j: JointId,
    run: impl FnOnce(&crate::whj::JointBus) -> R<T>,
) -> R<super::operation::Report<JointRow<T>, ()>> {
    bus_report(cx, op, bus, |b| {
        Ok(vec![crate::ops::DeviceResult::ok(j.get(), run(b)?)])
    })
}

fn duration(d: Option<f64>) -> R<Option<Duration>> {
    d.map(|d| {
        bounds::TARGET_DURATION_S
            .check("--duration", d)
            .map(Duration::from_secs_f64)
    })
    .transpose()
}
