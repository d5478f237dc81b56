//! One bridge per namespace, with bridges as Zenoh peers on loopback in this process: a
//! second bridge on a namespace in use does not start (the first keeps publishing), two
//! on different namespaces both run, and of two started at once on one namespace exactly
//! one keeps serving.

#![allow(clippy::unwrap_used, clippy::panic, clippy::result_large_err)] // tests

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Barrier};
use std::time::{Duration, Instant};

use robobus::ErrorKind;
use robobus::ops::StopToken;
use robobus::station::Station;
use robobus_bridge::{Bridge, BridgeConfig, BridgeError};
use zenoh::Wait as _;

/// A stop token already set: [`Bridge::run`] shuts down at once.
fn stopped() -> StopToken {
    let t = StopToken::new();
    t.stop();
    t
}

/// A free TCP port on loopback (bound, then released for Zenoh to take).
fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

fn endpoint(port: u16) -> String {
    format!("tcp/127.0.0.1:{port}")
}

/// A bridge on the built-in simulated robot, on `namespace`, listening on `listen` and
/// connecting to `connect`.
fn start(
    namespace: &str,
    listen: Option<u16>,
    connect: Option<u16>,
) -> Result<Bridge, BridgeError> {
    let (station, live) = Station::simulated_live(None).unwrap();
    Bridge::start(
        station,
        Some(live),
        BridgeConfig {
            namespace: Some(namespace.to_owned()),
            listen: listen.map(endpoint).into_iter().collect(),
            connect: connect.map(endpoint).into_iter().collect(),
            ..BridgeConfig::default()
        },
    )
}

/// Joint state messages on `key` a Zenoh peer connected to `port` receives in `window`.
fn states_heard(port: u16, key: &str, window: Duration) -> u64 {
    let mut config = zenoh::Config::default();
    for (k, v) in [
        ("mode", "\"peer\"".to_owned()),
        ("listen/endpoints", "[]".to_owned()),
        ("connect/endpoints", format!("[\"{}\"]", endpoint(port))),
        ("scouting/multicast/enabled", "false".to_owned()),
        ("scouting/gossip/enabled", "false".to_owned()),
    ] {
        config.insert_json5(k, &v).unwrap();
    }
    let session = zenoh::open(config).wait().unwrap();
    let heard = Arc::new(AtomicU64::new(0));
    let h = Arc::clone(&heard);
    let _sub = session
        .declare_subscriber(key)
        .callback(move |_| {
            h.fetch_add(1, Ordering::SeqCst);
        })
        .wait()
        .unwrap();
    std::thread::sleep(window);
    heard.load(Ordering::SeqCst)
}

#[test]
fn a_second_bridge_on_a_namespace_in_use_does_not_start_and_the_first_keeps_publishing() {
    let _beside = crate::bridges_beside_each_other();
    let port = free_port();
    let first = start("bot1", Some(port), None).unwrap();
    let e = start("bot1", None, Some(port)).unwrap_err();
    assert!(
        matches!(
            e,
            BridgeError::InUse {
                gave_way: false,
                ..
            }
        ),
        "{e:?}"
    );
    assert_eq!(e.kind(), ErrorKind::NotAvailable);
    let text = e.to_string();
    assert!(
        text.starts_with("namespace \"bot1\" is in use: another bridge (Zenoh ID ")
            && text.contains(&first.zid())
            && text.contains("another --namespace")
            && text.contains("did not start and declared nothing"),
        "{text}"
    );
    // The first serves on, alone.
    let published = first.health().states.published;
    assert!(states_heard(port, "bot1/joint_states", Duration::from_millis(600)) > 0);
    assert!(first.health().states.published > published);
    assert!(!first.gave_way());
    first.run(&stopped()).unwrap();
}

#[test]
fn bridges_on_different_namespaces_both_run() {
    let _beside = crate::bridges_beside_each_other();
    let (port, port2) = (free_port(), free_port());
    let one = start("site/arm1", Some(port), None).unwrap();
    // Connected to the first (peers without gossip forward nothing between others: a
    // consumer connects to the bridge it reads).
    let two = start("site/arm2", Some(port2), Some(port)).unwrap();
    assert!(states_heard(port2, "site/arm2/joint_states", Duration::from_millis(600)) > 0);
    assert!(states_heard(port, "site/arm1/joint_states", Duration::from_millis(300)) > 0);
    assert!(!one.gave_way() && !two.gave_way());
    two.run(&stopped()).unwrap();
    one.run(&stopped()).unwrap();
}

#[test]
fn of_two_bridges_started_at_once_on_one_namespace_exactly_one_keeps_serving() {
    let _beside = crate::bridges_beside_each_other();
    for _ in 0..3 {
        let (a, b) = (free_port(), free_port());
        let barrier = Arc::new(Barrier::new(2));
        let threads: Vec<_> = [(a, b), (b, a)]
            .into_iter()
            .map(|(listen, connect)| {
                let barrier = Arc::clone(&barrier);
                std::thread::spawn(move || {
                    barrier.wait();
                    start("bot1", Some(listen), Some(connect))
                })
            })
            .collect();
        let results: Vec<Result<Bridge, BridgeError>> =
            threads.into_iter().map(|t| t.join().unwrap()).collect();
        // Until both sessions have seen each other's claim, at most 5 s.
        let deadline = Instant::now() + Duration::from_secs(5);
        let serving = || {
            results
                .iter()
                .filter(|r| r.as_ref().is_ok_and(|b| !b.gave_way()))
                .count()
        };
        while serving() > 1 && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(20));
        }
        assert_eq!(serving(), 1, "{results:?}");
        for r in results {
            match r {
                Ok(bridge) if bridge.gave_way() => {
                    let e = bridge.run(&StopToken::new()).unwrap_err();
                    assert!(
                        matches!(e, BridgeError::InUse { gave_way: true, .. }),
                        "{e:?}"
                    );
                    assert!(e.to_string().contains("gave way"), "{e}");
                }
                Ok(bridge) => bridge.run(&stopped()).unwrap(),
                Err(e) => assert!(matches!(e, BridgeError::InUse { .. }), "{e:?}"),
            }
        }
    }
}
