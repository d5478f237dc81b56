//! Shared by the report tests: a request's report (or its error) as JSON, a case of
//! requests run in order, the pinned-JSON snapshot check, and the report schema's entry of
//! one operation (standalone, to validate against; as text, to find its fields in).

#![allow(clippy::unwrap_used, clippy::panic)]

use std::collections::BTreeMap;
use std::fmt::Write as _;

use robobus::catalogue::{self, Request};
use robobus::ops::{Control, OpError};
use robobus::station::Station;
use serde_json::{Value, json};

/// An error as `{"error", "kind"}`.
pub fn error(e: &OpError) -> Value {
    json!({"error": e.to_string(), "kind": e.kind().name()})
}

/// The report of `request` on `station` as JSON, or its error as `{"error", "kind"}`.
pub fn report_of(station: &Station, request: &Request) -> Value {
    catalogue::run(station, request, &mut Control::none())
        .map_or_else(|e| error(&e), |r| serde_json::to_value(r).unwrap())
}

/// `text` with its `SETTINGS` (if any) replaced by `settings` as a JSON string: a case
/// restores what a `whj.backup` before it returned.
pub fn with_settings(text: &str, settings: &Value) -> String {
    text.replace("SETTINGS", &Value::from(settings.to_string()).to_string())
}

/// The report (or error) of the case's last request, after the ones before it, on
/// `station`; a `SETTINGS` in a request is the summary of the last `whj.backup`.
pub fn last_report(station: &Station, case: &[&str]) -> Value {
    let mut last = Value::Null;
    let mut settings = Value::Null;
    for text in case {
        let r = Request::parse(&with_settings(text, &settings)).unwrap();
        last = report_of(station, &r);
        if r.op() == "whj.backup" {
            settings = last["summary"].clone();
        }
    }
    last
}

/// The path of the pinned JSON `name` (`tests/snapshots/{name}.json`).
pub fn snapshot_path(name: &str) -> String {
    format!("{}/tests/snapshots/{name}.json", env!("CARGO_MANIFEST_DIR"))
}

/// `got` is the JSON pinned in `tests/snapshots/{name}.json`, case by case
/// (`UPDATE_SNAPSHOTS=1` rewrites it first).
pub fn assert_pinned(name: &str, got: &BTreeMap<String, Value>) {
    let path = snapshot_path(name);
    if std::env::var_os("UPDATE_SNAPSHOTS").is_some() {
        let text = serde_json::to_string_pretty(got).unwrap() + "\n";
        std::fs::create_dir_all(std::path::Path::new(&path).parent().unwrap()).unwrap();
        std::fs::write(&path, &text).unwrap();
    }
    let want: BTreeMap<String, Value> =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    for (case, value) in got {
        assert_eq!(Some(value), want.get(case), "{case}");
    }
    assert_eq!(got.len(), want.len());
}

/// The schema of `op`'s report, standalone (its `$defs` beside it), from the whole report
/// schema `all`.
pub fn schema_of(all: &Value, op: &str) -> Value {
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

/// What is wrong with `report` under its own operation's schema (nothing: valid).
pub fn schema_errors(all: &Value, report: &Value) -> Vec<String> {
    let op = report["op"]
        .as_str()
        .unwrap_or_else(|| panic!("a report without an op: {report}"));
    let schema = schema_of(all, op);
    let v = jsonschema::validator_for(&schema).unwrap();
    v.iter_errors(report).map(|e| e.to_string()).collect()
}

/// The text of `op`'s schema and of every definition it refers to, directly or not: each
/// key as `"key"`, so a field's name can be looked for in it.
pub fn schema_text(all: &Value, op: &str) -> String {
    let mut seen = Vec::new();
    let mut out = String::new();
    reachable(all, &schema_of(all, op), &mut seen, &mut out);
    out
}

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

/// Each operation's rows (and summary) are its own types: its schema (and what it refers
/// to) names each of `fields` (a row of JSON values would accept anything).
pub fn assert_schema_names(all: &Value, ops: &[(&str, &[&str])]) {
    for (op, fields) in ops {
        let text = schema_text(all, op);
        for f in *fields {
            assert!(text.contains(&format!("\"{f}\"")), "{op}: no {f} in {text}");
        }
    }
}

/// Every report the report tests pin (`tests/snapshots/*.json`: a case's report, or its
/// `{"plan", "report"}`), by case; refusals and errors (no `results`) are left out.
pub fn pinned_reports() -> Vec<(String, Value)> {
    let dir = format!("{}/tests/snapshots", env!("CARGO_MANIFEST_DIR"));
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "json"))
        .collect();
    files.sort();
    let mut out = Vec::new();
    for path in files {
        let pinned: BTreeMap<String, Value> =
            serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
        let file = path.file_name().unwrap().to_string_lossy().into_owned();
        for (case, value) in pinned {
            let report = value.get("report").unwrap_or(&value);
            if report.get("results").is_some() {
                out.push((format!("{file}: {case}"), report.clone()));
            }
        }
    }
    out
}

/// The operations whose report (not a refusal or an error) `tests/snapshots/{name}.json`
/// pins.
pub fn pinned_ops(name: &str) -> std::collections::BTreeSet<String> {
    let pinned: BTreeMap<String, Value> =
        serde_json::from_str(&std::fs::read_to_string(snapshot_path(name)).unwrap()).unwrap();
    pinned
        .values()
        .map(|v| v.get("report").unwrap_or(v))
        .filter(|r| r.get("results").is_some())
        .filter_map(|r| r["op"].as_str().map(str::to_owned))
        .collect()
}
