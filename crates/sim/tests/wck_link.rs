//! The in-process link on its virtual clock: time moves only when the client waits, and
//! then exactly to the reply's last byte or the deadline.
#![allow(clippy::unwrap_used, clippy::panic)] // test helpers

use std::time::Duration;

use robobus_link::{ByteLink, LinkError};
use robobus_sim::wck::{Bus, BusConfig, Model, SimLink, Timing};
use robobus_wck::{BaudRate, Command, ServoId, timing};

fn bus(baud: BaudRate) -> Bus {
    let config = BusConfig {
        host_baud: baud,
        timing: Timing::MANUAL,
        max_skew: Duration::ZERO,
        ..BusConfig::default()
    };
    Bus::with_servos(config, Model::W1108, [0])
}

#[test]
fn a_reply_arrives_exactly_one_modelled_transaction_after_the_command() {
    for baud in [BaudRate::B115200, BaudRate::B921600, BaudRate::B4800] {
        let (mut link, handle) = SimLink::virtual_clock(bus(baud));
        let t0 = link.now();
        link.sleep_until(t0 + Duration::from_millis(70)); // past the deafness after power-up
        let start = link.now();
        assert_eq!(start - t0, Duration::from_millis(70));
        assert_eq!(handle.now(), Duration::from_millis(70));
        let status = Command::StatusRead {
            id: ServoId::new(0).unwrap(),
        };
        link.write_all(&status.encode()).unwrap();
        let mut reply = [0u8; 2];
        link.read_exact(&mut reply, start + Duration::from_secs(1))
            .unwrap();
        assert_eq!(reply, [0, 127]);
        // The model puts bytes on bit boundaries rounded to whole nanoseconds.
        let took = link.now() - start;
        let modelled = timing::transaction_time(&status, baud);
        assert!(
            took.abs_diff(modelled) < Duration::from_nanos(10),
            "at {baud}: {took:?}, modelled {modelled:?}"
        );
    }
}

#[test]
fn a_silent_module_times_out_exactly_at_the_deadline_and_the_wall_clock_moves_nothing() {
    let (mut link, handle) = SimLink::virtual_clock(bus(BaudRate::B115200));
    handle.sleep(Duration::from_millis(70));
    let start = link.now();
    assert_eq!(handle.now(), Duration::from_millis(70));
    // Module 5 is not there.
    let status = Command::StatusRead {
        id: ServoId::new(5).unwrap(),
    };
    link.write_all(&status.encode()).unwrap();
    let deadline = start + Duration::from_millis(12);
    let mut reply = [0u8; 2];
    let err = link.read_exact(&mut reply, deadline).unwrap_err();
    assert!(
        matches!(
            err,
            LinkError::Timeout {
                received: 0,
                expected: 2
            }
        ),
        "{err:?}"
    );
    assert_eq!(link.now(), deadline);
    // Simulated time stands still while the client does not wait.
    std::thread::sleep(Duration::from_millis(5));
    assert_eq!(link.now(), deadline);
    // A deadline in the past reads only what is there, and moves nothing.
    assert!(link.read_some(&mut reply, start).unwrap_err().is_timeout());
    assert_eq!(link.now(), deadline);
    assert_eq!(handle.now(), Duration::from_millis(82));
}

#[test]
fn a_fast_forwarding_link_skips_its_waits_in_simulated_time_on_the_wall_clock() {
    let (mut link, handle) = SimLink::fast_forward(bus(BaudRate::B115200));
    handle.sleep(Duration::from_millis(70));
    // A silent module: the read jumps 1 s of simulated time, at once on the wall clock.
    let status = Command::StatusRead {
        id: ServoId::new(5).unwrap(),
    };
    let wall = std::time::Instant::now();
    let sim0 = handle.now();
    link.write_all(&status.encode()).unwrap();
    let deadline = link.now() + Duration::from_secs(1);
    let mut reply = [0u8; 2];
    assert!(
        link.read_exact(&mut reply, deadline)
            .unwrap_err()
            .is_timeout()
    );
    // Its clock is the wall clock; simulated time ran ahead by the wait.
    assert!(link.now() < deadline);
    assert!(handle.now().saturating_sub(sim0) >= Duration::from_secs(1));
    assert!(
        wall.elapsed() < Duration::from_millis(900),
        "{:?}",
        wall.elapsed()
    );
}
