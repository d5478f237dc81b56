//! Running a catalogue request for a subcommand and rendering its report: the one place
//! where `robobus wck` / `robobus whj` meet the library's dispatcher
//! ([`robobus::catalogue`]).
//!
//! A subcommand builds its [`Request`] from its arguments; [`confirm`] asks what the
//! request's plan says needs asking (or refuses without a terminal), [`run`] runs it
//! on a station holding the one bus the subcommand opened, with the one stop token and a
//! progress bar, and renders the [`Report`]: `--json` prints the report itself, the text
//! form is a table (one row per device or register, columns named like the JSON fields)
//! followed by the summary's fields. The exit code is the report's worst failure.

use std::fmt::Write as _;
use std::io::{BufRead as _, IsTerminal as _, Write as _};

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use robobus::ErrorKind;
use robobus::catalogue::{self, Interaction, NoInteraction, Report, Request};
use robobus::ops::{Control, OpError, Progress};
use robobus::station::Station;
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
    run_with(station, request, &mut NoInteraction)
}

/// [`run`] with the front end's side of an interactive operation (teach's key presses).
pub(crate) fn run_with(
    station: &Station,
    request: &Request,
    interaction: &mut dyn Interaction,
) -> anyhow::Result<Report> {
    let pb = progress_bar(request.op());
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
    let report = catalogue::run_with(
        station,
        request,
        &mut Control::new(&stop).with_progress(&mut on_progress),
        interaction,
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

/// How a family's tables look.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Style {
    /// The header of the `id` column (`JOINT`, `ID`).
    pub(crate) id_header: &'static str,
    /// Decimals of a float cell.
    pub(crate) decimals: usize,
}

/// Prints `report` (`--json`: the report itself; else its table, then its summary) and
/// returns its worst failure as the exit code's error.
pub(crate) fn print(report: &Report, json: bool, style: &Style) -> anyhow::Result<()> {
    if json {
        output::print_json(&serde_json::to_value(report)?)?;
    } else {
        let mut text = results_table(report, style);
        // The summary's fields below the table (an empty list says nothing).
        if let Some(Value::Object(s)) = &report.summary {
            for (k, v) in s {
                if v.as_array().is_some_and(Vec::is_empty) {
                    continue;
                }
                let _ = writeln!(text, "{k}: {}", cell(v, style.decimals));
            }
        }
        output::print(&text)?;
    }
    outcome(report)
}

/// The report's per-device results as a [`table`] (empty without results).
pub(crate) fn results_table(report: &Report, style: &Style) -> String {
    let rows: Vec<Map<String, Value>> = report
        .results
        .iter()
        .filter_map(|r| r.as_object().cloned())
        .collect();
    if rows.is_empty() {
        String::new()
    } else {
        table(&rows, style)
    }
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
        ErrorKind::NotAvailable => anyhow::Error::new(OpError::NotAvailable(message)),
        _ => anyhow::Error::new(OpError::Device(message)),
    }
}

/// One value as table text: floats with `decimals` decimals, null as `-`.
pub(crate) fn cell(v: &Value, decimals: usize) -> String {
    match v {
        Value::Null => "-".to_owned(),
        Value::String(s) => s.clone(),
        Value::Number(n) => n
            .as_f64()
            .filter(|_| n.is_f64())
            .map_or_else(|| n.to_string(), |f| format!("{f:.decimals$}")),
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
    // wCK replies, in the order of a reply's fields.
    "baud",
    "target_position",
    "target_position10",
    "target_degrees",
    "positions",
    "torque",
    "speed",
    "accel",
    "load_before",
    "position_before",
    "position10_before",
    "degrees_before",
    "load",
    "rotations",
    "answered_by",
    "position",
    "position10",
    "degrees",
    "p_gain",
    "d_gain",
    "i_gain",
    "new_id",
    "milliamps",
    "overload_code",
    "lower",
    "lower_degrees",
    "upper",
    "upper_degrees",
    "outputs",
    "do1",
    "do2",
    "adc",
    "adc_volts",
    "instructions",
    "reply",
    "error_after",
    "error",
    "kind",
];

/// Rows as an aligned table; columns in [`COLUMNS`] order, the `id` column headed as
/// `style` says; a row's `meaning` (what a reply means) is a `# ` note below the table.
pub(crate) fn table(rows: &[Map<String, Value>], style: &Style) -> String {
    let id_header = style.id_header;
    // A device that failed has `kind` and `error` only: its row names the kind (the
    // message goes to stderr with the exit code).
    let failed = |r: &Map<String, Value>| r.contains_key("kind") && r.contains_key("error");
    let mut cols: Vec<&str> = vec!["id"];
    for r in rows.iter().filter(|r| !failed(r)) {
        for k in r.keys() {
            if k != "meaning" && !cols.contains(&k.as_str()) {
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
    // `Err((id, kind))` for a failed device's row.
    let cells: Vec<Result<Vec<String>, (String, String)>> = rows
        .iter()
        .map(|r| {
            if failed(r) {
                let id = r.get("id").map_or_else(String::new, |v| cell(v, 0));
                let kind = r.get("kind").map_or_else(String::new, |v| cell(v, 0));
                return Err((id, kind));
            }
            Ok(cols
                .iter()
                .map(|c| {
                    r.get(*c)
                        .map_or_else(String::new, |v| cell(v, style.decimals))
                })
                .collect())
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
                .filter_map(|r| match r {
                    Ok(r) => r.get(i).map(String::len),
                    Err((id, _)) => (i == 0).then_some(id.len()),
                })
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
    let id_width = widths.first().copied().unwrap_or(0);
    for r in &cells {
        match r {
            Ok(r) => line(&mut s, &mut r.iter().cloned()),
            Err((id, kind)) => {
                let _ = writeln!(s, "{id:<id_width$}  ({kind})");
            }
        }
    }
    for m in rows.iter().filter_map(|r| r.get("meaning")) {
        let _ = writeln!(s, "# {}", cell(m, style.decimals));
    }
    s
}

/// `--dry-run`: the plan's text (the packets / frames, one per line) or, with `--json`,
/// the one plan view every front end shows (`robobus::frontend::PlanView`).
pub(crate) fn print_plan(
    g: crate::Global,
    view: &robobus::frontend::PlanView,
) -> anyhow::Result<()> {
    if g.json {
        output::print_json(&view.to_value())
    } else {
        output::print(&view.text)
    }
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
        let style = Style {
            id_header: "joint",
            decimals: 4,
        };
        let t = table(&[a, b], &style);
        let lines: Vec<&str> = t.lines().collect();
        assert_eq!(lines[0], "JOINT  VALUE  ERROR");
        assert_eq!(lines[1], "1             none");
        assert_eq!(lines[2], "12     -");
    }

    #[test]
    fn a_meaning_goes_below_the_table_and_floats_get_the_styles_decimals() {
        let mut a = Map::new();
        a.insert("id".into(), json!(3));
        a.insert("degrees".into(), json!(134.0));
        let mut b = Map::new();
        b.insert("id".into(), json!(12));
        b.insert("degrees".into(), json!(1.5));
        b.insert("meaning".into(), json!("heard"));
        let style = Style {
            id_header: "id",
            decimals: 1,
        };
        let t = table(&[a, b], &style);
        let lines: Vec<&str> = t.lines().collect();
        assert_eq!(lines, ["ID  DEGREES", "3   134.0", "12  1.5", "# heard"]);
    }

    #[test]
    fn a_reports_failure_kind_gives_that_kinds_exit_code() {
        use crate::exit::Exit;
        for kind in [
            ErrorKind::BadInput,
            ErrorKind::Refused,
            ErrorKind::NoDevice,
            ErrorKind::Device,
            ErrorKind::Link,
            ErrorKind::Interrupted,
            ErrorKind::NotAvailable,
        ] {
            let e = kind_error(kind, "what failed".into());
            assert_eq!(Exit::of(&e), Exit::of_kind(kind), "{kind:?}");
            assert!(format!("{e:#}").contains("what failed"), "{kind:?}: {e:#}");
        }
    }

    #[test]
    fn a_failed_device_has_its_row_with_the_kind_only() {
        let mut a = Map::new();
        a.insert("id".into(), json!(7));
        a.insert("kind".into(), json!("no-device"));
        a.insert("error".into(), json!("servo 7 did not answer"));
        let mut b = Map::new();
        b.insert("id".into(), json!(1));
        b.insert("position".into(), json!(127));
        let style = Style {
            id_header: "id",
            decimals: 1,
        };
        let t = table(&[a.clone(), b], &style);
        let lines: Vec<&str> = t.lines().collect();
        assert_eq!(lines, ["ID  POSITION", "7   (no-device)", "1   127"]);
        assert_eq!(table(&[a], &style), "ID\n7   (no-device)\n");
    }
}
