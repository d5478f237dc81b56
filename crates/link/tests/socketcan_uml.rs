//! Real `SocketCAN`, CAN FD on `vcan0`, inside User-Mode Linux (this machine's kernel has no
//! CAN support). `scripts/uml/ensure-uml` provisions the kernel and can-utils under
//! `target/uml`; `scripts/uml/run-in-uml` boots it with vcan0 (MTU 72) and runs this test
//! binary's inner test inside the guest, which exchanges frames with can-utils' `cansend`,
//! `candump` and `canplayer` and checks candump logs both ways.

// Helpers outside #[test] functions may unwrap and panic too: a failure is a failed test.
#![allow(clippy::unwrap_used, clippy::panic)]
#![cfg(target_os = "linux")]

use crate::common;

use std::fmt::Write as _;
use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant, SystemTime};

use robobus_link::capture::{CandumpWriter, parse_candump_line};
use robobus_link::frame_link::FrameLinkError;
use robobus_link::{CandumpRecord, FrameLink, IdFilter, SocketCanLink, read_candump};
use robobus_whj::CanFrame;

const IN_UML_ENV: &str = "ROBOBUS_LINK_IN_UML";

#[test]
fn socketcan_fd_on_vcan0_inside_user_mode_linux() {
    let uml = common::provision("uml/ensure-uml");
    robobus_testkit::Inner::exact(module_path!(), "inner_socketcan_in_uml", IN_UML_ENV)
        .env(IN_UML_ENV, uml)
        .in_uml()
        .expect_marker("UML SOCKETCAN OK");
}

fn fd(id: u16, data: &[u8]) -> CanFrame {
    CanFrame::new_fd(CanFrame::standard_id(id).unwrap(), data).unwrap()
}

fn ramp(n: usize, k: u8) -> Vec<u8> {
    (0..n)
        .map(|i| u8::try_from(i).unwrap().wrapping_mul(k).wrapping_add(1))
        .collect()
}

fn hex(b: &[u8]) -> String {
    let mut s = String::with_capacity(2 * b.len());
    for x in b {
        let _ = write!(s, "{x:02X}");
    }
    s
}

fn run(cmd: &str, args: &[&str]) -> String {
    let out = Command::new(cmd)
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("{cmd}: {e}"));
    assert!(
        out.status.success(),
        "{cmd} {args:?} failed: {}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Raw-socket receivers registered on vcan0 (the kernel's `rx_all` list).
fn vcan0_receivers() -> usize {
    std::fs::read_to_string("/proc/net/can/rcvlist_all")
        .unwrap()
        .lines()
        .filter(|l| l.trim_start().starts_with("vcan0 ") && l.trim_end().ends_with("raw"))
        .count()
}

/// Starts `candump` with `args` and waits until its socket is registered with the kernel,
/// so no frame sent afterwards can be missed.
fn candump(args: &[&str], cwd: &std::path::Path) -> Child {
    let before = vcan0_receivers();
    let child = Command::new("candump")
        .args(args)
        .current_dir(cwd)
        .stdout(Stdio::piped())
        .spawn()
        .expect("candump (can-utils) on PATH inside the guest");
    let deadline = Instant::now() + Duration::from_secs(20);
    while vcan0_receivers() <= before {
        assert!(Instant::now() < deadline, "candump never opened its socket");
        std::thread::sleep(Duration::from_millis(10));
    }
    child
}

fn recv(link: &mut SocketCanLink) -> CanFrame {
    let r = link.recv(Instant::now() + Duration::from_secs(10)).unwrap();
    let age = SystemTime::now()
        .duration_since(r.timestamp.expect("kernel timestamp"))
        .unwrap();
    assert!(age < Duration::from_secs(10), "timestamp too old: {age:?}");
    r.frame
}

/// Runs inside the UML guest (started by the test above); fails anywhere else.
#[test]
#[ignore = "run by socketcan_fd_on_vcan0_inside_user_mode_linux inside User-Mode Linux"]
// One guest boot runs the whole scenario, step by step.
#[allow(clippy::too_many_lines)]
fn inner_socketcan_in_uml() {
    std::env::var(IN_UML_ENV)
        .expect("this test only runs inside the UML guest its outer test boots");
    let dir = tempfile::tempdir().unwrap();

    // Bad input: each error names the interface.
    run("ip", &["link", "add", "dev", "vcan1", "type", "vcan"]);
    run("ip", &["link", "set", "vcan1", "mtu", "16", "up"]);
    let e = SocketCanLink::open("vcan1").unwrap_err();
    assert!(
        matches!(&e, FrameLinkError::NotFdCapable { iface, mtu: 16 } if iface == "vcan1"),
        "{e}"
    );
    let e = SocketCanLink::open("vcan9").unwrap_err();
    assert!(
        matches!(&e, FrameLinkError::NoSuchInterface { iface, .. } if iface == "vcan9"),
        "{e}"
    );
    assert!(e.to_string().contains("type vcan"), "{e}");
    let e = SocketCanLink::open("lo").unwrap_err();
    assert!(
        matches!(&e, FrameLinkError::NotCan { iface, .. } if iface == "lo"),
        "{e}"
    );

    let mut link = SocketCanLink::open("vcan0").unwrap();
    assert_eq!(link.iface(), "vcan0");

    // 1. Our frames, seen by candump -L.
    let ext = CanFrame::new_fd(CanFrame::extended_id(0x1234_5678).unwrap(), &ramp(12, 3))
        .unwrap()
        .with_esi(true);
    let classic =
        CanFrame::new_classic(CanFrame::standard_id(0x321).unwrap(), &ramp(8, 9)).unwrap();
    let ours = [
        fd(0x007, &ramp(4, 1)),
        fd(0x017, &ramp(16, 5)),
        fd(0x027, &ramp(64, 7)),
        fd(0x037, &ramp(8, 11)).with_brs(false),
        ext,
        classic,
    ];
    let mut dump = candump(&["-L", "-n", &ours.len().to_string(), "vcan0"], dir.path());
    for f in &ours {
        link.send(f).unwrap();
    }
    let lines: Vec<String> = BufReader::new(dump.stdout.take().unwrap())
        .lines()
        .map(Result::unwrap)
        .collect();
    assert!(dump.wait().unwrap().success());
    let seen: Vec<CanFrame> = lines
        .iter()
        .map(|l| {
            let rec = parse_candump_line(l).unwrap_or_else(|e| panic!("{l:?}: {e}"));
            assert_eq!(rec.iface, "vcan0");
            rec.frame
        })
        .collect();
    assert_eq!(seen, ours, "candump -L saw:\n{}", lines.join("\n"));

    // 2. cansend's frames, received by us (flags, lengths, extended IDs).
    run("cansend", &["vcan0", "123##1DEADBEEF"]);
    assert_eq!(recv(&mut link), fd(0x123, &[0xDE, 0xAD, 0xBE, 0xEF]));
    let d16 = ramp(16, 13);
    run("cansend", &["vcan0", &format!("1ABCDEF0##3{}", hex(&d16))]);
    let want = CanFrame::new_fd(CanFrame::extended_id(0x1ABC_DEF0).unwrap(), &d16)
        .unwrap()
        .with_esi(true);
    assert_eq!(recv(&mut link), want);
    let d64 = ramp(64, 17);
    run("cansend", &["vcan0", &format!("7FF##1{}", hex(&d64))]);
    assert_eq!(recv(&mut link), fd(0x7FF, &d64));
    run("cansend", &["vcan0", "042##0AABB"]);
    assert_eq!(recv(&mut link), fd(0x042, &[0xAA, 0xBB]).with_brs(false));
    run("cansend", &["vcan0", "100#0102"]);
    assert_eq!(
        recv(&mut link),
        CanFrame::new_classic(CanFrame::standard_id(0x100).unwrap(), &[1, 2]).unwrap()
    );
    assert!(
        link.recv(Instant::now() + Duration::from_millis(100))
            .unwrap_err()
            .is_timeout()
    );

    // 3. Kernel ID filters.
    link.set_filters(&[IdFilter::standard(0x123)]).unwrap();
    run("cansend", &["vcan0", "124##1AA"]);
    run("cansend", &["vcan0", "123##1BB"]);
    assert_eq!(recv(&mut link), fd(0x123, &[0xBB]));
    assert!(
        link.recv(Instant::now() + Duration::from_millis(100))
            .unwrap_err()
            .is_timeout()
    );
    link.set_filters(&[]).unwrap();

    // 4. A `candump -l` capture parses with our reader.
    let mut dump = candump(&["-l", "-n", "3", "vcan0"], dir.path());
    let sent = [
        fd(0x201, &ramp(4, 2)),
        fd(0x202, &ramp(16, 4)),
        fd(0x203, &ramp(64, 6)),
    ];
    for f in &sent {
        link.send(f).unwrap();
    }
    assert!(dump.wait().unwrap().success());
    let log = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| {
            p.file_name()
                .unwrap()
                .to_string_lossy()
                .starts_with("candump-")
        })
        .expect("candump -l wrote no log file");
    let text = std::fs::read_to_string(&log).unwrap();
    let records: Vec<CandumpRecord> = read_candump(text.as_bytes())
        .collect::<Result<_, _>>()
        .unwrap();
    let frames: Vec<CanFrame> = records.iter().map(|r| r.frame).collect();
    assert_eq!(frames, sent, "candump -l wrote:\n{text}");
    assert!(
        records
            .iter()
            .all(|r| r.iface == "vcan0" && r.timestamp.as_secs() > 1_000_000_000)
    );

    // 5. A log we write is played by canplayer onto vcan0 (and received by us) and
    //    converted by log2asc.
    let ours_path = dir.path().join("ours.log");
    let mut w = CandumpWriter::new(std::fs::File::create(&ours_path).unwrap());
    for (i, f) in ours.iter().enumerate() {
        let rec = CandumpRecord {
            timestamp: Duration::new(1_795_360_410, 1_000 * u32::try_from(i).unwrap()),
            iface: "vcan0".into(),
            frame: *f,
        };
        w.write(&rec).unwrap();
    }
    w.flush().unwrap();
    drop(w);
    let path = ours_path.to_str().unwrap();
    run("canplayer", &["-I", path, "-t"]);
    let mut played = Vec::new();
    for _ in &ours {
        played.push(recv(&mut link));
    }
    assert_eq!(played, ours);
    let asc = run("log2asc", &["-I", path, "vcan0"]);
    assert!(asc.lines().count() >= ours.len(), "log2asc output:\n{asc}");
    assert!(asc.contains("CANFD"), "log2asc output:\n{asc}");
    println!("UML SOCKETCAN OK");
}
