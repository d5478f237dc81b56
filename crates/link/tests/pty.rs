//! Pseudo-terminal pairs: raw transparency at every wCK baud code, deadlines, symlinks,
//! and the serial-port path (`serialport` opening the slave side by path).

// Pseudo-terminals are Unix's (Windows has none: simulators serve TCP there).
#![cfg(unix)]
// Helpers outside #[test] functions may unwrap and panic too: a failure is a failed test.
#![allow(clippy::unwrap_used, clippy::panic)]

use std::time::{Duration, Instant};

use robobus_link::pty::termios_speed;
use robobus_link::{ByteLink, LinkError, PtyOptions, PtyPair, PtySymlink, SerialLink};

/// The wCK baud codes (manual §"Baud rate").
const BAUDS: [u32; 8] = [
    921_600, 460_800, 230_400, 115_200, 57_600, 38_400, 9_600, 4_800,
];

fn all_bytes() -> Vec<u8> {
    (0..=255u8).collect()
}

fn soon() -> Instant {
    Instant::now() + Duration::from_secs(5)
}

fn assert_transparent(a: &mut dyn ByteLink, b: &mut dyn ByteLink, baud: u32) {
    let bytes = all_bytes();
    let mut got = vec![0u8; 256];
    a.write_all(&bytes).unwrap();
    b.read_exact(&mut got, soon()).unwrap();
    assert_eq!(got, bytes, "a -> b at {baud}");
    // Reverse order the other way, so a swapped direction cannot pass by accident.
    let rev: Vec<u8> = bytes.iter().rev().copied().collect();
    b.write_all(&rev).unwrap();
    a.read_exact(&mut got, soon()).unwrap();
    assert_eq!(got, rev, "b -> a at {baud}");
}

#[test]
fn all_byte_values_both_ways_at_every_baud_code() {
    let PtyPair {
        mut master,
        mut slave,
        ..
    } = PtyPair::open(&PtyOptions::default()).unwrap();
    for baud in BAUDS {
        master.set_baud(baud).unwrap();
        slave.set_baud(baud).unwrap();
        assert_eq!(termios_speed(&slave).unwrap(), Some(baud));
        assert_eq!(slave.baud(), Some(baud));
        assert_transparent(&mut master, &mut slave, baud);
    }
}

#[test]
fn serial_link_on_the_slave_path_is_transparent_at_every_baud_code() {
    let pair = PtyPair::open(&PtyOptions::default()).unwrap();
    let PtyPair {
        mut master,
        slave,
        slave_path,
    } = pair;
    drop(slave);
    for baud in BAUDS {
        let mut port = SerialLink::open(&slave_path, baud).unwrap();
        assert_eq!(port.baud(), Some(baud));
        assert_transparent(&mut master, &mut port, baud);
    }
    // Changing the rate on an open port.
    let mut port = SerialLink::open(&slave_path, 115_200).unwrap();
    port.set_baud(921_600).unwrap();
    assert_transparent(&mut master, &mut port, 921_600);
    assert_eq!(port.latency_timer(), None, "a pty has no USB latency timer");
}

#[test]
fn reads_with_nothing_to_read_time_out_near_their_deadline() {
    let PtyPair {
        mut master,
        mut slave,
        ..
    } = PtyPair::open(&PtyOptions::default()).unwrap();
    let mut buf = [0u8; 4];
    for wait in [Duration::from_millis(30), Duration::from_millis(150)] {
        let start = Instant::now();
        let err = slave.read_exact(&mut buf, start + wait).unwrap_err();
        let took = start.elapsed();
        assert!(
            matches!(
                err,
                LinkError::Timeout {
                    received: 0,
                    expected: 4
                }
            ),
            "{err:?}"
        );
        assert!(took >= wait, "returned early: {took:?} < {wait:?}");
        assert!(
            took < wait + Duration::from_millis(500),
            "returned late: {took:?}"
        );
    }
    // A deadline in the past still returns what is already there.
    master.write_all(&[1, 2]).unwrap();
    std::thread::sleep(Duration::from_millis(20));
    let err = slave.read_exact(&mut buf, Instant::now()).unwrap_err();
    assert!(
        matches!(
            err,
            LinkError::Timeout {
                received: 2,
                expected: 4
            }
        ),
        "{err:?}"
    );
    assert_eq!(&buf[..2], &[1, 2]);
    // Bytes arriving while waiting are picked up before the deadline.
    let t = std::thread::spawn(move || {
        std::thread::sleep(Duration::from_millis(50));
        master.write_all(&[3, 4, 5, 6]).unwrap();
        master
    });
    let start = Instant::now();
    slave
        .read_exact(&mut buf, start + Duration::from_secs(5))
        .unwrap();
    assert_eq!(buf, [3, 4, 5, 6]);
    assert!(start.elapsed() < Duration::from_secs(4));
    let _master = t.join().unwrap();
}

#[test]
fn a_reply_read_whole_waits_for_its_last_byte_and_single_bytes_still_wake_reads() {
    let PtyPair {
        mut master,
        mut slave,
        ..
    } = PtyPair::open(&PtyOptions::default()).unwrap();
    // The two bytes of a reply written 40 ms apart: the read waits for both (the slave
    // is readable only once both are there) and returns them together.
    let t = std::thread::spawn(move || {
        master.write_all(&[7]).unwrap();
        std::thread::sleep(Duration::from_millis(40));
        master.write_all(&[8]).unwrap();
        master
    });
    let mut two = [0u8; 2];
    slave.read_exact(&mut two, soon()).unwrap();
    assert_eq!(two, [7, 8]);
    let mut master = t.join().unwrap();
    // Only one byte of two by the deadline: the timeout keeps it.
    master.write_all(&[9]).unwrap();
    let err = slave
        .read_exact(&mut two, Instant::now() + Duration::from_millis(30))
        .unwrap_err();
    assert!(
        matches!(
            err,
            LinkError::Timeout {
                received: 1,
                expected: 2
            }
        ),
        "{err:?}"
    );
    assert_eq!(two[0], 9);
    // A read of whatever comes is woken by a single byte again.
    master.write_all(&[10]).unwrap();
    let mut buf = [0u8; 8];
    assert_eq!(slave.read_some(&mut buf, soon()).unwrap(), 1);
    assert_eq!(buf[0], 10);
    // The master side is woken by single bytes whatever the slave asked for.
    slave.write_all(&[11]).unwrap();
    assert_eq!(master.read_some(&mut buf, soon()).unwrap(), 1);
    assert_eq!(buf[0], 11);
}

#[test]
fn discard_input_drops_pending_bytes() {
    let PtyPair {
        mut master,
        mut slave,
        ..
    } = PtyPair::open(&PtyOptions::default()).unwrap();
    master.write_all(&[0xAA; 32]).unwrap();
    std::thread::sleep(Duration::from_millis(20));
    slave.discard_input().unwrap();
    master.write_all(&[0x55]).unwrap();
    let mut one = [0u8; 1];
    slave.read_exact(&mut one, soon()).unwrap();
    assert_eq!(one, [0x55]);
    slave.write_all(&[0x11; 8]).unwrap();
    std::thread::sleep(Duration::from_millis(20));
    master.discard_input().unwrap();
    assert!(
        master
            .read_some(&mut one, Instant::now())
            .unwrap_err()
            .is_timeout()
    );
}

#[test]
fn stable_symlink_is_created_replaced_and_removed() {
    let dir = tempfile::tempdir().unwrap();
    let link = dir.path().join("robobus-wck");
    std::os::unix::fs::symlink("/dev/pts/stale-robobus", &link).unwrap();
    let pair = PtyPair::open(&PtyOptions {
        symlink: Some(link.clone()),
        ..PtyOptions::default()
    })
    .unwrap();
    assert_eq!(std::fs::read_link(&link).unwrap(), pair.slave_path);
    assert_eq!(pair.master.symlink(), Some(link.as_path()));
    // Programs open it by the stable name.
    let PtyPair {
        mut master, slave, ..
    } = pair;
    drop(slave);
    let mut port = SerialLink::open(&link, 57_600).unwrap();
    port.write_all(&[0xFF, 0x03, 0x7F, 0x7C]).unwrap();
    let mut got = [0u8; 4];
    master.read_exact(&mut got, soon()).unwrap();
    assert_eq!(got, [0xFF, 0x03, 0x7F, 0x7C]);
    drop(port);
    drop(master);
    assert!(
        std::fs::symlink_metadata(&link).is_err(),
        "symlink left behind"
    );

    // A regular file in the way is not clobbered.
    std::fs::write(&link, "keep me").unwrap();
    let err = PtyPair::open(&PtyOptions {
        symlink: Some(link.clone()),
        ..PtyOptions::default()
    })
    .unwrap_err();
    assert!(err.to_string().contains("robobus-wck"), "{err}");
    assert_eq!(std::fs::read_to_string(&link).unwrap(), "keep me");
}

#[test]
fn a_pty_symlink_takes_only_stale_links_of_its_own_and_removes_only_its_own() {
    let dir = tempfile::tempdir().unwrap();
    let link = dir.path().join("wck");
    let a = PtyPair::open(&PtyOptions::default()).unwrap();
    let b = PtyPair::open(&PtyOptions::default()).unwrap();

    let first = PtySymlink::create(&link, &a.slave_path).unwrap();
    assert_eq!(std::fs::read_link(&link).unwrap(), a.slave_path);
    // A live one's link is not taken over: the error names the process holding it.
    let e = PtySymlink::create(&link, &b.slave_path).unwrap_err();
    assert!(
        matches!(&e, LinkError::PathInUse { path, .. } if path == &link),
        "{e}"
    );
    assert!(
        e.to_string().contains(&std::process::id().to_string()),
        "{e}"
    );
    assert_eq!(std::fs::read_link(&link).unwrap(), a.slave_path);

    // Somebody replaces the link while it lives: dropping ours leaves theirs alone.
    std::fs::remove_file(&link).unwrap();
    std::os::unix::fs::symlink(&b.slave_path, &link).unwrap();
    drop(first);
    assert_eq!(std::fs::read_link(&link).unwrap(), b.slave_path);

    // Somebody else's symlink to an existing file is refused.
    let e = PtySymlink::create(&link, &a.slave_path).unwrap_err();
    assert!(e.to_string().contains("did not make"), "{e}");
    assert_eq!(std::fs::read_link(&link).unwrap(), b.slave_path);

    // A directory is refused; a dangling link into /dev/pts is stale and replaced.
    std::fs::remove_file(&link).unwrap();
    std::fs::create_dir(&link).unwrap();
    let e = PtySymlink::create(&link, &a.slave_path).unwrap_err();
    assert!(e.to_string().contains("a directory"), "{e}");
    std::fs::remove_dir(&link).unwrap();
    std::os::unix::fs::symlink("/dev/pts/robobus-gone", &link).unwrap();
    let ours = PtySymlink::create(&link, &a.slave_path).unwrap();
    assert_eq!(ours.path(), link);
    drop(ours);
    assert!(std::fs::symlink_metadata(&link).is_err());
    let mut lock = link.as_os_str().to_owned();
    lock.push(".lock");
    assert!(std::fs::symlink_metadata(&lock).is_err(), "lock file left");
}

#[test]
fn the_master_survives_programs_closing_the_slave_and_sees_its_own_close() {
    let PtyPair {
        mut master,
        slave,
        slave_path,
    } = PtyPair::open(&PtyOptions::default()).unwrap();
    drop(slave);
    {
        let mut port = SerialLink::open(&slave_path, 115_200).unwrap();
        port.write_all(&[1]).unwrap();
    }
    let mut b = [0u8; 1];
    master.read_exact(&mut b, soon()).unwrap();
    // No hang-up although no program has the slave open.
    assert!(
        master
            .read_some(&mut b, Instant::now() + Duration::from_millis(20))
            .unwrap_err()
            .is_timeout()
    );

    let PtyPair {
        master, mut slave, ..
    } = PtyPair::open(&PtyOptions::default()).unwrap();
    drop(master);
    let err = slave.read_some(&mut b, soon()).unwrap_err();
    assert!(matches!(err, LinkError::Closed { .. }), "{err:?}");
}

#[test]
fn bad_paths_and_busy_ports_are_clear_errors() {
    let err = SerialLink::open("/dev/ttyUSB-robobus-missing", 115_200).unwrap_err();
    assert!(matches!(err, LinkError::NoSuchDevice { .. }));
    assert!(err.to_string().contains("/dev/ttyUSB-robobus-missing"));

    let PtyPair {
        slave_path,
        slave,
        master,
    } = PtyPair::open(&PtyOptions::default()).unwrap();
    drop(slave);
    let _first = SerialLink::open(&slave_path, 115_200).unwrap();
    let err = SerialLink::open(&slave_path, 115_200).unwrap_err();
    assert!(
        matches!(&err, LinkError::Busy { path } if *path == slave_path),
        "{err:?}"
    );
    assert!(
        err.to_string().contains(&slave_path.display().to_string()),
        "{err}"
    );
    drop(master);

    let err = SerialLink::open("/proc/self/status", 115_200).unwrap_err();
    assert!(err.to_string().contains("/proc/self/status"), "{err}");

    let err = PtyPair::open(&PtyOptions {
        baud: 12_345,
        ..PtyOptions::default()
    })
    .unwrap_err();
    assert!(matches!(
        err,
        LinkError::UnsupportedBaud { baud: 12_345, .. }
    ));
}

#[test]
fn writes_nobody_drains_time_out_instead_of_hanging() {
    let PtyPair {
        mut master, slave, ..
    } = PtyPair::open(&PtyOptions::default()).unwrap();
    master.set_write_timeout(Duration::from_millis(100));
    let big = vec![0x5A; 1 << 20];
    let start = Instant::now();
    let err = master.write_all(&big).unwrap_err();
    assert!(
        matches!(err, LinkError::WriteTimeout { written, total } if written > 0 && written < total),
        "{err:?}"
    );
    assert!(start.elapsed() < Duration::from_secs(5));
    drop(slave);
}

/// `serialport` sets line rates with termios2 (`BOTHER`); the master side must read any
/// such rate back, standard or not, without failing (a simulator reads it to follow its
/// client's baud rate).
#[test]
fn termios2_rates_set_through_serialport_read_back_on_the_master() {
    let PtyPair {
        master, slave_path, ..
    } = PtyPair::open(&PtyOptions::default()).unwrap();
    let path = slave_path.to_str().unwrap().to_owned();
    let mut port = SerialLink::open(&path, 115_200).unwrap();
    assert_eq!(termios_speed(&master).unwrap(), Some(115_200));
    port.set_baud(250_000).unwrap();
    assert_eq!(termios_speed(&master).unwrap(), Some(250_000));
}

/// Child processes must not inherit the pty: an inherited master keeps the pty alive, so
/// closing it would never hang up the slave side (a client's terminal, a test's child).
#[test]
fn pty_descriptors_are_close_on_exec() {
    use std::os::fd::AsFd;
    let pair = PtyPair::open(&PtyOptions::default()).unwrap();
    for link in [&pair.master, &pair.slave] {
        let flags = nix::fcntl::fcntl(link.as_fd(), nix::fcntl::FcntlArg::F_GETFD).unwrap();
        assert!(
            nix::fcntl::FdFlag::from_bits_truncate(flags).contains(nix::fcntl::FdFlag::FD_CLOEXEC),
            "{link:?}"
        );
    }
}
