//! `robobus wck`: drive wCK servos on a serial (UART) bus.
//!
//! Every subcommand maps onto the commands of the wCK manual's appendix A-1
//! ([`robobus_wck::Command`]). A subcommand's arguments are its catalogue request
//! ([`robobus::catalogue::wck`], `clap::Args` with the library's `cli` feature), whose
//! value parsers check each range, so an out-of-range value is refused (exit code 2, the
//! message names the value, the range and the argument) before anything is opened; the
//! command adds only the files it names (read into the request's text) and `get` / `set`'s
//! parameter subcommands. The library validates and plans the request: `--dry-run` prints
//! the plan, otherwise [`crate::report`] runs it on a station holding the one port.

use std::fmt::Write as _;
use std::path::Path;

use robobus::catalogue::{self, Report, Request, wck as cw};
use robobus::ops::wck::MOTION_FILE_LIMIT;
use robobus::ops::{Control, OpError, read_bounded};
use robobus::station::{self, Station, WckPort};
use robobus_wck::ServoId;
use serde_json::Value;

use crate::Global;
use crate::exit::usage;
use crate::{output, report};

mod args;
mod teach;

pub(crate) use args::{Args, parse_baud, parse_margin, parse_port};
use args::{GetParam, ProgramCommand, SetParam, WckCommand};

/// `wck tune` as text: the table of responses and the best set, or the tie; the traces
/// are in `--json`.
fn print_tune(mut report: Report) -> anyhow::Result<()> {
    if let Some(Value::Object(s)) = &mut report.summary {
        let set = |s: &serde_json::Map<String, Value>, i: u64| {
            s.get("responses")
                .and_then(|r| r.get(usize::try_from(i).ok()?))
                .map(|r| format!("P {} D {} (row {})", r["p"], r["d"], i + 1))
        };
        if let Some(text) = s
            .get("best")
            .and_then(Value::as_u64)
            .and_then(|b| set(s, b))
        {
            s.insert("best".into(), Value::String(text));
        } else {
            let tied: Vec<String> = s
                .get("tied")
                .and_then(Value::as_array)
                .into_iter()
                .flatten()
                .filter_map(Value::as_u64)
                .filter_map(|i| set(s, i))
                .collect();
            s.insert(
                "best".into(),
                Value::String(format!(
                    "none: a tie of {} (the responses differ by no more than a reading)",
                    tied.join(", ")
                )),
            );
        }
        s.remove("tied");
        s.remove("responses");
    }
    report::print(&report, false, &WCK_TABLE)
}

/// A settings file's text, read bounded.
fn settings_file(path: &Path) -> anyhow::Result<String> {
    Ok(read_bounded(
        path,
        robobus::ops::wck::settings::WCK_SETTINGS_FILE_LIMIT,
    )?)
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
        WckCommand::Play(args::Play { file, .. })
        | WckCommand::Program(
            ProgramCommand::Upload(args::ProgramUpload { file, .. })
            | ProgramCommand::Check(args::ProgramCheck { file, .. }),
        ) => Some(file),
        _ => None,
    }
}

/// Runs `robobus wck`: the subcommand's request, planned (`--dry-run` prints the plan)
/// or confirmed and run on the port, its report printed.
pub(crate) fn run(g: Global, args: &Args) -> anyhow::Result<()> {
    let file = input_file(&args.command);
    let request = request(args)?;
    if let WckCommand::Program(ProgramCommand::Check(args::ProgramCheck { file, .. })) =
        &args.command
    {
        return check_program(g, file, &request);
    }
    if let WckCommand::Backup(args::Backup { output, .. }) = &args.command {
        output::check_output_path(output, "--output")?;
    }
    if g.dry_run {
        let view =
            robobus::frontend::PlanView::at(&request, args.baud).map_err(|e| in_file(e, file))?;
        return report::print_plan(g, &view);
    }
    let Some(port) = args.port.as_deref() else {
        return Err(usage(
            "robobus wck: --port PORT is required (e.g. --port /dev/ttyUSB0, --port COM3 or \
             --port socket://127.0.0.1:5600), unless --dry-run is given",
        ));
    };
    // Validated (and confirmed) before anything is opened.
    catalogue::validate(&request).map_err(|e| in_file(e, file))?;
    let request = report::confirm(request, g.yes)?;
    // A teach output file is created before the port is opened: an unwritable path fails
    // before any servo is touched.
    let mut teacher = match &args.command {
        WckCommand::Teach(args::Teach { output, .. }) => {
            Some(teach::Teacher::new(&request, output.as_deref(), g.json)?)
        }
        _ => None,
    };
    let mut bus = station::open_wck_port(port, args.baud, args.capture.as_deref())?;
    if let Some(margin) = args.reply_margin {
        bus.config_mut().margin = margin;
    }
    bus.config_mut().wait = g.wait;
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
    if let (WckCommand::Backup(args::Backup { output, request }), Some(doc)) =
        (&args.command, &report.summary)
    {
        let text = serde_json::to_string_pretty(doc)? + "\n";
        std::fs::write(output, text)
            .map_err(|e| anyhow::anyhow!("cannot write {}: {e}", output.display()))?;
        eprintln!(
            "robobus: the settings of servo {} written to {}",
            request.id,
            output.display()
        );
    }
    if g.json {
        return report::print(&report, true, &WCK_TABLE);
    }
    match &args.command {
        WckCommand::Scan(_) => print_scan(&report),
        WckCommand::Play(_) => print_play(&report),
        WckCommand::Tune(_) => print_tune(report),
        WckCommand::Teach(args::Teach { output, .. }) => {
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

fn id(i: ServoId) -> u32 {
    u32::from(i.get())
}

/// The catalogue request of a subcommand: the request its arguments are, with the files
/// the command names read into its text fields; the library validates it and plans it.
fn request(args: &Args) -> anyhow::Result<Request> {
    use Request as Q;
    let settings =
        |file: &Option<std::path::PathBuf>| file.as_deref().map(settings_file).transpose();
    Ok(match &args.command {
        WckCommand::Scan(r) => Q::WckScan(r.clone()),
        WckCommand::Status(r) => Q::WckStatus(r.clone()),
        WckCommand::Move(r) => Q::WckMove(r.clone()),
        WckCommand::Move10(r) => Q::WckMove10(r.clone()),
        WckCommand::Read10(r) => Q::WckRead10(r.clone()),
        WckCommand::SyncMove(r) => Q::WckSyncMove(r.clone()),
        WckCommand::Passive(r) => Q::WckPassive(r.clone()),
        WckCommand::Wheel(r) => Q::WckWheel(r.clone()),
        WckCommand::Brake(r) => Q::WckBrake(r.clone()),
        WckCommand::Get(p) => Q::WckGet(get_request(p)),
        WckCommand::Set(p) => Q::WckSet(set_request(p)),
        WckCommand::Tune(r) => Q::WckTune(r.clone()),
        WckCommand::Backup(a) => Q::WckBackup(a.request.clone()),
        WckCommand::Diff(a) => Q::WckDiff(cw::Diff {
            settings: settings(&a.file)?,
            ..a.request.clone()
        }),
        WckCommand::Restore(a) => Q::WckRestore(cw::Restore {
            settings: settings(&a.file)?,
            ..a.request.clone()
        }),
        WckCommand::SetId(r) => Q::WckSetId(r.clone()),
        WckCommand::SetBaud(r) => Q::WckSetBaud(r.clone()),
        WckCommand::Program(ProgramCommand::Upload(a)) => Q::WckProgramUpload(cw::ProgramUpload {
            program: read_bounded(&a.file, PROGRAM_FILE_LIMIT)?,
            ..a.request.clone()
        }),
        WckCommand::Program(ProgramCommand::Download(r)) => Q::WckProgramDownload(r.clone()),
        WckCommand::Program(ProgramCommand::Check(a)) => Q::WckProgramCheck(cw::ProgramCheck {
            program: read_bounded(&a.file, PROGRAM_FILE_LIMIT)?,
            ..a.request.clone()
        }),
        WckCommand::Teach(a) => Q::WckTeach(a.request.clone()),
        WckCommand::Play(a) => Q::WckPlay(cw::Play {
            motion: read_bounded(&a.file, MOTION_FILE_LIMIT)?,
            ..a.request.clone()
        }),
    })
}

fn get_request(p: &GetParam) -> cw::Get {
    let (param, a) = match p {
        GetParam::Gains(a) => (cw::Param::Gains, a),
        GetParam::IGain(a) => (cw::Param::IGain, a),
        GetParam::Speed(a) => (cw::Param::Speed, a),
        GetParam::Overload(a) => (cw::Param::Overload, a),
        GetParam::Bounds(a) => (cw::Param::Bounds, a),
        GetParam::Io(a) => (cw::Param::Io, a),
    };
    cw::Get {
        bus: None,
        param,
        id: id(a.id),
    }
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
