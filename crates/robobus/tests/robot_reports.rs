//! The robot and host operations' typed reports: the published report schema names each
//! one's row and summary fields (what a generated client gets), a run's rows carry exactly
//! those fields, and a Rust front end gets the rows and the summary as types
//! (`catalogue::run_typed`), the same report `catalogue::run` gives as JSON.

#![allow(clippy::unwrap_used, clippy::panic)]

use crate::common;

use std::collections::BTreeSet;

use robobus::catalogue::host::Ports;
use robobus::catalogue::robot::{Calibrate, Sample, ZeroPose};
use robobus::catalogue::{self, NoInteraction, Request};
use robobus::ops::{Control, ErrorKind, Outcome};
use robobus::station::Station;
use serde_json::Value;

use common::reports::schema_of;

/// The schema `$ref` points at, in `root`'s `$defs`.
fn resolve<'a>(root: &'a Value, node: &'a Value) -> &'a Value {
    match node.get("$ref").and_then(Value::as_str) {
        Some(r) => {
            let name = r.trim_start_matches("#/$defs/");
            resolve(root, &root["$defs"][name])
        }
        None => node,
    }
}

/// The property names an object of `node` can have (through `$ref`, `allOf`, `anyOf`,
/// `oneOf`; not the properties of its properties).
fn fields(root: &Value, node: &Value) -> BTreeSet<String> {
    let node = resolve(root, node);
    let mut out: BTreeSet<String> = node
        .get("properties")
        .and_then(Value::as_object)
        .map(|p| p.keys().cloned().collect())
        .unwrap_or_default();
    for key in ["allOf", "anyOf", "oneOf"] {
        for sub in node
            .get(key)
            .and_then(Value::as_array)
            .into_iter()
            .flatten()
        {
            out.extend(fields(root, sub));
        }
    }
    out
}

/// `op`'s report schema: (its rows' fields, its summary's fields).
fn report_fields(op: &str) -> (BTreeSet<String>, BTreeSet<String>) {
    let entry = schema_of(&catalogue::report_schema(), op);
    let report = resolve(&entry, &entry["allOf"][0]);
    let props = &report["properties"];
    (
        fields(&entry, &props["results"]["items"]),
        fields(&entry, &props["summary"]),
    )
}

fn set(names: &[&str]) -> BTreeSet<String> {
    names.iter().map(|&s| s.to_owned()).collect()
}

/// A row's fields beside `id`, or a failed row's `kind` and `error`.
const FAILED: &[&str] = &["id", "kind", "error"];

fn row_set(names: &[&str]) -> BTreeSet<String> {
    let mut s = set(names);
    s.extend(set(FAILED));
    s
}

/// Each robot operation: its rows' fields (beside `id`, or `kind` and `error`) and its
/// summary's.
const ROBOT_FIELDS: &[(&str, &[&str], &[&str])] = &[
    (
        "robot.sample",
        &[
            "position_deg",
            "speed_deg_s",
            "current_ma",
            "effort_nm",
            "load",
            "enabled",
        ],
        &[],
    ),
    (
        "robot.calibrate",
        &[
            "samples",
            "failed",
            "min_deg",
            "max_deg",
            "zero_deg",
            "offset_before_rad",
            "offset_rad",
            "limits_before_rad",
            "limits_rad",
        ],
        &["readings", "interrupted"],
    ),
    (
        "robot.play",
        &[
            "commands",
            "failed",
            "limited",
            "start_deg",
            "target_deg",
            "position_deg",
            "sent_deg_s",
            "sent_nm",
            "tracking_max_deg",
            "tracking_rms_deg",
        ],
        &[
            "lead_in_s",
            "duration_s",
            "ticks",
            "overruns",
            "buses",
            "skew_ms",
            "late_ms",
            "interrupted",
            "safe_state",
            "protection",
            "preflight",
        ],
    ),
    (
        "robot.teach",
        &["samples", "failed", "min_deg", "max_deg", "ended"],
        &["trajectory", "points", "dropped", "readings", "interrupted"],
    ),
    (
        "robot.teleop",
        &[
            "leader",
            "commands",
            "limited",
            "failed",
            "target_deg",
            "position_deg",
            "tracking_max_deg",
            "tracking_rms_deg",
        ],
        &[
            "cycles",
            "commanded",
            "held",
            "overruns",
            "seconds",
            "rate_hz",
            "latency_ms",
            "leaders",
            "leader_lost",
            "interrupted",
            "safe_state",
            "protection",
        ],
    ),
];

#[test]
fn the_report_schema_names_each_robot_and_host_operations_row_and_summary_fields() {
    for &(op, row, summary) in ROBOT_FIELDS {
        assert_eq!(report_fields(op), (row_set(row), set(summary)), "{op}");
    }
    // A port's row has no failure: the listing fails whole or not at all.
    assert_eq!(
        report_fields("host.ports"),
        (
            set(&[
                "id",
                "kind",
                "vid",
                "pid",
                "manufacturer",
                "product",
                "serial_number",
                "adapter",
                "use_for",
                "latency_timer_ms",
                "latency_advice",
            ]),
            set(&["os", "ports", "left_out", "where"]),
        )
    );
}

/// The keys of each row (`id`, then the fields or `kind` and `error`) and of the summary
/// of `request`'s report on `station`.
fn keys_of(station: &Station, request: &str) -> (Vec<BTreeSet<String>>, BTreeSet<String>) {
    let r = Request::parse(request).unwrap();
    let v =
        serde_json::to_value(catalogue::run(station, &r, &mut Control::none()).unwrap()).unwrap();
    let keys = |o: &Value| -> BTreeSet<String> {
        o.as_object()
            .map(|m| m.keys().cloned().collect())
            .unwrap_or_default()
    };
    let rows: Vec<BTreeSet<String>> = v["results"].as_array().unwrap().iter().map(keys).collect();
    assert!(!rows.is_empty(), "{v:#}");
    (rows, keys(&v["summary"]))
}

#[test]
fn a_robot_run_reports_exactly_the_fields_its_schema_names() {
    let station = Station::simulated().unwrap();
    // Every joint answers: each row is the sample's fields (its `error` the joint's error
    // bits), no summary.
    let (rows, summary) = keys_of(&station, r#"{"op": "robot.sample"}"#);
    let (fields, none) = report_fields("robot.sample");
    let ok: BTreeSet<String> = fields.into_iter().filter(|f| f != "kind").collect();
    assert!(rows.iter().all(|r| *r == ok), "{rows:?}");
    assert_eq!((summary, none), (BTreeSet::new(), BTreeSet::new()));
    // No joint was moved by hand: each row is a failure, the summary the readings.
    let (rows, summary) = keys_of(&station, r#"{"op": "robot.calibrate", "seconds": 0.2}"#);
    assert!(rows.iter().all(|r| *r == set(FAILED)), "{rows:?}");
    assert_eq!(summary, report_fields("robot.calibrate").1);
}

#[test]
fn a_rust_front_end_gets_the_robot_and_host_reports_typed() {
    let station = Station::simulated().unwrap();
    let calibrate = Calibrate {
        seconds: 0.2,
        rate_hz: 20.0,
        zero: ZeroPose::Keep,
        margin_deg: 2.0,
        passive: true,
    };
    let report = catalogue::run_typed(
        &station,
        &calibrate,
        &mut Control::none(),
        &mut NoInteraction,
    )
    .unwrap();
    let summary = report.summary.unwrap();
    assert_eq!((summary.readings, summary.interrupted), (4, false));
    assert_eq!(report.bus, "robot");
    assert_eq!(report.failed, Some(ErrorKind::Device));
    let s0 = report.results.iter().find(|r| r.id == "s0").unwrap();
    // Nothing moved it: a range of a point calibrates nothing.
    let Outcome::Failed(f) = &s0.outcome else {
        panic!("{s0:?}")
    };
    assert_eq!(f.kind, ErrorKind::Device);
    assert!(f.error.contains("s0: moved through 0.0°"), "{f:?}");

    let report = catalogue::run_typed(
        &station,
        &Sample {},
        &mut Control::none(),
        &mut NoInteraction,
    )
    .unwrap();
    assert_eq!(report.summary, None);
    let reading = |name: &str| match &report
        .results
        .iter()
        .find(|r| r.id == name)
        .unwrap()
        .outcome
    {
        Outcome::Ok(s) => s.clone(),
        Outcome::Failed(f) => panic!("{name}: {f:?}"),
    };
    // A wCK joint has a load and no drive state, a WHJ joint the other way round.
    let (s0, j1) = (reading("s0"), reading("j1"));
    assert!(s0.load.is_some() && s0.enabled.is_none(), "{s0:?}");
    assert!(j1.load.is_none() && j1.enabled.is_some(), "{j1:?}");

    let report = catalogue::run_typed(
        &station,
        &Ports {},
        &mut Control::none(),
        &mut NoInteraction,
    )
    .unwrap();
    let summary = report.summary.unwrap();
    assert_eq!(report.bus, "host");
    assert_eq!(summary.ports, report.results.len());
    assert_eq!(
        summary.where_,
        robobus::ops::ports::where_ports_are(summary.os)
    );
}
