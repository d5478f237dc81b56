//! `whj.end-board` through the catalogue against the simulator's end board, on its
//! virtual clock: the state, the tool power switched and read back (asking for
//! confirmation to switch it on, not off), a digital channel's direction shown in the
//! status bits, the force sensor's six values, and a silent board reported as no device.

#![allow(clippy::unwrap_used, clippy::result_large_err)] // tests

use crate::whj_common;

use robobus::catalogue::{self, Request};
use robobus::ops::{Control, ErrorKind};
use robobus::station::Station;
use serde_json::{Value, json};
use whj_common::{sim_link, virtual_config};

fn station(end_board: bool) -> (Station, robobus_sim::whj::WhjSimHandle) {
    let mut bus = robobus_sim::whj::WhjBus::chain(1..=2, robobus_sim::whj::WhjModel::Whj30, 5);
    if end_board {
        bus = bus.with_end_board();
    }
    let (link, sim) = sim_link(bus);
    let mut station = Station::new();
    station.add_whj(
        "arm",
        robobus::whj::JointBus::open_with(link, virtual_config()).unwrap(),
    );
    (station, sim)
}

fn run(station: &Station, v: Value) -> Result<Value, robobus::ops::OpError> {
    let request: Request = serde_json::from_value(v).unwrap();
    catalogue::run(station, &request, &mut Control::none())
        .map(|r| serde_json::to_value(r).unwrap())
}

#[test]
fn the_end_board_is_read_switched_and_verified() {
    let (station, _sim) = station(true);
    let s = run(&station, json!({"op": "whj.end-board", "action": "status"})).unwrap();
    let row = &s["results"][0];
    assert_eq!(row["id"], "end-board", "{s:#}");
    assert_eq!(
        (row["tool_volts"].as_u64(), row["io1_output"].as_bool()),
        (Some(0), Some(false)),
        "{row}"
    );

    // Switching the tool power on needs confirmation; nothing is sent without it.
    let on = json!({"op": "whj.end-board", "action": "power", "volts": 24});
    let request: Request = serde_json::from_value(on.clone()).unwrap();
    assert!(
        catalogue::confirmation(&request)
            .unwrap()
            .unwrap()
            .contains("attached to the tool")
    );
    assert_eq!(
        run(&station, on.clone()).unwrap_err().kind(),
        ErrorKind::Refused
    );
    let mut yes = on;
    yes["confirm"] = json!(true);
    let r = run(&station, yes).unwrap();
    assert_eq!(r["results"][0]["read_back"], 3, "{r:#}");
    assert_eq!(r["results"][0]["meaning"], "tool power 24 V");
    let s = run(&station, json!({"op": "whj.end-board", "action": "status"})).unwrap();
    assert_eq!(s["results"][0]["tool_volts"], 24);
    // Off is the safe direction: no confirmation.
    let off = json!({"op": "whj.end-board", "action": "power", "volts": 0});
    assert_eq!(run(&station, off).unwrap()["results"][0]["read_back"], 0);

    // Channel 1 an output: the board's status bits say so.
    let io = json!({"op": "whj.end-board", "action": "io", "channel": 1, "mode": "output", "confirm": true});
    assert_eq!(run(&station, io).unwrap()["results"][0]["read_back"], 1);
    let s = run(&station, json!({"op": "whj.end-board", "action": "status"})).unwrap();
    assert_eq!(s["results"][0]["io1_output"], true, "{s:#}");

    let f = run(&station, json!({"op": "whj.end-board", "action": "force"})).unwrap();
    let row = &f["results"][0];
    for k in ["fx", "fy", "fz", "mx", "my", "mz"] {
        assert!(row[k].is_i64(), "{row}");
    }

    // Bad values are refused before anything is sent, naming the option.
    for (v, says) in [
        (
            json!({"op": "whj.end-board", "action": "power", "volts": 5}),
            "--volts",
        ),
        (json!({"op": "whj.end-board", "action": "power"}), "--volts"),
        (
            json!({"op": "whj.end-board", "action": "io", "channel": 3, "mode": "input"}),
            "--channel",
        ),
        (
            json!({"op": "whj.end-board", "action": "io", "channel": 1}),
            "--mode",
        ),
    ] {
        let request: Request = serde_json::from_value(v).unwrap();
        let e = catalogue::validate(&request).unwrap_err();
        assert_eq!(e.kind(), ErrorKind::BadInput, "{e}");
        assert!(e.to_string().contains(says), "{e}");
    }
}

#[test]
fn a_silent_end_board_is_no_device() {
    let (station, _sim) = station(false);
    let s = run(&station, json!({"op": "whj.end-board", "action": "status"})).unwrap();
    assert_eq!(s["failed"], "no-device", "{s:#}");
    assert!(
        s["results"][0]["error"]
            .as_str()
            .unwrap()
            .starts_with("end board: no reply"),
        "{s:#}"
    );
}
