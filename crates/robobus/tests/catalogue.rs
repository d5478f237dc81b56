//! The catalogue: requests parse from their documented JSON and back, are planned and run on
//! a station of simulated buses, and a request out of range, with an unknown field or
//! needing a confirmation it lacks is refused with its kind before anything is sent.
//! On the simulators' virtual clocks.

#![allow(
    clippy::unwrap_used,
    clippy::panic,
    clippy::result_large_err,
    clippy::many_single_char_names
)]

use crate::station_support;

use robobus::catalogue::bounds::ConfirmClass;
use robobus::catalogue::{self, ErrorKind, Request};
use robobus::ops::Control;
use robobus::station::{Station, WckPort, WhjPort};
use robobus::whj::{JointBus, JointBusConfig};
use robobus_sim::whj::{WhjBus, WhjModel, WhjSimLink};

/// The station and the handles are shared by a server's threads.
const _: () = {
    const fn send_sync<T: Send + Sync>() {}
    send_sync::<Station>();
    send_sync::<WckPort>();
    send_sync::<WhjPort>();
    send_sync::<Request>();
};

/// 3 wCK servos (0..=2) and 2 WHJ joints (1, 2) on the virtual clocks, and the handles
/// that keep the simulators.
fn station() -> (Station, WckPort, WhjPort) {
    station_support::station("arm-wck", "arm-whj")
}

fn parse(json: &str) -> Request {
    let mut r = Request::parse_many(json).unwrap_or_else(|e| panic!("{json}: {e}"));
    assert_eq!(r.len(), 1);
    r.remove(0)
}

fn run(s: &Station, json: &str) -> Result<catalogue::Report, robobus::ops::OpError> {
    catalogue::run(s, &parse(json), &mut Control::none())
}

/// What went out so far: wCK packets written, WHJ frames sent.
fn sent(w: &WckPort, j: &WhjPort) -> (u64, u64) {
    (
        w.lock().stats().attempts,
        j.bus().telemetry().bus.frames_sent,
    )
}

#[test]
fn the_documented_requests_parse_and_serialise_back_equal() {
    for json in [
        r#"{"op": "wck.status", "ids": "0-2"}"#,
        r#"{"op": "whj.move", "joint": 1, "degrees": 30, "max_speed": 20}"#,
        r#"{"op": "whj.write", "joints": "1", "register": "SYS_ID", "value": 2, "confirm": true}"#,
        r#"{"op": "wck.status", "ids": [0, 1]}"#,
        r#"{"op": "whj.status", "joints": "1-7", "broadcast": true}"#,
    ] {
        let r = parse(json);
        let back = serde_json::to_string(&r).unwrap();
        assert_eq!(parse(&back), r, "{json} -> {back}");
        assert_eq!(r.op(), json.split('"').nth(3).unwrap());
    }
    // An array is a list of requests, in order.
    let many = Request::parse_many(r#"[{"op": "wck.brake"}, {"op": "whj.registers"}]"#).unwrap();
    assert_eq!(
        many.iter().map(Request::op).collect::<Vec<_>>(),
        ["wck.brake", "whj.registers"]
    );
}

#[test]
fn unknown_operations_and_fields_are_bad_input_naming_them() {
    for (json, names) in [
        (r#"{"op": "wck.status", "ids": "0", "idz": 1}"#, "idz"),
        (r#"{"op": "whj.fly", "joint": 1}"#, "whj.fly"),
        (r#"{"ids": "0"}"#, "op"),
        (r#"[{"op": "wck.brake"}, {"op": "wck.nope"}]"#, "request 2"),
    ] {
        let e = Request::parse_many(json).unwrap_err();
        assert_eq!(e.kind(), ErrorKind::BadInput, "{json}: {e}");
        assert!(e.to_string().contains(names), "{json}: {e}");
    }
}

#[test]
fn requests_out_of_range_are_refused_with_the_range_and_nothing_is_sent() {
    let (s, w, j) = station();
    let before = sent(&w, &j);
    for (json, says) in [
        (r#"{"op": "whj.move", "joint": 1, "degrees": 400}"#, "-360"),
        (
            r#"{"op": "whj.move", "joint": 1, "degrees": 10, "max_speed": 500}"#,
            "180",
        ),
        (r#"{"op": "whj.speed", "joint": 1, "rpm": 99}"#, "37.5"),
        (r#"{"op": "whj.status", "joints": "0"}"#, "1..=30"),
        (
            r#"{"op": "wck.move", "id": 3, "position": 255, "torque": 0}"#,
            "254",
        ),
        (
            r#"{"op": "wck.move", "id": 31, "position": 10, "torque": 0}"#,
            "30",
        ),
        // Past a byte: still the servo's own range, with the value given.
        (
            r#"{"op": "wck.move", "id": 3, "position": 300}"#,
            "position 300 is out of range 0..=254",
        ),
    ] {
        let r = parse(json);
        let e = catalogue::plan(&r).unwrap_err();
        assert_eq!(e.kind(), ErrorKind::BadInput, "{json}: {e}");
        assert!(e.to_string().contains(says), "{json}: {e}");
        let e = catalogue::run(&s, &r, &mut Control::none()).unwrap_err();
        assert_eq!(e.kind(), ErrorKind::BadInput, "{json}: {e}");
    }
    assert_eq!(sent(&w, &j), before, "a refused request sent something");
}

#[test]
fn writes_of_ids_eeprom_and_flash_need_confirm_and_without_it_nothing_is_sent() {
    let (s, w, j) = station();
    let before = sent(&w, &j);
    for json in [
        r#"{"op": "wck.set-id", "id": 1, "new_id": 5}"#,
        r#"{"op": "wck.set", "param": "gains", "id": 1, "p": 10, "d": 5}"#,
        r#"{"op": "whj.save", "joints": "1"}"#,
        r#"{"op": "whj.set-id", "joint": 1, "new_id": 9}"#,
    ] {
        let e = run(&s, json).unwrap_err();
        assert_eq!(e.kind(), ErrorKind::Refused, "{json}: {e}");
        assert!(e.to_string().contains("confirm"), "{json}: {e}");
        // The plan says so too.
        assert_ne!(
            catalogue::plan(&parse(json)).unwrap().confirm,
            ConfirmClass::None
        );
    }
    assert_eq!(sent(&w, &j), before, "a refused request sent something");
    // With confirm, the same write runs and is read back.
    let r = run(
        &s,
        r#"{"op": "wck.set", "param": "gains", "id": 1, "p": 10, "d": 5, "confirm": true}"#,
    )
    .unwrap();
    assert_eq!(r.failed, None, "{r:?}");
    assert_ne!(sent(&w, &j), before);
}

#[test]
fn reports_key_devices_by_id_for_both_families_and_mark_a_silent_one() {
    let (s, _w, _j) = station();
    let r = run(&s, r#"{"op": "wck.status", "ids": "0-3"}"#).unwrap();
    assert_eq!((r.op.as_str(), r.bus.as_str()), ("wck.status", "arm-wck"));
    let ids: Vec<_> = r.results.iter().map(|v| v["id"].clone()).collect();
    assert_eq!(ids, [0, 1, 2, 3].map(|i| serde_json::json!(i)));
    assert!(
        r.results[..3].iter().all(|v| v["position"].is_u64()),
        "{r:?}"
    );
    // Servo 3 does not exist: its row carries the failure, the report the worst kind.
    assert_eq!(r.results[3]["kind"], "no-device", "{r:?}");
    assert_eq!(r.failed_kind(), Some(ErrorKind::NoDevice));
    let r = run(&s, r#"{"op": "whj.status", "joints": "1-3"}"#).unwrap();
    assert_eq!(r.bus, "arm-whj");
    let ids: Vec<_> = r.results.iter().map(|v| v["id"].clone()).collect();
    assert_eq!(ids, [1, 2, 3].map(|i| serde_json::json!(i)));
    assert_eq!(r.results[0]["mode"], "position", "{r:?}");
    assert_eq!(r.results[2]["kind"], "no-device", "{r:?}");
    assert_eq!(r.failed_kind(), Some(ErrorKind::NoDevice));
}

#[test]
fn a_request_names_its_bus_when_the_station_has_more_than_one() {
    let (mut s, _w, _j) = station();
    let (link, sim) = WhjSimLink::new(WhjBus::chain(3..=3, WhjModel::Whj30, 12));
    s.add_whj(
        "gripper",
        JointBus::open_with(link, JointBusConfig::default()).unwrap(),
    );
    s.keep(Box::new(std::sync::Mutex::new(sim)));
    let e = run(&s, r#"{"op": "whj.status", "joints": "3"}"#).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::BadInput, "{e}");
    let r = run(
        &s,
        r#"{"op": "whj.status", "joints": "3", "bus": "gripper"}"#,
    )
    .unwrap();
    assert_eq!(
        (r.bus.as_str(), r.failed.map(robobus::ErrorKind::name)),
        ("gripper", None)
    );
    let e = run(&s, r#"{"op": "whj.status", "joints": "3", "bus": "nope"}"#).unwrap_err();
    assert!(e.to_string().contains("nope"), "{e}");
}

#[test]
fn the_plan_is_what_the_run_sends() {
    // A wCK move: the plan's packet, and the report of the move it made.
    let r = parse(r#"{"op": "wck.move", "id": 1, "position": 200, "torque": 2}"#);
    let plan = catalogue::plan(&r).unwrap();
    assert_eq!(plan.steps.len(), 1, "{plan:?}");
    let (s, w, _j) = station();
    let before = w.lock().stats().attempts;
    let rep = catalogue::run(&s, &r, &mut Control::none()).unwrap();
    assert_eq!(rep.failed, None, "{rep:?}");
    assert_eq!(w.lock().stats().attempts - before, 1);
    // A WHJ status: one query frame per joint, as planned.
    let r = parse(r#"{"op": "whj.status", "joints": "1-2"}"#);
    let plan = catalogue::plan(&r).unwrap();
    assert!(
        plan.to_text().contains("0x601") || plan.to_text().contains("601#"),
        "{}",
        plan.to_text()
    );
}

#[test]
fn telemetry_eight_subscribers_one_never_reading_the_others_lose_nothing() {
    const SAMPLES: u64 = 300;
    use robobus::catalogue::telemetry::{RecvError, Telemetry};
    let (s, _w, _j) = station();
    let s = std::sync::Arc::new(s);
    let t = Telemetry::paused(
        &s,
        parse(r#"{"op": "whj.sample", "joints": "1-2"}"#),
        1000.0,
        Some(SAMPLES),
    )
    .unwrap();
    // Seven readers with room for the whole run; one that never reads, with room for 8.
    let readers: Vec<_> = (0..7)
        .map(|_| t.subscribe(usize::try_from(SAMPLES).unwrap()).unwrap())
        .collect();
    let idle = t.subscribe(8).unwrap();
    let threads: Vec<_> = readers
        .into_iter()
        .map(|sub| {
            std::thread::spawn(move || {
                let mut seqs = Vec::new();
                let mut lost = 0;
                for d in sub {
                    lost += d.lost;
                    let rep = d.sample.report.as_ref().expect("a report");
                    assert_eq!(rep.results.len(), 2);
                    assert!(rep.results.iter().all(|r| r["position_deg"].is_number()));
                    seqs.push(d.sample.seq);
                }
                (seqs, lost)
            })
        })
        .collect();
    let stats = t.join();
    assert_eq!(stats.samples, SAMPLES);
    assert_eq!(stats.failed, 0);
    for th in threads {
        let (seqs, lost) = th.join().unwrap();
        assert_eq!(lost, 0);
        assert_eq!(seqs, (0..SAMPLES).collect::<Vec<_>>());
    }
    // The idle subscriber holds its last 8 samples and was told of the rest.
    assert_eq!(idle.queued(), 8);
    assert_eq!(idle.lost(), SAMPLES - 8);
    let first = idle.try_recv().unwrap();
    assert_eq!((first.sample.seq, first.lost), (SAMPLES - 8, SAMPLES - 8));
    for _ in 1..8 {
        assert_eq!(idle.try_recv().unwrap().lost, 0);
    }
    assert_eq!(idle.try_recv().unwrap_err(), RecvError::Ended);
}

/// Every sample of `request` on `s` (`n` of them) taken into `table`.
fn fill(
    s: &std::sync::Arc<Station>,
    request: &str,
    n: u64,
    table: &mut robobus::record::SampleTable,
) {
    use robobus::catalogue::telemetry::Telemetry;
    let t = Telemetry::paused(s, parse(request), 50.0, Some(n)).unwrap();
    let sub = t.subscribe(16).unwrap();
    assert_eq!(t.join().samples, n);
    for (k, d) in sub.enumerate() {
        #[allow(clippy::cast_precision_loss)] // a few samples
        table.take(&d, k as f64 * 0.02).unwrap();
    }
}

#[test]
fn every_stream_fills_one_sample_table_and_a_silent_device_is_stale() {
    use robobus::record::{Effort, SampleTable, SpeedUnit};
    let (s, _w, _j) = station();
    let s = std::sync::Arc::new(s);
    // wCK servos by ID: servo 3 does not exist, servo 2 answers every sample.
    let mut wck = SampleTable::wck(&[2, 3]);
    fill(&s, r#"{"op": "wck.sample", "ids": "2-3"}"#, 2, &mut wck);
    assert_eq!((wck.samples, wck.t_s), (2, 0.02));
    let (s2, s3) = (&wck.rows[0], &wck.rows[1]);
    assert!(s2.fresh && s2.answered == 2 && s2.failures == 0, "{s2:?}");
    assert_eq!(s2.speed, Some(0.0), "two readings of a servo at rest");
    assert!(s2.position_deg.is_some() && s2.effort.is_some());
    assert!(!s3.fresh && s3.answered == 0 && s3.failures == 2, "{s3:?}");
    assert_eq!(s3.error, "no reply");
    assert_eq!(wck.silent(), ["s3 (2 of 2 samples missing)"]);
    let line: serde_json::Value = serde_json::from_str(&wck.json_line()).unwrap();
    assert!(line["channels"][1]["position_deg"].is_null());
    assert_eq!(line["channels"][1]["stale"], true);
    // WHJ joints by ID: joint 3 is not on the bus (a timeout), in RPM and mA.
    let mut whj = SampleTable::whj(&[1, 3]);
    assert_eq!(whj.speed_unit, SpeedUnit::Rpm);
    fill(&s, r#"{"op": "whj.sample", "joints": "1,3"}"#, 1, &mut whj);
    let (j1, j3) = (&whj.rows[0], &whj.rows[1]);
    assert!(
        j1.fresh && j1.speed.is_some() && j1.enabled.is_some(),
        "{j1:?}"
    );
    assert_eq!(j1.effort_kind, Effort::Milliamps);
    assert_eq!(j1.error, "no error");
    assert_eq!((j3.fresh, j3.error.as_str()), (false, "timeout"));
    // A robot file's joints by name, across both families.
    let sim = std::sync::Arc::new(Station::simulated().unwrap());
    let config = sim.robot().unwrap();
    let joints = robobus::station::sampler::monitored_joints(config);
    let mut robot = SampleTable::robot(joints.iter().map(|j| (j.name.as_str(), j.wck)));
    fill(&sim, r#"{"op": "robot.sample"}"#, 1, &mut robot);
    assert_eq!(robot.rows.len(), joints.len());
    assert!(robot.rows.iter().all(|r| r.fresh), "{robot:?}");
    assert!(robot.silent().is_empty());
    assert!(robot.rows.iter().any(|r| r.effort_kind == Effort::Load));
    assert!(
        robot
            .rows
            .iter()
            .any(|r| r.effort_kind == Effort::Milliamps && r.enabled.is_some())
    );
}

#[test]
fn telemetry_marks_a_silent_device_and_refuses_what_it_cannot_stream() {
    use robobus::catalogue::telemetry::Telemetry;
    let (s, _w, _j) = station();
    let s = std::sync::Arc::new(s);
    // Servo 3 does not exist: every sample has its row as a failure, never a value.
    let t = Telemetry::paused(
        &s,
        parse(r#"{"op": "wck.sample", "ids": "2-3"}"#),
        50.0,
        Some(3),
    )
    .unwrap();
    let sub = t.subscribe(16).unwrap();
    assert_eq!(t.join().samples, 3);
    let got: Vec<_> = sub.collect();
    assert_eq!(got.len(), 3);
    for (k, d) in got.iter().enumerate() {
        let rep = d.sample.report.as_ref().unwrap();
        assert!(rep.results[0]["position_deg"].is_number(), "{rep:?}");
        assert_eq!(rep.results[1]["kind"], "no-device", "{rep:?}");
        assert_eq!(rep.failed.map(robobus::ErrorKind::name), Some("no-device"));
        // Servo 2 rests: no speed from its first reading, 0 deg/s from two.
        let speed = &rep.results[0]["speed_deg_s"];
        if k == 0 {
            assert!(speed.is_null(), "{rep:?}");
        } else {
            assert_eq!(speed.as_f64(), Some(0.0), "{rep:?}");
        }
    }
    // Only readings are streamed, at a rate in range, on a bus the station has.
    for (json, rate) in [
        (r#"{"op": "whj.move", "joint": 1, "degrees": 5}"#, 10.0),
        (r#"{"op": "wck.status", "ids": "0"}"#, 0.0),
        (r#"{"op": "wck.status", "ids": "0"}"#, f64::NAN),
        (
            r#"{"op": "whj.sample", "joints": "1", "bus": "nope"}"#,
            10.0,
        ),
        (r#"{"op": "whj.sample", "joints": "0"}"#, 10.0),
    ] {
        let e = Telemetry::start(&s, parse(json), rate, None).unwrap_err();
        assert_eq!(e.kind(), ErrorKind::BadInput, "{json}: {e}");
    }
    // A queue is bounded.
    let t = Telemetry::start(&s, parse(r#"{"op": "wck.status", "ids": "0"}"#), 10.0, None).unwrap();
    assert_eq!(t.subscribe(0).unwrap_err().kind(), ErrorKind::BadInput);
    assert_eq!(
        t.subscribe(1 << 20).unwrap_err().kind(),
        ErrorKind::BadInput
    );
    // Stopped while it runs: the subscriber gets what was queued, then the end.
    let sub = t.subscribe(64).unwrap();
    let first = sub
        .recv_timeout(std::time::Duration::from_secs(10))
        .unwrap();
    let stats = t.stop();
    assert!(stats.samples > first.sample.seq, "{stats:?}");
    let last = sub.last().map_or(first.sample.seq, |d| d.sample.seq);
    assert_eq!(last, stats.samples - 1, "{stats:?}");
}

/// Runs `json`, stopping its token once a progress event has `done == at`.
fn run_stopped_at(s: &Station, json: &str, at: u64) -> catalogue::Report {
    let stop = robobus::ops::StopToken::new();
    let token = stop.clone();
    let mut on_progress = |p: &robobus::ops::Progress| {
        if p.done == at {
            token.stop();
        }
    };
    catalogue::run(
        s,
        &parse(json),
        &mut Control::new(&stop).with_progress(&mut on_progress),
    )
    .unwrap()
}

#[test]
fn a_stopped_scan_keeps_what_it_found_and_says_how_far_it_got() {
    let (s, _, _) = station();
    // wCK: progress after each ID; stopped after IDs 0 and 1 of 0..=5.
    let r = run_stopped_at(&s, r#"{"op": "wck.scan", "ids": "0-5"}"#, 2);
    let ids: Vec<u64> = r
        .results
        .iter()
        .map(|v| v["id"].as_u64().unwrap())
        .collect();
    assert_eq!(ids, [0, 1]);
    assert_eq!(r.failed.map(robobus::ErrorKind::name), Some("interrupted"));
    assert_eq!(
        r.error.as_deref(),
        Some("arm-wck: scan stopped after 2 of 6 probes")
    );
    // WHJ: progress before each ID; the stop asked before J2 is seen before J3.
    let r = run_stopped_at(&s, r#"{"op": "whj.scan", "joints": "1-5"}"#, 1);
    let ids: Vec<u64> = r
        .results
        .iter()
        .map(|v| v["id"].as_u64().unwrap())
        .collect();
    assert_eq!(ids, [1, 2]);
    assert_eq!(r.failed.map(robobus::ErrorKind::name), Some("interrupted"));
    assert_eq!(
        r.error.as_deref(),
        Some("arm-whj: scan stopped after 2 of 5 IDs")
    );
    // Not stopped, the same scans report every servo / joint and no failure.
    let r = run(&s, r#"{"op": "whj.scan", "joints": "1-5"}"#).unwrap();
    assert_eq!((r.results.len(), r.failed), (2, None));
}

fn row<'a>(report: &'a catalogue::Report, id: &str) -> &'a serde_json::Value {
    report
        .results
        .iter()
        .find(|r| r["id"] == id)
        .unwrap_or_else(|| panic!("no row {id}: {:?}", report.results))
}

#[test]
fn robot_sample_reads_the_robot_files_joints_by_name_in_joint_units() {
    let s = Station::simulated().unwrap();
    assert_eq!(s.robot().unwrap().joints.len(), 16 + 7);
    run(&s, r#"{"op": "wck.move", "id": 3, "position": 200}"#).unwrap();
    for json in [
        r#"{"op": "whj.enable", "joints": "2"}"#,
        r#"{"op": "whj.mode", "joints": "2", "mode": "position"}"#,
        r#"{"op": "whj.move", "joint": 2, "degrees": 12, "max_speed": 60}"#,
    ] {
        assert_eq!(run(&s, json).unwrap().failed, None, "{json}");
    }
    // The servo turns on the simulator's clock, which runs with the bus: read until it is there.
    let mut status = run(&s, r#"{"op": "wck.status", "ids": "3"}"#).unwrap();
    for _ in 0..5000 {
        if status.results[0]["position"] == 200 {
            break;
        }
        status = run(&s, r#"{"op": "wck.status", "ids": "3"}"#).unwrap();
    }
    assert_eq!(status.results[0]["position"], 200, "{:?}", status.results);
    let whj = run(&s, r#"{"op": "whj.status", "joints": "2"}"#).unwrap();
    let r = run(&s, r#"{"op": "robot.sample"}"#).unwrap();
    assert_eq!((r.op.as_str(), r.bus.as_str()), ("robot.sample", "robot"));
    assert_eq!(r.failed, None, "{:?}", r.results);
    let names: Vec<&str> = r
        .results
        .iter()
        .map(|r| r["id"].as_str().unwrap())
        .collect();
    assert_eq!(names[..3], ["s0", "s1", "s2"]);
    assert_eq!(names[16..], ["j1", "j2", "j3", "j4", "j5", "j6", "j7"]);
    // wCK: the joint angle is the servo's angle from its centre step (127), 0 there.
    let centre_deg = 127.0 * 269.0 / 255.0;
    let s3 = row(&r, "s3");
    let want = status.results[0]["degrees"].as_f64().unwrap() - centre_deg;
    assert!(
        (s3["position_deg"].as_f64().unwrap() - want).abs() < 0.01,
        "{s3} vs {want}"
    );
    assert!(s3["position_deg"].as_f64().unwrap() > 70.0, "{s3}");
    assert!(s3["load"].is_u64(), "{s3}");
    assert!(
        s3["current_ma"].is_null() && s3["enabled"].is_null(),
        "{s3}"
    );
    assert_eq!(row(&r, "s0")["position_deg"].as_f64(), Some(0.0));
    // WHJ: the joint's own angle (offset 0, direction 1), its enable state and current.
    let j2 = row(&r, "j2");
    let at = whj.results[0]["position_deg"].as_f64().unwrap();
    assert!(
        (j2["position_deg"].as_f64().unwrap() - at).abs() < 0.05,
        "{j2} vs {at}"
    );
    assert!((at - 12.0).abs() < 0.1, "{at}");
    assert_eq!(j2["enabled"], true);
    assert!(j2["current_ma"].is_number() && j2["load"].is_null(), "{j2}");
    // Its plan says what it reads without a station: notes, no frames.
    let plan = catalogue::plan(&parse(r#"{"op": "robot.sample"}"#)).unwrap();
    assert!(plan.steps.is_empty() && plan.to_text().starts_with("# reads every joint"));
    s.leave();
}

#[test]
fn robot_sample_marks_a_silent_joint_and_needs_a_robot_file() {
    let (mut s, w, j) = station();
    // Without a robot file: bad input, and nothing sent.
    let before = sent(&w, &j);
    let e = run(&s, r#"{"op": "robot.sample"}"#).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::BadInput, "{e}");
    assert!(e.to_string().contains("no robot file"), "{e}");
    assert_eq!(sent(&w, &j), before);
    // A file whose bus the station does not have is refused when it is given.
    let file = |bus: &str| {
        format!(
            "[buses.{bus}]\nkind = \"wck-external\"\n[buses.arm-whj]\nkind = \"whj-external\"\n\
             [[joints]]\nname = \"hip\"\nbus = \"{bus}\"\nid = 1\nlimits = [-1.0, 1.0]\n\
             max_velocity = 1.0\nmax_acceleration = 1.0\n\
             [[joints]]\nname = \"gone\"\nbus = \"{bus}\"\nid = 9\nlimits = [-1.0, 1.0]\n\
             max_velocity = 1.0\nmax_acceleration = 1.0\n\
             [[joints]]\nname = \"wrist\"\nbus = \"arm-whj\"\nid = 2\nlimits = [-1.0, 1.0]\n\
             max_velocity = 1.0\nmax_acceleration = 1.0\n\
             [[joints]]\nname = \"lost\"\nbus = \"arm-whj\"\nid = 7\nlimits = [-1.0, 1.0]\n\
             max_velocity = 1.0\nmax_acceleration = 1.0\n"
        )
    };
    let config = |bus: &str| robobus::RobotConfig::from_toml_str(&file(bus)).unwrap();
    let e = s.set_robot(config("legs")).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::BadInput, "{e}");
    assert!(e.to_string().contains("legs"), "{e}");
    s.set_robot(config("arm-wck")).unwrap();
    // Servo 9 and joint 7 are not there: their rows are failures, never values.
    for _ in 0..2 {
        let r = run(&s, r#"{"op": "robot.sample"}"#).unwrap();
        assert_eq!(
            r.failed.map(robobus::ErrorKind::name),
            Some("no-device"),
            "{:?}",
            r.results
        );
        for silent in ["gone", "lost"] {
            let row = row(&r, silent);
            assert_eq!(row["kind"], "no-device", "{row}");
            assert!(row.get("position_deg").is_none(), "{row}");
        }
        assert!(row(&r, "hip")["position_deg"].is_number());
        assert!(row(&r, "wrist")["position_deg"].is_number());
    }
}

#[test]
fn robot_sample_streams_with_each_wck_joints_speed_from_its_previous_reading() {
    use robobus::catalogue::telemetry::Telemetry;
    let s = std::sync::Arc::new(Station::simulated().unwrap());
    let t = Telemetry::paused(&s, parse(r#"{"op": "robot.sample"}"#), 20.0, Some(3)).unwrap();
    let sub = t.subscribe(8).unwrap();
    t.join();
    let rows: Vec<_> = sub
        .map(|d| d.sample.report.clone().expect("a report"))
        .collect();
    assert_eq!(rows.len(), 3);
    assert!(row(&rows[0], "s5")["speed_deg_s"].is_null());
    for r in &rows[1..] {
        assert_eq!(row(r, "s5")["speed_deg_s"].as_f64(), Some(0.0), "{r:?}");
        assert_eq!(r.results.len(), 23);
    }
    // A station without a robot file cannot stream it.
    let (plain, _w, _j) = station();
    let e = Telemetry::start(
        &std::sync::Arc::new(plain),
        parse(r#"{"op": "robot.sample"}"#),
        10.0,
        Some(1),
    )
    .unwrap_err();
    assert_eq!(e.kind(), ErrorKind::BadInput, "{e}");
}

#[test]
fn a_cyclic_loop_checks_its_joints_and_every_target_before_the_loop_sends_it() {
    use robobus::ops::whj::ServoLoop;
    use robobus::station::cyclic::CyclicLoop;
    use std::time::Duration;
    let s = Station::simulated().unwrap();
    // Not enabled in position mode: refused, no loop.
    run(&s, r#"{"op": "whj.disable", "joints": "1-2"}"#).unwrap();
    let e = CyclicLoop::start(&s, None, &[1, 2], ServoLoop::Position, 200.0).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Refused, "{e}");
    for bad in [
        CyclicLoop::start(&s, None, &[1], ServoLoop::Position, 5000.0),
        CyclicLoop::start(&s, None, &[0], ServoLoop::Position, 200.0),
        CyclicLoop::start(&s, None, &[], ServoLoop::Position, 200.0),
    ] {
        assert_eq!(bad.unwrap_err().kind(), ErrorKind::BadInput);
    }
    for json in [
        r#"{"op": "whj.enable", "joints": "1-2"}"#,
        r#"{"op": "whj.mode", "joints": "1-2", "mode": "position"}"#,
    ] {
        assert_eq!(run(&s, json).unwrap().failed, None, "{json}");
    }
    let mut l = CyclicLoop::start(&s, None, &[1, 2], ServoLoop::Position, 200.0).unwrap();
    assert_eq!(l.joints(), [1, 2]);
    l.set(&[10.0, -5.0]).unwrap();
    let mut last = None;
    for _ in 0..2000 {
        let c = l.next(Duration::from_secs(1)).expect("a cycle");
        let at: Vec<f64> = c
            .feedback
            .iter()
            .map(|f| f.as_ref().unwrap().position_deg)
            .collect();
        let sent = (c.commanded[0] - 10.0).abs() < 1e-3 && (c.commanded[1] + 5.0).abs() < 1e-3;
        if sent && (at[0] - 10.0).abs() < 0.01 && (at[1] + 5.0).abs() < 0.01 {
            last = Some(c);
            break;
        }
    }
    let last = last.expect("the joints reached their targets");
    assert!(
        last.feedback.iter().all(|f| f.as_ref().unwrap().enabled),
        "{last:?}"
    );
    // Out of the joint's limits, not finite, or the wrong count: refused, targets kept.
    let (lo, hi) = l.limits()[0];
    for targets in [vec![hi + 1.0, 0.0], vec![f64::NAN, 0.0], vec![1.0]] {
        let e = l.set(&targets).unwrap_err();
        assert_eq!(e.kind(), ErrorKind::BadInput, "{e}");
    }
    let e = l.set(&[lo - 1.0, 0.0]).unwrap_err().to_string();
    assert!(
        e.contains("target of joint J1") && e.contains("no target was changed"),
        "{e}"
    );
    l.clear();
    let c = l.next(Duration::from_secs(1)).unwrap();
    assert!((c.commanded[0] - 10.0).abs() < 1e-3, "{c:?}");
    let summary = l.stop().unwrap();
    assert!(
        summary.cycles > 0 && summary.missing_replies == 0,
        "{summary:?}"
    );
    assert!(l.stop().is_none());
    assert_eq!(l.set(&[0.0, 0.0]).unwrap_err().kind(), ErrorKind::Refused);
    s.leave();
}
