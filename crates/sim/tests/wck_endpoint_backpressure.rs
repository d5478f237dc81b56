//! Input backpressure of the pty endpoint: a client that floods the port (4 MB in one
//! write) is held back at the wire rate, as a real port holds it, instead of the simulator
//! swallowing everything and staying deaf for the minutes the flood takes on the simulated
//! wire. After the flood the client discards what it could not send (`tcflush`), as a
//! program does after a write timeout, and its next command is answered at once.
#![cfg(target_os = "linux")]
#![allow(clippy::unwrap_used, clippy::panic)] // test code

use std::os::fd::AsFd as _;
use std::time::{Duration, Instant};

use robobus_link::{ByteLink, LinkError};
use robobus_sim::wck::{Bus, BusConfig, Model, spawn};

#[test]
fn a_4mb_flood_blocks_the_writer_and_a_command_after_it_is_answered() {
    let mut bus = Bus::with_servos(BusConfig::default(), Model::W1108, [0]);
    bus.advance(Duration::from_millis(70)); // past the deafness after power-up
    let (endpoint, mut client) = spawn(bus).unwrap();
    client.set_write_timeout(Duration::from_millis(500));

    // Zero bytes: no command header, so the servo ignores all of them.
    let flood = vec![0u8; 4 << 20];
    let written = match client.write_all(&flood) {
        Ok(()) => flood.len(),
        Err(LinkError::WriteTimeout { written, .. }) => written,
        Err(e) => panic!("{e}"),
    };
    // At 115200 bit/s the wire carries 11.5 kB/s: in the 0.5 s the write waited, the
    // simulator may take a few kB, the kernel buffers a few dozen more.
    assert!(
        written < 512 << 10,
        "the simulator took {written} bytes of the flood at once"
    );
    nix::sys::termios::tcflush(client.as_fd(), nix::sys::termios::FlushArg::TCOFLUSH).unwrap();

    client.discard_input().unwrap();
    let t0 = Instant::now();
    client.write_all(&[0xFF, 0xA0, 0x00, 0x20]).unwrap(); // status of servo 0
    let mut reply = [0u8; 2];
    client
        .read_exact(&mut reply, t0 + Duration::from_secs(3))
        .unwrap_or_else(|e| panic!("no answer after the flood ({e})"));
    assert_eq!(reply[0], 0x00, "{reply:?}");
    let stats = endpoint.stop().unwrap();
    assert!(stats.bytes_in < 512 << 10, "{stats:?}");
}
