//! The WHJ catalogue's register, settings, bus and signal operations through the
//! catalogue: for write, registers, set-id, wave, release-iap, sample, backup, defaults,
//! end-board, set-rates, can-health, diff and restore the exact JSON of each report on the
//! simulated bus (joints 1 and 2; 9 silent), pinned in
//! `tests/snapshots/whj_config_reports.json` (`UPDATE_SNAPSHOTS=1` rewrites it), and that
//! each report validates against its operation's typed schema, whose rows name their
//! fields.

#![allow(clippy::unwrap_used, clippy::panic)]

mod whj_common;

use std::collections::BTreeMap;
use std::fmt::Write as _;

use robobus::catalogue::{self, Request};
use robobus::ops::Control;
use robobus::station::Station;
use robobus::whj::JointBus;
use serde_json::Value;
use whj_common::{sim_link, virtual_config};

/// One case per row shape (and silent joints, and refusals): requests run in order on
/// one fresh station; the last one's report is the case's. `SETTINGS` in a request is
/// the settings file the case's last `whj.backup` gave.
const CASES: &[&[&str]] = &[
    &[r#"{"op": "whj.write", "joints": "1", "register": "SYS_ID", "value": 12, "confirm": true}"#],
    &[r#"{"op": "whj.write", "joints": "1", "register": "SYS_ID", "value": 12}"#],
    &[r#"{"op": "whj.write", "joints": "2", "register": "LIT_MAX_SPEED", "value": 20}"#],
    &[
        r#"{"op": "whj.write", "joints": "2", "register": "LIT_MAX_SPEED", "value": 2000, "raw": true}"#,
    ],
    &[
        r#"{"op": "whj.write", "joints": "1-2,7", "register": "LIT_MAX_SPEED", "value": 2000, "raw": true, "broadcast": true}"#,
    ],
    &[
        r#"{"op": "whj.write", "joints": "1-2", "register": "LIT_MAX_SPEED", "value": 2000, "raw": true, "broadcast": true, "end_board": "EB_IO1_MODE=1", "confirm": true}"#,
    ],
    &[
        r#"{"op": "whj.write", "joints": "9", "register": "LIT_MAX_SPEED", "value": 2000, "raw": true}"#,
    ],
    &[r#"{"op": "whj.registers"}"#],
    &[r#"{"op": "whj.set-id", "joint": 2, "new_id": 12, "confirm": true}"#],
    &[r#"{"op": "whj.set-id", "joint": 1, "new_id": 2, "confirm": true}"#],
    &[
        r#"{"op": "whj.mode", "joints": "1", "mode": "position"}"#,
        r#"{"op": "whj.enable", "joints": "1"}"#,
        r#"{"op": "whj.wave", "joint": 1, "amplitude": 1, "duration": 0.5}"#,
    ],
    &[
        r#"{"op": "whj.mode", "joints": "1", "mode": "speed"}"#,
        r#"{"op": "whj.enable", "joints": "1"}"#,
        r#"{"op": "whj.wave", "joint": 1, "mode": "speed", "shape": "square", "amplitude": 2, "frequency": 2, "duration": 0.3, "rate_hz": 100}"#,
    ],
    &[
        r#"{"op": "whj.mode", "joints": "1", "mode": "position"}"#,
        r#"{"op": "whj.enable", "joints": "1"}"#,
        r#"{"op": "whj.wave", "joint": 1, "amplitude": 1, "duration": 0.5, "broadcast": true}"#,
    ],
    &[r#"{"op": "whj.wave", "joint": 9, "amplitude": 1, "duration": 0.2}"#],
    &[r#"{"op": "whj.release-iap", "joints": "1,9"}"#],
    &[r#"{"op": "whj.sample", "joints": "1-2,9"}"#],
    &[r#"{"op": "whj.sample", "joints": "1-2", "broadcast": true}"#],
    &[r#"{"op": "whj.backup", "joint": 1}"#],
    &[r#"{"op": "whj.backup", "joint": 9}"#],
    &[r#"{"op": "whj.defaults", "joint": 2}"#],
    &[r#"{"op": "whj.end-board", "action": "status"}"#],
    &[r#"{"op": "whj.end-board", "action": "force"}"#],
    &[r#"{"op": "whj.end-board", "action": "power", "volts": 24}"#],
    &[r#"{"op": "whj.end-board", "action": "power", "volts": 24, "confirm": true}"#],
    &[r#"{"op": "whj.end-board", "action": "power", "volts": 0}"#],
    &[
        r#"{"op": "whj.end-board", "action": "io", "channel": 2, "mode": "output", "confirm": true}"#,
    ],
    &[
        r#"{"op": "whj.end-board", "action": "io", "channel": 3, "mode": "output", "confirm": true}"#,
    ],
    &[
        r#"{"op": "whj.disable", "joints": "1"}"#,
        r#"{"op": "whj.set-rates", "joints": "1,9", "bitrate": 1000000, "dbitrate": 5000000, "confirm": true}"#,
    ],
    &[
        r#"{"op": "whj.disable", "joints": "1-2"}"#,
        r#"{"op": "whj.set-rates", "joints": "1-2", "bitrate": 1000000, "dbitrate": 2000000, "confirm": true}"#,
    ],
    &[
        r#"{"op": "whj.enable", "joints": "2"}"#,
        r#"{"op": "whj.set-rates", "joints": "2", "bitrate": 1000000, "dbitrate": 2000000, "confirm": true}"#,
    ],
    &[r#"{"op": "whj.set-rates", "joints": "1", "bitrate": 1000000, "dbitrate": 5000000}"#],
    &[r#"{"op": "whj.can-health"}"#],
    &[
        r#"{"op": "whj.write", "joints": "2", "register": "LIT_MAX_SPEED", "value": 2000, "raw": true}"#,
        r#"{"op": "whj.diff", "joint": 1, "other": 2}"#,
    ],
    &[
        r#"{"op": "whj.backup", "joint": 2}"#,
        r#"{"op": "whj.write", "joints": "1", "register": "LIT_MAX_SPEED", "value": 2000, "raw": true}"#,
        r#"{"op": "whj.diff", "joint": 1, "settings": SETTINGS}"#,
    ],
    &[
        r#"{"op": "whj.write", "joints": "2", "register": "LIT_MAX_SPEED", "value": 2000, "raw": true}"#,
        r#"{"op": "whj.backup", "joint": 2}"#,
        r#"{"op": "whj.disable", "joints": "1"}"#,
        r#"{"op": "whj.restore", "joint": 1, "settings": SETTINGS, "confirm": true}"#,
    ],
    &[
        r#"{"op": "whj.backup", "joint": 2}"#,
        r#"{"op": "whj.restore", "joint": 1, "settings": SETTINGS}"#,
    ],
];

/// WHJ joints 1 and 2 and an end board on the bus `whj`, on the simulator's virtual
/// clock.
fn station() -> Station {
    let bus = robobus_sim::whj::WhjBus::chain(1..=2, robobus_sim::whj::WhjModel::Whj30, 11)
        .with_end_board();
    let (link, sim) = sim_link(bus);
    let mut s = Station::new();
    s.add_whj("whj", JointBus::open_with(link, virtual_config()).unwrap());
    s.keep(Box::new(std::sync::Mutex::new(sim)));
    s
}

/// The report of the case's last request (after the ones before it) on a fresh station,
/// or its error as `{"error", "kind"}`.
fn report_of(case: &[&str]) -> Value {
    let s = station();
    let mut last = Value::Null;
    let mut settings = Value::Null;
    for json in case {
        let json = json.replace("SETTINGS", &Value::from(settings.to_string()).to_string());
        let r = Request::parse(&json).unwrap();
        last = match catalogue::run(&s, &r, &mut Control::none()) {
            Ok(r) => serde_json::to_value(r).unwrap(),
            Err(e) => serde_json::json!({"error": e.to_string(), "kind": e.kind().name()}),
        };
        if r.op() == "whj.backup" {
            settings = last["summary"].clone();
        }
    }
    last
}

fn reports() -> BTreeMap<String, Value> {
    CASES
        .iter()
        .map(|case| (case.join(" then "), report_of(case)))
        .collect()
}

#[test]
fn the_whj_config_reports_are_the_pinned_json() {
    let got = reports();
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/snapshots/whj_config_reports.json"
    );
    let text = serde_json::to_string_pretty(&got).unwrap() + "\n";
    if std::env::var_os("UPDATE_SNAPSHOTS").is_some() {
        std::fs::create_dir_all(std::path::Path::new(path).parent().unwrap()).unwrap();
        std::fs::write(path, &text).unwrap();
    }
    let want: BTreeMap<String, Value> =
        serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    for (json, report) in &got {
        assert_eq!(Some(report), want.get(json), "{json}");
    }
    assert_eq!(got.len(), want.len());
}

/// The schema of `op`'s report, standalone (its `$defs` beside it).
fn schema_of(all: &Value, op: &str) -> Value {
    let one = all["oneOf"]
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["title"] == op)
        .unwrap_or_else(|| panic!("{op} is not in the report schema"));
    let mut schema = one.clone();
    schema["$defs"] = all["$defs"].clone();
    schema
}

/// The text of `schema` and of every definition it refers to, directly or not.
fn reachable(all: &Value, schema: &Value, seen: &mut Vec<String>, out: &mut String) {
    match schema {
        Value::Object(m) => {
            for (k, v) in m {
                if k == "$defs" {
                    continue;
                }
                if k == "$ref"
                    && let Some(name) = v.as_str().and_then(|r| r.strip_prefix("#/$defs/"))
                {
                    if !seen.iter().any(|s| s == name) {
                        seen.push(name.to_owned());
                        reachable(all, &all["$defs"][name], seen, out);
                    }
                    continue;
                }
                let _ = write!(out, "\"{k}\" ");
                reachable(all, v, seen, out);
            }
        }
        Value::Array(a) => a.iter().for_each(|v| reachable(all, v, seen, out)),
        _ => {}
    }
}

#[test]
fn every_whj_config_report_validates_against_its_operations_typed_schema() {
    let all = catalogue::report_schema();
    let mut ran = Vec::new();
    for (json, report) in reports() {
        if report.get("results").is_none() {
            continue; // a refusal: no report
        }
        let op = report["op"].as_str().unwrap().to_owned();
        let v = jsonschema::validator_for(&schema_of(&all, &op)).unwrap();
        let errors: Vec<String> = v.iter_errors(&report).map(|e| e.to_string()).collect();
        assert!(errors.is_empty(), "{json}: {errors:?}\n{report:#}");
        ran.push(op);
    }
    // Each operation's rows and summary are its own types: its schema (and what it
    // refers to) names their fields (a row of JSON values would accept anything).
    for (op, fields) in [
        ("whj.write", &["addr", "register", "raw", "unit"][..]),
        (
            "whj.registers",
            &["writable", "safety", "safety_note", "range"],
        ),
        (
            "whj.set-id",
            &["new_id", "read_back", "answered_at", "saved"],
        ),
        (
            "whj.wave",
            &["position_deg", "cycles", "stale", "tracking_rms"],
        ),
        ("whj.release-iap", &["firmware", "unique_id", "released"]),
        ("whj.sample", &["position_deg", "speed_rpm", "current_ma"]),
        ("whj.backup", &["model", "settings", "format", "version"]),
        ("whj.defaults", &["model", "settings", "format", "version"]),
        (
            "whj.end-board",
            &["tool_volts", "read_back", "fx", "teach_button"],
        ),
        ("whj.set-rates", &["before", "after", "saved", "next"]),
        ("whj.can-health", &["state", "advice", "classic", "bus_off"]),
        ("whj.diff", &["a", "b", "differ", "left_out"]),
        ("whj.restore", &["from", "to", "action", "differ_after"]),
    ] {
        assert!(ran.iter().any(|o| o == op), "{op}: no report ran");
        let mut seen = Vec::new();
        let mut text = String::new();
        reachable(&all, &schema_of(&all, op), &mut seen, &mut text);
        for f in fields {
            assert!(text.contains(&format!("\"{f}\"")), "{op}: no {f} in {text}");
        }
    }
}
