//! `robobus wck`: drive wCK servos on a serial (UART) bus.
//!
//! Every subcommand maps onto the commands of the wCK manual's appendix A-1
//! ([`robobus_wck::Command`]). Arguments are parsed into the protocol crate's range-checked
//! newtypes by clap value parsers, so an out-of-range value is refused (exit code 2, the
//! message names the value, the range and the argument) before anything is opened. The
//! subcommand then becomes its catalogue request ([`robobus::catalogue::wck`]); the library
//! validates and plans it: `--dry-run` prints the plan, otherwise [`crate::report`] runs it
//! on a station holding the one port.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Duration;

use clap::{Subcommand, ValueEnum};
use robobus::catalogue::args::{Ids, WckOnStop};
use robobus::catalogue::station::{self, Station, WckPort};
use robobus::catalogue::{self, Report, Request, wck as cw};
use robobus::ops::wck::{FORMAT_HELP, MOTION_FILE_LIMIT};
use robobus::ops::{Control, IdList, OpError, read_bounded};
use robobus_wck::{
    Accel, BaudRate, DGain, DataByte, ExtServoId, IGain, IoBits, Overload, PGain, Position,
    Position10, RangeError, ServoId, Speed, TorqueLevel, WheelSpeed,
};
use serde_json::Value;

use crate::Global;
use crate::exit::usage;
use crate::{output, report};

mod teach;

/// The safe state of a loop that ends early (play, teach, timed wheel) or, for teach and
/// wheel, when it ends at all.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum OnStop {
    /// Release the torque (the servos turn freely).
    Passive,
    /// Dynamic brake on every servo of the bus (A-1 (6) break mode).
    Break,
    /// Keep the current position, with torque (a position move to where each servo is).
    Hold,
}

const AFTER_HELP: &str = "\
IDs: 4- and 6-byte commands address servos 0..=30 (31 is the broadcast ID used by
sync-move and brake); move10 / read10 address 0..=253. Positions are 0..=254
(1 step = 269/255 degrees ~ 1.055 deg), 10-bit positions 0..=1023 (333/1023 deg).
Torque levels are 0 (maximum) ..= 4 (minimum).

Without --dry-run the command runs on the bus at --port: each reply is printed as a table
(--json: one JSON object; fields carry their units: position, degrees, load, milliamps).
Settings stored in EEPROM are verified by reading them back, set-id / set-baud by talking
to the servo at its new ID / rate. A servo that does not answer gives exit code 3 (the
message names the port and the servo). move / move10 reply the status before the move
(load_before, position_before). Ctrl-C during play, teach or a timed wheel run
first brings the servos to the --on-stop state, then exits with 130.

With --dry-run every subcommand prints the packets it would send, one per line in hex
(`FF 03 7F 7C`), lines starting with `#` are comments; --json prints them as JSON.
Commands marked (EEPROM) rewrite the servo's non-volatile memory.";

/// Options of `robobus wck`.
#[derive(Debug, clap::Args)]
#[command(after_help = AFTER_HELP)]
pub(crate) struct Args {
    /// Serial port of the wCK bus, e.g. /dev/ttyUSB0 or the path `robobus sim wck` printed.
    /// Required unless --dry-run is given or the subcommand needs no device.
    #[arg(long, value_name = "PATH", global = true)]
    port: Option<String>,
    /// Baud rate the servos are set to: 4800, 9600, 38400, 57600, 115200, 230400, 460800 or
    /// 921600.
    #[arg(long, default_value = "115200", value_parser = parse_baud, global = true)]
    baud: BaudRate,
    /// Extra time to wait for each reply beyond its modelled wire time and turnaround, in
    /// ms (default 10, plus a USB adapter's latency timer when it can be read). Raise it
    /// for a simulator on a heavily loaded machine.
    #[arg(long, value_name = "MS", value_parser = parse_margin, global = true)]
    reply_margin: Option<core::time::Duration>,
    /// Accept a read only when two replies in a row agree (wCK replies carry no checksum,
    /// so line noise can look like a value). On by default for `get` (gains, speed,
    /// over-load, bounds, I/O); this turns it on for every read (status, scan excepted).
    /// Costs one more exchange per read (about 1.5 ms at 115200 bit/s).
    #[arg(long, global = true, conflicts_with = "no_verify_reads")]
    verify_reads: bool,
    /// Accept a `get` read from a single reply (faster, but noise may pass as a value).
    #[arg(long, global = true)]
    no_verify_reads: bool,
    /// Record every byte written to and read from the port to FILE, a timestamped hex log
    /// (`<seconds> > FF 03 7F 7C`, `<` for bytes read); `robobus replay FILE` decodes it.
    /// An existing FILE is not overwritten.
    #[arg(long, value_name = "FILE", global = true)]
    capture: Option<PathBuf>,
    /// What to do.
    #[command(subcommand)]
    command: WckCommand,
}

#[derive(Debug, Subcommand)]
enum WckCommand {
    /// Find servos: read the status of every ID (0..=30 unless --ids is given).
    ///
    /// Prints the servos found (ID, baud rate, load, position); IDs answered by more than
    /// one module are flagged as duplicates. On a terminal a progress bar shows on stderr.
    /// Exit code 3 if no servo answers.
    Scan {
        /// Try every baud rate the wCK supports, not just --baud.
        #[arg(long)]
        all_bauds: bool,
        /// IDs to try: a list of IDs and ranges, e.g. `0-5,7`.
        #[arg(long, default_value = "0-30", value_parser = parse_servo_ids)]
        ids: ServoIds,
    },
    /// Read load and position of servos (A-1 (3) status read).
    Status {
        /// Servo IDs: a list of IDs and ranges, e.g. `3` or `0-5,7`.
        #[arg(value_parser = parse_servo_ids)]
        ids: ServoIds,
    },
    /// Move one servo to a position (A-1 (1) position move); replies load and position
    Move {
        /// Servo ID, 0..=30.
        #[arg(value_parser = parse_servo_id)]
        id: ServoId,
        /// Target position, 0..=254.
        #[arg(value_parser = parse_position)]
        position: Position,
        /// Torque level, 0 (maximum) ..= 4 (minimum).
        #[arg(long, default_value = "0", value_parser = parse_torque)]
        torque: TorqueLevel,
    },
    /// Move one servo to a 10-bit position (A-1 (26)).
    Move10 {
        /// Servo ID, 0..=253.
        #[arg(value_parser = parse_ext_id)]
        id: ExtServoId,
        /// Target position, 0..=1023.
        #[arg(value_parser = parse_position10)]
        position: Position10,
        /// Torque, 0..=254 (a full data byte, as the manual gives it).
        #[arg(long, default_value = "0", value_parser = parse_data_byte)]
        torque: DataByte,
    },
    /// Read the 10-bit position of a servo (A-1 (27)).
    Read10 {
        /// Servo ID, 0..=253.
        #[arg(value_parser = parse_ext_id)]
        id: ExtServoId,
    },
    /// Move servos 0..N-1 at once (A-1 (2) synchronized move, no reply).
    SyncMove {
        /// Target positions of servos 0, 1, 2, ... (1..=31 values, each 0..=254).
        #[arg(required = true, num_args = 1..=31, value_parser = parse_position)]
        positions: Vec<Position>,
        /// Torque level, 0 (maximum) ..= 4 (minimum).
        #[arg(long, default_value = "0", value_parser = parse_torque)]
        torque: TorqueLevel,
    },
    /// Release the torque of servos (A-1 (4) passive); replies the position.
    Passive {
        /// Servo IDs, e.g. `3` or `0-5`.
        #[arg(value_parser = parse_servo_ids)]
        ids: ServoIds,
    },
    /// Turn a servo continuously (A-1 (5) wheel mode).
    Wheel {
        /// Servo ID, 0..=30.
        #[arg(value_parser = parse_servo_id)]
        id: ServoId,
        /// Direction.
        direction: Direction,
        /// Speed 0 (stop), 1 (minimum) ..= 15 (maximum).
        #[arg(value_parser = parse_wheel_speed)]
        speed: WheelSpeed,
        /// Turn for this many seconds (0.1..=3600), then stop per --on-stop. Without it the
        /// servo keeps turning after the command returns.
        #[arg(long, value_name = "SECS", value_parser = parse_seconds)]
        duration: Option<Duration>,
        /// How the servo stops after --duration or on Ctrl-C: hold (position move to where
        /// it is), passive or break.
        #[arg(long, value_enum, default_value = "hold", hide_possible_values = true)]
        on_stop: OnStop,
    },
    /// Put every servo on the bus into break mode (A-1 (6)).
    Brake,
    /// Read a parameter of a servo.
    #[command(subcommand)]
    Get(GetParam),
    /// Write a parameter of a servo.
    #[command(subcommand)]
    Set(SetParam),
    /// Give a servo a new ID (A-1 (14), EEPROM). IDs above 30 are reachable only with
    /// move10 / read10.
    SetId {
        /// Current ID, 0..=30.
        #[arg(value_parser = parse_servo_id)]
        id: ServoId,
        /// New ID, 0..=253.
        #[arg(value_parser = parse_ext_id)]
        new_id: ExtServoId,
    },
    /// Set a servo's baud rate (A-1 (7), EEPROM); reach it afterwards with --baud RATE.
    SetBaud {
        /// Servo ID, 0..=30.
        #[arg(value_parser = parse_servo_id)]
        id: ServoId,
        /// New baud rate: 4800, 9600, 38400, 57600, 115200, 230400, 460800 or 921600.
        #[arg(value_parser = parse_baud)]
        rate: BaudRate,
    },
    /// Self-running motion programs (manual section 3-11).
    #[command(subcommand)]
    Program(ProgramCommand),
    /// Record poses by hand: servos go passive, their positions are recorded as poses.
    ///
    /// Move the servos by hand; each Enter records a pose (q + Enter or Ctrl-D finishes).
    /// With --rate-hz / --duration poses are recorded at a rate instead (for --duration,
    /// or until Enter). Writes a keyframe motion file that `play` plays.
    Teach {
        /// Servo IDs to record: 0..N-1 (e.g. `0-15`), since a pose lists servos 0, 1, ...
        #[arg(value_parser = parse_servo_ids)]
        ids: ServoIds,
        /// Record at this many poses per second (0.1..=200) instead of per keypress.
        #[arg(long, value_parser = parse_rate)]
        rate_hz: Option<f64>,
        /// Record for this many seconds (0.1..=3600), at --rate-hz (default 10).
        #[arg(long, value_name = "SECS", value_parser = parse_seconds)]
        duration: Option<Duration>,
        /// Transition time written for each pose recorded by keypress, ms (0..=600000).
        #[arg(long, default_value_t = 1000, value_parser = clap::value_parser!(u32).range(0..=600_000))]
        pose_ms: u32,
        /// Torque level written into the file, 0 (maximum) ..= 4 (minimum).
        #[arg(long, default_value = "0", value_parser = parse_torque)]
        torque: TorqueLevel,
        /// Write the poses as a keyframe motion file (see `robobus wck play --help`);
        /// without it the file is printed on stdout.
        #[arg(short, long, value_name = "FILE")]
        output: Option<PathBuf>,
        /// What the servos do when recording ends: passive (stay limp), hold (keep the last
        /// pose with torque) or break.
        #[arg(
            long,
            value_enum,
            default_value = "passive",
            hide_possible_values = true
        )]
        on_stop: OnStop,
    },
    /// Play a keyframe motion file: poses with transition times, interpolated and sent as
    /// synchronized moves.
    #[command(after_help = FORMAT_HELP)]
    Play {
        /// The keyframe motion file.
        file: PathBuf,
        /// Synchronized moves per second while interpolating (1..=200).
        #[arg(long, default_value_t = 50.0, value_parser = parse_rate)]
        rate_hz: f64,
        /// What the servos do on Ctrl-C: hold (keep the current position), passive or
        /// break.
        #[arg(long, value_enum, default_value = "hold", hide_possible_values = true)]
        on_stop: OnStop,
    },
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
enum Direction {
    /// Counter-clockwise.
    Ccw,
    /// Clockwise.
    Cw,
}

#[derive(Debug, Subcommand)]
enum GetParam {
    /// P and D gains (A-1 (9)).
    Gains(IdArg),
    /// I gain (A-1 (11)).
    IGain(IdArg),
    /// Speed level and acceleration range (A-1 (16)).
    Speed(IdArg),
    /// Over-load (over-current) threshold, shown in mA (A-1 (19)).
    Overload(IdArg),
    /// Movement boundaries (A-1 (21)).
    Bounds(IdArg),
    /// Digital outputs and the A/D input (A-1 (23)).
    Io(IdArg),
}

#[derive(Debug, clap::Args)]
struct IdArg {
    /// Servo ID, 0..=30.
    #[arg(value_parser = parse_servo_id)]
    id: ServoId,
}

#[derive(Debug, Subcommand)]
enum SetParam {
    /// P and D gains (A-1 (8), EEPROM; --runtime: A-1 (12), lost at power-off).
    Gains {
        /// Servo ID, 0..=30.
        #[arg(value_parser = parse_servo_id)]
        id: ServoId,
        /// P gain, 1..=254 (the manual recommends up to 120, and P = 1.5 x D).
        #[arg(value_parser = parse_p_gain)]
        p: PGain,
        /// D gain, 0..=254.
        #[arg(value_parser = parse_d_gain)]
        d: DGain,
        /// Only until power-off (runtime gains), not in EEPROM.
        #[arg(long)]
        runtime: bool,
    },
    /// I gain (A-1 (10), EEPROM; --runtime: A-1 (13)).
    IGain {
        /// Servo ID, 0..=30.
        #[arg(value_parser = parse_servo_id)]
        id: ServoId,
        /// I gain, 0..=254 (the manual recommends 0..=10).
        #[arg(value_parser = parse_i_gain)]
        i: IGain,
        /// Only until power-off, not in EEPROM.
        #[arg(long)]
        runtime: bool,
    },
    /// Speed level and acceleration range (A-1 (15), EEPROM; --runtime: A-1 (17)).
    Speed {
        /// Servo ID, 0..=30.
        #[arg(value_parser = parse_servo_id)]
        id: ServoId,
        /// Speed level, 0..=30 (0 = no limit).
        #[arg(value_parser = parse_speed)]
        speed: Speed,
        /// Acceleration range, 20..=100.
        #[arg(value_parser = parse_accel)]
        accel: Accel,
        /// Only until power-off, not in EEPROM (the servo does not reply).
        #[arg(long)]
        runtime: bool,
    },
    /// Over-load (over-current) threshold in mA, 400..=1800 (A-1 (18), EEPROM).
    Overload {
        /// Servo ID, 0..=30.
        #[arg(value_parser = parse_servo_id)]
        id: ServoId,
        /// Threshold in mA, 400..=1800 (rounded to the nearest code).
        #[arg(value_parser = parse_overload_ma)]
        milliamps: Overload,
    },
    /// Movement boundaries (A-1 (20), EEPROM).
    Bounds {
        /// Servo ID, 0..=30.
        #[arg(value_parser = parse_servo_id)]
        id: ServoId,
        /// Lower boundary, 0..=254.
        #[arg(value_parser = parse_position)]
        lower: Position,
        /// Upper boundary, 0..=254, not below the lower one.
        #[arg(value_parser = parse_position)]
        upper: Position,
    },
    /// Digital outputs (A-1 (22)): 0..=3, bit 0 = D/O 1, bit 1 = D/O 2.
    Io {
        /// Servo ID, 0..=30.
        #[arg(value_parser = parse_servo_id)]
        id: ServoId,
        /// Output bits, 0..=3.
        #[arg(value_parser = parse_io_bits)]
        outputs: IoBits,
    },
}

#[derive(Debug, Subcommand)]
enum ProgramCommand {
    /// Store a motion program (text form) in a servo (A-1 (24), EEPROM).
    #[command(after_help = PROGRAM_HELP)]
    Upload {
        /// Servo ID, 0..=30.
        #[arg(value_parser = parse_servo_id)]
        id: ServoId,
        /// The program, in the text form (see `robobus wck program check --help`).
        file: PathBuf,
    },
    /// Read how many instructions a servo's program has (A-1 (25)).
    Download {
        /// Servo ID, 0..=30.
        #[arg(value_parser = parse_servo_id)]
        id: ServoId,
    },
    /// Check a program file without a device: report errors with line:column, print the
    /// encoded bytes.
    #[command(after_help = PROGRAM_HELP)]
    Check {
        /// The program, in the text form.
        file: PathBuf,
        /// Servo ID for the printed upload packet, 0..=30.
        #[arg(long, default_value = "0", value_parser = parse_servo_id)]
        id: ServoId,
    },
}

const PROGRAM_HELP: &str = "\
Program text form (manual section 3-11): one instruction per line, at most 8; `#` starts a
comment.
  none                      no operation
  move <0..=254> torque <0..=4>
  motion passive | motion break
  wheel ccw|cw <0..=15>
  delay <0..=4095>ms        (delays whose low byte is 0xFF, e.g. 255, cannot be sent)
  output <0..=3>
  if pos <op> <0..=254>     <op>: == > < >= <=; a false condition skips the next line
  if adc <op> <0..=254>
  repeat <1..=254> | repeat forever
  end";

/// A parsed list of servo IDs (`0-5,7`), in the order given, without repeats.
type ServoIds = IdList<ServoId>;

/// Parses a number: decimal or `0x` hex.
pub(crate) fn parse_u32(s: &str) -> Result<u32, String> {
    let t = s.trim();
    let parsed = match t.strip_prefix("0x").or_else(|| t.strip_prefix("0X")) {
        Some(hex) => u32::from_str_radix(hex, 16),
        None => t.parse(),
    };
    parsed.map_err(|_| format!("`{s}` is not a whole number"))
}

/// Parses a byte-sized value with a protocol constructor; values above 255 get the same
/// message as the constructor's own range error.
fn ranged<T>(s: &str, new: impl Fn(u8) -> Result<T, RangeError>) -> Result<T, String> {
    // A negative number is out of range, not "not a number": name the range.
    if let Some(magnitude) = s.trim().strip_prefix('-')
        && parse_u32(magnitude).is_ok()
    {
        let (what, min, max) = (0..=u8::MAX)
            .find_map(|b| new(b).err())
            .or_else(|| new(u8::MAX).err())
            .map_or(("value", 0, 255), |e| (e.what, e.min, e.max));
        return Err(format!("{what} {} is out of range {min}..={max}", s.trim()));
    }
    let v = parse_u32(s)?;
    match u8::try_from(v) {
        Ok(b) => new(b).map_err(|e| e.to_string()),
        Err(_) => match new(u8::MAX) {
            Err(e) => Err(RangeError { value: v, ..e }.to_string()),
            Ok(_) => Err(format!("{v} is out of range 0..=255")),
        },
    }
}

pub(crate) fn parse_servo_id(s: &str) -> Result<ServoId, String> {
    ranged(s, ServoId::new)
}
fn parse_ext_id(s: &str) -> Result<ExtServoId, String> {
    ranged(s, ExtServoId::new)
}
pub(crate) fn parse_position(s: &str) -> Result<Position, String> {
    ranged(s, Position::new)
}
pub(crate) fn parse_torque(s: &str) -> Result<TorqueLevel, String> {
    ranged(s, TorqueLevel::new)
}
fn parse_data_byte(s: &str) -> Result<DataByte, String> {
    ranged(s, DataByte::new)
}
fn parse_wheel_speed(s: &str) -> Result<WheelSpeed, String> {
    ranged(s, WheelSpeed::new)
}
fn parse_p_gain(s: &str) -> Result<PGain, String> {
    ranged(s, PGain::new)
}
fn parse_d_gain(s: &str) -> Result<DGain, String> {
    ranged(s, DGain::new)
}
fn parse_i_gain(s: &str) -> Result<IGain, String> {
    ranged(s, IGain::new)
}
fn parse_speed(s: &str) -> Result<Speed, String> {
    ranged(s, Speed::new)
}
fn parse_accel(s: &str) -> Result<Accel, String> {
    ranged(s, Accel::new)
}
fn parse_io_bits(s: &str) -> Result<IoBits, String> {
    ranged(s, IoBits::new)
}

fn parse_position10(s: &str) -> Result<Position10, String> {
    let v = parse_u32(s)?;
    let raw = u16::try_from(v).unwrap_or(u16::MAX);
    Position10::new(raw).map_err(|e| RangeError { value: v, ..e }.to_string())
}

fn parse_overload_ma(s: &str) -> Result<Overload, String> {
    let v = parse_u32(s.trim().trim_end_matches("mA").trim_end_matches("ma"))?;
    let raw = u16::try_from(v).unwrap_or(u16::MAX);
    Overload::from_milliamps(raw).map_err(|e| RangeError { value: v, ..e }.to_string())
}

/// Parses `--reply-margin`: whole milliseconds, 0..=10000.
pub(crate) fn parse_margin(s: &str) -> Result<core::time::Duration, String> {
    match s.parse::<u64>() {
        Ok(ms) if ms <= 10_000 => Ok(core::time::Duration::from_millis(ms)),
        _ => Err(format!(
            "{s:?} is not a reply margin: whole milliseconds, 0..=10000"
        )),
    }
}

/// Parses a baud rate in bit/s.
pub(crate) fn parse_baud(s: &str) -> Result<BaudRate, String> {
    let v = parse_u32(s)?;
    BaudRate::from_bits_per_second(v).map_err(|e| e.to_string())
}

/// A rate in Hz, 0.1..=200.
fn parse_rate(s: &str) -> Result<f64, String> {
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("`{s}` is not a number"))?;
    if (0.1..=200.0).contains(&v) {
        Ok(v)
    } else {
        Err(format!("rate {v} Hz is out of range 0.1..=200"))
    }
}

/// A duration in seconds, 0.1..=3600.
fn parse_seconds(s: &str) -> Result<Duration, String> {
    let v: f64 = s
        .trim()
        .trim_end_matches('s')
        .parse()
        .map_err(|_| format!("`{s}` is not a number of seconds"))?;
    if (0.1..=3600.0).contains(&v) {
        Ok(Duration::from_secs_f64(v))
    } else {
        Err(format!("{v} s is out of range 0.1..=3600"))
    }
}

fn parse_servo_ids(spec: &str) -> Result<ServoIds, String> {
    spec.parse()
}

/// The largest motion program file read (a program has at most 8 instructions).
const PROGRAM_FILE_LIMIT: u64 = 64 << 10;

/// A catalogue error about a file's text (`motion` / `program`: `line:column` and what
/// is wrong) as `FILE:line:column: ...` (exit 2); other errors as they are.
fn in_file(e: OpError, path: Option<&Path>) -> anyhow::Error {
    match (e, path) {
        (
            OpError::Invalid {
                option,
                value,
                reason,
            },
            Some(path),
        ) if option == "motion" || option == "program" => {
            usage(format!("{}:{value}: {reason}", path.display()))
        }
        (e, _) => e.into(),
    }
}

/// The file a subcommand reads, if any (for [`in_file`]).
fn input_file(c: &WckCommand) -> Option<&Path> {
    match c {
        WckCommand::Play { file, .. }
        | WckCommand::Program(
            ProgramCommand::Upload { file, .. } | ProgramCommand::Check { file, .. },
        ) => Some(file),
        _ => None,
    }
}

/// Runs `robobus wck`: the subcommand's request, planned (`--dry-run` prints the plan)
/// or confirmed and run on the port, its report printed.
pub(crate) fn run(g: Global, args: &Args) -> anyhow::Result<()> {
    let file = input_file(&args.command);
    let request = request(args)?;
    if let WckCommand::Program(ProgramCommand::Check { file, .. }) = &args.command {
        return check_program(g, file, &request);
    }
    if g.dry_run {
        let plan = catalogue::plan_at(&request, args.baud).map_err(|e| in_file(e, file))?;
        return if g.json {
            output::print_json(&serde_json::to_value(&plan)?)
        } else {
            output::print(plan.to_text())
        };
    }
    let Some(port) = args.port.as_deref() else {
        return Err(usage(
            "robobus wck: --port PATH is required (e.g. --port /dev/ttyUSB0), unless --dry-run is given",
        ));
    };
    // Validated (and confirmed) before anything is opened.
    catalogue::validate(&request).map_err(|e| in_file(e, file))?;
    let request = report::confirm(request, g.yes)?;
    // A teach output file is created before the port is opened: an unwritable path fails
    // before any servo is touched.
    let mut teacher = match &args.command {
        WckCommand::Teach { output, .. } => {
            Some(teach::Teacher::new(&request, output.as_deref(), g.json)?)
        }
        _ => None,
    };
    let mut bus = station::open_wck_port(port, args.baud, args.capture.as_deref())?;
    if let Some(margin) = args.reply_margin {
        bus.config_mut().margin = margin;
    }
    let verify = match (args.verify_reads, args.no_verify_reads) {
        (true, _) => Some(true),
        (_, true) => Some(false),
        _ => None,
    };
    let mut station = Station::new();
    station.add_wck_port(WckPort::with_verify_reads(port, bus, verify));
    let report = match teacher.as_mut() {
        Some(t) => report::run_with(&station, &request, t),
        None => report::run(&station, &request),
    };
    station.leave();
    let report = report?;
    if g.json {
        return report::print(&report, true, &WCK_TABLE);
    }
    match &args.command {
        WckCommand::Scan { .. } => print_scan(&report),
        WckCommand::Play { .. } => print_play(&report),
        WckCommand::Teach { output, .. } => {
            teacher.map_or(Ok(()), |t| t.finish(&report, output.as_deref()))?;
            report::outcome(&report)
        }
        _ => report::print(&report, false, &WCK_TABLE),
    }
}

/// How wCK tables look: the ID column, degrees with one decimal.
const WCK_TABLE: report::Style = report::Style {
    id_header: "ID",
    decimals: 1,
};

/// `scan`: the servos found, each duplicate ID, a count.
fn print_scan(r: &Report) -> anyhow::Result<()> {
    let mut text = report::results_table(r, &WCK_TABLE);
    let none = Vec::new();
    let dups = r
        .summary
        .as_ref()
        .and_then(|s| s["duplicates"].as_array())
        .unwrap_or(&none);
    for d in dups {
        let _ = writeln!(
            text,
            "DUPLICATE  ID {} at {} bit/s: more than one module answers ({})",
            d["id"],
            d["baud"],
            d["evidence"].as_str().unwrap_or("")
        );
    }
    let _ = writeln!(
        text,
        "# {} servo(s) found, {} duplicate ID(s)",
        r.results.len(),
        dups.len()
    );
    output::print(&text)?;
    report::outcome(r)
}

/// `play`: one line of what was played.
fn print_play(r: &Report) -> anyhow::Result<()> {
    if let Some(s) = &r.summary {
        let last: Vec<String> = s["last_positions"]
            .as_array()
            .map(|a| a.iter().map(ToString::to_string).collect())
            .unwrap_or_default();
        output::print(&format!(
            "played {} synchronized moves in {} ms (planned {} ms; {} status reads watched \
             the servos); last pose: {}\n",
            s["moves"],
            s["duration_ms"],
            s["planned_ms"],
            s["watch_reads"],
            last.join(" ")
        ))?;
    }
    report::outcome(r)
}

fn ids(list: &ServoIds) -> Ids {
    Ids::List(list.as_slice().iter().map(|i| u32::from(i.get())).collect())
}

fn id(i: ServoId) -> u32 {
    u32::from(i.get())
}

const fn on_stop(o: OnStop) -> WckOnStop {
    match o {
        OnStop::Passive => WckOnStop::Passive,
        OnStop::Break => WckOnStop::Break,
        OnStop::Hold => WckOnStop::Hold,
    }
}

/// The catalogue request of a subcommand (its files read as text); the library
/// validates it again and plans it.
#[allow(clippy::too_many_lines)] // one arm per subcommand
fn request(args: &Args) -> anyhow::Result<Request> {
    use Request as Q;
    Ok(match &args.command {
        WckCommand::Scan {
            all_bauds,
            ids: list,
        } => Q::WckScan(cw::Scan {
            bus: None,
            ids: ids(list),
            all_bauds: *all_bauds,
        }),
        WckCommand::Status { ids: list } => Q::WckStatus(cw::Status {
            bus: None,
            ids: ids(list),
        }),
        WckCommand::Move {
            id: i,
            position,
            torque,
        } => Q::WckMove(cw::Move {
            bus: None,
            id: id(*i),
            position: u32::from(position.get()),
            torque: u32::from(torque.get()),
        }),
        WckCommand::Move10 {
            id: i,
            position,
            torque,
        } => Q::WckMove10(cw::Move10 {
            bus: None,
            id: u32::from(i.get()),
            position: u32::from(position.get()),
            torque: u32::from(torque.get()),
        }),
        WckCommand::Read10 { id: i } => Q::WckRead10(cw::Read10 {
            bus: None,
            id: u32::from(i.get()),
        }),
        WckCommand::SyncMove { positions, torque } => Q::WckSyncMove(cw::SyncMove {
            bus: None,
            positions: positions.iter().map(|p| u32::from(p.get())).collect(),
            torque: u32::from(torque.get()),
        }),
        WckCommand::Passive { ids: list } => Q::WckPassive(cw::Passive {
            bus: None,
            ids: ids(list),
        }),
        WckCommand::Wheel {
            id: i,
            direction,
            speed,
            duration,
            on_stop: o,
        } => Q::WckWheel(cw::Wheel {
            bus: None,
            id: id(*i),
            direction: match direction {
                Direction::Ccw => cw::Direction::Ccw,
                Direction::Cw => cw::Direction::Cw,
            },
            speed: u32::from(speed.get()),
            duration: duration.map(|d| d.as_secs_f64()),
            on_stop: on_stop(*o),
        }),
        WckCommand::Brake => Q::WckBrake(cw::Brake { bus: None }),
        WckCommand::Get(p) => {
            let (param, a) = match p {
                GetParam::Gains(a) => (cw::Param::Gains, a),
                GetParam::IGain(a) => (cw::Param::IGain, a),
                GetParam::Speed(a) => (cw::Param::Speed, a),
                GetParam::Overload(a) => (cw::Param::Overload, a),
                GetParam::Bounds(a) => (cw::Param::Bounds, a),
                GetParam::Io(a) => (cw::Param::Io, a),
            };
            Q::WckGet(cw::Get {
                bus: None,
                param,
                id: id(a.id),
            })
        }
        WckCommand::Set(p) => Q::WckSet(set_request(p)),
        WckCommand::SetId { id: i, new_id } => Q::WckSetId(cw::SetId {
            bus: None,
            id: id(*i),
            new_id: u32::from(new_id.get()),
            confirm: false,
        }),
        WckCommand::SetBaud { id: i, rate } => Q::WckSetBaud(cw::SetBaud {
            bus: None,
            id: id(*i),
            rate: rate.bits_per_second(),
            confirm: false,
        }),
        WckCommand::Program(ProgramCommand::Upload { id: i, file }) => {
            Q::WckProgramUpload(cw::ProgramUpload {
                bus: None,
                id: id(*i),
                program: read_bounded(file, PROGRAM_FILE_LIMIT)?,
                confirm: false,
            })
        }
        WckCommand::Program(ProgramCommand::Download { id: i }) => {
            Q::WckProgramDownload(cw::ProgramDownload {
                bus: None,
                id: id(*i),
            })
        }
        WckCommand::Program(ProgramCommand::Check { id: i, file }) => {
            Q::WckProgramCheck(cw::ProgramCheck {
                bus: None,
                id: id(*i),
                program: read_bounded(file, PROGRAM_FILE_LIMIT)?,
            })
        }
        WckCommand::Teach {
            ids: list,
            rate_hz,
            duration,
            pose_ms,
            torque,
            output: _,
            on_stop: o,
        } => Q::WckTeach(cw::Teach {
            bus: None,
            ids: ids(list),
            rate_hz: *rate_hz,
            duration: duration.map(|d| d.as_secs_f64()),
            pose_ms: *pose_ms,
            torque: u32::from(torque.get()),
            on_stop: on_stop(*o),
        }),
        WckCommand::Play {
            file,
            rate_hz,
            on_stop: o,
        } => Q::WckPlay(cw::Play {
            bus: None,
            motion: read_bounded(file, MOTION_FILE_LIMIT)?,
            rate_hz: *rate_hz,
            on_stop: on_stop(*o),
        }),
    })
}

fn set_request(p: &SetParam) -> cw::Set {
    let base = |param, id: ServoId| cw::Set {
        bus: None,
        param,
        id: u32::from(id.get()),
        p: None,
        d: None,
        i: None,
        speed: None,
        accel: None,
        milliamps: None,
        lower: None,
        upper: None,
        outputs: None,
        runtime: false,
        confirm: false,
    };
    match *p {
        SetParam::Gains { id, p, d, runtime } => cw::Set {
            p: Some(u32::from(p.get())),
            d: Some(u32::from(d.get())),
            runtime,
            ..base(cw::Param::Gains, id)
        },
        SetParam::IGain { id, i, runtime } => cw::Set {
            i: Some(u32::from(i.get())),
            runtime,
            ..base(cw::Param::IGain, id)
        },
        SetParam::Speed {
            id,
            speed,
            accel,
            runtime,
        } => cw::Set {
            speed: Some(u32::from(speed.get())),
            accel: Some(u32::from(accel.get())),
            runtime,
            ..base(cw::Param::Speed, id)
        },
        SetParam::Overload { id, milliamps } => cw::Set {
            milliamps: Some(u32::from(milliamps.milliamps())),
            ..base(cw::Param::Overload, id)
        },
        SetParam::Bounds { id, lower, upper } => cw::Set {
            lower: Some(u32::from(lower.get())),
            upper: Some(u32::from(upper.get())),
            ..base(cw::Param::Bounds, id)
        },
        SetParam::Io { id, outputs } => cw::Set {
            outputs: Some(u32::from(outputs.get())),
            ..base(cw::Param::Io, id)
        },
    }
}

/// `program check`: the library's check of the program (nothing is opened): the
/// instructions and the upload packet (`--json`: the report).
fn check_program(g: Global, file: &Path, request: &Request) -> anyhow::Result<()> {
    let report = catalogue::run(
        &Station::new(),
        request,
        &mut Control::new(&crate::interrupt::stop_token()),
    )
    .map_err(|e| in_file(e, Some(file)))?;
    if g.json {
        return output::print_json(&serde_json::to_value(&report)?);
    }
    let none = Value::Null;
    let s = report.summary.as_ref().unwrap_or(&none);
    let instructions = s["instructions"].as_array().map_or(&[][..], Vec::as_slice);
    let mut text = format!(
        "# {}: OK, {} instruction(s)\n",
        file.display(),
        instructions.len()
    );
    if instructions.is_empty() {
        text.push_str("# an empty program: uploading it switches the servo's program off\n");
    }
    for (n, i) in instructions.iter().enumerate() {
        let byte = |k: &str| i[k].as_u64().unwrap_or(0);
        let _ = writeln!(
            text,
            "# {:>2}  {:02X} {:02X}  {}",
            n + 1,
            byte("command"),
            byte("data"),
            i["text"].as_str().unwrap_or("")
        );
    }
    let packet = &s["upload_packet"];
    let _ = writeln!(
        text,
        "# upload packet for servo {}:\n{}",
        packet["id"],
        packet["hex"].as_str().unwrap_or("")
    );
    output::print(&text)
}
