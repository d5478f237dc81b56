//! `robobus whj`: drive WHJ joints on a CAN FD bus.
//!
//! Each subcommand is one catalogue request ([`robobus::catalogue`]): its arguments are
//! parsed (joint IDs 1..=30 by [`JointId`], registers by [`RegisterInfo`], motion values
//! against the library's host bounds, [`robobus::catalogue::bounds`]), turned into the
//! request, and handed to the library's dispatcher: `--dry-run` prints its plan as
//! `cansend` lines, a real run goes through [`crate::report`].

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::Context as _;

use clap::{Subcommand, ValueEnum};
use robobus::catalogue::args::{Ids, WhjOnStop};
use robobus::catalogue::bounds::{self, Bound};
use robobus::catalogue::{self, whj as cw};
use robobus::ops::IdList;
use robobus::ops::whj as ops;
use robobus::station::{self, Station};
use robobus_link::FrameLinkSpec;
use robobus_whj::{JointId, REGISTERS, RegisterAddr, RegisterInfo};

use crate::Global;
use crate::exit::usage;
use crate::{output, report};

/// What brings a joint to a safe state when `move` or `wave` is interrupted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ValueEnum)]
pub(crate) enum OnStop {
    // Plain comments: doc comments would become clap's per-value help and switch every
    // `robobus whj` help page to the long layout; `--on-stop`'s own help explains them.
    // Stay enabled and hold the present position (speed / current waves: target 0).
    #[default]
    Hold,
    // Disable the drive.
    Disable,
}

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
    /// serves), `udp:GROUP:PORT`, a SocketCAN interface such as can0 / vcan0, or a
    /// serial-line adapter: `slcan:PORT` (a `CANable` 2.0-class adapter) or `fdcanusb:PORT` (PORT:
    /// /dev/ttyACM0, COM8, socket://HOST:PORT). Required unless --dry-run is given.
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
    /// The bus's CAN interface as the kernel reports it: the controller's state
    /// (error-active / -warning / -passive, bus-off), error counters, state changes and
    /// restarts, and what to do. Nothing is sent on the bus.
    CanHealth,
    /// Back up every setting of a joint (the registers it keeps in flash: limits, gains,
    /// modes at power-up, ID and bit rates) to a JSON settings file, with its model and
    /// firmware.
    Backup {
        /// Joint ID, 1..=30.
        #[arg(value_parser = parse_joint)]
        joint: JointId,
        /// The settings file to write (an existing one is replaced).
        #[arg(short, long, value_name = "FILE.json")]
        output: PathBuf,
    },
    /// Write the settings file of the values the vendor documents for a joint's model and
    /// firmware (modes at power-up, speed and acceleration limits, following error,
    /// feature switches), to restore with `whj restore`: the joints have no factory reset.
    /// The loop gains and the current and position limits are tuned per joint at the
    /// factory and not published: the file leaves them out, and a restore keeps them.
    Defaults {
        /// Joint ID, 1..=30.
        #[arg(value_parser = parse_joint)]
        joint: JointId,
        /// The settings file to write (an existing one is replaced).
        #[arg(short, long, value_name = "FILE.json")]
        output: PathBuf,
    },
    /// The end-effector board: its state, tool power, a digital channel's direction, its
    /// force sensor. Switching the tool power on or a channel's direction asks for
    /// confirmation (--yes): it switches what is attached to the tool.
    EndBoard {
        /// status | power (with --volts) | io (with --channel and --mode) | force.
        #[arg(value_enum)]
        action: EndBoardActionArg,
        /// The tool power, volts: 0, 12 or 24.
        #[arg(long)]
        volts: Option<u8>,
        /// The digital channel, 1 or 2.
        #[arg(long)]
        channel: Option<u8>,
        /// The channel's direction.
        #[arg(long, value_enum)]
        mode: Option<IoModeArg>,
    },
    /// List the settings on which a joint differs from a settings file, or from another
    /// joint (--with).
    ///
    /// Against a file, only the settings it holds count (a `whj defaults` file leaves out
    /// the gains, limits and bus identity); `left_out` says how many the file leaves out.
    Diff {
        /// Joint ID, 1..=30.
        #[arg(value_parser = parse_joint)]
        joint: JointId,
        /// A settings file (from `whj backup`).
        #[arg(required_unless_present = "with")]
        file: Option<PathBuf>,
        /// Compare with this joint instead of a file.
        #[arg(long, value_name = "JOINT", value_parser = parse_joint, conflicts_with = "file")]
        with: Option<JointId>,
    },
    /// Restore a settings file onto a joint: only the settings that differ are written,
    /// then saved to flash and read back. The joint must be disabled and be the file's
    /// model and firmware; its ID and bit rates are never written. Needs --yes.
    Restore {
        /// Joint ID, 1..=30.
        #[arg(value_parser = parse_joint)]
        joint: JointId,
        /// The settings file (from `whj backup`).
        file: PathBuf,
    },
    /// Give a joint a new ID (register 0x01, then save to flash; power-cycle afterwards).
    SetId {
        /// Current joint ID, 1..=30.
        #[arg(value_parser = parse_joint)]
        joint: JointId,
        /// New joint ID, 1..=30.
        #[arg(value_parser = parse_joint)]
        new_id: JointId,
    },
    /// Set joints' CAN FD bit rates (registers 0x08 / 0x09, read back, saved to flash).
    ///
    /// The joints must be disabled. They keep talking at the old rates until they are
    /// power-cycled, and from then on only at the new ones: set the adapter to them (the
    /// output says how), then `whj scan` finds them. Every joint on a bus must be at the
    /// bus's rates. Asks for confirmation (--yes).
    SetRates {
        /// Joint IDs, e.g. `1-6`.
        #[arg(value_parser = parse_joints)]
        joints: Joints,
        /// Arbitration bit rate, bit/s: 250000, 500000 or 1000000.
        #[arg(long)]
        bitrate: u32,
        /// Data bit rate, bit/s: 250000, 500000, 1000000, 2000000, 4000000 or 5000000.
        #[arg(long)]
        dbitrate: u32,
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

/// A number within one of the library's host bounds (the message names the quantity).
fn bounded(s: &str, bound: &Bound) -> Result<f64, String> {
    let v = parse_finite(s)?;
    bound.message(v).map_or(Ok(v), Err)
}

fn parse_angle(s: &str) -> Result<f64, String> {
    bounded(s, &bounds::ANGLE_DEG)
}
fn parse_max_speed(s: &str) -> Result<f64, String> {
    bounded(s, &bounds::MOVE_SPEED_DEG_S)
}
fn parse_frame_rate(s: &str) -> Result<f64, String> {
    bounded(s, &bounds::FRAME_RATE_HZ)
}
fn parse_rpm(s: &str) -> Result<f64, String> {
    bounded(s, &bounds::SPEED_RPM)
}
fn parse_ma(s: &str) -> Result<f64, String> {
    bounded(s, &bounds::CURRENT_MA)
}
fn parse_duration(s: &str) -> Result<f64, String> {
    bounded(s, &bounds::TARGET_DURATION_S)
}

/// Runs `robobus whj`: the subcommand's request goes to the library's dispatcher
/// (`--dry-run`: its plan).
/// `whj end-board`'s actions.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum EndBoardActionArg {
    /// Read its state.
    Status,
    /// Switch the tool power (--volts).
    Power,
    /// Set a digital channel's direction (--channel, --mode).
    Io,
    /// Read the force sensor (raw).
    Force,
}

/// A digital channel's direction.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum IoModeArg {
    /// Input.
    Input,
    /// Output.
    Output,
}

pub(crate) fn run(g: Global, args: &Args) -> anyhow::Result<()> {
    if let Some(bus) = &args.bus {
        bus.parse::<FrameLinkSpec>()
            .map_err(|e| usage(format!("--bus: {e}")))?;
    }
    if matches!(args.command, WhjCommand::Registers) {
        return list_registers(g);
    }
    let request = request(args)?;
    if let WhjCommand::Backup { output, .. } | WhjCommand::Defaults { output, .. } = &args.command {
        output::check_output_path(output, "--output")?;
    }
    if g.dry_run {
        let plan = catalogue::plan(&request)?;
        return if g.json {
            output::print_json(&serde_json::to_value(&plan)?)
        } else {
            output::print(plan.to_text())
        };
    }
    let Some(bus) = args.bus.as_deref() else {
        return Err(usage(
            "robobus whj: --bus is required (udp, udp:GROUP:PORT, a SocketCAN interface \
             such as can0, slcan:PORT or fdcanusb:PORT), unless --dry-run is given",
        ));
    };
    let request = report::confirm(request, g.yes)?;
    let mut station = Station::new();
    let config = robobus::whj::JointBusConfig {
        wait: g.wait,
        ..robobus::whj::JointBusConfig::default()
    };
    station.add_whj_at(
        bus,
        station::open_whj_with(bus, args.capture.as_deref(), config)?,
    );
    let result = report::run(&station, &request);
    station.leave();
    let report = result?;
    if let (
        WhjCommand::Backup { output, joint } | WhjCommand::Defaults { output, joint },
        Some(doc),
    ) = (&args.command, &report.summary)
    {
        let text = serde_json::to_string_pretty(doc)? + "\n";
        std::fs::write(output, text)
            .with_context(|| format!("cannot write {}", output.display()))?;
        let what = if matches!(args.command, WhjCommand::Defaults { .. }) {
            "the documented defaults for"
        } else {
            "the settings of"
        };
        eprintln!(
            "robobus: {what} joint {} written to {}",
            joint.get(),
            output.display()
        );
    }
    if let Some(note) = report
        .results
        .first()
        .filter(|r| r["keeps_running"] == true)
        .and_then(|r| r["note"].as_str())
    {
        eprintln!("robobus: {note}");
    }
    report::print(&report, g.json, &WHJ_TABLE)
}

/// How WHJ tables look: the `JOINT` column, four decimals.
const WHJ_TABLE: report::Style = report::Style {
    id_header: "joint",
    decimals: 4,
};

/// The joints as a request's list.
fn ids(joints: &Joints) -> Ids {
    Ids::List(joints.0.iter().map(|j| u32::from(j.get())).collect())
}

fn joint(j: JointId) -> u32 {
    u32::from(j.get())
}

const fn model(m: ModelArg) -> cw::Model {
    match m {
        ModelArg::Whj03 => cw::Model::Whj03,
        ModelArg::Whj10 => cw::Model::Whj10,
        ModelArg::Whj30 => cw::Model::Whj30,
        ModelArg::Whj60 => cw::Model::Whj60,
        ModelArg::Whj120 => cw::Model::Whj120,
    }
}

const fn on_stop(o: OnStop) -> WhjOnStop {
    match o {
        OnStop::Hold => WhjOnStop::Hold,
        OnStop::Disable => WhjOnStop::Disable,
    }
}

/// A settings file's text, read bounded.
fn settings_file(path: &Path) -> anyhow::Result<String> {
    Ok(robobus::ops::read_bounded(
        path,
        ops::settings::SETTINGS_FILE_LIMIT,
    )?)
}

/// The catalogue request of a subcommand: its arguments under the request's names.
#[allow(clippy::too_many_lines)] // one arm per subcommand
fn request(args: &Args) -> anyhow::Result<catalogue::Request> {
    use catalogue::Request as Q;
    let on_stop = on_stop(args.on_stop);
    let model = args.model.map(model);
    Ok(match &args.command {
        WhjCommand::Scan { joints } => Q::WhjScan(cw::Scan {
            bus: None,
            joints: ids(joints),
        }),
        WhjCommand::Info { joint: j } => Q::WhjInfo(cw::Info {
            bus: None,
            joint: joint(*j),
        }),
        WhjCommand::Status {
            joints,
            broadcast,
            end_board,
        } => Q::WhjStatus(cw::Status {
            bus: None,
            joints: ids(joints),
            broadcast: *broadcast,
            end_board: *end_board,
        }),
        WhjCommand::Enable { joints } => Q::WhjEnable(cw::Enable {
            bus: None,
            joints: ids(joints),
        }),
        WhjCommand::Disable { joints } => Q::WhjDisable(cw::Disable {
            bus: None,
            joints: ids(joints),
        }),
        WhjCommand::Mode { joints, mode } => Q::WhjMode(cw::Mode {
            bus: None,
            joints: ids(joints),
            mode: match mode {
                ModeArg::OpenLoop => cw::ModeName::OpenLoop,
                ModeArg::Current => cw::ModeName::Current,
                ModeArg::Speed => cw::ModeName::Speed,
                ModeArg::Position => cw::ModeName::Position,
            },
        }),
        WhjCommand::Move {
            joint: j,
            degrees,
            max_speed,
            rate_hz,
            from,
        } => Q::WhjMove(cw::Move {
            bus: None,
            joint: joint(*j),
            degrees: *degrees,
            max_speed: *max_speed,
            rate_hz: *rate_hz,
            from: *from,
            on_stop,
        }),
        WhjCommand::Speed {
            joint: j,
            rpm,
            duration,
        } => Q::WhjSpeed(cw::Speed {
            bus: None,
            joint: joint(*j),
            rpm: *rpm,
            duration: *duration,
            on_stop,
        }),
        WhjCommand::Current {
            joint: j,
            milliamps,
            duration,
        } => Q::WhjCurrent(cw::Current {
            bus: None,
            joint: joint(*j),
            milliamps: *milliamps,
            duration: *duration,
            model,
            on_stop,
        }),
        WhjCommand::Zero { joint: j } => Q::WhjZero(cw::Zero {
            bus: None,
            joint: joint(*j),
        }),
        WhjCommand::Clear { joints } => Q::WhjClear(cw::Clear {
            bus: None,
            joints: ids(joints),
        }),
        WhjCommand::Save { joints } => Q::WhjSave(cw::Save {
            bus: None,
            joints: ids(joints),
            confirm: false,
        }),
        WhjCommand::Read {
            joints,
            register,
            count,
            broadcast,
            end_board,
        } => Q::WhjRead(cw::Read {
            bus: None,
            joints: ids(joints),
            register: format!("{:#04X}", register.addr.get()),
            count: *count,
            broadcast: *broadcast,
            end_board: end_board.map(|a| format!("{a:#04X}")),
        }),
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
            Q::WhjWrite(cw::Write {
                bus: None,
                joints: ids(joints),
                register: format!("{:#04X}", register.addr.get()),
                value: v,
                raw: *raw,
                broadcast: *broadcast,
                end_board: end_board
                    .map(|e| format!("{:#04X}={}", e.addr, e.value.unwrap_or_default())),
                model,
                confirm: false,
            })
        }
        WhjCommand::Registers => Q::WhjRegisters(cw::Registers { bus: None }),
        WhjCommand::CanHealth => Q::WhjCanHealth(cw::CanHealth { bus: None }),
        WhjCommand::Backup { joint: j, .. } => Q::WhjBackup(cw::Backup {
            bus: None,
            joint: joint(*j),
        }),
        WhjCommand::Defaults { joint: j, .. } => Q::WhjDefaults(cw::Defaults {
            bus: None,
            joint: joint(*j),
        }),
        WhjCommand::EndBoard {
            action,
            volts,
            channel,
            mode,
        } => Q::WhjEndBoard(cw::EndBoard {
            bus: None,
            action: match action {
                EndBoardActionArg::Status => cw::EndBoardAction::Status,
                EndBoardActionArg::Power => cw::EndBoardAction::Power,
                EndBoardActionArg::Io => cw::EndBoardAction::Io,
                EndBoardActionArg::Force => cw::EndBoardAction::Force,
            },
            volts: *volts,
            channel: *channel,
            mode: mode.map(|m| match m {
                IoModeArg::Input => cw::IoMode::Input,
                IoModeArg::Output => cw::IoMode::Output,
            }),
            confirm: false,
        }),
        WhjCommand::Diff {
            joint: j,
            file,
            with,
        } => Q::WhjDiff(cw::Diff {
            bus: None,
            joint: joint(*j),
            settings: file.as_deref().map(settings_file).transpose()?,
            other: with.map(joint),
        }),
        WhjCommand::Restore { joint: j, file } => Q::WhjRestore(cw::Restore {
            bus: None,
            joint: joint(*j),
            settings: settings_file(file)?,
            confirm: false,
        }),
        WhjCommand::SetRates {
            joints,
            bitrate,
            dbitrate,
        } => Q::WhjSetRates(cw::SetRates {
            bus: None,
            joints: ids(joints),
            bitrate: *bitrate,
            dbitrate: *dbitrate,
            confirm: false,
        }),
        WhjCommand::SetId { joint: j, new_id } => Q::WhjSetId(cw::SetId {
            bus: None,
            joint: joint(*j),
            new_id: joint(*new_id),
            confirm: false,
        }),
        WhjCommand::Wave {
            joint: j,
            shape,
            mode,
            amplitude,
            frequency,
            offset,
            duration,
            rate_hz,
            broadcast,
            from,
        } => Q::WhjWave(cw::Wave {
            bus: None,
            joint: joint(*j),
            shape: match shape {
                Shape::Sine => cw::Shape::Sine,
                Shape::Square => cw::Shape::Square,
            },
            mode: match mode {
                WaveMode::Position => cw::WaveMode::Position,
                WaveMode::Speed => cw::WaveMode::Speed,
                WaveMode::Current => cw::WaveMode::Current,
            },
            amplitude: *amplitude,
            frequency: *frequency,
            offset: *offset,
            duration: *duration,
            rate_hz: *rate_hz,
            broadcast: *broadcast,
            from: *from,
            model,
            on_stop,
        }),
        WhjCommand::ReleaseIap { joints } => Q::WhjReleaseIap(cw::ReleaseIap {
            bus: None,
            joints: ids(joints),
        }),
    })
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
