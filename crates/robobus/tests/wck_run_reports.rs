//! The wCK operations that are more than one exchange per servo, and the program ones,
//! through the catalogue: for set-baud, program upload / download / check, teach, play,
//! sample, tune, backup, diff and restore the exact JSON of each plan and report on the
//! simulated bus (servos 0..=2; 7 silent), pinned in
//! `tests/snapshots/wck_run_reports.json` (`UPDATE_SNAPSHOTS=1` rewrites it; that each
//! pinned report validates against its operation's typed schema: `report_schema.rs`). On
//! the virtual clock.

#![allow(clippy::unwrap_used)]

use crate::common;
use crate::station_support;

use std::collections::BTreeMap;

use robobus::catalogue::{self, Request};
use serde_json::{Value, json};

use common::reports::{assert_pinned, error, report_of};

const PROGRAM: &str = r"move 82 torque 0\ndelay 266ms\nmove 172 torque 0\nrepeat forever\n";
const MOTION: &str = r"torque 1\npose 100 100 140\nhold 40\npose 100 127 127\n";

/// One case per report shape (and a silent servo, a refusal, a bad argument): requests
/// run in order on one fresh station; the last one's plan and report are the case's.
fn cases() -> Vec<Vec<String>> {
    let one = |s: &str| vec![s.to_owned()];
    vec![
        one(r#"{"op": "wck.set-baud", "id": 2, "rate": 57600, "confirm": true}"#),
        one(r#"{"op": "wck.set-baud", "id": 7, "rate": 57600, "confirm": true}"#),
        one(r#"{"op": "wck.set-baud", "id": 2, "rate": 57600}"#),
        one(r#"{"op": "wck.set-baud", "id": 2, "rate": 1234}"#),
        one(&format!(
            r#"{{"op": "wck.program.upload", "id": 0, "program": "{PROGRAM}", "confirm": true}}"#
        )),
        one(&format!(
            r#"{{"op": "wck.program.upload", "id": 7, "program": "{PROGRAM}", "confirm": true}}"#
        )),
        one(r#"{"op": "wck.program.upload", "id": 0, "program": "move 300 torque 0"}"#),
        vec![
            format!(
                r#"{{"op": "wck.program.upload", "id": 1, "program": "{PROGRAM}", "confirm": true}}"#
            ),
            r#"{"op": "wck.program.download", "id": 1}"#.to_owned(),
        ],
        one(r#"{"op": "wck.program.download", "id": 7}"#),
        one(&format!(
            r#"{{"op": "wck.program.check", "program": "{PROGRAM}"}}"#
        )),
        one(&format!(
            r#"{{"op": "wck.program.check", "id": 3, "bus": "wck", "program": "{PROGRAM}"}}"#
        )),
        one(r#"{"op": "wck.program.check", "program": "move 300 torque 0"}"#),
        one(r#"{"op": "wck.teach", "ids": "0-1", "rate_hz": 10, "duration": 0.25, "torque": 2}"#),
        one(
            r#"{"op": "wck.teach", "ids": "0-1", "rate_hz": 10, "duration": 0.25, "on_stop": "hold"}"#,
        ),
        one(r#"{"op": "wck.teach", "ids": "0-1", "pose_ms": 700000}"#),
        one(r#"{"op": "wck.teach", "ids": "1-2", "duration": 0.2}"#),
        one(r#"{"op": "wck.teach", "ids": "0-3", "rate_hz": 10, "duration": 0.25}"#),
        one(r#"{"op": "wck.teach", "ids": "0-2,7", "duration": 0.2}"#),
        one(&format!(
            r#"{{"op": "wck.play", "motion": "{MOTION}", "rate_hz": 25}}"#
        )),
        one(r#"{"op": "wck.play", "motion": "pose 100 300\n"}"#),
        one(r#"{"op": "wck.play", "motion": "pose 100 100 100 100 100 100 100 100\n"}"#),
        one(r#"{"op": "wck.sample", "ids": "0-1,7"}"#),
        one(r#"{"op": "wck.tune", "id": 1, "gains": [[20, 30], [2, 0]], "hold_ms": 200}"#),
        one(
            r#"{"op": "wck.tune", "id": 1, "gains": [[20, 30]], "hold_ms": 200, "keep": "eeprom"}"#,
        ),
        one(
            r#"{"op": "wck.tune", "id": 1, "gains": [[20, 30]], "hold_ms": 200, "keep": "runtime"}"#,
        ),
        one(r#"{"op": "wck.tune", "id": 7, "gains": [[20, 30]], "hold_ms": 200}"#),
        one(r#"{"op": "wck.backup", "id": 0}"#),
        one(r#"{"op": "wck.backup", "id": 7}"#),
        one(r#"{"op": "wck.diff", "id": 0, "factory": true}"#),
        vec![
            r#"{"op": "wck.set", "param": "gains", "id": 1, "p": 40, "d": 20, "confirm": true}"#
                .to_owned(),
            r#"{"op": "wck.diff", "id": 0, "other": 1}"#.to_owned(),
        ],
        one(r#"{"op": "wck.diff", "id": 0, "other": 0}"#),
        one(r#"{"op": "wck.diff", "id": 0}"#),
        vec![
            r#"{"op": "wck.set", "param": "gains", "id": 0, "p": 40, "d": 20, "confirm": true}"#
                .to_owned(),
            r#"{"op": "wck.restore", "id": 0, "factory": true, "confirm": true}"#.to_owned(),
        ],
        one(r#"{"op": "wck.restore", "id": 0, "factory": true}"#),
        one(r#"{"op": "wck.restore", "id": 0}"#),
    ]
}

/// The plan and the report (or their errors) of the case's last request, after the ones
/// before it, on a fresh station.
fn outcome_of(case: &[String]) -> Value {
    let (s, _w, _j) = station_support::station("wck", "whj");
    let mut last = Value::Null;
    for text in case {
        let r = Request::parse(text).unwrap();
        let plan = catalogue::plan(&r).map_or_else(|e| error(&e), |p| json!(p));
        let report = report_of(&s, &r);
        last = json!({"plan": plan, "report": report});
    }
    last
}

fn outcomes() -> BTreeMap<String, Value> {
    cases()
        .iter()
        .map(|case| (case.join(" then "), outcome_of(case)))
        .collect()
}

#[test]
fn the_wck_run_reports_and_plans_are_the_pinned_json() {
    assert_pinned("wck_run_reports", &outcomes());
}
