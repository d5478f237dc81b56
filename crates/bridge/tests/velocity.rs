//! Velocity commands through Zenoh, end to end: a peer on loopback switches a simulated
//! wheel and WHJ joint to velocity on `NS/robobus/interface`, streams
//! `NS/joint_commands/velocity`, and stops; the simulators turn at the asked speeds, then
//! the quiet stream's joints are brought back to position.

#![allow(clippy::unwrap_used, clippy::panic, clippy::float_cmp)] // tests; a zero is exact

use std::time::{Duration, Instant};

use robobus::cdr::Float64MultiArray;
use robobus::frontend::live::{LiveSimulator, SimSnapshot};
use robobus::ops::StopToken;
use robobus::robot::RobotConfig;
use robobus::robot::simulated::{DRIVE_ROBOT, sim_1108_wheel_speeds};
use robobus::station::Station;
use robobus_bridge::{Bridge, BridgeConfig};
use zenoh::Wait as _;

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// An armed bridge on `bot` on the built-in simulators, through their robot file of a
/// wheel `s0`, a WHJ joint `j1` with velocity and effort and `j2` with position alone
/// ([`DRIVE_ROBOT`]); and the simulators.
fn start(port: u16) -> (Bridge, LiveSimulator) {
    let (mut station, live) = Station::simulated_live(None).unwrap();
    station
        .set_robot(RobotConfig::from_toml_str(DRIVE_ROBOT).unwrap())
        .unwrap();
    let bridge = Bridge::start(
        station,
        Some(live.clone()),
        BridgeConfig {
            namespace: Some("bot".into()),
            listen: vec![format!("tcp/127.0.0.1:{port}")],
            armed: true,
            ..BridgeConfig::default()
        },
    )
    .unwrap();
    (bridge, live)
}

fn peer(port: u16) -> zenoh::Session {
    let mut config = zenoh::Config::default();
    for (k, v) in [
        ("mode", "\"peer\"".to_owned()),
        ("listen/endpoints", "[]".to_owned()),
        ("connect/endpoints", format!("[\"tcp/127.0.0.1:{port}\"]")),
        ("scouting/multicast/enabled", "false".to_owned()),
        ("scouting/gossip/enabled", "false".to_owned()),
    ] {
        config.insert_json5(k, &v).unwrap();
    }
    zenoh::open(config).wait().unwrap()
}

/// A query's JSON reply (an error reply panics with its text).
fn query(s: &zenoh::Session, key: &str, payload: &str) -> serde_json::Value {
    let replies = s
        .get(key)
        .payload(payload.to_owned())
        .timeout(Duration::from_secs(20))
        .wait()
        .unwrap();
    let reply = replies.recv().unwrap();
    match reply.result() {
        Ok(sample) => serde_json::from_str(&sample.payload().try_to_string().unwrap()).unwrap(),
        Err(e) => panic!("{key}: {}", e.payload().try_to_string().unwrap()),
    }
}

/// The simulators once `ok` holds of them, or the last state after 5 s.
fn until(live: &LiveSimulator, ok: impl Fn(&SimSnapshot) -> bool) -> SimSnapshot {
    let deadline = Instant::now() + Duration::from_secs(5);
    loop {
        let snap = live.snapshot();
        if ok(&snap) || Instant::now() > deadline {
            return snap;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}

#[test]
fn a_zenoh_peer_turns_a_wheel_and_a_whj_joint_at_the_asked_velocity_until_it_stops() {
    let _alone = crate::live_bridge_alone(); // timed on the wall clock
    let port = free_port();
    let (bridge, live) = start(port);
    let s = peer(port);
    // The WHJ joint enabled in position mode, as a program would.
    for r in [
        r#"{"op":"whj.mode","joints":"1","mode":"position"}"#,
        r#"{"op":"whj.enable","joints":"1"}"#,
    ] {
        query(&s, "bot/robobus/run", r);
    }
    let reply = query(
        &s,
        "bot/robobus/interface",
        r#"{"interface": "velocity", "joints": ["s0", "j1"]}"#,
    );
    assert_eq!(
        reply["velocity"],
        serde_json::json!(["s0", "j1"]),
        "{reply}"
    );
    let level_7 = sim_1108_wheel_speeds()[6];
    let payload = Float64MultiArray {
        dim: Vec::new(),
        data_offset: 0,
        data: vec![level_7, 0.5],
    }
    .encode();
    let publisher = s
        .declare_publisher("bot/joint_commands/velocity")
        .wait()
        .unwrap();
    for _ in 0..30 {
        publisher.put(payload.clone()).wait().unwrap();
        std::thread::sleep(Duration::from_millis(20));
    }
    let rpm = 0.5 * 60.0 / std::f64::consts::TAU;
    let snap = until(&live, |n| (n.whj[0].speed_rpm - rpm).abs() < 0.05 * rpm);
    assert_eq!(snap.whj[0].mode, 2, "{:?}", snap.whj[0]);
    assert!(
        (snap.whj[0].speed_rpm - rpm).abs() < 0.05 * rpm,
        "{:?}",
        snap.whj[0]
    );
    assert_eq!(snap.wck[0].mode, "wheel", "{:?}", snap.wck[0]);
    let h = bridge.health().drives;
    assert!(
        h.velocity.applied > 0 && h.velocity.refused_out_of_range == 0,
        "{h:?}"
    );
    // Quiet: after the 200 ms timeout, at rest and back on position.
    let snap = until(&live, |n| n.whj[0].mode == 3 && n.wck[0].mode != "wheel");
    assert_eq!(
        (snap.whj[0].mode, snap.whj[0].target_speed_rpm),
        (3, 0.0),
        "{:?}",
        snap.whj[0]
    );
    assert_ne!(snap.wck[0].mode, "wheel", "{:?}", snap.wck[0]);
    let h = bridge.health().drives;
    assert_eq!(h.velocity.timeouts, 1, "{h:?}");
    assert!(h.velocity_joints.is_empty(), "{h:?}");
    let t = StopToken::new();
    t.stop();
    bridge.run(&t).unwrap();
}
