//! Running a `robobus wck` command through the library's operations
//! ([`robobus::ops::wck`]): open the port, hand over the stop token of the one Ctrl-C
//! handler and a progress bar, render the typed report as a table or as JSON (the report
//! itself: its schema is documented in [`robobus::ops::wck`]).
//!
//! Exit codes come from the library's error kinds ([`crate::exit`]); a run over several
//! servos prints every servo that answered and then fails with the most serious kind
//! among the others (a silent servo: exit code 3).

use std::fmt::Write as _;
use std::io::{BufRead as _, IsTerminal as _};
use std::path::PathBuf;
use std::sync::mpsc;
use std::time::Duration;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use robobus::ErrorKind;
use robobus::ops::capture::{Overwrite, capture_byte_link};
use robobus::ops::wck::{
    self as ops, Fields, Motion, MotionWriter, Pose, ScanArgs, StepResult, TeachArgs, TeachEvent,
    TeachTrigger, WckPlan, WheelArgs,
};
use robobus::ops::{Control, Failure, OpError, Progress, SafeState, worst_kind};
use robobus::wck::WckBus;
use robobus_link::ByteLink;
use robobus_wck::BaudRate;
use serde_json::json;

use crate::exit::{Interrupted, Timeout, usage};
use crate::output;

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

impl From<OnStop> for SafeState {
    fn from(o: OnStop) -> Self {
        match o {
            OnStop::Passive => Self::Passive,
            OnStop::Break => Self::Break,
            OnStop::Hold => Self::Hold,
        }
    }
}

/// How a command runs.
#[derive(Debug)]
pub(crate) enum WckRun {
    /// One exchange per planned packet; one result per servo.
    Steps,
    /// Find servos.
    Scan(ScanArgs),
    /// Wheel mode, optionally timed.
    Wheel(WheelArgs),
    /// Record poses.
    Teach {
        /// The operation's arguments.
        args: TeachArgs,
        /// Where the poses go (stdout if `None`).
        output: Option<PathBuf>,
    },
    /// Play a keyframe motion.
    Play {
        /// The motion.
        motion: Motion,
        /// Moves per second.
        rate_hz: f64,
        /// Safe state on Ctrl-C.
        on_stop: SafeState,
    },
}

/// A wCK job as [`super::execute`] hands it over.
#[derive(Debug)]
pub(crate) struct WckJob<'a> {
    /// The subcommand, e.g. `"move"`.
    pub(crate) action: &'static str,
    /// Serial port path.
    pub(crate) port: &'a str,
    /// Baud rate.
    pub(crate) baud: BaudRate,
    /// `--reply-margin`: replaces the bus's reply margin.
    pub(crate) margin: Option<Duration>,
    /// `--verify-reads`: equal replies a read needs (see [`robobus::wck::WckConfig`]).
    pub(crate) confirm_reads: u8,
    /// `--capture FILE`.
    pub(crate) capture: Option<&'a std::path::Path>,
    /// The validated plan (for [`WckRun::Steps`]).
    pub(crate) plan: &'a WckPlan,
    /// How to run it.
    pub(crate) run: &'a WckRun,
    /// `--json`.
    pub(crate) json: bool,
}

/// Opens the port and runs the job (a teach output file is created first: an unwritable
/// path fails before any servo is touched).
#[allow(clippy::result_large_err)] // the capture wrapper's OpError, converted at once
pub(crate) fn execute(job: &WckJob<'_>) -> anyhow::Result<()> {
    tracing::debug!(port = job.port, baud = %job.baud, action = job.action, "wck run");
    let writer = match job.run {
        WckRun::Teach {
            args,
            output: Some(path),
        } => Some(MotionWriter::create(path, &args.ids, args.torque)?),
        _ => None,
    };
    let mut bus = WckBus::open(job.port, job.baud)?;
    if let Some(margin) = job.margin {
        bus.config_mut().margin = margin;
    }
    bus.config_mut().confirm_reads = job.confirm_reads;
    match job.capture {
        Some(path) => run(
            bus.try_map_link(|link| capture_byte_link(link, path, Overwrite::No))?,
            job,
            writer,
        ),
        None => run(bus, job, writer),
    }
}

/// Runs the job on the opened bus.
fn run<L: ByteLink>(
    mut bus: WckBus<L>,
    job: &WckJob<'_>,
    writer: Option<MotionWriter>,
) -> anyhow::Result<()> {
    let stop = crate::interrupt::stop_token();
    let mut control = Control::new(&stop);
    match job.run {
        WckRun::Steps => steps(&mut bus, job, &mut control),
        WckRun::Scan(args) => scan(&mut bus, job, args),
        WckRun::Wheel(args) => {
            let row = ops::wheel(&mut bus, args, &mut control)?;
            print_rows(job, std::slice::from_ref(&row))
        }
        WckRun::Teach { args, output } => teach(&mut bus, job, args, output.as_ref(), writer),
        WckRun::Play {
            motion,
            rate_hz,
            on_stop,
        } => play(&mut bus, job, motion, *rate_hz, *on_stop),
    }
}

// ----- rendering -----

/// A table: the header of the first row's fields, one line per row, columns aligned; a
/// `meaning` field is printed below the table as a `#` note.
fn table(rows: &[&Fields], ids: &[String]) -> String {
    let Some(first) = rows.first() else {
        return String::new();
    };
    let shown = |k: &str| k != "meaning";
    let mut headers = vec!["ID".to_string()];
    headers.extend(
        first
            .0
            .iter()
            .filter(|(k, _)| shown(k))
            .map(|(k, _)| k.to_uppercase()),
    );
    let cells: Vec<Vec<String>> = rows
        .iter()
        .zip(ids)
        .map(|(r, id)| {
            std::iter::once(id.clone())
                .chain(r.0.iter().filter(|(k, _)| shown(k)).map(|(_, v)| v.cell()))
                .collect()
        })
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
    for r in rows {
        if let Some(m) = r.get("meaning") {
            let _ = writeln!(s, "# {}", m.cell());
        }
    }
    s
}

/// The error for the failed servos of a run: the most serious kind; the others' messages
/// go to stderr first.
fn failures(results: &[StepResult]) -> anyhow::Result<()> {
    let Some(kind) = worst_kind(results) else {
        return Ok(());
    };
    let failed: Vec<&Failure> = results.iter().filter_map(|r| r.failure()).collect();
    let chosen = failed.iter().find(|f| f.kind == kind).copied();
    for f in &failed {
        if chosen.is_none_or(|c| !std::ptr::eq(c, *f)) {
            eprintln!("robobus: {}", f.error);
        }
    }
    let message = chosen.map_or_else(String::new, |f| f.error.clone());
    Err(match kind {
        ErrorKind::NoDevice => anyhow::Error::new(Timeout(message)),
        ErrorKind::BadInput | ErrorKind::Refused => usage(message),
        ErrorKind::Interrupted => anyhow::Error::new(Interrupted).context(message),
        _ => anyhow::anyhow!(message),
    })
}

fn print_rows(job: &WckJob<'_>, rows: &[StepResult]) -> anyhow::Result<()> {
    if job.json {
        output::print_json(&json!({
            "port": job.port,
            "baud": job.baud.bits_per_second(),
            "command": job.action,
            "results": rows,
        }))?;
    } else {
        let ok: Vec<(&Fields, String)> = rows
            .iter()
            .filter_map(|r| r.value().map(|v| (v, r.id.cell())))
            .collect();
        let (fields, ids): (Vec<&Fields>, Vec<String>) = ok.into_iter().unzip();
        output::print(&table(&fields, &ids))?;
    }
    failures(rows)
}

fn print_report(report: &impl serde::Serialize) -> anyhow::Result<()> {
    output::print_json(&serde_json::to_value(report)?)
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

// ----- runs -----

fn steps<L: ByteLink>(
    bus: &mut WckBus<L>,
    job: &WckJob<'_>,
    control: &mut Control<'_>,
) -> anyhow::Result<()> {
    let report = ops::run_steps(bus, job.action, job.plan, control)?;
    print_rows(job, &report.results)
}

fn scan<L: ByteLink>(bus: &mut WckBus<L>, job: &WckJob<'_>, args: &ScanArgs) -> anyhow::Result<()> {
    let total = (args.bauds.len() * args.ids.len()) as u64;
    let pb = progress_bar(total, "scan {bar:30} {pos}/{len} IDs  {msg}");
    let stop = crate::interrupt::stop_token();
    let mut on_progress = |p: &Progress| {
        pb.set_position(p.done);
        if let Some(n) = &p.note {
            pb.set_message(n.clone());
        }
    };
    let mut control = Control::new(&stop).with_progress(&mut on_progress);
    let report = ops::scan(bus, args, &mut control);
    drop(control);
    pb.finish_and_clear();
    let report = report?;
    if job.json {
        print_report(&report)?;
    } else {
        let rows: Vec<Fields> = report
            .found
            .iter()
            .map(|f| {
                let mut r = Fields::default();
                r.push("baud", f.baud);
                r.push("load", f.load);
                r.push("position", f.position);
                r.0.push(("degrees", robobus::ops::wck::FieldValue::real(f.degrees)));
                r
            })
            .collect();
        let ids: Vec<String> = report.found.iter().map(|f| f.id.to_string()).collect();
        let mut text = table(&rows.iter().collect::<Vec<_>>(), &ids);
        for d in &report.duplicates {
            let _ = writeln!(
                text,
                "DUPLICATE  ID {} at {} bit/s: more than one module answers ({})",
                d.id, d.baud, d.evidence
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
    if !report.duplicates.is_empty() {
        // As `whj scan`: an ID that more than one module answers is a device fault (exit 1).
        let ids: Vec<String> = report
            .duplicates
            .iter()
            .map(|d| format!("ID {} at {} bit/s", d.id, d.baud))
            .collect();
        return Err(anyhow::Error::new(robobus::ops::OpError::Device(format!(
            "{}: more than one module answers at {}; give each module its own ID",
            job.port,
            ids.join(", ")
        ))));
    }
    if report.is_empty() {
        let rates: Vec<String> = args.bauds.iter().map(ToString::to_string).collect();
        return Err(anyhow::Error::new(Timeout(format!(
            "{}: no servo answered at any of the scanned IDs ({}) at {}; check power, wiring \
             and the baud rate (--all-bauds tries every rate)",
            job.port,
            ops::ids_text(&args.ids),
            rates.join(", ")
        ))));
    }
    Ok(())
}

fn play<L: ByteLink>(
    bus: &mut WckBus<L>,
    job: &WckJob<'_>,
    motion: &Motion,
    rate_hz: f64,
    on_stop: SafeState,
) -> anyhow::Result<()> {
    let pb = progress_bar(motion.end_ms(), "play {bar:30} {pos}/{len} ms  {msg}");
    let stop = crate::interrupt::stop_token();
    let mut moves = 0u64;
    let mut on_progress = |p: &Progress| {
        moves += 1;
        pb.set_position(p.done);
        pb.set_message(format!("{moves} moves"));
    };
    let mut control = Control::new(&stop).with_progress(&mut on_progress);
    let report = ops::play(bus, motion, rate_hz, on_stop, &mut control);
    drop(control);
    pb.finish_and_clear();
    let report = report?;
    if job.json {
        print_report(&report)
    } else {
        let ps: Vec<String> = report
            .last_positions
            .iter()
            .map(ToString::to_string)
            .collect();
        output::print(&format!(
            "played {} synchronized moves in {} ms (planned {} ms; {} status reads watched \
             the servos); last pose: {}\n",
            report.moves,
            report.duration_ms,
            report.planned_ms,
            report.watch_reads,
            ps.join(" ")
        ))
    }
}

/// Longest line `teach` reads as a key press.
const MAX_KEY_LINE: usize = 1024;

/// Lines typed on stdin (Enter = a line, EOF ends), read in a thread so Ctrl-C is seen
/// while waiting.
/// Lines are bounded ([`MAX_KEY_LINE`]) and so is the queue (a few lines), so an endless
/// input (`< /dev/zero`, `yes |`) costs no memory: an overlong line ends the input.
fn stdin_lines() -> mpsc::Receiver<Option<String>> {
    use std::io::Read as _;
    let (tx, rx) = mpsc::sync_channel(4);
    std::thread::spawn(move || {
        let stdin = std::io::stdin();
        let mut lock = stdin.lock();
        loop {
            let mut line = String::new();
            let limit = MAX_KEY_LINE as u64 + 1;
            match (&mut lock).take(limit).read_line(&mut line) {
                Ok(0) | Err(_) => {
                    let _ = tx.send(None);
                    return;
                }
                Ok(n) if n > MAX_KEY_LINE && !line.ends_with('\n') => {
                    eprintln!(
                        "robobus: a line of more than {MAX_KEY_LINE} bytes on stdin: that is \
                         not a key press; input ends here"
                    );
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

/// `teach`: each pose is written (to `--output`, or as text to stdout) as it is recorded;
/// with `--json` and no file the poses are printed at the end (also after Ctrl-C).
fn teach<L: ByteLink>(
    bus: &mut WckBus<L>,
    job: &WckJob<'_>,
    args: &TeachArgs,
    output: Option<&PathBuf>,
    writer: Option<MotionWriter>,
) -> anyhow::Result<()> {
    let interactive = std::io::stdin().is_terminal();
    let by_key = matches!(args.trigger, TeachTrigger::Events { .. });
    let timed_ends = matches!(
        args.trigger,
        TeachTrigger::Rate {
            duration: Some(_),
            ..
        }
    );
    if by_key && interactive {
        eprintln!(
            "robobus: servo(s) {} are passive: move them by hand. Enter records a pose, \
             q + Enter (or Ctrl-D) finishes, Ctrl-C aborts.",
            ops::ids_text(&args.ids)
        );
    } else if let TeachTrigger::Rate {
        rate_hz,
        duration: None,
    } = args.trigger
    {
        eprintln!("robobus: recording at {rate_hz} Hz; press Enter (or Ctrl-C) to stop");
    }
    // A timed recording does not read stdin; otherwise a line records (by key) or ends
    // (at a rate), `q` and the end of input end.
    let keys = (!timed_ends).then(stdin_lines);
    let mut events = |wait: Duration| {
        let Some(keys) = &keys else {
            std::thread::sleep(wait);
            return TeachEvent::Nothing;
        };
        match keys.recv_timeout(wait) {
            Ok(Some(line)) if by_key && line.trim() != "q" => TeachEvent::Record,
            Ok(_) | Err(mpsc::RecvTimeoutError::Disconnected) => TeachEvent::Finish,
            Err(mpsc::RecvTimeoutError::Timeout) => TeachEvent::Nothing,
        }
    };
    // Text to stdout without a file, JSON collected without a file.
    let mut writer = match (writer, job.json) {
        (Some(w), _) => Some(w),
        (None, false) => Some(MotionWriter::new(
            Box::new(std::io::stdout()),
            &args.ids,
            args.torque,
        )?),
        (None, true) => None,
    };
    let mut collected: Vec<Pose> = Vec::new();
    let mut count = 0usize;
    #[allow(clippy::result_large_err)] // the library's error type
    let mut on_pose = |pose: &Pose| -> Result<(), OpError> {
        count += 1;
        if by_key && interactive {
            let ps: Vec<String> = pose.positions.iter().map(ToString::to_string).collect();
            eprintln!("pose {count}: {}", ps.join(" "));
        }
        if let Some(w) = writer.as_mut() {
            w.pose(pose).map_err(|e| OpError::File {
                path: output
                    .cloned()
                    .unwrap_or_else(|| "(standard output)".into()),
                reason: format!("cannot write: {e}"),
                kind: ErrorKind::Link,
            })
        } else {
            collected.push(pose.clone());
            Ok(())
        }
    };
    let stop = crate::interrupt::stop_token();
    let mut control = Control::new(&stop);
    let result = ops::teach(bus, args, &mut control, &mut events, &mut on_pose);
    let ids: Vec<u8> = args.ids.iter().map(|i| i.get()).collect();
    let printed = match (output, job.json) {
        (Some(path), true) if result.is_ok() => output::print_json(&json!({
            "port": job.port,
            "file": path.display().to_string(),
            "poses": count,
            "ids": ids,
        })),
        (Some(path), false) if result.is_ok() => output::print(&format!(
            "recorded {count} pose(s) of servo(s) {} to {}\n",
            ops::ids_text(&args.ids),
            path.display()
        )),
        (None, true) => output::print_json(&json!({
            "port": job.port,
            "ids": ids,
            "torque": args.torque.get(),
            "poses": collected,
        })),
        _ => Ok(()),
    };
    result?;
    printed
}

#[cfg(test)]
mod tests {
    use super::*;
    use robobus::ops::wck::FieldValue;

    #[test]
    fn tables_align_columns_and_put_a_meaning_below() {
        let mut a = Fields::default();
        a.0.push(("degrees", FieldValue::real(134.0)));
        let mut b = Fields::default();
        b.0.push(("degrees", FieldValue::real(1.5)));
        b.push("meaning", "heard");
        let t = table(&[&a, &b], &["3".into(), "12".into()]);
        let lines: Vec<&str> = t.lines().collect();
        assert_eq!(lines, ["ID  DEGREES", "3   134.0", "12  1.5", "# heard"]);
    }
}
