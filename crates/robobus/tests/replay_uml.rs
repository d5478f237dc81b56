//! can-utils read our captures: inside User-Mode Linux (real SocketCAN, a CAN FD vcan0),
//! a candump log written by `ops::capture::capture_frame_link` around a link to the WHJ
//! simulator is played onto vcan0 by can-utils' `canplayer` while `candump -L` records;
//! the recorded frames equal the captured ones, and both logs replay to the same meanings.
//! `scripts/uml/ensure-uml` provisions the kernel and can-utils; `scripts/uml/run-in-uml`
//! boots the guest and runs this binary's inner test there.

#![allow(clippy::unwrap_used, clippy::panic)]
#![cfg(target_os = "linux")]

use crate::whj_common;

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use robobus::ops::capture::{Overwrite, capture_frame_link};
use robobus::ops::replay::{self, Direction, EntryKind, ReplayOptions};
use robobus_link::FrameLink;
use robobus_link::capture::parse_candump_line;
use robobus_whj::broadcast::BroadcastPosition;
use robobus_whj::units::Position;
use robobus_whj::{CanFrame, JointId, ReplyMask, Request};

const IN_UML_ENV: &str = "ROBOBUS_REPLAY_IN_UML";

#[test]
fn can_utils_play_our_capture_inside_user_mode_linux() {
    robobus_testkit::Inner::exact(
        module_path!(),
        "inner_can_utils_play_our_capture",
        IN_UML_ENV,
    )
    .in_uml()
    .expect_marker("UML REPLAY OK");
}

/// Raw-socket receivers registered on vcan0.
fn vcan0_receivers() -> usize {
    std::fs::read_to_string("/proc/net/can/rcvlist_all")
        .unwrap()
        .lines()
        .filter(|l| l.trim_start().starts_with("vcan0 ") && l.trim_end().ends_with("raw"))
        .count()
}

/// `candump -L -n N vcan0`, once its socket is registered (no frame can be missed).
fn candump(n: usize) -> Child {
    let before = vcan0_receivers();
    let child = Command::new("candump")
        .args(["-L", "-n", &n.to_string(), "vcan0"])
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

fn frames_of(text: &str) -> Vec<CanFrame> {
    text.lines()
        .map(|l| {
            parse_candump_line(l)
                .unwrap_or_else(|e| panic!("{l:?}: {e}"))
                .frame
        })
        .collect()
}

fn meanings(path: &Path) -> Vec<(Direction, EntryKind, Option<u32>, String)> {
    replay::open(path, &ReplayOptions::default())
        .unwrap()
        .map(|e| {
            let e = e.unwrap();
            (e.direction, e.kind, e.can_id, e.text)
        })
        .collect()
}

/// Runs inside the UML guest (started by the test above); fails anywhere else.
#[test]
#[ignore = "run by can_utils_play_our_capture_inside_user_mode_linux inside User-Mode Linux"]
fn inner_can_utils_play_our_capture() {
    std::env::var(IN_UML_ENV)
        .expect("this test only runs inside the UML guest its outer test boots");
    let dir = tempfile::tempdir().unwrap();
    let ours = dir.path().join("capture.log");

    // 1. A capture of a session with the simulated joint, written by our helper.
    let j1 = JointId::new(1).unwrap();
    let target = Position::from_degrees(-7.25).unwrap();
    let broadcast = BroadcastPosition::new(ReplyMask::only(j1).unwrap())
        .with_target(j1, target)
        .unwrap();
    let requests = [
        Request::start_application(j1),
        Request::read_position(j1),
        Request::enable(j1, true),
        Request::PositionServo { joint: j1, target },
        Request::StatusQuery { joint: j1 },
        Request::BroadcastPosition(broadcast),
    ];
    {
        let (_sim, endpoint) = whj_common::memory(whj_common::chain(1));
        let mut link = capture_frame_link(endpoint, &ours, "can0", Overwrite::No).unwrap();
        for r in &requests {
            link.send(&r.to_frame()).unwrap();
            link.recv(Instant::now() + Duration::from_secs(5)).unwrap();
        }
    }
    let captured = std::fs::read_to_string(&ours).unwrap();
    let want = frames_of(&captured);
    assert_eq!(want.len(), 2 * requests.len(), "{captured}");

    // 2. canplayer plays it onto vcan0 (frames logged on can0), candump -L records.
    let mut dump = candump(want.len());
    let out = Command::new("canplayer")
        .args(["-I", ours.to_str().unwrap(), "-t", "vcan0=can0"])
        .output()
        .expect("canplayer (can-utils) on PATH inside the guest");
    assert!(
        out.status.success(),
        "canplayer: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let lines: Vec<String> = BufReader::new(dump.stdout.take().unwrap())
        .lines()
        .map(Result::unwrap)
        .collect();
    assert!(dump.wait().unwrap().success());
    let recorded = lines.join("\n");
    assert_eq!(
        frames_of(&recorded),
        want,
        "candump -L recorded:\n{recorded}\nfrom:\n{captured}"
    );
    assert!(lines.iter().all(|l| l.contains(" vcan0 ")), "{recorded}");

    // 3. Both logs replay to the same meanings (the flags and lengths survived).
    let theirs = dir.path().join("candump.log");
    std::fs::write(&theirs, format!("{recorded}\n")).unwrap();
    let ours_meant = meanings(&ours);
    assert_eq!(meanings(&theirs), ours_meant);
    assert!(
        ours_meant.iter().all(|m| m.1 != EntryKind::Malformed),
        "{ours_meant:#?}"
    );
    assert_eq!(
        ours_meant[6].3,
        "J1 position servo target position -7.2500 °"
    );
    println!("UML REPLAY OK");
}
