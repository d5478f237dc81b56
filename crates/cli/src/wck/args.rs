//! The arguments of `robobus wck`: its options, its subcommands (each the catalogue request
//! it runs, or a small struct holding the request and the file it names), and the value
//! parsers of `get` / `set`'s parameter subcommands, which turn text into the protocol
//! crate's range-checked newtypes (an out-of-range value is refused with exit code 2,
//! naming the value, the range and the argument).

use std::path::PathBuf;

use clap::Subcommand;
use robobus::catalogue::wck as cw;
use robobus::ops::wck::FORMAT_HELP;
use robobus_wck::{
    Accel, BaudRate, DGain, IGain, IoBits, Overload, PGain, Position, RangeError, ServoId, Speed,
};

pub(super) const AFTER_HELP: &str = "\
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
    /// Port of the wCK bus: a serial device (/dev/ttyUSB0, /dev/cu.usbserial-A1), a
    /// Windows port (COM3, COM12), or what `robobus sim wck` printed (a pty path, or
    /// `socket://127.0.0.1:5600` with --listen). Required unless --dry-run is given or the
    /// subcommand needs no device.
    #[arg(long, value_name = "PORT", value_parser = parse_port::<String>, global = true)]
    pub(super) port: Option<String>,
    /// Baud rate the servos are set to: 4800, 9600, 38400, 57600, 115200, 230400, 460800 or
    /// 921600.
    #[arg(long, default_value = "115200", value_parser = parse_baud, global = true)]
    pub(super) baud: BaudRate,
    /// Extra time to wait for each reply beyond its modelled wire time and turnaround, in
    /// ms (default 10, plus a USB adapter's latency timer when it can be read, or 50 on
    /// a pseudo-terminal or over TCP: a simulator in another process). Raise it for a
    /// simulator on a heavily loaded machine.
    #[arg(long, value_name = "MS", value_parser = parse_margin, global = true)]
    pub(super) reply_margin: Option<core::time::Duration>,
    /// Accept a read only when two replies in a row agree (wCK replies carry no checksum,
    /// so line noise can look like a value). On by default for `get` (gains, speed,
    /// over-load, bounds, I/O); this turns it on for every read (status, scan excepted).
    /// Costs one more exchange per read (about 1.5 ms at 115200 bit/s).
    #[arg(long, global = true, conflicts_with = "no_verify_reads")]
    pub(super) verify_reads: bool,
    /// Accept a `get` read from a single reply (faster, but noise may pass as a value).
    #[arg(long, global = true)]
    pub(super) no_verify_reads: bool,
    /// Record every byte written to and read from the port to FILE, a timestamped hex log
    /// (`<seconds> > FF 03 7F 7C`, `<` for bytes read); `robobus replay FILE` decodes it.
    /// An existing FILE is not overwritten.
    #[arg(long, value_name = "FILE", global = true)]
    pub(super) capture: Option<PathBuf>,
    /// What to do.
    #[command(subcommand)]
    pub(super) command: WckCommand,
}

/// The subcommands of `robobus wck`. Each takes its arguments from its catalogue request
/// ([`robobus::catalogue::wck`], whose field docs are the help, with the `cli` feature);
/// what only the command has (a file named on the command line, the `get` / `set`
/// parameter subcommands) is in the small structs below.
#[derive(Debug, Subcommand)]
pub(super) enum WckCommand {
    /// Find servos: read the status of every ID (0..=30 unless --ids is given).
    ///
    /// Prints the servos found (ID, baud rate, load, position); IDs answered by more than
    /// one module are flagged as duplicates. On a terminal a progress bar shows on stderr.
    /// Exit code 3 if no servo answers.
    Scan(cw::Scan),
    /// Read load and position of servos (A-1 (3) status read).
    Status(cw::Status),
    /// Move one servo to a position (A-1 (1) position move); replies load and position
    Move(cw::Move),
    /// Move one servo to a 10-bit position (A-1 (26)).
    Move10(cw::Move10),
    /// Read the 10-bit position of a servo (A-1 (27)).
    Read10(cw::Read10),
    /// Move servos 0..N-1 at once (A-1 (2) synchronized move, no reply).
    SyncMove(cw::SyncMove),
    /// Release the torque of servos (A-1 (4) passive); replies the position.
    Passive(cw::Passive),
    /// Turn a servo continuously (A-1 (5) wheel mode).
    Wheel(cw::Wheel),
    /// Put every servo on the bus into break mode (A-1 (6)).
    Brake(cw::Brake),
    /// Read a parameter of a servo.
    #[command(subcommand)]
    Get(GetParam),
    /// Write a parameter of a servo.
    #[command(subcommand)]
    Set(SetParam),
    /// Tune the P and D gains: the same position step with each gain set (as runtime
    /// gains), its rise time, overshoot, settling time and steady-state error measured,
    /// the best one named (or a tie when they differ by no more than a reading); each step
    /// starts at rest at the start, and the servo is back there when it ends. --keep keeps
    /// the best set.
    Tune(cw::Tune),
    /// Back up a servo's settings (gains, I gain, speed, over-load, boundaries) to a
    /// JSON settings file.
    Backup(Backup),
    /// List the settings on which a servo differs from a settings file, the factory
    /// settings (--factory) or another servo (--with).
    Diff(Diff),
    /// Restore a settings file (or, with --factory, the manual's factory settings, A-5)
    /// into a servo's EEPROM: only the groups that differ are written, each verified.
    /// Needs --yes.
    Restore(Restore),
    /// Give a servo a new ID (A-1 (14), EEPROM). IDs above 30 are reachable only with
    /// move10 / read10.
    SetId(cw::SetId),
    /// Set a servo's baud rate (A-1 (7), EEPROM); reach it afterwards with --baud RATE.
    SetBaud(cw::SetBaud),
    /// Self-running motion programs (manual section 3-11).
    #[command(subcommand)]
    Program(ProgramCommand),
    /// Record poses by hand: servos go passive, their positions are recorded as poses.
    ///
    /// Move the servos by hand; each Enter records a pose (q + Enter or Ctrl-D finishes).
    /// With --rate-hz / --duration poses are recorded at a rate instead (for --duration,
    /// or until Enter). Writes a keyframe motion file that `play` plays.
    Teach(Teach),
    /// Play a keyframe motion file: poses with transition times, interpolated and sent as
    /// synchronized moves.
    #[command(after_help = FORMAT_HELP)]
    Play(Play),
}

// What only the command has: the files it reads into a request's text field or writes
// a report to. Each holds its request (flattened) and the file.

#[derive(Debug, clap::Args)]
#[group(skip)]
pub(super) struct Backup {
    #[command(flatten)]
    pub(super) request: cw::Backup,
    /// The settings file to write (an existing one is replaced).
    #[arg(short, long, value_name = "FILE.json")]
    pub(super) output: PathBuf,
}

#[derive(Debug, clap::Args)]
#[group(skip)]
pub(super) struct Diff {
    #[command(flatten)]
    pub(super) request: cw::Diff,
    /// A settings file (from `wck backup`).
    #[arg(required_unless_present_any = ["factory", "other"], conflicts_with_all = ["factory", "other"])]
    pub(super) file: Option<PathBuf>,
}

#[derive(Debug, clap::Args)]
#[group(skip)]
pub(super) struct Restore {
    #[command(flatten)]
    pub(super) request: cw::Restore,
    /// A settings file (from `wck backup`).
    #[arg(required_unless_present = "factory", conflicts_with = "factory")]
    pub(super) file: Option<PathBuf>,
}

#[derive(Debug, clap::Args)]
#[group(skip)]
pub(super) struct Teach {
    #[command(flatten)]
    pub(super) request: cw::Teach,
    /// Write the poses as a keyframe motion file (see `robobus wck play --help`);
    /// without it the file is printed on stdout.
    #[arg(short, long, value_name = "FILE")]
    pub(super) output: Option<PathBuf>,
}

#[derive(Debug, clap::Args)]
#[group(skip)]
pub(super) struct Play {
    /// The keyframe motion file.
    pub(super) file: PathBuf,
    #[command(flatten)]
    pub(super) request: cw::Play,
}

#[derive(Debug, clap::Args)]
#[group(skip)]
pub(super) struct ProgramUpload {
    #[command(flatten)]
    pub(super) request: cw::ProgramUpload,
    /// The program, in the text form (see `robobus wck program check --help`).
    pub(super) file: PathBuf,
}

#[derive(Debug, clap::Args)]
#[group(skip)]
pub(super) struct ProgramCheck {
    /// The program, in the text form.
    pub(super) file: PathBuf,
    #[command(flatten)]
    pub(super) request: cw::ProgramCheck,
}

#[derive(Debug, Subcommand)]
pub(super) enum GetParam {
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
pub(super) struct IdArg {
    /// Servo ID, 0..=30.
    #[arg(value_parser = parse_servo_id)]
    pub(super) id: ServoId,
}

#[derive(Debug, Subcommand)]
pub(super) enum SetParam {
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
pub(super) enum ProgramCommand {
    /// Store a motion program (text form) in a servo (A-1 (24), EEPROM).
    #[command(after_help = PROGRAM_HELP)]
    Upload(ProgramUpload),
    /// Read how many instructions a servo's program has (A-1 (25)).
    Download(cw::ProgramDownload),
    /// Check a program file without a device: report errors with line:column, print the
    /// encoded bytes.
    #[command(after_help = PROGRAM_HELP)]
    Check(ProgramCheck),
}

pub(super) const PROGRAM_HELP: &str = "\
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

use robobus::catalogue::wck::cli::parse_u32;
use robobus::catalogue::wck::cli::ranged;

fn parse_position(s: &str) -> Result<Position, String> {
    ranged(s, Position::new)
}
fn parse_servo_id(s: &str) -> Result<ServoId, String> {
    ranged(s, ServoId::new)
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

/// Checks a `--port` value ([`robobus_link::PortSpec`]: a device path, `COMn`,
/// `socket://HOST:PORT`) and keeps it as given; a bad one names the value and the forms.
pub(crate) fn parse_port<T: for<'a> From<&'a str>>(s: &str) -> Result<T, String> {
    s.parse::<robobus_link::PortSpec>()
        .map(|_| T::from(s))
        .map_err(|e| format!("{e}; a port is {}", robobus_link::port::PORT_SYNTAX))
}

/// Parses a baud rate in bit/s.
pub(crate) fn parse_baud(s: &str) -> Result<BaudRate, String> {
    let v = parse_u32(s)?;
    BaudRate::from_bits_per_second(v).map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeSet;

    use clap::Args as _;
    use robobus::catalogue::registry::root_schema;
    use robobus::catalogue::{self, Family, wck as cw};

    /// A subcommand (its path under `wck`) and its request's schema.
    fn subcommands() -> Vec<(&'static str, serde_json::Value)> {
        vec![
            ("scan", root_schema::<cw::Scan>()),
            ("status", root_schema::<cw::Status>()),
            ("move", root_schema::<cw::Move>()),
            ("move10", root_schema::<cw::Move10>()),
            ("read10", root_schema::<cw::Read10>()),
            ("sync-move", root_schema::<cw::SyncMove>()),
            ("passive", root_schema::<cw::Passive>()),
            ("wheel", root_schema::<cw::Wheel>()),
            ("brake", root_schema::<cw::Brake>()),
            ("get", root_schema::<cw::Get>()),
            ("set", root_schema::<cw::Set>()),
            ("tune", root_schema::<cw::Tune>()),
            ("backup", root_schema::<cw::Backup>()),
            ("diff", root_schema::<cw::Diff>()),
            ("restore", root_schema::<cw::Restore>()),
            ("set-id", root_schema::<cw::SetId>()),
            ("set-baud", root_schema::<cw::SetBaud>()),
            ("program upload", root_schema::<cw::ProgramUpload>()),
            ("program download", root_schema::<cw::ProgramDownload>()),
            ("program check", root_schema::<cw::ProgramCheck>()),
            ("teach", root_schema::<cw::Teach>()),
            ("play", root_schema::<cw::Play>()),
        ]
    }

    /// Where the command and its request differ, on purpose: (subcommand, the command's
    /// own arguments, the request fields the command fills itself). A file named on the
    /// command line is read into a text field; `get` / `set` name the parameter as a
    /// subcommand; diff's other servo is `--with`.
    const CLI_ONLY: &[(&str, &[&str], &[&str])] = &[
        ("get", &[], &["param"]),
        ("set", &[], &["param"]),
        ("backup", &["output"], &[]),
        ("diff", &["file", "with"], &["settings", "other"]),
        ("restore", &["file"], &["settings"]),
        ("program upload", &["file"], &["program"]),
        ("program check", &["file"], &["program"]),
        ("teach", &["output"], &[]),
        ("play", &["file"], &["motion"]),
    ];

    /// The long options and positionals of a subcommand (and of its own subcommands,
    /// `get gains`, ...), `-` written `_`, without `--help`.
    fn arguments(cmd: &clap::Command) -> BTreeSet<String> {
        let mut names: BTreeSet<String> = cmd
            .get_arguments()
            .filter(|a| !a.is_global_set())
            .map(|a| {
                a.get_long()
                    .map_or_else(|| a.get_id().to_string(), str::to_owned)
                    .replace('-', "_")
            })
            .filter(|n| n != "help")
            .collect();
        for sub in cmd.get_subcommands() {
            names.extend(arguments(sub));
        }
        names
    }

    #[test]
    fn every_request_field_is_an_argument_of_its_subcommand_without_a_cli_edit() {
        let wck = super::Args::augment_args(clap::Command::new("wck"));
        let covered: BTreeSet<String> = subcommands()
            .iter()
            .map(|(path, _)| format!("wck.{}", path.replace(' ', ".")))
            .collect();
        // Every wCK operation is a subcommand, except the monitor's sample.
        for info in catalogue::operations() {
            if info.family == Family::Wck && info.op != "wck.sample" {
                assert!(covered.contains(info.op), "{} has no subcommand", info.op);
            }
        }
        for (path, schema) in subcommands() {
            let cmd = path.split(' ').fold(&wck, |c, name| {
                c.find_subcommand(name)
                    .unwrap_or_else(|| panic!("no subcommand {path}"))
            });
            let (cli, request) = CLI_ONLY
                .iter()
                .find(|(p, _, _)| *p == path)
                .map_or((&[][..], &[][..]), |(_, c, r)| (*c, *r));
            let mut expected: BTreeSet<String> = schema["properties"]
                .as_object()
                .unwrap_or_else(|| panic!("{path}: no properties"))
                .keys()
                .filter(|k| *k != "bus" && *k != "confirm" && !request.contains(&k.as_str()))
                .cloned()
                .collect();
            expected.extend(cli.iter().map(|s| (*s).to_owned()));
            assert_eq!(arguments(cmd), expected, "robobus wck {path}");
        }
    }
}
