//! The bridge at the buses' rate, with a Zenoh peer on loopback in this process: a steady
//! command stream within what the buses carry is applied command for command (the
//! states give way to it, counted), held commands are counted with their reason, and a
//! joint state rate the buses cannot carry is said at start and counted lost in the
//! health.

#![allow(clippy::unwrap_used, clippy::panic, clippy::result_large_err)] // tests

use std::time::{Duration, Instant};

use robobus::ops::StopToken;
use robobus::station::Station;
use robobus_bridge::cdr::Float64MultiArray;
use robobus_bridge::{Bridge, BridgeConfig, Health};
use zenoh::Wait as _;

/// One bridge of these tests at a time, and none of the other files' while one runs
/// (`crate::live_bridge_alone`): each runs a live simulated robot and a bridge whose command
/// stream is timed on the wall clock; three at once on a 2-core machine starve each other's
/// threads for longer than a command's room to spare, which the bridge rightly counts as a
/// superseded command or a hold (the first test then failed about one run in six).
use crate::live_bridge_alone as one_at_a_time;

/// A free TCP port on loopback (bound, then released for Zenoh to take).
fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// A bridge on the built-in simulated robot (16 wCK servos at 115200 bit/s, 7 WHJ
/// joints), namespace `bot`, listening on `port`.
fn bridge(port: u16, rate_hz: f64, armed: bool) -> Bridge {
    let (station, live) = Station::simulated_live(None).unwrap();
    Bridge::start(
        station,
        Some(live),
        BridgeConfig {
            namespace: Some("bot".into()),
            rate_hz,
            armed,
            listen: vec![format!("tcp/127.0.0.1:{port}")],
            ..BridgeConfig::default()
        },
    )
    .unwrap()
}

/// A Zenoh peer connected to the bridge on `port`, and its publisher of `bot/joint_commands`,
/// once the bridge's subscriber is matched.
fn commander(port: u16) -> (zenoh::Session, zenoh::pubsub::Publisher<'static>) {
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
    let session = zenoh::open(config).wait().unwrap();
    let publisher = session
        .declare_publisher("bot/joint_commands")
        .wait()
        .unwrap();
    let deadline = Instant::now() + Duration::from_secs(10);
    while !publisher.matching_status().wait().unwrap().matching() {
        assert!(
            Instant::now() < deadline,
            "the bridge's subscriber never matched"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
    (session, publisher)
}

fn command(targets: &[f64]) -> Vec<u8> {
    Float64MultiArray {
        dim: Vec::new(),
        data_offset: 0,
        data: targets.to_vec(),
    }
    .encode()
}

/// Publishes `n` commands `every` apart (on a schedule, not after each other's sends).
fn stream(
    publisher: &zenoh::pubsub::Publisher<'static>,
    n: usize,
    every: Duration,
    payload: &[u8],
) {
    let start = Instant::now();
    for k in 0..n {
        let at = start + every * u32::try_from(k).unwrap();
        std::thread::sleep(at.saturating_duration_since(Instant::now()));
        publisher.put(payload.to_vec()).wait().unwrap();
    }
}

/// The health once every one of `n` commands was received and dealt with (applied,
/// superseded, held or refused), at most 10 s.
fn settled(bridge: &Bridge, n: u64) -> Health {
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        let h = bridge.health();
        let c = &h.commands;
        let dealt = c.applied + c.superseded + c.held + h.refused.malformed;
        if (c.received == n && dealt == n) || Instant::now() > deadline {
            return h;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}

#[test]
fn a_steady_10_hz_stream_the_buses_carry_is_applied_command_for_command() {
    let _one = one_at_a_time();
    let port = free_port();
    let b = bridge(port, 50.0, true);
    let joints = b.joint_names().len();
    // The buses carry the stream with room to spare: one command to the 23 joints is less
    // than a third of its 100 ms (26 ms on the wire: 16 wCK servos at 115200 bit/s). The
    // room is what a loaded 2-core machine may take from the bridge's threads; at 20 Hz
    // (24 ms to spare) a command now and then waited for its predecessor and was rightly
    // counted superseded.
    let carried = b.capacity().commands_hz().unwrap();
    assert!(carried > 30.0, "{:?}", b.capacity());
    // But not 50 Hz of states beside it.
    assert!(
        b.capacity().sample_ms() + b.capacity().command_ms() > 20.0,
        "{:?}",
        b.capacity()
    );
    let (_session, publisher) = commander(port);
    let payload = command(&vec![0.0; joints]);
    // The stream's first command reads every servo before its step (no answer of theirs
    // is recent yet): twice the wire time of the next ones. Then 30 more, 100 ms apart.
    stream(&publisher, 1, Duration::ZERO, &payload);
    assert_eq!(settled(&b, 1).commands.applied, 1);
    stream(&publisher, 30, Duration::from_millis(100), &payload);
    let h = settled(&b, 31);
    let c = &h.commands;
    assert_eq!(
        (c.received, c.applied, c.superseded, c.held, c.stale),
        (31, 31, 0, 0, 0),
        "{h:#?}"
    );
    // No hold while the stream ran: a command every 100 ms, within the 200 ms timeout.
    assert_eq!(c.holds, 0, "{h:#?}");
    // The buses cannot carry 50 Hz of states beside it: the samples gave way, counted.
    assert!(h.states.lost_to_commands > 0, "{h:#?}");
    assert_eq!(
        h.states.lost_reason.as_deref(),
        Some("the buses were busy with commands (commands come first)")
    );
    // Once the stream stopped, its joints were held once.
    std::thread::sleep(Duration::from_millis(400));
    assert_eq!(b.health().commands.holds, 1);
    b.run(&stopped()).unwrap();
}

#[test]
fn held_commands_are_counted_with_their_reason() {
    let _one = one_at_a_time();
    let port = free_port();
    let b = bridge(port, 5.0, false);
    let joints = b.joint_names().len();
    let (_session, publisher) = commander(port);
    stream(
        &publisher,
        5,
        Duration::from_millis(20),
        &command(&vec![0.0; joints]),
    );
    let h = settled(&b, 5);
    assert_eq!(
        (h.commands.held, h.refused.not_armed, h.commands.applied),
        (5, 5, 0)
    );
    let why = h.commands.last_held.unwrap();
    assert!(
        why.starts_with("joint_commands: not armed: motion needs this bridge armed"),
        "{why}"
    );
    // A command of the wrong count: held too, with its own reason.
    stream(
        &publisher,
        3,
        Duration::from_millis(20),
        &command(&[0.0; 2]),
    );
    let h = settled(&b, 8);
    assert_eq!((h.commands.held, h.refused.not_armed), (8, 8), "{h:#?}");
    // Armed, the same three are out of range.
    b.run(&stopped()).unwrap();
    let port = free_port();
    let b = bridge(port, 5.0, true);
    let (_session, publisher) = commander(port);
    stream(
        &publisher,
        3,
        Duration::from_millis(20),
        &command(&[0.0; 2]),
    );
    let h = settled(&b, 3);
    assert_eq!(
        (h.commands.held, h.refused.out_of_range, h.commands.applied),
        (3, 3, 0),
        "{h:#?}"
    );
    let why = h.commands.last_held.unwrap();
    assert!(
        why.starts_with("joint_commands: ")
            && why.contains("2 values")
            && why.contains("23 values"),
        "{why}"
    );
    b.run(&stopped()).unwrap();
}

#[test]
fn a_state_rate_the_buses_cannot_carry_is_said_and_its_lost_samples_counted() {
    let _one = one_at_a_time();
    let port = free_port();
    let b = bridge(port, 200.0, false);
    let limit = b.capacity().states_hz().unwrap();
    // 16 status reads at 115200 bit/s with their guard, and 7 WHJ joints' two reads:
    // 1.3 ms each at the least (the wCK command, turnaround and reply).
    assert!(limit < 1e3 / (16.0 * 1.3), "{:?}", b.capacity());
    let note = b.rate_note().unwrap();
    assert!(
        note.starts_with(&format!(
            "the buses carry at most {limit:.1} Hz of joint states, not the 200 Hz asked"
        )),
        "{note}"
    );
    std::thread::sleep(Duration::from_millis(1500));
    let h = b.health();
    let s = &h.states;
    assert_eq!(s.limited.as_deref(), Some(note.as_str()));
    assert_eq!(s.bus_limit_hz, Some(limit));
    assert!(s.published > 0 && s.lost_samples > s.published, "{s:#?}");
    assert_eq!(s.lost_to_commands, 0, "{s:#?}");
    assert_eq!(
        s.lost_reason.as_deref(),
        Some("a sample took longer than the period asked (the buses cannot carry the rate)")
    );
    assert!(s.achieved_hz.unwrap() < 200.0, "{s:#?}");
    // A rate they carry is not said.
    let b2 = bridge(free_port(), 5.0, false);
    assert_eq!(b2.rate_note(), None);
    assert_eq!(b2.health().states.limited, None);
    b2.run(&stopped()).unwrap();
    b.run(&stopped()).unwrap();
}

/// A stop token already set: [`Bridge::run`] shuts down at once.
fn stopped() -> StopToken {
    let t = StopToken::new();
    t.stop();
    t
}
