//! The WHJ requests (`whj.*`): one struct per `robobus whj` subcommand, its arguments
//! under the CLI's names (`-` written `_`), and how each is planned through
//! [`crate::ops::whj`].

use std::time::Duration;

use robobus_whj::registers::{self, Half};
use robobus_whj::units::CurrentScale;
use robobus_whj::{JointId, RegisterAddr, RegisterInfo, Request as Wire, WorkMode};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::args::{Ids, WhjOnStop};
use super::bounds::{self, ConfirmClass, NON_VOLATILE_TEXT};
use super::plan::WhjSteps;
use super::wck::request;
use crate::ops::OpError;
use crate::ops::whj::{self as ops, EndBoardArg, MoveArgs, ServoLoop, TargetArgs, WaveArgs};
use crate::whj::JointBusConfig;

pub(crate) mod end_board;
mod rates;
mod settings;

pub use end_board::{EndBoard, EndBoardAction, IoMode};
pub use rates::{CanHealth, SetRates};
pub(crate) use settings::DiffWith;
pub use settings::{Backup, Defaults, Diff, Restore};

fn default_scan_joints() -> Ids {
    Ids::Text("1-30".into())
}
const fn d10() -> f64 {
    10.0
}
const fn d200() -> f64 {
    200.0
}
const fn d05() -> f64 {
    0.5
}
const fn d4() -> f64 {
    4.0
}

request!(
    /// `whj.scan`: find joints (identity of every ID).
    Scan { /// Joint IDs to try (`"1-30"`).
        #[serde(default = "default_scan_joints")] joints: Ids }
);
request!(
    /// `whj.info`: identity, unique ID and position limits of a joint.
    Info { /// Joint ID, 1..=30.
        joint: u32 }
);
request!(
    /// `whj.status` (0x600+ID, or one broadcast 0x7F frame).
    Status {
        /// Joint IDs (`"1-7"`).
        joints: Ids,
        /// One broadcast status frame for joints 1..=7.
        #[serde(default)]
        broadcast: bool,
        /// With `broadcast`: the end board answers too.
        #[serde(default)]
        end_board: bool,
    }
);
request!(
    /// `whj.enable`: register 0x0A := 1.
    Enable { /// Joint IDs.
        joints: Ids }
);
request!(
    /// `whj.disable`: register 0x0A := 0.
    Disable { /// Joint IDs.
        joints: Ids }
);
request!(
    /// `whj.mode`: work mode (register 0x30).
    Mode {
        /// Joint IDs.
        joints: Ids,
        /// `open-loop`, `current`, `speed` or `position`.
        mode: ModeName,
    }
);
request!(
    /// `whj.move`: smooth move in position mode.
    Move {
        /// Joint ID, 1..=30.
        joint: u32,
        /// Target angle, degrees, -360..=360.
        degrees: f64,
        /// Largest speed, degrees per second, 0.1..=180.
        #[serde(default = "d10")]
        max_speed: f64,
        /// Position frames per second, 1..=1000.
        #[serde(default = "d200")]
        rate_hz: f64,
        /// Start angle of a plan (a run reads the present position).
        #[serde(default)]
        from: Option<f64>,
        /// What a stop leaves the joint in: `hold` or `disable`.
        #[serde(default)]
        on_stop: WhjOnStop,
    }
);
request!(
    /// `whj.speed`: speed target (0x300+ID), output RPM.
    Speed {
        /// Joint ID.
        joint: u32,
        /// Target, RPM, -37.5..=37.5.
        rpm: f64,
        /// Keep it this many seconds (0.01..=3600), then target 0.
        #[serde(default)]
        duration: Option<f64>,
        /// What a stop leaves the joint in.
        #[serde(default)]
        on_stop: WhjOnStop,
    }
);
request!(
    /// `whj.current`: current target (0x400+ID), mA.
    Current {
        /// Joint ID.
        joint: u32,
        /// Target, mA, -30000..=30000.
        milliamps: f64,
        /// Keep it this many seconds (0.01..=3600), then target 0.
        #[serde(default)]
        duration: Option<f64>,
        /// Model for the plan's current scale (a run reads it from the joint).
        #[serde(default)]
        model: Option<Model>,
        /// What a stop leaves the joint in.
        #[serde(default)]
        on_stop: WhjOnStop,
    }
);
request!(
    /// `whj.zero`: the present position becomes 0° (register 0x0E := 1).
    Zero { /// Joint ID.
        joint: u32 }
);
request!(
    /// `whj.clear`: clear latched errors (0x0F := 1).
    Clear { /// Joint IDs.
        joints: Ids }
);
request!(
    /// `whj.save`: save the register table to flash; needs `confirm`.
    Save {
        /// Joint IDs.
        joints: Ids,
        /// Confirms the flash write.
        #[serde(default)]
        confirm: bool,
    }
);
request!(
    /// `whj.read`: registers by name or address.
    Read {
        /// Joint ID (with `broadcast`: joints 1..=7).
        joints: Ids,
        /// Register name (`cur_position`) or address (`"0x14"`).
        register: String,
        /// Registers, 1..=31 (default: 2 for a 32-bit pair, else 1).
        #[serde(default)]
        count: Option<u8>,
        /// One broadcast frame (0x0F).
        #[serde(default)]
        broadcast: bool,
        /// With `broadcast`: an end-board register too (name or address).
        #[serde(default)]
        end_board: Option<String>,
    }
);
request!(
    /// `whj.write`: a register in its unit, read back; the register's safety class decides
    /// (refused, or needs `confirm`).
    Write {
        /// Joint ID (with `broadcast`: joints 1..=7).
        joints: Ids,
        /// Register name or address.
        register: String,
        /// The value, in the register's unit (with `raw`: counts).
        value: f64,
        /// The value is in counts.
        #[serde(default)]
        raw: bool,
        /// One broadcast frame, then a read-back.
        #[serde(default)]
        broadcast: bool,
        /// With `broadcast`: an end-board write `REGISTER=VALUE`.
        #[serde(default)]
        end_board: Option<String>,
        /// Model for the current scale of a plan.
        #[serde(default)]
        model: Option<Model>,
        /// Confirms a write of the `confirm` class.
        #[serde(default)]
        confirm: bool,
    }
);
request!(
    /// `whj.registers`: the register table (nothing sent).
    Registers {}
);
request!(
    /// `whj.set-id`: new ID, saved to flash; needs `confirm`.
    SetId {
        /// Current ID.
        joint: u32,
        /// New ID, 1..=30.
        new_id: u32,
        /// Confirms the ID change.
        #[serde(default)]
        confirm: bool,
    }
);
request!(
    /// `whj.wave`: a test signal as servo frames.
    Wave {
        /// Joint ID.
        joint: u32,
        /// `sine` or `square`.
        #[serde(default)]
        shape: Shape,
        /// `position` (deg), `speed` (RPM) or `current` (mA).
        #[serde(default)]
        mode: WaveMode,
        /// Amplitude, >= 0.
        amplitude: f64,
        /// Hz, 0.01..=20 and at most `rate_hz` / 4.
        #[serde(default = "d05")]
        frequency: f64,
        /// Offset.
        #[serde(default)]
        offset: f64,
        /// Seconds, 0.01..=600.
        #[serde(default = "d4")]
        duration: f64,
        /// Frames per second, 1..=1000.
        #[serde(default = "d200")]
        rate_hz: f64,
        /// As broadcast frames (0x2F / 0x4F).
        #[serde(default)]
        broadcast: bool,
        /// Where a plan assumes the joint starts, degrees (a run measures it).
        #[serde(default)]
        from: Option<f64>,
        /// Model for the current scale of a plan.
        #[serde(default)]
        model: Option<Model>,
        /// What a stop leaves the joint in.
        #[serde(default)]
        on_stop: WhjOnStop,
    }
);
request!(
    /// `whj.release-iap`: start the application of joints in the bootloader (connect).
    ReleaseIap { /// Joint IDs.
        joints: Ids }
);
request!(
    /// `whj.sample`: one monitor sample (status and servo feedback, or one broadcast
    /// status frame).
    Sample {
        /// Joint IDs.
        joints: Ids,
        /// One broadcast status frame.
        #[serde(default)]
        broadcast: bool,
    }
);

/// Work mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum ModeName {
    /// Open loop.
    OpenLoop,
    /// Current servo.
    Current,
    /// Speed servo.
    Speed,
    /// Position servo.
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

/// Wave shape.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum Shape {
    /// Sine.
    #[default]
    Sine,
    /// Square.
    Square,
}

/// Which loop a wave drives.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum WaveMode {
    /// Position frames, degrees.
    #[default]
    Position,
    /// Speed frames, RPM.
    Speed,
    /// Current frames, mA.
    Current,
}

/// How a validated WHJ request runs.
#[derive(Debug, Clone)]
pub(crate) enum Job {
    Scan(Vec<JointId>),
    Info(JointId),
    Status(Vec<JointId>),
    BroadcastStatus(Vec<JointId>, bool),
    Enable(Vec<JointId>, bool),
    Mode(Vec<JointId>, WorkMode),
    Move(MoveArgs),
    Target(TargetArgs),
    Zero(JointId),
    Clear(Vec<JointId>),
    Save(Vec<JointId>),
    Read(Vec<JointId>, RegisterAddr, Option<u8>, bool, Option<u8>),
    Write {
        joints: Vec<JointId>,
        addr: RegisterAddr,
        value: f64,
        raw: bool,
        scale: Option<CurrentScale>,
        broadcast: bool,
        end_board: Option<EndBoardArg>,
    },
    Registers,
    Backup(JointId),
    Defaults(JointId),
    EndBoard(end_board::EndBoardJob),
    SetRates(Vec<JointId>, robobus_whj::timing::BitRates),
    CanHealth,
    Diff(JointId, DiffWith),
    Restore(JointId, Box<ops::settings::Settings>),
    SetId(JointId, JointId),
    Wave(WaveArgs, bool),
    ReleaseIap(Vec<JointId>),
    Sample(Vec<JointId>, bool),
}

/// A validated WHJ request.
#[derive(Debug)]
pub(crate) struct Prepared {
    pub(crate) plan: WhjSteps,
    pub(crate) job: Job,
    pub(crate) confirm: ConfirmClass,
    pub(crate) confirm_text: String,
    pub(crate) confirmed: bool,
    pub(crate) on_stop: WhjOnStop,
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

fn end_board_write(s: &str) -> Result<EndBoardArg, String> {
    let (reg, value) = s
        .split_once('=')
        .ok_or_else(|| format!("`{s}` is not REGISTER=VALUE (e.g. EB_IO1_MODE=1)"))?;
    let v = parse_u32(value.trim()).ok_or_else(|| format!("`{value}` is not a number"))?;
    let value = u16::try_from(v).map_err(|_| format!("value {v} is out of range 0..=65535"))?;
    Ok(EndBoardArg {
        addr: parse_end_board_register(reg)?,
        value: Some(value),
    })
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
            "one joint without broadcast (--broadcast); with it, joints 1..=7 share one frame",
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

fn prepared(plan: WhjSteps, job: Job) -> Prepared {
    Prepared {
        plan,
        job,
        confirm: ConfirmClass::None,
        confirm_text: String::new(),
        confirmed: false,
        on_stop: WhjOnStop::Hold,
    }
}

/// Validates and plans a WHJ request (`dry_run`: a plan only, so a current needs a model),
/// its notes headed by the connect a real run makes first (except where the operation is
/// the connect or sends nothing to a joint).
pub(crate) fn prepare(req: &super::Request, dry_run: bool) -> R<Prepared> {
    let mut p = prepare_steps(req, dry_run)?;
    if !matches!(p.job, Job::Scan(_) | Job::Registers | Job::ReleaseIap(_)) {
        let mut joints: Vec<JointId> = Vec::new();
        for (_, r) in &p.plan.steps {
            if let Some(j) = r.joint()
                && !joints.contains(&j)
            {
                joints.push(j);
            }
        }
        if let Some(note) = super::plan::connect_note(&joints) {
            p.plan.notes.insert(0, note);
        }
    }
    Ok(p)
}

#[allow(clippy::too_many_lines)] // one arm per operation
fn prepare_steps(req: &super::Request, dry_run: bool) -> R<Prepared> {
    use super::Request as Q;
    let js = |ids: &Ids| ids.parse_sorted::<JointId>("<JOINTS>");
    Ok(match req {
        Q::WhjScan(r) => {
            let ids = r.joints.parse_sorted::<JointId>("--joints")?;
            let mut p = each(&ids, Wire::read_identity);
            p.notes.push(
                "reads signature, ID, model and firmware of each ID; a joint that answers \
                 is present"
                    .into(),
            );
            prepared(p, Job::Scan(ids))
        }
        Q::WhjBackup(r) => settings::backup(r)?,
        Q::WhjDefaults(r) => settings::defaults(r)?,
        Q::WhjEndBoard(r) => end_board::end_board(r)?,
        Q::WhjSetRates(r) => rates::set_rates(r)?,
        Q::WhjDiff(r) => settings::diff(r)?,
        Q::WhjRestore(r) => settings::restore(r)?,
        Q::WhjInfo(r) => {
            let j = joint("<JOINT>", r.joint)?;
            let mut p = WhjSteps::default();
            p.push(Wire::read_identity(j));
            p.push(Wire::read_unique_id(j));
            p.push(Wire::read_position_limits(j));
            p.push(Wire::StatusQuery { joint: j });
            prepared(p, Job::Info(j))
        }
        Q::WhjStatus(r) if r.broadcast => {
            let ids = js(&r.joints)?;
            let mask = ops::reply_mask_with(&ids, r.end_board)?;
            let mut p = WhjSteps::default();
            p.push(Wire::BroadcastStatus(
                robobus_whj::broadcast::BroadcastStatus::new(mask),
            ));
            p.notes.push(format!(
                "one broadcast status query, reply mask {:#X} (joints {}{}); a real run \
                 connects each joint first",
                mask.get(),
                mask.joints()
                    .map(|j| j.get().to_string())
                    .collect::<Vec<_>>()
                    .join(","),
                if mask.selects_end_board() {
                    " and the end board"
                } else {
                    ""
                }
            ));
            prepared(p, Job::BroadcastStatus(ids, r.end_board))
        }
        Q::WhjStatus(r) => {
            if r.end_board {
                return Err(OpError::invalid("end_board", true, "needs broadcast"));
            }
            let ids = js(&r.joints)?;
            prepared(
                each(&ids, |joint| Wire::StatusQuery { joint }),
                Job::Status(ids),
            )
        }
        Q::WhjEnable(r) => {
            let ids = js(&r.joints)?;
            prepared(
                each(&ids, |j| Wire::enable(j, true)),
                Job::Enable(ids, true),
            )
        }
        Q::WhjDisable(r) => {
            let ids = js(&r.joints)?;
            prepared(
                each(&ids, |j| Wire::enable(j, false)),
                Job::Enable(ids, false),
            )
        }
        Q::WhjMode(r) => {
            let ids = js(&r.joints)?;
            let mode = work_mode(r.mode);
            prepared(
                each(&ids, |j| Wire::set_mode(j, mode)),
                Job::Mode(ids, mode),
            )
        }
        Q::WhjMove(r) => {
            let j = joint("<JOINT>", r.joint)?;
            let degrees = bounds::ANGLE_DEG.check("<DEGREES>", r.degrees)?;
            let from = r
                .from
                .map(|f| bounds::ANGLE_DEG.check("--from", f))
                .transpose()?;
            let args = MoveArgs {
                joint: j,
                target_deg: degrees,
                max_speed_deg_s: bounds::MOVE_SPEED_DEG_S.check("--max-speed", r.max_speed)?,
                rate_hz: bounds::FRAME_RATE_HZ.check("--rate-hz", r.rate_hz)?,
                step_limit_deg: step_limit(),
            };
            let plan = ops::plan_move(&args, from.unwrap_or(0.0), from.is_none())?;
            let mut p = prepared(WhjSteps::of(&plan), Job::Move(args));
            p.on_stop = r.on_stop;
            p
        }
        Q::WhjSpeed(r) => {
            let args = TargetArgs {
                joint: joint("<JOINT>", r.joint)?,
                servo: ServoLoop::Speed,
                value: bounds::SPEED_RPM.check("<RPM>", r.rpm)?,
                duration: duration(r.duration)?,
            };
            let mut p = prepared(
                target_steps(&args, CurrentScale::OneMilliamp)?,
                Job::Target(args),
            );
            p.on_stop = r.on_stop;
            p
        }
        Q::WhjCurrent(r) => {
            let args = TargetArgs {
                joint: joint("<JOINT>", r.joint)?,
                servo: ServoLoop::Current,
                value: bounds::CURRENT_MA.check("<MILLIAMPS>", r.milliamps)?,
                duration: duration(r.duration)?,
            };
            let scale = scale_for(r.model, dry_run, "current <MILLIAMPS>")?;
            let mut p = prepared(target_steps(&args, scale)?, Job::Target(args));
            p.on_stop = r.on_stop;
            p
        }
        Q::WhjZero(r) => {
            let j = joint("<JOINT>", r.joint)?;
            let mut p = WhjSteps::default();
            p.push(Wire::set_zero(j));
            prepared(p, Job::Zero(j))
        }
        Q::WhjClear(r) => {
            let ids = js(&r.joints)?;
            prepared(each(&ids, Wire::clear_error), Job::Clear(ids))
        }
        Q::WhjSave(r) => {
            let ids = js(&r.joints)?;
            let mut p = each(&ids, Wire::save_to_flash);
            p.notes
                .push("the joints must be disabled; each needs ~50 ms to write flash".into());
            let mut p = prepared(p, Job::Save(ids));
            p.confirm = ConfirmClass::NonVolatile;
            p.confirm_text = NON_VOLATILE_TEXT.into();
            p.confirmed = r.confirm;
            p
        }
        Q::WhjRead(r) => {
            let ids = js(&r.joints)?;
            let (addr, info) = parse_register(&r.register)
                .map_err(|e| OpError::invalid("<REGISTER>", &r.register, e))?;
            let eb = r
                .end_board
                .as_deref()
                .map(|s| {
                    parse_end_board_register(s).map_err(|e| OpError::invalid("--end-board", s, e))
                })
                .transpose()?;
            if eb.is_some() && !r.broadcast {
                return Err(OpError::invalid("end_board", "given", "needs broadcast"));
            }
            let plan = if r.broadcast {
                WhjSteps::of_broadcast(&ops::plan_broadcast_read(&ids, addr, r.count, eb)?)
            } else {
                let j = one_joint(&ids, "read <JOINT>")?;
                let count = r.count.unwrap_or(match info.map(|i| i.half) {
                    Some(Half::Low) => 2,
                    _ => 1,
                });
                let mut p = WhjSteps::default();
                p.push(
                    Wire::read(j, addr, count)
                        .map_err(|e| OpError::invalid("[COUNT]", count, e.to_string()))?,
                );
                p
            };
            prepared(plan, Job::Read(ids, addr, r.count, r.broadcast, eb))
        }
        Q::WhjWrite(r) => return write(r, dry_run),
        Q::WhjRegisters(_) => prepared(WhjSteps::default(), Job::Registers),
        Q::WhjCanHealth(_) => {
            let mut p = WhjSteps::default();
            p.notes.push(
                "reads the CAN interface's state from the kernel (netlink); nothing is sent on \
                 the bus"
                    .into(),
            );
            prepared(p, Job::CanHealth)
        }
        Q::WhjSetId(r) => {
            let (j, new_id) = (joint("<JOINT>", r.joint)?, joint("<NEW_ID>", r.new_id)?);
            let (frames, note) = ops::plan_set_id(j, new_id)?;
            let mut p = WhjSteps::default();
            for f in frames {
                p.push(f);
            }
            p.notes.push(note);
            let mut p = prepared(p, Job::SetId(j, new_id));
            p.confirm = ConfirmClass::Id;
            p.confirm_text = NON_VOLATILE_TEXT.into();
            p.confirmed = r.confirm;
            p
        }
        Q::WhjWave(r) => {
            let args = WaveArgs {
                joint: joint("<JOINT>", r.joint)?,
                shape: match r.shape {
                    Shape::Sine => ops::Shape::Sine,
                    Shape::Square => ops::Shape::Square,
                },
                servo: match r.mode {
                    WaveMode::Position => ServoLoop::Position,
                    WaveMode::Speed => ServoLoop::Speed,
                    WaveMode::Current => ServoLoop::Current,
                },
                amplitude: r.amplitude,
                frequency: r.frequency,
                offset: r.offset,
                duration: r.duration,
                rate_hz: bounds::FRAME_RATE_HZ.check("--rate-hz", r.rate_hz)?,
                step_limit_deg: step_limit(),
            };
            let scale = if r.mode == WaveMode::Current {
                scale_for(r.model, dry_run, "wave --mode current")?
            } else {
                CurrentScale::OneMilliamp
            };
            let from = r
                .from
                .map(|f| bounds::ANGLE_DEG.check("--from", f))
                .transpose()?;
            let start = from.unwrap_or(0.0);
            let plan = if r.broadcast {
                ops::plan_broadcast_wave(&args, start, scale, from.is_none())?
            } else {
                ops::plan_wave(&args, start, scale, from.is_none())?
            };
            let mut p = prepared(WhjSteps::of(&plan), Job::Wave(args, r.broadcast));
            p.on_stop = r.on_stop;
            p
        }
        Q::WhjReleaseIap(r) => {
            let ids = js(&r.joints)?;
            prepared(each(&ids, Wire::start_application), Job::ReleaseIap(ids))
        }
        Q::WhjSample(r) => {
            let ids = js(&r.joints)?;
            let p = if r.broadcast {
                let mask = ops::reply_mask(&ids)?;
                let mut p = WhjSteps::default();
                p.push(Wire::BroadcastStatus(
                    robobus_whj::broadcast::BroadcastStatus::new(mask),
                ));
                p
            } else {
                let mut p = WhjSteps::default();
                for &j in &ids {
                    p.push(Wire::StatusQuery { joint: j });
                }
                p.notes
                    .push("status query and servo feedback of each joint".into());
                p
            };
            prepared(p, Job::Sample(ids, r.broadcast))
        }
        _ => return Err(OpError::invalid("op", req.op(), "not a WHJ operation")),
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

fn write(r: &Write, dry_run: bool) -> R<Prepared> {
    let ids = r.joints.parse_sorted::<JointId>("<JOINTS>")?;
    let (addr, info) =
        parse_register(&r.register).map_err(|e| OpError::invalid("<REGISTER>", &r.register, e))?;
    let name = info.map_or("reserved register", |i| i.name);
    if !r.value.is_finite() {
        return Err(OpError::invalid("<VALUE>", r.value, "not a finite number"));
    }
    // Motion targets and `never` registers are refused here, plan or run.
    if let Err(e @ OpError::Refused(_)) = ops::check_write(addr, true) {
        return Err(e);
    }
    let eb = r
        .end_board
        .as_deref()
        .map(|s| end_board_write(s).map_err(|e| OpError::invalid("--end-board", s, e)))
        .transpose()?;
    if eb.is_some() && !r.broadcast {
        return Err(OpError::invalid("end_board", "given", "needs broadcast"));
    }
    let scale = if ops::needs_current_scale(addr, r.raw) {
        scale_for(r.model, dry_run, &format!("write {name}"))?
    } else {
        CurrentScale::OneMilliamp
    };
    let (plan, confirm_text) = if r.broadcast {
        let b = ops::plan_broadcast_write(&ids, addr, r.value, r.raw, &|_| scale, eb)?;
        let text = b
            .frames
            .iter()
            .find_map(ops::confirm_text)
            .map(str::to_owned)
            .or_else(|| eb.map(|_| ops::END_BOARD_WRITE_TEXT.to_owned()));
        (WhjSteps::of_broadcast(&b), text)
    } else {
        let j = one_joint(&ids, "write <JOINT>")?;
        let req = ops::write_request(j, addr, r.value, r.raw, scale)?;
        let mut p = WhjSteps::default();
        p.push(req);
        let text = ops::confirm_text(&req).map(str::to_owned);
        if let Some(what) = &text {
            p.notes.push(format!("{name}: {what} (needs --yes)"));
        }
        (p, text)
    };
    let flash = plan.steps.iter().any(|(_, s)| {
        matches!(s, Wire::Write { addr, .. }
            if *addr == registers::addr::SYS_SAVE_TO_FLASH || *addr == registers::addr::SYS_ID)
    });
    let mut p = prepared(
        plan,
        Job::Write {
            joints: ids,
            addr,
            value: r.value,
            raw: r.raw,
            scale: r.model.map(Model::scale),
            broadcast: r.broadcast,
            end_board: eb,
        },
    );
    match confirm_text {
        Some(what) => {
            p.confirm = ConfirmClass::Register;
            p.confirm_text = format!("This write {what}.");
        }
        None if flash => {
            p.confirm = ConfirmClass::NonVolatile;
            p.confirm_text = NON_VOLATILE_TEXT.into();
        }
        None => {}
    }
    p.confirmed = r.confirm;
    Ok(p)
}
