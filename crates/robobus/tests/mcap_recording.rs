//! MCAP recordings of the simulated robot, written to a file and decoded: their
//! `/joint_states` name the joints as the bridge and the studio do (the robot file's
//! names; a device by ID as the built-in robot names it) and carry the torque the bridge
//! publishes as the effort, not `NaN`.

#![allow(clippy::unwrap_used, clippy::panic, clippy::float_cmp)] // tests

use std::sync::Arc;
use std::time::{Duration, Instant};

use robobus::catalogue::Request;
use robobus::catalogue::telemetry::Telemetry;
use robobus::cdr::JointState;
use robobus::record::{JOINT_STATES_TOPIC, Recorder, SampleTable};
use robobus::robot::simulated::SimArm;
use robobus::station::Station;
use robobus::station::sampler::monitored_joints;
use robobus_whj::JointId;

/// `table`'s latest sample recorded to an MCAP file, read back: its joint states.
fn record_and_decode(table: &SampleTable) -> Vec<JointState> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mcap");
    let mut rec = Recorder::create(&path, "simulated robot", table).unwrap();
    rec.record(table).unwrap();
    rec.finish().unwrap();
    let bytes = std::fs::read(&path).unwrap();
    mcap::MessageStream::new(&bytes)
        .unwrap()
        .map(Result::unwrap)
        .filter(|m| m.channel.topic == JOINT_STATES_TOPIC)
        .map(|m| JointState::decode(&m.data).unwrap())
        .collect()
}

#[test]
fn a_recording_of_the_robot_names_joints_and_gives_efforts_as_the_bridge_publishes_them() {
    let station = Arc::new(Station::simulated().unwrap());
    let config = station.robot().unwrap();
    let joints = monitored_joints(config);
    let mut table = SampleTable::robot(joints.iter().map(|j| (j.name.as_str(), j.wck)));
    let request = Request::parse_many(r#"{"op": "robot.sample"}"#)
        .unwrap()
        .remove(0);
    let t = Telemetry::paused(&station, request, 50.0, Some(1)).unwrap();
    let sub = t.subscribe(4).unwrap();
    t.resume();
    assert_eq!(t.join().samples, 1);
    let delivery = sub.recv_timeout(Duration::from_secs(5)).unwrap();
    table.take(&delivery, 0.0).unwrap();
    let states = record_and_decode(&table);
    assert_eq!(states.len(), 1);
    let state = &states[0];
    // The built-in robot's names, in its file's order: what the bridge's joint states say
    // (each row's `id` of the robot sample).
    let mut names: Vec<String> = (0..16).map(|i| format!("s{i}")).collect();
    names.extend((1..=7).map(|i| format!("j{i}")));
    assert_eq!(state.name, names);
    let report = delivery.sample.report.as_ref().unwrap();
    let ids: Vec<&str> = report
        .results
        .iter()
        .map(|r| r["id"].as_str().unwrap())
        .collect();
    assert_eq!(state.name, ids);
    // The effort: the robot sample's `effort_nm`, the bridge's effort, for every WHJ
    // joint (the simulated WHJ30s are identified); NaN for a wCK servo (a load is not a
    // torque).
    for ((name, effort), row) in state.name.iter().zip(&state.effort).zip(&report.results) {
        if name.starts_with('s') {
            assert!(effort.is_nan(), "{name}: {effort}");
            assert!(row.get("effort_nm").is_none_or(serde_json::Value::is_null));
        } else {
            let published = row["effort_nm"].as_f64();
            assert_eq!(Some(*effort), published, "{name}: {row}");
        }
    }
}

#[test]
fn a_recording_of_the_simulated_arm_names_its_joints_as_the_robot_file_and_estimates_torque() {
    // `robobus monitor --sim --record run.mcap`: the arm's joints by ID.
    let ids = [JointId::new(1).unwrap(), JointId::new(2).unwrap()];
    let arm = SimArm::start(&ids).unwrap();
    let constants = arm.torque_constants();
    assert!(constants.iter().all(Option::is_some), "{constants:?}");
    let mut table = SampleTable::whj(&[1, 2]).with_torque_constants(&constants);
    let deadline = Instant::now() + Duration::from_secs(10);
    let report = loop {
        if let Some(r) = arm.sample()
            && r.feedback.iter().all(Option::is_some)
        {
            break r;
        }
        assert!(Instant::now() < deadline, "no cycle with both joints");
        std::thread::sleep(Duration::from_millis(10));
    };
    table.take_cycle(Some(&report), 0.0);
    let states = record_and_decode(&table);
    let state = &states[0];
    // The names the built-in robot's file gives WHJ joints 1 and 2 on its arm.
    let station = Station::simulated().unwrap();
    let file_names: Vec<&str> = ids
        .iter()
        .map(|id| {
            station
                .robot()
                .unwrap()
                .joints
                .iter()
                .find(|j| j.bus == "sim-whj" && j.id == id.get())
                .unwrap()
                .name
                .as_str()
        })
        .collect();
    assert_eq!(file_names, ["j1", "j2"]);
    assert_eq!(state.name, file_names);
    // Each effort: the current times the joint's torque constant, by the robot sample's
    // (the bridge's) function.
    for ((effort, fb), k) in state.effort.iter().zip(&report.feedback).zip(&constants) {
        let ma = fb
            .as_ref()
            .unwrap()
            .current
            .milliamps(robobus_whj::units::CurrentScale::OneMilliamp);
        let want = robobus::station::sampler::effort_nm(ma, k.unwrap(), false);
        assert_eq!(*effort, want);
        assert!(effort.is_finite());
    }
}
