//! The WHJ joint operations' reports through the catalogue: for scan, info, status,
//! enable, disable, mode, move, speed, current, zero, clear, save and read the exact JSON
//! of each report on the simulated bus (joints 1 and 2; 9 and 5..=6 silent), pinned in
//! `tests/snapshots/whj_reports.json` (`UPDATE_SNAPSHOTS=1` rewrites it), and that the
//! published report schema describes it: each operation's rows are its own typed fields
//! (that every pinned report validates against its operation's schema:
//! `report_schema.rs`).

#![allow(clippy::unwrap_used, clippy::panic)]

use crate::common;
use crate::station_support;

use std::collections::BTreeMap;

use robobus::catalogue;
use serde_json::Value;

use common::reports::{assert_pinned, assert_schema_names, last_report};

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

fn reports() -> BTreeMap<String, Value> {
    CASES
        .iter()
        .map(|case| {
            let (s, _w, _j) = station_support::station("wck", "whj");
            (case.join(" then "), last_report(&s, case))
        })
        .collect()
}

#[test]
fn the_whj_reports_are_the_pinned_json() {
    assert_pinned("whj_reports", &reports());
}

/// Each operation's rows are its own types: its schema (and what it refers to) names
/// their fields (a row of JSON values would accept anything). That every report is valid
/// under its schema: `report_schema.rs`, over these pinned reports too.
#[test]
fn the_report_schema_names_each_whj_joint_operations_row_fields() {
    assert_schema_names(
        &catalogue::report_schema(),
        &[
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
        ],
    );
}
