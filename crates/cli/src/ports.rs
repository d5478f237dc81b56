//! `robobus ports`: the serial ports of this machine as its OS knows them: the catalogue's
//! `host.ports` on an empty station, rendered as a table (`--json`: the report itself).

use std::fmt::Write as _;

use robobus::catalogue::{self, Report, Request};
use robobus::station::Station;
use serde_json::Value;

use crate::Global;

/// Options of `robobus ports`.
#[derive(Debug, clap::Args)]
#[command(after_help = "\
Lists what the OS knows: COM ports on Windows, /dev/cu.* on macOS, /dev/ttyUSB* /
/dev/ttyACM* and on-board UARTs on Linux. A simulator's pseudo-terminal is not a port the
OS lists: `robobus sim wck` prints its path. Nothing is opened or sent; exit code 0 also
when no port is found.")]
pub(crate) struct Args {}

/// The request this command runs.
pub(crate) fn request() -> Request {
    Request::HostPorts(catalogue::host::Ports {})
}

/// Runs `robobus ports`.
pub(crate) fn run(g: Global, _args: &Args) -> anyhow::Result<()> {
    let request = request();
    if g.dry_run {
        let plan = catalogue::plan(&request)?;
        return if g.json {
            crate::output::print_json(&serde_json::to_value(&plan)?)
        } else {
            crate::output::print(plan.to_text())
        };
    }
    let report = crate::report::run(&Station::new(), &request)?;
    if g.json {
        crate::output::print_json(&serde_json::to_value(&report)?)?;
    } else {
        crate::output::print(&text(&report))?;
    }
    crate::report::outcome(&report)
}

fn field<'a>(row: &'a Value, key: &str) -> Option<&'a str> {
    row.get(key).and_then(Value::as_str)
}

/// `vid:pid` as four hex digits each (`0403:6001`), or `-`.
fn usb_id(row: &Value) -> String {
    match (
        row.get("vid").and_then(Value::as_u64),
        row.get("pid").and_then(Value::as_u64),
    ) {
        (Some(v), Some(p)) => format!("{v:04x}:{p:04x}"),
        _ => "-".to_owned(),
    }
}

/// The table: one line per port (PORT, KIND, USB, ADAPTER, USE), then its USB strings
/// and its latency timer and advice on indented lines; a line for no port at all.
pub(crate) fn text(report: &Report) -> String {
    let mut s = String::new();
    let rows = &report.results;
    let summary = report.summary.as_ref();
    if rows.is_empty() {
        let where_ = summary.and_then(|v| field(v, "where")).unwrap_or_default();
        let _ = writeln!(s, "no serial port found; {where_}");
        return s;
    }
    let port_w = rows
        .iter()
        .map(|r| field(r, "id").unwrap_or("-").chars().count())
        .max()
        .unwrap_or(4)
        .clamp(4, 40);
    let adapter_w = rows
        .iter()
        .map(|r| field(r, "adapter").unwrap_or("-").chars().count())
        .max()
        .unwrap_or(7)
        .clamp(7, 40);
    let _ = writeln!(
        s,
        "{:<port_w$}  {:<9}  {:<9}  {:<adapter_w$}  USE",
        "PORT", "KIND", "USB", "ADAPTER"
    );
    for r in rows {
        let _ = writeln!(
            s,
            "{:<port_w$}  {:<9}  {:<9}  {:<adapter_w$}  {}",
            field(r, "id").unwrap_or("-"),
            field(r, "kind").unwrap_or("-"),
            usb_id(r),
            field(r, "adapter").unwrap_or("-"),
            field(r, "use_for").unwrap_or("-"),
        );
        let strings: Vec<String> = [
            ("manufacturer", ""),
            ("product", ""),
            ("serial_number", "serial "),
        ]
        .iter()
        .filter_map(|(k, label)| field(r, k).map(|v| format!("{label}{v}")))
        .collect();
        if !strings.is_empty() {
            let _ = writeln!(s, "    {}", strings.join(", "));
        }
        if let Some(ms) = r.get("latency_timer_ms").and_then(Value::as_u64) {
            let _ = writeln!(s, "    latency timer: {ms} ms");
        }
        if let Some(advice) = field(r, "latency_advice") {
            let _ = writeln!(s, "    fix: {advice}");
        }
    }
    if let Some(n) = summary
        .and_then(|v| v.get("left_out"))
        .and_then(Value::as_u64)
        .filter(|&n| n > 0)
    {
        let _ = writeln!(s, "({n} more ports not shown)");
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn the_table_shows_each_port_its_adapter_use_and_advice() {
        let report = Report {
            op: "host.ports".into(),
            bus: "host".into(),
            results: vec![
                json!({"id": "COM3", "kind": "usb", "vid": 0x0403, "pid": 0x6001,
                    "manufacturer": "FTDI", "product": "FT232R USB UART",
                    "serial_number": "A10K1234", "adapter": "FTDI FT232R",
                    "use_for": "wCK bus: --port COM3", "latency_timer_ms": null,
                    "latency_advice": "Device Manager > COM3"}),
                json!({"id": "COM12", "kind": "usb", "vid": 0x16d0, "pid": 0x117e,
                    "manufacturer": null, "product": null, "serial_number": null,
                    "adapter": "CANable 2.0 (slcan firmware)",
                    "use_for": "CAN FD adapter: --bus slcan:COM12",
                    "latency_timer_ms": null, "latency_advice": null}),
                json!({"id": "/dev/ttyS0", "kind": "unknown", "vid": null, "pid": null,
                    "manufacturer": null, "product": null, "serial_number": null,
                    "adapter": null, "use_for": null, "latency_timer_ms": 16,
                    "latency_advice": null}),
            ],
            summary: Some(json!({"os": "windows", "ports": 3, "left_out": 2, "where": "x"})),
            failed: None,
            error: None,
        };
        assert_eq!(
            text(&report),
            "\
PORT        KIND       USB        ADAPTER                       USE
COM3        usb        0403:6001  FTDI FT232R                   wCK bus: --port COM3
    FTDI, FT232R USB UART, serial A10K1234
    fix: Device Manager > COM3
COM12       usb        16d0:117e  CANable 2.0 (slcan firmware)  CAN FD adapter: --bus slcan:COM12
/dev/ttyS0  unknown    -          -                             -
    latency timer: 16 ms
(2 more ports not shown)
"
        );
    }

    #[test]
    fn no_port_says_where_this_os_puts_them() {
        let report = Report {
            op: "host.ports".into(),
            bus: "host".into(),
            results: vec![],
            summary: Some(json!({"os": "macos", "ports": 0, "left_out": 0,
                "where": "ports are /dev/cu.*"})),
            failed: None,
            error: None,
        };
        assert_eq!(text(&report), "no serial port found; ports are /dev/cu.*\n");
    }
}
