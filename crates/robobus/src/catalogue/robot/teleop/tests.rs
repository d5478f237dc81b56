#![allow(clippy::unwrap_used)]

use std::time::Duration;

use serde_json::{Value, json};

use crate::catalogue::robot::row;
use crate::catalogue::{Request, run, validate};
use crate::ops::Control;
use crate::station::Station;

const CENTRE: f64 = 127.0 * robobus_sim::wck::mechanics::DEG_PER_STEP8;

/// Servo `id`'s shaft turned by hand to `deg` joint degrees at simulated `at_ms`.
fn turn(sim: &robobus_sim::wck::SimHandle, at_ms: u64, id: usize, deg: f64) {
    sim.at(Duration::from_millis(at_ms), move |bus| {
        bus.servo_mut(id).unwrap().set_angle(CENTRE + deg);
    });
}

/// Servo `id`'s joint angle in the simulation, degrees.
fn angle(sim: &robobus_sim::wck::SimHandle, id: usize) -> f64 {
    let p = sim.with_bus(|b| b.servo(id).unwrap().position());
    (f64::from(p) - 127.0) * robobus_sim::wck::mechanics::DEG_PER_STEP8
}

#[test]
fn the_follower_tracks_the_leader_and_holds_when_it_goes_silent() {
    let (station, wck, _) = Station::simulated_with_handles().unwrap();
    let t = wck.now().as_millis();
    let t = u64::try_from(t).unwrap();
    // The leader s0 is turned to +30°, then to -15°, then its power goes (at 900 ms).
    turn(&wck, t + 50, 0, 30.0);
    turn(&wck, t + 450, 0, -15.0);
    let kill = Duration::from_millis(t + 900);
    wck.at(kill, move |bus| bus.servo_mut(0).unwrap().power_off(kill));
    // s1 mirrors it; s2 is mirrored and shifted, within ±20°.
    let request: Request = serde_json::from_value(json!({
        "op": "robot.teleop",
        "rate_hz": 50,
        "seconds": 10,
        "map": [
            {"leader": "s0", "follower": "s1"},
            {"leader": "s0", "follower": "s2", "scale": -1, "offset_deg": 10,
             "limits_deg": [-20, 20]},
        ],
    }))
    .unwrap();
    let report = run(&station, &request, &mut Control::none()).unwrap();
    let v = serde_json::to_value(&report).unwrap();
    // The leader's silence ends the run and fails it, once no complete reading has
    // come for 500 ms (each silent reading costs the bus's retries, so it is more).
    assert_eq!(v["failed"], "no-device", "{v:#}");
    let e = v["error"].as_str().unwrap();
    let silent_ms: u64 = e
        .strip_prefix("the leader gave no complete reading for ")
        .and_then(|r| r.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("{e}"));
    assert!((500..1000).contains(&silent_ms), "{e}");
    assert!(e.contains("s0: sim-wck: servo 0 did not answer"), "{e}");
    let s = &v["summary"];
    assert_eq!(s["leader_lost"], true, "{s}");
    // Free following with the default protection: no event.
    assert_eq!(s["protection"], json!([]), "{s}");
    assert_eq!(s["interrupted"], false, "{s}");
    // 50 Hz on the simulated clock: a command every 20 ms until the kill at 0.9 s,
    // then cycles that hold (each as long as its silent reading).
    let commanded = s["commanded"].as_u64().unwrap();
    assert!((44..=46).contains(&commanded), "{s}");
    let held = s["held"].as_u64().unwrap();
    assert!((2..=6).contains(&held), "{s}");
    assert_eq!(s["cycles"].as_u64().unwrap(), commanded + held, "{s}");
    assert_eq!(row(&v, "s1")["commands"], commanded, "{v:#}");
    assert_eq!(s["leaders"][0]["name"], "s0");
    assert_eq!(s["leaders"][0]["failed"], held, "{s}");
    // s1 went where the leader went last, and is there.
    let s1 = row(&v, "s1");
    assert_eq!(s1["leader"], "s0");
    let near = |x: f64, want: f64, tol: f64| (x - want).abs() <= tol;
    let step = robobus_sim::wck::mechanics::DEG_PER_STEP8;
    assert!(
        near(s1["target_deg"].as_f64().unwrap(), -15.0, step),
        "{s1}"
    );
    assert!(near(angle(&wck, 1), -15.0, 2.0 * step), "{s1}");
    assert!(s1["tracking_max_deg"].as_f64().unwrap() > 30.0, "{s1}");
    assert!(s1["limited"].as_u64().unwrap() > 0, "{s1}");
    // s2 at its map's limit: -(-15) + 10 = 25 is cut to 20.
    let s2 = row(&v, "s2");
    assert!(near(s2["target_deg"].as_f64().unwrap(), 20.0, 1e-9), "{s2}");
    assert!(near(angle(&wck, 2), 20.0, 2.0 * step), "{s2}");
    // The follower holds: nothing moves it once the leader is gone.
    let (a1, a2) = (angle(&wck, 1), angle(&wck, 2));
    wck.sleep(Duration::from_millis(500));
    assert_eq!((angle(&wck, 1), angle(&wck, 2)), (a1, a2));
}

#[test]
fn a_map_is_checked_before_anything_is_sent() {
    let bad = |map: Value, option: &str, says: &str| {
        let request: Request =
            serde_json::from_value(json!({"op": "robot.teleop", "map": map})).unwrap();
        let e = validate(&request).unwrap_err().to_string();
        assert!(e.contains(option) && e.contains(says), "{e}");
    };
    bad(json!([]), "--map", "1..=64 pairs");
    bad(
        json!([{"leader": "s0", "follower": "s1"}, {"leader": "s1", "follower": "s2"}]),
        "--map",
        "s1 follows, so it cannot also lead",
    );
    bad(
        json!([{"leader": "s0", "follower": "s1"}, {"leader": "s3", "follower": "s1"}]),
        "--map",
        "one pair per follower",
    );
    bad(
        json!([{"leader": "s0", "follower": "s1", "scale": 11}]),
        "--map scale",
        "-10..=10",
    );
    bad(
        json!([{"leader": "s0", "follower": "s1", "limits_deg": [5, -5]}]),
        "--limit",
        "MIN below MAX",
    );
    for (field, value, option, range) in [
        ("rate_hz", json!(500), "--rate-hz", "1..=200"),
        ("seconds", json!(0), "--seconds", "0.1..=86400"),
        (
            "leader_timeout_ms",
            json!(5),
            "--leader-timeout-ms",
            "10..=10000",
        ),
    ] {
        let mut r = json!({"op": "robot.teleop", "map": [{"leader": "s0", "follower": "s1"}]});
        r[field] = value;
        let request: Request = serde_json::from_value(r).unwrap();
        let e = validate(&request).unwrap_err().to_string();
        assert!(e.contains(option) && e.contains(range), "{e}");
    }
    // A name the robot file does not have is refused at the run, before anything moves.
    let station = Station::simulated().unwrap();
    let request: Request = serde_json::from_value(
        json!({"op": "robot.teleop", "map": [{"leader": "s0", "follower": "elbow"}]}),
    )
    .unwrap();
    let e = run(&station, &request, &mut Control::none()).unwrap_err();
    assert_eq!(e.kind(), crate::ErrorKind::BadInput, "{e}");
    assert!(e.to_string().contains("elbow"), "{e}");
}

#[test]
fn a_follower_pushing_into_an_obstacle_is_stopped_and_named() {
    let (station, wck, whj) = Station::simulated_with_handles().unwrap();
    for r in [
        json!({"op": "whj.mode", "joints": "1", "mode": "position"}),
        json!({"op": "whj.enable", "joints": "1"}),
    ] {
        run(
            &station,
            &serde_json::from_value(r).unwrap(),
            &mut Control::none(),
        )
        .unwrap();
    }
    // A stop at 10° in j1's way; the leader s0 is turned to 30°.
    whj.with_bus(|b| {
        b.joint_mut(1)
            .unwrap()
            .set_obstacle(Some(robobus_sim::whj::Obstacle::above(10.0)));
    });
    let t = u64::try_from(wck.now().as_millis()).unwrap();
    turn(&wck, t + 50, 0, 30.0);
    // j1 reaches the stop about 0.2 s in (2° a cycle); the current passes the stall
    // current within 0.2 s and the stall time (0.3 s) later the run stops, long before
    // its 5 s, failing it and naming the joint, the quantity, the limit and the time.
    teleop_stopped_by_a_stall(
        &station,
        ("j1", 7.8, 0.68),
        "j1: stall protection: current 23.40 A reached the limit 7.8 A at 0.6",
    );
    // j1 (a WHJ30, braked) is disabled: no longer pushing.
    let j1 = whj.with_bus(|b| b.joint(1).unwrap().state());
    assert!(!j1.enabled && j1.current_a.abs() < 1e-9, "{j1:?}");
}

/// A wCK follower gripped by the simulator's hand, its own over-load at its highest
/// (1800 mA, so only the host can stop it): its move replies answer with the load it
/// pushes with (read as a current), so the stall stops the run, naming it, and leaves it
/// passive.
#[test]
fn a_gripped_wck_follower_is_stopped_as_a_stall_naming_it() {
    let (station, wck, _) = Station::simulated_with_handles().unwrap();
    wck.with_bus(|b| {
        let s = b.servo_mut(1).unwrap();
        let e = robobus_sim::wck::Eeprom {
            overload: robobus_wck::Overload::new(199).unwrap(),
            ..*s.eeprom()
        };
        s.set_eeprom(e);
        s.hold(true);
    });
    let t = u64::try_from(wck.now().as_millis()).unwrap();
    turn(&wck, t + 50, 0, 30.0);
    // s1 pushes from the first cycle after the leader's turn (0.08 s) with 1.2 A; the
    // wCK stall time (0.4 s) later the run stops, long before its 5 s.
    teleop_stopped_by_a_stall(
        &station,
        ("s1", 0.2, 0.483),
        "s1: stall protection: current 1.20 A reached the limit 0.2 A at 0.48",
    );
    wck.with_bus(|b| {
        assert_eq!(b.servo(1).unwrap().mode(), robobus_sim::wck::Mode::Passive);
    });
}

/// Runs a 5 s teleop of leader s0 to `follower` and checks that a stall stopped it:
/// failed (kind device) with one protection event, a stop of `follower` at `limit` A of
/// current at `at_s` (within 5 ms), where the run ended, its row's error starting with
/// `error_start`.
fn teleop_stopped_by_a_stall(
    station: &Station,
    (follower, limit, at_s): (&str, f64, f64),
    error_start: &str,
) {
    let request: Request = serde_json::from_value(json!({
        "op": "robot.teleop",
        "rate_hz": 50,
        "seconds": 5,
        "map": [{"leader": "s0", "follower": follower}],
    }))
    .unwrap();
    let report = run(station, &request, &mut Control::none()).unwrap();
    let v = serde_json::to_value(&report).unwrap();
    assert_eq!(v["failed"], "device", "{v:#}");
    let s = &v["summary"];
    let events = s["protection"].as_array().unwrap();
    assert_eq!(events.len(), 1, "{s:#}");
    let stop = &events[0];
    assert_eq!(
        (&stop["joint"], &stop["check"], &stop["action"]),
        (&json!(follower), &json!("stall"), &json!("stop")),
        "{stop}"
    );
    assert_eq!(
        (&stop["quantity"], &stop["limit"]),
        (&json!("current_a"), &json!(limit))
    );
    let at = stop["at_s"].as_f64().unwrap();
    assert!((at - at_s).abs() < 0.005, "{stop}");
    assert!((s["seconds"].as_f64().unwrap() - at).abs() < 0.001, "{s}");
    let e = row(&v, follower)["error"].as_str().unwrap();
    assert!(e.starts_with(error_start), "{e}");
}
