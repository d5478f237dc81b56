//! Running a `robobus wck` plan through the client library ([`robobus::wck::WckBus`]).
//!
//! [`execute`] opens the port named by `--port` at `--baud` and runs the plan in one of
//! the ways of [`WckRun`]:
//!
//! - [`WckRun::Steps`]: each planned command goes through [`WckBus::execute`] (retries,
//!   EEPROM read-back, ID / baud verification as the client does them), in order; each
//!   reply becomes one row of the result table.
//! - [`WckRun::Scan`]: [`WckBus::scan`] with a progress bar on a terminal.
//! - [`WckRun::Wheel`]: the wheel command, then optionally a timed run and a stop.
//! - [`WckRun::Teach`]: servos go passive, their positions are recorded as poses.
//! - [`WckRun::Play`]: the plan's synchronized moves, each sent at its planned time.
//!
//! # Output
//!
//! Text: a table, one row per reply, columns named like the JSON fields. `--json`: one
//! object `{"port", "baud", "command", "results": [...]}` (scan, teach and play have their
//! own documents, see their functions). Field names carry their units: `position`
//! (0..=254 steps), `position10` (0..=1023), `degrees`, `load`, `milliamps`, `baud`
//! (bit/s), `adc_volts`.
//!
//! # Errors and exit codes
//!
//! [`wck_error`]: a module that does not answer ([`WckError::Timeout`]) and a port that does
//! not exist are [`Timeout`] (exit code 3), every other client error is a runtime error (1).
//! Ctrl-C / SIGTERM during a play, teach or timed wheel run stops the motion (per
//! `--on-stop`) and returns [`Interrupted`] (exit code 130).

use std::fmt::Write as _;
use std::io::{BufRead as _, IsTerminal as _};
use std::path::PathBuf;
use std::sync::mpsc;
use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use robobus::wck::{ScanOptions, ScanProgress, ScanReport, WckBus, WckError};
use robobus_link::{ByteLink, LinkError};
use robobus_wck::{BaudRate, Command, Position, Reply, ServoId, Target, TorqueLevel};
use serde_json::{Value, json};

use crate::exit::{Interrupted, Timeout};
use crate::output::{self, WckPlan};
use crate::wck::play::{Frame, Motion, Pose};

/// What brings servos to a safe state when a loop (play, teach, timed wheel) ends early
/// or, for teach and wheel, when it ends at all.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum OnStop {
    /// Release the torque (the servos turn freely).
    Passive,
    /// Dynamic brake on every servo of the bus (A-1 (6) break mode).
    Break,
    /// Keep the current position, with torque (a position move to where each servo is).
    Hold,
}

/// How a plan is run.
#[derive(Debug)]
pub(crate) enum WckRun<'a> {
    /// One exchange per step, in order; one result row per reply.
    Steps,
    /// Find servos.
    Scan {
        /// The IDs to probe.
        ids: &'a [ServoId],
        /// Every baud rate instead of `--baud` alone.
        all_bauds: bool,
    },
    /// Wheel mode, optionally for a time.
    Wheel {
        /// Turn this long, then stop per `on_stop`; `None` = leave it turning.
        duration: Option<Duration>,
        /// How to stop.
        on_stop: OnStop,
    },
    /// Record poses.
    Teach(&'a Teach),
    /// Play the plan's timed synchronized moves.
    Play {
        /// How to stop when interrupted.
        on_stop: OnStop,
    },
}

/// Options of `robobus wck teach`.
#[derive(Debug, Clone)]
pub(crate) struct Teach {
    /// Servos to record: 0..n-1 (a pose lists servos 0, 1, ... in order).
    pub(crate) ids: Vec<ServoId>,
    /// Record at this rate (`None` with no duration: one pose per Enter).
    pub(crate) rate_hz: Option<f64>,
    /// Stop recording after this long.
    pub(crate) duration: Option<Duration>,
    /// Transition time written for each pose recorded by keypress, ms.
    pub(crate) pose_ms: u32,
    /// Torque level written into the file.
    pub(crate) torque: TorqueLevel,
    /// Where to write the motion (stdout if `None`).
    pub(crate) output: Option<PathBuf>,
    /// What the servos do when recording ends.
    pub(crate) on_stop: OnStop,
}

/// A wCK job as [`super::execute`] hands it over.
#[derive(Debug)]
pub(crate) struct WckJob<'a> {
    /// The subcommand, e.g. `"move"`.
    pub(crate) action: &'a str,
    /// Serial port path.
    pub(crate) port: &'a str,
    /// Baud rate.
    pub(crate) baud: BaudRate,
    /// `--reply-margin`: replaces the bus's reply margin.
    pub(crate) margin: Option<Duration>,
    /// The validated plan.
    pub(crate) plan: &'a WckPlan,
    /// How to run it.
    pub(crate) run: &'a WckRun<'a>,
    /// `--json`.
    pub(crate) json: bool,
}

/// Installs the one Ctrl-C / SIGTERM handler ([`crate::interrupt`]).
fn arm_ctrlc() {
    let _ = crate::interrupt::stop_token();
}

fn stopped() -> bool {
    crate::interrupt::stop_token().is_stopped()
}

/// Sleeps until `deadline`, waking early when Ctrl-C arrives; returns whether it did.
fn sleep_until(deadline: Instant) -> bool {
    loop {
        if stopped() {
            return true;
        }
        let now = Instant::now();
        if now >= deadline {
            return false;
        }
        std::thread::sleep((deadline - now).min(Duration::from_millis(20)));
    }
}

/// The exit-code-selecting error for a client error: a module that does not answer, or a
/// port that does not exist, is a timeout (exit code 3); anything else a runtime error (1).
pub(crate) fn wck_error(e: WckError) -> anyhow::Error {
    let missing = matches!(
        &e,
        WckError::Link {
            source: LinkError::NoSuchDevice { .. },
            ..
        }
    );
    if e.is_timeout() || missing {
        anyhow::Error::new(Timeout(e.to_string()))
    } else {
        anyhow::Error::new(e)
    }
}

/// Opens the port and runs the job.
pub(crate) fn execute(job: &WckJob<'_>) -> anyhow::Result<()> {
    tracing::debug!(
        port = job.port,
        baud = %job.baud,
        steps = job.plan.steps.len(),
        action = job.action,
        "wck run"
    );
    if matches!(
        job.run,
        WckRun::Play { .. } | WckRun::Teach(_) | WckRun::Wheel { .. }
    ) {
        arm_ctrlc();
    }
    let mut bus = WckBus::open(job.port, job.baud).map_err(wck_error)?;
    if let Some(margin) = job.margin {
        bus.config_mut().margin = margin;
    }
    run(&mut bus, job)
}

fn run<L: ByteLink>(bus: &mut WckBus<L>, job: &WckJob<'_>) -> anyhow::Result<()> {
    match job.run {
        WckRun::Steps => steps(bus, job),
        WckRun::Scan { ids, all_bauds } => scan(bus, job, ids, *all_bauds),
        WckRun::Wheel { duration, on_stop } => wheel(bus, job, *duration, *on_stop),
        WckRun::Teach(t) => teach(bus, job, t),
        WckRun::Play { on_stop } => play(bus, job, *on_stop),
    }
}

// ----- results -----

/// One result row: field names (the JSON keys, the table headers) and values.
type Row = Vec<(&'static str, Value)>;

fn degrees(d: f64) -> Value {
    json!((d * 100.0).round() / 100.0)
}

fn target_value(t: Target) -> Value {
    match t {
        Target::Servo(id) => json!(id.get()),
        Target::Extended(id) => json!(id.get()),
        Target::Broadcast => json!("all"),
    }
}

fn position_fields(row: &mut Row, key: &'static str, deg_key: &'static str, p: Position) {
    row.push((key, json!(p.get())));
    row.push((deg_key, degrees(p.degrees())));
}

/// The row for a command and its reply.
#[allow(clippy::too_many_lines)] // one arm per reply shape
fn result_row(command: &Command, reply: Option<Reply>) -> Row {
    let mut row: Row = vec![("id", target_value(command.target()))];
    let moving = matches!(command, Command::Move { .. } | Command::Move10 { .. });
    match *command {
        Command::Move {
            position, torque, ..
        } => {
            position_fields(&mut row, "target_position", "target_degrees", position);
            row.push(("torque", json!(torque.get())));
        }
        Command::Move10 {
            position, torque, ..
        } => {
            row.push(("target_position10", json!(position.get())));
            row.push(("target_degrees", degrees(position.degrees())));
            row.push(("torque", json!(torque.get())));
        }
        Command::SyncMove(sync) => {
            row.push((
                "positions",
                json!(sync.positions().iter().map(|p| p.get()).collect::<Vec<_>>()),
            ));
            row.push(("torque", json!(sync.torque().get())));
            row.push(("reply", json!("none (the command has no reply)")));
        }
        Command::RuntimeSpeedSet { speed, accel, .. } => {
            row.push(("speed", json!(speed.get())));
            row.push(("accel", json!(accel.get())));
            row.push(("reply", json!("none (the command has no reply)")));
        }
        _ => {}
    }
    let Some(reply) = reply else {
        if matches!(command, Command::Break) {
            row.push(("reply", json!("collided (several modules answered)")));
        }
        return row;
    };
    match reply {
        Reply::Status { load, position } => {
            if moving {
                row.push(("load_before", json!(load.get())));
                position_fields(&mut row, "position_before", "degrees_before", position);
            } else {
                row.push(("load", json!(load.get())));
                position_fields(&mut row, "position", "degrees", position);
            }
        }
        Reply::Passive { position } => position_fields(&mut row, "position", "degrees", position),
        Reply::Wheel {
            rotations,
            position,
        } => {
            row.push(("rotations", json!(rotations)));
            position_fields(&mut row, "position", "degrees", position);
        }
        Reply::Break { id, position } => {
            row.push(("answered_by", json!(id.get())));
            position_fields(&mut row, "position", "degrees", position);
        }
        Reply::Baud(b) => row.push(("baud", json!(b.bits_per_second()))),
        Reply::Gains { p, d } => {
            row.push(("p_gain", json!(p.get())));
            row.push(("d_gain", json!(d.get())));
        }
        Reply::IGain(i) => row.push(("i_gain", json!(i.get()))),
        Reply::Id(id) => row.push(("new_id", json!(id.get()))),
        Reply::SpeedAccel { speed, accel } => {
            row.push(("speed", json!(speed.get())));
            row.push(("accel", json!(accel.get())));
        }
        Reply::Overload(o) => {
            row.push(("milliamps", json!(o.milliamps())));
            row.push(("overload_code", json!(o.get())));
        }
        Reply::Boundaries(b) => {
            position_fields(&mut row, "lower", "lower_degrees", b.lower());
            position_fields(&mut row, "upper", "upper_degrees", b.upper());
        }
        Reply::Outputs(o) => {
            row.push(("outputs", json!(o.get())));
            row.push(("do1", json!(o.do1())));
            row.push(("do2", json!(o.do2())));
        }
        Reply::Io { outputs, adc } => {
            row.push(("outputs", json!(outputs.get())));
            row.push(("do1", json!(outputs.do1())));
            row.push(("do2", json!(outputs.do2())));
            row.push(("adc", json!(adc)));
            row.push((
                "adc_volts",
                json!((f64::from(adc) * 5.0 / 255.0 * 100.0).round() / 100.0),
            ));
        }
        Reply::MotionCount(n) => row.push(("instructions", json!(n.get()))),
        Reply::Position10(p) => {
            if moving {
                row.push(("position10_before", json!(p.get())));
                row.push(("degrees_before", degrees(p.degrees())));
            } else {
                row.push(("position10", json!(p.get())));
                row.push(("degrees", degrees(p.degrees())));
            }
        }
    }
    row
}

fn cell(v: &Value) -> String {
    match v {
        Value::String(s) => s.clone(),
        Value::Array(a) => a.iter().map(cell).collect::<Vec<_>>().join(" "),
        Value::Number(n) => match n.as_f64() {
            Some(f) if !n.is_i64() && !n.is_u64() => format!("{f:.1}"),
            _ => n.to_string(),
        },
        other => other.to_string(),
    }
}

/// A table: the header of the first row's fields, one line per row, columns aligned.
fn table(rows: &[Row]) -> String {
    let Some(first) = rows.first() else {
        return String::new();
    };
    let headers: Vec<String> = first.iter().map(|(k, _)| k.to_uppercase()).collect();
    let cells: Vec<Vec<String>> = rows
        .iter()
        .map(|r| r.iter().map(|(_, v)| cell(v)).collect())
        .collect();
    let mut widths: Vec<usize> = headers.iter().map(String::len).collect();
    for r in &cells {
        for (i, c) in r.iter().enumerate() {
            if let Some(w) = widths.get_mut(i) {
                *w = (*w).max(c.len());
            } else {
                widths.push(c.len());
            }
        }
    }
    let mut s = String::new();
    for line in std::iter::once(&headers).chain(&cells) {
        let mut l = String::new();
        for (i, c) in line.iter().enumerate() {
            let w = widths.get(i).copied().unwrap_or(0);
            let _ = write!(l, "{c:<w$}  ");
        }
        let _ = writeln!(s, "{}", l.trim_end());
    }
    s
}

fn row_object(row: &Row) -> Value {
    Value::Object(
        row.iter()
            .map(|(k, v)| ((*k).to_string(), v.clone()))
            .collect(),
    )
}

fn print_rows(job: &WckJob<'_>, rows: &[Row]) -> anyhow::Result<()> {
    if job.json {
        output::print_json(&json!({
            "port": job.port,
            "baud": job.baud.bits_per_second(),
            "command": job.action,
            "results": rows.iter().map(row_object).collect::<Vec<_>>(),
        }))
    } else {
        output::print(&table(rows))
    }
}

// ----- runs -----

/// Each step through [`WckBus::execute`]; the rows printed at the end, or the rows so far
/// and then the error.
fn steps<L: ByteLink>(bus: &mut WckBus<L>, job: &WckJob<'_>) -> anyhow::Result<()> {
    let mut rows = Vec::with_capacity(job.plan.steps.len());
    for step in &job.plan.steps {
        if let Some(b) = step.baud {
            bus.set_host_baud(b).map_err(wck_error)?;
        }
        match bus.execute(&step.command) {
            Ok(reply) => rows.push(result_row(&step.command, reply)),
            Err(e) => {
                if !rows.is_empty() && !job.json {
                    output::print(&table(&rows))?;
                }
                return Err(wck_error(e));
            }
        }
    }
    print_rows(job, &rows)
}

/// A progress bar on stderr when it is a terminal, hidden otherwise.
fn progress_bar(len: u64, template: &str) -> ProgressBar {
    if !std::io::stderr().is_terminal() {
        return ProgressBar::hidden();
    }
    let pb = ProgressBar::with_draw_target(Some(len), ProgressDrawTarget::stderr());
    if let Ok(style) = ProgressStyle::with_template(template) {
        pb.set_style(style);
    }
    pb
}

/// Contiguous runs of IDs (a scan takes a range).
fn id_runs(ids: &[ServoId]) -> Vec<(u8, u8)> {
    let mut raw: Vec<u8> = ids.iter().map(|i| i.get()).collect();
    raw.sort_unstable();
    raw.dedup();
    let mut runs: Vec<(u8, u8)> = Vec::new();
    for id in raw {
        match runs.last_mut() {
            Some((_, hi)) if hi.checked_add(1) == Some(id) => *hi = id,
            _ => runs.push((id, id)),
        }
    }
    runs
}

/// `scan`: JSON `{"port", "bauds_tried", "found": [{"id", "baud", "load", "position",
/// "degrees"}], "duplicates": [{"id", "baud", "evidence"}]}`. Finding nothing is a
/// [`Timeout`] (exit code 3) after the (empty) result is printed.
fn scan<L: ByteLink>(
    bus: &mut WckBus<L>,
    job: &WckJob<'_>,
    ids: &[ServoId],
    all_bauds: bool,
) -> anyhow::Result<()> {
    let base = if all_bauds {
        ScanOptions::all_bauds()
    } else {
        ScanOptions::at(job.baud)
    };
    let bauds = base.bauds.clone();
    let total = bauds.len() * ids.len();
    let pb = progress_bar(total as u64, "scan {bar:30} {pos}/{len} IDs  {msg}");
    let mut report = ScanReport::default();
    let mut found_before = 0;
    for (lo, hi) in id_runs(ids) {
        let options = base.clone().ids(lo..=hi);
        let part = bus
            .scan(&options, |p: &ScanProgress| {
                pb.inc(1);
                pb.set_message(format!(
                    "{} bit/s, ID {}: {} found",
                    p.baud.bits_per_second(),
                    p.id,
                    found_before + p.found
                ));
            })
            .map_err(|e| {
                pb.finish_and_clear();
                wck_error(e)
            })?;
        found_before += part.found.len() + part.duplicates.len();
        report.found.extend(part.found);
        report.duplicates.extend(part.duplicates);
    }
    pb.finish_and_clear();
    report.found.sort_by_key(|f| (f.baud, f.id));
    let rows: Vec<Row> = report
        .found
        .iter()
        .map(|f| {
            let mut row: Row = vec![
                ("id", json!(f.id.get())),
                ("baud", json!(f.baud.bits_per_second())),
                ("load", json!(f.status.load.get())),
            ];
            position_fields(&mut row, "position", "degrees", f.status.position);
            row
        })
        .collect();
    let dups: Vec<Value> = report
        .duplicates
        .iter()
        .map(
            |d| json!({"id": d.id.get(), "baud": d.baud.bits_per_second(), "evidence": d.evidence}),
        )
        .collect();
    if job.json {
        output::print_json(&json!({
            "port": job.port,
            "bauds_tried": bauds.iter().map(|b| b.bits_per_second()).collect::<Vec<_>>(),
            "found": rows.iter().map(row_object).collect::<Vec<_>>(),
            "duplicates": dups,
        }))?;
    } else {
        let mut text = table(&rows);
        for d in &report.duplicates {
            let _ = writeln!(
                text,
                "DUPLICATE  ID {} at {} bit/s: more than one module answers ({})",
                d.id,
                d.baud.bits_per_second(),
                d.evidence
            );
        }
        let _ = writeln!(
            text,
            "# {} servo(s) found, {} duplicate ID(s)",
            report.found.len(),
            report.duplicates.len()
        );
        output::print(&text)?;
    }
    if report.is_empty() {
        let rates: Vec<String> = bauds.iter().map(ToString::to_string).collect();
        return Err(anyhow::Error::new(Timeout(format!(
            "{}: no servo answered at any of the scanned IDs ({}) at {}; check power, wiring \
             and the baud rate (--all-bauds tries every rate)",
            job.port,
            ids_text(ids),
            rates.join(", ")
        ))));
    }
    Ok(())
}

fn ids_text(ids: &[ServoId]) -> String {
    id_runs(ids)
        .iter()
        .map(|&(lo, hi)| {
            if lo == hi {
                lo.to_string()
            } else {
                format!("{lo}-{hi}")
            }
        })
        .collect::<Vec<_>>()
        .join(",")
}

/// Brings `ids` to the safe state `on_stop`; returns the first error after trying all.
fn safe_stop<L: ByteLink>(
    bus: &mut WckBus<L>,
    ids: &[ServoId],
    on_stop: OnStop,
    torque: TorqueLevel,
) -> anyhow::Result<()> {
    let mut first = None;
    match on_stop {
        OnStop::Break => {
            if let Err(e) = bus.break_all() {
                first = Some(e);
            }
        }
        OnStop::Passive => {
            for &id in ids {
                if let Err(e) = bus.servo(id).passive() {
                    first.get_or_insert(e);
                }
            }
        }
        OnStop::Hold => {
            for &id in ids {
                let mut servo = bus.servo(id);
                let held = match servo.status() {
                    Ok(s) => servo.move_to(torque, s.position).map(drop),
                    Err(e) => Err(e),
                };
                if let Err(e) = held {
                    first.get_or_insert(e);
                }
            }
        }
    }
    first.map_or(Ok(()), |e| Err(wck_error(e)))
}

/// After Ctrl-C: the safe stop, then [`Interrupted`] (a failed stop is reported too).
fn interrupted<L: ByteLink>(
    bus: &mut WckBus<L>,
    ids: &[ServoId],
    on_stop: OnStop,
    torque: TorqueLevel,
) -> anyhow::Error {
    match safe_stop(bus, ids, on_stop, torque) {
        Ok(()) => {
            eprintln!(
                "robobus: interrupted; servo(s) {} brought to {} state",
                ids_text(ids),
                on_stop_name(on_stop)
            );
            anyhow::Error::new(Interrupted)
        }
        Err(e) => anyhow::Error::new(Interrupted).context(format!(
            "could not bring the servos to the safe state: {e:#}"
        )),
    }
}

const fn on_stop_name(o: OnStop) -> &'static str {
    match o {
        OnStop::Passive => "passive",
        OnStop::Break => "break",
        OnStop::Hold => "hold",
    }
}

/// `wheel`: the command's row; with a duration, turns that long, then stops per `on_stop`.
fn wheel<L: ByteLink>(
    bus: &mut WckBus<L>,
    job: &WckJob<'_>,
    duration: Option<Duration>,
    on_stop: OnStop,
) -> anyhow::Result<()> {
    let Some(step) = job.plan.steps.first() else {
        return Ok(());
    };
    let Command::Wheel { id, .. } = step.command else {
        return steps(bus, job);
    };
    let start = Instant::now();
    let reply = bus.execute(&step.command).map_err(wck_error)?;
    let mut row = result_row(&step.command, reply);
    if let Some(d) = duration {
        if sleep_until(start + d) {
            return Err(interrupted(bus, &[id], on_stop, TorqueLevel::MIN));
        }
        safe_stop(bus, &[id], on_stop, TorqueLevel::MIN)?;
        row.push((
            "ran_ms",
            json!(u64::try_from(start.elapsed().as_millis()).unwrap_or(u64::MAX)),
        ));
        row.push(("stopped", json!(on_stop_name(on_stop))));
    }
    print_rows(job, &[row])
}

/// `play`: each synchronized move at its planned time. JSON `{"port", "moves", "sent",
/// "duration_ms", "last_positions"}`.
fn play<L: ByteLink>(bus: &mut WckBus<L>, job: &WckJob<'_>, on_stop: OnStop) -> anyhow::Result<()> {
    let end_ms = job
        .plan
        .steps
        .iter()
        .filter_map(|s| s.at_ms)
        .max()
        .unwrap_or(0);
    let (servos, torque) = match job.plan.steps.first().map(|s| &s.command) {
        Some(Command::SyncMove(s)) => (s.positions().len(), s.torque()),
        _ => (0, TorqueLevel::MIN),
    };
    let ids: Vec<ServoId> = (0..servos)
        .filter_map(|i| u8::try_from(i).ok().and_then(|i| ServoId::new(i).ok()))
        .collect();
    let pb = progress_bar(end_ms, "play {bar:30} {pos}/{len} ms  {msg}");
    let start = Instant::now();
    let mut sent = 0usize;
    let mut last: Vec<u8> = Vec::new();
    for step in &job.plan.steps {
        let due = start + Duration::from_millis(step.at_ms.unwrap_or(0));
        if sleep_until(due) {
            pb.finish_and_clear();
            return Err(interrupted(bus, &ids, on_stop, torque));
        }
        if let Err(e) = bus.execute(&step.command) {
            pb.finish_and_clear();
            return Err(wck_error(e));
        }
        sent += 1;
        if let Command::SyncMove(s) = &step.command {
            last = s.positions().iter().map(|p| p.get()).collect();
        }
        pb.set_position(step.at_ms.unwrap_or(0));
        pb.set_message(format!("{sent} moves"));
    }
    pb.finish_and_clear();
    let took = u64::try_from(start.elapsed().as_millis()).unwrap_or(u64::MAX);
    if job.json {
        output::print_json(&json!({
            "port": job.port,
            "command": "play",
            "moves": job.plan.steps.len(),
            "sent": sent,
            "planned_ms": end_ms,
            "duration_ms": took,
            "last_positions": last,
        }))
    } else {
        let ps: Vec<String> = last.iter().map(ToString::to_string).collect();
        output::print(&format!(
            "played {sent} synchronized moves in {took} ms (planned {end_ms} ms); last pose: {}\n",
            ps.join(" ")
        ))
    }
}

/// Lines typed on stdin (Enter = a line, EOF ends), read in a thread so Ctrl-C is seen
/// while waiting.
fn stdin_lines() -> mpsc::Receiver<Option<String>> {
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let stdin = std::io::stdin();
        let mut lock = stdin.lock();
        loop {
            let mut line = String::new();
            match lock.read_line(&mut line) {
                Ok(0) | Err(_) => {
                    let _ = tx.send(None);
                    return;
                }
                Ok(_) => {
                    if tx.send(Some(line)).is_err() {
                        return;
                    }
                }
            }
        }
    });
    rx
}

/// One passive round: the positions of `ids`, in order.
fn read_pose<L: ByteLink>(bus: &mut WckBus<L>, ids: &[ServoId]) -> anyhow::Result<Vec<Position>> {
    let mut pose = Vec::with_capacity(ids.len());
    for &id in ids {
        pose.push(bus.servo(id).passive().map_err(wck_error)?);
    }
    Ok(pose)
}

/// How a teach recording ended.
enum Ended {
    /// Duration over, Enter, q or end of input.
    Normally,
    /// Ctrl-C / SIGTERM.
    Interrupted,
}

/// Poses at `rate_hz` (default 10) for `duration`, or until Enter / Ctrl-C.
fn record_timed<L: ByteLink>(
    bus: &mut WckBus<L>,
    t: &Teach,
    first: Vec<Position>,
    poses: &mut Vec<Pose>,
) -> anyhow::Result<Ended> {
    let start = Instant::now();
    let rate = t.rate_hz.unwrap_or(10.0);
    let period = Duration::from_secs_f64(1.0 / rate);
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // 5..=10000 ms
    let period_ms = (1000.0 / rate).round() as u32;
    poses.push(Pose {
        ms: period_ms,
        positions: first,
    });
    let keys = t.duration.is_none().then(stdin_lines);
    if t.duration.is_none() {
        eprintln!("robobus: recording at {rate} Hz; press Enter (or Ctrl-C) to stop");
    }
    let mut next = start + period;
    loop {
        if sleep_until(next) {
            return Ok(Ended::Interrupted);
        }
        if let Some(d) = t.duration
            && start.elapsed() >= d
        {
            return Ok(Ended::Normally);
        }
        if let Some(k) = &keys
            && k.try_recv().is_ok()
        {
            return Ok(Ended::Normally);
        }
        poses.push(Pose {
            ms: period_ms,
            positions: read_pose(bus, &t.ids)?,
        });
        next += period;
    }
}

/// One pose per line on stdin (Enter) until `q`, end of input or Ctrl-C.
fn record_by_key<L: ByteLink>(
    bus: &mut WckBus<L>,
    t: &Teach,
    first: Vec<Position>,
    poses: &mut Vec<Pose>,
) -> anyhow::Result<Ended> {
    let interactive = std::io::stdin().is_terminal();
    poses.push(Pose {
        ms: t.pose_ms,
        positions: first,
    });
    if interactive {
        eprintln!(
            "robobus: servo(s) {} are passive: move them by hand. Enter records a pose, \
             q + Enter (or Ctrl-D) finishes, Ctrl-C aborts.",
            ids_text(&t.ids)
        );
    }
    let keys = stdin_lines();
    loop {
        if stopped() {
            return Ok(Ended::Interrupted);
        }
        match keys.recv_timeout(Duration::from_millis(50)) {
            Ok(Some(line)) if line.trim() == "q" => return Ok(Ended::Normally),
            Ok(Some(_)) => {
                let pose = read_pose(bus, &t.ids)?;
                if interactive {
                    let ps: Vec<String> = pose.iter().map(ToString::to_string).collect();
                    eprintln!("pose {}: {}", poses.len() + 1, ps.join(" "));
                }
                poses.push(Pose {
                    ms: t.pose_ms,
                    positions: pose,
                });
            }
            Ok(None) | Err(mpsc::RecvTimeoutError::Disconnected) => return Ok(Ended::Normally),
            Err(mpsc::RecvTimeoutError::Timeout) => {}
        }
    }
}

/// `teach`: servos passive, a pose recorded per Enter (or at `rate_hz`), written as a
/// keyframe motion file. JSON (with `--output`): `{"port", "file", "poses", "ids"}`;
/// without `--output`, `{"port", "ids", "torque", "poses": [{"ms", "positions"}]}`.
/// After Ctrl-C what was recorded is still written, then the servos go to the
/// `--on-stop` state and the error is [`Interrupted`].
fn teach<L: ByteLink>(bus: &mut WckBus<L>, job: &WckJob<'_>, t: &Teach) -> anyhow::Result<()> {
    // Every servo goes passive first; the first round's positions are the first pose.
    let first = read_pose(bus, &t.ids)?;
    let mut poses: Vec<Pose> = Vec::new();
    let ended = if t.rate_hz.is_some() || t.duration.is_some() {
        record_timed(bus, t, first, &mut poses)?
    } else {
        record_by_key(bus, t, first, &mut poses)?
    };
    let count = poses.len();
    let motion = Motion {
        torque: t.torque,
        frames: poses.into_iter().map(Frame::Pose).collect(),
    };
    let text = motion.to_text(&t.ids);
    if let Some(path) = &t.output {
        std::fs::write(path, &text)
            .map_err(|e| anyhow::anyhow!("cannot write {}: {e}", path.display()))?;
    }
    if matches!(ended, Ended::Interrupted) {
        return Err(interrupted(bus, &t.ids, t.on_stop, t.torque));
    }
    // Recording ended normally: servos are passive; another stop state if asked for.
    if t.on_stop != OnStop::Passive {
        safe_stop(bus, &t.ids, t.on_stop, t.torque)?;
    }
    let ids: Vec<u8> = t.ids.iter().map(|i| i.get()).collect();
    match (&t.output, job.json) {
        (Some(path), true) => output::print_json(&json!({
            "port": job.port,
            "file": path.display().to_string(),
            "poses": count,
            "ids": ids,
        })),
        (Some(path), false) => output::print(&format!(
            "recorded {count} pose(s) of servo(s) {} to {}\n",
            ids_text(&t.ids),
            path.display()
        )),
        (None, true) => {
            let poses: Vec<Value> = motion
                .frames
                .iter()
                .filter_map(|f| match f {
                    Frame::Pose(p) => Some(json!({
                        "ms": p.ms,
                        "positions": p.positions.iter().map(|p| p.get()).collect::<Vec<_>>(),
                    })),
                    Frame::Hold(_) => None,
                })
                .collect();
            output::print_json(&json!({
                "port": job.port,
                "ids": ids,
                "torque": t.torque.get(),
                "poses": poses,
            }))
        }
        (None, false) => output::print(&text),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ids(raw: &[u8]) -> Vec<ServoId> {
        raw.iter().map(|&i| ServoId::new(i).unwrap()).collect()
    }

    #[test]
    fn id_runs_group_contiguous_ids() {
        assert_eq!(id_runs(&ids(&[0, 1, 2, 5, 7, 8])), [(0, 2), (5, 5), (7, 8)]);
        assert_eq!(id_runs(&ids(&[3, 1, 2])), [(1, 3)]);
        assert_eq!(ids_text(&ids(&[0, 1, 2, 5])), "0-2,5");
    }

    #[test]
    fn tables_align_columns_under_their_headers() {
        let rows = vec![
            vec![("id", json!(3)), ("degrees", json!(134.0))],
            vec![("id", json!(12)), ("degrees", json!(1.5))],
        ];
        let t = table(&rows);
        let lines: Vec<&str> = t.lines().collect();
        assert_eq!(lines, ["ID  DEGREES", "3   134.0", "12  1.5"]);
    }

    #[test]
    fn a_move_row_names_the_reply_as_the_status_before_the_move() {
        let cmd = Command::Move {
            id: ServoId::new(3).unwrap(),
            torque: TorqueLevel::MIN,
            position: Position::new(200).unwrap(),
        };
        let reply = Reply::Status {
            load: robobus_wck::Load::new(5).unwrap(),
            position: Position::new(127).unwrap(),
        };
        let row = row_object(&result_row(&cmd, Some(reply)));
        assert_eq!(row["id"], 3);
        assert_eq!(row["target_position"], 200);
        assert_eq!(row["position_before"], 127);
        assert_eq!(row["load_before"], 5);
    }

    #[test]
    fn timeouts_and_missing_ports_select_exit_code_3() {
        use crate::exit::Exit;
        let e = WckError::Link {
            device: "/dev/x".into(),
            command: "open",
            source: LinkError::Closed {
                context: "gone".into(),
            },
        };
        assert_eq!(Exit::of(&wck_error(e)), Exit::Runtime);
        let e = WckError::Link {
            device: "/dev/x".into(),
            command: "open",
            source: LinkError::NoSuchDevice {
                path: "/dev/x".into(),
            },
        };
        let e = wck_error(e);
        assert_eq!(Exit::of(&e), Exit::Timeout);
        assert!(e.to_string().contains("/dev/x"), "{e}");
        let e = WckError::Timeout {
            device: "/dev/x".into(),
            target: Target::Servo(ServoId::new(9).unwrap()),
            command: "status read",
            baud: BaudRate::B115200,
            waited: Duration::from_millis(12),
            received: Vec::new(),
            expected: 2,
            attempts: 4,
        };
        let e = wck_error(e);
        assert_eq!(Exit::of(&e), Exit::Timeout);
        assert!(e.to_string().contains("servo 9"), "{e}");
    }
}
