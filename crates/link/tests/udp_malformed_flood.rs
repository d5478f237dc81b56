//! A flood of 10 000 malformed datagrams on the UDP bus: every one is counted
//! (`UdpBusStats::malformed`), the WARN log stays a few lines long (the first five, then
//! one summary per second at most; it used to be one line per datagram), and `recv` keeps
//! its deadline while the flood goes on.
//!
//! Runs inside a private network namespace (`unshare -n`, loopback up, 224.0.0.0/4 routed
//! to it): the outer test starts this binary's inner test there.

#![allow(clippy::unwrap_used, clippy::panic)] // test code
#![cfg(target_os = "linux")]

use std::io::Write;
use std::net::{SocketAddrV4, UdpSocket};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use robobus_link::{FrameLink, UdpBus, UdpBusConfig};

const IN_NETNS_ENV: &str = "ROBOBUS_LINK_IN_NETNS";
const FLOOD: u64 = 10_000;

#[test]
fn a_flood_of_malformed_datagrams_is_counted_and_logged_a_few_times() {
    robobus_testkit::Inner::exact(module_path!(), "inner_malformed_flood", IN_NETNS_ENV)
        .in_private_netns()
        .expect_marker("MALFORMED FLOOD OK");
}

/// Log lines written by the subscriber.
#[derive(Clone, Default)]
struct Lines(Arc<Mutex<Vec<u8>>>);

impl Write for Lines {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0.lock().unwrap().extend_from_slice(buf);
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

#[test]
#[ignore = "run inside unshare -n by a_flood_of_malformed_datagrams_is_counted_and_logged_a_few_times"]
fn inner_malformed_flood() {
    std::env::var(IN_NETNS_ENV).expect("runs only inside the namespace its outer test makes");
    let log = Lines::default();
    let writer = log.clone();
    let subscriber = tracing_subscriber::fmt()
        .with_writer(move || writer.clone())
        .with_ansi(false)
        .with_max_level(tracing::Level::WARN)
        .finish();
    let _guard = tracing::subscriber::set_default(subscriber);

    let cfg = UdpBusConfig::default();
    let mut bus = UdpBus::open(&cfg).unwrap();
    let sender = UdpSocket::bind("127.0.0.1:0").unwrap();
    let dest = SocketAddrV4::new(cfg.group, cfg.port);
    let t0 = Instant::now();
    let mut sent = 0u64;
    while sent < FLOOD {
        // In batches the receiver keeps up with, so no datagram is lost in the kernel.
        for _ in 0..100 {
            sender.send_to(b"\x00not msgpack", dest).unwrap();
            sent += 1;
        }
        let deadline = Instant::now() + Duration::from_secs(10);
        while bus.stats().malformed < sent {
            // Nothing valid arrives: every recv ends at its (short) deadline.
            let asked = Instant::now();
            let e = bus.recv(asked + Duration::from_millis(2)).unwrap_err();
            assert!(e.is_timeout(), "{e}");
            assert!(
                asked.elapsed() < Duration::from_millis(500),
                "recv overran its deadline by {:?}",
                asked.elapsed()
            );
            assert!(
                Instant::now() < deadline,
                "datagrams lost: {:?}",
                bus.stats()
            );
        }
    }
    let took = t0.elapsed();
    assert_eq!(bus.stats().malformed, FLOOD);
    assert_eq!(bus.stats().echoes, 0);
    drop(bus); // logs the last summary
    let text = String::from_utf8(log.0.lock().unwrap().clone()).unwrap();
    let lines = text.lines().count();
    // Five datagrams, the "further ... summarised" note, one summary per started second,
    // the final one on drop.
    let allowed = 5 + 1 + usize::try_from(took.as_secs()).unwrap() + 2;
    assert!(
        lines <= allowed,
        "{lines} log lines for {FLOOD} datagrams in {took:?} (allowed {allowed}):\n{}",
        text.lines().take(20).collect::<Vec<_>>().join("\n")
    );
    assert!(
        text.lines()
            .filter(|l| l.contains("skipping malformed datagram"))
            .count()
            == 5,
        "{text}"
    );
    assert!(text.contains("total=10000"), "{text}");
    println!("{lines} log lines in {took:?}; MALFORMED FLOOD OK");
}
