//! The wCK requests (`wck.*`): one struct per `robobus wck` subcommand, its arguments
//! under the CLI's names (`-` written `_`), and how each is planned and run through
//! [`crate::ops::wck`].

use crate::ops::wck::settings::WckSettings;
use crate::ops::wck::tune::{Keep, TuneArgs};
use std::time::Duration;

use robobus_wck::program::Program;
use robobus_wck::{
    Accel, BaudRate, Boundaries, Command, DGain, DataByte, ExtServoId, IGain, IoBits, Overload,
    PGain, Position, Position10, Rotation, ServoId, Speed, SyncMove as SyncMoveCmd, TorqueLevel,
    WheelSpeed,
};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::args::{Ids, WckOnStop, byte};
use super::bounds::{self, ConfirmClass, NON_VOLATILE_TEXT};
use crate::ops::wck::{self as ops, Motion, ScanArgs, TeachArgs, TeachTrigger, WckPlan, WheelArgs};
use crate::ops::{OpError, SafeState};

fn default_scan_ids() -> Ids {
    Ids::Text("0-30".into())
}
const fn default_rate() -> f64 {
    50.0
}
const fn default_pose_ms() -> u32 {
    1000
}
const fn default_hold() -> WckOnStop {
    WckOnStop::Hold
}
const fn default_passive() -> WckOnStop {
    WckOnStop::Passive
}

macro_rules! request {
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

request!(
    /// `wck.scan`: find servos (status read of every ID).
    Scan {
        /// IDs to try (`"0-30"`).
        #[serde(default = "default_scan_ids")]
        ids: Ids,
        /// Try every baud rate the wCK supports, not only the bus's.
        #[serde(default)]
        all_bauds: bool,
    }
);
request!(
    /// `wck.status` (A-1 (3)): load and position of servos.
    Status { /// Servo IDs (`"0-5,7"` or `[0, 1]`).
        ids: Ids }
);
request!(
    /// `wck.move` (A-1 (1)): position move of one servo.
    Move {
        /// Servo ID, 0..=30.
        id: u32,
        /// Target position, 0..=254.
        position: u32,
        /// Torque level 0 (maximum) ..= 4.
        #[serde(default)]
        torque: u32,
    }
);
request!(
    /// `wck.move10` (A-1 (26)): 10-bit position move.
    Move10 {
        /// Servo ID, 0..=253.
        id: u32,
        /// Target position, 0..=1023.
        position: u32,
        /// Torque, 0..=254.
        #[serde(default)]
        torque: u32,
    }
);
request!(
    /// `wck.read10` (A-1 (27)): 10-bit position of a servo.
    Read10 { /// Servo ID, 0..=253.
        id: u32 }
);
request!(
    /// `wck.sync-move` (A-1 (2)): servos 0..N-1 at once, no reply.
    SyncMove {
        /// Positions of servos 0, 1, ... (1..=31 values, each 0..=254).
        positions: Vec<u32>,
        /// Torque level.
        #[serde(default)]
        torque: u32,
    }
);
request!(
    /// `wck.passive` (A-1 (4)): release the torque; replies the position.
    Passive { /// Servo IDs.
        ids: Ids }
);
request!(
    /// `wck.wheel` (A-1 (5)): turn continuously, optionally for a time.
    Wheel {
        /// Servo ID, 0..=30.
        id: u32,
        /// `ccw` or `cw`.
        direction: Direction,
        /// Speed 0 (stop) ..= 15.
        speed: u32,
        /// Seconds (0.1..=3600), then stop per `on_stop`.
        #[serde(default)]
        duration: Option<f64>,
        /// How it stops: `hold`, `passive` or `break`.
        #[serde(default = "default_hold")]
        on_stop: WckOnStop,
    }
);
request!(
    /// `wck.brake` (A-1 (6)): break mode on every servo of the bus.
    Brake {}
);
request!(
    /// `wck.get`: read a parameter of a servo.
    Get {
        /// The parameter: `gains`, `i-gain`, `speed`, `overload`, `bounds`, `io`.
        param: Param,
        /// Servo ID, 0..=30.
        id: u32,
    }
);
const fn d20() -> u32 {
    20
}
const fn d1000() -> u32 {
    1000
}
request!(
    /// `wck.tune`: the same position step with each gain set (runtime gains), the
    /// responses measured (rise, overshoot, settling, steady-state error) and the best
    /// one found; kept in runtime or EEPROM (`confirm`) on request.
    Tune {
        /// Servo ID, 0..=30.
        id: u32,
        /// The gain sets, `[[P, D], ...]` (1..=8).
        gains: Vec<[u32; 2]>,
        /// The step, position steps (2..=60).
        #[serde(default = "d20")]
        amplitude: u32,
        /// How long each step is recorded, ms (100..=5000).
        #[serde(default = "d1000")]
        hold_ms: u32,
        /// Torque level of the moves, 0..=4.
        #[serde(default)]
        torque: u32,
        /// Keep the best set: `none` (default), `runtime` or `eeprom`.
        #[serde(default)]
        keep: KeepArg,
        /// Confirms an EEPROM keep.
        #[serde(default)]
        confirm: bool,
    }
);
/// What `wck.tune` keeps.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum KeepArg {
    /// Nothing.
    #[default]
    None,
    /// The runtime gains.
    Runtime,
    /// The EEPROM gains.
    Eeprom,
}
request!(
    /// `wck.backup`: a servo's settings (gains, I gain, speed, over-load, boundaries) as
    /// the settings file (the report's `summary`).
    Backup { /// Servo ID, 0..=30.
        id: u32 }
);
request!(
    /// `wck.diff`: the settings on which a servo differs from a settings file, the
    /// factory settings, or another servo.
    Diff {
        /// Servo ID, 0..=30.
        id: u32,
        /// A settings file's text (what `wck.backup` gives).
        #[serde(default)]
        settings: Option<String>,
        /// Compare with the factory settings (the manual's A-5).
        #[serde(default)]
        factory: bool,
        /// Another servo to compare with.
        #[serde(default)]
        other: Option<u32>,
    }
);
request!(
    /// `wck.restore`: writes a settings file (or the factory settings) into a servo's
    /// EEPROM where it differs, each write verified; needs `confirm`.
    Restore {
        /// Servo ID, 0..=30.
        id: u32,
        /// A settings file's text.
        #[serde(default)]
        settings: Option<String>,
        /// Restore the factory settings (the manual's A-5) instead of a file.
        #[serde(default)]
        factory: bool,
        /// Confirms the EEPROM writes.
        #[serde(default)]
        confirm: bool,
    }
);
request!(
    /// `wck.set`: write a parameter (EEPROM unless `runtime`; needs `confirm`).
    Set {
        /// The parameter: `gains` (p, d), `i-gain` (i), `speed` (speed, accel), `overload`
        /// (milliamps), `bounds` (lower, upper), `io` (outputs).
        param: Param,
        /// Servo ID, 0..=30.
        id: u32,
        /// P gain 1..=254 (gains).
        #[serde(default)]
        p: Option<u32>,
        /// D gain 0..=254 (gains).
        #[serde(default)]
        d: Option<u32>,
        /// I gain 0..=254 (i-gain).
        #[serde(default)]
        i: Option<u32>,
        /// Speed level 0..=30 (speed).
        #[serde(default)]
        speed: Option<u32>,
        /// Acceleration range 20..=100 (speed).
        #[serde(default)]
        accel: Option<u32>,
        /// Over-load threshold in mA, 400..=1800 (overload).
        #[serde(default)]
        milliamps: Option<u32>,
        /// Lower boundary 0..=254 (bounds).
        #[serde(default)]
        lower: Option<u32>,
        /// Upper boundary 0..=254 (bounds).
        #[serde(default)]
        upper: Option<u32>,
        /// Output bits 0..=3 (io).
        #[serde(default)]
        outputs: Option<u32>,
        /// Only until power-off (gains, i-gain, speed), not in EEPROM.
        #[serde(default)]
        runtime: bool,
        /// Confirms an EEPROM write (the CLI's `--yes`).
        #[serde(default)]
        confirm: bool,
    }
);
request!(
    /// `wck.set-id` (A-1 (14), EEPROM): a new ID; needs `confirm`.
    SetId {
        /// Current ID, 0..=30.
        id: u32,
        /// New ID, 0..=253.
        new_id: u32,
        /// Confirms the EEPROM write.
        #[serde(default)]
        confirm: bool,
    }
);
request!(
    /// `wck.set-baud` (A-1 (7), EEPROM): a servo's baud rate; needs `confirm`.
    SetBaud {
        /// Servo ID, 0..=30.
        id: u32,
        /// New rate, bit/s.
        rate: u32,
        /// Confirms the EEPROM write.
        #[serde(default)]
        confirm: bool,
    }
);
request!(
    /// `wck.program.upload` (A-1 (24), EEPROM): store a motion program; needs `confirm`.
    ProgramUpload {
        /// Servo ID, 0..=30.
        id: u32,
        /// The program in its text form (what a program file holds).
        program: String,
        /// Confirms the EEPROM write.
        #[serde(default)]
        confirm: bool,
    }
);
request!(
    /// `wck.program.download` (A-1 (25)): read a servo's motion program.
    ProgramDownload { /// Servo ID, 0..=30.
        id: u32 }
);
request!(
    /// `wck.program.check`: parse a program and show its upload packet (nothing sent).
    ProgramCheck {
        /// Servo ID the packet is for, 0..=30 (the CLI's `--id`, default 0).
        #[serde(default)]
        id: u32,
        /// The program text.
        program: String,
    }
);
request!(
    /// `wck.teach`: record poses at a rate for a time (servos passive meanwhile).
    Teach {
        /// Servos 0..N-1.
        ids: Ids,
        /// Poses per second, 0.1..=200 (10 when only `duration` is given). Without it and
        /// without `duration` a pose is recorded at each of the front end's record
        /// events ([`super::Interaction::teach_event`]) until its finish event.
        #[serde(default)]
        rate_hz: Option<f64>,
        /// Seconds, 0.1..=3600; without it a recording at a rate runs until the front
        /// end's finish event or a stop.
        #[serde(default)]
        duration: Option<f64>,
        /// Transition time written for each pose recorded by an event, ms (0..=600000).
        #[serde(default = "default_pose_ms")]
        pose_ms: u32,
        /// Torque level written into the poses (and of a hold at the end).
        #[serde(default)]
        torque: u32,
        /// What the servos do at the end: `passive`, `hold` or `break`.
        #[serde(default = "default_passive")]
        on_stop: WckOnStop,
    }
);
request!(
    /// `wck.play`: play a keyframe motion (its text) as synchronized moves.
    Play {
        /// The keyframe motion text (what a motion file holds).
        motion: String,
        /// Synchronized moves per second, 0.1..=200.
        #[serde(default = "default_rate")]
        rate_hz: f64,
        /// What the servos do on a stop.
        #[serde(default = "default_hold")]
        on_stop: WckOnStop,
    }
);
request!(
    /// `wck.sample`: one monitor sample of servos (position, speed from the previous
    /// sample of the same request, load).
    Sample { /// Servo IDs.
        ids: Ids }
);

/// Wheel direction.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum Direction {
    /// Counter-clockwise.
    Ccw,
    /// Clockwise.
    Cw,
}

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

/// How a validated wCK request runs.
#[derive(Debug)]
pub(crate) enum Job {
    /// One exchange per planned packet.
    Steps(&'static str),
    Scan(ScanArgs),
    Wheel(WheelArgs),
    Teach(TeachArgs),
    Play(Motion, f64, SafeState),
    /// `program check`: nothing to send.
    Check(Program, ServoId),
    Sample(Vec<ServoId>),
    Backup(ServoId),
    Tune(TuneArgs),
    Diff(ServoId, WckDiffWith),
    Restore(ServoId, WckSettings),
}

/// What `wck.diff` compares a servo with.
#[derive(Debug)]
pub(crate) enum WckDiffWith {
    /// A settings file, or the factory settings.
    File(WckSettings),
    /// Another servo.
    Servo(ServoId),
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

/// A validated wCK request: its plan, how it runs, what it needs confirmed.
#[derive(Debug)]
pub(crate) struct Prepared {
    pub(crate) plan: WckPlan,
    pub(crate) job: Job,
    pub(crate) confirm: ConfirmClass,
    pub(crate) confirmed: bool,
}

type R<T> = Result<T, OpError>;

/// The longest transition time a pose recorded by an event gets, ms.
pub const MAX_POSE_MS: u32 = 600_000;

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

fn simple(plan: WckPlan, action: &'static str) -> Prepared {
    let confirm = if plan.writes_eeprom() {
        ConfirmClass::NonVolatile
    } else {
        ConfirmClass::None
    };
    Prepared {
        plan,
        job: Job::Steps(action),
        confirm,
        confirmed: false,
    }
}

/// Validates a request against the protocol's ranges and the host bounds and plans it
/// (`baud`: the bus's rate). Nothing is sent.
#[allow(clippy::too_many_lines)] // one arm per operation
pub(crate) fn prepare(req: &super::Request, baud: BaudRate) -> R<Prepared> {
    use super::Request as Q;
    let one = |c: Command, a: &'static str| Ok(simple(WckPlan::one(c), a));
    match req {
        Q::WckScan(r) => {
            let scan = ScanArgs::new(r.ids.parse("--ids")?, baud, r.all_bauds);
            Ok(Prepared {
                plan: scan.plan(&|_, _| false),
                job: Job::Scan(scan),
                confirm: ConfirmClass::None,
                confirmed: false,
            })
        }
        Q::WckTune(r) => {
            let id = sid(r.id)?;
            let mut gains = Vec::new();
            for &[p, d] in &r.gains {
                gains.push(crate::wck::Gains {
                    p: byte("--gains P", p, robobus_wck::PGain::new)?,
                    d: byte("--gains D", d, robobus_wck::DGain::new)?,
                });
            }
            let args = TuneArgs {
                id,
                amplitude: u8::try_from(r.amplitude).unwrap_or(u8::MAX),
                gains,
                hold_ms: r.hold_ms,
                torque: torque(r.torque)?,
                keep: match r.keep {
                    KeepArg::None => Keep::None,
                    KeepArg::Runtime => Keep::Runtime,
                    KeepArg::Eeprom => Keep::Eeprom,
                },
            };
            args.validate()?;
            let mut plan = WckPlan::default();
            plan.push(Command::GainRead { id });
            plan.push(Command::BoundaryRead { id });
            plan.push(Command::StatusRead { id });
            plan.notes.push(format!(
                "then for each of the {} gain sets: runtime gains (A-1 (12)), a move to the \
                 present position and 0.5 s of status reads to settle, a step of {} \
                 positions away from the nearer boundary and {} ms of status reads; then \
                 back to the start, runtime gains {}",
                args.gains.len(),
                args.amplitude,
                args.hold_ms,
                match args.keep {
                    Keep::None => "as in EEPROM",
                    Keep::Runtime => "the best set's",
                    Keep::Eeprom => "and EEPROM gains the best set's",
                }
            ));
            let confirm = if args.keep == Keep::Eeprom {
                ConfirmClass::NonVolatile
            } else {
                ConfirmClass::None
            };
            Ok(Prepared {
                plan,
                job: Job::Tune(args),
                confirm,
                confirmed: r.confirm,
            })
        }
        Q::WckBackup(r) => {
            let id = sid(r.id)?;
            let mut plan = WckPlan::default();
            settings_reads(&mut plan, id);
            Ok(Prepared {
                plan,
                job: Job::Backup(id),
                confirm: ConfirmClass::None,
                confirmed: false,
            })
        }
        Q::WckDiff(r) => {
            let id = sid(r.id)?;
            let mut plan = WckPlan::default();
            settings_reads(&mut plan, id);
            let with = match (settings_of(r.settings.as_ref(), r.factory)?, r.other) {
                (Some(s), None) => WckDiffWith::File(s),
                (None, Some(o)) => {
                    let o = byte("--with", o, ServoId::new)?;
                    if o == id {
                        return Err(OpError::invalid("--with", o.get(), "the servo itself"));
                    }
                    settings_reads(&mut plan, o);
                    WckDiffWith::Servo(o)
                }
                _ => {
                    return Err(OpError::invalid(
                        "settings / factory / other",
                        "none or several",
                        "give one: a settings file, the factory settings or another servo",
                    ));
                }
            };
            Ok(Prepared {
                plan,
                job: Job::Diff(id, with),
                confirm: ConfirmClass::None,
                confirmed: false,
            })
        }
        Q::WckRestore(r) => {
            let id = sid(r.id)?;
            let s = settings_of(r.settings.as_ref(), r.factory)?.ok_or_else(|| {
                OpError::invalid(
                    "settings / factory",
                    "neither",
                    "give a settings file or the factory settings",
                )
            })?;
            let mut plan = WckPlan::default();
            settings_reads(&mut plan, id);
            plan.notes.push(
                "then one EEPROM write (about 121 ms, verified by the servo's read-back) per \
                 group that differs: gains, I gain, speed, over-load, boundaries; then the \
                 settings are read again"
                    .into(),
            );
            Ok(Prepared {
                plan,
                job: Job::Restore(id, s),
                confirm: ConfirmClass::NonVolatile,
                confirmed: r.confirm,
            })
        }
        Q::WckStatus(r) => Ok(simple(
            each(&r.ids.parse("<IDS>")?, |id| Command::StatusRead { id }),
            "status",
        )),
        Q::WckMove(r) => one(
            Command::Move {
                id: sid(r.id)?,
                torque: torque(r.torque)?,
                position: pos("<POSITION>", r.position)?,
            },
            "move",
        ),
        Q::WckMove10(r) => one(
            Command::Move10 {
                id: byte("<ID>", r.id, ExtServoId::new)?,
                torque: byte("--torque", r.torque, DataByte::new)?,
                position: Position10::new(u16::try_from(r.position).unwrap_or(u16::MAX))
                    .map_err(|e| OpError::invalid("<POSITION>", r.position, e.to_string()))?,
            },
            "move10",
        ),
        Q::WckRead10(r) => one(
            Command::Read10 {
                id: byte("<ID>", r.id, ExtServoId::new)?,
            },
            "read10",
        ),
        Q::WckSyncMove(r) => {
            let ps = r
                .positions
                .iter()
                .map(|&p| pos("<POSITIONS>", p))
                .collect::<R<Vec<_>>>()?;
            let sync = SyncMoveCmd::new(torque(r.torque)?, &ps).map_err(|e| {
                OpError::invalid(
                    "<POSITIONS>",
                    ps.len(),
                    format!("{e} (one position per servo 0..=30)"),
                )
            })?;
            one(Command::SyncMove(sync), "sync-move")
        }
        Q::WckPassive(r) => Ok(simple(
            each(&r.ids.parse("<IDS>")?, |id| Command::Passive { id }),
            "passive",
        )),
        Q::WckWheel(r) => {
            let wheel = WheelArgs {
                id: sid(r.id)?,
                rotation: match r.direction {
                    Direction::Ccw => Rotation::Ccw,
                    Direction::Cw => Rotation::Cw,
                },
                speed: byte("<SPEED>", r.speed, WheelSpeed::new)?,
                duration: r.duration.map(|d| secs("--duration", d)).transpose()?,
                on_stop: r.on_stop.into(),
            };
            Ok(Prepared {
                plan: wheel.plan(),
                job: Job::Wheel(wheel),
                confirm: ConfirmClass::None,
                confirmed: false,
            })
        }
        Q::WckBrake(_) => one(Command::Break, "brake"),
        Q::WckGet(r) => {
            let id = sid(r.id)?;
            one(
                match r.param {
                    Param::Gains => Command::GainRead { id },
                    Param::IGain => Command::IGainRead { id },
                    Param::Speed => Command::SpeedRead { id },
                    Param::Overload => Command::OverloadRead { id },
                    Param::Bounds => Command::BoundaryRead { id },
                    Param::Io => Command::IoRead { id },
                },
                "get",
            )
        }
        Q::WckSet(r) => {
            let mut p = one(set_command(r)?, "set")?;
            p.confirmed = r.confirm;
            Ok(p)
        }
        Q::WckSetId(r) => {
            let mut p = one(
                Command::IdSet {
                    id: sid(r.id)?,
                    new_id: byte("<NEW_ID>", r.new_id, ExtServoId::new)?,
                },
                "set-id",
            )?;
            p.confirm = ConfirmClass::Id;
            p.confirmed = r.confirm;
            Ok(p)
        }
        Q::WckSetBaud(r) => {
            let mut p = one(
                Command::BaudSet {
                    id: sid(r.id)?,
                    baud: BaudRate::from_bits_per_second(r.rate)
                        .map_err(|e| OpError::invalid("<RATE>", r.rate, e.to_string()))?,
                },
                "set-baud",
            )?;
            p.confirmed = r.confirm;
            Ok(p)
        }
        Q::WckProgramUpload(r) => {
            let mut p = one(
                Command::MotionWrite {
                    id: sid(r.id)?,
                    program: program(&r.program)?,
                },
                "program upload",
            )?;
            p.confirmed = r.confirm;
            Ok(p)
        }
        Q::WckProgramDownload(r) => one(Command::MotionRead { id: sid(r.id)? }, "program download"),
        Q::WckProgramCheck(r) => {
            let (id, prog) = (sid(r.id)?, program(&r.program)?);
            Ok(Prepared {
                plan: WckPlan::one(Command::MotionWrite { id, program: prog }),
                job: Job::Check(prog, id),
                confirm: ConfirmClass::None,
                confirmed: false,
            })
        }
        Q::WckTeach(r) => {
            if r.pose_ms > MAX_POSE_MS {
                return Err(OpError::invalid(
                    "--pose-ms",
                    r.pose_ms,
                    format!("allowed: 0..={MAX_POSE_MS} ms"),
                ));
            }
            let trigger = match (r.rate_hz, r.duration) {
                (None, None) => TeachTrigger::Events { pose_ms: r.pose_ms },
                (rate, duration) => TeachTrigger::Rate {
                    rate_hz: bounds::WCK_RATE_HZ.check("--rate-hz", rate.unwrap_or(10.0))?,
                    duration: duration.map(|d| secs("--duration", d)).transpose()?,
                },
            };
            let teach = TeachArgs {
                ids: r.ids.parse("<IDS>")?,
                trigger,
                torque: torque(r.torque)?,
                on_stop: r.on_stop.into(),
            };
            teach.check()?;
            Ok(Prepared {
                plan: teach.plan(),
                job: Job::Teach(teach),
                confirm: ConfirmClass::None,
                confirmed: false,
            })
        }
        Q::WckPlay(r) => {
            let rate = bounds::WCK_RATE_HZ.check("--rate-hz", r.rate_hz)?;
            let motion = Motion::parse(&r.motion).map_err(|e| {
                OpError::invalid("motion", format!("{}:{}", e.line, e.column), e.message)
            })?;
            let mut plan = WckPlan::default();
            plan.notes.push(Motion::plan_note(rate));
            for step in motion.moves(rate).take(super::plan::MAX_PLAN_STEPS) {
                plan.steps.push(step);
            }
            Ok(Prepared {
                plan,
                job: Job::Play(motion, rate, r.on_stop.into()),
                confirm: ConfirmClass::None,
                confirmed: false,
            })
        }
        Q::WckSample(r) => {
            let ids = r.ids.parse("<IDS>")?;
            Ok(Prepared {
                plan: each(&ids, |id| Command::StatusRead { id }),
                job: Job::Sample(ids),
                confirm: ConfirmClass::None,
                confirmed: false,
            })
        }
        _ => Err(OpError::invalid("op", req.op(), "not a wCK operation")),
    }
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

fn set_command(r: &Set) -> R<Command> {
    let id = sid(r.id)?;
    let gain = |o: &str, v: Option<u32>| need(o, v);
    Ok(match r.param {
        Param::Gains => {
            let p = byte("<P>", gain("<P>", r.p)?, PGain::new)?;
            let d = byte("<D>", gain("<D>", r.d)?, DGain::new)?;
            if r.runtime {
                Command::RuntimeGainSet { id, p, d }
            } else {
                Command::GainSet { id, p, d }
            }
        }
        Param::IGain => {
            let i = byte("<I>", gain("<I>", r.i)?, IGain::new)?;
            if r.runtime {
                Command::RuntimeIGainSet { id, i }
            } else {
                Command::IGainSet { id, i }
            }
        }
        Param::Speed => {
            let speed = byte("<SPEED>", need("<SPEED>", r.speed)?, Speed::new)?;
            let accel = byte("<ACCEL>", need("<ACCEL>", r.accel)?, Accel::new)?;
            if r.runtime {
                Command::RuntimeSpeedSet { id, speed, accel }
            } else {
                Command::SpeedSet { id, speed, accel }
            }
        }
        Param::Overload => {
            let ma = need("<MILLIAMPS>", r.milliamps)?;
            Command::OverloadSet {
                id,
                overload: Overload::from_milliamps(u16::try_from(ma).unwrap_or(u16::MAX))
                    .map_err(|e| OpError::invalid("<MILLIAMPS>", ma, e.to_string()))?,
            }
        }
        Param::Bounds => {
            let lower = pos("<LOWER>", need("<LOWER>", r.lower)?)?;
            let upper = pos("<UPPER>", need("<UPPER>", r.upper)?)?;
            Command::BoundarySet {
                id,
                bounds: Boundaries::new(lower, upper)
                    .map_err(|e| OpError::invalid("<UPPER>", upper.get(), e.to_string()))?,
            }
        }
        Param::Io => Command::IoWrite {
            id,
            outputs: byte("<OUTPUTS>", need("<OUTPUTS>", r.outputs)?, IoBits::new)?,
        },
    })
}

/// The text a refusal of an unconfirmed wCK request says.
pub(crate) const fn confirm_text(class: ConfirmClass) -> &'static str {
    match class {
        ConfirmClass::Id => "This changes a servo's ID (EEPROM).",
        _ => NON_VOLATILE_TEXT,
    }
}

pub(crate) use ops::confirm_reads_for;
