//! The WHJ joint operations' reports through the catalogue: for scan, info, status,
//! enable, disable, mode, move, speed, current, zero, clear, save and read the exact JSON
//! of each report on the simulated bus (joints 1 and 2; 9 and 5..=6 silent), pinned in
//! `tests/snapshots/whj_reports.json` (`UPDATE_SNAPSHOTS=1` rewrites it), and that the
//! published report schema describes it: each operation's rows are its own typed fields,
//! and every report validates against its operation's schema.

#![allow(clippy::unwrap_used, clippy::panic)]

mod station_support;

use std::collections::BTreeMap;
use std::fmt::Write as _;

use robobus::catalogue::{self, Request};
use robobus::ops::Control;
use serde_json::Value;

/// One case per row shape (and a silent joint, and a refusal): requests run in order on
/// one fresh station; the last one's report is the case's.
const CASES: &[&[&str]] = &[
    &[r#"{"op": "whj.scan", "joints": "1-3"}"#],
    &[r#"{"op": "whj.scan", "joints": "5-6"}"#],
    &[r#"{"op": "whj.info", "joint": 1}"#],
    &[r#"{"op": "whj.info", "joint": 9}"#],
    &[r#"{"op": "whj.status", "joints": "1-2,9"}"#],
    &[r#"{"op": "whj.status", "joints": "1-2", "broadcast": true}"#],
    &[r#"{"op": "whj.status", "joints": "1-2", "broadcast": true, "end_board": true}"#],
    &[r#"{"op": "whj.status", "joints": "1", "end_board": true}"#],
    &[r#"{"op": "whj.enable", "joints": "1,9"}"#],
    &[r#"{"op": "whj.disable", "joints": "1"}"#],
    &[r#"{"op": "whj.mode", "joints": "1-2", "mode": "speed"}"#],
    &[
        r#"{"op": "whj.mode", "joints": "1", "mode": "position"}"#,
        r#"{"op": "whj.enable", "joints": "1"}"#,
        r#"{"op": "whj.move", "joint": 1, "degrees": 2, "max_speed": 20}"#,
    ],
    &[r#"{"op": "whj.move", "joint": 1, "degrees": 2}"#],
    &[
        r#"{"op": "whj.mode", "joints": "1", "mode": "speed"}"#,
        r#"{"op": "whj.enable", "joints": "1"}"#,
        r#"{"op": "whj.speed", "joint": 1, "rpm": 1, "duration": 0.1}"#,
    ],
    &[
        r#"{"op": "whj.mode", "joints": "1", "mode": "current"}"#,
        r#"{"op": "whj.enable", "joints": "1"}"#,
        r#"{"op": "whj.current", "joint": 1, "milliamps": 100, "duration": 0.1}"#,
    ],
    &[r#"{"op": "whj.zero", "joint": 2}"#],
    &[r#"{"op": "whj.clear", "joints": "1,9"}"#],
    &[r#"{"op": "whj.save", "joints": "1", "confirm": true}"#],
    &[r#"{"op": "whj.save", "joints": "1"}"#],
    &[
        r#"{"op": "whj.disable", "joints": "1-2"}"#,
        r#"{"op": "whj.save", "joints": "1-2", "confirm": true}"#,
    ],
    &[r#"{"op": "whj.read", "joints": "1", "register": "SYS_ID", "count": 2}"#],
    &[r#"{"op": "whj.read", "joints": "2", "register": "cur_position"}"#],
    &[r#"{"op": "whj.read", "joints": "1-2", "register": "SYS_ID", "broadcast": true}"#],
    &[
        r#"{"op": "whj.read", "joints": "1-2", "register": "0x14", "broadcast": true, "end_board": "0x00"}"#,
    ],
];

/// The report of the case's last request (after the ones before it) on a fresh station,
/// or its error as `{"error", "kind"}`.
fn report_of(case: &[&str]) -> Value {
    let (s, _w, _j) = station_support::station("wck", "whj");
    let mut last = Value::Null;
    for json in case {
        let r = Request::parse(json).unwrap();
        last = match catalogue::run(&s, &r, &mut Control::none()) {
            Ok(r) => serde_json::to_value(r).unwrap(),
            Err(e) => serde_json::json!({"error": e.to_string(), "kind": e.kind().name()}),
        };
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
fn the_whj_reports_are_the_pinned_json() {
    let got = reports();
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/snapshots/whj_reports.json"
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

#[test]
fn every_whj_joint_report_validates_against_its_operations_typed_schema() {
    let all = catalogue::report_schema();
    for (json, report) in reports() {
        if report.get("results").is_none() {
            continue; // a refusal: no report
        }
        let op = report["op"].as_str().unwrap();
        let schema = schema_of(&all, op);
        let v = jsonschema::validator_for(&schema).unwrap();
        let errors: Vec<String> = v.iter_errors(&report).map(|e| e.to_string()).collect();
        assert!(errors.is_empty(), "{json}: {errors:?}\n{report:#}");
    }
    // Each operation's rows are its own type: its schema (and what it refers to) names
    // their fields (a row of JSON values would accept anything).
    let text = |op: &str| {
        let mut seen = Vec::new();
        let mut out = String::new();
        reachable(&all, &schema_of(&all, op), &mut seen, &mut out);
        out
    };
    for (op, fields) in [
        (
            "whj.scan",
            &["unique_id", "reduction", "duplicates", "probed"][..],
        ),
        ("whj.info", &["node_id", "min_deg", "max_deg", "mode"]),
        (
            "whj.status",
            &["temperature_c", "brake", "current_ma", "teach_button"],
        ),
        ("whj.enable", &["enabled", "error"]),
        ("whj.disable", &["enabled", "error"]),
        ("whj.mode", &["mode"]),
        (
            "whj.move",
            &["from_deg", "step_limited", "held_back", "frames"],
        ),
        ("whj.speed", &["speed_rpm", "keeps_running", "note"]),
        ("whj.current", &["current_ma", "keeps_running", "note"]),
        ("whj.zero", &["position_deg"]),
        ("whj.clear", &["error_before", "error_after"]),
        ("whj.save", &["saved"]),
        ("whj.read", &["addr", "register", "raw", "unit"]),
    ] {
        let schema = text(op);
        for f in fields {
            assert!(
                schema.contains(&format!("\"{f}\"")),
                "{op}: no {f} in {schema}"
            );
        }
    }
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
                    && let Some(name) = v.as_str().and_then(|r| r.rsplit('/').next())
                    && !seen.iter().any(|s| s == name)
                {
                    seen.push(name.to_owned());
                    reachable(all, &all["$defs"][name], seen, out);
                }
                let _ = write!(out, "\"{k}\" ");
                reachable(all, v, seen, out);
            }
        }
        Value::Array(items) => {
            for v in items {
                reachable(all, v, seen, out);
            }
        }
        _ => {}
    }
}
