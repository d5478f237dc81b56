//! The pty endpoint on the wall clock, driven in-process through the pty's slave side.
#![cfg(target_os = "linux")]
#![allow(clippy::unwrap_used, clippy::panic)] // test helpers

use std::time::{Duration, Instant};

use robobus_link::{ByteLink, LinkError, PtyOptions, PtyPair};
use robobus_sim::WaitMode;
use robobus_sim::wck::{Bus, BusConfig, Endpoint, Model, spawn, spawn_waiting};

fn transact(client: &mut impl ByteLink, packet: &[u8], wait: Duration) -> (Vec<u8>, Duration) {
    client.discard_input().unwrap();
    let t0 = Instant::now();
    client.write_all(packet).unwrap();
    let mut buf = [0u8; 2];
    match client.read_exact(&mut buf, t0 + wait) {
        Ok(()) => (buf.to_vec(), t0.elapsed()),
        Err(LinkError::Timeout { received, .. }) => (buf[..received].to_vec(), t0.elapsed()),
        Err(e) => panic!("{e}"),
    }
}

#[test]
fn endpoint_serves_paced_replies_follows_the_client_baud_and_takes_commands() {
    let pair = PtyPair::open(&PtyOptions::default()).unwrap();
    let bus = Bus::with_servos(BusConfig::default(), Model::W1413, [0, 1]);
    let endpoint = Endpoint::spawn(bus, pair.master, pair.slave_path.clone()).unwrap();
    assert_eq!(endpoint.path(), pair.slave_path);
    let mut client = pair.slave;
    // Past the 65 ms of deafness after power-up, in simulated time (the serving thread
    // may start late on a busy machine).
    let awake = |from: Duration| {
        while endpoint.with_bus(|b| b.now()).unwrap() < from + Duration::from_millis(70) {
            std::thread::sleep(Duration::from_millis(5));
        }
    };
    awake(Duration::ZERO);

    // Generous: a shared virtual machine can stall the serving thread for ~200 ms.
    let wait = Duration::from_secs(1);
    let (reply, took) = transact(&mut client, &[0xFF, 0xA0, 0x00, 0x20], wait);
    assert_eq!(reply, [0x00, 0x7F]);
    // Command 347 µs + turnaround 1006.6 µs + reply 173.6 µs on the simulated wire.
    assert!(took >= Duration::from_micros(1520), "{took:?}");

    // The test API through the serving thread.
    endpoint
        .with_bus(|b| b.servo_mut(1).unwrap().set_position(40))
        .unwrap();
    assert_eq!(
        transact(&mut client, &[0xFF, 0xA1, 0x00, 0x21], wait).0,
        [0x00, 40]
    );

    // A client at another baud rate gets nothing sensible.
    client.set_baud(57_600).unwrap();
    std::thread::sleep(Duration::from_millis(30));
    let (reply, _) = transact(
        &mut client,
        &[0xFF, 0xA0, 0x00, 0x20],
        Duration::from_millis(30),
    );
    assert_ne!(reply, [0x00, 0x7F]);
    client.set_baud(115_200).unwrap();
    std::thread::sleep(Duration::from_millis(30));
    assert_eq!(
        transact(&mut client, &[0xFF, 0xA0, 0x00, 0x20], wait).0,
        [0x00, 0x7F]
    );

    // Power-cycled, the module is deaf for 65 ms.
    let cycled_at = endpoint
        .with_bus(|b| {
            b.power_cycle(0);
            b.now()
        })
        .unwrap();
    let (reply, _) = transact(
        &mut client,
        &[0xFF, 0xA0, 0x00, 0x20],
        Duration::from_millis(20),
    );
    assert!(reply.is_empty(), "{reply:?}");
    awake(cycled_at);
    assert_eq!(
        transact(&mut client, &[0xFF, 0xA0, 0x00, 0x20], wait).0,
        [0x00, 0x7F]
    );

    let stats = endpoint.stop().unwrap();
    assert!(stats.bytes_in >= 24 && stats.bytes_out >= 8, "{stats:?}");
    assert!(stats.cpu < stats.wall, "{stats:?}");
}

#[test]
fn a_status_read_wakes_the_serving_thread_for_the_command_and_each_reply_byte_only() {
    let mut bus = Bus::with_servos(BusConfig::default(), Model::W1108, [0]);
    bus.advance(Duration::from_millis(70));
    let (endpoint, mut client) = spawn(bus).unwrap();
    let reads = 200u64;
    let t0 = Instant::now();
    for _ in 0..reads {
        let (reply, _) = transact(
            &mut client,
            &[0xFF, 0xA0, 0x00, 0x20],
            Duration::from_secs(1),
        );
        assert_eq!(reply, [0x00, 0x7F]);
    }
    let wall = t0.elapsed();
    let stats = endpoint.stop().unwrap();
    // The command, each of the two reply bytes, and the 10 ms idle ticks; not every byte
    // a module receives (four per command, which would make seven).
    let ticks = u64::try_from(wall.as_millis() / 10).unwrap() + 2;
    assert!(
        stats.wakeups <= 3 * reads + ticks,
        "{} wake-ups for {reads} reads in {wall:?}",
        stats.wakeups
    );
}

#[test]
fn the_precise_endpoint_answers_the_same_and_reports_each_reply_bytes_lateness() {
    for wait in [WaitMode::Sleep, WaitMode::SPIN] {
        let mut bus = Bus::with_servos(BusConfig::default(), Model::W1108, [0]);
        bus.advance(Duration::from_millis(70));
        let (endpoint, mut client) = spawn_waiting(bus, wait).unwrap();
        let reads = 50u64;
        for _ in 0..reads {
            let (reply, took) = transact(
                &mut client,
                &[0xFF, 0xA0, 0x00, 0x20],
                Duration::from_secs(1),
            );
            assert_eq!(reply, [0x00, 0x7F], "{wait}");
            // Never before the wire and the module's turnaround allow (6 bytes at 115200
            // bit/s and 1006.6 µs).
            assert!(took >= Duration::from_micros(1527), "{wait}: {took:?}");
        }
        let stats = endpoint.stop().unwrap();
        assert_eq!(stats.wait, wait);
        // Every reply byte's release is in the record (wall-clock values, not checked).
        let l = stats.lateness;
        assert_eq!(l.releases, 2 * reads, "{wait}: {stats:?}");
        assert!(
            l.p50 <= l.p99 && l.p99.is_some_and(|p| p <= l.max),
            "{wait}: {l:?}"
        );
    }
}
