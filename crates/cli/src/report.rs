//! Running a catalogue request for a subcommand and rendering its report: the one place
//! where `robobus wck` / `robobus whj` meet the library's dispatcher
//! ([`robobus::catalogue`]).
//!
//! A subcommand builds its [`Request`] from its arguments; [`confirm`] asks what the
//! request's plan says needs asking (or refuses without a terminal), [`execute`] runs it
//! on a station holding the one bus the subcommand opened, with the one stop token and a
//! progress bar, and renders the [`Report`]: `--json` prints the report itself, the text
//! form is a table (one row per device or register, columns named like the JSON fields)
//! followed by the summary's fields. The exit code is the report's worst failure.

use std::fmt::Write as _;
use std::io::{BufRead as _, IsTerminal as _, Write as _};

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use robobus::ErrorKind;
use robobus::catalogue::{self, Report, Request, Station};
use robobus::ops::{Control, OpError, Progress};
use serde_json::{Map, Value};

use crate::exit::{Interrupted, Timeout, usage};
use crate::output;

/// Asks before a request that needs confirmation (what its plan says it rewrites):
/// `--yes` skips the question; on a terminal the user answers y/N; without a terminal the
/// request is refused (exit 2). Returns the request, confirmed where it needed it.
pub(crate) fn confirm(request: Request, yes: bool) -> anyhow::Result<Request> {
    let Some(what) = catalogue::confirmation(&request)? else {
        return Ok(request);
    };
    if yes {
        return Ok(request.confirmed());
    }
    let stdin = std::io::stdin();
    if !stdin.is_terminal() {
        return Err(usage(format!(
            "{what} Confirm with --yes; nothing was sent"
        )));
    }
    let mut err = std::io::stderr().lock();
    let _ = write!(err, "{what} Continue? [y/N] ");
    let _ = err.flush();
    let mut answer = String::new();
    stdin.lock().read_line(&mut answer)?;
    if matches!(answer.trim(), "y" | "Y" | "yes" | "YES") {
        Ok(request.confirmed())
    } else {
        Err(usage("not confirmed; nothing was sent"))
    }
}

/// Runs `request` on `station` with the stop token of the one Ctrl-C handler and, on a
/// terminal, a progress bar fed by the operation's progress events.
pub(crate) fn run(station: &Station, request: &Request) -> anyhow::Result<Report> {
    let pb = progress_bar(&request.op());
    let mut on_progress = |p: &Progress| {
        if let Some(total) = p.total {
            pb.set_length(total);
        }
        pb.set_position(p.done);
        if let Some(n) = &p.note {
            pb.set_message(n.clone());
        }
    };
    let stop = crate::interrupt::stop_token();
    let report = catalogue::run(
        station,
        request,
        &mut Control::new(&stop).with_progress(&mut on_progress),
    );
    pb.finish_and_clear();
    Ok(report?)
}

/// A progress bar on stderr when it is a terminal, hidden otherwise.
fn progress_bar(op: &str) -> ProgressBar {
    if !std::io::stderr().is_terminal() {
        return ProgressBar::hidden();
    }
    let pb = ProgressBar::with_draw_target(Some(0), ProgressDrawTarget::stderr());
    let template = format!("{op} [{{bar:30}}] {{pos}}/{{len}}  {{msg}}");
    if let Ok(style) = ProgressStyle::with_template(&template) {
        pb.set_style(style.progress_chars("=> "));
    }
    pb
}

/// Prints `report` (`--json`: the report itself; else its table, `id_header` naming the
/// ID column, then its summary) and returns its worst failure as the exit code's error.
pub(crate) fn print(report: &Report, json: bool, id_header: &str) -> anyhow::Result<()> {
    if json {
        output::print_json(&serde_json::to_value(report)?)?;
    } else {
        let rows: Vec<Map<String, Value>> = report
            .results
            .iter()
            .filter_map(|r| r.as_object().cloned())
            .collect();
        let mut text = if rows.is_empty() {
            String::new()
        } else {
            table(&rows, id_header)
        };
        // The summary's fields below the table (an empty list says nothing).
        if let Some(Value::Object(s)) = &report.summary {
            for (k, v) in s {
                if v.as_array().is_some_and(Vec::is_empty) {
                    continue;
                }
                let _ = writeln!(text, "{k}: {}", cell(v));
            }
        }
        output::print(&text)?;
    }
    outcome(report)
}

/// The report's worst failure as an error with its exit code (`Ok` when every device
/// answered as asked).
pub(crate) fn outcome(report: &Report) -> anyhow::Result<()> {
    let Some(kind) = report.failed_kind() else {
        return Ok(());
    };
    let message = report.error.clone().unwrap_or_default();
    Err(kind_error(kind, message))
}

/// An error with the exit code of `kind` ([`crate::exit::Exit::of_kind`]).
pub(crate) fn kind_error(kind: ErrorKind, message: String) -> anyhow::Error {
    match kind {
        ErrorKind::NoDevice => anyhow::Error::new(Timeout(message)),
        ErrorKind::Interrupted => anyhow::Error::new(Interrupted).context(message),
        ErrorKind::BadInput | ErrorKind::Refused => usage(message),
        _ => anyhow::Error::new(OpError::Device(message)),
    }
}

/// One value as table text: floats with 4 decimals, null as `-`.
pub(crate) fn cell(v: &Value) -> String {
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
    "id",
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

/// Rows as an aligned table; columns in [`COLUMNS`] order, the `id` column headed
/// `id_header`.
pub(crate) fn table(rows: &[Map<String, Value>], id_header: &str) -> String {
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
    let header = |c: &str| {
        if c == "id" {
            id_header.to_ascii_uppercase()
        } else {
            c.to_ascii_uppercase()
        }
    };
    let widths: Vec<usize> = cols
        .iter()
        .enumerate()
        .map(|(i, c)| {
            cells
                .iter()
                .filter_map(|r| r.get(i).map(String::len))
                .chain([header(c).len()])
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
    line(&mut s, &mut cols.iter().map(|c| header(c)));
    for r in &cells {
        line(&mut s, &mut r.iter().cloned());
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn tables_align_columns_and_show_missing_values() {
        let mut a = Map::new();
        a.insert("id".into(), json!(1));
        a.insert("error".into(), json!("none"));
        let mut b = Map::new();
        b.insert("id".into(), json!(12));
        b.insert("value".into(), Value::Null);
        let t = table(&[a, b], "joint");
        let lines: Vec<&str> = t.lines().collect();
        assert_eq!(lines[0], "JOINT  VALUE  ERROR");
        assert_eq!(lines[1], "1             none");
        assert_eq!(lines[2], "12     -");
    }
}
