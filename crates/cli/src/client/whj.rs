//! Running a `robobus whj` command: a thin shell over [`robobus::ops::whj`].
//!
//! [`execute`] opens the bus named by `--bus` ([`FrameLinkSpec`]), calls the operation of
//! the command ([`WhjRun`]) and renders its typed report: a table (one row per joint or
//! register, columns named like the JSON fields) or, with `--json`, one object
//! `{"bus", "command", "results": [...]}` (`wave` adds `"stats"`); the field names are the
//! reports' (see [`robobus::ops::whj`]), with each joint's ID under `joint`. A progress bar
//! is drawn on a terminal for long operations.
//!
//! # Errors and exit codes
//!
//! The exit code follows the library error's kind ([`crate::exit::Exit::of_kind`]). For a
//! command on many joints, every joint is reported (a failed one with `kind` and `error`)
//! and the worst failure decides the exit code afterwards: 3 when a joint was silent.
//! Ctrl-C / SIGTERM sets the one stop token ([`crate::interrupt`]); the operation brings
//! the joint to the `--on-stop` state and returns `Interrupted` (exit code 130).

use std::fmt::Write as _;
use std::io::IsTerminal as _;
use std::path::Path;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use robobus::ops::capture::{Overwrite, capture_frame_link};
use robobus::ops::whj::{self as ops, MoveArgs, TargetArgs, WaveArgs};
use robobus::ops::{Control, DeviceResult, Progress, SafeState, worst_kind};
use robobus::whj::{JointBus, JointBusConfig, WhjError};
use robobus_link::{FrameLink, FrameLinkSpec};
use robobus_whj::units::CurrentScale;
use robobus_whj::{JointId, RegisterAddr, WorkMode};
use serde::Serialize;
use serde_json::{Map, Value, json};

use crate::exit::Timeout;
use crate::output;

/// What brings a joint to a safe state when `move` or `wave` is interrupted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub(crate) enum OnStop {
    // Plain comments: doc comments would become clap's per-value help and switch every
    // `robobus whj` help page to the long layout; `--on-stop`'s own help explains them.
    // Stay enabled and hold the present position (speed / current waves: target 0).
    #[default]
    Hold,
    // Disable the drive.
    Disable,
}

impl OnStop {
    /// The library's safe state.
    pub(crate) const fn safe_state(self) -> SafeState {
        match self {
            Self::Hold => SafeState::Hold,
            Self::Disable => SafeState::Disable,
        }
    }
}

/// How a `robobus whj` command runs on the bus: the operation and its typed arguments.
#[derive(Debug, Clone)]
pub(crate) enum WhjRun {
    /// Find joints among these IDs.
    Scan(Vec<JointId>),
    /// Identity, limits, status of one joint.
    Info(JointId),
    /// Status of joints.
    Status(Vec<JointId>),
    /// Status of joints 1..=7 by one broadcast frame (`true`: and of the end board).
    BroadcastStatus(Vec<JointId>, bool),
    /// Enable (`true`) or disable drives.
    Enable(Vec<JointId>, bool),
    /// Set the work mode.
    Mode(Vec<JointId>, WorkMode),
    /// Smooth move to an angle.
    Move(MoveArgs),
    /// A speed or current target.
    Target(TargetArgs),
    /// Set zero.
    Zero(JointId),
    /// Clear errors.
    Clear(Vec<JointId>),
    /// Save to flash.
    Save(Vec<JointId>),
    /// Read registers.
    Read {
        /// The joint (one without a broadcast).
        joints: Vec<JointId>,
        /// First register.
        addr: RegisterAddr,
        /// Registers to read; `None` = the register (or pair) by name.
        count: Option<u8>,
        /// By one broadcast frame.
        broadcast: bool,
        /// With `broadcast`: the end board's register too.
        end_board: Option<u8>,
    },
    /// Write a register and read it back.
    Write {
        /// The joint (one without a broadcast).
        joints: Vec<JointId>,
        /// The register.
        addr: RegisterAddr,
        /// The value (unit of the register, or counts with `raw`).
        value: f64,
        /// The value is in counts.
        raw: bool,
        /// `--model`'s current scale, if given.
        scale: Option<CurrentScale>,
        /// By one broadcast frame (and its read-back).
        broadcast: bool,
        /// With `broadcast`: the end board's write too.
        end_board: Option<ops::EndBoardArg>,
    },
    /// New ID, saved to flash.
    SetId(JointId, JointId),
    /// A test signal (`true`: as broadcast frames).
    Wave(WaveArgs, bool),
    /// Start the application of joints in the bootloader.
    ReleaseIap(Vec<JointId>),
}

/// Everything [`execute`] needs.
#[derive(Debug)]
pub(crate) struct WhjJob<'a> {
    /// The subcommand, for messages.
    pub(crate) action: &'static str,
    /// The bus as given.
    pub(crate) bus: &'a str,
    /// `--capture FILE`.
    pub(crate) capture: Option<&'a Path>,
    /// What to do.
    pub(crate) run: &'a WhjRun,
    /// Safe state after Ctrl-C.
    pub(crate) on_stop: OnStop,
    /// `--json`.
    pub(crate) json: bool,
    /// The user confirmed (`--yes` or the prompt).
    pub(crate) confirmed: bool,
}

/// Opens the link of a `--bus` value; an interface that cannot be opened is "no device"
/// (exit code 3), like a serial port that is not there. With `capture` every frame sent
/// and received is logged there as a candump log (`--capture FILE`; an existing file is
/// refused before anything is sent).
pub(crate) fn open_link(
    bus: &str,
    capture: Option<&Path>,
) -> anyhow::Result<Box<dyn FrameLink + Send>> {
    let spec: FrameLinkSpec = bus
        .parse()
        .map_err(|e| crate::exit::usage(format!("--bus: {e}")))?;
    // Its exit code is the error's kind (`robobus::error::open_error_kind`).
    let link = spec.open()?;
    let Some(path) = capture else {
        return Ok(link);
    };
    Ok(Box::new(capture_frame_link(
        link,
        path,
        spec.candump_iface(),
        Overwrite::No,
    )?))
}

/// One table row / JSON object: field names and values.
type Row = Map<String, Value>;

/// A report as a row, with the joint's ID first (`joint`; a broadcast's end board:
/// `"end-board"`).
fn row(joint: impl Serialize, report: &impl Serialize) -> Row {
    let mut r = Row::new();
    r.insert("joint".into(), json!(joint));
    if let Ok(Value::Object(fields)) = serde_json::to_value(report) {
        for (k, v) in fields {
            r.insert(k, v);
        }
    }
    r
}

/// Per-joint results as rows (`id` becomes `joint`); the worst failure, for the exit code.
fn rows_of<I: Serialize, T: Serialize>(
    results: &[DeviceResult<I, T>],
) -> (Vec<Row>, anyhow::Result<()>) {
    let rows = results
        .iter()
        .map(|r| match (r.value(), r.failure()) {
            (Some(v), _) => row(&r.id, v),
            (None, Some(f)) => row(&r.id, f),
            (None, None) => row(&r.id, &()),
        })
        .collect();
    let outcome = match worst_kind(results) {
        None => Ok(()),
        Some(kind) => {
            let failed: Vec<String> = results
                .iter()
                .filter_map(|r| r.failure().map(|f| f.error.clone()))
                .collect();
            Err(kind_error(kind, failed.join("; ")))
        }
    };
    (rows, outcome)
}

/// An error with the exit code of `kind` ([`crate::exit::Exit::of_kind`]).
fn kind_error(kind: robobus::ErrorKind, message: String) -> anyhow::Error {
    use robobus::ErrorKind as K;
    match kind {
        K::NoDevice => anyhow::Error::new(Timeout(message)),
        K::Interrupted => anyhow::Error::new(crate::exit::Interrupted).context(message),
        K::BadInput | K::Refused => crate::exit::usage(message),
        _ => anyhow::Error::new(robobus::ops::OpError::Device(message)),
    }
}

/// Runs a `robobus whj` command on the bus.
pub(crate) fn execute(job: &WhjJob<'_>) -> anyhow::Result<()> {
    let link = open_link(job.bus, job.capture)?;
    let connect_timeout = match job.run {
        // A joint in its bootloader answers the IAP release at once; a scan must not wait
        // seconds for every absent ID.
        WhjRun::Scan(_) => std::time::Duration::from_millis(150),
        // As the library's default: joints with a staggered power-up stay silent for a
        // few seconds (the help says so).
        _ => JointBusConfig::default().connect_timeout,
    };
    let bus = JointBus::open_with(
        link,
        JointBusConfig {
            connect_timeout,
            ..JointBusConfig::default()
        },
    )?;
    let mut stats = None;
    let (rows, outcome) = run(&bus, job, &mut stats)?;
    if job.json {
        let mut doc = json!({
            "bus": job.bus,
            "command": job.action,
            "results": rows,
        });
        if let (Some(s), Some(obj)) = (stats, doc.as_object_mut()) {
            obj.insert("stats".into(), s);
        }
        output::print_json(&doc)?;
    } else {
        let mut text = table(&rows);
        if let Some(Value::Object(s)) = stats {
            for (k, v) in s {
                let _ = writeln!(text, "{k}: {}", cell(&v));
            }
        }
        output::print(&text)?;
    }
    outcome
}

type Ran = (Vec<Row>, anyhow::Result<()>);

fn one(joint: JointId, report: &impl Serialize) -> Ran {
    (vec![row(joint.get(), report)], Ok(()))
}

fn run(bus: &JointBus, job: &WhjJob<'_>, stats: &mut Option<Value>) -> anyhow::Result<Ran> {
    let safe = job.on_stop.safe_state();
    Ok(match job.run {
        WhjRun::Scan(ids) => scan(bus, ids, stats)?,
        WhjRun::Info(id) => one(*id, &ops::info(bus, *id)?),
        WhjRun::Status(ids) => rows_of(&ops::status(bus, ids)),
        WhjRun::BroadcastStatus(ids, end_board) => {
            ops::connect_for_broadcast(bus, ids);
            if *end_board {
                let (joints, board) = ops::broadcast_status_with_end_board(bus, ids)?;
                let (mut rows, outcome) = rows_of(&joints);
                let (board_row, board_outcome) = rows_of(&[board]);
                rows.extend(board_row);
                (rows, outcome.and(board_outcome))
            } else {
                rows_of(&ops::broadcast_status(bus, ids)?)
            }
        }
        WhjRun::Enable(ids, on) => rows_of(&ops::enable(bus, ids, *on)),
        WhjRun::Mode(ids, mode) => rows_of(&ops::set_mode(bus, ids, *mode)),
        WhjRun::Move(args) => {
            let j = bus.joint(args.joint)?;
            let plan = ops::prepare_move(&j, args)?;
            let report = with_progress(&plan, "move [{bar:30}] {pos}/{len} frames", |c| {
                Ok(ops::execute_move(&j, args, &plan, c, safe)?)
            })?;
            one(args.joint, &report)
        }
        WhjRun::Target(args) => {
            let j = bus.joint(args.joint)?;
            let token = crate::interrupt::stop_token();
            let report = ops::run_target(&j, args, &mut Control::new(&token), safe)?;
            if report.keeps_running {
                eprintln!("robobus: {}", report.note);
            }
            one(args.joint, &report)
        }
        WhjRun::Zero(id) => one(*id, &ops::zero(bus, *id)?),
        WhjRun::Clear(ids) => rows_of(&ops::clear(bus, ids)),
        WhjRun::Save(ids) => rows_of(&ops::save(bus, ids)),
        WhjRun::Read { .. } | WhjRun::Write { .. } => registers(bus, job)?,
        WhjRun::SetId(id, new_id) => one(*id, &ops::set_id(bus, *id, *new_id)?),
        WhjRun::Wave(args, broadcast) => wave(bus, args, *broadcast, safe, stats)?,
        WhjRun::ReleaseIap(ids) => {
            let results = ops::release_iap(bus, ids);
            let (mut rows, outcome) = rows_of(&results);
            for (r, res) in rows.iter_mut().zip(&results) {
                if res.is_ok() {
                    r.insert("released".into(), json!(true));
                }
            }
            (rows, outcome)
        }
    })
}

/// Register reports of each joint as rows (point-to-point: the first error ends the run).
fn joint_rows(
    joints: &[JointId],
    f: impl Fn(JointId) -> anyhow::Result<Vec<ops::RegisterReport>>,
) -> anyhow::Result<Ran> {
    let mut out = Vec::new();
    for &joint in joints {
        out.extend(f(joint)?.iter().map(|r| row(joint.get(), r)));
    }
    Ok((out, Ok(())))
}

/// `whj read` / `whj write`, point-to-point or by broadcast frames.
fn registers(bus: &JointBus, job: &WhjJob<'_>) -> anyhow::Result<Ran> {
    Ok(match job.run {
        WhjRun::Read {
            joints,
            addr,
            count,
            broadcast,
            end_board,
        } => {
            if *broadcast {
                rows_of(&ops::broadcast_read(bus, joints, *addr, *count, *end_board)?.1)
            } else {
                joint_rows(joints, |j| Ok(ops::read_registers(bus, j, *addr, *count)?))?
            }
        }
        WhjRun::Write {
            joints,
            addr,
            value,
            raw,
            scale,
            broadcast,
            end_board,
        } => {
            let (v, raw, scale, yes) = (*value, *raw, *scale, job.confirmed);
            if *broadcast {
                let (_, results) =
                    ops::broadcast_write(bus, joints, *addr, v, raw, scale, *end_board, yes)?;
                rows_of(&results)
            } else {
                joint_rows(joints, |j| {
                    Ok(ops::write(bus, j, *addr, v, raw, scale, yes)?)
                })?
            }
        }
        _ => (Vec::new(), Ok(())),
    })
}

fn scan(bus: &JointBus, ids: &[JointId], stats: &mut Option<Value>) -> anyhow::Result<Ran> {
    let pb = progress_bar(ids.len() as u64, "scan [{bar:30}] {pos}/{len} {msg}");
    let mut on = |p: &Progress| {
        pb.set_position(p.done);
        if let Some(n) = &p.note {
            pb.set_message(n.clone());
        }
    };
    let token = crate::interrupt::stop_token();
    let report = ops::scan(bus, ids, &mut Control::new(&token).with_progress(&mut on))?;
    pb.finish_and_clear();
    if report.found.is_empty() {
        let list: Vec<String> = ids.iter().map(|j| j.get().to_string()).collect();
        return Err(anyhow::Error::new(Timeout(format!(
            "no joint answered on IDs {} (check power, bit rate 1 / 5 Mbit/s, \
             termination, and --bus)",
            list.join(",")
        ))));
    }
    let (rows, mut outcome) = rows_of(&report.found);
    if !report.duplicates.is_empty() {
        let text: Vec<String> = report
            .duplicates
            .iter()
            .map(|d| {
                format!(
                    "ID {} is answered by two joints (unique IDs {} and {})",
                    d.id, d.unique_ids[0], d.unique_ids[1]
                )
            })
            .collect();
        *stats = Some(json!({ "duplicates": report.duplicates }));
        outcome = outcome.and(Err(kind_error(robobus::ErrorKind::Device, text.join("; "))));
    }
    Ok((rows, outcome))
}

/// Runs a planned operation with the one stop token and a progress bar over its frames.
fn with_progress<T>(
    plan: &ops::Plan,
    template: &str,
    f: impl FnOnce(&mut Control<'_>) -> anyhow::Result<T>,
) -> anyhow::Result<T> {
    let pb = progress_bar(plan.frames.len() as u64, template);
    let mut on = |p: &Progress| pb.set_position(p.done);
    let token = crate::interrupt::stop_token();
    let result = f(&mut Control::new(&token).with_progress(&mut on));
    pb.finish_and_clear();
    result
}

/// Frames without a reply at the end of a wave after which the joint counts as gone
/// (exit code 3): one lost reply is a glitch, ten in a row at the end are a silent joint.
const GONE_AFTER: u64 = 10;

fn wave(
    bus: &JointBus,
    args: &WaveArgs,
    broadcast: bool,
    safe: SafeState,
    stats: &mut Option<Value>,
) -> anyhow::Result<Ran> {
    let j = bus.joint(args.joint)?;
    let plan = if broadcast {
        ops::prepare_broadcast_wave(&j, args)?
    } else {
        ops::prepare_wave(&j, args)?
    };
    let report = with_progress(&plan, "wave [{bar:30}] {pos}/{len} cycles", |c| {
        Ok(ops::execute_wave(&j, args, &plan, c, safe)?)
    })?;
    let mut r = match &report.last {
        Some(fb) => row(args.joint.get(), fb),
        None => row(args.joint.get(), &()),
    };
    r.insert("cycles".into(), json!(report.cycles));
    r.insert("stale".into(), json!(report.stale || report.last.is_none()));
    let value = serde_json::to_value(&report).unwrap_or(Value::Null);
    let mut s = Map::new();
    if let Value::Object(fields) = value {
        for (k, v) in fields {
            if k != "last" {
                s.insert(k, v);
            }
        }
    }
    *stats = Some(Value::Object(s));
    let outcome = if report.complete == 0 {
        Err(anyhow::Error::new(Timeout(format!(
            "joint {}: no reply to any of the {} wave frames",
            args.joint.get(),
            report.cycles
        ))))
    } else if report.missing_at_end >= GONE_AFTER {
        Err(anyhow::Error::new(Timeout(format!(
            "joint {}: silent for the last {} wave frames ({} of {} without a reply; the last \
             values shown are stale)",
            args.joint.get(),
            report.missing_at_end,
            report.missing_replies,
            report.cycles
        ))))
    } else {
        Ok(())
    };
    Ok((vec![r], outcome))
}

/// Maps a client error to its exit code (kept for the other front ends of the CLI).
pub(crate) fn whj_error(e: WhjError) -> anyhow::Error {
    anyhow::Error::new(e)
}

fn progress_bar(len: u64, template: &str) -> ProgressBar {
    if !std::io::stderr().is_terminal() {
        return ProgressBar::hidden();
    }
    let pb = ProgressBar::with_draw_target(Some(len), ProgressDrawTarget::stderr());
    if let Ok(style) = ProgressStyle::with_template(template) {
        pb.set_style(style.progress_chars("=> "));
    }
    pb
}

/// One value as table text: floats with 4 decimals, null as `-`.
fn cell(v: &Value) -> String {
    match v {
        Value::Null => "-".to_owned(),
        Value::String(s) => s.clone(),
        Value::Number(n) => n
            .as_f64()
            .filter(|_| n.is_f64())
            .map_or_else(|| n.to_string(), |f| format!("{f:.4}")),
        other => other.to_string(),
    }
}

/// The column order of the tables (fields not listed follow, alphabetically).
const COLUMNS: &[&str] = &[
    "joint",
    "model",
    "firmware",
    "node_id",
    "reduction",
    "unique_id",
    "cycles",
    "enabled",
    "mode",
    "min_deg",
    "max_deg",
    "from_deg",
    "target_deg",
    "position_deg",
    "speed_rpm",
    "current_ma",
    "voltage_v",
    "temperature_c",
    "brake",
    "addr",
    "register",
    "raw",
    "value",
    "unit",
    "frames",
    "seconds",
    "error_before",
    "error_after",
    "error",
    "kind",
];

/// Rows as an aligned table; columns in [`COLUMNS`] order.
fn table(rows: &[Row]) -> String {
    let mut cols: Vec<&str> = Vec::new();
    for r in rows {
        for k in r.keys() {
            if !cols.contains(&k.as_str()) {
                cols.push(k);
            }
        }
    }
    let rank = |c: &str| {
        COLUMNS
            .iter()
            .position(|k| *k == c)
            .unwrap_or(COLUMNS.len())
    };
    cols.sort_by(|a, b| rank(a).cmp(&rank(b)).then(a.cmp(b)));
    let cells: Vec<Vec<String>> = rows
        .iter()
        .map(|r| {
            cols.iter()
                .map(|c| r.get(*c).map_or_else(String::new, cell))
                .collect()
        })
        .collect();
    let widths: Vec<usize> = cols
        .iter()
        .enumerate()
        .map(|(i, c)| {
            cells
                .iter()
                .filter_map(|r| r.get(i).map(String::len))
                .chain([c.len()])
                .max()
                .unwrap_or(0)
        })
        .collect();
    let mut s = String::new();
    let line = |s: &mut String, items: &mut dyn Iterator<Item = String>| {
        let parts: Vec<String> = items
            .zip(&widths)
            .map(|(t, w)| format!("{t:<w$}"))
            .collect();
        let _ = writeln!(s, "{}", parts.join("  ").trim_end());
    };
    line(&mut s, &mut cols.iter().map(|c| c.to_ascii_uppercase()));
    for r in &cells {
        line(&mut s, &mut r.iter().cloned());
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tables_align_columns_and_show_missing_values() {
        let mut a = Row::new();
        a.insert("joint".into(), json!(1));
        a.insert("error".into(), json!("none"));
        let mut b = Row::new();
        b.insert("joint".into(), json!(12));
        b.insert("value".into(), Value::Null);
        let t = table(&[a, b]);
        let lines: Vec<&str> = t.lines().collect();
        assert_eq!(lines[0], "JOINT  VALUE  ERROR");
        assert_eq!(lines[1], "1             none");
        assert_eq!(lines[2], "12     -");
    }
}
