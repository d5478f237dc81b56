//! Every operation's report against the published report schema (`robobus schema report`):
//! each registered operation runs on the built-in simulated robot (answering devices and a
//! silent one where it takes IDs, failures as well as successes), and every report is
//! valid under the schema of its own operation: a client generated from the schema accepts
//! what the catalogue returns. So is every report the other report tests pin
//! (`tests/snapshots/*.json`, each checked against a run there).

#![allow(clippy::result_large_err)]

use crate::common;

use std::collections::BTreeSet;

use robobus::catalogue::{self, Request};
use robobus::ops::{Control, StopToken};
use robobus::station::Station;
use serde_json::Value;

const PROGRAM: &str = "move 82 torque 0\\ndelay 266ms\\nmove 172 torque 0\\ndelay 266ms\\n";

/// One case per line: requests run in order on one fresh simulated station; every report
/// is checked (a request that fails as a whole is a test failure unless it is the last
/// and marked `!`).
fn cases() -> Vec<Vec<String>> {
    let trajectory = "time_s,j1,j2\\n0,0,0\\n0.2,1,1\\n";
    let raw: Vec<Vec<String>> = vec![
        vec![r#"{"op":"wck.scan","ids":"0-2,20"}"#.into()],
        vec![r#"{"op":"wck.status","ids":"0-2,20"}"#.into()],
        vec![r#"{"op":"wck.move","id":0,"position":120}"#.into()],
        vec![r#"{"op":"wck.move","id":20,"position":120}"#.into()],
        vec![r#"{"op":"wck.move10","id":0,"position":500}"#.into()],
        vec![r#"{"op":"wck.read10","id":0}"#.into()],
        vec![r#"{"op":"wck.sync-move","positions":[120,130]}"#.into()],
        vec![r#"{"op":"wck.passive","ids":"0,20"}"#.into()],
        vec![r#"{"op":"wck.wheel","id":1,"direction":"ccw","speed":3,"duration":0.2}"#.into()],
        vec![r#"{"op":"wck.brake"}"#.into()],
        vec![r#"{"op":"wck.get","param":"gains","id":0}"#.into()],
        vec![r#"{"op":"wck.get","param":"io","id":0}"#.into()],
        vec![r#"{"op":"wck.set","param":"gains","id":0,"p":20,"d":10,"runtime":true}"#.into()],
        vec![r#"{"op":"wck.set","param":"bounds","id":0,"lower":10,"upper":240,"confirm":true}"#.into()],
        vec![r#"{"op":"wck.set-id","id":2,"new_id":9,"confirm":true}"#.into()],
        vec![r#"{"op":"wck.set-baud","id":2,"rate":115200,"confirm":true}"#.into()],
        vec![format!(r#"{{"op":"wck.program.upload","id":0,"program":"{PROGRAM}","confirm":true}}"#)],
        vec![r#"{"op":"wck.program.download","id":0}"#.into()],
        vec![format!(r#"{{"op":"wck.program.check","program":"{PROGRAM}"}}"#)],
        vec![r#"{"op":"wck.teach","ids":"0-1","rate_hz":10,"duration":0.3}"#.into()],
        vec![r#"{"op":"wck.play","motion":"torque 1\npose 100 100 140\nhold 40\npose 100 127 127\n"}"#.into()],
        vec![r#"{"op":"wck.sample","ids":"0-1,20"}"#.into()],
        vec![r#"{"op":"wck.tune","id":3,"gains":[[20,30],[2,0]],"hold_ms":200}"#.into()],
        vec![r#"{"op":"wck.backup","id":0}"#.into()],
        vec![r#"{"op":"wck.diff","id":0,"factory":true}"#.into()],
        vec![r#"{"op":"wck.diff","id":0,"other":1}"#.into()],
        vec![r#"{"op":"wck.restore","id":0,"factory":true,"confirm":true}"#.into()],
        vec![r#"{"op":"whj.scan","joints":"1-3"}"#.into()],
        vec![r#"{"op":"whj.info","joint":1}"#.into()],
        vec![r#"{"op":"whj.status","joints":"1-2,9"}"#.into()],
        vec![r#"{"op":"whj.status","joints":"1-2","broadcast":true}"#.into()],
        vec![r#"{"op":"whj.enable","joints":"1,9"}"#.into()],
        vec![r#"{"op":"whj.disable","joints":"1"}"#.into()],
        vec![r#"{"op":"whj.mode","joints":"1","mode":"position"}"#.into()],
        vec![
            r#"{"op":"whj.mode","joints":"1","mode":"position"}"#.into(),
            r#"{"op":"whj.enable","joints":"1"}"#.into(),
            r#"{"op":"whj.move","joint":1,"degrees":2,"max_speed":20}"#.into(),
        ],
        vec![
            r#"{"op":"whj.mode","joints":"1","mode":"speed"}"#.into(),
            r#"{"op":"whj.enable","joints":"1"}"#.into(),
            r#"{"op":"whj.speed","joint":1,"rpm":1,"duration":0.1}"#.into(),
        ],
        vec![
            r#"{"op":"whj.mode","joints":"1","mode":"current"}"#.into(),
            r#"{"op":"whj.enable","joints":"1"}"#.into(),
            r#"{"op":"whj.current","joint":1,"milliamps":100,"duration":0.1}"#.into(),
        ],
        vec![r#"{"op":"whj.zero","joint":1}"#.into()],
        vec![r#"{"op":"whj.clear","joints":"1,9"}"#.into()],
        vec![r#"{"op":"whj.save","joints":"1","confirm":true}"#.into()],
        vec![r#"{"op":"whj.read","joints":"1","register":"SYS_ID","count":2}"#.into()],
        vec![r#"{"op":"whj.read","joints":"1-2","register":"SYS_ID","broadcast":true}"#.into()],
        vec![r#"{"op":"whj.write","joints":"1","register":"SYS_ID","value":12,"confirm":true}"#.into()],
        vec![r#"{"op":"whj.registers"}"#.into()],
        vec![r#"{"op":"whj.set-id","joint":2,"new_id":12,"confirm":true}"#.into()],
        vec![
            r#"{"op":"whj.mode","joints":"1","mode":"position"}"#.into(),
            r#"{"op":"whj.enable","joints":"1"}"#.into(),
            r#"{"op":"whj.wave","joint":1,"amplitude":1,"duration":0.5}"#.into(),
        ],
        vec![r#"{"op":"whj.release-iap","joints":"1,9"}"#.into()],
        vec![r#"{"op":"whj.sample","joints":"1-2,9"}"#.into()],
        vec![r#"{"op":"whj.sample","joints":"1-2","broadcast":true}"#.into()],
        vec![r#"{"op":"whj.backup","joint":1}"#.into()],
        vec![r#"{"op":"whj.defaults","joint":1}"#.into()],
        vec![r#"{"op":"whj.end-board","action":"status"}"#.into()],
        vec![r#"{"op":"whj.set-rates","joints":"1","bitrate":1000000,"dbitrate":5000000,"confirm":true}"#.into()],
        vec![r#"{"op":"whj.can-health"}"#.into()],
        vec![r#"{"op":"whj.diff","joint":1,"other":2}"#.into()],
        vec![
            r#"{"op":"whj.backup","joint":2}"#.into(),
            r#"{"op":"whj.disable","joints":"1"}"#.into(),
            r#"{"op":"whj.restore","joint":1,"settings":SETTINGS,"confirm":true}"#.into(),
        ],
        vec![r#"{"op":"robot.sample"}"#.into()],
        vec![r#"{"op":"robot.calibrate","seconds":0.3}"#.into()],
        vec![r#"{"op":"robot.teach","seconds":0.3,"confirm":true}"#.into()],
        vec![
            r#"{"op":"whj.mode","joints":"1-2","mode":"position"}"#.into(),
            r#"{"op":"whj.enable","joints":"1-2"}"#.into(),
            format!(r#"{{"op":"robot.play","trajectory":"{trajectory}"}}"#),
        ],
        vec![r#"{"op":"robot.teleop","seconds":0.3,"map":[{"leader":"s0","follower":"s4"}]}"#.into()],
        vec![r#"{"op":"host.ports"}"#.into()],
    ];
    raw
}

fn run(station: &Station, request: &Request) -> Result<catalogue::Report, robobus::ops::OpError> {
    let stop = StopToken::new();
    catalogue::run(station, request, &mut Control::new(&stop))
}

#[test]
fn every_operations_report_is_valid_under_its_own_schema() {
    let schema = catalogue::report_schema();
    let validator = jsonschema::validator_for(&schema).unwrap();
    let mut covered = BTreeSet::new();
    let mut problems = Vec::new();
    for case in cases() {
        let station = Station::simulated().unwrap();
        let mut last_settings = Value::Null;
        for text in &case {
            let text = &common::reports::with_settings(text, &last_settings);
            let request = Request::parse(text).unwrap_or_else(|e| panic!("{text}: {e}"));
            let report = match run(&station, &request) {
                Ok(r) => r,
                Err(e) => {
                    problems.push(format!("{text}: failed as a whole: {e}"));
                    continue;
                }
            };
            if request.op() == "whj.backup" {
                last_settings = report.summary.clone().unwrap_or_default();
            }
            let json = serde_json::to_value(&report).unwrap();
            let errors: Vec<String> = validator
                .iter_errors(&json)
                .map(|e| e.to_string())
                .collect();
            if !errors.is_empty() {
                problems.push(format!("{text}: {errors:?}\n  report: {json}"));
            }
            covered.insert(request.op().to_owned());
        }
        station.leave();
    }
    assert_eq!(problems, Vec::<String>::new());
    let all: BTreeSet<String> = catalogue::operations()
        .iter()
        .map(|o| o.op.to_owned())
        .collect();
    let missing: Vec<&String> = all.iter().filter(|o| !covered.contains(*o)).collect();
    assert_eq!(missing, Vec::<&String>::new(), "operations without a case");
}

#[test]
fn every_report_the_report_tests_pin_is_valid_under_its_operations_schema() {
    let all = catalogue::report_schema();
    let pinned = common::reports::pinned_reports();
    let problems: Vec<String> = pinned
        .iter()
        .filter_map(|(case, report)| {
            let errors = common::reports::schema_errors(&all, report);
            (!errors.is_empty()).then(|| format!("{case}: {errors:?}\n  report: {report}"))
        })
        .collect();
    assert_eq!(problems, Vec::<String>::new());
    // The four pinned suites, each with its reports (not only refusals).
    let files: BTreeSet<&str> = pinned
        .iter()
        .filter_map(|(case, _)| case.split_once(": ").map(|(file, _)| file))
        .collect();
    let want = [
        "wck_reports.json",
        "wck_run_reports.json",
        "whj_config_reports.json",
        "whj_reports.json",
    ];
    assert_eq!(files, BTreeSet::from(want));
}
