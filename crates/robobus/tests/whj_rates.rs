//! `whj.set-rates` end to end on the simulator, whose bit rates are real: a joint talks at
//! the rates it took from flash at power-up and hears nothing on a bus at others. The
//! change is written, read back and saved; the joints answer at the old rates until they
//! are power-cycled, then only once the bus (the adapter) is at the new rates.

#![allow(clippy::unwrap_used, clippy::result_large_err)] // tests

use crate::whj_common;

use robobus::catalogue::{self, Request};
use robobus::ops::{Control, ErrorKind};
use robobus::station::Station;
use robobus_whj::timing::BitRates;
use serde_json::{Value, json};
use whj_common::{sim_link, virtual_config};

fn run(station: &Station, v: Value) -> Result<Value, robobus::ops::OpError> {
    let request: Request = serde_json::from_value(v).unwrap();
    catalogue::run(station, &request, &mut Control::none())
        .map(|r| serde_json::to_value(r).unwrap())
}

#[test]
fn new_bit_rates_take_at_power_up_and_the_joints_then_answer_only_there() {
    let (link, sim) = sim_link(robobus_sim::whj::WhjBus::chain(
        1..=2,
        robobus_sim::whj::WhjModel::Whj30,
        5,
    ));
    // The simulated joints as if behind a SocketCAN adapter on can0.
    let mut station = Station::new();
    station.add_whj_at(
        "can0",
        robobus::whj::JointBus::open_with(link, virtual_config()).unwrap(),
    );
    let change =
        json!({"op": "whj.set-rates", "joints": "1-2", "bitrate": 500_000, "dbitrate": 2_000_000});
    // Confirmation first; bad pairs are refused naming the option.
    assert_eq!(
        run(&station, change.clone()).unwrap_err().kind(),
        ErrorKind::Refused
    );
    for (b, d, says) in [
        (750_000, 2_000_000, "--bitrate"),
        (500_000, 3_000_000, "--dbitrate"),
        (1_000_000, 500_000, "at least"),
    ] {
        let bad = json!({"op": "whj.set-rates", "joints": "1", "bitrate": b, "dbitrate": d});
        let request: Request = serde_json::from_value(bad).unwrap();
        let e = catalogue::validate(&request).unwrap_err().to_string();
        assert!(e.contains(says), "{e}");
    }
    // An enabled joint (they enable at power-up) is refused: flash is written only while
    // it is disabled.
    run(&station, json!({"op": "whj.disable", "joints": "1"})).unwrap();
    let mut yes = change;
    yes["confirm"] = json!(true);
    let r = run(&station, yes.clone()).unwrap();
    assert_eq!(
        r["results"][0]["after"],
        json!([500_000, 2_000_000]),
        "{r:#}"
    );
    assert_eq!(
        r["results"][0]["before"],
        json!([1_000_000, 5_000_000]),
        "{r:#}"
    );
    assert_eq!(r["results"][1]["kind"], "refused", "{r:#}");
    assert!(
        r["summary"]["next"]
            .as_str()
            .unwrap()
            .contains("type can bitrate 500000 sample-point 0.8 dbitrate 2000000"),
        "{r:#}"
    );
    run(&station, json!({"op": "whj.disable", "joints": "2"})).unwrap();
    let r = run(&station, yes).unwrap();
    assert_eq!(r["failed"], Value::Null, "{r:#}");

    // Until a power cycle they still answer at the old rates.
    let info = run(&station, json!({"op": "whj.status", "joints": "1-2"})).unwrap();
    assert_eq!(info["failed"], Value::Null, "{info:#}");
    sim.with_bus(|b| {
        let now = b.now();
        for id in 1..=2 {
            b.joint_mut(id).unwrap().power_cycle(now);
        }
    });
    // Past their power-up (simulated time runs while the client waits on its bus).
    let port = station.whj(None).unwrap();
    port.bus()
        .sleep_until(port.bus().now() + std::time::Duration::from_secs(3));
    // The bus is still at 1 / 5 Mbit/s: they are silent.
    let lost = run(&station, json!({"op": "whj.status", "joints": "1-2"})).unwrap();
    assert_eq!(lost["failed"], "no-device", "{lost:#}");
    // The adapter follows: at 500 k / 2 M they answer, and read their new rates.
    sim.with_bus(|b| b.set_rates(BitRates::new(500_000, 2_000_000).unwrap()));
    for j in [1, 2] {
        let back = run(
            &station,
            json!({"op": "whj.read", "joints": j.to_string(), "register": "SYS_BPS_CANFD_BRT", "count": 2}),
        )
        .unwrap();
        assert_eq!(back["failed"], Value::Null, "{back:#}");
        let raw: Vec<u64> = back["results"]
            .as_array()
            .unwrap()
            .iter()
            .map(|r| r["raw"].as_u64().unwrap())
            .collect();
        assert_eq!(raw, [1, 3], "{back:#}");
    }
}

#[test]
fn a_bus_without_a_can_controller_has_no_can_health() {
    let (link, _sim) = sim_link(robobus_sim::whj::WhjBus::chain(
        1..=1,
        robobus_sim::whj::WhjModel::Whj30,
        5,
    ));
    let mut station = Station::new();
    station.add_whj(
        "sim",
        robobus::whj::JointBus::open_with(link, virtual_config()).unwrap(),
    );
    let r = run(&station, json!({"op": "whj.can-health"})).unwrap();
    let row = &r["results"][0];
    assert_eq!(
        (row["id"].as_str(), row["state"].is_null()),
        (Some("sim"), true),
        "{r:#}"
    );
    assert!(
        row["advice"]
            .as_str()
            .unwrap()
            .contains("no CAN controller"),
        "{r:#}"
    );
    assert_eq!(r["failed"], Value::Null, "{r:#}");
    // A telemetry stream takes it (read-only), as it takes the other readings.
    let request: Request = serde_json::from_value(json!({"op": "whj.can-health"})).unwrap();
    assert_eq!(request.effect(), robobus::catalogue::Effect::Read);
}

#[test]
fn on_the_simulated_robot_the_next_steps_name_the_simulator_not_an_adapter() {
    let station = Station::simulated().unwrap();
    run(&station, json!({"op": "whj.disable", "joints": "1"})).unwrap();
    let r = run(
        &station,
        json!({"op": "whj.set-rates", "joints": "1", "bitrate": 500_000,
               "dbitrate": 2_000_000, "confirm": true}),
    )
    .unwrap();
    assert_eq!(r["failed"], Value::Null, "{r:#}");
    let next = r["summary"]["next"].as_str().unwrap();
    assert!(
        next.contains("robobus sim whj --bitrate 500000 --dbitrate 2000000"),
        "{next}"
    );
    assert!(!next.contains("ip link"), "{next}");
}
