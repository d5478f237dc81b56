//! `robobus whj`: drive WHJ joints on a CAN FD bus.
//!
//! Every subcommand maps onto requests of the WHJ protocol ([`robobus_whj::Request`]).
//! Arguments are validated first (joint IDs 1..=30 by [`JointId`], registers by
//! [`RegisterInfo`] with their documented ranges and units, motion values against the
//! limits below); the subcommand builds a [`WhjPlan`], which `--dry-run` prints as
//! `cansend` lines (see [`crate::output`]) and a real run hands to
//! [`crate::client::execute`].
//!
//! Motion limits of the CLI (on top of the joint's own limit registers): targets within
//! ±[`MAX_DEG`]°, speeds within ±[`MAX_RPM`] RPM, currents within ±[`MAX_MA`] mA; `move`
//! steps at most `--max-speed` / `--rate-hz` degrees per frame.

use std::fmt::Write as _;
use std::time::Duration;

use clap::{Subcommand, ValueEnum};
use robobus::ops::IdList;
use robobus::ops::OpError;
use robobus::ops::whj::{self as ops, MoveArgs, ServoLoop, TargetArgs, WaveArgs};
use robobus::whj::JointBusConfig;
use robobus_link::FrameLinkSpec;
use robobus_whj::registers::Half;
use robobus_whj::units::CurrentScale;
use robobus_whj::{JointId, REGISTERS, RegisterAddr, RegisterInfo, Request, WorkMode};

use crate::Global;
use crate::client::whj::{OnStop, WhjRun};
use crate::client::{Job, execute};
use crate::exit::usage;
use crate::output::{self, WhjPlan};

/// Largest |target angle| the CLI sends, degrees: one turn either way (a host policy; the
/// joint's own limits, 0x44..0x47, are checked as well once it is connected).
pub(crate) const MAX_DEG: f64 = 360.0;
/// Largest |target speed| the CLI sends, output RPM: the highest published peak output
/// speed of any model (WHJ10 / WHJ30, 37.5 RPM); once connected, the joint's own model's
/// peak is checked as well.
pub(crate) const MAX_RPM: f64 = 37.5;
/// Largest |target current| the CLI sends, mA (a host policy: the vendor publishes no
/// peak current; once connected, the joint's current limit 0x40 is checked as well).
pub(crate) const MAX_MA: f64 = 30_000.0;

const AFTER_HELP: &str = "\
Joint IDs are 1..=30 (0 is the interface board); lists and ranges are allowed where the
argument says JOINTS: `1`, `1-7`, `1,3,5-7`.
Units: angles in degrees (0.0001 deg per count), speeds in output RPM (0.002 RPM per
count), currents in mA (1 mA per count; 2 mA on WHJ60/WHJ120: give --model).
CLI safety limits: |angle| <= 360 deg, |speed| <= 37.5 RPM, |current| <= 30000 mA;
once a joint is connected, and before any servo frame, its own bounds are checked too:
angles within its position limits (0x44..0x47), speeds within its model's peak output
speed (30 RPM on WHJ03/60/120), currents within its current limit (0x40).

Without --dry-run the command runs on the bus: each joint is connected first (IAP
release, identify; up to 5 s, since joints with a staggered power-up stay silent for a few
seconds), results are printed as a table, one row per joint (--json: one JSON object;
fields carry their units: position_deg, speed_rpm, current_ma). `move` and `wave` send
exactly the frames their dry run prints, planned from the measured position (a move that
is too fast for the step limit is split into smaller steps); `wave` reports cycles,
missing replies, deadline misses, overruns, clamps, tracking against the requested
target and the round trip of each frame to its feedback (p50 / p99 / max, µs). A joint that does not answer gives exit code 3 (the others are still reported);
`save` is refused while a joint is enabled. `write` follows each register's safety class:
motion targets and the drive switch are refused with the command to use, calibration,
bit rates, IAP and brake need --yes. Without --duration, `speed` / `current` leave the
joint running. Ctrl-C during move, wave, speed or current first brings the joint to the
--on-stop state, then exits with 130.

--broadcast (status, read, write, wave; joints 1..=7) uses the broadcast protocol: one
frame for every joint (and with --end-board the end-effector board's own registers)
instead of one per joint. Each joint is still reported, one that does not answer named;
broadcast writes follow the same safety classes and are read back by a second frame;
end-board writes need --yes. Broadcast waves need --rate-hz >= 100 (a joint stops a
broadcast position stream after 20 ms without a frame). Whether it is worth it (frames
and wire time per cycle): docs/hardware.md.

With --dry-run every subcommand prints the CAN FD frames it would send, one per line in
cansend syntax (`001##1020A01`: ID 0x001, FD with bit-rate switch, data 02 0A 01); lines
starting with `#` are comments; --json prints them as JSON.";

/// Options of `robobus whj`.
#[derive(Debug, clap::Args)]
#[command(after_help = AFTER_HELP)]
pub(crate) struct Args {
    /// The bus: `udp` (python-can UDP multicast 239.74.163.2:43113, what `robobus sim whj`
    /// serves), `udp:GROUP:PORT`, or a SocketCAN interface such as can0 / vcan0. Required
    /// unless --dry-run is given.
    #[arg(long, value_name = "BUS", global = true)]
    bus: Option<String>,
    /// Joint model, for current scaling: whj03, whj10, whj30, whj60, whj120 (2 mA per
    /// count on whj60 / whj120, else 1 mA). A real run reads it from the joint.
    #[arg(long, value_enum, global = true)]
    model: Option<ModelArg>,
    /// What Ctrl-C leaves a moving joint in (move, wave): hold (stay enabled at the
    /// present position; speed / current waves get target 0) or disable.
    #[arg(long, value_enum, default_value = "hold", global = true)]
    on_stop: OnStop,
    /// Record every frame sent and received to FILE as a candump log (`candump -L`'s
    /// format: can-utils' canplayer plays it back; `robobus replay FILE` decodes it). An
    /// existing FILE is not overwritten.
    #[arg(long, value_name = "FILE", global = true)]
    capture: Option<std::path::PathBuf>,
    /// What to do.
    #[command(subcommand)]
    command: WhjCommand,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
enum ModelArg {
    Whj03,
    Whj10,
    Whj30,
    Whj60,
    Whj120,
}

impl ModelArg {
    fn scale(self) -> CurrentScale {
        match self {
            Self::Whj60 | Self::Whj120 => CurrentScale::TwoMilliamps,
            _ => CurrentScale::OneMilliamp,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
enum ModeArg {
    /// Open loop (PWM duty; not recommended).
    OpenLoop,
    /// Current (torque) servo.
    Current,
    /// Speed servo.
    Speed,
    /// Position servo (factory default).
    Position,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
enum Shape {
    /// offset + amplitude * sin(2 pi f t).
    Sine,
    /// offset + amplitude while sin(2 pi f t) >= 0, else offset - amplitude.
    Square,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
enum WaveMode {
    /// Position servo frames (0x200+ID); amplitude and offset in degrees.
    Position,
    /// Speed servo frames (0x300+ID); amplitude and offset in RPM.
    Speed,
    /// Current servo frames (0x400+ID); amplitude and offset in mA.
    Current,
}

#[derive(Debug, Subcommand)]
enum WhjCommand {
    /// Find joints: read signature, ID, model and firmware of every ID (1..=30 unless
    /// --joints is given).
    Scan {
        /// Joint IDs to try.
        #[arg(long, default_value = "1-30", value_parser = parse_joints)]
        joints: Joints,
    },
    /// Identity, unique ID and position limits of a joint.
    Info {
        /// Joint ID, 1..=30.
        #[arg(value_parser = parse_joint)]
        joint: JointId,
    },
    /// Status query (0x600+ID): position, speed, current, errors, enable state.
    Status {
        /// Joint IDs, e.g. `1-7`.
        #[arg(value_parser = parse_joints)]
        joints: Joints,
        /// Ask joints 1..=7 with one broadcast status frame (0x7F) instead of one query
        /// each; a joint that does not answer is named.
        #[arg(long)]
        broadcast: bool,
        /// With --broadcast: the end board answers the same frame (IO modes and levels,
        /// buttons, gripper / hand in position, error byte).
        #[arg(long, requires = "broadcast")]
        end_board: bool,
    },
    /// Enable the drive (register 0x0A := 1).
    Enable {
        /// Joint IDs, e.g. `1-7`.
        #[arg(value_parser = parse_joints)]
        joints: Joints,
    },
    /// Disable the drive (register 0x0A := 0).
    Disable {
        /// Joint IDs, e.g. `1-7`.
        #[arg(value_parser = parse_joints)]
        joints: Joints,
    },
    /// Set the work mode (register 0x30).
    Mode {
        /// Joint IDs, e.g. `1-7`.
        #[arg(value_parser = parse_joints)]
        joints: Joints,
        /// The mode.
        mode: ModeArg,
    },
    /// Move a joint to an angle in position mode, in steps no faster than --max-speed.
    Move {
        /// Joint ID, 1..=30.
        #[arg(value_parser = parse_joint)]
        joint: JointId,
        /// Target angle in degrees, -360..=360.
        #[arg(allow_hyphen_values = true, value_parser = parse_angle)]
        degrees: f64,
        /// Largest speed of the steps, degrees per second (0.1..=180).
        #[arg(long, default_value_t = 10.0, value_parser = parse_max_speed)]
        max_speed: f64,
        /// Position frames per second (1..=1000).
        #[arg(long, default_value_t = 200.0, value_parser = parse_frame_rate)]
        rate_hz: f64,
        /// Start angle for --dry-run (a real run reads the present position; without
        /// --from a dry run assumes 0).
        #[arg(long, allow_hyphen_values = true, value_parser = parse_angle)]
        from: Option<f64>,
    },
    /// Speed servo target (0x300+ID) in output RPM, -37.5..=37.5.
    Speed {
        /// Joint ID, 1..=30.
        #[arg(value_parser = parse_joint)]
        joint: JointId,
        /// Target speed, RPM.
        #[arg(allow_hyphen_values = true, value_parser = parse_rpm)]
        rpm: f64,
        /// Keep the target this many seconds (0.01..=3600), then target 0 (also on
        /// Ctrl-C). Without it the joint keeps turning after the command exits.
        #[arg(long, value_name = "SECS", value_parser = parse_duration)]
        duration: Option<f64>,
    },
    /// Current servo target (0x400+ID) in mA, -30000..=30000.
    Current {
        /// Joint ID, 1..=30.
        #[arg(value_parser = parse_joint)]
        joint: JointId,
        /// Target current, mA.
        #[arg(allow_hyphen_values = true, value_parser = parse_ma)]
        milliamps: f64,
        /// Keep the target this many seconds (0.01..=3600), then target 0 (also on
        /// Ctrl-C). Without it the joint keeps the current after the command exits.
        #[arg(long, value_name = "SECS", value_parser = parse_duration)]
        duration: Option<f64>,
    },
    /// Make the present position 0 degrees (register 0x0E := 1).
    Zero {
        /// Joint ID, 1..=30.
        #[arg(value_parser = parse_joint)]
        joint: JointId,
    },
    /// Clear latched errors (register 0x0F := 1).
    Clear {
        /// Joint IDs, e.g. `1-7`.
        #[arg(value_parser = parse_joints)]
        joints: Joints,
    },
    /// Save the register table to flash (register 0x0C := 1; the joint must be disabled).
    Save {
        /// Joint IDs, e.g. `1-7`.
        #[arg(value_parser = parse_joints)]
        joints: Joints,
    },
    /// Read registers by name (`cur_position`, `SYS_TEMP`) or address (`0x14`, `20`).
    Read {
        /// Joint ID, 1..=30 (with --broadcast: joints 1..=7, e.g. `1-7`).
        #[arg(value_parser = parse_joints)]
        joints: Joints,
        /// Register name or address (0x00..=0x91).
        #[arg(value_parser = parse_register)]
        register: Register,
        /// Number of registers, 1..=31 (default: 2 for a 32-bit pair, else 1).
        count: Option<u8>,
        /// Read the register of joints 1..=7 with one broadcast frame (0x0F) instead of
        /// one request each; a joint that does not answer is named.
        #[arg(long)]
        broadcast: bool,
        /// With --broadcast: also read this register of the end board's own map (name
        /// or address, e.g. `EB_SW_VERSION` or 0x03).
        #[arg(long, value_name = "REGISTER", requires = "broadcast", value_parser = parse_end_board_register)]
        end_board: Option<u8>,
    },
    /// Write a register by name or address, in its unit (degrees, RPM, mA, V, ...).
    Write {
        /// Joint ID, 1..=30 (with --broadcast: joints 1..=7, e.g. `1-7`).
        #[arg(value_parser = parse_joints)]
        joints: Joints,
        /// Register name or address (0x00..=0x91).
        #[arg(value_parser = parse_register)]
        register: Register,
        /// The value, in the register's unit (see `robobus whj registers`); with --raw, in
        /// counts.
        #[arg(allow_hyphen_values = true)]
        value: String,
        /// The value is in raw counts.
        #[arg(long)]
        raw: bool,
        /// Write the register of joints 1..=7 with one broadcast frame (0x0F), then read
        /// it back with a second one; a joint that does not answer is named.
        #[arg(long)]
        broadcast: bool,
        /// With --broadcast: also write a register of the end board's own map,
        /// `REGISTER=VALUE` (e.g. `EB_IO1_MODE=1`, 0x07=3); needs --yes.
        #[arg(long, value_name = "REGISTER=VALUE", requires = "broadcast", value_parser = parse_end_board_write)]
        end_board: Option<ops::EndBoardArg>,
    },
    /// List the register table: address, name, unit, range, access, meaning.
    Registers,
    /// Give a joint a new ID (register 0x01, then save to flash; power-cycle afterwards).
    SetId {
        /// Current joint ID, 1..=30.
        #[arg(value_parser = parse_joint)]
        joint: JointId,
        /// New joint ID, 1..=30.
        #[arg(value_parser = parse_joint)]
        new_id: JointId,
    },
    /// Send a test signal (sine or square) as servo frames, like the vendor tool.
    Wave {
        /// Joint ID, 1..=30.
        #[arg(value_parser = parse_joint)]
        joint: JointId,
        /// Signal shape.
        #[arg(long, value_enum, default_value = "sine")]
        shape: Shape,
        /// Which servo loop the signal drives.
        #[arg(long, value_enum, default_value = "position")]
        mode: WaveMode,
        /// Amplitude (degrees, RPM or mA by --mode), >= 0.
        #[arg(long, value_parser = parse_finite)]
        amplitude: f64,
        /// Frequency in Hz, 0.01..=20 and at most --rate-hz / 4.
        #[arg(long, default_value_t = 0.5, value_parser = parse_finite)]
        frequency: f64,
        /// Offset (degrees, RPM or mA by --mode).
        #[arg(long, default_value_t = 0.0, allow_hyphen_values = true, value_parser = parse_finite)]
        offset: f64,
        /// Duration in seconds, 0.01..=600.
        #[arg(long, default_value_t = 4.0, value_parser = parse_finite)]
        duration: f64,
        /// Frames per second (1..=1000).
        #[arg(long, default_value_t = 200.0, value_parser = parse_frame_rate)]
        rate_hz: f64,
        /// Send the wave as broadcast frames (0x2F position, 0x4F current; joints
        /// 1..=7; position waves at --rate-hz >= 100, since a joint stops a broadcast
        /// position stream after 20 ms without a frame).
        #[arg(long)]
        broadcast: bool,
        /// Start angle of a position wave for --dry-run (a real run starts the step
        /// limiter at the present position; without --from a dry run assumes 0).
        #[arg(long, allow_hyphen_values = true, value_parser = parse_angle)]
        from: Option<f64>,
    },
    /// Start the application on joints waiting in the bootloader (`IAP_FLAG` 0x49 := 0).
    ReleaseIap {
        /// Joint IDs, e.g. `1-7`.
        #[arg(value_parser = parse_joints)]
        joints: Joints,
    },
}

/// A parsed list of joint IDs, sorted, without repeats.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Joints(Vec<JointId>);

/// A register: its address and, unless reserved, its table entry.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Register {
    addr: RegisterAddr,
    info: Option<&'static RegisterInfo>,
}

fn parse_joint(s: &str) -> Result<JointId, String> {
    let v = crate::wck::parse_u32(s)?;
    let raw = u8::try_from(v).unwrap_or(u8::MAX);
    JointId::new(raw).map_err(|_| robobus_whj::JointIdError { value: v }.to_string())
}

fn parse_joints(spec: &str) -> Result<Joints, String> {
    let ids: IdList<JointId> = spec.parse()?;
    Ok(Joints(ids.sorted().into_vec()))
}

fn parse_register(s: &str) -> Result<Register, String> {
    let t = s.trim();
    if let Ok(v) = crate::wck::parse_u32(t) {
        let raw = u8::try_from(v).unwrap_or(u8::MAX);
        let addr = RegisterAddr::new(raw)
            .map_err(|_| robobus_whj::RegisterAddrError { value: v }.to_string())?;
        return Ok(Register {
            addr,
            info: RegisterInfo::by_addr(addr),
        });
    }
    RegisterInfo::by_name(t)
        .map(|info| Register {
            addr: info.addr,
            info: Some(info),
        })
        .ok_or_else(|| {
            format!(
                "no register is named `{t}` (names as in `robobus whj registers`, e.g. \
                 SYS_TEMP, cur_position; or an address 0x00..=0x91)"
            )
        })
}

fn parse_end_board_register(s: &str) -> Result<u8, String> {
    let t = s.trim();
    if let Ok(v) = crate::wck::parse_u32(t) {
        return u8::try_from(v)
            .ok()
            .filter(|a| *a < 0x80)
            .ok_or_else(|| format!("end-board register {v:#x} is out of range 0x00..=0x7F"));
    }
    robobus_whj::broadcast::EndBoardRegister::by_name(t)
        .map(|r| r.addr)
        .ok_or_else(|| {
            format!(
                "no end-board register is named `{t}` (names: {})",
                robobus_whj::broadcast::END_BOARD_REGISTERS
                    .iter()
                    .map(|r| r.name)
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        })
}

fn parse_end_board_write(s: &str) -> Result<ops::EndBoardArg, String> {
    let (reg, value) = s
        .split_once('=')
        .ok_or_else(|| format!("`{s}` is not REGISTER=VALUE (e.g. EB_IO1_MODE=1)"))?;
    let v = crate::wck::parse_u32(value.trim())?;
    let value = u16::try_from(v).map_err(|_| format!("value {v} is out of range 0..=65535"))?;
    Ok(ops::EndBoardArg {
        addr: parse_end_board_register(reg)?,
        value: Some(value),
    })
}

fn parse_finite(s: &str) -> Result<f64, String> {
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("`{s}` is not a number"))?;
    if v.is_finite() {
        Ok(v)
    } else {
        Err(format!("`{s}` is not a finite number"))
    }
}

fn in_range(s: &str, what: &str, min: f64, max: f64) -> Result<f64, String> {
    let v = parse_finite(s)?;
    if (min..=max).contains(&v) {
        Ok(v)
    } else {
        Err(format!("{what} {v} is out of range {min}..={max}"))
    }
}

fn parse_angle(s: &str) -> Result<f64, String> {
    in_range(s, "angle (degrees)", -MAX_DEG, MAX_DEG)
}
fn parse_max_speed(s: &str) -> Result<f64, String> {
    in_range(s, "speed (degrees/s)", 0.1, 180.0)
}
fn parse_frame_rate(s: &str) -> Result<f64, String> {
    in_range(s, "rate (Hz)", 1.0, 1000.0)
}
fn parse_rpm(s: &str) -> Result<f64, String> {
    in_range(s, "speed (RPM)", -MAX_RPM, MAX_RPM)
}
fn parse_ma(s: &str) -> Result<f64, String> {
    in_range(s, "current (mA)", -MAX_MA, MAX_MA)
}
fn parse_duration(s: &str) -> Result<f64, String> {
    in_range(s, "duration (s)", 0.01, 3600.0)
}

/// Runs `robobus whj`.
pub(crate) fn run(g: Global, args: &Args) -> anyhow::Result<()> {
    if let Some(bus) = &args.bus {
        bus.parse::<FrameLinkSpec>()
            .map_err(|e| usage(format!("--bus: {e}")))?;
    }
    if matches!(args.command, WhjCommand::Registers) {
        return list_registers(g);
    }
    let plan = plan(args, g.dry_run)?;
    if g.dry_run {
        let bus = args.bus.as_deref().unwrap_or("(none)");
        return if g.json {
            output::print_json(&plan.to_json(bus))
        } else {
            output::print(&plan.to_text())
        };
    }
    let Some(bus) = args.bus.as_deref() else {
        return Err(usage(
            "robobus whj: --bus is required (udp, udp:GROUP:PORT or a SocketCAN interface \
             such as can0), unless --dry-run is given",
        ));
    };
    let run = whj_run(args);
    execute(
        &Job::Whj {
            action: action_name(&args.command),
            bus,
            capture: args.capture.as_deref(),
            plan: &plan,
            run: &run,
            on_stop: args.on_stop,
            json: g.json,
        },
        g.yes,
    )
}

const fn work_mode(mode: ModeArg) -> WorkMode {
    match mode {
        ModeArg::OpenLoop => WorkMode::OpenLoop,
        ModeArg::Current => WorkMode::Current,
        ModeArg::Speed => WorkMode::Speed,
        ModeArg::Position => WorkMode::Position,
    }
}

/// The step limit moves are planned with (the client's, also for dry runs).
fn step_limit() -> f64 {
    JointBusConfig::default().step_limit_deg
}

fn move_args(joint: JointId, degrees: f64, max_speed: f64, rate_hz: f64) -> MoveArgs {
    MoveArgs {
        joint,
        target_deg: degrees,
        max_speed_deg_s: max_speed,
        rate_hz,
        step_limit_deg: step_limit(),
    }
}

fn target_args(joint: JointId, servo: ServoLoop, value: f64, duration: Option<f64>) -> TargetArgs {
    TargetArgs {
        joint,
        servo,
        value,
        duration: duration.map(Duration::from_secs_f64),
    }
}

fn wave_args(c: &WhjCommand) -> Option<WaveArgs> {
    let WhjCommand::Wave {
        joint,
        shape,
        mode,
        amplitude,
        frequency,
        offset,
        duration,
        rate_hz,
        ..
    } = c
    else {
        return None;
    };
    Some(WaveArgs {
        joint: *joint,
        shape: match shape {
            Shape::Sine => ops::Shape::Sine,
            Shape::Square => ops::Shape::Square,
        },
        servo: match mode {
            WaveMode::Position => ServoLoop::Position,
            WaveMode::Speed => ServoLoop::Speed,
            WaveMode::Current => ServoLoop::Current,
        },
        amplitude: *amplitude,
        frequency: *frequency,
        offset: *offset,
        duration: *duration,
        rate_hz: *rate_hz,
        step_limit_deg: step_limit(),
    })
}

/// How a (validated) command runs on the bus.
fn whj_run(args: &Args) -> WhjRun {
    let c = &args.command;
    match c {
        WhjCommand::Scan { joints } => WhjRun::Scan(joints.0.clone()),
        WhjCommand::Info { joint } => WhjRun::Info(*joint),
        WhjCommand::Status {
            joints,
            broadcast: true,
            end_board,
        } => WhjRun::BroadcastStatus(joints.0.clone(), *end_board),
        WhjCommand::Status { joints, .. } => WhjRun::Status(joints.0.clone()),
        WhjCommand::Enable { joints } => WhjRun::Enable(joints.0.clone(), true),
        WhjCommand::Disable { joints } => WhjRun::Enable(joints.0.clone(), false),
        WhjCommand::Mode { joints, mode } => WhjRun::Mode(joints.0.clone(), work_mode(*mode)),
        WhjCommand::Move {
            joint,
            degrees,
            max_speed,
            rate_hz,
            ..
        } => WhjRun::Move(move_args(*joint, *degrees, *max_speed, *rate_hz)),
        WhjCommand::Speed {
            joint,
            rpm,
            duration,
        } => WhjRun::Target(target_args(*joint, ServoLoop::Speed, *rpm, *duration)),
        WhjCommand::Current {
            joint,
            milliamps,
            duration,
        } => WhjRun::Target(target_args(
            *joint,
            ServoLoop::Current,
            *milliamps,
            *duration,
        )),
        WhjCommand::Zero { joint } => WhjRun::Zero(*joint),
        WhjCommand::Clear { joints } => WhjRun::Clear(joints.0.clone()),
        WhjCommand::Save { joints } => WhjRun::Save(joints.0.clone()),
        WhjCommand::Read {
            joints,
            register,
            count,
            broadcast,
            end_board,
        } => WhjRun::Read {
            joints: joints.0.clone(),
            addr: register.addr,
            count: *count,
            broadcast: *broadcast,
            end_board: *end_board,
        },
        WhjCommand::Write {
            joints,
            register,
            value,
            raw,
            broadcast,
            end_board,
        } => WhjRun::Write {
            joints: joints.0.clone(),
            addr: register.addr,
            // Validated by the plan (a finite number).
            value: value.trim().parse().unwrap_or(0.0),
            raw: *raw,
            scale: args.model.map(ModelArg::scale),
            broadcast: *broadcast,
            end_board: *end_board,
        },
        // Handled before a plan is made.
        WhjCommand::Registers => WhjRun::Status(Vec::new()),
        WhjCommand::SetId { joint, new_id } => WhjRun::SetId(*joint, *new_id),
        WhjCommand::Wave { broadcast, .. } => match wave_args(c) {
            Some(w) => WhjRun::Wave(w, *broadcast),
            None => WhjRun::Status(Vec::new()),
        },
        WhjCommand::ReleaseIap { joints } => WhjRun::ReleaseIap(joints.0.clone()),
    }
}

fn action_name(c: &WhjCommand) -> &'static str {
    match c {
        WhjCommand::Scan { .. } => "scan",
        WhjCommand::Info { .. } => "info",
        WhjCommand::Status { .. } => "status",
        WhjCommand::Enable { .. } => "enable",
        WhjCommand::Disable { .. } => "disable",
        WhjCommand::Mode { .. } => "mode",
        WhjCommand::Move { .. } => "move",
        WhjCommand::Speed { .. } => "speed",
        WhjCommand::Current { .. } => "current",
        WhjCommand::Zero { .. } => "zero",
        WhjCommand::Clear { .. } => "clear",
        WhjCommand::Save { .. } => "save",
        WhjCommand::Read { .. } => "read",
        WhjCommand::Write { .. } => "write",
        WhjCommand::Registers => "registers",
        WhjCommand::SetId { .. } => "set-id",
        WhjCommand::Wave { .. } => "wave",
        WhjCommand::ReleaseIap { .. } => "release-iap",
    }
}

fn each(joints: &Joints, f: impl Fn(JointId) -> Request) -> WhjPlan {
    let mut plan = WhjPlan::default();
    for &j in &joints.0 {
        plan.push(f(j));
    }
    plan
}

/// The current scale for a command that needs one: --model, or (real runs) the joint's.
fn current_scale(args: &Args, dry_run: bool, option: &str) -> anyhow::Result<CurrentScale> {
    match args.model {
        Some(m) => Ok(m.scale()),
        None if dry_run => Err(usage(format!(
            "{option}: converting mA to counts needs the joint model in a dry run: give \
             --model whj03|whj10|whj30|whj60|whj120"
        ))),
        // A real run reads the model from the joint; the client does the scaling.
        None => Ok(CurrentScale::OneMilliamp),
    }
}

/// The plan of a command, with the connect a real run makes first shown as comments (the
/// frames of [`robobus::whj::Joint::connect_requests`] for each joint its frames address).
fn plan(args: &Args, dry_run: bool) -> anyhow::Result<WhjPlan> {
    let mut p = command_plan(args, dry_run)?;
    let connects = !matches!(
        args.command,
        WhjCommand::Scan { .. } | WhjCommand::Registers | WhjCommand::ReleaseIap { .. }
    );
    let mut joints: Vec<JointId> = Vec::new();
    for step in &p.steps {
        if let Some(j) = step.request.joint()
            && !joints.contains(&j)
        {
            joints.push(j);
        }
    }
    if connects && let Some(note) = robobus::catalogue::plan::connect_note(&joints) {
        p.notes.insert(0, note);
    }
    Ok(p)
}

#[allow(clippy::too_many_lines)]
fn command_plan(args: &Args, dry_run: bool) -> anyhow::Result<WhjPlan> {
    Ok(match &args.command {
        WhjCommand::Scan { joints } => {
            let mut p = each(joints, Request::read_identity);
            p.notes.push(
                "reads signature, ID, model and firmware of each ID; a joint that answers \
                 is present"
                    .into(),
            );
            p
        }
        WhjCommand::Info { joint } => {
            let mut p = WhjPlan::default();
            p.push(Request::read_identity(*joint));
            p.push(Request::read_unique_id(*joint));
            p.push(Request::read_position_limits(*joint));
            p.push(Request::StatusQuery { joint: *joint });
            p
        }
        WhjCommand::Status {
            joints,
            broadcast: true,
            end_board,
        } => {
            let mask = ops::reply_mask_with(&joints.0, *end_board)?;
            let mut p = WhjPlan::default();
            p.push(Request::BroadcastStatus(
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
            p
        }
        WhjCommand::Status { joints, .. } => each(joints, |joint| Request::StatusQuery { joint }),
        WhjCommand::Enable { joints } => each(joints, |j| Request::enable(j, true)),
        WhjCommand::Disable { joints } => each(joints, |j| Request::enable(j, false)),
        WhjCommand::Mode { joints, mode } => {
            let mode = work_mode(*mode);
            each(joints, |j| Request::set_mode(j, mode))
        }
        WhjCommand::Move {
            joint,
            degrees,
            max_speed,
            rate_hz,
            from,
        } => {
            let args = move_args(*joint, *degrees, *max_speed, *rate_hz);
            WhjPlan::of(&ops::plan_move(&args, from.unwrap_or(0.0), from.is_none())?)
        }
        WhjCommand::Speed {
            joint,
            rpm,
            duration,
        } => plan_target(
            &target_args(*joint, ServoLoop::Speed, *rpm, *duration),
            CurrentScale::OneMilliamp,
        )?,
        WhjCommand::Current {
            joint,
            milliamps,
            duration,
        } => {
            let scale = current_scale(args, dry_run, "current <MILLIAMPS>")?;
            plan_target(
                &target_args(*joint, ServoLoop::Current, *milliamps, *duration),
                scale,
            )?
        }
        WhjCommand::Zero { joint } => {
            let mut p = WhjPlan::default();
            p.push(Request::set_zero(*joint));
            p
        }
        WhjCommand::Clear { joints } => each(joints, Request::clear_error),
        WhjCommand::Save { joints } => {
            let mut p = each(joints, Request::save_to_flash);
            p.notes
                .push("the joints must be disabled; each needs ~50 ms to write flash".into());
            p
        }
        WhjCommand::Read {
            joints,
            register,
            count,
            broadcast: true,
            end_board,
        } => broadcast_plan(&ops::plan_broadcast_read(
            &joints.0,
            register.addr,
            *count,
            *end_board,
        )?),
        WhjCommand::Read {
            joints,
            register,
            count,
            ..
        } => {
            let joint = &one_joint(joints, "read")?;
            let count = count.unwrap_or(match register.info.map(|i| i.half) {
                Some(Half::Low) => 2,
                _ => 1,
            });
            let req = Request::read(*joint, register.addr, count)
                .map_err(|e| usage(format!("read <REGISTER> [COUNT]: {e}")))?;
            let mut p = WhjPlan::default();
            p.push(req);
            p
        }
        WhjCommand::Write {
            joints,
            register,
            value,
            raw,
            broadcast,
            end_board,
        } => {
            let name = register.info.map_or("reserved register", |i| i.name);
            let v: f64 = value
                .trim()
                .parse()
                .map_err(|_| usage(format!("write {name} <VALUE>: `{value}` is not a number")))?;
            // Motion targets and `never` registers are refused here, dry run or not.
            if let Err(e @ OpError::Refused(_)) = ops::check_write(register.addr, true) {
                return Err(usage(e.to_string()));
            }
            let scale = if ops::needs_current_scale(register.addr, *raw) {
                current_scale(args, dry_run, &format!("write {name}"))?
            } else {
                CurrentScale::OneMilliamp
            };
            if *broadcast {
                return Ok(broadcast_plan(&ops::plan_broadcast_write(
                    &joints.0,
                    register.addr,
                    v,
                    *raw,
                    &|_| scale,
                    *end_board,
                )?));
            }
            let joint = &one_joint(joints, "write")?;
            let req = ops::write_request(*joint, register.addr, v, *raw, scale)?;
            let mut p = WhjPlan::default();
            p.push(req);
            if let Some(what) = ops::confirm_text(&req) {
                p.notes.push(format!("{name}: {what} (needs --yes)"));
            }
            p
        }
        WhjCommand::Registers => WhjPlan::default(),
        WhjCommand::SetId { joint, new_id } => {
            let (frames, note) = ops::plan_set_id(*joint, *new_id)?;
            let mut p = WhjPlan::default();
            for f in frames {
                p.push(f);
            }
            p.notes.push(note);
            p
        }
        WhjCommand::Wave {
            mode,
            broadcast,
            from,
            ..
        } => {
            let scale = if *mode == WaveMode::Current {
                current_scale(args, dry_run, "wave --mode current")?
            } else {
                CurrentScale::OneMilliamp
            };
            let Some(w) = wave_args(&args.command) else {
                return Ok(WhjPlan::default());
            };
            let start = from.unwrap_or(0.0);
            if *broadcast {
                WhjPlan::of(&ops::plan_broadcast_wave(&w, start, scale, from.is_none())?)
            } else {
                WhjPlan::of(&ops::plan_wave(&w, start, scale, from.is_none())?)
            }
        }
        WhjCommand::ReleaseIap { joints } => each(joints, Request::start_application),
    })
}

/// The one joint of a command without --broadcast.
fn one_joint(joints: &Joints, what: &str) -> anyhow::Result<JointId> {
    match joints.0.as_slice() {
        [one] => Ok(*one),
        _ => Err(usage(format!(
            "{what} <JOINT>: one joint without --broadcast (got {}); with --broadcast, \
             joints 1..=7 share one frame",
            joints.0.len()
        ))),
    }
}

/// A broadcast register plan: its frames and notes.
fn broadcast_plan(b: &ops::BroadcastPlan) -> WhjPlan {
    let mut p = WhjPlan::default();
    for f in &b.frames {
        p.push(*f);
    }
    p.notes.clone_from(&b.notes);
    p
}

/// A speed or current target: the frame, and target 0 after `--duration`.
fn plan_target(args: &TargetArgs, scale: CurrentScale) -> anyhow::Result<WhjPlan> {
    let mut p = WhjPlan::default();
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
            #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // <= 3600 s
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

/// `robobus whj registers`: the table as text or JSON.
fn list_registers(g: Global) -> anyhow::Result<()> {
    if g.json {
        let rows: Vec<_> = REGISTERS
            .iter()
            .map(|r| {
                serde_json::json!({
                    "addr": r.addr.get(),
                    "name": r.name,
                    "unit": r.unit.symbol(),
                    "scale": r.unit.scale(),
                    "range": r.range.map(|(a, b)| [a, b]),
                    "writable": r.access.is_writable(),
                    "meaning": r.meaning,
                })
            })
            .collect();
        return output::print_json(&serde_json::Value::Array(rows));
    }
    let mut s = format!(
        "{:<5} {:<24} {:<6} {:<4} {:<25} {}\n",
        "ADDR", "NAME", "UNIT", "RW", "RANGE", "MEANING"
    );
    for r in &REGISTERS {
        let range = match r.range {
            Some((a, b)) if (a, b) == (i32::MIN, i32::MAX) => "i32".to_owned(),
            Some((a, b)) => format!("{a}..={b}"),
            None => "-".to_owned(),
        };
        let _ = writeln!(
            s,
            "0x{:02X}  {:<24} {:<6} {:<4} {:<25} {}",
            r.addr.get(),
            r.name,
            r.unit.symbol(),
            if r.access.is_writable() { "rw" } else { "r" },
            range,
            r.meaning
        );
    }
    output::print(&s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn joint_lists_sort_and_dedup() {
        let j = parse_joints("3,1-2,2").unwrap();
        let raw: Vec<u8> = j.0.iter().map(|j| j.get()).collect();
        assert_eq!(raw, [1, 2, 3]);
        assert!(parse_joints("0").unwrap_err().contains("1..=30"));
        assert!(parse_joints("5-2").is_err());
        assert!(parse_joint("300").unwrap_err().contains("300"));
    }

    #[test]
    fn registers_by_name_or_address() {
        let r = parse_register("cur_position").unwrap();
        assert_eq!(r.addr.get(), 0x14);
        assert_eq!(parse_register("0x14").unwrap().addr.get(), 0x14);
        assert_eq!(parse_register("20").unwrap().addr.get(), 0x14);
        assert!(parse_register("0x92").unwrap_err().contains("0x92"));
        assert!(parse_register("nope").is_err());
    }
}
