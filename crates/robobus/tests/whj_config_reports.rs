//! The WHJ catalogue's register, settings, bus and signal operations through the
//! catalogue: for write, registers, set-id, wave, release-iap, sample, backup, defaults,
//! end-board, set-rates, can-health, diff and restore the exact JSON of each report on the
//! simulated bus (joints 1 and 2; 9 silent), pinned in
//! `tests/snapshots/whj_config_reports.json` (`UPDATE_SNAPSHOTS=1` rewrites it), and that
//! each operation's typed schema names its rows' fields (that each pinned report validates
//! against it: `report_schema.rs`).

#![allow(clippy::unwrap_used, clippy::panic)]

use crate::common;
use crate::whj_common;

use std::collections::BTreeMap;

use robobus::catalogue;
use robobus::station::Station;
use robobus::whj::JointBus;
use serde_json::Value;

use common::reports::{assert_pinned, assert_schema_names, last_report, pinned_ops};
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

fn reports() -> BTreeMap<String, Value> {
    CASES
        .iter()
        .map(|case| (case.join(" then "), last_report(&station(), case)))
        .collect()
}

#[test]
fn the_whj_config_reports_are_the_pinned_json() {
    assert_pinned("whj_config_reports", &reports());
}

/// Each operation's rows and summary are its own types: its schema (and what it refers
/// to) names their fields (a row of JSON values would accept anything), and a report of
/// each is pinned. That every report is valid under its schema: `report_schema.rs`, over
/// these pinned reports too.
#[test]
fn the_report_schema_names_each_whj_config_operations_row_and_summary_fields() {
    let ops: &[(&str, &[&str])] = &[
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
    ];
    assert_schema_names(&catalogue::report_schema(), ops);
    let pinned = pinned_ops("whj_config_reports");
    for (op, _) in ops {
        assert!(pinned.contains(*op), "{op}: no report ran");
    }
}
