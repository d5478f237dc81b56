//! The wCK operations' reports through the catalogue: for each operation that runs one
//! exchange per packet (scan, status, move, move10, read10, sync-move, passive, wheel,
//! brake, get, set, set-id) the exact JSON of its report on the simulated bus (pinned in
//! `tests/snapshots/wck_reports.json`: `UPDATE_SNAPSHOTS=1` rewrites it), and that the
//! published report schema describes it: each operation's rows are its own typed fields
//! (that every pinned report validates against its operation's schema:
//! `report_schema.rs`). On the virtual clock.

#![allow(clippy::unwrap_used, clippy::panic)]

use crate::common;
use crate::station_support;

use std::collections::BTreeMap;

use robobus::catalogue::args::Ids;
use robobus::catalogue::{self, ErrorKind, NoInteraction, Request, wck};
use robobus::ops::wck::reply_fields;
use robobus::ops::{Control, Outcome};
use robobus::station::Station;
use robobus::wck::WckBus;
use robobus_link::ByteLink as _;
use robobus_sim::wck::{Bus, BusConfig, Faults, Model, SimLink};
use robobus_wck::{BaudRate, Command};
use serde_json::Value;

use common::reports::{assert_pinned, assert_schema_names, schema_errors};

/// One request per row shape of the operations (and a silent servo, and a refusal).
const REQUESTS: &[&str] = &[
    r#"{"op": "wck.scan", "ids": "0-3"}"#,
    r#"{"op": "wck.status", "ids": "0-3"}"#,
    r#"{"op": "wck.move", "id": 1, "position": 200, "torque": 2}"#,
    r#"{"op": "wck.move", "id": 7, "position": 20}"#,
    r#"{"op": "wck.move10", "id": 1, "position": 700, "torque": 3}"#,
    r#"{"op": "wck.read10", "id": 2}"#,
    r#"{"op": "wck.sync-move", "positions": [10, 20, 30], "torque": 1}"#,
    r#"{"op": "wck.passive", "ids": "1-2"}"#,
    r#"{"op": "wck.wheel", "id": 1, "direction": "ccw", "speed": 5}"#,
    r#"{"op": "wck.wheel", "id": 1, "direction": "cw", "speed": 3, "duration": 0.5}"#,
    r#"{"op": "wck.wheel", "id": 2, "direction": "cw", "speed": 3, "duration": 0.3, "on_stop": "passive"}"#,
    r#"{"op": "wck.wheel", "id": 2, "direction": "cw", "speed": 3, "duration": 0.3, "on_stop": "break"}"#,
    r#"{"op": "wck.brake"}"#,
    r#"{"op": "wck.get", "param": "gains", "id": 0}"#,
    r#"{"op": "wck.get", "param": "i-gain", "id": 0}"#,
    r#"{"op": "wck.get", "param": "speed", "id": 0}"#,
    r#"{"op": "wck.get", "param": "overload", "id": 0}"#,
    r#"{"op": "wck.get", "param": "bounds", "id": 0}"#,
    r#"{"op": "wck.get", "param": "io", "id": 0}"#,
    r#"{"op": "wck.get", "param": "io", "id": 9}"#,
    r#"{"op": "wck.set", "param": "gains", "id": 1, "p": 10, "d": 5, "confirm": true}"#,
    r#"{"op": "wck.set", "param": "gains", "id": 1, "p": 10, "d": 5, "runtime": true}"#,
    r#"{"op": "wck.set", "param": "i-gain", "id": 1, "i": 3, "confirm": true}"#,
    r#"{"op": "wck.set", "param": "i-gain", "id": 1, "i": 3, "runtime": true}"#,
    r#"{"op": "wck.set", "param": "speed", "id": 1, "speed": 12, "accel": 40, "confirm": true}"#,
    r#"{"op": "wck.set", "param": "speed", "id": 1, "speed": 12, "accel": 40, "runtime": true}"#,
    r#"{"op": "wck.set", "param": "overload", "id": 1, "milliamps": 800, "confirm": true}"#,
    r#"{"op": "wck.set", "param": "bounds", "id": 1, "lower": 10, "upper": 240, "confirm": true}"#,
    r#"{"op": "wck.set", "param": "io", "id": 1, "outputs": 3}"#,
    r#"{"op": "wck.set-id", "id": 2, "new_id": 9, "confirm": true}"#,
];

fn reports() -> BTreeMap<String, Value> {
    REQUESTS
        .iter()
        .map(|json| {
            let (s, _w, _j) = station_support::station("wck", "whj");
            let report = common::reports::last_report(&s, &[*json]);
            ((*json).to_owned(), report)
        })
        .collect()
}

#[test]
fn the_wck_reports_are_the_pinned_json() {
    assert_pinned("wck_reports", &reports());
}

/// A Rust front end gets the rows as the operations' own types (`run_typed`): a status
/// row's `position`, a parameter's `ParamRow` variant, a silent servo's failure.
#[test]
fn a_rust_front_end_gets_the_wck_rows_as_types() {
    let (s, _w, _j) = station_support::station("wck", "whj");
    let status = wck::Status {
        bus: None,
        ids: Ids::Text("0-1,7".into()),
    };
    let r = catalogue::run_typed(&s, &status, &mut Control::none(), &mut NoInteraction).unwrap();
    let rows: Vec<(u8, Option<u8>)> = r
        .results
        .iter()
        .map(|d| match &d.outcome {
            Outcome::Ok(row) => (d.id, Some(row.position)),
            Outcome::Failed(f) => (d.id, (f.kind == ErrorKind::NoDevice).then_some(0)),
        })
        .collect();
    assert_eq!(rows, [(0, Some(127)), (1, Some(127)), (7, Some(0))]);
    assert_eq!(r.failed, Some(ErrorKind::NoDevice));
    let get = wck::Get {
        bus: None,
        param: wck::Param::Gains,
        id: 0,
    };
    let r = catalogue::run_typed(&s, &get, &mut Control::none(), &mut NoInteraction).unwrap();
    assert_eq!(
        r.results[0].outcome,
        Outcome::Ok(wck::ParamRow::Gains {
            p_gain: 20,
            d_gain: 30
        })
    );
}

/// A break whose reply comes back garbled (on a shared bus: the modules' replies
/// collided; here one module's reply bytes have a bit flipped each) is the row
/// `reply_fields` made of it: `"reply"` collided and what that `"meaning"`s, no failure
/// (the command was heard).
#[test]
fn a_garbled_break_reply_is_the_collided_row_and_no_failure() {
    let config = BusConfig {
        seed: SEED,
        faults: Faults {
            flip_reply: 1.0,
            ..Faults::default()
        },
        ..BusConfig::default()
    };
    let (mut link, sim) = SimLink::virtual_clock(Bus::with_servos(config, Model::W1108, 0..1));
    let now = link.now();
    link.sleep_until(now + std::time::Duration::from_millis(100));
    let bus = WckBus::new(
        Box::new(link) as robobus::robot::DynByteLink,
        BaudRate::B115200,
    )
    .unwrap();
    let mut s = Station::new();
    s.add_wck("wck", bus);
    s.keep(Box::new(std::sync::Mutex::new(sim)));
    let r = catalogue::run(
        &s,
        &Request::parse(r#"{"op": "wck.brake"}"#).unwrap(),
        &mut Control::none(),
    )
    .unwrap();
    let mut want = serde_json::to_value(reply_fields(&Command::Break, None)).unwrap();
    want["id"] = "all".into();
    assert_eq!(r.results, [want], "{r:?}");
    assert_eq!((r.failed, r.error.as_deref()), (None, None));
    // Its operation's schema describes this row too.
    let report = serde_json::to_value(&r).unwrap();
    let errors = schema_errors(&catalogue::report_schema(), &report);
    assert!(errors.is_empty(), "{errors:?}\n{report}");
}

/// A seed whose bit flips make the break's reply implausible (an ID past 30 or the
/// position 255).
const SEED: u64 = 3;

/// Each operation's rows are its own type: its schema (and what it refers to) names their
/// fields (a row of JSON values would accept anything). That every report is valid under
/// its schema: `report_schema.rs`, over these pinned reports too.
#[test]
fn the_report_schema_names_each_wck_operations_row_fields() {
    assert_schema_names(
        &catalogue::report_schema(),
        &[
            ("wck.scan", &["baud", "bauds_tried", "duplicates"][..]),
            ("wck.status", &["load", "position", "degrees"]),
            (
                "wck.move",
                &["target_position", "load_before", "degrees_before"],
            ),
            ("wck.move10", &["target_position10", "position10_before"]),
            ("wck.read10", &["position10"]),
            ("wck.sync-move", &["positions", "reply"]),
            ("wck.passive", &["position", "degrees"]),
            (
                "wck.wheel",
                &["rotations", "ran_ms", "stopped_at", "stopped_load"],
            ),
            ("wck.brake", &["answered_by", "meaning"]),
            (
                "wck.get",
                &["p_gain", "overload_code", "adc_volts", "lower_degrees"],
            ),
            ("wck.set", &["i_gain", "milliamps", "do1", "accel"]),
            ("wck.set-id", &["new_id"]),
        ],
    );
}
