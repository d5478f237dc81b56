//! `robobus whj`: drive WHJ joints on a CAN FD bus.
//!
//! Each subcommand is one catalogue request ([`robobus::catalogue`]) and takes that
//! request's fields as its arguments: the request types derive `clap::Args` (the library's
//! `cli` feature), so their names, help, defaults and value parsers (joint IDs 1..=30,
//! registers by name or address, motion values against the library's host bounds,
//! [`robobus::catalogue::bounds`]) are the request's own. The command adds what only it
//! has (--bus, --model, --on-stop, --capture; files named on the command line) and hands
//! the request to the library's dispatcher: `--dry-run` prints its plan as `cansend`
//! lines, a real run goes through [`crate::report`].

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::Context as _;

use clap::{Subcommand, ValueEnum};
use robobus::catalogue::args::WhjOnStop;
use robobus::catalogue::whj::cli as whj_cli;
use robobus::catalogue::{self, whj as cw};
use robobus::ops::whj as ops;
use robobus::station::{self, Station};
use robobus_link::FrameLinkSpec;
use robobus_whj::REGISTERS;

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

/// The subcommands: each takes its catalogue request's fields as its arguments
/// (`robobus::catalogue::whj`, the `cli` feature: names, help, parsers and defaults are the
/// request's). What only the command has (a file named on the command line) is a small
/// struct here. `bus`, `confirm`, `model` and `on_stop` are not a subcommand's arguments:
/// `--bus`, `--yes`, `--model` and `--on-stop` of `robobus whj` give them.
#[derive(Debug, Clone, Subcommand)]
enum WhjCommand {
    /// Find joints: read signature, ID, model and firmware of every ID (1..=30 unless
    /// --joints is given).
    Scan(cw::Scan),
    /// Identity, unique ID and position limits of a joint.
    Info(cw::Info),
    /// Status query (0x600+ID): position, speed, current, errors, enable state.
    Status(cw::Status),
    /// Enable the drive (register 0x0A := 1).
    Enable(cw::Enable),
    /// Disable the drive (register 0x0A := 0).
    Disable(cw::Disable),
    /// Set the work mode (register 0x30).
    Mode(cw::Mode),
    /// Move a joint to an angle in position mode, in steps no faster than --max-speed.
    Move(cw::Move),
    /// Speed servo target (0x300+ID) in output RPM, -37.5..=37.5.
    Speed(cw::Speed),
    /// Current servo target (0x400+ID) in mA, -30000..=30000.
    Current(cw::Current),
    /// Make the present position 0 degrees (register 0x0E := 1).
    Zero(cw::Zero),
    /// Clear latched errors (register 0x0F := 1).
    Clear(cw::Clear),
    /// Save the register table to flash (register 0x0C := 1; the joint must be disabled).
    Save(cw::Save),
    /// Read registers by name (`cur_position`, `SYS_TEMP`) or address (`0x14`, `20`).
    Read(cw::Read),
    /// Write a register by name or address, in its unit (degrees, RPM, mA, V, ...).
    Write(cw::Write),
    /// List the register table: address, name, unit, range, access, meaning.
    Registers(cw::Registers),
    /// The bus's CAN interface as the kernel reports it: the controller's state
    /// (error-active / -warning / -passive, bus-off), error counters, state changes and
    /// restarts, and what to do. Nothing is sent on the bus.
    CanHealth(cw::CanHealth),
    /// Back up every setting of a joint (the registers it keeps in flash: limits, gains,
    /// modes at power-up, ID and bit rates) to a JSON settings file, with its model and
    /// firmware.
    Backup(ToFile<cw::Backup>),
    /// Write the settings file of the values the vendor documents for a joint's model and
    /// firmware (modes at power-up, speed and acceleration limits, following error,
    /// feature switches), to restore with `whj restore`: the joints have no factory reset.
    /// The loop gains and the current and position limits are tuned per joint at the
    /// factory and not published: the file leaves them out, and a restore keeps them.
    Defaults(ToFile<cw::Defaults>),
    /// The end-effector board: its state, tool power, a digital channel's direction, its
    /// force sensor. Switching the tool power on or a channel's direction asks for
    /// confirmation (--yes): it switches what is attached to the tool.
    EndBoard(cw::EndBoard),
    /// List the settings on which a joint differs from a settings file, or from another
    /// joint (--with).
    ///
    /// Against a file, only the settings it holds count (a `whj defaults` file leaves out
    /// the gains, limits and bus identity); `left_out` says how many the file leaves out.
    Diff(Diff),
    /// Restore a settings file onto a joint: only the settings that differ are written,
    /// then saved to flash and read back. The joint must be disabled and be the file's
    /// model and firmware; its ID and bit rates are never written. Needs --yes.
    Restore(Restore),
    /// Give a joint a new ID (register 0x01, then save to flash; power-cycle afterwards).
    SetId(cw::SetId),
    /// Set joints' CAN FD bit rates (registers 0x08 / 0x09, read back, saved to flash).
    ///
    /// The joints must be disabled. They keep talking at the old rates until they are
    /// power-cycled, and from then on only at the new ones: set the adapter to them (the
    /// output says how), then `whj scan` finds them. Every joint on a bus must be at the
    /// bus's rates. Asks for confirmation (--yes).
    SetRates(cw::SetRates),
    /// Send a test signal (sine or square) as servo frames, like the vendor tool.
    Wave(cw::Wave),
    /// Start the application on joints waiting in the bootloader (`IAP_FLAG` 0x49 := 0).
    ReleaseIap(cw::ReleaseIap),
}

// The command-line shapes of the requests whose text the command reads from a file named
// on the command line (plain comments: a doc comment would be the subcommand's help).

// `whj backup` / `whj defaults`: the request, and the file its settings go to.
#[derive(Debug, Clone, clap::Args)]
struct ToFile<R: clap::Args> {
    #[command(flatten)]
    request: R,
    /// The settings file to write (an existing one is replaced).
    #[arg(short, long, value_name = "FILE.json")]
    output: PathBuf,
}

// `whj diff`: `settings` is read from FILE; `other` is --with.
#[derive(Debug, Clone, clap::Args)]
struct Diff {
    /// Joint ID, 1..=30.
    #[arg(value_parser = whj_cli::joint)]
    joint: u32,
    /// A settings file (from `whj backup`).
    #[arg(required_unless_present = "with")]
    file: Option<PathBuf>,
    /// Compare with this joint instead of a file.
    #[arg(long, value_name = "JOINT", value_parser = whj_cli::joint, conflicts_with = "file")]
    with: Option<u32>,
}

// `whj restore`: `settings` is read from FILE.
#[derive(Debug, Clone, clap::Args)]
struct Restore {
    /// Joint ID, 1..=30.
    #[arg(value_parser = whj_cli::joint)]
    joint: u32,
    /// The settings file (from `whj backup`).
    file: PathBuf,
}

/// Runs `robobus whj`: the subcommand's request goes to the library's dispatcher
/// (`--dry-run`: its plan).
pub(crate) fn run(g: Global, args: &Args) -> anyhow::Result<()> {
    if let Some(bus) = &args.bus {
        bus.parse::<FrameLinkSpec>()
            .map_err(|e| usage(format!("--bus: {e}")))?;
    }
    if matches!(args.command, WhjCommand::Registers(_)) {
        return list_registers(g);
    }
    let request = request(args)?;
    if let Some((output, _)) = settings_output(&args.command) {
        output::check_output_path(output, "--output")?;
    }
    if g.dry_run {
        return report::print_plan(g, &robobus::frontend::PlanView::of(&request)?);
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
    if let (Some((output, joint)), Some(doc)) = (settings_output(&args.command), &report.summary) {
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
            joint,
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

/// The settings file `whj backup` / `whj defaults` write, and the joint.
fn settings_output(command: &WhjCommand) -> Option<(&Path, u32)> {
    match command {
        WhjCommand::Backup(b) => Some((&b.output, b.request.joint)),
        WhjCommand::Defaults(d) => Some((&d.output, d.request.joint)),
        _ => None,
    }
}

/// How WHJ tables look: the `JOINT` column, four decimals.
const WHJ_TABLE: report::Style = report::Style {
    id_header: "joint",
    decimals: 4,
};

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

/// The catalogue request of a subcommand: its own request, with `robobus whj`'s
/// --model and --on-stop where the request takes them, or a file's text read.
fn request(args: &Args) -> anyhow::Result<catalogue::Request> {
    use catalogue::Request as Q;
    let on_stop = on_stop(args.on_stop);
    let model = args.model.map(model);
    Ok(match args.command.clone() {
        WhjCommand::Scan(r) => Q::WhjScan(r),
        WhjCommand::Info(r) => Q::WhjInfo(r),
        WhjCommand::Status(r) => Q::WhjStatus(r),
        WhjCommand::Enable(r) => Q::WhjEnable(r),
        WhjCommand::Disable(r) => Q::WhjDisable(r),
        WhjCommand::Mode(r) => Q::WhjMode(r),
        WhjCommand::Move(r) => Q::WhjMove(cw::Move { on_stop, ..r }),
        WhjCommand::Speed(r) => Q::WhjSpeed(cw::Speed { on_stop, ..r }),
        WhjCommand::Current(r) => Q::WhjCurrent(cw::Current {
            model,
            on_stop,
            ..r
        }),
        WhjCommand::Zero(r) => Q::WhjZero(r),
        WhjCommand::Clear(r) => Q::WhjClear(r),
        WhjCommand::Save(r) => Q::WhjSave(r),
        WhjCommand::Read(r) => Q::WhjRead(r),
        WhjCommand::Write(r) => Q::WhjWrite(cw::Write { model, ..r }),
        WhjCommand::Registers(r) => Q::WhjRegisters(r),
        WhjCommand::CanHealth(r) => Q::WhjCanHealth(r),
        WhjCommand::Backup(b) => Q::WhjBackup(b.request),
        WhjCommand::Defaults(d) => Q::WhjDefaults(d.request),
        WhjCommand::EndBoard(r) => Q::WhjEndBoard(r),
        WhjCommand::Diff(d) => Q::WhjDiff(cw::Diff {
            bus: None,
            joint: d.joint,
            settings: d.file.as_deref().map(settings_file).transpose()?,
            other: d.with,
        }),
        WhjCommand::Restore(r) => Q::WhjRestore(cw::Restore {
            bus: None,
            joint: r.joint,
            settings: settings_file(&r.file)?,
            confirm: false,
        }),
        WhjCommand::SetId(r) => Q::WhjSetId(r),
        WhjCommand::SetRates(r) => Q::WhjSetRates(r),
        WhjCommand::Wave(r) => Q::WhjWave(cw::Wave {
            model,
            on_stop,
            ..r
        }),
        WhjCommand::ReleaseIap(r) => Q::WhjReleaseIap(r),
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
    use std::collections::BTreeSet;

    use clap::Subcommand as _;

    use super::WhjCommand;

    /// Request fields that no subcommand takes as an argument: `robobus whj`'s own --bus,
    /// --model and --on-stop and the command's --yes give them.
    const FROM_THE_COMMAND: &[&str] = &["bus", "confirm", "model", "on_stop"];

    /// The subcommands whose arguments differ from their request's fields, and how: the
    /// command's own arguments, and the request fields it fills from them.
    const CLI_ONLY: &[(&str, &[&str], &[&str])] = &[
        // The settings file the report's summary is written to.
        ("backup", &["output"], &[]),
        ("defaults", &["output"], &[]),
        // `settings` is the text of FILE; `other` is --with.
        ("diff", &["file", "with"], &["settings", "other"]),
        ("restore", &["file"], &["settings"]),
        // The optional `preflight` field is --preflight and its negation --no-preflight.
        ("move", &["no_preflight"], &[]),
        ("wave", &["no_preflight"], &[]),
    ];

    fn request_fields(op: &str) -> BTreeSet<String> {
        let schema = robobus::catalogue::request_schema();
        let entry = schema["oneOf"]
            .as_array()
            .unwrap()
            .iter()
            .find(|e| e["properties"]["op"]["const"] == op)
            .unwrap_or_else(|| panic!("{op} is not in the request schema"));
        entry["properties"]
            .as_object()
            .unwrap()
            .keys()
            .filter(|k| *k != "op" && !FROM_THE_COMMAND.contains(&k.as_str()))
            .cloned()
            .collect()
    }

    #[test]
    fn every_subcommand_takes_exactly_its_requests_fields_as_arguments() {
        let whj = WhjCommand::augment_subcommands(clap::Command::new("whj"));
        let mut seen = 0;
        for sub in whj.get_subcommands() {
            let name = sub.get_name();
            let args: BTreeSet<String> = sub
                .get_arguments()
                .map(|a| a.get_id().as_str().to_owned())
                .collect();
            let mut want = request_fields(&format!("whj.{name}"));
            if let Some((_, own, filled)) = CLI_ONLY.iter().find(|(n, ..)| *n == name) {
                for f in *filled {
                    assert!(want.remove(*f), "whj.{name} has no field {f}");
                }
                want.extend(own.iter().map(|s| (*s).to_owned()));
            }
            assert_eq!(args, want, "robobus whj {name}");
            seen += 1;
        }
        assert_eq!(seen, 25);
    }
}
